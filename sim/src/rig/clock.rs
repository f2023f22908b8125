//! Simulated clocks: a linear map from the host's monotonic clock ([`Instant`]) to a device's
//! counter, `t_device = offset + (t_host − epoch) · (1 + drift_ppm · 10⁻⁶)`.
//!
//! Contract: [`LinearClock::at_us`] is monotonic non-decreasing in its argument and saturates at
//! `offset` for instants before the epoch; [`LinearClock::instant_at_us`] is its inverse (to the
//! nearest ns) and saturates at the epoch for times before `offset`. Drift is limited to
//! ±[`MAX_DRIFT_PPM`] so `1 + drift` stays positive and the inverse exists.

use std::time::{Duration, Instant};

use super::RigError;

/// Largest |drift| a simulated clock accepts, ppm (10 %: far beyond any crystal, still invertible).
pub const MAX_DRIFT_PPM: f64 = 100_000.0;

/// A device counter that runs at `1 + drift_ppm·10⁻⁶` times the host's rate from `offset` at `epoch`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearClock {
    epoch: Instant,
    offset_us: u64,
    drift_ppm: f64,
}

impl LinearClock {
    /// A clock reading `offset_us` at `epoch`; refuses a non-finite drift or one beyond ±[`MAX_DRIFT_PPM`].
    pub fn new(epoch: Instant, offset_us: u64, drift_ppm: f64) -> Result<Self, RigError> {
        if !drift_ppm.is_finite() || drift_ppm.abs() > MAX_DRIFT_PPM {
            return Err(RigError::Parameter {
                name: "drift_ppm",
                value: drift_ppm,
                expected: "finite, within ±100000 ppm",
            });
        }
        Ok(Self {
            epoch,
            offset_us,
            drift_ppm,
        })
    }

    /// The host instant at which the clock reads `offset_us`.
    pub fn epoch(&self) -> Instant {
        self.epoch
    }

    /// The reading at the epoch, µs.
    pub fn offset_us(&self) -> u64 {
        self.offset_us
    }

    /// Rate error against the host clock, ppm.
    pub fn drift_ppm(&self) -> f64 {
        self.drift_ppm
    }

    fn rate(&self) -> f64 {
        1.0 + self.drift_ppm * 1e-6
    }

    /// The reading at host instant `t`, ns (the counter's own ns; `offset` scaled by 1000).
    pub fn at_ns(&self, t: Instant) -> u64 {
        let elapsed_ns = t.saturating_duration_since(self.epoch).as_nanos() as f64;
        // rate > 0.9 by the drift limit, so the product is non-negative; `as` saturates.
        let scaled_ns = (elapsed_ns * self.rate()).round() as u64;
        self.offset_us
            .saturating_mul(1_000)
            .saturating_add(scaled_ns)
    }

    /// The reading at host instant `t`, µs (truncated).
    pub fn at_us(&self, t: Instant) -> u64 {
        let elapsed_ns = t.saturating_duration_since(self.epoch).as_nanos() as f64;
        let scaled_us = (elapsed_ns * self.rate() * 1e-3).floor() as u64;
        self.offset_us.saturating_add(scaled_us)
    }

    /// The reading now, µs.
    pub fn now_us(&self) -> u64 {
        self.at_us(Instant::now())
    }

    /// The host instant at which the clock reads `t_us` (the epoch for readings before `offset`).
    pub fn instant_at_us(&self, t_us: u64) -> Instant {
        let since_offset_us = t_us.saturating_sub(self.offset_us) as f64;
        // rate ≥ 0.9 (drift limit): the division is safe.
        let host_ns = (since_offset_us * 1e3 / self.rate()).ceil();
        self.epoch + Duration::from_nanos(host_ns.min(u64::MAX as f64) as u64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drift_and_offset_are_applied_and_inverted() {
        let epoch = Instant::now();
        let clock = LinearClock::new(epoch, 5_000_000_000, 25.0).unwrap();
        let t = epoch + Duration::from_secs(40);
        // 40 s × (1 + 25e-6) = 40 s + 1000 µs
        assert_eq!(clock.at_us(t), 5_000_000_000 + 40_000_000 + 1_000);
        assert_eq!(clock.at_ns(t), 5_000_000_000_000 + 40_001_000_000);
        let back = clock.instant_at_us(clock.at_us(t));
        let err_ns = back.duration_since(epoch).as_nanos() as i128 - 40_000_000_000i128;
        assert!(err_ns.abs() <= 1_000, "inverse off by {err_ns} ns");
        assert_eq!(clock.at_us(epoch - Duration::from_secs(1)), 5_000_000_000);
        assert_eq!(clock.instant_at_us(0), epoch);
    }

    #[test]
    fn absurd_drift_is_refused() {
        let epoch = Instant::now();
        assert!(LinearClock::new(epoch, 0, f64::NAN).is_err());
        assert!(LinearClock::new(epoch, 0, -2e5).is_err());
        assert!(LinearClock::new(epoch, 0, -9e4).is_ok());
    }
}
