//! A bracketed capture end to end on the simulated rig: the virtual board (the real firmware core)
//! behind a real pseudo-terminal, the host's real `TriggerLink`, capture loop, pairing and session
//! writer, and a simulated camera that meters the flash's light and drops frames in transfer.
//!
//! Each frame's pixels carry the flash energy the camera really integrated
//! (`PoseIndexSource` writes it into pixel 5), so the session's recorded energy of every frame is
//! checked against what lit it — around the frames lost mid-capture too: a lost frame must not
//! shift the next frames' bracket steps.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use ellipso_protocol::{BoardLimits, Bracket, CaptureConfig, PulseCount, TriggerSource};
use ellipso_rig::acquire::capture::{CapturePlan, capture};
use ellipso_rig::acquire::pairing::PairingConfig;
use ellipso_rig::camera::sim::SimCameraBackend;
use ellipso_rig::camera::{CameraInfo, CameraSettings};
use ellipso_rig::link::{LinkConfig, TriggerLink};
use ellipso_session::events::SessionEvent;
use ellipso_session::manifest::{Manifest, SensorInfo, SessionSource};
use ellipso_session::reader;
use ellipso_session::time::HostClock;
use ellipso_session::writer::SessionWriter;
use ellipso_sim::rig::{
    PoseIndexSource, SimCamera, SimCameraConfig, VirtualBoard, VirtualBoardConfig, wire,
};
use serialport::{SerialPort, TTYPort};

const PULSES: u32 = 30;
/// The full pulse's on-time; the steps are 400, 100 and 25 µs.
const FULL_ON_US: u32 = 400;
const ENERGIES: [f64; 3] = [1.0, 0.25, 0.0625];

#[test]
fn a_bracketed_capture_over_a_pty_records_every_frame_with_the_energy_that_lit_it() {
    // Board: LED-rig limits with a 5 ms readout, on a fresh pty; the wire to the camera.
    let mut board_config = VirtualBoardConfig::new(11);
    board_config.board.limits = BoardLimits {
        readout_us: 5_000,
        min_frame_period_us: 5_020,
        ..board_config.board.limits
    };
    let (mut master, device_end) = TTYPort::pair().expect("openpty");
    master.set_timeout(Duration::from_millis(20)).unwrap();
    let reader_end = master.try_clone_native().unwrap();
    let (edges_tx, edges_rx) = wire::wire();
    let board = VirtualBoard::spawn(
        board_config,
        Box::new(reader_end),
        Box::new(master),
        Some(edges_tx),
    )
    .unwrap();
    let clock = HostClock::new();
    let link = TriggerLink::open(
        &device_end.name().expect("pty path"),
        clock,
        LinkConfig::default(),
    )
    .expect("handshake");

    // Camera: meters the flash against the full pulse, loses ~15 % of frames in transfer, and
    // delivers within 10 ms so one frame period holds its latency.
    let mut camera_config = SimCameraConfig::new(11, 64, board.device_clock());
    camera_config.timing.exposure_us = 2_000;
    camera_config.timing.readout_us = 5_000;
    camera_config.timing.transfer_us = 3_000;
    camera_config.timing.transfer_jitter_us = 200.0;
    camera_config.flash_reference_us = Some(FULL_ON_US);
    camera_config.faults.drop_probability = 0.15;
    let source = Arc::new(PoseIndexSource {
        width: 16,
        height: 8,
    });
    let sim_camera = SimCamera::spawn(camera_config, source, edges_rx).unwrap();
    let info = CameraInfo {
        backend: "sim",
        model: "pose-index test pattern".into(),
        width: 16,
        height: 8,
        layout: "mono_polar".into(),
        bit_depth: 16,
    };
    let camera = Box::new(SimCameraBackend::new(sim_camera, clock, info));

    let tmp = tempfile::tempdir().unwrap();
    let manifest = Manifest::new(
        SessionSource::Simulator {
            scene: "pose-index pattern".into(),
            seed: 11,
        },
        SensorInfo {
            layout: ellipso_model::mosaic::SensorLayout::MonoPolar,
            width: 16,
            height: 8,
            bit_depth: 16,
        },
        clock.wall_at_epoch_unix_us(),
    );
    let session = SessionWriter::create(&tmp.path().join("s"), manifest).unwrap();
    let board_cfg = CaptureConfig {
        exposure_us: 2_000,
        flash_delay_us: 100,
        flash_duration_us: FULL_ON_US,
        frame_period_us: 20_000,
        pulses: PulseCount::Count(PULSES),
        trigger: TriggerSource::FreeRun,
        report_edges: false,
        bracket: Bracket::from_relative(&ENERGIES).unwrap(),
    };
    let plan = CapturePlan {
        board: board_cfg,
        camera: CameraSettings {
            exposure_us: 2_000,
            gain_db: 0.0,
            bit_depth: 16,
            external_trigger: true,
        },
        clock_sync_pings: 20,
        pairing: PairingConfig::for_capture(2_000, 20_000, 15_000),
        frame_queue: 8,
        writer_threads: 1,
        max_duration: Duration::from_secs(60),
    };
    let (report, dir) = capture(
        &link,
        camera,
        session,
        &plan,
        &AtomicBool::new(false),
        |_| {},
    )
    .expect("capture runs");
    drop(link);
    let truth = board.shutdown();

    // The board fired the bracket in turn.
    assert_eq!(truth.pulses.len(), PULSES as usize);
    for (k, p) in truth.pulses.iter().enumerate() {
        assert_eq!(usize::from(p.bracket_step), k % 3);
        assert_eq!(p.flash_on_us, [400, 100, 25][k % 3]);
    }
    // Frames were lost mid-capture, and the pairing reported each lost one.
    assert_eq!(report.pulses, u64::from(PULSES), "{report:?}");
    let lost = report.pairing.pulse_without_frame;
    assert!(lost >= 2, "{:?}", report.pairing);
    assert_eq!(report.pairing.paired + lost, u64::from(PULSES));
    assert_eq!(report.pairing.frame_without_pulse, 0);
    assert_eq!(
        report.paired_per_step.iter().sum::<u64>(),
        report.pairing.paired
    );

    // Every recorded frame carries the energy that really lit it.
    let s = reader::open(&dir).expect("session opens");
    assert_eq!(s.frames.len() as u64, report.pairing.paired);
    let seqs: Vec<u64> = s.frames.iter().filter_map(|f| f.pulse_seq).collect();
    let gaps = seqs.windows(2).filter(|w| w[1] > w[0] + 1).count();
    assert!(
        gaps >= 1,
        "no frame lost between two recorded ones: {seqs:?}"
    );
    for f in &s.frames {
        let (_, _, px) = s.load_frame(f).unwrap();
        let lit = PoseIndexSource::decode_energy(&px).unwrap();
        let seq = f.pulse_seq.expect("every recorded frame is paired");
        let step = usize::from(f.bracket_step);
        assert_eq!(step as u64, seq % 3, "frame {} of pulse {seq}", f.frame_id);
        assert_eq!(f.flash_on_us, Some([400, 100, 25][step]));
        assert_eq!(f.flash_energy_rel, ENERGIES[step]);
        assert!(
            (lit - f.flash_energy_rel).abs() < 1e-4,
            "frame {} recorded at {} but lit at {lit}",
            f.frame_id,
            f.flash_energy_rel
        );
    }
    // The configured bracket is on record, as Q15.
    let configured = s.events.iter().find_map(|e| match e {
        SessionEvent::Configured { config, .. } => Some(config.clone()),
        _ => None,
    });
    assert_eq!(configured.unwrap().bracket, [32768, 8192, 2048]);
}
