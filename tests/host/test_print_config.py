"""sphere-mouse --print-config is a commented config file that loads to exactly the defaults; --version."""

import subprocess
import sys

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

from sphere import __version__
from sphere.daemon.config import Config, load


def mouse(*args):
    return subprocess.run([sys.executable, "-m", "sphere.mouse", *args], capture_output=True, text=True, timeout=60)


def test_print_config_is_the_defaults_commented(tmp_path):
    r = mouse("--print-config")
    assert r.returncode == 0, r.stderr
    text = r.stdout
    parsed = tomllib.loads(text)
    defaults = Config().as_dict()
    flat = {}
    for name, keys in defaults.items():
        node = parsed
        for part in name.split("."):
            node = node[part]
        flat[name] = {k: node[k] for k in keys}
    assert flat == defaults
    lines = text.splitlines()
    for i, line in enumerate(lines):  # every key has its meaning in a comment right above it
        if "=" in line and not line.startswith("#"):
            assert lines[i - 1].startswith("# "), line
    assert "[outputs.opentrack]" in text and "one of: pointer, tilt, 3d" in text
    path = tmp_path / "config.toml"
    path.write_text(text)
    assert load(path).as_dict() == defaults
    r = mouse("--config", str(path), "--check-config")
    assert r.returncode == 0 and "config OK" in r.stdout


def test_version():
    r = mouse("--version")
    assert r.returncode == 0 and r.stdout.strip() == f"sphere-mouse {__version__}"
