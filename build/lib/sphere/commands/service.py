"""`sphere service install|print`: the systemd user unit for sphere-mouse, written for this installation.

The unit shipped in the package (host/packaging/sphere-mouse.service) names ``%h/.local/bin/sphere-mouse``
(``pip install --user``); this command writes it with the ``sphere-mouse`` that sits beside the running
Python (a virtual environment's bin folder, wherever it is) and points ``Documentation=`` at the daemon's
manual installed with the package.
"""

from __future__ import annotations

import os
import re
import shutil
import sys
from pathlib import Path

from sphere.paths import DATA_DIR

HELP = "write the systemd user unit for sphere-mouse with this installation's paths"
UNIT_NAME = "sphere-mouse.service"


def add_arguments(p) -> None:
    p.add_argument("action", choices=("install", "print"),
                   help="install: write ~/.config/systemd/user/sphere-mouse.service; print: show it")
    p.add_argument("--force", action="store_true", help="replace a unit that differs from the one this writes")


def daemon_executable() -> Path | None:
    """The sphere-mouse of this installation: beside the running interpreter, else on PATH."""
    beside = Path(sys.executable).parent / "sphere-mouse"
    if beside.is_file():
        return beside
    found = shutil.which("sphere-mouse")
    return Path(found).resolve() if found else None


def unit_text(executable: Path) -> str:
    template = (DATA_DIR / "packaging" / UNIT_NAME).read_text()
    manual = DATA_DIR / "docs" / "sphere-mouse.md"
    text = re.sub(r"^ExecStart=\S+", f"ExecStart={executable}", template, count=1, flags=re.M)
    text = re.sub(r"^Documentation=.*$", f"Documentation=file://{manual}", text, count=1, flags=re.M)
    return text


def unit_path() -> Path:
    base = os.environ.get("XDG_CONFIG_HOME") or os.path.join(os.path.expanduser("~"), ".config")
    return Path(base) / "systemd" / "user" / UNIT_NAME


def run(args) -> int:
    exe = daemon_executable()
    if exe is None:
        print("sphere service: no sphere-mouse found beside this Python or on PATH; install the package "
              "with its daemon extra (pip install 'marg-sphere[daemon]')", file=sys.stderr)
        return 1
    text = unit_text(exe)
    if args.action == "print":
        sys.stdout.write(text)
        return 0
    dest = unit_path()
    if dest.exists() and dest.read_text() != text and not args.force:
        print(f"sphere service: {dest} exists and differs; compare with `sphere service print`, "
              "then run again with --force to replace it", file=sys.stderr)
        return 1
    try:
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_text(text)
    except OSError as e:  # a file where a folder belongs ($XDG_CONFIG_HOME), a read-only home
        print(f"sphere service: cannot write {dest}: {e.strerror}; check $XDG_CONFIG_HOME (or ~/.config) is a "
              "folder you can write, or use `sphere service print` and place the unit yourself", file=sys.stderr)
        return 2
    print(f"wrote {dest} (ExecStart={exe})")
    print("now: systemctl --user daemon-reload && systemctl --user enable --now sphere-mouse")
    return 0
