"""The bad-input battery of issue 14, run as a user would run it: every case is one clear line on stderr and
the documented exit status (2 for a bad flag, file or setting; 1 for a device that went away or a disk that
filled up, with what was kept), never a traceback, never a run that does not end."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
import tty

import pytest

from sphere.daemon.scripted_sphere import script_bytes

pytestmark = pytest.mark.slow  # a command per case, many in subprocesses (./scripts/test --quick leaves it out)

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def run(module, *argv, timeout=60, env=None, cwd=None):
    e = dict(os.environ)
    e.update(env or {})
    return subprocess.run([sys.executable, "-m", module, *argv], capture_output=True, text=True, timeout=timeout,
                          env=e, cwd=cwd)


def mouse(*argv, **kw):
    return run("sphere.mouse", "--no-stream", "--backend", "log", "--quiet", *argv, **kw)


def sphere(*argv, **kw):
    return run("sphere.cli", *argv, **kw)


def clear(r, status, words=""):
    """One clear line: the status, the words, no traceback."""
    assert "Traceback" not in r.stderr, r.stderr
    assert r.returncode == status, (r.returncode, r.stderr)
    assert words.lower() in r.stderr.lower(), r.stderr
    return r


@pytest.fixture
def home(tmp_path):
    """An empty config home, so that the user's own file plays no part."""
    (tmp_path / "xdg").mkdir()
    return {"XDG_CONFIG_HOME": str(tmp_path / "xdg")}


@pytest.fixture
def capture_file(tmp_path):
    p = tmp_path / "c.bin"
    p.write_bytes(script_bytes([("still", 0.3), ("turn", (0, 0, 1), 10.0, 0.3)]))
    return p


# ---- sphere-mouse: config file, flags, settings ----

@pytest.mark.parametrize("argv, words", [
    (["--set", "tilt.max_speed_px_s=inf"], "finite"),
    (["--set", "tilt.max_speed_px_s=nan"], "finite"),
    (["--sensitivity", "1e-306"], "slow_deg_per_width"),
    (["--sensitivity", "1e308"], "slow_deg_per_width"),
    (["--set", f"output.screen_width_px={2 ** 70}"], "too large"),
    (["--set", "output.screen_width_px=-1"], "screen_width_px"),
    (["--baud", "1000000000000"], "baud"),
    (["--baud", "0"], "baud"),
    (["--set", "nosuch.key=1"], "unknown section"),
    (["--set", "pointer.axes=sideways"], "must be one of"),
    (["--set", "pointer"], "SECTION.KEY=VALUE"),
    (["--stream-port", "70000"], "TCP port"),
    (["--speed", "-1"], "speed"),
    (["--set", "source.serial.usb_ids=[\"xyz\"]"], "VID:PID"),
    (["--set", "source.discovery_timeout_s=1e300"], "discovery_timeout_s"),
    (["--set", "status.interval_s=0"], "interval_s"),
    (["--set", "source.kind=\"camera2\""], "must be one of"),
])
def test_mouse_bad_settings(home, argv, words):
    clear(mouse("--check-config", *argv, env=home), 2, words)


@pytest.mark.parametrize("content, words", [
    (b"\xff\xfe[\x00p\x00o\x00", "not a UTF-8"),  # a file saved as UTF-16 by an editor
    (b"[pointer\n", "not valid TOML"),
    (b"[pointer]\nslow_deg_per_width = inf\n", "finite"),
    (b"[paths]\nbroad = 1\n[pointr]\n", "unknown section"),
])
def test_mouse_bad_config_file(tmp_path, home, content, words):
    cfg = tmp_path / "config.toml"
    cfg.write_bytes(content)
    clear(mouse("--config", str(cfg), env=home), 2, words)


def test_mouse_config_that_is_a_folder_or_missing(tmp_path, home):
    clear(mouse("--config", str(tmp_path), env=home), 2, "is a folder")
    clear(mouse("--config", str(tmp_path / "nope.toml"), env=home), 2, "no such config file")
    # the default file where a folder on the way is a file: defaults, no traceback
    (tmp_path / "notadir").write_text("x")
    r = mouse("--check-config", env={"XDG_CONFIG_HOME": str(tmp_path / "notadir")})
    assert r.returncode == 0 and "Traceback" not in r.stderr


@pytest.mark.skipif(os.geteuid() == 0, reason="[optional] root reads any folder, so an unreadable one cannot be made")
def test_mouse_unreadable_config_folder(tmp_path):
    d = tmp_path / "xdg" / "sphere-mouse"
    d.mkdir(parents=True)
    (d / "config.toml").write_text("[pointer]\n")
    d.chmod(0)
    try:
        clear(mouse("--check-config", env={"XDG_CONFIG_HOME": str(tmp_path / "xdg")}), 2, "cannot read")
    finally:
        d.chmod(0o755)


# ---- sphere-mouse: sources ----

def test_mouse_replay_of_things_that_are_not_captures(tmp_path, home):
    clear(mouse("--replay", "/dev/zero", env=home), 2, "is a device")
    clear(mouse("--replay", str(tmp_path), env=home), 2, "is a folder")
    clear(mouse("--replay", str(tmp_path / "nope.bin"), env=home), 2, "no such capture")
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    clear(mouse("--replay", str(fifo), env=home), 2, "not a regular file")


def _started(p, until, timeout_s: float = 60.0) -> str:
    """What sphere-mouse wrote to stderr up to the first line ``until(line)`` is true of (a fixed sleep before a
    signal could end a daemon still starting, before its handlers were in place)."""
    seen, got = [], threading.Event()

    def read():
        for line in p.stderr:
            seen.append(line)
            if until(line):
                got.set()
                return

    threading.Thread(target=read, daemon=True).start()
    assert got.wait(timeout_s), "sphere-mouse did not start: " + "".join(seen)
    return "".join(seen)


def test_mouse_replay_stops_at_once_on_sigterm(tmp_path, home):
    """A slow replay (a long pause between packets) still ends within a moment of SIGTERM."""
    cap = tmp_path / "slow.bin"
    cap.write_bytes(script_bytes([("still", 2.0)]))
    p = subprocess.Popen([sys.executable, "-m", "sphere.mouse", "--no-stream", "--backend", "log", "--quiet",
                          "--replay", str(cap), "--speed", "0.001"], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL,
                         text=True, env={**os.environ, **home})
    # its line "source …, backend …" is the last before the handlers go in; the replay waits 5 s for its next packet
    first = _started(p, lambda line: ", backend log, " in line)
    time.sleep(0.2)
    p.send_signal(signal.SIGTERM)
    t0 = time.monotonic()
    _, err = p.communicate(timeout=10)
    err = first + err
    assert time.monotonic() - t0 < 2.0 and p.returncode == 0 and "Traceback" not in err, err


def test_mouse_page_port_another_program_holds(home, capture_file):
    """A second sphere-mouse (or any program) on the page's port: one line saying which flag to change; the pointer
    runs on (it said only asyncio's bind error, no way out)."""
    import socket

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        r = run("sphere.mouse", "--backend", "log", "--quiet", "--replay", str(capture_file), "--speed", "0",
                "--stream-port", str(port), env=home)
    clear(r, 0, f"output page cannot start: cannot listen on 127.0.0.1:{port}: another program")
    assert "set --stream-port PORT ([outputs.page] port), or --no-stream" in r.stderr and "stopped:" in r.stderr, r.stderr


def test_mouse_print_stats_into_a_pipe_closed_early(home, capture_file):
    """`sphere-mouse --replay … --print-stats | head -1`: the reader went away before the figures; that is no error
    (it was a BrokenPipeError traceback and exit status 1)."""
    p = subprocess.Popen([sys.executable, "-m", "sphere.mouse", "--no-stream", "--backend", "log", "--replay",
                          str(capture_file), "--speed", "0", "--print-stats"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env={**os.environ, **home})
    p.stdout.close()  # as head does once it has its line
    err = p.stderr.read()
    p.wait(60)
    assert p.returncode == 0 and "Traceback" not in err and "Exception ignored" not in err, (p.returncode, err)
    assert "stopped:" in err, err


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_mouse_stopped_twice_in_quick_succession_still_exits_0(tmp_path, home, sig):
    """A double Ctrl-C: the second press comes while the first stop finishes. Once the daemon has said its last
    line ("stopped: ...", then --print-stats) the run is over and the exit status is 0, not a death by signal
    (it was: the interpreter's teardown after the last line takes ~0.2 s and SIGINT was back to its default)."""
    cap = tmp_path / "slow.bin"
    cap.write_bytes(script_bytes([("still", 2.0)]))
    p = subprocess.Popen([sys.executable, "-m", "sphere.mouse", "--no-stream", "--backend", "log", "--quiet",
                          "--print-stats", "--replay", str(cap), "--speed", "0.001"], stderr=subprocess.PIPE,
                         stdout=subprocess.PIPE, text=True, env={**os.environ, **home})
    first = _started(p, lambda line: ", backend log, " in line)
    time.sleep(0.2)
    p.send_signal(sig)
    rest = _started(p, lambda line: "stopped:" in line, timeout_s=10)
    alive = p.poll() is None
    p.send_signal(sig)  # the second press, at once
    out, err = p.communicate(timeout=10)
    err = first + rest + err
    assert alive, "the daemon ended before its second signal: nothing was tested"
    assert p.returncode == 0 and "Traceback" not in err, (p.returncode, err)
    assert "sphere-mouse stats: frames" in out, out  # nothing lost: the figures were printed


def test_mouse_whose_teardown_hangs_still_ends_on_ctrl_c(tmp_path, home):
    """After the last lines a stop ends the process at once with the run's status: a teardown that hangs (here a
    thread that never ends, which the interpreter waits for at exit) is not left deaf to Ctrl-C and kill."""
    cap = tmp_path / "slow.bin"
    cap.write_bytes(script_bytes([("still", 2.0)]))
    code = ("import sys, threading; threading.Thread(target=threading.Event().wait).start(); "
            "from sphere.daemon.cli import main; sys.exit(main())")
    p = subprocess.Popen([sys.executable, "-c", code, "--no-stream", "--backend", "log", "--quiet", "--replay",
                          str(cap), "--speed", "0.001"], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
                         env={**os.environ, **home})
    first = _started(p, lambda line: ", backend log, " in line)
    time.sleep(0.2)
    p.send_signal(signal.SIGINT)
    rest = _started(p, lambda line: "stopped:" in line, timeout_s=10)
    time.sleep(0.5)  # the teardown, waiting for the thread
    assert p.poll() is None, "the process ended without waiting: nothing was tested"
    p.send_signal(signal.SIGINT)
    try:
        p.wait(timeout=10)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0, (p.returncode, first + rest)


@pytest.mark.parametrize("nohup", [False, True], ids=["terminal-closed", "under-nohup"])
def test_mouse_sighup_is_a_clean_stop_unless_ignored(tmp_path, home, nohup):
    """Its terminal closed (SIGHUP): the daemon stops as on SIGTERM, the outputs closed (the 3-D mouse's socket
    removed), exit 0; it was a death by SIGHUP with nothing closed. Started under nohup (SIGHUP ignored) it runs on."""
    cap = tmp_path / "slow.bin"
    cap.write_bytes(script_bytes([("still", 2.0)]))
    sock = tmp_path / "spnav.sock"
    p = subprocess.Popen([sys.executable, "-m", "sphere.mouse", "--no-stream", "--backend", "log", "--quiet",
                          "--replay", str(cap), "--speed", "0.001", "--set", "outputs.spacenav.enabled=true", "--set",
                          f"outputs.spacenav.socket={sock}"], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
                         env={**os.environ, **home},
                         preexec_fn=(lambda: signal.signal(signal.SIGHUP, signal.SIG_IGN)) if nohup else None)
    first = _started(p, lambda line: ", backend log, " in line)  # the last line before the handlers go in
    time.sleep(0.2)
    assert sock.exists()
    p.send_signal(signal.SIGHUP)
    if nohup:
        time.sleep(1.0)
        assert p.poll() is None, "sphere-mouse under nohup ended on SIGHUP"
        p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=10)
    err = first + err
    assert p.returncode == 0 and "Traceback" not in err and "stopped:" in err, (p.returncode, err)
    assert not sock.exists(), "the 3-D mouse's socket was left behind"


def test_mouse_named_port_that_is_missing_waits_and_stops(home):
    p = subprocess.Popen([sys.executable, "-m", "sphere.mouse", "--no-stream", "--backend", "log", "--status",
                          "--port", "/dev/ttyNOPE7"], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
                         env={**os.environ, **home})
    first = _started(p, lambda line: line.startswith("waiting for"))  # the status line: the loop runs
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=10)
    err = first + err
    assert p.returncode == 0 and "Traceback" not in err and "waiting for /dev/ttyNOPE7" in err, err


# ---- sphere decode ----

def test_decode_bad_inputs(tmp_path):
    clear(sphere("decode", "/dev/zero"), 2, "is a device")
    clear(sphere("decode", str(tmp_path)), 2, "is a folder")
    clear(sphere("decode", str(tmp_path / "nope.cap")), 2, "no such capture")
    clear(sphere("decode", "/proc/self/mem"), 2, "cannot read")  # a file whose read fails (EIO)
    (tmp_path / "empty.cap").write_bytes(b"")
    clear(sphere("decode", str(tmp_path / "empty.cap")), 1, "is empty")


def test_decode_reads_a_fifo_by_its_contents(tmp_path, capture_file):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    data = capture_file.read_bytes()

    def writer():
        with open(fifo, "wb") as f:
            f.write(data)

    t = threading.Thread(target=writer)
    t.start()
    r = sphere("decode", str(fifo), "--jsonl")
    t.join(10)
    assert r.returncode == 0 and "Traceback" not in r.stderr and len(r.stdout.splitlines()) > 100, r.stderr


# ---- sphere capture ----

def _pty_with_data(stop):
    master, slave = os.openpty()
    tty.setraw(slave)
    name = os.ttyname(slave)
    os.close(slave)
    data = script_bytes([("still", 1.0)])

    def feed():
        while not stop.is_set():
            try:
                os.write(master, data[:2000])
            except OSError:
                pass
            time.sleep(0.05)

    threading.Thread(target=feed, daemon=True).start()
    return master, name


def test_capture_bad_outputs_and_flags(tmp_path):
    stop = threading.Event()
    master, name = _pty_with_data(stop)
    try:
        clear(sphere("capture", "--port", name, "--out", str(tmp_path)), 2, "is a folder")
        clear(sphere("capture", "--port", name, "--out", str(tmp_path / "x.cap"), "--seconds", "-5"), 2, "seconds")
        clear(sphere("capture", "--port", name, "--out", str(tmp_path / "x.cap"), "--baud", "1000000000000"), 2, "baud")
        r = clear(sphere("capture", "--port", name, "--out", "/dev/full", "--seconds", "5", "--quiet"), 1,
                  "no space left")
        assert len(r.stderr.strip().splitlines()) == 1
    finally:
        stop.set()
        os.close(master)
    clear(sphere("capture", "--port", "/dev/ttyNOPE9", "--out", str(tmp_path / "x.cap")), 2, "plugged in")


# ---- sphere sim ----

@pytest.mark.parametrize("argv, words", [
    (["--seconds", "1e9"], "at most 86400"),
    (["--seconds", "-5"], "greater than 0"),
    (["--seconds", "nan"], "greater than 0"),
    (["--capture", "/tmp"], "is a folder"),
    (["--stats", "/tmp"], "is a folder"),
    (["--capture", "/nonexistent-dir/x.bin"], "does not exist"),
])
def test_sim_bad_flags(argv, words):
    clear(sphere("sim", "--trace", "synthetic:still", *argv), 2, words)


def test_output_paths_are_tried_without_leaving_anything(tmp_path):
    """--json and --plot are tried (made and taken away) while the flags are read: a later bad flag leaves no
    file or folder behind, and a file that is there already is kept as it was."""
    kept = tmp_path / "kept.json"
    kept.write_text("mine")
    clear(sphere("eval", "--json", str(tmp_path / "new.json"), "--plot", str(tmp_path / "plots" / "a"), "--jobs", "0"),
          2, "jobs")
    clear(sphere("eval", "--json", str(kept), "--jobs", "0"), 2, "jobs")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.json"] and kept.read_text() == "mine"


def test_an_image_name_matplotlib_cannot_write_is_refused_before_the_run(tmp_path):
    """hybrid-sim --plot (and monitor --plot-out) named x.jpgg: argparse's line, exit 2, nothing run (it was
    matplotlib's ValueError traceback once the run was done)."""
    pytest.importorskip("matplotlib")
    r = clear(sphere("hybrid-sim", "--plot", str(tmp_path / "signals.jpgg")), 2, "image format matplotlib writes")
    assert "wrote" not in r.stderr and not list(tmp_path.iterdir())


def test_a_plot_flag_without_matplotlib_is_refused_before_the_run(tmp_path):
    """Without the plot extra, --plot FILE/DIR is argparse's one line naming the extra, exit 2, before any work
    (hybrid-sim ran the simulation, then ended in an ImportError traceback; eval ran every trial first)."""
    blocked = tmp_path / "blocked"
    blocked.mkdir()
    (blocked / "matplotlib.py").write_text("raise ImportError(\"No module named 'matplotlib'\")\n")
    env = {"PYTHONPATH": os.pathsep.join([str(blocked), os.environ.get("PYTHONPATH", "")])}
    for argv in (["hybrid-sim", "--plot", str(tmp_path / "s.png")], ["eval", "--plot", str(tmp_path / "plots")],
                 ["hybrid-eval", "--plot", str(tmp_path / "plots")],
                 ["monitor", "--port", "/dev/null", "--plot-out", str(tmp_path / "v.png")]):
        clear(sphere(*argv, env=env), 2, "pip install 'marg-sphere[plot]'")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["blocked"]


# ---- sphere calibrate ----

def test_calibrate_bad_flags(tmp_path):
    clear(sphere("calibrate", "--port", "/dev/ttyNOPE9", "--timeout", "-1"), 2, "greater than 0")
    clear(sphere("calibrate", "--capture", str(tmp_path)), 2, "is a folder")
    clear(sphere("calibrate", "--capture", "/dev/zero"), 2, "is a device")
    clear(sphere("calibrate", "--port", "/dev/ttyNOPE9", "--yes"), 2, "plugged in")


def test_calibrate_when_the_port_goes_away(tmp_path):
    """The sphere is unplugged in the middle of the session: one line saying so, exit 1, no SerialException."""
    from sphere.daemon.scripted_sphere import ScriptedSphere, hello_packet

    master, slave = os.openpty()
    tty.setraw(slave)
    name = os.ttyname(slave)
    os.close(slave)
    p = subprocess.Popen([sys.executable, "-m", "sphere.cli", "calibrate", "--port", name, "--yes", "--timeout", "30"],
                         stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    from sphere.link.port import holders

    deadline = time.monotonic() + 60
    while p.pid not in [pid for pid, _ in holders(name)] and time.monotonic() < deadline:
        time.sleep(0.05)  # until it has the port open
    s = ScriptedSphere()
    os.write(master, s.frame(hello_packet()))
    end = time.monotonic() + 2.5
    while time.monotonic() < end:  # moving: the gyro step waits
        for _, f in s.steps([("turn", (0, 0, 1), 30.0, 0.05)]):
            try:
                os.write(master, f)
            except OSError:
                pass
        time.sleep(0.04)
    os.close(master)  # unplugged
    _, err = p.communicate(timeout=20)
    assert "Traceback" not in err and p.returncode == 1, err
    assert "went away" in err or "no RAW_SAMPLE" in err, err
