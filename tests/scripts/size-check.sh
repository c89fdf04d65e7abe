#!/usr/bin/env bash
# Print the size of the release ELF against the budgets: flash (.text +
# .data) <= 64 KiB, static RAM (.data + .bss) <= 5 KiB.
#
#   size-check.sh firmware.elf [--over-budget-known]
#
# Fails when static RAM is over budget or when flash is over the 64 KiB
# budget. A build that is known to be over (an optional feature, or a
# machine still being shrunk: docs/benchmarks.md) passes --over-budget-known:
# its overshoot is printed as OVER BUDGET and it fails only past what the
# chip holds (248 KiB: 256 KiB less the 8 KiB bootloader).
# Also refuses code known to be miscompiled on avr-none (see below).
set -euo pipefail
elf=${1:?usage: size-check.sh firmware.elf [--over-budget-known]}
over_known=${2:-}
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
elif [ "$flash" -gt "$flash_budget" ]; then
  if [ "$over_known" = "--over-budget-known" ]; then echo "OVER BUDGET: flash $((flash - flash_budget)) bytes over the 64 KiB budget (known, see docs/benchmarks.md)"
  else echo "FAIL: flash $((flash - flash_budget)) bytes over the 64 KiB budget" >&2; status=1; fi
fi
if [ "$ram" -gt "$ram_budget" ]; then echo "FAIL: static RAM over budget" >&2; status=1; fi
# compiler-builtins' __mulosi4/__mulodi4 (i32/i64 checked_mul) write a 32/64-
# bit overflow flag where the AVR ABI reserves a 16-bit int: stack corruption.
if avr-nm "$elf" | grep -qE ' (__mulosi4|__mulodi4)$'; then
  echo "FAIL: the ELF calls __mulosi4/__mulodi4 (checked multiplication), which corrupts the stack on AVR" >&2
  status=1
fi
# LLVM's AVR back end lays out stack-passed arguments for a 2-byte return
# address, but `call` on the ATmega2560 (22-bit PC) pushes 3 bytes: a
# callee reading arguments from the stack reads them one byte off (found
# as a PID whose error came out 256 times too large). Every argument must
# travel in registers (at most 18 bytes of them; bundle the rest in a
# struct passed by reference). This finds functions that read above their
# own frame and saved registers, i.e. stack arguments.
stack_args=$(avr-objdump -d "$elf" | awk '
  function hex(s,   i, v) { v = 0; s = tolower(s); for (i = 3; i <= length(s); i++) v = v * 16 + index("0123456789abcdef", substr(s, i, 1)) - 1; return v }
  /^[0-9a-f]+ <.*>:$/ { name = $2; pushes = 0; frame = -1; maxq = 0; seen = 0; next }
  name == "" { next }
  /\tpush\t/ && frame < 0 { pushes++ }
  /\tin\tr28, 0x3d/ { frame = 0; seen = 1; look = 4; next }
  look > 0 && /\t(sbiw|subi)\tr28, 0x/ { match($0, /0x[0-9a-fA-F]+/); frame = hex(substr($0, RSTART, RLENGTH)); look = 0; high = 1; next }
  high && /\tsbci\tr29, 0x/ { match($0, /0x[0-9a-fA-F]+/); frame += 256 * hex(substr($0, RSTART, RLENGTH)) }
  { high = 0 }
  look > 0 { look-- }
  /\tldd\t[^,]+, Y\+[0-9]+/ { match($0, /Y\+[0-9]+/); q = substr($0, RSTART + 2, RLENGTH - 2) + 0; if (q > maxq) maxq = q }
  /^$/ { if (seen && frame >= 0 && maxq > frame + pushes) print name; name = "" }
')
if [ -n "$stack_args" ]; then
  echo "FAIL: functions read arguments from the stack (miscompiled on the ATmega2560, see size-check.sh):" >&2
  echo "$stack_args" >&2
  status=1
fi
exit $status
