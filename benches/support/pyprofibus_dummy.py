#!/usr/bin/env python3
"""CPU cost of pyprofibus's DP master per Data_Exchange on its in-process
dummy PHY (type=dummy_slave: a simulated slave that echoes the outputs),
for the dp_master benchmark. Prints one JSON line:
{"cycles": N, "cpu_s": ..., "wall_s": ...}."""

import json
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "tests", "interop"))
import pbmaster  # noqa: E402


def main():
    gsd, cycles = sys.argv[1], int(sys.argv[2])
    master, desc = pbmaster.start(
        gsd, 8, ["dummy output module", "dummy input module"], 1, 1, master=2)
    # Start-up until the first Data_Exchange answer.
    while True:
        desc.setMasterOutData(b"\x42")
        if master.run() is desc and desc.getMasterInData() is not None:
            break
    n = 0
    cpu0, wall0 = time.process_time(), time.monotonic()
    while n < cycles:
        desc.setMasterOutData(bytes([n & 0xFF]))
        if master.run() is desc and desc.getMasterInData() is not None:
            n += 1
    cpu, wall = time.process_time() - cpu0, time.monotonic() - wall0
    master.destroy()
    print(json.dumps({"cycles": n, "cpu_s": cpu, "wall_s": wall}))


if __name__ == "__main__":
    main()
