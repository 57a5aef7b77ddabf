-- PROFIBUS DL / DP dissector for Wireshark (Lua).
--
-- Decodes captures with link type 257 (LINKTYPE_PROFIBUS_DL), one FDL
-- telegram per packet, as `dpctl sniff --pcap`, `dpctl bus --pcap` and
-- `dpctl demo --pcap` write them (pcapng). Wireshark has no encapsulation
-- of its own for link type 257, so such packets arrive with encapsulation
-- "Unknown" (0); this script claims that encapsulation.
--
-- Layer 2 (protocol "pbdl"): telegram type (SD1, SD2, SD3, SD4 token, SC
-- short acknowledge), LE/LEr, destination and source address with their
-- extension bits, FC (request: FCB/FCV and function; response: station
-- type and answer), DSAP/SSAP with the DP service names, FCS (checked)
-- and ED. `pbdl.fcs.good` is false (the filter `pbdl.fcs.good == 0`) for
-- every corrupted packet: a wrong FCS, a telegram cut off or malformed,
-- or bytes the recorder flagged as no valid telegram (pcapng epb_flags
-- CRC error, `frame.packet_flags_crc_error`: `dpctl bus --pcap` and
-- `dpctl sniff --pcap` keep corrupted telegrams that way).
-- DP (protocol "pbdp"): Set_Prm, Chk_Cfg / Get_Cfg identifiers,
-- Slave_Diag station status bits, Global_Control, Set_Slave_Add,
-- DP-V1 MSAC_C1 read / write / errors, Data_Exchange outputs and inputs.
-- FMS (protocol "pbfms"): the LLI PDU and the FMS PDU in it on a
-- connection SAP (0..48), in the (unverified) encoding of docs/fms.md.
--
-- Every packet also shows (generated fields): `pbdl.src` / `pbdl.dst`,
-- the station addresses, which also fill the Source and Destination
-- columns (`pbdl.addr` matches either); `pbdl.delta_us`, the time since
-- the previous record's first byte; and `pbdl.idle_us`, the line's idle
-- time before this telegram: the delta minus the previous record's
-- transmission time (11 bits per character at the baud rate of the
-- preference "Baud rate", Edit > Preferences > Protocols > PBDL; 0
-- leaves it out). Time stamps are those of each record's first byte.
-- Records flagged corrupt carry the expert info `pbdl.corrupt`.
--
-- The meanings are those of IEC 61158-4-3 / -6-3 (EN 50170 volume 2) as
-- the crates profibus-fdl and profibus-dp implement them.
--
-- Install: copy this file into Wireshark's personal Lua plugins folder
-- (Help > About Wireshark > Folders, "Personal Lua Plugins", usually
-- ~/.local/lib/wireshark/plugins/), or run
--   wireshark -X lua_script:tools/wireshark/profibus_dl.lua capture.pcapng
--   tshark    -X lua_script:tools/wireshark/profibus_dl.lua -r capture.pcapng

local pbdl = Proto("pbdl", "PROFIBUS DL (FDL)")
local pbdp = Proto("pbdp", "PROFIBUS DP")

---------------------------------------------------------------------------
-- Layer 2 fields

local SD_NAMES = {
  [0x10] = "SD1", [0x68] = "SD2", [0xA2] = "SD3", [0xDC] = "SD4", [0xE5] = "SC",
}
local SD_DESCR = {
  [0x10] = "SD1 (no data)", [0x68] = "SD2 (variable data)", [0xA2] = "SD3 (8 data bytes)",
  [0xDC] = "SD4 (token)", [0xE5] = "SC (short acknowledge)",
}

local REQ_FUNCTIONS = {
  [0x0] = "TE (time event)", [0x3] = "SDA_low", [0x4] = "SDN_low", [0x5] = "SDA_high",
  [0x6] = "SDN_high", [0x7] = "MSRD", [0x9] = "FDL_Status", [0xC] = "SRD_low",
  [0xD] = "SRD_high", [0xE] = "Ident", [0xF] = "LSAP_Status",
}
local RESP_FUNCTIONS = {
  [0x0] = "OK", [0x1] = "UE (user error)", [0x2] = "RR (no resources)",
  [0x3] = "RS (SAP not activated)", [0x8] = "DL (data low)", [0x9] = "NR (no response data)",
  [0xA] = "DH (data high)", [0xC] = "RDL (data low, no resources)",
  [0xD] = "RDH (data high, no resources)",
}
local STATION_TYPES = {
  [0] = "slave", [1] = "master not ready", [2] = "master ready for the ring",
  [3] = "master in the ring",
}
local SAP_NAMES = {
  [0] = "default SAP (Data_Exchange)", [49] = "MSAC_C2 Initiate", [50] = "Alarm_Ack",
  [51] = "MSAC_C1 (DP-V1 read/write)", [54] = "master-master", [55] = "Set_Slave_Add",
  [56] = "Rd_Inp", [57] = "Rd_Outp", [58] = "Global_Control", [59] = "Get_Cfg",
  [60] = "Slave_Diag", [61] = "Set_Prm", [62] = "Chk_Cfg / DP master",
}

local f = pbdl.fields
f.sd = ProtoField.uint8("pbdl.sd", "Start delimiter", base.HEX, SD_DESCR)
f.type = ProtoField.string("pbdl.type", "Telegram type")
f.le = ProtoField.uint8("pbdl.le", "LE", base.DEC)
f.ler = ProtoField.uint8("pbdl.ler", "LEr", base.DEC)
f.da = ProtoField.uint8("pbdl.da", "Destination (DA)", base.HEX)
f.da_ext = ProtoField.bool("pbdl.da.ext", "Address extension (DSAP follows)", 8, nil, 0x80)
f.da_addr = ProtoField.uint8("pbdl.da.addr", "Destination address", base.DEC, nil, 0x7F)
f.sa = ProtoField.uint8("pbdl.sa", "Source (SA)", base.HEX)
f.sa_ext = ProtoField.bool("pbdl.sa.ext", "Address extension (SSAP follows)", 8, nil, 0x80)
f.sa_addr = ProtoField.uint8("pbdl.sa.addr", "Source address", base.DEC, nil, 0x7F)
f.fc = ProtoField.uint8("pbdl.fc", "Function code (FC)", base.HEX)
f.fc_req = ProtoField.bool("pbdl.fc.request", "Request", 8, {"request", "response / acknowledge"}, 0x40)
f.fc_fcb = ProtoField.bool("pbdl.fc.fcb", "FCB (frame count bit)", 8, nil, 0x20)
f.fc_fcv = ProtoField.bool("pbdl.fc.fcv", "FCV (frame count bit valid)", 8, nil, 0x10)
f.fc_stype = ProtoField.uint8("pbdl.fc.station_type", "Station type", base.DEC, STATION_TYPES, 0x30)
f.fc_function = ProtoField.string("pbdl.fc.function", "Function")
f.dsap = ProtoField.uint8("pbdl.dsap", "DSAP", base.DEC, SAP_NAMES, 0x3F)
f.ssap = ProtoField.uint8("pbdl.ssap", "SSAP", base.DEC, SAP_NAMES, 0x3F)
f.data = ProtoField.bytes("pbdl.data", "Data unit")
f.fcs = ProtoField.uint8("pbdl.fcs", "FCS", base.HEX)
f.fcs_status = ProtoField.string("pbdl.fcs.status", "FCS status")
f.fcs_good = ProtoField.bool("pbdl.fcs.good", "FCS good (false: corrupted telegram)")
f.ed = ProtoField.uint8("pbdl.ed", "End delimiter", base.HEX)
f.token = ProtoField.bool("pbdl.token", "Token")
f.src = ProtoField.uint8("pbdl.src", "Source station", base.DEC)
f.dst = ProtoField.uint8("pbdl.dst", "Destination station", base.DEC)
f.addr = ProtoField.uint8("pbdl.addr", "Station (source or destination)", base.DEC)
f.delta = ProtoField.double("pbdl.delta_us", "Delta since the previous record (µs)")
f.idle = ProtoField.double("pbdl.idle_us", "Line idle before this telegram (µs)")

pbdl.prefs.baud = Pref.uint("Baud rate", 1500000,
  "Baud rate of the recorded line, for the idle time before each telegram (0: unknown)")

local e_fcs = ProtoExpert.new("pbdl.fcs.bad", "FCS wrong", expert.group.CHECKSUM, expert.severity.ERROR)
local e_len = ProtoExpert.new("pbdl.malformed", "Malformed telegram", expert.group.MALFORMED, expert.severity.ERROR)
local e_flag = ProtoExpert.new("pbdl.corrupt", "Recorded as corrupt", expert.group.CHECKSUM, expert.severity.ERROR)
pbdl.experts = { e_fcs, e_len, e_flag }

-- The recorder's CRC-error flag (Wireshark 1.12 and later know the field).
local ok_flag, crc_flag = pcall(Field.new, "frame.packet_flags_crc_error")
if not ok_flag then crc_flag = nil end

-- Whether the packet being dissected was already marked corrupt, and
-- whether the recorder flagged it.
local marked_bad = false
local flagged = false

-- Per frame number: delta and idle time, computed on the first pass (in
-- file order) from the previous record's start and length.
local timing = {}
local prev_ts, prev_len = nil, nil
-- The last request's {sa, da} on the first pass: a short acknowledge
-- carries no addresses; it comes from the station that request asked.
local last_request = nil

function pbdl.init()
  timing = {}
  prev_ts, prev_len = nil, nil
  last_request = nil
end

-- Adds the delta and idle times of this record.
local function add_timing(tvb, pinfo, tree)
  local t = timing[pinfo.number]
  if t == nil and not pinfo.visited then
    t = {}
    local ts = pinfo.rel_ts
    if prev_ts ~= nil then
      t.delta = (ts - prev_ts) * 1e6
      local baud = pbdl.prefs.baud
      if baud and baud > 0 then
        t.idle = t.delta - prev_len * 11 * 1e6 / baud
      end
    end
    prev_ts, prev_len = ts, tvb:len()
    timing[pinfo.number] = t
  end
  if t and t.delta then
    tree:add(f.delta, t.delta):set_generated()
    if t.idle then tree:add(f.idle, t.idle):set_generated() end
  end
end

-- Shows the station addresses (fields and the Source / Destination
-- columns).
local function add_stations(tree, pinfo, sa, da)
  sa, da = bit.band(sa, 0x7F), bit.band(da, 0x7F)
  tree:add(f.src, sa):set_generated()
  tree:add(f.dst, da):set_generated()
  tree:add(f.addr, sa):set_generated()
  tree:add(f.addr, da):set_generated()
  pinfo.cols.src = tostring(sa)
  pinfo.cols.dst = tostring(da)
end

-- Marks the packet corrupt: FCS status Bad, `pbdl.fcs.good` false, and an
-- expert info saying why.
local function mark_bad(tree, e, why)
  if not marked_bad then
    tree:add(f.fcs_status, "Bad"):set_generated()
    tree:add(f.fcs_good, false):set_generated()
    marked_bad = true
  end
  tree:add_proto_expert_info(e, why)
end

---------------------------------------------------------------------------
-- DP fields

local d = pbdp.fields
d.service = ProtoField.string("pbdp.service", "DP service")
-- Set_Prm
d.prm_status = ProtoField.uint8("pbdp.prm.status", "Station status", base.HEX)
d.prm_lock = ProtoField.bool("pbdp.prm.lock_req", "Lock_Req", 8, nil, 0x80)
d.prm_unlock = ProtoField.bool("pbdp.prm.unlock_req", "Unlock_Req", 8, nil, 0x40)
d.prm_sync = ProtoField.bool("pbdp.prm.sync_req", "Sync_Req", 8, nil, 0x20)
d.prm_freeze = ProtoField.bool("pbdp.prm.freeze_req", "Freeze_Req", 8, nil, 0x10)
d.prm_wd_on = ProtoField.bool("pbdp.prm.wd_on", "WD_On", 8, nil, 0x08)
d.prm_wd1 = ProtoField.uint8("pbdp.prm.wd_fact_1", "WD_Fact_1", base.DEC)
d.prm_wd2 = ProtoField.uint8("pbdp.prm.wd_fact_2", "WD_Fact_2", base.DEC)
d.prm_tsdr = ProtoField.uint8("pbdp.prm.min_tsdr", "min TSDR (bit times, 0 = unchanged)", base.DEC)
d.prm_ident = ProtoField.uint16("pbdp.prm.ident", "Ident_Number", base.HEX)
d.prm_group = ProtoField.uint8("pbdp.prm.group", "Group_Ident", base.HEX)
d.prm_user = ProtoField.bytes("pbdp.prm.user_data", "User_Prm_Data")
-- Chk_Cfg / Get_Cfg
d.cfg_id = ProtoField.uint8("pbdp.cfg.id", "Identifier", base.HEX)
d.cfg_text = ProtoField.string("pbdp.cfg.text", "Module")
d.cfg_in = ProtoField.uint16("pbdp.cfg.inputs", "Input bytes (total)", base.DEC)
d.cfg_out = ProtoField.uint16("pbdp.cfg.outputs", "Output bytes (total)", base.DEC)
-- Slave_Diag
d.diag_s1 = ProtoField.uint8("pbdp.diag.status1", "Station_Status_1", base.HEX)
d.diag_nonexist = ProtoField.bool("pbdp.diag.station_non_existent", "Station_Non_Existent", 8, nil, 0x01)
d.diag_notready = ProtoField.bool("pbdp.diag.station_not_ready", "Station_Not_Ready", 8, nil, 0x02)
d.diag_cfgfault = ProtoField.bool("pbdp.diag.cfg_fault", "Cfg_Fault", 8, nil, 0x04)
d.diag_extdiag = ProtoField.bool("pbdp.diag.ext_diag", "Ext_Diag", 8, nil, 0x08)
d.diag_notsupp = ProtoField.bool("pbdp.diag.not_supported", "Not_Supported", 8, nil, 0x10)
d.diag_invalid = ProtoField.bool("pbdp.diag.invalid_slave_response", "Invalid_Slave_Response", 8, nil, 0x20)
d.diag_prmfault = ProtoField.bool("pbdp.diag.prm_fault", "Prm_Fault", 8, nil, 0x40)
d.diag_mlock = ProtoField.bool("pbdp.diag.master_lock", "Master_Lock", 8, nil, 0x80)
d.diag_s2 = ProtoField.uint8("pbdp.diag.status2", "Station_Status_2", base.HEX)
d.diag_prmreq = ProtoField.bool("pbdp.diag.prm_req", "Prm_Req", 8, nil, 0x01)
d.diag_statdiag = ProtoField.bool("pbdp.diag.stat_diag", "Stat_Diag", 8, nil, 0x02)
d.diag_one = ProtoField.bool("pbdp.diag.always_one", "(always 1)", 8, nil, 0x04)
d.diag_wdon = ProtoField.bool("pbdp.diag.wd_on", "WD_On", 8, nil, 0x08)
d.diag_freeze = ProtoField.bool("pbdp.diag.freeze_mode", "Freeze_Mode", 8, nil, 0x10)
d.diag_sync = ProtoField.bool("pbdp.diag.sync_mode", "Sync_Mode", 8, nil, 0x20)
d.diag_deact = ProtoField.bool("pbdp.diag.deactivated", "Deactivated", 8, nil, 0x80)
d.diag_s3 = ProtoField.uint8("pbdp.diag.status3", "Station_Status_3", base.HEX)
d.diag_ovf = ProtoField.bool("pbdp.diag.ext_diag_overflow", "Ext_Diag_Overflow", 8, nil, 0x80)
d.diag_master = ProtoField.uint8("pbdp.diag.master_add", "Master_Add (255 = none)", base.DEC)
d.diag_ident = ProtoField.uint16("pbdp.diag.ident", "Ident_Number", base.HEX)
d.diag_ext = ProtoField.bytes("pbdp.diag.ext", "Extended diagnosis")
-- Global_Control
d.gc_cmd = ProtoField.uint8("pbdp.gc.command", "Control_Command", base.HEX)
d.gc_clear = ProtoField.bool("pbdp.gc.clear_data", "Clear_Data", 8, nil, 0x02)
d.gc_unfreeze = ProtoField.bool("pbdp.gc.unfreeze", "Unfreeze", 8, nil, 0x04)
d.gc_freeze = ProtoField.bool("pbdp.gc.freeze", "Freeze", 8, nil, 0x08)
d.gc_unsync = ProtoField.bool("pbdp.gc.unsync", "Unsync", 8, nil, 0x10)
d.gc_sync = ProtoField.bool("pbdp.gc.sync", "Sync", 8, nil, 0x20)
d.gc_group = ProtoField.uint8("pbdp.gc.group", "Group_Select", base.HEX)
-- Set_Slave_Add
d.ssa_new = ProtoField.uint8("pbdp.ssa.new_address", "New_Slave_Add", base.DEC)
d.ssa_ident = ProtoField.uint16("pbdp.ssa.ident", "Ident_Number", base.HEX)
d.ssa_nochg = ProtoField.uint8("pbdp.ssa.no_add_chg", "No_Add_Chg", base.DEC)
d.ssa_rem = ProtoField.bytes("pbdp.ssa.rem_slave_data", "Rem_Slave_Data")
-- DP-V1 MSAC_C1
local DPV1_FUNCTIONS = {
  [0x48] = "Idle", [0x57] = "Initiate", [0x58] = "Abort", [0x5C] = "Alarm_Ack",
  [0x5E] = "Read", [0x5F] = "Write", [0xD7] = "Initiate error", [0xDC] = "Alarm_Ack error",
  [0xDE] = "Read error", [0xDF] = "Write error",
}
d.v1_fn = ProtoField.uint8("pbdp.dpv1.function", "Function_Num", base.HEX, DPV1_FUNCTIONS)
d.v1_slot = ProtoField.uint8("pbdp.dpv1.slot", "Slot_Number", base.DEC)
d.v1_index = ProtoField.uint8("pbdp.dpv1.index", "Index", base.DEC)
d.v1_len = ProtoField.uint8("pbdp.dpv1.length", "Length", base.DEC)
d.v1_data = ProtoField.bytes("pbdp.dpv1.data", "Data")
d.v1_edec = ProtoField.uint8("pbdp.dpv1.error_decode", "Error_Decode", base.HEX,
  { [0x80] = "DP-V1", [0xFE] = "FMS", [0xFF] = "HART" })
d.v1_ec1 = ProtoField.uint8("pbdp.dpv1.error_code_1", "Error_Code_1", base.HEX)
d.v1_class = ProtoField.uint8("pbdp.dpv1.error_class", "Error class", base.HEX, {
  [0xA] = "application", [0xB] = "access", [0xC] = "resource" }, 0xF0)
d.v1_code = ProtoField.uint8("pbdp.dpv1.error_code", "Error code", base.HEX, nil, 0x0F)
d.v1_ec2 = ProtoField.uint8("pbdp.dpv1.error_code_2", "Error_Code_2", base.HEX)
d.v1_poll = ProtoField.bool("pbdp.dpv1.poll", "Poll (request without data)")
-- DP-V1 alarm and status blocks (in Slave_Diag) and Alarm_Ack
-- (dpv1-c2-im-alarms.md §4.4-4.5: type, slot, specifier = Seq_Nr b7-3,
-- Add_Ack b2, appears/disappears b1-0).
local ALARM_TYPES = {
  [1] = "diagnostic", [2] = "process", [3] = "pull", [4] = "plug", [5] = "status", [6] = "update",
}
local STATUS_TYPES = {
  [0x81] = "status message", [0x82] = "module status", [0x83] = "DXB link status",
  [0x9E] = "PrmCmdAck", [0x9F] = "Red_State",
}
local ALARM_CHANGES = {
  [0] = "none", [1] = "appears", [2] = "disappears", [3] = "disappears-still-faulty",
}
d.alarm = ProtoField.bytes("pbdp.alarm", "DP-V1 alarm block")
d.alarm_type = ProtoField.uint8("pbdp.alarm.type", "Alarm_Type", base.DEC, ALARM_TYPES)
d.alarm_slot = ProtoField.uint8("pbdp.alarm.slot", "Slot_Number", base.DEC)
d.alarm_spec = ProtoField.uint8("pbdp.alarm.specifier", "Alarm_Specifier", base.HEX)
d.alarm_seq = ProtoField.uint8("pbdp.alarm.seq", "Seq_Nr", base.DEC, nil, 0xF8)
d.alarm_addack = ProtoField.bool("pbdp.alarm.add_ack", "Add_Ack", 8, nil, 0x04)
d.alarm_change = ProtoField.uint8("pbdp.alarm.change", "Appears/disappears", base.DEC,
  ALARM_CHANGES, 0x03)
d.alarm_data = ProtoField.bytes("pbdp.alarm.data", "Diagnostic_User_Data")
d.status_type = ProtoField.uint8("pbdp.status.type", "Status_Type", base.HEX, STATUS_TYPES)
-- Data_Exchange
d.outputs = ProtoField.bytes("pbdp.outputs", "Outputs")
d.inputs = ProtoField.bytes("pbdp.inputs", "Inputs")

---------------------------------------------------------------------------
-- DP decoding

-- Length in bytes of a unit count with the word bit.
local function unit_bytes(count, words)
  if words then return count * 2 end
  return count
end

local function length_byte_text(b)
  local n = bit.band(b, 0x3F) + 1
  local words = bit.band(b, 0x40) ~= 0
  local s = n .. (words and " word" or " byte") .. (n > 1 and "s" or "")
  if bit.band(b, 0x80) ~= 0 then s = s .. " consistent" end
  return s, unit_bytes(n, words)
end

-- Decodes a configuration (Chk_Cfg / Get_Cfg data unit).
local function dissect_cfg(tvb, tree)
  local pos, len = 0, tvb:len()
  local total_in, total_out = 0, 0
  while pos < len do
    local id = tvb(pos, 1):uint()
    local dir = bit.band(bit.rshift(id, 4), 3)
    if dir ~= 0 then
      -- general format
      local n = bit.band(id, 0x0F) + 1
      local words = bit.band(id, 0x40) ~= 0
      local bytes = unit_bytes(n, words)
      local what = ({ "input", "output", "input/output" })[dir]
      local text = string.format("%d %s%s %s%s", n, words and "word" or "byte", n > 1 and "s" or "",
        what, bit.band(id, 0x80) ~= 0 and ", consistent" or "")
      if dir == 1 or dir == 3 then total_in = total_in + bytes end
      if dir == 2 or dir == 3 then total_out = total_out + bytes end
      local t = tree:add(d.cfg_id, tvb(pos, 1))
      t:add(d.cfg_text, tvb(pos, 1), text)
      t:append_text(" (" .. text .. ")")
      pos = pos + 1
    elseif id == 0 then
      local t = tree:add(d.cfg_id, tvb(pos, 1))
      t:add(d.cfg_text, tvb(pos, 1), "free place")
      t:append_text(" (free place)")
      pos = pos + 1
    else
      -- special format
      local kind = bit.rshift(id, 6)
      local vendor = bit.band(id, 0x0F)
      local nlen = (kind == 3) and 2 or ((kind == 0) and 0 or 1)
      local size = 1 + nlen + vendor
      if pos + size > len then
        tree:add_proto_expert_info(e_len, "identifier runs past the data unit")
        return
      end
      local parts = {}
      local k = pos + 1
      if kind == 2 or kind == 3 then
        local s, b = length_byte_text(tvb(k, 1):uint())
        parts[#parts + 1] = s .. " output"
        total_out = total_out + b
        k = k + 1
      end
      if kind == 1 or kind == 3 then
        local s, b = length_byte_text(tvb(k, 1):uint())
        parts[#parts + 1] = s .. " input"
        total_in = total_in + b
        k = k + 1
      end
      local text = table.concat(parts, ", ")
      if vendor > 0 then text = text .. string.format(", %d manufacturer byte%s", vendor, vendor > 1 and "s" or "") end
      local t = tree:add(d.cfg_id, tvb(pos, size), id)
      t:add(d.cfg_text, tvb(pos, size), text)
      t:append_text(" (special: " .. text .. ")")
      pos = pos + size
    end
  end
  tree:add(d.cfg_in, total_in):set_generated()
  tree:add(d.cfg_out, total_out):set_generated()
end

local function dissect_set_prm(tvb, tree)
  if tvb:len() < 7 then
    tree:add_proto_expert_info(e_len, "Set_Prm shorter than 7 bytes")
    return
  end
  local st = tree:add(d.prm_status, tvb(0, 1))
  st:add(d.prm_lock, tvb(0, 1)); st:add(d.prm_unlock, tvb(0, 1))
  st:add(d.prm_sync, tvb(0, 1)); st:add(d.prm_freeze, tvb(0, 1)); st:add(d.prm_wd_on, tvb(0, 1))
  local w1, w2 = tvb(1, 1):uint(), tvb(2, 1):uint()
  tree:add(d.prm_wd1, tvb(1, 1))
  tree:add(d.prm_wd2, tvb(2, 1)):append_text(string.format(" (watchdog %d ms at a 10 ms base)", 10 * w1 * w2))
  tree:add(d.prm_tsdr, tvb(3, 1))
  tree:add(d.prm_ident, tvb(4, 2))
  tree:add(d.prm_group, tvb(6, 1))
  if tvb:len() > 7 then tree:add(d.prm_user, tvb(7)) end
end

-- Defined with the alarm fields below.
local dissect_dpv1_blocks

local function dissect_diag(tvb, tree)
  if tvb:len() < 6 then
    tree:add_proto_expert_info(e_len, "Slave_Diag response shorter than 6 bytes")
    return
  end
  local s1 = tree:add(d.diag_s1, tvb(0, 1))
  for _, fl in ipairs({ d.diag_nonexist, d.diag_notready, d.diag_cfgfault, d.diag_extdiag,
    d.diag_notsupp, d.diag_invalid, d.diag_prmfault, d.diag_mlock }) do
    s1:add(fl, tvb(0, 1))
  end
  local s2 = tree:add(d.diag_s2, tvb(1, 1))
  for _, fl in ipairs({ d.diag_prmreq, d.diag_statdiag, d.diag_one, d.diag_wdon, d.diag_freeze,
    d.diag_sync, d.diag_deact }) do
    s2:add(fl, tvb(1, 1))
  end
  tree:add(d.diag_s3, tvb(2, 1)):add(d.diag_ovf, tvb(2, 1))
  tree:add(d.diag_master, tvb(3, 1))
  tree:add(d.diag_ident, tvb(4, 2))
  if tvb:len() > 6 then
    tree:add(d.diag_ext, tvb(6))
    dissect_dpv1_blocks(tvb(6):tvb(), tree)
  end
end

local function alarm_type_text(t)
  if ALARM_TYPES[t] then return ALARM_TYPES[t] end
  if t >= 32 and t <= 126 then return "manufacturer" end
  return "reserved"
end

-- Alarm_Type, Slot_Number, Alarm_Specifier at `tvb(0..3)`; returns the
-- alarm in words ("diagnostic alarm slot 1 seq 0 appears").
local function alarm_fields(tvb, tree)
  local t, slot, spec = tvb(0, 1):uint(), tvb(1, 1):uint(), tvb(2, 1):uint()
  tree:add(d.alarm_type, tvb(0, 1))
  tree:add(d.alarm_slot, tvb(1, 1))
  local st = tree:add(d.alarm_spec, tvb(2, 1))
  st:add(d.alarm_seq, tvb(2, 1)); st:add(d.alarm_addack, tvb(2, 1)); st:add(d.alarm_change, tvb(2, 1))
  return string.format("%s alarm slot %d seq %d %s", alarm_type_text(t), slot,
    bit.rshift(spec, 3), ALARM_CHANGES[bit.band(spec, 3)])
end

-- The DP-V1 alarm and status blocks of an extended diagnosis: the
-- device-related blocks (header b7-6 = 00, length 4..63) whose type byte
-- is an alarm type (1..6, 32..126) or a status type (0x81..0x83, 0x9E,
-- 0x9F). Other blocks are left to the "Extended diagnosis" bytes.
function dissect_dpv1_blocks(tvb, tree)
  local pos, len = 0, tvb:len()
  while pos < len do
    local h = tvb(pos, 1):uint()
    local kind = bit.rshift(h, 6)
    local n
    if kind == 2 then n = 3 else n = bit.band(h, 0x3F) end
    if n == 0 or pos + n > len then return end
    if kind == 0 and n >= 4 then
      local t = tvb(pos + 1, 1):uint()
      local alarm = (t >= 1 and t <= 6) or (t >= 32 and t <= 126)
      if alarm then
        local at = tree:add(d.alarm, tvb(pos, n))
        local words = alarm_fields(tvb(pos + 1, 3):tvb(), at)
        if n > 4 then at:add(d.alarm_data, tvb(pos + 4, n - 4)) end
        at:set_text("DP-V1 alarm: " .. words)
      elseif STATUS_TYPES[t] then
        local at = tree:add(d.alarm, tvb(pos, n))
        at:add(d.status_type, tvb(pos + 1, 1))
        at:add(d.alarm_slot, tvb(pos + 2, 1))
        at:add(d.alarm_change, tvb(pos + 3, 1))
        if n > 4 then at:add(d.alarm_data, tvb(pos + 4, n - 4)) end
        at:set_text("DP-V1 status: " .. STATUS_TYPES[t] .. " slot " .. tvb(pos + 2, 1):uint())
      end
    end
    pos = pos + n
  end
end

local function dissect_gc(tvb, tree)
  if tvb:len() < 2 then
    tree:add_proto_expert_info(e_len, "Global_Control shorter than 2 bytes")
    return
  end
  local c = tree:add(d.gc_cmd, tvb(0, 1))
  for _, fl in ipairs({ d.gc_clear, d.gc_unfreeze, d.gc_freeze, d.gc_unsync, d.gc_sync }) do
    c:add(fl, tvb(0, 1))
  end
  tree:add(d.gc_group, tvb(1, 1))
end

local function dissect_set_slave_add(tvb, tree)
  if tvb:len() < 4 then
    tree:add_proto_expert_info(e_len, "Set_Slave_Add shorter than 4 bytes")
    return
  end
  tree:add(d.ssa_new, tvb(0, 1))
  tree:add(d.ssa_ident, tvb(1, 2))
  tree:add(d.ssa_nochg, tvb(3, 1))
  if tvb:len() > 4 then tree:add(d.ssa_rem, tvb(4)) end
end

-- DP-V1 MSAC_C1 PDU; `request` is the FDL direction. Returns a summary.
local function dissect_dpv1(tvb, tree, request)
  local fn = tvb(0, 1):uint()
  tree:add(d.v1_fn, tvb(0, 1))
  local name = DPV1_FUNCTIONS[fn] or string.format("function 0x%02X", fn)
  if bit.band(fn, 0x80) ~= 0 then
    if tvb:len() >= 4 then
      tree:add(d.v1_edec, tvb(1, 1))
      local e1 = tree:add(d.v1_ec1, tvb(2, 1))
      e1:add(d.v1_class, tvb(2, 1)); e1:add(d.v1_code, tvb(2, 1))
      tree:add(d.v1_ec2, tvb(3, 1))
      return string.format("%s 0x%02X 0x%02X", name, tvb(2, 1):uint(), tvb(3, 1):uint())
    end
    tree:add_proto_expert_info(e_len, "DP-V1 error shorter than 4 bytes")
    return name
  end
  if tvb:len() >= 4 and fn == 0x5C then
    local words = alarm_fields(tvb(1, 3):tvb(), tree)
    return name .. " " .. words
  end
  if tvb:len() >= 4 and (fn == 0x5E or fn == 0x5F) then
    tree:add(d.v1_slot, tvb(1, 1))
    tree:add(d.v1_index, tvb(2, 1))
    tree:add(d.v1_len, tvb(3, 1))
    if tvb:len() > 4 then tree:add(d.v1_data, tvb(4)) end
    return string.format("%s slot %d index %d length %d", name, tvb(1, 1):uint(), tvb(2, 1):uint(),
      tvb(3, 1):uint())
  end
  if tvb:len() > 1 then tree:add(d.v1_data, tvb(1)) end
  return name
end

-- The DP layer of one telegram. `dsap`/`ssap` are nil without extension.
-- `tvb` is the data unit (nil when there is none), `whole` the telegram.
local function dissect_dp(tvb, whole, pinfo, root, request, dsap, ssap, function_code)
  local service, detail
  local len = tvb and tvb:len() or 0
  if dsap == nil and ssap == nil then
    if len == 0 then return nil end
    if request then
      service = "Data_Exchange"
      local t = root:add(pbdp, tvb(), "PROFIBUS DP, Data_Exchange request")
      t:add(d.service, service):set_generated()
      t:add(d.outputs, tvb())
    else
      service = "Data_Exchange"
      local t = root:add(pbdp, tvb(), "PROFIBUS DP, Data_Exchange response")
      t:add(d.service, service):set_generated()
      t:add(d.inputs, tvb())
      if function_code == 0xA then detail = "diagnosis pending" end
    end
    return service, detail
  end
  -- The slave's SAP is the DSAP of a request and the SSAP of a response.
  local sap = request and dsap or ssap
  local dp_names = {
    [49] = "MSAC_C2 Initiate", [50] = "Alarm_Ack", [51] = "DP-V1", [55] = "Set_Slave_Add",
    [56] = "Rd_Inp", [57] = "Rd_Outp", [58] = "Global_Control", [59] = "Get_Cfg",
    [60] = "Slave_Diag", [61] = "Set_Prm", [62] = "Chk_Cfg",
  }
  service = dp_names[sap]
  if service == nil then return nil end
  local t = root:add(pbdp, tvb or whole, "PROFIBUS DP, " .. service .. (request and " request" or " response"))
  t:add(d.service, service):set_generated()
  if sap == 61 and request then
    dissect_set_prm(tvb, t)
  elseif sap == 62 and request then
    dissect_cfg(tvb, t)
  elseif sap == 59 and not request and len > 0 then
    dissect_cfg(tvb, t)
  elseif sap == 60 and not request and len > 0 then
    dissect_diag(tvb, t)
  elseif sap == 58 and request then
    dissect_gc(tvb, t)
  elseif sap == 55 and request then
    dissect_set_slave_add(tvb, t)
  elseif sap == 56 and not request and len > 0 then
    t:add(d.inputs, tvb())
  elseif sap == 57 and not request and len > 0 then
    t:add(d.outputs, tvb())
  elseif sap == 51 or sap == 50 then
    if tvb == nil then
      t:add(d.v1_poll, true):set_generated()
      detail = "poll"
    else
      detail = dissect_dpv1(tvb, t, request)
    end
  end
  return service, detail
end


---------------------------------------------------------------------------
-- FMS (protocol "pbfms") on a connection SAP: a request or response with
-- both SAPs, the slave's SAP 0..48 (which DP-V1 leaves to MSAC_C2
-- connections and FMS shares), whose data unit starts with an LLI or FMS
-- type octet (none of them is a DP-V1 function number). The encoding is
-- profibus_dp::fms::{lli, pdu}: every octet value here is (unverified),
-- see docs/fms.md. Text as `dpctl sniff` prints it.

local pbfms = Proto("pbfms", "PROFIBUS FMS")
local FMS_TYPES = {
  [1] = "Confirmed-Request", [2] = "Confirmed-Response", [3] = "Confirmed-Error",
  [4] = "Unconfirmed", [5] = "Reject", [6] = "Initiate-Request", [7] = "Initiate-Response",
  [8] = "Initiate-Error",
}
local FMS_SERVICES = { [0] = "Status", [1] = "Identify", [2] = "Read", [3] = "Write", [4] = "Get-OD" }
local FMS_WORDS = { [0] = "status", [1] = "identify", [2] = "read", [3] = "write", [4] = "get_od" }
local LLI_TYPES = { [0x10] = "Associate", [0x11] = "Associate.resp", [0x12] = "Abort", [0x13] = "Idle" }
local LOGICAL = { [0x00] = "ready for communication", [0x02] = "limited services" }
local PHYSICAL = {
  [0x10] = "operational", [0x11] = "partly operational", [0x12] = "not operational",
  [0x13] = "maintenance required",
}
local ABORT_REASONS = {
  [0] = "released by the user", [1] = "connection monitoring: the peer fell silent",
  [2] = "protocol error", [3] = "Initiate refused",
}
local FMS_ERRORS = {
  [6] = { [7] = "object does not exist", [3] = "object access denied", [10] = "type or length conflict",
          [2] = "hardware fault", [5] = "object attribute inconsistent", [6] = "object access unsupported",
          any = "access error" },
  [5] = { [3] = "parameter inconsistent", any = "service error" },
  [7] = { [1] = "index not in the object dictionary", any = "object dictionary error" },
}

local m = pbfms.fields
m.lli = ProtoField.string("pbfms.lli", "LLI PDU")
m.lli_type = ProtoField.uint8("pbfms.lli.type", "LLI PDU type", base.HEX, LLI_TYPES)
m.monitoring = ProtoField.uint32("pbfms.monitoring_ms", "Connection monitoring (ms, 0: none)", base.DEC)
m.abort_reason = ProtoField.uint8("pbfms.abort.reason", "Abort reason", base.DEC, ABORT_REASONS)
m.abort_detail = ProtoField.uint8("pbfms.abort.detail", "Abort detail", base.DEC)
m.pdu = ProtoField.string("pbfms.pdu", "FMS PDU")
m.type = ProtoField.uint8("pbfms.type", "FMS PDU type", base.DEC, FMS_TYPES)
m.invoke = ProtoField.uint8("pbfms.invoke_id", "Invoke ID", base.DEC)
m.service = ProtoField.uint8("pbfms.service", "Service", base.DEC, FMS_SERVICES)
m.index = ProtoField.uint16("pbfms.index", "Index", base.DEC)
m.subindex = ProtoField.uint8("pbfms.subindex", "Subindex", base.DEC)
m.data = ProtoField.bytes("pbfms.data", "Data")
m.getod_flags = ProtoField.uint8("pbfms.getod.flags", "Get-OD flags", base.HEX)
m.long_form = ProtoField.bool("pbfms.getod.long_form", "All attributes (long form)", 8, nil, 0x80)
m.from_index = ProtoField.bool("pbfms.getod.from_index", "From the index on", 8, nil, 0x40)
m.more = ProtoField.uint8("pbfms.getod.more_follows", "More follows", base.HEX, { [0] = "no", [0xFF] = "yes" })
m.count = ProtoField.uint8("pbfms.getod.count", "Descriptions", base.DEC)
m.description = ProtoField.bytes("pbfms.getod.description", "Object description")
m.logical = ProtoField.uint8("pbfms.status.logical", "Logical status", base.HEX, LOGICAL)
m.physical = ProtoField.uint8("pbfms.status.physical", "Physical status", base.HEX, PHYSICAL)
m.detail = ProtoField.bytes("pbfms.status.local_detail", "Local detail")
m.vendor = ProtoField.string("pbfms.identify.vendor", "Vendor name")
m.model = ProtoField.string("pbfms.identify.model", "Model name")
m.revision = ProtoField.string("pbfms.identify.revision", "Revision")
m.err_class = ProtoField.uint8("pbfms.error.class", "Error class", base.DEC)
m.err_code = ProtoField.uint8("pbfms.error.code", "Error code", base.DEC)
m.err_add = ProtoField.uint16("pbfms.error.additional", "Additional code", base.DEC)
m.err_text = ProtoField.string("pbfms.error.text", "Error")
m.rej_invoke = ProtoField.uint8("pbfms.reject.invoke_id", "Original invoke ID", base.DEC)
m.rej_type = ProtoField.uint8("pbfms.reject.pdu_type", "Rejected PDU type", base.DEC, FMS_TYPES)
m.rej_code = ProtoField.uint8("pbfms.reject.code", "Reject code", base.DEC)
m.version_od = ProtoField.int16("pbfms.initiate.version_od", "Version OD", base.DEC)
m.profile = ProtoField.bytes("pbfms.initiate.profile", "Profile number")
m.protection = ProtoField.uint8("pbfms.initiate.access_protection", "Access protection supported", base.HEX,
  { [0] = "no", [0xFF] = "yes" })
m.password = ProtoField.uint8("pbfms.initiate.password", "Password", base.DEC)
m.groups = ProtoField.uint8("pbfms.initiate.access_groups", "Access groups", base.HEX)
m.max_pdu = ProtoField.bytes("pbfms.initiate.max_pdu", "Max PDU send high/low, receive high/low")
m.features = ProtoField.bytes("pbfms.initiate.features", "FMS features supported")
m.init_err = ProtoField.uint8("pbfms.initiate.error_code", "Initiate error code", base.DEC)
m.malformed = ProtoField.string("pbfms.malformed", "Does not decode")

local e_fms = ProtoExpert.new("pbfms.malformed.expert", "Malformed FMS PDU", expert.group.MALFORMED,
  expert.severity.ERROR)
pbfms.experts = { e_fms }

-- Whether a data unit's first octet is an LLI or FMS PDU type.
local function is_fms_start(b)
  return (b >= 1 and b <= 8) or (b >= 0x10 and b <= 0x13)
end

local function hex_text(tvb)
  local out = {}
  for i = 0, tvb:len() - 1 do out[#out + 1] = string.format("%02X", tvb(i, 1):uint()) end
  return table.concat(out, " ")
end

-- Raised (as a table) when the PDU is too short or wrong; caught in
-- dissect_fms.
local function bad(why) error({ fms = why }) end

local function need(tvb, o, n, what)
  if tvb:len() < o + n then
    bad(string.format("FMS %s is %d bytes long, needs %d", what, tvb:len(), o + n))
  end
end

local function visible(tvb, t, o, field, what)
  need(tvb, o, 1, what)
  local n = tvb(o, 1):uint()
  need(tvb, o + 1, n, what)
  local s = n > 0 and tvb(o + 1, n):string() or ""
  t:add(field, n > 0 and tvb(o + 1, n) or tvb(o, 1), s)
  return s, o + 1 + n
end

local function ends(tvb, o, what)
  if tvb:len() > o then bad(string.format("FMS %s has %d bytes too many", what, tvb:len() - o)) end
end

-- The FMS PDU in `tvb` (from octet 0); the text line.
local function fms_pdu(tvb, t)
  local ty = tvb(0, 1):uint()
  local kind = FMS_TYPES[ty]
  if kind == nil then bad(string.format("unknown FMS PDU type %d", ty)) end
  t:add(m.type, tvb(0, 1))
  local function service_at(o, what)
    need(tvb, o, 1, what)
    local s = tvb(o, 1):uint()
    if FMS_SERVICES[s] == nil then
      bad(string.format("unknown FMS service %d in a %s PDU", s, what))
    end
    t:add(m.service, tvb(o, 1))
    return s
  end
  if ty == 1 or ty == 2 or ty == 3 then
    local what = ({ "confirmed request", "confirmed response", "confirmed error" })[ty]
    need(tvb, 1, 1, what)
    local invoke = tvb(1, 1):uint()
    t:add(m.invoke, tvb(1, 1))
    local s = service_at(2, what)
    local name = FMS_SERVICES[s]
    if ty == 3 then
      need(tvb, 3, 4, what)
      ends(tvb, 7, what)
      local class, code = tvb(3, 1):uint(), tvb(4, 1):uint()
      t:add(m.pdu, "error"):set_generated()
      t:add(m.err_class, tvb(3, 1)); t:add(m.err_code, tvb(4, 1)); t:add(m.err_add, tvb(5, 2))
      local c = FMS_ERRORS[class]
      local text = c and (c[code] or c.any) or "error"
      t:add(m.err_text, text):set_generated()
      return string.format("FMS Error invoke %d (%s) class %d code %d additional %d: %s", invoke, name,
        class, code, tvb(5, 2):uint(), text)
    end
    local suffix = ty == 1 and "req" or "resp"
    t:add(m.pdu, FMS_WORDS[s] .. "_" .. suffix):set_generated()
    local text = string.format("FMS %s.%s invoke %d", name, suffix, invoke)
    local n = tvb:len()
    if ty == 1 then
      if s == 2 then
        need(tvb, 3, 2, "Read request")
        t:add(m.index, tvb(3, 2))
        text = text .. " index " .. tvb(3, 2):uint()
        if n == 6 then
          t:add(m.subindex, tvb(5, 1)); text = text .. " subindex " .. tvb(5, 1):uint()
        end
        ends(tvb, 6, "Read request")
      elseif s == 3 then
        need(tvb, 3, 3, "Write request")
        t:add(m.index, tvb(3, 2))
        text = text .. " index " .. tvb(3, 2):uint()
        if tvb(5, 1):uint() ~= 0 then
          t:add(m.subindex, tvb(5, 1)); text = text .. " subindex " .. tvb(5, 1):uint()
        end
        if n > 6 then t:add(m.data, tvb(6)) end
        text = text .. " data " .. (n > 6 and hex_text(tvb(6)) or "")
      elseif s == 4 then
        need(tvb, 3, 3, "Get-OD request")
        ends(tvb, 6, "Get-OD request")
        local ft = t:add(m.getod_flags, tvb(3, 1))
        ft:add(m.long_form, tvb(3, 1)); ft:add(m.from_index, tvb(3, 1))
        t:add(m.index, tvb(4, 2))
        local flags = tvb(3, 1):uint()
        text = text .. string.format(" index %d%s, %s form", tvb(4, 2):uint(),
          bit.band(flags, 0x40) ~= 0 and " onwards" or "",
          bit.band(flags, 0x80) ~= 0 and "long" or "short")
      else
        ends(tvb, 3, what)
      end
      return text
    end
    -- Responses.
    if s == 0 then
      need(tvb, 3, 5, "Status response")
      ends(tvb, 8, "Status response")
      t:add(m.logical, tvb(3, 1)); t:add(m.physical, tvb(4, 1)); t:add(m.detail, tvb(5, 3))
      local l, p = tvb(3, 1):uint(), tvb(4, 1):uint()
      return text .. string.format(": %s, %s (logical 0x%02X, physical 0x%02X, detail %s)",
        LOGICAL[l] or "unknown logical status", PHYSICAL[p] or "unknown physical status", l, p,
        hex_text(tvb(5, 3)))
    elseif s == 1 then
      local v, o = visible(tvb, t, 3, m.vendor, "Identify response")
      local mo, o2 = visible(tvb, t, o, m.model, "Identify response")
      local r, o3 = visible(tvb, t, o2, m.revision, "Identify response")
      ends(tvb, o3, "Identify response")
      return text .. string.format(': vendor "%s" model "%s" revision "%s"', v, mo, r)
    elseif s == 2 then
      if n > 3 then t:add(m.data, tvb(3)) end
      return text .. " data " .. (n > 3 and hex_text(tvb(3)) or "")
    elseif s == 3 then
      ends(tvb, 3, "Write response")
      return text
    else
      need(tvb, 3, 2, "Get-OD response")
      local more = tvb(3, 1):uint()
      if more ~= 0 and more ~= 0xFF then
        bad(string.format("FMS more-follows is 0x%02X, neither 0x00 (false) nor 0xFF (true)", more))
      end
      t:add(m.more, tvb(3, 1)); t:add(m.count, tvb(4, 1))
      local count, o = tvb(4, 1):uint(), 5
      for _ = 1, count do
        need(tvb, o, 1, "Get-OD response")
        local len = tvb(o, 1):uint()
        need(tvb, o + 1, len, "Get-OD response")
        t:add(m.description, len > 0 and tvb(o + 1, len) or tvb(o, 1))
        o = o + 1 + len
      end
      ends(tvb, o, "Get-OD response")
      return text .. string.format(": %d description%s%s", count, count == 1 and "" or "s",
        more == 0xFF and ", more follow" or "")
    end
  elseif ty == 4 then
    need(tvb, 1, 1, "unconfirmed")
    if tvb(1, 1):uint() ~= 0 then
      bad(string.format("unknown FMS service %d in a unconfirmed PDU", tvb(1, 1):uint()))
    end
    need(tvb, 2, 2, "Information-Report")
    t:add(m.pdu, "information_report"):set_generated()
    t:add(m.index, tvb(2, 2))
    if tvb:len() > 4 then t:add(m.data, tvb(4)) end
    return string.format("FMS Information-Report index %d data %s", tvb(2, 2):uint(),
      tvb:len() > 4 and hex_text(tvb(4)) or "")
  elseif ty == 5 then
    need(tvb, 1, 3, "reject")
    ends(tvb, 4, "reject")
    t:add(m.pdu, "reject"):set_generated()
    t:add(m.rej_invoke, tvb(1, 1)); t:add(m.rej_type, tvb(2, 1)); t:add(m.rej_code, tvb(3, 1))
    return string.format("FMS Reject invoke %d (PDU type %d) code %d", tvb(1, 1):uint(), tvb(2, 1):uint(),
      tvb(3, 1):uint())
  elseif ty == 6 or ty == 7 then
    local what = ty == 6 and "Initiate request" or "Initiate response"
    need(tvb, 1, ty == 6 and 17 or 7, what)
    ends(tvb, ty == 6 and 18 or 8, what)
    t:add(m.pdu, ty == 6 and "initiate_req" or "initiate_resp"):set_generated()
    t:add(m.version_od, tvb(1, 2)); t:add(m.profile, tvb(3, 2)); t:add(m.protection, tvb(5, 1))
    t:add(m.password, tvb(6, 1)); t:add(m.groups, tvb(7, 1))
    local text = string.format("FMS Initiate.%s OD version %d, profile %s", ty == 6 and "req" or "resp",
      tvb(1, 2):int(), hex_text(tvb(3, 2)))
    if ty == 6 then
      t:add(m.max_pdu, tvb(8, 4)); t:add(m.features, tvb(12, 6))
      text = text .. string.format(", max PDU send %d/%d receive %d/%d, features %s", tvb(8, 1):uint(),
        tvb(9, 1):uint(), tvb(10, 1):uint(), tvb(11, 1):uint(), hex_text(tvb(12, 6)))
    end
    return text
  else
    need(tvb, 1, 1, "Initiate error")
    ends(tvb, 2, "Initiate error")
    t:add(m.pdu, "initiate_error"):set_generated()
    t:add(m.init_err, tvb(1, 1))
    return "FMS Initiate error code " .. tvb(1, 1):uint()
  end
end

-- The LLI PDU (and the FMS PDU in it) of a data unit; the text line.
local function lli_pdu(tvb, t)
  local ty = tvb(0, 1):uint()
  if ty == 0x10 then
    need(tvb, 1, 3, "LLI Associate")
    if tvb(3, 1):uint() ~= 6 then bad("LLI Associate carries no Initiate") end
    t:add(m.lli, "associate"):set_generated()
    t:add(m.lli_type, tvb(0, 1))
    local units = tvb(1, 2):uint()
    t:add(m.monitoring, tvb(1, 2), units * 10)
    local inner = fms_pdu(tvb(3):tvb(), t)
    local mon = units == 0 and "no monitoring" or string.format("monitoring %d ms", units * 10)
    return string.format("LLI Associate (%s): %s", mon, inner)
  elseif ty == 0x11 then
    need(tvb, 1, 1, "LLI Associate.resp")
    local b = tvb(1, 1):uint()
    if b ~= 7 and b ~= 8 then bad("LLI Associate.resp carries no Initiate") end
    t:add(m.lli, "associate_res"):set_generated()
    t:add(m.lli_type, tvb(0, 1))
    local inner = fms_pdu(tvb(1):tvb(), t)
    return "LLI Associate.resp: " .. inner
  elseif ty == 0x12 then
    need(tvb, 1, 2, "LLI Abort")
    ends(tvb, 3, "LLI Abort")
    t:add(m.lli, "abort"):set_generated()
    t:add(m.lli_type, tvb(0, 1))
    t:add(m.abort_reason, tvb(1, 1)); t:add(m.abort_detail, tvb(2, 1))
    local r = tvb(1, 1):uint()
    return string.format("LLI Abort reason %d detail %d: %s", r, tvb(2, 1):uint(),
      ABORT_REASONS[r] or "unknown reason")
  elseif ty == 0x13 then
    ends(tvb, 1, "LLI Idle")
    t:add(m.lli, "idle"):set_generated()
    t:add(m.lli_type, tvb(0, 1))
    return "LLI Idle"
  end
  local text = fms_pdu(tvb, t)
  t:add(m.lli, "data"):set_generated()
  return text
end

-- The FMS layer of a telegram, when it is one: its text, else nil.
local function dissect_fms(du, root, request, dsap, ssap)
  if du == nil or dsap == nil or ssap == nil then return nil end
  local sap = request and dsap or ssap
  if sap > 48 or not is_fms_start(du(0, 1):uint()) then return nil end
  local t = root:add(pbfms, du, "PROFIBUS FMS")
  local ok, text = pcall(lli_pdu, du:tvb(), t)
  if ok then
    t:append_text(", " .. text)
    return text
  end
  local why = type(text) == "table" and text.fms or tostring(text)
  t:add(m.lli, "malformed"):set_generated()
  t:add(m.malformed, why):set_generated()
  t:add_proto_expert_info(e_fms, why)
  return "FMS malformed: " .. why
end

---------------------------------------------------------------------------
-- Layer 2

local function fcs_of(tvb, from, to)
  local s = 0
  for i = from, to - 1 do s = s + tvb(i, 1):uint() end
  return s % 256
end

-- Dissects DA SA FC [DSAP] [SSAP] DU FCS ED starting at `pos`, with
-- `body` bytes from DA through the last DU byte.
local function dissect_body(tvb, pinfo, tree, root, pos, body, sdname)
  local da, sa, fc = tvb(pos, 1):uint(), tvb(pos + 1, 1):uint(), tvb(pos + 2, 1):uint()
  local dt = tree:add(f.da, tvb(pos, 1))
  dt:add(f.da_ext, tvb(pos, 1)); dt:add(f.da_addr, tvb(pos, 1))
  local st = tree:add(f.sa, tvb(pos + 1, 1))
  st:add(f.sa_ext, tvb(pos + 1, 1)); st:add(f.sa_addr, tvb(pos + 1, 1))
  add_stations(tree, pinfo, sa, da)

  local request = bit.band(fc, 0x40) ~= 0
  local code = bit.band(fc, 0x0F)
  if not pinfo.visited then
    last_request = request and { sa, da } or nil
  end
  local fname
  local ft = tree:add(f.fc, tvb(pos + 2, 1))
  ft:add(f.fc_req, tvb(pos + 2, 1))
  if request then
    ft:add(f.fc_fcb, tvb(pos + 2, 1)); ft:add(f.fc_fcv, tvb(pos + 2, 1))
    fname = REQ_FUNCTIONS[code] or string.format("reserved (0x%X)", code)
  else
    ft:add(f.fc_stype, tvb(pos + 2, 1))
    fname = RESP_FUNCTIONS[code] or string.format("reserved (0x%X)", code)
  end
  ft:add(f.fc_function, tvb(pos + 2, 1), fname)
  ft:append_text(" (" .. fname .. ")")

  local k = pos + 3
  local stop = pos + body
  local dsap, ssap
  if bit.band(da, 0x80) ~= 0 and k < stop then
    dsap = bit.band(tvb(k, 1):uint(), 0x3F); tree:add(f.dsap, tvb(k, 1)); k = k + 1
  end
  if bit.band(sa, 0x80) ~= 0 and k < stop then
    ssap = bit.band(tvb(k, 1):uint(), 0x3F); tree:add(f.ssap, tvb(k, 1)); k = k + 1
  end
  local du = nil
  if stop > k then
    du = tvb(k, stop - k)
    tree:add(f.data, du)
  end

  local fcs = tvb(stop, 1):uint()
  local want = fcs_of(tvb, pos, stop)
  local fct = tree:add(f.fcs, tvb(stop, 1))
  if fcs == want and flagged then
    fct:append_text(" [correct]")
    mark_bad(tree, e_flag, "FCS right, but recorded as no valid telegram (CRC-error flag)")
  elseif fcs == want then
    fct:append_text(" [correct]")
    tree:add(f.fcs_status, "Good"):set_generated()
    tree:add(f.fcs_good, true):set_generated()
  else
    fct:append_text(string.format(" [incorrect, should be 0x%02X]", want))
    tree:add(f.fcs_status, "Bad"):set_generated()
    tree:add(f.fcs_good, false):set_generated()
    marked_bad = true
    fct:add_proto_expert_info(e_fcs, string.format("FCS 0x%02X, computed 0x%02X", fcs, want))
  end
  tree:add(f.ed, tvb(stop + 1, 1))

  local info = string.format("%s %d → %d %s", sdname, bit.band(sa, 0x7F), bit.band(da, 0x7F), fname)
  if dsap or ssap then
    info = info .. string.format(" [%s:%s]", ssap and tostring(ssap) or "-", dsap and tostring(dsap) or "-")
  end
  local fms = dissect_fms(du, root, request, dsap, ssap)
  local service, detail
  if fms then
    pinfo.cols.protocol = "PROFIBUS FMS"
    info = info .. " " .. fms
  else
    service, detail = dissect_dp(du, tvb(), pinfo, root, request, dsap, ssap, code)
  end
  if service then
    pinfo.cols.protocol = "PROFIBUS DP"
    info = info .. " " .. service
    if detail then info = info .. " (" .. detail .. ")" end
  end
  if fcs ~= want then info = info .. " [FCS wrong]" end
  pinfo.cols.info = info
end

local function dissect_telegram(tvb, pinfo, tree, root)
  local len = tvb:len()
  pinfo.cols.protocol = "PROFIBUS DL"
  local sd = tvb(0, 1):uint()
  local sdname = SD_NAMES[sd]
  tree:add(f.sd, tvb(0, 1))
  if sdname == nil then
    mark_bad(tree, e_len, string.format("unknown start delimiter 0x%02X", sd))
    pinfo.cols.info = string.format("unknown start delimiter 0x%02X", sd)
    return len
  end
  tree:add(f.type, tvb(0, 1), sdname):set_generated()
  tree:append_text(", " .. sdname)

  if sd == 0xE5 then
    local t = timing[pinfo.number]
    if t and not pinfo.visited then
      t.answers = last_request
      last_request = nil
    end
    if t and t.answers then
      -- From the station asked to the one that asked.
      add_stations(tree, pinfo, t.answers[2], t.answers[1])
    end
    pinfo.cols.info = "SC short acknowledge"
    return 1
  elseif sd == 0xDC then
    if len < 3 then
      mark_bad(tree, e_len, "token shorter than 3 bytes"); return len
    end
    local dt = tree:add(f.da, tvb(1, 1)); dt:add(f.da_addr, tvb(1, 1))
    local st = tree:add(f.sa, tvb(2, 1)); st:add(f.sa_addr, tvb(2, 1))
    tree:add(f.token, true):set_generated()
    add_stations(tree, pinfo, tvb(2, 1):uint(), tvb(1, 1):uint())
    pinfo.cols.info = string.format("SD4 token %d → %d", bit.band(tvb(2, 1):uint(), 0x7F),
      bit.band(tvb(1, 1):uint(), 0x7F))
    return 3
  elseif sd == 0x10 then
    if len < 6 then
      mark_bad(tree, e_len, "SD1 telegram shorter than 6 bytes"); return len
    end
    dissect_body(tvb, pinfo, tree, root, 1, 3, sdname)
    return 6
  elseif sd == 0xA2 then
    if len < 14 then
      mark_bad(tree, e_len, "SD3 telegram shorter than 14 bytes"); return len
    end
    dissect_body(tvb, pinfo, tree, root, 1, 11, sdname)
    return 14
  else -- SD2
    if len < 4 then
      mark_bad(tree, e_len, "SD2 header cut off"); return len
    end
    local le, ler = tvb(1, 1):uint(), tvb(2, 1):uint()
    tree:add(f.le, tvb(1, 1))
    tree:add(f.ler, tvb(2, 1))
    if le ~= ler or tvb(3, 1):uint() ~= 0x68 or le < 3 or len < le + 6 then
      mark_bad(tree, e_len, string.format("SD2 with LE %d, LEr %d in %d bytes", le, ler, len))
      pinfo.cols.info = "SD2 malformed"
      return len
    end
    dissect_body(tvb, pinfo, tree, root, 4, le, sdname)
    return le + 6
  end
end

function pbdl.dissector(tvb, pinfo, root)
  if tvb:len() < 1 then return 0 end
  local tree = root:add(pbdl, tvb(), "PROFIBUS DL")
  add_timing(tvb, pinfo, tree)
  marked_bad = false
  local flag = crc_flag and crc_flag()
  flagged = flag ~= nil and flag.value == true
  local n = dissect_telegram(tvb, pinfo, tree, root)
  if flagged and not marked_bad then
    mark_bad(tree, e_flag, "recorded as no valid telegram (CRC-error flag)")
    pinfo.cols.info:append(" [corrupt]")
  end
  return n
end

-- Link type 257 has no Wireshark encapsulation of its own: pcapng files
-- with it arrive as WTAP_ENCAP_UNKNOWN (0). Newer Wireshark versions
-- that map it to a name in `wtap_encaps` are served too.
local encap_table = DissectorTable.get("wtap_encap")
encap_table:add(0, pbdl)
if wtap_encaps and wtap_encaps.PROFIBUS_DL then
  encap_table:add(wtap_encaps.PROFIBUS_DL, pbdl)
end
