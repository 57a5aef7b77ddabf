#!/usr/bin/env python3
"""CPU cost of pyprofibus's DP master per Data_Exchange on its in-process
dummy PHY (type=dummy_slave: a simulated slave that echoes the outputs),
for the dp_master benchmark. Prints one JSON line:
{"cycles": N, "cpu_s": ..., "wall_s": ...}."""

import io
import json
import sys
import time

import pyprofibus

CONF = """
[PROFIBUS]
debug = 0
[PHY]
type = dummy_slave
[DP]
master_class = 1
master_addr = 2
[SLAVE_0]
name = dummy
addr = 8
gsd = %s
sync_mode = 0
freeze_mode = 0
group_mask = 1
watchdog_ms = 1000
input_size = 1
output_size = 1
module_0 = dummy output module
module_1 = dummy input module
"""


def main():
    gsd, cycles = sys.argv[1], int(sys.argv[2])
    conf = pyprofibus.PbConf(io.StringIO(CONF % gsd), "dummy.conf")
    master = conf.makeDPM()
    desc = None
    for sc in conf.slaveConfs:
        desc = sc.makeDpSlaveDesc()
        master.addSlave(desc)
    master.initialize()
    # Start-up until the first Data_Exchange answer.
    n = 0
    while True:
        desc.setMasterOutData(b"\x42")
        if master.run() is desc and desc.getMasterInData() is not None:
            break
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
