"""`sphere flash`: the real avrdude writes the real firmware image through an STK500v1 bootloader model
on a pseudo-terminal (tests/host/stk500_model.py, from AVR061); the bytes the model received are compared
with the image's Intel HEX records, then the command reads the HELLO (the spec's golden vector)."""

import shutil
import stat
import subprocess

import pytest

from sphere.link import bootloader
from sphere.cli import main
from sphere.paths import firmware_image
from sphere.protocol.vectors import load_vectors

from stk500_model import Stk500Board, parse_intel_hex

HELLO = next(v for v in load_vectors() if v.name == "hello")
HELLO_WIRE = HELLO.wire
HELLO_TEXT = "firmware {}.{}.{} (protocol {})".format(*HELLO.fields["firmware_version"], HELLO.fields["protocol_version"])

needs_avrdude = pytest.mark.skipif(shutil.which("avrdude") is None,
                                   reason="[optional] avrdude is not installed (scripts/setup installs it)")


@pytest.fixture(scope="module")
def hex_image():
    from sphere.sim.board import firmware_elf

    firmware_elf(build=True)  # `make -C firmware` writes the .hex beside the .elf
    image = firmware_image(".hex")
    assert image.is_file()
    return image


@pytest.fixture
def board(request):
    boards = []

    def make(**kw):
        b = Stk500Board(**kw)
        boards.append(b)
        return b

    yield make
    for b in boards:
        b.close()


@pytest.mark.slow
@needs_avrdude
@pytest.mark.parametrize("baud", [115200, 57600])
def test_flash_detects_the_bootloader_writes_the_image_and_reads_the_hello(baud, board, hex_image, capsys):
    nano = board(baud=baud, hello=HELLO_WIRE)
    assert main(["flash", "--port", nano.path]) == 0
    out = capsys.readouterr().out
    assert f"at {baud} baud" in out and ("Optiboot" if baud == 115200 else "old bootloader") in out
    assert "written and verified" in out
    assert HELLO_TEXT in out and "adxl345" in out.lower()  # the spec's golden HELLO, as the model sent it
    expected = parse_intel_hex(hex_image.read_text())
    assert expected and set(expected) <= nano.written
    assert all(nano.flash[a] == v for a, v in expected.items())
    padding = nano.written - set(expected)  # avrdude writes whole 128-byte pages, filled with 0xFF
    assert all(nano.flash[a] == 0xFF and a // 128 == max(expected) // 128 for a in padding)
    assert nano.app_running


def test_no_bootloader_is_a_clear_error(board, hex_image, capsys):
    nano = board(baud=115200, answers=False)
    assert main(["flash", "--port", nano.path, "--avrdude", "true"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("sphere flash: no bootloader answered on") and "--baud" in err
    assert "Traceback" not in err


def test_a_given_baud_is_checked_before_avrdude_runs(tmp_path, board, hex_image, capsys):
    """--baud where no bootloader answers at that rate: one line, avrdude not run (before: avrdude's ten sync
    attempts and 'unable to open programmer'); at the bootloader's rate avrdude runs with it."""
    log = tmp_path / "argv"
    fake = tmp_path / "avrdude"
    fake.write_text(f"#!/bin/sh\nprintf '%s\\n' \"$@\" > {log}\nexit 0\n")
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    nano = board(baud=57600)
    assert main(["flash", "--port", nano.path, "--baud", "115200", "--avrdude", str(fake), "--no-hello"]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"sphere flash: no bootloader answered on {nano.path} at 115200 baud") and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1 and not log.exists()
    assert main(["flash", "--port", nano.path, "--baud", "57600", "--avrdude", str(fake), "--no-hello"]) == 0
    assert log.read_text().split("\n")[6:8] == ["-b", "57600"]


@pytest.mark.slow
@needs_avrdude
def test_ctrl_c_while_avrdude_writes_says_so_and_flashing_again_mends_it(board, hex_image):
    """SIGINT in the middle of the write: before, 'sphere: interrupted' and nothing about the Nano, which held part
    of the image. Now one line saying so and that flashing again writes the whole image; exit 130; it does."""
    import signal
    import sys
    import time

    nano = board(baud=115200, hello=HELLO_WIRE, page_write_s=0.02)  # about 4 s for the image's pages
    p = subprocess.Popen([sys.executable, "-m", "sphere.cli", "flash", "--port", nano.path],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not nano.written and time.monotonic() < deadline:
        time.sleep(0.02)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=30)
    assert p.returncode == 130 and "Traceback" not in err, err
    assert err.strip() == ("sphere flash: interrupted; avrdude was writing: the Nano may hold part of the image; its "
                           "bootloader is untouched, so `sphere flash` again writes the whole image"), err
    expected = parse_intel_hex(hex_image.read_text())
    assert not nano.app_running and not set(expected) <= nano.written  # interrupted half way
    nano.page_write_s = 0.0
    assert subprocess.run([sys.executable, "-m", "sphere.cli", "flash", "--port", nano.path],
                          capture_output=True, text=True, timeout=120).returncode == 0
    assert all(nano.flash[a] == v for a, v in expected.items()) and nano.app_running


def test_avrdude_command_line_and_its_failure(tmp_path, board, hex_image, capsys):
    """A stand-in avrdude records its arguments and fails as a real one does when the board is wrong."""
    log = tmp_path / "argv"
    fake = tmp_path / "avrdude"
    fake.write_text(f"#!/bin/sh\nprintf '%s\\n' \"$@\" > {log}\necho 'avrdude: stk500_recv(): programmer is not responding' >&2\nexit 1\n")
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    nano = board(baud=57600)
    assert main(["flash", "--port", nano.path, "--avrdude", str(fake)]) == 1
    argv = log.read_text().split("\n")[:-1]
    assert argv == ["-p", "atmega328p", "-c", "arduino", "-P", nano.path, "-b", "57600", "-D",
                    "-U", f"flash:w:{hex_image}:i"]
    err = capsys.readouterr().err
    assert "avrdude failed (exit status 1)" in err and "programmer is not responding" in err


def test_bad_input_is_one_line(tmp_path, capsys):
    assert main(["flash", "--port", "/dev/null", "--image", str(tmp_path / "nope.hex")]) == 2
    assert "no such image file" in capsys.readouterr().err
    elf = tmp_path / "x.elf"
    elf.write_bytes(b"\x7fELF")
    assert main(["flash", "--port", "/dev/null", "--image", str(elf)]) == 2
    assert "Intel HEX" in capsys.readouterr().err
    assert main(["flash", "--port", "/dev/null", "--avrdude", "no-such-avrdude"]) == 2
    assert "install avrdude" in capsys.readouterr().err


def test_avrdude_parses_the_shipped_hex():
    """avrdude's own reader accepts the image (-n: nothing written) on the bootloader model."""
    if shutil.which("avrdude") is None:
        pytest.skip("[optional] avrdude is not installed")
    image = firmware_image(".hex")
    if not image.exists():
        pytest.skip("[optional] no firmware image: `make -C firmware`")
    nano = Stk500Board(baud=115200)
    try:
        r = subprocess.run(bootloader.avrdude_command(nano.path, 115200, image)[:-2] + ["-n", "-U", f"flash:w:{image}:i"],
                           capture_output=True, text=True, timeout=60)
    finally:
        nano.close()
    assert r.returncode == 0, r.stderr
    assert not nano.written  # -n writes nothing
