"""A minimal DP slave on a serial line or pty, written from the standard
(EN 50170 Vol. 2 / IEC 61158-4-3 and -6-3), independent of the Rust
stack: the FDL telegram formats SD1/SD2/SD3/SD4/SC with their FCS, and the
slave's DP state machine Wait_Prm -> Wait_Cfg -> Data_Exch.

Like some home-made and older slave cores, its Slave_Diag answer leaves
bit 2 of Station_Status_2 ("always 1") clear unless --always-one is given,
e.g. `02 08 00 02 00 2B` after Set_Prm by master 2.

Services:
  Slave_Diag (DSAP 60)   diagnosis, 6 bytes
  Set_Prm    (DSAP 61)   SC; the ident number must match (else Prm_Fault)
  Chk_Cfg    (DSAP 62)   SC; the identifiers must match (else Cfg_Fault)
  Get_Cfg    (DSAP 59)   its configuration
  Global_Control (58)    no answer (broadcast)
  Data_Exchange (no SAP) in Data_Exch: the outputs echoed as inputs
                         (cut or padded to the input length); else RS
  FDL status request     passive station, OK

Only the Python standard library is used. Prints `ready` once the port
is open, and `data_exchange` once the first Data_Exchange is answered.
"""

import argparse
import os
import select
import sys
import termios
import tty

SD1, SD2, SD3, SD4, SC = 0x10, 0x68, 0xA2, 0xDC, 0xE5
ED = 0x16

# Function codes (IEC 61158-4-3): request bit 6, function in bits 3-0.
FC_REQ = 0x40
FN_FDL_STATUS = 0x9
FN_SRD_LOW = 0xC
FN_SRD_HIGH = 0xD
FN_SDN_LOW = 0x4
FN_SDN_HIGH = 0x6
# Response status (bits 3-0), station type passive (bits 5-4 = 00).
RS_OK = 0x0
RS_RS = 0x3
RS_DL = 0x8

SAP_GLOBAL_CONTROL = 58
SAP_GET_CFG = 59
SAP_SLAVE_DIAG = 60
SAP_SET_PRM = 61
SAP_CHK_CFG = 62

# Station_Status_1 / _2 bits (IEC 61158-6-3, Slave_Diag).
S1_NOT_READY = 0x02
S1_CFG_FAULT = 0x04
S1_PRM_FAULT = 0x40
S2_PRM_REQ = 0x01
S2_ALWAYS_ONE = 0x04
S2_WD_ON = 0x08

WAIT_PRM, WAIT_CFG, DATA_EXCH = "wait_prm", "wait_cfg", "data_exch"


def fcs(body):
    return sum(body) & 0xFF


def sd1(da, sa, fc):
    body = bytes([da, sa, fc])
    return bytes([SD1]) + body + bytes([fcs(body), ED])


def sd2(da, sa, fc, data):
    body = bytes([da, sa, fc]) + bytes(data)
    n = len(body)
    return bytes([SD2, n, n, SD2]) + body + bytes([fcs(body), ED])


def frames(buf):
    """Split complete telegrams off `buf` (a bytearray, consumed). Yields
    (da, sa, fc, data) for SD1/SD2/SD3; skips SD4, SC and garbage."""
    while buf:
        sd = buf[0]
        if sd == SD1:
            if len(buf) < 6:
                return
            t, rest = buf[:6], buf[6:]
            if t[5] == ED and fcs(t[1:4]) == t[4]:
                del buf[:6]
                yield t[1], t[2], t[3], b""
                continue
        elif sd == SD2:
            if len(buf) < 4:
                return
            n = buf[1]
            if buf[2] == n and buf[3] == SD2 and 3 <= n <= 249:
                if len(buf) < n + 6:
                    return
                t = buf[: n + 6]
                body = t[4 : 4 + n]
                if t[-1] == ED and fcs(body) == t[-2]:
                    del buf[: n + 6]
                    yield body[0], body[1], body[2], bytes(body[3:])
                    continue
        elif sd == SD3:
            if len(buf) < 14:
                return
            t = buf[:14]
            if t[13] == ED and fcs(t[1:12]) == t[12]:
                del buf[:14]
                yield t[1], t[2], t[3], bytes(t[4:12])
                continue
        elif sd == SD4:
            if len(buf) < 3:
                return
            del buf[:3]
            continue
        elif sd == SC:
            del buf[:1]
            continue
        del buf[:1]  # garbage or a broken telegram: resynchronise


class Slave:
    def __init__(self, addr, ident, cfg, inputs, always_one):
        self.addr = addr
        self.ident = ident
        self.cfg = cfg
        self.inputs = bytearray(inputs)
        self.always_one = always_one
        self.state = WAIT_PRM
        self.master = 0xFF
        self.prm_fault = False
        self.cfg_fault = False
        self.wd_on = False
        self.exchanges = 0

    def diag(self):
        s1 = 0
        if self.state != DATA_EXCH:
            s1 |= S1_NOT_READY
        if self.cfg_fault:
            s1 |= S1_CFG_FAULT
        if self.prm_fault:
            s1 |= S1_PRM_FAULT
        s2 = S2_WD_ON if self.wd_on else 0
        if self.state == WAIT_PRM:
            s2 |= S2_PRM_REQ
        if self.always_one:
            s2 |= S2_ALWAYS_ONE
        return bytes([s1, s2, 0, self.master, self.ident >> 8, self.ident & 0xFF])

    def on_request(self, da, sa, fc, data):
        """The answer to one request (bytes), or None."""
        if da & 0x7F != self.addr or not fc & FC_REQ:
            return None
        master = sa & 0x7F
        fn = fc & 0x0F
        if fn == FN_FDL_STATUS:
            return sd1(master, self.addr, RS_OK)
        has_saps = bool(da & 0x80)
        dsap = ssap = None
        if has_saps:
            if len(data) < 1:
                return None
            dsap, data = data[0], data[1:]
            if sa & 0x80:
                if len(data) < 1:
                    return None
                ssap, data = data[0], data[1:]
        if fn in (FN_SDN_LOW, FN_SDN_HIGH):
            return None  # no answer to SDN (Global_Control)
        if fn not in (FN_SRD_LOW, FN_SRD_HIGH):
            return sd1(master, self.addr, RS_RS)

        def reply(payload):
            # A reply carries the request's SAPs swapped.
            if ssap is None:
                return sd2(master, self.addr, RS_DL, payload)
            return sd2(master | 0x80, self.addr | 0x80, RS_DL,
                       bytes([ssap, dsap]) + payload)

        if dsap is None:
            return self.data_exchange(master, data)
        if dsap == SAP_SLAVE_DIAG:
            return reply(self.diag())
        if dsap == SAP_GET_CFG:
            return reply(self.cfg)
        if dsap == SAP_SET_PRM:
            self.set_prm(master, data)
            return bytes([SC])
        if dsap == SAP_CHK_CFG:
            self.chk_cfg(data)
            return bytes([SC])
        return sd1(master, self.addr, RS_RS)

    def set_prm(self, master, prm):
        # Station_Status, WD_Fact_1, WD_Fact_2, min TSDR, Ident (2),
        # Group_Ident, User_Prm_Data.
        if len(prm) < 7 or (prm[4] << 8 | prm[5]) != self.ident:
            self.prm_fault = True
            self.state = WAIT_PRM
            return
        self.prm_fault = False
        self.wd_on = bool(prm[0] & 0x08)
        self.master = master
        self.state = WAIT_CFG

    def chk_cfg(self, cfg):
        if self.state == WAIT_PRM:
            return
        self.cfg_fault = bytes(cfg) != self.cfg
        self.state = WAIT_PRM if self.cfg_fault else DATA_EXCH

    def data_exchange(self, master, outputs):
        if self.state != DATA_EXCH or master != self.master:
            return sd1(master, self.addr, RS_RS)
        n = min(len(outputs), len(self.inputs))
        self.inputs[:n] = outputs[:n]
        self.exchanges += 1
        if self.exchanges == 1:
            print("data_exchange", flush=True)
        if not self.inputs:
            return bytes([SC])
        return sd2(master, self.addr, RS_DL, self.inputs)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--port", required=True)
    ap.add_argument("--addr", type=int, required=True)
    ap.add_argument("--ident", type=lambda s: int(s, 0), required=True)
    ap.add_argument("--cfg", required=True, help="identifier bytes, hex")
    ap.add_argument("--inputs", type=int, required=True, help="input bytes")
    ap.add_argument("--always-one", action="store_true",
                    help="set bit 2 of Station_Status_2, as the standard asks")
    a = ap.parse_args()
    slave = Slave(a.addr, a.ident, bytes.fromhex(a.cfg), bytes(a.inputs),
                  a.always_one)
    fd = os.open(a.port, os.O_RDWR | os.O_NOCTTY)
    tty.setraw(fd)
    try:  # 8E1 on a real line; a pty refuses parity
        attrs = termios.tcgetattr(fd)
        attrs[2] |= termios.PARENB
        termios.tcsetattr(fd, termios.TCSANOW, attrs)
    except termios.error:
        pass
    print("ready", flush=True)
    buf = bytearray()
    while True:
        r, _, _ = select.select([fd], [], [], 1.0)
        if not r:
            continue
        try:
            chunk = os.read(fd, 512)
        except OSError:  # the other end of a pty closed
            return 0
        if not chunk:
            return 0
        buf += chunk
        for da, sa, fc, data in frames(buf):
            answer = slave.on_request(da, sa, fc, data)
            if answer:
                os.write(fd, answer)


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:
        sys.exit(0)
