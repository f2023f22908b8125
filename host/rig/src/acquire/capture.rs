//! One capture: trigger board + camera → a recorded, paired session.
//!
//! Threads and queues (every queue bounded, every loss counted):
//! ```text
//! camera thread ──frames (bounded, `frame_queue`)──▶ writer pool ──written──▶ main loop ◀── link events
//!   (drains the camera's buffers)                    (PNG encode, parallel)   (pairing, log, progress)
//! ```
//! - The camera thread only moves frames from the camera into the queue, so slow disk or slow
//!   processing never starves the camera's own buffers until the queue is full; then the camera
//!   reports underruns (counted in its [`CameraCounters`]), never silently.
//! - The main loop owns the session log: pulses, frames (after their PNG is in place), pairings
//!   and pairing errors, faults, link counters, the end. Pose tracking and fitting run after the
//!   recorder, never on this path.
//! - A disconnect of the trigger link ends the capture cleanly: frames already queued are
//!   written, pending pairs are resolved, and the session's end record says what happened.
//!
//! Termination: a counted capture ends once the board reports its last pulse and every pulse is
//! paired or timed out; a continuous one on the `stop` flag; any capture at `max_duration`.
//!
//! Flash-energy bracket: each pulse's bracket step and actual flash on-time (from its `Pulse`
//! report) are kept by sequence number until the pulse is paired or given up, and written on the
//! frame's `pairing` event with its relative energy, `flash_on_us / flash_duration_us`. The
//! pairer matches frames to pulses by id and timing only; a frame inherits whatever its pulse
//! really fired, so a lost frame or pulse never shifts another frame's step.

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, bounded, select, unbounded};
use ellipso_protocol::{BoardState, CaptureConfig, PulseCount};

use super::pairing::{FrameArrival, Pairer, PairingConfig, PairingCounts, PairingOutcome, Pulse};
use crate::camera::{
    Camera, CameraClockSample, CameraCounters, CameraError, CameraSettings, Frame, FrameStatus,
};
use crate::link::clock::ClockFit;
use crate::link::{LinkCounters, LinkError, LinkEvent, TriggerLink, describe_reject};
use ellipso_session::SessionError;
use ellipso_session::events::SessionEvent;

use super::board_record::board_config_record;
use ellipso_session::time::{DeviceTimeUs, HostTimeUs};
use ellipso_session::writer::{FrameRecord, PreparedFrame, SessionWriter};

/// What to capture and how.
#[derive(Debug, Clone)]
pub struct CapturePlan {
    /// Timing sent to the trigger board.
    pub board: CaptureConfig,
    /// Camera settings.
    pub camera: CameraSettings,
    /// Pings for the clock model before starting.
    pub clock_sync_pings: usize,
    /// Pairing windows.
    pub pairing: PairingConfig,
    /// Frames that may wait between camera and disk.
    pub frame_queue: usize,
    /// PNG encoder threads.
    pub writer_threads: usize,
    /// Hard stop.
    pub max_duration: Duration,
}

/// Live figures for a progress display.
#[derive(Debug, Clone, Copy, Default)]
pub struct CaptureProgress {
    /// Pulses the board reported.
    pub pulses: u64,
    /// Frames written.
    pub frames: u64,
    /// Pulses expected (counted captures).
    pub expected: Option<u64>,
    /// Frames paired.
    pub paired: u64,
    /// Pairing errors of any kind.
    pub pairing_errors: u64,
    /// Frames the camera lost or flagged (underruns + missing packets + other).
    pub camera_drops: u64,
    /// Frames written per second since start.
    pub fps: f64,
}

/// What happened, for the summary and the closing figures.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CaptureReport {
    /// Why it ended.
    pub end_reason: String,
    /// Wall time, s.
    pub duration_s: f64,
    /// Pulses reported by the board.
    pub pulses: u64,
    /// Frames written.
    pub frames: u64,
    /// Frames delivered flagged (kept, never fitted).
    pub flagged: u64,
    /// Pairing outcome counts.
    pub pairing: PairingCounts,
    /// Trigger-link counters.
    pub link: LinkCounters,
    /// Camera counters.
    pub camera: CameraCounters,
    /// Faults the board reported.
    pub board_faults: u64,
    /// Clock fit used for pairing.
    pub clock: Option<ClockFit>,
    /// Paired frames per bracket step (one entry without a bracket).
    pub paired_per_step: Vec<u64>,
}

/// Why a capture could not run (problems during a running capture end it cleanly instead).
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// The trigger board refused or failed a command before the capture started.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The camera failed before the capture started.
    #[error(transparent)]
    Camera(#[from] CameraError),
    /// The session could not be written.
    #[error(transparent)]
    Session(#[from] SessionError),
    /// The clock model did not settle.
    #[error("the trigger board's clock did not settle after up to {pings} pings; check the link")]
    ClockNotSettled {
        /// Pings sent.
        pings: usize,
    },
}

struct Written {
    prepared: PreparedFrame,
    arrival: FrameArrival,
    flagged: bool,
}

/// Latch readings of the camera's counter taken before streaming; the tightest brackets win.
const CAMERA_CLOCK_SAMPLES: usize = 8;

/// Runs one capture into `session`; returns the report and the session directory.
///
/// The session always ends with an end record: a capture that fails after the session was
/// created (the board refuses the configuration, the camera fails to start, the disk fills)
/// records `failed: <why>` rather than looking like a crash.
pub fn capture(
    link: &TriggerLink,
    camera: Box<dyn Camera>,
    mut session: SessionWriter,
    plan: &CapturePlan,
    stop: &AtomicBool,
    progress: impl FnMut(&CaptureProgress),
) -> Result<(CaptureReport, std::path::PathBuf), CaptureError> {
    match record(link, camera, &mut session, plan, stop, progress) {
        Ok(report) => {
            let dir = session.finish(link.host_clock().now(), &report.end_reason)?;
            Ok((report, dir))
        }
        Err(e) => {
            let reason = format!("failed: {e}");
            if let Err(finish) = session.finish(link.host_clock().now(), &reason) {
                tracing::warn!("recording why the capture failed: {finish}");
            }
            Err(e)
        }
    }
}

fn record(
    link: &TriggerLink,
    mut camera: Box<dyn Camera>,
    session: &mut SessionWriter,
    plan: &CapturePlan,
    stop: &AtomicBool,
    mut progress: impl FnMut(&CaptureProgress),
) -> Result<CaptureReport, CaptureError> {
    let clock_now = || link.host_clock().now();
    let started = Instant::now();
    let board = link.board();
    session.log(&SessionEvent::Board {
        t_host_us: clock_now(),
        name: board.board_name.to_string(),
        firmware: format!(
            "{}.{}.{}",
            board.firmware_version.major,
            board.firmware_version.minor,
            board.firmware_version.patch
        ),
        protocol_version: board.protocol_version,
    })?;
    let clock = link
        .sync_clock(plan.clock_sync_pings)?
        .ok_or(CaptureError::ClockNotSettled {
            pings: plan.clock_sync_pings * (1 + crate::link::SYNC_EXTRA_PING_FACTOR),
        })?;
    session.log(&SessionEvent::ClockFit {
        t_host_us: clock_now(),
        gain: clock.gain,
        offset_us: clock.offset_us,
        rms_us: clock.rms_us,
        n_samples: clock.n_samples,
    })?;

    camera.configure(&plan.camera)?;
    // the camera's clock model: exposure timestamps then pair frames at any frame rate
    let mut latches: Vec<CameraClockSample> = (0..CAMERA_CLOCK_SAMPLES)
        .filter_map(|_| camera.clock_sample())
        .collect();
    latches.sort_by_key(|s| s.t_host_after.0.saturating_sub(s.t_host_before.0));
    latches.truncate(2);
    for l in &latches {
        session.log(&SessionEvent::CameraClock {
            t_host_us: clock_now(),
            t_camera_ns: l.t_camera_ns,
            t_host_before_us: l.t_host_before,
            t_host_after_us: l.t_host_after,
        })?;
    }
    camera.start()?;
    link.configure(plan.board).map_err(|e| match e {
        LinkError::Rejected { reason, .. } => {
            tracing::error!("capture refused: {}", describe_reject(&reason));
            e
        }
        other => other,
    })?;
    session.log(&SessionEvent::Configured {
        t_host_us: clock_now(),
        config: board_config_record(&plan.board),
    })?;

    // camera thread → bounded queue → writer pool → main loop
    let camera_stop = Arc::new(AtomicBool::new(false));
    let in_flight = Arc::new(AtomicU64::new(0));
    let (frame_tx, frame_rx) = bounded::<Frame>(plan.frame_queue.max(1));
    let camera_thread = {
        let (camera_stop, in_flight) = (camera_stop.clone(), in_flight.clone());
        thread::Builder::new().name("camera".into()).spawn(move || {
            while !camera_stop.load(Ordering::Acquire) {
                let next = camera.next_frame(Duration::from_millis(50));
                in_flight.store(camera.frames_in_flight(), Ordering::Release);
                match next {
                    Ok(Some(frame)) => {
                        if frame_tx.send(frame).is_err() {
                            break;
                        }
                    }
                    Ok(None) => {}
                    Err(CameraError::EndOfStream) => break,
                    Err(e) => {
                        tracing::error!("{e}");
                        break;
                    }
                }
            }
            let _ = camera.stop();
            camera.counters()
        })
    }
    .map_err(|e| CameraError::Stream {
        device: "camera thread".into(),
        reason: e.to_string(),
    })?;
    let (written_tx, written_rx) = unbounded::<Result<Written, SessionError>>();
    let frames_dir = session.frames_dir();
    let writers: Vec<_> = (0..plan.writer_threads.max(1))
        .map(|i| {
            let (rx, tx, dir) = (frame_rx.clone(), written_tx.clone(), frames_dir.clone());
            thread::Builder::new()
                .name(format!("frame-writer-{i}"))
                .spawn(move || {
                    for frame in rx.iter() {
                        let m = &frame.meta;
                        let flagged = match &m.status {
                            FrameStatus::Complete => None,
                            FrameStatus::Flagged(r) => Some(r.as_str()),
                        };
                        let record = FrameRecord {
                            t_host_us: m.t_host_us,
                            frame_id: m.frame_id,
                            t_camera_ns: m.t_camera_ns,
                            exposure_us: m.exposure_us,
                            gain_db: m.gain_db,
                            width: m.width,
                            height: m.height,
                            pixels: &frame.pixels,
                            flagged,
                        };
                        let r =
                            SessionWriter::prepare_frame(&dir, record).map(|prepared| Written {
                                prepared,
                                arrival: FrameArrival {
                                    frame_id: m.frame_id,
                                    t_host_arrival: m.t_host_us,
                                    t_camera_ns: m.t_camera_ns,
                                },
                                flagged: flagged.is_some(),
                            });
                        if tx.send(r).is_err() {
                            break;
                        }
                    }
                })
        })
        .collect::<Result<_, _>>()
        .map_err(|e| CameraError::Stream {
            device: "writer threads".into(),
            reason: e.to_string(),
        })?;
    drop((frame_rx, written_tx));

    if let Err(e) = link.arm().and_then(|()| link.start()) {
        camera_stop.store(true, Ordering::Release);
        let _ = camera_thread.join();
        for w in writers {
            let _ = w.join();
        }
        return Err(e.into());
    }

    let expected = match plan.board.pulses {
        PulseCount::Count(n) => Some(u64::from(n)),
        PulseCount::Continuous => None,
    };
    let mut state = LoopState::new(plan, expected, clock.clone());
    for l in &latches {
        state.pairer.add_camera_clock_sample(l);
    }
    let ended = state.run(
        link,
        session,
        &written_rx,
        plan,
        stop,
        started,
        &in_flight,
        &mut progress,
    );
    // wind down — also after an error (a full disk): stop the board (idempotent), then the
    // camera, then drain what is in flight
    if link.is_connected()
        && let Err(e) = link.stop()
    {
        tracing::warn!("stopping the trigger board: {e}");
    }
    camera_stop.store(true, Ordering::Release);
    let camera_counters = camera_thread.join().unwrap_or_default();
    for w in writers {
        let _ = w.join();
    }
    let end_reason = ended?;
    for w in written_rx.try_iter() {
        state.on_written(w?, session)?;
    }
    let outcomes = state.pairer.finish(Some(&state.clock));
    state.log_outcomes(&outcomes, session, clock_now())?;
    let counters = link.counters();
    session.log(&SessionEvent::Link {
        t_host_us: clock_now(),
        counters,
    })?;
    let report = CaptureReport {
        end_reason: end_reason.clone(),
        duration_s: started.elapsed().as_secs_f64(),
        pulses: state.pulses,
        frames: session.frames_written(),
        flagged: state.flagged,
        pairing: state.pairer.counts(),
        link: counters,
        camera: camera_counters,
        board_faults: state.faults,
        clock: Some(state.clock.clone()),
        paired_per_step: state.paired_per_step.clone(),
    };
    Ok(report)
}

struct LoopState {
    pairer: Pairer,
    /// The device→host clock fit, refreshed by pings during the capture.
    clock: ClockFit,
    expected: Option<u64>,
    pulses: u64,
    flagged: u64,
    faults: u64,
    board_done: bool,
    done_since: Option<Instant>,
    /// What each pulse not yet paired (or given up) lit its frame with, by sequence number.
    light: HashMap<u64, PulseLight>,
    /// The on-time of relative energy 1, µs (the capture's `flash_duration_us`).
    full_on_us: u32,
    paired_per_step: Vec<u64>,
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
    fn new(plan: &CapturePlan, expected: Option<u64>, clock: ClockFit) -> Self {
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
    fn run(
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

    fn on_written(&mut self, w: Written, session: &mut SessionWriter) -> Result<(), SessionError> {
        session.commit_frame(w.prepared)?;
        if w.flagged {
            self.flagged += 1;
        }
        let out = self.pairer.add_frame(w.arrival, Some(&self.clock));
        self.log_outcomes(&out, session, w.arrival.t_host_arrival)
    }

    fn log_outcomes(
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
