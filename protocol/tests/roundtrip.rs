//! Round trips: every message survives encode → decode, whole, chunked and back to back.

mod common;

use common::{board_message, frame, host_message};
use ellipso_protocol::*;
use proptest::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn host(seed: u64) -> HostMessage {
    host_message(&mut ChaCha8Rng::seed_from_u64(seed))
}

fn board(seed: u64) -> BoardMessage {
    board_message(&mut ChaCha8Rng::seed_from_u64(seed))
}

fn decode_all<M: Message>(bytes: &[u8]) -> Vec<Result<M, FrameError>> {
    let mut d = Decoder::<M>::new();
    d.feed(bytes).collect()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    #[test]
    fn host_messages_round_trip(seed in any::<u64>()) {
        let msg = host(seed);
        let f = frame(&msg);
        prop_assert!(f.len() <= MAX_FRAME_LEN);
        prop_assert_eq!(f.iter().filter(|&&b| b == 0).count(), 1, "only the delimiter is zero");
        prop_assert_eq!(decode_all::<HostMessage>(&f), vec![Ok(msg)]);
    }

    #[test]
    fn board_messages_round_trip(seed in any::<u64>()) {
        let msg = board(seed);
        let f = frame(&msg);
        prop_assert!(f.len() <= MAX_FRAME_LEN);
        prop_assert_eq!(f.iter().filter(|&&b| b == 0).count(), 1, "only the delimiter is zero");
        prop_assert_eq!(decode_all::<BoardMessage>(&f), vec![Ok(msg)]);
    }

    /// Any 0..=8 steps survive a Configure round trip in order; the bracket's bytes are its
    /// count and its varints, nothing else (the encoding is the documented one).
    #[test]
    fn brackets_round_trip(steps in proptest::collection::vec(any::<u16>(), 0..=MAX_BRACKET_STEPS)) {
        let bracket = Bracket::from_q15(&steps).unwrap();
        prop_assert_eq!(bracket.steps_q15(), &steps[..]);
        let msg = HostMessage::Configure(CaptureConfig {
            exposure_us: 6_000,
            flash_delay_us: 100,
            flash_duration_us: 5_000,
            frame_period_us: 100_000,
            pulses: PulseCount::Continuous,
            trigger: TriggerSource::FreeRun,
            report_edges: false,
            bracket,
        });
        prop_assert_eq!(decode_all::<HostMessage>(&frame(&msg)), vec![Ok(msg)]);
        let mut buf = [0u8; MAX_MESSAGE_LEN];
        let alone = postcard::to_slice(&bracket, &mut buf).unwrap();
        let varint_len = |v: u16| if v < 0x80 { 1 } else if v < 0x4000 { 2 } else { 3 };
        prop_assert_eq!(alone.len(), 1 + steps.iter().map(|&v| varint_len(v)).sum::<usize>());
    }

    /// Decoding then re-encoding reproduces the bytes (the encoding is canonical).
    #[test]
    fn encoding_is_canonical(seed in any::<u64>()) {
        let f = frame(&board(seed));
        let back: Vec<u8> = decode_all::<BoardMessage>(&f)
            .into_iter()
            .flat_map(|m| frame(&m.unwrap()))
            .collect();
        prop_assert_eq!(back, f);
    }
}

/// Delivery split into chunks of every size 1..N, many messages back to back.
#[test]
fn chunked_delivery_of_every_size() {
    let msgs: Vec<BoardMessage> = (0..64).map(board).collect();
    let stream: Vec<u8> = msgs.iter().flat_map(frame).collect();
    for chunk in 1..=MAX_FRAME_LEN + 3 {
        let mut d = Decoder::<BoardMessage>::new();
        let mut got = Vec::new();
        for piece in stream.chunks(chunk) {
            got.extend(d.feed(piece).map(|r| r.unwrap()));
        }
        assert_eq!(got, msgs, "chunk size {chunk}");
        assert_eq!(d.pending(), 0);
    }
}

/// Extra delimiters between frames are resync bytes, not frames.
#[test]
fn back_to_back_and_padded_frames() {
    let a = HostMessage::Ping { nonce: 1 };
    let b = HostMessage::Arm;
    let mut stream = vec![0, 0];
    stream.extend(frame(&a));
    stream.extend(frame(&b));
    stream.extend([0, 0, 0]);
    stream.extend(frame(&a));
    let got: Vec<_> = decode_all::<HostMessage>(&stream);
    assert_eq!(got, vec![Ok(a), Ok(b), Ok(a)]);
}

/// The worst case of every variant fits MAX_MESSAGE_LEN (and so MAX_FRAME_LEN).
#[test]
fn worst_case_sizes_fit() {
    let max_name: heapless::String<BOARD_NAME_MAX> =
        core::iter::repeat_n('é', BOARD_NAME_MAX / 2).collect();
    let limits = BoardLimits {
        min_exposure_us: u32::MAX,
        max_exposure_us: u32::MAX,
        max_flash_on_us: u32::MAX,
        max_flash_duty_permille: u16::MAX,
        readout_us: u32::MAX,
        min_frame_period_us: u32::MAX,
        max_frame_period_us: u32::MAX,
        max_pulse_count: u32::MAX,
    };
    let biggest = [
        BoardMessage::HelloReply(BoardInfo {
            protocol_version: u16::MAX,
            firmware_version: FirmwareVersion {
                major: 255,
                minor: 255,
                patch: 255,
            },
            board_name: max_name,
            timer_clock_hz: u32::MAX,
            limits,
        }),
        BoardMessage::Pulse(PulseEvent {
            seq: u64::MAX,
            t_trigger_us: u64::MAX,
            t_flash_on_us: u64::MAX,
            t_flash_off_us: u64::MAX,
            flags: u8::MAX,
            bracket_step: u8::MAX,
            flash_on_us: u32::MAX,
        }),
        BoardMessage::Status(Status {
            state: BoardState::Running,
            pulses_fired: u64::MAX,
            t_device_us: u64::MAX,
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
    for msg in &biggest {
        let f = frame(msg);
        assert!(f.len() <= MAX_FRAME_LEN, "{msg:?} is {} bytes", f.len());
        assert_eq!(decode_all::<BoardMessage>(&f), vec![Ok(msg.clone())]);
    }
    let cfg = HostMessage::Configure(CaptureConfig {
        exposure_us: u32::MAX,
        flash_delay_us: u32::MAX,
        flash_duration_us: u32::MAX,
        frame_period_us: u32::MAX,
        pulses: PulseCount::Count(u32::MAX),
        trigger: TriggerSource::FreeRun,
        report_edges: true,
        bracket: Bracket::from_q15(&[u16::MAX; MAX_BRACKET_STEPS]).unwrap(),
    });
    assert!(frame(&cfg).len() <= MAX_FRAME_LEN);
    assert_eq!(decode_all::<HostMessage>(&frame(&cfg)), vec![Ok(cfg)]);
}

#[test]
fn encode_into_short_buffer_is_an_error() {
    let mut tiny = [0u8; 4];
    assert!(matches!(
        encode(&HostMessage::Ping { nonce: u32::MAX }, &mut tiny),
        Err(EncodeError::BufferTooSmall { .. })
    ));
}
