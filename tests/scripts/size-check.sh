#!/usr/bin/env bash
# Print the size of the release ELF against the budgets: flash (.text +
# .data) <= 64 KiB, static RAM (.data + .bss) <= 5 KiB.
#
# Fails when static RAM is over budget, or when flash would not fit the
# ATmega2560 (256 KiB less the 8 KiB bootloader). Flash over the 64 KiB
# budget is printed as OVER BUDGET without failing: with the planner (f32,
# soft float) and the thermal control wired, the default machine needs
# ≈ 82 KB; the miss is a known, open defect (README, "Sizes"), tracked by
# this figure rather than hidden behind a larger budget.
# Also refuses code known to be miscompiled on avr-none (see below).
set -euo pipefail
elf=${1:?usage: size-check.sh firmware.elf}
flash_budget=$((64 * 1024))
flash_capacity=$((248 * 1024))
ram_budget=$((5 * 1024))

read -r text data bss _ < <(avr-size "$elf" | awk 'NR == 2 { print $1, $2, $3 }')
flash=$((text + data))
ram=$((data + bss))
avr-size -A "$elf" | awk '$1 ~ /^\.(text|text\.code|data|bss|noinit)$/'
printf 'flash: %6d bytes of %6d (%d%%)\n' "$flash" "$flash_budget" $((100 * flash / flash_budget))
printf 'RAM:   %6d bytes of %6d (%d%%) static (.data + .bss)\n' "$ram" "$ram_budget" $((100 * ram / ram_budget))

status=0
if [ "$flash" -gt "$flash_capacity" ]; then echo "FAIL: flash over the chip's capacity ($flash_capacity bytes)" >&2; status=1
elif [ "$flash" -gt "$flash_budget" ]; then echo "OVER BUDGET: flash $((flash - flash_budget)) bytes over the 64 KiB budget (known defect, see README)"; fi
if [ "$ram" -gt "$ram_budget" ]; then echo "FAIL: static RAM over budget" >&2; status=1; fi
# compiler-builtins' __mulosi4/__mulodi4 (i32/i64 checked_mul) write a 32/64-
# bit overflow flag where the AVR ABI reserves a 16-bit int: stack corruption.
if avr-nm "$elf" | grep -qE ' (__mulosi4|__mulodi4)$'; then
  echo "FAIL: the ELF calls __mulosi4/__mulodi4 (checked multiplication), which corrupts the stack on AVR" >&2
  status=1
fi
exit $status
