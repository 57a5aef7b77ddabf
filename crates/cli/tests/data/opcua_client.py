"""An independent OPC UA client (python asyncua) for crates/cli/tests/opcua.rs.

Usage: opcua_client.py URL SCENARIO [ARGS...]; prints one JSON object
with what it saw on stdout and exits non-zero (with the reason on
stderr) when something is not as expected.

Scenarios:
  check            browse, read, subscribe, write, methods, refusals
  hold             subscribe and print "subscribed", then wait to be killed
  many N           N clients at once, each reading and subscribing
  secure USER PW CERT KEY   Basic256Sha256 SignAndEncrypt with a user;
                   then the same endpoint anonymously (must be refused)
  events ADDR      wait for slave ADDR's SerialNumber (I&M0), subscribe
                   to its events, print "subscribed", then print the
                   first DpAlarmEventType event's fields
  access ADDR CH.. the AccessLevel and UserAccessLevel of output
                   channels CH of slave ADDR, and a write of each
  cert CERT KEY    Basic256Sha256 SignAndEncrypt anonymously with the
                   client certificate CERT: "accepted" or why not
"""

import asyncio
import json
import sys
import time

from asyncua import Client, ua
from asyncua.common.events import get_filter_from_event_type

NS_URI = "urn:profibus:dpctl"
T = 20.0


def fail(msg):
    print(msg, file=sys.stderr)
    sys.exit(1)


async def slave(client, ns, bus, address):
    """The slave object named `<address> <name>` under PROFIBUS/<bus>."""
    b = await client.nodes.objects.get_child([f"{ns}:PROFIBUS", f"{ns}:{bus}"])
    for child in await b.get_children():
        name = (await child.read_browse_name()).Name
        if name.split(" ")[0] == str(address):
            return child, name
    fail(f"no slave {address} under PROFIBUS/{bus}")


async def wait_value(node, pred, what, timeout=T):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        dv = await node.read_data_value(raise_on_bad_status=False)
        if dv.StatusCode.is_good() and pred(dv.Value.Value):
            return dv
        await asyncio.sleep(0.05)
    fail(f"timed out waiting for {what}; last {dv}")


async def write_typed(node, value):
    vt = await node.read_data_type_as_variant_type()
    await node.write_value(ua.DataValue(ua.Variant(value, vt)))


class Collect:
    def __init__(self):
        self.values = []

    def datachange_notification(self, node, val, data):
        self.values.append(val)


async def check(url):
    out = {}
    async with Client(url, timeout=T) as client:
        ns = await client.get_namespace_index(NS_URI)
        out["ns"] = ns
        bus = await client.nodes.objects.get_child([f"{ns}:PROFIBUS", f"{ns}:line"])
        out["master"] = await (await bus.get_child(f"{ns}:MasterState")).read_value()
        out["slaves"] = sorted(
            [(await c.read_browse_name()).Name for c in await bus.get_children()
             if (await c.read_node_class()) == ua.NodeClass.Object])

        # BK3000 (15): a scaled analog input with units, and a digital input.
        coupler, _ = await slave(client, ns, "line", 15)
        inputs = await coupler.get_child(f"{ns}:Inputs")
        names = [(await c.read_browse_name()).Name for c in await inputs.get_children()]
        out["bk3000_inputs"] = names
        analog = next(n for n in names if "KL3102" in n)
        a = await inputs.get_child([ua.QualifiedName(analog, ns)])
        await wait_value(a, lambda v: True, "the BK3000 analog input")
        dv = await a.read_data_value()
        out["bk3000_analog"] = {"name": analog, "value": dv.Value.Value,
                                "type": dv.Value.VariantType.name,
                                "source_ts": dv.SourceTimestamp is not None}
        eu = await (await a.get_child(f"{ns}:EngineeringUnits")).read_value()
        out["bk3000_unit"] = {"display": eu.DisplayName.Text, "unit_id": eu.UnitId}
        out["bk3000_state"] = await (await coupler.get_child(f"{ns}:State")).read_value()

        # Omega (25): subscribe its actual value, write its setpoint.
        drive, _ = await slave(client, ns, "line", 25)
        actual = await drive.get_child([f"{ns}:Inputs", f"{ns}:actual1"])
        setpoint = await drive.get_child([f"{ns}:Outputs", f"{ns}:setpoint1"])
        await wait_value(actual, lambda v: True, "the drive's first value")
        plain, banded = Collect(), Collect()
        sub = await client.create_subscription(20, plain)
        await sub.subscribe_data_change(actual)
        sub2 = await client.create_subscription(20, banded)
        await sub2.deadband_monitor(actual, 1000)
        await write_typed(setpoint, 1500)
        await wait_value(actual, lambda v: v == 1500, "actual1 = 1500")
        # The subscription reports 1500 before the next write (on a busy
        # host its sampling can lag the read above).
        end = time.monotonic() + T
        while time.monotonic() < end and 1500 not in plain.values:
            await asyncio.sleep(0.05)
        await write_typed(setpoint, 1600)
        await wait_value(actual, lambda v: v == 1600, "actual1 = 1600")
        end = time.monotonic() + T
        while time.monotonic() < end and (not plain.values or plain.values[-1] != 1600):
            await asyncio.sleep(0.05)
        await asyncio.sleep(0.5)
        out["subscribed"] = plain.values
        out["deadband"] = banded.values
        await sub.delete()
        await sub2.delete()

        # Refusals: a slave not in `writable`, a channel not allowed.
        locked, _ = await slave(client, ns, "line", 4)
        louts = await locked.get_child(f"{ns}:Outputs")
        lnode = (await louts.get_children())[0]
        out["locked_access"] = (await lnode.read_attribute(ua.AttributeIds.UserAccessLevel)).Value.Value
        for key, node in [("refused_locked", lnode),
                          ("refused_control", await drive.get_child([f"{ns}:Outputs", f"{ns}:control1"]))]:
            try:
                await write_typed(node, 1)
                out[key] = "Good"
            except ua.UaStatusCodeError as e:
                out[key] = ua.StatusCode(e.code).name

        # DP-V1 (3): WriteRecord then ReadRecord.
        echo, _ = await slave(client, ns, "line", 3)
        await echo.call_method(f"{ns}:WriteRecord", ua.Variant(1, ua.VariantType.Byte),
                               ua.Variant(7, ua.VariantType.Byte),
                               ua.Variant(b"\xca\xfe", ua.VariantType.ByteString))
        data = await echo.call_method(f"{ns}:ReadRecord", ua.Variant(1, ua.VariantType.Byte),
                                      ua.Variant(7, ua.VariantType.Byte),
                                      ua.Variant(240, ua.VariantType.Byte))
        out["read_record"] = data.hex()
        out["manufacturer"] = await (await echo.get_child(f"{ns}:Manufacturer")).read_value()
        out["ident_number"] = await (await echo.get_child(f"{ns}:IdentNumber")).read_value()
        out["echo_modules"] = [(await c.read_browse_name()).Name
                               for c in await (await echo.get_child(f"{ns}:Modules")).get_children()]
        out["echo_stats"] = await (await echo.get_child([f"{ns}:Statistics", f"{ns}:DataExchanges"])).read_value()
        out["echo_diag"] = await (await echo.get_child([f"{ns}:Diagnosis", f"{ns}:Text"])).read_value()
    print(json.dumps(out))


async def hold(url):
    client = Client(url, timeout=T)
    await client.connect()
    ns = await client.get_namespace_index(NS_URI)
    drive, _ = await slave(client, ns, "line", 25)
    actual = await drive.get_child([f"{ns}:Inputs", f"{ns}:actual1"])
    c = Collect()
    sub = await client.create_subscription(10, c)
    await sub.subscribe_data_change(actual)
    while not c.values:
        await asyncio.sleep(0.02)
    print("subscribed", flush=True)
    await asyncio.sleep(3600)


async def one(url, i, got):
    async with Client(url, timeout=60) as client:
        ns = await client.get_namespace_index(NS_URI)
        drive, _ = await slave(client, ns, "line", 25)
        actual = await drive.get_child([f"{ns}:Inputs", f"{ns}:actual1"])
        c = Collect()
        sub = await client.create_subscription(50, c)
        await sub.subscribe_data_change(actual)
        end = time.monotonic() + 60
        while not c.values and time.monotonic() < end:
            await asyncio.sleep(0.05)
        got[i] = bool(c.values)
        await asyncio.sleep(1.0)


async def many(url, n):
    got = [False] * n
    t0 = time.monotonic()
    await asyncio.gather(*(one(url, i, got) for i in range(n)))
    print(json.dumps({"clients": n, "ok": sum(got), "seconds": round(time.monotonic() - t0, 2)}))


async def secure(url, user, pw, cert, key):
    out = {}
    client = Client(url, timeout=T)
    client.application_uri = "urn:profibus:dpctl:test-client"
    await client.set_security_string(f"Basic256Sha256,SignAndEncrypt,{cert},{key}")
    client.set_user(user)
    client.set_password(pw)
    async with client:
        ns = await client.get_namespace_index(NS_URI)
        bus = await client.nodes.objects.get_child([f"{ns}:PROFIBUS", f"{ns}:line"])
        out["master"] = await (await bus.get_child(f"{ns}:MasterState")).read_value()
    anon = Client(url, timeout=T)
    anon.application_uri = "urn:profibus:dpctl:test-client"
    await anon.set_security_string(f"Basic256Sha256,SignAndEncrypt,{cert},{key}")
    try:
        async with anon:
            out["anonymous"] = "accepted"
    except Exception as e:  # the server refuses the session
        out["anonymous"] = type(e).__name__ + ": " + str(e)[:80]
    nosec = Client(url, timeout=T)
    try:
        async with nosec:
            out["no_security"] = "accepted"
    except Exception as e:
        out["no_security"] = type(e).__name__
    print(json.dumps(out))


class Events:
    def __init__(self):
        self.events = []

    def event_notification(self, event):
        self.events.append(event)


async def events(url, address):
    out = {}
    async with Client(url, timeout=T) as client:
        ns = await client.get_namespace_index(NS_URI)
        node, name = await slave(client, ns, "line", int(address))
        serial = await node.get_child(f"{ns}:SerialNumber")
        # The slave reaches Data_Exchange, then the master reads I&M0.
        dv = await wait_value(serial, lambda v: v != "", "the SerialNumber from I&M0", 90)
        out["serial_number"] = dv.Value.Value
        for p in ["RevisionCounter", "ProductCode", "HardwareRevision", "SoftwareRevision",
                  "Manufacturer", "ManufacturerId"]:
            out[p] = await (await node.get_child(f"{ns}:{p}")).read_value()
        notifier = (await node.read_attribute(ua.AttributeIds.EventNotifier)).Value.Value
        out["event_notifier"] = int(notifier)
        evtype = client.get_node(ua.NodeId("DpAlarmEventType", ns))
        # The type's fields, filtered with OfType (asyncua's default
        # where clause, EventType InList [...], compares NodeIds, which
        # async-opcua 0.19 does not evaluate: see docs/opcua.md).
        evfilter = await get_filter_from_event_type([evtype])
        evfilter.WhereClause = ua.ContentFilter(Elements=[ua.ContentFilterElement(
            FilterOperator_=ua.FilterOperator.OfType,
            FilterOperands=[ua.LiteralOperand(Value=ua.Variant(evtype.nodeid))])])
        h = Events()
        sub = await client.create_subscription(20, h)
        await sub.subscribe_events(node, evtype, evfilter=evfilter)
        # The Server object stands for the bus (one server per bus).
        bus_h = Events()
        sub2 = await client.create_subscription(20, bus_h)
        await sub2.subscribe_events(client.nodes.server, evtype, evfilter=evfilter)
        print("subscribed", flush=True)
        end = time.monotonic() + T
        while time.monotonic() < end and not (h.events and bus_h.events):
            await asyncio.sleep(0.05)
        if not h.events:
            fail("no event from the slave")
        e = h.events[0]
        out["event"] = {
            "source_node": e.SourceNode.to_string(),
            "source_name": e.SourceName,
            "severity": e.Severity,
            "message": e.Message.Text,
            "slot": e.Slot,
            "alarm_type": e.AlarmType,
            "sequence_number": e.SequenceNumber,
            "specifier": e.Specifier,
            "data": e.Data.hex() if e.Data is not None else None,
            "acknowledged": e.Acknowledged,
            "event_type": e.EventType.to_string(),
        }
        out["slave_node"] = node.nodeid.to_string()
        out["slave_name"] = name
        out["server_events"] = len(bus_h.events)
    print(json.dumps(out))


async def access(url, address, *channels):
    out = {}
    async with Client(url, timeout=T) as client:
        ns = await client.get_namespace_index(NS_URI)
        node, _ = await slave(client, ns, "line", int(address))
        for ch in channels:
            n = await node.get_child([f"{ns}:Outputs", f"{ns}:{ch}"])
            level = (await n.read_attribute(ua.AttributeIds.AccessLevel)).Value.Value
            user = (await n.read_attribute(ua.AttributeIds.UserAccessLevel)).Value.Value
            try:
                await write_typed(n, 7)
                written = "Good"
            except ua.UaStatusCodeError as e:
                written = ua.StatusCode(e.code).name
            out[ch] = {"access_level": int(level), "user_access_level": int(user),
                       "write": written}
    print(json.dumps(out))


async def cert(url, cert, key):
    client = Client(url, timeout=T)
    client.application_uri = "urn:profibus:dpctl:test-client"
    await client.set_security_string(f"Basic256Sha256,SignAndEncrypt,{cert},{key}")
    try:
        async with client:
            ns = await client.get_namespace_index(NS_URI)
            bus = await client.nodes.objects.get_child([f"{ns}:PROFIBUS", f"{ns}:line"])
            await (await bus.get_child(f"{ns}:MasterState")).read_value()
            result = "accepted"
    except Exception as e:  # the server refuses the channel or session
        result = type(e).__name__ + ": " + str(e)[:120]
    print(json.dumps({"result": result}))


def main():
    url, what, *rest = sys.argv[1:]
    if what == "check":
        asyncio.run(check(url))
    elif what == "hold":
        asyncio.run(hold(url))
    elif what == "many":
        asyncio.run(many(url, int(rest[0])))
    elif what == "secure":
        asyncio.run(secure(url, *rest))
    elif what == "events":
        asyncio.run(events(url, *rest))
    elif what == "access":
        asyncio.run(access(url, *rest))
    elif what == "cert":
        asyncio.run(cert(url, *rest))
    else:
        fail(f"unknown scenario {what}")


if __name__ == "__main__":
    main()
