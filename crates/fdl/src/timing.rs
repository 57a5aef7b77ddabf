//! Baud rates, bus parameters and timing arithmetic.
//!
//! PROFIBUS specifies every layer-2 time in *bit times* (t_bit = 1 / baud):
//! slot time TSL, station delay TSDR, setup time TSET, quiet time TQUI, sync
//! time TSYN, the idle times TID1/TID2 and the target rotation time TTR.
//! [`BusParams`] holds them for one bus; [`BusParams::defaults`] gives the
//! usual defaults per baud rate, and the conversions turn bit times into
//! [`Duration`]s (rounded up to whole nanoseconds).
//!
//! Sources of the defaults (the standard, IEC 61158-4-3 / EN 50170 volume 2,
//! fixes the ranges and TSYN; the values per baud rate come from):
//! TSL, max TSDR, TSET and TQUI per baud rate from the Felser PROFIBUS
//! manual's table, cross-checked with profirust's minimum slot times and
//! with the `MaxTsdr_*` defaults of the BM4-O-PRO-01 and Omega GSD files
//! (60/60/60/60/100/150/250/450/800); min TSDR = 11 (the standard's lower
//! bound, used by profirust and pyprofibus); TSYN = 33 (the standard);
//! GAP factor 10, HSA 126 and retry limit 1 (profirust, a COM PROFIBUS
//! export, the ABB FPBA-01 manual); TTR = 32436 bit (profirust's default).
//! 31.25 kbit/s (MBP/PA) and 45.45 kbit/s take the ≤ 187.5 kbit/s values
//! as profirust does; DP/PA couplers may need larger ones from their GSD.
//! The idle-time formulas TSM = 2 + 2·TSET + TQUI, TID1 = max(TSYN + TSM,
//! min TSDR) and TID2 = max(TSYN + TSM, max TSDR) come from the Horner
//! SmartStack manual and a COM PROFIBUS bus-parameter export; the
//! token-lost timeout TTO = 6·TSL + 2·n·TSL (n = own address) from
//! profirust.

#[allow(unused_imports)]
use crate::prelude::*;
use crate::wire::consts::BITS_PER_CHAR;
use core::fmt;
use core::str::FromStr;
use core::time::Duration;

/// A PROFIBUS baud rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Baud {
    /// 9.6 kbit/s
    B9600,
    /// 19.2 kbit/s
    B19200,
    /// 31.25 kbit/s (MBP / PROFIBUS PA)
    B31250,
    /// 45.45 kbit/s
    B45450,
    /// 93.75 kbit/s
    B93750,
    /// 187.5 kbit/s
    B187500,
    /// 500 kbit/s
    B500000,
    /// 1.5 Mbit/s
    B1500000,
    /// 3 Mbit/s
    B3000000,
    /// 6 Mbit/s
    B6000000,
    /// 12 Mbit/s
    B12000000,
}

impl Baud {
    /// Every baud rate, slowest first.
    pub const ALL: [Baud; 11] = [
        Baud::B9600,
        Baud::B19200,
        Baud::B31250,
        Baud::B45450,
        Baud::B93750,
        Baud::B187500,
        Baud::B500000,
        Baud::B1500000,
        Baud::B3000000,
        Baud::B6000000,
        Baud::B12000000,
    ];

    /// Bits per second.
    pub const fn bps(self) -> u32 {
        match self {
            Baud::B9600 => 9_600,
            Baud::B19200 => 19_200,
            Baud::B31250 => 31_250,
            Baud::B45450 => 45_450,
            Baud::B93750 => 93_750,
            Baud::B187500 => 187_500,
            Baud::B500000 => 500_000,
            Baud::B1500000 => 1_500_000,
            Baud::B3000000 => 3_000_000,
            Baud::B6000000 => 6_000_000,
            Baud::B12000000 => 12_000_000,
        }
    }

    /// The baud rate with exactly this many bits per second.
    pub fn from_bps(bps: u32) -> Option<Baud> {
        Baud::ALL.into_iter().find(|b| b.bps() == bps)
    }

    /// The GSD keyword suffix of this rate (`9.6`, `19.2`, `45.45`, `93.75`,
    /// `187.5`, `500`, `1.5M`, `3M`, `6M`, `12M`; 31.25 kbit/s has none in
    /// DP GSD files and uses `31.25`).
    pub const fn gsd_suffix(self) -> &'static str {
        match self {
            Baud::B9600 => "9.6",
            Baud::B19200 => "19.2",
            Baud::B31250 => "31.25",
            Baud::B45450 => "45.45",
            Baud::B93750 => "93.75",
            Baud::B187500 => "187.5",
            Baud::B500000 => "500",
            Baud::B1500000 => "1.5M",
            Baud::B3000000 => "3M",
            Baud::B6000000 => "6M",
            Baud::B12000000 => "12M",
        }
    }

    /// Duration of `bits` bit times at this rate, rounded up to whole
    /// nanoseconds.
    pub const fn bits_to_duration(self, bits: u64) -> Duration {
        let bps = self.bps() as u128;
        let nanos = (bits as u128 * 1_000_000_000).div_ceil(bps);
        Duration::from_nanos(nanos as u64)
    }

    /// Whole bit times elapsed in `d` (rounded down).
    pub const fn duration_to_bits(self, d: Duration) -> u64 {
        (d.as_nanos() * self.bps() as u128 / 1_000_000_000) as u64
    }

    /// Wire time of `n` characters (11 bit each).
    pub const fn chars_to_duration(self, n: u64) -> Duration {
        self.bits_to_duration(n * BITS_PER_CHAR as u64)
    }
}

impl fmt::Display for Baud {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let b = self.bps();
        if b >= 1_000_000 {
            write!(f, "{}", self.gsd_suffix())?;
            f.write_str("bit/s")
        } else {
            write!(f, "{}kbit/s", self.gsd_suffix())
        }
    }
}

/// Error for a string that names no PROFIBUS baud rate.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown baud rate `{0}`; use one of 9600, 19200, 31250, 45450, 93750, 187500, 500000, 1500000, 3000000, 6000000, 12000000 (or 1.5M, 500k, …)")]
pub struct UnknownBaud(pub String);

impl FromStr for Baud {
    type Err = UnknownBaud;

    /// Accepts bits per second (`1500000`), with a k/M suffix (`1.5M`,
    /// `187.5k`, `45.45k`), and the GSD spelling (`187.5`, `1.5M`).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim().to_ascii_lowercase();
        let t = t
            .trim_end_matches("bit/s")
            .trim_end_matches("bps")
            .trim_end_matches("baud");
        let (num, mult) = if let Some(n) = t.strip_suffix('m') {
            (n, 1_000_000.0)
        } else if let Some(n) = t.strip_suffix('k') {
            (n, 1_000.0)
        } else {
            (t, 1.0)
        };
        let err = || UnknownBaud(s.to_string());
        let v: f64 = num.trim().parse().map_err(|_| err())?;
        let mut bps = crate::math::round(v * mult);
        // GSD style "187.5" / "9.6" means kbit/s.
        if mult == 1.0 && v < 1000.0 {
            bps = crate::math::round(v * 1000.0);
        }
        if !(0.0..=u32::MAX as f64).contains(&bps) {
            return Err(err());
        }
        Baud::from_bps(bps as u32).ok_or_else(err)
    }
}

/// Bus parameters of one PROFIBUS segment, all times in bit times.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BusParams {
    /// Transmission rate.
    pub baud: Baud,
    /// TSL: slot time, the longest a requester waits for the first
    /// character of a response.
    pub slot_time: u32,
    /// min TSDR: the shortest delay before a responder may answer.
    pub min_tsdr: u32,
    /// max TSDR: the longest delay before a responder must answer.
    pub max_tsdr: u32,
    /// TSET: setup time (reaction to an event).
    pub tset: u32,
    /// TQUI: quiet time of transmitter/repeater switching.
    pub tqui: u32,
    /// TSYN: idle line before a request or token (33 bit times).
    pub tsyn: u32,
    /// G: GAP update factor (token rotations between GAP polls).
    pub gap_factor: u8,
    /// HSA: highest station address looked at by GAP polling.
    pub hsa: u8,
    /// Retry limit: repetitions of an unanswered request.
    pub max_retry: u8,
    /// TTR: target token rotation time.
    pub ttr: u32,
}

impl BusParams {
    /// The usual defaults for `baud` (sources in the module docs).
    pub const fn defaults(baud: Baud) -> BusParams {
        let (slot_time, max_tsdr, tset, tqui) = match baud {
            Baud::B9600
            | Baud::B19200
            | Baud::B31250
            | Baud::B45450
            | Baud::B93750
            | Baud::B187500 => (100, 60, 1, 0),
            Baud::B500000 => (200, 100, 1, 0),
            Baud::B1500000 => (300, 150, 1, 0),
            Baud::B3000000 => (400, 250, 4, 3),
            Baud::B6000000 => (600, 450, 8, 6),
            Baud::B12000000 => (1000, 800, 16, 9),
        };
        BusParams {
            baud,
            slot_time,
            min_tsdr: 11,
            max_tsdr,
            tset,
            tqui,
            tsyn: 33,
            gap_factor: 10,
            hsa: 126,
            max_retry: 1,
            ttr: 32_436,
        }
    }

    /// TSM = 2 + 2·TSET + TQUI: safety margin.
    pub const fn tsm(&self) -> u32 {
        2 + 2 * self.tset + self.tqui
    }

    /// TID1 = max(TSYN + TSM, min TSDR): idle time after a response,
    /// acknowledge or token before the next request.
    pub const fn tid1(&self) -> u32 {
        let a = self.tsyn + self.tsm();
        if a > self.min_tsdr {
            a
        } else {
            self.min_tsdr
        }
    }

    /// TID2 = max(TSYN + TSM, max TSDR): idle time after an unacknowledged
    /// request (SDN, broadcast) before the next request.
    pub const fn tid2(&self) -> u32 {
        let a = self.tsyn + self.tsm();
        if a > self.max_tsdr {
            a
        } else {
            self.max_tsdr
        }
    }

    /// TTO = 6·TSL + 2·n·TSL: bus idle time after which the station with
    /// address `n` considers the token lost and claims it. Lower addresses
    /// time out first.
    pub const fn token_lost_timeout(&self, own_address: u8) -> u32 {
        6 * self.slot_time + 2 * own_address as u32 * self.slot_time
    }

    /// Minimum wire time in bit times of one request/response exchange:
    /// TID1 (the idle time, which contains TSYN) + the request characters +
    /// min TSDR + the response characters.
    pub const fn exchange_bits(&self, request_len: usize, response_len: usize) -> u64 {
        self.tid1() as u64
            + BITS_PER_CHAR as u64 * request_len as u64
            + self.min_tsdr as u64
            + BITS_PER_CHAR as u64 * response_len as u64
    }

    /// [`BusParams::exchange_bits`] as a duration.
    pub const fn exchange_time(&self, request_len: usize, response_len: usize) -> Duration {
        self.baud
            .bits_to_duration(self.exchange_bits(request_len, response_len))
    }

    /// Duration of `bits` bit times at this bus's rate.
    pub const fn bits(&self, bits: u64) -> Duration {
        self.baud.bits_to_duration(bits)
    }

    /// Slot time as a duration.
    pub const fn slot_duration(&self) -> Duration {
        self.bits(self.slot_time as u64)
    }

    /// Check the standard's constraints between the parameters:
    /// max TSDR + 15 ≤ TSL ≤ 16383, 35 + 2·TSET + TQUI ≤ max TSDR ≤ 1023
    /// (relaxed to TSYN + TSM), 11 ≤ min TSDR ≤ max TSDR, HSA ≤ 126,
    /// GAP factor 1..=100, TTR ≥ 256.
    pub fn validate(&self) -> Result<(), BusParamsError> {
        use BusParamsError as E;
        if self.min_tsdr < 11 || self.min_tsdr > self.max_tsdr {
            return Err(E::MinTsdr(self.min_tsdr, self.max_tsdr));
        }
        if self.max_tsdr > 1023 {
            return Err(E::MaxTsdr(self.max_tsdr));
        }
        if self.slot_time < self.max_tsdr + 15 || self.slot_time > 16383 {
            return Err(E::SlotTime(self.slot_time, self.max_tsdr));
        }
        if self.hsa > 126 {
            return Err(E::Hsa(self.hsa));
        }
        if !(1..=100).contains(&self.gap_factor) {
            return Err(E::GapFactor(self.gap_factor));
        }
        if self.ttr < 256 {
            return Err(E::Ttr(self.ttr));
        }
        Ok(())
    }
}

/// A violated constraint between bus parameters.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BusParamsError {
    /// min TSDR outside 11..=max TSDR.
    #[error("min TSDR {0} must be between 11 and max TSDR ({1})")]
    MinTsdr(u32, u32),
    /// max TSDR above 1023.
    #[error("max TSDR {0} exceeds 1023 bit times")]
    MaxTsdr(u32),
    /// TSL too small or too big.
    #[error("slot time {0} must be at least max TSDR + 15 ({1} + 15) and at most 16383")]
    SlotTime(u32, u32),
    /// HSA above 126.
    #[error("HSA {0} exceeds 126")]
    Hsa(u8),
    /// GAP factor outside 1..=100.
    #[error("GAP factor {0} outside 1..=100")]
    GapFactor(u8),
    /// TTR below 256.
    #[error("TTR {0} below 256 bit times")]
    Ttr(u32),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_table_tid() {
        // TID1/TID2 column of the COM PROFIBUS bus-parameter export.
        let expect = [
            (Baud::B9600, 37, 60),
            (Baud::B19200, 37, 60),
            (Baud::B93750, 37, 60),
            (Baud::B187500, 37, 60),
            (Baud::B500000, 37, 100),
            (Baud::B1500000, 37, 150),
            (Baud::B3000000, 46, 250),
            (Baud::B6000000, 57, 450),
            (Baud::B12000000, 76, 800),
        ];
        for (b, tid1, tid2) in expect {
            let p = BusParams::defaults(b);
            assert_eq!((p.tid1(), p.tid2()), (tid1, tid2), "{b}");
            p.validate().unwrap();
        }
    }

    #[test]
    fn exchange_time_of_reference_example() {
        // §13: 32 slaves × (37 + 121 + 11 + 121) bits at 1.5 Mbit/s.
        let p = BusParams::defaults(Baud::B1500000);
        assert_eq!(p.exchange_bits(11, 11), 290);
        let per = p.exchange_time(11, 11);
        assert_eq!(per, Duration::from_nanos(193_334));
    }

    #[test]
    fn conversions() {
        assert_eq!(
            Baud::B19200.chars_to_duration(2000),
            Duration::from_nanos(1_145_833_334)
        );
        assert_eq!(
            Baud::B12000000.bits_to_duration(12),
            Duration::from_micros(1)
        );
        assert_eq!(
            Baud::B1500000.duration_to_bits(Duration::from_millis(1)),
            1500
        );
    }

    #[test]
    fn parse_baud() {
        for (s, b) in [
            ("1.5M", Baud::B1500000),
            ("1500000", Baud::B1500000),
            ("187.5k", Baud::B187500),
            ("187.5", Baud::B187500),
            ("9.6", Baud::B9600),
            ("45.45k", Baud::B45450),
            ("12M", Baud::B12000000),
            ("500k", Baud::B500000),
            ("19200", Baud::B19200),
        ] {
            assert_eq!(s.parse::<Baud>(), Ok(b), "{s}");
        }
        assert!("115200".parse::<Baud>().is_err());
        assert!("fast".parse::<Baud>().is_err());
    }
}
