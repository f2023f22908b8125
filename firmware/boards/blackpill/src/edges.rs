//! Hardware-timed edges: TIM2 is both the 1 MHz device clock and the edge generator.
//!
//! # How an edge is placed
//!
//! After every call into the core, [`TimerOutputs::schedule`] looks at the core's next deadline
//! `D` and programs the matching TIM2 channel to move its pin **by itself** when `CNT = D`
//! (output compare, "set active/inactive on match"): the edge lands at timer-clock resolution
//! with no interrupt latency in it. The compare interrupt then calls `Board::poll` with the
//! compare time `D`, so the core records and reports the time the pin really moved; its own
//! writes through [`Outputs`] only *force* the level the hardware already set. A deadline closer
//! than [`MIN_LEAD_US`] cannot be left to the hardware any more (the counter could pass it while
//! the register is written): it is executed in software, and the core reports any lateness.
//!
//! # The flash cannot stay on
//!
//! [`Outputs::flash_on`] programs the flash channel to go **inactive on match** at
//! `t_on + max_on_us` before it returns, and the planned off-edge only moves that compare
//! earlier. From the moment the flash is lit, turning it off is the timer's job: a firmware that
//! hangs, a USB interrupt storm or a long critical section cannot keep the LED on past its
//! limit. (A hung core also stops re-arming the *on* edge, so no new flash starts.)
//!
//! # Bracketed pulse widths
//!
//! The flash's off-compare is the core's flash-off deadline, `t_on + w`, where `w` is the on-time
//! of the pulse's bracket step (`CapturePlan::step_on_time_us`; `flash_duration_us` without a
//! bracket). So the bracket sets the timer-compare pulse width directly: the on-edge and the
//! off-edge are both matches of TIM2 CH4 at 1 MHz, and the LED is lit for exactly `w` ticks
//! (± the compare unit's synchronisation, under one tick), whatever the step. Only a deadline
//! closer than [`MIN_LEAD_US`] falls back to software, and the core then reports the real time
//! and the real on-time in the pulse's `flash_on_us`.
//!
//! # Which edge is next
//!
//! The core exposes only the time of its next deadline; the edge follows from its state
//! ([`next_edge`]): trigger low → camera on; flash lit → flash off; otherwise the exposure end
//! `t_trigger + exposure_us` means camera off and anything earlier is the flash-on (a flash must
//! end inside the exposure, so its on-edge is always strictly before the exposure end).

use ellipso_firmware::{Outputs, Sequencer};
use embassy_stm32::pac;
use embassy_stm32::pac::timer::vals::Ocm;

/// TIM2 channel of the camera trigger: CH3 on PA2 (0-based index).
pub const CAMERA_CH: usize = 2;
/// TIM2 channel of the flash: CH4 on PA3 (0-based index).
pub const FLASH_CH: usize = 3;
/// Deadlines closer than this are executed in software: writing CCR and enabling the channel
/// takes well under 1 µs at 96 MHz, so 3 µs leaves margin for an interrupt arriving in between.
pub const MIN_LEAD_US: u64 = 3;

/// The next edge the core will execute.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NextEdge {
    /// Camera trigger rises (a new pulse).
    CameraOn,
    /// Flash lights.
    FlashOn,
    /// Flash goes off.
    FlashOff,
    /// Camera trigger falls (exposure end).
    CameraOff,
}

impl NextEdge {
    /// The TIM2 channel and the compare mode that produce this edge on match.
    pub fn channel_and_mode(self) -> (usize, Ocm) {
        match self {
            Self::CameraOn => (CAMERA_CH, Ocm::ACTIVE_ON_MATCH),
            Self::CameraOff => (CAMERA_CH, Ocm::INACTIVE_ON_MATCH),
            Self::FlashOn => (FLASH_CH, Ocm::ACTIVE_ON_MATCH),
            Self::FlashOff => (FLASH_CH, Ocm::INACTIVE_ON_MATCH),
        }
    }
}

/// Which edge the core's next deadline `deadline_us` belongs to; `t_trigger_us` is the time the
/// running pulse's trigger rose (see the [module docs](self)).
pub fn next_edge(seq: &Sequencer, t_trigger_us: u64, deadline_us: u64) -> NextEdge {
    if !seq.camera_high() {
        return NextEdge::CameraOn;
    }
    if seq.flash_on() {
        return NextEdge::FlashOff;
    }
    let exposure_us = seq.plan().map_or(0, |p| u64::from(p.exposure_us()));
    if deadline_us >= t_trigger_us.saturating_add(exposure_us) {
        NextEdge::CameraOff
    } else {
        NextEdge::FlashOn
    }
}

/// Starts TIM2 as a free-running 32-bit counter at 1 MHz with CH3/CH4 as forced-low outputs.
///
/// `timer_clock_hz` is TIM2's input clock (APB1 timer clock: `2 · f_APB1` when the APB1
/// prescaler is above 1, i.e. 96 MHz with the clock tree in `main.rs`); `PSC = timer_clock_hz /
/// 1 MHz − 1`.
pub fn start_tim2(timer_clock_hz: u32) {
    let tim = pac::TIM2;
    tim.cr1().modify(|w| w.set_cen(false));
    tim.psc()
        .write_value((timer_clock_hz / 1_000_000 - 1) as u16);
    tim.arr().write_value(u32::MAX);
    for ch in [CAMERA_CH, FLASH_CH] {
        set_mode(ch, Ocm::FORCE_INACTIVE);
        tim.ccer().modify(|w| {
            w.set_ccp(ch, false); // active high
            w.set_cce(ch, true);
        });
    }
    tim.egr().write(|w| w.set_ug(true)); // load PSC
    tim.sr().write_value(pac::timer::regs::SrGp16(0));
    tim.cr1().modify(|w| w.set_cen(true));
}

fn set_mode(ch: usize, mode: Ocm) {
    pac::TIM2
        .ccmr_output(ch / 2)
        .modify(|w| w.set_ocm(ch % 2, mode));
}

/// TIM2's raw count.
pub fn read_count() -> u32 {
    pac::TIM2.cnt().read()
}

/// The board's two outputs on TIM2 CH3 (camera) and CH4 (flash); see the [module docs](self).
#[derive(Debug, Default)]
pub struct TimerOutputs {
    t_trigger_us: u64,
}

impl TimerOutputs {
    /// Outputs whose channels [`start_tim2`] configured.
    pub const fn new() -> Self {
        Self { t_trigger_us: 0 }
    }

    /// Programs `edge` to happen in hardware at `deadline_us` (low 32 bits of the µs clock) and
    /// enables its compare interrupt.
    pub fn arm(&mut self, edge: NextEdge, deadline_us: u64) {
        let (ch, mode) = edge.channel_and_mode();
        let tim = pac::TIM2;
        tim.ccr(ch).write_value(deadline_us as u32);
        set_mode(ch, mode);
        tim.sr()
            .write_value(pac::timer::regs::SrGp16(!(1 << (ch + 1)))); // rc_w0: clear CCxIF
        tim.dier().modify(|w| w.set_ccie(ch, true));
    }

    /// Disables both compare interrupts (the channels keep their forced levels).
    pub fn disarm(&mut self) {
        pac::TIM2.dier().modify(|w| {
            w.set_ccie(CAMERA_CH, false);
            w.set_ccie(FLASH_CH, false);
        });
    }

    /// The time the running pulse's trigger rose.
    pub fn t_trigger_us(&self) -> u64 {
        self.t_trigger_us
    }
}

impl Outputs for TimerOutputs {
    fn set_camera(&mut self, high: bool, t_device_us: u64) {
        if high {
            self.t_trigger_us = t_device_us;
        }
        pac::TIM2.dier().modify(|w| w.set_ccie(CAMERA_CH, false));
        set_mode(
            CAMERA_CH,
            if high {
                Ocm::FORCE_ACTIVE
            } else {
                Ocm::FORCE_INACTIVE
            },
        );
    }

    fn flash_on(&mut self, t_device_us: u64, max_on_us: u32) {
        set_mode(FLASH_CH, Ocm::FORCE_ACTIVE);
        // The hardware cut-off: the timer drives the flash low at t_on + max_on_us whatever the
        // firmware does next. The planned (earlier) off-edge replaces this compare in `arm`.
        let cutoff_us = t_device_us.saturating_add(u64::from(max_on_us));
        self.arm(NextEdge::FlashOff, cutoff_us);
    }

    fn flash_off(&mut self, _t_device_us: u64) {
        pac::TIM2.dier().modify(|w| w.set_ccie(FLASH_CH, false));
        set_mode(FLASH_CH, Ocm::FORCE_INACTIVE);
    }
}
