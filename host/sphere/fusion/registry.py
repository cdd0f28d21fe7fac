"""Every orientation filter by the name `sphere eval` and the daemon use: one table, name → :class:`Filter`.

Adding a filter is one module and one line in :data:`FILTERS`. Each entry holds the factory, the default
values of the filter's free parameters (defined here once; the daemon and `sphere eval` both build from
them) and the small grid ``sphere eval --cv`` chooses them from, leave one trial out. The defaults are the
grid point ``--cv`` picks on all shipped BROAD trials (it prints that choice; host/docs/fusion.md has the
run), so the figures that describe them are the held-out ones.

Ours: ``madgwick`` (NWU), ``dissertation-kf`` (NWU), ``sphere`` (ENU). Peers (optional packages):
``vqf``, ``fusion``, ``ahrs-madgwick``, ``ahrs-mahony``, ``ahrs-ekf`` (see :mod:`sphere.fusion.peers`),
run with their published defaults and never tuned.

Our Madgwick and KF start from the e-compass orientation of the first sample (as BROAD's own example
code starts its Madgwick and Mahony) and get the start-up gyro calibration (``startup_bias``); the
firmware starts from [1, 0, 0, 0], so do the classes by default. SphereFilter initialises itself from its
first samples and estimates its own bias.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Callable

from sphere.fusion import peers
from sphere.fusion.common import ecompass
from sphere.fusion.kalman import DissertationKF
from sphere.fusion.madgwick import Madgwick
from sphere.fusion.sphere_filter import STRUCTURES, SphereFilter

#: seconds of still data at the start used as the start-up gyro calibration for madgwick and the KF
STARTUP_BIAS_S = 1.0


@dataclass(frozen=True)
class Filter:
    """One filter: ``factory(dt_s, q0, gyro_bias_rad_s, **params)``, its defaults and its ``--cv`` grid."""

    factory: Callable
    defaults: dict = field(default_factory=dict)
    grid: dict = field(default_factory=dict)
    #: gets the device's start-up gyro calibration and the e-compass initial orientation
    startup_bias: bool = False
    #: usable by the daemon (per-sample update with acc_valid / mag_valid)
    live: bool = False

    #: structure variants (dicts of the filter's part switches), simplest first; ``--cv`` chooses among them as it
    #: chooses parameters (nested: crossval.nested)
    structures: tuple = ()
    #: point → the same point with the parameters its structure does not use set to one value (so that equal
    #: filters are one point)
    canonical: Callable | None = None

    def grid_points(self) -> list[dict]:
        """Every combination of the structures and the grid's values, structures first and in their order (one
        point, the defaults, for a filter without either); points that build the same filter appear once."""
        keys = sorted(self.grid)
        params = [dict(zip(keys, vals)) for vals in itertools.product(*(self.grid[k] for k in keys))]
        out = []
        for s in self.structures or ({},):
            for p in params:
                pt = dict(s, **p)
                if self.canonical is not None:
                    pt = self.canonical(pt)
                if pt not in out:
                    out.append(pt)
        return out

    def structure_of(self, point: dict) -> tuple:
        """The structure a grid point belongs to (its part switches), as a hashable key."""
        keys = sorted(self.structures[0]) if self.structures else []
        return tuple((k, point[k]) for k in keys)


def _madgwick(dt_s, q0, bias, **p):
    return Madgwick(q0=q0, gyro_bias_rad_s=bias, **p)


def _kf(dt_s, q0, bias, **p):
    # R = 10⁻² I, P₀ = I, H = I are the dissertation's and fixed in the class; only σ_g and ψ are free
    return DissertationKF(q0=q0, gyro_bias_rad_s=bias, **p)


def _sphere(dt_s, q0, bias, **p):
    return SphereFilter(**p)


#: the step a live peer is built with when the caller gives none (the sphere's sample rate, 200 Hz)
LIVE_DT_S = 0.005


def _peer(name):
    return lambda dt_s, q0, bias: peers.PEERS[name](LIVE_DT_S if dt_s is None else dt_s)


FILTERS: dict[str, Filter] = {
    "madgwick": Filter(_madgwick, {"beta": 0.0135},
                       {"beta": (0.005, 0.0075, 0.01, 0.0135, 0.02, 0.03, 0.05)}, startup_bias=True, live=True),
    "dissertation-kf": Filter(_kf, {"gyro_noise_rad_s": 0.5, "robust": "huber-norm", "threshold": 0.036},
                              {"gyro_noise_rad_s": (0.1, 0.5), "robust": ("huber-norm",),
                               "threshold": (0.012, 0.024, 0.036, 0.07, 0.15)}, startup_bias=True),
    "sphere": Filter(_sphere, {}, {"tau_acc_s": (3.0, 4.5)}, live=True, structures=STRUCTURES),
    **{name: Filter(_peer(name), live=name == "vqf") for name in peers.PEERS},
}

OURS = ("madgwick", "dissertation-kf", "sphere")
PEERS = tuple(peers.PEERS)
ALL = tuple(FILTERS)
#: the daemon's ``[orientation] filter = auto``: the filter that wins on the held-out folds of the shipped BROAD
#: trials (nested leave-one-trial-out, `sphere eval --cv`) and on the stress seeds (sphere.fusion.stress), see
#: host/docs/fusion.md
DAEMON_DEFAULT = "vqf"
#: the filters the daemon can run, the default first, then ours (its ``auto`` takes the first one installed)
LIVE = (DAEMON_DEFAULT, *(n for n in ("sphere", "vqf", "madgwick") if n != DAEMON_DEFAULT and FILTERS[n].live))
#: what a peer in LIVE needs installed
_LIVE_NEEDS = {"vqf": "vqf"}


def live_available() -> tuple:
    """The names of LIVE whose libraries are installed, in LIVE's order."""
    import importlib.util

    return tuple(n for n in LIVE if n not in _LIVE_NEEDS or importlib.util.find_spec(_LIVE_NEEDS[n]) is not None)


def startup_gyro_bias(gyr_rad_s, dt_s: float, seconds: float = STARTUP_BIAS_S, max_std_rad_s: float = 0.02):
    """Mean gyro over the first ``seconds`` if the sensor was still then (the device's start-up gyro
    calibration); zeros otherwise."""
    import numpy as np

    n = max(1, int(round(seconds / dt_s)))
    g = np.asarray(gyr_rad_s, dtype=float)[:n]
    if len(g) < n or np.any(g.std(axis=0) > max_std_rad_s):
        return (0.0, 0.0, 0.0)
    return tuple(g.mean(axis=0).tolist())


def params(name: str, **overrides) -> dict:
    """The defaults of ``name`` with ``overrides`` (the class refuses a parameter it does not have)."""
    return dict(_spec(name).defaults, **overrides)


def make(name: str, dt_s: float | None = None, first_acc=None, first_mag=None, gyro_bias_rad_s=(0.0, 0.0, 0.0),
         **overrides):
    """A fresh filter called ``name`` for a stream with step ``dt_s``; first samples give the initial state.

    ``gyro_bias_rad_s`` (filters with ``startup_bias`` only) is the start-up gyro calibration the device
    would apply; ``overrides`` replace the defaults (``sphere eval --cv`` passes its grid points)."""
    spec = _spec(name)
    q0 = (1.0, 0.0, 0.0, 0.0)
    if first_acc is not None:
        q0 = ecompass(*map(float, first_acc), *(map(float, first_mag) if first_mag is not None else (0.0, 0.0, 0.0)),
                      frame="NWU")
    return spec.factory(dt_s, q0, gyro_bias_rad_s, **params(name, **overrides))


def make_for_trial(name: str, gyr, acc, mag, dt_s: float, **overrides):
    """``make`` as `sphere eval` calls it for a recording: the start-up calibration from its first second and
    the initial orientation from its first sample, for the filters that take them."""
    spec = _spec(name)
    if not spec.startup_bias:
        return make(name, dt_s, **overrides)
    return make(name, dt_s, acc[0], None if mag is None else mag[0],
                gyro_bias_rad_s=startup_gyro_bias(gyr, dt_s), **overrides)


def settings(name: str, f) -> dict:
    s = dict(f.settings)
    if _spec(name).startup_bias:
        s["initial"] = "e-compass of the first sample (BROAD example code's choice)"
        s["gyro_bias"] = f"start-up calibration: mean of the first {STARTUP_BIAS_S:g} s if still"
    return s


def _spec(name: str) -> Filter:
    try:
        return FILTERS[name]
    except KeyError:
        raise KeyError(f"unknown filter {name!r}; known: {', '.join(FILTERS)}") from None
