//! The virtual rig: a simulated trigger board running the real firmware core, a trigger wire,
//! and a simulated GigE-like camera, with seeded faults — so the host's real link, pairing and
//! session code can run without hardware.
//!
//! # Pieces
//!
//! - [`board::VirtualBoard`]: the [`ellipso_firmware::Board`] core on a thread, over any byte
//!   transport (the device end of a pty for `ellipso sim serve`, an in-memory
//!   [`duplex::duplex`] in unit tests), with link faults ([`link_fault`]) and a
//!   [`board::BoardTruth`] of everything it really sent.
//! - [`wire`]: trigger edges ([`wire::TriggerEdge`]: time and level only) from the board to the
//!   cameras: a channel in-process, a unix socket of 16-byte records across processes.
//! - [`camera::CameraCore`] decides per edge (missed trigger, block id, timestamps, faults);
//!   [`flash_meter::FlashMeter`] integrates the flash's light (its edges on the wire) over each
//!   exposure, so a bracketed pulse renders at its energy; [`sim_camera::SimCamera`] renders
//!   through a [`sim_camera::FrameSource`] on worker threads and delivers
//!   [`sim_camera::SimFrame`]s in order with backpressure.
//! - [`seeds`]: one ChaCha stream per fault, so faults are independent and reproducible.
//!
//! # In-process rig in five lines
//!
//! ```no_run
//! # use std::{sync::Arc, time::Duration};
//! # use ellipso_sim::rig::*;
//! let (host_end, board_end) = duplex::duplex(Duration::from_millis(20)); // or a pty pair
//! let (edges_tx, edges_rx) = wire::wire();
//! let board = board::VirtualBoard::spawn(
//!     board::VirtualBoardConfig::new(7),
//!     Box::new(board_end.reader), Box::new(board_end.writer), Some(edges_tx))?;
//! let camera = sim_camera::SimCamera::spawn(
//!     camera::SimCameraConfig::new(7, 36, board.device_clock()),
//!     Arc::new(sim_camera::PoseIndexSource { width: 64, height: 48 }), edges_rx)?;
//! // host: TriggerLink::connect(Box::new(host_end.reader), Box::new(host_end.writer), ..);
//! // frames: camera.frames().recv()
//! # Ok::<(), RigError>(())
//! ```
//!
//! # Time model: which clock each timestamp is in
//!
//! | timestamp | clock | relation |
//! |---|---|---|
//! | [`std::time::Instant`] (`epoch`, `SimFrame::arrival`, `FramePlan::exposure_start`) | host monotonic | the reference; the host's `HostClock` is this clock from its own epoch |
//! | `PulseEvent` times, `Pong::t_device_us`, `TriggerEdge::t_device_us`, `FrameTruth::t_trigger_device_us` | board device µs | `offset + (t_host − epoch)·(1 + drift)`, default offset 10¹² µs, drift +25 ppm ([`clock::LinearClock`]) |
//! | `SimFrame::t_camera_ns` | camera's own ns counter | another [`clock::LinearClock`]: default 1 h uptime, −12 ppm; it marks the exposure start |
//!
//! - An edge's device time is exact: the board polls every deadline with the deadline's own time,
//!   as a compare-timer port does. Bytes from the host are stamped with the device time at which
//!   the board's receive thread got them.
//! - Exposure start (host) = instant of the edge's device time (inverse board clock) + trigger
//!   delay + trigger jitter (clamped so it never precedes the edge).
//! - Arrival (host) = exposure start + exposure + readout + transfer (± jitter, ≥ 0) + late extra.
//!   It is simulated, not the instant the frame left the simulator, which may be later when
//!   rendering is slow (or equal with `pace_to_arrival`).
//! - The host must fit board ↔ host by ping/pong (its clock model) and pair frames to pulses
//!   from block ids and arrival times; `truth` fields exist only to score that.

pub mod board;
pub mod camera;
pub mod clock;
pub mod duplex;
pub mod flash_meter;
pub mod link_fault;
pub mod seeds;
pub mod sim_camera;
pub mod wire;

#[cfg(test)]
mod tests;

pub use board::{BoardTruth, VirtualBoard, VirtualBoardConfig};
pub use camera::{
    CameraCore, CameraCounters, CameraFaults, CameraTiming, FrameStatus, SimCameraConfig,
};
pub use clock::LinearClock;
pub use flash_meter::FlashMeter;
pub use link_fault::{Disconnect, LinkFaults};
pub use sim_camera::{FrameSource, FrameTruth, PoseIndexSource, SimCamera, SimFrame};
pub use wire::{TriggerEdge, WireProblems, WireServer, connect_wire, connect_wire_reporting};

/// Errors of the virtual rig.
#[derive(Debug, thiserror::Error)]
pub enum RigError {
    /// A setting out of its range.
    #[error("virtual rig: {name} = {value} is invalid, expected {expected}")]
    Parameter {
        /// The setting.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        expected: &'static str,
    },
    /// The firmware core refused the board description.
    #[error("virtual rig: the firmware core refused the board configuration: {0:?}")]
    Board(ellipso_firmware::ConfigError),
    /// A socket, file or thread could not be set up.
    #[error("virtual rig: {what}: {source}")]
    Io {
        /// What was being set up.
        what: String,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A trigger-wire record that is not one.
    #[error("virtual rig: malformed trigger-wire record {record:02x?}")]
    WireRecord {
        /// The 16 bytes received.
        record: [u8; wire::EDGE_RECORD_LEN],
    },
}
