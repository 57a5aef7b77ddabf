//! The simulated line's options as command-line flags: clap types live
//! in the command line, the medium they configure in `profibus-fdl`.

use profibus_fdl::line::medium::{Collisions, MediumConfig, MediumConfigError};
use profibus_fdl::Baud;

/// What happens when a station starts transmitting while the line is busy
/// ([`Collisions`] as a flag value).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CollisionsArg {
    /// The overlapping characters of both transmissions are corrupted, as
    /// on a real line, and a collision is counted.
    Garble,
    /// The late transmitter waits until the line is free (as if it had
    /// perfect carrier sense); nothing is corrupted.
    Serialize,
}

impl From<CollisionsArg> for Collisions {
    fn from(c: CollisionsArg) -> Collisions {
        match c {
            CollisionsArg::Garble => Collisions::Garble,
            CollisionsArg::Serialize => Collisions::Serialize,
        }
    }
}

/// A number given for a [`MediumConfig`] field that is out of range.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MediumArgError {
    /// Not a probability.
    #[error("`{0}` is not a probability between 0 and 1")]
    Probability(String),
    /// Not a finite rate ≥ 0.
    #[error("`{0}` is not a number ≥ 0")]
    Rate(String),
}

/// A probability (0 … 1) from text.
pub fn parse_probability(s: &str) -> Result<f64, MediumArgError> {
    match s.parse::<f64>() {
        Ok(p) if (0.0..=1.0).contains(&p) => Ok(p),
        _ => Err(MediumArgError::Probability(s.into())),
    }
}

/// A finite rate ≥ 0 from text.
pub fn parse_rate(s: &str) -> Result<f64, MediumArgError> {
    match s.parse::<f64>() {
        Ok(r) if r >= 0.0 && r.is_finite() => Ok(r),
        _ => Err(MediumArgError::Rate(s.into())),
    }
}

/// A [`MediumConfig`] as command-line flags (`dpctl bus`). The field
/// docs are the flags' help.
#[derive(clap::Args, Debug, Clone)]
pub struct MediumArgs {
    /// Pace the line at this rate (9600 … 12M; 11 bit per character, one
    /// transmitter at a time). Without it bytes pass as fast as they come.
    #[arg(long, value_name = "B")]
    pub baud: Option<Baud>,
    /// Probability of losing each character (0 … 1).
    #[arg(long, value_name = "P", default_value_t = 0.0, value_parser = parse_probability)]
    pub drop: f64,
    /// Bit error rate: probability of flipping each data bit (0 … 1).
    #[arg(long, value_name = "BER", default_value_t = 0.0, value_parser = parse_probability)]
    pub flip: f64,
    /// Bursts of random characters per second of idle line.
    #[arg(long, value_name = "RATE", default_value_t = 0.0, value_parser = parse_rate)]
    pub noise: f64,
    /// Seed of the fault injection, for reproducible runs (default: from
    /// the clock; printed at start).
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,
    /// What two stations sending at once do on a paced line: garble each
    /// other (as on a real line) or serialize (the later one waits).
    #[arg(long, value_enum, default_value_t = CollisionsArg::Garble)]
    pub collisions: CollisionsArg,
}

impl MediumArgs {
    /// The configuration, checked; without a seed, one from the clock.
    pub fn config(&self) -> Result<MediumConfig, MediumConfigError> {
        let seed = self.seed.unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_nanos() as u64)
                .unwrap_or(0)
        });
        let cfg = MediumConfig {
            baud: self.baud,
            drop: self.drop,
            flip_ber: self.flip,
            noise_rate: self.noise,
            seed,
            collisions: self.collisions.into(),
        };
        cfg.validate().map(|()| cfg)
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn medium_arguments_in_range() {
        assert_eq!(super::parse_probability("0.25"), Ok(0.25));
        let e = super::parse_probability("1.5").unwrap_err().to_string();
        assert_eq!(e, "`1.5` is not a probability between 0 and 1");
        assert!(super::parse_rate("-1").is_err() && super::parse_rate("inf").is_err());
        assert_eq!(super::parse_rate("20"), Ok(20.0));
    }
}
