"""The sphere-mouse daemon (``sphere-mouse``; user guide: host/docs/sphere-mouse.md).

Pure core, fed packets, never opening a device:

- :mod:`~sphere.daemon.pointer` — :class:`PointerMapper` (angular rate → pointer steps) and
  :class:`TiltMapper` (orientation → pointer velocity);
- :mod:`~sphere.daemon.motion` — :class:`MotionTracker`: bias-corrected rate, the vertical, orientation;
- :mod:`~sphere.daemon.actions` — events → actions and the freeze around a tap;
- :mod:`~sphere.daemon.config` — the TOML settings, composed from the components' PARAMS, validated;
- :mod:`~sphere.daemon.scripted_sphere` — a scripted sphere's frames.

Edges: :mod:`~sphere.daemon.sources` (a package: one reconnect loop in ``base``, then serial with
discovery, HID, capture replay, the virtual board, the scripted sphere, and a registry),
:mod:`~sphere.daemon.backends` (uinput, x11, pynput, log, and a registry),
:mod:`~sphere.daemon.outputs` (the 3-D page over :mod:`~sphere.daemon.stream3d`, OpenTrack, OSC, gamepad,
spacenav, DSU, and a registry), :mod:`~sphere.daemon.status`,
:mod:`~sphere.daemon.app` (the loop) and :mod:`~sphere.daemon.cli` (flags). This package imports none of them.
"""
