"""FDL telegrams for the raw class-2 peers (raw_c2_client.py,
raw_c2_slave.py), written from the wire reference
(../shared/reference/profibus-dp.md sections 1-3, IEC 61158-4-3), not from
the Rust stack: SD1/SD2/SD3/SD4/SC with their FCS, the request and
response function codes, FCB/FCV, and opening a pty or serial line.

Only the Python standard library is used.
"""

import os
import select
import termios
import time
import tty

SD1, SD2, SD3, SD4, SC, ED = 0x10, 0x68, 0xA2, 0xDC, 0xE5, 0x16

# Request FC: bit 6 set, FCB bit 5, FCV bit 4, function bits 3-0.
FC_REQUEST = 0x40
FC_FCB = 0x20
FC_FCV = 0x10
FN_SRD_LOW = 0xC
FN_SRD_HIGH = 0xD
FN_SDN_LOW = 0x4
FN_SDN_HIGH = 0x6
FN_FDL_STATUS = 0x9

# Response FC: bit 6 clear, station type bits 5-4, status bits 3-0.
ST_OK, ST_UE, ST_RR, ST_RS = 0x0, 0x1, 0x2, 0x3
ST_DL, ST_NR, ST_DH, ST_RDL, ST_RDH = 0x8, 0x9, 0xA, 0xC, 0xD
STATUS_NAMES = {
    ST_OK: "OK", ST_UE: "UE (user error)", ST_RR: "RR (no resources)",
    ST_RS: "RS (SAP not activated)", ST_DL: "DL", ST_NR: "NR (no data)",
    ST_DH: "DH", ST_RDL: "RDL", ST_RDH: "RDH",
}

EXT = 0x80  # address extension: a SAP byte follows FC


def fcs(body):
    """Arithmetic sum mod 256 of DA, SA, FC, the SAP bytes and the DU."""
    return sum(body) & 0xFF


def telegram(da, sa, fc, du=b""):
    """SD1 for an empty data field, else SD2 (as slave ASICs answer)."""
    body = bytes([da, sa, fc]) + bytes(du)
    if not du:
        return bytes([SD1]) + body + bytes([fcs(body), ED])
    n = len(body)
    if n > 249:
        raise ValueError("data field of %d bytes, at most 246" % (n - 3))
    return bytes([SD2, n, n, SD2]) + body + bytes([fcs(body), ED])


class Frame:
    """One received telegram. `kind` is "sc", "token" or "data" (SD1,
    SD2 or SD3); for "data": da and sa without the extension bit, fc,
    dsap/ssap (None when absent) and du (the data after the SAP bytes)."""

    def __init__(self, kind, raw, da=None, sa=None, fc=None, dsap=None,
                 ssap=None, du=b""):
        self.kind, self.raw = kind, bytes(raw)
        self.da, self.sa, self.fc = da, sa, fc
        self.dsap, self.ssap, self.du = dsap, ssap, bytes(du)

    @property
    def is_request(self):
        return self.kind == "data" and bool(self.fc & FC_REQUEST)

    @property
    def status(self):
        """Response status (bits 3-0 of FC); SC counts as no data."""
        return None if self.kind != "data" else self.fc & 0x0F


def _data_frame(raw, body):
    da, sa, fc, rest = body[0], body[1], body[2], body[3:]
    dsap = ssap = None
    if da & EXT and rest:
        dsap, rest = rest[0], rest[1:]
    if sa & EXT and rest:
        ssap, rest = rest[0], rest[1:]
    return Frame("data", raw, da & 0x7F, sa & 0x7F, fc, dsap, ssap, rest)


def split(buf):
    """Take the complete telegrams off the front of `buf` (a bytearray,
    consumed) and return them as Frames. A broken telegram is dropped one
    byte at a time until a start delimiter resynchronises."""
    out = []
    while buf:
        sd = buf[0]
        if sd == SC:
            out.append(Frame("sc", buf[:1]))
            del buf[:1]
            continue
        if sd == SD4:
            if len(buf) < 3:
                break
            out.append(Frame("token", buf[:3], buf[1] & 0x7F, buf[2] & 0x7F))
            del buf[:3]
            continue
        if sd == SD1:
            if len(buf) < 6:
                break
            t = bytes(buf[:6])
            if t[5] == ED and fcs(t[1:4]) == t[4]:
                del buf[:6]
                out.append(_data_frame(t, t[1:4]))
                continue
        elif sd == SD3:
            if len(buf) < 14:
                break
            t = bytes(buf[:14])
            if t[13] == ED and fcs(t[1:12]) == t[12]:
                del buf[:14]
                out.append(_data_frame(t, t[1:12]))
                continue
        elif sd == SD2:
            if len(buf) < 4:
                break
            n = buf[1]
            if buf[2] == n and buf[3] == SD2 and 3 <= n <= 249:
                if len(buf) < n + 6:
                    break
                t = bytes(buf[: n + 6])
                body = t[4: 4 + n]
                if t[-1] == ED and fcs(body) == t[-2]:
                    del buf[: n + 6]
                    out.append(_data_frame(t, body))
                    continue
        del buf[:1]
    return out


def open_port(path):
    """Open a pty or serial device raw (8E1 where the device takes
    parity; a pty refuses it)."""
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    tty.setraw(fd)
    try:
        attrs = termios.tcgetattr(fd)
        attrs[2] |= termios.PARENB
        termios.tcsetattr(fd, termios.TCSANOW, attrs)
    except termios.error:
        pass
    return fd


class Port:
    """A line: write telegrams, read Frames with a deadline."""

    def __init__(self, fd):
        self.fd = fd
        self.buf = bytearray()
        self.frames = []

    def write(self, data):
        os.write(self.fd, data)

    def read(self, timeout):
        """The next Frame within `timeout` seconds, or None. Raises
        EOFError when the other end closed."""
        end = time.monotonic() + timeout
        while not self.frames:
            left = end - time.monotonic()
            if left <= 0:
                return None
            r, _, _ = select.select([self.fd], [], [], left)
            if not r:
                continue
            try:
                chunk = os.read(self.fd, 512)
            except OSError as e:
                raise EOFError(str(e))
            if not chunk:
                raise EOFError("end of file")
            self.buf += chunk
            self.frames.extend(split(self.buf))
        return self.frames.pop(0)


class NoAnswer(Exception):
    """The responder did not answer within the slot time, retries
    included."""


class Requester:
    """The initiator side of SRD: one FCB per responder (the first
    request to a responder FCV=0 FCB=1, then FCV=1 with FCB toggled; a
    retry repeats the same FC), a slot time, one retry."""

    def __init__(self, port, own, slot_s=0.5, retries=1, high=True):
        self.port, self.own = port, own
        self.slot_s, self.retries = slot_s, retries
        self.fn = FN_SRD_HIGH if high else FN_SRD_LOW
        self.fcb = {}  # responder -> FCB of the last request, None = new
        self.log = []  # (direction, telegram) of the last exchange

    def next_fc(self, da):
        last = self.fcb.get(da)
        if last is None:
            fcb, fcv = 1, 0
        else:
            fcb, fcv = last ^ 1, 1
        self.fcb[da] = fcb
        return FC_REQUEST | (fcb << 5) | (fcv << 4) | self.fn

    def srd(self, da, dsap, ssap, du=b""):
        """Send SRD with SAPs and `du`; the answer Frame (kind "sc" or a
        "data" response addressed to us). Raises NoAnswer."""
        fc = self.next_fc(da)
        t = telegram(da | EXT, self.own | EXT, fc, bytes([dsap, ssap]) + du)
        self.log = []
        for _ in range(1 + self.retries):
            self.port.write(t)
            self.log.append(("req", t))
            end = time.monotonic() + self.slot_s
            while True:
                left = end - time.monotonic()
                f = self.port.read(left) if left > 0 else None
                if f is None:
                    break
                if f.kind == "sc" or (f.kind == "data" and not f.is_request
                                      and f.da == self.own and f.sa == da):
                    self.log.append(("res", f.raw))
                    return f
        self.fcb[da] = None  # non-operational: start again with FCV=0
        raise NoAnswer("station %d did not answer SRD to SAP %d within "
                       "%.0f ms (%d tries)" % (da, dsap, self.slot_s * 1000,
                                               1 + self.retries))
