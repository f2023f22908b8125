//! The simulated camera: its fault rates match their settings and are seeded, block ids wrap,
//! timestamps follow the time model, `SimCamera` delivers in order (duplicates too), waits for a
//! slow consumer and, paced, never delivers before a frame's arrival; bad camera and link settings
//! are refused by name.

use std::sync::Arc;
use std::time::{Duration, Instant};

use super::super::tests::fast_board;
use super::super::*;

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
