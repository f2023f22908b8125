//! Board tests: the shared rig and helpers, Hello/Ping, the state table, every Configure
//! rejection, bad frames through the byte path, edge reports, dropped replies and the bootloader
//! request; captures, the bracket and the byte-path property test are in `tests/`.

use super::*;
use crate::config::{LED_RIG_LIMITS, SequencerTiming};
use crate::outputs::RecordingOutputs;
use crate::sink::{FrameWriter, TxQueue};
use ellipso_protocol::{
    BadFrameKind, Bracket, CaptureConfig, MAX_FRAME_LEN, Output, PROTOCOL_VERSION, PulseCount,
    PulseEvent, encode,
};

pub(super) const LEAD: u64 = SequencerTiming::DEFAULT.lead_us as u64;

pub(super) struct Rig {
    pub(super) board: Board,
    pub(super) out: RecordingOutputs<64>,
}

impl Rig {
    pub(super) fn new() -> Self {
        let board = Board::new(BoardConfig::new("test-board", 1_000_000)).unwrap();
        Self {
            board,
            out: RecordingOutputs::new(),
        }
    }

    /// Handles `msg` at `now_us`; returns every message the board sent.
    pub(super) fn send(&mut self, msg: HostMessage, now_us: u64) -> Vec<BoardMessage> {
        let mut got = Vec::new();
        self.board
            .handle(msg, now_us, &mut self.out, &mut |m| got.push(m));
        got
    }

    /// Polls at every deadline up to and including `until_us`.
    pub(super) fn run_until(&mut self, until_us: u64) -> Vec<BoardMessage> {
        let mut got = Vec::new();
        while let Some(t) = self.board.next_deadline().filter(|&t| t <= until_us) {
            self.board.poll(t, &mut self.out, &mut |m| got.push(m));
        }
        got
    }

    pub(super) fn armed(config: CaptureConfig) -> Self {
        let mut rig = Self::new();
        assert_eq!(
            rig.send(HostMessage::Configure(config), 0),
            [ack(CommandKind::Configure)]
        );
        assert_eq!(rig.send(HostMessage::Arm, 0), [ack(CommandKind::Arm)]);
        rig
    }
}

pub(super) fn ack(kind: CommandKind) -> BoardMessage {
    BoardMessage::Ack(kind)
}

pub(super) fn rejected(command: CommandKind, reason: RejectReason) -> BoardMessage {
    BoardMessage::Rejected { command, reason }
}

pub(super) fn config(trigger: TriggerSource, pulses: PulseCount) -> CaptureConfig {
    CaptureConfig {
        exposure_us: 1_000,
        flash_delay_us: 100,
        flash_duration_us: 500,
        frame_period_us: 50_000,
        pulses,
        trigger,
        report_edges: false,
        bracket: Bracket::NONE,
    }
}

pub(super) fn pulses(msgs: &[BoardMessage]) -> Vec<PulseEvent> {
    msgs.iter()
        .filter_map(|m| {
            if let BoardMessage::Pulse(p) = m {
                Some(*p)
            } else {
                None
            }
        })
        .collect()
}

#[test]
fn hello_answers_with_the_boards_version_even_when_the_hosts_differs() {
    let mut rig = Rig::new();
    let other = PROTOCOL_VERSION.wrapping_add(1);
    let got = rig.send(
        HostMessage::Hello {
            protocol_version: other,
        },
        0,
    );
    assert_eq!(got, [BoardMessage::HelloReply(rig.board.info().clone())]);
    let BoardMessage::HelloReply(info) = &got[0] else {
        unreachable!()
    };
    assert_eq!(info.protocol_version, PROTOCOL_VERSION);
    assert_eq!(info.board_name.as_str(), "test-board");
    assert_eq!(rig.board.host_protocol_version(), Some(other));
    assert_eq!(rig.board.state(), BoardState::Idle, "Hello changes nothing");
}

#[test]
fn after_a_mismatched_hello_only_safe_commands_are_obeyed() {
    let mut rig = Rig::new();
    let board_version = PROTOCOL_VERSION;
    let mismatch = RejectReason::ProtocolMismatch {
        board: board_version,
    };
    rig.send(
        HostMessage::Hello {
            protocol_version: board_version.wrapping_add(1),
        },
        0,
    );
    let c = config(TriggerSource::FreeRun, PulseCount::Count(1));
    assert_eq!(
        rig.send(HostMessage::Configure(c), 0),
        [rejected(CommandKind::Configure, mismatch)]
    );
    assert_eq!(
        rig.send(HostMessage::Arm, 0),
        [rejected(CommandKind::Arm, mismatch)]
    );
    assert_eq!(
        rig.send(HostMessage::Start, 0),
        [rejected(CommandKind::Start, mismatch)]
    );
    assert_eq!(
        rig.send(HostMessage::FireOne, 0),
        [rejected(CommandKind::FireOne, mismatch)]
    );
    assert_eq!(rig.send(HostMessage::Stop, 0), [ack(CommandKind::Stop)]);
    assert!(matches!(
        rig.send(HostMessage::StatusRequest, 0)[..],
        [BoardMessage::Status(_)]
    ));
    assert_eq!(rig.board.state(), BoardState::Idle);
    // A Hello with the board's version lifts the refusal.
    rig.send(
        HostMessage::Hello {
            protocol_version: board_version,
        },
        0,
    );
    assert_eq!(
        rig.send(HostMessage::Configure(c), 0),
        [ack(CommandKind::Configure)]
    );
}

#[test]
fn ping_is_answered_with_the_device_time() {
    let mut rig = Rig::new();
    let got = rig.send(HostMessage::Ping { nonce: 0xdead_beef }, 123_456_789_012);
    assert_eq!(
        got,
        [BoardMessage::Pong {
            nonce: 0xdead_beef,
            t_device_us: 123_456_789_012
        }]
    );
}

#[test]
fn the_state_table_for_a_free_run() {
    let mut rig = Rig::new();
    let free = config(TriggerSource::FreeRun, PulseCount::Continuous);
    use CommandKind as K;
    use RejectReason as R;
    // Idle
    assert_eq!(
        rig.send(HostMessage::Arm, 0),
        [rejected(K::Arm, R::NotConfigured)]
    );
    assert_eq!(
        rig.send(HostMessage::Start, 0),
        [rejected(K::Start, R::NotConfigured)]
    );
    assert_eq!(
        rig.send(HostMessage::FireOne, 0),
        [rejected(K::FireOne, R::NotConfigured)]
    );
    assert_eq!(rig.send(HostMessage::Stop, 0), [ack(K::Stop)]);
    assert_eq!(rig.board.state(), BoardState::Idle);
    // Configured
    assert_eq!(
        rig.send(HostMessage::Configure(free), 0),
        [ack(K::Configure)]
    );
    assert_eq!(rig.board.state(), BoardState::Configured);
    assert_eq!(
        rig.send(HostMessage::Start, 0),
        [rejected(K::Start, R::NotArmed)]
    );
    assert_eq!(
        rig.send(HostMessage::FireOne, 0),
        [rejected(K::FireOne, R::WrongTriggerSource)]
    );
    // Armed
    assert_eq!(rig.send(HostMessage::Arm, 0), [ack(K::Arm)]);
    assert_eq!(rig.send(HostMessage::Arm, 0), [ack(K::Arm)]);
    assert_eq!(rig.board.state(), BoardState::Armed);
    assert_eq!(
        rig.send(HostMessage::FireOne, 0),
        [rejected(K::FireOne, R::WrongTriggerSource)]
    );
    // Running
    assert_eq!(rig.send(HostMessage::Start, 10), [ack(K::Start)]);
    assert_eq!(rig.board.state(), BoardState::Running);
    assert_eq!(rig.board.next_deadline(), Some(10 + LEAD));
    assert_eq!(
        rig.send(HostMessage::Configure(free), 20),
        [rejected(K::Configure, R::Busy)]
    );
    assert_eq!(rig.send(HostMessage::Arm, 20), [rejected(K::Arm, R::Busy)]);
    assert_eq!(
        rig.send(HostMessage::Start, 20),
        [rejected(K::Start, R::Busy)]
    );
    assert_eq!(rig.send(HostMessage::Stop, 30), [ack(K::Stop)]);
    assert_eq!(
        rig.board.state(),
        BoardState::Configured,
        "every capture needs its own Arm"
    );
    // Stop and Configure both disarm.
    assert_eq!(rig.send(HostMessage::Arm, 40), [ack(K::Arm)]);
    assert_eq!(rig.send(HostMessage::Stop, 40), [ack(K::Stop)]);
    assert_eq!(rig.board.state(), BoardState::Configured);
    assert_eq!(rig.send(HostMessage::Arm, 40), [ack(K::Arm)]);
    assert_eq!(
        rig.send(HostMessage::Configure(free), 40),
        [ack(K::Configure)]
    );
    assert_eq!(rig.board.state(), BoardState::Configured);
    assert_eq!(rig.out.edges().count(), 0, "no pulse was ever due");
    assert_eq!(rig.board.faults().rejected_commands, 9);
}

#[test]
fn configure_rejects_every_invalid_config_with_its_reason_and_keeps_the_old_plan() {
    let good = config(TriggerSource::FreeRun, PulseCount::Count(3));
    let mut rig = Rig::armed(good);
    type Edit = fn(&mut CaptureConfig);
    let cases: [(Edit, RejectReason); 7] = [
        (|c| c.exposure_us = 1, RejectReason::ExposureOutOfRange),
        (|c| c.frame_period_us = 1, RejectReason::PeriodOutOfRange),
        (
            |c| c.pulses = PulseCount::Count(0),
            RejectReason::CountOutOfRange,
        ),
        (
            |c| c.flash_delay_us = 900,
            RejectReason::FlashOutsideExposure,
        ),
        (
            |c| {
                c.exposure_us = 9_000;
                c.flash_duration_us = 6_000;
            },
            RejectReason::FlashTooLong { max_us: 5_000 },
        ),
        (
            |c| {
                c.exposure_us = 3_000;
                c.flash_delay_us = 0;
                c.flash_duration_us = 2_500;
                c.frame_period_us = 23_000; // 2.5 / 23 = 10.9 %
            },
            RejectReason::DutyCycleTooHigh { max_permille: 100 },
        ),
        (
            |c| {
                c.flash_duration_us = 0;
                c.frame_period_us = 20_500;
            },
            RejectReason::PeriodTooShort { min_us: 21_000 },
        ),
    ];
    for (edit, reason) in cases {
        let mut c = good;
        edit(&mut c);
        assert_eq!(
            rig.send(HostMessage::Configure(c), 0),
            [rejected(CommandKind::Configure, reason)]
        );
        assert_eq!(
            rig.board.state(),
            BoardState::Armed,
            "a rejection changes nothing"
        );
        assert_eq!(rig.board.plan().map(|p| *p.config()), Some(good));
    }
    assert_eq!(rig.board.faults().rejected_commands, 7);
}

fn frame(msg: &HostMessage) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = encode(msg, &mut buf).unwrap();
    buf[..n].to_vec()
}

#[test]
fn bad_frames_are_counted_and_a_good_frame_after_them_is_handled() {
    let mut rig = Rig::new();
    let mut wire = Vec::new();
    let mut corrupt = frame(&HostMessage::Ping { nonce: 1 });
    corrupt[2] ^= 0x10; // CRC mismatch
    wire.extend(&corrupt);
    wire.extend([0x05, 0x01, 0x00]); // COBS code pointing past the end
    wire.extend([0x42; MAX_FRAME_LEN + 10]); // overflow
    wire.push(0);
    wire.extend(frame(&HostMessage::Ping { nonce: 2 }));
    let mut got = Vec::new();
    for &b in &wire {
        rig.board
            .feed_rx_byte(b, 77, &mut rig.out, &mut |m| got.push(m));
    }
    assert_eq!(
        got,
        [
            BoardMessage::Fault(Fault::BadFrame(BadFrameKind::Crc)),
            BoardMessage::Fault(Fault::BadFrame(BadFrameKind::Cobs)),
            BoardMessage::Fault(Fault::BadFrame(BadFrameKind::Overflow)),
            BoardMessage::Pong {
                nonce: 2,
                t_device_us: 77
            },
        ]
    );
    assert_eq!(rig.board.faults().bad_frames, 3);
}

#[test]
fn the_byte_path_round_trips_through_frame_writer() {
    let mut rig = Rig::new();
    let mut tx = FrameWriter::new(heapless::Deque::<u8, 512>::new());
    let c = config(TriggerSource::FreeRun, PulseCount::Count(1));
    for msg in [
        HostMessage::Configure(c),
        HostMessage::Arm,
        HostMessage::Start,
    ] {
        for b in frame(&msg) {
            rig.board.feed_rx_byte(b, 0, &mut rig.out, &mut tx);
        }
    }
    while let Some(t) = rig.board.next_deadline() {
        rig.board.poll(t, &mut rig.out, &mut tx);
    }
    let bytes: Vec<u8> = tx.bytes().iter().copied().collect();
    let mut dec = ellipso_protocol::Decoder::<BoardMessage>::new();
    let got: Vec<BoardMessage> = dec.feed(&bytes).map(Result::unwrap).collect();
    assert_eq!(
        got[..3],
        [
            ack(CommandKind::Configure),
            ack(CommandKind::Arm),
            ack(CommandKind::Start)
        ]
    );
    assert!(matches!(
        got[3],
        BoardMessage::Pulse(PulseEvent { seq: 0, .. })
    ));
    assert!(matches!(got[4], BoardMessage::Status(_)));
    assert_eq!(got.len(), 5);
}

#[test]
fn edge_reports_follow_report_edges() {
    let mut c = config(TriggerSource::FreeRun, PulseCount::Count(1));
    c.report_edges = true;
    let mut rig = Rig::armed(c);
    rig.send(HostMessage::Start, 0);
    let got = rig.run_until(u64::MAX);
    let edges: Vec<_> = got
        .iter()
        .filter_map(|m| match m {
            BoardMessage::Edge(e) => Some((e.output, e.high, e.t_device_us, e.seq)),
            _ => None,
        })
        .collect();
    assert_eq!(
        edges,
        [
            (Output::CameraTrigger, true, LEAD, 0),
            (Output::Flash, true, LEAD + 100, 0),
            (Output::Flash, false, LEAD + 600, 0),
            (Output::CameraTrigger, false, LEAD + 1_000, 0),
        ]
    );
}

#[test]
fn dropped_replies_are_counted_and_change_nothing_else() {
    let mut rig = Rig::new();
    let mut q = TxQueue::<1>::new();
    rig.board
        .handle(HostMessage::Ping { nonce: 1 }, 0, &mut rig.out, &mut q);
    rig.board
        .handle(HostMessage::Ping { nonce: 2 }, 0, &mut rig.out, &mut q);
    rig.board.on_bad_frame(FrameError::Malformed, &mut q);
    let c = config(TriggerSource::FreeRun, PulseCount::Count(1));
    rig.board
        .handle(HostMessage::Configure(c), 0, &mut rig.out, &mut q);
    assert_eq!(
        rig.board.state(),
        BoardState::Configured,
        "applied though its Ack was dropped"
    );
    assert_eq!(
        q.pop(),
        Some(BoardMessage::Pong {
            nonce: 1,
            t_device_us: 0
        })
    );
    assert_eq!(rig.board.faults().tx_overflows, 3);
    assert_eq!(rig.board.faults().bad_frames, 1);
}

#[test]
fn contradictory_board_configs_are_refused_at_construction() {
    let mut c = BoardConfig::new("x", 1_000_000);
    c.limits = LED_RIG_LIMITS;
    c.limits.max_flash_on_us = 0;
    assert_eq!(Board::new(c).err(), Some(ConfigError::ZeroFlashOnTime));
}

mod bracket;

mod captures;

mod proptests;

#[test]
fn enter_bootloader_is_refused_while_running_and_otherwise_requested_once_with_outputs_low() {
    use CommandKind as K;
    let free = config(TriggerSource::FreeRun, PulseCount::Continuous);
    let mut rig = Rig::armed(free);
    assert_eq!(rig.send(HostMessage::Start, 10), [ack(K::Start)]);
    assert_eq!(
        rig.send(HostMessage::EnterBootloader, 20),
        [rejected(K::EnterBootloader, RejectReason::Busy)],
        "a firmware update never cuts a scan"
    );
    assert!(!rig.board.take_bootloader_request());
    assert_eq!(rig.board.state(), BoardState::Running);
    assert_eq!(rig.send(HostMessage::Stop, 30), [ack(K::Stop)]);
    // armed, not running: accepted, disarmed, requested exactly once
    assert_eq!(rig.send(HostMessage::Arm, 40), [ack(K::Arm)]);
    assert_eq!(
        rig.send(HostMessage::EnterBootloader, 50),
        [ack(K::EnterBootloader)]
    );
    assert_eq!(rig.board.state(), BoardState::Configured);
    assert!(rig.board.take_bootloader_request());
    assert!(!rig.board.take_bootloader_request());
    // the byte path carries the new command too
    let mut got = Vec::new();
    for b in frame(&HostMessage::EnterBootloader) {
        rig.board
            .feed_rx_byte(b, 60, &mut rig.out, &mut |m| got.push(m));
    }
    assert_eq!(got, [ack(K::EnterBootloader)]);
    assert!(rig.board.take_bootloader_request());
}
