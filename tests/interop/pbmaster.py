"""Start a pyprofibus DP master (class 1) with one slave: the setup shared
by the interop scripts and the pyprofibus benchmark."""

import io

import pyprofibus

CONF = """
[PROFIBUS]
debug = %(debug)d
[PHY]
%(phy)s
[DP]
master_class = 1
master_addr = %(master)d
[SLAVE_0]
name = dut
addr = %(addr)d
gsd = %(gsd)s
sync_mode = 0
freeze_mode = %(freeze)d
group_mask = 1
watchdog_ms = %(watchdog_ms)d
# pyprofibus names the sizes from the slave's side of the master:
# input_size = bytes the master sends, output_size = bytes it receives.
input_size = %(out_len)d
output_size = %(in_len)d
%(modules)s
"""


def start(gsd, addr, modules, out_len, in_len, port=None, baud=19200,
          master=2, freeze=False, watchdog_ms=1000, debug=0):
    """Build, configure and initialise the master; returns (master, slave
    descriptor). Without `port` the PHY is pyprofibus's in-process dummy
    slave (which echoes the outputs)."""
    phy = ("type = serial\ndev = %s\nbaud = %d" % (port, baud)
           if port else "type = dummy_slave")
    text = CONF % {
        "debug": debug, "phy": phy, "master": master, "addr": addr,
        "gsd": gsd, "freeze": 1 if freeze else 0, "watchdog_ms": watchdog_ms,
        "out_len": out_len, "in_len": in_len,
        "modules": "\n".join("module_%d = %s" % (i, m)
                             for i, m in enumerate(modules)),
    }
    conf = pyprofibus.PbConf(io.StringIO(text), "pbmaster.conf")
    dpm = conf.makeDPM()
    desc = None
    for sc in conf.slaveConfs:
        desc = sc.makeDpSlaveDesc()
        dpm.addSlave(desc)
    dpm.initialize()
    return dpm, desc
