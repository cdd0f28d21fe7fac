"""Adapters for published orientation filters, so `sphere eval` runs them beside ours.

Each adapter follows the project's filter API (``update``, ``update_batch``, ``quat``, ``earth_frame``,
``settings``) and runs its library with the library's documented default settings; the only values we
set are the sampling rate and the units the library asks for. The libraries are optional (install the
``peers`` extra: ``pip install marg-sphere[peers]``); a missing one raises :class:`PeerMissing` with
the package to install.

| name            | library, class                          | earth frame | inputs we convert                  |
|-----------------|-----------------------------------------|-------------|------------------------------------|
| `vqf`           | vqf ``VQF`` (Laidig & Seel 2023)        | ENU         | none (rad/s, m/s², any mag unit)   |
| `fusion`        | imufusion ``Ahrs`` (x-io Fusion)        | NWU         | gyro °/s, acc in g                 |
| `ahrs-madgwick` | ahrs ``filters.Madgwick``               | see below   | mag in nT                          |
| `ahrs-mahony`   | ahrs ``filters.Mahony``                 | see below   | mag in nT                          |
| `ahrs-ekf`      | ahrs ``filters.EKF`` (frame="NED")      | NED         | mag in nT, acc sign (see below)    |

ahrs's Madgwick follows Madgwick's original (earth x along horizontal magnetic north, z up: NWU); its
Mahony puts the horizontal field along earth y (ENU). Both measured against BROAD's optical reference.
ahrs's EKF in its default NED frame takes gravity reference a_ref = [0, 0, 1], i.e. it expects the
accelerometer to read +g along *down*, the opposite sign of a specific-force accelerometer (BROAD, ours);
the adapter therefore passes −acc (with +acc its output is off by ~20–180°). Stated in its settings.
"""

from __future__ import annotations

import importlib
from importlib.metadata import PackageNotFoundError, version

import numpy as np

from sphere import quaternion as quat
from sphere.chips import STANDARD_GRAVITY_M_S2
from sphere.errors import SphereError
from sphere.fusion.common import ecompass


class PeerMissing(SphereError, ImportError):
    """A peer filter's package is not installed."""


def _need(module: str, package: str):
    try:
        return importlib.import_module(module)
    except ImportError:
        raise PeerMissing(f"the {package!r} package is not installed; pip install {package} "
                          f"(or pip install 'marg-sphere[peers]')") from None


#: Rotation taking an NED earth frame to ENU: q_ENU = Q_NED_TO_ENU ⊗ q_NED (x_E = y_N, y_E = x_N, z_E = −z_N).
Q_NED_TO_ENU = np.array([0.0, np.sqrt(0.5), np.sqrt(0.5), 0.0])


def to_enu(q: np.ndarray, frame: str) -> np.ndarray:
    """Sensor-to-earth quaternion(s) in ``frame`` (ENU, NWU, NED) expressed as sensor-to-ENU."""
    if frame == "ENU":
        return np.asarray(q, dtype=float)
    if frame == "NWU":
        return quat.nwu_to_enu(q)
    if frame == "NED":
        return quat.multiply(Q_NED_TO_ENU, q)
    raise ValueError(f"unknown earth frame {frame!r}")


#: the step a live peer is built with when the caller gives none (the sphere's sample rate, 200 Hz)
LIVE_DT_S = 0.005


class _Peer:
    """A published filter with its library's defaults: no parameters of ours, never tuned."""

    earth_frame = "ENU"
    PARAMS: dict = {}

    @classmethod
    def from_settings(cls, s=None, dt_s=None, q0=None, gyro_bias_rad_s=None):
        return cls(LIVE_DT_S if dt_s is None else dt_s)

    def update_batch(self, gyr, acc, mag, dt_s):
        out = np.empty((len(gyr), 4))
        for i in range(len(gyr)):
            self.update(gyr[i], acc[i], None if mag is None else mag[i], dt_s)
            out[i] = self.quat
        return out


class VqfPeer(_Peer):
    """VQF with its default parameters (``vqf.VQF(gyrTs)``); output ``quat9D`` (ENU), or ``quat6D`` without mag."""

    NAME = "vqf"
    NEEDS = "vqf"  # the package a live daemon needs installed to run it
    LIVE = True  # the daemon can run it (per-sample update with acc_valid / mag_valid)

    earth_frame = "ENU"

    #: a live stream whose step differs from the filter's by more than this share for ``RESTEP_SAMPLES`` samples
    #: in a row, each within this share of their mean, gets the filter rebuilt at that step (``_restep``)
    RESTEP_TOL = 0.05
    RESTEP_SAMPLES = 10

    def __init__(self, dt_s: float):
        self._vqf_mod = _need("vqf", "vqf")
        self.dt_s = float(dt_s)
        self._f = self._vqf_mod.VQF(self.dt_s)
        self._mag_used = False  # quat9D once a field was used, quat6D before
        self._off = []  # the latest steps that differed from dt_s (a rate change in the making)

    @property
    def settings(self) -> dict:
        p = self._f.params
        keys = ("tauAcc", "tauMag", "motionBiasEstEnabled", "restBiasEstEnabled", "magDistRejectionEnabled",
                "biasSigmaInit", "biasForgettingTime", "biasClip", "biasSigmaMotion", "biasVerticalForgettingFactor",
                "biasSigmaRest", "restMinT", "restFilterTau", "restThGyr", "restThAcc", "magCurrentTau",
                "magRefTau", "magNormTh", "magDipTh", "magNewTime", "magNewFirstTime", "magNewMinGyr",
                "magMinUndisturbedTime", "magMaxRejectionTime", "magRejectionFactor")
        s = {"library": "vqf " + _version("vqf"), "class": "VQF", "parameters": "defaults", "output": "quat9D",
             "earth_frame": "ENU"}
        for k in keys:
            if isinstance(p, dict) and k in p:
                s[k] = p[k]
            elif hasattr(p, k):
                s[k] = getattr(p, k)
        return s

    @property
    def quat(self) -> np.ndarray:
        return np.asarray(self._f.getQuat9D() if self._mag_used else self._f.getQuat6D(), dtype=float)

    def update(self, gyr_rad_s, acc_m_s2, mag_uT, dt_s, *, acc_valid: bool = True, mag_valid: bool = True):
        """One sample (VQF's own ``updateGyr``, ``updateAcc``, ``updateMag``: what its ``update`` does in turn).
        ``acc_valid=False`` (a tap in progress) skips the accelerometer, ``mag_valid=False`` or ``mag_uT=None`` the
        magnetometer; the output is ``quat9D`` once a field has been used, ``quat6D`` before (a stream without a
        magnetometer).

        VQF integrates every gyro sample over the step it was built with, so ``dt_s`` (the time since the previous
        sample) decides how often that step runs: a live link's jitter of a few µs leaves it at once, a lost sample
        (twice the step) runs it twice with the same rate, so the angle turned is kept; a stream steadily at
        another rate (the sphere's ``raw_rate_hz`` 100 or 50, a replay at its recording's rate) has VQF rebuilt at
        that step after ``RESTEP_SAMPLES`` samples, its state carried over."""
        f = self._f
        ts = self.dt_s
        n = 1
        if dt_s is not None and abs(dt_s - ts) > self.RESTEP_TOL * ts:
            off = self._off
            off.append(float(dt_s))
            mean = sum(off) / len(off)
            if any(abs(d - mean) > self.RESTEP_TOL * mean for d in off):
                del off[:-1]
            elif len(off) >= self.RESTEP_SAMPLES:
                self._restep(mean)
                f, ts = self._f, self.dt_s
            n = max(1, int(round(dt_s / ts)))
        elif self._off:
            self._off.clear()
        g = np.array(gyr_rad_s, dtype=float)
        for _ in range(n):
            f.updateGyr(g)
        if acc_valid:
            f.updateAcc(np.array(acc_m_s2, dtype=float))
        if mag_uT is not None and mag_valid:
            f.updateMag(np.array(mag_uT, dtype=float))
            self._mag_used = True
        return f.getQuat9D() if self._mag_used else f.getQuat6D()

    def _restep(self, dt_s: float) -> None:
        """Rebuild VQF for step ``dt_s`` keeping its state: the orientations, bias, rest and field state carry over
        as they are; each low-pass's state is moved to the new coefficients with VQF's own
        ``filterAdaptStateForCoeffChange`` (its output does not jump), as VQF's ``setTauAcc`` does for a new time
        constant (the motion bias estimate's low-passes have no last output in the state: their first state
        entries stand for it, as there)."""
        v = self._vqf_mod.VQF
        old, new = self._f, v(float(dt_s))
        st, co, cn = old.state, old.coeffs, new.coeffs
        for last, key, lp in (("lastAccLp", "accLpState", "accLp"), ("restLastGyrLp", "restGyrLpState", "restGyrLp"),
                              ("restLastAccLp", "restAccLpState", "restAccLp"),
                              ("magNormDip", "magNormDipLpState", "magNormDipLp"),
                              (None, "motionBiasEstRLpState", "accLp"), (None, "motionBiasEstBiasLpState", "accLp")):
            state = np.array(st[key], dtype=float)
            y = np.array(st[last], dtype=float) if last else state[0::2].copy()
            v.filterAdaptStateForCoeffChange(y, np.asarray(co[lp + "B"], float), np.asarray(co[lp + "A"], float),
                                             np.asarray(cn[lp + "B"], float), np.asarray(cn[lp + "A"], float), state)
            st[key] = state
        new.state = st
        self._f = new
        self.dt_s = float(dt_s)
        self._off = []

    #: ``update_batch(..., diagnostics=True)`` returns VQF's own per-sample rest flag, bias and disturbance flag
    diagnostics = ("rest", "bias_rad_s", "mag_disturbed")

    def update_batch(self, gyr, acc, mag, dt_s, diagnostics: bool = False):
        g = np.ascontiguousarray(gyr, dtype=float)
        a = np.ascontiguousarray(acc, dtype=float)
        if mag is None:
            out = self._f.updateBatch(g, a)
            q = np.asarray(out["quat6D"])
        else:
            self._mag_used = True
            out = self._f.updateBatch(g, a, np.ascontiguousarray(mag, dtype=float))
            q = np.asarray(out["quat9D"])
        if not diagnostics:
            return q
        return {"quat": q, "rest": np.asarray(out["restDetected"], bool), "bias_rad_s": np.asarray(out["bias"]),
                "mag_disturbed": np.asarray(out.get("magDistDetected", np.zeros(len(q))), bool)}


def _version(dist: str) -> str:
    try:
        return version(dist)
    except PackageNotFoundError:
        return "?"


class FusionPeer(_Peer):
    """x-io Fusion (imufusion ``Ahrs``) with ``AhrsSettings(sample_rate=…)`` defaults, NWU convention."""

    NAME = "fusion"

    earth_frame = "NWU"

    def __init__(self, dt_s: float):
        imf = _need("imufusion", "imufusion")
        self._imf = imf
        self._f = imf.Ahrs()
        s = imf.AhrsSettings()
        s.sample_rate = 1.0 / float(dt_s)
        self._s = s
        self._f.set_settings(s)
        self._f.set_sample_period(float(dt_s)) if hasattr(self._f, "set_sample_period") else None

    @property
    def settings(self) -> dict:
        s = self._s
        out = {"library": "imufusion " + _version("imufusion"), "class": "Ahrs", "parameters": "AhrsSettings() defaults"}
        for k in ("sample_rate", "convention", "gain", "gyroscope_range", "acceleration_rejection",
                  "magnetic_rejection", "rejection_timeout"):
            if hasattr(s, k):
                out[k] = getattr(s, k)
        out["convention"] = "NWU" if out.get("convention") == self._imf.CONVENTION_NWU else out.get("convention")
        out["earth_frame"] = "NWU"
        return out

    @property
    def quat(self) -> np.ndarray:
        return np.asarray(self._f.get_quaternion(), dtype=float)

    def update(self, gyr_rad_s, acc_m_s2, mag_uT, dt_s):
        g = np.degrees(np.asarray(gyr_rad_s, dtype=float))
        a = np.asarray(acc_m_s2, dtype=float) / STANDARD_GRAVITY_M_S2
        if mag_uT is None:
            self._f.update_no_magnetometer(g, a)
        else:
            self._f.update(g, a, np.asarray(mag_uT, dtype=float))
        return self.quat


class _AhrsPeer(_Peer):
    """ahrs filters run through their per-sample ``updateMARG``/``updateIMU`` (the same code as their batch)."""

    cls_name = ""
    earth_frame = "NWU"
    acc_sign = 1.0

    def __init__(self, dt_s: float):
        mod = _need("ahrs.filters", "ahrs")
        self.rate = 1.0 / float(dt_s)
        self._f = getattr(mod, self.cls_name)(frequency=self.rate, **self._kwargs())
        self._q = None

    def _kwargs(self) -> dict:
        return {}

    @property
    def settings(self) -> dict:
        s = {"library": "ahrs " + _version("ahrs"), "class": f"ahrs.filters.{self.cls_name}",
             "parameters": "defaults", "frequency": self.rate, "earth_frame": self.earth_frame,
             "initial": "first acc+mag sample (ahrs's own q0 for batch input)"}
        for k in self._shown:
            if hasattr(self._f, k):
                v = getattr(self._f, k)
                s[k] = v.tolist() if isinstance(v, np.ndarray) else v
        return s

    @property
    def quat(self) -> np.ndarray:
        return np.asarray(self._q, dtype=float)

    def update_batch(self, gyr, acc, mag, dt_s):
        mod = _need("ahrs.filters", "ahrs")
        kw = dict(gyr=np.asarray(gyr, float), acc=self.acc_sign * np.asarray(acc, float), frequency=self.rate,
                  **self._kwargs())
        if mag is not None:
            kw["mag"] = np.asarray(mag, float) * 1000.0  # µT → nT, the unit ahrs documents
        f = getattr(mod, self.cls_name)(**kw)
        q = np.asarray(f.Q, dtype=float)
        self._q = q[-1]
        return q


class AhrsMadgwickPeer(_AhrsPeer):
    NAME = "ahrs-madgwick"
    cls_name = "Madgwick"
    earth_frame = "NWU"
    _shown = ("gain", "frequency")

    def update(self, gyr_rad_s, acc_m_s2, mag_uT, dt_s):
        g, a = np.asarray(gyr_rad_s, float), np.asarray(acc_m_s2, float)
        if self._q is None:
            self._q = _first_q(a, mag_uT, self.earth_frame)
        if mag_uT is None:
            self._q = self._f.updateIMU(self._q, g, a)
        else:
            self._q = self._f.updateMARG(self._q, g, a, np.asarray(mag_uT, float) * 1000.0)
        return self.quat


class AhrsMahonyPeer(AhrsMadgwickPeer):
    NAME = "ahrs-mahony"
    cls_name = "Mahony"
    earth_frame = "ENU"
    _shown = ("k_P", "k_I", "frequency")


class AhrsEkfPeer(AhrsMadgwickPeer):
    NAME = "ahrs-ekf"
    cls_name = "EKF"
    earth_frame = "NED"
    _shown = ("frame", "noises", "magnetic_ref", "frequency")

    acc_sign = -1.0  # ahrs EKF (NED) expects the accelerometer to read +g along down; see the module docstring

    def _kwargs(self) -> dict:
        return {"frame": "NED"}

    @property
    def settings(self) -> dict:
        s = super().settings
        s["acc_input"] = "-acc (ahrs NED a_ref = [0, 0, 1])"
        return s

    def update(self, gyr_rad_s, acc_m_s2, mag_uT, dt_s):
        """One sample, the way ahrs's own batch run takes it: the first sample only sets the initial
        orientation (ahrs's ``ecompass``), each later one is ``EKF.update``. ahrs's measurement model picks
        gravity-only or gravity + field from the ``mag`` attribute it was constructed with, not from the
        sample (so a per-sample filter built without ``mag`` fails with shapes (6,) vs (3,) on the first
        field sample); the attribute is set to the stream's kind of input here."""
        g, a = np.asarray(gyr_rad_s, float), self.acc_sign * np.asarray(acc_m_s2, float)
        m = None if mag_uT is None else np.asarray(mag_uT, float) * 1000.0
        self._f.mag = None if m is None else m[None, :]
        if self._q is None:
            self._q = _ahrs_initial_q(a, m)
            return self.quat
        self._q = self._f.update(self._q, g, a, m) if m is not None else self._f.update(self._q, g, a)
        return self.quat


def _ahrs_initial_q(acc, mag_nT):
    """ahrs's EKF batch start: ``ecompass(acc, mag, frame="NED")``, or ``acc2q(acc)`` without a field."""
    from ahrs.common.orientation import acc2q, ecompass  # optional dependency: the peers extra

    q = ecompass(acc, mag_nT, frame="NED", representation="quaternion") if mag_nT is not None else acc2q(acc)
    return np.asarray(q, float) / np.linalg.norm(q)


def _first_q(acc, mag, frame):
    if frame == "NED":
        qn = np.array(ecompass(*acc, *(mag if mag is not None else (0.0, 0.0, 0.0)), frame="NWU"))
        # NWU → NED: rotate 180° about north (x)
        return quat.multiply(np.array([0.0, 1.0, 0.0, 0.0]), qn)
    return np.array(ecompass(*acc, *(mag if mag is not None else (0.0, 0.0, 0.0)), frame=frame))
