//! The GigE Vision camera backend end to end: libaravis' fake camera serving real GVCP/GVSP on
//! 127.0.0.1, read through `ellipso_rig::camera::aravis::AravisCamera` opened by IP.
//!
//! Network safety: every test re-executes itself inside `unshare -rn` (a private network
//! namespace whose only interface is `lo`, brought up first) and **fails** if that is impossible;
//! its body never runs in the host's namespace. Cameras are opened by `127.0.0.1` only; nothing
//! here enumerates or discovers. `gige_open_sends_no_discovery` proves the open path sends no
//! discovery by reading libaravis' own debug log.
//!
//! Scene content: the fake camera's fill callback writes a pattern derived from the frame's GVSP
//! block id into every pixel, so each delivered frame can be checked to belong to its id, and a
//! frame with stale or missing data cannot pass as complete.

use std::process::Command;
use std::time::Duration;

use ellipso_rig::acquire::pairing::{FrameArrival, Pairer, PairingConfig, PairingOutcome, Pulse};
use ellipso_rig::camera::aravis::fake::{FakeGigeCamera, FakeGigeOptions};
use ellipso_rig::camera::aravis::format::{PFNC_MONO12, PFNC_MONO12_PACKED};
use ellipso_rig::camera::aravis::{AravisCamera, AravisOptions};
use ellipso_rig::camera::{Camera, CameraSettings, Frame, FrameStatus};
use ellipso_rig::link::clock::ClockFit;
use ellipso_session::time::{DeviceTimeUs, HostClock, HostTimeUs};

#[path = "gige/support.rs"]
mod support;

use support::*;

#[test]
fn gige_mono12_stream_is_complete_and_crosses_the_id_wrap() {
    if reexec_in_netns("gige_mono12_stream_is_complete_and_crosses_the_id_wrap") {
        return;
    }
    let mut rig = rig(256, 192, PFNC_MONO12, 1400, 500.0);
    assert_eq!(rig.camera.info().width, 256);
    let frames = grab(&mut rig.camera, 200);
    assert_clean(&frames);
    let blocks: Vec<u64> = frames.iter().filter_map(content_block).collect();
    assert!(
        blocks[0] > 65_000,
        "the fake camera starts near the wrap: {}",
        blocks[0]
    );
    assert!(
        blocks.windows(2).any(|w| w[0] == 65_535 && w[1] == 1),
        "block id 65535 → 1 wrap crossed"
    );
    let c = rig.camera.counters();
    assert_eq!(
        (c.completed, c.missing_packets, c.other_failures),
        (200, 0, 0)
    );
    assert_eq!(c.underruns, 0, "pool sized for 0.5 s at the frame rate");
    assert_eq!(rig.camera.frames_skipped_by_id(), 0);
    assert_eq!(frames[0].meta.width * frames[0].meta.height, 256 * 192);
    assert!(
        frames
            .windows(2)
            .all(|w| w[0].meta.t_host_us <= w[1].meta.t_host_us)
    );
}

#[test]
fn gige_mono12_packed_stream_unpacks_exactly() {
    if reexec_in_netns("gige_mono12_packed_stream_unpacks_exactly") {
        return;
    }
    let mut rig = rig(256, 192, PFNC_MONO12_PACKED, 1400, 500.0);
    assert_eq!(
        rig.camera.encoding(),
        ellipso_rig::camera::unpack::RawEncoding::Mono12Packed
    );
    let frames = grab(&mut rig.camera, 40);
    assert_clean(&frames);
}

#[test]
fn gige_full_sensor_mono12_frames_arrive_bit_exact() {
    if reexec_in_netns("gige_full_sensor_mono12_frames_arrive_bit_exact") {
        return;
    }
    let mut rig = rig(2448, 2048, PFNC_MONO12, 8000, 24.0);
    let frames = grab(&mut rig.camera, 6);
    assert_clean(&frames);
    assert_eq!(frames[0].pixels.len(), 2448 * 2048);
}

#[test]
fn gige_packet_loss_flags_frames_and_never_passes_bad_content() {
    if reexec_in_netns("gige_packet_loss_flags_frames_and_never_passes_bad_content") {
        return;
    }
    // 256×192 Mono12 in 1400 B packets: ~70 packets a frame, so 1 % loss damages about half
    let mut rig = rig(256, 192, PFNC_MONO12, 1400, 500.0);
    rig.fake.set_lost_ratio(0.01);
    let frames = grab(&mut rig.camera, 150);
    let mut complete = 0u64;
    let mut flagged = 0u64;
    for f in &frames {
        match &f.meta.status {
            FrameStatus::Complete => {
                complete += 1;
                let block = content_block(f).expect("a complete frame has its whole pattern");
                let first = frames
                    .iter()
                    .find(|g| g.meta.status == FrameStatus::Complete)
                    .unwrap();
                let first_block = content_block(first).unwrap();
                assert_eq!(
                    block_distance(first_block, block),
                    f.meta.frame_id - first.meta.frame_id,
                    "complete frame {} carries another id's content",
                    f.meta.frame_id
                );
            }
            FrameStatus::Flagged(reason) => {
                flagged += 1;
                assert_eq!(reason, "missing packets");
                assert_eq!(
                    (f.meta.width, f.meta.height),
                    (256, 192),
                    "flagged frames keep their size"
                );
                assert_eq!(f.pixels.len(), 256 * 192);
            }
        }
    }
    let c = rig.camera.counters();
    let span = frames.last().unwrap().meta.frame_id - frames[0].meta.frame_id + 1;
    println!(
        "1% loss: {complete} complete, {flagged} flagged, {} other {:?}, {} skipped by id, span {span}",
        c.other_failures,
        rig.camera.failures_by_reason(),
        rig.camera.frames_skipped_by_id()
    );
    assert_eq!(c.completed, complete);
    assert_eq!(c.missing_packets, flagged);
    assert_eq!(complete + flagged, frames.len() as u64);
    assert!(
        frames
            .windows(2)
            .all(|w| w[0].meta.frame_id < w[1].meta.frame_id)
    );
    // every id in the span is accounted for: delivered, failed, lost whole, or underrun
    assert!(c.completed + c.missing_packets + c.other_failures + c.underruns >= span);
    assert!(
        flagged > 0,
        "1 % loss over ~10 000 packets must damage frames"
    );
    assert!(complete > 0, "about half the frames survive 1 % loss");
}

#[test]
fn gige_frames_pair_with_their_own_pulses() {
    if reexec_in_netns("gige_frames_pair_with_their_own_pulses") {
        return;
    }
    // Simulated: the trigger board. Its pulse k fires at t0 + k·P, P being the fake camera's
    // frame period (the fake camera free-runs on that period, as a triggered camera follows its
    // pulses); the clock fit is exact (device clock ≡ host clock) and t0 puts the most common
    // arrival phase 1 ms after its pulse, as a clock sync would. Real: the frames, their ids
    // and arrival times, from GVSP on loopback, with the host's scheduling jitter. Truth: the
    // block id in the pixels. The fake camera's first frame leaves at start, off its period
    // grid: it stands for a frame from before the pulse train and is not fed. Frames 12, 25, …
    // are withheld (lost on the wire). A quarter period after pulse K−1 an extra pulse fires that the camera ignores
    // (it came during readout: a missed trigger), and every later pulse's sequence number is one
    // higher, so ids and pulses disagree from then on. The period (50 ms) is chosen so the timing
    // evidence (extra pulse ≥ 37 ms before frame K) beats this host's arrival jitter (~1–10 ms
    // after the trigger, seen on a loaded 2-core machine, plus the 12 ms tolerance).
    const FPS: f64 = 20.0;
    const N: usize = 40;
    const K: u64 = 20;
    const SEQ0: u64 = 1_000;
    let period_us = 1e6 / FPS;
    let mut rig = rig(256, 192, PFNC_MONO12, 1400, FPS);
    let frames = grab(&mut rig.camera, N);
    assert_clean(&frames);
    assert!(
        frames
            .windows(2)
            .all(|w| w[0].meta.t_camera_ns < w[1].meta.t_camera_ns),
        "camera timestamps present and increasing"
    );
    let first_block = content_block(&frames[0]).unwrap();
    let index = |f: &Frame| block_distance(first_block, content_block(f).unwrap());
    let truth_seq = |k: u64| if k < K { SEQ0 + k } else { SEQ0 + k + 1 };
    let phases: Vec<f64> = frames
        .iter()
        .map(|f| f.meta.t_host_us.0 as f64 - index(f) as f64 * period_us)
        .collect();
    // The pulse train is anchored on the most common phase (the one with the most frames
    // within ±2 ms), not the median: on a loaded host the fake camera can shift its phase
    // mid-run (measured in CI: 19 frames at one phase, 16 at 100 ms later, one 9 ms off), and
    // the median of such a run is a stray frame between the groups, which put the whole first
    // group 8 ms *before* its pulses while that one frame looked in time.
    let support = |p: f64| phases.iter().filter(|q| (*q - p).abs() <= 2_000.0).count();
    let mode = phases
        .iter()
        .copied()
        .max_by(|a, b| support(*a).cmp(&support(*b)).then(b.total_cmp(a)))
        .unwrap();
    let t0 = mode - 1_000.0;

    let trigger = |k: f64| (t0 + k * period_us).max(0.0) as u64;

    let mut events: Vec<(u64, Option<&Frame>, u64, u64)> = Vec::new(); // (host µs, frame, seq, t_dev)
    for k in 1..N as u64 {
        let t = trigger(k as f64);
        events.push((t + 300, None, truth_seq(k), t));
    }
    let t_extra = trigger(K as f64 - 0.75);
    events.push((t_extra + 300, None, SEQ0 + K, t_extra));
    let fed = |f: &&Frame| index(f) >= 1 && index(f) % 13 != 12;
    for f in frames.iter().filter(fed) {
        events.push((f.meta.t_host_us.0, Some(f), 0, 0));
    }
    events.sort_by_key(|e| e.0);

    let fit = ClockFit {
        gain: 1.0,
        offset_us: 0.0,
        residuals_us: vec![0.0; 8],
        rms_us: 0.0,
        n_samples: 8,
    };
    let max_latency_us = period_us * 0.9;
    let config = PairingConfig {
        min_latency_us: 0.0,
        max_latency_us,
        min_pulse_spacing_us: period_us,
        max_exposure_delay_us: 2_000.0,
        pulse_timeout_us: period_us * 4.0,
        // host scheduling puts frame arrivals 1–10 ms after their trigger here
        latency_tolerance_us: 12_000.0,
    };
    let mut pairer = Pairer::new(config);
    let mut outcomes = Vec::new();
    let by_id = |id: u64| frames.iter().find(|f| f.meta.frame_id == id).unwrap();
    for (t_host, frame, seq, t_dev) in events {
        outcomes.extend(pairer.expire(Some(&fit)));
        outcomes.extend(match frame {
            Some(f) => pairer.add_frame(
                FrameArrival {
                    frame_id: f.meta.frame_id,
                    t_host_arrival: f.meta.t_host_us,
                    // no latch of the fake camera's counter: pairing on arrival time
                    t_camera_ns: None,
                },
                Some(&fit),
            ),
            None => pairer.add_pulse(
                Pulse {
                    seq,
                    t_trigger: DeviceTimeUs(t_dev),
                    t_host_recv: HostTimeUs(t_host),
                },
                Some(&fit),
            ),
        });
    }
    outcomes.extend(pairer.finish(Some(&fit)));
    // The pairer's contract holds while every frame arrives within [min, max] latency of its
    // trigger. Outside it the timing evidence itself is wrong: a host stall longer than that
    // makes a frame look like the next pulse's, and the fake camera occasionally shifts its
    // phase (a frame arrives before its grid slot, i.e. the simulated pulse train no longer
    // matches it). Such frames are counted and reported, and only they may pair wrongly.
    let late: Vec<u64> = frames
        .iter()
        .filter(fed)
        .filter(|f| {
            let latency = f.meta.t_host_us.0 as f64 - trigger(index(f) as f64) as f64;
            !(0.0..=max_latency_us).contains(&latency)
        })
        .map(index)
        .collect();
    let mut paired = 0;
    let mut wrong = Vec::new();
    for o in &outcomes {
        if let PairingOutcome::Paired {
            frame_id, pulse, ..
        } = *o
        {
            let seq = pulse.seq;
            let k = index(by_id(frame_id));
            if seq != truth_seq(k) {
                wrong.push((k, seq));
            }
            paired += 1;
        }
    }
    let n_fed = frames.iter().filter(fed).count();
    let latencies: Vec<i64> = frames
        .iter()
        .filter(fed)
        .map(|f| (f.meta.t_host_us.0 as f64 - trigger(index(f) as f64) as f64) as i64)
        .collect();
    println!("arrival after trigger, µs: {latencies:?}");
    let fed = n_fed;
    println!(
        "pairing: {paired} of {fed} fed frames paired, wrong {wrong:?}, outside the window \
         {late:?}, counts {:?}",
        pairer.counts()
    );
    for (k, seq) in &wrong {
        assert!(
            late.contains(k),
            "frame index {k} arrived in time but was paired with pulse {seq}, not {}",
            truth_seq(*k)
        );
    }
    // Known limit of `Pairer` (reported, not ours to change here): its learned latency window
    // starts from the first confirmed pair, so when the very first fed frame is a host-jitter
    // outlier the window excludes the typical latency and later frames stay unpaired (never
    // wrongly paired). The pairing rate is only asserted when that did not happen and every
    // frame kept to the simulated timing.
    let mut sorted = latencies.clone();
    sorted.sort_unstable();
    let median = sorted[sorted.len() / 2];
    let first_is_outlier = (latencies[0] - median) as f64 > 12_000.0 / 2.0;
    if !first_is_outlier && late.is_empty() {
        assert!(
            paired * 10 >= fed * 9,
            "{paired} of {fed} paired ({} late), latencies {latencies:?}",
            late.len()
        );
    }
}

#[test]
fn gige_slow_consumer_shows_underruns_not_missing_packets() {
    if reexec_in_netns("gige_slow_consumer_shows_underruns_not_missing_packets") {
        return;
    }
    // an 8-buffer pool (datasheet rate understated on purpose) at 500 fps, and a consumer that
    // stalls for 60 ms: the camera keeps sending, libaravis has no free buffer, frames are lost
    // declared before the camera, so dropped after it
    let _fake = FakeGigeCamera::serve_on_loopback(
        &FakeGigeOptions {
            pixel_format: PFNC_MONO12,
            ..FakeGigeOptions::default()
        },
        Some(Box::new(fill)),
    )
    .expect("fake camera");
    let options = AravisOptions {
        region: Some((0, 0, 64, 64)),
        packet_size_bytes: Some(1400),
        frame_rate_hz: Some(500.0),
        datasheet_fps: 1.0,
        pool_span_s: 1.0,
        ..AravisOptions::default()
    };
    let mut camera = AravisCamera::open("127.0.0.1", options, HostClock::new()).expect("open");
    camera.start().expect("start");
    let mut frames = Vec::new();
    for _ in 0..4 {
        std::thread::sleep(Duration::from_millis(60));
        for _ in 0..12 {
            if let Some(f) = camera.next_frame(Duration::from_secs(3)).expect("stream") {
                frames.push(f);
            }
        }
    }
    camera.stop().expect("stop");
    let c = camera.counters();
    println!(
        "slow consumer: {} frames, counters {c:?}, skipped by id {}",
        frames.len(),
        camera.frames_skipped_by_id()
    );
    assert!(
        c.underruns > 0,
        "a stalled consumer with 8 buffers at 500 fps underruns"
    );
    // every id gap is an underrun, or (rarely, on a loaded host) a frame lost whole
    let lost_whole = camera
        .failures_by_reason()
        .get("frame lost whole (id gap without underrun)")
        .copied()
        .unwrap_or(0);
    assert_eq!(c.underruns + lost_whole, camera.frames_skipped_by_id());
    assert!(
        c.underruns > lost_whole,
        "the stalls, not the wire, lost the frames"
    );
    assert!(
        camera.underrun_packets() >= c.underruns,
        "libaravis counts packets"
    );
    assert_eq!(
        c.missing_packets, 0,
        "no packet was lost: underruns are not missing packets"
    );
    assert!(
        frames
            .iter()
            .all(|f| f.meta.status == FrameStatus::Complete)
    );
    assert!(
        frames
            .windows(2)
            .all(|w| w[0].meta.frame_id < w[1].meta.frame_id)
    );
    for f in &frames {
        assert!(
            content_block(f).is_some(),
            "frame {} content",
            f.meta.frame_id
        );
    }
}

#[test]
fn gige_settings_that_break_the_mosaic_or_lack_hardware_are_refused() {
    if reexec_in_netns("gige_settings_that_break_the_mosaic_or_lack_hardware_are_refused") {
        return;
    }
    let _fake =
        FakeGigeCamera::serve_on_loopback(&FakeGigeOptions::default(), Some(Box::new(fill)))
            .expect("fake camera");
    let open = |region| {
        AravisCamera::open(
            "127.0.0.1",
            AravisOptions {
                region: Some(region),
                ..AravisOptions::default()
            },
            HostClock::new(),
        )
    };
    let Err(e) = open((1, 0, 256, 192)) else {
        panic!("an odd offset must be refused")
    };
    assert!(e.to_string().contains("odd"), "{e}");
    let mut camera = open((0, 0, 256, 192)).expect("an even region opens");
    let settings = CameraSettings {
        exposure_us: 1_000,
        gain_db: 0.0,
        bit_depth: 12,
        external_trigger: true,
    };
    // the fake camera has TriggerSelector/TriggerMode/TriggerSource with Line0, and nothing
    // drives that line: armed on it, it sends nothing
    camera
        .configure(&settings)
        .expect("external trigger on Line0");
    camera.start().expect("start");
    assert_eq!(
        camera
            .next_frame(Duration::from_millis(300))
            .expect("stream"),
        None
    );
    assert_eq!(camera.counters().timeouts, 1);
    camera.stop().expect("stop");
    let e = camera
        .configure(&CameraSettings {
            bit_depth: 10,
            external_trigger: false,
            ..settings
        })
        .expect_err("the fake camera offers no 10-bit mono format");
    println!("10-bit on the fake camera: {e}");
    assert!(e.to_string().contains("no raw 10-bit"), "{e}");
    camera
        .configure(&CameraSettings {
            external_trigger: false,
            ..settings
        })
        .expect("12-bit free-running is fine");
    camera.start().expect("start");
    let frame = camera.next_frame(Duration::from_secs(3)).expect("stream");
    assert!(
        frame.is_some_and(|f| content_block(&f).is_some()),
        "free-running again"
    );
    camera.stop().expect("stop");
}

/// Child of `gige_open_sends_no_discovery`: opens and streams through the backend. Ignored when
/// run on its own: it only means something under its parent's debug log.
#[test]
#[ignore = "run by gige_open_sends_no_discovery"]
fn gige_child_open_by_ip() {
    assert!(
        std::env::var_os(CHILD).is_some(),
        "run by gige_open_sends_no_discovery"
    );
    assert!(
        std::env::var_os(IN_NETNS).is_some(),
        "must run inside the namespace"
    );
    let mut rig = rig(64, 64, PFNC_MONO12, 1400, 200.0);
    assert_clean(&grab(&mut rig.camera, 5));
}

#[test]
fn gige_open_sends_no_discovery() {
    if reexec_in_netns("gige_open_sends_no_discovery") {
        return;
    }
    let out = Command::new(std::env::current_exe().unwrap())
        .args([
            "gige_child_open_by_ip",
            "--exact",
            "--ignored",
            "--nocapture",
        ])
        .env(CHILD, "1")
        .env("ARV_DEBUG", "interface:3,device:3")
        .output()
        .expect("spawn child");
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "child failed:\n{log}");
    assert!(
        log.contains("[GvDevice::new] Device address = 127.0.0.1"),
        "aravis' debug log must show the open for this test to mean anything:\n{log}"
    );
    assert!(
        !log.contains("GvDiscoverSocket"),
        "opening by IP sent a discovery broadcast:\n{log}"
    );
}

/// `ellipso devices --gige --json` (the binary built with `--features aravis`) run inside the
/// namespace: `(exit status, parsed report, stdout)`.
fn devices_json() -> (std::process::ExitStatus, serde_json::Value, String) {
    let out = Command::new(ellipso_tests::ellipso_bin())
        .args(["devices", "--gige", "--json"])
        .output()
        .expect("spawn ellipso devices");
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(
        !stderr.contains("--features aravis"),
        "the ellipso binary lacks aravis: build it with `cargo build -p ellipso --features \
         aravis` before this test (or point ELLIPSO_BIN at one that has it): {stderr}"
    );
    let report = serde_json::from_str(&stdout)
        .unwrap_or_else(|e| panic!("devices --json is not JSON ({e}): {stdout}{stderr}"));
    (out.status, report, stdout)
}

/// Issue 45: `ellipso devices` says nothing is attached (exit 0) where no camera answers, and
/// lists the fake camera once one serves on the namespace's loopback.
#[test]
fn gige_devices_lists_the_fake_camera_and_says_when_nothing_is_attached() {
    if reexec_in_netns("gige_devices_lists_the_fake_camera_and_says_when_nothing_is_attached") {
        return;
    }
    let (status, none, text) = devices_json();
    assert!(status.success(), "no camera is not an error: {text}");
    assert_eq!(none["cameras"], serde_json::json!([]), "{text}");
    // nothing else is attached in the namespace of a CI machine (no board, no video device):
    // the report says so
    if none["v4l2"] == serde_json::json!([]) && none["dfu_bootloaders"] == serde_json::json!([]) {
        assert_eq!(none["nothing_attached"], true, "{text}");
        let table = Command::new(ellipso_tests::ellipso_bin())
            .args(["devices", "--gige"])
            .output()
            .expect("spawn ellipso devices");
        assert!(table.status.success());
        let table = String::from_utf8_lossy(&table.stdout);
        assert!(table.contains("nothing attached"), "{table}");
    }
    let options = FakeGigeOptions::default();
    let _fake = FakeGigeCamera::serve_on_loopback(&options, None).expect("fake camera on lo");
    let (status, found, text) = devices_json();
    assert!(status.success(), "{text}");
    let cameras = found["cameras"].as_array().expect("cameras listed");
    assert_eq!(cameras.len(), 1, "one fake camera serves: {text}");
    assert_eq!(cameras[0]["address"], "127.0.0.1", "{text}");
    assert!(
        cameras[0]["id"]
            .as_str()
            .is_some_and(|id| id.contains(&options.serial)),
        "its id names the fake's serial {}: {text}",
        options.serial
    );
    assert_eq!(found["nothing_attached"], false, "{text}");
}
