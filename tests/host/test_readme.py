"""The README's example commands run as written (those that need no sphere plugged in)."""

import re
import shlex
import subprocess
import sys

import pytest

from sphere.paths import REPO_ROOT

README = (REPO_ROOT / "README.md").read_text()


def example_commands():
    blocks = re.findall(r"```sh\n(.*?)```", README, re.S)
    for block in blocks:
        for line in block.splitlines():
            cmd = line.split("#", 1)[0].strip()
            if cmd.startswith("sphere ") and "--port" not in cmd:
                yield cmd


COMMANDS = list(example_commands())


def test_readme_has_examples_and_the_two_commands():
    assert "./scripts/demo" in README and "./scripts/test" in README
    assert len(COMMANDS) >= 3


@pytest.mark.parametrize("cmd", COMMANDS)
def test_readme_example_runs(cmd):
    argv = shlex.split(cmd)
    if argv[:2] == ["sphere", "bench"]:
        argv += ["--seconds", "2", "--repeat", "1"]  # the figure itself comes from running it by hand
    r = subprocess.run([sys.executable, "-m", "sphere.cli", *argv[1:]], cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip()


def test_ci_runs_the_readme_test_command():
    ci = (REPO_ROOT / ".ci" / "run").read_text()
    assert "./scripts/test" in ci and "./scripts/test" in README
