//! Report by exception: when a slave's changed process image is worth a
//! message ([`ImageFilter`]), from the `[mqtt]` settings `min_interval_ms`,
//! `deadband` and `[[mqtt.slave]]` ([`Traffic`]).
//!
//! An image is published when it is first seen, and then when it differs
//! *significantly* from the image last published and at least the
//! slave's minimum interval has passed since that publish. Significant:
//! an analog channel moved further than its deadband from the value last
//! published, or any other byte changed (bits, bytes, channels without a
//! deadband). A change that is not significant, or that comes too soon,
//! is not lost: once the image has stayed the same for the minimum
//! interval (it settled), it is published if it differs at all from the
//! one last published, so a subscriber always ends with the last value.
//!
//! The analog channels are the channels of 16 bits or more (integers,
//! F32). A percentage deadband needs the channel's range, which the
//! gateway knows only for channels in engineering units (a device
//! profile's [`profibus_devices::channels::Scale`], e.g. ±10 V for a
//! KL3102 input): the range of the channel's type in its unit. Other
//! channels have no known range and are compared exactly unless a
//! deadband in their unit (an absolute one) is given. GSD files give no
//! ranges of process data (their modules are `Cfg` identifiers and
//! lengths only), so the bytes of a slave given by GSD modules
//! (`MODULE[i]`) are compared exactly.

use crate::settings::{Deadband, MqttSettings, SettingsError};
use crate::slave::SlaveInfo;
use profibus_devices::channels::{Channel, ChannelType, Direction, Value};
use std::time::Duration;

/// Whether `c` is an analog channel (16 bits or more).
pub fn analog(c: &Channel) -> bool {
    !matches!(
        c.ty,
        ChannelType::Bool { .. } | ChannelType::U8 | ChannelType::I8
    )
}

/// The range of `c` in its unit, when known (channels in engineering
/// units).
pub fn range(c: &Channel) -> Option<f64> {
    let s = c.scale.as_ref()?;
    let (lo, hi) = c.ty.range()?;
    Some((s.value(hi) - s.value(lo)).abs())
}

/// The deadband `d` of channel `c` in its unit (0: every change).
pub fn absolute(d: Deadband, c: &Channel) -> f64 {
    if !analog(c) {
        return 0.0;
    }
    match d {
        Deadband::Absolute(a) => a,
        Deadband::Percent(p) => range(c).map_or(0.0, |r| r * p / 100.0),
    }
}

/// The traffic settings as they apply to one slave.
#[derive(Debug, Clone, PartialEq)]
pub struct Traffic {
    /// The least time between two publishes of an image.
    pub min_interval: Duration,
    /// The deadband of each channel of the slave, by its index in the
    /// channel map, in the channel's unit.
    pub deadbands: Vec<f64>,
}

impl Traffic {
    /// The traffic settings of slave `info` under `s`.
    pub fn of(s: &MqttSettings, info: &SlaveInfo) -> Traffic {
        let own = s
            .slave_traffic
            .iter()
            .find(|t| t.address == info.layout.address);
        let min_interval = own.and_then(|t| t.min_interval).unwrap_or(s.min_interval);
        let slave_band = own.and_then(|t| t.deadband).unwrap_or(s.deadband);
        let deadbands = info
            .channels
            .iter()
            .flat_map(|m| &m.channels)
            .map(|c| {
                let band = own
                    .and_then(|t| t.channels.iter().find(|(n, _)| *n == c.name))
                    .map_or(slave_band, |(_, d)| *d);
                absolute(band, c)
            })
            .collect();
        Traffic {
            min_interval,
            deadbands,
        }
    }

    /// The filter of the image in `direction` of slave `info`.
    pub fn filter(&self, info: &SlaveInfo, direction: Direction) -> ImageFilter {
        let analog = info
            .channels
            .iter()
            .flat_map(|m| &m.channels)
            .zip(&self.deadbands)
            .filter(|(c, d)| c.direction == direction && **d > 0.0)
            .map(|(c, d)| (c.clone(), *d))
            .collect();
        ImageFilter {
            min_interval_ms: self.min_interval.as_millis() as u64,
            analog,
            last: None,
            published_ms: 0,
            seen: vec![],
            changed_ms: 0,
        }
    }
}

/// Check `[[mqtt.slave]]` against the configured slaves: each address
/// configured, each channel named one of the slave's (closest names
/// otherwise) and not a bit or byte.
pub fn check(s: &MqttSettings, infos: &[SlaveInfo]) -> Result<(), SettingsError> {
    for (i, t) in s.slave_traffic.iter().enumerate() {
        let entry = format!("mqtt.slave.{}", i + 1);
        let Some(info) = infos.iter().find(|i| i.layout.address == t.address) else {
            return Err(SettingsError::Bad {
                key: "slave",
                problem: format!(
                    "names slave {}, which the bus file does not have",
                    t.address
                ),
            }
            .at(format!("{entry}.address")));
        };
        let channels: Vec<&Channel> = info.channels.iter().flat_map(|m| &m.channels).collect();
        for (name, _) in &t.channels {
            match channels.iter().find(|c| c.name == *name) {
                Some(c) if analog(c) => {}
                Some(c) => {
                    return Err(SettingsError::Bad {
                        key: "slave",
                        problem: format!(
                            "slave {}: channel `{name}` is a {}, not an analog channel: it takes no deadband",
                            t.address, c.ty
                        ),
                    }
                    .at(format!("{entry}.channels.{name}")))
                }
                None => {
                    let close = profibus_dp::config::names::closest(
                        name,
                        channels.iter().map(|c| c.name.as_str()),
                    );
                    let hint = match close.as_slice() {
                        [] => String::new(),
                        c => format!("; did you mean `{}`?", c.join("`, `")),
                    };
                    return Err(SettingsError::Bad {
                        key: "slave",
                        problem: format!("slave {} has no channel `{name}`{hint}", t.address),
                    }
                    .at(format!("{entry}.channels.{name}")));
                }
            }
        }
    }
    Ok(())
}

/// Report by exception for one process image of one slave (see the
/// module documentation). Sans-IO: hand it every image with the time
/// ([`ImageFilter::due`]) and tell it what was published
/// ([`ImageFilter::published`]).
#[derive(Debug, Clone)]
pub struct ImageFilter {
    min_interval_ms: u64,
    /// The analog channels with a deadband (> 0), in their unit.
    analog: Vec<(Channel, f64)>,
    /// The image last published.
    last: Option<Vec<u8>>,
    published_ms: u64,
    /// The image last seen, and since when it is unchanged.
    seen: Vec<u8>,
    changed_ms: u64,
}

fn number(v: Option<Value>) -> Option<f64> {
    Some(match v? {
        Value::Bool(b) => b as u8 as f64,
        Value::Int(i) => i as f64,
        Value::Float(x) => x,
    })
}

impl ImageFilter {
    /// Whether `img`, seen at `ts_ms` (ms, monotonic enough: a clock
    /// going back counts as no time passed), is to be published now.
    pub fn due(&mut self, img: &[u8], ts_ms: u64) -> bool {
        let changed_now = self.seen != img;
        if changed_now {
            self.seen = img.to_vec();
            self.changed_ms = ts_ms;
        }
        let Some(last) = &self.last else {
            return true;
        };
        if last.as_slice() == img {
            return false;
        }
        let since_publish = ts_ms.saturating_sub(self.published_ms);
        if since_publish < self.min_interval_ms {
            return false;
        }
        // Settled: the same image as the step before, for the interval.
        let settled = !changed_now && ts_ms.saturating_sub(self.changed_ms) >= self.min_interval_ms;
        settled || self.significant(last, img)
    }

    /// Whether `img` differs from `last` by more than the deadbands.
    fn significant(&self, last: &[u8], img: &[u8]) -> bool {
        if last.len() != img.len() {
            return true;
        }
        let mut covered = vec![false; img.len()];
        for (c, band) in &self.analog {
            let (a, b) = (number(c.read(last)), number(c.read(img)));
            match (a, b) {
                (Some(a), Some(b)) if (a - b).abs() > *band => return true,
                (Some(_), Some(_)) => {
                    let end = (c.offset + c.ty.size()).min(img.len());
                    covered[c.offset.min(end)..end].fill(true);
                }
                _ => {}
            }
        }
        (0..img.len()).any(|i| !covered[i] && last[i] != img[i])
    }

    /// `img` was published at `ts_ms`.
    pub fn published(&mut self, img: &[u8], ts_ms: u64) {
        self.last = Some(img.to_vec());
        self.published_ms = ts_ms;
    }

    /// Take the minimum interval and deadbands of `fresh` (new settings,
    /// `dpctl gateway` on SIGHUP), keeping what was published and seen:
    /// the next publish follows the new rules from the last one.
    pub fn retune(&mut self, fresh: ImageFilter) {
        self.min_interval_ms = fresh.min_interval_ms;
        self.analog = fresh.analog;
    }

    /// Forget what was published (a new connection publishes everything
    /// again).
    pub fn reset(&mut self) {
        self.last = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use profibus_devices::channels::{ChannelMap, Scale};
    use profibus_dp::config::layout::SlaveLayout;

    /// A slave with a ±10 V input (signed word), a status byte and a
    /// counter word without a unit.
    fn info() -> SlaveInfo {
        let mut m = ChannelMap::new();
        m.channels.push(
            Channel::new("ai", Direction::Input, 0, ChannelType::I16).scaled(Scale {
                num: 10,
                den: 32767,
                unit: "V".into(),
            }),
        );
        m.push("status", Direction::Input, 2, ChannelType::U8);
        m.push("count", Direction::Input, 3, ChannelType::U16);
        SlaveInfo {
            layout: SlaveLayout {
                address: 4,
                ..SlaveLayout::default()
            },
            channels: Some(m),
            pkw: None,
        }
    }

    fn settings(text: &str) -> MqttSettings {
        let t: toml::Table = toml::from_str(text).unwrap();
        MqttSettings::from_table(Some(&t), "l").unwrap()
    }

    /// The image with `ai` at raw `ai`, the status byte and the counter.
    fn img(ai: i16, status: u8, count: u16) -> Vec<u8> {
        let mut v = ai.to_be_bytes().to_vec();
        v.push(status);
        v.extend(count.to_be_bytes());
        v
    }

    #[test]
    fn percent_of_range_applies_to_channels_in_units_only() {
        let t = Traffic::of(&settings(""), &info());
        // 1 % of 20 V; the byte and the counter without a unit: exact.
        assert!((t.deadbands[0] - 0.2).abs() < 1e-3, "{:?}", t.deadbands);
        assert_eq!(&t.deadbands[1..], [0.0, 0.0]);
        assert_eq!(t.min_interval, Duration::from_millis(250));
        let t = Traffic::of(
            &settings(
                "deadband = 3\n[[slave]]\naddress = 4\nmin_interval_ms = 0\nchannels = { ai = 0.5 }",
            ),
            &info(),
        );
        assert_eq!(t.deadbands, [0.5, 0.0, 3.0]);
        assert_eq!(t.min_interval, Duration::ZERO);
    }

    #[test]
    fn noise_within_the_deadband_waits_until_the_value_settles() {
        let i = info();
        let mut f = Traffic::of(&settings(""), &i).filter(&i, Direction::Input);
        assert!(f.due(&img(0, 0, 0), 0), "the first image");
        f.published(&img(0, 0, 0), 0);
        // 0.1 V of noise every 10 ms: within the 0.2 V deadband.
        let mut sent = 0;
        for k in 1..100u64 {
            let raw = if k % 2 == 1 { 0 } else { 328 };
            if f.due(&img(raw, 0, 0), k * 10) {
                sent += 1;
                f.published(&img(raw, 0, 0), k * 10);
            }
        }
        assert_eq!(sent, 0, "noise within the deadband is not published");
        // It settles at 0.1 V: published once the minimum interval passed.
        let at = 1000;
        assert!(!f.due(&img(328, 0, 0), at));
        assert!(!f.due(&img(328, 0, 0), at + 100));
        assert!(!f.due(&img(328, 0, 0), at + 249));
        assert!(f.due(&img(328, 0, 0), at + 250), "the last value");
        f.published(&img(328, 0, 0), at + 250);
        assert!(!f.due(&img(328, 0, 0), at + 900));
    }

    #[test]
    fn significant_changes_are_limited_by_the_minimum_interval() {
        let i = info();
        let mut f = Traffic::of(&settings(""), &i).filter(&i, Direction::Input);
        f.published(&img(0, 0, 0), 0);
        // A 1 V step every ms: at most one publish per 250 ms.
        let mut at = vec![];
        for ms in 1..=1000u64 {
            let raw = (ms as i16 % 9 + 1) * 3277;
            if f.due(&img(raw, 0, 0), ms) {
                f.published(&img(raw, 0, 0), ms);
                at.push(ms);
            }
        }
        assert_eq!(at, [250, 500, 750, 1000]);
        // A bit is never within a deadband.
        let mut f = Traffic::of(&settings("min_interval_ms = 0"), &i).filter(&i, Direction::Input);
        f.published(&img(0, 0, 0), 0);
        assert!(f.due(&img(0, 1, 0), 1));
        assert!(!f.due(&img(1, 0, 0), 1), "1 raw step of ai: within");
        assert!(f.due(&img(0, 0, 1), 1), "the counter: exact");
    }

    /// New settings (SIGHUP) change the rules from the next image on and
    /// keep what was published: no image again at once.
    #[test]
    fn a_retuned_filter_keeps_what_was_published() {
        let i = info();
        let mut f = Traffic::of(&settings(""), &i).filter(&i, Direction::Input);
        f.published(&img(0, 0, 0), 0);
        assert!(!f.due(&img(328, 0, 0), 10), "within 0.2 V, too soon");
        f.retune(
            Traffic::of(&settings("deadband = 0\nmin_interval_ms = 0"), &i)
                .filter(&i, Direction::Input),
        );
        assert!(!f.due(&img(0, 0, 0), 11), "the image published before");
        assert!(f.due(&img(328, 0, 0), 12), "every change now");
        f.published(&img(328, 0, 0), 12);
        f.retune(Traffic::of(&settings("min_interval_ms = 1000"), &i).filter(&i, Direction::Input));
        assert!(!f.due(&img(9000, 0, 0), 500), "1 s since the last publish");
        assert!(f.due(&img(9000, 0, 0), 1012));
    }

    #[test]
    fn slave_entries_are_checked_against_the_bus() {
        let e = check(
            &settings("[[slave]]\naddress = 4\nchannels = { aj = 1 }"),
            &[info()],
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "[mqtt]: `slave` slave 4 has no channel `aj`; did you mean `ai`?"
        );
        let e = check(
            &settings("[[slave]]\naddress = 4\nchannels = { status = 1 }"),
            &[info()],
        )
        .unwrap_err();
        assert!(e.to_string().contains("not an analog channel"), "{e}");
        let e = check(&settings("[[slave]]\naddress = 5"), &[info()]).unwrap_err();
        assert!(e.to_string().contains("names slave 5"), "{e}");
        check(
            &settings("[[slave]]\naddress = 4\nchannels = { count = 2 }"),
            &[info()],
        )
        .unwrap();
    }
}
