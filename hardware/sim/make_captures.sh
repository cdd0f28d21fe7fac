#!/usr/bin/env bash
# Regenerates the serial captures in tests/captures/ with the virtual board and the current firmware.
# Part of the MARG sphere's virtual board (hardware/sim); GPL-3.0-or-later.
#
#   hardware/sim/make_captures.sh            (from the repository root; needs firmware/build/sphere.elf)
#
# Each capture is the raw device-to-host byte stream of a few simulated seconds (`sphere decode` reads it).
# tests/captures/README lists the same commands.
set -euo pipefail
cd "$(dirname "$0")/../.."
out=tests/captures
sim() { python -m sphere.cli sim --no-build "$@"; }
[ -f firmware/build/sphere.elf ] || { echo "no firmware/build/sphere.elf: run make -C firmware" >&2; exit 2; }
make -C hardware/sim >/dev/null

sim --trace 24 --start 49 --hold 1 --seconds 6 --capture $out/sim_24_tapping.bin --stats $out/sim_24_tapping.stats.json
sim --trace 07 --start 44.48 --hold 2 --seconds 6 --capture $out/sim_07_fast_rotation.bin --stats $out/sim_07_fast_rotation.stats.json
sim --trace synthetic:toss --seconds 4 --capture $out/sim_toss.bin --stats $out/sim_toss.stats.json
sim --trace synthetic:still --seconds 6 --nack hmc5883l:2:4 --capture $out/sim_mag_fault.bin --stats $out/sim_mag_fault.stats.json
sim --trace synthetic:turn --seconds 9 --capture $out/sim_turn_90.bin --stats $out/sim_turn_90.stats.json
