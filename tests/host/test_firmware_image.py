"""The checkout's firmware image is never run older than its sources: sphere.sim.board.firmware_elf rebuilds it
with `make -C firmware` (what make decides), or with --no-build refuses in one line naming the newer source and
the command. Here on a throwaway firmware folder whose Makefile copies its one source into build/sphere.elf
(the real make runs; the real firmware build is left alone: other tests run it)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from sphere import paths
from sphere.cli import main
from sphere.sim import board

needs_make = pytest.mark.skipif(shutil.which("make") is None, reason="[optional] make is not installed")

MAKEFILE = "build/sphere.elf: src/core/a.cpp src/core/a.h\n\tmkdir -p build && cat src/core/a.cpp src/core/a.h > $@\n"


@pytest.fixture
def firmware(tmp_path, monkeypatch):
    fw = tmp_path / "firmware"
    (fw / "src" / "core").mkdir(parents=True)
    (fw / "Makefile").write_text(MAKEFILE)
    (fw / "src" / "core" / "a.cpp").write_text("one\n")
    (fw / "src" / "core" / "a.h").write_text("header\n")
    (fw / "build").mkdir()
    elf = fw / "build" / "sphere.elf"
    elf.write_text("one\nheader\n")
    monkeypatch.setattr(board, "FIRMWARE_DIR", fw)
    monkeypatch.setattr(board, "FIRMWARE_ELF", elf)
    monkeypatch.setattr(paths, "firmware_build_dir", lambda: fw / "build")
    return fw, elf


def _age(path: Path, seconds: float) -> None:
    t = path.stat().st_mtime - seconds
    os.utime(path, (t, t))


def test_an_image_as_new_as_its_sources_is_used_as_it_is(firmware):
    fw, elf = firmware
    _age(fw / "src" / "core" / "a.cpp", 60)
    _age(fw / "src" / "core" / "a.h", 60)
    assert board.firmware_elf(build=False) == elf and elf.read_text() == "one\nheader\n"


@needs_make
def test_a_source_newer_than_the_image_rebuilds_it(firmware, capsys):
    fw, elf = firmware
    _age(elf, 60)
    (fw / "src" / "core" / "a.h").write_text("changed\n")
    assert board.firmware_elf(build=True) == elf
    assert elf.read_text() == "one\nchanged\n"  # what make made from the new source
    err = capsys.readouterr().err
    assert "older than its source firmware/src/core/a.h: rebuilding it (`make -C firmware`)" in err, err
    assert board.firmware_elf(build=False) == elf  # now as new as its sources: used without make


def test_without_building_an_image_older_than_its_sources_is_refused_in_one_line(firmware, capsys):
    fw, elf = firmware
    _age(elf, 60)
    (fw / "src" / "core" / "a.cpp").write_text("two\n")
    with pytest.raises(board.BoardUnavailable, match=r"older than its source firmware/src/core/a.cpp: run `make -C"):
        board.firmware_elf(build=False)
    # the user's path: `sphere sim --no-build` says so and runs nothing (exit 2, as for a missing image)
    assert main(["sim", "--no-build", "--trace", "synthetic:still", "--seconds", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("sphere sim: the firmware image") and "older than its source firmware/src/core/a.cpp" in err
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert elf.read_text() == "one\nheader\n"  # not rebuilt


def test_an_image_named_by_the_user_is_used_whatever_its_age(firmware, tmp_path, monkeypatch):
    fw, _ = firmware
    named = tmp_path / "old.elf"
    named.write_text("old")
    _age(named, 3600)
    monkeypatch.setattr(board, "FIRMWARE_ELF", named)  # $SPHERE_FIRMWARE / [paths] firmware: not the checkout's
    assert board.firmware_elf(build=False) == named


@needs_make
def test_two_builds_of_one_folder_at_once_take_turns(tmp_path):
    """Two test workers that both find an image missing build it one after the other (CI of stop 35: a worker's
    `make testfw` cleared the object folder under the other's link: `undefined reference to attachInterrupt`)."""
    import threading

    # a rule like hardware/sim's sketches: clear the objects, make them, link from them
    (tmp_path / "Makefile").write_text(
        "all:\n\trm -rf o && mkdir o && touch o/a.o && sleep 0.3 && touch o/b.o && cat o/a.o o/b.o > image\n")
    errors = []

    def build():
        try:
            board._make(tmp_path, "make", None)
        except board.BoardUnavailable as e:
            errors.append(str(e))

    workers = [threading.Thread(target=build) for _ in range(3)]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    assert errors == []
    assert (tmp_path / "image").exists()
