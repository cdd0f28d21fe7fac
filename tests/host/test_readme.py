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
            # everything that needs no sphere plugged in (`sphere-mouse` alone waits for one)
            if cmd.startswith(("sphere ", "sphere-mouse ")) and "--port" not in cmd:
                yield cmd


COMMANDS = list(example_commands())


def test_readme_has_examples_and_the_two_commands():
    assert "./scripts/demo" in README and "./scripts/test" in README
    assert len(COMMANDS) >= 3


@pytest.mark.parametrize("cmd", COMMANDS)
def test_readme_example_runs(cmd):
    argv = shlex.split(cmd)
    # shortened with the commands' own options: the figures themselves come from running them by hand
    shorter = {
        ("sphere", "bench", "decode"): ["--seconds", "2", "--repeat", "1"],
        ("sphere", "bench", "pointer"): ["--seconds", "30", "--filters", "none,one-euro"],
        ("sphere", "eval"): ["--only", "07", "--seconds", "40", "--jobs", "1"],
    }
    for prefix, extra in shorter.items():
        if tuple(argv[: len(prefix)]) == prefix:
            argv += extra
    module = "sphere.mouse" if argv[0] == "sphere-mouse" else "sphere.cli"
    r = subprocess.run([sys.executable, "-m", module, *argv[1:]], cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() or r.stderr.strip()


def test_ci_runs_the_readme_test_command():
    ci = (REPO_ROOT / ".ci" / "run").read_text()
    assert "./scripts/test" in ci and "./scripts/test" in README
