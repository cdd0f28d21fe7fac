"""A virtual gamepad through uinput (python-evdev), for games and drone or robot simulators: the sphere's
tilt moves the sticks, taps press buttons.

- left stick: roll → X (rolled right = right), pitch → Y (nose down = stick forward = up, as a flight stick);
- right stick X: yaw (turned right = right);
- buttons: single tap → A (BTN_SOUTH), double tap → B (BTN_EAST), free fall → Y (BTN_NORTH);
- the sphere's link lost (unplugged, out of range): the sticks back to the centre.

``full_tilt_deg`` of tilt from the reference pose is a full stick; the sticks report −32767 … 32767.
Needs write access to /dev/uinput (host/packaging/70-sphere-mouse.rules, as for the uinput backend).
"""

from __future__ import annotations

from sphere.daemon.outputs.base import Output, OutputUnavailable
from sphere.settings import Param

STICK_MAX = 32767
BUTTONS = {"single_tap": "BTN_SOUTH", "double_tap": "BTN_EAST", "free_fall": "BTN_NORTH"}


def stick_values(angles_deg, full_tilt_deg: float) -> dict[str, int]:
    """The axes for (yaw, pitch, roll) from the reference pose."""
    yaw, pitch, roll = angles_deg

    def scale(deg):
        return int(round(max(-1.0, min(1.0, deg / full_tilt_deg)) * STICK_MAX))

    return {"ABS_X": scale(roll), "ABS_Y": scale(pitch), "ABS_RX": scale(-yaw)}


class GamepadOutput(Output):
    NAME = "gamepad"
    PARAMS = {
        "enabled": Param(False, doc="a virtual gamepad (uinput): tilt → sticks, taps → buttons"),
        "name": Param("MARG sphere gamepad", doc="the device's name as games list it"),
        "full_tilt_deg": Param(30.0, doc="tilt from the reference pose that is a full stick", lo=1.0, hi=90.0),
        "rate_hz": Param(200.0, doc="stick updates a second at most", lo=1.0, hi=1000.0),
    }

    def __init__(self, name: str = "MARG sphere gamepad", full_tilt_deg: float = 30.0, rate_hz: float = 200.0, **kw):
        super().__init__(rate_hz, **kw)
        try:
            import evdev  # optional: python-evdev (the daemon extra, Linux)
            from evdev import AbsInfo, UInput, ecodes  # optional: python-evdev
        except ImportError:
            raise OutputUnavailable("python-evdev is not installed: pip install evdev (Linux only)") from None
        self.ecodes = ecodes
        self.full_tilt_deg = full_tilt_deg
        axis = AbsInfo(value=0, min=-STICK_MAX, max=STICK_MAX, fuzz=0, flat=0, resolution=0)
        caps = {ecodes.EV_KEY: [getattr(ecodes, b) for b in BUTTONS.values()],
                ecodes.EV_ABS: [(ecodes.ABS_X, axis), (ecodes.ABS_Y, axis), (ecodes.ABS_RX, axis), (ecodes.ABS_RY, axis)]}
        try:
            self.ui = UInput(caps, name=name, vendor=0x1209, product=0x5350, version=1, bustype=ecodes.BUS_VIRTUAL)
        except (OSError, evdev.UInputError) as e:
            raise OutputUnavailable(f"cannot create a uinput gamepad: {e}; load the module (sudo modprobe uinput) and "
                                    "install host/packaging/70-sphere-mouse.rules for write access to /dev/uinput") from None
        self.name = name
        self.last = {}

    @classmethod
    def from_settings(cls, s, log=None) -> "GamepadOutput":
        return cls(s.name, s.full_tilt_deg, s.rate_hz)

    def describe(self) -> str:
        return f"uinput gamepad \"{self.name}\" at {self.ui.device.path}" if self.ui.device else f"uinput gamepad \"{self.name}\""

    def send_pose(self, q, angles_deg, moved_m, position_m, t_us) -> None:
        values = stick_values(angles_deg, self.full_tilt_deg)
        changed = False
        for code, v in values.items():
            if self.last.get(code) != v:
                self.ui.write(self.ecodes.EV_ABS, getattr(self.ecodes, code), v)
                self.last[code] = v
                changed = True
        if changed:
            self.ui.syn()

    def link_lost(self) -> None:
        """The sticks back to the centre: a stick left deflected keeps a game steering with no sphere there."""
        moved = False
        for code, v in self.last.items():
            if v != 0:
                self.ui.write(self.ecodes.EV_ABS, getattr(self.ecodes, code), 0)
                self.last[code] = 0
                moved = True
        if moved:
            self.ui.syn()
        self._next = 0.0  # the first pose after a reconnect is sent at once

    def send_event(self, name: str, t_us) -> None:
        button = BUTTONS.get(name)
        if button is None:
            return
        code = getattr(self.ecodes, button)
        self.ui.write(self.ecodes.EV_KEY, code, 1)
        self.ui.syn()
        self.ui.write(self.ecodes.EV_KEY, code, 0)
        self.ui.syn()

    def close(self) -> None:
        self.ui.close()
