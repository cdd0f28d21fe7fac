"""Where frames come from. One module per source, all on :class:`~sphere.daemon.sources.base.Source`
(one connection loop: connect, read, decode, notice a lost link, look again):

- :mod:`.serial` — the sphere on a serial port (USB or Bluetooth SPP), discovery that touches only spheres;
- :mod:`.hid` — a HID receiver (hidapi);
- :mod:`.replay` — a capture file;
- :mod:`.simulated` — the virtual board (``sphere sim --pty``), a child that dies with the daemon;
- :mod:`.scripted` — the built-in scripted sphere.

A new source is one module (a ``Source`` subclass with ``NAME``, ``PARAMS`` — its ``[source.NAME]``
section — and ``from_settings(settings, log, cfg)``) and one line in :data:`REGISTRY` (see
host/docs/where-things-go.md). This package imports none of them.
"""

from __future__ import annotations

from sphere.settings import Param, Registry

#: ``[source] kind`` → "module:Class". One line per source.
REGISTRY = Registry("source", {
    "serial": "sphere.daemon.sources.serial:SerialSource",
    "hid": "sphere.daemon.sources.hid:HidSource",
    "replay": "sphere.daemon.sources.replay:ReplaySource",
    "simulate": "sphere.daemon.sources.simulated:SimulatorSource",
    "scripted": "sphere.daemon.sources.scripted:ScriptedSource",
}, label="source")

#: The ``[source]`` section: which source, and what every source that looks for a device shares.
PARAMS = {
    "kind": Param("auto", doc="where frames come from, a source of the registry: `serial`, `hid`, `replay`, "
                              "`simulate`, `scripted` (each with its settings in [source.NAME]); `auto` = serial "
                              "(with discovery), or `replay` when a capture file is named",
                  choices=lambda: ("auto", *REGISTRY)),
    "reconnect_interval_s": Param(1.0, doc="pause between attempts to find the sphere again", lo=0.01, hi=3600.0),
}


def source_class(kind: str):
    return REGISTRY.load(kind)


def kind_of(cfg) -> str:
    """The source kind the settings ask for (``auto``: replay when a capture is named, else serial)."""
    kind = cfg.source.kind
    if kind == "auto":
        kind = "replay" if cfg["source.replay"].file else "serial"
    return kind


def open_source(cfg, log):
    """The source the settings ask for, built from its ``[source.NAME]`` settings. Raises SourceError with
    what to do."""
    kind = kind_of(cfg)
    return REGISTRY.build(kind, cfg.get(REGISTRY.section(kind)), log=log, cfg=cfg)
