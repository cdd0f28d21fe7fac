"""Figures of the 3-D outputs against clients we did not write, printed side by side with their targets:

    python tests/host/outputs_bench.py [--json OUT]

For each spacenavd protocol version (1, then 0) sphere-mouse replays tests/captures/sim_turn_90.bin (the
virtual sphere: 3 s still, a 90° turn left at 90 °/s, still, a single tap, a double tap; made by
``sphere sim --trace synthetic:turn``) at its real speed with ``[outputs.spacenav]`` on ("direct"
mapping, 3-D mode), while two clients read it at once: Debian's libspnav through ctypes
(tests/host/spnav_client.py, which also integrates the motion with libspnav's ``spnav_posrot_moveobj``)
and libspnav-dev's own examples/simple.c compiled with ``-lspnav -lm``. Figures:

- the device name the client read (``spnav_dev_name``; protocol 1 only, v0 has no requests);
- motion events a second while the sphere turns (target ≥ 60): those with motion over the turn's 1 s, and
  as they arrived (first to last arrival; on a loaded machine the reader's own delays show here);
  events while it lies still (target 0);
- the zero event's delay after the stop: its arrival minus (the first motion event's arrival + the turn's
  duration), both wall clock, ms (target ≤ 50); and the same by the sphere's clock, from the events'
  ``period`` fields (the sum of the periods from the first motion event to the zero event, minus the
  turn's duration), which this machine's load does not move;
- the angle ``spnav_posrot_moveobj`` turned the object by (target 90 ± 5°) and about which axis;
- the buttons (single tap 0, double tap 1, whose first knock is a single tap too).

Then the DSU ("cemuhook") motion server: sphere-mouse replays the same turn (pointer mode: the server
works in every mode) while :class:`DsuClient` — written here from the protocol's description
(github.com/v1993/cemuhook-protocol), its own offsets and ``binascii.crc32``, nothing shared with the
server's module — asks for the version, the controller list and pad data, and sends a foreign datagram
and a truncated one. Figures: pad data packets a second (target ≥ 100), bad CRCs (target 0), the gyro's
yaw over the middle of the turn against the sphere's 90 °/s (target within 2 %), the buttons seen. Last,
10,000 hostile datagrams thrown at the server during a replay: the daemon's exit status, what it counted,
and its pointer moves against a run without them (target: equal).

The tests (tests/host/test_spacenav.py, tests/host/test_dsu.py) run the same functions and assert the
targets.
"""

from __future__ import annotations

import json
import math
import os
import random
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
TURN_CAPTURE = REPO / "tests" / "captures" / "sim_turn_90.bin"
TURN_S = 1.0  # sphere.sim.turn: 90° at 90 °/s
SIMPLE_C = Path("/usr/share/doc/libspnav-dev/examples/simple/simple.c")
LIBSPNAV = "libspnav.so.0"


def libspnav_missing() -> str | None:
    """Why the libspnav tests cannot run here, or None."""
    import ctypes.util

    try:
        import ctypes

        ctypes.CDLL(LIBSPNAV)
    except OSError:
        return "Debian's libspnav0 is not installed (./scripts/setup installs it)"
    if not SIMPLE_C.is_file() or shutil.which("gcc") is None:
        return "libspnav-dev's examples/simple.c or gcc is missing (./scripts/setup installs them)"
    return None


def compile_simple(folder: Path) -> Path:
    """libspnav-dev's example, as its Makefile builds simple_af_unix (plus -lm, which the static lib needs)."""
    exe = folder / "simple_af_unix"
    subprocess.run(["gcc", "-DBUILD_AF_UNIX", "-o", str(exe), str(SIMPLE_C), "-lspnav", "-lm"], check=True,
                   capture_output=True, timeout=120)
    return exe


def _reader(proc, lines: list) -> threading.Thread:
    def run():
        for line in proc.stdout:
            lines.append((time.monotonic(), line.rstrip("\n")))

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


def run_turn(folder: Path, protocol: int, mapping: str = "direct", extra_config: str = "",
             capture: Path = TURN_CAPTURE, simple: Path | None = None) -> dict:
    """Replay the turn with the spacenav output on; the ctypes client and (if given) the compiled example
    read it. Returns the clients' records and the daemon's log."""
    sock = folder / f"spnav-v{protocol}.sock"
    config = folder / f"spnav-v{protocol}.toml"
    config.write_text(f"[mode]\nstart = \"3d\"\n[outputs.spacenav]\nenabled = true\nsocket = \"{sock}\"\n"
                      f"protocol = {protocol}\nmapping = \"{mapping}\"\n{extra_config}")
    daemon = subprocess.Popen([sys.executable, "-m", "sphere.mouse", "--config", str(config), "--replay", str(capture),
                               "--speed", "1", "--backend", "log", "--no-stream"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 20
        while not sock.exists():
            if daemon.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"sphere-mouse did not open {sock}: {daemon.stderr.read()}")
            time.sleep(0.02)
        env = dict(os.environ, SPNAV_SOCKET=str(sock))
        client = subprocess.Popen([sys.executable, str(HERE / "spnav_client.py"), "30"], env=env,
                                  stdout=subprocess.PIPE, text=True)
        client_lines: list = []
        readers = [_reader(client, client_lines)]
        simple_lines: list = []
        example = None
        if simple is not None:  # line-buffered so each line's arrival time is the event's
            example = subprocess.Popen(["stdbuf", "-oL", str(simple)], env=env, stdout=subprocess.PIPE, text=True)
            readers.append(_reader(example, simple_lines))
        _, err = daemon.communicate(timeout=60)
        for p in (client, example):
            if p is not None:
                p.wait(timeout=30)
        for r in readers:
            r.join(timeout=5)
    finally:
        for p in (daemon,):
            if p.poll() is None:
                p.kill()
    return {"daemon_rc": daemon.returncode, "daemon_log": err, "client": [json.loads(l) for _, l in client_lines],
            "simple": simple_lines, "simple_rc": None if example is None else example.returncode}


def motion_figures(events: list[tuple[float, list]], turn_s: float = TURN_S, periods: list | None = None) -> dict:
    """From (arrival time, [x, y, z, rx, ry, rz]) in order: rate while turning, events while still, the zero
    event's delay after the stop — by arrival (wall clock), and by the events' ``period`` fields (the
    sphere's clock: what the daemon decided, free of this machine's load) when given."""
    moving = [i for i, (_, v) in enumerate(events) if any(v)]
    if not moving:
        return {"motion_events": 0}
    first, last = moving[0], moving[-1]
    t_first = events[first][0]
    zero = next((i for i in range(last + 1, len(events)) if not any(events[i][1])), None)
    t_zero = events[zero][0] if zero is not None else None
    span = events[last][0] - t_first
    return {
        "motion_events": len(moving),
        "events_per_s": len(moving) / turn_s,  # sent for the turn
        "arrival_per_s": (len(moving) - 1) / span if span > 0 else float("nan"),  # as they arrived (load-bound)
        "still_events": first + (len(events) - zero - 1 if zero is not None else 0),
        "zero_events": sum(1 for _, v in events if not any(v)),
        "zero_after_stop_ms": (t_zero - (t_first + turn_s)) * 1000 if t_zero is not None else None,
        "zero_after_last_ms": (t_zero - events[last][0]) * 1000 if t_zero is not None else None,
        "sums": [sum(v[k] for _, v in events) for k in range(6)],
        "zero_after_stop_device_ms": (sum(periods[first + 1:zero + 1]) - turn_s * 1000)
        if periods is not None and zero is not None else None,
    }


SIMPLE_MOTION = re.compile(r"got motion event: t\((-?\d+), (-?\d+), (-?\d+)\) r\((-?\d+), (-?\d+), (-?\d+)\)")
SIMPLE_BUTTON = re.compile(r"got button (press|release) event b\((\d+)\)")


def figures(run: dict) -> dict:
    c = run["client"]
    opened = next(r for r in c if r["kind"] == "open")
    end = next(r for r in c if r["kind"] == "end")
    x, y, z, w = end["rot_xyzw"]
    angle = math.degrees(2 * math.atan2(math.sqrt(x * x + y * y + z * z), w))
    s = math.sqrt(x * x + y * y + z * z) or 1.0
    out = {
        "protocol": opened["proto"], "device_name": opened["name"], "axes": opened["axes"],
        "buttons": opened["buttons"], "open_s": opened["open_s"],
        "ctypes": motion_figures([(r["t"], r["v"]) for r in c if r["kind"] == "motion"],
                                 periods=[r["period"] for r in c if r["kind"] == "motion"]),
        "moveobj_deg": angle, "moveobj_axis": [x / s, y / s, z / s],
        "button_events": [(r["bnum"], r["press"]) for r in c if r["kind"] == "button"],
    }
    if run["simple"]:
        lines = run["simple"]
        motions = [(t, [int(g) for g in m.groups()]) for t, l in lines if (m := SIMPLE_MOTION.search(l))]
        out["simple"] = motion_figures(motions)
        out["simple"]["device_line"] = next((l for _, l in lines if l.startswith("Device:")), None)
        out["simple"]["protocol_line"] = next((l for _, l in lines if "protocol version" in l), None)
        out["simple"]["button_events"] = [(int(m.group(2)), int(m.group(1) == "press"))
                                          for _, l in lines if (m := SIMPLE_BUTTON.search(l))]
        out["simple_rc"] = run["simple_rc"]
    return out


def spacenav_turns(folder: Path) -> dict:
    simple = compile_simple(folder)
    return {f"v{p}": figures(run_turn(folder, p, simple=simple)) for p in (1, 0)}


def _print_spacenav(res: dict) -> None:
    print("spacenav output, sphere-mouse --replay sim_turn_90.bin (direct mapping), Debian libspnav 1.0")
    print(f"{'':34s}{'target':>12s}" + "".join(f"{k + ' ' + p:>16s}" for k in res for p in ("ctypes", "simple.c")))

    def row(label, target, get):
        cells = []
        for k in res:
            for p in ("ctypes", "simple"):
                try:
                    v = get(res[k], p)
                except (KeyError, TypeError):
                    v = None
                cells.append("-" if v is None else (f"{v:.1f}" if isinstance(v, float) else str(v)))
        print(f"{label:34s}{target:>12s}" + "".join(f"{c:>16s}" for c in cells))

    row("device name", "ours", lambda r, p: r["device_name"] if p == "ctypes" else
        (r["simple"]["device_line"] or "").removeprefix("Device: ") or None)
    row("motion events/s of the turn", ">= 60", lambda r, p: r[p]["events_per_s"])
    row("  as they arrived (events/s)", "", lambda r, p: r[p]["arrival_per_s"])
    row("events while still", "0", lambda r, p: r[p]["still_events"])
    row("zero events", "1", lambda r, p: r[p]["zero_events"])
    row("zero event after the stop (ms)", "<= 50", lambda r, p: r[p]["zero_after_stop_ms"])
    row("  by the sphere's clock (ms)", "<= 50", lambda r, p: r[p]["zero_after_stop_device_ms"])
    row("zero event after the last (ms)", "", lambda r, p: r[p]["zero_after_last_ms"])
    row("ry summed (mrad)", "1571", lambda r, p: r[p]["sums"][4])
    row("spnav_posrot_moveobj angle (deg)", "90 +- 5", lambda r, p: r["moveobj_deg"] if p == "ctypes" else None)
    row("buttons (v press, ^ release)", "0v0^0v0^1v1^", lambda r, p: "".join(f"{b}{'v' if d else '^'}" for b, d in
                                                          (r["button_events"] if p == "ctypes" else r[p]["button_events"])))


# ------------------------------------------------------------------ DSU, from the protocol description

class DsuClient:
    """A cemuhook client as the description has it: every message ``"DSUC"``, u16 version 1001, u16 length
    of what follows the 16-byte header, u32 CRC-32 of the whole message with these 4 bytes zero, u32 client
    id, then u32 message type and its data, little-endian. Server messages are read the same way."""

    def __init__(self, port: int, host: str = "127.0.0.1"):
        import binascii
        import socket

        self._crc = binascii.crc32
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.settimeout(0.05)
        self.server = (host, port)
        self.client_id = 0x2626
        self.bad_crc = 0
        self.foreign = 0
        self.pads: list[dict] = []
        self.replies: list[tuple[int, bytes]] = []

    def build(self, mtype: int, data: bytes) -> bytearray:
        msg = bytearray(20 + len(data))
        msg[0:4] = b"DSUC"
        msg[4:6] = (1001).to_bytes(2, "little")
        msg[6:8] = (4 + len(data)).to_bytes(2, "little")
        msg[12:16] = self.client_id.to_bytes(4, "little")
        msg[16:20] = mtype.to_bytes(4, "little")
        msg[20:] = data
        msg[8:12] = (self._crc(bytes(msg)) & 0xFFFFFFFF).to_bytes(4, "little")
        return msg

    def send(self, mtype: int, data: bytes = b"") -> None:
        self.sock.sendto(bytes(self.build(mtype, data)), self.server)

    def ask_version(self):
        self.send(0x100000)

    def ask_ports(self, slots=(0, 1, 2, 3)):
        self.send(0x100001, len(slots).to_bytes(4, "little", signed=True) + bytes(slots))

    def subscribe_all(self):
        self.send(0x100002, bytes(8))  # flags 0: every pad

    def receive(self, until: float) -> None:
        import socket

        while time.monotonic() < until:
            try:
                data, _ = self.sock.recvfrom(2048)
            except (socket.timeout, ConnectionRefusedError):
                return
            t = time.monotonic()
            if len(data) < 20 or data[0:4] != b"DSUS" or int.from_bytes(data[4:6], "little") != 1001:
                self.foreign += 1
                continue
            length = int.from_bytes(data[6:8], "little")
            msg = bytearray(data[:16 + length])
            sent = int.from_bytes(msg[8:12], "little")
            msg[8:12] = bytes(4)
            if self._crc(bytes(msg)) & 0xFFFFFFFF != sent or len(data) < 16 + length:
                self.bad_crc += 1
                continue
            mtype = int.from_bytes(msg[16:20], "little")
            body = bytes(msg[20:])
            if mtype != 0x100002:
                self.replies.append((mtype, body))
                continue
            # after the type: 11 bytes shared, connected (11), packet number (12-15), buttons (16, 17), HOME,
            # touch, sticks (20-23), 12 analog (24-35: dpad L D R U, Y, B, A, X, R1, L1, R2, L2), two touches
            # (36-47), timestamp u64 (48-55), accel x y z (56-67), gyro pitch yaw roll (68-79)
            f = struct.unpack("<3f", body[56:68]), struct.unpack("<3f", body[68:80])
            self.pads.append({"t": t, "slot": body[0], "state": body[1], "model": body[2], "connected": body[11],
                              "number": int.from_bytes(body[12:16], "little"), "buttons2": body[17],
                              "analog_a": body[30], "analog_b": body[29], "sticks": list(body[20:24]),
                              "t_us": int.from_bytes(body[48:56], "little"), "accel": f[0], "gyro": f[1],
                              "length": len(data)})

    def close(self):
        self.sock.close()


def free_udp_port() -> int:
    import socket

    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def _daemon(folder: Path, name: str, config_text: str, capture: Path = TURN_CAPTURE, speed: str = "1"):
    config = folder / f"{name}.toml"
    config.write_text(config_text)
    return subprocess.Popen([sys.executable, "-m", "sphere.mouse", "--config", str(config), "--replay", str(capture),
                             "--speed", speed, "--backend", "log", "--no-stream"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def run_dsu_turn(folder: Path) -> dict:
    port = free_udp_port()
    daemon = _daemon(folder, "dsu", f"[outputs.dsu]\nenabled = true\nport = {port}\n")
    client = DsuClient(port)
    try:
        end = time.monotonic() + 30
        asked = 0.0
        odd_sent = False
        while daemon.poll() is None and time.monotonic() < end:
            now = time.monotonic()
            if now - asked > 0.5:  # as emulators do: ask again before the server's timeout
                client.subscribe_all()
                client.ask_version()
                client.ask_ports()
                asked = now
                if client.pads and not odd_sent:  # a foreign datagram and a truncated request
                    client.sock.sendto(b"GET / HTTP/1.0\r\n\r\n", client.server)
                    client.sock.sendto(bytes(client.build(0x100002, bytes(8)))[:22], client.server)
                    odd_sent = True
            client.receive(now + 0.1)
        _, err = daemon.communicate(timeout=30)
    finally:
        if daemon.poll() is None:
            daemon.kill()
        client.close()
    return {"daemon_rc": daemon.returncode, "daemon_log": err, "pads": client.pads, "replies": client.replies,
            "bad_crc": client.bad_crc, "foreign": client.foreign}


def dsu_figures(run: dict) -> dict:
    from statistics import median

    pads = run["pads"]
    t0 = pads[0]["t_us"]
    # the turn: 3.0 s to 4.0 s of the trace; the device clock starts with the trace (the still lead-in)
    moving = [p for p in pads if abs(p["gyro"][1]) > 10.0]
    turn_t = [p["t_us"] for p in moving]
    mid = [p["gyro"][1] for p in moving if turn_t[0] + 200_000 <= p["t_us"] <= turn_t[-1] - 200_000]
    span_us = pads[-1]["t_us"] - t0
    arrivals = pads[-1]["t"] - pads[0]["t"]
    yaw = median(mid)
    still = [p for p in pads if p["t_us"] < turn_t[0] - 100_000]
    presses = []
    for p in pads:
        for name, bit in (("A", 0x20), ("B", 0x40)):
            if p["buttons2"] & bit and (not presses or presses[-1][0] != name or p["t_us"] - presses[-1][1] > 200_000):
                presses.append((name, p["t_us"]))
    versions = [int.from_bytes(b[:2], "little") for t, b in run["replies"] if t == 0x100000]
    ports = {b[0]: (b[1], b[2]) for t, b in run["replies"] if t == 0x100001}
    log = run["daemon_log"]
    ignored = re.search(r"dsu: (\d+) datagrams received, (\d+) ignored", log)
    return {
        "packets": len(pads), "packets_per_s_device": (len(pads) - 1) / (span_us / 1e6),
        "packets_per_s_arrival": (len(pads) - 1) / arrivals, "bad_crc": run["bad_crc"],
        "numbers_increasing": all(b["number"] == a["number"] + 1 for a, b in zip(pads, pads[1:])),
        "yaw_dps": yaw, "yaw_error_pct": (yaw - 90.0) / 90.0 * 100, "turn_samples": len(mid),
        "pitch_roll_max_dps": max(max(abs(p["gyro"][0]), abs(p["gyro"][2])) for p in moving),
        "accel_still_g": [round(sum(p["accel"][k] for p in still) / len(still), 3) for k in range(3)],
        "buttons": [n for n, _ in presses], "version": versions[:1], "ports": ports,
        "server_ignored": int(ignored.group(2)) if ignored else None, "daemon_rc": run["daemon_rc"],
    }


def hostile_datagrams(n: int, seed: int = 26):
    """``n`` datagrams a DSU server must ignore: random bytes, wrong magic or version, a CRC that does not
    match, lengths beyond the datagram, truncations, unknown types, controller requests with impossible
    counts or slots, a pad request too short."""
    import binascii

    rng = random.Random(seed)
    client = DsuClient.__new__(DsuClient)
    client._crc = binascii.crc32
    client.client_id = 0xBAD
    out = []
    for i in range(n):
        kind = i % 9
        if kind == 0:
            d = rng.randbytes(rng.randrange(0, 200))
        elif kind == 1:
            d = bytes(client.build(0x100002, bytes(8)))
            d = b"DSUS" + d[4:]
        elif kind == 2:
            d = bytearray(client.build(0x100001, (1).to_bytes(4, "little") + b"\0"))
            d[4:6] = (1000).to_bytes(2, "little")
            d = bytes(d)
        elif kind == 3:
            d = bytearray(client.build(0x100000, b""))
            d[8] ^= 0xFF
            d = bytes(d)
        elif kind == 4:
            d = bytearray(client.build(0x100002, bytes(8)))
            d[6:8] = (60000).to_bytes(2, "little")
            d = bytes(d)
        elif kind == 5:
            d = bytes(client.build(0x100002, bytes(8)))[:rng.randrange(0, 27)]
        elif kind == 6:
            d = bytes(client.build(rng.choice([0, 0x100003, 0x110002, 0xFFFFFFFF]), rng.randbytes(8)))
        elif kind == 7:
            count = rng.choice([-1, 5, 1000, 2**31 - 1])
            d = bytes(client.build(0x100001, count.to_bytes(4, "little", signed=True) + bytes([0, 1, 2, 3])))
        else:
            d = bytes(client.build(rng.choice([0x100001, 0x100002]), rng.choice([b"", b"\x01", (2).to_bytes(4, "little") + b"\x07\x09"])))
        out.append(d)
    return out


def udp_drops(port: int) -> int:
    """Datagrams the kernel dropped for the UDP socket bound to ``port`` here (/proc/net/udp, last column)."""
    with open("/proc/net/udp") as f:
        for line in f.readlines()[1:]:
            cols = line.split()
            if int(cols[1].split(":")[1], 16) == port:
                return int(cols[-1])
    return 0


def run_dsu_hostile(folder: Path, n: int = 10000) -> dict:
    """The turn replayed twice in pointer mode, the DSU server on; the second time ``n`` hostile datagrams
    arrive while it runs. Pointer moves, exit status and the server's counts."""
    import socket

    results = {}
    for flood in (False, True):
        port = free_udp_port()
        daemon = _daemon(folder, f"hostile{int(flood)}", f"[outputs.dsu]\nenabled = true\nport = {port}\n")
        sent = 0
        kernel_drops = 0
        probe = None
        if flood:
            probe = DsuClient(port)

            def answered(seconds):  # a version request answered: all sent before it were read
                n = len(probe.replies)
                deadline = time.monotonic() + seconds
                while len(probe.replies) == n and time.monotonic() < deadline and daemon.poll() is None:
                    probe.ask_version()
                    probe.receive(time.monotonic() + 0.1)
                return len(probe.replies) > n

            answered(20)  # the server is up (the replay's still lead-in is 3 s)
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            data = hostile_datagrams(n)
            for i in range(0, n, 200):  # in chunks the socket's buffer holds, each read before the next
                for d in data[i:i + 200]:
                    s.sendto(d, ("127.0.0.1", port))
                    sent += 1
                answered(5)
            s.close()
            probe.receive(time.monotonic() + 0.3)
            probe.close()
            kernel_drops = udp_drops(port)  # a loaded machine: datagrams the socket's buffer had no room for
        _, err = daemon.communicate(timeout=60)
        moves = re.search(r"stopped: (\d+) pointer moves", err)
        ignored = re.search(r"dsu: (\d+) datagrams received, (\d+) ignored", err)
        results["flood" if flood else "calm"] = {
            "rc": daemon.returncode, "moves": int(moves.group(1)) if moves else None, "sent": sent,
            "received": int(ignored.group(1)) - (len(probe.replies) if probe else 0) if ignored else None,
            "ignored": int(ignored.group(2)) if ignored else None, "kernel_drops": kernel_drops,
            "traceback": "Traceback" in err}
    return results


def _rss_kib(pid: int) -> int:
    with open(f"/proc/{pid}/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:"))


def run_spnav_hostile(folder: Path, connects: int = 1000) -> dict:
    """The turn replayed twice in pointer mode with the spacenav output on in every mode, a ctypes libspnav
    client reading; the second time also a client that sends random bytes, ``connects`` connections opened
    and closed, and one that connects and never reads. Pointer moves, what the good client got, the
    daemon's memory before and after the hostile clients, its exit status."""
    import socket

    results = {}
    for hostile in (False, True):
        sock = folder / f"hostile{int(hostile)}.sock"
        daemon = _daemon(folder, f"spnav-hostile{int(hostile)}",
                         f"[outputs.spacenav]\nenabled = true\nsocket = \"{sock}\"\nmapping = \"direct\"\n"
                         "only_3d = false\n")
        deadline = time.monotonic() + 20
        while not sock.exists() and daemon.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        good = subprocess.Popen([sys.executable, str(HERE / "spnav_client.py"), "30"], stdout=subprocess.PIPE,
                                text=True, env=dict(os.environ, SPNAV_SOCKET=str(sock)))
        lines: list = []
        reader = _reader(good, lines)
        rss = []
        held = []
        time.sleep(0.5)
        rss.append(_rss_kib(daemon.pid))
        if hostile:
            rng = random.Random(26)
            noisy = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            noisy.connect(str(sock))
            noisy.sendall(bytes([0x42, 0x13, 0x37, 0xFF]) + rng.randbytes(4000))
            held.append(noisy)
            mute = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            mute.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            mute.connect(str(sock))
            mute.sendall(struct.pack("=i", 0x7FAA5501))
            held.append(mute)
            for _ in range(connects):
                c = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                c.connect(str(sock))
                c.close()
        while daemon.poll() is None:  # memory through the run (the mute client never reads)
            try:
                rss.append(_rss_kib(daemon.pid))
            except (OSError, StopIteration):
                break
            time.sleep(0.25)
        _, err = daemon.communicate(timeout=60)
        for h in held:
            h.close()
        good.wait(timeout=30)
        reader.join(timeout=5)
        client = [json.loads(line) for _, line in lines]
        moves = re.search(r"stopped: (\d+) pointer moves", err)
        motion = [(r["t"], r["v"]) for r in client if r["kind"] == "motion"]
        results["hostile" if hostile else "calm"] = {
            "rc": daemon.returncode, "moves": int(moves.group(1)) if moves else None,
            "good": motion_figures(motion), "traceback": "Traceback" in err,
            "dropped_logged": err.count("spacenav: dropped a client"),
            "rss_growth_kib": (max(rss) - rss[0]) if len(rss) > 1 else None}
    return results


DSU_READER = """
import socket, sys, time
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.settimeout(0.2)
port, seconds = int(sys.argv[1]), float(sys.argv[2])
req = bytearray(28)  # DSUC, 1001, length 12, CRC, id, type 0x100002, flags 0 (all pads)
req[0:4] = b"DSUC"; req[4:6] = (1001).to_bytes(2, "little"); req[6:8] = (12).to_bytes(2, "little")
req[16:20] = (0x100002).to_bytes(4, "little")
import binascii; req[8:12] = (binascii.crc32(bytes(req)) & 0xFFFFFFFF).to_bytes(4, "little")
end = time.monotonic() + seconds; asked = 0; n = 0
while time.monotonic() < end:
    if time.monotonic() - asked > 0.5:
        s.sendto(bytes(req), ("127.0.0.1", port)); asked = time.monotonic()
    try:
        s.recv(2048); n += 1
    except socket.timeout:
        pass
print(n)
"""


def output_cost(name: str | None, samples: int = 4000) -> float:
    """Process CPU seconds (every thread: the output's server thread too) to pass ``samples`` samples of a
    sphere turning at 90 °/s (the daemon's 200 Hz RAW_SAMPLE rate in device time) through the outputs'
    fan-out with ``name``'s output on and a client of it reading in its own process; None: no output."""
    from sphere import quaternion as quat
    from sphere.daemon.outputs.fanout import Outputs

    client = None
    folder = tempfile.mkdtemp()
    outs = []
    if name == "spacenav":
        from sphere.daemon.outputs.spacenav import SpacenavOutput

        path = os.path.join(folder, "cost.sock")
        outs = [SpacenavOutput(path, mapping="direct")]
        client = subprocess.Popen([sys.executable, str(HERE / "spnav_client.py"), "120"], stdout=subprocess.DEVNULL,
                                  env=dict(os.environ, SPNAV_SOCKET=path))
        wait = lambda: outs[0].server.clients  # noqa: E731
    elif name == "dsu":
        from sphere.daemon.outputs.dsu import DsuOutput

        port = free_udp_port()
        outs = [DsuOutput(port=port)]
        client = subprocess.Popen([sys.executable, "-c", DSU_READER, str(port), "120"], stdout=subprocess.DEVNULL)
        wait = lambda: outs[0].server.subscribers  # noqa: E731
    try:
        if client is not None:
            deadline = time.monotonic() + 20
            while not wait() and time.monotonic() < deadline:
                time.sleep(0.02)
            time.sleep(0.5)
        fan = Outputs(outs)
        fan.mode = "3d"
        dt_us = 5000
        step = quat.from_axis_angle((0.0, 0.0, 1.0), math.radians(90.0) * dt_us / 1e6)
        q = (1.0, 0.0, 0.0, 0.0)
        poses = []
        for _ in range(samples):
            q = tuple(float(v) for v in quat.multiply(q, step))
            poses.append(q)
        gyro, accel = (0.0, 0.0, 90.0), (0.0, 0.0, 1.0)
        t0 = time.process_time()
        for i, q in enumerate(poses):
            t_us = 1_000_000 + i * dt_us
            if fan.wants_pose:  # as the daemon does
                fan.publish_orientation(q, t_us)
            fan.publish_motion(gyro, accel, t_us, q)
            if i % 200 == 199:
                time.sleep(0.01)  # let the clients read (as at the real rate) without counting it
        cpu = time.process_time() - t0
        fan.stop()
    finally:
        if client is not None:
            client.kill()
            client.wait()
        shutil.rmtree(folder, ignore_errors=True)
    return cpu


def output_costs(samples: int = 4000, repeats: int = 3) -> dict:
    """Extra CPU of each output over the fan-out alone, as % of one core at 200 samples/s (median of
    ``repeats`` interleaved runs)."""
    from statistics import median

    runs = {k: [] for k in (None, "spacenav", "dsu")}
    for _ in range(repeats):
        for k in runs:
            runs[k].append(output_cost(k, samples))
    base = median(runs[None])
    return {k: (median(v) - base) / samples * 200 * 100 for k, v in runs.items() if k}


def _print_dsu(f: dict, h: dict) -> None:
    print()
    print("dsu output, sphere-mouse --replay sim_turn_90.bin (pointer mode), a client written from the description")
    rows = [("pad data packets/s (sphere's clock)", ">= 100", f"{f['packets_per_s_device']:.1f}"),
            ("  as they arrived", "", f"{f['packets_per_s_arrival']:.1f}"),
            ("bad CRCs", "0", str(f["bad_crc"])),
            ("gyro yaw in the turn (deg/s)", "90", f"{f['yaw_dps']:.2f}"),
            ("  error", "within 2 %", f"{f['yaw_error_pct']:+.2f} %"),
            ("pitch, roll in the turn (max deg/s)", "~0", f"{f['pitch_roll_max_dps']:.2f}"),
            ("accel lying still (g)", "0 -1 0", " ".join(f"{v:+.3f}" for v in f["accel_still_g"])),
            ("buttons", "A A B", " ".join(f["buttons"])),
            ("foreign + truncated datagrams ignored", "2", str(f["server_ignored"])),
            ("10,000 hostile datagrams: exit status", "0", str(h["flood"]["rc"])),
            ("  received / ignored / kernel drops", "10000", f"{h['flood']['received']} / {h['flood']['ignored']} / "
                                                        f"{h['flood']['kernel_drops']}"),
            ("  pointer moves, calm / flooded", "equal", f"{h['calm']['moves']} / {h['flood']['moves']}")]
    for label, target, value in rows:
        print(f"{label:40s}{target:>12s}{value:>24s}")


def main(argv=None) -> int:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", metavar="OUT", help="also write the figures as JSON")
    args = ap.parse_args(argv)
    why = libspnav_missing()
    if why:
        print(f"outputs_bench: {why}", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory() as d:
        res = {"spacenav": spacenav_turns(Path(d)), "spacenav_hostile": run_spnav_hostile(Path(d)),
               "dsu": dsu_figures(run_dsu_turn(Path(d))), "dsu_hostile": run_dsu_hostile(Path(d)),
               "cost_pct": output_costs()}
    _print_spacenav(res["spacenav"])
    h = res["spacenav_hostile"]
    print("hostile clients (random bytes, 1,000 connects, one that never reads) during a replay, pointer mode:")
    for label, target, value in (
            ("exit status", "0", h["hostile"]["rc"]),
            ("pointer moves, calm / hostile", "equal", f"{h['calm']['moves']} / {h['hostile']['moves']}"),
            ("good client: ry summed, calm / hostile", "1571", f"{h['calm']['good']['sums'][4]} / "
                                                               f"{h['hostile']['good']['sums'][4]}"),
            ("good client: zero events", "1", h["hostile"]["good"]["zero_events"]),
            ("clients dropped (said in the log)", "1", h["hostile"]["dropped_logged"]),
            ("daemon memory growth, calm / hostile (KiB)", "alike",
             f"{h['calm']['rss_growth_kib']} / {h['hostile']['rss_growth_kib']}")):
        print(f"  {label:38s}{target:>12s}{str(value):>16s}")
    _print_dsu(res["dsu"], res["dsu_hostile"])
    print()
    print("extra CPU of the daemon's loop and the output's thread, a client connected and reading, 200 samples/s")
    for k, v in res["cost_pct"].items():
        print(f"{k:40s}{'<= 0.5 %':>12s}{v:>20.3f} % of a core")
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
