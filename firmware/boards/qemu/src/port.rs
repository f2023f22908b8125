//! The port: one [`Board`] (the sync core), its outputs and its transmit queue, driven from the
//! three places a cortex-m-rt board has: the USART1 RX interrupt, the SysTick alarm and boot.
//!
//! Contract: [`Port`] holds no hardware; every method takes the device time `now_us` from the
//! caller ([`WideClock`](crate::WideClock) on the board, chosen values in tests). After every
//! call the caller re-arms the alarm for [`Port::next_deadline`]. Replies are whole wire frames in
//! [`TxBytes`]; the main loop moves them to the UART with [`Port::pop_tx_byte`].

use ellipso_firmware::{Board, BoardConfig, FrameWriter, Outputs, parse_version};
use ellipso_protocol::{BoardMessage, FirmwareVersion, MAX_FRAME_LEN};

use crate::clock::DEVICE_CLOCK_HZ;

/// The name sent in `HelloReply`.
pub const BOARD_NAME: &str = "qemu-netduinoplus2";

/// Transmit queue size, bytes: `8 · MAX_FRAME_LEN` holds two worst-case pulse bursts (the core
/// proves one burst is under `4 · MAX_FRAME_LEN`) while the host is slow to read.
pub const TX_QUEUE_BYTES: usize = 8 * MAX_FRAME_LEN;

/// The transmit queue: whole frames, drained byte by byte into USART1.
pub type TxBytes = heapless::Deque<u8, TX_QUEUE_BYTES>;

/// This crate's version, sent in `HelloReply`.
pub const FIRMWARE_VERSION: FirmwareVersion = match parse_version(env!("CARGO_PKG_VERSION")) {
    Some(v) => v,
    None => panic!("CARGO_PKG_VERSION is not MAJOR.MINOR.PATCH"),
};

/// The board's description: the LED rig's default limits and sequencer timing, a 1 MHz timer.
pub fn board_config() -> BoardConfig {
    let mut config = BoardConfig::new(BOARD_NAME, DEVICE_CLOCK_HZ);
    config.firmware_version = FIRMWARE_VERSION;
    config
}

/// The sync core with its outputs and transmit queue.
pub struct Port<O> {
    board: Board,
    outputs: O,
    tx: FrameWriter<TxBytes>,
}

impl<O: Outputs> Port<O> {
    /// A port in `Idle` with the [`board_config`]; touches nothing until [`Port::boot`].
    pub fn new(outputs: O) -> Self {
        let board = match Board::new(board_config()) {
            Ok(board) => board,
            // The config is a constant; the on-target test `board_config_is_accepted` checks it.
            Err(e) => panic!("board config refused: {e}"),
        };
        Self {
            board,
            outputs,
            tx: FrameWriter::new(TxBytes::new()),
        }
    }

    /// Drives both outputs low and queues the boot announcement, an unsolicited `Status`
    /// (state `Idle`, no pulses): a host that sees it knows the board (re)started and that its
    /// receiver is enabled.
    pub fn boot(&mut self, now_us: u64) {
        self.board.reset_outputs(now_us, &mut self.outputs);
        let status = self.board.status(now_us);
        ellipso_firmware::MessageSink::send(&mut self.tx, BoardMessage::Status(status));
    }

    /// One byte from the host, received at `now_us`.
    pub fn on_rx_byte(&mut self, byte: u8, now_us: u64) {
        self.board
            .feed_rx_byte(byte, now_us, &mut self.outputs, &mut self.tx);
    }

    /// The alarm fired (or the loop polls): runs every edge due at `now_us`.
    pub fn on_alarm(&mut self, now_us: u64) {
        self.board.poll(now_us, &mut self.outputs, &mut self.tx);
    }

    /// When [`Port::on_alarm`] must next run, device µs.
    pub fn next_deadline(&self) -> Option<u64> {
        self.board.next_deadline()
    }

    /// The next byte to transmit.
    pub fn pop_tx_byte(&mut self) -> Option<u8> {
        self.tx.bytes_mut().pop_front()
    }

    /// The sync core.
    pub fn board(&self) -> &Board {
        &self.board
    }

    /// The outputs.
    pub fn outputs(&self) -> &O {
        &self.outputs
    }

    /// Bytes waiting to be sent.
    pub fn tx_pending(&self) -> usize {
        self.tx.bytes().len()
    }
}
