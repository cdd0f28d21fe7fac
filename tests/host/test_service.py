"""`sphere service`: the systemd user unit for this installation: ExecStart is this environment's
sphere-mouse, Documentation= the manual installed with the package; an edited unit is not overwritten."""

import os
import subprocess
import sys
from pathlib import Path
import pytest


def service(tmp_path, *args):
    env = dict(os.environ, XDG_CONFIG_HOME=str(tmp_path))
    return subprocess.run([sys.executable, "-m", "sphere.cli", "service", *args], capture_output=True, text=True,
                          env=env, timeout=60)


@pytest.mark.slow
def test_install_writes_a_unit_for_this_installation(tmp_path):
    r = service(tmp_path, "install")
    assert r.returncode == 0, r.stderr
    unit = tmp_path / "systemd" / "user" / "sphere-mouse.service"
    text = unit.read_text()
    exec_start = next(l for l in text.splitlines() if l.startswith("ExecStart="))
    exe = Path(exec_start.split("=", 1)[1].split()[0])
    assert exe == Path(sys.executable).parent / "sphere-mouse" and os.access(exe, os.X_OK)
    assert "--backend uinput --quiet" in exec_start
    doc = next(l for l in text.splitlines() if l.startswith("Documentation="))
    assert doc.startswith("Documentation=file:///") and Path(doc[len("Documentation=file://"):]).is_file()
    assert "[Install]" in text and "RestartPreventExitStatus=2" in text
    assert service(tmp_path, "install").returncode == 0  # the same again: fine
    unit.write_text(text.replace("--quiet", "--quiet --sensitivity 30"))  # the user's own change
    r = service(tmp_path, "install")
    assert r.returncode == 1 and "differs" in r.stderr and "--force" in r.stderr
    assert "--sensitivity 30" in unit.read_text()
    assert service(tmp_path, "install", "--force").returncode == 0 and unit.read_text() == text


def test_spnav_link_writes_a_tmpfiles_rule_and_says_how_to_install_it(tmp_path):
    env_run = tmp_path / "run"
    r = subprocess.run([sys.executable, "-m", "sphere.cli", "service", "install", "--spnav-link"], capture_output=True,
                       text=True, timeout=60, env=dict(os.environ, XDG_CONFIG_HOME=str(tmp_path),
                                                       XDG_RUNTIME_DIR=str(env_run), SPNAV_SOCKET=""))
    assert r.returncode == 0, r.stderr
    rule = (tmp_path / "sphere-mouse" / "sphere-mouse-spnav.conf").read_text()
    assert f"\nL /run/spnav.sock - - - - {env_run}/spnav.sock\n" in rule
    assert "sudo install -m 644" in r.stdout and "sudo systemd-tmpfiles --create" in r.stdout
