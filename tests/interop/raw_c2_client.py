#!/usr/bin/env python3
"""A raw DP-V1 class-2 client (MSAC_C2 master) written from the wire
reference alone (../shared/reference/dpv1-c2-im-alarms.md and
profibus-dp.md), independent of the Rust stack.

It is the only active station on its line (a pty pair or serial line
with the slave, as pyprofibus runs): it sends SRDs and never passes a
token. Steps, one JSON line each on stdout with the PDUs and telegrams in
hex:

  initiate   Initiate.req to the resource manager (DSAP 49, SSAP 50); the
             RM reply `56 SAP u16` comes in the answer or, after a short
             acknowledge, on polls of SAP 49 (Felser's manual: "a poll
             cycle at SAP 49 with response data")
  connect    polls of the assigned SAP (empty SRDs) until Initiate.res;
             with --repeat-initiate the first poll carries Initiate.req
  im0        Write of the call header 08 00 FD E8 to slot 0 index 255,
             then Read of 68 bytes: call header + I&M0 in fields
  write      Write of --data to --slot/--index
  read       Read of that record back; must equal --data
  transport  (with --transport HEX) Data_Transport
  idle       Idle (48 00); with --idle-for S repeated every Send_Timeout/2
             for S seconds (the connection must survive)
  silent     (with --silent-for S) no telegram for S seconds, then an Idle
             that must be refused: the slave's Send_Timeout supervision
  abort      Abort (instance User) unless the connection is gone already
  closed     a Read on the old SAP must not be served any more

Every request on the connection SAP follows the class-1 pattern: SRD with
the request, short acknowledge (SC) while the slave works, polls (empty
SRDs, FCB toggled) until the response comes as DL.

Exit status 0 when every step went as the reference says; 1 with one line
`raw_c2_client: STEP: what happened` on stderr otherwise.
"""

import argparse
import json
import sys
import time

import raw_c2 as c2
import raw_fdl as fdl


class StepError(Exception):
    pass


class Client:
    def __init__(self, req, slave, send_timeout, reply_timeout):
        self.req = req
        self.slave = slave
        self.send_timeout = send_timeout  # 10 ms units
        self.reply_timeout = reply_timeout
        self.sap = None
        self.telegrams = []

    def emit(self, step, **fields):
        line = {"step": step}
        line.update(fields)
        line["telegrams"] = [c2.hexs(t) for _, t in self.telegrams]
        self.telegrams = []
        print(json.dumps(line), flush=True)

    def srd(self, dsap, du=b""):
        try:
            f = self.req.srd(self.slave, dsap, c2.SAP_MASTER_C2, du)
        except fdl.NoAnswer as e:
            raise StepError(str(e))
        self.telegrams.extend(self.req.log)
        return f

    def transaction(self, dsap, pdu, first_answer=None):
        """Send `pdu` to `dsap` and poll until the slave answers with data
        (DL/DH). Returns the PDU of the answer. A negative response or an
        Abort is raised in words."""
        f = first_answer or self.srd(dsap, pdu)
        polls = 0
        end = time.monotonic() + self.reply_timeout
        while True:
            if f.kind == "data":
                st = f.status
                if st in (fdl.ST_DL, fdl.ST_DH) and f.du:
                    if f.dsap != c2.SAP_MASTER_C2 or f.ssap != dsap:
                        raise StepError(
                            "answer with DSAP %s SSAP %s, expected DSAP %d "
                            "SSAP %d" % (f.dsap, f.ssap, c2.SAP_MASTER_C2,
                                         dsap))
                    return check(f.du)
                if st not in (fdl.ST_OK, fdl.ST_NR, fdl.ST_DL, fdl.ST_DH):
                    raise StepError("SAP %d answered FDL %s"
                                    % (dsap, fdl.STATUS_NAMES.get(st, st)))
            if time.monotonic() > end:
                raise StepError("no answer on SAP %d after %d polls in %.1f s"
                                % (dsap, polls, self.reply_timeout))
            time.sleep(0.002)
            f = self.srd(dsap)
            polls += 1

    # ---- steps ---------------------------------------------------------

    def initiate(self, repeat_initiate):
        req = c2.initiate_req(self.send_timeout)
        rm = c2.parse_rm(self.transaction(c2.SAP_RM, req))
        self.sap = rm["sap"]
        self.emit("initiate", request=c2.hexs(req),
                  response=c2.hexs(c2.rm_reply(rm["sap"], rm["poll_timeout"])),
                  **rm)
        first = self.srd(self.sap, req) if repeat_initiate else None
        res_pdu = self.transaction(self.sap, b"", first_answer=first or
                                   self.srd(self.sap))
        res = c2.parse_initiate_res(res_pdu)
        self.emit("connect", sap=self.sap, response=c2.hexs(res_pdu), **res)
        return res

    def write(self, slot, index, data, step="write"):
        req = c2.write_req(slot, index, data)
        res = self.transaction(self.sap, req)
        want = req[:4]
        if res != want:
            raise StepError("Write.res %s, expected %s" % (c2.hexs(res),
                                                           c2.hexs(want)))
        self.emit(step, slot=slot, index=index, request=c2.hexs(req),
                  response=c2.hexs(res))

    def read(self, slot, index, length):
        req = c2.read_req(slot, index, length)
        res = self.transaction(self.sap, req)
        if len(res) < 4 or res[0] != c2.FN_READ or res[1:3] != req[1:3]:
            raise StepError("Read.res %s does not answer %s"
                            % (c2.hexs(res), c2.hexs(req)))
        if res[3] != len(res) - 4 or not 1 <= res[3] <= length:
            raise StepError("Read.res length byte %d with %d data bytes "
                            "(asked for %d)" % (res[3], len(res) - 4, length))
        return req, res

    def im0(self):
        head = c2.call_header(c2.IM0_FI)
        self.write(0, c2.IM_INDEX, head, step="im0_call")
        req, res = self.read(0, c2.IM_INDEX, 4 + c2.IM_RECORD_LEN)
        data = res[4:]
        if data[:4] != head:
            raise StepError("I&M0 answer starts %s, not the call header %s"
                            % (c2.hexs(data[:4]), c2.hexs(head)))
        try:
            fields = c2.parse_im0(data[4:])
        except c2.PduError as e:
            raise StepError(str(e))
        self.emit("im0", request=c2.hexs(req), response=c2.hexs(res),
                  **fields)

    def record(self, slot, index, data):
        self.write(slot, index, data)
        req, res = self.read(slot, index, 240)
        got = res[4:]
        self.emit("read", slot=slot, index=index, request=c2.hexs(req),
                  response=c2.hexs(res), data=c2.hexs(got))
        if got != data:
            raise StepError("read back %s, wrote %s" % (c2.hexs(got),
                                                        c2.hexs(data)))

    def transport(self, slot, index, data):
        req = c2.transport_req(slot, index, data)
        res = self.transaction(self.sap, req)
        if len(res) < 4 or res[0] != c2.FN_TRANSPORT or res[3] != len(res) - 4:
            raise StepError("Data_Transport answer %s" % c2.hexs(res))
        self.emit("transport", slot=slot, index=index, request=c2.hexs(req),
                  response=c2.hexs(res), data=c2.hexs(res[4:]))

    def idle(self, seconds):
        end = time.monotonic() + seconds
        n = 0
        while True:
            res = self.transaction(self.sap, c2.idle())
            if len(res) < 1 or res[0] != c2.FN_IDLE:
                raise StepError("Idle answered by %s" % c2.hexs(res))
            n += 1
            if time.monotonic() >= end:
                break
            time.sleep(min(self.send_timeout * 0.01 / 2,
                           max(0.0, end - time.monotonic())))
        self.emit("idle", idles=n, response=c2.hexs(res))

    def silent(self, seconds):
        """Fall silent longer than Send_Timeout: the slave must have
        dropped the connection (an Abort TO, FDL RS, or no Idle answer)."""
        time.sleep(seconds)
        f = self.srd(self.sap, c2.idle())
        how = None
        if f.kind == "data" and f.status == fdl.ST_RS:
            how = "RS"
        elif f.kind == "data" and f.du and f.du[0] == c2.FN_ABORT:
            how = c2.describe_abort(f.du)
        elif f.kind == "sc":
            # The Idle went in as a request: poll for what it becomes.
            try:
                res = self.transaction(self.sap, b"", first_answer=f)
            except StepError as e:
                how = str(e)
            else:
                raise StepError("the connection outlived Send_Timeout: "
                                "Idle answered by %s" % c2.hexs(res))
        else:
            raise StepError("after %.1f s of silence the slave still answers "
                            "the Idle: %s" % (seconds, c2.hexs(f.du)))
        self.emit("silent", seconds=seconds, refused=how)

    def abort(self):
        pdu = c2.abort(c2.INSTANCE_USER, 0)
        f = self.srd(self.sap, pdu)
        if f.kind == "data" and f.status not in (fdl.ST_OK, fdl.ST_NR,
                                                 fdl.ST_DL):
            raise StepError("Abort answered FDL %s"
                            % fdl.STATUS_NAMES.get(f.status, f.status))
        self.emit("abort", sap=self.sap, request=c2.hexs(pdu),
                  answer="SC" if f.kind == "sc" else c2.hexs(f.du))

    def closed(self):
        """After Abort the SAP must not serve requests any more."""
        req = c2.read_req(0, 1, 240)
        f = self.srd(self.sap, req)
        how = None
        if f.kind == "data" and f.status == fdl.ST_RS:
            how = "RS"
        elif f.kind == "data" and f.du and f.du[0] == c2.FN_ABORT:
            how = c2.describe_abort(f.du)
        elif f.kind == "data" and f.du and f.du[0] & c2.NEGATIVE:
            how = c2.describe_negative(f.du)
        else:
            try:
                res = self.transaction(self.sap, b"", first_answer=f)
            except StepError as e:
                how = str(e)
            else:
                raise StepError("SAP %d still serves requests after Abort: %s"
                                % (self.sap, c2.hexs(res)))
        self.emit("closed", sap=self.sap, refused=how)


def check(pdu):
    """Raise negative responses and aborts in words."""
    if pdu and pdu[0] == c2.FN_ABORT:
        raise StepError("the slave aborted: %s" % c2.describe_abort(pdu))
    if pdu and pdu[0] & c2.NEGATIVE:
        raise StepError(c2.describe_negative(pdu))
    return pdu


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--port", required=True, help="pty or serial device")
    ap.add_argument("--addr", type=int, default=1,
                    help="own station address (default 1)")
    ap.add_argument("--slave", type=int, required=True)
    ap.add_argument("--send-timeout", type=int, default=300,
                    help="Send_Timeout in 10 ms units (default 300 = 3 s)")
    ap.add_argument("--slot", type=int, default=0)
    ap.add_argument("--index", type=int, default=1)
    ap.add_argument("--data", default="C2 01 02 03",
                    help="record bytes to write and read back, hex")
    ap.add_argument("--transport", help="Data_Transport bytes, hex")
    ap.add_argument("--no-im", action="store_true", help="skip I&M0")
    ap.add_argument("--repeat-initiate", action="store_true",
                    help="first poll of the connection SAP carries the "
                         "Initiate.req again")
    ap.add_argument("--idle-for", type=float, default=0.0)
    ap.add_argument("--silent-for", type=float)
    ap.add_argument("--slot-ms", type=float, default=300.0,
                    help="wait this long for each answer (default 300)")
    ap.add_argument("--reply-timeout", type=float, default=10.0,
                    help="seconds to poll for a response (default 10)")
    ap.add_argument("--low", action="store_true",
                    help="SRD low instead of SRD high")
    a = ap.parse_args()
    try:
        data = bytes.fromhex(a.data)
        transport = bytes.fromhex(a.transport) if a.transport else None
    except ValueError as e:
        ap.error("bad hex: %s" % e)
    if not 1 <= len(data) <= 240:
        ap.error("--data must be 1..240 bytes")

    port = fdl.Port(fdl.open_port(a.port))
    req = fdl.Requester(port, a.addr, slot_s=a.slot_ms / 1000.0,
                        high=not a.low)
    cl = Client(req, a.slave, a.send_timeout, a.reply_timeout)
    step = "initiate"
    try:
        cl.initiate(a.repeat_initiate)
        if not a.no_im:
            step = "im0"
            cl.im0()
        step = "record"
        cl.record(a.slot, a.index, data)
        if transport is not None:
            step = "transport"
            cl.transport(a.slot, a.index, transport)
        step = "idle"
        cl.idle(a.idle_for)
        if a.silent_for is not None:
            step = "silent"
            cl.silent(a.silent_for)
        else:
            step = "abort"
            cl.abort()
            step = "closed"
            cl.closed()
    except (StepError, c2.PduError, EOFError) as e:
        print("raw_c2_client: %s: %s" % (step, e), file=sys.stderr,
              flush=True)
        return 1
    print(json.dumps({"step": "done"}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
