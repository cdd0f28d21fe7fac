"""`sphere bench decode`: its figures are written where asked, and its side-by-side mode runs both trees and
prints each row's ratio. No timing is asserted."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # runs the benchmark (./scripts/test --quick leaves it out)

ROOT = Path(__file__).resolve().parents[2]


def _bench(*args):
    return subprocess.run([sys.executable, "-m", "sphere.cli", "bench", "decode", "--seconds", "0.5", "--repeat", "1",
                           *args], capture_output=True, text=True, timeout=240, cwd=ROOT)


def test_one_tree_prints_and_writes_every_feed_size(tmp_path):
    out = _bench("--json", str(tmp_path / "d.json"))
    assert out.returncode == 0, out.stderr
    r = json.loads((tmp_path / "d.json").read_text())
    assert r["frames"] == 201 and set(r["frames_per_s"]) == {"1", "64", "4096", "0"}
    assert all(v > 0 for v in r["frames_per_s"].values()) and r["empty_method_byte_fed_frames_per_s"] > 0
    for label in ("1", "64", "4096", "whole stream"):
        assert any(line.split()[:len(label.split())] == label.split() for line in out.stdout.splitlines()), label


def test_side_by_side_with_a_revision_of_this_repository():
    if not (ROOT / ".git").exists():
        pytest.skip("[optional] not a git checkout: --against compares revisions of one")
    out = _bench("--against", "HEAD", "--pairs", "1")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert sum("pair 1/1" in line for line in lines) == 2
    table = lines[[i for i, line in enumerate(lines) if line.startswith("medians of 1 runs each")][0] + 2:]
    assert [row.rsplit(None, 3)[0].strip() for row in table] == ["1", "64", "4096", "whole stream", "empty method, 1"]
    for row in table:
        this, other, ratio = (float(v.replace(",", "")) for v in row.split()[-3:])
        assert this > 0 and other > 0 and ratio == pytest.approx(this / other, abs=0.01)
