"""Each filter's parameters, defined once: default, unit, allowed range and meaning.

A filter class lists them in ``PARAMS`` (name → :class:`Param`, in constructor order) and the values
`sphere bench pointer` tries in ``GRID``; :func:`resolve` turns constructor arguments into checked values.
The daemon's ``[smoothing.NAME]`` config sections and their documentation are generated from ``PARAMS``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Param:
    default: float
    unit: str
    lo: float
    hi: float
    doc: str
    integer: bool = False
    choices: tuple | None = None  # for text parameters

    def check(self, name: str, value):
        if self.choices is not None:
            if value not in self.choices:
                raise ValueError(f"{name} = {value!r}: must be one of {', '.join(map(repr, self.choices))}")
            return value
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"{name} = {value!r}: must be a finite number ({self.unit})")
        if self.integer and int(value) != value:
            raise ValueError(f"{name} = {value!r}: must be an integer")
        if not self.lo <= value <= self.hi:
            raise ValueError(f"{name} = {value!r}: must be between {self.lo:g} and {self.hi:g} {self.unit}".rstrip())
        return int(value) if self.integer else float(value)


def resolve(params: dict, args: tuple, kwargs: dict) -> dict:
    """Constructor arguments (positional in ``params`` order, then keywords) → every parameter, checked."""
    names = list(params)
    if len(args) > len(names):
        raise TypeError(f"at most {len(names)} positional parameters")
    values = dict(zip(names, args))
    for k, v in kwargs.items():
        if k not in params:
            raise ValueError(f"unknown parameter {k!r}; parameters are {', '.join(names) or 'none'}")
        if k in values:
            raise TypeError(f"{k} given twice")
        values[k] = v
    return {k: p.check(k, values[k]) if k in values else p.default for k, p in params.items()}
