//! The firmware core's two ports on the virtual board: the [`MessageSink`] that puts encoded
//! frames on the host link (recording them in the [`BoardTruth`] and applying the link faults:
//! bit flips, a disconnect at its pulse, a blackout) and the [`Outputs`] that put camera-trigger
//! and flash level changes on the trigger wire and in the truth.

use std::sync::Mutex;
use std::time::Instant;

use crossbeam_channel::{Sender, TrySendError};
use ellipso_firmware::{MessageSink, Outputs};
use ellipso_protocol::{BoardMessage, MAX_FRAME_LEN, encode};

use super::{BoardTruth, TxItem, lock};
use crate::rig::link_fault::{BitErrorInjector, Disconnect};
use crate::rig::wire::TriggerEdge;

/// Where the link stands.
#[derive(Default)]
pub(super) struct LinkState {
    down_until: Option<Instant>,
    pub(super) closed: bool,
}

impl LinkState {
    pub(super) fn is_down(&self, now: Instant) -> bool {
        self.closed || self.down_until.is_some_and(|t| now < t)
    }
}

/// The [`MessageSink`] between the core and the transmit thread.
pub(super) struct LinkTx<'a> {
    pub(super) frames: &'a Sender<TxItem>,
    pub(super) to_host: &'a mut BitErrorInjector,
    pub(super) disconnect: &'a mut Option<Disconnect>,
    pub(super) link: &'a mut LinkState,
    pub(super) truth: &'a Mutex<BoardTruth>,
}

impl MessageSink for LinkTx<'_> {
    fn send(&mut self, msg: BoardMessage) -> bool {
        let mut truth = lock(self.truth);
        let now = Instant::now();
        let pulse_seq = match &msg {
            BoardMessage::Pulse(ev) => {
                truth.pulses.push(*ev);
                Some(ev.seq)
            }
            _ => None,
        };
        if let (Some(seq), Some(d)) = (pulse_seq, *self.disconnect)
            && seq >= d.at_pulse
        {
            *self.disconnect = None;
            truth.disconnected_at_pulse = Some(seq);
            match d.blackout {
                Some(duration) => self.link.down_until = Some(now + duration),
                // The frames queued before go out; the thread ends at its next turn and closes
                // the writer behind them.
                None => self.link.closed = true,
            }
        }
        if self.link.is_down(now) {
            // The board cannot tell a dead cable from a live one: not a transmit overflow.
            truth.frames_lost += 1;
            return true;
        }
        let mut frame = [0u8; MAX_FRAME_LEN];
        let Ok(n) = encode(&msg, &mut frame) else {
            return false;
        };
        let flipped = self.to_host.corrupt(&mut frame[..n]);
        match self.frames.try_send(TxItem::Frame(frame[..n].to_vec())) {
            Ok(()) => {
                truth.frames_sent += 1;
                truth.bits_flipped_to_host += u64::from(flipped);
                if flipped > 0 {
                    truth.frames_corrupted += 1;
                    truth.corrupted_pulse_seqs.extend(pulse_seq);
                }
                true
            }
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                truth.frames_lost += 1;
                false
            }
        }
    }
}

/// [`Outputs`] that put camera-trigger and flash edges on the wire.
pub(super) struct WireOutputs<'a> {
    pub(super) wire: Option<&'a Sender<TriggerEdge>>,
    pub(super) camera_high: bool,
    pub(super) flash_high: bool,
    pub(super) truth: &'a Mutex<BoardTruth>,
}

impl WireOutputs<'_> {
    fn publish(&self, edge: TriggerEdge) {
        {
            let mut truth = lock(self.truth);
            match edge.output {
                ellipso_protocol::Output::CameraTrigger => truth.trigger_edges.push(edge),
                ellipso_protocol::Output::Flash => truth.flash_edges.push(edge),
            }
        }
        if let Some(w) = self.wire {
            // A camera that went away does not stop the board.
            let _ = w.send(edge);
        }
    }
}

impl Outputs for WireOutputs<'_> {
    fn set_camera(&mut self, high: bool, t_device_us: u64) {
        if high == self.camera_high {
            return;
        }
        self.camera_high = high;
        self.publish(TriggerEdge::trigger(t_device_us, high));
    }

    fn flash_on(&mut self, t_device_us: u64, _max_on_us: u32) {
        if !self.flash_high {
            self.flash_high = true;
            self.publish(TriggerEdge::flash(t_device_us, true));
        }
    }

    fn flash_off(&mut self, t_device_us: u64) {
        if self.flash_high {
            self.flash_high = false;
            self.publish(TriggerEdge::flash(t_device_us, false));
        }
    }
}
