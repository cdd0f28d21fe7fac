"""`sphere service install|print`: the systemd user unit for sphere-mouse, written for this installation.

The unit shipped in the package (host/packaging/sphere-mouse.service) names ``%h/.local/bin/sphere-mouse``
(``pip install --user``); this command writes it with the ``sphere-mouse`` that sits beside the running
Python (a virtual environment's bin folder, wherever it is) and points ``Documentation=`` at the daemon's
manual installed with the package.

``--spnav-link`` also writes a systemd-tmpfiles rule that makes ``/run/spnav.sock`` (``/var/run/spnav.sock``,
libspnav's default socket and the path Blender checks before it looks for a 3-D mouse) a link to the
socket of sphere-mouse's ``[outputs.spacenav]``. The rule goes into the user's config folder; installing
it under /etc needs root, so the command prints the two ``sudo`` lines and runs neither.
"""

from __future__ import annotations

import os
import re
import shutil
import sys
from pathlib import Path

from sphere.daemon.config import ConfigError, load
from sphere.daemon.outputs.spacenav import SYSTEM_SOCKET, default_socket_path, socket_owner
from sphere.paths import DATA_DIR, config_file

HELP = "write the systemd user unit for sphere-mouse with this installation's paths"
UNIT_NAME = "sphere-mouse.service"


def add_arguments(p) -> None:
    p.add_argument("action", choices=("install", "print"),
                   help="install: write ~/.config/systemd/user/sphere-mouse.service; print: show it")
    p.add_argument("--force", action="store_true", help="replace a unit that differs from the one this writes")
    p.add_argument("--spnav-link", action="store_true",
                   help="also write a systemd-tmpfiles rule linking /run/spnav.sock (where Blender looks for a 3-D "
                        "mouse) to sphere-mouse's [outputs.spacenav] socket, and print the sudo commands that install it")


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


SPNAV_RULE_NAME = "sphere-mouse-spnav.conf"


def spnav_socket() -> str:
    """The socket sphere-mouse's [outputs.spacenav] serves when started by the user unit."""
    try:
        configured = load()["outputs.spacenav"].socket
    except ConfigError:
        configured = ""
    env = dict(os.environ)
    env.setdefault("XDG_RUNTIME_DIR", f"/run/user/{os.getuid()}")  # what systemd gives the user unit
    return configured or default_socket_path(env)


def write_spnav_rule() -> int:
    target = spnav_socket()
    rule = (f"# sphere-mouse: libspnav's default socket ({SYSTEM_SOCKET}, the one Blender checks) leads to the\n"
            f"# sphere's 3-D mouse ([outputs.spacenav]). 'L' leaves an existing {SYSTEM_SOCKET} (spacenavd's) alone.\n"
            f"L /run/spnav.sock - - - - {target}\n")
    dest = config_file().parent / SPNAV_RULE_NAME
    try:
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_text(rule)
    except OSError as e:
        print(f"sphere service: cannot write {dest}: {e.strerror}; check $XDG_CONFIG_HOME (or ~/.config) is a "
              "folder you can write", file=sys.stderr)
        return 2
    print(f"wrote {dest} (/run/spnav.sock -> {target}); to install it, as root:")
    print(f"  sudo install -m 644 {dest} /etc/tmpfiles.d/{SPNAV_RULE_NAME}")
    print(f"  sudo systemd-tmpfiles --create /etc/tmpfiles.d/{SPNAV_RULE_NAME}")
    if socket_owner(SYSTEM_SOCKET) == "live":
        print(f"sphere service: a running spacenavd owns {SYSTEM_SOCKET}; the link waits until it is stopped "
              "(sudo systemctl disable --now spacenavd)")
    return 0


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
    return write_spnav_rule() if args.spnav_link else 0
