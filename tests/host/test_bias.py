"""Gyro bias on synthetic traces whose truth is known (sphere.fusion.bias_scenarios): SphereFilter, as `sphere eval`
and the daemon build it, learns the bias at rest and holds it in motion (its motion measurement did not earn its
place on held-out folds and went, host/docs/fusion.md); and the generator itself checked against physics with an
independent library."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sphere.fusion import bias_scenarios, factory

DEG = np.pi / 180.0
SECONDS = 31.0


def _run(scenario, seconds, **kw):
    tr = bias_scenarios.trace(scenario, seconds=seconds, **kw)
    f = factory.make("sphere", tr.dt_s)
    d = f.update_batch(tr.gyr_rad_s, tr.acc_m_s2, tr.mag_uT, tr.dt_s, diagnostics=True)
    return tr, d


@pytest.fixture(scope="module", params=bias_scenarios.SCENARIOS)
def run(request):
    return _run(request.param, SECONDS)


def test_trace_rests_only_for_the_first_two_seconds(run):
    tr, d = run
    moving = np.linalg.norm(tr.gyr_rad_s - tr.bias_rad_s, axis=1) > 5 * DEG
    assert not moving[: int(1.9 / tr.dt_s)].any()
    assert moving[int(3.0 / tr.dt_s):].mean() > 0.99
    assert not d["rest"][int(2.5 / tr.dt_s):].any()  # the filter never sees a rest after the first 2 s


def _err_dps(tr, bias_rad_s, at_s):
    i = int(round(at_s / tr.dt_s)) - 1
    return float(np.linalg.norm(bias_rad_s[i] - tr.bias_rad_s[i]) / DEG)


def test_the_bias_is_learned_at_rest_and_held_in_motion():
    """A 6 s rest: the rest measurement (from 1.5 s of stillness on) brings b within 0.05 °/s of the power-on bias
    (0.52 °/s off at the start); in motion nothing measures it, so b stays what the rest left, to the bit."""
    tr, d = _run("motion", 20.0, rest_s=6.0)
    assert _err_dps(tr, np.zeros_like(tr.bias_rad_s), 1.0) > 0.5
    assert _err_dps(tr, d["bias_rad_s"], 5.9) < 0.05
    moving = ~d["rest"] & (np.arange(len(tr.gyr_rad_s)) * tr.dt_s > 7.0)
    assert moving.sum() > 0.6 * len(moving)
    assert np.array_equal(d["bias_rad_s"][moving], np.broadcast_to(d["bias_rad_s"][moving][0], (moving.sum(), 3)))
    # without the rest measurement (a structure --cv may choose) b stays zero
    f = factory.make("sphere", tr.dt_s, bias_rest=False)
    off = f.update_batch(tr.gyr_rad_s, tr.acc_m_s2, tr.mag_uT, tr.dt_s, diagnostics=True)
    assert not off["bias_rad_s"].any()


def test_magnet_from_the_start_is_flagged(run):
    tr, d = run
    after = d["mag_disturbed"][int(5.0 / tr.dt_s):]
    if tr.name == "magnet":
        assert after.mean() > 0.8
    else:
        assert after.mean() < 0.05


def test_batch_diagnostics_are_the_per_sample_state():
    tr = bias_scenarios.trace("step", seconds=6.0, seed=3)  # rest 2 s, then motion
    d = factory.make("sphere", tr.dt_s).update_batch(tr.gyr_rad_s, tr.acc_m_s2, tr.mag_uT, tr.dt_s, diagnostics=True)
    f = factory.make("sphere", tr.dt_s)
    q = np.array([f.update(g, a, m, tr.dt_s) for g, a, m in zip(tr.gyr_rad_s, tr.acc_m_s2, tr.mag_uT)])
    assert np.array_equal(q, d["quat"])
    assert np.array_equal(np.array(f.bias), d["bias_rad_s"][-1])
    assert f.at_rest == d["rest"][-1] and f.mag_disturbed == d["mag_disturbed"][-1]
    assert d["rest"].any()  # the first 2 s are a rest


# -- the generator, against physics (scipy's rotations, not our quaternion code) -------------------------

def test_generator_orientation_integrates_its_gyro():
    tr = bias_scenarios.trace("ramp", seconds=8.0, noise=0.0)
    w = tr.gyr_rad_s - tr.bias_rad_s
    r = Rotation.from_quat(tr.quat[0, [1, 2, 3, 0]])
    for i in range(1, len(w)):
        r = r * Rotation.from_rotvec(w[i] * tr.dt_s)  # body rate: right multiplication
    truth = Rotation.from_quat(tr.quat[-1, [1, 2, 3, 0]])
    assert (r.inv() * truth).magnitude() < 1e-9


def test_generator_sensors_read_the_earth_at_rest():
    tr = bias_scenarios.trace("magnet", seconds=2.0, noise=0.0)
    r = Rotation.from_quat(tr.quat[:, [1, 2, 3, 0]])
    acc_e = r.apply(tr.acc_m_s2)
    assert np.allclose(acc_e, [0.0, 0.0, bias_scenarios.G], atol=1e-9)  # specific force: up, at rest
    mag_e = r.apply(tr.mag_uT - bias_scenarios.MAGNET_UT)
    dip = np.degrees(np.arctan2(-mag_e[:, 2], np.hypot(mag_e[:, 0], mag_e[:, 1])))
    assert np.allclose(dip, bias_scenarios.DIP_DEG) and np.allclose(mag_e[:, 0], 0.0, atol=1e-9)  # north = +y
    assert np.allclose(np.linalg.norm(tr.mag_uT, axis=1), np.linalg.norm(tr.mag_uT[0]))  # constant while still


def test_generator_biases():
    t = bias_scenarios.trace("step", seconds=10.0, noise=0.0)
    jump = t.bias_rad_s[-1] - t.bias_rad_s[0]
    assert np.allclose(jump, bias_scenarios.STEP_DPS * DEG)
    r = bias_scenarios.trace("ramp", seconds=300.0, noise=0.0, translation=0.0, rate_hz=20.0)
    assert np.isclose(np.linalg.norm(r.bias_rad_s[-1] - r.bias_rad_s[0]) / DEG, 0.5, atol=0.01)  # 0.5 °/s in 5 min
    with pytest.raises(ValueError, match="unknown scenario"):
        bias_scenarios.trace("nope")
