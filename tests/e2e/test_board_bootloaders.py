"""The virtual board's boot loaders and the ATmega328P behaviours they depend on (hardware/sim/README.md,
"Boot loaders"; hardware/sim/mcu.c), checked with the bench sketch (hardware/sim/probe), never the firmware.

The boot loaders are the Nano's real images: Optiboot 4.4 (the Nano's "new bootloader", built from the source
Debian's arduino-core-avr ships), the old ATmegaBOOT (Debian's hex) and Optiboot 8.3 (its published image). What
each does with MCUSR and the watchdog is read from its source (optiboot.c 4.4: `ch = MCUSR; MCUSR = 0; if (!(ch &
_BV(EXTRF))) appStart();`; Optiboot 8: the application runs unless EXTRF is set without WDRF, MCUSR is kept but
WDRF when EXTRF is set, the flags handed over in r2; ATmegaBOOT_168.c: the watchdog is touched only under
WATCHDOG_MODS, which the atmega328 target does not define) and the ATmega328P datasheet ("Watchdog Timer",
"WDTCSR", "MCUSR", "EEPROM Data Memory").
"""

from __future__ import annotations

import re

import pytest

from simscenarios import need_board, probe
from sphere.sim import trace as T
from sphere.sim.board import BOOTLOADERS, bootloader_hex

PORF, EXTRF, BORF, WDRF = 1, 2, 4, 8
LOADERS = [b for b in BOOTLOADERS if b != "none"]


def _flash(path) -> dict[int, int]:
    """Intel HEX data records -> {address: byte} (extended addresses are not used by these images)."""
    mem = {}
    for line in path.read_text().split():
        b = bytes.fromhex(line[1:])
        assert sum(b) & 0xFF == 0, line
        if b[3] == 0:
            addr = b[1] << 8 | b[2]
            mem.update({addr + i: v for i, v in enumerate(b[4:4 + b[0]])})
    return mem


def _causes(r) -> list[int]:
    return [b.data[0] for b in r.tagged("probe")]


@pytest.fixture(scope="module", autouse=True)
def _board():
    need_board()


def test_the_images_are_the_versions_named_and_fit_their_boot_sections():
    """Optiboot keeps its version at the last word of the flash (optiboot.c: `.version` section at 0x7FFE,
    major * 256 + minor); Optiboot 4.4 must end before that word, within the 512-byte section from 0x7E00 (the
    Nano's high fuse 0xDE). ATmegaBOOT lies within its 2 KB section from 0x7800 (high fuse 0xDA)."""
    src = (bootloader_hex("optiboot4").parent.parent / "Makefile").read_text()
    arduino = re.search(r"^ARDUINO \?= (\S+)", src, re.M).group(1)
    text = open(f"{arduino}/bootloaders/optiboot/optiboot.c").read()
    assert "#define OPTIBOOT_MAJVER 4" in text and "#define OPTIBOOT_MINVER 4" in text
    o4 = _flash(bootloader_hex("optiboot4"))
    assert min(o4) == 0x7E00 and max(a for a in o4 if a < 0x7FFE) <= 0x7FFD
    assert o4[0x7FFE] == 4 and o4[0x7FFF] == 4  # 4.4
    o8 = _flash(bootloader_hex("optiboot8"))
    assert min(o8) == 0x7E00 and (o8[0x7FFF], o8[0x7FFE]) == (8, 3)  # 8.3
    ab = _flash(bootloader_hex("atmegaboot"))
    assert min(ab) == 0x7800 and max(ab) <= 0x7FFF


@pytest.mark.parametrize("loader, cause", [("none", PORF), ("optiboot4", 0), ("optiboot8", PORF), ("atmegaboot", PORF)])
def test_power_on_starts_the_program_with_the_flags_each_loader_leaves(loader, cause):
    """Optiboot 4.4 clears MCUSR and starts the program at once; Optiboot 8 starts it at once and leaves MCUSR;
    ATmegaBOOT waits for a programmer first (about 1.3 s here) and leaves MCUSR."""
    r = probe([], T.still(2.0), 2.0, bootloader=loader)
    assert _causes(r) == [cause], r.lines
    assert r.stats["resets"] == 0


@pytest.mark.parametrize("loader, cause, resets", [("none", EXTRF, 1), ("optiboot4", 0, 2), ("optiboot8", EXTRF, 2),
                                                   ("atmegaboot", EXTRF, 1)])
def test_an_external_reset_runs_the_loader_then_the_program(loader, cause, resets):
    """The reset pin (a host's DTR): both Optiboots wait for a programmer until their 1 s watchdog resets the
    chip, then start the program (4.4 with MCUSR cleared; 8 with WDRF cleared and EXTRF kept); ATmegaBOOT
    times out by itself."""
    r = probe([], T.still(4.0), 4.0, bootloader=loader, reset_at=[1.6])
    assert _causes(r) == [PORF if loader != "optiboot4" else 0, cause], r.lines
    assert r.stats["resets"] == resets


@pytest.mark.parametrize("loader, cause", [("none", WDRF), ("optiboot4", 0), ("optiboot8", WDRF)])
def test_a_watchdog_reset_returns_to_the_program_through_optiboot(loader, cause):
    """Optiboot starts the program after a watchdog reset and switches the watchdog off first (appStart), having
    cleared WDRF (4.4: all of MCUSR) so that WDE can be cleared."""
    r = probe([(1.6, "W"), (1.8, "r 1e 0a 3")], T.still(2.0), 2.0, bootloader=loader)
    assert _causes(r) == [PORF if loader != "optiboot4" else 0, cause], r.lines
    assert r.stats["resets"] == 1
    assert r.tagged("r")[0].data == [0x48, 0x34, 0x33]  # the program runs on ("H43")


def test_the_old_bootloader_and_a_watchdog_reset_loop_until_a_power_on():
    """ATmegaBOOT for the atmega328 leaves the watchdog alone; after a watchdog reset WDE is forced on by WDRF at
    the reset prescaler (16 ms: "WDE is always set when WDRF is set"), so it resets again before its own
    time-out, for good (Arduino issue 4492). A reset from the pin does not clear WDRF ("reset by a Power-on
    Reset, or by writing a logic zero to the flag"): the loop goes on. A power-on ends it."""
    r = probe([(1.6, "W")], T.still(5.0), 5.0, bootloader="atmegaboot", reset_at=[2.2], power_off=[3.0])
    assert _causes(r) == [PORF, PORF], r.lines  # before the W, and after the power-on only
    # 1.6 .. 3.0 s of 16 ms watchdog periods (2K cycles of the 128 kHz oscillator), plus the pin and the power-on
    expected = (3.0 - 1.6) / (2048 / 128e3) + 2
    assert abs(r.stats["resets"] - expected) <= 3, (r.stats["resets"], expected)


def test_an_unserved_watchdog_interrupt_is_followed_by_a_system_reset():
    """Interrupt and system reset mode (WDE and WDIE): "If the interrupt is not executed before the next
    time-out, a System Reset will be applied." With interrupts off the vector never runs: the reset comes at the
    second 16 ms time-out, with WDRF."""
    r = probe([(0.3, "I")], T.still(0.6), 0.6)
    assert _causes(r) == [PORF, WDRF], r.lines
    (f,) = r.stats["faults"]
    assert f["kind"] == "watchdog_unserved"
    t_i = r.tagged("I")[0].t_us / 1e6  # the program's clock; it started with the simulation (no boot loader)
    # its line goes out (about 1 ms at 115200 baud), then two time-outs of 2K cycles at 128 kHz (16.0 ms each)
    assert 0.0325 <= f["t"] - t_i <= 0.0345, (f, t_i)
    assert r.stats["watchdog_interrupts"] == 1


def test_mcusr_flags_are_cleared_by_writing_zero_and_not_set_by_writing_one():
    """MCUSR: each flag "is reset by a Power-on Reset, or by writing a logic zero to the flag"; the probe cleared
    MCUSR at start, so writing ones leaves it zero; after an external reset with MCUSR kept (`k`), writing
    ~WDRF (Optiboot 8's `MCUSR = ~_BV(WDRF)`) keeps EXTRF alone."""
    r = probe([(0.1, "M ff"), (0.2, "k"), (0.4, "M f7")], T.still(0.5), 0.5, reset_at=[0.3])
    assert [m.data for m in r.tagged("M")] == [[0], [EXTRF]], r.lines


def test_an_eeprom_write_keeps_eepe_set_for_its_datasheet_time():
    """"EEPROM Mode Bits": erase and write in one operation (EEPM = 00) takes 3.4 ms, during which EEPE stays
    one; the byte reads back once it is done."""
    r = probe([(0.1, "x 20 5a"), (0.2, "x 20 a5")], T.still(0.3), 0.3)
    for line, value in zip(r.tagged("x"), (0x5A, 0xA5)):
        busy_us = int(f"{line.data[0]:x}")  # printed in decimal, parsed as hex by the probe reader
        assert 3390 <= busy_us <= 3420 and line.data[1] == value, r.lines
    assert r.stats["eeprom_writes"] == 2
