//! A station's role, DP state and health as table cells, the same in
//! every view that has the analyser's live list (`dpctl sniff`'s
//! stations, `dpctl monitor`'s slaves and token ring).
//!
//! The numbers come from the statistics core
//! ([`profibus_dp::monitor::stats::Stats::live`], health by
//! [`profibus_dp::monitor::stats::health`], docs/analyser.md); this
//! module only draws them.

use profibus_dp::monitor::stats::LiveStation;
use ratatui::style::{Color, Style};
use ratatui::widgets::Cell;

/// The headings of [`cells`], left to right.
pub const COLUMNS: [&str; 3] = ["Role", "DP state", "Health"];

/// The widths of [`cells`]' columns.
pub const WIDTHS: [u16; 3] = [7, 14, 15];

/// A health score 0 … 100 as a bar of ten cells and the number, e.g.
/// `████████░░  80`.
pub fn health_bar(health: u8) -> String {
    let full = (health.min(100) as usize + 5) / 10;
    format!("{}{} {health:>3}", "█".repeat(full), "░".repeat(10 - full))
}

/// The colour of a health score: green from 90, yellow from 60, else red.
pub fn health_style(health: u8) -> Style {
    match health {
        90.. => Style::default().fg(Color::Green),
        60..=89 => Style::default().fg(Color::Yellow),
        _ => Style::default().fg(Color::Red),
    }
}

/// Role, DP state and the coloured health bar of a station of the live
/// list (`None`: not heard by the analyser yet: `-`, `-`, a full bar).
pub fn cells(live: Option<&LiveStation>) -> [Cell<'static>; 3] {
    let health = live.map_or(100, |l| l.health);
    [
        Cell::from(live.and_then(|l| l.role).map_or("-", |r| r.name())),
        Cell::from(live.and_then(|l| l.dp_state).map_or("-", |s| s.name())),
        Cell::from(health_bar(health)).style(health_style(health)),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bar_rounds_to_tenths_and_keeps_the_number() {
        assert_eq!(health_bar(80), "████████░░  80");
        assert_eq!(health_bar(100), "██████████ 100");
        assert_eq!(health_bar(94), "█████████░  94");
        assert_eq!(health_bar(0), "░░░░░░░░░░   0");
        assert_eq!(health_style(59), Style::default().fg(Color::Red));
        assert_eq!(health_style(60), Style::default().fg(Color::Yellow));
        assert_eq!(health_style(90), Style::default().fg(Color::Green));
    }
}
