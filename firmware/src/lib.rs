//! `ellipso-firmware`: the trigger board's hardware-independent sync core.
//!
//! Every decision of the trigger board lives here: validating a capture configuration, placing
//! the camera-trigger and flash edges in time, keeping the LED safe, counting faults, and answering
//! the host. Board crates (QEMU, embassy, the simulator's virtual board) only move bytes, read a
//! µs clock, arm an alarm and write two pins. The crate is `no_std`, allocates nothing, never
//! panics on input, and never reads a clock: time is an argument (`now_us`), so simulated time
//! needs no framework and host tests run in milliseconds.
//!
//! # Modules
//!
//! - [`config`] — [`BoardConfig`] (name, version, timer clock, [`BoardLimits`], [`SequencerTiming`])
//!   and the documented default limits of the LED rig, [`LED_RIG_LIMITS`].
//! - [`plan`] — [`CapturePlan`], a [`CaptureConfig`] checked against the limits, with a documented
//!   check order mapping each failure to a protocol [`RejectReason`].
//! - [`sequencer`] — [`Sequencer`], the pulse state machine (`next_deadline` / `poll`), its flash
//!   safety rules and lateness reporting.
//! - [`outputs`] — the [`Outputs`] trait, [`PinOutputs`] over embedded-hal 1.0 pins, and
//!   [`RecordingOutputs`].
//! - [`sink`] — [`MessageSink`] for replies, [`TxQueue`], and [`FrameWriter`], which writes wire
//!   frames into a [`ByteSink`].
//! - [`board`] — [`Board`], the command state machine tying it all together.
//!
//! # A board port in one page
//!
//! ```
//! use ellipso_firmware::{Board, BoardConfig, FrameWriter, RecordingOutputs};
//! use ellipso_protocol::{encode, CaptureConfig, HostMessage, PulseCount, TriggerSource, MAX_FRAME_LEN};
//!
//! // Boot: describe the board, drive both outputs low.
//! let mut board = Board::new(BoardConfig::new("doc-board", 1_000_000)).unwrap();
//! let mut outputs = RecordingOutputs::<64>::new(); // a real port: PinOutputs::new(trigger, flash)
//! let mut tx = FrameWriter::new(heapless::Deque::<u8, 1024>::new()); // drained by the UART
//! board.reset_outputs(0, &mut outputs);
//!
//! // RX path: every received byte goes in with the time it arrived.
//! let config = CaptureConfig {
//!     exposure_us: 1_000, flash_delay_us: 100, flash_duration_us: 500,
//!     frame_period_us: 50_000, pulses: PulseCount::Count(3),
//!     trigger: TriggerSource::FreeRun, report_edges: false,
//! };
//! let mut now_us = 0;
//! for msg in [HostMessage::Configure(config), HostMessage::Arm, HostMessage::Start] {
//!     let mut frame = [0u8; MAX_FRAME_LEN];
//!     let n = encode(&msg, &mut frame).unwrap();
//!     for &byte in &frame[..n] {
//!         board.feed_rx_byte(byte, now_us, &mut outputs, &mut tx);
//!     }
//! }
//!
//! // Timer path: sleep until the next deadline, then poll (simulated time jumps there).
//! while let Some(deadline_us) = board.next_deadline() {
//!     now_us = deadline_us;
//!     board.poll(now_us, &mut outputs, &mut tx);
//! }
//! assert_eq!(board.sequencer().pulses_fired(), 3);
//! assert_eq!(outputs.edges().count(), 12); // 3 × (trigger ↑, flash ↑, flash ↓, trigger ↓)
//! ```
//!
//! # Timing model
//!
//! Times are µs of the board's monotonic 64-bit device clock; the host maps them to its own clock
//! by `Ping`/`Pong`. Edge times reported in `PulseEvent`s are the times `poll` executed them, so a
//! port whose alarm fires late reports (and flags) the lateness instead of hiding it. A port that
//! places edges with timer hardware calls `poll` from the compare ISR with the compare time.
#![cfg_attr(not(test), no_std)]
#![warn(missing_docs)]

pub mod board;
pub mod config;
pub mod outputs;
pub mod plan;
pub mod sequencer;
pub mod sink;

pub use board::{Board, ButtonOutcome};
pub use config::{
    BoardConfig, CORE_VERSION, ConfigError, LED_RIG_LIMITS, SequencerTiming, parse_version,
};
pub use outputs::{OutputEdge, Outputs, PinOutputs, RecordingOutputs};
pub use plan::CapturePlan;
pub use sequencer::{PollOutcome, Sequencer, SequencerCounters};
pub use sink::{ByteSink, FrameWriter, MessageSink, TxQueue};

#[cfg(doc)]
use ellipso_protocol::{BoardLimits, CaptureConfig, RejectReason};
