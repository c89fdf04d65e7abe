#!/usr/bin/env bash
# Command two: set up what is missing, then run every test.
#   bash tests/scripts/test.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
SETUP_PROFILE=test source tests/scripts/setup.sh

target=${CARGO_TARGET_DIR:-target}
elf=$target/avr-none/release/mega2560-ramps.elf

say "building the Mega 2560 release firmware once: cargo avr"
cargo avr

say "checking the firmware against its budgets"
bash tests/scripts/size-check.sh "$elf"

# Every machine file, each with every option it names (FERROSTEP_ALL_OPTIONS:
# the Prusa i3 with its display and its NSE-5310 loops), in one target
# directory (core and the device crate are built once; only the firmware
# and the board are rebuilt per file), each ELF kept under
# $target/machines/NAME.elf for the tests. One size table at the end.
machines_dir=$target/machines
mkdir -p "$machines_dir"
table="machine file (every option)     flash  of 128 KiB    RAM  of 6 KiB"
for file in machines/*.toml; do
  name=$(basename "$file" .toml)
  say "building $file with every option: FERROSTEP_MACHINE=$file FERROSTEP_ALL_OPTIONS=1 cargo avr"
  FERROSTEP_MACHINE=$file FERROSTEP_ALL_OPTIONS=1 CARGO_TARGET_DIR=$machines_dir/build cargo avr
  cp "$machines_dir/build/avr-none/release/mega2560-ramps.elf" "$machines_dir/$name.elf"
  row=$(bash tests/scripts/size-check.sh "$machines_dir/$name.elf" "$name")
  table+=$'\n'"$row"
done
say "sizes"
echo "$table"

arm_dir=$target/thumbv7em-none-eabihf/release
say "building the SKR Pro release firmware once: cargo arm"
cargo arm
"$(rustc --print sysroot)/lib/rustlib/$(rustc -vV | sed -n 's/^host: //p')/bin/llvm-size" "$arm_dir/skr-pro"

say "fault-injection campaign: cargo faults"
cargo faults

say "running every test: cargo test (host crates, the emulated Mega 2560, the simavr bench)"
FERROSTEP_ELF="$PWD/$elf" FERROSTEP_MACHINES_DIR="$PWD/$machines_dir" FERROSTEP_ARM_DIR="$PWD/$arm_dir" cargo test
say "all tests passed"
