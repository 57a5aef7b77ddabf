//! Telegrams seen on a line, as a live list with filters and
//! per-station statistics (`dpctl sniff` on a terminal).
//!
//! [`SniffView`] takes telegrams ([`SniffView::telegram`]) and skipped
//! bytes ([`SniffView::skipped`]) with the line of text that describes
//! them, keys ([`SniffView::key`]), and draws itself
//! ([`SniffView::render`]). Keys:
//!
//! | key | what it does |
//! |-----|--------------|
//! | `q`, Ctrl-C | quit |
//! | `p` | pause / resume the list (telegrams are still counted) |
//! | `a` | show only telegrams from or to an address (empty: all) |
//! | `s` | show only telegrams whose service or text contains a word, e.g. `Slave_Diag`, `token`, `SRD` (empty: all) |
//! | `e` | show only errors (skipped bytes, negative acknowledges, requests without an answer) |
//! | `c` | clear the filters |
//! | ↑ / ↓, PgUp / PgDn | scroll; ↓ at the end follows new telegrams again |
//!
//! The stations table shows each station's role, DP state and a health
//! bar from the analyser's statistics core
//! ([`profibus_dp::monitor::stats`], docs/analyser.md).

use crate::{fit, hex, Key};
use profibus_dp::monitor::stats::{Stats, StatsOptions};
use profibus_fdl::codec::CodecStats;
use profibus_fdl::wire::{FunctionCode, RequestKind, Telegram};
use profibus_fdl::Instant;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Borders, Paragraph, Row, Table};
use ratatui::Frame;
use std::collections::{BTreeMap, VecDeque};

/// One line of the list.
#[derive(Debug, Clone)]
struct Entry {
    at_us: u64,
    /// Source and destination address (none for a short acknowledge or
    /// skipped bytes).
    sa: Option<u8>,
    da: Option<u8>,
    service: String,
    text: String,
    error: bool,
}

/// Counters of one station.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StationStats {
    /// Requests it sent (as a master).
    pub requests: u64,
    /// Responses it sent.
    pub responses: u64,
    /// Tokens it passed.
    pub tokens: u64,
    /// Requests addressed to it that got no answer before the next
    /// request or token on the line.
    pub no_answer: u64,
    /// Negative acknowledges it sent (UE, RR, RS, RDL, RDH).
    pub negative: u64,
}

impl StationStats {
    /// Whether the station sent anything or a request to it went
    /// unanswered (FDL Status requests of the GAP polling do not count).
    pub fn on_the_line(&self) -> bool {
        self.requests + self.responses + self.tokens + self.no_answer > 0
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Prompt {
    Address,
    Service,
}

/// The sniffer's view.
pub struct SniffView {
    title: String,
    entries: VecDeque<Entry>,
    stations: BTreeMap<u8, StationStats>,
    /// Role, DP state and health per station.
    analysis: Stats,
    telegrams: u64,
    errors: u64,
    /// A request waiting for its answer: (master, slave).
    awaiting: Option<(u8, u8)>,
    address: Option<u8>,
    service: Option<String>,
    errors_only: bool,
    paused: bool,
    /// Lines scrolled back from the end; 0 follows new telegrams.
    back: usize,
    prompt: Option<(Prompt, String)>,
    message: Option<String>,
}

/// Entries kept for scrolling back.
const KEEP: usize = 20_000;

impl SniffView {
    /// An empty view titled `title` (e.g. `dpctl sniff /dev/ttyUSB0`).
    pub fn new(title: impl Into<String>) -> SniffView {
        SniffView {
            title: title.into(),
            entries: VecDeque::new(),
            stations: BTreeMap::new(),
            analysis: Stats::new(StatsOptions::default()),
            telegrams: 0,
            errors: 0,
            awaiting: None,
            address: None,
            service: None,
            errors_only: false,
            paused: false,
            back: 0,
            prompt: None,
            message: None,
        }
    }

    /// The counters of the station at `address`.
    pub fn station(&self, address: u8) -> Option<StationStats> {
        self.stations.get(&address).copied()
    }

    /// The statistics core the stations table shows role, DP state and
    /// health from.
    pub fn analysis(&self) -> &Stats {
        &self.analysis
    }

    /// Whether the list is paused.
    pub fn paused(&self) -> bool {
        self.paused
    }

    /// A telegram of an FMS connection (`profibus_dp::pdu::decode::Layer::Fms`)
    /// seen at `at`: counted like [`SniffView::telegram`], listed with
    /// the service `FMS` (a response `FMS` and its status) instead of
    /// the SAP's DP name, and `text` (the LLI/FMS PDUs in words first,
    /// so a narrow column still shows them).
    pub fn fms_telegram(&mut self, at: Instant, bytes: &[u8], text: impl Into<String>) {
        self.telegram(at, bytes, text);
        let service = match Telegram::parse(bytes) {
            Ok((Telegram::Data(d), _)) => match d.fc {
                FunctionCode::Response { status, .. } => format!("FMS {}", status.mnemonic()),
                FunctionCode::Request { .. } => "FMS".into(),
            },
            Ok((Telegram::ShortAck, _)) => "FMS short ack".into(),
            _ => return,
        };
        if let Some(e) = self.entries.back_mut() {
            e.service = service;
        }
    }

    /// A telegram seen at `at`; `text` describes it (as `dpctl decode`
    /// does). Bytes that do not parse are taken as skipped.
    pub fn telegram(&mut self, at: Instant, bytes: &[u8], text: impl Into<String>) {
        let text = text.into();
        let Ok((t, _)) = Telegram::parse(bytes) else {
            self.skipped(at, text);
            return;
        };
        self.telegrams += 1;
        self.analysis.observe(at, &t, bytes.len());
        let (sa, da, service, error) = match &t {
            Telegram::ShortAck => {
                self.awaiting = None;
                (None, None, "short ack".to_string(), false)
            }
            Telegram::Token { da, sa } => {
                self.no_answer();
                self.stations.entry(*sa).or_default().tokens += 1;
                (Some(*sa), Some(*da), "token".to_string(), false)
            }
            Telegram::Data(d) => match d.fc {
                FunctionCode::Request { kind, .. } => {
                    self.no_answer();
                    self.stations.entry(d.sa).or_default().requests += 1;
                    // FDL Status requests to absent stations (GAP
                    // polling) go unanswered by design.
                    if !d.is_broadcast() && kind.expects_reply() && kind != RequestKind::FdlStatus {
                        self.awaiting = Some((d.sa, d.da));
                    }
                    let sap = d.dsap.and_then(|s| profibus_dp::pdu::sap::name(s & 0x3F));
                    let service = match (sap, d.dsap) {
                        (Some(n), _) => n.to_string(),
                        (None, None) if !d.data.is_empty() => "Data_Exchange".into(),
                        _ => kind.mnemonic().to_string(),
                    };
                    (Some(d.sa), Some(d.da), service, false)
                }
                FunctionCode::Response { status, .. } => {
                    self.awaiting = None;
                    let s = self.stations.entry(d.sa).or_default();
                    s.responses += 1;
                    if status.is_negative() {
                        s.negative += 1;
                    }
                    let sap = d.ssap.and_then(|s| profibus_dp::pdu::sap::name(s & 0x3F));
                    let service = match sap {
                        Some(n) => format!("{n} {}", status.mnemonic()),
                        None => status.mnemonic().to_string(),
                    };
                    (Some(d.sa), Some(d.da), service, status.is_negative())
                }
            },
        };
        self.push(Entry {
            at_us: at.as_nanos() / 1000,
            sa,
            da,
            service,
            text,
            error,
        });
    }

    /// A request before went unanswered: count it for its slave.
    fn no_answer(&mut self) {
        if let Some((_, da)) = self.awaiting.take() {
            self.stations.entry(da).or_default().no_answer += 1;
            self.errors += 1;
            if let Some(e) = self.entries.back_mut() {
                e.error = true;
                e.text.push_str("  [no answer]");
            }
        }
    }

    /// Bytes the framer skipped at `at`, described by `text`.
    pub fn skipped(&mut self, at: Instant, text: impl Into<String>) {
        self.errors += 1;
        self.analysis.observe_skipped(at, 0, &CodecStats::default());
        self.push(Entry {
            at_us: at.as_nanos() / 1000,
            sa: None,
            da: None,
            service: "error".into(),
            text: text.into(),
            error: true,
        });
    }

    fn push(&mut self, e: Entry) {
        if e.error && e.service != "error" {
            self.errors += 1;
        }
        self.entries.push_back(e);
        if self.entries.len() > KEEP {
            self.entries.pop_front();
        }
    }

    fn shown(&self, e: &Entry) -> bool {
        if self.errors_only && !e.error {
            return false;
        }
        if let Some(a) = self.address {
            if e.sa != Some(a) && e.da != Some(a) {
                return false;
            }
        }
        if let Some(s) = &self.service {
            let s = s.to_lowercase();
            if !e.service.to_lowercase().contains(&s) && !e.text.to_lowercase().contains(&s) {
                return false;
            }
        }
        true
    }

    /// Handle a key; `true`: quit.
    pub fn key(&mut self, key: Key) -> bool {
        if key == Key::Interrupt {
            return true;
        }
        if let Some((kind, text)) = &mut self.prompt {
            match key {
                Key::Char(c) => text.push(c),
                Key::Backspace => {
                    text.pop();
                }
                Key::Esc => self.prompt = None,
                Key::Enter => {
                    let (kind, text) = (*kind, text.trim().to_string());
                    self.prompt = None;
                    self.set_filter(kind, &text);
                }
                _ => {}
            }
            return false;
        }
        match key {
            Key::Char('q') => return true,
            Key::Char('p') => self.paused = !self.paused,
            Key::Char('a') => self.prompt = Some((Prompt::Address, String::new())),
            Key::Char('s') => self.prompt = Some((Prompt::Service, String::new())),
            Key::Char('e') => self.errors_only = !self.errors_only,
            Key::Char('c') => {
                self.address = None;
                self.service = None;
                self.errors_only = false;
                self.message = None;
            }
            Key::Up => self.back += 1,
            Key::PageUp => self.back += 20,
            Key::Down => self.back = self.back.saturating_sub(1),
            Key::PageDown => self.back = self.back.saturating_sub(20),
            _ => {}
        }
        false
    }

    fn set_filter(&mut self, kind: Prompt, text: &str) {
        self.message = None;
        match kind {
            Prompt::Address if text.is_empty() => self.address = None,
            Prompt::Address => match text.parse::<u8>() {
                Ok(a) if a <= 127 => self.address = Some(a),
                _ => self.message = Some(format!("not a station address (0-127): {text}")),
            },
            Prompt::Service if text.is_empty() => self.service = None,
            Prompt::Service => self.service = Some(text.to_string()),
        }
        self.back = 0;
    }

    /// Draw the view into `area` of a frame.
    pub fn render(&self, f: &mut Frame<'_>, area: Rect) {
        let [head, body, foot] = Layout::vertical([
            Constraint::Length(1),
            Constraint::Min(3),
            Constraint::Length(1),
        ])
        .areas(area);
        let [list, stats] =
            Layout::horizontal([Constraint::Min(40), Constraint::Length(80)]).areas(body);
        let mut spans = vec![
            Span::styled(
                self.title.clone(),
                Style::default().add_modifier(Modifier::BOLD),
            ),
            Span::raw(format!(
                "  telegrams {}  errors {}",
                self.telegrams, self.errors
            )),
        ];
        let mut filters = vec![];
        if let Some(a) = self.address {
            filters.push(format!("address {a}"));
        }
        if let Some(s) = &self.service {
            filters.push(format!("service \"{s}\""));
        }
        if self.errors_only {
            filters.push("errors only".into());
        }
        if !filters.is_empty() {
            spans.push(Span::raw(format!("  filter: {}", filters.join(", "))));
        }
        if self.paused {
            spans.push(Span::styled(
                "  PAUSED",
                Style::default().add_modifier(Modifier::REVERSED),
            ));
        }
        f.render_widget(Paragraph::new(Line::from(spans)), head);

        // The list: the last lines that pass the filters.
        let height = list.height.saturating_sub(2) as usize;
        let width = list.width.saturating_sub(2) as usize;
        let shown: Vec<&Entry> = self.entries.iter().filter(|e| self.shown(e)).collect();
        let back = self.back.min(shown.len().saturating_sub(height));
        let end = shown.len() - back;
        let lines: Vec<Line> = shown[end.saturating_sub(height)..end]
            .iter()
            .map(|e| {
                let l = fit(
                    &format!("{:>12} {:<18} {}", e.at_us, e.service, e.text),
                    width,
                );
                if e.error {
                    Line::styled(l, Style::default().fg(Color::Red))
                } else {
                    Line::raw(l)
                }
            })
            .collect();
        let title = if back > 0 {
            format!(" telegrams ({back} lines back) ")
        } else {
            " telegrams ".to_string()
        };
        f.render_widget(
            Paragraph::new(lines).block(Block::default().borders(Borders::ALL).title(title)),
            list,
        );

        let live: BTreeMap<u8, _> = (self.analysis.live().into_iter())
            .map(|l| (l.address, l))
            .collect();
        let rows = self
            .stations
            .iter()
            .filter(|(_, s)| s.on_the_line())
            .map(|(a, s)| {
                let mut cells = vec![ratatui::widgets::Cell::from(format!("{a:>3}"))];
                cells.extend(crate::health::cells(live.get(a)));
                cells.extend([
                    ratatui::widgets::Cell::from(format!("{:>6}", s.requests)),
                    ratatui::widgets::Cell::from(format!("{:>6}", s.responses)),
                    ratatui::widgets::Cell::from(format!("{:>5}", s.tokens)),
                    ratatui::widgets::Cell::from(format!("{:>5}", s.no_answer)),
                    ratatui::widgets::Cell::from(format!("{:>3}", s.negative)),
                ]);
                Row::new(cells)
            });
        let [role_w, state_w, health_w] = crate::health::WIDTHS;
        let table = Table::new(
            rows,
            [
                Constraint::Length(4),
                Constraint::Length(role_w),
                Constraint::Length(state_w),
                Constraint::Length(health_w),
                Constraint::Length(7),
                Constraint::Length(7),
                Constraint::Length(6),
                Constraint::Length(6),
                Constraint::Length(4),
            ],
        )
        .header(
            Row::new(
                ["Addr"]
                    .into_iter()
                    .chain(crate::health::COLUMNS)
                    .chain(["Req", "Resp", "Token", "NoAns", "Neg"]),
            )
            .style(Style::default().add_modifier(Modifier::BOLD)),
        )
        .block(Block::default().borders(Borders::ALL).title(" stations "));
        f.render_widget(table, stats);

        let footer = match &self.prompt {
            Some((kind, text)) => Line::from(vec![
                Span::styled(
                    match kind {
                        Prompt::Address => "show address (empty: all, Esc cancels): ",
                        Prompt::Service => {
                            "show service (e.g. Slave_Diag, token, SRD; empty: all): "
                        }
                    },
                    Style::default().add_modifier(Modifier::BOLD),
                ),
                Span::raw(format!("{text}_")),
            ]),
            None => Line::raw(self.message.clone().unwrap_or_else(|| {
                "q quit  p pause  a address  s service  e errors only  c clear filters  ↑/↓ scroll"
                    .to_string()
            })),
        };
        f.render_widget(Paragraph::new(footer), foot);
    }
}

/// Skipped bytes in words for the list, e.g. `bad FCS: 3 bytes skipped: 68 01 02`.
pub fn skipped_text(what: &str, bytes: &[u8]) -> String {
    format!("!! {what}: {} bytes skipped: {}", bytes.len(), hex(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::screen_text;
    use profibus_fdl::wire::{DataTelegram, ResponseStatus, StationType};
    use ratatui::backend::TestBackend;
    use ratatui::Terminal;
    use std::time::Duration;

    fn emit(t: Telegram<'_>) -> Vec<u8> {
        let mut buf = [0u8; 300];
        let n = t.emit(&mut buf).unwrap();
        buf[..n].to_vec()
    }

    fn request(sa: u8, da: u8, dsap: Option<u8>) -> Vec<u8> {
        emit(Telegram::Data(DataTelegram {
            da,
            sa,
            fc: FunctionCode::Request {
                kind: RequestKind::SrdHigh,
                fcb: false,
                fcv: false,
            },
            dsap,
            ssap: dsap.map(|_| 62),
            data: &[],
            format: None,
        }))
    }

    fn response(sa: u8, da: u8, status: ResponseStatus) -> Vec<u8> {
        emit(Telegram::Data(DataTelegram {
            da,
            sa,
            fc: FunctionCode::Response {
                status,
                station: StationType::Passive,
            },
            dsap: None,
            ssap: None,
            data: &[1, 2],
            format: None,
        }))
    }

    fn screen(v: &SniffView) -> String {
        let mut t = Terminal::new(TestBackend::new(160, 20)).unwrap();
        t.draw(|f| v.render(f, f.area())).unwrap();
        screen_text(t.backend().buffer())
    }

    fn feed(v: &mut SniffView) {
        let mut at = Instant::ZERO;
        let mut tick = |v: &mut SniffView, bytes: Vec<u8>, text: &str| {
            at += Duration::from_micros(100);
            v.telegram(at, &bytes, text);
        };
        tick(
            v,
            request(2, 8, Some(60)),
            "SD2 2→8 SRD_HIGH DSAP=60 (Slave_Diag)",
        );
        tick(
            v,
            response(8, 2, ResponseStatus::Dl),
            "SD2 8→2 DL diag answer",
        );
        tick(v, request(2, 9, None), "SD1 2→9 SRD_HIGH");
        // 9 does not answer: the next request counts against it.
        tick(v, request(2, 8, None), "SD1 2→8 SRD_HIGH poll");
        tick(v, response(8, 2, ResponseStatus::Rs), "SD2 8→2 RS refused");
        tick(v, emit(Telegram::Token { da: 2, sa: 2 }), "SD4 token 2→2");
        v.skipped(at, skipped_text("bad FCS", &[0x68, 0x01]));
    }

    #[test]
    fn fms_telegrams_are_listed_as_fms_with_their_meaning_first() {
        let mut v = SniffView::new("dpctl sniff");
        let at = Instant::ZERO + Duration::from_micros(100);
        v.fms_telegram(
            at,
            &request(3, 5, Some(40)),
            "FMS Read.req invoke 1 index 2020 | SD2 3→5 SRD_HIGH DSAP=40 (FMS)",
        );
        v.fms_telegram(
            at,
            &response(5, 3, ResponseStatus::Dl),
            "FMS Read.resp invoke 1 data 01 02 | SD2 5→3 DL",
        );
        let s = screen(&v);
        let req = s.lines().find(|l| l.contains("Read.req")).expect(&s);
        assert!(req.contains(" FMS ") && !req.contains("MSAC_C2 "), "{req}");
        let res = s.lines().find(|l| l.contains("Read.resp")).expect(&s);
        assert!(res.contains("FMS DL"), "{res}");
        assert_eq!(v.station(5).unwrap().responses, 1);
    }

    #[test]
    fn statistics_count_requests_answers_and_missing_answers() {
        let mut v = SniffView::new("dpctl sniff");
        feed(&mut v);
        let m = v.station(2).unwrap();
        assert_eq!((m.requests, m.tokens), (3, 1));
        let s8 = v.station(8).unwrap();
        assert_eq!((s8.responses, s8.negative, s8.no_answer), (2, 1, 0));
        assert_eq!(v.station(9).unwrap().no_answer, 1);
        let s = screen(&v);
        assert!(s.contains("telegrams 6  errors 3"), "{s}");
        assert!(s.contains("[no answer]"), "{s}");
        assert!(s.contains("!! bad FCS: 2 bytes skipped: 68 01"), "{s}");
        let row9 = s.lines().find(|l| l.contains("│  9 ")).expect(&s);
        assert!(row9.contains("      1"), "{row9}");
    }

    #[test]
    fn stations_show_role_dp_state_and_a_health_bar() {
        let mut v = SniffView::new("dpctl sniff");
        feed(&mut v);
        let s = screen(&v);
        assert!(
            s.contains("Role") && s.contains("DP state") && s.contains("Health"),
            "{s}"
        );
        // Slave 8 answered a diagnosis, then refused Data_Exchange (RS):
        // back to `diag`, healthy. 9 never answered its one request, and
        // the corrupt bytes came while master 2 held the token: both 0.
        let flat = s.split_whitespace().collect::<Vec<_>>().join(" ");
        assert!(flat.contains("│ 8 slave diag ██████████ 100 0 2"), "{s}");
        assert!(flat.contains("│ 2 master - ░░░░░░░░░░ 0 3 0"), "{s}");
        assert!(flat.contains("│ 9 - - ░░░░░░░░░░ 0 0 0"), "{s}");
    }

    #[test]
    fn any_terminal_size_draws_without_panicking() {
        let mut v = SniffView::new("dpctl sniff");
        feed(&mut v);
        for (w, h) in [(1, 1), (10, 5), (40, 10), (80, 24), (300, 80)] {
            let mut t = Terminal::new(TestBackend::new(w, h)).unwrap();
            t.draw(|f| v.render(f, f.area())).unwrap();
        }
        for _ in 0..100 {
            v.key(Key::PageUp);
        }
        // Four lines of list for seven entries: scrolled back to the first.
        let mut t = Terminal::new(TestBackend::new(140, 8)).unwrap();
        t.draw(|f| v.render(f, f.area())).unwrap();
        let s = screen_text(t.backend().buffer());
        assert!(
            s.contains("(3 lines back)") && s.contains("Slave_Diag"),
            "{s}"
        );
        assert!(!s.contains("bad FCS"), "{s}");
    }

    #[test]
    fn filters_by_address_service_and_errors() {
        let mut v = SniffView::new("dpctl sniff");
        feed(&mut v);
        for k in [Key::Char('a'), Key::Char('9'), Key::Enter] {
            assert!(!v.key(k));
        }
        let s = screen(&v);
        assert!(s.contains("filter: address 9"), "{s}");
        assert!(s.contains("2→9") && !s.contains("8→2"), "{s}");

        v.key(Key::Char('c'));
        for k in "sslave_diag".chars() {
            v.key(Key::Char(k));
        }
        v.key(Key::Enter);
        let s = screen(&v);
        assert!(s.contains("Slave_Diag") && !s.contains("poll"), "{s}");

        v.key(Key::Char('c'));
        v.key(Key::Char('e'));
        let s = screen(&v);
        assert!(s.contains("errors only"), "{s}");
        assert!(s.contains("RS refused") && s.contains("bad FCS") && !s.contains("token 2→2"));

        v.key(Key::Char('c'));
        for k in [Key::Char('a'), Key::Char('x'), Key::Enter] {
            v.key(k);
        }
        assert!(screen(&v).contains("not a station address"));
        assert!(v.key(Key::Char('q')));
    }
}
