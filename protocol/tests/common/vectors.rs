//! The canonical example of every message, as listed in `docs/protocol.md` with its frame.

use ellipso_protocol::*;

/// Direction of a spec vector.
pub enum Vector {
    Host(HostMessage),
    Board(BoardMessage),
}

pub fn vectors() -> Vec<(&'static str, Vector)> {
    use Vector::{Board, Host};
    let config = CaptureConfig {
        exposure_us: 8_000,
        flash_delay_us: 500,
        flash_duration_us: 2_000,
        frame_period_us: 250_000,
        pulses: PulseCount::Count(150),
        trigger: TriggerSource::GripButton,
        report_edges: false,
        bracket: Bracket::NONE,
    };
    // 1, 1/4, 1/16 of the 2 ms full-energy pulse: 2000, 500 and 125 µs.
    let bracketed = CaptureConfig {
        bracket: Bracket::from_q15(&[ENERGY_ONE_Q15, 0x2000, 0x0800]).unwrap(),
        ..config
    };
    let limits = BoardLimits {
        min_exposure_us: 20,
        max_exposure_us: 1_000_000,
        max_flash_on_us: 5_000,
        max_flash_duty_permille: 100,
        readout_us: 20_000,
        min_frame_period_us: 10_000,
        max_frame_period_us: 10_000_000,
        max_pulse_count: 100_000,
    };
    vec![
        (
            "hello",
            Host(HostMessage::Hello {
                protocol_version: 2,
            }),
        ),
        ("configure", Host(HostMessage::Configure(config))),
        ("configure_bracket", Host(HostMessage::Configure(bracketed))),
        ("arm", Host(HostMessage::Arm)),
        ("fire_one", Host(HostMessage::FireOne)),
        ("start", Host(HostMessage::Start)),
        ("stop", Host(HostMessage::Stop)),
        ("ping", Host(HostMessage::Ping { nonce: 0x1234_5678 })),
        ("status_request", Host(HostMessage::StatusRequest)),
        (
            "hello_reply",
            Board(BoardMessage::HelloReply(BoardInfo {
                protocol_version: 2,
                firmware_version: FirmwareVersion {
                    major: 0,
                    minor: 1,
                    patch: 0,
                },
                board_name: heapless::String::try_from("qemu-netduinoplus2").unwrap(),
                timer_clock_hz: 1_000_000,
                limits,
            })),
        ),
        ("ack", Board(BoardMessage::Ack(CommandKind::Configure))),
        (
            "rejected",
            Board(BoardMessage::Rejected {
                command: CommandKind::Configure,
                reason: RejectReason::FlashOutsideExposure,
            }),
        ),
        (
            "rejected_bracket",
            Board(BoardMessage::Rejected {
                command: CommandKind::Configure,
                reason: RejectReason::BracketStepTooShort { step: 2 },
            }),
        ),
        (
            "pulse",
            Board(BoardMessage::Pulse(PulseEvent {
                seq: 41,
                t_trigger_us: 12_000_000,
                t_flash_on_us: 12_000_500,
                t_flash_off_us: 12_002_500,
                flags: 0,
                bracket_step: 0,
                flash_on_us: 2_000,
            })),
        ),
        (
            "pulse_bracket",
            Board(BoardMessage::Pulse(PulseEvent {
                seq: 43,
                t_trigger_us: 12_500_000,
                t_flash_on_us: 12_500_500,
                t_flash_off_us: 12_500_625,
                flags: 0,
                bracket_step: 2,
                flash_on_us: 125,
            })),
        ),
        (
            "pong",
            Board(BoardMessage::Pong {
                nonce: 0x1234_5678,
                t_device_us: 5_000_123,
            }),
        ),
        (
            "status",
            Board(BoardMessage::Status(Status {
                state: BoardState::Running,
                pulses_fired: 42,
                t_device_us: 12_250_000,
                faults: FaultCounters {
                    bad_frames: 1,
                    ..FaultCounters::default()
                },
            })),
        ),
        (
            "fault",
            Board(BoardMessage::Fault(Fault::FlashForcedOff {
                seq: 41,
                on_for_us: 5_000,
            })),
        ),
        (
            "edge",
            Board(BoardMessage::Edge(Edge {
                output: Output::Flash,
                high: true,
                t_device_us: 12_000_500,
                seq: 41,
            })),
        ),
    ]
}

pub fn encode_vector(v: &Vector) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = match v {
        Vector::Host(m) => encode(m, &mut buf),
        Vector::Board(m) => encode(m, &mut buf),
    }
    .expect("fits");
    buf[..n].to_vec()
}

pub fn hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}
