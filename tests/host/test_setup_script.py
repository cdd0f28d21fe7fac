"""./scripts/setup run again needs no network when nothing is missing: no pip upgrade, no reinstall."""

import shutil
import subprocess

import pytest

from sphere.paths import REPO_ROOT

EXTRAS_LINE = "EXTRAS='"


def _stamp_current() -> bool:
    setup = (REPO_ROOT / "scripts" / "setup").read_text()
    extras = setup.split(EXTRAS_LINE, 1)[1].split("'", 1)[0]
    stamp = REPO_ROOT / ".venv" / ".sphere-setup"
    want = (REPO_ROOT / "pyproject.toml").read_text().rstrip("\n") + "\n" + extras
    return stamp.is_file() and stamp.read_text() == want


def test_setup_again_offline():
    if not _stamp_current():
        pytest.skip("[optional] .venv was not set up from this pyproject.toml yet (./scripts/setup does it)")
    if shutil.which("unshare") is None or subprocess.run(["unshare", "-rn", "true"]).returncode != 0:
        pytest.skip("[optional] cannot make a network namespace here (unshare -rn)")
    r = subprocess.run(["unshare", "-rn", str(REPO_ROOT / "scripts" / "setup")], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    assert "installing" not in r.stdout + r.stderr and "creating" not in r.stdout
    assert r.stdout.strip().endswith("setup: ready (.venv/bin/sphere, .venv/bin/sphere-mouse)")
