"""`sphere calibrate` against `synthetic:calibration` however late it joins: the script repeats (still,
turns about each axis, six faces held longer than the 3 s still the gyro step needs, tumbling), so each
guided step finds what it asks for within one round. The steps are fed the script in chip units as the
samples would arrive (no board; tests/e2e/test_calibrate_sim.py runs the real session on the virtual sphere)."""

import numpy as np
import pytest

from sphere.calibration import axis_check
from sphere.calibration import session as session
from sphere import chips
from sphere.sim import trace as T

ROUND_S = T.calibration_script(200.0)[1][11][1]  # the second round's still starts here


@pytest.fixture(scope="module")
def full():
    ct = T.to_chips(T.calibration(200.0))
    t = np.arange(len(ct.accel_lsb)) / ct.accel_rate_hz
    mag_t = np.arange(len(ct.mag_lsb)) / ct.mag_rate_hz
    return session.Series(t, ct.accel_lsb.astype(float), ct.gyro_lsb.astype(float), mag_t, ct.mag_lsb.astype(float))


def _window(full, t0, t1):
    i0, i1 = np.searchsorted(full.t, [t0, t1], "right")
    k0, k1 = np.searchsorted(full.mag_t, [t0, t1], "right")
    return session.Series(full.t[i0:i1], full.accel[i0:i1], full.gyro[i0:i1], full.mag_t[k0:k1], full.mag[k0:k1])


def test_the_script_repeats():
    _, timeline = T.calibration_script(200.0)
    names = [n for n, _, _ in timeline]
    assert names[:11] == ["still", "turn x", "turn y", "turn z", "+x", "+y", "-x", "-y", "-z", "+z", "tumble"]
    assert names[:11] == names[11:22]
    assert all(t1 - t0 >= session.STILL_S + 0.5 for n, t0, t1 in timeline[:22] if n[0] in "+-s")


@pytest.mark.slow
@pytest.mark.parametrize("join_s", [0.5, 7.0, 20.0, 40.0, 60.0])
def test_every_step_finishes_within_a_round_of_joining(full, join_s):
    step = 0.1
    now, span = join_s, None
    while span is None or span.seconds < session.STILL_S:
        now += step
        span = session.trailing_still(_window(full, join_s, now))
    assert now - join_s < ROUND_S, "gyro step"
    sel = (full.t >= span.t0) & (full.t < span.t1)  # the span's samples, by device time (as calibrate does)
    gyro = full.gyro[sel]
    start = now
    while not (f := axis_check.fit(_window(full, start, now), gyro.mean(axis=0), full=False)).done:
        now += 0.5
        assert now - start < ROUND_S, "axis step"
    assert axis_check.verdict(f, "aligned").ok
    start, seen = now, {}
    while len(seen) < 6:
        now += step
        seen, _ = session.update_faces(seen, _window(full, start, now))
        assert now - start < ROUND_S + 10, session.missing_faces(seen)
    start = now
    while not (st := session.turn_status(_window(full, start, now))).done:
        now += step
        assert now - start < ROUND_S + session.TURN_S, "turn step"
    assert st.reason == "coverage"
    cal = session.calibrate(gyro, {k: v.mean for k, v in seen.items()}, _window(full, start, now).mag)
    assert not cal.notes, cal.notes
    assert np.allclose(cal.gyro.bias_lsb, T.CAL_GYRO_BIAS_DPS * chips.ITG3200_LSB_PER_DPS, atol=0.7)
    assert np.allclose(cal.accel.offset_lsb, T.CAL_ACCEL_OFFSET_G * 256, atol=0.3)
