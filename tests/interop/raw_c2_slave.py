#!/usr/bin/env python3
"""A scripted raw DP-V1 slave with class-2 services (MSAC_C2), written
from the wire reference alone (../shared/reference/dpv1-c2-im-alarms.md
and profibus-dp.md), independent of the Rust stack.

A passive station: FDL status, a minimal Slave_Diag (not parameterised)
and the class-2 services; every other SAP is answered RS.

  SAP 49 (resource manager)  Initiate.req (from SSAP 50): checked for
        length (FE), address types and lengths (IA) and Send_Timeout
        against --min-send-timeout (STO); refused with an Abort PDU then.
        With no free connection SAP: FDL RS (Felser's manual: "if the
        resource manager has no more free SAPs, it reports this at the
        FDL layer with RS"). Otherwise the RM reply `56 SAP u16` (u16 =
        --min-send-timeout), immediately in the answer (--rm immediate,
        [VPC3]) or after SC on the next poll of SAP 49 (--rm poll,
        Felser).
  connection SAPs 48, 47, ... (--channels of them, highest first as in
        the [BAL] trace): the first SRDs are answered SC until
        --delay-polls polls went by, then Initiate.res. After that each
        request (Read, Write, Data_Transport) is answered SC and its
        response comes as DL on a later poll; Idle is answered at once
        (48 00) unless a response is ready, which then comes instead.
        Abort closes the connection (SC). A request while a response is
        still pending aborts the connection with SE.
  Send_Timeout supervision: no telegram on a connection for its
        Send_Timeout closes it (reason TO); the next request on the SAP
        is answered with that Abort PDU, later ones RS.

Records: --record SLOT:INDEX=HEX (repeatable) preset the table; Write
stores any record; Read of an unknown record: negative B0 (invalid
index). I&M: slot 0 index 255 with the call header 08 00 FI_Index; Write
of the bare header selects I&Mn (65000+n), the next Read returns call
header + 64 bytes; Write of header + 64 bytes stores I&M1..4 (I&M0 is
read-only: B6 access denied). Data_Transport answers the data reversed.
--mute-after N stops answering anything after N class-2 requests (a
slave that falls silent).

Logs one JSON line per event on stdout: {"event": "ready"}, then "rx"
for every class-2 telegram (sap, master, service, pdu, answer),
"connection" (open/closed with the reason), "abort" (sent or received,
instance and reason in words).
"""

import argparse
import json
import sys
import time

import raw_c2 as c2
import raw_fdl as fdl

SAP_SLAVE_DIAG = 60


def log(event, **fields):
    line = {"event": event}
    line.update(fields)
    print(json.dumps(line), flush=True)


class Conn:
    def __init__(self, sap, master, send_timeout, delay_polls, init_res):
        self.sap = sap
        self.master = master
        self.send_timeout = send_timeout  # 10 ms units
        self.last_rx = time.monotonic()
        self.open = False
        self.pending = init_res  # response waiting for a poll
        self.delay = delay_polls
        self.im_fi = None  # FI_Index selected by the call header


class C2Slave:
    def __init__(self, a):
        self.a = a
        self.addr = a.addr
        self.free = [48 - i for i in range(a.channels)]
        self.conns = {}  # sap -> Conn
        self.dead = {}  # sap -> Abort PDU owed to the master
        self.rm_owed = {}  # master -> RM answer owed on a poll of SAP 49
        self.fcb = {}  # master -> (fcb, answer) for FCB repeats
        self.records = dict(a.records)
        self.im = {n: bytes([0x20] * 64) for n in (1, 2, 3)}
        self.im[4] = bytes(64)
        self.im[0] = c2.im0(a.manufacturer_id, a.order_id, a.serial, 1,
                            ("V", 1, 2, 3), im_supported=0x001E)
        self.requests = 0
        self.muted = False

    # ---- FDL -----------------------------------------------------------

    def on_frame(self, f):
        if self.muted or f.kind != "data" or not f.is_request:
            return None
        if f.da != self.addr:
            return None
        fn = f.fc & 0x0F
        if fn == fdl.FN_FDL_STATUS:
            return fdl.telegram(f.sa, self.addr, fdl.ST_OK)
        if fn in (fdl.FN_SDN_LOW, fdl.FN_SDN_HIGH):
            return None
        if fn not in (fdl.FN_SRD_LOW, fdl.FN_SRD_HIGH):
            return fdl.telegram(f.sa, self.addr, fdl.ST_RS)
        fcv, fcb = bool(f.fc & fdl.FC_FCV), bool(f.fc & fdl.FC_FCB)
        last = self.fcb.get(f.sa)
        if fcv and last is not None and last[0] == fcb:
            return last[1]  # a retry: the answer again, not executed again
        answer = self.srd(f)
        self.fcb[f.sa] = (fcb, answer)
        return answer

    def reply(self, f, pdu):
        return fdl.telegram(f.sa | fdl.EXT, self.addr | fdl.EXT, fdl.ST_DL,
                            bytes([f.ssap, f.dsap]) + pdu)

    def srd(self, f):
        if f.dsap is None:
            return fdl.telegram(f.sa, self.addr, fdl.ST_RS)
        if f.dsap == SAP_SLAVE_DIAG:
            # Not parameterised: Station_Not_Ready; Prm_Req, always-1 bit.
            return self.reply(f, bytes([0x02, 0x05, 0x00, 0xFF,
                                        self.a.ident >> 8,
                                        self.a.ident & 0xFF]))
        if f.dsap == c2.SAP_RM or f.dsap in c2.CONNECTION_SAPS:
            self.requests += 1
            if self.a.mute_after and self.requests > self.a.mute_after:
                self.muted = True
                log("muted", after=self.a.mute_after)
                return None
            if f.dsap == c2.SAP_RM:
                kind, pdu = self.rm(f)
            else:
                kind, pdu = self.connection(f)
            log("rx", sap=f.dsap, master=f.sa, ssap=f.ssap,
                service=service(f.du), pdu=c2.hexs(f.du), answer=kind,
                response=c2.hexs(pdu) if pdu else None)
            if kind == "SC":
                return bytes([fdl.SC])
            if kind == "RS":
                return fdl.telegram(f.sa, self.addr, fdl.ST_RS)
            return self.reply(f, pdu)
        return fdl.telegram(f.sa, self.addr, fdl.ST_RS)

    # ---- resource manager ----------------------------------------------

    def rm(self, f):
        if not f.du:
            owed = self.rm_owed.pop(f.sa, None)
            return ("DL", owed) if owed else ("SC", None)
        if f.ssap != c2.SAP_MASTER_C2:
            return self.refuse(f.dsap, c2.REASON_CODES["FE"])
        try:
            req = c2.parse_initiate_req(f.du)
        except c2.PduError as e:
            reason = "IA" if "Type" in str(e) or "address" in str(e) else "FE"
            log("initiate_refused", master=f.sa, why=str(e))
            return self.refuse(f.dsap, c2.REASON_CODES[reason])
        if req["send_timeout"] < self.a.min_send_timeout:
            log("initiate_refused", master=f.sa,
                why="Send_Timeout %d below %d" % (req["send_timeout"],
                                                  self.a.min_send_timeout))
            return self.refuse(f.dsap, c2.REASON_CODES["STO"])
        if not self.free:
            log("initiate_refused", master=f.sa, why="no free connection")
            return ("RS", None)
        sap = self.free.pop(0)
        res = c2.initiate_res(max_len=self.a.max_len,
                              s_addr=b"\x00\x00", d_addr=b"\x00\x00")
        self.conns[sap] = Conn(sap, f.sa, req["send_timeout"],
                               self.a.delay_polls, res)
        self.dead.pop(sap, None)
        log("connection", sap=sap, master=f.sa, state="initiating",
            send_timeout=req["send_timeout"])
        pdu = c2.rm_reply(sap, self.a.min_send_timeout)
        if self.a.rm == "poll":
            self.rm_owed[f.sa] = pdu
            return ("SC", None)
        return ("DL", pdu)

    def refuse(self, sap, reason):
        pdu = c2.abort(c2.INSTANCE_MSAC_C2, reason)
        log("abort", direction="sent", sap=sap, **c2.parse_abort(pdu))
        return ("DL", pdu)

    # ---- connections ---------------------------------------------------

    def close(self, conn, why, pdu=None):
        del self.conns[conn.sap]
        self.free.append(conn.sap)
        self.free.sort(reverse=True)
        if pdu is not None:
            self.dead[conn.sap] = pdu
        log("connection", sap=conn.sap, master=conn.master, state="closed",
            why=why)

    def supervise(self):
        now = time.monotonic()
        for conn in list(self.conns.values()):
            if now - conn.last_rx > conn.send_timeout * 0.01:
                pdu = c2.abort(c2.INSTANCE_MSAC_C2, c2.REASON_CODES["TO"])
                log("abort", direction="sent", sap=conn.sap,
                    **c2.parse_abort(pdu))
                self.close(conn, "Send_Timeout", pdu)

    def connection(self, f):
        conn = self.conns.get(f.dsap)
        if conn is None or conn.master != f.sa:
            owed = self.dead.pop(f.dsap, None)
            return ("DL", owed) if owed else ("RS", None)
        conn.last_rx = time.monotonic()
        du = f.du
        if not conn.open:
            if du and du[0] != c2.FN_INITIATE:
                pdu = c2.abort(c2.INSTANCE_MSAC_C2, c2.REASON_CODES["SE"])
                log("abort", direction="sent", sap=conn.sap,
                    **c2.parse_abort(pdu))
                self.close(conn, "request before Initiate.res")
                return ("DL", pdu)
            return self.poll(conn)
        if not du:
            return self.poll(conn)
        fn = du[0]
        if fn == c2.FN_ABORT:
            try:
                a = c2.parse_abort(du)
            except c2.PduError:
                a = {"pdu": c2.hexs(du)}
            log("abort", direction="received", sap=conn.sap, **a)
            self.close(conn, "Abort received")
            return ("SC", None)
        if fn == c2.FN_IDLE:
            if conn.pending is not None and conn.delay == 0:
                return self.poll(conn)
            return ("DL", c2.idle())
        if conn.pending is not None:
            pdu = c2.abort(c2.INSTANCE_MSAC_C2, c2.REASON_CODES["SE"])
            log("abort", direction="sent", sap=conn.sap,
                **c2.parse_abort(pdu))
            self.close(conn, "request while a response was pending")
            return ("DL", pdu)
        conn.pending = self.serve(conn, du)
        conn.delay = self.a.delay_polls
        return ("SC", None)

    def poll(self, conn):
        if conn.pending is None:
            return ("SC", None)
        if conn.delay > 0:
            conn.delay -= 1
            return ("SC", None)
        pdu, conn.pending = conn.pending, None
        if not conn.open:
            conn.open = True
            log("connection", sap=conn.sap, master=conn.master, state="open")
        return ("DL", pdu)

    def serve(self, conn, du):
        fn = du[0]
        if fn == c2.FN_READ:
            if len(du) != 4 or not 1 <= du[3] <= 240:
                return c2.negative(fn, 0xB3)
            slot, index, n = du[1], du[2], du[3]
            if index == c2.IM_INDEX:
                return self.im_read(conn, slot, n)
            data = self.records.get((slot, index))
            if data is None:
                return c2.negative(fn, 0xB0)
            data = data[:n]
            return bytes([fn, slot, index, len(data)]) + data
        if fn in (c2.FN_WRITE, c2.FN_TRANSPORT):
            if len(du) < 5 or du[3] != len(du) - 4:
                return c2.negative(fn, 0xB1)
            slot, index, data = du[1], du[2], du[4:]
            if fn == c2.FN_TRANSPORT:
                back = data[::-1]
                return bytes([fn, slot, index, len(back)]) + back
            if index == c2.IM_INDEX:
                return self.im_write(conn, slot, data)
            self.records[(slot, index)] = bytes(data)
            return du[:4]
        return c2.negative(fn & 0x7F, 0xA9)

    def im_write(self, conn, slot, data):
        if slot != 0 or len(data) < 4 or data[0] != c2.CALL or data[1] != 0:
            return c2.negative(c2.FN_WRITE, 0xB0)
        n = c2.u16(data, 2) - c2.IM0_FI
        if n not in self.im:
            return c2.negative(c2.FN_WRITE, 0xB0)
        body = data[4:]
        if body:
            if n == 0:
                return c2.negative(c2.FN_WRITE, 0xB6)
            if len(body) != c2.IM_RECORD_LEN:
                return c2.negative(c2.FN_WRITE, 0xB1)
            self.im[n] = bytes(body)
        conn.im_fi = n
        return bytes([c2.FN_WRITE, slot, c2.IM_INDEX, len(data)])

    def im_read(self, conn, slot, n):
        if slot != 0 or conn.im_fi is None:
            return c2.negative(c2.FN_READ, 0xB5)  # state conflict
        data = (c2.call_header(c2.IM0_FI + conn.im_fi) + self.im[conn.im_fi])
        data = data[:n]
        return bytes([c2.FN_READ, slot, c2.IM_INDEX, len(data)]) + data


def service(du):
    if not du:
        return "poll"
    name = c2.FN_NAMES.get(du[0] & 0x7F, "%02X" % du[0])
    return name + ("_negative" if du[0] & c2.NEGATIVE else "")


def record_arg(s):
    try:
        where, data = s.split("=", 1)
        slot, index = where.split(":")
        return (int(slot, 0), int(index, 0)), bytes.fromhex(data)
    except ValueError:
        raise argparse.ArgumentTypeError("SLOT:INDEX=HEX, e.g. 1:2=0A0B")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--port", required=True)
    ap.add_argument("--addr", type=int, required=True)
    ap.add_argument("--ident", type=lambda s: int(s, 0), default=0x0DCE)
    ap.add_argument("--channels", type=int, default=1,
                    help="connection SAPs (C2_Max_Count_Channels)")
    ap.add_argument("--max-len", type=int, default=240,
                    help="Max_Len_Data_Unit in Initiate.res")
    ap.add_argument("--min-send-timeout", type=int, default=100,
                    help="smallest Send_Timeout accepted, 10 ms units")
    ap.add_argument("--rm", choices=["immediate", "poll"], default="poll")
    ap.add_argument("--delay-polls", type=int, default=1,
                    help="polls answered SC before each response")
    ap.add_argument("--record", type=record_arg, action="append",
                    default=[], dest="records")
    ap.add_argument("--order-id", default="RAW-C2-SLAVE")
    ap.add_argument("--serial", default="0001")
    ap.add_argument("--manufacturer-id", type=lambda s: int(s, 0),
                    default=0x0000)
    ap.add_argument("--mute-after", type=int, default=0)
    a = ap.parse_args()
    slave = C2Slave(a)
    port = fdl.Port(fdl.open_port(a.port))
    log("ready", addr=a.addr)
    while True:
        slave.supervise()
        try:
            f = port.read(0.01)
        except EOFError:
            return 0
        if f is None:
            continue
        answer = slave.on_frame(f)
        if answer:
            port.write(answer)


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:
        sys.exit(0)
