"""`sphere decode` on the bundled example capture and on unusable input (run as a user would)."""

import json
import os
import subprocess
import sys

import pytest

from sphere.paths import repo_path
from sphere.protocol import Orientation, encode_frame

EXAMPLE = repo_path("protocol", "examples", "broad_fast_rotation_4s.cap")


def sphere(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "sphere.cli", *args], capture_output=True, text=True, cwd=cwd, timeout=60)


def test_example_capture_decodes_to_jsonl():
    r = sphere("decode", str(EXAMPLE), "--jsonl")
    assert r.returncode == 0, r.stderr
    lines = [json.loads(line) for line in r.stdout.splitlines()]
    types = [o["type"] for o in lines]
    assert types[0] == "hello" and lines[0]["protocol_version"] == 1
    assert types.count("raw_sample") == 800 and types.count("orientation") == 400 and types.count("status") == 4
    raw = next(o for o in lines if o["type"] == "raw_sample")
    assert set(raw) == {"type", "seq", "t_us", "flags", "accel", "gyro", "mag"}
    assert all(isinstance(v, float) for v in raw["accel"])  # physical units (g)
    times = [o["t_us"] for o in lines if o["type"] == "raw_sample"]
    assert all(b - a == 5000 for a, b in zip(times, times[1:]))  # 200 Hz clock
    summary = json.loads(r.stderr.strip().splitlines()[-1])
    assert summary["frames_ok"] == len(lines) and summary["crc_errors"] == 0 and summary["seq_gaps"] == 0


def test_raw_flag_prints_wire_integers():
    r = sphere("decode", str(EXAMPLE), "--jsonl", "--raw", "--type", "orientation")
    first = json.loads(r.stdout.splitlines()[0])
    assert first["type"] == "orientation" and all(isinstance(v, int) for v in first["quat"])


def test_missing_file(tmp_path):
    r = sphere("decode", str(tmp_path / "nope.cap"))
    assert r.returncode == 2 and "no such capture file" in r.stderr and "sphere capture" in r.stderr


def test_empty_file(tmp_path):
    (tmp_path / "empty.cap").write_bytes(b"")
    r = sphere("decode", str(tmp_path / "empty.cap"))
    assert r.returncode == 1 and "is empty" in r.stderr


def test_pure_noise(tmp_path):
    (tmp_path / "noise.cap").write_bytes(os.urandom(5000))
    r = sphere("decode", str(tmp_path / "noise.cap"), "--jsonl")
    assert r.returncode == 1 and "no valid frame" in r.stderr and "baud" in r.stderr
    assert r.stdout == ""


def test_a_capture_cut_in_the_middle_of_a_frame_says_so(tmp_path):
    """The bytes after the last delimiter are a frame the recording stopped in: decoded frames as before, and the
    summary counts them instead of leaving them out of every figure."""
    data = EXAMPLE.read_bytes()
    cut = data[:777]
    unfinished = len(cut) - cut.rindex(b"\x00") - 1
    assert unfinished > 0
    (tmp_path / "cut.cap").write_bytes(cut)
    r = sphere("decode", str(tmp_path / "cut.cap"), "--jsonl")
    summary = json.loads(r.stderr.strip().splitlines()[-1])
    assert r.returncode == 0 and summary["bytes_unfinished"] == unfinished and summary["frames_ok"] == 30
    r = sphere("decode", str(tmp_path / "cut.cap"))
    assert r.returncode == 0 and f"the last {unfinished} bytes are a frame the capture ends in the middle of" in r.stderr
    whole = sphere("decode", str(EXAMPLE), "--jsonl")
    assert json.loads(whole.stderr.strip().splitlines()[-1])["bytes_unfinished"] == 0
    assert "middle" not in sphere("decode", str(EXAMPLE)).stderr


def test_damaged_capture_still_decodes_what_is_intact(tmp_path):
    data = bytearray(EXAMPLE.read_bytes())
    for i in range(100, len(data), 997):  # a bit flip every ~1 kB
        data[i] ^= 0x04
    (tmp_path / "damaged.cap").write_bytes(bytes(data))
    r = sphere("decode", str(tmp_path / "damaged.cap"), "--jsonl")
    assert r.returncode == 0
    summary = json.loads(r.stderr.strip().splitlines()[-1])
    assert summary["crc_errors"] + summary["framing_errors"] >= 25
    assert summary["frames_ok"] >= 1205 - 2 * 32


def test_capture_records_a_real_serial_port(tmp_path):
    """`sphere capture` on a pty (pyserial opens the slave side as it would /dev/ttyUSB0)."""
    pytest.importorskip("serial")
    import tty

    master, slave = os.openpty()
    tty.setraw(slave)
    name = os.ttyname(slave)
    os.close(slave)  # nobody else holds the port (sphere capture refuses a port another program has open)
    out = tmp_path / "rec.cap"
    proc = subprocess.Popen(
        [sys.executable, "-m", "sphere.cli", "capture", "--port", name, "--out", str(out), "--times", "--seconds", "30"],
        stderr=subprocess.PIPE, text=True,
    )
    import time

    sent = b"".join(encode_frame(Orientation(i * 10000, 1, (16384, 0, 0, 0)), i & 0xFF) for i in range(300))
    from sphere.link.port import holders

    deadline = time.time() + 60
    while proc.pid not in [pid for pid, _ in holders(name)] and time.time() < deadline:
        time.sleep(0.05)  # until it has the port open (a busy machine takes a while to start Python)
    for i in range(0, len(sent), 100):
        os.write(master, sent[i : i + 100])
        time.sleep(0.005)
    deadline = time.time() + 10
    while time.time() < deadline and (not out.exists() or out.stat().st_size < len(sent)):
        time.sleep(0.05)
    os.close(master)  # the "device" goes away: capture must keep what it has and say so
    proc.wait(timeout=15)
    assert out.read_bytes() == sent
    sidecar = (tmp_path / "rec.cap.rx.csv").read_text().splitlines()
    assert sidecar[0] == "byte_offset,host_time_s" and len(sidecar) > 1
    r = sphere("decode", str(out), "--jsonl")
    assert r.returncode == 0 and len(r.stdout.splitlines()) == 300


def test_capture_on_a_missing_port_says_what_to_do(tmp_path):
    r = sphere("capture", "--port", "/dev/ttyNOPE9", "--out", str(tmp_path / "x.cap"))
    assert r.returncode == 2 and "cannot open /dev/ttyNOPE9" in r.stderr and "list_ports" in r.stderr


def test_protocol_budget_matches_spec():
    from sphere.protocol.budget import budget_table

    spec = repo_path("protocol", "spec.md").read_text()
    begin, end = "<!-- link-budget:begin -->\n", "\n<!-- link-budget:end -->"
    table = spec[spec.index(begin) + len(begin) : spec.index(end)]
    assert table == budget_table(), "protocol/spec.md §6 differs from `sphere protocol budget`: paste the new table"
