//! Executing the sequencer's edges one at a time: trigger rise, flash on (or its skip), flash off,
//! trigger fall, each with its lateness check, edge report and pulse bookkeeping (flash safety
//! rules 1–3 and the pulse spacing of the [sequencer docs](super)). Each handler runs only the
//! edge it names; [`Sequencer::poll`] decides what is due.

use ellipso_protocol::{
    BoardMessage, Fault, Output, PULSE_FLASH_FORCED_OFF, PULSE_FLASH_SKIPPED, PULSE_LATE,
    PULSE_NO_FLASH, TriggerSource,
};

use super::pulse::{Flash, Pulse, pulse_event, report_edge};
use super::{Capture, Sequencer, Step, schedule};
use crate::outputs::Outputs;
use crate::sink::MessageSink;

impl Sequencer {
    /// Runs the next edge if it is due.
    pub(super) fn step<O, S>(
        &mut self,
        cap: &mut Capture,
        now_us: u64,
        outputs: &mut O,
        sink: &mut S,
    ) -> Step
    where
        O: Outputs + ?Sized,
        S: MessageSink + ?Sized,
    {
        let Some(pulse) = cap.pulse else {
            return match cap.next_trigger_us {
                Some(due) if now_us >= due => {
                    self.camera_on(cap, due, now_us, outputs, sink);
                    Step::Progressed
                }
                _ => Step::Waiting,
            };
        };
        match pulse.flash {
            Flash::Pending { on_due_us } if now_us >= on_due_us => {
                self.flash_on_or_skip(cap, on_due_us, now_us, outputs, sink);
                Step::Progressed
            }
            Flash::On { off_due_us, .. } if now_us >= off_due_us => {
                self.flash_off(cap, now_us, outputs, sink);
                Step::Progressed
            }
            Flash::Done { .. } | Flash::NotFired { .. } if now_us >= pulse.camera_off_due_us => {
                self.camera_off(cap, now_us, outputs, sink)
            }
            _ => Step::Waiting,
        }
    }

    /// Raises the trigger (due at `due`, run at `now`): numbers the pulse, fixes its bracket
    /// step and plans its flash and camera-off edges.
    fn camera_on<O, S>(
        &mut self,
        cap: &mut Capture,
        due: u64,
        now: u64,
        outputs: &mut O,
        sink: &mut S,
    ) where
        O: Outputs + ?Sized,
        S: MessageSink + ?Sized,
    {
        outputs.set_camera(true, now);
        let plan = cap.plan;
        let seq = self.next_seq;
        self.next_seq += 1;
        let bracket_step = plan.step_of_pulse(cap.pulses_risen);
        cap.pulses_risen = cap.pulses_risen.saturating_add(1);
        let flash_planned_us = plan.step_on_time_us(bracket_step);
        let (flash, flags) = if flash_planned_us > 0 {
            (
                Flash::Pending {
                    on_due_us: now.saturating_add(u64::from(plan.flash_delay_us())),
                },
                0,
            )
        } else {
            (Flash::NotFired { t_us: now }, PULSE_NO_FLASH)
        };
        let mut pulse = Pulse {
            seq,
            t_trigger_us: now,
            camera_off_due_us: now.saturating_add(u64::from(plan.exposure_us())),
            flash,
            flags,
            bracket_step,
            flash_planned_us,
        };
        cap.next_trigger_us = None;
        cap.period_ready_us = cap
            .period_ready_us
            .max(now.saturating_add(u64::from(plan.frame_period_us())));
        report_edge(
            plan.report_edges(),
            sink,
            Output::CameraTrigger,
            true,
            now,
            seq,
        );
        self.check_late(&mut pulse, due, now, sink);
        cap.pulse = Some(pulse);
    }

    /// Lights the flash, or skips it when it would end after the exposure (safety rule 2).
    fn flash_on_or_skip<O, S>(
        &mut self,
        cap: &mut Capture,
        due: u64,
        now: u64,
        outputs: &mut O,
        sink: &mut S,
    ) where
        O: Outputs + ?Sized,
        S: MessageSink + ?Sized,
    {
        let plan = cap.plan;
        let Some(pulse) = cap.pulse.as_mut() else {
            return;
        };
        let planned_off = now.saturating_add(u64::from(pulse.flash_planned_us));
        if planned_off > pulse.camera_off_due_us {
            // Safety rule 2: it would end after the exposure; never light outside it.
            pulse.flash = Flash::NotFired { t_us: now };
            pulse.flags |= PULSE_FLASH_SKIPPED;
            self.counters.flash_skipped = self.counters.flash_skipped.saturating_add(1);
            sink.send(BoardMessage::Fault(Fault::FlashSkipped { seq: pulse.seq }));
            return;
        }
        outputs.flash_on(now, plan.max_flash_on_us());
        // Safety rule 1: the cap binds even if a plan ever allowed a longer flash.
        let cap_off = now.saturating_add(u64::from(plan.max_flash_on_us()));
        pulse.flash = Flash::On {
            t_on_us: now,
            off_due_us: planned_off.min(cap_off),
        };
        report_edge(
            plan.report_edges(),
            sink,
            Output::Flash,
            true,
            now,
            pulse.seq,
        );
        self.check_late(pulse, due, now, sink);
    }

    /// Turns a lit flash off and checks its on-time (safety rules 1 and 3).
    pub(super) fn flash_off<O, S>(
        &mut self,
        cap: &mut Capture,
        now: u64,
        outputs: &mut O,
        sink: &mut S,
    ) where
        O: Outputs + ?Sized,
        S: MessageSink + ?Sized,
    {
        let plan = cap.plan;
        let Some(pulse) = cap.pulse.as_mut() else {
            return;
        };
        let Flash::On {
            t_on_us,
            off_due_us,
        } = pulse.flash
        else {
            return;
        };
        outputs.flash_off(now);
        pulse.flash = Flash::Done {
            t_on_us,
            t_off_us: now,
        };
        report_edge(
            plan.report_edges(),
            sink,
            Output::Flash,
            false,
            now,
            pulse.seq,
        );
        self.check_late(pulse, off_due_us, now, sink);
        self.check_forced_off(pulse, t_on_us, now, plan.max_flash_on_us(), sink);
    }

    /// Safety rule 3: flags and reports a flash that was on longer than `max_on_us`.
    pub(super) fn check_forced_off<S: MessageSink + ?Sized>(
        &mut self,
        pulse: &mut Pulse,
        t_on_us: u64,
        now: u64,
        max_on_us: u32,
        sink: &mut S,
    ) {
        let on_for_us = now.saturating_sub(t_on_us);
        if on_for_us > u64::from(max_on_us) {
            pulse.flags |= PULSE_FLASH_FORCED_OFF;
            self.counters.flash_forced_off = self.counters.flash_forced_off.saturating_add(1);
            sink.send(BoardMessage::Fault(Fault::FlashForcedOff {
                seq: pulse.seq,
                on_for_us: u32::try_from(on_for_us).unwrap_or(u32::MAX),
            }));
        }
    }

    /// Lowers the trigger and sends the pulse event; completes a counted capture after its
    /// last pulse, or schedules a free run's next pulse.
    fn camera_off<O, S>(
        &mut self,
        cap: &mut Capture,
        now: u64,
        outputs: &mut O,
        sink: &mut S,
    ) -> Step
    where
        O: Outputs + ?Sized,
        S: MessageSink + ?Sized,
    {
        let plan = cap.plan;
        let Some(mut pulse) = cap.pulse.take() else {
            return Step::Waiting;
        };
        outputs.set_camera(false, now);
        report_edge(
            plan.report_edges(),
            sink,
            Output::CameraTrigger,
            false,
            now,
            pulse.seq,
        );
        let due = pulse.camera_off_due_us;
        self.check_late(&mut pulse, due, now, sink);
        self.camera_ready_us = self
            .camera_ready_us
            .max(now.saturating_add(u64::from(plan.readout_us())));
        sink.send(BoardMessage::Pulse(pulse_event(&pulse)));
        if plan
            .pulse_count()
            .is_some_and(|n| cap.pulses_scheduled >= n)
        {
            return Step::Complete;
        }
        if plan.trigger() == TriggerSource::FreeRun {
            let t = self.camera_ready_us.max(cap.period_ready_us);
            schedule(cap, t);
        }
        Step::Progressed
    }

    /// Flags and reports an edge run more than the late tolerance after `due`.
    fn check_late<S: MessageSink + ?Sized>(
        &mut self,
        pulse: &mut Pulse,
        due: u64,
        now: u64,
        sink: &mut S,
    ) {
        let late_by = now.saturating_sub(due);
        if late_by > u64::from(self.timing.late_tolerance_us) {
            pulse.flags |= PULSE_LATE;
            self.counters.late_edges = self.counters.late_edges.saturating_add(1);
            sink.send(BoardMessage::Fault(Fault::DeadlineMissed {
                seq: pulse.seq,
                late_by_us: u32::try_from(late_by).unwrap_or(u32::MAX),
            }));
        }
    }
}
