"""Where frames come from. One module per source, all on :class:`~sphere.daemon.sources.base.Source`
(one connection loop: connect, read, decode, notice a lost link, look again):

- :mod:`.serial` — the sphere on a serial port (USB or Bluetooth SPP), discovery that touches only spheres;
- :mod:`.hid` — a HID receiver (hidapi);
- :mod:`.replay` — a capture file;
- :mod:`.simulated` — the virtual board (``sphere sim --pty``), a child that dies with the daemon;
- :mod:`.scripted` — the built-in scripted sphere.

A new source is one module (a ``Source`` subclass with ``NAME`` and ``from_config(cfg, log)``) and one
line in :data:`REGISTRY`; its settings, if it needs its own, are a config section declared in its module
(see host/docs/where-things-go.md).
"""

from __future__ import annotations

from sphere.daemon.sources.base import LinkLost, Source, SourceEnded, SourceError, version_problem
from sphere.daemon.sources.hid import HidSource, hid_report_bytes
from sphere.daemon.sources.replay import ReplaySource
from sphere.daemon.sources.scripted import ScriptedSource
from sphere.daemon.sources.serial import SerialSource, candidate_ports, expand_candidates, usb_ports
from sphere.daemon.sources.simulated import (DEFAULT_SIM_TRACE, PTY_RE, SimulatorSource, simulator_available,
                                             simulator_command, start_simulator)
from sphere.settings import load

#: ``[source] kind`` → "module:Class". One line per source.
REGISTRY = {
    "serial": "sphere.daemon.sources.serial:SerialSource",
    "hid": "sphere.daemon.sources.hid:HidSource",
    "replay": "sphere.daemon.sources.replay:ReplaySource",
    "simulate": "sphere.daemon.sources.simulated:SimulatorSource",
    "scripted": "sphere.daemon.sources.scripted:ScriptedSource",
}


def source_class(kind: str):
    return load(REGISTRY[kind])


def kind_of(cfg) -> str:
    """The source kind the settings ask for (``auto``: replay when a capture is named, else serial)."""
    kind = cfg.source.kind
    if kind == "auto":
        kind = "replay" if cfg.source.replay else "serial"
    return kind


def open_source(cfg, log) -> Source:
    """The source the settings ask for. Raises SourceError (or ConfigError) with what to do."""
    return source_class(kind_of(cfg)).from_config(cfg, log)


__all__ = ["REGISTRY", "open_source", "source_class", "kind_of", "Source", "SourceError", "SourceEnded",
           "LinkLost", "version_problem", "SerialSource", "HidSource", "ReplaySource", "ScriptedSource",
           "SimulatorSource", "hid_report_bytes", "candidate_ports", "expand_candidates", "usb_ports",
           "simulator_available", "simulator_command", "start_simulator", "DEFAULT_SIM_TRACE", "PTY_RE"]
