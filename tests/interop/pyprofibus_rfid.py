#!/usr/bin/env python3
"""pyprofibus (an independent DP master) runs the RFID reader profile of
`dpctl slave` into Data_Exchange and runs one reader command by hand over
the 16-byte handshake of the manual: the command with its length, then
S + 1; once the data flag (status bit 3) is set, R + 1 and wait until E
changes; take L bytes; again while the flag stays set.

Used by crates/cli/tests/rfid.rs. Prints one JSON summary line (the answer in hex,
the distinct request/response pairs); exit status 0 when the whole answer
came, 1 otherwise.
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
    p.add_argument("--command", required=True)
    p.add_argument("--timeout", type=float, default=60.0)
    a = p.parse_args()
    cmd = a.command.encode("ascii") + b"\r"
    assert len(cmd) <= 13, "one fragment only"

    master, desc = pbmaster.start(
        a.gsd, a.addr, ["16 Byte In/Out"], 16, 16, port=a.port,
        baud=a.baud, master=a.master)

    out = bytearray(16)
    phase = "idle"      # idle -> send -> flag -> fetch -> done
    cycles = 0
    answer = b""
    e_before = None
    pairs = []
    errors = []
    start = time.monotonic()
    try:
        while phase != "done":
            if time.monotonic() - start > a.timeout:
                errors.append("timeout in phase %s after %d cycles" % (phase, cycles))
                break
            desc.setMasterOutData(bytes(out))
            got = master.run()
            if got is not desc:
                continue
            data = desc.getMasterInData()
            if data is None:
                continue
            data = bytes(data)
            cycles += 1
            if len(data) != 16:
                errors.append("cycle %d: %d input bytes" % (cycles, len(data)))
                break
            pair = [bytes(out).hex().upper(), data.hex().upper()]
            if not pairs or pairs[-1] != pair:
                pairs.append(pair)
            flag = data[0] & 0x08
            if phase == "idle" and cycles >= 5 and not flag:
                # Payload and length first, then S + 1 (one image here).
                out[2] = len(cmd)
                out[3:3 + len(cmd)] = cmd
                out[1] = (out[1] + 1) & 0xFF
                phase = "flag"
            elif phase == "flag" and flag:
                e_before = data[1]
                out[0] = (out[0] + 1) & 0xFF
                out[2:] = bytes(14)
                phase = "fetch"
            elif phase == "fetch" and data[1] != e_before:
                answer += data[3:3 + data[2]]
                if flag:
                    e_before = data[1]
                    out[0] = (out[0] + 1) & 0xFF
                else:
                    phase = "done"
    finally:
        master.destroy()
    print(json.dumps({"event": "summary", "cycles": cycles, "phase": phase,
                      "answer": answer.hex().upper(), "pairs": pairs,
                      "errors": errors}))
    sys.stdout.flush()
    return 0 if phase == "done" and not errors else 1


if __name__ == "__main__":
    sys.exit(main())
