"""Stream a G-code file through Printrun's printcore, as Pronterface does.

usage: printcore_stream.py <serial port> <gcode file> <timeout seconds>

printcore numbers every line and adds checksums, resends on `Resend:`,
and waits for `ok` after each line. Exits 0 when the whole file was sent
and acknowledged, 2 when the printer never came online, 3 on timeout.
"""
import sys
import time

from printrun import gcoder
from printrun.printcore import printcore

port, path, timeout = sys.argv[1], sys.argv[2], float(sys.argv[3])
deadline = time.time() + timeout

core = printcore()
core.connect(port, 115200)
while not core.online and time.time() < deadline:
    time.sleep(0.05)
if not core.online:
    print("printcore: printer never came online", file=sys.stderr)
    sys.exit(2)

with open(path) as f:
    lines = [line.rstrip("\n") for line in f]
core.startprint(gcoder.LightGCode(lines))
while core.printing and time.time() < deadline:
    time.sleep(0.05)
finished = not core.printing
time.sleep(0.5)  # let the last replies arrive
core.disconnect()
if not finished:
    print("printcore: timed out while printing", file=sys.stderr)
    sys.exit(3)
print("printcore: sent %d lines" % len(lines))
