"""Discovery touches only spheres (issue 14 item 1): a fake 3-D printer held open by its own host program sits
next to a sphere that streams by itself; sphere-mouse with ``port = auto`` finds the sphere and takes not one
byte from the printer's stream and writes not one into it.

SPHERE_DISCOVERY_SECONDS (default 4) sets how long the two run side by side; the figure quoted in the notes is
from a 60 s run."""

from __future__ import annotations

import os
import select
import subprocess
import sys
import threading
import time
import tty


import pytest

from sphere.daemon.app import SphereMouse
from sphere.daemon.backends.memory import RecordingBackend
from sphere.daemon.config import Config
from sphere.daemon.sources.serial import SerialSource
from sphere.daemon.scripted_sphere import ScriptedSphere, hello_packet
from sphere.protocol import PacketStream

SECONDS = float(os.environ.get("SPHERE_DISCOVERY_SECONDS", "4"))

HOST_PROGRAM = r'''
import os, sys, time
fd = os.open(sys.argv[1], os.O_RDWR | os.O_NOCTTY)   # the printer's host program (OctoPrint-like)
import tty; tty.setraw(fd)
print("open", flush=True)
got = 0
end = time.monotonic() + float(sys.argv[2])
os.set_blocking(fd, False)
while time.monotonic() < end:
    try:
        data = os.read(fd, 4096)
        got += len(data)
    except BlockingIOError:
        time.sleep(0.005)
print(got, flush=True)
'''


class Printer:
    """The printer end of a pty (master): sends a temperature report every 10 ms, counts what it receives."""

    def __init__(self, link):
        self.master, slave = os.openpty()
        tty.setraw(slave)
        self.slave_name = os.ttyname(slave)
        os.close(slave)
        os.symlink(self.slave_name, link)
        self.sent = 0
        self.received = 0
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        line = b"ok T:210.0 /210.0 B:60.0 /60.0\n"
        while not self.stop.is_set():
            r, _, _ = select.select([self.master], [], [], 0.01)
            if r:
                try:
                    self.received += len(os.read(self.master, 4096))
                except OSError:
                    pass
            try:
                self.sent += os.write(self.master, line)
            except OSError:
                pass


class StreamingSphere:
    """A USB sphere that streams on its own (as after power-up) and answers GET_HELLO with a HELLO."""

    def __init__(self, link):
        self.master, slave = os.openpty()
        tty.setraw(slave)
        name = os.ttyname(slave)
        os.close(slave)
        os.symlink(name, link)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        sphere = ScriptedSphere()
        commands = PacketStream("host")
        steps = sphere.iter_steps([("still", 3600.0)])
        t_next = time.monotonic()
        while not self.stop.is_set():
            r, _, _ = select.select([self.master], [], [], max(0.0, t_next - time.monotonic()))
            if r:
                try:
                    for dp in commands.feed(os.read(self.master, 256)):
                        if dp.packet.NAME == "GET_HELLO":
                            os.write(self.master, sphere.frame(hello_packet()))
                except OSError:
                    pass
            if time.monotonic() >= t_next:
                t_next += 0.005
                try:
                    os.write(self.master, b"".join(f for _, f in next(steps)))
                except OSError:
                    pass


@pytest.mark.slow
def test_a_port_held_by_another_program_is_never_touched(tmp_path):
    printer = Printer(tmp_path / "ttyUSB0")
    host = subprocess.Popen([sys.executable, "-c", HOST_PROGRAM, printer.slave_name, str(SECONDS + 1.0)],
                            stdout=subprocess.PIPE, text=True)
    assert host.stdout.readline().strip() == "open"
    printer.thread.start()
    sphere = StreamingSphere(tmp_path / "ttyUSB1")
    logs = []
    source = SerialSource("auto", candidates=[str(tmp_path / "ttyUSB*")], usb_ids=[], hello_timeout_s=0.2,
                          discovery_timeout_s=1.0, reconnect_interval_s=0.2, log=logs.append)
    cfg = Config().with_overrides({"outputs.page": {"enabled": False}}, "t")
    daemon = SphereMouse(cfg, source, RecordingBackend(), log=lambda m: None)
    thread = threading.Thread(target=daemon.run, daemon=True)
    thread.start()
    found = None
    try:
        end = time.monotonic() + SECONDS
        while time.monotonic() < end:  # the port the daemon settles on, whenever in the window it does
            found = source.port_name or found
            time.sleep(0.05)
    finally:
        daemon.stop()
        thread.join(5)
        printer.stop.set()
        printer.thread.join(2)
        sphere.stop.set()
    got = int(host.stdout.readline())
    host.wait(5)
    print(f"\n{SECONDS:g} s: printer sent {printer.sent} B, its host program read {got} B, "
          f"written into the printer {printer.received} B; sphere found on {found}")
    assert found == str(tmp_path / "ttyUSB1")
    assert got == printer.sent  # the daemon read 0 bytes of the printer's stream
    assert printer.received == 0  # and wrote 0 bytes into it
    assert any("open in another program" in m for m in logs), logs
    assert sum("open in another program" in m for m in logs) == 1  # said once, not every second
