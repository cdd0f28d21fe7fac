#!/bin/sh
# Runs the MARG cycle benchmark ELF on simavr and prints its lines (make -C firmware bench); then checks
# that the AVR build ends in the same filter state as the native build of the same code.
set -e
elf="$1"
native="$2"
command -v simavr >/dev/null || { echo "skip: simavr not installed (apt-get install simavr)"; exit 0; }
out=$(timeout 120 simavr -m atmega328p -f 16000000 "$elf" 2>&1 | sed -e 's/\x1b\[[0-9;]*m//g' | tr -d '\r' || true)
echo "$out" | grep -v '^\s*$' | grep -v '^Loaded' | sed -e 's/\.$//'
echo "$out" | grep -q "bench: done" || { echo "bench did not finish"; exit 1; }
if [ -n "$native" ]; then
    avr_states=$(echo "$out" | grep "state after run" | sed -e 's/.*state after run://' -e 's/\.$//')
    native_states=$("$native" | sed -e 's/.*state after run://')
    if [ "$avr_states" = "$native_states" ]; then
        echo "bench: AVR and native builds end in the same Q30 state (bit-exact)"
    else
        echo "bench: AVR and native states differ:"; echo "$avr_states"; echo "native:"; echo "$native_states"; exit 1
    fi
fi
