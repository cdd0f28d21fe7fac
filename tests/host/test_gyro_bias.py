"""The host's gyro bias (its one owner): learnt lying still when gyro, accelerometer and compass agree, and
held in the hand when the intent is still; never from a slow steady turn or aim, never from a steady turn at
start-up; a warm-up drift is followed; a wrong estimate is replaced by lying still for long enough."""

from types import SimpleNamespace

import numpy as np
import pytest

from sphere.daemon.motion import GyroBias
from sphere.sim import trace as T

RATE = 200.0


def feed(bias: GyroBias, motion: T.Motion, mag=True, bias_dps=(0.0, 0.0, 0.0), seed=0):
    """Physical motion at RATE with ITG-3200/ADXL345/HMC5883L datasheet noise, through the chips' units."""
    rng = np.random.default_rng(seed)
    m = T.to_chips(motion)
    n = len(m.gyro_lsb)
    gyro = m.gyro_lsb / 14.375 + np.asarray(bias_dps) + rng.normal(0, 0.38, (n, 3))
    acc = m.accel_lsb / 256.0 + rng.normal(0, 1 / 256, (n, 3))
    mags = m.mag_lsb / 10.9 + rng.normal(0, 0.2, m.mag_lsb.shape)
    for i in range(n):
        a = acc[i]
        k = min(int(i / RATE * 75.0), len(mags) - 1)
        bias.add(tuple(gyro[i]), float(np.linalg.norm(a)), 1 / RATE, tuple(mags[k]) if mag else None, tuple(a))


def test_still_window_gives_the_bias_and_averages_down_its_noise():
    b = GyroBias()
    feed(b, T.still(6.0), bias_dps=(0.4, -0.3, 0.2))
    assert b.updates >= 5 and b.confirmed
    assert np.allclose(b.bias, (0.4, -0.3, 0.2), atol=0.03)


@pytest.mark.parametrize("axis", [(0, 0, 1), (0, 1, 0), (1, 0, 0)])
@pytest.mark.parametrize("rate", [1.0, 3.0])
def test_a_slow_steady_turn_is_never_taken_as_bias(axis, rate):
    """1 and 3 °/s about each axis pass the gyro's stillness test; the accelerometer or compass sees them."""
    b = GyroBias()
    feed(b, T.still(3.0), bias_dps=(0.2, 0.2, 0.2))
    before = list(b.bias)
    feed(b, T.rotation(4.0, rate_dps=rate, axis=axis, still_s=0.0), bias_dps=(0.2, 0.2, 0.2), seed=1)
    assert np.allclose(b.bias, before, atol=0.05), (b.bias, before)


def test_a_steady_turn_at_start_up_is_not_taken_as_bias():
    """Issue 14's case, at its cause: a steady 20 °/s yaw during the first 3 s with no compass looks like a bias
    to the gyro and accelerometer, but it is beyond what a chip leaves (prior_dps) and it stops before
    persist_s; the first still window after it gives the bias."""
    b = GyroBias()
    feed(b, T.rotation(3.0, rate_dps=20.0, still_s=0.0), mag=False)
    assert not b.known and b.bias == [0.0, 0.0, 0.0]
    feed(b, T.still(1.2), mag=False, seed=2)
    assert b.known and abs(b.bias[2]) < 0.1


def test_a_large_bias_is_taken_once_it_persists_or_the_compass_confirms_it():
    """A chip left with 8 °/s (within the ITG-3200's ±40 °/s): lying still without a compass it is taken after
    persist_s of agreeing windows; with the compass at the first window."""
    b = GyroBias()
    feed(b, T.still(5.5), mag=False, bias_dps=(0.0, 8.0, 0.0))
    assert not b.known
    feed(b, T.still(1.0), mag=False, bias_dps=(0.0, 8.0, 0.0), seed=1)
    assert b.known and abs(b.bias[1] - 8.0) < 0.05
    c = GyroBias()
    feed(c, T.still(1.05), bias_dps=(0.0, 8.0, 0.0))
    assert c.known and c.confirmed and abs(c.bias[1] - 8.0) < 0.1


def test_a_wrong_estimate_is_replaced_after_lying_still_for_persist_s():
    """A first estimate taken from a slow turn within the prior (3 °/s yaw, compass silent) is replaced once
    lying still has contradicted it for persist_s."""
    b = GyroBias()
    feed(b, T.rotation(2.0, rate_dps=3.0, still_s=0.0), mag=False)
    assert abs(b.bias[2] - 3.0) < 0.1
    feed(b, T.still(5.0), mag=False, seed=2)
    assert abs(b.bias[2] - 3.0) < 0.1 and b.rejected >= 4  # a bias does not jump: held back ...
    feed(b, T.still(2.0), mag=False, seed=3)
    assert abs(b.bias[2]) < 0.05  # ... until it has lasted persist_s


def feed_hold(bias: GyroBias, h, mag=True, start_s=0.0, end_s=None):
    """A synthetic:hold trace (its own bias and noise) at 200 Hz; returns the estimate after every second."""
    m = h.motion
    k = int(round(m.rate_hz / RATE))
    gyro = np.degrees(m.gyr_rad_s[::k])
    acc = m.acc_m_s2[::k] / 9.80665
    mags = m.mag_uT[::k]
    a, b = int(start_s * RATE), len(gyro) if end_s is None else int(end_s * RATE)
    out = []
    for i in range(a, b):
        g = acc[i]
        bias.add(tuple(gyro[i]), float(np.linalg.norm(g)), 1 / RATE, tuple(mags[i]) if mag else None, tuple(g))
        if (i + 1) % int(RATE) == 0:
            out.append(list(bias.bias))
    return np.array(out)


@pytest.mark.parametrize("mag", [True, False])
def test_learnt_while_held_in_the_hand_and_a_warm_up_followed(mag):
    """Switched on in the hand, never laid down (tremor, wander, an aim every 20 s), the bias starting at
    ±0.6 °/s and warming by 0.5 °/s over 5 minutes: from 10 s on within 0.04 °/s RMS of the truth on every
    axis, never 0.15 °/s off (before: never learnt in the hand, 0.6 °/s and more off all along)."""
    from sphere.sim.hold import WARM_UP, hold_script, long_hold_script

    h = hold_script(150.0, 5, WARM_UP, script=long_hold_script(150.0, 5))
    b = GyroBias()
    est = feed_hold(b, h, mag=mag)
    truth = h.bias_dps[int(h.motion.rate_hz) - 1:: int(h.motion.rate_hz)][: len(est)]
    err = np.abs(est - truth)[10:]
    assert b.held_updates >= 10
    assert np.sqrt((err ** 2).mean(axis=0)).max() < 0.04 and err.max() < 0.15, (np.sqrt((err ** 2).mean(axis=0)), err.max())


def test_a_slow_steady_aim_in_the_hand_is_not_taken_as_bias():
    """Held, bias known; then a steady 1 °/s yaw aim for 8 s (compass silent: nothing but its size tells it
    from a bias): the estimate does not follow it."""
    from sphere.sim.hold import hold_script

    script = [("held", 12.0, "", 0.0, ""), ("turn", 8.0, "fine", 1.0, "yaw"), ("held", 4.0, "", 0.0, "")]
    h = hold_script(24.0, 2, script=script)
    b = GyroBias()
    feed_hold(b, h, mag=False, end_s=12.0)
    before = list(b.bias)
    assert b.known
    feed_hold(b, h, mag=False, start_s=12.0, end_s=20.0)
    assert np.allclose(b.bias, before, atol=0.03), (b.bias, before)


def test_the_compass_confirmed_window_replaces_an_unconfirmed_one_at_once():
    b = GyroBias()
    feed(b, T.rotation(2.0, rate_dps=20.0, still_s=0.0), mag=False)
    assert not b.confirmed
    feed(b, T.still(1.1), seed=3)
    assert b.confirmed and abs(b.bias[2]) < 0.1


def test_the_bias_may_only_change_slowly():
    """A still window whose mean is far from a confirmed bias is held back (once); a close one is averaged in."""
    b = GyroBias()
    feed(b, T.still(3.0), bias_dps=(0.0, 0.0, 0.0))
    n = b.updates
    b.add((0.0, 0.0, 2.0), 1.0, 1 / RATE, (20.0, 0.0, -44.0), (0.0, 0.0, 1.0))
    for _ in range(int(RATE)):
        b.add((0.0, 0.0, 2.0), 1.0, 1 / RATE, (20.0, 0.0, -44.0), (0.0, 0.0, 1.0))
    assert b.updates == n and b.rejected == 1 and abs(b.bias[2]) < 0.1


def test_implausible_bias_is_refused():
    b = GyroBias()
    for _ in range(int(2 * RATE)):
        b.add((0.0, 0.0, 45.0), 1.0, 1 / RATE, (20.0, 0.0, -44.0), (0.0, 0.0, 1.0))
    assert b.updates == 0  # beyond the ITG-3200's ±40 °/s zero-rate tolerance


def test_steady_turn_at_start_up_then_still_pointer_stops_within_5_s():
    """Issue 14's target through the daemon (SphereMouse.handle, memory backend): a steady 20 °/s turn during
    start-up with the compass silent, then put down: the pointer speed is < 5 px/s within 5 s."""
    from sphere.bench.pointer import daemon
    from sphere.sim.trace import raw_packets

    d = daemon()
    motion = T.rotation(3.0, rate_dps=20.0, still_s=0.0)
    still = T.still(8.0)
    packets = raw_packets(motion) + [(t + 3_000_000, p) for t, p in raw_packets(still)]
    xs = []
    for t_us, p in packets:
        if t_us < 4_000_000:  # the compass does not answer during start-up
            p = type(p)(t_us=p.t_us, flags=p.flags & ~0x04, accel=p.accel, gyro=p.gyro, mag=(-4096, -4096, -4096))
        d.handle(SimpleNamespace(packet=p, t_us=t_us))
        xs.append((t_us, d.backend.x, d.backend.y))
    xs = np.array(xs, dtype=float)
    put_down = 4_000_000
    late = xs[(xs[:, 0] >= put_down + 5_000_000) & (xs[:, 0] <= put_down + 7_000_000)]
    speed = np.hypot(late[-1, 1] - late[0, 1], late[-1, 2] - late[0, 2]) / ((late[-1, 0] - late[0, 0]) * 1e-6)
    assert speed < 5.0, speed


def test_lying_still_the_pointer_is_held_and_a_slow_turn_from_rest_is_followed():
    """Through the daemon (SphereMouse.handle, memory backend): lying still with the ITG-3200's noise and a
    bias, the pointer does not move at all once the rest hold holds it (before: 1-2 px/s of noise crept
    through the tightening); a 2 °/s turn from rest is followed to within 5 % of its 192 px (as before the
    hold: 1 °/s is the tightening's knee, which shortens it by 7 % with or without the hold)."""
    from sphere.bench.pointer import daemon, raw_packets
    from sphere.sim.hold import CLEAN, hold_script

    script = [("rest", 5.0, "", 0.0, ""), ("turn", 2.0, "fine", 2.0, "yaw"), ("rest", 2.0, "", 0.0, "")]
    h = hold_script(9.0, 4, CLEAN, script=script)
    d = daemon()
    rows = []
    for t_us, p in raw_packets(h.motion):
        d.handle(SimpleNamespace(packet=p, t_us=t_us))
        rows.append((t_us * 1e-6 - 1.0, d.backend.x, d.backend.y, d.motion.rest_hold.holding))
    a = np.array(rows, dtype=float)
    still = (a[:, 0] >= 2.0) & (a[:, 0] < 5.0)
    assert a[still, 3].mean() > 0.95
    assert np.ptp(a[still, 1]) == 0 and np.ptp(a[still, 2]) == 0
    before, after = a[a[:, 0] < 4.95][-1], a[a[:, 0] < 7.9][-1]
    assert abs((after[1] - before[1]) - (-192.0)) <= 0.05 * 192.0, after[1] - before[1]


def test_the_rest_hold_let_go_by_a_failed_still_window_carries_nothing():
    """Held lying still; then the owner's still time drops to 0 (a still window's trend test failed) while the
    rate stays in the band: the hold lets go with the sample's own rate, not the short mean's whole displacement
    (that carry is for a move's start; here it moved a turntable-stopped pointer by a third of a pixel)."""
    from sphere.daemon.gyro_bias import RestHold

    h = RestHold()
    for _ in range(40):
        assert h((0.3, -0.2, 0.1), 0.005, still_s=2.0, still_dps=3.0) == (0.0, 0.0, 0.0)
    assert h((0.3, -0.2, 0.1), 0.005, still_s=0.0, still_dps=3.0) == (0.3, -0.2, 0.1)
    assert not h.holding
    h = RestHold()  # a move from rest still brings the short mean's displacement
    for _ in range(40):
        h((0.0, 0.0, 0.0), 0.005, still_s=2.0, still_dps=3.0)
    out = [h((0.0, 0.0, 2.5), 0.005, still_s=2.0, still_dps=3.0) for _ in range(10)]
    released = next(o for o in out if o != (0.0, 0.0, 0.0))
    assert released[2] > 2.5
