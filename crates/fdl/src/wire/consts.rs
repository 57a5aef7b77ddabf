//! Byte constants of the FDL telegram formats (IEC 61158-4-3 / EN 50170
//! volume 2, the telegram formats of the data-link layer).

/// Start delimiter of a telegram without data unit: `10 DA SA FC FCS 16`.
pub const SD1: u8 = 0x10;
/// Start delimiter of a telegram with a variable data unit:
/// `68 LE LEr 68 DA SA FC [DSAP SSAP] DU FCS 16`.
pub const SD2: u8 = 0x68;
/// Start delimiter of a telegram with a fixed 8-byte data field:
/// `A2 DA SA FC [DSAP SSAP] DU FCS 16`.
pub const SD3: u8 = 0xA2;
/// Start delimiter of the token telegram `DC DA SA` (no FCS, no end delimiter).
pub const SD4: u8 = 0xDC;
/// The short acknowledge, a telegram of one byte.
pub const SC: u8 = 0xE5;
/// End delimiter of SD1, SD2 and SD3 telegrams.
pub const ED: u8 = 0x16;

/// Bit 7 of DA/SA: an address extension byte (DSAP / SSAP) follows FC.
pub const ADDRESS_EXTENSION: u8 = 0x80;
/// Destination address 127 addresses every station (broadcast / multicast).
pub const BROADCAST: u8 = 127;
/// Highest address a station may own (126 is the commissioning address of
/// DP slaves; 127 is broadcast).
pub const MAX_STATION_ADDRESS: u8 = 126;

/// Smallest LE an SD2 telegram may carry on receive (DA SA FC with no data;
/// senders use SD1 for this, but pyprofibus and profirust accept it).
pub const MIN_LE: u8 = 3;
/// Largest LE of an SD2 telegram (DA SA FC + 246 bytes of data field).
pub const MAX_LE: u8 = 249;
/// Size of the data field of an SD3 telegram, SAP bytes included.
pub const SD3_DATA_FIELD: usize = 8;
/// Largest data field of an SD2 telegram, SAP bytes included.
pub const MAX_DATA_FIELD: usize = 246;
/// Largest telegram on the wire (SD2 with LE = 249): 255 bytes.
pub const MAX_TELEGRAM_LEN: usize = MAX_LE as usize + 6;

/// Bits per character on the wire: start, 8 data, even parity, stop.
pub const BITS_PER_CHAR: u32 = 11;
