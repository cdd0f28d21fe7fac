"""The axis check of `sphere calibrate` (sphere.calibration.axis_check) on synthetic turns: the turns about each body axis
of `synthetic:calibration`, in chip units, with each sensor's axes put through a known signed permutation
(what a chip mounted another way, read through the wrong board profile, reports). The fit must name the
permutation; the verdict must name the chip and the profile that fits, for the boards of
hardware/sim/README.md (each chip's mounting there, an independent statement from the firmware's profiles)."""

import numpy as np
import pytest

from sphere.calibration import axis_check as A
from sphere.calibration import session as session
from sphere import chips
from sphere import quaternion as quat
from sphere.sim import trace as T

#: The virtual board's mountings (hardware/sim/README.md, "Board variants"): chip axis i reads ± body axis k.
MOUNTS = {
    "aligned": {"gyro": "+x +y +z", "mag": "+x +y +z"},
    "sen10724": {"gyro": "+x +y +z", "mag": "-y +x +z"},
    "gy85": {"gyro": "-x -y +z", "mag": "+y -x +z"},
}


def _series(motion, t0=3.0, t1=16.5, mag_delay_s=0.0):
    """A motion in chip units as RAW_SAMPLE gives it (200 Hz, the magnetometer at 75 Hz), from t0 to t1."""
    ct = T.to_chips(motion)
    t = np.arange(len(ct.accel_lsb)) / ct.accel_rate_hz
    mag_t = np.arange(len(ct.mag_lsb)) / ct.mag_rate_hz + mag_delay_s
    s = session.Series(t, ct.accel_lsb.astype(float), ct.gyro_lsb.astype(float), mag_t, ct.mag_lsb.astype(float))
    i0, i1 = np.searchsorted(s.t, [t0, t1])
    k0, k1 = np.searchsorted(s.mag_t, [t0, t1])
    return session.Series(s.t[i0:i1], s.accel[i0:i1], s.gyro[i0:i1], s.mag_t[k0:k1], s.mag[k0:k1])


@pytest.fixture(scope="module")
def turns():
    """synthetic:calibration's still and its turns about x, y, z (with its gyro bias, accelerometer offset and
    scale, hard and soft iron and noise)."""
    return _series(T.calibration(17.0))


def _mapped(s, g, m):
    """The same samples with the gyro read as g · body and the magnetometer as m · body (its hard iron too)."""
    return session.Series(s.t, s.accel, s.gyro @ g.T, s.mag_t, s.mag @ m.T)


def test_there_are_48_signed_permutations_24_of_them_rotations():
    allp = A.signed_permutations()
    assert len(allp) == 48 and len({m.tobytes() for m in allp}) == 48
    assert len(A.signed_permutations(proper=True)) == 24 and len(A.signed_permutations(proper=False)) == 24
    assert all(np.isclose(abs(np.linalg.det(m)), 1) and np.allclose(m @ m.T, np.eye(3)) for m in allp)


@pytest.mark.slow
@pytest.mark.parametrize("which", ["gyro", "mag", "both"])
def test_every_signed_permutation_is_named(turns, which):
    """All 48 gyro maps (the magnetometer aligned), all 24 magnetometer rotations (the gyro aligned), and
    24 pairs of both; the aligned board comes out aligned."""
    rng = np.random.default_rng(12)
    eye = np.eye(3)
    if which == "gyro":
        cases = [(g, eye) for g in A.signed_permutations()]
    elif which == "mag":
        cases = [(eye, m) for m in A.signed_permutations(proper=True)]
    else:
        allp, rots = A.signed_permutations(), A.signed_permutations(proper=True)
        cases = [(allp[i], rots[j]) for i, j in zip(rng.permutation(48)[:24], rng.permutation(24))]
    for g, m in cases:
        f = A.fit(_mapped(turns, g, m))
        assert f.done, (g, m, f)
        assert np.allclose(f.gyro.matrix, g) and np.allclose(f.mag.matrix, m), (g, m, f)


def test_a_mirrored_magnetometer_is_named_as_its_rotation(turns):
    """Turning cannot tell a vector from its negative: a magnetometer read through a mirror M turns its
    readings as −M does; the fit names the rotation of the pair (what a chip mounted by turning it can be)."""
    for m in A.signed_permutations(proper=False)[::4]:
        f = A.fit(_mapped(turns, np.eye(3), m))
        assert f.done and np.allclose(f.mag.matrix, -m), (m, f.mag)


def test_a_hand_that_wobbles_and_pushes_still_gives_the_map():
    """Turns about each axis by a hand: an off-axis wobble of up to ~15°, 0.1 g of the hand's own
    acceleration (smooth, ~0.3 s), the magnetometer's samples 10 ms older than their time stamps, and the
    gyro's bias not removed; read as on a GY-85 through the aligned profile."""
    from scipy.ndimage import uniform_filter1d

    rate = 1000.0
    q, _ = T.calibration_script(17.0, rate)
    n = len(q)
    tt = np.arange(n) / rate
    wob = 0.25 * np.stack([np.sin(2 * np.pi * 0.7 * tt), np.sin(2 * np.pi * 1.1 * tt + 1), np.sin(2 * np.pi * 0.9 * tt + 2)], 1)
    q = quat.multiply(q, quat.normalize(np.column_stack([np.ones(n), 0.5 * wob])))
    m = T._from_orientation(q, T._body_rates(q, rate), rate, "hand")
    rng = np.random.default_rng(5)
    push = uniform_filter1d(rng.normal(0, 1, (n, 3)), 300, axis=0)
    m.acc_m_s2 = m.acc_m_s2 + push / push.std() * 0.1 * chips.STANDARD_GRAVITY_M_S2
    m.gyr_rad_s = m.gyr_rad_s + np.radians([3.0, -4.0, 2.0])
    m.mag_uT = m.mag_uT @ T.CAL_MAG_SOFT_IRON.T + T.CAL_MAG_HARD_IRON_UT
    g, mm = A.axes_matrix(MOUNTS["gy85"]["gyro"]), A.axes_matrix(MOUNTS["gy85"]["mag"])
    f = A.fit(_mapped(_series(m, mag_delay_s=0.010), g, mm))
    assert f.done, f
    assert np.allclose(f.gyro.matrix, g) and np.allclose(f.mag.matrix, mm)
    assert f.gyro.unexplained < 0.3 and f.mag.unexplained < 0.1


def test_turns_about_two_axes_are_not_enough(turns):
    """Without the turn about z the step is not done: z has not turned, whatever the fit says."""
    s = turns.since(0.0)
    cut = np.searchsorted(s.t, 12.2)  # synthetic:calibration's turn about z starts at 12.2 s
    short = session.Series(s.t[:cut], s.accel[:cut], s.gyro[:cut], s.mag_t[s.mag_t < 12.2], s.mag[s.mag_t < 12.2])
    f = A.fit(short, full=False)
    assert f.axes_turned == [True, True, False] and not f.done
    assert f.turned_deg[0] > 300 and f.turned_deg[1] > 300 and f.turned_deg[2] < 10
    still = short.since(0.0)
    sel = still.t < 4.9  # the still lead-in alone: nothing turned
    f = A.fit(session.Series(still.t[sel], still.accel[sel], still.gyro[sel], still.mag_t[still.mag_t < 4.9],
                             still.mag[still.mag_t < 4.9]))
    assert not f.done and f.axes_turned == [False, False, False]


def _reported(board, profile):
    """What RAW_SAMPLE shows on ``board`` through ``profile``: reported = A_profile · B_board (signed perms)."""
    return {c: A.profile_matrix(profile, c) @ A.axes_matrix(MOUNTS[board][c]) for c in ("gyro", "mag")}


@pytest.mark.parametrize("board", sorted(MOUNTS))
@pytest.mark.parametrize("profile", sorted(A.PROFILE_AXES))
def test_the_verdict_names_the_chip_and_the_profile_that_fits(turns, board, profile):
    r = _reported(board, profile)
    f = A.fit(_mapped(turns, r["gyro"], r["mag"]))
    assert f.done
    v = A.verdict(f, profile, "/dev/ttyUSB0")
    text = "\n".join(v.lines)
    if board == profile:
        assert v.ok and "axes agree" in text and v.fitting_profile == profile, text
        return
    assert not v.ok and v.fitting_profile == board, text
    assert f"`sphere device --port /dev/ttyUSB0 set board={board}`" in text, text
    for c, name in (("gyro", "gyroscope"), ("mag", "magnetometer")):
        differs = not np.allclose(r[c], np.eye(3))
        assert (f"the {name}:" in text) == differs, (c, text)
        if differs:  # the chip as mounted, whatever the profile: the board's own table
            assert np.allclose(v.mounts[c], A.axes_matrix(MOUNTS[board][c])), (c, v.mounts[c])


def test_the_words_for_a_gy85_read_as_aligned(turns):
    r = _reported("gy85", "aligned")
    v = A.verdict(A.fit(_mapped(turns, r["gyro"], r["mag"])), "aligned", "/dev/pts/3")
    text = "\n".join(v.lines)
    assert "the gyroscope: its chip is turned 180° about +z (its x axis along the body’s −x, y along −y; z agrees)" in text
    assert "the magnetometer: its chip is turned 90° about +z (its x axis along the body’s +y, y along −x; z agrees)" in text
    assert "the board looks like a GY-85: set its profile with `sphere device --port /dev/pts/3 set board=gy85`" in text


def test_a_mounting_no_profile_has_says_so(turns):
    m = A.axes_matrix("+z +x +y")  # the magnetometer turned 120° about the diagonal
    v = A.verdict(A.fit(_mapped(turns, np.eye(3), m)), "aligned")
    text = "\n".join(v.lines)
    assert not v.ok and v.fitting_profile is None
    assert "turned 120° about" in text and "no board profile (aligned, sen10724, gy85)" in text, text
    assert "--no-axis-check" in text
    v = A.verdict(A.fit(_mapped(turns, np.eye(3), m)), None)  # the device did not say its profile
    assert not v.ok and "did not say which profile" in "\n".join(v.lines)


def test_profiles_are_the_specs_table_and_rotations():
    """protocol/spec.md §4.2.1, as text: body x, y, z from which of the chip's axes."""
    import re
    from pathlib import Path

    spec = (Path(__file__).resolve().parents[2] / "protocol" / "spec.md").read_text()
    for name, axes in A.PROFILE_AXES.items():
        row = re.search(rf"^\| \d `{name}` \| ([^|]+) \| ([^|]+) \| ([^|]+) \|", spec, re.M)
        assert row, name
        for chip, cell in zip(("accel", "gyro", "mag"), row.groups()):
            want = " ".join(w if w[0] in "+-−" else "+" + w for w in cell.replace(",", " ").split())
            assert np.allclose(A.axes_matrix(want), A.axes_matrix(axes[chip])), (name, chip, cell)
            assert np.isclose(np.linalg.det(A.axes_matrix(axes[chip])), 1.0)


def test_a_mounting_no_profile_has_gets_the_maps_a_profile_would_need(turns):
    """The maps are said in the spec's notation (body x, y, z from which chip axis), and a profile with exactly
    those maps makes the three agree: map · mounting = identity, for every rotation of the magnetometer."""
    m = A.axes_matrix("+z +x +y")
    text = "\n".join(A.verdict(A.fit(_mapped(turns, np.eye(3), m)), "aligned").lines)
    assert "maps accelerometer +x +y +z, gyroscope +x +y +z, magnetometer +y +z +x" in text, text
    for rot in A.signed_permutations(proper=True):
        words = A.profile_words({"mag": rot, "gyro": rot.T})
        mag_words = words.split("magnetometer ")[1]
        gyro_words = words.split("gyroscope ")[1].split(",")[0]
        assert np.allclose(A.axes_matrix(mag_words) @ rot, np.eye(3)), (rot, words)
        assert np.allclose(A.axes_matrix(gyro_words) @ rot.T, np.eye(3)), (rot, words)


@pytest.mark.parametrize("profile", ["aligned", "gy85"])
def test_the_gy85_profile_is_said_to_be_unverified_where_the_check_names_it(turns, profile):
    """No board has confirmed the GY-85's maps (spec §4.2.1): a check that passes with them, or finds that they
    fit, says so and asks for the report; the other profiles get no such line."""
    r = _reported("gy85", profile)
    text = "\n".join(A.verdict(A.fit(_mapped(turns, r["gyro"], r["mag"])), profile).lines)
    assert "the gy85 profile is unverified" in text and "please report it" in text, text
    r = _reported("sen10724", "aligned")
    text = "\n".join(A.verdict(A.fit(_mapped(turns, r["gyro"], r["mag"])), "aligned").lines)
    assert "unverified" not in text, text
