"""Build and run the virtual board (hardware/sim/build/sphere-board) on a firmware image.

    from sphere.sim.board import run_board, firmware_elf
    result = run_board(firmware_elf(), "trace.bin", seconds=5, capture="out.bin")
    result.stats["cycles_per_update"]["median"]
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from sphere import paths
from sphere.errors import SphereError
from sphere.paths import repo_path

# Installed (not a checkout), the board is built from the package's sources in the user's cache (sphere.paths).
SIM_DIR = paths.sim_build_root()
BOARD = SIM_DIR / "build" / "sphere-board"
FIRMWARE_DIR = repo_path("firmware")
FIRMWARE_ELF = paths.firmware_image(".elf")
BUILD_BOARD_CMD = paths.sim_build_command()
BUILD_FIRMWARE_CMD = "make -C firmware"
BOARD_SOURCES = ("sphere_board.c", "sensors.c", "sensors.h", "mcu.c", "mcu.h", "Makefile",
                 "bootloaders/optiboot8_atmega328.hex")


class BoardUnavailable(SphereError, RuntimeError):
    """The simulator or the firmware image cannot be had; the message says which command makes it."""


def _stale(target: Path, sources) -> bool:
    if not target.exists():
        return True
    t = target.stat().st_mtime
    return any(Path(s).exists() and Path(s).stat().st_mtime > t for s in sources)


@contextlib.contextmanager
def _folder_lock(directory: Path):
    """One build at a time per folder, across processes: two test workers (or a bench beside a test, or two
    first runs) that both found an image missing would otherwise build it together, and a rule that clears its
    object folder (hardware/sim's sketches) pulls objects from under the other's link. The second waits, then
    finds it built."""
    fd = os.open(directory, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def _run_make(directory: Path, cmd_text: str, target: str | None = None, quiet: bool = True) -> None:
    if shutil.which("make") is None:
        raise BoardUnavailable(f"`make` is not installed; install it and run `{cmd_text}`")
    cmd = ["make", "-C", str(directory)] + ([target] if target else [])
    r = subprocess.run(cmd, capture_output=quiet, text=True)
    if r.returncode != 0:
        tail = (r.stderr or r.stdout or "")[-2000:] if quiet else ""
        raise BoardUnavailable(f"`{cmd_text}` failed:\n{tail}")


def _make(directory: Path, cmd_text: str, target: str | None = None, quiet: bool = True) -> None:
    with _folder_lock(directory):
        _run_make(directory, cmd_text, target, quiet)


def board_path(build: bool = True) -> Path:
    """The simulator binary, built first when it is missing or older than its sources."""
    if _stale(BOARD, [paths.sim_source_dir() / s for s in BOARD_SOURCES]):
        if not build:
            raise BoardUnavailable(f"the simulator is not built: run `{BUILD_BOARD_CMD}`")
        if not Path("/usr/include/simavr/sim_avr.h").exists() and not os.environ.get("SIMAVR_CFLAGS"):
            raise BoardUnavailable(
                "simavr's headers are missing: install Debian's `simavr libsimavr-dev libelf-dev pkg-config` "
                + (f"and run `{BUILD_BOARD_CMD}`" if paths.in_checkout() else "and run this command again"))
        first_use = SIM_DIR != paths.sim_source_dir()
        if first_use:  # installed: first use builds a copy in the user's cache
            print(f"sphere: building the virtual board in {SIM_DIR} (first use only) ...", file=sys.stderr, flush=True)
            SIM_DIR.mkdir(parents=True, exist_ok=True)
        t0 = time.monotonic()
        with _folder_lock(SIM_DIR):  # the copy too: another first run must not rewrite a source make is reading
            for name in BOARD_SOURCES if first_use else ():
                (SIM_DIR / name).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(paths.sim_source_dir() / name, SIM_DIR / name)
            _run_make(SIM_DIR, BUILD_BOARD_CMD)
        if first_use:
            print(f"sphere: the virtual board is built ({time.monotonic() - t0:.1f} s; kept for next time)",
                  file=sys.stderr, flush=True)
    return BOARD


def firmware_sources() -> list[Path]:
    """The firmware's own sources (firmware/src, what `make -C firmware` compiles and its headers)."""
    return sorted(p for p in (FIRMWARE_DIR / "src").rglob("*") if p.suffix in (".c", ".cpp", ".h", ".S"))


def _newer_source(elf: Path) -> Path | None:
    """A firmware source changed after ``elf`` was made (the newest one), or None."""
    t = elf.stat().st_mtime
    newer = [(p.stat().st_mtime, p) for p in firmware_sources() if p.stat().st_mtime > t]
    return max(newer)[1] if newer else None


def firmware_elf(build: bool = True) -> Path:
    """The firmware image, built with `make -C firmware` when it is missing and can be built. In a checkout,
    the checkout's own image is also rebuilt when a firmware source is newer than it (with ``build=False``:
    refused, saying which source and what to run): an image older than its sources is never run as if it
    were them. An image named by $SPHERE_FIRMWARE or [paths] firmware is used as it is."""
    build_dir = paths.firmware_build_dir()
    ours = build_dir is not None and FIRMWARE_ELF == build_dir / "sphere.elf" and (FIRMWARE_DIR / "Makefile").exists()
    newer = _newer_source(FIRMWARE_ELF) if ours and FIRMWARE_ELF.exists() else None
    if FIRMWARE_ELF.exists() and newer is None:
        return FIRMWARE_ELF
    if newer is not None:
        what = (f"the firmware image {FIRMWARE_ELF} is older than its source "
                f"{newer.relative_to(FIRMWARE_DIR.parent)}")
        if not build:
            raise BoardUnavailable(f"{what}: run `{BUILD_FIRMWARE_CMD}`")
        print(f"sphere: {what}: rebuilding it (`{BUILD_FIRMWARE_CMD}`) ...", file=sys.stderr, flush=True)
        _make(FIRMWARE_DIR, BUILD_FIRMWARE_CMD)
        return FIRMWARE_ELF  # make decides what the change needs (a source no object depends on rebuilds nothing)
    if os.environ.get(paths.FIRMWARE_ENV) or not paths.in_checkout():
        raise BoardUnavailable(f"no firmware image at {FIRMWARE_ELF}: {paths.firmware_missing_hint()}")
    if not (FIRMWARE_DIR / "Makefile").exists():
        raise BoardUnavailable(f"no firmware image at {FIRMWARE_ELF} and no firmware/Makefile to build it")
    if not build:
        raise BoardUnavailable(f"no firmware image at {FIRMWARE_ELF}: run `{BUILD_FIRMWARE_CMD}`")
    _make(FIRMWARE_DIR, BUILD_FIRMWARE_CMD)
    if not FIRMWARE_ELF.exists():
        raise BoardUnavailable(f"`{BUILD_FIRMWARE_CMD}` did not make {FIRMWARE_ELF}")
    return FIRMWARE_ELF


def _sketch_elf(name: str, build: bool) -> Path:
    elf = SIM_DIR / "build" / f"{name}.elf"
    if _stale(elf, [SIM_DIR / name / f"{name}.cpp", SIM_DIR / "sketch_wire.h", SIM_DIR / "Makefile"]):
        if not build:
            raise BoardUnavailable(f"the {name} sketch is not built: run `make -C hardware/sim {name}`")
        _make(SIM_DIR, f"make -C hardware/sim {name}", name)
    return elf


def testfw_elf(build: bool = True) -> Path:
    """The board's own test sketch (hardware/sim/testfw), for checking the board without the firmware."""
    return _sketch_elf("testfw", build)


def probe_elf(build: bool = True) -> Path:
    """The bench I2C master (hardware/sim/probe): text commands on the UART, one result line each."""
    return _sketch_elf("probe", build)


#: The boot loaders the board can run in front of the firmware (hardware/sim/README.md, "Boot loaders"):
#: the Nano's Optiboot 4.4, the old Nano's ATmegaBOOT, a current Optiboot (8.3), or none (the reset vector at 0).
BOOTLOADERS = ("optiboot4", "atmegaboot", "optiboot8", "none")


def bootloader_hex(name: str, build: bool = True) -> Path | None:
    """The Intel HEX image of boot loader ``name`` (None for "none"), made by `make -C hardware/sim bootloaders`."""
    if name not in BOOTLOADERS:
        raise ValueError(f"unknown boot loader {name!r}: one of {', '.join(BOOTLOADERS)}")
    if name == "none":
        return None
    path = SIM_DIR / "build" / f"bootloader-{name}.hex"
    if not path.exists():
        board_path(build)
        if not path.exists():
            if not build:
                raise BoardUnavailable(f"the boot loaders are not built: run `{BUILD_BOARD_CMD} bootloaders`")
            _make(SIM_DIR, f"{BUILD_BOARD_CMD} bootloaders", "bootloaders")
    return path


#: The board variants sphere-board knows (hardware/sim/sensors.c, board_variants).
BOARD_VARIANTS = ("aligned", "sen10724", "gy85", "gy85-qmc")


@dataclass
class BoardRun:
    stats: dict
    capture: Path | None
    returncode: int
    stderr: str = ""
    command: list = field(default_factory=list)


def board_command(elf, trace, seconds: float, capture=None, pty=False, realtime=False, stats=None,
                  nack=(), stall=(), send=None, timing_pin=None, loop_pin=None, rate_hz=None,
                  verbose=0, build=True, i2c_real_timing=True, board=None, noise=False, seed=None,
                  clock_ppm=(), clocks_random=False, glitch=None, reset_mid_read=(), brownout=(), sda_held=False,
                  host_stall=(), adapter=None, capture_times=None, reset_at=(), drdy_pin=None,
                  power_off=(), latency_timer_ms=None, bootloader=None, hang=(), host_log=None, previous=None,
                  bus_pullup_kohm=None) -> list[str]:
    """sphere-board's command line. I2C runs at its real 400 kHz timing unless ``i2c_real_timing=False``."""
    cmd = [str(board_path(build)), str(elf), "--trace", str(trace), "--seconds", f"{seconds:g}"]
    if capture:
        cmd += ["--capture", str(capture)]
    if pty:
        cmd.append("--pty")
    if realtime:
        cmd.append("--realtime")
    if stats:
        cmd += ["--stats", str(stats)]
    for n in nack:
        cmd += ["--nack", n]
    for s in stall:
        cmd += ["--stall", s]
    if send:
        cmd += ["--send", str(send)]
    if timing_pin:
        cmd += ["--timing-pin", timing_pin]
    if loop_pin:
        cmd += ["--loop-pin", loop_pin]
    if rate_hz:
        cmd += ["--rate", f"{rate_hz:g}"]
    if not i2c_real_timing:
        cmd.append("--simavr-i2c-timing")
    if board:
        cmd += ["--board", board]
    if noise:
        cmd.append("--noise")
    if seed is not None:
        cmd += ["--seed", str(int(seed))]
    for c in clock_ppm:
        cmd += ["--clock-ppm", c]
    if clocks_random:
        cmd += ["--clocks", "random"]
    if glitch:
        cmd += ["--glitch", f"{glitch:g}"]
    for t in reset_mid_read:
        cmd += ["--reset-mid-read", f"{t:g}"]
    for t in brownout:
        cmd += ["--brownout", f"{t:g}"]
    for t in reset_at:
        cmd += ["--reset-at", f"{t:.6f}"]
    for t in power_off:
        cmd += ["--power-off", f"{t:g}"]
    if sda_held:
        cmd.append("--sda-held")
    for h in host_stall:
        cmd += ["--host-stall", h]
    if adapter:
        cmd += ["--adapter", adapter]
    if latency_timer_ms:
        cmd += ["--latency-timer", str(int(latency_timer_ms))]
    if host_log:
        cmd += ["--host-log", str(host_log)]
    if capture_times:
        cmd += ["--capture-times", str(capture_times)]
    if drdy_pin:
        cmd += ["--drdy-pin", drdy_pin]
    hexfile = bootloader_hex(bootloader, build) if bootloader else None
    if hexfile:
        cmd += ["--bootloader", str(hexfile)]
    for h in hang:
        cmd += ["--hang", h]
    if bus_pullup_kohm:
        cmd += ["--bus-pullup", f"{bus_pullup_kohm:g}"]
    if previous:  # (an earlier sketch's ELF, the time the firmware is flashed over it)
        cmd += ["--previous", f"{previous[0]}:{previous[1]:g}"]
    cmd += ["-v"] * verbose
    return cmd


def start_pty_board(cmd: list) -> tuple[subprocess.Popen, str]:
    """Start sphere-board with ``--pty`` (``board_command(..., pty=True)``); returns the process and its pty path once
    the board says it (``sphere-board: UART on /dev/pts/N``). Raises BoardUnavailable with the board's own words when
    it ends before that."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for line in proc.stdout:
        if "UART on " in line:
            return proc, line.split("UART on ", 1)[1].strip()
    proc.wait(10)
    raise BoardUnavailable(f"the virtual board did not start: {proc.stderr.read().strip()[-300:]}")


def run_board(elf, trace, seconds: float, capture=None, *, interactive: bool = False, **kw) -> BoardRun:
    """Run the board to completion; returns its stats (the JSON the board writes) and the capture path.

    ``interactive``: let the board's output (the pty path, logs) go straight to this process's streams.
    """
    with tempfile.TemporaryDirectory(prefix="sphere-sim-") as tmp:
        stats_path = Path(kw.pop("stats", None) or Path(tmp) / "stats.json")
        cmd = board_command(elf, trace, seconds, capture=capture, stats=stats_path, **kw)
        if interactive:
            r = subprocess.run(cmd, stderr=None, stdout=None)
            err = ""
        else:
            r = subprocess.run(cmd, capture_output=True, text=True)
            err = r.stderr
        stats = json.loads(stats_path.read_text()) if stats_path.exists() else {}
    return BoardRun(stats, Path(capture) if capture else None, r.returncode, err, cmd)


