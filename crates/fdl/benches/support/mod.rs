//! What the wire benches share: the telegram they encode and decode, ours
//! and profirust's.

use profibus_fdl::wire::{DataTelegram, FunctionCode, RequestKind, Telegram};

/// A Data_Exchange request from master 2 to slave 8 (SRD high, FCB and FCV
/// set, no SAPs) with `data` as its data unit.
#[inline]
pub fn data_exchange(data: &[u8]) -> Telegram<'_> {
    let fc = FunctionCode::Request {
        kind: RequestKind::SrdHigh,
        fcb: true,
        fcv: true,
    };
    Telegram::Data(DataTelegram::new(8, 2, fc, data))
}

/// The header of the same request for profirust's encoder.
pub fn profirust_data_exchange() -> profirust::fdl::DataTelegramHeader {
    profirust::fdl::DataTelegramHeader {
        da: 8,
        sa: 2,
        dsap: None,
        ssap: None,
        fc: profirust::fdl::FunctionCode::new_srd_high(
            profirust::fdl::FrameCountBit::from_fcv_fcb(true, true),
        ),
    }
}
