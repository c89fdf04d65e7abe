#!/usr/bin/env bash
# Command one: build the Mega 2560 + RAMPS 1.4 firmware and run it.
#
#   bash tests/scripts/main.sh                # on an emulated Mega 2560 (QEMU)
#   bash tests/scripts/main.sh /dev/ttyACM0   # flash a real board with avrdude
#
# In the emulator the serial port is this terminal: type G-code (M115, M105,
# M114, ...) and press Enter; Ctrl-C quits.
set -euo pipefail
cd "$(dirname "$0")/../.."
device=${1:-}
if [ -n "$device" ]; then export SETUP_FLASH=1; fi
SETUP_PROFILE=run source tests/scripts/setup.sh

say "building the firmware: cargo avr"
cargo avr
elf=${CARGO_TARGET_DIR:-target}/avr-none/release/mega2560-ramps.elf
avr-size "$elf"

if [ -n "$device" ]; then
  hex=${elf%.elf}.hex
  avr-objcopy -O ihex -R .eeprom "$elf" "$hex"
  say "flashing $hex to $device (Mega 2560 bootloader: stk500v2 at 115200 baud)"
  # -D: do not erase first (the bootloader erases as it writes).
  avrdude -p atmega2560 -c wiring -P "$device" -b 115200 -D -U "flash:w:$hex:i"
  say "done: open $device at 115200 baud (e.g. Pronterface, or: screen $device 115200)"
  exit 0
fi

say "starting an emulated Mega 2560 (QEMU); type G-code and press Enter, Ctrl-C quits"
say "QEMU has no ADC: the thermistors read as shorted there"
# Feeding QEMU through `cat` keeps this terminal in line mode, so what you
# type is echoed and edited locally and sent on Enter, like a host would.
cat | qemu-system-avr -M mega2560 -bios "$elf" -display none -serial stdio -monitor none
