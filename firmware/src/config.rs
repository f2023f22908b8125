//! Board configuration: identity, safety limits and sequencer timing, and the [`BoardInfo`] built
//! from them.
//!
//! A board port describes itself once, at start-up, with a [`BoardConfig`]; [`BoardConfig::check`]
//! (called by [`Board::new`](crate::Board::new)) refuses limits that contradict each other, so a
//! port cannot boot with a configuration under which no capture could ever be valid or the flash
//! could never be forced off. Every [`CaptureConfig`](ellipso_protocol::CaptureConfig) the host
//! sends is then checked against [`BoardConfig::limits`] by [`CapturePlan`](crate::CapturePlan).
//!
//! # Default limits for the LED flash rig ([`LED_RIG_LIMITS`])
//!
//! | limit | value | where it comes from |
//! |---|---|---|
//! | `min_exposure_us` | 20 µs | IMX250 minimum exposure 19.9 µs (Genie Nano M2450 datasheet), rounded up |
//! | `max_exposure_us` | 1 s | a flash capture never needs more; longer exposures only collect ambient light |
//! | `max_flash_on_us` | 5 ms | LED pulse rating: a high-power LED driven at several times its DC current survives pulses of a few ms; 5 ms also bounds motion blur of a hand-held rig |
//! | `max_flash_duty_permille` | 100 ‰ (10 %) | LED thermal limit at pulse overdrive: mean power ≤ 10 % of peak |
//! | `readout_us` | 20 ms | 2048 rows × ≈ 9.8 µs/row, i.e. a 5 MP global-shutter sensor read out at ≈ 50 fps |
//! | `min_frame_period_us` | 20.02 ms | `min_exposure_us + readout_us` |
//! | `max_frame_period_us` | 10 s | slowest useful free run (one shot per step of a turntable) |
//! | `max_pulse_count` | 100 000 | far above a 100–300-shot session; bounds a runaway counted capture |
//!
//! Consequences, for the host's planning: the shortest frame period for exposure `e` is
//! `e + 20 ms`; a 5 ms flash needs a period of at least `1000 · 5 ms / 100 = 50 ms` (20 fps); a
//! 1 ms flash at 20 fps uses 2 % duty.
//!
//! `readout_us` is the *sensor's* limit. A GigE link sustains fewer frames per second (≈ 23 fps
//! for 8-bit 5 MP); the camera buffers a burst, and the host paces longer captures by its link.
//!
//! # Sequencer timing ([`SequencerTiming::DEFAULT`])
//!
//! - `lead_us` = 1 ms: a pulse requested at `now` (Start, FireOne, button) rises at `now + lead_us`,
//!   so the first deadline is never in the past when the command handler returns. 1 ms covers a
//!   USB full-speed frame and the command path of an ISR-driven board.
//! - `late_tolerance_us` = 50 µs: an edge executed more than this after its deadline is reported
//!   late (`PULSE_LATE`, `Fault::DeadlineMissed`). Cortex-M ISR latency is well under 1 µs and
//!   the QEMU ISR path costs 7–13 µs under `-icount shift=3`; 50 µs flags real misses (a blocked
//!   loop, a long critical section) without flagging emulator noise.

use core::fmt;

use ellipso_protocol::{BOARD_NAME_MAX, BoardInfo, BoardLimits, FirmwareVersion, PROTOCOL_VERSION};

/// Default limits for the polarisation-camera + LED flash rig; see the [module docs](self).
pub const LED_RIG_LIMITS: BoardLimits = BoardLimits {
    min_exposure_us: 20,
    max_exposure_us: 1_000_000,
    max_flash_on_us: 5_000,
    max_flash_duty_permille: 100,
    readout_us: 20_000,
    min_frame_period_us: 20 + 20_000,
    max_frame_period_us: 10_000_000,
    max_pulse_count: 100_000,
};

/// The version of this core crate, parsed from `CARGO_PKG_VERSION` at compile time.
pub const CORE_VERSION: FirmwareVersion = match parse_version(env!("CARGO_PKG_VERSION")) {
    Some(v) => v,
    None => panic!("CARGO_PKG_VERSION is not MAJOR.MINOR.PATCH with parts ≤ 255"),
};

/// Parses `MAJOR.MINOR.PATCH` (each ≤ 255), ignoring a `-pre` or `+build` suffix; `None` otherwise.
///
/// `const`, so a board port writes
/// `const VERSION: FirmwareVersion = match parse_version(env!("CARGO_PKG_VERSION")) { .. }`.
pub const fn parse_version(text: &str) -> Option<FirmwareVersion> {
    let bytes = text.as_bytes();
    let mut parts = [0u16; 3];
    let mut part = 0usize;
    let mut digits = 0usize;
    let mut i = 0usize;
    while i < bytes.len() {
        let b = bytes[i];
        if b == b'-' || b == b'+' {
            break;
        }
        if b == b'.' {
            if digits == 0 || part == 2 {
                return None;
            }
            part += 1;
            digits = 0;
        } else if b.is_ascii_digit() {
            parts[part] = parts[part] * 10 + (b - b'0') as u16;
            if parts[part] > 255 {
                return None;
            }
            digits += 1;
        } else {
            return None;
        }
        i += 1;
    }
    if part != 2 || digits == 0 {
        return None;
    }
    Some(FirmwareVersion {
        major: parts[0] as u8,
        minor: parts[1] as u8,
        patch: parts[2] as u8,
    })
}

/// How the sequencer places and judges edges; see the [module docs](self) for the defaults.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SequencerTiming {
    /// Delay from a pulse request (Start, FireOne, button) to its trigger edge, µs.
    pub lead_us: u32,
    /// Lateness above which an executed edge is reported late, µs.
    pub late_tolerance_us: u32,
}

impl SequencerTiming {
    /// 1 ms lead, 50 µs tolerance.
    pub const DEFAULT: Self = Self {
        lead_us: 1_000,
        late_tolerance_us: 50,
    };
}

impl Default for SequencerTiming {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Everything a board port tells the core about itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BoardConfig {
    /// Human-readable name sent in `HelloReply`, at most [`BOARD_NAME_MAX`] bytes of UTF-8.
    pub name: &'static str,
    /// The port's firmware version (usually [`parse_version`] of its `CARGO_PKG_VERSION`).
    pub firmware_version: FirmwareVersion,
    /// Frequency of the timer behind the µs device clock, Hz (the resolution of edge times).
    pub timer_clock_hz: u32,
    /// Safety and timing limits every configuration is checked against.
    pub limits: BoardLimits,
    /// Pulse lead and lateness tolerance.
    pub timing: SequencerTiming,
}

impl BoardConfig {
    /// A config with [`CORE_VERSION`], [`LED_RIG_LIMITS`] and [`SequencerTiming::DEFAULT`].
    pub const fn new(name: &'static str, timer_clock_hz: u32) -> Self {
        Self {
            name,
            firmware_version: CORE_VERSION,
            timer_clock_hz,
            limits: LED_RIG_LIMITS,
            timing: SequencerTiming::DEFAULT,
        }
    }

    /// Refuses names that do not fit the wire and limits that contradict each other.
    ///
    /// Checked, in this order: name length; `timer_clock_hz > 0`;
    /// `1 ≤ min_exposure_us ≤ max_exposure_us`; `1 ≤ min_frame_period_us ≤ max_frame_period_us`;
    /// `max_flash_on_us ≥ 1`; `max_flash_duty_permille ≤ 1000`; `max_pulse_count ≥ 1`;
    /// `min_exposure_us + readout_us ≤ max_frame_period_us` (otherwise no configuration is valid).
    pub fn check(&self) -> Result<(), ConfigError> {
        let l = &self.limits;
        if self.name.len() > BOARD_NAME_MAX {
            return Err(ConfigError::NameTooLong {
                len: self.name.len(),
            });
        }
        if self.timer_clock_hz == 0 {
            return Err(ConfigError::ZeroTimerClock);
        }
        if l.min_exposure_us == 0 || l.min_exposure_us > l.max_exposure_us {
            return Err(ConfigError::ExposureRange);
        }
        if l.min_frame_period_us == 0 || l.min_frame_period_us > l.max_frame_period_us {
            return Err(ConfigError::PeriodRange);
        }
        if l.max_flash_on_us == 0 {
            return Err(ConfigError::ZeroFlashOnTime);
        }
        if l.max_flash_duty_permille > 1000 {
            return Err(ConfigError::DutyAbove1000 {
                permille: l.max_flash_duty_permille,
            });
        }
        if l.max_pulse_count == 0 {
            return Err(ConfigError::ZeroPulseCount);
        }
        if u64::from(l.min_exposure_us) + u64::from(l.readout_us) > u64::from(l.max_frame_period_us)
        {
            return Err(ConfigError::NoValidPeriod);
        }
        Ok(())
    }

    /// The `HelloReply` payload: this config with the core's [`PROTOCOL_VERSION`].
    pub fn board_info(&self) -> Result<BoardInfo, ConfigError> {
        self.check()?;
        let board_name =
            heapless::String::try_from(self.name).map_err(|_| ConfigError::NameTooLong {
                len: self.name.len(),
            })?;
        Ok(BoardInfo {
            protocol_version: PROTOCOL_VERSION,
            firmware_version: self.firmware_version,
            board_name,
            timer_clock_hz: self.timer_clock_hz,
            limits: self.limits,
        })
    }
}

/// Why a [`BoardConfig`] was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConfigError {
    /// The board name does not fit [`BOARD_NAME_MAX`].
    NameTooLong {
        /// Its length, bytes.
        len: usize,
    },
    /// `timer_clock_hz` is 0.
    ZeroTimerClock,
    /// `min_exposure_us` is 0 or above `max_exposure_us`.
    ExposureRange,
    /// `min_frame_period_us` is 0 or above `max_frame_period_us`.
    PeriodRange,
    /// `max_flash_on_us` is 0: no flash could ever fire.
    ZeroFlashOnTime,
    /// `max_flash_duty_permille` above 1000.
    DutyAbove1000 {
        /// The value given.
        permille: u16,
    },
    /// `max_pulse_count` is 0.
    ZeroPulseCount,
    /// `min_exposure_us + readout_us > max_frame_period_us`: no configuration could be valid.
    NoValidPeriod,
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NameTooLong { len } => {
                write!(f, "board name of {len} bytes exceeds {BOARD_NAME_MAX}")
            }
            Self::ZeroTimerClock => write!(f, "timer_clock_hz is 0"),
            Self::ExposureRange => {
                write!(f, "min_exposure_us must be ≥ 1 and ≤ max_exposure_us")
            }
            Self::PeriodRange => {
                write!(
                    f,
                    "min_frame_period_us must be ≥ 1 and ≤ max_frame_period_us"
                )
            }
            Self::ZeroFlashOnTime => write!(f, "max_flash_on_us is 0"),
            Self::DutyAbove1000 { permille } => {
                write!(f, "max_flash_duty_permille {permille} exceeds 1000")
            }
            Self::ZeroPulseCount => write!(f, "max_pulse_count is 0"),
            Self::NoValidPeriod => write!(
                f,
                "min_exposure_us + readout_us exceeds max_frame_period_us: no capture could be valid"
            ),
        }
    }
}

impl core::error::Error for ConfigError {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn versions_parse_with_suffixes_and_refuse_garbage() {
        let v = |major, minor, patch| {
            Some(FirmwareVersion {
                major,
                minor,
                patch,
            })
        };
        assert_eq!(parse_version("0.1.0"), v(0, 1, 0));
        assert_eq!(parse_version("12.255.3-rc.1"), v(12, 255, 3));
        assert_eq!(parse_version("1.2.3+build5"), v(1, 2, 3));
        for bad in [
            "", "1", "1.2", "1.2.", "1..2", "1.2.3.4", "256.0.0", "a.b.c", "1.2.x",
        ] {
            assert_eq!(parse_version(bad), None, "{bad:?}");
        }
        assert_eq!(Some(CORE_VERSION), parse_version(env!("CARGO_PKG_VERSION")));
    }

    #[test]
    fn default_limits_follow_their_documented_formulas() {
        let l = LED_RIG_LIMITS;
        assert_eq!(l.min_frame_period_us, l.min_exposure_us + l.readout_us);
        // A maximal flash at the duty limit needs a 50 ms period.
        assert_eq!(
            1000 * l.max_flash_on_us / u32::from(l.max_flash_duty_permille),
            50_000
        );
        BoardConfig::new("rig", 1_000_000).check().unwrap();
    }

    #[test]
    fn contradictory_limits_are_refused() {
        let base = BoardConfig::new("rig", 1_000_000);
        let with = |f: fn(&mut BoardConfig)| {
            let mut c = base;
            f(&mut c);
            c.check()
        };
        assert_eq!(
            with(|c| c.name = "a-name-that-is-longer-than-24"),
            Err(ConfigError::NameTooLong { len: 29 })
        );
        assert_eq!(
            with(|c| c.timer_clock_hz = 0),
            Err(ConfigError::ZeroTimerClock)
        );
        assert_eq!(
            with(|c| c.limits.min_exposure_us = 0),
            Err(ConfigError::ExposureRange)
        );
        assert_eq!(
            with(|c| c.limits.min_exposure_us = c.limits.max_exposure_us + 1),
            Err(ConfigError::ExposureRange)
        );
        assert_eq!(
            with(|c| c.limits.min_frame_period_us = 0),
            Err(ConfigError::PeriodRange)
        );
        assert_eq!(
            with(|c| c.limits.max_flash_on_us = 0),
            Err(ConfigError::ZeroFlashOnTime)
        );
        assert_eq!(
            with(|c| c.limits.max_flash_duty_permille = 1001),
            Err(ConfigError::DutyAbove1000 { permille: 1001 })
        );
        assert_eq!(
            with(|c| c.limits.max_pulse_count = 0),
            Err(ConfigError::ZeroPulseCount)
        );
        assert_eq!(
            with(|c| c.limits.readout_us = u32::MAX),
            Err(ConfigError::NoValidPeriod)
        );
    }

    #[test]
    fn board_info_carries_the_config() {
        let info = BoardConfig::new("qemu-netduinoplus2", 1_000_000)
            .board_info()
            .unwrap();
        assert_eq!(info.protocol_version, PROTOCOL_VERSION);
        assert_eq!(info.board_name.as_str(), "qemu-netduinoplus2");
        assert_eq!(info.limits, LED_RIG_LIMITS);
        assert_eq!(info.firmware_version, CORE_VERSION);
    }
}
