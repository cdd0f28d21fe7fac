"""The one way a configurable part of the host declares its settings, and the registries that list the parts.

A component (an orientation filter, a smoothing filter, a source, a backend, an output, the pointer and
tilt mappers, the gyro-bias estimator, the camera) is a class with

- ``NAME``: the name users write (``[pointer] smoothing = "tremor"``, ``[source] kind = "serial"``);
- ``PARAMS``: name → :class:`Param` (default, unit, range or choices, meaning), in constructor order;
- optionally ``GRID`` (name → values a cross-validation tries), ``check_settings(values) -> str | None``
  (keys that must agree) and ``from_settings(settings, **context)`` (how it is built from its values;
  without it the class is called with the values as keywords).

A kind's components are listed in a :class:`Registry`: one line per component, ``NAME: "module:Class"``,
imported only when that component is asked for. The daemon's config file has a section per component
(``[smoothing.tremor]``, ``[outputs.osc]`` ...) composed from the registries by :mod:`sphere.daemon.config`;
``--print-config``, ``--set``, the checks, the reference in host/docs/sphere-mouse.md and the ``--cv``
grids all come from the ``PARAMS``.

This module is the bottom layer: it imports nothing of the package (the registry lines are strings).
"""

from __future__ import annotations

import importlib
import itertools
import math

from sphere.errors import SphereError


class ParamError(SphereError, ValueError):
    """A value a parameter does not take; the message is the reason (``must be between 1 and 5 Hz``)."""


#: largest integer a setting may hold (screen sizes, ports, IDs are far below; 2**70 is a typo)
MAX_INT = 1 << 31

_TYPES = {bool: "true or false", int: "an integer", float: "a number", str: "a string", list: "a list"}


class Param:
    """One setting: its default, unit, allowed range (``lo`` … ``hi``) or ``choices``, and its meaning.

    The type is the default's (``bool``, ``int``, ``float``, ``str``, ``list``); ``integer=True`` makes a
    number an integer. ``choices`` is a tuple or a callable returning one (a registry's names, read when
    checked). ``check`` is a callable returning the reason a value is bad, or None, for what a range cannot
    say (a list's entries, a port's syntax)."""

    __slots__ = ("default", "unit", "lo", "hi", "doc", "kind", "choices", "extra_check")

    def __init__(self, default, unit: str = "", lo=None, hi=None, doc: str = "", integer: bool | None = None,
                 choices=None, check=None):
        self.default = list(default) if isinstance(default, list) else default
        self.unit = unit
        self.lo = lo
        self.hi = hi
        self.doc = doc
        self.choices = choices
        self.extra_check = check
        if isinstance(default, bool):
            self.kind = bool
        elif integer or (integer is None and isinstance(default, int)):
            self.kind = int
        elif isinstance(default, (int, float)):
            self.kind = float
        elif isinstance(default, (str, list)):
            self.kind = type(default)
        else:
            raise TypeError(f"a Param's default is a bool, number, string or list, not {default!r}")

    def __repr__(self) -> str:
        return f"Param({self.default!r}, {self.unit!r}, {self.lo!r}, {self.hi!r}, {self.doc!r})"

    def replace(self, **changes) -> "Param":
        """A copy with some fields changed (``p.replace(default=0.5)``)."""
        fields = {"default": self.default, "unit": self.unit, "lo": self.lo, "hi": self.hi, "doc": self.doc,
                  "integer": self.kind is int, "choices": self.choices, "check": self.extra_check}
        fields.update(changes)
        return Param(**fields)

    def fresh_default(self):
        """The default (a new list for a list, so no two settings share one)."""
        return list(self.default) if self.kind is list else self.default

    def allowed(self) -> tuple | None:
        """The choices now (a callable's are read when asked), or None."""
        c = self.choices
        return tuple(c()) if callable(c) else c

    def describe(self) -> str:
        """The meaning with the unit: ``cutoff when still (Hz)``."""
        return f"{self.doc} ({self.unit})" if self.unit else self.doc

    def _bound(self, v) -> str:
        return repr(float(v)) if self.kind is float else str(v)

    def convert(self, value):
        """``value`` as this parameter's type, checked; :class:`ParamError` with the reason otherwise."""
        kind = self.kind
        if kind is float or kind is int:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ParamError(f"must be {_TYPES[kind]}" + (f" ({self.unit})" if self.unit else ""))
            try:
                finite = math.isfinite(value)
            except OverflowError:
                raise ParamError("is too large") from None
            if not finite:
                raise ParamError("must be a finite number")
            if kind is int:
                if int(value) != value:
                    raise ParamError("must be an integer")
                value = int(value)
                if abs(value) > MAX_INT:
                    raise ParamError("is too large")
            else:
                try:
                    value = float(value)
                except OverflowError:
                    raise ParamError("is too large") from None
            lo, hi = self.lo, self.hi
            if (lo is not None and value < lo) or (hi is not None and value > hi):
                if lo is not None and hi is not None:
                    where = f"between {self._bound(lo)} and {self._bound(hi)}"
                elif lo is not None:
                    where = f"at least {self._bound(lo)}"
                else:
                    where = f"at most {self._bound(hi)}"
                raise ParamError(f"must be {where}{' ' + self.unit if self.unit else ''}")
        elif not isinstance(value, kind):
            raise ParamError(f"must be {_TYPES[kind]}")
        elif kind is list:
            value = list(value)
        choices = self.allowed()
        if choices is not None and value not in choices:
            raise ParamError(f"must be one of {', '.join(map(repr, choices))}")
        if self.extra_check is not None:
            reason = self.extra_check(value)
            if reason:
                raise ParamError(reason)
        return value

    def check(self, name: str, value):
        """:meth:`convert`, the error naming the parameter: ``notch_q = 0: must be between 0.1 and 20.0``."""
        try:
            return self.convert(value)
        except ParamError as e:
            raise ParamError(f"{name} = {value!r}: {e}") from None


# ---- checks a range cannot say, for Param(check=...) ------------------------------------------------


def positive(v):
    return None if v > 0 else "must be greater than 0"


def str_list(v):
    return None if all(isinstance(s, str) for s in v) else "must be a list of strings"


def port_number(v):
    return None if 0 <= v <= 65535 else "must be a TCP port number, 0 … 65535 (0 picks a free one)"


def resolve(params: dict, args: tuple = (), kwargs: dict | None = None) -> dict:
    """Constructor arguments (positional in ``params`` order, then keywords) → every parameter, checked,
    the defaults for those not given."""
    names = list(params)
    if len(args) > len(names):
        raise TypeError(f"at most {len(names)} positional parameters")
    values = dict(zip(names, args))
    for k, v in (kwargs or {}).items():
        if k not in params:
            raise ParamError(f"unknown parameter {k!r}; parameters are {', '.join(names) or 'none'}")
        if k in values:
            raise TypeError(f"{k} given twice")
        values[k] = v
    return {k: p.check(k, values[k]) if k in values else p.fresh_default() for k, p in params.items()}


class Settings:
    """The values of one component's parameters, read as attributes (``s.rate_hz``); read-only.

    ``Settings(PARAMS, {"rate_hz": 30})`` checks the values and fills in the defaults (``checked=False``
    for values already checked, as the daemon's config passes them)."""

    def __init__(self, params: dict, values: dict | None = None, checked: bool = False):
        values = values or {}
        if checked:
            out = {k: _copy(values[k]) if k in values else p.fresh_default() for k, p in params.items()}
        else:
            out = resolve(params, (), values)
        self.__dict__.update(out)

    def __setattr__(self, key, value):
        raise AttributeError(f"settings are read-only ({key})")

    def as_dict(self) -> dict:
        return {k: _copy(v) for k, v in self.__dict__.items()}

    def __eq__(self, other):
        return isinstance(other, Settings) and self.__dict__ == other.__dict__

    def __repr__(self) -> str:
        return "Settings(" + ", ".join(f"{k}={v!r}" for k, v in self.__dict__.items()) + ")"


def _copy(v):
    return list(v) if isinstance(v, list) else v


def load(spec: str):
    """The object a ``"package.module:attribute"`` string names."""
    module, _, attr = spec.partition(":")
    return getattr(importlib.import_module(module), attr)


class UnknownComponent(SphereError, ValueError):
    """A name no registry line has; the message lists the names there are."""


class Registry:
    """The components of one kind: ``NAME → "module:Class"``, one line each, imported when first asked for.

    ``section`` is the config section of a component's parameters, ``{name}`` replaced by its name (the
    daemon reads ``[smoothing.tremor]`` for the smoothing filter ``tremor``); ``label`` names one
    component in messages (``unknown smoothing filter 'x'``)."""

    def __init__(self, kind: str, entries: dict, section: str | None = None, label: str | None = None):
        self.kind = kind
        self.label = label or kind
        self.entries = dict(entries)
        self.section_pattern = section if section is not None else kind + ".{name}"
        self._loaded: dict = {}

    def __iter__(self):
        return iter(self.entries)

    def __contains__(self, name) -> bool:
        return name in self.entries

    def __len__(self) -> int:
        return len(self.entries)

    def __getitem__(self, name: str) -> str:
        return self.entries[name]

    def names(self) -> tuple:
        return tuple(self.entries)

    def add(self, name: str, spec: str) -> None:
        """One more component (the registry line, made at run time: a plug-in or a test's)."""
        self.entries[name] = spec
        self._loaded.pop(name, None)

    def remove(self, name: str) -> None:
        self.entries.pop(name, None)
        self._loaded.pop(name, None)

    def load(self, name: str):
        """The component's class (imported on first use)."""
        cls = self._loaded.get(name)
        if cls is None:
            try:
                spec = self.entries[name]
            except KeyError:
                raise UnknownComponent(f"unknown {self.label} {name!r}; choose from {', '.join(self.entries)}") from None
            cls = self._loaded[name] = load(spec)
        return cls

    def params(self, name: str) -> dict:
        """The component's parameters: name → :class:`Param`."""
        return dict(getattr(self.load(name), "PARAMS", {}))

    def section(self, name: str) -> str:
        return self.section_pattern.format(name=name)

    def settings(self, name: str, values: dict | None = None) -> Settings:
        """The component's settings: ``values`` checked, its defaults for the rest."""
        return Settings(self.params(name), values)

    def build(self, name: str, settings=None, **context):
        """A new component from its settings (a :class:`Settings` or a dict of values to check):
        ``Class.from_settings(settings, **context)``, or ``Class(**values, **context)`` without it."""
        cls = self.load(name)
        if not isinstance(settings, Settings):
            settings = Settings(getattr(cls, "PARAMS", {}), settings)
        make = getattr(cls, "from_settings", None)
        return make(settings, **context) if make is not None else cls(**settings.as_dict(), **context)

    def grid(self, name: str) -> list:
        """Every combination of the component's ``GRID`` (one empty point when it has none)."""
        space = getattr(self.load(name), "GRID", None) or {}
        keys = list(space)
        return [dict(zip(keys, values)) for values in itertools.product(*(space[k] for k in keys))]
