//! `--stats SECS` and `--alert RULE` of `dpctl sniff` and `dpctl monitor`:
//! the flags, and the loop glue around `profibus_dp::monitor::stats`.

use crate::common;
use profibus_dp::monitor::alert::{Alert, AlertRule};
use profibus_dp::monitor::stats::{Stats, StatsOptions, StatsReport};
use profibus_fdl::line::tap::TapEvent;
use profibus_fdl::Instant;
use std::io::Write;
use std::time::Duration;

/// Seconds > 0 from text.
fn parse_secs(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v > 0.0 && v.is_finite() && v <= 86_400.0 => Ok(v),
        _ => Err(format!(
            "`{s}` is not a number of seconds (0 < SECS ≤ 86400)"
        )),
    }
}

/// The statistics flags.
#[derive(clap::Args, Debug, Clone)]
pub struct StatsArgs {
    /// Print statistics per station every SECS seconds: requests,
    /// answers, retries, no answer, illegal telegrams, diagnoses,
    /// restarts, response, idle, token rotation and cycle times, role, DP
    /// state and health 0 … 100 (docs/analyser.md). JSON: `{"event":
    /// "stats", "interval_s", "stations": {"ADDR": {…}}, "totals"}`.
    #[arg(long, value_name = "SECS", value_parser = parse_secs)]
    pub stats: Option<f64>,
    /// Raise an alert when RULE holds for a station over an interval
    /// (`--stats` SECS, default 1 s); repeatable. RULE is
    /// `[ADDR:]STATISTIC [OP VALUE[%|ms|us|s]]`, e.g. `retries>1%`,
    /// `restart`, `no_answer>3`, `response_time_max>5ms`, `illegal>0`,
    /// `health<80`. JSON: `{"event": "alert", "rule", "station", "value",
    /// …}`.
    #[arg(long, value_name = "RULE", value_parser = AlertRule::parse)]
    pub alert: Vec<AlertRule>,
}

/// What one interval produced.
pub struct Due {
    /// The statistics (when `--stats` was given).
    pub report: Option<StatsReport>,
    /// The alerts that fired.
    pub alerts: Vec<Alert>,
}

impl Due {
    /// Print as JSON lines or text lines.
    pub fn print(&self, json: bool, out: &mut impl Write) -> std::io::Result<()> {
        if let Some(r) = &self.report {
            if json {
                writeln!(out, "{}", common::json_line(r))?;
            } else {
                writeln!(out, "{r}")?;
            }
        }
        for a in &self.alerts {
            if json {
                writeln!(out, "{}", common::json_line(a))?;
            } else {
                writeln!(out, "{a}")?;
            }
        }
        Ok(())
    }
}

/// The statistics core with its interval clock and rules.
pub struct StatsRun {
    /// The core.
    pub stats: Stats,
    every: Duration,
    next: Option<Instant>,
    rules: Vec<AlertRule>,
    print: bool,
}

impl StatsRun {
    /// Statistics as the flags ask; `None` without `--stats` or `--alert`.
    pub fn new(args: &StatsArgs, options: StatsOptions) -> Option<StatsRun> {
        if args.stats.is_none() && args.alert.is_empty() {
            return None;
        }
        Some(StatsRun {
            stats: Stats::new(options),
            every: Duration::from_secs_f64(args.stats.unwrap_or(1.0)),
            next: None,
            rules: args.alert.clone(),
            print: args.stats.is_some(),
        })
    }

    /// Statistics that print nothing and raise no alerts: for a view's
    /// live list (role, DP state, health).
    pub fn quiet(options: StatsOptions) -> StatsRun {
        StatsRun {
            stats: Stats::new(options),
            every: Duration::from_secs(1),
            next: None,
            rules: vec![],
            print: false,
        }
    }

    /// A tap event.
    pub fn hear(&mut self, e: &TapEvent) {
        self.stats.hear(e);
        let at = match e {
            TapEvent::Telegram { at, .. } | TapEvent::Skipped { at, .. } => *at,
        };
        self.next.get_or_insert(at + self.every);
    }

    /// The interval's report and alerts when one ended by `now`.
    pub fn due(&mut self, now: Instant) -> Option<Due> {
        let next = self.next?;
        if now < next {
            return None;
        }
        Some(self.take(next.max(now)))
    }

    /// The report of the interval up to `now`, at the end.
    pub fn last(&mut self, now: Instant) -> Option<Due> {
        self.next?;
        Some(self.take(now.max(self.stats.now())))
    }

    fn take(&mut self, now: Instant) -> Due {
        let report = self.stats.snapshot(now);
        self.next = Some(now + self.every);
        let alerts = AlertRule::alerts(&self.rules, &report);
        Due {
            report: self.print.then_some(report),
            alerts,
        }
    }
}
