//! `ellipso-rig`: the driver of the physical (or simulated) rig — the trigger link to the board,
//! the cameras, and capture orchestration with frame ↔ pulse pairing. Everything it records goes
//! through `ellipso-session`.
//!
//! - [`link`]: the trigger link (serial/pty/socket), version handshake, pulse events, clock model.
//! - [`camera`]: the camera trait, frame ids, counters; backends (simulated; aravis and V4L2
//!   behind cargo features).
//! - [`acquire`]: capture orchestration and frame ↔ pulse pairing.
//! - [`dfu`]: firmware updates of the trigger board over USB (STM32 DfuSe, `rusb`).
//! - [`sim_serve`]: the virtual trigger board served on a pseudo-terminal (`ellipso sim serve`).

pub mod acquire;
pub mod camera;
pub mod dfu;
pub mod link;
pub mod sim_serve;
