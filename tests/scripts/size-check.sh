#!/usr/bin/env bash
# Check a release ELF against the budgets and print its size: flash
# (.text + .data) <= 128 KiB, static RAM (.data + .bss) <= 6 KiB, the
# constant tables and .data's initial values in the low 64 KiB of flash
# (read with lpm/elpm without RAMPZ games on QEMU), no EIND trampolines
# (every call and function pointer word-addressed). Every build is held
# to them: no exemption.
#
#   size-check.sh firmware.elf [NAME]
#
# With NAME, the last line printed is one row of the size table CI prints
# (NAME, flash, RAM). Also refuses code known to be miscompiled on avr-none
# (see below).
set -euo pipefail
elf=${1:?usage: size-check.sh firmware.elf [NAME]}
name=${2:-}
flash_budget=$((128 * 1024))
ram_budget=$((6 * 1024))

read -r text data bss _ < <(avr-size "$elf" | awk 'NR == 2 { print $1, $2, $3 }')
flash=$((text + data))
ram=$((data + bss))
if [ -z "$name" ]; then
  avr-size -A "$elf" | awk '$1 ~ /^\.(text|text\.code|data|bss|noinit)$/'
  printf 'flash: %6d bytes of %6d (%d%%)\n' "$flash" "$flash_budget" $((100 * flash / flash_budget))
  printf 'RAM:   %6d bytes of %6d (%d%%) static (.data + .bss)\n' "$ram" "$ram_budget" $((100 * ram / ram_budget))
fi

status=0
if [ "$flash" -gt "$flash_budget" ]; then echo "FAIL: $elf: flash $((flash - flash_budget)) bytes over the 128 KiB budget" >&2; status=1; fi
if [ "$ram" -gt "$ram_budget" ]; then echo "FAIL: $elf: static RAM $ram bytes, over the 6 KiB budget" >&2; status=1; fi
symbol() { echo $((16#$(avr-nm "$elf" | awk -v s="$1" '$3 == s { print $1 }'))); }
if [ "$(symbol __trampolines_start)" != "$(symbol __trampolines_end)" ]; then
  echo "FAIL: $elf has EIND trampolines (a call or function pointer beyond 128 KiB)" >&2; status=1
fi
if [ "$(symbol __data_load_end)" -gt 65536 ]; then
  echo "FAIL: $elf: constant tables or .data's initial values reach past the low 64 KiB of flash" >&2; status=1
fi
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
if [ -n "$name" ]; then
  permille() { echo "$(($1 * 1000 / $2 / 10)).$(($1 * 1000 / $2 % 10))"; }
  printf '%-28s %7d B %5s %%   %5d B %5s %%\n' "$name" "$flash" "$(permille "$flash" "$flash_budget")" "$ram" "$(permille "$ram" "$ram_budget")"
fi
exit $status
