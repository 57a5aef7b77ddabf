"""DP-V1 class-2 (MSAC_C2) and I&M PDUs for the raw peers, written from
../shared/reference/dpv1-c2-im-alarms.md (sections 4.2-4.4 and 4.6) and
profibus-dp.md section 9 alone, not from the Rust stack. Section numbers
below refer to dpv1-c2-im-alarms.md.

Only the Python standard library is used.
"""

# SAPs (4.2): the resource manager on the slave, the class-2 master's SAP,
# the range the RM assigns connection SAPs from.
SAP_RM = 49
SAP_MASTER_C2 = 50
CONNECTION_SAPS = range(0, 49)

# Function numbers (4.3); the negative form sets bit 7.
FN_IDLE = 0x48
FN_TRANSPORT = 0x51
FN_RM = 0x56
FN_INITIATE = 0x57
FN_ABORT = 0x58
FN_READ = 0x5E
FN_WRITE = 0x5F
NEGATIVE = 0x80
FN_NAMES = {
    FN_IDLE: "idle", FN_TRANSPORT: "data_transport", FN_RM: "rm",
    FN_INITIATE: "initiate", FN_ABORT: "abort", FN_READ: "read",
    FN_WRITE: "write", 0x5C: "alarm_ack",
}

# Abort (4.4): Subnet, Instance (b5-4) | Reason (b3-0), Additional detail.
INSTANCES = {0x00: "FDL", 0x10: "MSAC_C2", 0x20: "User", 0x30: "reserved"}
INSTANCE_FDL, INSTANCE_MSAC_C2, INSTANCE_USER = 0x00, 0x10, 0x20
REASONS = {
    1: ("SE", "sequence error"),
    2: ("FE", "invalid request PDU"),
    3: ("TO", "connection timeout"),
    4: ("RE", "invalid response PDU"),
    5: ("IV", "invalid service from the user"),
    6: ("STO", "Send_Timeout too small"),
    7: ("IA", "invalid additional address information"),
    8: ("OC", "waiting for FDL_DATA_REPLY.con"),
    0xF: ("RES", "resource error"),
}
REASON_CODES = {name: code for code, (name, _) in REASONS.items()}

# I&M (4.6): the Call on index 255, FI_Index 65000 + n for I&Mn.
IM_INDEX = 255
CALL = 0x08
IM0_FI = 65000
IM_RECORD_LEN = 64

# Error_Code_1 classes and codes (profibus-dp.md section 9).
ERROR_CLASSES = {
    0xA: ("application", {0: "read error", 1: "write error",
                          2: "module failure", 8: "version conflict",
                          9: "feature not supported"}),
    0xB: ("access", {0: "invalid index", 1: "write length error",
                     2: "invalid slot", 3: "type conflict",
                     4: "invalid area", 5: "state conflict",
                     6: "access denied", 7: "invalid range",
                     8: "invalid parameter", 9: "invalid type"}),
    0xC: ("resource", {0: "read constraint conflict",
                       1: "write constraint conflict", 2: "busy",
                       3: "unavailable"}),
}


def hexs(b):
    return bytes(b).hex(" ").upper()


def u16(b, off):
    return b[off] << 8 | b[off + 1]


def be16(v):
    return bytes([(v >> 8) & 0xFF, v & 0xFF])


class PduError(Exception):
    """A PDU that does not follow the reference."""


# ---- Initiate ------------------------------------------------------------

def initiate_req(send_timeout, features1=0x01, features2=0x00,
                 profile_features=0, profile_ident=0,
                 s_addr=b"\x00\x00", d_addr=b"\x00\x00"):
    """Initiate.req (4.4): 57, 3 reserved, Send_Timeout (10 ms units),
    features, profile features, profile ident, S_Type S_Len D_Type D_Len
    (type 0: API and SCL only), S_Addr, D_Addr."""
    return (bytes([FN_INITIATE, 0, 0, 0]) + be16(send_timeout)
            + bytes([features1, features2]) + be16(profile_features)
            + be16(profile_ident)
            + bytes([0 if len(s_addr) == 2 else 1, len(s_addr),
                     0 if len(d_addr) == 2 else 1, len(d_addr)])
            + bytes(s_addr) + bytes(d_addr))


def _addresses(b, off):
    """S_Type, S_Len, D_Type, D_Len at `off` and the two addresses after
    them; checks each Type/Len pair (type 0: length 2; type 1: API, SCL,
    network address 6 and a MAC address, so at least 8)."""
    if len(b) < off + 4:
        raise PduError("%d bytes, the address parameters need %d"
                       % (len(b), off + 4))
    s_type, s_len, d_type, d_len = b[off:off + 4]
    for name, t, n in (("S", s_type, s_len), ("D", d_type, d_len)):
        if t == 0 and n != 2:
            raise PduError("%s_Type 0 with %s_Len %d (must be 2)"
                           % (name, name, n))
        if t == 1 and n < 8:
            raise PduError("%s_Type 1 with %s_Len %d (at least 8)"
                           % (name, name, n))
        if t not in (0, 1):
            raise PduError("%s_Type %d (0 or 1)" % (name, t))
    if len(b) != off + 4 + s_len + d_len:
        raise PduError("%d bytes, the address lengths give %d"
                       % (len(b), off + 4 + s_len + d_len))
    s = b[off + 4:off + 4 + s_len]
    d = b[off + 4 + s_len:]
    return {"s_type": s_type, "s_addr": hexs(s), "d_type": d_type,
            "d_addr": hexs(d)}


def parse_initiate_req(b):
    if len(b) < 20:
        raise PduError("Initiate.req of %d bytes, at least 20" % len(b))
    if b[0] != FN_INITIATE:
        raise PduError("function %02X, not Initiate (57)" % b[0])
    out = {"send_timeout": u16(b, 4), "features_supported": hexs(b[6:8]),
           "profile_features": hexs(b[8:10]),
           "profile_ident": u16(b, 10)}
    out.update(_addresses(b, 12))
    return out


def initiate_res(max_len=240, features1=0x01, features2=0x00,
                 profile_features=0, profile_ident=0,
                 s_addr=b"\x00\x00", d_addr=b"\x00\x00"):
    return (bytes([FN_INITIATE, max_len, features1, features2])
            + be16(profile_features) + be16(profile_ident)
            + bytes([0, len(s_addr), 0, len(d_addr)])
            + bytes(s_addr) + bytes(d_addr))


def parse_initiate_res(b):
    if len(b) < 16:
        raise PduError("Initiate.res of %d bytes, at least 16" % len(b))
    if b[0] != FN_INITIATE:
        raise PduError("function %02X, not Initiate (57)" % b[0])
    out = {"max_len_data_unit": b[1], "features_supported": hexs(b[2:4]),
           "profile_features": hexs(b[4:6]), "profile_ident": u16(b, 6)}
    out.update(_addresses(b, 8))
    return out


# ---- RM, Idle, Abort -----------------------------------------------------

def rm_reply(sap, poll_timeout):
    """The resource manager's reply (4.4, single source [VPC3]; Felser's
    manual calls the u16 Min Send Timeout): 56 SAP u16."""
    return bytes([FN_RM, sap]) + be16(poll_timeout)


def parse_rm(b):
    if len(b) != 4 or b[0] != FN_RM:
        raise PduError("not an RM reply (56 SAP u16): %s" % hexs(b))
    if b[1] not in CONNECTION_SAPS:
        raise PduError("RM assigned SAP %d, outside 0..48" % b[1])
    return {"sap": b[1], "poll_timeout": u16(b, 2)}


def idle():
    return bytes([FN_IDLE, 0])


def abort(instance, reason, subnet=0, detail=0):
    return bytes([FN_ABORT, subnet, (instance & 0x30) | (reason & 0x0F),
                  detail])


def parse_abort(b):
    if len(b) != 4 or b[0] != FN_ABORT:
        raise PduError("not an Abort (58 subnet instance|reason detail): %s"
                       % hexs(b))
    inst = b[2] & 0x30
    code = b[2] & 0x0F
    out = {"subnet": b[1], "instance": INSTANCES[inst], "reason_code": code,
           "detail": b[3]}
    if inst == INSTANCE_MSAC_C2 and code in REASONS:
        out["reason"], out["words"] = REASONS[code]
    return out


def describe_abort(b):
    a = parse_abort(b)
    if "reason" in a:
        return "Abort by %s: %s (%s)" % (a["instance"], a["reason"],
                                         a["words"])
    return "Abort by %s, reason %d" % (a["instance"], a["reason_code"])


# ---- Read / Write / Data_Transport ---------------------------------------

def read_req(slot, index, length):
    return bytes([FN_READ, slot, index, length])


def write_req(slot, index, data):
    return bytes([FN_WRITE, slot, index, len(data)]) + bytes(data)


def transport_req(slot, index, data):
    return bytes([FN_TRANSPORT, slot, index, len(data)]) + bytes(data)


def negative(fn, code1, decode=0x80, code2=0):
    return bytes([fn | NEGATIVE, decode, code1, code2])


def describe_negative(b):
    """Words for a 4-byte negative response `Fn|80 decode code1 code2`."""
    if len(b) != 4:
        return "negative response of %d bytes (4 expected): %s" % (len(b),
                                                                   hexs(b))
    fn = FN_NAMES.get(b[0] & 0x7F, "%02X" % (b[0] & 0x7F))
    decode, c1, c2 = b[1], b[2], b[3]
    cls, code = c1 >> 4, c1 & 0x0F
    if decode == 0x80 and cls in ERROR_CLASSES:
        cname, codes = ERROR_CLASSES[cls]
        words = "%s: %s" % (cname, codes.get(code, "code %d" % code))
    else:
        words = "Error_Decode %02X Error_Code_1 %02X" % (decode, c1)
    return "negative %s response (%s, Error_Code_2 %02X)" % (fn, words, c2)


# ---- I&M -----------------------------------------------------------------

def call_header(fi_index):
    """The Call header (4.6): 08 00 FI_Index (u16)."""
    return bytes([CALL, 0]) + be16(fi_index)


def _text(b):
    return bytes(b).decode("latin-1").rstrip(" \x00")


def parse_im0(b):
    """I&M0, 64 bytes after the call header (4.6)."""
    if len(b) != IM_RECORD_LEN:
        raise PduError("I&M0 of %d bytes, 64 expected" % len(b))
    sw = b[50:54]
    return {
        "header": hexs(b[0:10]),
        "manufacturer_id": u16(b, 10),
        "order_id": _text(b[12:32]),
        "serial_number": _text(b[32:48]),
        "hardware_revision": u16(b, 48),
        "software_revision": "%s%d.%d.%d" % (chr(sw[0]), sw[1], sw[2], sw[3]),
        "revision_counter": u16(b, 54),
        "profile_id": u16(b, 56),
        "profile_specific_type": u16(b, 58),
        "im_version": "%d.%d" % (b[60], b[61]),
        "im_supported": u16(b, 62),
    }


def im0(manufacturer_id, order_id, serial, hw_rev, sw_rev, rev_counter=0,
        profile_id=0xF600, profile_type=0x0003, im_version=(1, 1),
        im_supported=0x001E):
    """I&M0 bytes; `sw_rev` as (char, x, y, z)."""
    def text(s, n):
        e = s.encode("latin-1")[:n]
        return e + b" " * (n - len(e))
    return (b" " * 10 + be16(manufacturer_id) + text(order_id, 20)
            + text(serial, 16) + be16(hw_rev)
            + bytes([ord(sw_rev[0]), sw_rev[1], sw_rev[2], sw_rev[3]])
            + be16(rev_counter) + be16(profile_id) + be16(profile_type)
            + bytes(im_version) + be16(im_supported))
