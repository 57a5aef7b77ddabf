#!/usr/bin/env python3
"""pyprofibus (an independent DP master) drives an emulated BK3000
(`dpctl slave --device bk3000`) with the modules of crates/devices/gsd/BK30BECF.GSD and
sends fixed outputs.

Used by crates/cli/tests/bk3000.rs. Prints {"event": "dx", "cycle": n, "inputs": HEX}
for every Data_Exchange answer and a final {"event": "summary", ...}.
Exit status 0 when `--cycles` answers came with the expected length.
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
    p.add_argument("--addr", type=int, required=True)
    p.add_argument("--module", action="append", required=True)
    p.add_argument("--out-len", type=int, required=True)
    p.add_argument("--in-len", type=int, required=True)
    p.add_argument("--outputs", required=True, help="hex bytes to send")
    p.add_argument("--cycles", type=int, default=50)
    p.add_argument("--timeout", type=float, default=60.0)
    a = p.parse_args()

    outputs = bytes.fromhex(a.outputs)
    master, desc = pbmaster.start(a.gsd, a.addr, a.module, a.out_len,
                                  a.in_len, port=a.port)
    errors = []
    cycle = 0
    start = time.monotonic()
    try:
        while cycle < a.cycles:
            if time.monotonic() - start > a.timeout:
                errors.append("timeout after %d cycles" % cycle)
                break
            desc.setMasterOutData(outputs)
            got = master.run()
            if got is not desc:
                continue
            data = desc.getMasterInData()
            if data is None:
                continue
            data = bytes(data)
            cycle += 1
            if len(data) != a.in_len:
                errors.append("cycle %d: %d input bytes" % (cycle, len(data)))
            print(json.dumps({"event": "dx", "cycle": cycle,
                              "inputs": data.hex().upper()}))
            sys.stdout.flush()
    finally:
        master.destroy()
    print(json.dumps({"event": "summary", "cycles": cycle, "errors": errors}))
    sys.stdout.flush()
    return 0 if not errors and cycle >= a.cycles else 1


if __name__ == "__main__":
    sys.exit(main())
