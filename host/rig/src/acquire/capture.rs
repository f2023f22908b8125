//! One capture: trigger board + camera → a recorded, paired session.
//!
//! Threads and queues (every queue bounded, every loss counted):
//! ```text
//! camera thread ──frames (bounded, `frame_queue`)──▶ writer pool ──written──▶ main loop ◀── link events
//!   (drains the camera's buffers)                    (PNG encode, parallel)   (pairing, log, progress)
//! ```
//! - The camera thread only moves frames from the camera into the queue, so slow disk or slow
//!   processing never starves the camera's own buffers until the queue is full; then the camera
//!   reports underruns (counted in its [`CameraCounters`](crate::camera::CameraCounters)),
//!   never silently.
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
//!
//! Here: the start (board, clock, camera, threads) and the wind-down; the plan, progress, report
//! and error types are in `api`, the main loop in `main_loop`.

mod api;
mod main_loop;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, Sender, bounded, unbounded};
use ellipso_protocol::PulseCount;

pub use api::{CaptureError, CapturePlan, CaptureProgress, CaptureReport};

use super::pairing::FrameArrival;
use crate::camera::{Camera, CameraClockSample, CameraCounters, CameraError, Frame, FrameStatus};
use crate::link::clock::ClockFit;
use crate::link::{LinkError, TriggerLink, describe_reject};
use ellipso_session::SessionError;
use ellipso_session::events::SessionEvent;
use main_loop::LoopState;

use super::board_record::board_config_record;
use ellipso_session::writer::{FrameRecord, PreparedFrame, SessionWriter};

/// A frame the writer pool has prepared (PNG encoded under a temporary name, not yet committed),
/// for the main loop.
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

/// What the start measured before streaming: the device→host clock fit and the tightest
/// latches of the camera's clock.
struct Started {
    clock: ClockFit,
    latches: Vec<CameraClockSample>,
}

/// The running threads of a capture (camera thread → bounded queue → writer pool → main loop).
struct Pipeline {
    /// Set to stop the camera thread.
    camera_stop: Arc<AtomicBool>,
    /// Frames the camera has exposed but not yet delivered, as its thread last read them.
    in_flight: Arc<AtomicU64>,
    /// The camera thread; it returns the camera's counters.
    camera_thread: JoinHandle<CameraCounters>,
    /// The writer pool.
    writers: Vec<JoinHandle<()>>,
    /// Frames the writer pool has prepared, for the main loop.
    written: Receiver<Result<Written, SessionError>>,
}

fn record(
    link: &TriggerLink,
    mut camera: Box<dyn Camera>,
    session: &mut SessionWriter,
    plan: &CapturePlan,
    stop: &AtomicBool,
    mut progress: impl FnMut(&CaptureProgress),
) -> Result<CaptureReport, CaptureError> {
    let started = Instant::now();
    let Started { clock, latches } = start_devices(link, camera.as_mut(), session, plan)?;
    let Pipeline {
        camera_stop,
        in_flight,
        camera_thread,
        writers,
        written: written_rx,
    } = spawn_pipeline(camera, session, plan)?;

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
    wind_up(
        link,
        session,
        state,
        &written_rx,
        end_reason,
        camera_counters,
        started,
    )
}

/// The start, logged: the board's identity, the clock fit, the camera configured and its clock
/// latched, the camera started, then the board configured (a refusal is logged with why).
fn start_devices(
    link: &TriggerLink,
    camera: &mut dyn Camera,
    session: &mut SessionWriter,
    plan: &CapturePlan,
) -> Result<Started, CaptureError> {
    let clock_now = || link.host_clock().now();
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
    Ok(Started { clock, latches })
}

/// Starts the camera thread (it owns `camera` from here) and the writer pool, joined by a queue
/// of `plan.frame_queue` frames.
fn spawn_pipeline(
    mut camera: Box<dyn Camera>,
    session: &SessionWriter,
    plan: &CapturePlan,
) -> Result<Pipeline, CaptureError> {
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
                .spawn(move || write_frames(&rx, &tx, &dir))
        })
        .collect::<Result<_, _>>()
        .map_err(|e| CameraError::Stream {
            device: "writer threads".into(),
            reason: e.to_string(),
        })?;
    drop((frame_rx, written_tx));
    Ok(Pipeline {
        camera_stop,
        in_flight,
        camera_thread,
        writers,
        written: written_rx,
    })
}

/// A writer thread: each frame from `rx` prepared (PNG encoded) under `dir` and handed to the
/// main loop on `tx`, until either side closes.
fn write_frames(
    rx: &Receiver<Frame>,
    tx: &Sender<Result<Written, SessionError>>,
    dir: &std::path::Path,
) {
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
        let r = SessionWriter::prepare_frame(dir, record).map(|prepared| Written {
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
}

/// After the threads are joined: the frames still in `written_rx` committed and paired, the
/// pairing finished and logged, the link counters logged, and the report.
fn wind_up(
    link: &TriggerLink,
    session: &mut SessionWriter,
    mut state: LoopState,
    written_rx: &Receiver<Result<Written, SessionError>>,
    end_reason: String,
    camera_counters: CameraCounters,
    started: Instant,
) -> Result<CaptureReport, CaptureError> {
    let clock_now = || link.host_clock().now();
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
