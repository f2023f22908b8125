//! The bracket on the virtual rig: the real firmware core fires it, the flash's light goes on the
//! wire, and the simulated camera renders each frame at the energy its exposure collected —
//! also when a frame is lost in transfer in the middle of the capture.

use std::sync::Arc;
use std::time::Duration;

use ellipso_protocol::{Bracket, HostMessage, PULSE_FLASH_SKIPPED};

use super::super::tests::{capture, fast_board, start_board};
use super::super::*;

/// 1, 1/4, 1/16 of a 400 µs pulse: 400, 100 and 25 µs.
fn bracket() -> Bracket {
    Bracket::from_relative(&[1.0, 0.25, 0.0625]).unwrap()
}

#[test]
fn the_camera_sees_each_bracketed_pulse_at_its_energy_even_around_a_dropped_frame() {
    const N: u32 = 30;
    let (board, mut host, edges) = start_board(fast_board(7));
    let mut config = SimCameraConfig::new(7, 64, board.device_clock());
    config.timing.exposure_us = 500;
    config.flash_reference_us = Some(400);
    config.faults.drop_probability = 0.15;
    let camera = SimCamera::spawn(
        config,
        Arc::new(PoseIndexSource {
            width: 16,
            height: 8,
        }),
        edges,
    )
    .unwrap();
    let mut plan = capture(N, 4_000); // 400 µs at 10 % duty
    plan.flash_duration_us = 400;
    plan.bracket = bracket();
    host.command(HostMessage::Configure(plan));
    host.command(HostMessage::Arm);
    host.command(HostMessage::Start);
    host.read_until(|r| {
        r.iter()
            .filter(|m| matches!(m, ellipso_protocol::BoardMessage::Pulse(_)))
            .count()
            == N as usize
    });
    let truth = board.shutdown(); // closes the wire: the camera delivers what is left
    let frames: Vec<SimFrame> = camera.frames().iter().collect();
    let counters = camera.join();

    // The board fired the bracket in turn, each on-time exact.
    assert_eq!(truth.pulses.len(), N as usize);
    for (k, p) in truth.pulses.iter().enumerate() {
        assert_eq!(p.bracket_step as usize, k % 3);
        assert_eq!(p.flash_on_us, [400, 100, 25][k % 3]);
        assert_eq!(p.flags & PULSE_FLASH_SKIPPED, 0);
    }
    // Frames were lost in transfer, mid-capture, and the rest still carry their own energy:
    // exposure k was lit by pulse k (no missed triggers), whatever was dropped before it.
    assert!(counters.dropped >= 2, "{counters:?}");
    let indices: Vec<u64> = frames.iter().map(|f| f.truth.exposure_index).collect();
    let gaps = indices.windows(2).filter(|w| w[1] > w[0] + 1).count();
    assert!(gaps >= 1, "no drop between delivered frames: {indices:?}");
    assert_eq!(frames.len() as u64 + counters.dropped, u64::from(N));
    for f in &frames {
        let k = f.truth.exposure_index as usize;
        let pulse = truth.pulses[k];
        let expected = f64::from(pulse.flash_on_us) / 400.0;
        assert_eq!(f.truth.flash_lit_us, Some(f64::from(pulse.flash_on_us)));
        assert_eq!(f.truth.flash_energy_rel, expected, "frame of pulse {k}");
        let rendered = PoseIndexSource::decode_energy(&f.pixels).unwrap();
        assert!(
            (rendered - expected).abs() < 1e-4,
            "rendered at {rendered}, lit {expected}"
        );
    }
}

#[test]
fn without_a_flash_reference_frames_render_at_full_energy_as_before() {
    let (board, mut host, edges) = start_board(fast_board(8));
    let mut config = SimCameraConfig::new(8, 4, board.device_clock());
    config.timing.exposure_us = 500;
    let camera = SimCamera::spawn(
        config,
        Arc::new(PoseIndexSource {
            width: 8,
            height: 8,
        }),
        edges,
    )
    .unwrap();
    let mut plan = capture(3, 2_000);
    plan.bracket = Bracket::from_relative(&[1.0, 0.5]).unwrap();
    host.command(HostMessage::Configure(plan));
    host.command(HostMessage::Arm);
    host.command(HostMessage::Start);
    // Frames flow before the capture ends: nothing waits for metering.
    let first = camera
        .frames()
        .recv_timeout(Duration::from_secs(5))
        .unwrap();
    assert_eq!(first.truth.flash_energy_rel, 1.0);
    assert_eq!(first.truth.flash_lit_us, None);
    host.read_until(|r| {
        r.iter()
            .filter(|m| matches!(m, ellipso_protocol::BoardMessage::Pulse(_)))
            .count()
            == 3
    });
    board.shutdown();
    let rest: Vec<SimFrame> = camera.frames().iter().collect();
    assert!(rest.iter().all(|f| f.truth.flash_energy_rel == 1.0));
    assert_eq!(rest.len(), 2);
}
