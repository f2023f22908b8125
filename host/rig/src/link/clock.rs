//! Device-to-host clock model from bracketed ping/pong queries (the triggerbox recipe).
//!
//! Each sample is a ping sent at host time `t_send`, answered with the board's `t_device`, and
//! received at `t_recv`. A sample whose round trip `t_recv − t_send` exceeds
//! [`ClockModelConfig::max_round_trip_us`] is rejected (the board's time could lie anywhere in
//! that window); an accepted one is stamped at the midpoint `t_send + rtt/2`. Over a sliding window
//! of the last [`ClockModelConfig::window`] accepted samples the model fits
//! `host_us = gain · device_us + offset` by least squares on centred values, and exposes the
//! residuals so nobody has to trust an unsettled fit: [`ClockModel::fit`] is `None` until
//! [`ClockModelConfig::min_samples`] samples are in. A slope the window does not resolve to
//! 20 ppm (a short window of noisy pings), or beyond 1000 ppm, is not used: the fit is then
//! offset-only (gain 1).
//!
//! Re-synchronising is idempotent: adding samples only slides the window.

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

use super::time::{DeviceTimeUs, HostTimeUs};

/// Settings of the clock model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClockModelConfig {
    /// Largest accepted round trip, µs. A pty answers in well under 1 ms; USB CDC in ~1–2 ms.
    pub max_round_trip_us: u64,
    /// Number of most recent accepted samples the fit uses.
    pub window: usize,
    /// Accepted samples needed before [`ClockModel::fit`] returns a model.
    pub min_samples: usize,
}

impl Default for ClockModelConfig {
    fn default() -> Self {
        Self {
            max_round_trip_us: 5_000,
            window: 100,
            min_samples: 5,
        }
    }
}

/// One bracketed query.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ClockSample {
    /// Host time the ping was written.
    pub t_send: HostTimeUs,
    /// Device time in the pong.
    pub t_device: DeviceTimeUs,
    /// Host time the pong was read.
    pub t_recv: HostTimeUs,
}

impl ClockSample {
    /// Round trip, µs (0 if the host clock went backwards, which a monotonic clock cannot).
    pub fn round_trip_us(&self) -> u64 {
        self.t_recv.0.saturating_sub(self.t_send.0)
    }

    /// Host time the device time is attributed to: the midpoint of the bracket, µs.
    pub fn midpoint_us(&self) -> f64 {
        self.t_send.0 as f64 + self.round_trip_us() as f64 / 2.0
    }
}

/// A fitted device→host mapping.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClockFit {
    /// Host µs per device µs (1 + drift).
    pub gain: f64,
    /// Host µs at device time 0.
    pub offset_us: f64,
    /// Residuals of the window's samples, host µs (sample − model), oldest first.
    pub residuals_us: Vec<f64>,
    /// Root mean square of the residuals, µs.
    pub rms_us: f64,
    /// Samples in the fit.
    pub n_samples: usize,
}

impl ClockFit {
    /// Maps a device time to host time, µs (fractional; round at the caller).
    pub fn host_us(&self, t: DeviceTimeUs) -> f64 {
        self.gain * t.0 as f64 + self.offset_us
    }

    /// Drift of the device clock relative to the host, parts per million.
    pub fn drift_ppm(&self) -> f64 {
        (self.gain - 1.0) * 1e6
    }
}

/// Why a sample was not used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SampleRejected {
    /// The round trip exceeded the bound.
    #[error("round trip {rtt_us} µs exceeds the {max_us} µs bound")]
    RoundTripTooLong {
        /// Measured round trip, µs.
        rtt_us: u64,
        /// The bound, µs.
        max_us: u64,
    },
    /// The device clock went backwards relative to the previous accepted sample.
    #[error("device clock went backwards: {now} µs after {previous} µs")]
    DeviceTimeBackwards {
        /// Previous device time.
        previous: u64,
        /// This device time.
        now: u64,
    },
}

/// Largest standard error of the fitted slope that counts as a measured drift (20 ppm, the
/// tolerance of a good crystal); a vaguer slope is replaced by gain 1.
const MAX_SLOPE_ERROR: f64 = 20e-6;
/// Largest drift any real clock has (1000 ppm); a fitted gain beyond it is replaced by 1.
const MAX_DRIFT: f64 = 1e-3;

/// The sliding-window clock model.
#[derive(Debug, Clone)]
pub struct ClockModel {
    config: ClockModelConfig,
    samples: VecDeque<ClockSample>,
    rejected: u64,
}

impl ClockModel {
    /// An empty model.
    pub fn new(config: ClockModelConfig) -> Self {
        Self {
            config,
            samples: VecDeque::with_capacity(config.window),
            rejected: 0,
        }
    }

    /// Adds a sample; rejected ones are counted and not used.
    pub fn add(&mut self, sample: ClockSample) -> Result<(), SampleRejected> {
        let rtt_us = sample.round_trip_us();
        if rtt_us > self.config.max_round_trip_us {
            self.rejected += 1;
            return Err(SampleRejected::RoundTripTooLong {
                rtt_us,
                max_us: self.config.max_round_trip_us,
            });
        }
        if let Some(last) = self.samples.back()
            && sample.t_device < last.t_device
        {
            self.rejected += 1;
            return Err(SampleRejected::DeviceTimeBackwards {
                previous: last.t_device.0,
                now: sample.t_device.0,
            });
        }
        if self.samples.len() == self.config.window.max(1) {
            self.samples.pop_front();
        }
        self.samples.push_back(sample);
        Ok(())
    }

    /// Accepted samples in the window.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// True when no sample has been accepted.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Samples rejected so far.
    pub fn rejected(&self) -> u64 {
        self.rejected
    }

    /// The least-squares fit over the window, once at least `min_samples` are in.
    pub fn fit(&self) -> Option<ClockFit> {
        let n = self.samples.len();
        if n < self.config.min_samples.max(1) {
            return None;
        }
        // centre both axes on the first sample so f64 keeps sub-µs precision over days
        let d0 = self.samples[0].t_device.0 as f64;
        let h0 = self.samples[0].midpoint_us();
        let pts: Vec<(f64, f64)> = self
            .samples
            .iter()
            .map(|s| (s.t_device.0 as f64 - d0, s.midpoint_us() - h0))
            .collect();
        let mean_d = pts.iter().map(|p| p.0).sum::<f64>() / n as f64;
        let mean_h = pts.iter().map(|p| p.1).sum::<f64>() / n as f64;
        let sdd: f64 = pts.iter().map(|p| (p.0 - mean_d).powi(2)).sum();
        let sdh: f64 = pts.iter().map(|p| (p.0 - mean_d) * (p.1 - mean_h)).sum();
        // All samples at one device time (or a single sample): the slope is undetermined; assume
        // no drift (gain 1) rather than divide by zero.
        let mut gain = if sdd > 1e-6 { sdh / sdd } else { 1.0 };
        // A slope the window cannot resolve better than a crystal's tolerance is no measurement:
        // 20 pings over 20 ms on a loaded host gave gains of 0.95 and 1.014 (5 % — 15 ms of error
        // 300 ms later, enough to pair a 20 fps frame with the wrong pulse). Then fit the offset
        // only: over such a short window the true drift moves nothing.
        let slope_error = if n > 2 && sdd > 1e-6 {
            let ss: f64 = pts
                .iter()
                .map(|p| (p.1 - mean_h - gain * (p.0 - mean_d)).powi(2))
                .sum();
            (ss / (n - 2) as f64 / sdd).sqrt()
        } else {
            f64::INFINITY
        };
        if !(slope_error <= MAX_SLOPE_ERROR && (gain - 1.0).abs() <= MAX_DRIFT) {
            gain = 1.0;
        }
        let offset_c = mean_h - gain * mean_d;
        let residuals_us: Vec<f64> = pts.iter().map(|p| p.1 - (gain * p.0 + offset_c)).collect();
        let rms_us = (residuals_us.iter().map(|r| r * r).sum::<f64>() / n as f64).sqrt();
        // back from centred coordinates: h − h0 = gain (d − d0) + offset_c
        let offset_us = h0 + offset_c - gain * d0;
        Some(ClockFit {
            gain,
            offset_us,
            residuals_us,
            rms_us,
            n_samples: n,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t_send: u64, dev: u64, rtt: u64) -> ClockSample {
        ClockSample {
            t_send: HostTimeUs(t_send),
            t_device: DeviceTimeUs(dev),
            t_recv: HostTimeUs(t_send + rtt),
        }
    }

    #[test]
    fn recovers_gain_and_offset_exactly_from_symmetric_brackets() {
        let mut m = ClockModel::new(ClockModelConfig::default());
        // device runs 50 ppm fast and started 1 s before the host epoch
        for i in 0..20u64 {
            let host_mid = 10_000 + i * 100_000;
            let dev = ((host_mid as f64 + 1_000_000.0) * 1.000_05) as u64;
            m.add(sample(host_mid - 200, dev, 400)).unwrap();
        }
        let fit = m.fit().unwrap();
        assert!(
            (fit.drift_ppm() + 50.0).abs() < 0.1,
            "drift {}",
            fit.drift_ppm()
        );
        assert!(fit.rms_us < 1.0, "rms {}", fit.rms_us);
        let dev = DeviceTimeUs(((510_000.0 + 1_000_000.0) * 1.000_05) as u64);
        assert!((fit.host_us(dev) - 510_000.0).abs() < 1.0);
    }

    #[test]
    fn long_round_trips_are_rejected_and_counted() {
        let mut m = ClockModel::new(ClockModelConfig {
            max_round_trip_us: 1_000,
            ..Default::default()
        });
        assert_eq!(
            m.add(sample(0, 5, 1_001)),
            Err(SampleRejected::RoundTripTooLong {
                rtt_us: 1_001,
                max_us: 1_000
            })
        );
        assert!(m.add(sample(0, 5, 999)).is_ok());
        assert_eq!((m.len(), m.rejected()), (1, 1));
    }

    #[test]
    fn no_fit_until_settled_and_window_slides() {
        let cfg = ClockModelConfig {
            window: 10,
            min_samples: 5,
            ..Default::default()
        };
        let mut m = ClockModel::new(cfg);
        for i in 0..4 {
            m.add(sample(i * 1000, i * 1000, 10)).unwrap();
        }
        assert!(m.fit().is_none());
        for i in 4..50 {
            m.add(sample(i * 1000, i * 1000, 10)).unwrap();
        }
        let fit = m.fit().unwrap();
        assert_eq!((fit.n_samples, fit.residuals_us.len()), (10, 10));
        assert!((fit.gain - 1.0).abs() < 1e-9);
    }

    #[test]
    fn single_device_time_does_not_divide_by_zero() {
        let cfg = ClockModelConfig {
            min_samples: 1,
            ..Default::default()
        };
        let mut m = ClockModel::new(cfg);
        m.add(sample(100, 7, 10)).unwrap();
        let fit = m.fit().unwrap();
        assert_eq!(fit.gain, 1.0);
        assert!((fit.host_us(DeviceTimeUs(7)) - 105.0).abs() < 1e-9);
    }

    #[test]
    fn device_time_going_backwards_is_rejected() {
        let mut m = ClockModel::new(ClockModelConfig::default());
        m.add(sample(0, 100, 10)).unwrap();
        assert!(matches!(
            m.add(sample(10, 99, 10)),
            Err(SampleRejected::DeviceTimeBackwards { .. })
        ));
    }

    #[test]
    fn jittery_brackets_give_small_residuals() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut m = ClockModel::new(ClockModelConfig::default());
        for i in 0..100u64 {
            let t_true = 1_000 + i * 50_000;
            let up: u64 = rng.random_range(20..400);
            let down: u64 = rng.random_range(20..400);
            m.add(ClockSample {
                t_send: HostTimeUs(t_true - up),
                t_device: DeviceTimeUs(t_true + 777),
                t_recv: HostTimeUs(t_true + down),
            })
            .unwrap();
        }
        let fit = m.fit().unwrap();
        assert!(fit.rms_us < 200.0, "rms {}", fit.rms_us);
        assert!((fit.host_us(DeviceTimeUs(2_000_777)) - 2_000_000.0).abs() < 100.0);
    }

    #[test]
    fn a_short_noisy_window_gives_an_offset_not_an_absurd_gain() {
        // 20 pings in 20 ms with ±150 µs of host scheduling noise: the least-squares slope is off
        // by percent; the fit must keep gain 1 and the offset
        let mut m = ClockModel::new(ClockModelConfig::default());
        for i in 0..20u64 {
            let host_mid = 10_000 + i * 1_000;
            let noise = [0, 150, -120, 90, -150, 60][i as usize % 6];
            let dev = (host_mid as i64 + 1_000_000 + noise) as u64;
            m.add(sample(host_mid - 100, dev, 200)).unwrap();
        }
        let fit = m.fit().unwrap();
        assert_eq!(fit.gain, 1.0);
        // 300 ms later the mapping is still right to the noise
        let t = DeviceTimeUs(1_000_000 + 310_000);
        assert!(
            (fit.host_us(t) - 310_000.0).abs() < 200.0,
            "{}",
            fit.host_us(t)
        );
    }
}
