//! The receiving side of the trigger link: the reader thread that decodes every frame the
//! board sends, the [`LinkEvent`]s it passes on (pulses, faults, edges, unsolicited status, the
//! disconnect), the replies it hands to the waiting command, and the [`LinkStats`] it keeps.
//!
//! Contract: every decoded frame is stamped with the host time it was decoded; a bad frame is
//! counted by kind and skipped, never ends the link; a status goes both to the waiting command
//! and to the events; when the stream ends, fails or the host closes the link, the reader marks
//! the link disconnected and sends exactly one [`LinkEvent::Disconnected`], then stops.

use std::io::{ErrorKind, Read};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use crossbeam_channel::Sender;
use ellipso_protocol::{BoardMessage, Decoder, Edge, Fault, FrameError, PulseEvent, Status};

use super::LinkCounters;
use super::time::{HostClock, HostTimeUs};

/// Something the board sent that is not a reply to a command.
#[derive(Debug, Clone, PartialEq)]
pub enum LinkEvent {
    /// One pulse fired.
    Pulse {
        /// The event as the board reported it.
        event: PulseEvent,
        /// When its frame was decoded on the host.
        t_host_recv: HostTimeUs,
    },
    /// A fault on the board.
    Fault {
        /// What happened.
        fault: Fault,
        /// When its frame was decoded on the host.
        t_host_recv: HostTimeUs,
    },
    /// An output transition (only when `report_edges` is configured).
    Edge(Edge),
    /// A status the board sent by itself (e.g. a counted capture completed).
    Status(Status),
    /// The stream ended or failed; no more events follow.
    Disconnected {
        /// What the reader saw.
        reason: String,
    },
}

/// Counters of the link, readable at any time.
#[derive(Debug, Default)]
pub struct LinkStats {
    bytes_rx: AtomicU64,
    pub(super) bytes_tx: AtomicU64,
    frames_ok: AtomicU64,
    bad_cobs: AtomicU64,
    bad_crc: AtomicU64,
    too_short: AtomicU64,
    overflow: AtomicU64,
    unknown_message: AtomicU64,
    malformed: AtomicU64,
}

impl LinkStats {
    fn count_error(&self, e: &FrameError) {
        let c = match e {
            FrameError::BadCobs => &self.bad_cobs,
            FrameError::BadCrc => &self.bad_crc,
            FrameError::TooShort { .. } => &self.too_short,
            FrameError::Overflow { .. } => &self.overflow,
            FrameError::UnknownMessage { .. } => &self.unknown_message,
            FrameError::Malformed => &self.malformed,
        };
        c.fetch_add(1, Ordering::Relaxed);
    }

    /// Current counters.
    pub fn snapshot(&self) -> LinkCounters {
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        LinkCounters {
            bytes_rx: g(&self.bytes_rx),
            bytes_tx: g(&self.bytes_tx),
            frames_ok: g(&self.frames_ok),
            bad_cobs: g(&self.bad_cobs),
            bad_crc: g(&self.bad_crc),
            too_short: g(&self.too_short),
            overflow: g(&self.overflow),
            unknown_message: g(&self.unknown_message),
            malformed: g(&self.malformed),
        }
    }
}

/// A reply to a command and the host time its frame was decoded.
pub(super) type Reply = (BoardMessage, HostTimeUs);

pub(super) fn reader_loop(
    mut reader: Box<dyn Read + Send>,
    clock: HostClock,
    replies: Sender<Reply>,
    events: Sender<LinkEvent>,
    stats: &LinkStats,
    connected: &AtomicBool,
    stop: &AtomicBool,
) {
    let mut decoder = Decoder::<BoardMessage>::new();
    let mut buf = [0u8; 512];
    let reason = loop {
        if stop.load(Ordering::Acquire) {
            break "link closed by the host".to_string();
        }
        let n = match reader.read(&mut buf) {
            Ok(0) => break "end of stream".to_string(),
            Ok(n) => n,
            Err(e)
                if matches!(
                    e.kind(),
                    ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted
                ) =>
            {
                continue;
            }
            Err(e) => break e.to_string(),
        };
        stats.bytes_rx.fetch_add(n as u64, Ordering::Relaxed);
        let t = clock.now();
        for result in decoder.feed(&buf[..n]) {
            let msg = match result {
                Ok(m) => m,
                Err(e) => {
                    stats.count_error(&e);
                    tracing::debug!("bad frame from the trigger board: {e}");
                    continue;
                }
            };
            stats.frames_ok.fetch_add(1, Ordering::Relaxed);
            let event = match msg {
                BoardMessage::Pulse(event) => LinkEvent::Pulse {
                    event,
                    t_host_recv: t,
                },
                BoardMessage::Fault(fault) => LinkEvent::Fault {
                    fault,
                    t_host_recv: t,
                },
                BoardMessage::Edge(edge) => LinkEvent::Edge(edge),
                BoardMessage::Status(s) => {
                    // both a possible reply and news for whoever watches the capture
                    let _ = replies.send((BoardMessage::Status(s), t));
                    LinkEvent::Status(s)
                }
                reply => {
                    let _ = replies.send((reply, t));
                    continue;
                }
            };
            let _ = events.send(event);
        }
    };
    connected.store(false, Ordering::Release);
    let _ = events.send(LinkEvent::Disconnected { reason });
}
