"""The README's example commands run as written, as a new user runs them: from the wheel installed into a
fresh environment, in a folder outside the checkout, with an empty home (so the virtual board is built on
first use into the user's cache). Commands that need a sphere plugged in are left out."""

import os
import re
import shlex
import shutil
import site
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from sphere.paths import REPO_ROOT, broad_dir

pytestmark = pytest.mark.slow  # builds and installs the wheel (./scripts/test --quick leaves it out)

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

# shortened with the commands' own options: the figures themselves come from running them by hand
SHORTER = {
    ("sphere", "bench", "decode"): ["--seconds", "2", "--repeat", "1"],
    ("sphere", "bench", "pointer"): ["--seconds", "30", "--filters", "none,one-euro"],
    ("sphere", "bench", "latency"): ["--seconds", "6", "--adapters", "none", "--bauds", "115200", "--no-monitor"],
    ("sphere", "bench", "baud-switch"): ["--rounds", "4"],
    ("sphere", "eval"): ["--only", "07", "--seconds", "40", "--jobs", "1"],
}


def _stage_source(dest: Path) -> Path:
    """The files a wheel is built from, with the package's data links resolved (as a build would)."""
    skip = shutil.ignore_patterns("__pycache__", "*.pyc", "build", "app", "core", "libcore.a", "*.egg-info",
                                  "testfw", "make_captures.sh")
    shutil.copytree(REPO_ROOT / "host" / "sphere", dest / "host" / "sphere", symlinks=False, ignore=skip)
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(REPO_ROOT / name, dest / name)
    return dest


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(environment variables, working folder) for running the installed commands."""
    from sphere.sim.board import BoardUnavailable, firmware_elf

    try:
        firmware_elf(build=True)  # the wheel ships the image `make -C firmware` made
    except BoardUnavailable as e:
        pytest.fail(f"the wheel needs the firmware image: {e}")
    root = tmp_path_factory.mktemp("installed")
    src = _stage_source(root / "src")
    dist = root / "dist"
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation",
                        "--no-index", "-w", str(dist), str(src)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    (wheel,) = dist.glob("*.whl")
    env_dir = root / "env"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(env_dir)], check=True, timeout=120)
    py = env_dir / "bin" / "python"
    r = subprocess.run([sys.executable, "-m", "pip", "--python", str(py), "install", "-q", "--no-deps",
                        "--no-index", str(wheel)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    # the dependencies come from this environment's site-packages (a plain path line: its .pth files,
    # among them the checkout's editable install, are not read)
    purelib = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                             capture_output=True, text=True, check=True).stdout.strip()
    ours = {sysconfig.get_paths()["purelib"], *site.getsitepackages()}
    (Path(purelib) / "_deps_from_test_env.pth").write_text("\n".join(sorted(ours)) + "\n")
    home = root / "home"
    work = root / "somewhere"
    home.mkdir()
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("SPHERE_", "XDG_", "PYTHON", "VIRTUAL_ENV"))}
    env.update(HOME=str(home), PATH=f"{env_dir / 'bin'}:{env['PATH']}", SPHERE_BROAD_DIR=str(broad_dir()))
    env.pop("DISPLAY", None)
    return env, work, env_dir


def test_readme_has_examples_and_the_two_commands():
    assert "./scripts/demo" in README and "./scripts/test" in README
    assert len(COMMANDS) >= 3


def test_the_installed_package_is_not_the_checkout(installed):
    env, work, env_dir = installed
    r = subprocess.run(["python", "-c", "import sphere, sphere.paths as p; print(sphere.__file__, p.in_checkout())"],
                       cwd=work, env=env, capture_output=True, text=True, check=True)
    where, checkout = r.stdout.split()
    assert Path(where).is_relative_to(env_dir) and checkout == "False"
    data = Path(where).parent / "data"
    for shipped in ("examples/broad_fast_rotation_4s.cap", "vectors/frames.txt", "sim/sphere_board.c",
                    "firmware/sphere.elf", "firmware/sphere.hex", "docs/sphere-mouse.md",
                    "packaging/sphere-mouse.service"):
        assert (data / shipped).is_file() and not (data / shipped).is_symlink(), shipped


@pytest.mark.parametrize("cmd", COMMANDS)
def test_readme_example_runs_installed(cmd, installed):
    env, work, _ = installed
    argv = shlex.split(cmd)
    for prefix, extra in SHORTER.items():
        if tuple(argv[: len(prefix)]) == prefix:
            argv += extra
    r = subprocess.run(argv, cwd=work, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, f"{cmd}\n{r.stderr[-3000:]}"
    assert r.stdout.strip() or r.stderr.strip()
    assert "Traceback" not in r.stderr


def test_ci_runs_the_readme_test_command():
    ci = (REPO_ROOT / ".ci" / "run").read_text()
    assert "./scripts/test" in ci and "./scripts/test" in README


def test_the_demo_uses_the_settings_by_their_current_names():
    """scripts/demo's own sphere-mouse arguments are read without a note that a setting was renamed (it printed
    "[source] sim_seconds is now [source.simulate] seconds" at every demo start)."""
    line = next(ln for ln in (REPO_ROOT / "scripts" / "demo").read_text().splitlines() if ln.startswith("exec "))
    argv = [a for a in shlex.split(line)[1:] if a != "$@"]
    assert argv[0] == "sphere-mouse"
    r = subprocess.run([str(Path(sys.executable).parent / "sphere-mouse"), *argv[1:], "--check-config"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert "is now" not in r.stderr and "config OK" in r.stdout, r.stderr
