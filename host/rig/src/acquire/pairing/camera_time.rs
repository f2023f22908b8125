//! The camera's timestamp clock mapped to host time, for pairing on exposure times.
//!
//! A frame's `t_camera_ns` marks its exposure start on the camera's own counter. The map from
//! that counter to host time is anchored by:
//! - **latch samples** ([`CameraClockSample`]): the counter read between two host times; the
//!   anchor is the bracket's midpoint, uncertain by half the bracket;
//! - **confirmed pairs**: a frame paired with a pulse was exposed `[0, max_exposure_delay]`
//!   after the pulse's trigger (mapped through the board's clock fit); the anchor is the middle
//!   of that range, uncertain by half of it plus the clock fit's error.
//!
//! Between anchors the map assumes the two clocks run at the same rate and widens the
//! uncertainty by [`DRIFT_BOUND`] times the camera time elapsed since the anchor, so a crystal's
//! drift can never push an exposure outside its tolerance unnoticed. The anchor giving the
//! smallest uncertainty answers; pairs keep the newest anchors close to every frame, so the
//! uncertainty stays near the anchors' own.

use std::collections::VecDeque;

use crate::camera::CameraClockSample;

/// Largest rate difference between a camera's counter and the host's clock: two crystals of
/// ±100 ppm (typical parts are ±20–50 ppm).
pub const DRIFT_BOUND: f64 = 200e-6;

/// Anchors kept from confirmed pairs (latch anchors are kept apart, the tightest few).
const PAIR_ANCHORS: usize = 16;
/// Latch anchors kept.
const LATCH_ANCHORS: usize = 4;

#[derive(Debug, Clone, Copy, PartialEq)]
struct Anchor {
    camera_us: f64,
    host_us: f64,
    half_width_us: f64,
}

impl Anchor {
    fn predict(&self, camera_us: f64) -> (f64, f64) {
        let dt = camera_us - self.camera_us;
        (
            self.host_us + dt,
            self.half_width_us + dt.abs() * DRIFT_BOUND,
        )
    }
}

/// Camera counter → host time, with an uncertainty (see the module doc).
#[derive(Debug, Clone, Default)]
pub struct CameraTimeMap {
    latches: Vec<Anchor>,
    pairs: VecDeque<Anchor>,
}

impl CameraTimeMap {
    /// Adds a latch sample.
    pub fn add_latch(&mut self, s: &CameraClockSample) {
        let half = s.half_width_us();
        self.latches.push(Anchor {
            camera_us: s.t_camera_ns as f64 / 1e3,
            host_us: s.t_host_before.0 as f64 + half,
            half_width_us: half,
        });
        self.latches
            .sort_by(|a, b| a.half_width_us.total_cmp(&b.half_width_us));
        self.latches.truncate(LATCH_ANCHORS);
    }

    /// Adds a confirmed exposure: the frame stamped `t_camera_ns` started exposing at
    /// `host_us ± half_width_us`.
    pub fn add_exposure(&mut self, t_camera_ns: u64, host_us: f64, half_width_us: f64) {
        if self.pairs.len() == PAIR_ANCHORS {
            self.pairs.pop_front();
        }
        self.pairs.push_back(Anchor {
            camera_us: t_camera_ns as f64 / 1e3,
            host_us,
            half_width_us,
        });
    }

    /// Whether any anchor exists.
    pub fn is_anchored(&self) -> bool {
        !(self.latches.is_empty() && self.pairs.is_empty())
    }

    /// The host time of camera time `t_camera_ns` and its uncertainty (half-width, µs), from the
    /// anchor that gives the smallest uncertainty; `None` before any anchor.
    pub fn host_us(&self, t_camera_ns: u64) -> Option<(f64, f64)> {
        let camera_us = t_camera_ns as f64 / 1e3;
        self.latches
            .iter()
            .chain(&self.pairs)
            .map(|a| a.predict(camera_us))
            .min_by(|a, b| a.1.total_cmp(&b.1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_session::time::HostTimeUs;

    #[test]
    fn a_latch_maps_with_half_its_bracket_and_widens_with_time() {
        let mut m = CameraTimeMap::default();
        assert!(m.host_us(5).is_none());
        m.add_latch(&CameraClockSample {
            t_camera_ns: 3_600_000_000_000,
            t_host_before: HostTimeUs(1_000),
            t_host_after: HostTimeUs(1_040),
        });
        let (h, u) = m.host_us(3_600_000_000_000).unwrap();
        assert_eq!((h, u), (1_020.0, 20.0));
        // one second later on the camera's clock
        let (h, u) = m.host_us(3_601_000_000_000).unwrap();
        assert_eq!(h, 1_001_020.0);
        assert!((u - (20.0 + 200.0)).abs() < 1e-6);
    }

    #[test]
    fn the_nearest_tight_anchor_answers() {
        let mut m = CameraTimeMap::default();
        m.add_latch(&CameraClockSample {
            t_camera_ns: 0,
            t_host_before: HostTimeUs(0),
            t_host_after: HostTimeUs(100),
        });
        m.add_exposure(60_000_000_000, 60_000_050.0, 10.0);
        let (h, u) = m.host_us(60_001_000_000).unwrap();
        assert_eq!(h, 60_001_050.0);
        assert!(u < 10.5, "{u}");
    }
}
