//! Errors of the trigger link ([`LinkError`]) and a board's refusal of a command in words
//! ([`describe_reject`]).
//!
//! Contract: every error names what failed — the path that could not be opened, both protocol
//! versions of a mismatch, the command that timed out (with its timeout) or was refused (with
//! the board's typed reason, worded for the user: which limit was crossed, with its value where
//! the board sends one, or what to do).

use ellipso_protocol::{CommandKind, RejectReason};

/// Errors of the trigger link.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The port or socket could not be opened.
    #[error("cannot open trigger board at {path}: {reason}")]
    Open {
        /// What was opened.
        path: String,
        /// Why it failed.
        reason: String,
    },
    /// The board speaks another protocol version.
    #[error(
        "trigger board '{board_name}' speaks protocol v{board}, this ellipso speaks v{host}: \
         flash matching firmware or use a matching ellipso"
    )]
    VersionMismatch {
        /// The board's version.
        board: u16,
        /// Ours.
        host: u16,
        /// The board's name.
        board_name: String,
    },
    /// No reply in time.
    #[error("no reply from the trigger board to {command:?} within {timeout_ms} ms")]
    Timeout {
        /// The command.
        command: CommandKind,
        /// The timeout, ms.
        timeout_ms: u64,
    },
    /// The board refused the command.
    #[error("the trigger board refused {command:?}: {}", describe_reject(reason))]
    Rejected {
        /// The command.
        command: CommandKind,
        /// The board's reason.
        reason: RejectReason,
    },
    /// The stream is gone.
    #[error("trigger link disconnected: {0}")]
    Disconnected(String),
    /// Writing failed.
    #[error("writing to the trigger link failed: {0}")]
    Io(#[from] std::io::Error),
}

/// A readable sentence for a board's refusal.
pub fn describe_reject(reason: &RejectReason) -> String {
    match reason {
        RejectReason::FlashOutsideExposure => {
            "the flash would light outside the exposure (flash delay + on-time > exposure; with a \
             bracket, its longest step's on-time)"
                .into()
        }
        RejectReason::FlashTooLong { max_us } => {
            format!("flash on-time above the LED's safe maximum of {max_us} µs")
        }
        RejectReason::DutyCycleTooHigh { max_permille } => format!(
            "flash duty cycle above the LED's thermal limit of {:.1} %",
            *max_permille as f64 / 10.0
        ),
        RejectReason::PeriodTooShort { min_us } => {
            format!("frame period too short for exposure + readout: at least {min_us} µs")
        }
        RejectReason::ExposureOutOfRange => "exposure outside the board's range".into(),
        RejectReason::PeriodOutOfRange => "frame period outside the board's range".into(),
        RejectReason::CountOutOfRange => "pulse count 0 or above the board's maximum".into(),
        RejectReason::NotConfigured => "no capture configured yet".into(),
        RejectReason::NotArmed => "the board is not armed".into(),
        RejectReason::Busy => "a capture is running; stop it first".into(),
        RejectReason::WrongTriggerSource => {
            "the capture's trigger source is not host command".into()
        }
        RejectReason::TooSoon { wait_us } => {
            format!("too soon after the last pulse; wait {wait_us} µs")
        }
        RejectReason::ProtocolMismatch { board } => format!("the board speaks protocol v{board}"),
        RejectReason::BracketStepOutOfRange { step } => {
            format!("bracket step {step}: relative energy outside (0, 1]")
        }
        RejectReason::BracketStepTooShort { step } => format!(
            "bracket step {step}: its flash on-time rounds to 0 µs (raise the flash duration or \
             that step's energy; a bracket needs a flash)"
        ),
    }
}
