//! `events.jsonl`: the append-only log of a session, one tagged JSON object per line.
//!
//! Every event carries the host time it was recorded (`t_host_us`, µs since the manifest's host
//! epoch). Device times (`*_device_us`) are the trigger board's clock; the `clock_fit` events give
//! the mapping. Event types are snake_case in the `type` field; readers keep unknown types as
//! [`SessionEvent::Unknown`] so older builds read newer logs.

use serde::{Deserialize, Serialize};

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use crate::link_counters::LinkCounters;
use crate::time::{DeviceTimeUs, HostTimeUs};

/// Completion status of a camera frame.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum FrameStatus {
    /// All pixels arrived.
    Complete,
    /// Delivered but not trustworthy (missing packets, size mismatch…): kept, never fitted.
    Flagged {
        /// Why.
        reason: String,
    },
}

/// The capture timing the host sent the trigger board, as the log records it: the wire's
/// `CaptureConfig` in the session's own type, field for field in the same JSON form (the
/// session does not link the wire protocol: the fit reads sessions without it). Logs written
/// before the flash-energy bracket existed have no `bracket` and read as none.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct BoardConfig {
    /// Flash-energy bracket, Q15 steps (`0x8000` = the full pulse), fired in turn; empty: every
    /// pulse at energy 1.
    #[serde(default)]
    pub bracket: Vec<u16>,
    /// Exposure (trigger high) length, µs.
    pub exposure_us: u32,
    /// Flash-on delay after the trigger's rising edge, µs.
    pub flash_delay_us: u32,
    /// Flash-on length, µs (0: no flash).
    pub flash_duration_us: u32,
    /// Minimum time between two trigger rising edges, µs.
    pub frame_period_us: u32,
    /// How many pulses the capture fires.
    pub pulses: BoardPulses,
    /// One edge message per output transition (debug).
    pub report_edges: bool,
    /// What fires each pulse.
    pub trigger: BoardTrigger,
}

/// How many pulses a capture fires (the wire's `PulseCount`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum BoardPulses {
    /// Until the host stops it.
    Continuous,
    /// Exactly this many.
    Count(u32),
}

/// What fires each pulse (the wire's `TriggerSource`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum BoardTrigger {
    /// One pulse per host command.
    HostCommand,
    /// One pulse per press of the grip button.
    GripButton,
    /// Pulses every frame period from the start.
    FreeRun,
}

/// What a tracking outcome (`pose`, `pose_rejected`) was computed from, so a later stage can
/// tell a stale one (`crate::provenance`): both absent in logs written before outcomes carried
/// them (such outcomes are taken as they are).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub struct TrackedFrom {
    /// CRC-64/XZ of the frame file's bytes tracking read (absent: the file could not be read).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame_crc64: Option<u64>,
    /// CRC-64/XZ of the manifest's board definitions tracking used
    /// (`crate::provenance::boards_crc64`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub boards_crc64: Option<u64>,
}

/// One line of the log.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum SessionEvent {
    /// The trigger board answered the handshake.
    Board {
        /// Host time.
        t_host_us: HostTimeUs,
        /// Board name.
        name: String,
        /// Firmware version `major.minor.patch`.
        firmware: String,
        /// Protocol version.
        protocol_version: u16,
    },
    /// The capture configuration sent to the board.
    Configured {
        /// Host time.
        t_host_us: HostTimeUs,
        /// The configuration.
        config: BoardConfig,
    },
    /// A device→host clock fit.
    ClockFit {
        /// Host time.
        t_host_us: HostTimeUs,
        /// Host µs per device µs.
        gain: f64,
        /// Host µs at device time 0.
        offset_us: f64,
        /// RMS residual, µs.
        rms_us: f64,
        /// Samples in the fit.
        n_samples: usize,
    },
    /// A flash pulse reported by the board.
    Pulse {
        /// Host time its report was decoded.
        t_host_us: HostTimeUs,
        /// Pulse sequence number.
        seq: u64,
        /// Trigger rising edge, device µs.
        t_trigger_device_us: DeviceTimeUs,
        /// Flash on, device µs.
        t_flash_on_device_us: DeviceTimeUs,
        /// Flash off, device µs.
        t_flash_off_device_us: DeviceTimeUs,
        /// `PULSE_*` flags.
        flags: u8,
        /// Bracket step the pulse fired (0 without a bracket; absent before protocol v2: 0).
        #[serde(default)]
        bracket_step: u8,
        /// The flash's actual on-time, device µs (absent before protocol v2).
        #[serde(default)]
        flash_on_us: Option<u32>,
    },
    /// A camera frame written to `frames/`.
    Frame {
        /// Host arrival time.
        t_host_us: HostTimeUs,
        /// Monotonic 64-bit frame id (unwrapped from the camera's).
        frame_id: u64,
        /// File name inside `frames/`.
        file: String,
        /// Camera's own timestamp, ns, if it has one.
        #[serde(default)]
        t_camera_ns: Option<u64>,
        /// Exposure, µs.
        exposure_us: u32,
        /// Gain, dB.
        gain_db: f32,
        /// Completion.
        #[serde(flatten)]
        status: FrameStatus,
        /// CRC-64/XZ of the PNG's bytes as written (`crate::provenance`); absent in sessions
        /// recorded before frames carried one (their frames are not checked).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        crc64: Option<u64>,
    },
    /// A frame paired with the pulse that lit it.
    Pairing {
        /// Host time.
        t_host_us: HostTimeUs,
        /// Frame id.
        frame_id: u64,
        /// Pulse sequence number.
        seq: u64,
        /// Frame arrival minus the pulse's trigger mapped to host time, µs (when the clock is fitted).
        #[serde(default)]
        latency_us: Option<f64>,
        /// The pulse's bracket step (absent in older sessions: step 0).
        #[serde(default)]
        bracket_step: Option<u8>,
        /// The pulse's actual flash on-time, µs (absent in older sessions).
        #[serde(default)]
        flash_on_us: Option<u32>,
        /// The flash energy that lit the frame relative to a full pulse,
        /// `flash_on_us / flash_duration_us` of the `configured` event (absent in older
        /// sessions: 1).
        #[serde(default)]
        flash_energy_rel: Option<f64>,
        /// The evidence: `camera_time` (the frame's exposure timestamp) or `arrival_time`.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        basis: Option<String>,
    },
    /// A frame or pulse that could not be paired; never silently dropped.
    PairingError {
        /// Host time.
        t_host_us: HostTimeUs,
        /// `frame_without_pulse`, `pulse_without_frame`, `duplicate_frame`, `duplicate_pulse`.
        kind: String,
        /// Frame id, if a frame is involved.
        #[serde(default)]
        frame_id: Option<u64>,
        /// Pulse sequence number, if a pulse is involved.
        #[serde(default)]
        seq: Option<u64>,
        /// Why a frame found no pulse: `no_clock`, `no_pulse`, `ambiguous`, `pulse_taken`,
        /// `unconfirmed` (see `acquire::pairing::Unpaired`).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        reason: Option<String>,
    },
    /// The camera's timestamp counter read between two host times (its clock model for pairing
    /// on exposure times).
    CameraClock {
        /// Host time.
        t_host_us: HostTimeUs,
        /// The camera's counter, ns.
        t_camera_ns: u64,
        /// Host time before the latch.
        t_host_before_us: HostTimeUs,
        /// Host time after the read-back.
        t_host_after_us: HostTimeUs,
    },
    /// A fault reported by the board or seen by the host.
    Fault {
        /// Host time.
        t_host_us: HostTimeUs,
        /// What happened.
        what: String,
    },
    /// Link counters at a point in time.
    Link {
        /// Host time.
        t_host_us: HostTimeUs,
        /// Counters.
        counters: LinkCounters,
    },
    /// The trigger link went away.
    Disconnected {
        /// Host time.
        t_host_us: HostTimeUs,
        /// What was seen.
        reason: String,
    },
    /// A camera pose estimated for a frame (world frame → camera frame; the world is the frame
    /// the manifest's boards are placed in).
    Pose {
        /// Host time.
        t_host_us: HostTimeUs,
        /// Frame id.
        frame_id: u64,
        /// Rotation, axis-angle (rad), world → camera.
        rotation_camera_from_world: [f64; 3],
        /// Translation, m, world origin in the camera frame.
        translation_camera_from_world_m: [f64; 3],
        /// Reprojection RMS, px.
        rms_px: f64,
        /// Tags used.
        tags: u32,
        /// What the pose was computed from (absent in older logs).
        #[serde(flatten)]
        from: TrackedFrom,
    },
    /// A frame without a usable pose, and why.
    PoseRejected {
        /// Host time.
        t_host_us: HostTimeUs,
        /// Frame id.
        frame_id: u64,
        /// Why.
        reason: String,
        /// What the rejection was computed from (absent in older logs).
        #[serde(flatten)]
        from: TrackedFrom,
    },
    /// A short-pulse frame of a bracketed capture that tracking refused, posed from its tracked
    /// neighbours (`ellipso_vision::short_pulse_poses`); follows the frame's `pose_rejected`.
    PoseInterpolated {
        /// Host time.
        t_host_us: HostTimeUs,
        /// Frame id.
        frame_id: u64,
        /// Rotation, axis-angle (rad), world → camera.
        rotation_camera_from_world: [f64; 3],
        /// Translation, m, world origin in the camera frame.
        translation_camera_from_world_m: [f64; 3],
        /// The tracked frames it was interpolated between, `[before, after]` (the same id twice
        /// when taken from one neighbour).
        from_frame_ids: [u64; 2],
        /// Weight of `after` (0: the pose of `before`).
        weight: f64,
    },
    /// The capture ended.
    End {
        /// Host time.
        t_host_us: HostTimeUs,
        /// Why.
        reason: String,
    },
    /// An event type this build does not know (written by a newer one).
    #[serde(other)]
    Unknown,
}

/// The `camera_from_world` pose a `pose` or `pose_interpolated` event records: its axis-angle
/// rotation (rad) and translation (m) as written, the one decoding every reader of the log uses.
pub fn camera_from_world(
    rotation_axis_angle: &[f64; 3],
    translation_m: &[f64; 3],
) -> Isometry3<f64> {
    let (r, t) = (rotation_axis_angle, translation_m);
    Isometry3::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        UnitQuaternion::from_scaled_axis(Vector3::new(r[0], r[1], r[2])),
    )
}
