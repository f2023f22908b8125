//! The capture's main loop: it owns the session log while the capture runs — link events
//! (pulses with their flash, faults, the board's end, a disconnect), frames as the writer pool
//! hands them over (committed, then paired), pairing outcomes and errors, the clock model slid
//! along by pings, periodic link counters and progress — and decides when the capture ends.
//!
//! Contract (termination, as the `capture` module doc): a counted capture ends once the board
//! reports its last pulse and every pulse is paired or a grace period without frames in flight
//! has passed; any capture on the `stop` flag (after draining frames already exposed), on a
//! link disconnect, when the camera stream ends, or at `max_duration`. Each pulse's bracket step
//! and flash on-time are kept by sequence number until it is paired or given up.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, select};
use ellipso_protocol::BoardState;

use super::super::pairing::{Pairer, PairingConfig, PairingOutcome, Pulse};
use super::{CapturePlan, CaptureProgress, Written};
use crate::link::clock::ClockFit;
use crate::link::{LinkEvent, TriggerLink};
use ellipso_session::SessionError;
use ellipso_session::events::SessionEvent;
use ellipso_session::time::{DeviceTimeUs, HostTimeUs};
use ellipso_session::writer::SessionWriter;

pub(super) struct LoopState {
    pub(super) pairer: Pairer,
    /// The device→host clock fit, refreshed by pings during the capture.
    pub(super) clock: ClockFit,
    expected: Option<u64>,
    pub(super) pulses: u64,
    pub(super) flagged: u64,
    pub(super) faults: u64,
    board_done: bool,
    done_since: Option<Instant>,
    /// What each pulse not yet paired (or given up) lit its frame with, by sequence number.
    light: HashMap<u64, PulseLight>,
    /// The on-time of relative energy 1, µs (the capture's `flash_duration_us`).
    full_on_us: u32,
    pub(super) paired_per_step: Vec<u64>,
}

/// A pulse's flash as the board reported it.
#[derive(Debug, Clone, Copy)]
struct PulseLight {
    bracket_step: u8,
    flash_on_us: u32,
}

impl PulseLight {
    /// `flash_on_us / full_on_us`; 0 for a capture without a flash.
    fn energy_rel(&self, full_on_us: u32) -> f64 {
        if full_on_us == 0 {
            0.0
        } else {
            f64::from(self.flash_on_us) / f64::from(full_on_us)
        }
    }
}

impl LoopState {
    pub(super) fn new(plan: &CapturePlan, expected: Option<u64>, clock: ClockFit) -> Self {
        let pairing: PairingConfig = plan.pairing;
        Self {
            pairer: Pairer::new(pairing),
            clock,
            expected,
            pulses: 0,
            flagged: 0,
            faults: 0,
            board_done: false,
            done_since: None,
            light: HashMap::new(),
            full_on_us: plan.board.flash_duration_us,
            paired_per_step: vec![0; plan.board.bracket.cycle_len()],
        }
    }

    #[expect(
        clippy::too_many_arguments,
        reason = "one call site; the loop's whole context"
    )]
    pub(super) fn run(
        &mut self,
        link: &TriggerLink,
        session: &mut SessionWriter,
        written: &Receiver<Result<Written, SessionError>>,
        plan: &CapturePlan,
        stop: &AtomicBool,
        started: Instant,
        in_flight: &AtomicU64,
        progress: &mut impl FnMut(&CaptureProgress),
    ) -> Result<String, SessionError> {
        let mut events = link.events().clone();
        let mut written = written.clone();
        let mut ending: Option<(String, Instant)> = None;
        let mut camera_ended = false;
        let now = || link.host_clock().now();
        // after the last pulse, frames may still be in flight for up to the pulse timeout
        let grace =
            Duration::from_micros(plan.pairing.max_latency_us as u64) + Duration::from_secs(1);
        let mut last_progress = Instant::now();
        let mut last_ping = Instant::now();
        let mut last_fit_log = Instant::now();
        loop {
            if stop.load(Ordering::Acquire) && ending.is_none() {
                // stop the pulses now; frames already exposed are still collected below
                if let Err(e) = link.stop() {
                    tracing::warn!("stopping the trigger board: {e}");
                }
                ending = Some(("stopped by user".into(), Instant::now()));
            }
            if camera_ended {
                // drain link events queued or about to be (a disconnect explains why frames
                // stopped, and its event may trail the camera's end by a moment)
                while let Ok(ev) = events.recv_timeout(Duration::from_millis(200)) {
                    if let Some(reason) = self.on_link_event(ev, session, now())? {
                        ending.get_or_insert((reason, Instant::now()));
                    }
                }
                let reason = ending
                    .as_ref()
                    .map_or("camera stream ended".to_string(), |e| e.0.clone());
                return Ok(reason);
            }
            // Ending (user stop, link gone): keep collecting frames already exposed until the
            // camera has none in flight and a frame's worth of latency has passed, then end.
            if let Some((reason, since)) = &ending {
                let drained = in_flight.load(Ordering::Acquire) == 0
                    && since.elapsed() > Duration::from_micros(plan.pairing.max_latency_us as u64);
                if drained || since.elapsed() > 2 * grace {
                    return Ok(reason.clone());
                }
            }
            if started.elapsed() > plan.max_duration {
                return Ok(format!(
                    "time limit of {} s reached",
                    plan.max_duration.as_secs()
                ));
            }
            if let Some(t) = self.done_since {
                let all_in = self
                    .expected
                    .is_some_and(|n| self.pairer.counts().paired >= n);
                // frames still on their way (a camera behind real time) keep the capture open
                let settled = t.elapsed() > grace && in_flight.load(Ordering::Acquire) == 0;
                if all_in || settled {
                    return Ok("completed".into());
                }
            }
            select! {
                recv(events) -> ev => match ev {
                    Ok(ev) => {
                        if let Some(reason) = self.on_link_event(ev, session, now())? {
                            ending.get_or_insert((reason, Instant::now()));
                        }
                    }
                    Err(_) => {
                        events = crossbeam_channel::never();
                        ending.get_or_insert(("trigger link closed".into(), Instant::now()));
                    }
                },
                recv(written) -> w => match w {
                    Ok(w) => self.on_written(w?, session)?,
                    Err(_) => {
                        // every frame is in: end now, with the link's reason if it has one
                        written = crossbeam_channel::never();
                        camera_ended = true;
                    }
                },
                default(Duration::from_millis(50)) => {}
            }
            let outcomes = self.pairer.expire(Some(&self.clock));
            // keep the clock model current: a short initial fit extrapolates badly over a
            // capture of minutes; a ping every 250 ms slides it along
            if ending.is_none() && last_ping.elapsed() > Duration::from_millis(250) {
                last_ping = Instant::now();
                if link.ping().is_ok()
                    && let Some(fit) = link.clock_fit()
                {
                    if last_fit_log.elapsed() > Duration::from_secs(5) {
                        last_fit_log = Instant::now();
                        session.log(&SessionEvent::ClockFit {
                            t_host_us: now(),
                            gain: fit.gain,
                            offset_us: fit.offset_us,
                            rms_us: fit.rms_us,
                            n_samples: fit.n_samples,
                        })?;
                        // link counters along the way too, so a live view sees link errors
                        // while they happen rather than at the end
                        session.log(&SessionEvent::Link {
                            t_host_us: now(),
                            counters: link.counters(),
                        })?;
                    }
                    self.clock = fit;
                }
            }
            self.log_outcomes(&outcomes, session, now())?;
            if last_progress.elapsed() > Duration::from_millis(100) {
                last_progress = Instant::now();
                let c = self.pairer.counts();
                let frames = session.frames_written();
                progress(&CaptureProgress {
                    pulses: self.pulses,
                    frames,
                    expected: self.expected,
                    paired: c.paired,
                    pairing_errors: c.frame_without_pulse
                        + c.pulse_without_frame
                        + c.duplicate_frames
                        + c.duplicate_pulses,
                    camera_drops: self.flagged,
                    fps: frames as f64 / started.elapsed().as_secs_f64().max(1e-3),
                });
            }
        }
    }

    /// Handles one link event; `Some(reason)` ends the capture.
    fn on_link_event(
        &mut self,
        ev: LinkEvent,
        session: &mut SessionWriter,
        t: HostTimeUs,
    ) -> Result<Option<String>, SessionError> {
        match ev {
            LinkEvent::Pulse { event, t_host_recv } => {
                self.pulses += 1;
                session.log(&SessionEvent::Pulse {
                    t_host_us: t_host_recv,
                    seq: event.seq,
                    t_trigger_device_us: DeviceTimeUs(event.t_trigger_us),
                    t_flash_on_device_us: DeviceTimeUs(event.t_flash_on_us),
                    t_flash_off_device_us: DeviceTimeUs(event.t_flash_off_us),
                    flags: event.flags,
                    bracket_step: event.bracket_step,
                    flash_on_us: Some(event.flash_on_us),
                })?;
                self.light.insert(
                    event.seq,
                    PulseLight {
                        bracket_step: event.bracket_step,
                        flash_on_us: event.flash_on_us,
                    },
                );
                let pulse = Pulse {
                    seq: event.seq,
                    t_trigger: DeviceTimeUs(event.t_trigger_us),
                    t_host_recv,
                };
                let out = self.pairer.add_pulse(pulse, Some(&self.clock));
                self.log_outcomes(&out, session, t)?;
                if self.expected.is_some_and(|n| self.pulses >= n) {
                    self.mark_done();
                }
            }
            LinkEvent::Fault { fault, t_host_recv } => {
                self.faults += 1;
                session.log(&SessionEvent::Fault {
                    t_host_us: t_host_recv,
                    what: format!("{fault:?}"),
                })?;
            }
            LinkEvent::Status(s) => {
                if self.expected.is_some() && s.state == BoardState::Configured {
                    self.mark_done();
                }
            }
            LinkEvent::Edge(_) => {}
            LinkEvent::Disconnected { reason } => {
                session.log(&SessionEvent::Disconnected {
                    t_host_us: t,
                    reason: reason.clone(),
                })?;
                return Ok(Some(format!("trigger link disconnected: {reason}")));
            }
        }
        Ok(None)
    }

    fn mark_done(&mut self) {
        if !self.board_done {
            self.board_done = true;
            self.done_since = Some(Instant::now());
        }
    }

    pub(super) fn on_written(
        &mut self,
        w: Written,
        session: &mut SessionWriter,
    ) -> Result<(), SessionError> {
        session.commit_frame(w.prepared)?;
        if w.flagged {
            self.flagged += 1;
        }
        let out = self.pairer.add_frame(w.arrival, Some(&self.clock));
        self.log_outcomes(&out, session, w.arrival.t_host_arrival)
    }

    pub(super) fn log_outcomes(
        &mut self,
        outcomes: &[PairingOutcome],
        session: &mut SessionWriter,
        t: HostTimeUs,
    ) -> Result<(), SessionError> {
        for o in outcomes {
            let (kind, frame_id, seq, reason) = match *o {
                PairingOutcome::Paired {
                    frame_id,
                    pulse,
                    latency_us,
                    basis,
                } => {
                    let light = self.light.remove(&pulse.seq);
                    if let Some(n) = light
                        .and_then(|l| self.paired_per_step.get_mut(usize::from(l.bracket_step)))
                    {
                        *n += 1;
                    }
                    session.log(&SessionEvent::Pairing {
                        t_host_us: t,
                        frame_id,
                        seq: pulse.seq,
                        latency_us: Some(latency_us),
                        basis: serde_json::to_value(basis)
                            .ok()
                            .and_then(|v| v.as_str().map(str::to_string)),
                        bracket_step: light.map(|l| l.bracket_step),
                        flash_on_us: light.map(|l| l.flash_on_us),
                        flash_energy_rel: light.map(|l| l.energy_rel(self.full_on_us)),
                    })?;
                    continue;
                }
                PairingOutcome::FrameWithoutPulse { frame_id, reason } => (
                    "frame_without_pulse",
                    Some(frame_id),
                    None,
                    Some(reason.as_str().to_string()),
                ),
                PairingOutcome::PulseWithoutFrame { seq } => {
                    self.light.remove(&seq);
                    ("pulse_without_frame", None, Some(seq), None)
                }
                PairingOutcome::DuplicateFrame { frame_id } => {
                    ("duplicate_frame", Some(frame_id), None, None)
                }
                PairingOutcome::DuplicatePulse { seq } => {
                    ("duplicate_pulse", None, Some(seq), None)
                }
            };
            session.log(&SessionEvent::PairingError {
                t_host_us: t,
                kind: kind.into(),
                frame_id,
                seq,
                reason,
            })?;
        }
        Ok(())
    }
}
