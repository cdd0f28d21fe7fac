"""Do the three sensors report in one body frame? The axis check of ``sphere calibrate``, judged from the
RAW_SAMPLE stream while the sphere is turned back and forth about each of its axes: pure functions on
arrays in chip units (LSB) and device time (s); ``sphere calibrate`` does the I/O and the printing.

The body frame is the ADXL345's own (protocol spec §4.2.1); RAW_SAMPLE is already mapped into it by the
board profile the firmware uses. An earth-fixed vector seen from the turning sphere turns the other way:
between two instants v(t₂) = ΔRᵀ·v(t₁), ΔR the body's rotation, which the gyro measures in its own axes.
If the gyro reads G·ω (G a signed permutation), the body's rotation is Gᵀ·ΔR_g^det(G)·G. So

- the accelerometer (gravity, the body frame itself) tells which of the 48 signed permutations G relates
  the gyroscope's axes to the body's: the one whose rotations explain the accelerometer's changes best;
- the magnetometer (the earth's field plus a hard-iron offset h that turns with the sphere) tells the map
  Q = M·Gᵀ from the gyro's axes to its own: m(t₂) − h = Q·ΔR_g^det(G)ᵀ·Qᵀ·(m(t₁) − h), h fitted by least
  squares. Q and −Q turn a vector alike (turning cannot tell a vector from its negative), so the
  magnetometer's M = ±Q·G is taken as the rotation of the pair: a chip's axes are right-handed, a chip is
  mounted by turning it, and every profile's map is a rotation.

G and M are chosen together (the best sum of both unexplained shares): the accelerometer does not see a
turn about the vertical, the magnetometer does, and det(G) ties the two. Pairs of instants up to
``LAG_S`` apart that turned at least ``MIN_TURN_DEG`` are compared with the exact rotation, so a hand's
own accelerations stay small against the change of gravity's direction.

A correct profile gives G = M = I. Otherwise :func:`verdict` says which chip is mounted how (its own
axes, through the profile the firmware uses now) and which profile would make all three agree.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from sphere import chips
from sphere import quaternion as quat
from sphere.protocol.packets import BOARD_PROFILES

BLOCK_S = 0.05  # values are averaged over blocks of this much device time
LAG_S = 0.6  # blocks up to this far apart are compared ...
MIN_TURN_DEG = 15.0  # ... when the sphere turned at least this much between them
MIN_RATE_DPS = 20.0  # the gyro counts a turn above this rate ...
DOMINANT = 0.8  # ... about an axis that carries this share of the rate
TURN_DEG = 90.0  # each gyro axis must have turned this far on its own (summed over swings)
MAX_UNEXPLAINED = 0.5  # the best map must explain at least half of each vector's change ...
MIN_MARGIN = 2.0  # ... and leave the next best map this many times more unexplained

#: The firmware's board profiles (spec §4.2.1): per chip, body x, y, z from which of the chip's axes.
PROFILE_AXES = {
    "aligned": {"accel": "+x +y +z", "gyro": "+x +y +z", "mag": "+x +y +z"},
    "sen10724": {"accel": "+x +y +z", "gyro": "+x +y +z", "mag": "+y -x +z"},
    "gy85": {"accel": "+x +y +z", "gyro": "-x -y +z", "mag": "-y +x +z"},
}
#: Where each profile's maps come from, and whether a board has confirmed them (spec §4.2.1). A profile no board
#: has confirmed is said to be unverified wherever the check names it.
PROFILE_SOURCES = {
    "aligned": "by definition: all three chips mounted alike",
    "sen10724": "the Razor AHRS firmware's axis table for that board (public, not measured here)",
    "gy85": "unverified: no datasheet or schematic gives the GY-85's chip orientations, and no board has confirmed it",
}
UNVERIFIED = {"gy85"}
#: What a person calls each profile.
PROFILE_TITLES = {"aligned": "a board with all three chips mounted alike", "sen10724":
                  "a SparkFun 9DoF Sensor Stick (SEN-10724)", "gy85": "a GY-85"}
CHIP_NAMES = {"gyro": "gyroscope", "mag": "magnetometer"}


def axes_matrix(text: str) -> np.ndarray:
    """``"-y +x +z"`` (row i: axis i is ± which axis of the other frame) as a signed permutation matrix."""
    rows = []
    for word in text.split():
        r = np.zeros(3)
        r["xyz".index(word[-1])] = -1.0 if word[0] in "-−" else 1.0
        rows.append(r)
    m = np.array(rows)
    if m.shape != (3, 3) or not np.allclose(np.abs(m).sum(axis=0), 1):
        raise ValueError(f"not a signed permutation: {text!r}")
    return m


def profile_matrix(profile: str, chip: str) -> np.ndarray:
    """The profile's map for a chip: body = A · chip."""
    return axes_matrix(PROFILE_AXES[profile][chip])


def signed_permutations(proper: bool | None = None) -> list[np.ndarray]:
    """The 48 signed 3×3 permutation matrices (``proper=True``: the 24 rotations; ``False``: the 24 mirrors)."""
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            m = np.zeros((3, 3))
            m[range(3), perm] = signs
            if proper is None or (np.linalg.det(m) > 0) == proper:
                out.append(m)
    return out


_ALL = np.array(signed_permutations())
_PROPER = np.array(signed_permutations(proper=True))


def _blocks(t, x, block_s=BLOCK_S):
    """Means of ``x`` and of ``t`` over blocks of ``block_s`` (blocks with at least 2 samples)."""
    t = np.asarray(t, float)
    if len(t) < 2:
        return np.zeros(0), np.zeros((0, 3))
    k = np.floor((t - t[0]) / block_s).astype(int)
    edges = np.flatnonzero(np.diff(k)) + 1
    starts, stops = np.r_[0, edges], np.r_[edges, len(t)]
    n = stops - starts
    keep = n >= 2
    starts, stops, n = starts[keep], stops[keep], n[keep]
    c = np.vstack([np.zeros((1, 3)), np.cumsum(x, axis=0)])
    ct = np.r_[0.0, np.cumsum(t)]
    return (ct[stops] - ct[starts]) / n, (c[stops] - c[starts]) / n[:, None]


def _rotations(t, gyro_lsb, bias_lsb=None) -> np.ndarray:
    """The gyro's orientation (N, 4) at its sample times, integrated from the first (in its own axes)."""
    w = np.radians((np.asarray(gyro_lsb, float) - (0.0 if bias_lsb is None else np.asarray(bias_lsb, float)))
                   / chips.ITG3200_LSB_PER_DPS)
    n = len(t)
    out = np.empty((n, 4))
    if n == 0:
        return out
    step = 0.5 * (w[:-1] + w[1:]) * np.diff(np.asarray(t, float))[:, None]  # trapezoids
    ang = np.linalg.norm(step, axis=1)
    half = 0.5 * ang
    k = np.where(ang > 0, np.sin(half) / np.where(ang > 0, ang, 1.0), 0.5)
    inc = np.column_stack([np.cos(half), step * k[:, None]]).tolist()
    a = (1.0, 0.0, 0.0, 0.0)
    rows = [a]
    for b in inc:  # q ⊗ increment (a Python loop over floats: fast enough)
        a = quat.mul(a, b)
        rows.append(a)
    out[:] = rows
    return out


def _matrices(q) -> np.ndarray:
    w, x, y, z = np.moveaxis(q / np.linalg.norm(q, axis=-1, keepdims=True), -1, 0)
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], -2)


@dataclass
class Pairs:
    """Pairs of block means of one vector sensor, ``v1`` then ``v2`` (N, 3), and the gyro's rotation
    between them in its own axes ``rot`` (N, 3, 3): the earth's vectors turn by its transpose."""

    v1: np.ndarray
    v2: np.ndarray
    rot: np.ndarray


def _pairs(t, x, gyro_t, gyro_q, block_s=BLOCK_S, lag_s=LAG_S, min_turn_deg=MIN_TURN_DEG) -> Pairs:
    empty = Pairs(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3, 3)))
    tm, mean = _blocks(t, x, block_s)
    inside = (tm >= gyro_t[0]) & (tm <= gyro_t[-1]) if len(gyro_t) > 1 else np.zeros(len(tm), bool)
    tm, mean = tm[inside], mean[inside]
    if len(tm) < 2:
        return empty
    qi = np.stack([np.interp(tm, gyro_t, gyro_q[:, k]) for k in range(4)], 1)  # close neighbours: lerp is enough
    qi /= np.linalg.norm(qi, axis=1, keepdims=True)
    i1, i2 = [], []
    for lag in range(1, int(lag_s / block_s) + 1):
        i = np.arange(len(tm) - lag)
        i1.append(i)
        i2.append(i + lag)
    i1, i2 = np.concatenate(i1), np.concatenate(i2)
    i1, i2 = i1[tm[i2] - tm[i1] <= lag_s + 0.5 * block_s], i2[tm[i2] - tm[i1] <= lag_s + 0.5 * block_s]

    dq = quat.multiply(quat.conjugate(qi[i1]), qi[i2])
    turn = 2 * np.degrees(np.arccos(np.clip(np.abs(dq[:, 0]), 0, 1)))
    ok = turn >= min_turn_deg
    if not np.any(ok):
        return empty
    return Pairs(mean[i1[ok]], mean[i2[ok]], _matrices(dq[ok]))


def _turned_body(rot, g) -> np.ndarray:
    """The body's rotations (N, 3, 3) if the gyro reads G·ω: Gᵀ·ΔR^det(G)·G."""
    r = rot if np.linalg.det(g) > 0 else np.swapaxes(rot, 1, 2)
    return g.T @ r @ g


def _unexplained_gyro(p: Pairs) -> np.ndarray:
    """For each of the 48 maps G (gyro = G · body): the share of Σ|a₂ − a₁|² that a₂ = ΔR_bodyᵀ·a₁ leaves."""
    total = float(np.sum((p.v2 - p.v1) ** 2))
    out = []
    for g in _ALL:
        rb = _turned_body(p.rot, g)
        r = p.v2 - (np.swapaxes(rb, 1, 2) @ p.v1[:, :, None])[:, :, 0]
        out.append(float(np.sum(r * r)))
    return np.array(out) / max(total, 1e-12)


def _unexplained_mag(p: Pairs, det_g: float) -> tuple[np.ndarray, np.ndarray]:
    """For each of the 48 maps Q from the gyro's axes to the magnetometer's (a gyro map of determinant
    ``det_g``): the share of Σ|m₂ − m₁|² that m₂ − h = Q·ΔR^det(G)ᵀ·Qᵀ·(m₁ − h) leaves with the hard iron h
    fitted, and the fitted h (48, 3)."""
    total = float(np.sum((p.v2 - p.v1) ** 2))
    r = p.rot if det_g > 0 else np.swapaxes(p.rot, 1, 2)
    out, hs = np.zeros(len(_ALL)), np.zeros((len(_ALL), 3))
    eye = np.eye(3)
    rt = np.swapaxes(r, 1, 2)
    v1 = p.v1[:, :, None]
    for c, q in enumerate(_ALL):
        if np.linalg.det(q) < 0:
            continue  # −Q turns vectors as Q does: the same share (filled in below)
        pm = q @ rt @ q.T  # Q·ΔRᵀ·Qᵀ
        b = p.v2 - (pm @ v1)[:, :, 0]
        a = eye[None] - pm  # b = (I − P)·h when Q is right
        at = np.swapaxes(a, 1, 2)
        h = np.linalg.lstsq((at @ a).sum(axis=0), (at @ b[:, :, None]).sum(axis=0)[:, 0], rcond=None)[0]
        res = b - (a @ h)
        out[c], hs[c] = float(np.sum(res * res)), h
    for c, q in enumerate(_ALL):
        if np.linalg.det(q) < 0:
            twin = int(np.flatnonzero(np.all(np.isclose(_ALL, -q), axis=(1, 2)))[0])
            out[c], hs[c] = out[twin], hs[twin]
    return out / max(total, 1e-12), hs


@dataclass
class ChipFit:
    """A chip's map against the body frame (reported = ``matrix`` · body), how much of the change it leaves
    unexplained, and how many times more the next best map leaves (``margin``)."""

    matrix: np.ndarray
    unexplained: float
    margin: float
    pairs: int

    @property
    def decided(self) -> bool:
        return self.pairs >= 10 and self.unexplained <= MAX_UNEXPLAINED and self.margin >= MIN_MARGIN


@dataclass
class AxisFit:
    turned_deg: np.ndarray  # per gyro axis: how far it turned while it carried most of the rate
    gyro: ChipFit | None
    mag: ChipFit | None
    mag_hard_iron_lsb: np.ndarray | None = None

    @property
    def axes_turned(self) -> list[bool]:
        return [bool(d >= TURN_DEG) for d in self.turned_deg]

    @property
    def done(self) -> bool:
        """Every axis turned, and both maps told apart from every other."""
        return (all(self.axes_turned) and self.gyro is not None and self.gyro.decided
                and self.mag is not None and self.mag.decided)


def turned_deg(t, gyro_lsb, bias_lsb=None) -> np.ndarray:
    """Per gyro axis, the angle (°) turned in samples where that axis carries ``DOMINANT`` of the rate."""
    if len(t) < 2:
        return np.zeros(3)
    w = (np.asarray(gyro_lsb, float) - (0.0 if bias_lsb is None else np.asarray(bias_lsb, float)))
    w = w / chips.ITG3200_LSB_PER_DPS
    norm = np.linalg.norm(w, axis=1)
    dt = np.r_[np.diff(t), 0.0]
    dt = np.minimum(dt, 5 * float(np.median(np.diff(t))))  # a gap in the stream is not a turn
    moving = norm >= MIN_RATE_DPS
    out = np.zeros(3)
    for i in range(3):
        sel = moving & (np.abs(w[:, i]) >= DOMINANT * norm)
        out[i] = float(np.sum(np.abs(w[sel, i]) * dt[sel]))
    return out


def fit(s, gyro_bias_lsb=None, full: bool = True) -> AxisFit:
    """The maps from a :class:`sphere.calibration.session.Series` of the sphere turning. ``full=False``
    only measures how far each axis turned (cheap, for progress) until every axis has."""
    turned = turned_deg(s.t, s.gyro, gyro_bias_lsb)
    if not full and not all(turned >= TURN_DEG):
        return AxisFit(turned, None, None)
    t = np.asarray(s.t, float)
    gq = _rotations(t, s.gyro, gyro_bias_lsb)
    pa = _pairs(t, np.asarray(s.accel, float), t, gq)
    mag = np.asarray(s.mag, float).reshape(-1, 3)
    good = np.all(mag != chips.HMC5883L_OVERFLOW, axis=1)
    pm = _pairs(np.asarray(s.mag_t, float)[good], mag[good], t, gq)
    if len(pa.v1) < 2 or len(pm.v1) < 2:
        return AxisFit(turned, None, None)
    acc = _unexplained_gyro(pa)
    det = np.sign(np.linalg.det(_ALL))
    mq, hs = {}, {}
    for d in (1.0, -1.0):
        mq[d], hs[d] = _unexplained_mag(pm, d)
    # every (G, Q): the sum of both shares; M = ±Q·G, taken as the rotation of the pair
    score = acc[:, None] + np.stack([mq[d] for d in det])
    m_all = np.einsum("qij,gjk->gqik", _ALL, _ALL)
    m_all *= np.sign(np.linalg.det(m_all))[..., None, None]
    gi, qi = np.unravel_index(int(np.argmin(score)), score.shape)
    best = float(score[gi, qi])
    m_best = m_all[gi, qi]
    other_g = np.broadcast_to((np.arange(len(_ALL)) != gi)[:, None], score.shape)
    other_m = ~np.all(np.isclose(m_all, m_best), axis=(2, 3))

    def margin(sel):
        return float(score[sel].min()) / max(best, 1e-9) if np.any(sel) else float("inf")

    gfit = ChipFit(_ALL[gi].copy(), float(acc[gi]), margin(other_g), len(pa.v1))
    mfit = ChipFit(m_best.copy(), float(mq[det[gi]][qi]), margin(other_m), len(pm.v1))
    return AxisFit(turned, gfit, mfit, hs[det[gi]][qi])


# ---------------------------------------------------------------- what it means

def _signed_axis(v) -> str:
    """A body vector along an axis or a diagonal as text: '+x', '−y', 'x+y', 'x−y+z' ..."""
    v = np.round(np.asarray(v, float) / np.max(np.abs(v)), 6)
    parts = []
    for c, name in zip(v, "xyz"):
        if abs(c) > 1e-6:
            parts.append(("−" if c < 0 else "+") + name)
    text = "".join(parts)
    return text[1:] if len(parts) > 1 and text[0] == "+" else text


def turn_words(mount: np.ndarray) -> str:
    """How a chip whose axis i lies along the body's ``mount[i]`` is turned against the body frame:
    '90° about +z', '180° about x+y', 'mirrored (…)'."""
    r = np.asarray(mount, float).T  # columns: the chip's axes in body coordinates
    if np.linalg.det(r) < 0:
        return "mirrored (its axes are left-handed against the body's)"
    c = float(np.clip((np.trace(r) - 1) / 2, -1, 1))
    angle = int(round(np.degrees(np.arccos(c))))
    if angle == 0:
        return "not turned"
    if angle == 180:
        axis = np.sqrt(np.maximum((np.diag(r) + 1) / 2, 0))
        i = int(np.argmax(axis))
        axis = (r[:, i] + np.eye(3)[i]) / 2  # a column of (R + I)/2 is along the axis
    else:
        axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    return f"turned {angle}° about {_signed_axis(axis)}"


def axes_words(mount: np.ndarray) -> str:
    """'its x axis along the body’s +y, y along −x; z agrees' (``mount``: chip axis i along body ``mount[i]``)."""
    wrong = [i for i in range(3) if not np.isclose(mount[i, i], 1.0)]
    if not wrong:
        return "its axes along the body’s"
    parts = [("its {} axis along the body’s {}" if not k else "{} along {}").format("xyz"[i], _signed_axis(mount[i]))
             for k, i in enumerate(wrong)]
    agree = [("xyz"[i]) for i in range(3) if i not in wrong]
    return ", ".join(parts) + (f"; {' and '.join(agree)} agree{'s' if len(agree) == 1 else ''}" if agree else "")


def mount_words(mount: np.ndarray) -> str:
    """'turned 90° about +z (its x axis along the body’s +y, y along −x; z agrees)', or 'mounted like the
    accelerometer'."""
    if np.allclose(mount, np.eye(3)):
        return "mounted like the accelerometer"
    return f"{turn_words(mount)} ({axes_words(mount)})"


@dataclass
class Verdict:
    ok: bool
    lines: list = field(default_factory=list)  # what to print
    mounts: dict = field(default_factory=dict)  # chip -> its axes along the body's (chip = B · body)
    profile: str | None = None  # the profile the firmware uses
    fitting_profile: str | None = None  # the profile that makes all three agree (None: no profile does)


def profile_words(mounts: dict) -> str:
    """The maps a profile would need for these mountings, in the spec's notation (§4.2.1: body x, y, z from which
    of the chip's axes): 'accelerometer +x +y +z, gyroscope −x −y +z, magnetometer −y +x +z'."""
    def words(b):  # chip = B · body, so body = Bᵀ · chip: row i of Bᵀ says which chip axis is body axis i
        bt = np.asarray(b, float).T
        return " ".join(("−" if bt[i, int(np.argmax(np.abs(bt[i])))] < 0 else "+") + "xyz"[int(np.argmax(np.abs(bt[i])))]
                        for i in range(3))
    parts = ["accelerometer +x +y +z"]
    for c in ("gyro", "mag"):
        parts.append(f"{CHIP_NAMES[c]} {words(mounts.get(c, np.eye(3)))}")
    return ", ".join(parts)


def _unverified_line(name: str) -> str:
    return (f"the {name} profile is unverified ({PROFILE_SOURCES[name].split(': ', 1)[-1]}): this check confirms "
            "it for your board; please report it, with the lines above, so it can be marked verified")


def verdict(f: AxisFit, profile: str | None, port: str = "PORT") -> Verdict:
    """What the fit means for the profile the firmware uses (``profile``, a name of
    :data:`PROFILE_AXES`; None when the device did not say): pass, or which chip is mounted how and
    which profile to set. ``f`` must be decided (:attr:`AxisFit.done`)."""
    assert f.gyro is not None and f.mag is not None
    seen = {"gyro": f.gyro.matrix, "mag": f.mag.matrix}
    if all(np.allclose(m, np.eye(3)) for m in seen.values()):
        lines = ["axes agree: turning about each body axis shows on the same axis in the gyroscope, "
                 f"accelerometer and magnetometer (board profile {profile or 'unknown'})"]
        if profile in UNVERIFIED:
            lines.append(_unverified_line(profile))
        return Verdict(True, lines, {}, profile, profile)
    known = profile in PROFILE_AXES
    mounts = {c: (profile_matrix(profile, c).T @ m if known else m) for c, m in seen.items()}
    lines = [f"axes disagree with the board profile {profile or '(unknown)'}: a turn about one body axis (the "
             "accelerometer's axes) shows on another axis of"]
    for c, m in seen.items():
        if np.allclose(m, np.eye(3)):
            continue
        line = f"  the {CHIP_NAMES[c]}: its chip is {mount_words(mounts[c])}"
        if known and profile != "aligned":
            line += f"; the profile {profile} expects it {mount_words(profile_matrix(profile, c).T)}"
        lines.append(line)
    fitting = None
    if known:
        for name in PROFILE_AXES:
            if all(np.allclose(profile_matrix(name, c), mounts[c].T) for c in seen):
                fitting = name
    if fitting:
        lines.append(f"the board looks like {PROFILE_TITLES[fitting]}: set its profile with "
                     f"`sphere device --port {port} set board={fitting}`, then run `sphere calibrate` again")
        if fitting in UNVERIFIED:
            lines.append(_unverified_line(fitting))
    elif known:
        lines.append(f"no board profile ({', '.join(PROFILE_AXES)}) mounts the chips this way: the firmware needs a "
                     f"profile for this board with the maps {profile_words(mounts)} (body x, y, z from which of "
                     "each chip's axes, protocol spec §4.2.1); `sphere calibrate --no-axis-check` calibrates "
                     "it as it is, but the orientation will be wrong")
    else:
        lines.append("the firmware did not say which profile it uses (HELLO board_profile); update it and run "
                     "`sphere calibrate` again")
    return Verdict(False, lines, mounts, profile, fitting)


def profile_name(board_profile: int | None) -> str | None:
    """HELLO's ``board_profile`` number as a name of :data:`PROFILE_AXES`, None when unknown."""
    name = BOARD_PROFILES.get(board_profile) if board_profile is not None else None
    return name if name in PROFILE_AXES else None
