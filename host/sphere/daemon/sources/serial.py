"""The sphere on a serial port (USB or Bluetooth SPP), found by what it sends and reopened when lost.

Discovery (``port = "auto"``) touches only spheres:

- candidates are the ports whose USB VID:PID is in ``usb_ids`` (``serial.tools.list_ports``), the
  paths in ``candidates`` (``/dev/sphere``, the udev symlink) and the glob matches among them;
- a port another program has open is skipped and never opened (``sphere.link.port.holders``);
  every port is opened exclusively (flock + TIOCEXCL), with DTR held low where the driver allows;
- a port is only *listened to* until it identifies itself as a sphere: a HELLO, or
  ``IDENTIFY_FRAMES`` CRC-good frames of the sphere's types in a row. Only then is GET_HELLO sent (for
  the version handshake). A port the user named (``--port``, or a literal path in ``candidates`` such as
  ``/dev/sphere``) is asked with GET_HELLO at once (a Bluetooth module sends nothing by itself).
"""

from __future__ import annotations

import glob
import logging
import os
import select
import time

import serial
from serial.tools import list_ports

from sphere.daemon.sources.base import LinkLost, Source, SourceError, reconnect_interval_s, version_problem
from sphere.link.baud import CONFIRM_S, switch_baud
from sphere.link.clock import DeviceClock, SampleAges
from sphere.link.device import DeviceLink
from sphere.link.device_settings import SettingError, current_from_settings, parse_assignment, plan_settings, show
from sphere.link.port import (PortBusy, PortError, check_baud, open_port, port_problem, request_low_latency,
                              switchable_port)
from sphere.protocol import Echo, GetHello, Hello, PacketStream, RawSample, Reply
from sphere.protocol.packets import DEFAULT_BAUD, GetSettings
from sphere.settings import Param, str_list

DEFAULT_CANDIDATES = ("/dev/sphere",)
#: USB-serial chips of the Arduino Nano and its clones: CH340, FT232R, CP2102.
DEFAULT_USB_IDS = ("1a86:7523", "0403:6001", "10c4:ea60")
#: An unnamed port counts as a sphere after this many CRC-good sphere frames in a row.
IDENTIFY_FRAMES = 3
#: How often a version-3 sphere is sent ECHO: its clock on ours (each sample's age, spec §5.4), and the lease
#: that holds a faster baud rate (§5.3)
ECHO_EVERY_S = 0.5
#: at a faster rate, this long of bytes without an intact frame among them (at least GARBAGE_BYTES) sends the port
#: back to 115200: the sphere went back
FALLBACK_S = 0.5
GARBAGE_BYTES = 32


_HEX = frozenset("0123456789abcdefABCDEF")


def _usb_ids(v):
    bad = [s for s in v if not (isinstance(s, str) and len(s) == 9 and s[4] == ":" and _HEX.issuperset(s[:4] + s[5:]))]
    return f"has {bad!r}: each entry is a USB VID:PID in hex, e.g. \"1a86:7523\"" if bad else None


def _device_settings(items) -> str | None:
    seen = set()
    try:
        for item in items:
            key, _ = parse_assignment(item)
            if key in seen:
                return f"{key} given twice"
            seen.add(key)
    except SettingError as e:
        return str(e)
    return None


class DeviceSettings:
    """``[device]``: settings the serial source (and the virtual board's) sends the sphere at every connect."""

    NAME = "device"
    PARAMS = {
        "settings": Param([], doc="device settings sent to the sphere at every connect, as `sphere device set` takes "
                                  "them (`sphere device keys` lists them), e.g. [\"tap.threshold_g=2.5\", "
                                  "\"tap.axes=z\"]; they win over what the sphere saved (`sphere device save`), "
                                  "which it keeps for other programs; empty = the sphere's own",
                          check=_device_settings),
    }


def device_settings(cfg) -> list:
    """``[device] settings`` of a loaded config (none without one)."""
    return cfg.device.settings if cfg is not None else []


def _is_glob(pattern: str) -> bool:
    return any(c in pattern for c in "*?[")


def usb_ports(usb_ids, comports=None) -> list[str]:
    """Ports whose USB VID:PID (hex, ``"1a86:7523"``) is in ``usb_ids``."""
    wanted = {i.lower() for i in usb_ids}
    if not wanted:
        return []
    if comports is None:
        comports = list_ports.comports
    out = []
    for info in comports():
        if info.vid is not None and f"{info.vid:04x}:{info.pid:04x}" in wanted:
            out.append(info.device)
    return sorted(out)


def candidate_ports(patterns, usb_ids=(), comports=None) -> list[tuple[str, bool]]:
    """(path, named) in the order to try: literal paths (named by the user: asked with GET_HELLO), then glob
    matches and USB VID:PID matches (not named: only listened to). Each device once."""
    out: list[tuple[str, bool]] = []
    seen: set[str] = set()

    def add(path, named):
        if not os.path.exists(path):
            return
        real = os.path.realpath(path)
        if real in seen:
            return
        seen.add(real)
        out.append((path, named))

    for pattern in patterns:
        if _is_glob(pattern):
            for m in sorted(glob.glob(pattern)):
                add(m, False)
        else:
            add(pattern, True)
    for path in usb_ports(usb_ids, comports):
        add(path, False)
    return out


def expand_candidates(patterns) -> list[str]:
    """The paths that ``patterns`` name now (kept for callers of the older API)."""
    return [p for p, _ in candidate_ports(patterns)]


class SerialSource(Source):
    """The sphere on a serial port. ``port="auto"`` discovers it (module docstring); a named port is
    asked with GET_HELLO every ``hello_timeout_s`` until ``discovery_timeout_s``. A read error (unplug)
    or ``link_timeout_s`` without a byte (a lost Bluetooth link) closes the port; the source then looks
    for the sphere again every ``reconnect_interval_s`` without ending."""

    NAME = "serial"
    DEVICE_PACED = True
    PARAMS = {
        "port": Param("auto", doc="serial port (`/dev/ttyUSB0`, `/dev/rfcomm0`, `/dev/sphere`; `--port`); `auto` = "
                                  "discovery: the ports in `candidates` and those whose USB IDs are in `usb_ids`, not "
                                  "held by another program, listened to until one identifies itself as a sphere"),
        "candidates": Param(list(DEFAULT_CANDIDATES), doc="ports `port = \"auto\"` tries first: a literal path (the "
                            "udev symlink) is asked with GET_HELLO, a glob match is only listened to", check=str_list),
        "usb_ids": Param(list(DEFAULT_USB_IDS), doc="USB VID:PID of the sphere's USB-serial chip (the Nano's CH340, "
                         "FT232R, CP2102): such ports are listened to (never written to) until they identify "
                         "themselves; [] = only `candidates`", check=_usb_ids),
        "baud": Param(115200, doc="baud rate (the Nano's default; an HC-05/HC-06 must be set to the same; `--baud`)",
                      check=check_baud),
        "reset_on_open": Param(False, doc="let opening the port reset a USB Nano through DTR; false holds DTR low "
                                          "(Linux still raises it for a moment on open, so a Nano with its auto-reset "
                                          "capacitor may reset anyway)"),
        "low_latency": Param(True, doc="ask the serial driver to pass bytes on at once (ASYNC_LOW_LATENCY: an FTDI "
                                       "adapter's latency timer goes from 16 ms to 1 ms); false leaves the driver's "
                                       "default"),
        "baud_switch": Param(1000000, doc="on a USB link, move a version-3 sphere to this exact rate after it "
                                          "connects (SET_BAUD, confirmed, back to 115200 when either side stops "
                                          "hearing the other; a 29-byte sample takes 0.29 ms at 1,000,000 instead of "
                                          "2.5 ms); 0 = stay at `baud`. Never on Bluetooth",
                             choices=(0, 250000, 500000, 1000000)),
        "hello_timeout_s": Param(0.5, doc="send GET_HELLO to a named port if no HELLO came within this time "
                                          "(Bluetooth links do not reset the board)", lo=0.01, hi=60.0),
        "discovery_timeout_s": Param(3.0, doc="give up on a candidate port that did not identify itself within this "
                                              "time", lo=0.05, hi=600.0),
        "link_timeout_s": Param(2.0, doc="a connected port that delivers no byte for this long is taken as lost (a "
                                         "Bluetooth link that dropped) and reopened", lo=0.05, hi=3600.0),
    }

    def __init__(self, port: str = "auto", candidates=DEFAULT_CANDIDATES, baud: int = 115200,
                 reset_on_open: bool = False, hello_timeout_s: float = 0.5, discovery_timeout_s: float = 3.0,
                 link_timeout_s: float = 2.0, reconnect_interval_s: float = 1.0, log=None,
                 read_timeout_s: float = 0.02, usb_ids=DEFAULT_USB_IDS, comports=None, low_latency: bool = True,
                 device_settings=(), baud_switch: int = 0):
        super().__init__(reconnect_interval_s=reconnect_interval_s, link_timeout_s=link_timeout_s, log=log)
        self.port = port
        self.candidates = list(candidates)
        self.usb_ids = list(usb_ids)
        self.baud = baud
        self.reset_on_open = reset_on_open
        self.hello_timeout_s = hello_timeout_s
        self.discovery_timeout_s = discovery_timeout_s
        self.read_timeout_s = read_timeout_s
        self.low_latency = low_latency
        self.baud_switch = baud_switch  # 0: stay at `baud` (spec §5.4)
        self.link_baud = baud
        self._good_frames, self._good_at, self._bytes_at_good = 0, 0.0, 0
        self._switch_again = False  # a sphere that restarted (HELLO seq 0) is moved to the faster rate again
        self._heard_at_default: int | None = None  # frames_ok when the port fell back: heard again, up again
        self._fresh = ()  # the last batch read (_batch), for _after_batch
        self._held: list = []  # packets read while switching, for the next batch
        self.device_settings = list(device_settings)  # [device] settings: sent at every connect
        self.serial = None
        self.port_name = None
        self.link = None
        self.state = "looking for the sphere"
        self._comports = comports
        self.allow_pids: tuple[int, ...] = ()  # processes that may hold the port (the virtual board we started)
        self._warned: set[str] = set()
        #: the sphere's clock on ours and each RAW_SAMPLE's age on arrival (version-3 firmware: ECHO)
        self.clock = DeviceClock(baud)
        self.ages = SampleAges()
        self._next_echo = 0.0

    @classmethod
    def from_settings(cls, s, log=None, cfg=None):
        return cls(s.port, s.candidates, reset_on_open=s.reset_on_open, log=log, usb_ids=s.usb_ids,
                   device_settings=device_settings(cfg), **serial_timing(s, cfg))

    def _apply_device_settings(self, hello) -> None:
        """[device] settings, at every connect: the keys of a group not given keep what the sphere reports
        (GET_SETTINGS), so the config changes only what it names; what the sphere refuses is said."""
        current = None
        if hello.protocol_version >= 3:
            reply = self.link.command(GetSettings(), 1.0)
            if reply is not None and reply.ok:
                current = current_from_settings(reply.settings()[0])
        try:
            plan = plan_settings(self.device_settings, hello, current)
        except SettingError as e:  # checked at start; a sphere without a HELLO stream rate lands here
            self.log(f"[device] settings not sent: {e}", logging.WARNING)
            return
        for packet in plan.packets:
            reply = self.link.command(packet, 1.0)
            if reply is None or not reply.ok:
                why = "no reply" if reply is None else f"result {reply.result}"
                self.log(f"the sphere did not take {packet.NAME} from [device] settings ({why})", logging.WARNING)
                return
        given = {item.split("=", 1)[0].strip() for item in self.device_settings}
        self.log("[device] settings sent: " + ", ".join(f"{k} = {show(k, v)}" for k, v in plan.values.items()
                                                        if k in given))

    # -- connecting --
    def _open(self, path: str):
        ser = open_port(path, self.baud, self.read_timeout_s, reset_on_open=self.reset_on_open, write_timeout_s=0.5,
                        allow_pids=self.allow_pids, low_latency=self.low_latency)
        if ser.low_latency_problem and "low-latency:" + path not in self._warned:
            self._warned.add("low-latency:" + path)  # once per port, at -v: it costs latency, not function
            self.log(ser.low_latency_problem, logging.DEBUG)
        try:
            ser.reset_input_buffer()  # bytes from before the (DTR) reset belong to an older session
        except Exception:
            pass
        return ser

    def send(self, packet) -> None:
        """Send a command to the connected sphere (no reply awaited)."""
        if self.link is not None:
            self.link.send(packet)

    def _note_once(self, path: str, msg: str) -> None:
        if path not in self._warned:
            self._warned.add(path)
            self.log(msg)

    def _try_port(self, path: str, named: bool):
        """Open ``path`` and wait for the sphere to identify itself: (port, the packets from its HELLO on, the start of
        the frame after them), or None."""
        try:
            ser = self._open(path)
        except PortBusy as e:
            self._note_once(path, str(e))
            return None
        except PortError as e:
            self._note_once(path, str(e))
            return None
        self._warned.discard(path)
        self._warned.discard("missing:" + path)
        probe = PacketStream("device")
        link = DeviceLink(ser, probe)
        start = time.monotonic()
        next_ask = start + self.hello_timeout_s if named else None
        good_run = 0
        try:
            while time.monotonic() - start < self.discovery_timeout_s and not self._stop:
                data = self._read_port(ser)
                if data:
                    arrival = time.perf_counter_ns()
                    errors = probe.stats.errors
                    decoded = probe.feed(data)
                    if probe.stats.errors != errors:
                        good_run = 0
                    for i, dp in enumerate(decoded):
                        p = dp.packet
                        if p.TYPE == Hello.TYPE:
                            problem = version_problem(p)
                            if problem:
                                ser.close()
                                raise SourceError(f"{path}: {problem}")
                            self.arrival_ns = arrival
                            self.link = link
                            return ser, [d.packet for d in decoded[i:]], probe.decoder.pending()
                    good_run += len(decoded)
                    if good_run >= IDENTIFY_FRAMES and next_ask is None:
                        next_ask = time.monotonic()  # it speaks our protocol: now it may be asked
                if next_ask is not None and time.monotonic() >= next_ask:
                    next_ask += self.hello_timeout_s
                    link.send(GetHello())
        except (OSError, serial.SerialException):
            pass
        try:
            ser.close()
        except Exception:
            pass
        return None

    def _connect(self):
        if self.port != "auto":
            paths = [(self.port, True)]
        else:
            paths = candidate_ports(self.candidates, self.usb_ids, self._comports)
        if not paths:
            self.state = ("looking for the sphere (no sphere port: plug it in, name it with --port, or try the "
                          "simulated one: --simulate)")
        elif self.port != "auto" and not os.path.exists(self.port):
            self.state = f"waiting for {self.port} to appear"
            if "missing:" + self.port not in self._warned:
                self._warned.add("missing:" + self.port)
                self.log(f"{self.port} is not there (yet): waiting for it (is the sphere plugged in or paired?)")
            return None
        elif self.port != "auto" and port_problem(self.port):
            raise SourceError(port_problem(self.port))
        else:
            self.state = f"looking for the sphere (nothing identified itself on {', '.join(p for p, _ in paths)})"
        for path, named in paths:
            got = self._try_port(path, named)
            if got is None:
                continue
            ser, packets, pending = got
            self.serial = ser
            self.port_name = path
            self.stream.restart()
            self.state = f"{path}"
            self.log(f"sphere found on {path}" + (" (reconnected)" if self.connects >= 1 else ""))
            self.link.stream = self.stream
            self.clock.restart(self.baud)
            self.ages.clear()
            self._next_echo = 0.0
            adopted = self.stream.adopt(packets, pending)
            if self.device_settings:  # a few ms at connect; the samples read meanwhile are counted, not used
                self._apply_device_settings(self.stream.hello)
            self.link_baud = self.baud
            if self.baud_switch and self.baud == DEFAULT_BAUD and self.baud_switch != self.baud:
                self._switch_baud(path)
            return adopted + self._take_held()
        return None

    def _read_port(self, ser) -> bytes:
        """Whatever has arrived, waiting at most read_timeout_s. On POSIX one select + one read of all that
        is there (pyserial's read costs several system calls per call); elsewhere pyserial's read."""
        fd = getattr(ser, "fd", None)
        if fd is None or os.name != "posix":
            return ser.read(ser.in_waiting or 1)
        r, _, _ = select.select([fd], [], [], self.read_timeout_s)
        if not r:
            return b""
        data = os.read(fd, 4096)
        if not data:  # readable but nothing: the device went away (as pyserial reports it)
            raise LinkLost("the port reports data but returns none (unplugged?)")
        return data

    def _read(self) -> bytes:
        return self._read_port(self.serial)

    # -- a faster exact rate on USB (spec §5.4) --
    def _switch_baud(self, path: str) -> bool:
        """SET_BAUD to ``baud_switch``, confirmed by an ECHO answered at the new rate; back to 115200 when not. Only a
        version-3 sphere on a USB-serial port or a pty (the virtual board): a Bluetooth module's link runs at the
        rate the module is set to."""
        hello = self.stream.hello
        if hello is None or hello.protocol_version < 3 or not switchable_port(path):
            return False
        target = self.baud_switch
        self.link.on_packet = self._held.append  # what arrives meanwhile goes to the daemon, not lost
        try:
            return self._switch_to(path, target)
        finally:
            self.link.on_packet = None

    def _switch_to(self, path: str, target: int) -> bool:
        done = switch_baud(self.link, target, self._set_port_baud)
        if not done.ok and done.why != "no answer":
            self.log(f"{path}: the sphere did not take {target} baud ({done.why}); staying at {self.baud}")
            return False
        if not done.ok:  # the port is back at 115200; the sphere follows within 1 s, sending nothing meanwhile
            self.log(f"{path}: no answer at {target} baud ({done.echoes} ECHOs in {CONFIRM_S:g} s): back to "
                     f"{DEFAULT_BAUD}")
            return False
        self.clock.restart(target)
        self._good_frames, self._good_at = self.stream.stats.frames_ok, time.monotonic()
        self._bytes_at_good = self.stream.stats.bytes_in
        self.log(f"{path}: link at {target} baud" + (f" (confirmed by ECHO {done.echoes})" if done.echoes > 1 else ""))
        return True

    def _take_held(self) -> list:
        held, self._held = self._held, []
        return held

    def _set_port_baud(self, baud: int) -> None:
        self.serial.baudrate = baud  # pyserial rewrites the termios: the low-latency request again after it
        if self.low_latency:
            request_low_latency(self.serial)
        self.link_baud = baud

    def _watch_rate(self) -> None:
        """At a rate other than 115200: bytes for FALLBACK_S of which none made an intact frame mean the sphere went
        back (a reset, a lost lease) and talks at another rate: so does the port. Silence is not that (a stalled
        link keeps its rate; link_timeout_s judges it)."""
        now = time.monotonic()
        s = self.stream.stats
        if s.frames_ok != self._good_frames:
            self._good_frames, self._good_at, self._bytes_at_good = s.frames_ok, now, s.bytes_in
        elif now - self._good_at > FALLBACK_S and s.bytes_in - self._bytes_at_good >= GARBAGE_BYTES:
            self.log(f"{self.port_name}: nothing intact at {self.link_baud} baud for {FALLBACK_S:g} s: back to "
                     f"{DEFAULT_BAUD}", logging.WARNING)
            self._set_port_baud(DEFAULT_BAUD)
            self.link.send_delimiter()  # ends what the sphere took in of ours at the other rate
            self.clock.restart(DEFAULT_BAUD)
            self._good_at, self._bytes_at_good = now, s.bytes_in
            self._heard_at_default = s.frames_ok  # once the sphere is heard at 115200, up again

    def _batch(self):
        batch = super()._batch()
        if self.link is None:
            return batch
        self._fresh = batch  # what _after_batch notes: the packets read, not those held during a switch
        if not batch and self.link_baud != DEFAULT_BAUD:
            self._watch_rate()  # bytes that make no frame: a sphere at another rate (a batch's are in _after_batch)
        if self._switch_again:  # a restart or a fall-back seen in the last batch (_after_batch)
            self._switch_again = False
            self._switch_baud(self.port_name)
            batch = batch + self._take_held()
        return batch

    def _after_batch(self, batch) -> None:
        """The link's bookkeeping, once the daemon has handled the batch (its pointer move is out): the rate's
        watch, the device clock (sample ages, ECHO round trips) and a restarted sphere's switch to the faster rate,
        which the next read then makes."""
        if self.link is None:
            return
        fresh, self._fresh = self._fresh, ()
        if self.link_baud != DEFAULT_BAUD:
            self._watch_rate()
        arrival = self.arrival_ns / 1e9  # perf_counter: the clock the round trips are timed with
        for dp in fresh:
            p = dp.packet
            if p.TYPE == RawSample.TYPE:
                self.clock.note_sample(dp.t_us)
                if self.clock.ready:
                    said = self.ages.add(arrival - self.clock.host_s(dp.t_us), arrival)
                    if said:
                        self.log(said, logging.WARNING if self.ages.growing else logging.INFO)
            elif p.TYPE == Reply.TYPE and p.cmd_type == Echo.TYPE:
                self.clock.reply(p, arrival)
            elif p.TYPE == Hello.TYPE and p.seq == 0:
                self.clock.restart()  # the sphere restarted, its clock too; and at 115200 (spec §5.4)
                self._switch_again = bool(self.baud_switch) and self.link_baud == DEFAULT_BAUD
        if self._heard_at_default is not None and self.stream.stats.frames_ok > self._heard_at_default + 2:
            self._heard_at_default = None
            self._switch_again = bool(self.baud_switch) and self.link_baud == DEFAULT_BAUD
        hello = self.stream.hello
        if hello is not None and hello.protocol_version >= 3:
            now = time.perf_counter()
            if now >= self._next_echo:
                self._next_echo = now + ECHO_EVERY_S
                self.clock.echo(lambda: self.link.send(Echo()), time.perf_counter)

    def sample_age_ms(self) -> tuple[float, float] | None:
        """(median, p95) of the last 2 s of RAW_SAMPLE ages on arrival, ms; None before the clock is known."""
        return self.ages.percentiles_ms()

    def _lose(self, why: str) -> None:
        super()._lose(f"on {self.port_name}: {why}")

    def _disconnect(self) -> None:
        ser, self.serial, self.link = self.serial, None, None
        if ser is not None:
            ser.close()


def serial_timing(s, cfg=None) -> dict:
    """The link keys of ``[source.serial]`` (rates, low latency, timing) and ``[source]`` reconnect_interval_s as
    SerialSource's keyword arguments."""
    return dict(baud=s.baud, hello_timeout_s=s.hello_timeout_s, discovery_timeout_s=s.discovery_timeout_s,
                link_timeout_s=s.link_timeout_s, reconnect_interval_s=reconnect_interval_s(cfg),
                low_latency=s.low_latency, baud_switch=s.baud_switch)
