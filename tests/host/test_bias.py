"""Gyro bias without long rests (issue 13): SphereFilter, as `sphere eval` and the daemon build it, on synthetic
traces whose truth is known; and the generator itself checked against physics with an independent library."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sphere import broad
from sphere.fusion import bias_scenarios, registry
from sphere.fusion.sphere_filter import _f_quantile, _fit

DEG = np.pi / 180.0
SECONDS = 31.0
AT_S = 30.0
TOL_DPS = 0.05  # issue 13: within 0.05 °/s of the truth 30 s in


def _run(scenario, seconds):
    tr = bias_scenarios.trace(scenario, seconds=seconds)
    f = registry.make("sphere", tr.dt_s)
    d = f.update_batch(tr.gyr_rad_s, tr.acc_m_s2, tr.mag_uT, tr.dt_s, diagnostics=True)
    d["bias_changes"] = f.bias_changes
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


def test_bias_estimate_30_s_in(run):
    tr, d = run
    err = _err_dps(tr, d["bias_rad_s"], AT_S)
    start = np.linalg.norm(tr.bias_rad_s[0]) / DEG
    assert err < TOL_DPS, f"{tr.name}: bias off by {err:.3f} °/s at {AT_S:g} s (started {start:.2f} °/s off)"


def test_the_change_test_fires_on_the_step_only(run):
    """The 0.61 °/s step at 8 s is caught once (two consecutive 6 s windows, so some 15 s after the step, the low-pass
    chain's lag included); a constant bias, the warm-up ramp and the magnet raise no alarm."""
    tr, d = run
    assert d["bias_changes"] == (1 if tr.name == "step" else 0), tr.name


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_bias_step_30_s_in_on_more_seeds(seed):
    """The step on more seeds than the module's seed 0 (1 and 3 missed the target, 0.053 and 0.052 °/s, while the
    change test restarted b with P₀ and so threw away the window that had just measured the new bias)."""
    tr = bias_scenarios.trace("step", seconds=SECONDS, seed=seed)
    f = registry.make("sphere", tr.dt_s)
    d = f.update_batch(tr.gyr_rad_s, tr.acc_m_s2, tr.mag_uT, tr.dt_s, diagnostics=True)
    assert f.bias_changes == 1
    err = _err_dps(tr, d["bias_rad_s"], AT_S)
    assert err < TOL_DPS, f"seed {seed}: bias off by {err:.3f} °/s at {AT_S:g} s"


def test_a_detected_change_restarts_from_the_windows_least_squares_bias_and_its_covariance():
    """At a detected change b and P are the least-squares fit of one constant bias to the latest K blocks'
    measurements z = y + H·b_block (numpy's lstsq here; the magnetometer's rows already scaled to the tilt rows'
    noise) and that fit's covariance σ²·(HᵀH)⁻¹, σ² from its residuals."""
    from sphere.fusion.sphere_filter import SphereFilter

    seen = []

    class Spy(SphereFilter):
        def _ct_clear(self):
            self._last_blocks = [(list(r), list(b)) for r, b in self._ct_blocks]  # the 2K blocks the test saw
            super()._ct_clear()

        def _change_test(self, H, y, mag=None):
            fired = super()._change_test(H, y, mag)
            if fired:
                seen.append((self._last_blocks, list(self.bias), np.array(self.bias_P)))
            return fired

    tr = bias_scenarios.trace("step", seconds=SECONDS, seed=1)
    f = Spy(**registry.params("sphere"))
    f.update_batch(tr.gyr_rad_s, tr.acc_m_s2, tr.mag_uT, tr.dt_s)
    assert len(seen) == 1 and f.bias_changes == 1
    blocks, bias, P = seen[0]
    k = f.cfg["bias_change_blocks"]
    assert len(blocks) == 2 * k
    rows = np.array([r for rs, _ in blocks[k:] for r in rs])  # the latest window: (z, h0, h1, h2) per row
    assert len(rows) == 4 * k  # the tilt rows and the magnetometer's in every block
    H, z = rows[:, 1:], rows[:, 0]
    ls, rss, *_ = np.linalg.lstsq(H, z, rcond=None)
    var = rss[0] / (len(rows) - 3)
    assert np.allclose(bias, ls, rtol=1e-9, atol=1e-12)
    assert np.allclose(P, var * np.linalg.inv(H.T @ H), rtol=1e-9, atol=1e-15)
    assert np.isclose(f._track_w, var / f._tb)  # and the noise it showed, per step, while it pins the bias down


def test_the_change_test_does_not_fire_on_real_fast_rotation():
    """BROAD 07 (fast rotation, 184 s): its motion leaves bias-like errors of 0.3-1 °/s in the measurement that flip
    every few seconds; one window's F-test alone called them changes, the two agreeing windows do not."""
    try:
        t = broad.load_trial(broad.find_trial("07"))
    except broad.BroadMissing as e:
        pytest.skip(f"BROAD trials not available: {e}")
    f = registry.make("sphere", t.dt_s)
    f.update_batch(t.gyr_rad_s, t.acc_m_s2, t.mag_uT, t.dt_s)
    assert f.bias_changes == 0


def test_block_fit_is_least_squares_and_its_f_test_holds_its_level():
    """The change test's pieces against numpy and scipy: _fit is the least-squares solution with the regression's
    F statistic (against 0 or against a given bias), the quantiles written out are scipy's, and on pure noise (e = 0)
    F exceeds the (1 − α) quantile of F(3, n − 3) in a share α of windows."""
    from scipy.stats import f as f_dist

    from sphere.fusion.sphere_filter import _F_QUANTILES

    rng = np.random.default_rng(5)
    for (dfn, dfd, p), q in _F_QUANTILES.items():  # the table the daemon uses without importing scipy
        assert np.isclose(q, f_dist.ppf(p, dfn, dfd), rtol=1e-9), (dfn, dfd)
    assert np.isclose(_f_quantile(3, 25, 0.999), f_dist.ppf(0.999, 3, 25))  # computed
    e_true = np.array([0.3, -0.2, 0.1])
    for n in (12, 24, 17):  # a window of tilt rows only, with the magnetometer's rows, a mix
        h = rng.normal(0.0, 1.0, (n, 3))
        y = h @ e_true + rng.normal(0.0, 0.05, n)
        e, ai, var, fstat = _fit(np.c_[y, h].tolist())
        ls, rss, *_ = np.linalg.lstsq(h, y, rcond=None)
        assert np.allclose(e, ls) and np.isclose(var, rss[0] / (n - 3))
        assert np.isclose(fstat, (y @ y - rss[0]) / 3 / var) and np.allclose(ai, np.linalg.inv(h.T @ h))
        about = np.array([0.2, -0.1, 0.0])
        d = ls - about
        assert np.isclose(_fit(np.c_[y, h].tolist(), about=about)[3], d @ (h.T @ h) @ d / 3 / var)
    alpha, n, trials = 0.05, 12, 4000
    q = _f_quantile(3, n - 3, 1 - alpha)
    hits = 0
    for _ in range(trials):
        hits += _fit(rng.normal(0.0, 1.0, (n, 4)).tolist())[3] > q
    assert abs(hits / trials - alpha) < 4 * np.sqrt(alpha * (1 - alpha) / trials), hits / trials


@pytest.mark.parametrize("seed", [1, 8, 20])
def test_warm_up_ramp_30_s_in_on_the_seeds_it_missed(seed):
    """The ramp on the seeds that missed the target with the tilt rows alone (0.061, 0.051, 0.050 °/s at 30 s): the
    magnetometer's rows see the vertical component of the bias and, free of the hand's translation, the rest."""
    tr = bias_scenarios.trace("ramp", seconds=SECONDS, seed=seed)
    f = registry.make("sphere", tr.dt_s)
    d = f.update_batch(tr.gyr_rad_s, tr.acc_m_s2, tr.mag_uT, tr.dt_s, diagnostics=True)
    assert f.bias_changes == 0
    err = _err_dps(tr, d["bias_rad_s"], AT_S)
    assert err < TOL_DPS, f"seed {seed}: bias off by {err:.3f} °/s at {AT_S:g} s"
    # without them the filter is what it was: these seeds miss
    f = registry.make("sphere", tr.dt_s, bias_mag=False)
    d = f.update_batch(tr.gyr_rad_s, tr.acc_m_s2, tr.mag_uT, tr.dt_s, diagnostics=True)
    assert _err_dps(tr, d["bias_rad_s"], AT_S) >= TOL_DPS


def _rows_against_truth(tr):
    """Each magnetometer row's and tilt row's value minus h·b_true (°/s): what is not the bias in them."""
    f = registry.make("sphere", tr.dt_s)
    mag, tilt, i = [], [], [0]
    rows, test = f._mag_rows, f._change_test

    def mag_rows(*a):
        r = rows(*a)
        if r is not None:
            bt = tr.bias_rad_s[i[0]]
            mag.extend([r[2] - np.dot(r[0], bt), r[3] - np.dot(r[1], bt)])
        return r

    def change_test(H, y, m=None):
        bt, b = tr.bias_rad_s[i[0]], np.array(f.bias)
        tilt.extend([y[j] + np.dot(H[j], b - bt) for j in range(2)])
        return test(H, y, m)

    f._mag_rows, f._change_test = mag_rows, change_test
    for i[0] in range(len(tr.gyr_rad_s)):
        f.update(tr.gyr_rad_s[i[0]], tr.acc_m_s2[i[0]], tr.mag_uT[i[0]], tr.dt_s)
    return np.array(mag) / DEG, np.array(tilt[400:]) / DEG  # the tilt rows once their low-pass has settled


def test_magnetometer_rows_are_exact_and_free_of_the_hands_translation():
    """Noise-free traces: the magnetometer's rows equal h·b_true to within 0.005 °/s with the hand's translation and
    0.0015 °/s without it (second-order terms), where the tilt rows carry some 0.1 °/s of the translation."""
    mag, tilt = _rows_against_truth(bias_scenarios.trace("motion", seconds=20.0, seed=3, noise=0.0))
    assert len(mag) > 700 and np.abs(mag).max() < 0.005, np.abs(mag).max()
    assert np.sqrt(np.mean(tilt ** 2)) > 0.05
    mag, _ = _rows_against_truth(bias_scenarios.trace("motion", seconds=20.0, seed=3, noise=0.0, translation=0.0))
    assert np.abs(mag).max() < 0.0015, np.abs(mag).max()


def test_a_field_turning_with_the_sensor_is_not_used():
    """The magnet riding on the sensor: where the disturbance test lets the field through for a while (seed 120, at
    15.4 s) it turns with the sensor at several °/s; the χ² test on the rows refuses those steps (without it the bias
    was 0.098 °/s off at 30 s)."""
    tr = bias_scenarios.trace("magnet", seconds=SECONDS, seed=120)
    f = registry.make("sphere", tr.dt_s)
    verdicts = []
    consistent = f._mag_consistent
    f._mag_consistent = lambda *a: verdicts.append(consistent(*a)) or verdicts[-1]
    d = f.update_batch(tr.gyr_rad_s, tr.acc_m_s2, tr.mag_uT, tr.dt_s, diagnostics=True)
    assert verdicts.count(False) >= 5
    assert _err_dps(tr, d["bias_rad_s"], AT_S) < TOL_DPS


def test_magnet_from_the_start_is_flagged(run):
    tr, d = run
    after = d["mag_disturbed"][int(5.0 / tr.dt_s):]
    if tr.name == "magnet":
        assert after.mean() > 0.8
    else:
        assert after.mean() < 0.05


def test_batch_diagnostics_are_the_per_sample_state():
    tr = bias_scenarios.trace("step", seconds=6.0, seed=3)
    d = registry.make("sphere", tr.dt_s).update_batch(tr.gyr_rad_s, tr.acc_m_s2, tr.mag_uT, tr.dt_s, diagnostics=True)
    f = registry.make("sphere", tr.dt_s)
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
