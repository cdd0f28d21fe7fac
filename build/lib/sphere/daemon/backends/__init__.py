"""Output backends: where pointer steps and clicks go.

Every backend has ``move(dx, dy)`` (relative, pixels, x right, y down), ``press(button)``,
``release(button)``, ``click(button, count=1)``, ``move_to(x, y)`` (may be a no-op),
``screen_size()`` ((w, h) or None when unknown) and ``close()``. ``button`` is "left", "right" or
"middle". :func:`open_backend` builds one by name; ``auto`` tries uinput, x11, pynput and falls
back to ``log`` with the reasons the others could not start.
"""

from __future__ import annotations

import sys

from sphere.daemon.backends.base import Backend, BackendUnavailable

NAMES = ("uinput", "x11", "pynput", "log")


def _build(name: str, display: str = "", stream=None):
    if name == "uinput":
        from sphere.daemon.backends.uinput import UinputBackend

        return UinputBackend()
    if name == "x11":
        from sphere.daemon.backends.x11 import X11Backend

        return X11Backend(display or None)
    if name == "pynput":
        from sphere.daemon.backends.pynput_backend import PynputBackend

        return PynputBackend()
    if name == "log":
        from sphere.daemon.backends.log import LogBackend

        return LogBackend(stream or sys.stdout)
    raise BackendUnavailable(f"unknown backend {name!r}; backends are {', '.join(NAMES)}")


def open_backend(name: str = "auto", display: str = "", warn=None, stream=None) -> Backend:
    """The named backend (BackendUnavailable if it cannot start), or for ``auto`` the first that starts."""
    if name != "auto":
        return _build(name, display, stream)
    reasons = []
    for candidate in ("uinput", "x11", "pynput"):
        try:
            return _build(candidate, display, stream)
        except BackendUnavailable as e:
            reasons.append(f"{candidate}: {e}")
    if warn is not None:
        warn("no pointer backend could start, so sphere-mouse only prints what it would do (backend log):\n  "
             + "\n  ".join(reasons))
    return _build("log", display, stream)


__all__ = ["Backend", "BackendUnavailable", "open_backend", "NAMES"]
