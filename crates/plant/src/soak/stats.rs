//! Recovery-time distributions with fixed memory, and the process's
//! resident set.

use profibus_fdl::line::medium::MediumStats;
use serde::ser::SerializeStruct;
use serde::{Serialize, Serializer};
use std::time::Duration;

/// Width of a time bucket.
const TIME_BUCKET_NS: u64 = 10_000;
/// Time buckets: 10 µs each, up to 2 s; longer times share the last.
const TIME_BUCKETS: usize = 200_000;
/// Cycle buckets: one per cycle, up to 10,000; more share the last.
const CYCLE_BUCKETS: usize = 10_000;

/// A distribution of recovery times, in poll cycles and in bus time,
/// kept in fixed-size histograms (10 µs resolution up to 2 s) so that its
/// memory does not grow with the number of samples; the maxima are exact.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Distribution {
    cycles: Vec<u32>,
    time: Vec<u32>,
    count: u64,
    max_cycles: u64,
    max_time: Duration,
}

impl Distribution {
    /// An empty distribution (allocates its histograms once).
    pub fn new() -> Distribution {
        Distribution {
            cycles: vec![0; CYCLE_BUCKETS],
            time: vec![0; TIME_BUCKETS],
            ..Distribution::default()
        }
    }

    /// Add a sample.
    pub fn record(&mut self, cycles: u64, time: Duration) {
        if self.cycles.is_empty() {
            *self = Distribution::new();
        }
        let c = (cycles as usize).min(CYCLE_BUCKETS - 1);
        self.cycles[c] = self.cycles[c].saturating_add(1);
        let t = ((time.as_nanos() as u64 / TIME_BUCKET_NS) as usize).min(TIME_BUCKETS - 1);
        self.time[t] = self.time[t].saturating_add(1);
        self.count += 1;
        self.max_cycles = self.max_cycles.max(cycles);
        self.max_time = self.max_time.max(time);
    }

    /// Number of samples.
    pub fn count(&self) -> u64 {
        self.count
    }

    fn quantile(buckets: &[u32], count: u64, q: f64) -> Option<usize> {
        if count == 0 {
            return None;
        }
        let rank = ((q * count as f64).ceil() as u64).clamp(1, count);
        let mut seen = 0u64;
        buckets.iter().position(|&n| {
            seen += n as u64;
            seen >= rank
        })
    }

    /// The `q` quantile (0..=1) in cycles (the bucket's value).
    pub fn cycles_quantile(&self, q: f64) -> Option<u64> {
        Self::quantile(&self.cycles, self.count, q).map(|i| i as u64)
    }

    /// The `q` quantile (0..=1) in bus time, to the upper edge of its
    /// 10 µs bucket (never above the exact maximum).
    pub fn time_quantile(&self, q: f64) -> Option<Duration> {
        Self::quantile(&self.time, self.count, q)
            .map(|i| Duration::from_nanos((i as u64 + 1) * TIME_BUCKET_NS).min(self.max_time))
    }

    /// Longest recovery in cycles.
    pub fn max_cycles(&self) -> u64 {
        self.max_cycles
    }

    /// Longest recovery in bus time.
    pub fn max_time(&self) -> Duration {
        self.max_time
    }
}

fn ms(d: Option<Duration>) -> Option<f64> {
    d.map(|d| (d.as_nanos() as f64 / 1e6 * 1000.0).round() / 1000.0)
}

impl Serialize for Distribution {
    /// `{count, p50_cycles, p99_cycles, max_cycles, p50_ms, p99_ms, max_ms}`.
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut st = s.serialize_struct("Distribution", 7)?;
        st.serialize_field("count", &self.count)?;
        st.serialize_field("p50_cycles", &self.cycles_quantile(0.5))?;
        st.serialize_field("p99_cycles", &self.cycles_quantile(0.99))?;
        st.serialize_field("max_cycles", &(self.count > 0).then_some(self.max_cycles))?;
        st.serialize_field("p50_ms", &ms(self.time_quantile(0.5)))?;
        st.serialize_field("p99_ms", &ms(self.time_quantile(0.99)))?;
        st.serialize_field("max_ms", &ms((self.count > 0).then_some(self.max_time)))?;
        st.end()
    }
}

/// The line's counters as a JSON object.
pub(super) fn medium_stats<S: Serializer>(m: &MediumStats, s: S) -> Result<S::Ok, S::Error> {
    let mut st = s.serialize_struct("MediumStats", 8)?;
    st.serialize_field("transmissions", &m.transmissions)?;
    st.serialize_field("chars", &m.chars)?;
    st.serialize_field("dropped", &m.dropped)?;
    st.serialize_field("bits_flipped", &m.bits_flipped)?;
    st.serialize_field("noise_bursts", &m.noise_bursts)?;
    st.serialize_field("noise_chars", &m.noise_chars)?;
    st.serialize_field("collisions", &m.collisions)?;
    st.serialize_field("garbled_chars", &m.garbled_chars)?;
    st.end()
}

/// The resident set of this process in bytes (Linux; `None` elsewhere).
pub(super) fn resident_set() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kib: u64 = line
        .trim_start_matches("VmRSS:")
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kib * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_and_maxima() {
        let mut d = Distribution::new();
        assert_eq!(d.cycles_quantile(0.5), None);
        for i in 1..=100u64 {
            d.record(i % 3, Duration::from_micros(i * 100));
        }
        assert_eq!(d.count(), 100);
        assert_eq!(d.max_cycles(), 2);
        assert_eq!(d.max_time(), Duration::from_millis(10));
        assert_eq!(d.time_quantile(0.5), Some(Duration::from_micros(5010)));
        assert_eq!(d.time_quantile(1.0), Some(Duration::from_millis(10)));
        assert_eq!(d.cycles_quantile(0.99), Some(2));
        // Beyond the histogram: the maximum stays exact.
        d.record(50_000, Duration::from_secs(5));
        assert_eq!(d.max_cycles(), 50_000);
        assert_eq!(d.max_time(), Duration::from_secs(5));
        assert!(resident_set().is_none_or(|r| r > 0));
    }
}
