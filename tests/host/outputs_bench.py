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

The tests (tests/host/test_spacenav.py) run the same functions and assert the targets.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
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
        res = {"spacenav": spacenav_turns(Path(d))}
    _print_spacenav(res["spacenav"])
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
