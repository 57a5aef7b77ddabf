//! The analyser's alert rules and statistics core: arbitrary text through
//! `AlertRule::parse`, and arbitrary bytes, framed by a `Tap`, through
//! `Stats` with the rules checked on each report. Besides no panic: a
//! parse error names a column inside the rule (1 … length + 1); a rule
//! that parses prints back as the text given (trimmed) and parses again
//! to the same rule; every health is 0 … 100; the totals are never
//! smaller than an interval's counters.
//!
//! Run: `cargo +nightly fuzz run alert_rule`

#![no_main]

use libfuzzer_sys::fuzz_target;
use profibus_dp::monitor::alert::{AlertRule, AlertRuleError};
use profibus_dp::monitor::stats::{Stats, StatsOptions};
use profibus_fdl::line::tap::Tap;
use profibus_fdl::{Baud, Instant};
use std::time::Duration;

fuzz_target!(|data: &[u8]| {
    let Some((&split, rest)) = data.split_first() else {
        return;
    };
    let split = (split as usize).min(rest.len());
    let (text, bytes) = rest.split_at(split);
    let text = String::from_utf8_lossy(text);
    let mut rules = vec![];
    for line in text.split('\n') {
        match AlertRule::parse(line) {
            Ok(r) => {
                assert_eq!(r.to_string(), line.trim());
                assert_eq!(AlertRule::parse(&r.to_string()), Ok(r.clone()));
                rules.push(r);
            }
            Err(e) => {
                let column = match &e {
                    AlertRuleError::UnknownColumn { column, .. }
                    | AlertRuleError::Syntax { column, .. } => *column,
                };
                assert!((1..=line.chars().count() + 1).contains(&column), "{e}");
                assert!(!e.to_string().is_empty());
            }
        }
    }
    let baud = Baud::ALL[bytes.first().copied().unwrap_or(0) as usize % Baud::ALL.len()];
    let mut stats = Stats::new(StatsOptions {
        baud: Some(baud),
        ttr: Some(Duration::from_micros(500)),
    });
    let mut tap = Tap::new();
    let mut now = Instant::ZERO;
    for (i, chunk) in bytes.chunks(7).enumerate() {
        now += Duration::from_micros(chunk[0] as u64 * 13);
        tap.push(now, chunk);
        if i % 3 == 2 {
            tap.line_idle();
        }
        while let Some(e) = tap.poll() {
            stats.hear(&e);
        }
        if i % 5 == 4 {
            let report = stats.snapshot(now);
            for (a, s) in &report.interval.stations {
                assert!(s.health <= 100);
                let t = &report.totals.stations[a];
                assert!(t.requests >= s.requests && t.retries >= s.retries);
                assert!(t.illegal >= s.illegal && t.no_answer >= s.no_answer);
            }
            for alert in AlertRule::alerts(&rules, &report) {
                assert!(alert.value.is_finite());
            }
        }
    }
    tap.line_idle();
    while let Some(e) = tap.poll() {
        stats.hear(&e);
    }
    for l in stats.live() {
        assert!(l.health <= 100);
    }
});
