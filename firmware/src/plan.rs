//! Capture plan: a [`CaptureConfig`] checked against the board's [`BoardLimits`].
//!
//! A [`CapturePlan`] can only be made by [`CapturePlan::new`], so holding one proves the
//! configuration passed every check below; the [`Sequencer`](crate::Sequencer) takes nothing else.
//!
//! # Flash on-times and the bracket
//!
//! Without a bracket every pulse lights the flash for `flash_duration_us` (0: no flash). With a
//! [`Bracket`] of relative energies `q_i` (Q15), `flash_duration_us` is the on-time of energy 1
//! and step `i` lights for `w_i = round(flash_duration_us · q_i / 32768)` µs (one device-clock
//! tick is 1 µs); pulse `k` of a capture fires step `k mod len`. The plan computes every `w_i`
//! once ([`CapturePlan::step_on_time_us`]), and the flash rules below apply to the **longest**
//! on-time the capture fires, `w_max` (`flash_duration_us` without a bracket), so each of them
//! holds for every step.
//!
//! # Checks, in order (the first failure is the reason reported)
//!
//! Field ranges come first, so a relational check never reasons about a value that is out of
//! range; then the bracket's steps; then the flash geometry; then LED safety; then sensor timing.
//!
//! | # | rule | [`RejectReason`] |
//! |---|---|---|
//! | 1 | `min_exposure_us ≤ exposure_us ≤ max_exposure_us` and `exposure_us ≥ 1` | `ExposureOutOfRange` |
//! | 2 | `min_frame_period_us ≤ frame_period_us ≤ max_frame_period_us` | `PeriodOutOfRange` |
//! | 3 | `Count(n)`: `1 ≤ n ≤ max_pulse_count` | `CountOutOfRange` |
//! | 4 | every step `1 ≤ q_i ≤ 0x8000` (energy in (0, 1]) | `BracketStepOutOfRange { step }` (the first) |
//! | 5 | every step `w_i ≥ 1` µs (a bracket needs a flash, and no step may round to nothing) | `BracketStepTooShort { step }` (the first) |
//! | 6 | `flash_delay_us + w_max ≤ exposure_us` (also when there is no flash) | `FlashOutsideExposure` |
//! | 7 | `w_max ≤ max_flash_on_us` | `FlashTooLong { max_us }` |
//! | 8 | `1000 · w_max ≤ max_flash_duty_permille · frame_period_us` | `DutyCycleTooHigh { max_permille }` |
//! | 9 | `frame_period_us ≥ exposure_us + readout_us` | `PeriodTooShort { min_us }` |
//!
//! All sums and products are computed in `u64`, so no input overflows. For the host-command and
//! grip-button triggers `frame_period_us` is the *minimum* spacing of pulses, so rule 8 bounds the
//! worst case; it bounds every single step's duty, not only the bracket's mean. `report_edges` and
//! the trigger source are not limited.

use ellipso_protocol::{
    BoardLimits, Bracket, CaptureConfig, ENERGY_ONE_Q15, MAX_BRACKET_STEPS, PulseCount,
    RejectReason, TriggerSource,
};

/// A validated capture configuration (see the [module docs](self) for the checks).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CapturePlan {
    config: CaptureConfig,
    readout_us: u32,
    max_flash_on_us: u32,
    /// Planned on-time of each step, µs (`[flash_duration_us]` without a bracket).
    on_times_us: [u32; MAX_BRACKET_STEPS],
}

impl CapturePlan {
    /// Checks `config` against `limits` in the documented order.
    pub fn new(config: CaptureConfig, limits: &BoardLimits) -> Result<Self, RejectReason> {
        let exposure = u64::from(config.exposure_us);
        let period = u64::from(config.frame_period_us);

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
        let on_times_us = on_times(config.flash_duration_us, &config.bracket)?;
        let longest = u64::from(on_times_us.iter().copied().max().unwrap_or(0));
        if u64::from(config.flash_delay_us) + longest > exposure {
            return Err(RejectReason::FlashOutsideExposure);
        }
        if longest > u64::from(limits.max_flash_on_us) {
            return Err(RejectReason::FlashTooLong {
                max_us: limits.max_flash_on_us,
            });
        }
        if 1000 * longest > u64::from(limits.max_flash_duty_permille) * period {
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
            on_times_us,
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

    /// Flash-on length of relative energy 1, µs; 0 means no flash. A bracketed pulse lights for
    /// [`CapturePlan::step_on_time_us`] instead.
    pub fn flash_duration_us(&self) -> u32 {
        self.config.flash_duration_us
    }

    /// Whether pulses light the flash.
    pub fn has_flash(&self) -> bool {
        self.config.flash_duration_us > 0
    }

    /// The flash-energy bracket ([`Bracket::NONE`] when every pulse is at energy 1).
    pub fn bracket(&self) -> Bracket {
        self.config.bracket
    }

    /// The bracket step pulse `pulse_in_capture` (from 0) fires.
    pub fn step_of_pulse(&self, pulse_in_capture: u64) -> u8 {
        self.config.bracket.step_of_pulse(pulse_in_capture)
    }

    /// Planned flash on-time of bracket step `step`, µs (`flash_duration_us` for step 0 without
    /// a bracket; 0 past the last step).
    pub fn step_on_time_us(&self, step: u8) -> u32 {
        if usize::from(step) >= self.config.bracket.cycle_len() {
            return 0;
        }
        self.on_times_us[usize::from(step)]
    }

    /// The longest on-time any pulse of this plan fires, µs (the one the flash rules check).
    pub fn longest_on_time_us(&self) -> u32 {
        self.on_times_us.iter().copied().max().unwrap_or(0)
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

/// Rules 4 and 5: the on-time of every step (unused slots 0), or the first bad step.
fn on_times(full_on_us: u32, bracket: &Bracket) -> Result<[u32; MAX_BRACKET_STEPS], RejectReason> {
    let mut on_times_us = [0u32; MAX_BRACKET_STEPS];
    if bracket.is_empty() {
        on_times_us[0] = full_on_us;
        return Ok(on_times_us);
    }
    for (step, &q) in bracket.steps_q15().iter().enumerate() {
        if q == 0 || q > ENERGY_ONE_Q15 {
            return Err(RejectReason::BracketStepOutOfRange { step: step as u8 });
        }
    }
    for (step, &q) in bracket.steps_q15().iter().enumerate() {
        // q ≤ 1.0, so the on-time is at most `full_on_us` and fits a u32.
        let w = Bracket::on_time_us(full_on_us, q);
        if w == 0 {
            return Err(RejectReason::BracketStepTooShort { step: step as u8 });
        }
        on_times_us[step] = u32::try_from(w).unwrap_or(full_on_us);
    }
    Ok(on_times_us)
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
            bracket: Bracket::NONE,
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

    fn bracket(steps: &[u16]) -> Bracket {
        Bracket::from_q15(steps).unwrap()
    }

    const QUARTER: u16 = 0x2000;
    const SIXTEENTH: u16 = 0x0800;

    #[test]
    fn a_bracket_gets_one_rounded_on_time_per_step() {
        let plan = check(|c| {
            c.exposure_us = 6_000;
            c.flash_duration_us = 5_000;
            c.bracket = bracket(&[ENERGY_ONE_Q15, QUARTER, SIXTEENTH]);
        })
        .unwrap();
        // 5000 · 1/16 = 312.5 → 313 (halves up)
        let w: [u32; 4] = core::array::from_fn(|i| plan.step_on_time_us(i as u8));
        assert_eq!(w, [5_000, 1_250, 313, 0]);
        assert_eq!(plan.longest_on_time_us(), 5_000);
        let steps: [u8; 5] = core::array::from_fn(|k| plan.step_of_pulse(k as u64));
        assert_eq!(steps, [0, 1, 2, 0, 1]);
        // Any order is accepted; without a bracket step 0 is the whole flash.
        let any_order = check(|c| c.bracket = bracket(&[SIXTEENTH, ENERGY_ONE_Q15])).unwrap();
        assert_eq!(any_order.step_on_time_us(0), 31);
        let none = check(|_| {}).unwrap();
        assert_eq!((none.step_on_time_us(0), none.step_on_time_us(1)), (500, 0));
    }

    #[test]
    fn bracket_steps_outside_0_to_1_name_the_first_bad_step() {
        assert_eq!(
            check(|c| c.bracket = bracket(&[ENERGY_ONE_Q15, 0, QUARTER])),
            Err(RejectReason::BracketStepOutOfRange { step: 1 })
        );
        assert_eq!(
            check(|c| c.bracket = bracket(&[ENERGY_ONE_Q15 + 1])),
            Err(RejectReason::BracketStepOutOfRange { step: 0 })
        );
        // Exactly 1.0 and the smallest non-zero step are in range.
        assert!(check(|c| c.bracket = bracket(&[ENERGY_ONE_Q15; MAX_BRACKET_STEPS])).is_ok());
        assert_eq!(
            check(|c| c.bracket = bracket(&[1])),
            Err(RejectReason::BracketStepTooShort { step: 0 })
        );
    }

    #[test]
    fn a_step_that_rounds_to_zero_ticks_is_refused() {
        // 7 µs · 1/16 = 0.44 µs → 0; 8 µs · 1/16 = 0.5 → 1.
        let with = |w| {
            check(|c| {
                c.flash_duration_us = w;
                c.bracket = bracket(&[ENERGY_ONE_Q15, QUARTER, SIXTEENTH]);
            })
        };
        assert_eq!(with(7), Err(RejectReason::BracketStepTooShort { step: 2 }));
        assert_eq!(with(8).unwrap().step_on_time_us(2), 1);
        // A bracket without a flash has nothing to scale.
        assert_eq!(with(0), Err(RejectReason::BracketStepTooShort { step: 0 }));
        // Range is checked for every step before rounding: the later out-of-range step wins.
        assert_eq!(
            check(|c| {
                c.flash_duration_us = 7;
                c.bracket = bracket(&[SIXTEENTH, 0]);
            }),
            Err(RejectReason::BracketStepOutOfRange { step: 1 })
        );
    }

    #[test]
    fn the_longest_step_must_fit_the_exposure() {
        // 1 ms exposure, flash at 100 µs: 900 µs fit. Energy 1 would be 1800 µs.
        let with = |steps: &[u16]| {
            check(|c| {
                c.flash_duration_us = 1_800;
                c.bracket = bracket(steps);
            })
        };
        assert_eq!(
            check(|c| c.flash_duration_us = 1_800),
            Err(RejectReason::FlashOutsideExposure)
        );
        let half = ENERGY_ONE_Q15 / 2;
        assert_eq!(with(&[half, QUARTER]).unwrap().longest_on_time_us(), 900);
        // 0.51 of 1800 µs = 918 µs: past the exposure's end.
        assert_eq!(
            with(&[QUARTER, 16_712]),
            Err(RejectReason::FlashOutsideExposure)
        );
        assert_eq!(
            with(&[ENERGY_ONE_Q15, QUARTER]),
            Err(RejectReason::FlashOutsideExposure)
        );
    }

    #[test]
    fn flash_safety_holds_for_every_step() {
        // Max on-time 5 ms: 0.5 of 8 ms passes, 0.75 does not.
        let with = |steps: &[u16], period| {
            check(|c| {
                c.exposure_us = 10_000;
                c.flash_delay_us = 0;
                c.flash_duration_us = 8_000;
                c.frame_period_us = period;
                c.bracket = bracket(steps);
            })
        };
        let half = ENERGY_ONE_Q15 / 2;
        assert!(with(&[half, QUARTER], 1_000_000).is_ok());
        assert_eq!(
            with(&[QUARTER, 0x6000], 1_000_000),
            Err(RejectReason::FlashTooLong { max_us: 5_000 })
        );
        // Duty 10 %: the 4 ms step needs 40 ms whatever the shorter steps average to.
        assert!(with(&[half, QUARTER], 40_000).is_ok());
        assert_eq!(
            with(&[half, QUARTER], 39_999),
            Err(RejectReason::DutyCycleTooHigh { max_permille: 100 })
        );
        assert!(with(&[QUARTER], 39_999).is_ok());
    }
}
