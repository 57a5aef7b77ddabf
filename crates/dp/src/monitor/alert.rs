//! Alert rules on the statistics of [`super::stats`]: `--alert
//! 'retries>1%'`, `--alert restart`, `--alert 'response_time_max>5ms'`,
//! `--alert '8:health<80'`.
//!
//! A rule is `[ADDR:]COLUMN [OP VALUE[UNIT]]`:
//!
//! - `ADDR:` limits it to one station (0 … 126); without it every
//!   station is checked;
//! - `COLUMN` is a statistic of [`StationStats`]: a counter (`requests`,
//!   `answers`, `retries`, `no_answer`, `illegal`, `diag_requests`,
//!   `diag_answers`, `ext_diag`, `set_prm`, `chk_cfg`, `restarts`,
//!   `requests_sent`, `tokens`, `over_ttr`), a time (`response_time_min`,
//!   `_mean`, `_max`; the same for `idle_before_request`,
//!   `token_rotation`, `cycle`, `bus_cycle`) or `health`; `restart` is
//!   short for `restarts`;
//! - `OP` is one of `>`, `>=`, `<`, `<=`, `=`, `!=`; without `OP VALUE`
//!   the rule is `COLUMN>0`;
//! - `VALUE` is a number; after a counter `%` makes it a share of the
//!   requests addressed to the station; after a time the unit is `ms`
//!   (default), `us` or `s`.
//!
//! Rules are checked on each interval's statistics ([`StatsReport`]); a
//! rule that holds for a station gives one [`Alert`] per interval.

use super::stats::{Durations, StationStats, StatsReport};
use crate::config::names::closest;
use std::fmt;

/// Why a rule does not parse. `column` is the 1-based character position
/// in the rule.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AlertRuleError {
    /// No statistic of that name.
    #[error("alert rule `{rule}`, column {column}: unknown statistic `{name}`{}", hint(.closest))]
    UnknownColumn {
        /// The rule.
        rule: String,
        /// Where the name starts.
        column: usize,
        /// The name given.
        name: String,
        /// The closest valid names.
        closest: Vec<String>,
    },
    /// Something else is wrong at `column`.
    #[error("alert rule `{rule}`, column {column}: {what}")]
    Syntax {
        /// The rule.
        rule: String,
        /// Where.
        column: usize,
        /// What was expected.
        what: String,
    },
}

fn hint(c: &[String]) -> String {
    match c {
        [] => format!(
            " (valid: {})",
            COUNTERS.join(", ") + ", health, response_time_max, …"
        ),
        [one] => format!(" (did you mean `{one}`?)"),
        more => format!(
            " (did you mean {}?)",
            more.iter()
                .map(|s| format!("`{s}`"))
                .collect::<Vec<_>>()
                .join(" or ")
        ),
    }
}

/// Counter columns.
const COUNTERS: [&str; 14] = [
    "requests",
    "answers",
    "retries",
    "no_answer",
    "illegal",
    "diag_requests",
    "diag_answers",
    "ext_diag",
    "set_prm",
    "chk_cfg",
    "restarts",
    "requests_sent",
    "tokens",
    "over_ttr",
];

/// Time columns (each with `_min`, `_mean`, `_max`).
const TIMES: [&str; 5] = [
    "response_time",
    "idle_before_request",
    "token_rotation",
    "cycle",
    "bus_cycle",
];

/// Every valid column name.
pub fn columns() -> Vec<String> {
    let mut v: Vec<String> = COUNTERS.iter().map(|s| s.to_string()).collect();
    for t in TIMES {
        for s in ["min", "mean", "max"] {
            v.push(format!("{t}_{s}"));
        }
    }
    v.push("health".into());
    v.push("restart".into());
    v
}

/// A comparison.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Op {
    /// `>`
    Gt,
    /// `>=`
    Ge,
    /// `<`
    Lt,
    /// `<=`
    Le,
    /// `=` or `==`
    Eq,
    /// `!=`
    Ne,
}

impl Op {
    fn holds(self, a: f64, b: f64) -> bool {
        match self {
            Op::Gt => a > b,
            Op::Ge => a >= b,
            Op::Lt => a < b,
            Op::Le => a <= b,
            Op::Eq => a == b,
            Op::Ne => a != b,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stat {
    Min,
    Mean,
    Max,
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Column {
    Counter(&'static str),
    Time(&'static str, Stat),
    Health,
}

/// A parsed rule.
#[derive(Debug, Clone, PartialEq)]
pub struct AlertRule {
    text: String,
    station: Option<u8>,
    column: Column,
    op: Op,
    /// Threshold: a count, a share 0 … 1 (`percent`), ms, or health.
    value: f64,
    percent: bool,
}

impl fmt::Display for AlertRule {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text)
    }
}

impl std::str::FromStr for AlertRule {
    type Err = AlertRuleError;
    fn from_str(s: &str) -> Result<AlertRule, AlertRuleError> {
        AlertRule::parse(s)
    }
}

/// One firing of a rule: the JSON line `{"event": "alert", "rule",
/// "station", "column", "value", "threshold", "t_s", "interval_s"}`.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Alert {
    /// Always `"alert"`.
    pub event: &'static str,
    /// The rule as given.
    pub rule: String,
    /// The station it holds for.
    pub station: u8,
    /// The statistic.
    pub column: String,
    /// Its value (a share in % for `%` rules, ms for times).
    pub value: f64,
    /// The rule's threshold, in the same unit.
    pub threshold: f64,
    /// End of the interval, seconds on the telegram clock.
    pub t_s: f64,
    /// Length of the interval in seconds.
    pub interval_s: f64,
}

impl fmt::Display for Alert {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "alert t={:.1} s station {}: {} ({} = {})",
            self.t_s, self.station, self.rule, self.column, self.value
        )
    }
}

struct Cursor<'a> {
    s: &'a str,
    pos: usize,
}

impl<'a> Cursor<'a> {
    fn skip_ws(&mut self) {
        while self.rest().starts_with(char::is_whitespace) {
            self.pos += self.rest().chars().next().map_or(1, char::len_utf8);
        }
    }
    fn rest(&self) -> &'a str {
        &self.s[self.pos..]
    }
    fn column(&self) -> usize {
        self.s[..self.pos].chars().count() + 1
    }
    fn take_while(&mut self, f: impl Fn(char) -> bool) -> &'a str {
        let start = self.pos;
        while let Some(c) = self.rest().chars().next().filter(|&c| f(c)) {
            self.pos += c.len_utf8();
        }
        &self.s[start..self.pos]
    }
}

impl AlertRule {
    /// Parses a rule; see the module docs.
    pub fn parse(rule: &str) -> Result<AlertRule, AlertRuleError> {
        let syntax = |c: &Cursor, what: &str| AlertRuleError::Syntax {
            rule: rule.to_string(),
            column: c.column(),
            what: what.to_string(),
        };
        let mut c = Cursor { s: rule, pos: 0 };
        c.skip_ws();
        let mut station = None;
        if c.rest().starts_with(|ch: char| ch.is_ascii_digit()) {
            let at = Cursor {
                s: rule,
                pos: c.pos,
            };
            let digits = c.take_while(|ch| ch.is_ascii_digit());
            c.skip_ws();
            if !c.rest().starts_with(':') {
                return Err(syntax(&c, "expected `:` after the station address"));
            }
            match digits.parse::<u8>() {
                Ok(a) if a <= 126 => station = Some(a),
                _ => return Err(syntax(&at, "station address must be 0 … 126")),
            }
            c.pos += 1;
            c.skip_ws();
        }
        let name_at = Cursor {
            s: rule,
            pos: c.pos,
        };
        let name = c.take_while(|ch| ch.is_ascii_alphanumeric() || ch == '_');
        if name.is_empty() {
            return Err(syntax(
                &c,
                "expected a statistic (e.g. `retries`, `health`)",
            ));
        }
        let column = match column(name) {
            Some(col) => col,
            None => {
                let all = columns();
                return Err(AlertRuleError::UnknownColumn {
                    rule: rule.to_string(),
                    column: name_at.column(),
                    name: name.to_string(),
                    closest: closest(name, all.iter().map(String::as_str))
                        .into_iter()
                        .map(String::from)
                        .collect(),
                });
            }
        };
        c.skip_ws();
        if c.rest().is_empty() {
            return Ok(AlertRule {
                text: rule.trim().to_string(),
                station,
                column,
                op: Op::Gt,
                value: 0.0,
                percent: false,
            });
        }
        let op = [
            (">=", Op::Ge),
            ("<=", Op::Le),
            ("!=", Op::Ne),
            ("==", Op::Eq),
            (">", Op::Gt),
            ("<", Op::Lt),
            ("=", Op::Eq),
        ]
        .into_iter()
        .find(|(t, _)| c.rest().starts_with(t));
        let Some((tok, op)) = op else {
            return Err(syntax(
                &c,
                "expected one of > >= < <= = != after the statistic",
            ));
        };
        c.pos += tok.len();
        c.skip_ws();
        let num_at = Cursor {
            s: rule,
            pos: c.pos,
        };
        let num = c.take_while(|ch| ch.is_ascii_digit() || ch == '.');
        let value: f64 = match num.parse() {
            Ok(v) => v,
            Err(_) => return Err(syntax(&num_at, "expected a number")),
        };
        c.skip_ws();
        let unit_at = Cursor {
            s: rule,
            pos: c.pos,
        };
        let unit = c.take_while(|ch| !ch.is_whitespace());
        c.skip_ws();
        if !c.rest().is_empty() {
            return Err(syntax(&c, "unexpected text after the rule"));
        }
        let (value, percent) = match (&column, unit) {
            (Column::Counter(_), "") => (value, false),
            (Column::Counter(_), "%") => (value, true),
            (Column::Counter(_), _) => {
                return Err(syntax(&unit_at, "a count takes no unit but `%`"));
            }
            (Column::Time(..), "" | "ms") => (value, false),
            (Column::Time(..), "us" | "µs") => (value / 1000.0, false),
            (Column::Time(..), "s") => (value * 1000.0, false),
            (Column::Time(..), _) => {
                return Err(syntax(&unit_at, "a time takes the unit `ms`, `us` or `s`"));
            }
            (Column::Health, "") => (value, false),
            (Column::Health, _) => return Err(syntax(&unit_at, "health takes no unit")),
        };
        Ok(AlertRule {
            text: rule.trim().to_string(),
            station,
            column,
            op,
            value,
            percent,
        })
    }

    /// The column's name.
    pub fn column_name(&self) -> String {
        match &self.column {
            Column::Counter(n) => n.to_string(),
            Column::Time(n, s) => format!(
                "{n}_{}",
                match s {
                    Stat::Min => "min",
                    Stat::Mean => "mean",
                    Stat::Max => "max",
                }
            ),
            Column::Health => "health".into(),
        }
    }

    /// The value the rule compares for `s` (`None`: nothing measured,
    /// e.g. no response time in the interval).
    fn value_of(&self, s: &StationStats) -> Option<f64> {
        match &self.column {
            Column::Counter(n) => {
                let v = counter(s, n) as f64;
                if self.percent {
                    (s.requests > 0).then(|| 100.0 * v / s.requests as f64)
                } else {
                    Some(v)
                }
            }
            Column::Time(n, stat) => {
                let d: &Durations = time(s, n);
                let v = match stat {
                    Stat::Min => d.min(),
                    Stat::Mean => d.mean(),
                    Stat::Max => d.max(),
                };
                v.map(|d| d.as_nanos() as f64 / 1e6)
            }
            Column::Health => Some(s.health as f64),
        }
    }

    /// Whether the rule holds for `station`'s statistics `s`, with the
    /// value compared.
    pub fn check(&self, station: u8, s: &StationStats) -> Option<f64> {
        if self.station.is_some_and(|a| a != station) {
            return None;
        }
        let v = self.value_of(s)?;
        self.op.holds(v, self.value).then_some(v)
    }

    /// The alerts of `rules` on an interval's report.
    pub fn alerts(rules: &[AlertRule], report: &StatsReport) -> Vec<Alert> {
        let mut out = vec![];
        for r in rules {
            for (a, s) in &report.interval.stations {
                if let Some(v) = r.check(*a, s) {
                    out.push(Alert {
                        event: "alert",
                        rule: r.text.clone(),
                        station: *a,
                        column: r.column_name(),
                        value: (v * 1000.0).round() / 1000.0,
                        threshold: r.value,
                        t_s: report.t_s,
                        interval_s: report.interval_s,
                    });
                }
            }
        }
        out
    }
}

fn column(name: &str) -> Option<Column> {
    if name == "health" {
        return Some(Column::Health);
    }
    if name == "restart" {
        return Some(Column::Counter("restarts"));
    }
    if let Some(c) = COUNTERS.iter().find(|c| **c == name) {
        return Some(Column::Counter(c));
    }
    for t in TIMES {
        if let Some(rest) = name.strip_prefix(t).and_then(|r| r.strip_prefix('_')) {
            let stat = match rest {
                "min" => Stat::Min,
                "mean" => Stat::Mean,
                "max" => Stat::Max,
                _ => return None,
            };
            return Some(Column::Time(t, stat));
        }
    }
    None
}

fn counter(s: &StationStats, name: &str) -> u64 {
    match name {
        "requests" => s.requests,
        "answers" => s.answers,
        "retries" => s.retries,
        "no_answer" => s.no_answer,
        "illegal" => s.illegal,
        "diag_requests" => s.diag_requests,
        "diag_answers" => s.diag_answers,
        "ext_diag" => s.ext_diag,
        "set_prm" => s.set_prm,
        "chk_cfg" => s.chk_cfg,
        "restarts" => s.restarts,
        "requests_sent" => s.requests_sent,
        "tokens" => s.tokens,
        "over_ttr" => s.over_ttr,
        _ => 0,
    }
}

fn time<'a>(s: &'a StationStats, name: &str) -> &'a Durations {
    match name {
        "response_time" => &s.response_time,
        "idle_before_request" => &s.idle_before_request,
        "token_rotation" => &s.token_rotation,
        "cycle" => &s.cycle,
        _ => &s.bus_cycle,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::monitor::stats::{StatsReport, StatsSet};
    use std::time::Duration;

    fn report(s: StationStats) -> StatsReport {
        let mut set = StatsSet::default();
        set.stations.insert(8, s);
        StatsReport {
            event: "stats",
            interval_s: 1.0,
            t_s: 5.0,
            interval: set.clone(),
            totals: set,
        }
    }

    #[test]
    fn rules_fire_on_shares_counts_times_and_health() {
        let mut s = StationStats {
            requests: 200,
            retries: 3,
            restarts: 1,
            health: 75,
            ..StationStats::default()
        };
        s.response_time.add(Duration::from_micros(6500));
        let rules: Vec<AlertRule> = [
            "retries>1%",
            "retries>2%",
            "restart",
            "response_time_max > 5ms",
            "response_time_max>7",
            "health<80",
            "9:health<80",
            "8:no_answer>=0",
        ]
        .iter()
        .map(|r| r.parse().unwrap())
        .collect();
        let alerts = AlertRule::alerts(&rules, &report(s));
        let fired: Vec<&str> = alerts.iter().map(|a| a.rule.as_str()).collect();
        assert_eq!(
            fired,
            [
                "retries>1%",
                "restart",
                "response_time_max > 5ms",
                "health<80",
                "8:no_answer>=0"
            ]
        );
        assert_eq!(alerts[0].value, 1.5);
        assert_eq!(alerts[0].station, 8);
        assert_eq!(alerts[2].value, 6.5);
        assert_eq!(alerts[2].column, "response_time_max");
    }

    #[test]
    fn errors_name_the_column_and_the_closest_statistic() {
        let e = AlertRule::parse("retrys>1%").unwrap_err();
        assert_eq!(
            e.to_string(),
            "alert rule `retrys>1%`, column 1: unknown statistic `retrys` (did you mean `retries`?)"
        );
        let e = AlertRule::parse("8:response_time_mx>5").unwrap_err();
        assert!(e.to_string().contains("column 3"), "{e}");
        assert!(e.to_string().contains("`response_time_max`"), "{e}");
        let e = AlertRule::parse("retries>x").unwrap_err().to_string();
        assert_eq!(e, "alert rule `retries>x`, column 9: expected a number");
        let e = AlertRule::parse("health<80%").unwrap_err().to_string();
        assert_eq!(
            e,
            "alert rule `health<80%`, column 10: health takes no unit"
        );
        let e = AlertRule::parse("200:illegal").unwrap_err().to_string();
        assert!(e.contains("column 1: station address"), "{e}");
        assert!(AlertRule::parse("illegal ~ 3").is_err());
        assert!(AlertRule::parse("").is_err());
        assert!(AlertRule::parse("cycle_max>2s").is_ok());
    }
}
