//! Hex text for the command line's printing (telegram descriptions are
//! `profibus_dp::describe::TelegramSummary`).

/// Bytes as space-separated upper-case hex (`01 0A FF`).
pub fn hex(bytes: &[u8]) -> String {
    profibus_fdl::wire::Hex(bytes).to_string()
}
