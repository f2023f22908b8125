//! The rig's pieces together: board over an in-memory duplex, wire, camera statistics.

use std::io::{ErrorKind, Read, Write};
use std::sync::Arc;
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

fn camera_config(seed: u64, faults: CameraFaults) -> SimCameraConfig {
    camera_config_at(Instant::now(), seed, faults)
}

fn camera_config_at(epoch: Instant, seed: u64, faults: CameraFaults) -> SimCameraConfig {
    let clock = LinearClock::new(epoch, 1_000_000, 25.0).unwrap();
    let mut c = SimCameraConfig::new(seed, 36, clock);
    c.faults = faults;
    c
}

fn rising(i: u64) -> TriggerEdge {
    TriggerEdge::trigger(1_000_000 + i * 50_000, true)
}

#[test]
fn camera_fault_rates_match_their_settings_and_are_seeded() {
    let faults = CameraFaults {
        missed_trigger_probability: 0.02,
        drop_probability: 0.05,
        duplicate_probability: 0.03,
        late_probability: 0.1,
        late_extra_us: 30_000,
        ..CameraFaults::default()
    };
    let epoch = Instant::now();
    let run = |seed, faults| {
        let mut core = CameraCore::new(camera_config_at(epoch, seed, faults), 64).unwrap();
        let plans: Vec<_> = (0..2_000).map(|i| core.on_edge(rising(i))).collect();
        (plans, core.counters())
    };
    let (plans, c) = run(11, faults);
    let within = |count: u64, p: f64, n: u64| {
        let mean = p * n as f64;
        (count as f64 - mean).abs() < 5.0 * (mean * (1.0 - p)).sqrt()
    };
    assert_eq!(c.rising_edges, 2_000);
    assert!(within(c.missed_triggers, 0.02, 2_000), "{c:?}");
    assert_eq!(c.exposures, 2_000 - c.missed_triggers);
    assert!(within(c.dropped, 0.05, c.exposures), "{c:?}");
    assert!(within(c.duplicated, 0.03, c.exposures - c.dropped), "{c:?}");
    assert!(within(c.late, 0.1, c.exposures - c.dropped), "{c:?}");
    assert_eq!(
        plans.iter().flatten().count() as u64,
        c.exposures - c.dropped
    );
    // Same seed, same run; another seed, another run.
    assert_eq!(run(11, faults).0, plans);
    assert_ne!(run(12, faults).0, plans);
    // Independence: turning duplicates and lateness off leaves the drops where they were.
    let only_drops = CameraFaults {
        duplicate_probability: 0.0,
        late_probability: 0.0,
        ..faults
    };
    let ids = |p: &[Option<camera::FramePlan>]| -> Vec<Option<u16>> {
        p.iter().map(|f| f.as_ref().map(|f| f.block_id)).collect()
    };
    assert_eq!(ids(&run(11, only_drops).0), ids(&plans));
}

#[test]
fn block_ids_wrap_from_65535_to_1_and_never_use_0() {
    let mut core = CameraCore::new(camera_config(1, CameraFaults::default()), 64).unwrap();
    let ids: Vec<u16> = (0..300)
        .filter_map(|i| core.on_edge(rising(i)))
        .map(|p| p.block_id)
        .collect();
    assert_eq!(ids[0], 65_401);
    let wrap = ids.iter().position(|&id| id == u16::MAX).unwrap();
    assert_eq!(wrap, 134);
    assert_eq!(ids[wrap + 1], 1);
    assert!(!ids.contains(&0));
    assert_eq!(camera::next_block_id(7), 8);
    // Pose index follows exposures; falling edges do nothing.
    let mut core = CameraCore::new(camera_config(1, CameraFaults::default()), 64).unwrap();
    assert!(core.on_edge(TriggerEdge::trigger(5, false)).is_none());
    let poses: Vec<usize> = (0..40)
        .filter_map(|i| core.on_edge(rising(i)))
        .map(|p| p.pose_index)
        .collect();
    assert_eq!(poses[35..], [35, 0, 1, 2, 3]);
}

#[test]
fn camera_timestamps_follow_the_time_model() {
    let mut config = camera_config(3, CameraFaults::default());
    config.timing.transfer_jitter_us = 0.0;
    let board_clock = config.board_clock;
    let mut core = CameraCore::new(config, 64).unwrap();
    let a = core.on_edge(rising(0)).unwrap();
    let b = core.on_edge(rising(1)).unwrap();
    let t = config.timing;
    let latency = a.arrival.duration_since(a.exposure_start).as_micros() as u32;
    assert_eq!(latency, t.exposure_us + t.readout_us + t.transfer_us);
    let delay = a
        .exposure_start
        .duration_since(board_clock.instant_at_us(a.t_trigger_device_us))
        .as_nanos() as i64;
    assert!(
        (delay - i64::from(t.trigger_delay_us) * 1_000).abs() <= 1,
        "{delay} ns"
    );
    // 50 000 board µs = 50 000 / (1 + 25e-6) host µs = that × (1 − 12e-6) camera µs.
    let dt_camera_ns = (b.t_camera_ns - a.t_camera_ns) as f64;
    let expected_ns = 50_000_000.0 / (1.0 + 25e-6) * (1.0 - 12e-6);
    assert!(
        (dt_camera_ns - expected_ns).abs() < 5.0,
        "{dt_camera_ns} vs {expected_ns}"
    );
}

#[test]
fn sim_camera_delivers_in_order_with_duplicates_and_waits_for_a_slow_consumer() {
    let faults = CameraFaults {
        drop_probability: 0.1,
        duplicate_probability: 0.1,
        incomplete_probability: 0.1,
        ..CameraFaults::default()
    };
    let mut config = camera_config(21, faults);
    config.queue_frames = 2;
    config.render_workers = 3;
    let source = Arc::new(PoseIndexSource {
        width: 128,
        height: 64,
    });
    let (tx, rx) = wire::wire();
    let camera = SimCamera::spawn(config, source, rx).unwrap();
    for i in 0..200 {
        tx.send(rising(i)).unwrap();
        tx.send(TriggerEdge::trigger(rising(i).t_device_us + 500, false))
            .unwrap();
    }
    drop(tx);
    // Replay the core alone: the delivered stream must be exactly its plans (duplicates twice).
    let mut core = CameraCore::new(config, 128 * 64).unwrap();
    let expected: Vec<(u16, bool)> = (0..200)
        .filter_map(|i| core.on_edge(rising(i)))
        .flat_map(|p| {
            let dup = p.duplicate.then_some((p.block_id, true));
            std::iter::once((p.block_id, false)).chain(dup)
        })
        .collect();
    std::thread::sleep(Duration::from_millis(50)); // let the queue fill: the camera must wait
    let frames: Vec<SimFrame> = camera.frames().iter().collect();
    let got: Vec<(u16, bool)> = frames
        .iter()
        .map(|f| (f.block_id, f.truth.duplicate))
        .collect();
    assert_eq!(got, expected);
    for f in &frames {
        if f.status == FrameStatus::Complete {
            let (pose, seed) = PoseIndexSource::decode(&f.pixels).unwrap();
            assert_eq!(usize::from(pose), f.truth.pose_index);
            assert_eq!(seed, f.truth.frame_seed);
        } else {
            // Missing packets are zeroed, whole packets only.
            let zeros = f.pixels.iter().filter(|&&p| p == 0).count();
            assert!(zeros >= camera::PIXELS_PER_PACKET, "{zeros} zero pixels");
        }
    }
    let counters = camera.join();
    assert_eq!(counters.delivered, frames.len() as u64);
    assert!(counters.backpressure_waits > 0, "{counters:?}");
    assert!(counters.incomplete > 0 && counters.duplicated > 0 && counters.dropped > 0);
}

#[test]
fn bad_settings_are_refused_with_their_name() {
    let mut config = camera_config(1, CameraFaults::default());
    config.first_block_id = 0;
    let e = CameraCore::new(config, 1).unwrap_err().to_string();
    assert!(e.contains("first_block_id"), "{e}");
    let config = camera_config(
        1,
        CameraFaults {
            drop_probability: 1.0,
            ..Default::default()
        },
    );
    let e = CameraCore::new(config, 1).unwrap_err().to_string();
    assert!(e.contains("drop_probability"), "{e}");
    let mut board = fast_board(1);
    board.link.ber_to_host = 0.7;
    let (a, _b) = duplex::duplex(Duration::from_millis(1));
    let e = VirtualBoard::spawn(board, Box::new(a.reader), Box::new(a.writer), None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("ber_to_host"), "{e}");
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

#[test]
fn a_paced_camera_never_delivers_a_frame_before_its_arrival() {
    let mut config = camera_config(8, CameraFaults::default());
    config.pace_to_arrival = true;
    config.timing.readout_us = 2_000;
    config.timing.transfer_us = 3_000;
    let clock = config.board_clock;
    let (tx, rx) = wire::wire();
    let camera = SimCamera::spawn(
        config,
        Arc::new(PoseIndexSource {
            width: 8,
            height: 8,
        }),
        rx,
    )
    .unwrap();
    for i in 0..5u64 {
        tx.send(TriggerEdge::trigger(clock.now_us() + i * 1_000, true))
            .unwrap();
    }
    drop(tx);
    for f in camera.frames().iter() {
        assert!(
            Instant::now() >= f.arrival,
            "frame {} delivered early",
            f.block_id
        );
    }
    assert_eq!(camera.join().delivered, 5);
}

mod bracket;
