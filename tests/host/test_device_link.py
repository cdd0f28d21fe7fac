"""DeviceLink on a real pty (pyserial on the slave, a responder on the master that follows spec §5: one REPLY per
intact command, echoing its seq): replies matched by seq and type, an idempotent command sent again when its
reply is lost, SAVE_CALIBRATION never repeated, the unplugged port one clear LinkLost."""

from __future__ import annotations

import os
import select
import threading
import time
import tty

import pytest

pytest.importorskip("serial")

from sphere.errors import LinkLost  # noqa: E402
from sphere.link.device import DeviceLink  # noqa: E402
from sphere.protocol import GetCalibration, GetHello, PacketStream, Reply, SaveCalibration, encode_frame  # noqa: E402
from sphere.daemon.scripted_sphere import hello_packet  # noqa: E402
from sphere.link.port import open_port  # noqa: E402


class Responder:
    """The device end: answers every command with a REPLY (ok); drops the first ``drop`` replies; after GET_HELLO
    also sends a HELLO. Sends an unrelated REPLY (another seq) first, as a stale reply would be."""

    def __init__(self, drop: int = 0, silent=()):
        self.master, slave = os.openpty()
        tty.setraw(slave)
        self.name = os.ttyname(slave)
        os.close(slave)
        self.drop = drop
        self.silent = set(silent)  # commands it never answers (carried out, their REPLY lost on the way)
        self.commands: list[str] = []
        self.seq = 0
        self.stop = threading.Event()
        threading.Thread(target=self._run, daemon=True).start()

    def _send(self, packet):
        os.write(self.master, encode_frame(packet, self.seq))
        self.seq = (self.seq + 1) & 0xFF

    def _run(self):
        stream = PacketStream("host")
        while not self.stop.is_set():
            r, _, _ = select.select([self.master], [], [], 0.02)
            if not r:
                continue
            try:
                data = os.read(self.master, 256)
            except OSError:
                time.sleep(0.02)
                continue
            for dp in stream.feed(data):
                p = dp.packet
                self.commands.append(p.NAME)
                if self.drop or p.NAME in self.silent:
                    self.drop = max(self.drop - 1, 0)
                    continue
                self._send(Reply(cmd_seq=(p.seq + 7) & 0xFF, cmd_type=p.TYPE, result=0))  # not ours
                self._send(Reply(cmd_seq=p.seq, cmd_type=p.TYPE, result=0))
                if p.NAME == "GET_HELLO":
                    self._send(hello_packet())


@pytest.fixture
def dev():
    d = Responder()
    yield d
    d.stop.set()
    os.close(d.master)


def test_reply_is_matched_by_seq_and_type(dev):
    link = DeviceLink(open_port(dev.name, timeout_s=0.02))
    for _ in range(3):
        r = link.command(GetCalibration(), timeout_s=1.0)
        assert r is not None and r.cmd_type == GetCalibration.TYPE and r.cmd_seq == link.tx_seq - 1
    assert link.hello(timeout_s=2.0, ask_after_s=0.1).protocol_version == 1
    link.port.close()


def test_idempotent_command_is_sent_again_when_the_reply_is_lost():
    dev = Responder(drop=1)
    try:
        link = DeviceLink(open_port(dev.name, timeout_s=0.02))
        assert link.command(GetCalibration(), timeout_s=0.3) is not None
        assert dev.commands == ["GET_CALIBRATION", "GET_CALIBRATION"]
        dev.drop = 1
        assert link.command(SaveCalibration(), timeout_s=0.3) is None  # an EEPROM write is never repeated
        time.sleep(0.1)
        assert dev.commands[2:] == ["SAVE_CALIBRATION"]
        link.port.close()
    finally:
        dev.stop.set()
        os.close(dev.master)


def test_a_port_that_goes_away_is_one_clear_error(dev):
    link = DeviceLink(open_port(dev.name, timeout_s=0.02))
    dev.stop.set()
    os.close(dev.master)
    dev.master = os.open("/dev/null", os.O_RDONLY)  # so the fixture's close has something to close
    with pytest.raises(LinkLost, match="went away.*plugged in"):
        for _ in range(50):
            link.command(GetHello(), timeout_s=0.05, retries=0)
    link.port.close()


def test_sphere_device_does_not_claim_nothing_changed_when_a_reply_never_came():
    """A SET whose REPLY never comes may have been carried out (only the REPLY lost): before, `sphere device set`
    said '...: no REPLY (is the sphere still there?); nothing was changed'. Now it says that it is unknown and how
    to look; a refusal (a REPLY not OK) still says nothing was changed (spec §5: such a command changes nothing)."""
    import subprocess
    import sys

    dev = Responder(silent={"SET_TAP"})
    try:
        r = subprocess.run([sys.executable, "-m", "sphere.cli", "device", "--port", dev.name, "--timeout", "0.2", "set",
                            "board=gy85", "tap.threshold_g=2"], capture_output=True, text=True, timeout=30)
        assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
        assert r.stderr.strip() == (f"sphere device: SET_TAP: no REPLY (is the sphere still there?); whether the sphere "
                                    f"took it is unknown (`sphere device --port {dev.name} get` reads what it holds); "
                                    "the settings before it were applied"), r.stderr
        assert dev.commands.count("SET_TAP") == 3  # sent again twice: it is safe to repeat
        r = subprocess.run([sys.executable, "-m", "sphere.cli", "device", "--port", dev.name, "--timeout", "0.2", "set",
                            "tap.threshold_g=2"], capture_output=True, text=True, timeout=30)
        assert r.returncode == 1 and "nothing was changed" not in r.stderr, r.stderr
        assert r.stderr.strip().endswith("whether the sphere took it is unknown (`sphere device --port "
                                         f"{dev.name} get` reads what it holds)"), r.stderr
    finally:
        dev.stop.set()
        os.close(dev.master)
