"""`sphere sim` shows its progress in simulated seconds (tqdm on stderr) when asked, the figures stay clean."""

import os
import subprocess
import sys

import pytest

from simscenarios import need_board, need_firmware


@pytest.mark.slow
def test_sphere_sim_shows_simulated_seconds(tmp_path):
    need_board()
    need_firmware()
    env = dict(os.environ, SPHERE_PROGRESS="1")
    r = subprocess.run([sys.executable, "-m", "sphere.cli", "sim", "--trace", "synthetic:still", "--seconds", "3",
                        "--capture", str(tmp_path / "c.cap")], capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stderr
    frames = r.stderr.replace("\r", "\n")
    assert "sim synthetic:still:" in frames and "/3.0 simulated s" in frames
    assert "%|" not in r.stdout  # the figures stay clean
