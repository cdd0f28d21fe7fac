"""The config sections ``[smoothing.NAME]``, one per registry filter, and ``[position_smoothing.NAME]``, one
per position filter (:mod:`sphere.smoothing.position`), generated from the filters' PARAMS (so default,
unit, range and meaning are written once, in the filter's module). Listed in the daemon's
``config.CONTRIBUTORS``; ``pointer.smoothing``, ``stream.smoothing`` and ``stream.position_smoothing``
choose a filter by name.
"""

from __future__ import annotations

import dataclasses

from sphere.daemon.config import option, register_section
from sphere.smoothing import position
from sphere.smoothing.registry import FILTERS, params


def _check(p):
    if p.choices is not None:
        return None

    def check(v):
        return None if p.lo <= v <= p.hi else f"must be between {p.lo:g} and {p.hi:g}{' ' + p.unit if p.unit else ''}"

    return check


def _doc(p) -> str:
    return f"{p.doc}{f' ({p.unit})' if p.unit else ''}"


def declare(name: str, prefix: str = "smoothing", params=params) -> type:
    fields = []
    for key, p in params(name).items():
        kind = str if p.choices is not None else int if p.integer else float
        fields.append((key, kind, option(p.default, _doc(p), _check(p), p.choices)))
    cls = dataclasses.make_dataclass(f"{prefix.title()}_{name.replace('-', '_')}", fields, frozen=True)
    return register_section(f"{prefix}.{name}", cls)


for _name in FILTERS:
    if params(_name):  # a filter without parameters (`none`) has no section
        declare(_name)
for _name in position.FILTERS:
    if position.params(_name):
        declare(_name, "position_smoothing", position.params)


def filter_params(cfg, name: str, prefix: str = "smoothing") -> dict:
    """The ``[PREFIX.NAME]`` values of a loaded config (the filter's defaults where none are set)."""
    try:
        return cfg[f"{prefix}.{name}"].as_dict()
    except (KeyError, TypeError):
        return {}
