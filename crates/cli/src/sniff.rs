//! `dpctl sniff`: a passive bus monitor.
//!
//! Reads a serial line or pty (never writes), frames what it sees and
//! prints one line per telegram: the time in µs since the start, the
//! telegram as `dpctl decode` describes it and, after ` | `, its DP layer
//! in words (`Set_Prm request: WD_On; watchdog 5000 ms; …`). Bytes the framer had to skip
//! (garbage, a bad FCS, a broken length) are printed on lines starting
//! with `!! `, with their hex and the errors they raised. `--json` prints
//! the same as JSON lines (`"error"` marks the skipped bytes), with the
//! DP layer of each DP telegram in a `"dp"` object
//! (`profibus_dp::pdu::decode`: service and decoded data unit; a response is
//! read by the request it answers) and the LLI and FMS PDUs of a telegram
//! of an FMS connection in an `"fms"` object (`profibus_dp::fms::decode`;
//! the plain line has them in words after ` | `); `--pcap` records the telegrams, and
//! the skipped bytes flagged as corrupt; with `--trigger` only the
//! telegrams around each firing of a trigger expression
//! ([`profibus_dp::monitor::trigger`]), in segments. On Ctrl-C / SIGTERM it prints a summary line
//! with the codec counters and stops. On a terminal (without `--json` or
//! `--plain`) it shows the telegrams as a live list with filters and
//! per-station statistics instead (`profibus_tui::sniff`).

use crate::common;
use anyhow::{Context, Result};
use profibus_dp::fms::decode::FmsTelegram;
use profibus_dp::monitor::trigger::{Output, Recorder, Trigger, Watch};
use profibus_dp::pdu::decode::{DpTelegram, Exchanges, Layer};
use profibus_dp::pdu::describe::TelegramSummary;
use profibus_fdl::capture::pcap::PcapWriter;
use profibus_fdl::codec::CodecStats;
use profibus_fdl::line::tap::{Skipped, TapEvent};
use profibus_fdl::wire::Telegram;
use profibus_fdl::Baud;
use profibus_io::listen::{listen, Heard, ListenOptions};
use profibus_io::transport::Port;
use profibus_tui::lines::{monitor_slaves, SlaveInfo};
use profibus_tui::sniff::{skipped_text, SniffView};
use profibus_tui::term::LiveSniff;
use std::fs::File;
use std::io::{BufWriter, IsTerminal, Write};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Listen passively on a line and print every telegram.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Serial port or pty to listen on (e.g. /dev/ttyUSB0, a `dpctl bus`
    /// link), or tcp://HOST:PORT (serial device server, raw TCP).
    #[arg(long, value_name = "PATH")]
    pub port: String,
    /// Baud rate of the line (9600 … 12M; irrelevant on a pty), or
    /// `auto`: listen at each rate until a valid telegram decodes (printed
    /// first: a line, or a JSON object with `"event":"baud_found"`).
    /// Default: the bus file's (`--config`), else 19200.
    #[arg(long, value_name = "B")]
    pub baud: Option<common::BaudArg>,
    /// Print one JSON object per line; DP telegrams carry their decoded
    /// DP layer in `"dp"` (`service`, and the data unit's fields),
    /// telegrams of FMS connections their LLI and FMS PDUs in `"fms"`
    /// (`lli`, `pdu`, `invoke_id`, `index`, …).
    #[arg(long)]
    pub json: bool,
    /// Print lines even on a terminal. Without it a terminal shows a live
    /// list with per-station statistics: `q` quit, `p` pause, `a` filter
    /// by address, `s` by service, `e` errors only, `c` clear filters.
    #[arg(long, conflicts_with = "json")]
    pub plain: bool,
    /// Record the telegrams to FILE (pcapng, link type 257 PROFIBUS DL;
    /// bytes that are no telegram are kept, flagged as corrupt).
    #[arg(long, value_name = "FILE")]
    pub pcap: Option<PathBuf>,
    /// Record only around the telegrams that fire EXPR (repeatable; any
    /// one fires): `--pre` telegrams before, `--post` after, one segment
    /// each (overlapping windows merge), each record annotated. Syntax:
    /// docs/analyser.md, e.g. `cfg_fault`, `addr == 5 and service ==
    /// set_prm`, `fcs or no_answer or retry`, `restart and t > 10s`.
    #[arg(long, value_name = "EXPR", requires = "pcap", value_parser = parse_trigger)]
    pub trigger: Vec<Trigger>,
    /// Telegrams kept before each firing of a trigger.
    #[arg(long, value_name = "N", default_value_t = 100, requires = "trigger")]
    pub pre: usize,
    /// Telegrams kept after each firing of a trigger.
    #[arg(long, value_name = "N", default_value_t = 100, requires = "trigger")]
    pub post: usize,
    /// One file per segment instead of all in FILE: FILE-1.pcapng,
    /// FILE-2.pcapng, … (the number before FILE's extension).
    #[arg(long, requires = "trigger")]
    pub split: bool,
    /// Bus file of the segment: its slaves' modules split Data_Exchange
    /// data by module, and by the channels of a device profile (`device
    /// = "bk3000"`, …) as `dpctl monitor` names them (JSON `"channels":
    /// {"NAME": value}`); their GSD files name diagnosis bits; its master's
    /// bus parameters give the rate (unless --baud) and the TTR the
    /// token rotations are measured against. Without it the modules come
    /// from the Chk_Cfg seen on the wire.
    #[arg(long, value_name = "BUS.toml")]
    pub config: Option<PathBuf>,
    /// A folder of GSD files to name diagnosis bits with, found by the
    /// ident number in each diagnosis (also the built-in files and the
    /// user library). Repeatable.
    #[arg(long, value_name = "DIR")]
    pub gsd_dir: Vec<PathBuf>,
    /// Quiet time in ms after which an incomplete telegram is given up
    /// (default: 5 on a pty; on a serial line twice TSYN, at least 2).
    #[arg(long, value_name = "MS")]
    pub idle_ms: Option<f64>,
    #[command(flatten)]
    pub stats: crate::stats_args::StatsArgs,
}

fn parse_trigger(s: &str) -> Result<Trigger, String> {
    Trigger::parse(s).map_err(|e| e.to_string())
}

/// The file of segment `n` with `--split`: `cap.pcapng` → `cap-1.pcapng`.
fn split_path(path: &Path, n: u32) -> PathBuf {
    let stem = path.file_stem().unwrap_or_default().to_string_lossy();
    let name = match path.extension() {
        Some(ext) => format!("{stem}-{n}.{}", ext.to_string_lossy()),
        None => format!("{stem}-{n}"),
    };
    path.with_file_name(name)
}

/// One record the triggered recorder keeps.
struct Rec {
    at: profibus_fdl::Instant,
    bytes: Vec<u8>,
    corrupt: bool,
    /// The triggers it fired.
    fired: Vec<String>,
}

/// `--trigger`: the triggers, what they watch and the segments written.
struct Triggered {
    triggers: Vec<Trigger>,
    watch: Watch,
    recorder: Recorder<Rec>,
    path: PathBuf,
    split: bool,
    epoch: Duration,
    /// The file being written (all segments, or the open one with
    /// `--split`).
    writer: Option<PcapWriter<BufWriter<File>>>,
    /// The note on the first record of a segment.
    note: Option<String>,
}

/// The `--json` line of a trigger firing.
#[derive(serde::Serialize)]
struct Fired<'a> {
    event: &'static str,
    t_us: u64,
    trigger: String,
    segment: u32,
    file: &'a Path,
}

impl Triggered {
    fn open(&mut self, path: &Path) -> Result<()> {
        let w = PcapWriter::create(path, self.epoch)
            .with_context(|| format!("cannot create {}", path.display()))?;
        self.writer = Some(w);
        Ok(())
    }

    /// The file segment `n` goes to.
    fn file(&self, n: u32) -> PathBuf {
        if self.split {
            split_path(&self.path, n)
        } else {
            self.path.clone()
        }
    }

    fn output(&mut self, o: Output<Rec>) -> Result<()> {
        match o {
            Output::Start { segment } => {
                if self.split {
                    self.open(&split_path(&self.path, segment))?;
                }
                self.note = Some(format!("segment {segment}"));
            }
            Output::Record { record, .. } => {
                let mut parts: Vec<String> = self.note.take().into_iter().collect();
                parts.extend(record.fired.iter().map(|t| format!("trigger: {t}")));
                let comment = (!parts.is_empty()).then(|| parts.join("; "));
                if let Some(w) = self.writer.as_mut() {
                    w.write_record(record.at, &record.bytes, record.corrupt, comment.as_deref())
                        .context("writing the pcap file")?;
                }
            }
            Output::End { .. } => {
                if self.split {
                    if let Some(w) = self.writer.take() {
                        w.into_inner().context("writing the pcap file")?;
                    }
                } else if let Some(w) = self.writer.as_mut() {
                    w.flush().context("writing the pcap file")?;
                }
            }
        }
        Ok(())
    }

    /// Hear `ev`; the triggers it fired, with the segment they go to.
    fn hear(&mut self, ev: &TapEvent) -> Result<(Vec<String>, u32)> {
        let (o, _) = self.watch.hear(ev);
        let fired: Vec<String> = (self.triggers.iter())
            .filter(|t| t.matches(&o))
            .map(|t| t.to_string())
            .collect();
        let segment = self
            .recorder
            .open_segment()
            .unwrap_or(self.recorder.segments() + 1);
        let (at, bytes, corrupt) = match ev {
            TapEvent::Telegram { at, bytes } => (*at, bytes.to_vec(), false),
            TapEvent::Skipped { at, bytes, .. } => (*at, bytes.to_vec(), true),
        };
        let rec = Rec {
            at,
            bytes,
            corrupt,
            fired: fired.clone(),
        };
        let mut outs = vec![];
        self.recorder.push(rec, !fired.is_empty(), |o| outs.push(o));
        for o in outs {
            self.output(o)?;
        }
        Ok((fired, segment))
    }

    fn finish(mut self) -> Result<()> {
        let mut outs = vec![];
        self.recorder.finish(|o| outs.push(o));
        for o in outs {
            self.output(o)?;
        }
        if let Some(w) = self.writer.take() {
            w.into_inner().context("writing the pcap file")?;
        }
        Ok(())
    }
}

/// A line of `--json`: what was seen, and when (µs since the start).
#[derive(serde::Serialize)]
struct Seen<T: serde::Serialize> {
    t_us: u64,
    #[serde(flatten)]
    what: T,
    /// The DP layer (`profibus_dp::pdu::decode`), for DP telegrams.
    #[serde(skip_serializing_if = "Option::is_none")]
    dp: Option<DpTelegram>,
    /// The LLI and FMS PDUs (`profibus_dp::fms::decode`), for telegrams
    /// of FMS connections.
    #[serde(skip_serializing_if = "Option::is_none")]
    fms: Option<FmsTelegram>,
}

struct Printer {
    json: bool,
    /// The live list on a terminal.
    live: Option<LiveSniff>,
    out: BufWriter<crate::out::Stdout>,
    pcap: Option<PcapWriter<BufWriter<File>>>,
    /// Pairs responses with their requests for the `"dp"` object.
    exchanges: Exchanges,
    /// `--trigger`.
    triggered: Option<Triggered>,
    /// `--stats` / `--alert` (`crate::stats_args`).
    stats: Option<crate::stats_args::StatsRun>,
    /// When `out` was last flushed.
    last_flush: std::time::Instant,
}

/// Longest time a printed telegram waits in the output buffer while the
/// line keeps the reader busy (on a resting line it is printed at once).
const FLUSH_EVERY: Duration = Duration::from_millis(20);

impl Printer {
    fn event(&mut self, ev: TapEvent) -> Result<()> {
        if let Some(s) = self.stats.as_mut() {
            s.hear(&ev);
        }
        if let Some(tr) = self.triggered.as_mut() {
            let (fired, segment) = tr.hear(&ev)?;
            let at = match &ev {
                TapEvent::Telegram { at, .. } | TapEvent::Skipped { at, .. } => *at,
            };
            let t_us = at.as_nanos() / 1000;
            for trigger in fired {
                let file = tr.file(segment);
                if self.live.is_some() {
                    continue;
                }
                if self.json {
                    let f = Fired {
                        event: "trigger",
                        t_us,
                        trigger,
                        segment,
                        file: &file,
                    };
                    writeln!(self.out, "{}", common::json_line(&f))?;
                } else {
                    writeln!(
                        self.out,
                        ">> {t_us:>9} trigger `{trigger}` fired: segment {segment} in {}",
                        file.display()
                    )?;
                }
            }
        }
        match ev {
            TapEvent::Telegram { at, bytes } => {
                let t_us = at.as_nanos() / 1000;
                // The tap only yields telegrams that parse.
                let Ok((t, _)) = Telegram::parse(&bytes) else {
                    return Ok(());
                };
                let mut what = TelegramSummary::new(t, &bytes);
                let (dp, fms) = match self.exchanges.decode_layer(&t) {
                    Some(Layer::Dp(dp)) => (Some(dp), None),
                    Some(Layer::Fms(fms)) => {
                        what.service_sap = Some("FMS");
                        (None, Some(*fms))
                    }
                    None => (None, None),
                };
                if let Some(live) = &mut self.live {
                    // The live list: FMS telegrams with their LLI/FMS
                    // PDUs in words first, then the FDL header.
                    match &fms {
                        Some(f) => {
                            live.view_mut()
                                .fms_telegram(at, &bytes, format!("{f} | {what}"))
                        }
                        None => live.view_mut().telegram(at, &bytes, what.to_string()),
                    }
                } else {
                    if self.json {
                        let seen = Seen {
                            t_us,
                            what,
                            dp,
                            fms,
                        };
                        writeln!(self.out, "{}", common::json_line(&seen))?;
                    } else if let Some(dp) = dp {
                        // The DP or FMS layer in words after the telegram.
                        writeln!(self.out, "{t_us:>12} {what} | {dp}")?;
                    } else if let Some(fms) = fms {
                        writeln!(self.out, "{t_us:>12} {what} | {fms}")?;
                    } else {
                        writeln!(self.out, "{t_us:>12} {what}")?;
                    }
                }
                if let Some(p) = self.pcap.as_mut() {
                    p.write_telegram(at, &bytes)
                        .context("writing the pcap file")?;
                }
            }
            TapEvent::Skipped { at, bytes, errors } => {
                let t_us = at.as_nanos() / 1000;
                if let Some(p) = self.pcap.as_mut() {
                    p.write_corrupt(at, &bytes)
                        .context("writing the pcap file")?;
                }
                let what = Skipped::new(&bytes, errors);
                if let Some(live) = &mut self.live {
                    live.view_mut()
                        .skipped(at, skipped_text(&what.error, &bytes));
                } else if self.json {
                    let seen = Seen {
                        t_us,
                        what,
                        dp: None,
                        fms: None,
                    };
                    writeln!(self.out, "{}", common::json_line(&seen))?;
                } else {
                    writeln!(self.out, "!! {t_us:>9} {what}")?;
                }
            }
        }
        // Flushed when the line has no more bytes ready (`Heard::Drained`),
        // and at least every FLUSH_EVERY on a line that never rests.
        if self.live.is_none() && self.last_flush.elapsed() >= FLUSH_EVERY {
            self.flush()?;
        }
        Ok(())
    }

    /// Print what is buffered.
    fn flush(&mut self) -> Result<()> {
        self.last_flush = std::time::Instant::now();
        self.out.flush()?;
        Ok(())
    }

    /// The statistics and alerts of an interval ended by `now` (`last`:
    /// the interval up to the end).
    fn stats_due(&mut self, now: profibus_fdl::Instant, last: bool) -> Result<()> {
        let Some(s) = self.stats.as_mut() else {
            return Ok(());
        };
        let due = if last { s.last(now) } else { s.due(now) };
        if let (Some(due), None) = (due, &self.live) {
            due.print(self.json, &mut self.out)?;
            self.out.flush()?;
        }
        Ok(())
    }

    fn summary(&mut self, s: &CodecStats) -> Result<()> {
        if self.json {
            #[derive(serde::Serialize)]
            struct Summary<'a> {
                summary: &'a CodecStats,
            }
            writeln!(self.out, "{}", common::json_line(&Summary { summary: s }))?;
        } else {
            writeln!(self.out, "summary: {s}")?;
        }
        self.out.flush()?;
        Ok(())
    }
}

/// Listen until Ctrl-C / SIGTERM (or until the line goes away).
pub fn run(args: Args) -> Result<()> {
    common::runtime()?.block_on(sniff(args))
}

async fn sniff(args: Args) -> Result<()> {
    // The bus file first: its bus parameters are the line's.
    let bus = (args.config.as_ref())
        .map(profibus_devices::bus::ProfiledBus::load)
        .transpose()?;
    let params = bus.as_ref().map(|b| b.file.master.params);
    let baud = (args.baud)
        .or(params.map(|p| common::BaudArg::Fixed(p.baud)))
        .unwrap_or(common::BaudArg::Fixed(Baud::B19200));
    let at = match baud {
        common::BaudArg::Fixed(b) => b,
        common::BaudArg::Auto => Baud::B19200,
    };
    common::lock_port(&args.port)?;
    let mut port = Port::open(&args.port, at)?;
    let mut port_baud = at;
    if baud == common::BaudArg::Auto {
        let found = common::find_baud(&mut port, None).await?;
        port_baud = found.baud();
        if args.json {
            crate::out::outln!("{}", common::json_line(&found.json()))?;
        } else {
            crate::out::outln!("{found}")?;
        }
    }
    let mut options = ListenOptions::for_port(&port);
    // The live list redraws every 50 ms.
    options.tick = Duration::from_millis(50);
    match args.idle_ms {
        Some(ms) if ms > 0.0 && ms.is_finite() => {
            options.idle = Duration::from_secs_f64(ms / 1000.0)
        }
        Some(ms) => {
            crate::out::errln!("dpctl sniff: --idle-ms {ms} must be a positive number");
            std::process::exit(2)
        }
        None => {}
    }
    let epoch = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    let triggered = match (&args.pcap, args.trigger.is_empty()) {
        (Some(path), false) => {
            let mut t = Triggered {
                triggers: args.trigger.clone(),
                watch: Watch::default(),
                recorder: Recorder::new(args.pre, args.post),
                path: path.clone(),
                split: args.split,
                epoch,
                writer: None,
                note: None,
            };
            if !args.split {
                t.open(path)?;
            }
            Some(t)
        }
        _ => None,
    };
    let pcap = (args.pcap.as_deref())
        .filter(|_| triggered.is_none())
        .map(|p| {
            PcapWriter::create(p, epoch).with_context(|| format!("cannot create {}", p.display()))
        })
        .transpose()?;
    let live = (!args.json && !args.plain && std::io::stdout().is_terminal())
        .then(|| LiveSniff::open(SniffView::new(format!("dpctl sniff {}", args.port))))
        .transpose()?;
    let mut exchanges = Exchanges::default();
    if let Some(bus) = &bus {
        // The slaves as `dpctl monitor` knows them: modules, GSD, and the
        // named channels of device profiles.
        for s in monitor_slaves(&SlaveInfo::of_bus(bus)?) {
            let address = s.layout.address;
            exchanges.set_slave(address, s.layout.gsd, s.layout.modules);
            if let Some(d) = s.decoder {
                exchanges.set_decoder(address, d);
            }
        }
    }
    if !args.gsd_dir.is_empty() {
        for e in crate::scan::library(&args.gsd_dir)?.entries() {
            exchanges.add_gsd(e.gsd.clone());
        }
    }
    let mut printer = Printer {
        json: args.json,
        live,
        // One write per burst of telegrams, not one per telegram.
        out: BufWriter::with_capacity(64 * 1024, crate::out::stdout()),
        pcap,
        exchanges,
        triggered,
        last_flush: std::time::Instant::now(),
        stats: crate::stats_args::StatsRun::new(
            &args.stats,
            profibus_dp::monitor::stats::StatsOptions {
                baud: Some(port_baud),
                // TTR is not on the wire: the bus file's, in bit times
                // of the line's rate.
                ttr: params.map(|p| port_baud.bits_to_duration(p.ttr as u64)),
            },
        ),
    };
    let mut failure = None;
    let heard = listen(&mut port, options, common::shutdown(), |heard| {
        let r = match heard {
            Heard::Event(ev) => printer.event(ev),
            Heard::Drained(_) if printer.live.is_none() => printer.flush(),
            Heard::Drained(_) => Ok(()),
            Heard::Tick(at) => {
                let live = printer.live.as_mut();
                if live.is_some_and(|l| !l.tick().unwrap_or(false)) {
                    return ControlFlow::Break(());
                }
                printer.stats_due(at, false)
            }
        };
        match r {
            Ok(()) => ControlFlow::Continue(()),
            Err(e) => {
                failure = Some(e);
                ControlFlow::Break(())
            }
        }
    })
    .await;
    printer.live = None;
    let stats = match &heard {
        Ok(s) => *s,
        Err(e) => e.stats,
    };
    // The pcap file is finished also when printing failed (a closed
    // output, `crate::out::Closed`, ends the sniffer quietly).
    let summary = match failure {
        Some(e) => Err(e),
        None => (printer.stats_due(profibus_fdl::Instant::ZERO, true))
            .and_then(|()| printer.summary(&stats)),
    };
    if let Some(p) = printer.pcap.take() {
        p.into_inner().context("writing the pcap file")?;
    }
    if let Some(t) = printer.triggered.take() {
        t.finish()?;
    }
    summary?;
    heard
        .map(drop)
        .with_context(|| format!("reading {}", args.port))
}
