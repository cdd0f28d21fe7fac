"""The ``uinput`` backend: a virtual mouse through the kernel's uinput (python-evdev).

Works under X11 and Wayland alike, and needs no root: host/packaging/70-sphere-mouse.rules gives the
``input`` group (or the logged-in user, through ``uaccess``) write access to /dev/uinput.
"""

from __future__ import annotations

from sphere.daemon.backends.base import Backend, BackendUnavailable

DEVICE_NAME = "MARG sphere mouse"


def _ecodes():
    try:
        from evdev import ecodes  # optional: python-evdev (the daemon extra, Linux)
    except ImportError:
        raise BackendUnavailable("python-evdev is not installed: pip install evdev") from None
    return ecodes


def capabilities():
    e = _ecodes()
    return {e.EV_KEY: [e.BTN_LEFT, e.BTN_RIGHT, e.BTN_MIDDLE], e.EV_REL: [e.REL_X, e.REL_Y, e.REL_WHEEL]}


class UinputBackend(Backend):
    """``device`` is anything with ``write(type, code, value)`` and ``syn()`` (a python-evdev UInput);
    by default one is created on /dev/uinput."""

    NAME = "uinput"

    def __init__(self, device=None):
        e = _ecodes()
        self.e = e
        self._buttons = {"left": e.BTN_LEFT, "right": e.BTN_RIGHT, "middle": e.BTN_MIDDLE}
        if device is None:
            try:
                from evdev import UInput  # optional: python-evdev
                from evdev.uinput import UInputError  # optional: python-evdev
            except ImportError:
                raise BackendUnavailable("python-evdev is not installed: pip install evdev") from None
            try:
                device = UInput(capabilities(), name=DEVICE_NAME)
            except (UInputError, OSError) as err:
                raise BackendUnavailable(
                    f"cannot open /dev/uinput ({err}); load the module (`sudo modprobe uinput`) and install "
                    "host/packaging/70-sphere-mouse.rules so your user may write to it (see host/docs/sphere-mouse.md)"
                ) from None
        self.device = device

    def move(self, dx: int, dy: int) -> None:
        e, d = self.e, self.device
        if dx:
            d.write(e.EV_REL, e.REL_X, int(dx))
        if dy:
            d.write(e.EV_REL, e.REL_Y, int(dy))
        if dx or dy:
            d.syn()

    def press(self, button: str) -> None:
        self.device.write(self.e.EV_KEY, self._buttons[button], 1)
        self.device.syn()

    def release(self, button: str) -> None:
        self.device.write(self.e.EV_KEY, self._buttons[button], 0)
        self.device.syn()

    def close(self) -> None:
        close = getattr(self.device, "close", None)
        if close:
            close()
