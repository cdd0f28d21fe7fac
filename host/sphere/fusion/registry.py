"""Every orientation filter by the name `sphere eval` and the daemon use: one registry, name → "module:Class".

Adding a filter is one module and one line in :data:`REGISTRY`. The class carries ``NAME``, ``PARAMS`` (its
free parameters with their defaults, units and ranges: the daemon's ``[orientation.NAME]`` section and
`sphere eval` both build from them), ``GRID`` (the small grid ``sphere eval --cv`` chooses them from, leave
one trial out), ``STARTUP_BIAS`` (it takes the start-up gyro calibration and the e-compass start),
``STRUCTURES`` (part switches ``--cv`` chooses among, nested), ``LIVE`` (the daemon can run it: a per-sample
update with acc_valid / mag_valid) and ``from_settings(settings, dt_s, q0, gyro_bias_rad_s)``. The defaults
are the grid point ``--cv`` picks on all shipped BROAD trials (it prints that choice; host/docs/fusion.md
has the run), so the figures that describe them are the held-out ones.

Ours: ``madgwick`` (NWU), ``dissertation-kf`` (NWU), ``sphere`` (ENU). Peers (optional packages, the
entries in :mod:`sphere.fusion.peers`): ``vqf``, ``fusion``, ``ahrs-madgwick``, ``ahrs-mahony``,
``ahrs-ekf``, run with their published defaults and never tuned.

Our Madgwick and KF start from the e-compass orientation of the first sample (as BROAD's own example
code starts its Madgwick and Mahony) and get the start-up gyro calibration (``startup_bias``); the
firmware starts from [1, 0, 0, 0], so do the classes by default. SphereFilter initialises itself from its
first samples and estimates its own bias.
"""

from __future__ import annotations

import importlib.util
import itertools

from sphere.settings import Registry, Settings, UnknownComponent

#: seconds of still data at the start used as the start-up gyro calibration for madgwick and the KF
#: (sphere.fusion.factory.startup_gyro_bias)
STARTUP_BIAS_S = 1.0

#: name → "module:Class" (imported when first used). One line per filter.
REGISTRY = Registry("orientation", {
    "madgwick": "sphere.fusion.madgwick:Madgwick",
    "dissertation-kf": "sphere.fusion.kalman:DissertationKF",
    "sphere": "sphere.fusion.sphere_filter:SphereFilter",
    "vqf": "sphere.fusion.peers:VqfPeer",
    "fusion": "sphere.fusion.peers:FusionPeer",
    "ahrs-madgwick": "sphere.fusion.peers:AhrsMadgwickPeer",
    "ahrs-mahony": "sphere.fusion.peers:AhrsMahonyPeer",
    "ahrs-ekf": "sphere.fusion.peers:AhrsEkfPeer",
}, label="filter")

ALL = REGISTRY.names()
PEERS = tuple(n for n in ALL if REGISTRY[n].startswith("sphere.fusion.peers:"))
OURS = tuple(n for n in ALL if n not in PEERS)
#: the daemon's ``[orientation] filter = auto``: the filter that wins on the held-out folds of the shipped BROAD
#: trials (nested leave-one-trial-out, `sphere eval --cv`) and on every kind of the stress seeds
#: (sphere.fusion.stress), see host/docs/fusion.md: SphereFilter since it weighs the field (VQF before)
DAEMON_DEFAULT = "sphere"
#: the daemon's order of preference among the filters it can run (``LIVE = True`` on their class): the default
#: first, then ours (its ``auto`` takes the first one installed)
LIVE = (DAEMON_DEFAULT, *(n for n in ("sphere", "vqf", "madgwick") if n != DAEMON_DEFAULT))


def filter_class(name: str):
    try:
        return REGISTRY.load(name)
    except UnknownComponent:
        raise KeyError(f"unknown filter {name!r}; known: {', '.join(REGISTRY)}") from None


def live_available() -> tuple:
    """The filters the daemon can run (their class says ``LIVE = True``) whose libraries are installed (a
    peer's ``NEEDS``): those of LIVE in its order, then any other in the registry's."""
    names = list(LIVE) + [n for n in REGISTRY if n not in LIVE and getattr(filter_class(n), "LIVE", False)]
    out = []
    for n in names:
        needs = getattr(filter_class(n), "NEEDS", None)
        if needs is None or importlib.util.find_spec(needs) is not None:
            out.append(n)
    return tuple(out)


def grid(name: str) -> dict:
    """The filter's ``--cv`` grid of parameters: name → values (empty without one)."""
    return dict(getattr(filter_class(name), "GRID", None) or {})


def structures(name: str) -> tuple:
    """The filter's structure variants (dicts of its part switches), simplest first; () without any."""
    return tuple(getattr(filter_class(name), "STRUCTURES", ()) or ())


def grid_points(name: str) -> list[dict]:
    """Every combination of the structures and the grid's values, structures first and in their order (one
    point, the defaults, for a filter without either); points that build the same filter appear once."""
    space = grid(name)
    keys = sorted(space)
    params = [dict(zip(keys, vals)) for vals in itertools.product(*(space[k] for k in keys))]
    canonical = getattr(filter_class(name), "canonical", None)
    out = []
    for s in structures(name) or ({},):
        for p in params:
            pt = dict(s, **p)
            if canonical is not None:
                pt = canonical(pt)
            if pt not in out:
                out.append(pt)
    return out


def structure_of(name: str, point: dict) -> tuple:
    """The structure a grid point belongs to (its part switches), as a hashable key."""
    s = structures(name)
    keys = sorted(s[0]) if s else []
    return tuple((k, point[k]) for k in keys)


def defaults(name: str) -> dict:
    """The defaults of the filter's free parameters (its PARAMS)."""
    return {k: p.default for k, p in REGISTRY.params(name).items()}


def params(name: str, **overrides) -> dict:
    """The defaults of ``name`` with ``overrides`` (checked against its PARAMS; TypeError for a parameter it
    does not have)."""
    cls = filter_class(name)
    known = getattr(cls, "PARAMS", {})
    unknown = sorted(set(overrides) - set(known))
    if unknown:
        raise TypeError(f"filter {name!r} has no parameter {', '.join(unknown)}; its parameters are "
                        f"{', '.join(known) or 'none'}")
    return Settings(known, overrides).as_dict()


def settings(name: str, f) -> dict:
    s = dict(f.settings)
    if getattr(filter_class(name), "STARTUP_BIAS", False):
        s["initial"] = "e-compass of the first sample (BROAD example code's choice)"
        s["gyro_bias"] = f"start-up calibration: mean of the first {STARTUP_BIAS_S:g} s if still"
    return s


class FilterView:
    """One registry entry as `sphere eval` reads it (everything derived from the filter's class: nothing is
    declared here): ``defaults``, ``grid``, ``structures``, ``startup_bias``, ``live``, ``factory``,
    ``grid_points()`` and ``structure_of(point)``."""

    def __init__(self, name: str):
        self.name = name
        self.cls = filter_class(name)

    @property
    def defaults(self) -> dict:
        return defaults(self.name)

    @property
    def grid(self) -> dict:
        return grid(self.name)

    @property
    def structures(self) -> tuple:
        return structures(self.name)

    @property
    def startup_bias(self) -> bool:
        return bool(getattr(self.cls, "STARTUP_BIAS", False))

    @property
    def live(self) -> bool:
        return bool(getattr(self.cls, "LIVE", False))

    def factory(self, dt_s, q0, gyro_bias_rad_s, **overrides):
        s = Settings(getattr(self.cls, "PARAMS", {}), params(self.name, **overrides), checked=True)
        return self.cls.from_settings(s, dt_s=dt_s, q0=q0, gyro_bias_rad_s=gyro_bias_rad_s)

    def grid_points(self) -> list[dict]:
        return grid_points(self.name)

    def structure_of(self, point: dict) -> tuple:
        return structure_of(self.name, point)


class _Filters(dict):
    """name → :class:`FilterView`, made when first asked for (the registry's order)."""

    def __missing__(self, name):
        if name not in REGISTRY:
            raise KeyError(f"unknown filter {name!r}; known: {', '.join(REGISTRY)}")
        view = self[name] = FilterView(name)
        return view

    def __iter__(self):
        return iter(REGISTRY)

    def __len__(self):
        return len(REGISTRY)

    def __contains__(self, name):
        return name in REGISTRY

    def keys(self):
        return list(REGISTRY)

    def items(self):
        return [(n, self[n]) for n in REGISTRY]

    def values(self):
        return [self[n] for n in REGISTRY]


#: every entry as `sphere eval` reads it
FILTERS = _Filters()
