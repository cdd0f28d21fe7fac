"""The daemon's latency/CPU benchmark (python -m sphere.bench.daemon): what it measures is what the kernel
says, its side-by-side mode runs, and bad arguments get a clear line and exit 2. No timing is asserted."""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sphere.bench import daemon as bench

pytestmark = pytest.mark.slow  # runs the benchmark (./scripts/test --quick leaves it out)

ROOT = Path(__file__).resolve().parents[2]


def _bench(*args, timeout=240):
    return subprocess.run([sys.executable, "-m", "sphere.bench.daemon", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT)


def test_cpu_time_of_a_child_agrees_with_the_kernels_rusage():
    """proc_cpu_s (schedstat, read while the process runs) against getrusage of the same child once reaped."""
    child = subprocess.Popen([sys.executable, "-c",
                              "import time, sys\nt = time.process_time()\nwhile time.process_time() - t < 0.4: pass\n"
                              "sys.stdout.write('x'); sys.stdout.flush(); time.sleep(30)"],
                             stdout=subprocess.PIPE)
    try:
        assert child.stdout.read(1) == b"x"
        seen = bench.proc_cpu_s(child.pid)
    finally:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        child.kill()
        child.wait()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    kernel = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    assert seen >= 0.4
    assert abs(seen - kernel) < 0.05, (seen, kernel)


def test_json_run_reports_every_figure():
    out = _bench("--json", "--seconds", "1")
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout.strip().splitlines()[-1])
    for key, _ in bench.COMPARED:
        assert r[key] > 0, key
    assert r["calls"] >= 150 and r["frames"] >= r["calls"]
    assert r["after_read_p50_us"] < r["p50_us"]


def test_side_by_side_with_a_revision_of_this_repository():
    if not (ROOT / ".git").exists():
        pytest.skip("[optional] not a git checkout: --against compares revisions of one")
    out = _bench("--against", "HEAD", "--pairs", "1", "--seconds", "0.5")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert sum("pair 1/1" in line for line in lines) == 2
    table = lines[[i for i, line in enumerate(lines) if line.startswith("medians of 1 runs each")][0] + 2:]
    for (_, label), row in zip(bench.COMPARED, table):
        assert row.strip().startswith(label), (label, row)
        this, other, ratio = (float(v) for v in row.split()[-3:])
        # the figures are printed to 0.01: their ratio is known to that rounding (a 5 ms p99 beside 28 µs under
        # load is 181.01 printed, 181.02 from the printed figures)
        r = this / other
        assert this > 0 and other > 0 and ratio == pytest.approx(r, abs=0.005 + r * (0.005 / this + 0.005 / other))


@pytest.mark.parametrize("args, says", [
    (["--against", "no-such-revision"], "not a commit"),
    (["--seconds", "-1"], "--seconds"),
    (["--pairs", "0", "--against", "HEAD"], "--pairs"),
])
def test_bad_arguments_are_one_line_and_exit_2(args, says):
    t0 = time.monotonic()
    out = _bench(*args, timeout=60)
    assert out.returncode == 2, (out.stdout, out.stderr)
    assert says in out.stderr and "Traceback" not in out.stderr
    assert time.monotonic() - t0 < 30
    assert os.path.isdir(ROOT / "host")  # nothing was extracted over the checkout


def test_a_setting_reaches_every_part_of_the_measurement():
    """--set gyro.auto_bias=false: the in-process parts build the daemon with it, and the sphere-mouse
    subprocess of the CPU run accepts the same override (a bad key is refused as sphere-mouse refuses it)."""
    settings = bench._settings(["gyro.auto_bias=false"])
    cfg = bench._config(settings)
    assert cfg.gyro.auto_bias is False and cfg["outputs.page"].enabled is False
    assert bench._config({}).gyro.auto_bias is True
    assert bench.work_per_frame_us(frames=200, passes=1, settings=settings) > 0
    out = _bench("--json", "--seconds", "0.5", "--set", "gyro.auto_bias=false")
    assert out.returncode == 0, out.stderr
    bad = _bench("--set", "gyro.nope=1", timeout=60)
    assert bad.returncode == 2 and "nope" in bad.stderr and "Traceback" not in bad.stderr


def test_cpu_between_two_readings_never_goes_down_when_a_thread_ends():
    """A thread that ran 80 ms and ended between the readings took its total with it: the sum of the second
    reading is smaller than the first's (a -15 % CPU share was printed at load 6), each live thread's increase is not."""
    before = {"100": 500_000_000, "101": 80_000_000}
    after = {"100": 510_000_000, "102": 2_000_000}
    assert sum(after.values()) < sum(before.values())
    assert bench.cpu_between(before, after) == pytest.approx(0.012)
