//! Terminal views of a PROFIBUS-DP bus, on [ratatui].
//!
//! - [`bus::BusView`]: the slaves of a DP master (`dpctl master`,
//!   `dpctl demo`), or of a bus a passive monitor listens to (`dpctl
//!   monitor`: also the masters in the token ring; no writes), as a
//!   refreshing table: address, name, start-up state,
//!   the slave's Data_Exchange cycle time, retries, inputs and outputs in
//!   hex and decoded (by the device profile's named channels, or by the
//!   GSD modules the master configured), the last diagnosis in words, and
//!   a log of the master's events. Keys pause the view, select a slave,
//!   show its details and write its outputs.
//! - [`source`]: what the bus view shows, a [`source::BusSnapshot`]
//!   taken from a [`source::BusSource`] (a `DpMaster` or a `Monitor`).
//! - [`lines`]: the same as text and JSON lines when stdout is no
//!   terminal (`dpctl master --plain`, `--json`).
//! - [`sniff::SniffView`]: telegrams seen on a line (`dpctl sniff`), with
//!   filters by address, service and errors, and per-station statistics.
//! - [`term::Screen`]: the terminal session (raw mode, alternate screen)
//!   the views draw on, restored when it is dropped; [`term::LiveBus`]
//!   and [`term::LiveSniff`] run a view on it from an application's loop
//!   (keys every 20 ms, a frame every 100 ms of wall-clock time).
//!
//! The views are plain state: the application feeds them (a
//! [`DpMaster`](profibus_dp::master::DpMaster) or a
//! [`Monitor`](profibus_dp::monitor::Monitor) to snapshot, telegrams),
//! gives them [`Key`]s and draws them into any ratatui backend. Tests
//! draw them on a `TestBackend` and read the screen as text
//! ([`screen_text`]). Nothing here decodes process data or diagnosis by
//! itself: channels come from `profibus_devices::channels`, module sizes
//! from the GSD (`profibus_dp::config::gsd`), diagnosis words from
//! `profibus_dp::pdu::diag`, telegrams from `profibus_fdl::wire`.

pub mod bus;
pub mod health;
pub mod lines;
pub mod sniff;
pub mod source;
pub mod term;

pub use ratatui;

/// A key press, as the views understand it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Key {
    /// A printable character.
    Char(char),
    /// Cursor up.
    Up,
    /// Cursor down.
    Down,
    /// Page up.
    PageUp,
    /// Page down.
    PageDown,
    /// Enter / Return.
    Enter,
    /// Escape.
    Esc,
    /// Backspace.
    Backspace,
    /// Ctrl-C (raw mode delivers it as a key, not as a signal).
    Interrupt,
}

impl Key {
    /// The key of a crossterm key event; `None` for keys the views do not
    /// use and for key releases.
    pub fn from_crossterm(e: ratatui::crossterm::event::KeyEvent) -> Option<Key> {
        use ratatui::crossterm::event::{KeyCode, KeyEventKind, KeyModifiers};
        if e.kind == KeyEventKind::Release {
            return None;
        }
        Some(match e.code {
            KeyCode::Char('c') if e.modifiers.contains(KeyModifiers::CONTROL) => Key::Interrupt,
            KeyCode::Char(c) => Key::Char(c),
            KeyCode::Up => Key::Up,
            KeyCode::Down => Key::Down,
            KeyCode::PageUp => Key::PageUp,
            KeyCode::PageDown => Key::PageDown,
            KeyCode::Enter => Key::Enter,
            KeyCode::Esc => Key::Esc,
            KeyCode::Backspace => Key::Backspace,
            _ => return None,
        })
    }
}

/// What a person sees in a ratatui buffer: one line of text per row,
/// trailing blanks removed (for tests on a `TestBackend`).
pub fn screen_text(buffer: &ratatui::buffer::Buffer) -> String {
    let area = buffer.area;
    let mut out = String::new();
    for y in area.top()..area.bottom() {
        let mut line = String::new();
        for x in area.left()..area.right() {
            line.push_str(buffer[(x, y)].symbol());
        }
        out.push_str(line.trim_end());
        out.push('\n');
    }
    out
}

/// `text` cut to at most `width` characters, with `…` when cut: long
/// values stay on their line instead of wrapping.
pub(crate) fn fit(text: &str, width: usize) -> String {
    if text.chars().count() <= width {
        return text.to_string();
    }
    let mut s: String = text.chars().take(width.saturating_sub(1)).collect();
    s.push('…');
    s
}

/// Bytes as hex text (`01 0A FF`).
pub(crate) fn hex(bytes: &[u8]) -> String {
    profibus_fdl::wire::Hex(bytes).to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_cuts_long_text_with_an_ellipsis() {
        assert_eq!(fit("abcdef", 10), "abcdef");
        assert_eq!(fit("abcdef", 4), "abc…");
        assert_eq!(fit("äöüß", 3), "äö…");
    }
}
