#!/usr/bin/env python3
"""pyprofibus (an independent DP master) brings a JX2-PROFI1 emulation
(`dpctl slave --device jx2`) into Data_Exchange with the modules
"INPUT : 4 words" and "OUTPUT : 4 words" and checks the process data the
PLC script of crates/cli/tests/jx2.rs provides: input word 0 is 0x4A58, and input
word 1 becomes the output word 0 the master sends (0x0102) once the PLC
copied it.

Prints one JSON object per line; exit status 0 when the check passed.
"""

import argparse
import json
import sys
import time

import pbmaster


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--port", required=True)
    p.add_argument("--gsd", required=True)
    p.add_argument("--addr", type=int, default=4)
    p.add_argument("--timeout", type=float, default=90.0)
    a = p.parse_args()

    master, desc = pbmaster.start(
        a.gsd, a.addr, ["INPUT : 4 words", "OUTPUT : 4 words"], 8, 8,
        port=a.port, master=2, watchdog_ms=2000)
    outputs = bytes([0x01, 0x02, 0, 0, 0, 0, 0, 0])
    start = time.monotonic()
    cycles = 0
    last = None
    ok = False
    try:
        while time.monotonic() - start < a.timeout:
            desc.setMasterOutData(outputs)
            got = master.run()
            if got is not desc:
                continue
            data = desc.getMasterInData()
            if data is None:
                continue
            cycles += 1
            last = bytes(data)
            if last[:4] == bytes([0x4A, 0x58, 0x01, 0x02]):
                ok = True
                break
    finally:
        master.destroy()
    print(json.dumps({"event": "summary", "ok": ok, "cycles": cycles,
                      "inputs": None if last is None else last.hex().upper(),
                      "seconds": round(time.monotonic() - start, 3)}))
    sys.stdout.flush()
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
