//! Capture plan: a [`CaptureConfig`] checked against the board's [`BoardLimits`].
//!
//! A [`CapturePlan`] can only be made by [`CapturePlan::new`], so holding one proves the
//! configuration passed every check below; the [`Sequencer`](crate::Sequencer) takes nothing else.
//!
//! # Checks, in order (the first failure is the reason reported)
//!
//! Field ranges come first, so a relational check never reasons about a value that is out of
//! range; then the flash geometry; then LED safety; then sensor timing.
//!
//! | # | rule | [`RejectReason`] |
//! |---|---|---|
//! | 1 | `min_exposure_us ≤ exposure_us ≤ max_exposure_us` and `exposure_us ≥ 1` | `ExposureOutOfRange` |
//! | 2 | `min_frame_period_us ≤ frame_period_us ≤ max_frame_period_us` | `PeriodOutOfRange` |
//! | 3 | `Count(n)`: `1 ≤ n ≤ max_pulse_count` | `CountOutOfRange` |
//! | 4 | `flash_delay_us + flash_duration_us ≤ exposure_us` (also when the duration is 0) | `FlashOutsideExposure` |
//! | 5 | `flash_duration_us ≤ max_flash_on_us` | `FlashTooLong { max_us }` |
//! | 6 | `1000 · flash_duration_us ≤ max_flash_duty_permille · frame_period_us` | `DutyCycleTooHigh { max_permille }` |
//! | 7 | `frame_period_us ≥ exposure_us + readout_us` | `PeriodTooShort { min_us }` |
//!
//! All sums and products are computed in `u64`, so no input overflows. For the host-command and
//! grip-button triggers `frame_period_us` is the *minimum* spacing of pulses, so rule 6 bounds the
//! worst case. `report_edges` and the trigger source are not limited.

use ellipso_protocol::{BoardLimits, CaptureConfig, PulseCount, RejectReason, TriggerSource};

/// A validated capture configuration (see the [module docs](self) for the checks).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CapturePlan {
    config: CaptureConfig,
    readout_us: u32,
    max_flash_on_us: u32,
}

impl CapturePlan {
    /// Checks `config` against `limits` in the documented order.
    pub fn new(config: CaptureConfig, limits: &BoardLimits) -> Result<Self, RejectReason> {
        let exposure = u64::from(config.exposure_us);
        let period = u64::from(config.frame_period_us);
        let duration = u64::from(config.flash_duration_us);

        if config.exposure_us == 0
            || config.exposure_us < limits.min_exposure_us
            || config.exposure_us > limits.max_exposure_us
        {
            return Err(RejectReason::ExposureOutOfRange);
        }
        if config.frame_period_us < limits.min_frame_period_us
            || config.frame_period_us > limits.max_frame_period_us
        {
            return Err(RejectReason::PeriodOutOfRange);
        }
        if let PulseCount::Count(n) = config.pulses {
            if n == 0 || n > limits.max_pulse_count {
                return Err(RejectReason::CountOutOfRange);
            }
        }
        if u64::from(config.flash_delay_us) + duration > exposure {
            return Err(RejectReason::FlashOutsideExposure);
        }
        if config.flash_duration_us > limits.max_flash_on_us {
            return Err(RejectReason::FlashTooLong {
                max_us: limits.max_flash_on_us,
            });
        }
        if 1000 * duration > u64::from(limits.max_flash_duty_permille) * period {
            return Err(RejectReason::DutyCycleTooHigh {
                max_permille: limits.max_flash_duty_permille,
            });
        }
        let min_period = exposure + u64::from(limits.readout_us);
        if period < min_period {
            return Err(RejectReason::PeriodTooShort {
                min_us: u32::try_from(min_period).unwrap_or(u32::MAX),
            });
        }
        Ok(Self {
            config,
            readout_us: limits.readout_us,
            max_flash_on_us: limits.max_flash_on_us,
        })
    }

    /// The configuration as the host sent it.
    pub fn config(&self) -> &CaptureConfig {
        &self.config
    }

    /// Exposure (trigger high) length, µs; ≥ 1.
    pub fn exposure_us(&self) -> u32 {
        self.config.exposure_us
    }

    /// Flash-on delay after the trigger edge, µs.
    pub fn flash_delay_us(&self) -> u32 {
        self.config.flash_delay_us
    }

    /// Flash-on length, µs; 0 means no flash.
    pub fn flash_duration_us(&self) -> u32 {
        self.config.flash_duration_us
    }

    /// Whether pulses light the flash.
    pub fn has_flash(&self) -> bool {
        self.config.flash_duration_us > 0
    }

    /// Minimum spacing of trigger edges (the free-run period), µs; ≥ `exposure_us + readout_us`.
    pub fn frame_period_us(&self) -> u32 {
        self.config.frame_period_us
    }

    /// The sensor readout time of the limits the plan was checked against, µs.
    pub fn readout_us(&self) -> u32 {
        self.readout_us
    }

    /// The flash's hard on-time cap of the limits the plan was checked against, µs.
    pub fn max_flash_on_us(&self) -> u32 {
        self.max_flash_on_us
    }

    /// `Some(n)` for a counted capture, `None` for a continuous one.
    pub fn pulse_count(&self) -> Option<u32> {
        match self.config.pulses {
            PulseCount::Count(n) => Some(n),
            PulseCount::Continuous => None,
        }
    }

    /// What fires each pulse.
    pub fn trigger(&self) -> TriggerSource {
        self.config.trigger
    }

    /// Whether every output transition is also reported as a `BoardMessage::Edge`.
    pub fn report_edges(&self) -> bool {
        self.config.report_edges
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::LED_RIG_LIMITS;

    /// 1 ms exposure, flash 100..600 µs, 50 ms period, 10 pulses, free run.
    fn good() -> CaptureConfig {
        CaptureConfig {
            exposure_us: 1_000,
            flash_delay_us: 100,
            flash_duration_us: 500,
            frame_period_us: 50_000,
            pulses: PulseCount::Count(10),
            trigger: TriggerSource::FreeRun,
            report_edges: false,
        }
    }

    fn check(f: impl FnOnce(&mut CaptureConfig)) -> Result<CapturePlan, RejectReason> {
        let mut c = good();
        f(&mut c);
        CapturePlan::new(c, &LED_RIG_LIMITS)
    }

    #[test]
    fn a_good_config_is_accepted_and_exposed_unchanged() {
        let plan = check(|_| {}).unwrap();
        assert_eq!(*plan.config(), good());
        assert_eq!(plan.pulse_count(), Some(10));
        assert_eq!(plan.readout_us(), LED_RIG_LIMITS.readout_us);
        assert_eq!(plan.max_flash_on_us(), LED_RIG_LIMITS.max_flash_on_us);
        assert!(plan.has_flash());
    }

    #[test]
    fn exposure_out_of_range() {
        assert_eq!(
            check(|c| c.exposure_us = 19),
            Err(RejectReason::ExposureOutOfRange)
        );
        assert_eq!(
            check(|c| c.exposure_us = 0),
            Err(RejectReason::ExposureOutOfRange)
        );
        assert_eq!(
            check(|c| c.exposure_us = 1_000_001),
            Err(RejectReason::ExposureOutOfRange)
        );
        let mut zero_min = LED_RIG_LIMITS;
        zero_min.min_exposure_us = 0;
        let mut c = good();
        c.exposure_us = 0;
        c.flash_duration_us = 0;
        c.flash_delay_us = 0;
        assert_eq!(
            CapturePlan::new(c, &zero_min),
            Err(RejectReason::ExposureOutOfRange)
        );
    }

    #[test]
    fn period_out_of_range() {
        assert_eq!(
            check(|c| c.frame_period_us = 20_019),
            Err(RejectReason::PeriodOutOfRange)
        );
        assert_eq!(
            check(|c| c.frame_period_us = 10_000_001),
            Err(RejectReason::PeriodOutOfRange)
        );
    }

    #[test]
    fn count_out_of_range() {
        assert_eq!(
            check(|c| c.pulses = PulseCount::Count(0)),
            Err(RejectReason::CountOutOfRange)
        );
        assert_eq!(
            check(|c| c.pulses = PulseCount::Count(100_001)),
            Err(RejectReason::CountOutOfRange)
        );
        assert!(check(|c| c.pulses = PulseCount::Count(100_000)).is_ok());
        assert!(check(|c| c.pulses = PulseCount::Continuous).is_ok());
    }

    #[test]
    fn flash_outside_exposure() {
        // Ends exactly at the end of the exposure: allowed.
        assert!(check(|c| c.flash_delay_us = 500).is_ok());
        assert_eq!(
            check(|c| c.flash_delay_us = 501),
            Err(RejectReason::FlashOutsideExposure)
        );
        assert_eq!(
            check(|c| {
                c.flash_delay_us = 1_001;
                c.flash_duration_us = 0;
            }),
            Err(RejectReason::FlashOutsideExposure)
        );
        // No u32 overflow sneaks a huge delay through.
        assert_eq!(
            check(|c| c.flash_delay_us = u32::MAX),
            Err(RejectReason::FlashOutsideExposure)
        );
    }

    #[test]
    fn flash_too_long() {
        let r = check(|c| {
            c.exposure_us = 10_000;
            c.flash_duration_us = 5_001;
            c.frame_period_us = 1_000_000;
        });
        assert_eq!(r, Err(RejectReason::FlashTooLong { max_us: 5_000 }));
        assert!(
            check(|c| {
                c.exposure_us = 10_000;
                c.flash_duration_us = 5_000;
                c.frame_period_us = 1_000_000;
            })
            .is_ok()
        );
    }

    #[test]
    fn duty_cycle_too_high() {
        // 5 ms flash needs ≥ 50 ms at 10 %.
        let with_period = |p| {
            check(|c| {
                c.exposure_us = 5_000;
                c.flash_delay_us = 0;
                c.flash_duration_us = 5_000;
                c.frame_period_us = p;
            })
        };
        assert!(with_period(50_000).is_ok());
        assert_eq!(
            with_period(49_999),
            Err(RejectReason::DutyCycleTooHigh { max_permille: 100 })
        );
    }

    #[test]
    fn period_too_short_names_the_minimum() {
        let r = check(|c| {
            c.exposure_us = 100_000;
            c.frame_period_us = 119_999;
        });
        assert_eq!(r, Err(RejectReason::PeriodTooShort { min_us: 120_000 }));
        assert!(
            check(|c| {
                c.exposure_us = 100_000;
                c.frame_period_us = 120_000;
            })
            .is_ok()
        );
    }

    #[test]
    fn checks_run_in_the_documented_order() {
        // Everything wrong at once: the exposure range is reported first, and so on down the table.
        let mut c = good();
        c.exposure_us = 0;
        c.frame_period_us = 1;
        c.pulses = PulseCount::Count(0);
        c.flash_delay_us = 10;
        c.flash_duration_us = 9_000;
        assert_eq!(
            CapturePlan::new(c, &LED_RIG_LIMITS),
            Err(RejectReason::ExposureOutOfRange)
        );
        c.exposure_us = 1_000;
        assert_eq!(
            CapturePlan::new(c, &LED_RIG_LIMITS),
            Err(RejectReason::PeriodOutOfRange)
        );
        c.frame_period_us = 20_100;
        assert_eq!(
            CapturePlan::new(c, &LED_RIG_LIMITS),
            Err(RejectReason::CountOutOfRange)
        );
        c.pulses = PulseCount::Continuous;
        assert_eq!(
            CapturePlan::new(c, &LED_RIG_LIMITS),
            Err(RejectReason::FlashOutsideExposure)
        );
        c.exposure_us = 9_500;
        assert_eq!(
            CapturePlan::new(c, &LED_RIG_LIMITS),
            Err(RejectReason::FlashTooLong { max_us: 5_000 })
        );
        c.flash_duration_us = 4_000;
        assert_eq!(
            CapturePlan::new(c, &LED_RIG_LIMITS),
            Err(RejectReason::DutyCycleTooHigh { max_permille: 100 })
        );
        c.flash_duration_us = 2_000;
        assert_eq!(
            CapturePlan::new(c, &LED_RIG_LIMITS),
            Err(RejectReason::PeriodTooShort { min_us: 29_500 })
        );
        c.frame_period_us = 29_500;
        assert!(CapturePlan::new(c, &LED_RIG_LIMITS).is_ok());
    }
}
