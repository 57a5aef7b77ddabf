//! Fixtures shared by the unit tests of this crate.

use profibus_fdl::wire::{DataTelegram, FunctionCode, RequestKind, Telegram};

/// The bytes of an FDL Status request from station `sa` to station `da`.
pub(crate) fn fdl_status(da: u8, sa: u8) -> Vec<u8> {
    let fc = FunctionCode::request(RequestKind::FdlStatus);
    Telegram::Data(DataTelegram::new(da, sa, fc, &[]))
        .to_vec()
        .unwrap()
}
