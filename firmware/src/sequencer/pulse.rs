//! One pulse in flight: its flash phase, flags, and how it is reported (private to the
//! sequencer; see the [sequencer docs](super) for the timing rules).

use ellipso_protocol::{BoardMessage, Edge, Output, PulseEvent, PulseFlags};

use crate::sink::MessageSink;

/// The flash's phase within one pulse.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Flash {
    /// Waiting to light at `on_due_us`.
    Pending { on_due_us: u64 },
    /// Lit at `t_on_us`; goes off at `off_due_us`.
    On { t_on_us: u64, off_due_us: u64 },
    /// Fired and off.
    Done { t_on_us: u64, t_off_us: u64 },
    /// Will not fire this pulse (no flash configured, skipped, or stopped); decided at `t_us`.
    NotFired { t_us: u64 },
}

/// The pulse whose trigger is high.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Pulse {
    pub(super) seq: u64,
    pub(super) t_trigger_us: u64,
    pub(super) camera_off_due_us: u64,
    pub(super) flash: Flash,
    pub(super) flags: PulseFlags,
    /// The bracket step this pulse fires (0 without a bracket).
    pub(super) bracket_step: u8,
    /// The step's planned flash on-time, µs (0: no flash).
    pub(super) flash_planned_us: u32,
}

/// Sends an edge report when the capture asked for them.
pub(super) fn report_edge<S: MessageSink + ?Sized>(
    enabled: bool,
    sink: &mut S,
    output: Output,
    high: bool,
    t_device_us: u64,
    seq: u64,
) {
    if enabled {
        sink.send(BoardMessage::Edge(Edge {
            output,
            high,
            t_device_us,
            seq,
        }));
    }
}

/// The event sent when the pulse's trigger falls (or it is stopped).
pub(super) fn pulse_event(pulse: &Pulse) -> PulseEvent {
    let (t_flash_on_us, t_flash_off_us) = match pulse.flash {
        Flash::Done { t_on_us, t_off_us } => (t_on_us, t_off_us.max(t_on_us)),
        Flash::NotFired { t_us } => (t_us, t_us),
        // Not reachable: events are sent with the flash off. Report the trigger time.
        Flash::Pending { .. } | Flash::On { .. } => (pulse.t_trigger_us, pulse.t_trigger_us),
    };
    PulseEvent {
        seq: pulse.seq,
        t_trigger_us: pulse.t_trigger_us,
        t_flash_on_us,
        t_flash_off_us,
        flags: pulse.flags,
        bracket_step: pulse.bracket_step,
        flash_on_us: u32::try_from(t_flash_off_us - t_flash_on_us).unwrap_or(u32::MAX),
    }
}
