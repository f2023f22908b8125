//! Where the board's replies go: the [`MessageSink`] trait, a bounded [`TxQueue`], and a
//! [`FrameWriter`] that encodes each message as a wire frame into a [`ByteSink`].
//!
//! Contract:
//! - [`MessageSink::send`] must not block; it returns `false` when it had to drop the message
//!   (queue full, encoder failure). The [`Board`](crate::Board) counts every `false` in
//!   `FaultCounters::tx_overflows` and carries on: a full queue never stops the sequencer.
//! - Any `FnMut(BoardMessage)` closure is a sink that never drops.
//! - [`FrameWriter`] turns messages into `COBS(postcard ++ CRC-32C) ++ 0x00` frames (the
//!   protocol's [`encode`]) on the stack and hands each complete frame to a [`ByteSink`], so a
//!   board port only moves bytes: a UART ring buffer (`heapless::Deque<u8, N>` is one), a USB
//!   CDC writer, a pty in the simulator. A frame is handed over whole or not at all, so a full
//!   byte queue drops whole frames and never leaves half a frame on the wire.

use ellipso_protocol::{BoardMessage, MAX_FRAME_LEN, encode};

/// Receives the board's outgoing messages.
pub trait MessageSink {
    /// Takes `msg` for transmission; `false` if it was dropped.
    fn send(&mut self, msg: BoardMessage) -> bool;
}

impl<F: FnMut(BoardMessage)> MessageSink for F {
    fn send(&mut self, msg: BoardMessage) -> bool {
        self(msg);
        true
    }
}

/// A bounded FIFO of `N` messages; [`send`](MessageSink::send) drops the *new* message when full
/// (the oldest replies are the ones the host is waiting for).
#[derive(Debug, Clone)]
pub struct TxQueue<const N: usize> {
    queue: heapless::Deque<BoardMessage, N>,
}

impl<const N: usize> Default for TxQueue<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> TxQueue<N> {
    /// An empty queue.
    pub const fn new() -> Self {
        Self {
            queue: heapless::Deque::new(),
        }
    }

    /// Removes the oldest message.
    pub fn pop(&mut self) -> Option<BoardMessage> {
        self.queue.pop_front()
    }

    /// Messages held.
    pub fn len(&self) -> usize {
        self.queue.len()
    }

    /// Whether no message is held.
    pub fn is_empty(&self) -> bool {
        self.queue.is_empty()
    }
}

impl<const N: usize> MessageSink for TxQueue<N> {
    fn send(&mut self, msg: BoardMessage) -> bool {
        self.queue.push_back(msg).is_ok()
    }
}

/// Accepts complete frames of bytes.
pub trait ByteSink {
    /// Takes the whole `frame`, or nothing and returns `false`.
    fn write_frame(&mut self, frame: &[u8]) -> bool;
}

impl<F: FnMut(&[u8])> ByteSink for F {
    fn write_frame(&mut self, frame: &[u8]) -> bool {
        self(frame);
        true
    }
}

impl<const N: usize> ByteSink for heapless::Deque<u8, N> {
    fn write_frame(&mut self, frame: &[u8]) -> bool {
        if N - self.len() < frame.len() {
            return false;
        }
        for &b in frame {
            // Cannot fail: the free space was checked above.
            let _ = self.push_back(b);
        }
        true
    }
}

/// A [`MessageSink`] that encodes each message as one frame into a [`ByteSink`].
#[derive(Debug, Clone, Default)]
pub struct FrameWriter<B> {
    bytes: B,
}

impl<B: ByteSink> FrameWriter<B> {
    /// Writes frames into `bytes`.
    pub const fn new(bytes: B) -> Self {
        Self { bytes }
    }

    /// The byte sink.
    pub fn bytes(&self) -> &B {
        &self.bytes
    }

    /// The byte sink, mutably (e.g. to drain a queue into the UART).
    pub fn bytes_mut(&mut self) -> &mut B {
        &mut self.bytes
    }

    /// Gives the byte sink back.
    pub fn into_inner(self) -> B {
        self.bytes
    }
}

impl<B: ByteSink> MessageSink for FrameWriter<B> {
    fn send(&mut self, msg: BoardMessage) -> bool {
        let mut frame = [0u8; MAX_FRAME_LEN];
        match encode(&msg, &mut frame) {
            Ok(n) => self.bytes.write_frame(&frame[..n]),
            // Unreachable with the protocol's size guarantee; counted as a drop if it ever happens.
            Err(_) => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_protocol::{CommandKind, Decoder};

    #[test]
    fn the_worst_pulse_burst_fits_the_recommended_tx_buffer() {
        // One pulse with report_edges, late on every edge and forced off, at the largest times:
        // 4 edges, 2 deadline faults, 1 forced-off fault, the pulse, and a Status.
        use ellipso_protocol::{
            BoardState, Edge, Fault, FaultCounters, Output, PulseEvent, Status,
        };
        let t = u64::MAX;
        let edge = |output, high| {
            BoardMessage::Edge(Edge {
                output,
                high,
                t_device_us: t,
                seq: t,
            })
        };
        let late = BoardMessage::Fault(Fault::DeadlineMissed {
            seq: t,
            late_by_us: u32::MAX,
        });
        let burst = [
            edge(Output::CameraTrigger, true),
            edge(Output::Flash, true),
            edge(Output::Flash, false),
            late.clone(),
            BoardMessage::Fault(Fault::FlashForcedOff {
                seq: t,
                on_for_us: u32::MAX,
            }),
            edge(Output::CameraTrigger, false),
            late,
            BoardMessage::Pulse(PulseEvent {
                seq: t,
                t_trigger_us: t,
                t_flash_on_us: t,
                t_flash_off_us: t,
                flags: u8::MAX,
                bracket_step: u8::MAX,
                flash_on_us: u32::MAX,
            }),
            BoardMessage::Status(Status {
                state: BoardState::Configured,
                pulses_fired: t,
                t_device_us: t,
                faults: FaultCounters {
                    bad_frames: u32::MAX,
                    late_edges: u32::MAX,
                    flash_forced_off: u32::MAX,
                    flash_skipped: u32::MAX,
                    tx_overflows: u32::MAX,
                    rejected_commands: u32::MAX,
                },
            }),
        ];
        let mut w = FrameWriter::new(heapless::Deque::<u8, { 8 * MAX_FRAME_LEN }>::new());
        for m in burst {
            assert!(w.send(m));
        }
        assert!(
            w.bytes().len() <= 8 * MAX_FRAME_LEN / 2,
            "{} bytes",
            w.bytes().len()
        );
    }

    #[test]
    fn queue_drops_the_newest_when_full() {
        let mut q = TxQueue::<2>::new();
        assert!(q.send(BoardMessage::Ack(CommandKind::Arm)));
        assert!(q.send(BoardMessage::Ack(CommandKind::Start)));
        assert!(!q.send(BoardMessage::Ack(CommandKind::Stop)));
        assert_eq!(q.len(), 2);
        assert_eq!(q.pop(), Some(BoardMessage::Ack(CommandKind::Arm)));
        assert_eq!(q.pop(), Some(BoardMessage::Ack(CommandKind::Start)));
        assert!(q.is_empty());
    }

    #[test]
    fn frame_writer_output_decodes_on_the_host_side() {
        let mut wire = Vec::new();
        let mut w = FrameWriter::new(|frame: &[u8]| wire.extend_from_slice(frame));
        let msgs = [
            BoardMessage::Ack(CommandKind::Configure),
            BoardMessage::Pong {
                nonce: 9,
                t_device_us: u64::MAX,
            },
        ];
        for m in &msgs {
            assert!(w.send(m.clone()));
        }
        let mut dec = Decoder::<BoardMessage>::new();
        let got: Vec<_> = dec.feed(&wire).map(Result::unwrap).collect();
        assert_eq!(got, msgs);
    }

    #[test]
    fn full_byte_queue_drops_whole_frames_only() {
        let mut w = FrameWriter::new(heapless::Deque::<u8, 24>::new());
        assert!(w.send(BoardMessage::Pong {
            nonce: 1,
            t_device_us: 2
        }));
        let used = w.bytes().len();
        // A frame bigger than the space left is refused and nothing of it is written.
        assert!(!w.send(BoardMessage::Pong {
            nonce: u32::MAX,
            t_device_us: u64::MAX
        }));
        assert_eq!(w.bytes().len(), used);
        let bytes: Vec<u8> = w.into_inner().iter().copied().collect();
        let mut dec = Decoder::<BoardMessage>::new();
        let got: Vec<_> = dec.feed(&bytes).collect();
        assert_eq!(
            got,
            [Ok(BoardMessage::Pong {
                nonce: 1,
                t_device_us: 2
            })]
        );
    }
}
