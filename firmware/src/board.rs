//! The board: the command state machine between the link and the [`Sequencer`].
//!
//! A port owns one [`Board`] and calls it from four places, always with the current device time
//! `now_us` (µs, monotonic):
//!
//! | when | call |
//! |---|---|
//! | each received byte (UART ISR, USB read, pty) | [`Board::feed_rx_byte`] (or [`Board::handle`] with an already decoded message, [`Board::on_bad_frame`] with a decoder error) |
//! | at [`Board::next_deadline`] (timer alarm) or in a loop | [`Board::poll`] |
//! | a grip-button press (EXTI ISR) | [`Board::button_pressed`], then re-arm the alarm from `next_deadline` |
//! | boot | [`Board::new`], then [`Board::reset_outputs`] |
//!
//! After any call, re-read [`Board::next_deadline`]: commands (Start, FireOne) and presses
//! schedule edges. Replies go to a [`MessageSink`] (a closure, a [`TxQueue`](crate::TxQueue), or a
//! [`FrameWriter`](crate::FrameWriter) that writes wire frames); a sink that drops a message
//! counts in `tx_overflows` and nothing else changes. Nothing here blocks, allocates or panics on
//! any input, so all of it may run in interrupt context (the same context for all calls, or under
//! one critical section).
//!
//! # States ([`BoardState`]) and replies
//!
//! `Idle` (no configuration) → `Configured` → `Armed` → `Running`. A capture ends (`Stop`, or the
//! last pulse of a counted capture) in `Configured`: every capture needs its own `Arm`.
//!
//! | command | Idle | Configured | Armed | Running |
//! |---|---|---|---|---|
//! | `Hello` | `HelloReply` | same | same | same |
//! | `Configure(c)` | Ack → Configured, or `Rejected(reason)` from [`CapturePlan::new`] | same | same (disarms) | `Busy` |
//! | `Arm` | `NotConfigured` | outputs low, Ack → Armed | Ack | `Busy` |
//! | `Start` | `NotConfigured` | `NotArmed` | Ack → Running | `Busy` |
//! | `FireOne` | `NotConfigured` | `WrongTriggerSource` / `NotArmed` | `WrongTriggerSource` / fire → Running / `TooSoon` | `WrongTriggerSource` / fire / `TooSoon` / `Busy` |
//! | `Stop` | Ack | Ack | Ack → Configured | flash off, trigger low, Ack → Configured |
//! | `Ping { nonce }` | `Pong { nonce, t_device_us: now }` | same | same | same |
//! | `StatusRequest` | `Status` | same | same | same |
//! | `EnterBootloader` | outputs low, Ack, bootloader requested | same | same | `Busy` |
//!
//! - `FireOne` needs [`TriggerSource::HostCommand`] (checked before the armed state); it starts
//!   the capture when armed, fires one pulse at `now + lead_us`, and is refused with
//!   `TooSoon { wait_us }` within one frame period of the previous trigger (or before the sensor
//!   has read out), or `Busy` when a counted capture has all its pulses.
//! - `Hello` is answered whatever the host's protocol version, with the board's, so the host can
//!   report both; the host's version is kept in [`Board::host_protocol_version`]. After a `Hello`
//!   with another version, the commands that act (`Configure`, `Arm`, `Start`, `FireOne`) are
//!   refused with `ProtocolMismatch { board }` until a `Hello` with the board's version arrives: a
//!   frame from a host with another message layout may decode into a different configuration.
//!   `Stop`, `Ping` and `StatusRequest` always work. A host that never says `Hello` is trusted.
//! - `Stop` is always accepted and always writes both outputs low first: it is the host's
//!   panic button. Its `Ack` is sent after the flash is off.
//! - Each `Rejected` counts in `rejected_commands`; a bad frame counts in `bad_frames` and is
//!   answered with `Fault(BadFrame(kind))`; neither changes the state.
//! - `EnterBootloader` only records the request ([`Board::take_bootloader_request`]): the port
//!   resets into the chip's DFU bootloader once the `Ack` has left (a reset from here would cut
//!   the reply). A running capture refuses it (`Busy`): a firmware update never cuts a scan.
//! - When a counted capture completes, `poll` sends a `Status` (state `Configured`).
//! - Grip-button presses are accepted while `Running` with [`TriggerSource::GripButton`]; a press
//!   within one frame period of the previous trigger is debounced (ignored).

use ellipso_protocol::{
    BoardInfo, BoardLimits, BoardMessage, BoardState, CommandKind, Decoder, Fault, FaultCounters,
    FrameError, HostMessage, PROTOCOL_VERSION, RejectReason, Status, TriggerSource,
};

use crate::config::{BoardConfig, ConfigError};
use crate::outputs::Outputs;
use crate::plan::CapturePlan;
use crate::sequencer::{PollOutcome, Sequencer};
use crate::sink::MessageSink;

/// What a grip-button press did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ButtonOutcome {
    /// A pulse was scheduled; its trigger rises at `t_trigger_us`.
    Fired {
        /// Planned trigger edge, device µs.
        t_trigger_us: u64,
    },
    /// Within one frame period of the previous trigger (a bounce, or pressed too fast): ignored.
    Debounced,
    /// No grip-button capture is running, or a counted one has all its pulses: ignored.
    Ignored,
}

/// Counts messages a sink dropped.
struct Counted<'a, S: ?Sized> {
    inner: &'a mut S,
    dropped: u32,
}

impl<S: MessageSink + ?Sized> MessageSink for Counted<'_, S> {
    fn send(&mut self, msg: BoardMessage) -> bool {
        let ok = self.inner.send(msg);
        if !ok {
            self.dropped = self.dropped.saturating_add(1);
        }
        ok
    }
}

/// The trigger board's command state machine; see the [module docs](self).
#[derive(Clone)]
pub struct Board {
    info: BoardInfo,
    plan: Option<CapturePlan>,
    armed: bool,
    sequencer: Sequencer,
    decoder: Decoder<HostMessage>,
    host_protocol_version: Option<u16>,
    bad_frames: u32,
    tx_overflows: u32,
    rejected_commands: u32,
    bootloader_requested: bool,
}

impl Board {
    /// A board in `Idle`; refuses a contradictory [`BoardConfig`] (see [`BoardConfig::check`]).
    pub fn new(config: BoardConfig) -> Result<Self, ConfigError> {
        Ok(Self {
            info: config.board_info()?,
            plan: None,
            armed: false,
            sequencer: Sequencer::new(config.timing),
            decoder: Decoder::new(),
            host_protocol_version: None,
            bad_frames: 0,
            tx_overflows: 0,
            rejected_commands: 0,
            bootloader_requested: false,
        })
    }

    /// Whether the host asked for the DFU bootloader ([`HostMessage::EnterBootloader`]), and
    /// clears the request. The port calls it after sending its replies and, when `true`, resets
    /// into the bootloader.
    pub fn take_bootloader_request(&mut self) -> bool {
        core::mem::take(&mut self.bootloader_requested)
    }

    /// The `HelloReply` payload.
    pub fn info(&self) -> &BoardInfo {
        &self.info
    }

    /// The limits every configuration is checked against.
    pub fn limits(&self) -> &BoardLimits {
        &self.info.limits
    }

    /// The current state.
    pub fn state(&self) -> BoardState {
        if self.sequencer.is_running() {
            BoardState::Running
        } else if self.armed {
            BoardState::Armed
        } else if self.plan.is_some() {
            BoardState::Configured
        } else {
            BoardState::Idle
        }
    }

    /// The accepted configuration, if any.
    pub fn plan(&self) -> Option<&CapturePlan> {
        self.plan.as_ref()
    }

    /// The sequencer (read-only: pulse counts, levels, deadlines).
    pub fn sequencer(&self) -> &Sequencer {
        &self.sequencer
    }

    /// The protocol version of the last `Hello`, if one arrived.
    pub fn host_protocol_version(&self) -> Option<u16> {
        self.host_protocol_version
    }

    /// All fault counters since boot.
    pub fn faults(&self) -> FaultCounters {
        let c = self.sequencer.counters();
        FaultCounters {
            bad_frames: self.bad_frames,
            late_edges: c.late_edges,
            flash_forced_off: c.flash_forced_off,
            flash_skipped: c.flash_skipped,
            tx_overflows: self.tx_overflows,
            rejected_commands: self.rejected_commands,
        }
    }

    /// The status at `now_us`.
    pub fn status(&self, now_us: u64) -> Status {
        Status {
            state: self.state(),
            pulses_fired: self.sequencer.pulses_fired(),
            t_device_us: now_us,
            faults: self.faults(),
        }
    }

    /// When [`Board::poll`] must next run, device µs; `None` when nothing is scheduled.
    pub fn next_deadline(&self) -> Option<u64> {
        self.sequencer.next_deadline()
    }

    /// Writes flash off, then trigger low (at boot, and by `Arm` and `Stop`).
    pub fn reset_outputs<O: Outputs + ?Sized>(&self, now_us: u64, outputs: &mut O) {
        outputs.flash_off(now_us);
        outputs.set_camera(false, now_us);
    }

    /// Runs every edge due at `now_us`; when a counted capture completes, sends a `Status`.
    pub fn poll<O, S>(&mut self, now_us: u64, outputs: &mut O, sink: &mut S)
    where
        O: Outputs + ?Sized,
        S: MessageSink + ?Sized,
    {
        let mut sink = Counted {
            inner: sink,
            dropped: 0,
        };
        if self.sequencer.poll(now_us, outputs, &mut sink) == PollOutcome::Complete {
            self.armed = false;
            self.tx_overflows = self.tx_overflows.saturating_add(sink.dropped);
            sink.dropped = 0;
            sink.send(BoardMessage::Status(self.status(now_us)));
        }
        self.tx_overflows = self.tx_overflows.saturating_add(sink.dropped);
    }

    /// Feeds one received byte to the frame decoder; a completed frame is handled at `now_us`
    /// ([`Board::handle`]) or counted as bad ([`Board::on_bad_frame`]).
    pub fn feed_rx_byte<O, S>(&mut self, byte: u8, now_us: u64, outputs: &mut O, sink: &mut S)
    where
        O: Outputs + ?Sized,
        S: MessageSink + ?Sized,
    {
        match self.decoder.push(byte) {
            Some(Ok(msg)) => self.handle(msg, now_us, outputs, sink),
            Some(Err(err)) => self.on_bad_frame(err, sink),
            None => {}
        }
    }

    /// Drops any partially received frame (e.g. after the host reconnects).
    pub fn reset_decoder(&mut self) {
        self.decoder.reset();
    }

    /// Counts a frame the decoder dropped and reports `Fault(BadFrame(kind))`. Never fatal.
    pub fn on_bad_frame<S: MessageSink + ?Sized>(&mut self, err: FrameError, sink: &mut S) {
        self.bad_frames = self.bad_frames.saturating_add(1);
        let mut sink = Counted {
            inner: sink,
            dropped: 0,
        };
        sink.send(BoardMessage::Fault(Fault::BadFrame(err.kind())));
        self.tx_overflows = self.tx_overflows.saturating_add(sink.dropped);
    }

    /// A grip-button press at `now_us` (call from the button ISR; debouncing is done here).
    pub fn button_pressed(&mut self, now_us: u64) -> ButtonOutcome {
        if self.sequencer.plan().map(CapturePlan::trigger) != Some(TriggerSource::GripButton) {
            return ButtonOutcome::Ignored;
        }
        match self.sequencer.request_pulse(now_us) {
            Ok(t_trigger_us) => ButtonOutcome::Fired { t_trigger_us },
            Err(RejectReason::TooSoon { .. }) => ButtonOutcome::Debounced,
            Err(_) => ButtonOutcome::Ignored,
        }
    }

    /// Handles one decoded host message at `now_us`; see the state table in the
    /// [module docs](self).
    pub fn handle<O, S>(&mut self, msg: HostMessage, now_us: u64, outputs: &mut O, sink: &mut S)
    where
        O: Outputs + ?Sized,
        S: MessageSink + ?Sized,
    {
        let mut sink = Counted {
            inner: sink,
            dropped: 0,
        };
        let kind = msg.kind();
        let mismatch = self
            .host_protocol_version
            .is_some_and(|v| v != PROTOCOL_VERSION);
        let acts = matches!(
            msg,
            HostMessage::Configure(_)
                | HostMessage::Arm
                | HostMessage::Start
                | HostMessage::FireOne
        );
        let reply = match msg {
            _ if mismatch && acts => Err(RejectReason::ProtocolMismatch {
                board: PROTOCOL_VERSION,
            }),
            HostMessage::Hello { protocol_version } => {
                self.host_protocol_version = Some(protocol_version);
                Ok(BoardMessage::HelloReply(self.info.clone()))
            }
            HostMessage::Configure(config) => self.configure(config),
            HostMessage::Arm => self.arm(now_us, outputs),
            HostMessage::Start => self.start(now_us),
            HostMessage::FireOne => self.fire_one(now_us, outputs, &mut sink),
            HostMessage::Stop => {
                self.sequencer.stop(now_us, outputs, &mut sink);
                self.armed = false;
                Ok(BoardMessage::Ack(CommandKind::Stop))
            }
            HostMessage::Ping { nonce } => Ok(BoardMessage::Pong {
                nonce,
                t_device_us: now_us,
            }),
            HostMessage::StatusRequest => Ok(BoardMessage::Status(self.status(now_us))),
            HostMessage::EnterBootloader => {
                if self.state() == BoardState::Running {
                    Err(RejectReason::Busy)
                } else {
                    self.sequencer.stop(now_us, outputs, &mut sink);
                    self.armed = false;
                    self.bootloader_requested = true;
                    Ok(BoardMessage::Ack(CommandKind::EnterBootloader))
                }
            }
        };
        let reply = reply.unwrap_or_else(|reason| {
            self.rejected_commands = self.rejected_commands.saturating_add(1);
            BoardMessage::Rejected {
                command: kind,
                reason,
            }
        });
        sink.send(reply);
        self.tx_overflows = self.tx_overflows.saturating_add(sink.dropped);
    }

    fn configure(
        &mut self,
        config: ellipso_protocol::CaptureConfig,
    ) -> Result<BoardMessage, RejectReason> {
        if self.sequencer.is_running() {
            return Err(RejectReason::Busy);
        }
        let plan = CapturePlan::new(config, &self.info.limits)?;
        self.plan = Some(plan);
        self.armed = false;
        Ok(BoardMessage::Ack(CommandKind::Configure))
    }

    fn arm<O: Outputs + ?Sized>(
        &mut self,
        now_us: u64,
        outputs: &mut O,
    ) -> Result<BoardMessage, RejectReason> {
        if self.sequencer.is_running() {
            return Err(RejectReason::Busy);
        }
        if self.plan.is_none() {
            return Err(RejectReason::NotConfigured);
        }
        self.reset_outputs(now_us, outputs);
        self.armed = true;
        Ok(BoardMessage::Ack(CommandKind::Arm))
    }

    fn start(&mut self, now_us: u64) -> Result<BoardMessage, RejectReason> {
        if self.sequencer.is_running() {
            return Err(RejectReason::Busy);
        }
        let plan = self.plan.ok_or(RejectReason::NotConfigured)?;
        if !self.armed {
            return Err(RejectReason::NotArmed);
        }
        self.sequencer.start(plan, now_us)?;
        self.armed = false;
        Ok(BoardMessage::Ack(CommandKind::Start))
    }

    fn fire_one<O, S>(
        &mut self,
        now_us: u64,
        outputs: &mut O,
        sink: &mut S,
    ) -> Result<BoardMessage, RejectReason>
    where
        O: Outputs + ?Sized,
        S: MessageSink + ?Sized,
    {
        let running = self.sequencer.is_running();
        let plan = if running {
            self.sequencer.plan().copied()
        } else {
            self.plan
        };
        let plan = plan.ok_or(RejectReason::NotConfigured)?;
        if plan.trigger() != TriggerSource::HostCommand {
            return Err(RejectReason::WrongTriggerSource);
        }
        if !running {
            if !self.armed {
                return Err(RejectReason::NotArmed);
            }
            self.sequencer.start(plan, now_us)?;
        }
        match self.sequencer.request_pulse(now_us) {
            Ok(_) => {
                self.armed = false;
                Ok(BoardMessage::Ack(CommandKind::FireOne))
            }
            Err(reason) => {
                if !running {
                    // Back to Armed: the capture this FireOne started has no pulse.
                    self.sequencer.stop(now_us, outputs, sink);
                }
                Err(reason)
            }
        }
    }
}

#[cfg(test)]
mod tests;
