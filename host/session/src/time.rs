//! Typed timestamps of the two clocks a capture involves, so they can never be mixed.
//!
//! - [`DeviceTimeUs`]: microseconds of the trigger board's 64-bit monotonic clock, as carried in
//!   pulse events and pongs.
//! - [`HostTimeUs`]: microseconds of the host's monotonic clock since a [`HostClock`]'s epoch
//!   (the moment the link or session was opened). Frame arrival times are in this clock.
//!
//! Converting one into the other needs a clock model fit (`ellipso_rig::link::clock::ClockModel`); there is no
//! `From` between them on purpose.

use std::time::{Instant, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

/// A time on the trigger board's clock, µs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct DeviceTimeUs(pub u64);

/// A time on the host's monotonic clock, µs since its [`HostClock`] epoch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct HostTimeUs(pub u64);

impl HostTimeUs {
    /// Microseconds from `earlier` to `self`, negative if `self` is earlier.
    pub fn since(self, earlier: HostTimeUs) -> i64 {
        self.0 as i64 - earlier.0 as i64
    }
}

/// The host's monotonic clock with a fixed epoch, plus the wall time of that epoch for the record.
#[derive(Debug, Clone, Copy)]
pub struct HostClock {
    epoch: Instant,
    wall_at_epoch_unix_us: u64,
}

impl Default for HostClock {
    fn default() -> Self {
        Self::new()
    }
}

impl HostClock {
    /// A clock whose epoch is now.
    pub fn new() -> Self {
        let wall = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| d.as_micros() as u64);
        Self {
            epoch: Instant::now(),
            wall_at_epoch_unix_us: wall.unwrap_or(0),
        }
    }

    /// Now, µs since the epoch.
    pub fn now(&self) -> HostTimeUs {
        HostTimeUs(self.epoch.elapsed().as_micros() as u64)
    }

    /// The epoch (host time 0).
    pub fn epoch(&self) -> Instant {
        self.epoch
    }

    /// An instant on this clock (saturating at the epoch for earlier instants).
    pub fn at(&self, t: Instant) -> HostTimeUs {
        HostTimeUs(t.saturating_duration_since(self.epoch).as_micros() as u64)
    }

    /// Wall-clock time of the epoch, µs since the Unix epoch (for session manifests).
    pub fn wall_at_epoch_unix_us(&self) -> u64 {
        self.wall_at_epoch_unix_us
    }
}
