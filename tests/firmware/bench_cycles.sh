#!/bin/sh
# Runs the MARG cycle benchmark ELF on simavr and prints its console lines (make -C firmware bench).
set -e
elf="$1"
command -v simavr >/dev/null || { echo "skip: simavr not installed (apt-get install simavr)"; exit 0; }
out=$(timeout 120 simavr -m atmega328p -f 16000000 "$elf" 2>&1 || true)
echo "$out" | grep -v '^\s*$' | sed -e 's/\x1b\[[0-9;]*m//g'
echo "$out" | grep -q "bench: done" || { echo "bench did not finish"; exit 1; }
