//! The simulated camera's decisions: which trigger edges expose, which block id each frame gets,
//! its timestamps, and which faults hit it. Pure and seeded; the threads that render and deliver
//! are in [`sim_camera`](super::sim_camera).
//!
//! Contract of [`CameraCore::on_edge`]:
//! - Falling edges are ignored (the exposure length is the camera's own setting, as in
//!   "timed" trigger mode), and so are flash edges (light, not a trigger; they are metered by
//!   [`FlashMeter`](super::flash_meter::FlashMeter)); each rising trigger edge yields at most
//!   one [`FramePlan`], at flash energy 1 until the meter sets it.
//! - A **missed trigger** takes no exposure and no block id (the camera never saw it).
//! - Every exposure takes the next block id, emulating GigE Vision 1.x 16-bit ids: they start at
//!   [`SimCameraConfig::first_block_id`] (65401 by default so the wrap shows within 135 frames)
//!   and go 65535 → 1, never 0.
//! - Pose index = exposures so far (from 0) mod the pose count; frame seed =
//!   [`frame_seed`]`(seed, exposure index)`: the image depends on the exposure, never on faults.
//! - A **dropped** frame consumes its block id and exposure but yields no plan; a **duplicate**
//!   yields one plan with `duplicate = true` (delivered twice with the same block id); a **late**
//!   frame arrives `late_extra_us` later; an **incomplete** one is flagged with 1–3 missing
//!   packets, which are zeroed.
//! - Every rising edge draws the same number of values from each fault's own stream whether
//!   the fault fires or not (see [`seeds`](super::seeds)).

use std::time::{Duration, Instant};

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use ellipso_protocol::Output;

use super::RigError;
use super::clock::LinearClock;
use super::seeds::{FaultStream, fault_rng, frame_seed};
use super::wire::TriggerEdge;

/// The camera's exposure and delivery timing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraTiming {
    /// Exposure length, µs.
    pub exposure_us: u32,
    /// Trigger edge → exposure start, µs (≤ one line time on an IMX250: 6.25 µs).
    pub trigger_delay_us: u32,
    /// Sensor readout after the exposure, µs.
    pub readout_us: u32,
    /// Transfer of a frame to the host, µs.
    pub transfer_us: u32,
    /// Standard deviation of the transfer time, µs (Gaussian; the total is clamped at ≥ 0).
    pub transfer_jitter_us: f64,
}

impl Default for CameraTiming {
    /// 1 ms exposure, 6 µs trigger delay, 20 ms readout, 44 ms transfer (5 MB over GigE at
    /// ≈ 115 MB/s) with 0.5 ms jitter.
    fn default() -> Self {
        Self {
            exposure_us: 1_000,
            trigger_delay_us: 6,
            readout_us: 20_000,
            transfer_us: 44_000,
            transfer_jitter_us: 500.0,
        }
    }
}

/// Per-frame fault probabilities and sizes.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CameraFaults {
    /// Probability the camera ignores a rising edge.
    pub missed_trigger_probability: f64,
    /// Probability an exposed frame is lost in transfer.
    pub drop_probability: f64,
    /// Probability a frame is delivered twice.
    pub duplicate_probability: f64,
    /// Probability a frame arrives late.
    pub late_probability: f64,
    /// Extra latency of a late frame, µs.
    pub late_extra_us: u32,
    /// Probability a frame arrives with missing packets.
    pub incomplete_probability: f64,
    /// Standard deviation of the exposure start around trigger edge + delay, µs (Gaussian; the
    /// exposure never starts before the edge).
    pub trigger_jitter_sigma_us: f64,
}

impl CameraFaults {
    /// Refuses probabilities outside [0, 1) and negative or non-finite jitter.
    pub fn check(&self) -> Result<(), RigError> {
        for (name, p) in [
            (
                "missed_trigger_probability",
                self.missed_trigger_probability,
            ),
            ("drop_probability", self.drop_probability),
            ("duplicate_probability", self.duplicate_probability),
            ("late_probability", self.late_probability),
            ("incomplete_probability", self.incomplete_probability),
        ] {
            if !(0.0..1.0).contains(&p) {
                return Err(RigError::Parameter {
                    name,
                    value: p,
                    expected: "a probability in [0, 1)",
                });
            }
        }
        if !(self.trigger_jitter_sigma_us.is_finite() && self.trigger_jitter_sigma_us >= 0.0) {
            return Err(RigError::Parameter {
                name: "trigger_jitter_sigma_us",
                value: self.trigger_jitter_sigma_us,
                expected: "finite and ≥ 0",
            });
        }
        Ok(())
    }
}

/// Settings of a simulated camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimCameraConfig {
    /// Scene seed: frame seeds and fault streams derive from it.
    pub seed: u64,
    /// Number of capture poses; exposure `k` renders pose `k mod pose_count`.
    pub pose_count: usize,
    /// Block id of the first frame (1..=65535; GigE forbids 0).
    pub first_block_id: u16,
    /// Exposure and delivery timing.
    pub timing: CameraTiming,
    /// Faults.
    pub faults: CameraFaults,
    /// The trigger board's clock: maps an edge's device time to the host instant it happened
    /// (ground truth a real camera does not have; used only to place the exposure in time).
    pub board_clock: LinearClock,
    /// The camera's own timestamp counter (its `t_camera_ns` clock).
    pub camera_clock: LinearClock,
    /// Render threads.
    pub render_workers: usize,
    /// Frames the delivery queue holds before the camera waits for its consumer.
    pub queue_frames: usize,
    /// Hold each frame until its simulated arrival instant before delivering it.
    pub pace_to_arrival: bool,
    /// On-time of a full-energy flash pulse, µs — the pulse the scene's radiometry describes
    /// (the capture's `flash_duration_us`). With it the camera meters the flash's light on the
    /// wire and renders each frame at `lit time inside the exposure / reference`; `None` renders
    /// every frame at energy 1 and ignores flash edges.
    pub flash_reference_us: Option<u32>,
}

impl SimCameraConfig {
    /// Defaults: first block id 65401, [`CameraTiming::default`], no faults, a camera clock that
    /// has been up one hour and runs 12 ppm slow (against the host; the board's runs 25 ppm fast
    /// by default), 2 render workers, an 8-frame queue, no pacing.
    pub fn new(seed: u64, pose_count: usize, board_clock: LinearClock) -> Self {
        let camera_clock =
            LinearClock::new(board_clock.epoch(), 3_600_000_000, -12.0).unwrap_or(board_clock);
        Self {
            seed,
            pose_count,
            first_block_id: 65_401,
            timing: CameraTiming::default(),
            faults: CameraFaults::default(),
            board_clock,
            camera_clock,
            render_workers: 2,
            queue_frames: 8,
            pace_to_arrival: false,
            flash_reference_us: None,
        }
    }

    /// Defaults plus the scene's seed, pose count, exposure (`rig.camera.exposure_us`), frame
    /// drops (`effects.frame_drops`) and trigger jitter (`effects.trigger_jitter`).
    pub fn from_scene(scene: &crate::scene::Scene, board_clock: LinearClock) -> Self {
        let mut c = Self::new(scene.seed, scene.camera_poses.len(), board_clock);
        // Validated by the scene as positive and bounded; the cast saturates regardless.
        c.timing.exposure_us = scene.rig.camera.exposure_us.round().max(1.0) as u32;
        if let Some(d) = scene.effects.frame_drops {
            c.faults.drop_probability = d.probability;
        }
        if let Some(j) = scene.effects.trigger_jitter {
            c.faults.trigger_jitter_sigma_us = j.sigma_us;
        }
        c
    }

    /// Refuses settings no camera could have.
    pub fn check(&self) -> Result<(), RigError> {
        self.faults.check()?;
        let count_err = |name, value: usize| RigError::Parameter {
            name,
            value: value as f64,
            expected: "at least 1",
        };
        if self.pose_count == 0 {
            return Err(count_err("pose_count", 0));
        }
        if self.render_workers == 0 {
            return Err(count_err("render_workers", 0));
        }
        if self.queue_frames == 0 {
            return Err(count_err("queue_frames", 0));
        }
        if self.flash_reference_us == Some(0) {
            return Err(RigError::Parameter {
                name: "flash_reference_us",
                value: 0.0,
                expected: "at least 1 µs (or none: no flash metering)",
            });
        }
        if self.first_block_id == 0 {
            return Err(RigError::Parameter {
                name: "first_block_id",
                value: 0.0,
                expected: "1..=65535 (GigE Vision reserves block id 0)",
            });
        }
        if !(self.timing.transfer_jitter_us.is_finite() && self.timing.transfer_jitter_us >= 0.0) {
            return Err(RigError::Parameter {
                name: "transfer_jitter_us",
                value: self.timing.transfer_jitter_us,
                expected: "finite and ≥ 0",
            });
        }
        Ok(())
    }
}

/// Whether a frame arrived whole.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameStatus {
    /// Every packet arrived.
    Complete,
    /// Some packets never arrived; their pixels are zero.
    Flagged {
        /// Packets missing.
        missing_packets: u32,
    },
}

/// Pixels per GigE stream packet (8 KiB payload of 16-bit pixels) for the missing-packet model.
pub const PIXELS_PER_PACKET: usize = 4_096;

/// One frame the camera will deliver.
#[derive(Debug, Clone, PartialEq)]
pub struct FramePlan {
    /// The camera's 16-bit block id.
    pub block_id: u16,
    /// Exposures before this one (ground truth).
    pub exposure_index: u64,
    /// Pose rendered.
    pub pose_index: usize,
    /// Renderer seed.
    pub frame_seed: u64,
    /// The trigger edge that started it, board device µs (ground truth).
    pub t_trigger_device_us: u64,
    /// Exposure start on the camera's own clock, ns.
    pub t_camera_ns: u64,
    /// Exposure start, host instant (ground truth).
    pub exposure_start: Instant,
    /// Exposure start, board device µs (edge + trigger delay + jitter; fractional).
    pub exposure_start_device_us: f64,
    /// Flash energy the exposure collected, relative to a full pulse (1 until metered).
    pub flash_energy_rel: f64,
    /// Flash on-time inside the exposure, µs (`None` until metered).
    pub flash_lit_us: Option<f64>,
    /// When the frame arrives at the host, host instant.
    pub arrival: Instant,
    /// Whole or flagged.
    pub status: FrameStatus,
    /// First pixel of each missing packet (empty when complete).
    pub missing_packet_starts: Vec<usize>,
    /// Delivered a second time with the same block id.
    pub duplicate: bool,
    /// Extra latency of a late frame, µs (0 when on time).
    pub late_by_us: u32,
}

/// What the camera did so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CameraCounters {
    /// Rising edges seen.
    pub rising_edges: u64,
    /// Edges the camera missed.
    pub missed_triggers: u64,
    /// Exposures taken (block ids used).
    pub exposures: u64,
    /// Frames lost in transfer.
    pub dropped: u64,
    /// Frames delivered twice.
    pub duplicated: u64,
    /// Frames that arrived late.
    pub late: u64,
    /// Frames with missing packets.
    pub incomplete: u64,
    /// Frames handed to the consumer (duplicates count twice).
    pub delivered: u64,
    /// Times the camera had to wait for its consumer or its renderers (never a drop).
    pub backpressure_waits: u64,
    /// Renders whose pixel count did not match `frame_size` (padded or cut to size).
    pub render_size_errors: u64,
}

/// The next 16-bit GigE block id: 65535 wraps to 1, 0 is never used.
pub fn next_block_id(id: u16) -> u16 {
    if id == u16::MAX { 1 } else { id + 1 }
}

/// The per-edge decisions of a simulated camera; see the [module docs](self).
#[derive(Debug, Clone)]
pub struct CameraCore {
    config: SimCameraConfig,
    pixel_count: usize,
    next_block_id: u16,
    exposures: u64,
    counters: CameraCounters,
    missed: ChaCha8Rng,
    drop: ChaCha8Rng,
    duplicate: ChaCha8Rng,
    late: ChaCha8Rng,
    incomplete: ChaCha8Rng,
    trigger_jitter: ChaCha8Rng,
    transfer_jitter: ChaCha8Rng,
}

impl CameraCore {
    /// A camera that has taken no exposure; `pixel_count` sizes the missing-packet model.
    pub fn new(config: SimCameraConfig, pixel_count: usize) -> Result<Self, RigError> {
        config.check()?;
        let s = config.seed;
        Ok(Self {
            config,
            pixel_count,
            next_block_id: config.first_block_id,
            exposures: 0,
            counters: CameraCounters::default(),
            missed: fault_rng(s, FaultStream::MissedTrigger),
            drop: fault_rng(s, FaultStream::FrameDrop),
            duplicate: fault_rng(s, FaultStream::Duplicate),
            late: fault_rng(s, FaultStream::Late),
            incomplete: fault_rng(s, FaultStream::Incomplete),
            trigger_jitter: fault_rng(s, FaultStream::TriggerJitter),
            transfer_jitter: fault_rng(s, FaultStream::TransferJitter),
        })
    }

    /// The settings.
    pub fn config(&self) -> &SimCameraConfig {
        &self.config
    }

    /// Counters so far (`delivered` and `backpressure_waits` are kept by the delivery threads).
    pub fn counters(&self) -> CameraCounters {
        self.counters
    }

    /// The frames one trigger edge produces.
    pub fn on_edge(&mut self, edge: TriggerEdge) -> Option<FramePlan> {
        if !edge.rising || edge.output != Output::CameraTrigger {
            return None;
        }
        self.counters.rising_edges += 1;
        let f = self.config.faults;
        // Fixed draws per stream per rising edge (independence contract).
        let missed = self.missed.random::<f64>() < f.missed_trigger_probability;
        let dropped = self.drop.random::<f64>() < f.drop_probability;
        let duplicate = self.duplicate.random::<f64>() < f.duplicate_probability;
        let late = self.late.random::<f64>() < f.late_probability;
        let incomplete = self.incomplete.random::<f64>() < f.incomplete_probability;
        let missing_packets = self.incomplete.random_range(1..=3u32);
        let packet_draws: [f64; 3] = [
            self.incomplete.random(),
            self.incomplete.random(),
            self.incomplete.random(),
        ];
        let z_trigger: f64 = self.trigger_jitter.sample(StandardNormal);
        let z_transfer: f64 = self.transfer_jitter.sample(StandardNormal);
        if missed {
            self.counters.missed_triggers += 1;
            return None;
        }
        let block_id = self.next_block_id;
        self.next_block_id = next_block_id(block_id);
        let exposure_index = self.exposures;
        self.exposures += 1;
        self.counters.exposures += 1;
        if dropped {
            self.counters.dropped += 1;
            return None;
        }
        let t = self.config.timing;
        // Clamped at 0: an exposure never starts before its trigger edge.
        let delay_us =
            (f64::from(t.trigger_delay_us) + z_trigger * f.trigger_jitter_sigma_us).max(0.0);
        let edge_at = self.config.board_clock.instant_at_us(edge.t_device_us);
        let exposure_start = edge_at + Duration::from_secs_f64(delay_us * 1e-6);
        let transfer_us = (f64::from(t.transfer_us) + z_transfer * t.transfer_jitter_us).max(0.0);
        let late_by_us = if late { f.late_extra_us } else { 0 };
        let latency_us = f64::from(t.exposure_us)
            + f64::from(t.readout_us)
            + transfer_us
            + f64::from(late_by_us);
        let arrival = exposure_start + Duration::from_secs_f64(latency_us * 1e-6);
        let packets = self.pixel_count.div_ceil(PIXELS_PER_PACKET).max(1);
        let (status, missing_packet_starts) = if incomplete {
            let mut starts: Vec<usize> = packet_draws[..missing_packets as usize]
                .iter()
                // u in [0, 1): the index is < packets.
                .map(|u| ((u * packets as f64) as usize).min(packets - 1) * PIXELS_PER_PACKET)
                .collect();
            starts.sort_unstable();
            starts.dedup();
            self.counters.incomplete += 1;
            (
                FrameStatus::Flagged {
                    missing_packets: starts.len() as u32,
                },
                starts,
            )
        } else {
            (FrameStatus::Complete, Vec::new())
        };
        self.counters.duplicated += u64::from(duplicate);
        self.counters.late += u64::from(late);
        Some(FramePlan {
            block_id,
            exposure_index,
            pose_index: (exposure_index % self.config.pose_count as u64) as usize,
            frame_seed: frame_seed(self.config.seed, exposure_index),
            t_trigger_device_us: edge.t_device_us,
            t_camera_ns: self.config.camera_clock.at_ns(exposure_start),
            exposure_start,
            exposure_start_device_us: edge.t_device_us as f64 + delay_us,
            flash_energy_rel: 1.0,
            flash_lit_us: None,
            arrival,
            status,
            missing_packet_starts,
            duplicate,
            late_by_us,
        })
    }
}
