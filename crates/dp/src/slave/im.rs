//! I&M (identification and maintenance) in the slave core: the "Call"
//! on slot 0, index 255 (`shared/reference/dpv1-c2-im-alarms.md` §4.6,
//! \[ABB\], \[IFM\], \[SCH\]; the data units in [`crate::pdu::im`]).
//!
//! A master selects a record with a Write of the 4-byte call header
//! `08 00 FI_Index` (65000 = I&M0 … 65004 = I&M4); a Write of the call
//! header followed by the record's 64 bytes writes I&M1..I&M4. The next
//! Read of slot 0, index 255 returns the call header again and the 64
//! bytes of the selected record. Each channel (the class-1 master, each
//! class-2 connection) has its own selection, so a tool reading I&M over
//! class 2 does not disturb a PLC doing the same over class 1.
//!
//! Our reading where the sources leave a choice:
//! - a Read without a selection is refused with "access: state
//!   conflict" (0xB5); the selection stays after a Read, so the record
//!   can be read again;
//! - a record the device does not have (or an FI_Index outside
//!   65000..=65004) is "access: invalid index" (0xB0); writing I&M0 is
//!   "access: access denied" (0xB6);
//! - a Write of index 255 that is not a call (first byte not 08) is
//!   "access: invalid parameter" (0xB8); a call of another length than 4
//!   or 68 bytes is "access: write length error" (0xB1);
//! - a Read shorter than 68 bytes returns the first bytes only, as any
//!   DP-V1 read of a longer record.

use super::device::{
    Device, Dpv1Outcome, ERR_ACCESS_DENIED, ERR_CLASS_ACCESS, ERR_INVALID_INDEX,
    ERR_INVALID_PARAMETER, ERR_STATE_CONFLICT, ERR_WRITE_LENGTH,
};
use crate::pdu::im::{CallHeader, ImError, CALL_HEADER_LEN, CALL_INDEX, RECORD_LEN};
use profibus_fdl::Instant;

/// The I&M record a channel selected (0..=4), if any.
pub(super) type Selection = Option<u8>;

/// Whether a Read or Write of `slot`/`index` is an I&M call the core
/// answers (for a device with I&M).
pub(super) fn is_call(im: bool, slot: u8, index: u8) -> bool {
    im && slot == 0 && index == CALL_INDEX
}

/// A Write of `data` to slot 0, index 255: select (and for I&M1..4 with
/// data, write) a record.
pub(super) fn write<D: Device>(
    device: &mut D,
    now: Instant,
    selection: &mut Selection,
    data: &[u8],
) -> Dpv1Outcome {
    let fail = |code| Dpv1Outcome::write_error(ERR_CLASS_ACCESS, code);
    let (header, rest) = match CallHeader::parse(data) {
        Ok(h) => h,
        Err(ImError::ShortHeader(_)) => return fail(ERR_WRITE_LENGTH),
        Err(_) => return fail(ERR_INVALID_PARAMETER),
    };
    let mut record = [0u8; RECORD_LEN];
    let Some(n) = header
        .im_number()
        .filter(|&n| device.im_read(n, &mut record))
    else {
        return fail(ERR_INVALID_INDEX);
    };
    match rest.len() {
        0 => {}
        RECORD_LEN if n == 0 => return fail(ERR_ACCESS_DENIED),
        RECORD_LEN => {
            record.copy_from_slice(rest);
            if let Err(e) = device.im_write(now, n, &record) {
                return Dpv1Outcome::Error(e);
            }
        }
        _ => return fail(ERR_WRITE_LENGTH),
    }
    *selection = Some(n);
    Dpv1Outcome::Done(data.len())
}

/// A Read of slot 0, index 255 into `out` (the requested length): the
/// call header and the selected record.
pub(super) fn read<D: Device>(device: &mut D, selection: Selection, out: &mut [u8]) -> Dpv1Outcome {
    let Some(n) = selection else {
        return Dpv1Outcome::read_error(ERR_CLASS_ACCESS, ERR_STATE_CONFLICT);
    };
    let mut full = [0u8; CALL_HEADER_LEN + RECORD_LEN];
    let mut record = [0u8; RECORD_LEN];
    if !device.im_read(n, &mut record) {
        return Dpv1Outcome::read_error(ERR_CLASS_ACCESS, ERR_INVALID_INDEX);
    }
    full[..CALL_HEADER_LEN].copy_from_slice(&CallHeader::im(n).bytes());
    full[CALL_HEADER_LEN..].copy_from_slice(&record);
    let len = out.len().min(full.len());
    out[..len].copy_from_slice(&full[..len]);
    Dpv1Outcome::Done(len)
}
