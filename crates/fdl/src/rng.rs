//! A small deterministic pseudo-random number generator for fault
//! injection and simulation.
//!
//! xoshiro256** (Blackman and Vigna, 2018) seeded through SplitMix64, so
//! that every seed, including 0, gives a well-mixed state. Not
//! cryptographic. There is no global generator: each user owns one, and a
//! seed gives the same sequence on every run.

/// xoshiro256** seeded with SplitMix64.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rng {
    s: [u64; 4],
}

/// One step of SplitMix64: advances `state` and returns the next output.
pub fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Rng {
    /// A generator whose sequence is determined by `seed`.
    pub fn new(seed: u64) -> Rng {
        let mut sm = seed;
        let s = [
            splitmix64(&mut sm),
            splitmix64(&mut sm),
            splitmix64(&mut sm),
            splitmix64(&mut sm),
        ];
        Rng { s }
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let result = self.s[1].wrapping_mul(5).rotate_left(7).wrapping_mul(9);
        let t = self.s[1] << 17;
        self.s[2] ^= self.s[0];
        self.s[3] ^= self.s[1];
        self.s[1] ^= self.s[2];
        self.s[0] ^= self.s[3];
        self.s[2] ^= t;
        self.s[3] = self.s[3].rotate_left(45);
        result
    }

    /// A uniform float in `[0, 1)` with 53 random bits.
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// `true` with probability `p` (`p ≤ 0` never, `p ≥ 1` always).
    pub fn chance(&mut self, p: f64) -> bool {
        self.next_f64() < p
    }

    /// A uniform integer in `lo..=hi` (`lo ≤ hi`).
    pub fn range_inclusive(&mut self, lo: u64, hi: u64) -> u64 {
        debug_assert!(lo <= hi);
        let span = hi - lo;
        if span == u64::MAX {
            return self.next_u64();
        }
        // Lemire's multiply-shift; the bias of at most span/2^64 is
        // irrelevant for fault injection.
        lo + ((self.next_u64() as u128 * (span as u128 + 1)) >> 64) as u64
    }

    /// A random byte.
    pub fn next_u8(&mut self) -> u8 {
        (self.next_u64() >> 56) as u8
    }

    /// Number of failures before the first success of a Bernoulli(`p`)
    /// process (geometric distribution on 0, 1, 2, …); `u64::MAX` when
    /// `p ≤ 0`.
    pub fn geometric(&mut self, p: f64) -> u64 {
        if p <= 0.0 || p.is_nan() {
            return u64::MAX;
        }
        if p >= 1.0 {
            return 0;
        }
        // 1 - U lies in (0, 1], so the logarithm is finite.
        let u = 1.0 - self.next_f64();
        let k = crate::math::floor(crate::math::ln(u) / crate::math::ln_1p(-p));
        if k >= u64::MAX as f64 {
            u64::MAX
        } else {
            k as u64
        }
    }

    /// An exponentially distributed number of nanoseconds for events at
    /// `rate_per_s` per second; at least 1. `u64::MAX` when the rate is 0.
    pub fn exponential_nanos(&mut self, rate_per_s: f64) -> u64 {
        if rate_per_s <= 0.0 || rate_per_s.is_nan() {
            return u64::MAX;
        }
        let u = 1.0 - self.next_f64();
        let ns = -crate::math::ln(u) / rate_per_s * 1e9;
        if ns >= u64::MAX as f64 {
            u64::MAX
        } else {
            (ns as u64).max(1)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_sequence() {
        let mut a = Rng::new(42);
        let mut b = Rng::new(42);
        let mut c = Rng::new(43);
        let va: Vec<u64> = (0..8).map(|_| a.next_u64()).collect();
        let vb: Vec<u64> = (0..8).map(|_| b.next_u64()).collect();
        let vc: Vec<u64> = (0..8).map(|_| c.next_u64()).collect();
        assert_eq!(va, vb);
        assert_ne!(va, vc);
    }

    #[test]
    fn splitmix_reference_values() {
        // First outputs of SplitMix64 from state 0 (reference values of
        // the published algorithm).
        let mut s = 0u64;
        assert_eq!(splitmix64(&mut s), 0xE220_A839_7B1D_CDAF);
        assert_eq!(splitmix64(&mut s), 0x6E78_9E6A_A1B9_65F4);
    }

    #[test]
    fn distributions_are_plausible() {
        let mut r = Rng::new(7);
        let n = 100_000;
        let hits = (0..n).filter(|_| r.chance(0.1)).count();
        assert!((9_000..11_000).contains(&hits), "{hits}");
        let mean = (0..n).map(|_| r.geometric(0.01) as f64).sum::<f64>() / n as f64;
        // Mean of failures before success: (1 - p) / p = 99.
        assert!((94.0..104.0).contains(&mean), "{mean}");
        let mean_ns = (0..n)
            .map(|_| r.exponential_nanos(1000.0) as f64)
            .sum::<f64>()
            / n as f64;
        assert!((970_000.0..1_030_000.0).contains(&mean_ns), "{mean_ns}");
        for _ in 0..1000 {
            let v = r.range_inclusive(3, 9);
            assert!((3..=9).contains(&v));
        }
        assert_eq!(r.geometric(1.0), 0);
        assert_eq!(r.geometric(0.0), u64::MAX);
    }
}
