#!/usr/bin/env python3
"""pyprofibus (an independent DP master) drives a DP slave over a serial
line or pty and checks the process data both ways.

Used by the interop test (crates/cli/tests/slave_interop.rs) against
`dpctl slave --gsd crates/devices/gsd/DPCTL_GEN.GSD --inputs echo ...`: the slave echoes
the outputs, so every Data_Exchange answer must equal the first bytes of
the outputs sent with it. A freeze phase checks Global_Control: while
frozen the inputs must stay at the value latched by the Freeze command.

Prints one JSON object per line: {"event": "out", ...} for every cycle's
outputs, and a final {"event": "summary", ...}. Exit status 0 when every
check passed, 1 otherwise.
"""

import argparse
import json
import sys
import time

import pbmaster


def pattern(cycle, n):
    """Outputs of a cycle: the cycle number (32 bit, big-endian), then a
    ramp that moves with the cycle."""
    head = cycle.to_bytes(4, "big")
    body = bytes(((cycle * 7 + k) & 0xFF) for k in range(max(0, n - 4)))
    return (head + body)[:n]


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--port", required=True)
    p.add_argument("--gsd", required=True)
    p.add_argument("--addr", type=int, default=8)
    p.add_argument("--master", type=int, default=2)
    p.add_argument("--baud", type=int, default=19200)
    p.add_argument("--module", action="append", required=True)
    p.add_argument("--out-len", type=int, required=True,
                   help="bytes the master sends (slave outputs)")
    p.add_argument("--in-len", type=int, required=True,
                   help="bytes the slave answers (slave inputs)")
    p.add_argument("--cycles", type=int, default=1000)
    p.add_argument("--freeze", action="store_true",
                   help="freeze the inputs for a while and check them")
    p.add_argument("--watchdog-ms", type=int, default=1000)
    p.add_argument("--timeout", type=float, default=120.0)
    p.add_argument("--debug", type=int, default=0)
    a = p.parse_args()

    master, desc = pbmaster.start(
        a.gsd, a.addr, a.module, a.out_len, a.in_len, port=a.port,
        baud=a.baud, master=a.master, freeze=a.freeze,
        watchdog_ms=a.watchdog_ms, debug=a.debug)

    errors = []
    cycle = 0          # Data_Exchange answers received
    current = 1        # number of the outputs pattern being sent
    last_seen = 0      # pattern number of the last answer
    frozen = None
    freeze_at = a.cycles // 2 if a.freeze else -1
    unfreeze_at = freeze_at + 20 if a.freeze else -1
    frozen_checked = 0
    start = time.monotonic()
    first_dx = None
    try:
        while cycle < a.cycles:
            if time.monotonic() - start > a.timeout:
                errors.append("timeout after %d cycles" % cycle)
                break
            sent = pattern(current, a.out_len)
            desc.setMasterOutData(sent)
            got = master.run()
            if got is not desc:
                continue
            data = desc.getMasterInData()
            if data is None:
                continue
            cycle += 1
            if first_dx is None:
                first_dx = time.monotonic() - start
            data = bytes(data)
            print(json.dumps({"event": "out", "cycle": cycle,
                              "outputs": sent.hex().upper(),
                              "inputs": data.hex().upper()}))
            if frozen is not None:
                frozen_checked += 1
                if data != frozen:
                    errors.append("cycle %d (frozen): inputs %s, expected %s"
                                  % (cycle, data.hex(), frozen.hex()))
            else:
                # The echo names the outputs it answers: the pattern
                # number in its first 4 bytes. It must be the pattern
                # being sent (or, after a lost answer, the one before),
                # and every byte must match that pattern.
                n = int.from_bytes(data[:4], "big") if len(data) >= 4 else -1
                expect = (pattern(n, a.out_len) + bytes(a.in_len))[:a.in_len]
                if n not in (current, current - 1) or n < last_seen or data != expect:
                    errors.append("cycle %d: inputs %s do not echo outputs #%d"
                                  % (cycle, data.hex(), current))
                last_seen = max(last_seen, n)
            if len(errors) > 20:
                break
            if cycle == freeze_at:
                master.freezeMode(0)
                frozen = (sent + bytes(a.in_len))[:a.in_len]
            elif cycle == unfreeze_at:
                master.freezeModeCancel(0)
                frozen = None
            current += 1
    finally:
        master.destroy()
    if a.freeze and frozen_checked < 10:
        errors.append("only %d cycles checked while frozen" % frozen_checked)
    summary = {"event": "summary", "cycles": cycle, "errors": errors,
               "seconds": round(time.monotonic() - start, 3),
               "first_dx_s": None if first_dx is None else round(first_dx, 3),
               "frozen_checked": frozen_checked}
    print(json.dumps(summary))
    sys.stdout.flush()
    return 0 if not errors and cycle >= a.cycles else 1


if __name__ == "__main__":
    sys.exit(main())
