//! The slaves of a DP bus as a refreshing table.
//!
//! [`BusView`] takes snapshots of a [`BusSource`] (a DP master, or a
//! passive monitor of another master's bus) with [`BusView::update`] or
//! [`BusView::show`], lines for its log ([`BusView::log`]) and keys
//! ([`BusView::key`]), and draws itself ([`BusView::render`]). A
//! monitor's view also shows the masters in the token ring and the line's
//! counters, and is [`BusView::listen_only`]: no writes. Keys:
//!
//! | key | what it does |
//! |-----|--------------|
//! | `q`, Ctrl-C | quit ([`Action::Quit`]) |
//! | `p` | pause / resume the view (the bus keeps running) |
//! | ↑ / ↓ | select a slave |
//! | Enter | details of the selected slave (Esc or Enter closes them) |
//! | `w` | write the selected slave's outputs: the whole image in hex (`01 FF …`), or `NAME=VALUE ...` for named channels, checked as the MQTT gateway checks them ([`OutputWrite`]) ([`Action::Write`]; not in a listen-only view) |

use crate::source::{BusSnapshot, BusSource, Counters, Diagnosis};
use crate::{fit, hex, Key};
use profibus_devices::channels::{ChannelMap, Direction, OutputWriteError, Value};
use profibus_dp::config::gsd::Gsd;
use profibus_dp::config::layout::ModuleLayout;
use profibus_dp::master::{OperatingState, SlaveState};
use profibus_dp::monitor::stats::LiveStation;
use profibus_dp::monitor::{BusCounters, MasterStatus};
use profibus_dp::pdu::diag;
use profibus_fdl::{Baud, Instant};
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span, Text};
use ratatui::widgets::{Block, Borders, Cell, Clear, Paragraph, Row, Table, TableState};
use ratatui::Frame;
use std::collections::VecDeque;
use std::time::Duration;

/// How the view decodes a slave's process images.
#[derive(Debug, Clone, Default)]
pub enum Decoding {
    /// Hex only.
    #[default]
    None,
    /// The named, typed channels of a device profile.
    Channels(ChannelMap),
    /// The GSD modules the master configured, in slot order: each
    /// module's part of the images.
    Modules(Vec<ModuleLayout>),
}

impl Decoding {
    /// The modules `names` of `gsd` with their input and output sizes;
    /// [`Decoding::None`] when a name is not in the GSD.
    pub fn modules<S: AsRef<str>>(gsd: &Gsd, names: &[S]) -> Decoding {
        ModuleLayout::all_of_gsd(gsd, names).map_or(Decoding::None, Decoding::Modules)
    }

    /// One image decoded, one entry per channel or module: `name=value`
    /// (with the unit of a scaled channel) or `module: hex`.
    pub fn words(&self, dir: Direction, image: &[u8]) -> Vec<String> {
        match self {
            Decoding::None => vec![],
            Decoding::Channels(map) => map
                .decode(dir, image)
                .map(|(c, v)| match &c.scale {
                    Some(s) => format!("{}={v} {}", c.name, s.unit),
                    None => format!("{}={v}", c.name),
                })
                .collect(),
            Decoding::Modules(modules) => modules
                .iter()
                .filter_map(|m| {
                    let span = match dir {
                        Direction::Input => m.inputs,
                        Direction::Output => m.outputs,
                    };
                    (span.len > 0).then(|| format!("{}: {}", m.name, hex(span.of(image))))
                })
                .collect(),
        }
    }
}

/// What the view knows of a slave besides what the master tells.
#[derive(Debug, Clone)]
pub struct SlaveSpec {
    /// Station address.
    pub address: u8,
    /// Name shown.
    pub name: String,
    /// The GSD: diagnosis texts and the ident number.
    pub gsd: Option<Gsd>,
    /// How its images are decoded.
    pub decoding: Decoding,
}

/// A write the person asked for with `w`: the whole image or named
/// channels, checked by the rule every interface shares (the MQTT
/// gateway's too, [`OutputWrite::apply`]).
pub use profibus_devices::channels::OutputWrite;

/// What the application should do after a key.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Nothing.
    None,
    /// Stop.
    Quit,
    /// Write outputs of the slave at `address`; carry it out with
    /// [`BusView::write`].
    Write {
        /// Station address.
        address: u8,
        /// What to write.
        write: OutputWrite,
    },
}

/// Why a write was refused.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// Not hex bytes nor `NAME=VALUE` words.
    #[error("give the whole image in hex (01 FF …) or NAME=VALUE words: {0}")]
    Syntax(String),
    /// The write breaks the rule of output writes (a short image, an
    /// unknown channel, a value that does not fit).
    #[error(transparent)]
    Refused(#[from] OutputWriteError),
    /// Not a slave of the master, or a view that only listens.
    #[error("slave {0}: no outputs to write here")]
    UnknownSlave(u8),
}

/// A slave as last seen.
#[derive(Debug, Clone)]
struct Snapshot {
    state: Option<SlaveState>,
    master: Option<u8>,
    inputs: Vec<u8>,
    outputs: Vec<u8>,
    stats: Counters,
    diag: Vec<u8>,
    /// Diagnosis in words (kept while `diag` stays the same).
    diag_words: Vec<String>,
    /// FMS connections in words (a monitor's).
    fms: Vec<String>,
    /// Time between two Data_Exchange cycles of this slave.
    cycle: Option<Duration>,
    /// Where the cycle time is measured from: (time, data exchanges).
    mark: Option<(Instant, u64)>,
}

impl Snapshot {
    fn new() -> Snapshot {
        Snapshot {
            state: None,
            master: None,
            inputs: vec![],
            outputs: vec![],
            stats: Counters::default(),
            diag: vec![],
            diag_words: vec![],
            fms: vec![],
            cycle: None,
            mark: None,
        }
    }
}

/// What the header shows of the master(s) and the line.
#[derive(Debug, Clone, Default)]
struct MasterLine {
    address: Option<u8>,
    operating: Option<OperatingState>,
    cycles: u64,
    min_us: u64,
    avg_us: u64,
    max_us: u64,
    bus_time: Duration,
    ring: Option<Vec<MasterStatus>>,
    line: Option<BusCounters>,
    /// The analyser's live list (role, DP state, health), when
    /// statistics run beside the source.
    live: Option<Vec<LiveStation>>,
}

impl MasterLine {
    /// The station at `address` in the live list (`None` also without
    /// a live list).
    fn live(&self, address: u8) -> Option<&LiveStation> {
        self.live.as_ref()?.iter().find(|l| l.address == address)
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Mode {
    Table,
    Details { scroll: u16 },
    Prompt(String),
}

/// The headings of the table's columns, left to right.
pub const COLUMNS: [&str; 8] = [
    "Addr",
    "Name",
    "State",
    "Cycle",
    "Retry/Err",
    "Inputs",
    "Outputs",
    "Diagnosis",
];

/// The bus view: state of the table, the log and the prompts.
pub struct BusView {
    title: String,
    baud: Option<Baud>,
    specs: Vec<SlaveSpec>,
    rows: Vec<Snapshot>,
    master: MasterLine,
    log: VecDeque<String>,
    held: Vec<String>,
    paused: bool,
    selected: usize,
    mode: Mode,
    message: Option<String>,
    /// Slaves whose outputs the person wrote.
    by_hand: Vec<u8>,
    /// No writes (a passive monitor's view).
    listen_only: bool,
}

/// Lines kept in the log.
const LOG_LINES: usize = 200;

/// How long the cycle time is measured over.
const CYCLE_WINDOW: Duration = Duration::from_millis(500);

/// Most lines of one slave in the table (the details show everything).
const MAX_ROW_LINES: usize = 5;

/// After this long without a Data_Exchange a slave has no cycle time.
const CYCLE_STALE: Duration = Duration::from_secs(3);

impl BusView {
    /// A view titled `title` (e.g. `dpctl master`) of the slaves `specs`,
    /// in that order, on a line at `baud`.
    pub fn new(title: impl Into<String>, baud: Option<Baud>, specs: Vec<SlaveSpec>) -> BusView {
        let rows = specs.iter().map(|_| Snapshot::new()).collect();
        BusView {
            title: title.into(),
            baud,
            specs,
            rows,
            master: MasterLine::default(),
            log: VecDeque::new(),
            held: vec![],
            paused: false,
            selected: 0,
            mode: Mode::Table,
            message: None,
            by_hand: vec![],
            listen_only: false,
        }
    }

    /// The same view without writes (`w`): for a source that never
    /// sends, such as a passive monitor.
    pub fn listen_only(mut self) -> BusView {
        self.listen_only = true;
        self
    }

    /// Whether the person wrote the outputs of the slave at `address`
    /// (`w`): an application that writes outputs itself leaves them.
    pub fn written_by_hand(&self, address: u8) -> bool {
        self.by_hand.contains(&address)
    }

    /// Whether the view is paused (`p`).
    pub fn paused(&self) -> bool {
        self.paused
    }

    /// The station address of the selected slave.
    pub fn selected(&self) -> Option<u8> {
        self.specs.get(self.selected).map(|s| s.address)
    }

    /// Take a snapshot of `source` at `now` (bus time), unless the view
    /// is paused.
    pub fn update<S: BusSource + ?Sized>(&mut self, source: &S, now: Instant) {
        if !self.paused {
            self.show(&source.snapshot(now));
        }
    }

    /// Show `snap`, unless the view is paused. Slaves of the snapshot the
    /// view does not know yet (heard by a monitor, not in the bus file)
    /// get a row at the end.
    pub fn show(&mut self, snap: &BusSnapshot) {
        if self.paused {
            return;
        }
        let now = Instant::ZERO + snap.bus_time;
        self.master = MasterLine {
            address: snap.station,
            operating: snap.operating,
            cycles: snap.cycles,
            min_us: snap.cycle_us[0],
            avg_us: snap.cycle_us[1],
            max_us: snap.cycle_us[2],
            bus_time: snap.bus_time,
            ring: snap.ring.clone(),
            line: snap.line,
            live: snap.live.clone(),
        };
        for s in &snap.slaves {
            let i = match self.specs.iter().position(|x| x.address == s.address) {
                Some(i) => i,
                None => {
                    self.specs.push(SlaveSpec {
                        address: s.address,
                        name: String::new(),
                        gsd: None,
                        decoding: Decoding::None,
                    });
                    self.rows.push(Snapshot::new());
                    self.specs.len() - 1
                }
            };
            let (spec, row) = (&self.specs[i], &mut self.rows[i]);
            row.state = s.state;
            row.master = s.master;
            row.stats = s.counters;
            row.inputs.clone_from(&s.inputs);
            row.outputs.clone_from(&s.outputs);
            row.fms.clone_from(&s.fms);
            match &s.diag {
                Diagnosis::Raw { bytes, dpv1 } if *bytes != row.diag => {
                    row.diag.clone_from(bytes);
                    row.diag_words = if bytes.is_empty() {
                        vec![]
                    } else {
                        diag::describe(bytes, spec.gsd.as_ref(), *dpv1)
                    };
                }
                Diagnosis::Raw { .. } => {}
                Diagnosis::Words(w) => row.diag_words.clone_from(w),
            }
            let n = s.counters.data_exchanges;
            match row.mark {
                Some((t, k)) if n > k && now - t >= CYCLE_WINDOW => {
                    row.cycle = Some((now - t) / (n - k) as u32);
                    row.mark = Some((now, n));
                }
                Some((t, k)) if n == k && now - t >= CYCLE_STALE => row.cycle = None,
                Some((_, k)) if n < k => row.mark = Some((now, n)),
                Some(_) => {}
                None => row.mark = Some((now, n)),
            }
        }
    }

    /// Add a line to the log (held back while the view is paused).
    pub fn log(&mut self, line: impl Into<String>) {
        let line = line.into();
        if self.paused {
            self.held.push(line);
        } else {
            self.push_log(line);
        }
    }

    fn push_log(&mut self, line: String) {
        self.log.push_back(line);
        while self.log.len() > LOG_LINES {
            self.log.pop_front();
        }
    }

    /// Handle a key.
    pub fn key(&mut self, key: Key) -> Action {
        if key == Key::Interrupt {
            return Action::Quit;
        }
        match &mut self.mode {
            Mode::Prompt(text) => match key {
                Key::Char(c) => text.push(c),
                Key::Backspace => {
                    text.pop();
                }
                Key::Esc => self.mode = Mode::Table,
                Key::Enter => {
                    let text = std::mem::take(text);
                    self.mode = Mode::Table;
                    return self.parse_write(&text);
                }
                _ => {}
            },
            Mode::Details { scroll } => match key {
                Key::Esc | Key::Enter => self.mode = Mode::Table,
                Key::Char('q') => return Action::Quit,
                Key::Char('p') => self.toggle_pause(),
                Key::Up | Key::PageUp => *scroll = scroll.saturating_sub(1),
                Key::Down | Key::PageDown => *scroll = scroll.saturating_add(1),
                _ => {}
            },
            Mode::Table => match key {
                Key::Char('q') => return Action::Quit,
                Key::Char('p') => self.toggle_pause(),
                Key::Up => self.selected = self.selected.saturating_sub(1),
                Key::Down => {
                    self.selected = (self.selected + 1).min(self.specs.len().saturating_sub(1))
                }
                Key::PageUp => self.selected = 0,
                Key::PageDown => self.selected = self.specs.len().saturating_sub(1),
                Key::Enter if !self.specs.is_empty() => self.mode = Mode::Details { scroll: 0 },
                Key::Char('w') if !self.specs.is_empty() && !self.listen_only => {
                    self.message = None;
                    self.mode = Mode::Prompt(String::new());
                }
                Key::Esc => self.message = None,
                _ => {}
            },
        }
        Action::None
    }

    fn toggle_pause(&mut self) {
        self.paused = !self.paused;
        if !self.paused {
            for l in std::mem::take(&mut self.held) {
                self.push_log(l);
            }
        }
    }

    /// The prompt's text as a write to the selected slave.
    fn parse_write(&mut self, text: &str) -> Action {
        let Some(spec) = self.specs.get(self.selected) else {
            return Action::None;
        };
        let address = spec.address;
        let text = text.trim();
        if text.is_empty() {
            return Action::None;
        }
        let write = if text.contains('=') {
            let mut values = vec![];
            for word in text.split_whitespace() {
                let Some((name, v)) = word.split_once('=') else {
                    self.message = Some(WriteError::Syntax(word.into()).to_string());
                    return Action::None;
                };
                match parse_value(v) {
                    Some(v) => values.push((name.to_string(), v)),
                    None => {
                        self.message = Some(WriteError::Syntax(word.into()).to_string());
                        return Action::None;
                    }
                }
            }
            OutputWrite::Channels(values)
        } else {
            match profibus_fdl::wire::parse_hex(text) {
                Ok(b) => OutputWrite::Image(b),
                Err(e) => {
                    self.message = Some(WriteError::Syntax(e.to_string()).to_string());
                    return Action::None;
                }
            }
        };
        Action::Write { address, write }
    }

    /// Carry out a write on the source's output image (a master's); the
    /// view shows what was written or why not.
    pub fn write<S: BusSource + ?Sized>(
        &mut self,
        source: &mut S,
        address: u8,
        write: &OutputWrite,
    ) -> Result<(), WriteError> {
        let r = self.try_write(source, address, write);
        if r.is_ok() && !self.by_hand.contains(&address) {
            self.by_hand.push(address);
        }
        self.message = Some(match &r {
            Ok(()) => format!(
                "slave {address}: outputs {}",
                hex(source.outputs_mut(address).as_deref().unwrap_or(&[]))
            ),
            Err(e) => format!("not written: {e}"),
        });
        r
    }

    fn try_write<S: BusSource + ?Sized>(
        &self,
        source: &mut S,
        address: u8,
        write: &OutputWrite,
    ) -> Result<(), WriteError> {
        if self.listen_only {
            return Err(WriteError::UnknownSlave(address));
        }
        let out = source
            .outputs_mut(address)
            .ok_or(WriteError::UnknownSlave(address))?;
        let map = match self.specs.iter().find(|s| s.address == address) {
            Some(SlaveSpec {
                decoding: Decoding::Channels(map),
                ..
            }) => Some(map),
            _ => None,
        };
        // The person at the master's terminal may write every channel.
        let image = write.apply(address, out, map, None)?;
        out.copy_from_slice(&image);
        Ok(())
    }

    /// Draw the view into `area` of a frame.
    pub fn render(&self, f: &mut Frame<'_>, area: Rect) {
        let log_height = (self.log.len() as u16).clamp(3, 8) + 2;
        let head_lines = self.header_lines();
        let [head, table, log, foot] = Layout::vertical([
            Constraint::Length(head_lines.len() as u16),
            Constraint::Min(4),
            Constraint::Length(log_height),
            Constraint::Length(1),
        ])
        .areas(area);
        f.render_widget(Paragraph::new(head_lines), head);
        self.render_table(f, table);
        let lines: Vec<Line> = self
            .log
            .iter()
            .skip(self.log.len().saturating_sub(log_height as usize - 2))
            .map(|l| Line::raw(fit(l, log.width.saturating_sub(2) as usize)))
            .collect();
        f.render_widget(
            Paragraph::new(lines).block(Block::default().borders(Borders::ALL).title(" events ")),
            log,
        );
        f.render_widget(Paragraph::new(self.footer_line()), foot);
        if let Mode::Details { scroll } = self.mode {
            self.render_details(f, area, scroll);
        }
    }

    /// The header: the master (or the bus) and its cycle; for a monitor
    /// a second line with the token ring and the line's counters.
    fn header_lines(&self) -> Vec<Line<'static>> {
        let m = &self.master;
        let mut spans = vec![Span::styled(
            self.title.clone(),
            Style::default().add_modifier(Modifier::BOLD),
        )];
        spans.push(Span::raw(match m.address {
            Some(a) => format!("  master {a}"),
            None => "  listening".to_string(),
        }));
        if let Some(b) = self.baud {
            spans.push(Span::raw(format!(" at {b}")));
        }
        if let Some(o) = m.operating {
            spans.push(Span::raw(format!("  {}", o.as_str())));
        }
        spans.push(Span::raw(format!(
            "  cycles {}  cycle min/avg/max {}/{}/{} µs  t {:.1} s",
            m.cycles,
            m.min_us,
            m.avg_us,
            m.max_us,
            m.bus_time.as_secs_f64()
        )));
        if self.paused {
            spans.push(Span::styled(
                "  PAUSED",
                Style::default().add_modifier(Modifier::REVERSED),
            ));
        }
        let mut lines = vec![Line::from(spans)];
        if let Some(ring) = &m.ring {
            let mut spans = vec![Span::raw("token ring: ")];
            if ring.is_empty() {
                spans.push(Span::raw("no master heard"));
            } else {
                spans.push(Span::raw("masters "));
            }
            for (i, r) in ring.iter().enumerate() {
                let mut t = format!("{}{} (", if i > 0 { ", " } else { "" }, r.address);
                if let Some(o) = r.operating {
                    t.push_str(&format!("{}, ", o.as_str()));
                }
                t.push_str(&format!(
                    "rotation {})",
                    cycle_text(Some(Duration::from_micros(r.rotation_us.avg))).trim()
                ));
                spans.push(Span::raw(t));
                // The master's health, drawn as in the slaves' rows.
                if let Some(l) = m.live(r.address) {
                    spans.push(Span::raw(" "));
                    spans.push(Span::styled(
                        crate::health::health_bar(l.health),
                        crate::health::health_style(l.health),
                    ));
                }
            }
            if let Some(l) = m.line {
                spans.push(Span::raw(format!(
                    "  line: telegrams {}  corrupt {}  no reply {}",
                    l.telegrams, l.corrupt, l.no_reply
                )));
            }
            lines.push(Line::from(spans));
        }
        lines
    }

    fn footer_line(&self) -> Line<'static> {
        match &self.mode {
            Mode::Prompt(text) => {
                let (a, n) = self
                    .specs
                    .get(self.selected)
                    .map(|s| (s.address, s.name.as_str()))
                    .unwrap_or((0, ""));
                Line::from(vec![
                    Span::styled(
                        format!("write outputs of slave {a} {n} (the whole image in hex, or NAME=VALUE; Esc cancels): "),
                        Style::default().add_modifier(Modifier::BOLD),
                    ),
                    Span::raw(format!("{text}_")),
                ])
            }
            _ => match &self.message {
                Some(m) => Line::raw(m.clone()),
                None if self.listen_only => Line::raw(
                    "q quit  p pause  ↑/↓ select  Enter details  (listening only: no writes)",
                ),
                None => Line::raw("q quit  p pause  ↑/↓ select  Enter details  w write outputs"),
            },
        }
    }

    fn render_table(&self, f: &mut Frame<'_>, area: Rect) {
        let name_w = self
            .specs
            .iter()
            .map(|s| s.name.chars().count())
            .max()
            .unwrap_or(0)
            .clamp(4, 30) as u16;
        // With the analyser's live list, Role before and Health after
        // State ([`crate::health`]).
        let live = self.master.live.is_some();
        let [role_w, _, health_w] = crate::health::WIDTHS;
        // Addr, Name, State, Cycle, Retry/Err; 7 gaps between 8 columns
        // and the two borders.
        let mut fixed = 4 + name_w + 13 + 9 + 9 + 7 + 2;
        if live {
            fixed += role_w + health_w + 2;
        }
        let rest = area.width.saturating_sub(fixed).max(24);
        let io_w = rest * 3 / 8;
        let diag_w = rest - 2 * io_w;
        let [role_h, _, health_h] = crate::health::COLUMNS;
        let columns: Vec<&str> = if live {
            let mut c = COLUMNS.to_vec();
            c.insert(2, role_h);
            c.insert(4, health_h);
            c
        } else {
            COLUMNS.to_vec()
        };
        let header = Row::new(columns)
            .style(Style::default().add_modifier(Modifier::BOLD | Modifier::UNDERLINED));
        let rows = self.specs.iter().zip(&self.rows).map(|(spec, r)| {
            // Hex, then the decoded values, wrapped into the column.
            let io = |dir, image: &[u8]| {
                let bytes: Vec<String> = image.iter().map(|b| format!("{b:02X}")).collect();
                let mut lines: Vec<Line> = wrap(&bytes, " ", io_w as usize)
                    .into_iter()
                    .map(Line::raw)
                    .collect();
                let words = spec.decoding.words(dir, image);
                lines.extend(
                    wrap(&words, "  ", io_w as usize)
                        .into_iter()
                        .map(|l| Line::styled(l, Style::default().fg(Color::Cyan))),
                );
                lines
            };
            let state_style = match r.state {
                Some(SlaveState::DataExchange) => Style::default().fg(Color::Green),
                Some(SlaveState::Offline) => Style::default().fg(Color::Red),
                None => Style::default(),
                _ => Style::default().fg(Color::Yellow),
            };
            let (i, o) = (
                io(Direction::Input, &r.inputs),
                io(Direction::Output, &r.outputs),
            );
            // The diagnosis, then the FMS connections (`dpctl monitor`).
            let diag: Vec<String> = diag_summary(&r.diag_words);
            let mut diag = wrap(&diag, "; ", diag_w as usize);
            for c in &r.fms {
                diag.extend(wrap(
                    &c.split(' ').map(str::to_string).collect::<Vec<_>>(),
                    " ",
                    diag_w as usize,
                ));
            }
            let height = i.len().max(o.len()).max(diag.len()).clamp(1, MAX_ROW_LINES);
            let mut cells = vec![
                Cell::from(format!("{:>3}", spec.address)),
                Cell::from(fit(&spec.name, name_w as usize)),
                Cell::from(Span::styled(state_name(r.state), state_style)),
            ];
            if live {
                // The State column is the DP state already.
                let [role, _, health] = crate::health::cells(self.master.live(spec.address));
                cells.insert(2, role);
                cells.push(health);
            }
            cells.extend([
                Cell::from(cycle_text(r.cycle)),
                Cell::from(format!(
                    "{:>9}",
                    format!("{}/{}", r.stats.retries, r.stats.errors)
                )),
                Cell::from(Text::from(i)),
                Cell::from(Text::from(o)),
                Cell::from(Text::from(diag.join("\n"))),
            ]);
            Row::new(cells).height(height as u16)
        });
        let mut widths = vec![
            Constraint::Length(4),
            Constraint::Length(name_w),
            Constraint::Length(13),
            Constraint::Length(9),
            Constraint::Length(9),
            Constraint::Length(io_w),
            Constraint::Length(io_w),
            Constraint::Length(diag_w),
        ];
        if live {
            widths.insert(2, Constraint::Length(role_w));
            widths.insert(4, Constraint::Length(health_w));
        }
        let table = Table::new(rows, widths)
            .header(header)
            .row_highlight_style(Style::default().add_modifier(Modifier::REVERSED))
            .block(Block::default().borders(Borders::ALL).title(" slaves "));
        let mut state = TableState::default().with_selected(Some(self.selected));
        f.render_stateful_widget(table, area, &mut state);
    }

    /// The details of the selected slave, as lines.
    fn details(&self) -> Vec<String> {
        let (Some(spec), Some(r)) = (self.specs.get(self.selected), self.rows.get(self.selected))
        else {
            return vec![];
        };
        let mut out = vec![format!("slave {} {}", spec.address, spec.name)];
        let mut l = format!("state {}", state_name(r.state));
        if let Some(m) = r.master {
            l.push_str(&format!("  polled by master {m}"));
        }
        if let Some(live) = self.master.live(spec.address) {
            l.push_str(&format!(
                "  role {}  health {}",
                live.role.map_or("-", |r| r.name()),
                live.health
            ));
        }
        if let Some(g) = &spec.gsd {
            l.push_str(&format!(
                "  ident number 0x{:04X}  {} {}",
                g.ident_number,
                g.vendor_name.as_deref().unwrap_or(""),
                g.model_name.as_deref().unwrap_or("")
            ));
        }
        out.push(l);
        let s = &r.stats;
        let mut l = format!(
            "cycle {}  data exchanges {}  retries {}  errors {}  restarts {}",
            cycle_text(r.cycle).trim(),
            s.data_exchanges,
            s.retries,
            s.errors,
            s.restarts,
        );
        if let Some(n) = s.diag_reads {
            l.push_str(&format!("  diagnosis reads {n}"));
        }
        if let Some(n) = s.late_replies {
            l.push_str(&format!("  late replies {n}"));
        }
        out.push(l);
        if let Decoding::Modules(spans) = &spec.decoding {
            out.push(format!(
                "modules: {}",
                spans
                    .iter()
                    .map(|m| m.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        for (what, dir, image) in [
            ("inputs", Direction::Input, &r.inputs),
            ("outputs", Direction::Output, &r.outputs),
        ] {
            out.push(format!("{what} ({} bytes): {}", image.len(), hex(image)));
            for w in spec.decoding.words(dir, image) {
                out.push(format!("    {w}"));
            }
        }
        if r.diag.is_empty() && r.diag_words.is_empty() {
            out.push("diagnosis: none read yet".into());
        } else {
            out.push(format!("diagnosis: {}", hex(&r.diag)));
            for w in &r.diag_words {
                out.push(format!("    {w}"));
            }
        }
        out.extend(r.fms.iter().cloned());
        out
    }

    fn render_details(&self, f: &mut Frame<'_>, area: Rect, scroll: u16) {
        let popup = Rect {
            x: area.x + area.width / 20,
            y: area.y + area.height / 10,
            width: area.width - area.width / 10,
            height: area.height - area.height / 5,
        };
        let lines: Vec<Line> = self.details().into_iter().map(Line::raw).collect();
        f.render_widget(Clear, popup);
        f.render_widget(
            Paragraph::new(lines).scroll((scroll, 0)).block(
                Block::default()
                    .borders(Borders::ALL)
                    .title(" details (Esc closes, ↑/↓ scroll) "),
            ),
            popup,
        );
    }
}

/// A state for the table (`unseen`: no traffic heard yet).
fn state_name(s: Option<SlaveState>) -> &'static str {
    s.map_or("unseen", SlaveState::name)
}

/// A cycle time for the table.
fn cycle_text(c: Option<Duration>) -> String {
    match c {
        Some(d) if d >= Duration::from_secs(1) => format!("{:>7.2} s", d.as_secs_f64()),
        Some(d) => format!("{:>6.1} ms", d.as_secs_f64() * 1e3),
        None => format!("{:>9}", "—"),
    }
}

/// The diagnosis in a few words: the station status and the device's
/// own blocks, without the lines that are always there.
fn diag_summary(words: &[String]) -> Vec<String> {
    words
        .iter()
        .filter(|w| !w.starts_with("parameterised by") && !w.starts_with("ident number"))
        .map(|w| w.strip_prefix("station status: ").unwrap_or(w).to_string())
        .collect()
}

/// `words` joined by `sep` into lines of at most `width` characters,
/// breaking between words; a word longer than a line is cut.
fn wrap(words: &[String], sep: &str, width: usize) -> Vec<String> {
    let mut lines: Vec<String> = vec![];
    let mut line = String::new();
    for w in words {
        let w = fit(w, width.max(1));
        if !line.is_empty() && line.chars().count() + sep.len() + w.chars().count() > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push_str(sep);
        }
        line.push_str(&w);
    }
    if !line.is_empty() {
        lines.push(line);
    }
    lines
}

/// A channel value typed at the prompt: `true`/`false`, an integer
/// (also `0x…`), or a number.
fn parse_value(text: &str) -> Option<Value> {
    match text {
        "true" => return Some(Value::Bool(true)),
        "false" => return Some(Value::Bool(false)),
        _ => {}
    }
    if let Some(h) = text.strip_prefix("0x").or_else(|| text.strip_prefix("0X")) {
        return i64::from_str_radix(h, 16).ok().map(Value::Int);
    }
    if let Ok(i) = text.parse::<i64>() {
        return Some(Value::Int(i));
    }
    text.parse::<f64>()
        .ok()
        .filter(|x| x.is_finite())
        .map(Value::Float)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::screen_text;
    use profibus_devices::channels::ChannelType;
    use profibus_dp::config::layout::Span as ModuleSpan;
    use profibus_dp::master::{DpMaster, MasterConfig, MasterOptions, SlaveParams};
    use profibus_fdl::BusParams;
    use ratatui::backend::TestBackend;
    use ratatui::Terminal;

    fn master() -> DpMaster {
        let mut a = SlaveParams::new(8, 0x1234, vec![0x20]);
        a.name = "pump".into();
        let b = SlaveParams::new(25, 0x4711, vec![0x31]);
        DpMaster::new(&MasterConfig {
            address: 2,
            params: BusParams::defaults(Baud::B1500000),
            slaves: vec![a, b],
            options: MasterOptions::default(),
        })
        .unwrap()
    }

    fn view() -> BusView {
        let mut map = ChannelMap::new();
        map.push("speed", Direction::Output, 0, ChannelType::U16);
        map.push("actual", Direction::Input, 0, ChannelType::U16);
        BusView::new(
            "dpctl master",
            Some(Baud::B1500000),
            vec![
                SlaveSpec {
                    address: 8,
                    name: "pump".into(),
                    gsd: None,
                    decoding: Decoding::None,
                },
                SlaveSpec {
                    address: 25,
                    name: "drive".into(),
                    gsd: None,
                    decoding: Decoding::Channels(map),
                },
            ],
        )
    }

    fn screen(v: &BusView) -> String {
        let mut t = Terminal::new(TestBackend::new(160, 30)).unwrap();
        t.draw(|f| v.render(f, f.area())).unwrap();
        screen_text(t.backend().buffer())
    }

    #[test]
    fn the_table_shows_each_slave_with_state_and_decoded_outputs() {
        let mut m = master();
        let mut v = view();
        m.set_outputs(25, &[0x01, 0x02]);
        v.update(&m, Instant::ZERO);
        v.log("slave 8: offline → diag");
        let s = screen(&v);
        assert!(s.contains("dpctl master  master 2 at 1.5Mbit/s"), "{s}");
        // The headings up to Outputs.
        for h in &COLUMNS[..7] {
            assert!(s.contains(h), "{h} missing:\n{s}");
        }
        let row = s.lines().find(|l| l.contains("drive")).expect(&s);
        assert!(row.contains(" 25 ") && row.contains(" diag "), "{row}");
        assert!(row.contains("01 02"), "{row}");
        assert!(s.contains("speed=258"), "{s}");
        assert!(s.contains("slave 8: offline → diag"), "{s}");
        assert!(s.contains("q quit  p pause"), "{s}");
    }

    #[test]
    fn keys_select_open_details_and_pause() {
        let mut m = master();
        let mut v = view();
        v.update(&m, Instant::ZERO);
        assert_eq!(v.selected(), Some(8));
        assert_eq!(v.key(Key::Down), Action::None);
        assert_eq!(v.selected(), Some(25));
        v.key(Key::Down);
        assert_eq!(v.selected(), Some(25), "stays on the last slave");
        v.key(Key::Enter);
        let s = screen(&v);
        assert!(s.contains("details (Esc closes"), "{s}");
        assert!(s.contains("slave 25 drive"), "{s}");
        assert!(s.contains("outputs (2 bytes): 00 00"), "{s}");
        assert!(s.contains("speed=0"), "{s}");
        v.key(Key::Esc);
        assert!(!screen(&v).contains("details (Esc"));

        v.key(Key::Char('p'));
        assert!(v.paused());
        m.set_outputs(25, &[0xAB]);
        v.update(&m, Instant::ZERO);
        v.log("while paused");
        let s = screen(&v);
        assert!(s.contains("PAUSED") && !s.contains("AB") && !s.contains("while paused"));
        v.key(Key::Char('p'));
        v.update(&m, Instant::ZERO);
        let s = screen(&v);
        assert!(!s.contains("PAUSED") && s.contains("AB") && s.contains("while paused"));
        assert_eq!(v.key(Key::Char('q')), Action::Quit);
        assert_eq!(v.key(Key::Interrupt), Action::Quit);
    }

    #[test]
    fn the_prompt_writes_bytes_or_named_channels() {
        let mut m = master();
        let mut v = view();
        v.key(Key::Char('w'));
        for c in "7F".chars() {
            v.key(Key::Char(c));
        }
        assert!(screen(&v).contains("write outputs of slave 8 pump"));
        let a = v.key(Key::Enter);
        assert_eq!(
            a,
            Action::Write {
                address: 8,
                write: OutputWrite::Image(vec![0x7F])
            }
        );
        let Action::Write { address, write } = a else {
            unreachable!()
        };
        assert!(!v.written_by_hand(8));
        v.write(&mut m, address, &write).unwrap();
        assert_eq!(m.outputs(8), Some(&[0x7F][..]));
        assert!(v.written_by_hand(8) && !v.written_by_hand(25));
        assert!(screen(&v).contains("slave 8: outputs 7F"));

        // Too long: refused, nothing written.
        let e = v
            .write(&mut m, 8, &OutputWrite::Image(vec![1, 2]))
            .unwrap_err();
        assert!(matches!(
            e,
            WriteError::Refused(OutputWriteError::Length {
                expected: 1,
                given: 2,
                ..
            })
        ));
        assert_eq!(m.outputs(8), Some(&[0x7F][..]));
        // Too short for the drive's 2 bytes: the rest would be left to
        // chance, so it is refused too.
        let e = v
            .write(&mut m, 25, &OutputWrite::Image(vec![9]))
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "slave 25 has 2 output bytes, the write has 1: give the whole image or named channels"
        );
        assert!(screen(&v).contains("not written: slave 25 has 2 output bytes"));
        assert_eq!(m.outputs(25), Some(&[0, 0][..]));

        // Named channels on the drive.
        v.key(Key::Down);
        v.key(Key::Char('w'));
        for c in "speed=0x0102".chars() {
            v.key(Key::Char(c));
        }
        let Action::Write { address, write } = v.key(Key::Enter) else {
            panic!("no write")
        };
        assert_eq!(address, 25);
        v.write(&mut m, address, &write).unwrap();
        assert_eq!(m.outputs(25), Some(&[0x01, 0x02][..]));
        // An unknown name is refused with a message.
        let e = v
            .write(
                &mut m,
                25,
                &OutputWrite::Channels(vec![("nope".into(), Value::Int(1))]),
            )
            .unwrap_err();
        assert!(e.to_string().contains("nope"), "{e}");
        assert!(screen(&v).contains("not written"));
        // Garbage at the prompt is a message, not a write.
        v.key(Key::Char('w'));
        for c in "zz".chars() {
            v.key(Key::Char(c));
        }
        assert_eq!(v.key(Key::Enter), Action::None);
        assert!(screen(&v).contains("give the whole image in hex"));
    }

    #[test]
    fn a_monitor_view_shows_the_ring_and_unknown_slaves_and_never_writes() {
        use crate::source::{BusSnapshot, SlaveSnapshot};
        use profibus_dp::monitor::Interval;
        let mut v = view().listen_only();
        let mut rotation = Interval::default();
        rotation.avg = 2500;
        let slave = |address, state, diag: &[&str]| SlaveSnapshot {
            address,
            state,
            master: Some(2),
            inputs: vec![0x00, 0x7B],
            outputs: vec![0x01, 0x02],
            counters: Counters {
                retries: 3,
                errors: 2,
                ..Counters::default()
            },
            diag: Diagnosis::Words(diag.iter().map(|w| w.to_string()).collect()),
            fms: vec![],
        };
        let snap = BusSnapshot {
            station: None,
            operating: Some(OperatingState::Operate),
            cycles: 7,
            cycle_us: [900, 1000, 1100],
            bus_time: Duration::from_secs(2),
            ring: Some(vec![MasterStatus {
                address: 2,
                tokens: 40,
                rotation_us: rotation,
                operating: Some(OperatingState::Operate),
                in_ring: true,
            }]),
            line: Some(BusCounters {
                telegrams: 99,
                ..BusCounters::default()
            }),
            slaves: vec![
                slave(25, Some(SlaveState::DataExchange), &[]),
                slave(40, None, &["station status: station not existent"]),
            ],
            live: None,
        };
        v.show(&snap);
        let s = screen(&v);
        assert!(!s.contains("master 2 at"), "a monitor is no master:\n{s}");
        assert!(s.contains("dpctl master  listening at 1.5Mbit/s"), "{s}");
        assert!(
            s.contains("token ring: masters 2 (operate, rotation 2.5 ms)"),
            "{s}"
        );
        assert!(s.contains("line: telegrams 99"), "{s}");
        let drive = s.lines().find(|l| l.contains("drive")).expect(&s);
        assert!(
            drive.contains("data_exchange") && drive.contains(" 3/2 "),
            "{drive}"
        );
        assert!(s.contains("speed=258") && s.contains("actual=123"), "{s}");
        // Slave 8 of the bus file is not heard; 40 is heard, not in it.
        assert!(
            s.lines()
                .any(|l| l.contains("  8 ") && l.contains("unseen")),
            "{s}"
        );
        let other = s.lines().find(|l| l.contains(" 40 ")).expect(&s);
        assert!(
            other.contains("unseen") && other.contains("station not existent"),
            "{other}"
        );
        assert!(s.contains("listening only: no writes"), "{s}");
        // `w` opens no prompt, and a write is refused.
        v.key(Key::Char('w'));
        assert!(!screen(&v).contains("write outputs of"));
        let mut m = master();
        assert!(v.write(&mut m, 25, &OutputWrite::Image(vec![1])).is_err());
        assert_eq!(m.outputs(25), Some(&[0, 0][..]));
        // Details name the master that polls the slave.
        v.key(Key::Down);
        v.key(Key::Enter);
        let s = screen(&v);
        assert!(s.contains("state data_exchange  polled by master 2"), "{s}");
        assert!(!s.contains("diagnosis reads"), "{s}");
    }

    #[test]
    fn a_monitor_view_shows_the_fms_connections_of_a_station() {
        use profibus_dp::fms::lli::LliPdu;
        use profibus_dp::fms::pdu::{FmsPdu, Request, Response};
        use profibus_dp::monitor::{Monitor, MonitorOptions};
        use profibus_fdl::wire::{DataTelegram, FunctionCode, RequestKind, ResponseStatus};
        use profibus_fdl::Telegram;
        let mut mon = Monitor::new(vec![], MonitorOptions::default());
        let fc = FunctionCode::Request {
            kind: RequestKind::SrdLow,
            fcb: false,
            fcv: false,
        };
        let resp = FunctionCode::slave_response(ResponseStatus::Dl);
        // Master 3 reads object 2020 of station 25 on LSAP 40.
        let read = LliPdu::Data(FmsPdu::Request {
            invoke_id: 1,
            request: Request::Read {
                index: 2020,
                subindex: None,
            },
        })
        .to_vec()
        .unwrap();
        let value = LliPdu::Data(FmsPdu::Response {
            invoke_id: 1,
            response: Response::Read(vec![0, 0x12]),
        })
        .to_vec()
        .unwrap();
        let req = DataTelegram::new(25, 3, fc, &read).with_saps(Some(40), Some(41));
        let res = DataTelegram::new(3, 25, resp, &value).with_saps(Some(41), Some(40));
        mon.observe(Instant::from_nanos(1_000_000), &Telegram::Data(req));
        mon.observe(Instant::from_nanos(2_000_000), &Telegram::Data(res));
        let mut v = view().listen_only();
        v.update(&mon, Instant::from_nanos(3_000_000));
        let s = screen(&v);
        // In the drive's row, wrapped in the diagnosis column.
        let drive = s.lines().find(|l| l.contains("drive")).expect(&s);
        assert!(drive.contains("FMS master 3 LSAP 40:"), "{s}");
        assert!(s.contains("last Read 2020 ok"), "{s}");
        // The details carry the whole line.
        v.key(Key::Down);
        v.key(Key::Enter);
        let s = screen(&v);
        assert!(
            s.contains("FMS master 3 LSAP 40: connected, services 1, errors 0, last Read 2020 ok"),
            "{s}"
        );
    }

    #[test]
    fn a_monitor_view_with_statistics_shows_role_and_health_per_station() {
        use crate::source::WithLiveList;
        use profibus_dp::config::layout::SlaveLayout;
        use profibus_dp::monitor::stats::{Stats, StatsOptions};
        use profibus_dp::monitor::{Monitor, MonitorOptions, SlaveInfo};
        use profibus_fdl::wire::{DataTelegram, FunctionCode, RequestKind, ResponseStatus};
        use profibus_fdl::Telegram;
        let infos = [8, 25]
            .into_iter()
            .map(|address| {
                SlaveInfo::from(SlaveLayout {
                    address,
                    ..SlaveLayout::default()
                })
            })
            .collect();
        let mut mon = Monitor::new(infos, MonitorOptions::default());
        let mut stats = Stats::new(StatsOptions::default());
        let mut at = Instant::ZERO;
        let mut hear = |t: Telegram<'_>, mon: &mut Monitor, stats: &mut Stats| {
            at += Duration::from_micros(500);
            mon.observe(at, &t);
            stats.observe(at, &t, 8);
            at
        };
        let data = |da, sa, fc, du| {
            Telegram::Data(DataTelegram {
                da,
                sa,
                fc,
                dsap: None,
                ssap: None,
                data: du,
                format: None,
            })
        };
        let mut now = Instant::ZERO;
        for i in 0..20 {
            let fc = FunctionCode::Request {
                kind: RequestKind::SrdHigh,
                fcb: i % 2 == 0,
                fcv: true,
            };
            // 25 answers every Data_Exchange; 8 answers none.
            hear(data(25, 2, fc, &[0x01, 0x02]), &mut mon, &mut stats);
            let resp = FunctionCode::slave_response(ResponseStatus::Dl);
            hear(data(2, 25, resp, &[0x00, 0x7B]), &mut mon, &mut stats);
            hear(data(8, 2, fc, &[0x00]), &mut mon, &mut stats);
            now = hear(Telegram::Token { da: 2, sa: 2 }, &mut mon, &mut stats);
        }
        let mut v = view().listen_only();
        v.update(
            &WithLiveList {
                source: &mut mon,
                stats: &stats,
            },
            now,
        );
        let s = screen(&v);
        for h in crate::health::COLUMNS.iter().filter(|h| **h != "DP state") {
            assert!(s.contains(h), "heading {h} missing:\n{s}");
        }
        // The same cells sniff's stations show (`health::cells`).
        let flat = |l: &str| l.split_whitespace().collect::<Vec<_>>().join(" ");
        let drive = flat(s.lines().find(|l| l.contains("drive")).expect(&s));
        assert!(
            drive.contains("25 drive slave data_exchange ██████████ 100"),
            "{drive}"
        );
        let pump = flat(s.lines().find(|l| l.contains("pump")).expect(&s));
        assert!(pump.contains("8 pump - "), "{pump}");
        assert!(pump.contains("░░░░░░░░░░ 0"), "{pump}");
        // The master's health in the token ring line.
        let ring = s.lines().find(|l| l.contains("token ring")).expect(&s);
        assert!(ring.contains("rotation 2.0 ms) ██████████ 100"), "{ring}");
        // In the details too.
        v.key(Key::Down);
        v.key(Key::Enter);
        assert!(
            screen(&v).contains("polled by master 2  role slave  health 100"),
            "{}",
            screen(&v)
        );
        // Without statistics beside it, the monitor's table is as before.
        let mut plain = view().listen_only();
        plain.update(&mon, now);
        let s = screen(&plain);
        assert!(!s.contains("Health") && !s.contains("█"), "{s}");
    }

    #[test]
    fn modules_split_the_images_by_gsd_module() {
        let d = Decoding::Modules(vec![
            ModuleLayout {
                name: "2 words in".into(),
                inputs: ModuleSpan { offset: 0, len: 4 },
                outputs: ModuleSpan { offset: 0, len: 0 },
            },
            ModuleLayout {
                name: "1 byte out".into(),
                inputs: ModuleSpan { offset: 4, len: 1 },
                outputs: ModuleSpan { offset: 0, len: 1 },
            },
        ]);
        assert_eq!(
            d.words(Direction::Input, &[1, 2, 3, 4, 5]),
            ["2 words in: 01 02 03 04", "1 byte out: 05"]
        );
        assert_eq!(d.words(Direction::Output, &[9]), ["1 byte out: 09"]);
    }

    #[test]
    fn any_terminal_size_draws_without_panicking() {
        let mut m = master();
        let mut v = view();
        m.set_outputs(25, &[1, 2]);
        v.update(&m, Instant::ZERO);
        v.log("a line");
        for (w, h) in [(1, 1), (10, 5), (40, 10), (80, 24), (300, 80)] {
            for k in [Key::Esc, Key::Enter, Key::Esc, Key::Char('w')] {
                let mut t = Terminal::new(TestBackend::new(w, h)).unwrap();
                t.draw(|f| v.render(f, f.area())).unwrap();
                v.key(k);
            }
            v.key(Key::Esc);
        }
        // 80×24: both slaves and the keys are on the screen.
        let mut t = Terminal::new(TestBackend::new(80, 24)).unwrap();
        t.draw(|f| v.render(f, f.area())).unwrap();
        let s = screen_text(t.backend().buffer());
        assert!(
            s.contains("pump") && s.contains("drive") && s.contains("q quit"),
            "{s}"
        );
    }

    #[test]
    fn long_values_wrap_between_words_inside_their_column() {
        let w: Vec<String> = ["speed=1500", "actual=1499", "status1=512"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        assert_eq!(
            wrap(&w, "  ", 24),
            ["speed=1500  actual=1499", "status1=512"]
        );
        assert_eq!(wrap(&w, "  ", 5), ["spee…", "actu…", "stat…"]);
        assert!(wrap(&[], " ", 10).is_empty());
    }

    #[test]
    fn cycle_time_comes_from_data_exchanges_over_time() {
        assert_eq!(cycle_text(Some(Duration::from_micros(2500))), "   2.5 ms");
        assert_eq!(cycle_text(None).trim(), "—");
        assert_eq!(parse_value("-3"), Some(Value::Int(-3)));
        assert_eq!(parse_value("1.5"), Some(Value::Float(1.5)));
        assert_eq!(parse_value("true"), Some(Value::Bool(true)));
        assert_eq!(parse_value("x"), None);
    }
}
