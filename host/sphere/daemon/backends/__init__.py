"""Output backends: where pointer steps and clicks go.

Every backend has ``move(dx, dy)`` (relative, pixels, x right, y down), ``press(button)``,
``release(button)``, ``click(button, count=1)``, ``move_to(x, y)`` (may be a no-op),
``screen_size()`` ((w, h) or None when unknown) and ``close()``. ``button`` is "left", "right" or
"middle". A backend is one module (a :class:`~sphere.daemon.backends.base.Backend` with ``NAME``,
``PARAMS`` — its ``[backend.NAME]`` section, if it has settings — and optionally
``from_settings(settings, stream)``) and one line in :data:`REGISTRY`; this package imports none of them.
:func:`open_backend` builds one by name; ``auto`` tries them in the registry's order and falls back to
``log`` with the reasons the others could not start.
"""

from __future__ import annotations

from sphere.daemon.backends.base import BackendUnavailable
from sphere.settings import Registry, UnknownComponent

#: ``[output] backend`` → "module:Class", in the order ``auto`` tries them. One line per backend.
REGISTRY = Registry("backend", {
    "uinput": "sphere.daemon.backends.uinput:UinputBackend",
    "x11": "sphere.daemon.backends.x11:X11Backend",
    "pynput": "sphere.daemon.backends.pynput_backend:PynputBackend",
    "log": "sphere.daemon.backends.log:LogBackend",
}, label="backend")

#: what ``auto`` falls back to when no other backend starts (it always does)
FALLBACK = "log"


def _build(name: str, settings, stream):
    try:
        section = REGISTRY.section(name)
        s = settings(section) if settings is not None else None
        return REGISTRY.build(name, s, stream=stream)
    except UnknownComponent as e:
        raise BackendUnavailable(str(e)) from None


def open_backend(name: str = "auto", settings=None, warn=None, stream=None):
    """The named backend (BackendUnavailable if it cannot start), or for ``auto`` the first that starts.

    ``settings(section)`` gives a backend's ``[backend.NAME]`` settings (None: its defaults); ``stream`` is
    where the ``log`` backend prints."""
    if name != "auto":
        return _build(name, settings, stream)
    reasons = []
    for candidate in REGISTRY:
        if candidate == FALLBACK:
            continue
        try:
            return _build(candidate, settings, stream)
        except BackendUnavailable as e:
            reasons.append(f"{candidate}: {e}")
    if warn is not None:
        warn("no pointer backend could start, so sphere-mouse only prints what it would do (backend log):\n  "
             + "\n  ".join(reasons))
    return _build(FALLBACK, settings, stream)
