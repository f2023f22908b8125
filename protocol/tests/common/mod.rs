//! Random messages of every variant, for property, noise and chunking tests (seeded).

#![allow(dead_code, reason = "each test binary uses a different subset")]

use ellipso_protocol::*;
use rand::Rng;

/// Integers biased toward the edges of their range, where varint encodings change length.
pub fn edgy_u64(rng: &mut impl Rng) -> u64 {
    match rng.random_range(0..6) {
        0 => 0,
        1 => u64::MAX,
        2 => rng.random_range(0..300),
        3 => 1 << rng.random_range(0..64),
        _ => rng.random(),
    }
}

pub fn edgy_u32(rng: &mut impl Rng) -> u32 {
    edgy_u64(rng) as u32
}

fn config(rng: &mut impl Rng) -> CaptureConfig {
    CaptureConfig {
        exposure_us: edgy_u32(rng),
        flash_delay_us: edgy_u32(rng),
        flash_duration_us: edgy_u32(rng),
        frame_period_us: edgy_u32(rng),
        pulses: if rng.random_bool(0.5) {
            PulseCount::Continuous
        } else {
            PulseCount::Count(edgy_u32(rng))
        },
        trigger: match rng.random_range(0..3) {
            0 => TriggerSource::HostCommand,
            1 => TriggerSource::GripButton,
            _ => TriggerSource::FreeRun,
        },
        report_edges: rng.random_bool(0.5),
        bracket: bracket(rng),
    }
}

/// 0..=MAX_BRACKET_STEPS steps of any u16 (the codec does not range-check them).
pub fn bracket(rng: &mut impl Rng) -> Bracket {
    let len = rng.random_range(0..=MAX_BRACKET_STEPS);
    let steps: Vec<u16> = (0..len).map(|_| edgy_u32(rng) as u16).collect();
    Bracket::from_q15(&steps).expect("at most MAX_BRACKET_STEPS")
}

pub fn host_message(rng: &mut impl Rng) -> HostMessage {
    match rng.random_range(0..9) {
        8 => HostMessage::EnterBootloader,
        0 => HostMessage::Hello {
            protocol_version: edgy_u32(rng) as u16,
        },
        1 => HostMessage::Configure(config(rng)),
        2 => HostMessage::Arm,
        3 => HostMessage::FireOne,
        4 => HostMessage::Start,
        5 => HostMessage::Stop,
        6 => HostMessage::Ping {
            nonce: edgy_u32(rng),
        },
        _ => HostMessage::StatusRequest,
    }
}

fn command(rng: &mut impl Rng) -> CommandKind {
    match rng.random_range(0..9) {
        8 => CommandKind::EnterBootloader,
        0 => CommandKind::Hello,
        1 => CommandKind::Configure,
        2 => CommandKind::Arm,
        3 => CommandKind::FireOne,
        4 => CommandKind::Start,
        5 => CommandKind::Stop,
        6 => CommandKind::Ping,
        _ => CommandKind::StatusRequest,
    }
}

fn reason(rng: &mut impl Rng) -> RejectReason {
    match rng.random_range(0..15) {
        0 => RejectReason::FlashOutsideExposure,
        1 => RejectReason::FlashTooLong {
            max_us: edgy_u32(rng),
        },
        2 => RejectReason::DutyCycleTooHigh {
            max_permille: edgy_u32(rng) as u16,
        },
        3 => RejectReason::PeriodTooShort {
            min_us: edgy_u32(rng),
        },
        4 => RejectReason::ExposureOutOfRange,
        5 => RejectReason::PeriodOutOfRange,
        6 => RejectReason::CountOutOfRange,
        7 => RejectReason::NotConfigured,
        8 => RejectReason::NotArmed,
        9 => RejectReason::Busy,
        10 => RejectReason::WrongTriggerSource,
        11 => RejectReason::TooSoon {
            wait_us: edgy_u32(rng),
        },
        12 => RejectReason::ProtocolMismatch {
            board: edgy_u32(rng) as u16,
        },
        13 => RejectReason::BracketStepOutOfRange { step: rng.random() },
        _ => RejectReason::BracketStepTooShort { step: rng.random() },
    }
}

fn name(rng: &mut impl Rng) -> heapless::String<BOARD_NAME_MAX> {
    let mut s = heapless::String::new();
    let len = rng.random_range(0..=BOARD_NAME_MAX / 2);
    for _ in 0..len {
        // two-byte UTF-8 characters too, so the name can reach its byte limit
        let c = if rng.random_bool(0.3) {
            'é'
        } else {
            char::from(rng.random_range(b'a'..=b'z'))
        };
        let _ = s.push(c);
    }
    s
}

fn counters(rng: &mut impl Rng) -> FaultCounters {
    FaultCounters {
        bad_frames: edgy_u32(rng),
        late_edges: edgy_u32(rng),
        flash_forced_off: edgy_u32(rng),
        flash_skipped: edgy_u32(rng),
        tx_overflows: edgy_u32(rng),
        rejected_commands: edgy_u32(rng),
    }
}

fn fault(rng: &mut impl Rng) -> Fault {
    match rng.random_range(0..4) {
        0 => Fault::BadFrame(match rng.random_range(0..5) {
            0 => BadFrameKind::Cobs,
            1 => BadFrameKind::Crc,
            2 => BadFrameKind::Overflow,
            3 => BadFrameKind::UnknownMessage,
            _ => BadFrameKind::Malformed,
        }),
        1 => Fault::DeadlineMissed {
            seq: edgy_u64(rng),
            late_by_us: edgy_u32(rng),
        },
        2 => Fault::FlashForcedOff {
            seq: edgy_u64(rng),
            on_for_us: edgy_u32(rng),
        },
        _ => Fault::FlashSkipped { seq: edgy_u64(rng) },
    }
}

pub fn board_message(rng: &mut impl Rng) -> BoardMessage {
    match rng.random_range(0..8) {
        0 => BoardMessage::HelloReply(BoardInfo {
            protocol_version: edgy_u32(rng) as u16,
            firmware_version: FirmwareVersion {
                major: rng.random(),
                minor: rng.random(),
                patch: rng.random(),
            },
            board_name: name(rng),
            timer_clock_hz: edgy_u32(rng),
            limits: BoardLimits {
                min_exposure_us: edgy_u32(rng),
                max_exposure_us: edgy_u32(rng),
                max_flash_on_us: edgy_u32(rng),
                max_flash_duty_permille: edgy_u32(rng) as u16,
                readout_us: edgy_u32(rng),
                min_frame_period_us: edgy_u32(rng),
                max_frame_period_us: edgy_u32(rng),
                max_pulse_count: edgy_u32(rng),
            },
        }),
        1 => BoardMessage::Ack(command(rng)),
        2 => BoardMessage::Rejected {
            command: command(rng),
            reason: reason(rng),
        },
        3 => BoardMessage::Pulse(PulseEvent {
            seq: edgy_u64(rng),
            t_trigger_us: edgy_u64(rng),
            t_flash_on_us: edgy_u64(rng),
            t_flash_off_us: edgy_u64(rng),
            flags: rng.random(),
            bracket_step: rng.random(),
            flash_on_us: edgy_u32(rng),
        }),
        4 => BoardMessage::Pong {
            nonce: edgy_u32(rng),
            t_device_us: edgy_u64(rng),
        },
        5 => BoardMessage::Status(Status {
            state: match rng.random_range(0..4) {
                0 => BoardState::Idle,
                1 => BoardState::Configured,
                2 => BoardState::Armed,
                _ => BoardState::Running,
            },
            pulses_fired: edgy_u64(rng),
            t_device_us: edgy_u64(rng),
            faults: counters(rng),
        }),
        6 => BoardMessage::Fault(fault(rng)),
        _ => BoardMessage::Edge(Edge {
            output: if rng.random_bool(0.5) {
                Output::CameraTrigger
            } else {
                Output::Flash
            },
            high: rng.random_bool(0.5),
            t_device_us: edgy_u64(rng),
            seq: edgy_u64(rng),
        }),
    }
}

/// Encodes one message into a fresh Vec (frame with delimiter).
pub fn frame<M: Message>(msg: &M) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = encode(msg, &mut buf).expect("every message fits a frame");
    buf[..n].to_vec()
}
