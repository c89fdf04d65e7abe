#!/usr/bin/env bash
# Command one: build the Mega 2560 + RAMPS 1.4 firmware and run it.
#
#   bash scripts/run.sh                # on a simulated Mega 2560 + RAMPS (simavr)
#   bash scripts/run.sh /dev/ttyACM0   # flash a real board with avrdude
#
# Simulated, the release ELF runs on the avr-bench's virtual RAMPS (hot
# end, bed, thermistors, endstops and motors modelled) in real time. The
# serial port is this terminal (type G-code and press Enter; Ctrl-D or
# Ctrl-C quits) and also a pseudo-terminal for Pronterface or OctoPrint,
# whose path is printed at start. A status line (position, temperatures,
# heater duty) goes to stderr. Extra arguments after `--` go to the
# simulator (e.g. `-- --link /tmp/ferrostep`, see
# tests/avr-bench/src/bin/ramps-sim.rs).
set -euo pipefail
cd "$(dirname "$0")/.."
device=
if [ $# -gt 0 ] && [ "$1" != -- ]; then device=$1; shift; fi
if [ "${1:-}" = -- ]; then shift; fi
if [ -n "$device" ]; then export SETUP_FLASH=1; fi
SETUP_PROFILE=run source tests/scripts/setup.sh

say "building the firmware for ${FERROSTEP_MACHINE:-machines/prusa-i3.toml}: cargo avr"
cargo avr
elf=${CARGO_TARGET_DIR:-target}/avr-none/release/mega2560-ramps.elf
avr-size "$elf"

if [ -n "$device" ]; then
  hex=${elf%.elf}.hex
  avr-objcopy -O ihex -R .eeprom "$elf" "$hex"
  say "flashing $hex to $device (Mega 2560 bootloader: stk500v2 at 115200 baud)"
  # -D: do not erase first (the bootloader erases as it writes).
  avrdude -p atmega2560 -c wiring -P "$device" -b 115200 -D -U "flash:w:$hex:i"
  say "done: open $device at the machine file's baud (115200 for the shipped Prusa i3; e.g. Pronterface, or: screen $device 115200)"
  exit 0
fi

say "building the simulator: cargo build --release -p avr-bench --bin ramps-sim"
cargo build -q --release -p avr-bench --bin ramps-sim
say "starting the simulated Mega 2560 + RAMPS 1.4"
exec "${CARGO_TARGET_DIR:-target}/release/ramps-sim" --elf "$PWD/$elf" "$@"
