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
//! use ellipso_protocol::{
//!     encode, Bracket, CaptureConfig, HostMessage, PulseCount, TriggerSource, MAX_FRAME_LEN,
//! };
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
//!     trigger: TriggerSource::FreeRun, report_edges: false, bracket: Bracket::NONE,
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
//!
//! # Writing a board port
//!
//! 1. **Clock.** Provide `now_us() -> u64`, monotonic, never going backwards. On an STM32 run a
//!    32-bit timer at 1 MHz (QEMU `netduinoplus2`: TIM2 with `PSC = 999` from its 1 GHz model
//!    clock; silicon: `PSC = f_timer / 1 MHz − 1`) and extend it to 64 bits by counting wraps
//!    inside a critical section. Report the timer's input clock as
//!    [`BoardConfig::timer_clock_hz`].
//! 2. **Boot.** `Board::new(config)` (it refuses contradictory limits, see
//!    [`BoardConfig::check`]), then [`Board::reset_outputs`] so both outputs start low. Take the
//!    version from the port's own crate: `parse_version(env!("CARGO_PKG_VERSION"))`.
//! 3. **Sharing.** [`Board`] is a plain value without interior mutability. Either own it in one
//!    task (embassy: `select` over UART/USB read, `Timer::at(next_deadline)` and the button), or
//!    keep it in a `critical_section::Mutex<RefCell<Board>>` and call it from each ISR inside
//!    `critical_section::with`. Every call is short and bounded (at most 16 edges per `poll`, at
//!    most one frame per received byte).
//! 4. **Alarm.** After *every* call, re-arm the alarm for [`Board::next_deadline`] (Start,
//!    FireOne and button presses create deadlines); when it fires, call [`Board::poll`] with
//!    `now_us()`. A deadline already in the past means: poll now. Early or extra polls are
//!    harmless, so a busy loop that polls continuously is a valid port (the QEMU build busy-idles
//!    because of QEMU 7.2's late wake from `WFI`).
//! 5. **Receive.** Each byte from the host: [`Board::feed_rx_byte`]`(byte, now_us(), ..)`. Bad
//!    frames are counted and reported by the core; never reset the link on one.
//! 6. **Transmit.** Use a [`FrameWriter`] over a `heapless::Deque<u8, N>` as the sink and drain it
//!    into the UART data register (QEMU raises no TXE interrupt: poll TXE) or into CDC-ACM packets
//!    of ≤ 63 bytes. Size `N` for a burst: the worst one pulse can send (4 edge reports, 3
//!    faults, the pulse event and a completion `Status`, all at the largest values) is under
//!    `4 · MAX_FRAME_LEN` bytes (a test checks it), so `N = 8 · MAX_FRAME_LEN` holds two such
//!    bursts while the host stalls. A full queue drops whole frames and counts them in
//!    `tx_overflows`.
//! 7. **Button.** From the press-edge interrupt: [`Board::button_pressed`]`(now_us())`, then
//!    re-arm the alarm. Bounce is filtered by the frame period here.
//! 8. **Outputs.** [`PinOutputs`] over two embedded-hal 1.0 pins (active high). A board with a
//!    one-pulse timer implements [`Outputs`] itself and arms the timer in [`Outputs::flash_on`]
//!    with `max_on_us`: the hardware cut-off is the only guarantee that survives a hung CPU.
//! 9. **Emulators.** Without GPIO (QEMU) let the host set `report_edges` to see every transition as
//!    a `BoardMessage::Edge` with its time and pulse number.
//!
//! ```ignore
//! // Sketch of a cortex-m-rt port (not compiled here): shared board, SysTick alarm, USART RX.
//! static BOARD: Mutex<RefCell<Option<Port>>> = Mutex::new(RefCell::new(None));
//! struct Port { board: Board, pins: PinOutputs<Trig, Led>, tx: FrameWriter<Deque<u8, 1024>> }
//!
//! #[interrupt] fn USART1() {
//!     critical_section::with(|cs| {
//!         let mut p = BOARD.borrow_ref_mut(cs); let p = p.as_mut().unwrap();
//!         let byte = usart1_read_dr();
//!         p.board.feed_rx_byte(byte, now_us(), &mut p.pins, &mut p.tx);
//!         arm_alarm(p.board.next_deadline());
//!     });
//! }
//! #[exception] fn SysTick() { /* same shape: p.board.poll(now_us(), ..); arm_alarm(..) */ }
//! ```
#![cfg_attr(not(test), no_std)]
#![warn(missing_docs)]
#![forbid(unsafe_code)]

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
