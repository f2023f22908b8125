//! Every message that crosses the link, in both directions, and the types they carry.
//!
//! Contract:
//! - [`HostMessage`] travels host → board, [`BoardMessage`] board → host. Both are postcard-encoded
//!   (varint discriminants in declaration order, varint integers), so **the order of variants and
//!   fields is the wire format**: append new variants at the end and bump
//!   [`PROTOCOL_VERSION`](crate::PROTOCOL_VERSION) on any incompatible change. The spec test
//!   vectors in `docs/protocol.md` fail when the encoding drifts.
//! - Times on the board are microseconds of a 64-bit monotonic device clock (`t_device_us`), never
//!   host time. Durations are `*_us` in `u32`.
//! - Every message fits in [`MAX_MESSAGE_LEN`](crate::MAX_MESSAGE_LEN) bytes of postcard; a test
//!   encodes the worst case of every variant.

use heapless::String;
use serde::{Deserialize, Serialize};

use crate::bracket::Bracket;

/// What starts each pulse once a capture is running.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub enum TriggerSource {
    /// Each [`HostMessage::FireOne`] fires one pulse.
    HostCommand,
    /// Each press of the grip button fires one pulse.
    GripButton,
    /// Pulses repeat every `frame_period_us` from [`HostMessage::Start`].
    FreeRun,
}

/// How many pulses a capture fires before it ends by itself.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub enum PulseCount {
    /// Until [`HostMessage::Stop`].
    Continuous,
    /// Exactly this many pulses (must be ≥ 1 and within the board's limit).
    Count(u32),
}

/// One capture's timing, validated by the board against its [`BoardLimits`].
///
/// Within each frame period the board raises the camera trigger at `t0` (the exposure starts),
/// turns the flash on at `t0 + flash_delay_us` and off at `t0 + flash_delay_us + flash_duration_us`,
/// and lowers the trigger at `t0 + exposure_us`. The flash must lie inside the exposure:
/// `flash_delay_us + flash_duration_us ≤ exposure_us`. `flash_duration_us = 0` means no flash.
///
/// With a [`Bracket`], `flash_duration_us` is the on-time of relative energy 1 and pulse `k`
/// is lit for step `k mod len`'s share of it ([`Bracket::on_time_us`]); the rules above then
/// apply to the longest on-time the bracket fires (see `ellipso_firmware::CapturePlan`).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct CaptureConfig {
    /// Exposure (trigger high) length, µs.
    pub exposure_us: u32,
    /// Flash-on delay after the trigger's rising edge, µs.
    pub flash_delay_us: u32,
    /// Flash-on length, µs (0: no flash).
    pub flash_duration_us: u32,
    /// Minimum time between two trigger rising edges, µs (the period in free run).
    pub frame_period_us: u32,
    /// Pulse count or continuous.
    pub pulses: PulseCount,
    /// What fires each pulse.
    pub trigger: TriggerSource,
    /// Also send one [`BoardMessage::Edge`] per output transition (debug: the emulator has no GPIO).
    pub report_edges: bool,
    /// Flash-energy bracket fired in turn ([`Bracket::NONE`]: every pulse at energy 1).
    pub bracket: Bracket,
}

/// Messages from the host to the board.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub enum HostMessage {
    /// Opens the session; the board answers [`BoardMessage::HelloReply`] whatever the version.
    Hello {
        /// The host's [`PROTOCOL_VERSION`](crate::PROTOCOL_VERSION).
        protocol_version: u16,
    },
    /// Sets the capture timing; answered by `Ack` or `Rejected` with the reason.
    Configure(CaptureConfig),
    /// Prepares the outputs for a capture with the current configuration.
    Arm,
    /// Fires one pulse now (trigger source [`TriggerSource::HostCommand`]).
    FireOne,
    /// Starts the capture (free run begins; button or host pulses are accepted).
    Start,
    /// Stops the capture; the flash is off when the `Ack` is sent.
    Stop,
    /// Clock-sync probe: the board answers [`BoardMessage::Pong`] with its time.
    Ping {
        /// Echoed back unchanged.
        nonce: u32,
    },
    /// Asks for a [`BoardMessage::Status`].
    StatusRequest,
    /// Reboot into the USB DFU bootloader for a firmware update (`ellipso board flash`): the
    /// board stops any capture, writes both outputs low, sends the `Ack` and then resets into
    /// its bootloader; the serial port goes away. Refused with `Busy` while a capture runs.
    /// Appended (protocol version 3), so every older message keeps its encoding; a board
    /// older than this command answers `Fault(BadFrame(UnknownMessage))`.
    EnterBootloader,
}

/// Which command an `Ack` or `Rejected` answers.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub enum CommandKind {
    /// [`HostMessage::Hello`].
    Hello,
    /// [`HostMessage::Configure`].
    Configure,
    /// [`HostMessage::Arm`].
    Arm,
    /// [`HostMessage::FireOne`].
    FireOne,
    /// [`HostMessage::Start`].
    Start,
    /// [`HostMessage::Stop`].
    Stop,
    /// [`HostMessage::Ping`].
    Ping,
    /// [`HostMessage::StatusRequest`].
    StatusRequest,
    /// [`HostMessage::EnterBootloader`].
    EnterBootloader,
}

impl HostMessage {
    /// The command kind this message is, for matching replies.
    pub fn kind(&self) -> CommandKind {
        match self {
            Self::Hello { .. } => CommandKind::Hello,
            Self::Configure(_) => CommandKind::Configure,
            Self::Arm => CommandKind::Arm,
            Self::FireOne => CommandKind::FireOne,
            Self::Start => CommandKind::Start,
            Self::Stop => CommandKind::Stop,
            Self::Ping { .. } => CommandKind::Ping,
            Self::StatusRequest => CommandKind::StatusRequest,
            Self::EnterBootloader => CommandKind::EnterBootloader,
        }
    }
}

/// Why the board refused a command.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub enum RejectReason {
    /// `flash_delay_us + flash_duration_us > exposure_us`: the flash would light outside the exposure.
    FlashOutsideExposure,
    /// The flash would stay on longer than the LED's safe maximum.
    FlashTooLong {
        /// The board's maximum flash on-time, µs.
        max_us: u32,
    },
    /// Flash on-time / frame period exceeds the LED's thermal duty-cycle limit.
    DutyCycleTooHigh {
        /// The board's limit, per mille.
        max_permille: u16,
    },
    /// `frame_period_us < exposure_us + readout_us`: the sensor could not read out in time.
    PeriodTooShort {
        /// The shortest acceptable period for this exposure, µs.
        min_us: u32,
    },
    /// Exposure outside `[min_exposure_us, max_exposure_us]`.
    ExposureOutOfRange,
    /// Frame period above `max_frame_period_us` or below `min_frame_period_us`.
    PeriodOutOfRange,
    /// Pulse count 0 or above `max_pulse_count`.
    CountOutOfRange,
    /// The command needs a configuration first.
    NotConfigured,
    /// The command needs the board armed first.
    NotArmed,
    /// A capture is running; stop it first.
    Busy,
    /// `FireOne` with a trigger source other than host command.
    WrongTriggerSource,
    /// `FireOne` sooner than one frame period after the previous pulse.
    TooSoon {
        /// How long to wait, µs.
        wait_us: u32,
    },
    /// The host's protocol version is not this board's.
    ProtocolMismatch {
        /// The board's protocol version.
        board: u16,
    },
    /// A bracket step's relative energy is 0 or above 1.0 (Q15 above
    /// [`ENERGY_ONE_Q15`](crate::ENERGY_ONE_Q15)).
    BracketStepOutOfRange {
        /// Index of the first offending step, from 0.
        step: u8,
    },
    /// A bracket step's on-time rounds to 0 device-clock ticks (µs): too little energy to
    /// realise with this `flash_duration_us`, or a bracket without a flash.
    BracketStepTooShort {
        /// Index of the first offending step, from 0.
        step: u8,
    },
}

/// Firmware version, semantic.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct FirmwareVersion {
    /// Major.
    pub major: u8,
    /// Minor.
    pub minor: u8,
    /// Patch.
    pub patch: u8,
}

/// A board's safety and timing limits; every configuration is checked against them.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct BoardLimits {
    /// Shortest exposure, µs.
    pub min_exposure_us: u32,
    /// Longest exposure, µs.
    pub max_exposure_us: u32,
    /// Longest flash on-time, µs; the sequencer forces the flash off at this age whatever happens.
    pub max_flash_on_us: u32,
    /// Largest flash duty cycle, per mille: `1000 · flash_duration_us / frame_period_us ≤` this.
    pub max_flash_duty_permille: u16,
    /// Sensor readout time after an exposure, µs: `frame_period_us ≥ exposure_us + readout_us`.
    pub readout_us: u32,
    /// Shortest frame period, µs.
    pub min_frame_period_us: u32,
    /// Longest frame period, µs.
    pub max_frame_period_us: u32,
    /// Largest pulse count of a counted capture.
    pub max_pulse_count: u32,
}

/// Maximum length of a board name, bytes of UTF-8.
pub const BOARD_NAME_MAX: usize = 24;

/// The board's answer to `Hello`.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq, Eq)]
pub struct BoardInfo {
    /// The board's [`PROTOCOL_VERSION`](crate::PROTOCOL_VERSION).
    pub protocol_version: u16,
    /// Firmware version.
    pub firmware_version: FirmwareVersion,
    /// Human-readable board name, e.g. `"qemu-netduinoplus2"`.
    pub board_name: String<BOARD_NAME_MAX>,
    /// Frequency of the timer behind the device clock, Hz (resolution of edge times).
    pub timer_clock_hz: u32,
    /// Safety and timing limits.
    pub limits: BoardLimits,
}

/// Flags on a [`PulseEvent`]; bit set, see the `PULSE_*` constants.
pub type PulseFlags = u8;
/// The flash was skipped for this pulse (its on-deadline was missed too late to fit the exposure).
pub const PULSE_FLASH_SKIPPED: PulseFlags = 1 << 0;
/// The flash was forced off at its maximum on-time (its off-deadline was missed).
pub const PULSE_FLASH_FORCED_OFF: PulseFlags = 1 << 1;
/// At least one edge of this pulse was later than planned.
pub const PULSE_LATE: PulseFlags = 1 << 2;
/// The configuration had no flash (`flash_duration_us = 0`).
pub const PULSE_NO_FLASH: PulseFlags = 1 << 3;
/// The pulse was cut short by `Stop` (its times show where).
pub const PULSE_STOPPED: PulseFlags = 1 << 4;

/// One pulse: sent once its flash is off (or its exposure ended without flash).
///
/// `flash_on_us` is the flash's actual on-time, `t_flash_off_us − t_flash_on_us` (0 when it did
/// not light); with the capture's `flash_duration_us` it gives the pulse's relative energy.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct PulseEvent {
    /// Pulse sequence number since boot, from 0, never reused; the host pairs frames by it.
    pub seq: u64,
    /// Camera trigger rising edge (exposure start), device µs.
    pub t_trigger_us: u64,
    /// Flash on, device µs (equals `t_flash_off_us` when no flash fired).
    pub t_flash_on_us: u64,
    /// Flash off, device µs.
    pub t_flash_off_us: u64,
    /// `PULSE_*` flags.
    pub flags: PulseFlags,
    /// The bracket step this pulse fired (`seq`'s place in its capture mod the bracket length;
    /// 0 without a bracket).
    pub bracket_step: u8,
    /// Actual flash on-time, device µs (saturating; 0 when the flash did not light).
    pub flash_on_us: u32,
}

/// The board's state machine.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub enum BoardState {
    /// No configuration yet.
    Idle,
    /// Configured, not armed.
    Configured,
    /// Armed, waiting for `Start` (or `FireOne` for host-command captures).
    Armed,
    /// A capture is running.
    Running,
}

/// Counters of everything that went wrong since boot.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FaultCounters {
    /// Frames from the host that failed to decode (CRC, COBS, overflow, unknown message).
    pub bad_frames: u32,
    /// Edges executed later than planned.
    pub late_edges: u32,
    /// Flashes forced off at their maximum on-time.
    pub flash_forced_off: u32,
    /// Flashes skipped because their on-deadline was missed.
    pub flash_skipped: u32,
    /// Replies dropped because the transmit queue was full.
    pub tx_overflows: u32,
    /// Commands rejected.
    pub rejected_commands: u32,
}

/// The answer to `StatusRequest` (also sent when a counted capture completes).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct Status {
    /// State.
    pub state: BoardState,
    /// Pulses fired since boot.
    pub pulses_fired: u64,
    /// Device time of this status, µs.
    pub t_device_us: u64,
    /// Fault counters.
    pub faults: FaultCounters,
}

/// Which class of bad frame the board received (detail of [`Fault::BadFrame`]).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub enum BadFrameKind {
    /// COBS structure broken.
    Cobs,
    /// CRC mismatch.
    Crc,
    /// Longer than the maximum frame.
    Overflow,
    /// Unknown message discriminant.
    UnknownMessage,
    /// Known message, malformed body.
    Malformed,
}

/// Something went wrong on the board; sent as it happens.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// A frame from the host was dropped.
    BadFrame(BadFrameKind),
    /// An edge of pulse `seq` ran `late_by_us` after its deadline.
    DeadlineMissed {
        /// Pulse sequence number.
        seq: u64,
        /// Lateness, µs (saturating).
        late_by_us: u32,
    },
    /// The flash of pulse `seq` was forced off after `on_for_us`.
    FlashForcedOff {
        /// Pulse sequence number.
        seq: u64,
        /// How long it had been on, µs (saturating).
        on_for_us: u32,
    },
    /// The flash of pulse `seq` was skipped (its on-deadline was missed).
    FlashSkipped {
        /// Pulse sequence number.
        seq: u64,
    },
}

/// A board output.
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    /// Camera trigger (high = exposing).
    CameraTrigger,
    /// Flash LED driver (high = lit).
    Flash,
}

/// One output transition (sent only with `report_edges`).
#[derive(Serialize, Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
pub struct Edge {
    /// Which output.
    pub output: Output,
    /// New level.
    pub high: bool,
    /// When it was set, device µs.
    pub t_device_us: u64,
    /// Pulse it belongs to.
    pub seq: u64,
}

/// Messages from the board to the host.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq, Eq)]
pub enum BoardMessage {
    /// Answer to `Hello`.
    HelloReply(BoardInfo),
    /// The command was accepted.
    Ack(CommandKind),
    /// The command was refused.
    Rejected {
        /// Which command.
        command: CommandKind,
        /// Why.
        reason: RejectReason,
    },
    /// One pulse fired.
    Pulse(PulseEvent),
    /// Answer to `Ping`.
    Pong {
        /// The ping's nonce.
        nonce: u32,
        /// Device time when the ping was handled, µs.
        t_device_us: u64,
    },
    /// Board status.
    Status(Status),
    /// A fault.
    Fault(Fault),
    /// One output transition (debug, see [`CaptureConfig::report_edges`]).
    Edge(Edge),
}
