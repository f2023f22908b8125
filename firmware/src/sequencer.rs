//! The sequencer: turns a [`CapturePlan`] into camera-trigger and flash edges at planned device
//! times, one pulse at a time, and reports each pulse.
//!
//! # Driving it
//!
//! The sequencer is pure: it never reads a clock. The caller passes the device time `now_us`
//! (µs of a monotonic 64-bit clock) into every call, asks [`Sequencer::next_deadline`] when the
//! next edge is due, and calls [`Sequencer::poll`] at (or after) that time. `poll` executes every
//! edge due at `now_us`, in order, on the [`Outputs`] and sends the resulting messages to the
//! [`MessageSink`]. The same code therefore runs
//! - on an MCU, from a compare/alarm ISR armed for `next_deadline()` (or a busy loop),
//! - in the simulator and in tests, by jumping simulated time straight to each deadline.
//!
//! A `poll` before the next deadline does nothing, so extra polls are harmless. Time must not go
//! backwards; if it does, nothing is due until it catches up (all arithmetic saturates).
//!
//! # One pulse
//!
//! With `t` the time the trigger edge actually ran, `e` = `exposure_us`, `d` = `flash_delay_us`,
//! `w` = the on-time of this pulse's bracket step ([`CapturePlan::step_on_time_us`]; without a
//! bracket `flash_duration_us`):
//!
//! | edge | due at |
//! |---|---|
//! | camera on | the planned trigger time (free run: the period grid; requests: `now + lead_us`) |
//! | flash on | `t + d` |
//! | flash off | `min(t_on + w, t_on + max_flash_on_us)`, `t_on` = when the flash actually lit |
//! | camera off | `t + e` |
//!
//! Every later edge is anchored to the *actual* earlier edge, so a late trigger shifts the whole
//! pulse but keeps the exposure length and the flash's place and energy (its on-time `w`) exact.
//!
//! # Bracket
//!
//! Pulse `k` of a capture (counting the triggers that rose since `start`, from 0) fires bracket
//! step `k mod len` ([`CapturePlan::step_of_pulse`]); the step is fixed when its trigger rises and
//! reported in its [`PulseEvent`](ellipso_protocol::PulseEvent) with the flash's actual on-time
//! (`t_flash_off_us − t_flash_on_us`, 0 when it did not light). A pulse cancelled before its
//! trigger rose takes no step, and each capture starts again at step 0. The safety rules below
//! hold per pulse with that pulse's own `w`.
//! Edges due at the same instant run in the order **camera on, flash on, flash off, camera off**
//! (a flash with `d = 0` lights right after the trigger; one ending at `e` goes off before the
//! trigger falls). The [`PulseEvent`](ellipso_protocol::PulseEvent) is sent when the trigger
//! falls, with every flag known; its times are those of the polls that executed the edges. When no flash fired, `t_flash_on_us =
//! t_flash_off_us` = the time that was decided (the trigger edge for `flash_duration_us = 0`, the
//! skip, or the stop).
//!
//! # Flash safety rules
//!
//! 1. The flash-off deadline is `min(planned off, actual on + max_flash_on_us)`, and every `poll`
//!    processes a due flash-off **first**, before anything else.
//! 2. If the flash-on deadline is met so late that `now + w` would end after the exposure
//!    (`t + e`), the flash is **skipped** for that pulse (`PULSE_FLASH_SKIPPED`,
//!    [`Fault::FlashSkipped`]) rather than lit outside the exposure. The flash is therefore never
//!    on while the trigger is low: it lights only while the trigger is high and goes off at or
//!    before the trigger falls.
//! 3. If the flash goes off after more than `max_flash_on_us` on (a missed off-deadline), the pulse
//!    gets `PULSE_FLASH_FORCED_OFF` and [`Fault::FlashForcedOff`] with the measured on-time.
//! 4. [`Sequencer::stop`] turns the flash off immediately (then the trigger), whatever the state.
//! 5. Software can only turn the flash off at the first poll after its deadline; a port with a
//!    one-pulse timer arms it in [`Outputs::flash_on`] with `max_on_us`, which is the
//!    silicon-level guarantee against a stuck loop.
//!
//! # Lateness
//!
//! An edge executed more than [`SequencerTiming::late_tolerance_us`] after its deadline sets
//! `PULSE_LATE` on its pulse, counts in [`SequencerCounters::late_edges`] and sends
//! [`Fault::DeadlineMissed`] with the lateness. A skipped flash is not an executed edge: it is
//! reported by rule 2 only.
//!
//! # Pulse spacing and sources
//!
//! A trigger never rises before `previous trigger + frame_period_us` (within a capture) nor before
//! `previous trigger fall + readout_us` (across captures: the sensor must finish reading out).
//! - [`TriggerSource::FreeRun`]: [`Sequencer::start`] schedules the first pulse at `now + lead_us`
//!   (or when the sensor is ready); each next one at the earliest allowed time, which is the
//!   period grid when on time. A late pulse delays the grid; missed slots are dropped, never
//!   fired in a burst.
//! - [`TriggerSource::HostCommand`] / [`TriggerSource::GripButton`]: [`Sequencer::request_pulse`]
//!   schedules one pulse at `now + lead_us`, or refuses with [`RejectReason::TooSoon`] naming the
//!   wait.
//! - A counted capture ends by itself when its last pulse's trigger falls (`poll` returns
//!   [`PollOutcome::Complete`]); a continuous one runs until [`Sequencer::stop`].
//!
//! Sequence numbers count trigger edges since construction (boot), from 0, never reused; a pulse
//! cancelled by `stop` before its trigger rose takes no number.
//!
//! [`Fault::FlashSkipped`]: ellipso_protocol::Fault::FlashSkipped
//! [`Fault::FlashForcedOff`]: ellipso_protocol::Fault::FlashForcedOff
//! [`Fault::DeadlineMissed`]: ellipso_protocol::Fault::DeadlineMissed

use ellipso_protocol::{
    BoardMessage, Output, PULSE_FLASH_SKIPPED, PULSE_STOPPED, RejectReason, TriggerSource,
};

use self::pulse::{Flash, Pulse, pulse_event, report_edge};
use crate::config::SequencerTiming;
use crate::outputs::Outputs;
use crate::plan::CapturePlan;
use crate::sink::MessageSink;

/// At most this many edges run in one `poll` (a pulse has 4; a late poll may finish one pulse and
/// start the next). Anything left stays due and runs at the next poll.
const MAX_STEPS_PER_POLL: usize = 16;

/// What a [`Sequencer::poll`] left behind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[must_use]
pub enum PollOutcome {
    /// No capture is running.
    Idle,
    /// The capture goes on.
    Running,
    /// This poll ended the last pulse of a counted capture; the sequencer is now idle.
    Complete,
}

/// Fault counters kept by the sequencer since construction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SequencerCounters {
    /// Edges executed later than the tolerance.
    pub late_edges: u32,
    /// Flashes that were on longer than `max_flash_on_us`.
    pub flash_forced_off: u32,
    /// Flashes skipped because their on-deadline was missed too late.
    pub flash_skipped: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Capture {
    plan: CapturePlan,
    /// Pulses scheduled in this capture (fired, in flight, or waiting to rise).
    pulses_scheduled: u32,
    /// The next trigger edge, planned, not yet risen.
    next_trigger_us: Option<u64>,
    /// The pulse whose trigger is high.
    pulse: Option<Pulse>,
    /// No trigger of this capture may rise before this (previous trigger + period).
    period_ready_us: u64,
    /// Triggers of this capture that rose so far (the next pulse's place in the bracket).
    pulses_risen: u64,
}

enum Step {
    Progressed,
    Waiting,
    Complete,
}

/// The pulse sequencer; see the [module docs](self).
#[derive(Debug, Clone)]
pub struct Sequencer {
    timing: SequencerTiming,
    capture: Option<Capture>,
    next_seq: u64,
    /// No trigger may rise before this (previous trigger fall + readout), across captures.
    camera_ready_us: u64,
    counters: SequencerCounters,
}

impl Sequencer {
    /// An idle sequencer; sequence numbers start at 0.
    pub const fn new(timing: SequencerTiming) -> Self {
        Self {
            timing,
            capture: None,
            next_seq: 0,
            camera_ready_us: 0,
            counters: SequencerCounters {
                late_edges: 0,
                flash_forced_off: 0,
                flash_skipped: 0,
            },
        }
    }

    /// The lead and tolerance in use.
    pub fn timing(&self) -> SequencerTiming {
        self.timing
    }

    /// Whether a capture is running.
    pub fn is_running(&self) -> bool {
        self.capture.is_some()
    }

    /// The running capture's plan.
    pub fn plan(&self) -> Option<&CapturePlan> {
        self.capture.as_ref().map(|c| &c.plan)
    }

    /// Trigger edges fired since construction (= the next sequence number).
    pub fn pulses_fired(&self) -> u64 {
        self.next_seq
    }

    /// Fault counters since construction.
    pub fn counters(&self) -> SequencerCounters {
        self.counters
    }

    /// Whether the flash is lit (by the sequencer's account).
    pub fn flash_on(&self) -> bool {
        matches!(self.pulse().map(|p| p.flash), Some(Flash::On { .. }))
    }

    /// Whether the camera trigger is high (by the sequencer's account).
    pub fn camera_high(&self) -> bool {
        self.pulse().is_some()
    }

    /// The earliest time the next trigger may rise, if a capture is running.
    pub fn earliest_trigger_us(&self) -> Option<u64> {
        self.capture
            .as_ref()
            .map(|c| self.camera_ready_us.max(c.period_ready_us))
    }

    fn pulse(&self) -> Option<&Pulse> {
        self.capture.as_ref().and_then(|c| c.pulse.as_ref())
    }

    /// Starts a capture at `now_us`; a free run schedules its first pulse at
    /// `max(now_us + lead_us, sensor ready)`. [`RejectReason::Busy`] if one is running.
    pub fn start(&mut self, plan: CapturePlan, now_us: u64) -> Result<(), RejectReason> {
        if self.capture.is_some() {
            return Err(RejectReason::Busy);
        }
        let mut capture = Capture {
            plan,
            pulses_scheduled: 0,
            next_trigger_us: None,
            pulse: None,
            period_ready_us: 0,
            pulses_risen: 0,
        };
        if plan.trigger() == TriggerSource::FreeRun {
            let t = now_us
                .saturating_add(u64::from(self.timing.lead_us))
                .max(self.camera_ready_us);
            schedule(&mut capture, t);
        }
        self.capture = Some(capture);
        Ok(())
    }

    /// Schedules one pulse at `now_us + lead_us` for a host-command or grip-button capture and
    /// returns its trigger time.
    ///
    /// Refusals, in order: [`RejectReason::NotArmed`] (no capture running),
    /// [`RejectReason::WrongTriggerSource`] (free run), [`RejectReason::Busy`] (a counted capture
    /// has all its pulses), [`RejectReason::TooSoon`] (the trigger would rise before the previous
    /// one + `frame_period_us`, or before the sensor has read out; `wait_us` is how much later to
    /// ask).
    pub fn request_pulse(&mut self, now_us: u64) -> Result<u64, RejectReason> {
        let camera_ready_us = self.camera_ready_us;
        let Some(cap) = self.capture.as_mut() else {
            return Err(RejectReason::NotArmed);
        };
        if cap.plan.trigger() == TriggerSource::FreeRun {
            return Err(RejectReason::WrongTriggerSource);
        }
        if cap
            .plan
            .pulse_count()
            .is_some_and(|n| cap.pulses_scheduled >= n)
        {
            return Err(RejectReason::Busy);
        }
        let t = now_us.saturating_add(u64::from(self.timing.lead_us));
        let earliest = camera_ready_us.max(cap.period_ready_us);
        if t < earliest {
            let wait_us = u32::try_from(earliest - t).unwrap_or(u32::MAX);
            return Err(RejectReason::TooSoon { wait_us });
        }
        schedule(cap, t);
        Ok(t)
    }

    /// When the next edge is due, device µs; `None` when idle or waiting for a request.
    pub fn next_deadline(&self) -> Option<u64> {
        let cap = self.capture.as_ref()?;
        match &cap.pulse {
            Some(p) => Some(match p.flash {
                Flash::Pending { on_due_us } => on_due_us,
                Flash::On { off_due_us, .. } => off_due_us,
                Flash::Done { .. } | Flash::NotFired { .. } => p.camera_off_due_us,
            }),
            None => cap.next_trigger_us,
        }
    }

    /// Executes every edge due at `now_us` (a due flash-off first), sending pulse events, faults
    /// and (with `report_edges`) edge reports to `sink`.
    pub fn poll<O, S>(&mut self, now_us: u64, outputs: &mut O, sink: &mut S) -> PollOutcome
    where
        O: Outputs + ?Sized,
        S: MessageSink + ?Sized,
    {
        let Some(mut cap) = self.capture.take() else {
            return PollOutcome::Idle;
        };
        // Safety rule 1: a due flash-off runs before anything else.
        if let Some(Flash::On { off_due_us, .. }) = cap.pulse.map(|p| p.flash) {
            if now_us >= off_due_us {
                self.flash_off(&mut cap, now_us, outputs, sink);
            }
        }
        for _ in 0..MAX_STEPS_PER_POLL {
            match self.step(&mut cap, now_us, outputs, sink) {
                Step::Progressed => {}
                Step::Waiting => break,
                Step::Complete => return PollOutcome::Complete,
            }
        }
        self.capture = Some(cap);
        PollOutcome::Running
    }

    /// Ends the capture now: flash off (always written, safety rule 4), then trigger low (always
    /// written). A pulse whose trigger had risen is still reported (its camera was triggered, so
    /// a frame may arrive), flagged `PULSE_STOPPED`: its times show the truncation, and a flash
    /// that had not lit yet is also flagged `PULSE_FLASH_SKIPPED` without a fault. A pulse that had not risen is cancelled.
    pub fn stop<O, S>(&mut self, now_us: u64, outputs: &mut O, sink: &mut S)
    where
        O: Outputs + ?Sized,
        S: MessageSink + ?Sized,
    {
        outputs.flash_off(now_us);
        outputs.set_camera(false, now_us);
        let Some(cap) = self.capture.take() else {
            return;
        };
        let Some(mut pulse) = cap.pulse else {
            return;
        };
        let report = cap.plan.report_edges();
        pulse.flags |= PULSE_STOPPED;
        match pulse.flash {
            Flash::On { t_on_us, .. } => {
                pulse.flash = Flash::Done {
                    t_on_us,
                    t_off_us: now_us,
                };
                report_edge(report, sink, Output::Flash, false, now_us, pulse.seq);
                // A stop after a missed off-deadline still ends an overlong flash: rule 3.
                let max_on_us = cap.plan.max_flash_on_us();
                self.check_forced_off(&mut pulse, t_on_us, now_us, max_on_us, sink);
            }
            Flash::Pending { .. } => {
                pulse.flash = Flash::NotFired { t_us: now_us };
                pulse.flags |= PULSE_FLASH_SKIPPED;
            }
            Flash::Done { .. } | Flash::NotFired { .. } => {}
        }
        report_edge(
            report,
            sink,
            Output::CameraTrigger,
            false,
            now_us,
            pulse.seq,
        );
        self.camera_ready_us = self
            .camera_ready_us
            .max(now_us.saturating_add(u64::from(cap.plan.readout_us())));
        sink.send(BoardMessage::Pulse(pulse_event(&pulse)));
    }
}

/// Plans the capture's next trigger at `t`.
fn schedule(cap: &mut Capture, t: u64) {
    cap.next_trigger_us = Some(t);
    cap.pulses_scheduled = cap.pulses_scheduled.saturating_add(1);
    cap.period_ready_us = cap
        .period_ready_us
        .max(t.saturating_add(u64::from(cap.plan.frame_period_us())));
}

mod edges;
mod pulse;
#[cfg(test)]
mod tests;
