//! `ellipso-protocol`: the one wire contract between ellipso's trigger board and the host.
//!
//! Shared by the firmware (no_std, no alloc, in an ISR) and the host (a serial reader thread), in
//! the manner of postcard-rpc's shared ICD crate: both sides compile the same types, so they cannot
//! disagree about the layout.
//!
//! - [`messages`]: [`HostMessage`] (host → board) and [`BoardMessage`] (board → host).
//! - [`bracket`]: [`Bracket`], the flash energies a capture fires in turn (Q15, ≤ 8 steps).
//! - [`framing`]: `COBS(postcard(msg) ++ crc32c_le) ++ 0x00` frames, [`encode`] and the streaming
//!   [`Decoder`] that never panics and resynchronises at every delimiter.
//!
//! The byte-level spec with example frames is `docs/protocol.md`; its hex examples are test
//! vectors (`tests/spec_vectors.rs`).
//!
//! Versioning: [`PROTOCOL_VERSION`] changes on every incompatible change of any message; the
//! host refuses a board with another version at `Hello`, with both versions in the error.
#![no_std]
#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod bracket;
pub mod framing;
pub mod messages;

pub use bracket::{Bracket, BracketError, ENERGY_ONE_Q15, MAX_BRACKET_STEPS};
pub use framing::{
    CRC_LEN, CRC32C, Decoder, EncodeError, Feed, FrameError, MAX_FRAME_LEN, MAX_MESSAGE_LEN,
    Message, encode,
};
pub use messages::*;

/// Version of this protocol; both sides exchange it in `Hello` / `HelloReply`.
///
/// History: 1 — the first release; 2 — flash-energy brackets (`CaptureConfig::bracket`,
/// `PulseEvent::{bracket_step, flash_on_us}`, two bracket `RejectReason`s); 3 — reboot into the
/// DFU bootloader for a firmware update (`HostMessage::EnterBootloader`, appended).
pub const PROTOCOL_VERSION: u16 = 3;
