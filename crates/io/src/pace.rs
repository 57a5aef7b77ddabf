//! [`Pacer`]: runs a simulated line (virtual time) in step with the wall
//! clock, for `dpctl gateway --sim` and the gateway benchmarks. The
//! simulation stays sans-IO; this is the one place that reads the clock
//! for it.

use profibus_fdl::Instant;
use std::time::Duration;

/// Paces a simulated line on the wall clock: each turn runs the line up
/// to the time elapsed since [`Pacer::new`], at most [`Pacer::MOST`] of
/// bus time per turn, so on a machine too busy to keep up the line runs
/// slower than real time and the rest of the loop still gets its turn.
#[derive(Debug, Clone, Copy)]
pub struct Pacer {
    start: std::time::Instant,
}

impl Pacer {
    /// The pause between two turns that keep up: an input change on the
    /// line waits at most this long (plus the sleep's overshoot) for the
    /// loop's next step.
    pub const TICK: Duration = Duration::from_micros(500);
    /// The most bus time one turn runs.
    pub const MOST: Duration = Duration::from_millis(20);

    /// A pacer whose bus time 0 is now.
    pub fn new() -> Pacer {
        Pacer {
            start: std::time::Instant::now(),
        }
    }

    /// The bus time the next turn runs to, for a line now at `line_now`,
    /// and whether the line is behind the wall clock by more than
    /// [`Pacer::MOST`].
    pub fn target(&self, line_now: Instant) -> (Instant, bool) {
        let wall = self.bus_time(std::time::Instant::now());
        let most = line_now + Self::MOST;
        if wall > most {
            (most, true)
        } else {
            (wall, false)
        }
    }

    /// Bus time `at` on the wall clock.
    pub fn bus_time(&self, at: std::time::Instant) -> Instant {
        Instant::from_nanos(at.saturating_duration_since(self.start).as_nanos() as u64)
    }

    /// The wall-clock time of bus time `t`.
    pub fn wall_time(&self, t: Instant) -> std::time::Instant {
        self.start + Duration::from_nanos(t.as_nanos())
    }

    /// One turn: `run_until` the line to [`Pacer::target`]; returns the
    /// pause before the next turn ([`Pacer::TICK`], zero when behind).
    pub fn turn(&self, line_now: Instant, run_until: impl FnOnce(Instant)) -> Duration {
        let (t, behind) = self.target(line_now);
        run_until(t);
        if behind {
            Duration::ZERO
        } else {
            Self::TICK
        }
    }
}

impl Default for Pacer {
    fn default() -> Pacer {
        Pacer::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_far_behind_runs_at_most_one_step_and_does_not_pause() {
        let pacer = Pacer {
            start: std::time::Instant::now() - Duration::from_secs(1),
        };
        let mut ran = None;
        let pause = pacer.turn(Instant::ZERO, |t| ran = Some(t));
        assert_eq!(ran, Some(Instant::ZERO + Pacer::MOST));
        assert_eq!(pause, Duration::ZERO);
        let t = Instant::from_nanos(5_000);
        assert_eq!(pacer.bus_time(pacer.wall_time(t)), t);
    }
}
