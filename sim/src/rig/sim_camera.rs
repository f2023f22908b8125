//! The simulated camera's threads: decide per trigger edge ([`CameraCore`]), render through a
//! [`FrameSource`] on worker threads, and deliver [`SimFrame`]s in exposure order.
//!
//! Contract:
//! - Frames come out in the order of their exposures, duplicates right after their original,
//!   whatever order the renderers finish in.
//! - Each frame is rendered at the flash energy its exposure collected
//!   ([`FlashMeter`], with [`SimCameraConfig::flash_reference_us`]); metering holds a plan until
//!   its trigger falls, a few ms.
//! - Rendering may be slower than real time: each frame carries its simulated `arrival` instant,
//!   so the consumer sees camera-realistic latency even when the simulator lags. With
//!   [`SimCameraConfig::pace_to_arrival`] a frame is also held until that instant.
//! - Nothing is ever dropped because the consumer or the renderers are slow: the camera waits
//!   (bounded queues) and counts each wait in [`CameraCounters::backpressure_waits`]. Trigger
//!   edges queue up meanwhile (the wire is unbounded), so the board is never stalled.
//! - The threads end when the trigger wire's senders are gone and every frame is delivered, or
//!   when the consumer drops [`SimCamera::frames`]'s receiver.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Instant;

use crossbeam_channel::{Receiver, Sender, TrySendError};

use super::RigError;
use super::camera::{
    CameraCore, CameraCounters, FramePlan, FrameStatus, PIXELS_PER_PACKET, SimCameraConfig,
};
use super::flash_meter::FlashMeter;
use super::wire::TriggerEdge;

/// What a simulated camera renders through (the renderer, or a cheap test pattern).
pub trait FrameSource: Send + Sync {
    /// Width and height of every frame, pixels.
    fn frame_size(&self) -> (u32, u32);
    /// The raw frame (row-major, `width · height` values) of capture pose `pose_index`, with
    /// `frame_seed` for its noise, lit by `flash_energy_rel` of a full flash pulse (≥ 0; 1 is
    /// the scene as described). Must be a pure function of its arguments.
    fn render(&self, pose_index: usize, frame_seed: u64, flash_energy_rel: f64) -> Vec<u16>;
}

/// A test [`FrameSource`]: pixel 0 holds the pose index (low 16 bits), pixels 1–4 the frame seed
/// (16 bits each, least significant first), pixel 5 the flash energy in units of 1/10 000
/// (rounded, saturating), every other pixel the pose index again.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PoseIndexSource {
    /// Frame width, pixels.
    pub width: u32,
    /// Frame height, pixels.
    pub height: u32,
}

impl PoseIndexSource {
    /// Reads back `(pose index, frame seed)` from a frame it rendered (None if smaller than 5 px).
    pub fn decode(pixels: &[u16]) -> Option<(u16, u64)> {
        let seed = pixels
            .get(1..5)?
            .iter()
            .rev()
            .fold(0u64, |acc, &w| (acc << 16) | u64::from(w));
        Some((pixels[0], seed))
    }

    /// Reads back the flash energy it was rendered with (to 1/10 000; None if under 6 px).
    pub fn decode_energy(pixels: &[u16]) -> Option<f64> {
        pixels.get(5).map(|&e| f64::from(e) / ENERGY_SCALE)
    }
}

/// Pixel 5 of a [`PoseIndexSource`] frame holds `round(energy × ENERGY_SCALE)`.
const ENERGY_SCALE: f64 = 10_000.0;

impl FrameSource for PoseIndexSource {
    fn frame_size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    fn render(&self, pose_index: usize, frame_seed: u64, flash_energy_rel: f64) -> Vec<u16> {
        let n = self.width as usize * self.height as usize;
        let mut px = vec![pose_index as u16; n];
        for (i, p) in px.iter_mut().enumerate().skip(1).take(4) {
            *p = (frame_seed >> (16 * (i - 1))) as u16;
        }
        if let Some(p) = px.get_mut(5) {
            // `as` saturates: NaN → 0, above 6.5 → 65535.
            *p = (flash_energy_rel * ENERGY_SCALE).round() as u16;
        }
        px
    }
}

/// Ground truth a real camera would not give, for scoring the host's pairing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameTruth {
    /// Exposures before this one.
    pub exposure_index: u64,
    /// Pose rendered.
    pub pose_index: usize,
    /// Renderer seed.
    pub frame_seed: u64,
    /// The trigger edge that started it, board device µs.
    pub t_trigger_device_us: u64,
    /// This is the second delivery of the same frame.
    pub duplicate: bool,
    /// Extra latency of a late frame, µs.
    pub late_by_us: u32,
    /// Flash energy the exposure collected, relative to a full pulse (what it was rendered at).
    pub flash_energy_rel: f64,
    /// Flash on-time inside the exposure, µs (`None` without flash metering).
    pub flash_lit_us: Option<f64>,
}

/// One delivered frame.
#[derive(Debug, Clone, PartialEq)]
pub struct SimFrame {
    /// The camera's 16-bit block id (wraps 65535 → 1).
    pub block_id: u16,
    /// Exposure start on the camera's own clock, ns.
    pub t_camera_ns: u64,
    /// Simulated arrival at the host (host monotonic clock).
    pub arrival: Instant,
    /// Frame width, pixels.
    pub width: u32,
    /// Frame height, pixels.
    pub height: u32,
    /// Raw pixels, row-major.
    pub pixels: Vec<u16>,
    /// Whole or flagged.
    pub status: FrameStatus,
    /// What really happened (not available from a real camera).
    pub truth: FrameTruth,
}

/// A running simulated camera; see the [module docs](self).
pub struct SimCamera {
    frames: Receiver<SimFrame>,
    counters: Arc<Mutex<CameraCounters>>,
    threads: Vec<JoinHandle<()>>,
    camera_clock: super::clock::LinearClock,
}

fn lock(c: &Mutex<CameraCounters>) -> MutexGuard<'_, CameraCounters> {
    c.lock().unwrap_or_else(|p| p.into_inner())
}

impl SimCamera {
    /// Starts a camera that exposes on the rising edges of `edges` and renders through `source`.
    pub fn spawn(
        config: SimCameraConfig,
        source: Arc<dyn FrameSource>,
        edges: Receiver<TriggerEdge>,
    ) -> Result<Self, RigError> {
        let (w, h) = source.frame_size();
        let pixel_count = w as usize * h as usize;
        let mut core = CameraCore::new(config, pixel_count)?;
        let counters = Arc::new(Mutex::new(CameraCounters::default()));
        let (job_tx, job_rx) =
            crossbeam_channel::bounded::<(u64, FramePlan)>(config.render_workers);
        let (done_tx, done_rx) =
            crossbeam_channel::bounded::<(u64, SimFrame)>(config.render_workers);
        let (out_tx, frames) = crossbeam_channel::bounded(config.queue_frames);
        let spawn = |name: &str, f: Box<dyn FnOnce() + Send>| {
            std::thread::Builder::new()
                .name(name.into())
                .spawn(f)
                .map_err(|e| RigError::Io {
                    what: format!("camera thread {name}"),
                    source: e,
                })
        };
        let mut threads = Vec::new();
        {
            let counters = counters.clone();
            let mut meter = FlashMeter::new(config.flash_reference_us, config.timing.exposure_us);
            threads.push(spawn(
                "sim-camera-plan",
                Box::new(move || {
                    let mut index = 0u64;
                    let mut send = |plan: FramePlan| {
                        let sent = send_waiting(&job_tx, (index, plan), &counters);
                        index += 1;
                        sent
                    };
                    for edge in edges.iter() {
                        let plan = core.on_edge(edge);
                        sync_counters(&counters, &core);
                        for plan in meter.on_edge(edge, plan) {
                            if !send(plan) {
                                return;
                            }
                        }
                    }
                    if let Some(plan) = meter.finish() {
                        send(plan);
                    }
                }),
            )?);
        }
        for i in 0..config.render_workers {
            let (job_rx, done_tx, source, counters) = (
                job_rx.clone(),
                done_tx.clone(),
                source.clone(),
                counters.clone(),
            );
            threads.push(spawn(
                &format!("sim-camera-render-{i}"),
                Box::new(move || {
                    for (index, plan) in job_rx.iter() {
                        let frame = render(&*source, plan, &counters);
                        if done_tx.send((index, frame)).is_err() {
                            return;
                        }
                    }
                }),
            )?);
        }
        drop((job_rx, done_tx));
        {
            let counters = counters.clone();
            let pace = config.pace_to_arrival;
            threads.push(spawn(
                "sim-camera-deliver",
                Box::new(move || deliver(&done_rx, &out_tx, pace, &counters)),
            )?);
        }
        Ok(Self {
            frames,
            counters,
            threads,
            camera_clock: config.camera_clock,
        })
    }

    /// The camera's timestamp counter now, ns (the clock of [`SimFrame::t_camera_ns`]): what a
    /// GigE camera's `GevTimestampControlLatch` + `GevTimestampValue` read back.
    pub fn latch_timestamp_ns(&self) -> u64 {
        self.camera_clock.at_ns(std::time::Instant::now())
    }

    /// Delivered frames, in exposure order; disconnects after the last one.
    pub fn frames(&self) -> &Receiver<SimFrame> {
        &self.frames
    }

    /// Counters so far.
    pub fn counters(&self) -> CameraCounters {
        *lock(&self.counters)
    }

    /// Waits for every thread (the wire must be closed or the frames receiver dropped first,
    /// or this waits for ever) and returns the final counters.
    pub fn join(mut self) -> CameraCounters {
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
        self.counters()
    }
}

impl std::fmt::Debug for SimCamera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimCamera")
            .field("counters", &self.counters())
            .finish_non_exhaustive()
    }
}

fn sync_counters(shared: &Mutex<CameraCounters>, core: &CameraCore) {
    let c = core.counters();
    let mut s = lock(shared);
    let (delivered, waits, size_errors) = (s.delivered, s.backpressure_waits, s.render_size_errors);
    *s = c;
    s.delivered = delivered;
    s.backpressure_waits = waits;
    s.render_size_errors = size_errors;
}

/// Sends, waiting (and counting the wait) when the queue is full; false if the receiver is gone.
fn send_waiting<T>(tx: &Sender<T>, item: T, counters: &Mutex<CameraCounters>) -> bool {
    match tx.try_send(item) {
        Ok(()) => true,
        Err(TrySendError::Full(item)) => {
            lock(counters).backpressure_waits += 1;
            tx.send(item).is_ok()
        }
        Err(TrySendError::Disconnected(_)) => false,
    }
}

fn render(source: &dyn FrameSource, plan: FramePlan, counters: &Mutex<CameraCounters>) -> SimFrame {
    let (width, height) = source.frame_size();
    let n = width as usize * height as usize;
    let mut pixels = source.render(plan.pose_index, plan.frame_seed, plan.flash_energy_rel);
    if pixels.len() != n {
        lock(counters).render_size_errors += 1;
        pixels.resize(n, 0);
    }
    for &start in &plan.missing_packet_starts {
        let end = (start + PIXELS_PER_PACKET).min(n);
        if let Some(packet) = pixels.get_mut(start..end) {
            packet.fill(0);
        }
    }
    SimFrame {
        block_id: plan.block_id,
        t_camera_ns: plan.t_camera_ns,
        arrival: plan.arrival,
        width,
        height,
        pixels,
        status: plan.status,
        truth: FrameTruth {
            exposure_index: plan.exposure_index,
            pose_index: plan.pose_index,
            frame_seed: plan.frame_seed,
            t_trigger_device_us: plan.t_trigger_device_us,
            duplicate: plan.duplicate,
            late_by_us: plan.late_by_us,
            flash_energy_rel: plan.flash_energy_rel,
            flash_lit_us: plan.flash_lit_us,
        },
    }
}

fn deliver(
    done: &Receiver<(u64, SimFrame)>,
    out: &Sender<SimFrame>,
    pace: bool,
    counters: &Mutex<CameraCounters>,
) {
    let mut pending = BTreeMap::new();
    let mut next = 0u64;
    for (index, frame) in done.iter() {
        pending.insert(index, frame);
        while let Some(frame) = pending.remove(&next) {
            next += 1;
            if pace {
                let wait = frame.arrival.saturating_duration_since(Instant::now());
                std::thread::sleep(wait);
            }
            let copy = frame.truth.duplicate.then(|| frame.clone());
            let first = SimFrame {
                truth: super::sim_camera::FrameTruth {
                    duplicate: false,
                    ..frame.truth
                },
                ..frame
            };
            for f in std::iter::once(first).chain(copy) {
                if !send_waiting(out, f, counters) {
                    return;
                }
                lock(counters).delivered += 1;
            }
        }
    }
}
