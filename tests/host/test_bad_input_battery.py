"""The bad-input battery of issue 14: one table, one row per bad input to a user-facing entry point
(`sphere-mouse` flags, settings and config files; every `sphere` subcommand; capture and replay files; ports).

Each row: the program (``mouse`` = sphere-mouse, ``sphere`` = the sphere CLI), its command line, the files
and port it meets, the exit status the docs promise (2: a bad flag, file, setting or port named by the user;
1: a device or disk that failed during the run; 0: input that is odd but valid) and a fragment of the one
line that says what was wrong. Asserted for every row: no "Traceback" on stderr, that status, that fragment
on stderr in a short message (a few lines at most), and an end within the row's time limit.

The rows run in process, each in a forked child of the test (imports done once, so the battery is fast; a
child that hangs is killed and the row fails), with its own temporary folder and config home (parallel-safe).
Rows that need a whole program's life (signals, a port that vanishes) have their own tests in
test_bad_input.py.
"""

from __future__ import annotations

import os
import select
import signal
import sys
import threading
import time
import traceback
import tty
from dataclasses import dataclass, field

import pytest

from sphere.daemon.scripted_sphere import script_bytes

pytestmark = pytest.mark.slow  # a command per case, many in subprocesses (./scripts/test --quick leaves it out)

GOOD = script_bytes([("still", 0.3), ("turn", (0, 0, 1), 10.0, 0.3)])
GARBAGE = bytes((i * 167 + 13) % 256 for i in range(4000))  # no frame delimiter pattern, no valid CRC
UTF16 = b"\xff\xfe[\x00p\x00o\x00i\x00n\x00t\x00e\x00r\x00]\x00"


@dataclass
class Row:
    prog: str  # "mouse" | "sphere"
    argv: list  # "{tmp}" is the row's folder, "{port}" its pty
    code: int
    words: str
    files: dict = field(default_factory=dict)  # name -> bytes | "dir" | "fifo" | "loop"
    port: str | None = None  # None | "silent" | "garbage" (streams a capture) | "noise" (streams bytes that are
    # no frame) | "vanish" (streams for 0.5 s, then is unplugged)
    stdout: str | None = None  # where stdout goes (/dev/full: a full disk); None: a file the test reads
    timeout: float = 20.0
    broad: bool = False  # needs the BROAD trials (skips, saying so, where they are absent)

    @property
    def id(self):
        files = ",".join(f"{k}={v if isinstance(v, str) else v[:12]!r}" for k, v in self.files.items())
        return (f"{self.prog} " + " ".join(str(a) for a in self.argv)[:90] + (f" [{files}]" if files else "")
                + (f" >{self.stdout}" if self.stdout else ""))


def M(argv, code, words, **kw):
    return Row("mouse", ["--no-stream", "--backend", "log", "--quiet", *argv], code, words, **kw)


def C(argv, code, words, **kw):  # sphere-mouse --check-config: the settings alone
    return M(["--check-config", *argv], code, words, **kw)


def S(argv, code, words, **kw):
    return Row("sphere", list(argv), code, words, **kw)


def F(text, code, words, extra=(), **kw):  # a config file's contents
    data = text.encode() if isinstance(text, str) else text
    return C(["--config", "{tmp}/c.toml", *extra], code, words, files={"c.toml": data, **kw.pop("files", {})}, **kw)


CAP = {"good.cap": GOOD}
ROWS = [
    # ---- sphere-mouse flags ----
    C(["--baud", "fast"], 2, "invalid int value"),
    C(["--baud", "-1"], 2, "baud"),
    C(["--baud", "0"], 2, "baud"),
    C(["--baud", "1000000000000"], 2, "baud"),
    C(["--speed", "nan"], 2, "speed"),
    C(["--speed", "inf"], 2, "speed"),
    C(["--speed", "-1"], 2, "speed"),
    C(["--speed", "x"], 2, "invalid float value"),
    C(["--sensitivity", "nan"], 2, "finite"),
    C(["--sensitivity", "inf"], 2, "finite"),
    C(["--sensitivity", "-40"], 2, "slow_deg_per_width"),
    C(["--sensitivity", "0"], 2, "slow_deg_per_width"),
    C(["--sensitivity", "1e-306"], 2, "slow_deg_per_width"),
    C(["--sensitivity", "1e308"], 2, "slow_deg_per_width"),
    C(["--stream-port", "-1"], 2, "TCP port"),
    C(["--stream-port", "70000"], 2, "TCP port"),
    C(["--stream-port", "http"], 2, "invalid int value"),
    C(["--mode", "sideways"], 2, "invalid choice"),
    C(["--backend", "wayland9"], 2, "invalid choice"),
    C(["--port", "/dev/ttyUSB0", "--replay", "x.cap"], 2, "not allowed with"),
    C(["--nosuch-flag"], 2, "unrecognized arguments"),
    C(["--set", "pointer"], 2, "SECTION.KEY=VALUE"),
    C(["--set", "=1"], 2, "SECTION.KEY=VALUE"),
    C(["--set", "nosuch.key=1"], 2, "unknown section"),
    C(["--set", "pointer.nosuch=1"], 2, "unknown key"),
    C(["--set", "pointer.axes=sideways"], 2, "must be one of"),
    C(["--set", "pointer.slow_deg_per_width=fast"], 2, "slow_deg_per_width"),
    C(["--set", "pointer.slow_deg_per_width=nan"], 2, "finite"),
    C(["--set", "pointer.fast_deg_per_width=-inf"], 2, "finite"),
    C(["--set", "tilt.max_speed_px_s=inf"], 2, "finite"),
    C(["--set", "tilt.exponent=-1"], 2, "exponent"),
    C(["--set", f"output.screen_width_px={2 ** 70}"], 2, "too large"),
    C(["--set", "output.screen_width_px=-1"], 2, "screen_width_px"),
    C(["--set", "output.screen_width_px=1.5"], 2, "screen_width_px"),
    C(["--set", "pointer.invert_x=maybe"], 2, "invert_x"),
    C(["--set", "pointer.hold_band_dps=-0.5"], 2, "hold_band_dps"),
    C(["--set", "pointer.hold_slow_window_s=0"], 2, "hold_slow_window_s"),
    C(["--set", "pointer.hold_pass_dps=-4"], 2, "hold_pass_dps"),
    C(["--set", "pointer.hold_pass_spread=lots"], 2, "hold_pass_spread"),
    C(["--set", "pointer.step_at_px=0.3"], 2, "step_at_px"),
    C(["--set", "pointer.gyro_lowpass_hz=-42"], 2, "gyro_lowpass_hz"),
    C(["--set", "priority.realtime=100"], 2, "realtime"),
    C(["--set", "priority.realtime=2.5"], 2, "realtime"),
    C(["--set", "priority.nice=5"], 2, "nice"),
    C(["--set", "priority.runaway_ms=0"], 2, "runaway_ms"),
    C(["--set", "priority.enabled=sometimes"], 2, "enabled"),
    C(["--set", 'mode.cycle=["pointer", "sideways"]'], 2, "sideways"),
    C(["--set", "mode.start=sideways"], 2, "must be one of"),
    C(["--set", "events.single_tap=explode"], 2, "must be one of"),
    C(["--set", "events.single_tap_wait_ms=-5"], 2, "single_tap_wait_ms"),
    C(["--set", "freeze.tap_after_ms=-5"], 2, "tap_after_ms"),
    C(["--set", "gyro.still_dps=0"], 2, "still_dps"),
    C(["--set", "gyro.still_time_s=inf"], 2, "finite"),
    C(["--set", "orientation.filter=kalman9"], 2, "filter"),
    C(["--set", "orientation.beta=-1"], 2, "beta"),
    C(["--set", "outputs.page.rate_hz=0"], 2, "rate_hz"),
    C(["--set", "outputs.page.max_clients=0"], 2, "max_clients"),
    C(["--set", "status.interval_s=0"], 2, "interval_s"),
    C(["--set", 'source.serial.usb_ids=["xyz"]'], 2, "VID:PID"),
    C(["--set", "source.discovery_timeout_s=1e300"], 2, "discovery_timeout_s"),
    C(["--set", "source.reconnect_interval_s=-1"], 2, "reconnect_interval_s"),
    C(["--set", 'source.kind="camera2"'], 2, "must be one of"),
    C(["--set", "source.serial.candidates=5"], 2, "candidates"),
    C(["--set", "pointer.smoothing=wobble"], 2, "must be one of"),
    C(["--set", "stream.smoothing=wobble"], 2, "must be one of"),
    C(["--set", "smoothing.tremor.nosuch=1"], 2, "unknown key"),
    C(["--set", "outputs.osc.port=70000"], 2, "port"),
    C(["--set", "outputs.opentrack.rate_hz=-1"], 2, "rate_hz"),
    C(["--set", "outputs.gamepad.full_tilt_deg=0"], 2, "full_tilt_deg"),
    C(["--set", "camera.hue_deg=nan"], 2, "finite"),
    C(["--udev-rule", "/dev/null"], 2, "not a USB serial port"),
    # a flag of another source than the one that runs: it would do nothing (sphere-mouse --trace synthetic:tour
    # looked for a real sphere, without a word)
    C(["--trace", "synthetic:tour"], 2, "--trace synthetic:tour: the motion the simulated sphere plays, but the source "
                                        "is serial: use it with --simulate"),
    C(["--replay", "x.cap", "--trace", "synthetic:tour"], 2, "but the source is replay: use it with --simulate"),
    C(["--speed", "4"], 2, "--speed 4: the pace of a replay, but the source is serial: use it with --replay FILE"),
    C(["--simulate", "--speed", "0"], 2, "but the source is simulate: use it with --replay FILE"),
    C(["--speed", "4", "--set", "source.replay.file=x.cap"], 0, "config OK"),  # kind auto: a replay
    # ---- sphere-mouse config file ----
    F(UTF16, 2, "not a UTF-8"),
    F(bytes(range(256)) * 4, 2, "not a UTF-8"),
    F(b"\x00\x00\x00\x00", 2, "not valid TOML"),
    F("[pointer\n", 2, "not valid TOML"),
    F("[pointer]\n[pointer]\n", 2, "not valid TOML"),
    F("[pointer]\naxes = \"local\"\naxes = \"world\"\n", 2, "not valid TOML"),
    F("[pointr]\n", 2, "unknown section"),
    F("[pointer]\nslow_deg = 3\n", 2, "unknown key"),
    F("[pointer]\nslow_deg_per_width = \"fast\"\n", 2, "slow_deg_per_width"),
    F("[pointer]\nslow_deg_per_width = nan\n", 2, "finite"),
    F("[pointer]\nslow_deg_per_width = inf\n", 2, "finite"),
    F("[pointer]\nslow_deg_per_width = -40\n", 2, "slow_deg_per_width"),
    F("[output]\nscreen_width_px = 99999999999999999999999\n", 2, "too large"),
    F("[pointer]\naxes = \"diagonal\"\n", 2, "must be one of"),
    F("pointer = 5\n", 2, "pointer"),
    F("speed = 1\n", 2, "speed"),
    F("[source]\nkind = \"replay\"\n", 2, "needs a capture file"),
    # the line that sets the key, as file:LINE (tomllib gives none for a value it parsed)
    F("[pointer]\nslow_deg_per_width = 30\n\n[outputs.osc]\n# OSC\nport = 70000  # too far\n", 2,
      "c.toml:6: [outputs.osc] port = 70000: must be between 1 and 65535"),
    F("[outputs]\nosc.enabled = \"yes\"\n", 2, "c.toml:2: [outputs.osc] enabled = 'yes': must be true or false"),
    F('outputs.osc.enabeld = true\n', 2, "c.toml:1: unknown key [outputs.osc] enabeld (did you mean 'enabled'?)"),
    F('[pointer]\n\n[ "outputs" . "oscc" ]\nport = 1\n', 2, "c.toml:3: unknown section [outputs.oscc]"),
    F("[outputs]\nosc = {port = 0}\n", 2, "c.toml: [outputs.osc] port = 0"),  # an inline table: no line
    F("", 0, "config OK"),  # empty: all defaults (valid)
    F(b"\xef\xbb\xbf[pointer]\n", 2, "TOML"),  # a UTF-8 byte-order mark
    C(["--config", "{tmp}"], 2, "is a folder"),
    C(["--config", "{tmp}/nope.toml"], 2, "no such config file"),
    C(["--config", "/proc/self/mem"], 2, "cannot read"),
    C(["--config", "/dev/zero"], 2, "not a regular file"),
    C(["--config", "{tmp}/fifo"], 2, "not a regular file", files={"fifo": "fifo"}),
    C(["--config", "{tmp}/loop"], 2, "loop", files={"loop": "loop"}),
    C([], 2, "not a UTF-8", files={"xdg/sphere-mouse/config.toml": UTF16}),  # the default file
    # ---- sphere-mouse sources ----
    M(["--replay", "/dev/zero"], 2, "is a device"),
    M(["--replay", "{tmp}"], 2, "is a folder"),
    M(["--replay", "{tmp}/nope.cap"], 2, "no such capture"),
    M(["--replay", "{tmp}/fifo"], 2, "not a regular file", files={"fifo": "fifo"}),
    M(["--replay", "/proc/self/mem"], 2, "cannot read"),
    M(["--replay", "{tmp}/empty.cap"], 2, "is empty", files={"empty.cap": b""}),
    M(["--replay", "{tmp}/g.cap", "--speed", "0"], 2, "no valid frame", files={"g.cap": GARBAGE}),
    M(["--replay", "{tmp}/t.cap", "--speed", "0"], 0, "stopped", files={"t.cap": GOOD[:len(GOOD) // 2 + 7]}),
    M(["--port", "/dev/ttyNOPE7", "--set", "source.reconnect_interval_s=0.05"], 0, "waiting for it"),  # then SIGTERM
    M(["--port", "{tmp}"], 2, "not a serial port"),
    M(["--port", "{tmp}/plain"], 2, "not a serial port", files={"plain": b"x"}),
    M(["--port", "/dev/null"], 2, "not a serial port"),
    # the terminal itself: it was set raw at 1 Mbaud and written GET_HELLO frames, and stayed raw after the exit
    M(["--port", "/dev/tty"], 2, "/dev/tty is the terminal this runs in, not a serial port"),
    M(["--port", "/dev/console"], 2, "is the system console, not a serial port"),
    S(["monitor", "--port", "/dev/tty", "--seconds", "1"], 2, "not a serial port"),
    M(["--simulate", "--trace", "{tmp}/nope.mat"], 2, "nope.mat"),
    # an output that cannot start says what to set, and the pointer runs on
    M(["--replay", "{tmp}/good.cap", "--speed", "0", "--set", "outputs.dsu.enabled=true", "--set",
       "outputs.dsu.host=192.0.2.1"], 0, "set [outputs.dsu] host to an address of this machine", files=CAP),
    Row("mouse", ["--backend", "log", "--quiet", "--replay", "{tmp}/good.cap", "--speed", "0", "--set",
                  "outputs.page.host=nonexistent.invalid"], 0, "set [outputs.page] host to an address", files=CAP),
    # ---- sphere ----
    S([], 2, "usage"),
    S(["frobnicate"], 2, "invalid choice"),
    # decode
    S(["decode", "/dev/zero"], 2, "is a device"),
    S(["decode", "{tmp}"], 2, "is a folder"),
    S(["decode", "{tmp}/nope.cap"], 2, "no such capture"),
    S(["decode", "/proc/self/mem"], 2, "cannot read"),
    S(["decode", "{tmp}/empty.cap"], 1, "is empty", files={"empty.cap": b""}),
    S(["decode", "{tmp}/g.cap"], 1, "no valid frame", files={"g.cap": GARBAGE}),
    S(["decode", "{tmp}/t.cap"], 0, "", files={"t.cap": GOOD[:len(GOOD) // 2 + 7]}),
    S(["decode", "{tmp}/good.cap", "--type", "nosuch"], 2, "nosuch", files=CAP),
    S(["decode", "{tmp}/good.cap", "--type", "get_hello"], 2, "not a packet type the sphere sends", files=CAP),
    S(["decode"], 2, "required"),
    # capture
    S(["capture", "--port", "{port}", "--out", "{tmp}"], 2, "is a folder", port="garbage"),
    S(["capture", "--port", "{port}", "--out", "{tmp}/x.cap", "--seconds", "-5"], 2, "seconds", port="garbage"),
    S(["capture", "--port", "{port}", "--out", "{tmp}/x.cap", "--seconds", "nan"], 2, "seconds", port="garbage"),
    S(["capture", "--port", "{port}", "--out", "{tmp}/x.cap", "--baud", "1000000000000"], 2, "baud", port="garbage"),
    S(["capture", "--port", "{port}", "--out", "{tmp}/x.cap", "--baud", "0"], 2, "baud", port="garbage"),
    S(["capture", "--port", "{port}", "--out", "/dev/full", "--seconds", "5", "--quiet"], 1, "no space left",
      port="garbage"),
    S(["capture", "--port", "{port}", "--out", "{tmp}/afile/x.cap"], 2, "cannot be written", port="garbage",
      files={"afile": b"x"}),
    S(["capture", "--port", "/dev/ttyNOPE9", "--out", "{tmp}/x.cap"], 2, "plugged in"),
    S(["capture", "--port", "{tmp}", "--out", "{tmp}/x.cap"], 2, "not a serial port"),
    S(["capture", "--port", "/dev/null", "--out", "{tmp}/x.cap"], 2, "not a serial port"),
    S(["capture", "--port", "{port}", "--camera", "{tmp}/nope.avi", "--out", "{tmp}/s"], 2, "cannot open video file",
      port="garbage"),
    S(["capture", "--port", "{port}", "--camera", "{tmp}/v.avi", "--out", "{tmp}/s"], 2, "cannot open video file",
      port="garbage", files={"v.avi": b"not a video"}),
    M(["--replay", "{tmp}/s", "--speed", "0"], 2, "not a sphere-session version 1",
      files={"s": "dir", "s/session.json": b'{"format": "other"}'}),
    M(["--replay", "{tmp}/s", "--speed", "0"], 2, "session.json cannot be read",
      files={"s": "dir", "s/session.json": b'{"format": '}),
    M(["--replay", "{tmp}/s", "--speed", "0"], 2, "serial.bin.rx.csv line 2",
      files={"s": "dir", "s/session.json": b'{"format": "sphere-session", "version": 1}', "s/serial.bin": b"x",
             "s/serial.bin.rx.csv": b"byte_offset,host_time_s\nx,y\n", "s/video.csv": b"frame,host_time_s\n"}),
    M(["--replay", "{tmp}/s", "--speed", "0"], 2, "session's video",
      files={"s": "dir", "s/session.json": b'{"format": "sphere-session", "version": 1}', "s/serial.bin": GOOD,
             "s/serial.bin.rx.csv": b"byte_offset,host_time_s\n0,0.0\n", "s/video.csv": b"frame,host_time_s\n"}),
    S(["capture", "--out", "{tmp}/x.cap"], 2, "required"),
    S(["capture", "--port", "{port}", "--out", "{tmp}/x.cap", "--seconds", "1"], 1, "nothing arrived", port="silent"),
    S(["capture", "--port", "{port}", "--out", "{tmp}/x.cap", "--seconds", "1", "--quiet"], 1, "was a sphere frame",
      port="noise"),
    S(["capture", "--port", "{port}", "--out", "{tmp}/x.cap", "--quiet"], 1, "went away", port="vanish"),
    # sim
    S(["sim", "--trace", "synthetic:still", "--seconds", "1e9"], 2, "at most 86400"),
    S(["sim", "--trace", "synthetic:still", "--seconds", "-5"], 2, "greater than 0"),
    S(["sim", "--trace", "synthetic:still", "--seconds", "nan"], 2, "greater than 0"),
    S(["sim", "--trace", "synthetic:still", "--seconds", "inf"], 2, "seconds"),
    S(["sim", "--trace", "synthetic:still", "--capture", "{tmp}"], 2, "is a folder"),
    S(["sim", "--trace", "synthetic:still", "--stats", "{tmp}"], 2, "is a folder"),
    S(["sim", "--trace", "synthetic:still", "--capture", "{tmp}/nodir/x.bin"], 2, "does not exist"),
    S(["sim", "--trace", "synthetic:wobble"], 2, "wobble"),
    S(["sim", "--trace", "{tmp}/nope.mat"], 2, "nope.mat"),
    S(["sim", "--trace", "{tmp}/g.bin"], 2, "g.bin", files={"g.bin": GARBAGE}),
    S(["sim", "--trace", "{tmp}/good.cap"], 2, "is not a .mat file", files=CAP),  # was "no BROAD trial named"
    S(["sim", "--trace", "{tmp}"], 2, "is a folder"),
    S(["sim", "--trace", "synthetic:still", "--accuracy", "--seconds", "2"], 2, "BROAD's optical reference"),  # ran, exit 0
    S(["sim", "--trace", "synthetic:still", "--nack", "gpu:1:2"], 2, "CHIP:T0:T1"),
    S(["sim", "--trace", "synthetic:still", "--nack", "adxl345:x"], 2, "CHIP:T0:T1"),
    S(["sim", "--trace", "synthetic:still", "--nack", "adxl345:2:1"], 2, "T0 < T1"),
    S(["sim", "--trace", "synthetic:still", "--hold", "-1"], 2, "hold"),
    S(["sim", "--trace", "synthetic:still", "--brownout", "nan"], 2, "brownout"),
    S(["sim", "--trace", "synthetic:still", "--power-off", "-1"], 2, "power-off"),
    S(["sim", "--trace", "synthetic:still", "--json", "{tmp}"], 2, "is a folder"),
    S(["sim", "--trace", "synthetic:still", "--firmware", "{tmp}"], 2, "no firmware image"),
    S(["sim", "--trace", "synthetic:still", "--stall", "2:1"], 2, "stall"),
    S(["sim", "--trace", "synthetic:still", "--bootloader", "optiboot5"], 2, "invalid choice"),
    S(["sim", "--trace", "synthetic:still", "--hang", "3:1"], 2, "hang"),
    S(["sim", "--trace", "synthetic:still", "--hang", "x"], 2, "hang"),
    S(["sim", "--trace", "synthetic:still", "--previous", "{tmp}/nope.elf:1"], 2, "nope.elf"),
    S(["sim", "--trace", "synthetic:still", "--previous", "{tmp}/p.elf:-1"], 2, "FILE.elf:T", files={"p.elf": GARBAGE}),
    S(["sim", "--trace", "synthetic:still", "--bus-pullup", "0"], 2, "bus-pullup"),
    S(["sim", "--trace", "synthetic:still", "--rate", "0"], 2, "rate"),
    S(["sim", "--trace", "synthetic:still", "--board", "breadboard"], 2, "invalid choice"),
    S(["sim", "--trace", "synthetic:still", "--firmware", "{tmp}/nope.elf"], 2, "nope.elf"),
    S(["sim", "--trace", "synthetic:still", "--firmware", "{tmp}/g.elf", "--no-build"], 2, "g.elf",
      files={"g.elf": GARBAGE}),
    S(["sim", "--trace", "synthetic:still", "--glitch", "-1"], 2, "glitch"),
    S(["sim", "--trace", "synthetic:still", "--send", "{tmp}/nope.txt"], 2, "nope.txt"),
    S(["sim", "--trace", "synthetic:still", "--send", "{tmp}/s.txt"], 2, "s.txt", files={"s.txt": b"zz top\n"}),
    S(["sim", "--trace", "synthetic:still", "--clock-ppm", "itg3200"], 2, "clock-ppm"),
    S(["sim", "--soak", "-1"], 2, "soak"),
    S(["sim", "--trace", "synthetic:still", "--seconds", "0.1"], 0, "sent no frame in 0.1 simulated s"),  # "frames 0"
    S(["sim", "--trace", "synthetic:still", "--hold", "1e99"], 2, "at most 86400"),  # was an OverflowError
    S(["sim", "--trace", "synthetic:still", "--glitch", "1e99"], 2, "at most 1000"),  # the board hung
    S(["sim", "--trace", "synthetic:still", "--clock-ppm", "itg3200:nan"], 2, "PPM from"),  # "Expecting value"
    S(["sim", "--trace", "synthetic:still", "--clock-ppm", "itg3200:-1e6"], 2, "PPM from"),  # a stopped clock
    S(["sim", "--trace", "synthetic:still", "--beta", "nan"], 2, "beta"),
    S(["sim", "--trace", "synthetic:still", "--start", "nan"], 2, "--start"),  # "cannot convert float NaN"
    S(["sim", "--trace", "synthetic:still", "--start", "-1"], 2, "at least 0"),  # "array of sample points is empty"
    S(["sim", "--trace", "synthetic:still", "--start", "soon"], 2, "or auto"),
    S(["sim", "--trace", "07", "--start", "5000", "--seconds", "1"], 2, "only 183.8 s long", broad=True),
    S(["sim", "--trace", "synthetic:still", "--jobs", "0"], 2, "jobs"),
    # calibrate (H2)
    S(["calibrate", "--port", "/dev/ttyNOPE9", "--timeout", "-1"], 2, "greater than 0"),
    S(["calibrate", "--capture", "{tmp}"], 2, "is a folder"),
    S(["calibrate", "--capture", "/dev/zero"], 2, "is a device"),
    S(["calibrate", "--capture", "{tmp}/nope.cap"], 2, "no such capture"),
    S(["calibrate", "--capture", "{tmp}/empty.cap"], 2, "empty", files={"empty.cap": b""}),
    S(["calibrate", "--capture", "{tmp}/g.cap"], 2, "0 raw samples", files={"g.cap": GARBAGE}),
    S(["calibrate", "--port", "/dev/ttyNOPE9", "--yes"], 2, "plugged in"),
    S(["calibrate"], 2, "required"),
    # an output that cannot be written: refused before a guided session starts (it was a traceback at its end)
    S(["calibrate", "--port", "{port}", "--yes", "--json", "{tmp}/nope/cal.json"], 2, "does not exist", port="silent"),
    S(["calibrate", "--port", "{port}", "--yes", "--json", "{tmp}"], 2, "is a folder", port="silent"),
    S(["calibrate", "--port", "{port}", "--yes", "--plot", "{tmp}/nope/m.png"], 2, "does not exist", port="silent"),
    S(["calibrate", "--port", "{port}", "--yes", "--save-capture", "{tmp}"], 2, "is a folder", port="silent"),
    S(["calibrate", "--port", "{port}", "--baud", "0"], 2, "baud", port="silent"),
    S(["calibrate", "--capture", "{tmp}/good.cap", "--json", "/dev/full"], 1, "cannot write /dev/full", files=CAP),
    # eval
    S(["eval", "--trials", "{tmp}/nope"], 2, "nope"),
    S(["eval", "--trials", "{tmp}/empty"], 2, "no BROAD", files={"empty": "dir"}),
    S(["eval", "--json", "{tmp}"], 2, "is a folder"),
    S(["eval", "--seconds", "-1"], 2, "seconds"),
    S(["eval", "--jobs", "0"], 2, "jobs"),
    # flash
    S(["flash", "--port", "/dev/ttyNOPE9", "--image", "{tmp}/g.hex"], 2, "not an Intel HEX", files={"g.hex": GARBAGE}),
    S(["flash", "--port", "/dev/ttyNOPE9", "--image", "{tmp}/nope.hex"], 2, "no such image file"),
    S(["flash", "--port", "/dev/ttyNOPE9", "--image", "{tmp}"], 2, "is a folder"),
    S(["flash", "--port", "/dev/ttyNOPE9", "--image", "{tmp}/x.elf"], 2, "Intel HEX", files={"x.elf": b"\x7fELF"}),
    S(["flash", "--port", "/dev/ttyNOPE9", "--avrdude", "{tmp}/nope-avrdude"], 2, "avrdude"),
    S(["flash", "--baud", "9600"], 2, "invalid choice"),
    # monitor
    S(["monitor", "--port", "/dev/ttyNOPE9", "--seconds", "1"], 2, "plugged in"),
    S(["monitor", "--port", "{port}", "--seconds", "-1"], 2, "seconds", port="silent"),
    S(["monitor", "--port", "{port}", "--refresh", "0"], 2, "refresh", port="silent"),
    S(["monitor", "--port", "{port}", "--events", "-1"], 2, "events", port="silent"),
    S(["monitor", "--port", "{port}", "--baud", "0"], 2, "baud", port="silent"),
    S(["monitor", "--port", "/dev/null", "--seconds", "1"], 2, "not a serial port"),
    S(["monitor", "--port", "{port}", "--seconds", "5"], 1, "went away", port="vanish"),
    S(["monitor", "--port", "{port}", "--seconds", "1"], 1, "nothing arrived", port="silent"),
    S(["monitor", "--port", "{port}", "--seconds", "1.5"], 1, "was a sphere frame", port="noise"),  # "nothing arrived"
    # device
    S(["device", "--port", "/dev/ttyNOPE9", "get"], 2, "plugged in"),
    S(["device", "get"], 2, "--port"),
    S(["device", "--port", "{port}", "set", "tap.nosuch=1"], 2, "tap.nosuch", port="silent"),
    S(["device", "--port", "{port}", "set", "tap.threshold_g=nan"], 2, "threshold_g", port="silent"),
    S(["device", "--port", "{port}", "set", "tap.threshold_g"], 2, "KEY=VALUE", port="silent"),
    S(["device", "--port", "{port}", "set", "=3"], 2, "no KEY before '='", port="silent"),  # was ': no such setting'
    S(["device", "--port", "{port}", "set", "tap.duration_ms=20ms"], 2, "give the number alone", port="silent"),
    S(["device", "--port", "{port}", "set", "stream.raw_rate_hz=100 Hz"], 2, "stream.raw_rate_hz=100)", port="silent"),
    S(["device", "--port", "{port}", "set", "stream.raw_rate_hz=50.5"], 2, "not a whole number", port="silent"),
    S(["device", "--port", "{port}", "identify", "-1"], 2, "seconds", port="silent"),
    S(["device", "--port", "{port}", "--timeout", "-1", "get"], 2, "timeout", port="silent"),
    S(["device", "--port", "{port}", "get"], 1, "no HELLO", port="silent"),
    S(["device", "--port", "{port}", "--baud", "57600", "get"], 1, "at 57600 baud? (the firmware talks at 115200",
      port="silent"),  # it asked 'at 115200 baud?' whatever --baud said
    S(["device", "--port", "{port}", "get", "tap.threshold_g=1"], 2, "takes no KEY=VALUE", port="silent"),
    S(["device", "--port", "{port}", "set"], 2, "set what", port="silent"),
    S(["device", "--port", "{port}", "save", "tap.threshold_g=1"], 2, "takes no KEY=VALUE", port="silent"),
    S(["device", "--port", "{port}", "clear", "now"], 2, "takes no KEY=VALUE", port="silent"),
    S(["device", "--port", "{port}", "save"], 1, "no HELLO", port="silent"),
    S(["device", "--port", "/dev/null", "get"], 2, "not a serial port"),
    S(["device", "explode"], 2, "invalid choice"),
    # service
    S(["service", "explode"], 2, "invalid choice"),
    # camera
    S(["camera", "calibrate", "{tmp}/nope"], 2, "nope"),
    S(["camera", "track", "{tmp}/nope.avi"], 2, "nope.avi"),
    S(["camera", "track", "{tmp}/g.avi"], 2, "g.avi", files={"g.avi": GARBAGE}),
    S(["camera", "calibrate", "{tmp}/e", "--square-mm", "-5"], 2, "square-mm", files={"e": "dir"}),
    S(["camera", "calibrate", "{tmp}/e", "--board", "2x2"], 2, "--board", files={"e": "dir"}),
    S(["camera", "explode"], 2, "invalid choice"),
    S(["camera", "render", "--distance", "nan"], 2, "argument --distance"),  # rendered frames with no ball, exit 0
    S(["camera", "render", "--distance", "1e99"], 2, "at most 10 m"),
    S(["camera", "render", "--seconds", "-1"], 2, "argument --seconds"),  # was exit 1 after loading the trial
    S(["camera", "render", "--start", "nan"], 2, "argument --start"),
    S(["camera", "track", "{tmp}/v.avi", "--hue", "nan"], 2, "argument --hue", files={"v.avi": b"x"}),  # found no ball
    S(["camera", "track", "{tmp}/v.avi", "--seconds", "-1"], 2, "argument --seconds", files={"v.avi": b"x"}),
    S(["bench", "camera", "--distance", "nan"], 2, "argument --distance"),  # timed frames without a ball
    S(["hybrid-eval", "--distance", "1e99"], 2, "at most 10 m"),
    S(["hybrid-eval", "--hue", "nan"], 2, "--hue"),  # it was taken as a hue
    # hybrid-eval, hybrid-sim, bench, protocol
    S(["hybrid-eval", "--seconds", "1"], 2, "seconds"),
    S(["hybrid-eval", "--trials", "banana"], 2, "banana"),
    S(["hybrid-eval", "--jpeg", "200"], 2, "jpeg"),
    S(["hybrid-eval", "--distance", "-1"], 2, "distance"),
    S(["hybrid-sim", "--seed", "abc"], 2, "invalid int value"),
    S(["hybrid-sim", "--json", "{tmp}"], 2, "is a folder"),
    S(["bench", "explode"], 2, "invalid choice"),
    S(["bench", "pointer", "--seeds", "0"], 2, "seeds"),
    S(["bench", "pointer", "--seconds", "-1"], 2, "seconds"),
    S(["bench", "pointer", "--filters", "wobble", "--no-tune"], 2, "wobble"),
    S(["bench", "pointer", "--against", "no-such-revision"], 2, "not a commit"),
    S(["bench", "pointer", "--set", "pointer.hold_band=0"], 2, "hold_band"),
    S(["bench", "pointer", "--set", "pointer.hold_band_dps=-1"], 2, "hold_band_dps"),
    S(["bench", "pointer", "--set", "hold_band_dps"], 2, "SECTION.KEY=VALUE"),
    S(["bench", "decode", "--seconds", "-1"], 2, "seconds"),
    S(["bench", "decode", "--repeat", "0"], 2, "repeat"),
    S(["bench", "decode", "--json", "{tmp}"], 2, "is a folder"),
    S(["bench", "decode", "--against", "no-such-revision"], 2, "not a commit"),
    S(["bench", "decode", "--against", "HEAD", "--pairs", "0"], 2, "pairs"),
    S(["bench", "pointer", "--json", "{tmp}"], 2, "is a folder"),
    S(["bench", "fusion", "--scenarios", "wobble"], 2, "wobble"),
    S(["bench", "fusion", "--seeds", "0"], 2, "seeds"),
    S(["bench", "fusion", "--at", "-1"], 2, "at"),
    S(["bench", "fusion", "--at", "1e99"], 2, "at most 3600"),  # was a ValueError traceback after the header
    S(["bench", "fusion", "--at", "5", "--rest", "10"], 2, "not shorter than --at"),  # judged during the rest
    S(["bench", "decode", "--seconds", "1e99"], 2, "at most 3600"),  # was a struct.error traceback
    S(["bench", "stress", "--kinds", "wobble"], 2, "wobble"),
    S(["bench", "stress", "--filters", "wobble"], 2, "wobble"),
    S(["bench", "stress", "--seeds", "0"], 2, "seeds"),
    S(["bench", "stress", "--first", "-1"], 2, "first"),
    S(["bench", "daemon", "--seconds", "0.1"], 2, "--seconds"),
    S(["bench", "latency", "--adapters", "wobble"], 2, "unknown adapter row wobble"),
    S(["bench", "latency", "--adapters", ","], 2, "choose among"),
    S(["bench", "latency", "--bauds", "fast"], 2, "baud"),
    S(["bench", "latency", "--bauds", ","], 2, "no baud rate"),
    S(["bench", "latency", "--bauds", "115200,230400"], 2, "after SET_BAUD"),
    S(["bench", "baud-switch", "--baud", "230400"], 2, "exact on 16 MHz"),
    S(["bench", "baud-switch", "--baud", "fast"], 2, "not a baud rate"),
    S(["bench", "baud-switch", "--rounds", "0"], 2, "rounds"),
    S(["bench", "baud-switch", "--adapter", "wobble"], 2, "invalid choice"),
    S(["bench", "baud-switch", "--json", "{tmp}"], 2, "is a folder"),
    S(["bench", "latency", "--seconds", "0"], 2, "seconds"),
    S(["bench", "latency", "--seconds", "3"], 2, "leaves no onset"),
    S(["bench", "latency", "--seed", "-1"], 2, "seed"),
    S(["bench", "latency", "--instruments-nice", "5"], 2, "a nice value from -20 to 0"),
    S(["bench", "latency", "--instruments-nice", "fast"], 2, "not a whole number"),
    S(["bench", "latency", "--xvfb-nice", "-21"], 2, "a nice value from -20 to 0"),
    S(["bench", "latency", "--pointer", "sample"], 2, "invalid choice: 'sample'"),
    S(["bench", "latency", "--floor-writes", "-1"], 2, "give a whole number of at least 0"),
    S(["bench", "latency", "--json", "{tmp}"], 2, "is a folder"),
    S(["bench", "latency", "--against", "no-such-revision"], 2, "not a commit of the repository"),
    S(["bench", "daemon", "--set", "nope.x=1"], 2, "nope"),
    S(["bench", "daemon", "--against", "default", "--set", "outputs.spacenav.mapping=orbit"], 2, "mapping"),
    S(["sim", "--trace", "synthetic:turn:abc", "--seconds", "9"], 2, "number of degrees"),
    S(["sim", "--trace", "synthetic:rotation:nan", "--seconds", "2"], 2, "up to 10000"),  # was a still sphere
    S(["sim", "--trace", "synthetic:rotation:1e99", "--seconds", "2"], 2, "up to 10000"),
    S(["sim", "--trace", "synthetic:rotation:fast", "--seconds", "2"], 2, "degrees a second"),
    S(["sim", "--trace", "synthetic:still:5", "--seconds", "2"], 2, "takes no argument"),  # was ignored
    S(["sim", "--trace", "synthetic:onsets:abc", "--seconds", "2"], 2, "seed must be an integer"),
    S(["sim", "--trace", "synthetic:turn:5000", "--seconds", "9"], 2, "1 to 720 degrees"),
    S(["sim", "--trace", "synthetic:turn", "--seconds", "3"], 2, "--seconds 8.25 or more"),
    S(["bench", "position", "--seconds", "5"], 2, "at least 9"),
    S(["bench", "position", "--test", "10:40,banana"], 2, "banana"),
    S(["bench", "position", "--json", "{tmp}"], 2, "is a folder"),
    # a stretch that is no TRIAL:START_S: argparse's line naming the flag (was exit 1, "sphere hybrid-eval: --trials")
    S(["bench", "position", "--train", "10:x"], 2, "argument --train: '10:x'"),
    S(["bench", "position", "--test", "10:nan"], 2, "argument --test"),
    S(["bench", "ar", "--trials", "16:-4"], 2, "TRIAL:START_S"),
    S(["bench", "hybrid-replay", "--trials", "10:40,"], 2, "TRIAL:START_S"),
    S(["hybrid-eval", "--trials", "10:fast"], 2, "TRIAL:START_S"),
    S(["bench", "drift", "--seeds", "one"], 2, "integers"),
    S(["bench", "drift", "--scenarios", "wobble"], 2, "wobble"),
    S(["bench", "drift", "--set", "gyro.stil_dps=1"], 2, "stil_dps"),
    S(["bench", "drift", "--speed", "0"], 2, "speed"),
    S(["bench", "drift", "--json", "{tmp}"], 2, "is a folder"),
    S(["bench", "hybrid-replay", "--seconds", "5"], 2, "at least 9"),
    S(["bench", "hybrid-replay", "--trials", "banana"], 2, "banana"),
    S(["bench", "hybrid-replay", "--speed", "-1"], 2, "speed"),
    S(["bench", "hybrid-replay", "--json", "{tmp}"], 2, "is a folder"),
    S(["bench", "ar", "--seconds", "5"], 2, "at least 9"),
    S(["bench", "ar", "--trials", "banana"], 2, "banana"),
    S(["bench", "ar", "--speed", "-1"], 2, "speed"),
    S(["bench", "ar", "--lead", "0"], 2, "greater than 0"),
    S(["bench", "ar", "--json", "{tmp}"], 2, "is a folder"),
    S(["bench", "ar", "--against", "no-such-revision"], 2, "not a commit"),
    S(["bench", "tracker", "--breakdown", "16:x"], 2, "TRIAL:START_S"),
    S(["bench", "tracker", "--breakdown", "16:40", "--loss-at", "11.5"], 2, "ends within"),
    S(["bench", "tracker", "--breakdown", "16:40", "--loss-at", "-1"], 2, "at least 0"),
    S(["bench", "tracker", "--trials", "banana,10"], 2, "banana"),
    S(["bench", "tracker", "--trials", "10"], 2, "at least two trials"),
    S(["bench", "tracker", "--starts", "forty"], 2, "--starts"),
    S(["bench", "tracker", "--starts", "-5"], 2, "--starts"),
    S(["bench", "tracker", "--json", "{tmp}"], 2, "is a folder"),
    S(["decode", "{tmp}/good.cap"], 1, "no space left", files=CAP, stdout="/dev/full"),
    S(["decode", "{tmp}/good.cap", "--jsonl"], 1, "no space left", files=CAP, stdout="/dev/full"),
    S(["protocol", "types"], 1, "no space left", stdout="/dev/full"),
    S(["device", "keys"], 1, "no space left", stdout="/dev/full"),
    S(["service", "print"], 1, "no space left", stdout="/dev/full"),
    M(["--print-config"], 1, "no space left", stdout="/dev/full"),
    C(["--print-stats=yes"], 2, "ignored explicit argument"),
    M(["--replay", "{tmp}/good.cap", "--speed", "0", "--print-stats"], 1, "no space left", files=CAP,
      stdout="/dev/full"),
    # every command that writes a file, into a full disk: one line, exit 1, never a hang (sim used to read
    # /dev/full back forever)
    S(["sim", "--trace", "synthetic:tour", "--seconds", "1", "--capture", "/dev/full"], 1, "no space left"),
    S(["sim", "--trace", "synthetic:tour", "--seconds", "1", "--stats", "/dev/full"], 1, "no space left"),
    S(["sim", "--trace", "synthetic:tour", "--seconds", "1", "--json", "/dev/full"], 1, "no space left"),
    S(["eval", "--filters", "madgwick", "--only", "07", "--seconds", "30", "--json", "/dev/full"], 1, "no space left",
      broad=True),
    S(["hybrid-eval", "--trials", "07", "--seconds", "9", "--json", "/dev/full"], 1, "no space left", timeout=60,
      broad=True),
    S(["hybrid-sim", "--json", "/dev/full"], 1, "no space left"),
    S(["bench", "decode", "--seconds", "0.2", "--repeat", "1", "--json", "/dev/full"], 1, "no space left"),
    S(["bench", "pointer", "--seeds", "1", "--seconds", "2", "--no-tune", "--filters", "none", "--json", "/dev/full"],
      1, "no space left", timeout=60, broad=True),
    S(["camera", "render", "--seconds", "1", "-o", "/dev/full"], 1, "cannot write", timeout=60, broad=True),
    S(["service", "install"], 2, "xdg", files={"xdg": b"a file where a folder belongs"}),
    S(["protocol", "explode"], 2, "invalid choice"),
    S(["protocol"], 2, "required: {budget,types}"),  # was "required: what"
    # a file or folder that cannot be made is refused before the run, not in a traceback at its end
    S(["sim", "--trace", "synthetic:still", "--json", "/proc/sphere-x.json"], 2, "cannot be written"),
    S(["sim", "--trace", "synthetic:still", "--stats", "/proc/sphere-x.json"], 2, "cannot be written"),
    S(["eval", "--json", "/proc/sphere-x.json"], 2, "cannot be written"),
    S(["eval", "--plot", "/proc/sphere-x"], 2, "cannot be written"),
    S(["eval", "--plot", "{tmp}/f"], 2, "is a file", files={"f": b"x"}),
    S(["eval", "--plot", "{tmp}/f/plots"], 2, "is a file, not a folder", files={"f": b"x"}),
    S(["hybrid-eval", "--plot", "{tmp}/f"], 2, "is a file", files={"f": b"x"}),
    S(["bench", "decode", "--json", "/proc/sphere-x.json"], 2, "cannot be written"),
    S(["bench", "position", "--json", "/proc/sphere-x.json"], 2, "cannot be written"),
]


def _make(tmp, files):
    for name, what in files.items():
        p = os.path.join(tmp, name)
        os.makedirs(os.path.dirname(p), exist_ok=True)
        if what == "dir":
            os.mkdir(p)
        elif what == "fifo":
            os.mkfifo(p)
        elif what == "loop":
            os.symlink(p, p)
        else:
            with open(p, "wb") as f:
                f.write(what)


class _Port:
    """A pty standing for a serial device: silent, one that streams a capture while the row runs, or one
    that streams for 0.5 s once the program opens it and is then unplugged (its master end closed)."""

    def __init__(self, kind):
        self.master, slave = os.openpty()
        tty.setraw(slave)
        self.path = os.ttyname(slave)
        os.close(slave)
        self.stop = threading.Event()
        self.lock = threading.Lock()
        if kind in ("garbage", "noise", "vanish"):
            threading.Thread(target=self._feed, args=(kind == "vanish", GARBAGE if kind == "noise" else GOOD),
                             daemon=True).start()

    def _feed(self, vanish, data):
        if vanish:  # its 0.5 s count from when the program opens the port (a loaded machine may take longer to get
            # there: a CI rehearsal at load 10 found the port already gone). A pty's master reads POLLHUP while
            # no one has the device end open.
            hup = select.poll()
            hup.register(self.master, select.POLLHUP)
            deadline = time.monotonic() + 15.0
            while not self.stop.is_set() and time.monotonic() < deadline and hup.poll(0):
                time.sleep(0.005)
        end = time.monotonic() + 0.5
        while not self.stop.is_set():
            if vanish and time.monotonic() > end:
                self.close()
                return
            try:
                os.write(self.master, data[:2000])
            except OSError:
                pass
            time.sleep(0.05)

    def close(self):
        with self.lock:
            self.stop.set()
            if self.master is not None:
                os.close(self.master)
                self.master = None


def _child(row, argv, out_path, env, port):
    if port is not None:
        os.close(port.master)  # the device end stays with the test (an unplug must be one)
    os.environ.update(env)
    fd = os.open(out_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    os.dup2(fd, 2)
    os.dup2(os.open(row.stdout or out_path + ".out", os.O_WRONLY | os.O_CREAT | os.O_TRUNC), 1)
    os.dup2(os.open(os.devnull, os.O_RDONLY), 0)
    sys.stdout = open(1, "w", buffering=1, closefd=False)  # line-buffered: a write fails where it happens
    sys.stderr = open(2, "w", closefd=False)
    sys.stdin = open(0, "r", closefd=False)
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    code = 99
    try:
        if row.prog == "mouse":
            from sphere.daemon.cli import main
        else:
            from sphere.cli import main
        code = main(argv)
    except SystemExit as e:
        code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    except BaseException:  # what a user would see as a traceback
        traceback.print_exc()
        code = 98
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except OSError as e:  # what Python does when its last flush of stdout fails
        os.write(2, f"Exception ignored while flushing sys.stdout: {e!r}\n".encode())
        code = 120
    os._exit(code or 0)


def run_row(row, tmp):
    """Run one row in a forked child; returns (exit status, stderr)."""
    _make(tmp, row.files)
    port = _Port(row.port) if row.port else None
    argv = [a.replace("{tmp}", tmp).replace("{port}", port.path if port else "") for a in row.argv]
    env = {"XDG_CONFIG_HOME": os.path.join(tmp, "xdg"), "HOME": tmp, "DISPLAY": "", "COLUMNS": "120"}
    out = os.path.join(tmp, ".stderr")
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:
        _child(row, argv, out, env, port)
    deadline = time.monotonic() + row.timeout
    status = None
    stopped = False
    try:
        while True:
            done, st = os.waitpid(pid, os.WNOHANG)
            if done:
                status = os.waitstatus_to_exitcode(st)
                break
            if time.monotonic() > deadline and not stopped:
                if row.code == 0 and "waiting for" in row.words:
                    os.kill(pid, signal.SIGTERM)  # a run that waits for a device ends when asked to
                    stopped = True
                    deadline += 5
                    continue
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                raise AssertionError(f"still running after {row.timeout:g} s")
            time.sleep(0.01)
    finally:
        if port:
            port.close()
    with open(out, errors="replace") as f:
        err = f.read()
    if row.stdout:
        return status, err, ""
    with open(out + ".out", errors="replace") as f:
        return status, err, f.read()


# a run that waits for a device is stopped by SIGTERM after this long (the row's timeout)
for _r in ROWS:
    if _r.code == 0 and "waiting for" in _r.words:
        _r.timeout = 1.5


@pytest.fixture(scope="module", autouse=True)
def _imports():
    import sphere.cli  # noqa: F401  (imported once here, so each forked row starts at once)
    import sphere.daemon.app  # noqa: F401
    import sphere.daemon.cli  # noqa: F401
    from sphere import cli

    cli.build_parser()


@pytest.mark.parametrize("row", ROWS, ids=[r.id for r in ROWS])
def test_bad_input(row, tmp_path):
    if row.broad:
        from sphere import broad

        try:
            broad.trial_paths()
        except broad.BroadMissing as e:
            pytest.skip(f"BROAD trials not available: {e}")
    status, err, out = run_row(row, str(tmp_path))
    assert "Traceback" not in err, err
    assert status == row.code, (status, err)
    assert row.words.lower() in (err if row.code else err + out).lower(), err  # a run that succeeds may say so on stdout
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith(("usage:", " "))]
    assert len(lines) <= 4, err  # a clear message, not a wall of text


def test_the_battery_has_at_least_114_distinct_rows():
    keys = {(r.prog, tuple(r.argv), tuple(sorted((k, v if isinstance(v, str) else v[:64]) for k, v in r.files.items())))
            for r in ROWS}
    assert len(keys) == len(ROWS) >= 114, (len(keys), len(ROWS))
