"""Where frames come from: a serial port (USB or Bluetooth SPP), a HID receiver, a capture file, the
virtual board, or a scripted sphere.

A source is iterated for *batches*: each is a list of :class:`sphere.capture.DecodedPacket` (device
time unwrapped), possibly empty (a tick while nothing arrives, so the daemon can keep time), and
``source.arrival_ns`` holds ``time.perf_counter_ns()`` taken right after the bytes of that batch
were read — the start of the latency the benchmark measures. ``source.stats`` are the decoder's
counters, ``source.state`` a short text for the status line, and ``source.generation`` grows by one
at every new connection (the daemon then restarts its time base).
"""

from __future__ import annotations

import glob
import os
import re
import select
import subprocess
import sys
import threading
import time
from typing import Callable, Iterator

import serial

from sphere.capture import CaptureError, CaptureFile, DecodedPacket
from sphere.protocol import PROTOCOL_VERSION, FrameDecoder, GetHello, Hello, TimeUnwrapper, encode_frame
from sphere.serial_link import PortError, open_port


class SourceError(Exception):
    """A source that cannot go on; the message says what to do. The daemon stops with it."""


def version_problem(hello: Hello) -> str | None:
    """None if we speak the device's protocol, else what to update (spec §4.1, version handshake)."""
    v = hello.protocol_version
    if v == PROTOCOL_VERSION:
        return None
    side = "the host software (pip install -U marg-sphere)" if v > PROTOCOL_VERSION else "the sphere's firmware"
    return (f"the sphere speaks protocol version {v}, this sphere-mouse speaks version {PROTOCOL_VERSION}: "
            f"update {side}")


class _Decoding:
    """Bytes → DecodedPackets with unwrapped device time."""

    def __init__(self):
        self.decoder = FrameDecoder("device")
        self.unwrap = TimeUnwrapper()
        self.arrival_ns = 0
        self.generation = 0
        self.hello: Hello | None = None

    @property
    def stats(self):
        return self.decoder.stats

    def decode(self, data: bytes) -> list[DecodedPacket]:
        out = []
        unwrap = self.unwrap
        for p in self.decoder.feed(data):
            if p.TYPE == Hello.TYPE:
                if p.seq == 0:
                    unwrap.reset()
                self.hello = p
            t = getattr(p, "t_us", None)
            out.append(DecodedPacket(p, unwrap(t) if t is not None else None))
        return out


# ---- capture file ------------------------------------------------------------------------------


class ReplaySource(_Decoding):
    """A capture file, paced by its device times divided by ``speed`` (0 = as fast as possible).
    The iteration ends with the file."""

    def __init__(self, path, speed: float = 1.0, clock=time.perf_counter, sleep=time.sleep):
        super().__init__()
        try:
            self.capture = CaptureFile(path)
        except CaptureError as e:
            raise SourceError(str(e)) from None
        self.path = str(path)
        self.speed = float(speed)
        self.clock = clock
        self.sleep = sleep
        self.state = f"replay {os.path.basename(self.path)}" + (f" ×{speed:g}" if speed not in (0, 1) else "")
        self.generation = 1

    @property
    def stats(self):
        return self.capture.stats

    def __iter__(self) -> Iterator[list[DecodedPacket]]:
        t0_dev = None
        t0_wall = None
        for dp in self.capture.packets():
            p = dp.packet
            if p.TYPE == Hello.TYPE:
                self.hello = p
                problem = version_problem(p)
                if problem:
                    raise SourceError(f"{self.path}: {problem}")
            if self.speed > 0 and dp.t_us is not None:
                if t0_dev is None or dp.t_us < t0_dev:
                    t0_dev, t0_wall = dp.t_us, self.clock()
                wait = t0_wall + (dp.t_us - t0_dev) * 1e-6 / self.speed - self.clock()
                if wait > 0:
                    self.sleep(wait)
            self.arrival_ns = time.perf_counter_ns()
            yield [dp]
        self.state = f"replay {os.path.basename(self.path)}: ended"

    def close(self):
        pass


# ---- serial port -------------------------------------------------------------------------------


def expand_candidates(patterns) -> list[str]:
    out: list[str] = []
    for pattern in patterns:
        matches = sorted(glob.glob(pattern)) if any(c in pattern for c in "*?[") else [pattern]
        for m in matches:
            if os.path.exists(m) and m not in out:
                out.append(m)
    return out


class SerialSource(_Decoding):
    """The sphere on a serial port, found by its HELLO and reopened whenever the link is lost.

    ``port="auto"`` tries every path matching ``candidates``. Opening a USB Nano's port resets it
    through DTR (``reset_on_open``); its HELLO then follows the bootloader. If no HELLO comes within
    ``hello_timeout_s`` (a Bluetooth link does not reset the board), GET_HELLO is sent, again every
    ``hello_timeout_s``, until ``discovery_timeout_s``. A read error (unplug) or ``link_timeout_s``
    without a byte (a lost Bluetooth link) closes the port; the source then looks for the sphere again
    every ``reconnect_interval_s`` without ending.
    """

    def __init__(self, port: str = "auto", candidates=("/dev/sphere", "/dev/ttyUSB*", "/dev/ttyACM*", "/dev/rfcomm*"),
                 baud: int = 115200, reset_on_open: bool = True, hello_timeout_s: float = 0.5,
                 discovery_timeout_s: float = 3.0, link_timeout_s: float = 2.0, reconnect_interval_s: float = 1.0,
                 log: Callable[[str], None] | None = None, read_timeout_s: float = 0.02):
        super().__init__()
        self.port = port
        self.candidates = list(candidates)
        self.baud = baud
        self.reset_on_open = reset_on_open
        self.hello_timeout_s = hello_timeout_s
        self.discovery_timeout_s = discovery_timeout_s
        self.link_timeout_s = link_timeout_s
        self.reconnect_interval_s = reconnect_interval_s
        self.read_timeout_s = read_timeout_s
        self.log = log or (lambda msg: None)
        self.serial = None
        self.port_name = None
        self.state = "looking for the sphere"
        self.connects = 0
        self.losses = 0
        self._stop = False
        self._iterating = False
        self._tx_seq = 0
        self._warned: set[str] = set()

    # -- connecting --
    def _open(self, path: str):
        # DTR held low unless reset_on_open; the kernel may still pulse it (see host/docs/sphere-mouse.md)
        ser = open_port(path, self.baud, self.read_timeout_s, reset_on_open=self.reset_on_open, write_timeout_s=0.5)
        try:
            ser.reset_input_buffer()  # bytes from before the (DTR) reset belong to an older session
        except Exception:
            pass
        return ser

    def send(self, packet) -> None:
        if self.serial is not None:
            self.serial.write(encode_frame(packet, self._tx_seq))
            self._tx_seq = (self._tx_seq + 1) & 0xFF

    def _try_port(self, path: str):
        """Open ``path`` and wait for a HELLO: (serial, packets after and including the HELLO) or None."""
        try:
            ser = self._open(path)
        except PortError as e:
            if path not in self._warned:
                self._warned.add(path)
                self.log(str(e))
            return None
        self._warned.discard(path)
        self.serial = ser
        decoder = FrameDecoder("device")
        start = time.monotonic()
        next_ask = start + self.hello_timeout_s
        found: list = []
        try:
            while time.monotonic() - start < self.discovery_timeout_s and not self._stop:
                data = ser.read(ser.in_waiting or 1)
                if data:
                    arrival = time.perf_counter_ns()
                    packets = decoder.feed(data)
                    for i, p in enumerate(packets):
                        if p.TYPE == Hello.TYPE:
                            problem = version_problem(p)
                            if problem:
                                ser.close()
                                raise SourceError(f"{path}: {problem}")
                            found = packets[i:]
                            break
                    if found:
                        self.arrival_ns = arrival
                        return ser, found
                if time.monotonic() >= next_ask:
                    next_ask += self.hello_timeout_s
                    self.send(GetHello())
        except (serial.SerialException, OSError):
            pass
        ser.close()
        self.serial = None
        return None

    def _connect(self) -> list[DecodedPacket] | None:
        paths = [self.port] if self.port != "auto" else expand_candidates(self.candidates)
        if not paths:
            self.state = f"looking for the sphere (no port matches {' '.join(self.candidates)})"
        elif self.port != "auto" and not os.path.exists(self.port):
            self.state = f"waiting for {self.port} to appear"
        else:
            self.state = f"looking for the sphere (no HELLO from {', '.join(paths)})"
        for path in paths:
            got = self._try_port(path)
            if got is None:
                continue
            ser, packets = got
            self.serial = ser
            self.port_name = path
            self.connects += 1
            self.generation += 1
            self.unwrap.reset()
            self.decoder.feed(b"\x00")  # end any frame cut off by the previous link
            self.state = f"{path}"
            self.log(f"sphere found on {path}" + (" (reconnected)" if self.connects > 1 else ""))
            out = []
            for p in packets:
                if p.TYPE == Hello.TYPE:
                    if p.seq == 0:
                        self.unwrap.reset()
                    self.hello = p
                t = getattr(p, "t_us", None)
                out.append(DecodedPacket(p, self.unwrap(t) if t is not None else None))
            self.decoder.stats.frames_ok += len(packets)
            return out
        return None

    def _read(self, ser) -> bytes:
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
            raise OSError("device reports readiness to read but returned no data (unplugged?)")
        return data

    def _lose(self, why: str) -> None:
        ser, self.serial = self.serial, None
        try:
            ser.close()
        except Exception:
            pass
        self.state = "looking for the sphere (link lost)"
        self.log(f"lost the sphere on {self.port_name}: {why}; looking for it again")
        self.losses += 1

    def __iter__(self) -> Iterator[list[DecodedPacket]]:
        self._iterating = True
        try:
            yield from self._batches()
        finally:
            self._iterating = False
            self._close_port()

    def _batches(self) -> Iterator[list[DecodedPacket]]:

        last_try = -1e9
        last_byte = time.monotonic()
        while not self._stop:
            if self.serial is None:
                now = time.monotonic()
                if now - last_try < self.reconnect_interval_s:
                    time.sleep(min(0.05, self.reconnect_interval_s))
                    yield []
                    continue
                last_try = now
                packets = self._connect()
                if packets is None:
                    yield []
                    continue
                last_byte = time.monotonic()
                yield packets
                continue
            try:
                data = self._read(self.serial)
            except (serial.SerialException, OSError) as e:
                self._lose(f"read failed ({e})")
                yield []
                continue
            if data:
                self.arrival_ns = time.perf_counter_ns()
                last_byte = time.monotonic()
                yield self.decode(data)
            else:
                if time.monotonic() - last_byte > self.link_timeout_s:
                    self._lose(f"no data for {self.link_timeout_s:g} s")
                yield []

    def _close_port(self):
        if self.serial is not None:
            try:
                self.serial.close()
            except Exception:
                pass
            self.serial = None

    def close(self):
        """Stop: the reading loop closes the port when it sees this (safe from another thread or a signal)."""
        self._stop = True
        if not self._iterating:
            self._close_port()


# ---- HID ---------------------------------------------------------------------------------------


def hid_report_bytes(report) -> bytes:
    """The stream bytes in one HID input report: the first byte (the report ID, CP2110-style) is the
    count of valid bytes that follow."""
    if not report:
        return b""
    n = report[0]
    return bytes(report[1 : 1 + n])


class HidSource(_Decoding):
    """A receiver that delivers the serial byte stream in HID input reports (via hidapi), reopened
    when it is unplugged."""

    def __init__(self, vendor_id: int = 0, product_id: int = 0, product: str = "sphere",
                 reconnect_interval_s: float = 1.0, log=None, hid_module=None):
        super().__init__()
        self.vendor_id, self.product_id, self.product = vendor_id, product_id, product.lower()
        self.reconnect_interval_s = reconnect_interval_s
        self.log = log or (lambda msg: None)
        if hid_module is None:
            try:
                import hid as hid_module
            except ImportError:
                raise SourceError("the HID source needs hidapi: pip install hidapi") from None
        self.hid = hid_module
        self.device = None
        self.state = "looking for a HID receiver"
        self._stop = False
        self._iterating = False

    def _find(self):
        for info in self.hid.enumerate(self.vendor_id, self.product_id):
            if self.vendor_id or self.product_id or self.product in (info.get("product_string") or "").lower():
                return info
        return None

    def __iter__(self):
        self._iterating = True
        try:
            yield from self._batches()
        finally:
            self._iterating = False
            self._close_device()

    def _close_device(self):
        if self.device is not None:
            try:
                self.device.close()
            except Exception:
                pass
            self.device = None

    def _batches(self):
        while not self._stop:
            if self.device is None:
                info = self._find()
                if info is None:
                    time.sleep(self.reconnect_interval_s)
                    yield []
                    continue
                dev = self.hid.device()
                try:
                    dev.open_path(info["path"])
                except (OSError, IOError) as e:
                    self.log(f"cannot open HID device {info.get('product_string')}: {e} (see the udev rule in "
                             "host/packaging/)")
                    time.sleep(self.reconnect_interval_s)
                    yield []
                    continue
                self.device = dev
                self.generation += 1
                self.unwrap.reset()
                self.decoder.feed(b"\x00")
                self.state = f"HID {info.get('product_string') or info['path']}"
                self.log(f"receiver found: {self.state}")
            try:
                report = self.device.read(64, 50)
            except (OSError, IOError, ValueError) as e:
                self.log(f"lost the HID receiver: {e}; looking for it again")
                try:
                    self.device.close()
                except Exception:
                    pass
                self.device = None
                self.state = "looking for a HID receiver (lost)"
                yield []
                continue
            data = hid_report_bytes(report)
            if data:
                self.arrival_ns = time.perf_counter_ns()
                yield self.decode(data)
            else:
                yield []

    def close(self):
        """Stop: the reading loop closes the device when it sees this (safe from another thread or a signal)."""
        self._stop = True
        if not self._iterating:
            self._close_device()


# ---- scripted sphere and the virtual board -----------------------------------------------------


class ScriptedSource(_Decoding):
    """The built-in scripted sphere (sphere.daemon.synthetic), paced in real time, looping."""

    def __init__(self, script=None, speed: float = 1.0, loop: bool = True):
        super().__init__()
        from sphere.daemon import synthetic

        self.script = script or synthetic.DEMO_SCRIPT
        self.speed = speed
        self.loop = loop
        self.state = "scripted sphere (built in)"
        self._stop = False

    def __iter__(self):
        from sphere.daemon.synthetic import ScriptedSphere

        sphere = ScriptedSphere()
        t0, hello = sphere.hello()
        start = time.perf_counter()
        self.generation = 1
        self.arrival_ns = time.perf_counter_ns()
        yield self.decode(hello)
        while not self._stop:
            for sample in sphere.iter_steps(self.script):
                if self._stop:
                    return
                t_us = sample[0][0]
                if self.speed > 0:
                    wait = start + (t_us - t0) * 1e-6 / self.speed - time.perf_counter()
                    if wait > 0:
                        time.sleep(wait)
                self.arrival_ns = time.perf_counter_ns()
                yield self.decode(b"".join(f for _, f in sample))
            if not self.loop:
                return

    def close(self):
        self._stop = True


def simulator_available() -> bool:
    try:
        import importlib.util

        return importlib.util.find_spec("sphere.commands.sim") is not None
    except Exception:
        return False


PTY_RE = re.compile(r"(/dev/pts/\d+)")
DEFAULT_SIM_TRACE = "synthetic:rotation:15"


def simulator_command(trace: str = "", seconds: float = 600.0) -> list[str]:
    """How --simulate starts the virtual board: ``sphere sim --trace TRACE --pty --seconds S``."""
    return [sys.executable, "-m", "sphere.cli", "sim", "--trace", trace or DEFAULT_SIM_TRACE, "--pty",
            "--seconds", f"{seconds:g}"]


def start_simulator(trace: str = "", log=None, timeout_s: float = 120.0, seconds: float = 600.0):
    """Start the virtual board; returns (process, pty path). The board prints ``... UART on /dev/pts/N``;
    the rest of its output is read and dropped so that it never blocks on a full pipe. The first start
    may build the firmware and the board (make), hence the long timeout."""
    cmd = simulator_command(trace, seconds)
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + timeout_s
    tail: list[str] = []
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            if proc.poll() is not None:
                break
            continue
        tail = (tail + [line.rstrip()])[-8:]
        m = PTY_RE.search(line)
        if m and os.path.exists(m.group(1)):
            threading.Thread(target=lambda: [None for _ in proc.stdout], daemon=True).start()
            return proc, m.group(1)
    if proc.poll() is None:
        proc.kill()
    raise SourceError(f"`sphere {' '.join(cmd[3:])}` did not open its pty: " + " | ".join(tail[-4:]))


class SimulatorSource(SerialSource):
    """The virtual board's UART through the pty that `sphere sim --pty` exposes."""

    def __init__(self, trace: str = "", log=None, seconds: float = 600.0, **serial_kwargs):
        self.proc, path = start_simulator(trace, log, seconds=seconds)
        serial_kwargs.setdefault("reset_on_open", False)
        super().__init__(port=path, log=log, **serial_kwargs)
        self.state = f"simulated sphere on {path}"

    def _lose(self, why: str) -> None:
        # the pty closes when the board's simulated seconds are over and `sphere sim` exits right after:
        # that is the end of the run, not a lost link to look for again
        try:
            self.proc.wait(2.0)
        except subprocess.TimeoutExpired:
            super()._lose(why)
            return
        self._close_port()

    def _batches(self):
        for batch in super()._batches():
            yield batch
            if self.serial is None and self.proc.poll() is not None:
                rc = self.proc.returncode
                self.log("the simulated sphere's run is over" if rc == 0 else
                         f"the simulated sphere stopped (exit status {rc})")
                return

    def close(self):
        super().close()
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()

