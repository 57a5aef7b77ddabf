#!/usr/bin/env python3
"""pyprofibus (an independent DP master) runs a device profile of
`dpctl slave` into Data_Exchange and does one PKW job by hand over the
cyclic data: PKW words zero for a few cycles, then the request, until the
expected response appears, then zero again until the slave answers zero.

Used by crates/cli/tests/device_profiles.rs. Prints one JSON summary line; exit
status 0 when the response came and the handshake ended, 1 otherwise.
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
    p.add_argument("--master", type=int, default=2)
    p.add_argument("--baud", type=int, default=1500000)
    p.add_argument("--module", action="append", required=True)
    p.add_argument("--out-len", type=int, required=True)
    p.add_argument("--in-len", type=int, required=True)
    p.add_argument("--request", required=True, help="8 PKW bytes, hex")
    p.add_argument("--expect", required=True, help="8 PKW response bytes, hex")
    p.add_argument("--timeout", type=float, default=60.0)
    a = p.parse_args()
    request = bytes.fromhex(a.request)
    expect = bytes.fromhex(a.expect)

    master, desc = pbmaster.start(
        a.gsd, a.addr, a.module, a.out_len, a.in_len, port=a.port,
        baud=a.baud, master=a.master)

    phase = "idle"      # idle -> request -> reset -> done
    cycles = 0
    response = None
    errors = []
    start = time.monotonic()
    try:
        while phase != "done":
            if time.monotonic() - start > a.timeout:
                errors.append("timeout in phase %s after %d cycles" % (phase, cycles))
                break
            pkw = request if phase == "request" else bytes(8)
            desc.setMasterOutData(pkw + bytes(a.out_len - 8))
            got = master.run()
            if got is not desc:
                continue
            data = desc.getMasterInData()
            if data is None:
                continue
            data = bytes(data)
            cycles += 1
            if len(data) != a.in_len:
                errors.append("cycle %d: %d input bytes, expected %d" % (cycles, len(data), a.in_len))
                break
            head = data[:8]
            if phase == "idle" and cycles >= 5 and head == bytes(8):
                phase = "request"
            elif phase == "request" and head != bytes(8):
                response = head
                if head != expect:
                    errors.append("response %s, expected %s" % (head.hex(), expect.hex()))
                phase = "reset"
            elif phase == "reset" and head == bytes(8):
                phase = "done"
    finally:
        master.destroy()
    print(json.dumps({"event": "summary", "cycles": cycles, "phase": phase,
                      "response": None if response is None else response.hex().upper(),
                      "errors": errors}))
    sys.stdout.flush()
    return 0 if phase == "done" and not errors else 1


if __name__ == "__main__":
    sys.exit(main())
