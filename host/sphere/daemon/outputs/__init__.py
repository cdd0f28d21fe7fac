"""Outputs for other programs: sphere-mouse sends the sphere's orientation, position, events and mode to
them beside the pointer. Each has an ``enabled`` key; only the page is on by default.

- :mod:`.page` — the 3-D page and its WebSocket (sphere.daemon.stream3d), for browsers and local programs;
- :mod:`.opentrack` — OpenTrack's "UDP over network" input: six little-endian doubles per datagram;
- :mod:`.osc` — Open Sound Control over UDP (python-osc), for creative tools;
- :mod:`.gamepad` — a virtual gamepad through uinput (python-evdev): tilt → sticks, taps → buttons;
- :mod:`.spacenav` — a 3-D mouse for libspnav programs (Blender, FreeCAD): spacenavd's protocol on a socket;
- :mod:`.dsu` — a DSU ("cemuhook") motion server for emulators (Dolphin, Cemu, Citra/yuzu): gyro and taps.

A new output is one module (an :class:`~sphere.daemon.outputs.base.Output` subclass with ``NAME``,
``PARAMS`` — its ``[outputs.NAME]`` section — and ``from_settings(settings, log)``) and one line in
:data:`REGISTRY`. This package imports none of them.

The daemon talks to all of them through :class:`~sphere.daemon.outputs.fanout.Outputs`, which has the
orientation stream's interface (``publish_orientation``, ``publish_event``, ``publish_mode``,
``recentre``, ``position``, ``mode``, ``url``) and passes each call on to every enabled output.
"""

from __future__ import annotations

from sphere.settings import Registry

#: ``[outputs.NAME]`` → "module:Class". One line per output.
REGISTRY = Registry("outputs", {
    "page": "sphere.daemon.outputs.page:PageOutput",
    "opentrack": "sphere.daemon.outputs.opentrack:OpenTrackOutput",
    "osc": "sphere.daemon.outputs.osc:OscOutput",
    "gamepad": "sphere.daemon.outputs.gamepad:GamepadOutput",
    "spacenav": "sphere.daemon.outputs.spacenav:SpacenavOutput",
    "dsu": "sphere.daemon.outputs.dsu:DsuOutput",
}, label="output")


def output_class(name: str):
    return REGISTRY.load(name)
