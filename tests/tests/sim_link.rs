//! The host's real trigger-link code against the virtual board on a real pseudo-terminal.
//!
//! The board runs the real firmware core (`ellipso_sim::rig::VirtualBoard`); the host opens the
//! pty's path with `TriggerLink::open`, exactly as it opens `/dev/ttyACM0`. The board records
//! every pulse it sent, so every pulse the host accepts is checked against the truth.
//!
//! Until the host link retries idempotent commands by itself, [`command`] here retries a command
//! whose reply was lost to a link bit error (see its docs).

use std::time::{Duration, Instant};

use ellipso_protocol::{
    BoardLimits, CaptureConfig, CommandKind, PulseCount, PulseEvent, RejectReason, TriggerSource,
};
use ellipso_rig::camera::FrameIdUnwrapper;
use ellipso_rig::camera::frame_id::Unwrapped;
use ellipso_rig::link::clock::ClockModelConfig;
use ellipso_rig::link::{LinkConfig, LinkError, LinkEvent, TriggerLink};
use ellipso_session::time::HostClock;
use ellipso_sim::rig::{
    CameraFaults, Disconnect, PoseIndexSource, SimCamera, SimCameraConfig, SimFrame, VirtualBoard,
    VirtualBoardConfig, wire,
};
use ellipso_sim::scene::Scene;
use serialport::{SerialPort, TTYPort};

/// The LED-rig limits with a 5 ms readout, so a 20 ms (or 10 ms) free run is valid.
fn board_config(seed: u64) -> VirtualBoardConfig {
    let mut c = VirtualBoardConfig::new(seed);
    c.board.limits = BoardLimits {
        readout_us: 5_000,
        min_frame_period_us: 5_020,
        ..c.board.limits
    };
    c
}

fn capture(pulses: u32, period_us: u32) -> CaptureConfig {
    CaptureConfig {
        exposure_us: 2_000,
        flash_delay_us: 100,
        flash_duration_us: 500,
        frame_period_us: period_us,
        pulses: PulseCount::Count(pulses),
        trigger: TriggerSource::FreeRun,
        report_edges: false,
        bracket: ellipso_protocol::Bracket::NONE,
    }
}

struct Rig {
    board: VirtualBoard,
    link: TriggerLink,
    /// Held like `ellipso sim serve` does, so the board's end survives host closes.
    _device_end: TTYPort,
}

/// A virtual board on a fresh pty and the host's link on its path (handshake retried while a
/// corrupted reply times out).
fn start(config: VirtualBoardConfig) -> Rig {
    start_with_wire(config, None)
}

fn start_with_wire(
    config: VirtualBoardConfig,
    wire: Option<crossbeam_channel::Sender<ellipso_sim::rig::TriggerEdge>>,
) -> Rig {
    let (mut master, device_end) = TTYPort::pair().expect("openpty");
    master.set_timeout(Duration::from_millis(20)).unwrap();
    let reader = master.try_clone_native().unwrap();
    let board = VirtualBoard::spawn(config, Box::new(reader), Box::new(master), wire).unwrap();
    let path = device_end.name().expect("pty path");
    let link_config = LinkConfig {
        reply_timeout: Duration::from_millis(250),
        // A pty answers in tens of µs; a sample whose round trip a loaded machine stretched
        // past 2 ms says little about when the board stamped it.
        clock: ClockModelConfig {
            max_round_trip_us: 2_000,
            ..ClockModelConfig::default()
        },
        ..LinkConfig::default()
    };
    let mut last = None;
    for _ in 0..8 {
        match TriggerLink::open(&path, HostClock::new(), link_config) {
            Ok(link) => {
                return Rig {
                    board,
                    link,
                    _device_end: device_end,
                };
            }
            Err(e @ LinkError::Timeout { .. }) => last = Some(e),
            Err(e) => panic!("cannot open {path}: {e}"),
        }
    }
    panic!("no handshake in 8 tries: {last:?}");
}

/// Sends a command, retrying when its reply was lost (a `Timeout`) — safe for these commands:
/// `Configure` and `Arm` are idempotent before `Start`; a `Start` whose `Ack` was lost leaves the
/// board running, so a `Busy` refusal of its retry means the first one got through.
/// Returns how many retries it took.
fn command(link: &TriggerLink, kind: CommandKind, f: impl Fn() -> Result<(), LinkError>) -> u32 {
    let mut retries = 0;
    for _ in 0..10 {
        match f() {
            Ok(()) => return retries,
            Err(LinkError::Timeout { .. }) => retries += 1,
            Err(LinkError::Rejected {
                reason: RejectReason::Busy,
                ..
            }) if retries > 0 && kind == CommandKind::Start => return retries,
            Err(e) => panic!("{kind:?} failed: {e}"),
        }
    }
    panic!("{kind:?}: no reply in 10 tries ({:?})", link.counters());
}

/// Configure, arm, start; returns the retries needed.
fn run_capture(link: &TriggerLink, config: CaptureConfig) -> u32 {
    command(link, CommandKind::Configure, || link.configure(config))
        + command(link, CommandKind::Arm, || link.arm())
        + command(link, CommandKind::Start, || link.start())
}

/// Collects pulse events until the board has fired `n` and the link has been quiet for 100 ms,
/// pinging every `ping_every` meanwhile (pings lost to bit errors are skipped).
fn collect_pulses(rig: &Rig, n: usize, ping_every: Option<Duration>) -> Vec<(PulseEvent, u64)> {
    let mut pulses = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut next_ping = Instant::now();
    let mut quiet_since = None;
    while Instant::now() < deadline {
        if let Some(every) = ping_every
            && Instant::now() >= next_ping
        {
            let _ = rig.link.ping();
            next_ping = Instant::now() + every;
        }
        match rig.link.events().recv_timeout(Duration::from_millis(5)) {
            Ok(LinkEvent::Pulse { event, t_host_recv }) => {
                pulses.push((event, t_host_recv.0));
                quiet_since = None;
            }
            Ok(LinkEvent::Disconnected { reason }) => panic!("disconnected: {reason}"),
            Ok(_) => {}
            Err(_) => {
                if rig.board.truth().pulses.len() >= n {
                    let since = *quiet_since.get_or_insert_with(Instant::now);
                    if since.elapsed() > Duration::from_millis(100) {
                        return pulses;
                    }
                }
            }
        }
    }
    panic!("capture did not complete: {} of {n} pulses", pulses.len());
}

#[test]
fn host_link_captures_fifty_pulses_from_the_virtual_board_over_a_pty() {
    let rig = start(board_config(1));
    assert_eq!(rig.link.board().board_name.as_str(), "ellipso-virtual");
    rig.link.sync_clock(10).unwrap();
    run_capture(&rig.link, capture(50, 20_000));
    let pulses = collect_pulses(&rig, 50, Some(Duration::from_millis(10)));
    let truth = rig.board.truth();
    let got: Vec<PulseEvent> = pulses.iter().map(|p| p.0).collect();
    assert_eq!(
        got, truth.pulses,
        "the host must receive exactly what the board sent"
    );
    let seqs: Vec<u64> = got.iter().map(|p| p.seq).collect();
    assert_eq!(seqs, (0..50).collect::<Vec<_>>());
    assert!(got.iter().all(|p| p.flags == 0));
    assert_eq!(rig.link.counters().bad_frames(), 0);

    // Clock sync: the host's fit maps each pulse's device time to within 2 ms (a tenth of the
    // frame period, enough to pair frames) of when the board's device clock really read it
    // (truth: the board's LinearClock). Typical here: rms 30–250 µs, worst 10–100 µs; the bounds
    // leave room for a loaded 2-core CI machine.
    // On a loaded machine many round trips are too long to use: top the fit up to 20 samples.
    let deadline = Instant::now() + Duration::from_secs(5);
    while rig.link.clock_fit().is_none_or(|f| f.n_samples < 20) && Instant::now() < deadline {
        let _ = rig.link.ping();
        std::thread::sleep(Duration::from_millis(5));
    }
    let fit = rig.link.clock_fit().expect("a clock fit");
    assert!(fit.rms_us < 1_000.0, "clock residual rms {} µs", fit.rms_us);
    let device_clock = rig.board.device_clock();
    let host_clock = rig.link.host_clock();
    // The host clock's epoch, as an Instant (both clocks are the same monotonic clock).
    let now = Instant::now();
    let host_epoch = now - Duration::from_micros(host_clock.now().0);
    let mut worst_us = 0f64;
    for p in &got {
        let truth_host_us = device_clock
            .instant_at_us(p.t_trigger_us)
            .duration_since(host_epoch)
            .as_secs_f64()
            * 1e6;
        let fitted = fit.host_us(ellipso_session::time::DeviceTimeUs(p.t_trigger_us));
        worst_us = worst_us.max((fitted - truth_host_us).abs());
    }
    println!(
        "clock fit: {} samples, rms {:.1} µs, drift {:+.1} ppm (board truth +25 ppm fast = {:+.1} ppm host-per-device), worst pulse mapping error {:.1} µs",
        fit.n_samples,
        fit.rms_us,
        fit.drift_ppm(),
        (1.0 / (1.0 + 25e-6) - 1.0) * 1e6,
        worst_us
    );
    assert!(worst_us < 2_000.0, "pulse times mapped {worst_us} µs off");
    drop(rig.link);
    let truth = rig.board.shutdown();
    assert_eq!(truth.end_reason.as_deref(), Some("stopped by its owner"));
}

#[test]
fn an_invalid_configuration_is_rejected_with_its_reason() {
    let rig = start(board_config(2));
    let bad = CaptureConfig {
        flash_delay_us: 1_800,
        flash_duration_us: 500, // 1.8 ms + 0.5 ms > 2 ms exposure
        ..capture(5, 20_000)
    };
    match rig.link.configure(bad) {
        Err(
            e @ LinkError::Rejected {
                reason: RejectReason::FlashOutsideExposure,
                ..
            },
        ) => assert!(e.to_string().contains("outside the exposure"), "{e}"),
        other => panic!("expected FlashOutsideExposure, got {other:?}"),
    }
    let too_fast = capture(5, 6_000); // 2 ms exposure + 5 ms readout > 6 ms
    assert!(matches!(
        rig.link.configure(too_fast),
        Err(LinkError::Rejected {
            reason: RejectReason::PeriodTooShort { min_us: 7_000 },
            ..
        })
    ));
    // The board is still usable and never started.
    assert!(matches!(
        rig.link.start(),
        Err(LinkError::Rejected {
            reason: RejectReason::NotConfigured,
            ..
        })
    ));
    assert!(rig.board.truth().pulses.is_empty());
}

#[test]
fn link_bit_errors_are_dropped_and_counted_never_accepted() {
    println!(
        "| BER | frames sent | corrupted (truth) | accepted | bad frames dropped | pulses received | corrupt accepted | command retries |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (i, ber) in [0.0, 1e-5, 1e-4, 1e-3].into_iter().enumerate() {
        let mut config = board_config(100 + i as u64);
        config.link.ber_to_host = ber;
        let rig = start(config);
        let retries = run_capture(&rig.link, capture(50, 10_000));
        let pulses = collect_pulses(&rig, 50, None);
        let truth = rig.board.truth();
        assert_eq!(
            truth.pulses.len(),
            50,
            "BER {ber}: the capture did not complete"
        );
        let corrupt_accepted = pulses
            .iter()
            .filter(|(p, _)| truth.pulses.get(p.seq as usize) != Some(p))
            .count();
        let counters = rig.link.counters();
        println!(
            "| {ber:.0e} | {} | {} | {} | {} | {} / 50 | {corrupt_accepted} | {retries} |",
            truth.frames_sent,
            truth.frames_corrupted,
            counters.frames_ok,
            counters.bad_frames(),
            pulses.len(),
        );
        assert_eq!(
            corrupt_accepted, 0,
            "BER {ber}: a corrupted pulse was accepted"
        );
        let mut seqs: Vec<u64> = pulses.iter().map(|(p, _)| p.seq).collect();
        seqs.dedup();
        assert_eq!(seqs.len(), pulses.len(), "BER {ber}: a pulse arrived twice");
        if truth.frames_corrupted == 0 {
            assert_eq!(
                pulses.len(),
                50,
                "BER {ber}: pulses lost without corruption"
            );
            assert_eq!(counters.bad_frames(), 0);
        } else {
            assert!(
                counters.bad_frames() > 0,
                "BER {ber}: corruption went uncounted"
            );
        }
        // No corrupted frame decodes (CRC-32C), and each corruption costs at most its own frame
        // and the neighbour a flipped delimiter merges it with.
        let clean = truth.frames_sent - truth.frames_corrupted;
        assert!(counters.frames_ok <= clean, "BER {ber}: {counters:?}");
        assert!(
            clean - counters.frames_ok <= truth.frames_corrupted,
            "BER {ber}: {counters:?}"
        );
    }
}

#[test]
fn a_scene_disconnect_ends_the_stream_and_keeps_everything_before() {
    // The scene's `link_disconnect.at_frame` is the first pulse not delivered.
    let scene = Scene::from_toml_str(
        r#"
seed = 9
[materials.matte]
eta = 1.5
sigma_s = 0.3
sigma_ss = 0.5
rho_s = 0.2
rho_ss = [0.0, 0.0, 0.0]
rho_d = [0.5, 0.5, 0.5]
[[objects]]
name = "ball"
shape = "sphere"
radius_m = 0.03
pose = { translation_m = [0.0, 0.0, 0.03] }
material = "matte"
[rig.camera]
resolution_px = [64, 48]
fx_px = 60.0
fy_px = 60.0
cx_px = 32.0
cy_px = 24.0
sensor = "mono_polar"
exposure_us = 2000.0
[capture]
path = "orbit"
photo_count = 30
look_at_m = [0.0, 0.0, 0.03]
radius_m = 0.45
elevation_deg = [30.0, 60.0]
[effects.link_disconnect]
at_frame = 12
"#,
        std::path::Path::new("inline.toml"),
    )
    .expect("scene");
    let mut config = VirtualBoardConfig::from_scene(&scene);
    assert_eq!(
        config.link.disconnect,
        Some(Disconnect {
            at_pulse: 12,
            blackout: None
        })
    );
    config.board.limits = board_config(0).board.limits;
    let rig = start(config);
    run_capture(&rig.link, capture(30, 10_000));
    let mut pulses = Vec::new();
    let reason = loop {
        match rig.link.events().recv_timeout(Duration::from_secs(5)) {
            Ok(LinkEvent::Pulse { event, .. }) => pulses.push(event),
            Ok(LinkEvent::Disconnected { reason }) => break reason,
            Ok(_) => {}
            Err(e) => panic!("no disconnect: {e}"),
        }
    };
    assert!(rig.board.wait_finished(Duration::from_secs(5)));
    let truth = rig.board.truth();
    assert_eq!(truth.disconnected_at_pulse, Some(12));
    assert_eq!(
        pulses,
        truth.pulses[..12],
        "everything before the disconnect, intact"
    );
    assert!(!rig.link.is_connected(), "reader saw: {reason}");
    assert!(matches!(rig.link.status(), Err(LinkError::Disconnected(_))));
}

#[test]
fn the_in_process_rig_delivers_frames_the_host_can_pair_to_pulses_by_block_id() {
    // Board on a pty, trigger wire, camera with drops and duplicates whose block ids wrap early.
    let (edges_tx, edges_rx) = wire::wire();
    let rig = start_with_wire(board_config(4), Some(edges_tx));
    let mut camera_config = SimCameraConfig::new(4, 36, rig.board.device_clock());
    camera_config.first_block_id = 65_525;
    camera_config.faults = CameraFaults {
        drop_probability: 0.1,
        duplicate_probability: 0.1,
        ..CameraFaults::default()
    };
    let source = std::sync::Arc::new(PoseIndexSource {
        width: 32,
        height: 16,
    });
    let camera = SimCamera::spawn(camera_config, source, edges_rx).unwrap();
    run_capture(&rig.link, capture(40, 10_000));
    let pulses = collect_pulses(&rig, 40, None);
    let Rig { board, link, .. } = rig;
    let device_clock = board.device_clock();
    drop(link);
    board.shutdown(); // closes the wire: the camera delivers what is left and ends
    let frames: Vec<SimFrame> = camera.frames().iter().collect();
    let counters = camera.join();
    assert_eq!(counters.rising_edges, 40);
    assert!(
        counters.dropped > 0 && counters.duplicated > 0,
        "{counters:?}"
    );

    // What a host does: unwrap block ids to 64-bit frame ids; with no missed triggers the
    // first exposure is pulse 0, so frame id == pulse seq.
    let mut unwrapper = FrameIdUnwrapper::new();
    let (mut paired, mut duplicates, mut skipped_total) = (0, 0, 0);
    let mut wrapped = false;
    for f in &frames {
        wrapped |= f.block_id < 100;
        match unwrapper.push(f.block_id) {
            Unwrapped::Next { frame_id, skipped } => {
                skipped_total += skipped;
                assert_eq!(frame_id, f.truth.exposure_index);
                let (pulse, _) = pulses
                    .iter()
                    .find(|(p, _)| p.seq == frame_id)
                    .expect("a pulse for every frame");
                assert_eq!(pulse.t_trigger_us, f.truth.t_trigger_device_us);
                assert_eq!(f.truth.pose_index, (frame_id % 36) as usize);
                // Simulated arrival: exposure + readout + transfer (± jitter) after the trigger.
                let latency = f
                    .arrival
                    .duration_since(device_clock.instant_at_us(pulse.t_trigger_us))
                    .as_secs_f64()
                    * 1e6;
                assert!((60_000.0..70_000.0).contains(&latency), "{latency} µs");
                paired += 1;
            }
            Unwrapped::Duplicate { .. } => {
                assert!(f.truth.duplicate);
                duplicates += 1;
            }
            Unwrapped::Invalid => panic!("block id 0 delivered"),
        }
    }
    assert!(wrapped, "block ids did not wrap");
    assert_eq!(paired, 40 - counters.dropped);
    assert_eq!(skipped_total, counters.dropped);
    assert_eq!(duplicates, counters.duplicated);
}
