//! The rig's pieces together: the shared test board and host, and the board over an in-memory
//! duplex on the wire (handshake, pulses, clocks, disconnects, bit errors both ways); the camera
//! and the bracket are tested in `tests/`.

use std::io::{ErrorKind, Read, Write};
use std::time::{Duration, Instant};

use ellipso_firmware::LED_RIG_LIMITS;
use ellipso_protocol::{
    BoardMessage, CaptureConfig, Decoder, HostMessage, MAX_FRAME_LEN, PROTOCOL_VERSION, PulseCount,
    PulseEvent, TriggerSource, encode,
};

use super::*;

/// Fast limits so tests run pulses every 2 ms.
pub(super) fn fast_board(seed: u64) -> VirtualBoardConfig {
    let mut c = VirtualBoardConfig::new(seed);
    c.board.limits = ellipso_protocol::BoardLimits {
        readout_us: 1_000,
        min_frame_period_us: 1_100,
        ..LED_RIG_LIMITS
    };
    c
}

pub(super) fn capture(pulses: u32, period_us: u32) -> CaptureConfig {
    CaptureConfig {
        exposure_us: 500,
        flash_delay_us: 50,
        flash_duration_us: 40,
        frame_period_us: period_us,
        pulses: PulseCount::Count(pulses),
        trigger: TriggerSource::FreeRun,
        report_edges: false,
        bracket: ellipso_protocol::Bracket::NONE,
    }
}

/// A minimal host: writes commands, decodes everything the board sends.
pub(super) struct TestHost {
    reader: duplex::DuplexReader,
    writer: duplex::DuplexWriter,
    decoder: Decoder<BoardMessage>,
    received: Vec<BoardMessage>,
    eof: bool,
}

impl TestHost {
    fn new(end: duplex::DuplexEnd) -> Self {
        Self {
            reader: end.reader,
            writer: end.writer,
            decoder: Decoder::new(),
            received: Vec::new(),
            eof: false,
        }
    }

    pub(super) fn send(&mut self, msg: &HostMessage) {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = encode(msg, &mut buf).unwrap();
        self.writer.write_all(&buf[..n]).unwrap();
    }

    /// Reads until `done` holds for the received messages or the stream ends or 5 s pass.
    pub(super) fn read_until(&mut self, done: impl Fn(&[BoardMessage]) -> bool) {
        let deadline = Instant::now() + Duration::from_secs(5);
        let mut buf = [0u8; 256];
        while !done(&self.received) && !self.eof && Instant::now() < deadline {
            match self.reader.read(&mut buf) {
                Ok(0) => self.eof = true,
                Ok(n) => {
                    let msgs: Vec<_> = self
                        .decoder
                        .feed(&buf[..n])
                        .filter_map(Result::ok)
                        .collect();
                    self.received.extend(msgs);
                }
                Err(e) if e.kind() == ErrorKind::TimedOut => {}
                Err(e) => panic!("read failed: {e}"),
            }
        }
    }

    /// Reads whatever arrives for `d`.
    fn read_for(&mut self, d: Duration) {
        let until = Instant::now() + d;
        self.read_until(|_| Instant::now() >= until);
    }

    pub(super) fn pulses(&self) -> Vec<PulseEvent> {
        self.received
            .iter()
            .filter_map(|m| match m {
                BoardMessage::Pulse(p) => Some(*p),
                _ => None,
            })
            .collect()
    }

    pub(super) fn command(&mut self, msg: HostMessage) {
        let kind = msg.kind();
        self.send(&msg);
        self.read_until(|r| {
            r.iter()
                .any(|m| matches!(m, BoardMessage::Ack(k) if *k == kind))
        });
        assert!(
            self.received
                .iter()
                .any(|m| matches!(m, BoardMessage::Ack(k) if *k == kind)),
            "no Ack for {kind:?}: {:?}",
            self.received
        );
    }
}

pub(super) fn start_board(
    config: VirtualBoardConfig,
) -> (
    VirtualBoard,
    TestHost,
    crossbeam_channel::Receiver<TriggerEdge>,
) {
    let (host_end, board_end) = duplex::duplex(Duration::from_millis(10));
    let (edges_tx, edges_rx) = wire::wire();
    let board = VirtualBoard::spawn(
        config,
        Box::new(board_end.reader),
        Box::new(board_end.writer),
        Some(edges_tx),
    )
    .unwrap();
    (board, TestHost::new(host_end), edges_rx)
}

#[test]
fn board_answers_the_handshake_and_runs_pulses_whose_edges_go_on_the_wire() {
    let (board, mut host, edges) = start_board(fast_board(1));
    host.send(&HostMessage::Hello {
        protocol_version: PROTOCOL_VERSION,
    });
    host.read_until(|r| r.iter().any(|m| matches!(m, BoardMessage::HelloReply(_))));
    let Some(BoardMessage::HelloReply(info)) = host.received.first() else {
        panic!("no HelloReply: {:?}", host.received)
    };
    assert_eq!(info.protocol_version, PROTOCOL_VERSION);
    assert_eq!(info.board_name.as_str(), "ellipso-virtual");

    let n = 20;
    host.command(HostMessage::Configure(capture(n, 2_000)));
    host.command(HostMessage::Arm);
    host.command(HostMessage::Start);
    host.read_until(|r| {
        r.iter()
            .filter(|m| matches!(m, BoardMessage::Pulse(_)))
            .count()
            == n as usize
    });
    let pulses = host.pulses();
    assert_eq!(pulses.len(), n as usize);
    for (i, p) in pulses.iter().enumerate() {
        assert_eq!(p.seq, i as u64);
        assert_eq!(p.flags, 0, "pulse {i} flagged {:#x}", p.flags);
        assert_eq!(p.t_flash_on_us - p.t_trigger_us, 50);
        if i > 0 {
            // Exact period: deadlines are polled at their own device time.
            assert_eq!(p.t_trigger_us - pulses[i - 1].t_trigger_us, 2_000);
        }
    }
    let truth = board.shutdown();
    assert_eq!(truth.pulses, pulses);
    assert_eq!(truth.end_reason.as_deref(), Some("stopped by its owner"));
    let (wire, flash): (Vec<TriggerEdge>, Vec<TriggerEdge>) = edges
        .try_iter()
        .partition(|e| e.output == ellipso_protocol::Output::CameraTrigger);
    assert_eq!(
        flash, truth.flash_edges,
        "the flash's light is on the wire too"
    );
    let lit: Vec<(u64, u64)> = flash
        .chunks(2)
        .map(|p| (p[0].t_device_us, p[1].t_device_us))
        .collect();
    assert_eq!(
        lit,
        pulses
            .iter()
            .map(|p| (p.t_flash_on_us, p.t_flash_off_us))
            .collect::<Vec<_>>()
    );
    let rising: Vec<u64> = wire
        .iter()
        .filter(|e| e.rising)
        .map(|e| e.t_device_us)
        .collect();
    let falling: Vec<u64> = wire
        .iter()
        .filter(|e| !e.rising)
        .map(|e| e.t_device_us)
        .collect();
    assert_eq!(
        rising,
        pulses.iter().map(|p| p.t_trigger_us).collect::<Vec<_>>()
    );
    assert_eq!(
        falling,
        pulses
            .iter()
            .map(|p| p.t_trigger_us + 500)
            .collect::<Vec<_>>()
    );
    assert_eq!(wire, truth.trigger_edges);
}

#[test]
fn pong_times_follow_the_configured_device_clock() {
    let mut config = fast_board(2);
    config.clock_offset_us = 7_000_000_000;
    config.clock_drift_ppm = 100.0;
    let (board, mut host, _edges) = start_board(config);
    let clock = board.device_clock();
    for nonce in 0..5 {
        let before = clock.now_us();
        host.send(&HostMessage::Ping { nonce });
        host.read_until(|r| {
            r.iter()
                .any(|m| matches!(m, BoardMessage::Pong { nonce: k, .. } if *k == nonce))
        });
        let after = clock.now_us();
        let t = host
            .received
            .iter()
            .find_map(|m| match m {
                BoardMessage::Pong {
                    nonce: k,
                    t_device_us,
                } if *k == nonce => Some(*t_device_us),
                _ => None,
            })
            .unwrap();
        assert!((before..=after).contains(&t), "{before} ≤ {t} ≤ {after}");
        assert!(t >= 7_000_000_000);
    }
    drop(board);
}

#[test]
fn a_permanent_disconnect_ends_the_stream_after_the_last_good_pulse() {
    let mut config = fast_board(3);
    config.link.disconnect = Some(Disconnect {
        at_pulse: 7,
        blackout: None,
    });
    let (board, mut host, _edges) = start_board(config);
    host.command(HostMessage::Configure(capture(20, 2_000)));
    host.command(HostMessage::Arm);
    host.command(HostMessage::Start);
    host.read_until(|_| false);
    assert!(host.eof, "the board's end did not close");
    assert!(board.wait_finished(Duration::from_secs(5)));
    let truth = board.truth();
    assert_eq!(truth.disconnected_at_pulse, Some(7));
    assert_eq!(
        truth.end_reason.as_deref(),
        Some("link disconnected by the scene's fault")
    );
    assert_eq!(host.pulses(), truth.pulses[..7]);
}

#[test]
fn a_blackout_loses_pulses_then_the_link_recovers() {
    let mut config = fast_board(4);
    config.link.disconnect = Some(Disconnect {
        at_pulse: 3,
        blackout: Some(Duration::from_millis(9)),
    });
    let (board, mut host, _edges) = start_board(config);
    let continuous = CaptureConfig {
        pulses: PulseCount::Continuous,
        ..capture(1, 2_000)
    };
    host.command(HostMessage::Configure(continuous));
    host.command(HostMessage::Arm);
    host.command(HostMessage::Start);
    // Runs until a pulse after the blackout arrives, however slowly this machine runs.
    host.read_until(|r| {
        r.iter()
            .any(|m| matches!(m, BoardMessage::Pulse(p) if p.seq > 3))
    });
    host.command(HostMessage::Stop);
    let seqs: Vec<u64> = host.pulses().iter().map(|p| p.seq).collect();
    let truth = board.shutdown();
    assert_eq!(seqs[..3], [0, 1, 2], "{seqs:?}");
    assert!(!seqs.contains(&3), "{seqs:?}");
    assert!(
        seqs.last().is_some_and(|&s| s > 3),
        "the link did not recover: {seqs:?}"
    );
    assert_eq!(truth.disconnected_at_pulse, Some(3));
    assert!(truth.frames_lost >= 1);
    for p in host.pulses() {
        assert_eq!(p, truth.pulses[p.seq as usize]);
    }
}

#[test]
fn board_to_host_bit_errors_never_yield_a_wrong_pulse() {
    let mut config = fast_board(5);
    config.link.ber_to_host = 2e-3;
    let (board, mut host, _edges) = start_board(config);
    // Commands may lose their Ack at this BER: just send them and read the pulses.
    for msg in [
        HostMessage::Configure(capture(60, 1_600)),
        HostMessage::Arm,
        HostMessage::Start,
    ] {
        host.send(&msg);
        std::thread::sleep(Duration::from_millis(5));
    }
    let deadline = Instant::now() + Duration::from_secs(10);
    while board.truth().pulses.len() < 60 && Instant::now() < deadline {
        host.read_for(Duration::from_millis(20));
    }
    host.read_for(Duration::from_millis(50));
    let truth = board.shutdown();
    assert_eq!(truth.pulses.len(), 60);
    let got = host.pulses();
    for p in &got {
        assert_eq!(
            *p, truth.pulses[p.seq as usize],
            "a corrupted pulse was accepted"
        );
    }
    assert!(
        truth.frames_corrupted > 0,
        "BER 2e-3 over {} frames flipped nothing",
        truth.frames_sent
    );
    let lost = truth.pulses.len() - got.len();
    assert!(
        lost <= truth.corrupted_pulse_seqs.len(),
        "{lost} lost, {:?} corrupted",
        truth.corrupted_pulse_seqs
    );
}

#[test]
fn host_to_board_bit_errors_are_refused_by_the_core_and_counted() {
    let mut config = fast_board(6);
    config.link.ber_to_board = 2e-3;
    let (board, mut host, _edges) = start_board(config);
    // In batches of 10: a burst of hundreds would overflow the board's 64-frame transmit queue.
    for batch in 0..30 {
        for nonce in batch * 10..batch * 10 + 10 {
            host.send(&HostMessage::Ping { nonce });
        }
        host.read_for(Duration::from_millis(3));
    }
    host.read_for(Duration::from_millis(100));
    let truth = board.shutdown();
    let pongs: Vec<u32> = host
        .received
        .iter()
        .filter_map(|m| match m {
            BoardMessage::Pong { nonce, .. } => Some(*nonce),
            _ => None,
        })
        .collect();
    assert!(truth.bits_flipped_to_board > 0);
    assert!(
        truth.board_faults.bad_frames > 0,
        "{:?}",
        truth.board_faults
    );
    assert_eq!(truth.board_faults.tx_overflows, 0);
    // Only real pings are answered, in order, each at most once; the rest were lost.
    assert!(pongs.windows(2).all(|w| w[0] < w[1]), "{pongs:?}");
    assert!(pongs.iter().all(|&n| n < 300));
    assert!(
        pongs.len() < 300 && pongs.len() > 150,
        "{} pongs",
        pongs.len()
    );
}

mod bracket;

mod camera;
