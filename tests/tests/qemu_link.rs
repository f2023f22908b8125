//! The host's real trigger-link code against the real firmware on an emulated MCU.
//!
//! QEMU `netduinoplus2` runs the `firmware/boards/qemu` ELF; [`TriggerLink`] talks to its USART1
//! once over a unix socket and once over a pseudo-terminal (the path a USB CDC-ACM board takes).
//! Each run: handshake; an invalid configuration refused with its reason; a free-running capture
//! of [`PULSES`] pulses with edge reports, checked pulse by pulse (consecutive sequence numbers,
//! edges in the order camera on, flash on, flash off, camera off, at their configured offsets);
//! the same sequence read back from the firmware's GPIO register writes; clock sync by ping; a
//! bracket refused for a step that rounds to 0 µs; a 1, 1/4, 1/16 flash-energy bracket whose every
//! pulse reports its step and lights for its planned on-time within one timer tick (1 µs).
//!
//! Guest time is deterministic (`-icount shift=3,align=off,sleep=off`, busy-idle firmware), so
//! offsets are asserted as "at least the configured value, at most the board's late tolerance
//! more" — the same bound under which the firmware itself would flag the pulse late.
//!
//! Needs `qemu-system-arm` and the firmware ELF (`ELLIPSO_QEMU_FW`, or the default release path);
//! without them the tests print `skipped:` and pass, unless `ELLIPSO_REQUIRE_QEMU=1`.

use std::time::{Duration, Instant};

use ellipso_firmware::{LED_RIG_LIMITS, SequencerTiming};
use ellipso_protocol::{
    BoardState, Bracket, CaptureConfig, CommandKind, Edge, Output, PROTOCOL_VERSION, PulseCount,
    PulseEvent, RejectReason, TriggerSource,
};
use ellipso_rig::link::clock::ClockModelConfig;
use ellipso_rig::link::{LinkConfig, LinkError, LinkEvent, TriggerLink};
use ellipso_tests::qemu::{QemuBoard, Serial, firmware_or_skip};

const PULSES: u32 = 8;

const CAPTURE: CaptureConfig = CaptureConfig {
    exposure_us: 2_000,
    flash_delay_us: 300,
    flash_duration_us: 1_000,
    frame_period_us: 25_000,
    pulses: PulseCount::Count(PULSES),
    trigger: TriggerSource::FreeRun,
    report_edges: true,
    bracket: Bracket::NONE,
};

/// Pulses of the bracketed capture: two cycles of 1, 1/4, 1/16.
const BRACKET_PULSES: u32 = 6;

/// The BSRR stores of one pulse: PA0 (trigger) set, PA1 (flash) set, PA1 reset, PA0 reset.
const PULSE_BSRR: [u32; 4] = [1 << 0, 1 << 1, 1 << 17, 1 << 16];

fn link_config() -> LinkConfig {
    LinkConfig {
        reply_timeout: Duration::from_secs(5),
        // Emulated time is not host time: accept slow round trips, the fit is checked for sanity.
        clock: ClockModelConfig {
            max_round_trip_us: 200_000,
            ..ClockModelConfig::default()
        },
        ..LinkConfig::default()
    }
}

#[test]
fn capture_over_a_unix_socket() {
    run_scenario("capture_over_a_unix_socket", Serial::UnixSocket);
}

#[test]
fn capture_over_a_pty() {
    run_scenario("capture_over_a_pty", Serial::Pty);
}

fn run_scenario(name: &str, serial: Serial) {
    let Some(elf) = firmware_or_skip(name) else {
        return;
    };
    let mut board = QemuBoard::spawn(&elf, serial).expect("QEMU starts");
    if serial == Serial::Pty {
        assert!(board.pty_path().is_some_and(|p| p.starts_with("/dev/pts/")));
    }
    let link = board.open_link(link_config()).expect("handshake");
    let ctx = board.stderr_tail();

    // Handshake: the board describes itself.
    let info = link.board();
    assert_eq!(info.protocol_version, PROTOCOL_VERSION);
    assert_eq!(info.board_name.as_str(), "qemu-netduinoplus2");
    assert_eq!(info.timer_clock_hz, 1_000_000);
    assert_eq!(info.limits, LED_RIG_LIMITS);

    reject_flash_outside_exposure(&link);
    let (pulses, edges) = free_run_capture(&link, &ctx);
    check_pulses_and_edges(&pulses, &edges);

    let status = link.status().expect("status");
    assert_eq!(status.state, BoardState::Configured);
    assert_eq!(status.pulses_fired, u64::from(PULSES));
    assert_eq!(status.faults.rejected_commands, 2); // the bad Configure, the early Arm
    assert_eq!(status.faults.late_edges, 0);
    assert_eq!(status.faults.bad_frames, 0);
    assert_eq!(status.faults.tx_overflows, 0);

    check_gpio_writes(&board);
    check_clock_sync(&link);
    bracketed_capture(&link, name, &ctx);

    link.stop().expect("stop is always accepted");
    assert_eq!(link.counters().bad_frames(), 0, "{:?}", link.counters());
}

fn reject_flash_outside_exposure(link: &TriggerLink) {
    let bad = CaptureConfig {
        exposure_us: 1_000,
        flash_delay_us: 500,
        flash_duration_us: 600,
        ..CAPTURE
    };
    match link.configure(bad) {
        Err(e @ LinkError::Rejected { .. }) => {
            let LinkError::Rejected { command, reason } = &e else {
                unreachable!()
            };
            assert_eq!(*command, CommandKind::Configure);
            assert_eq!(*reason, RejectReason::FlashOutsideExposure);
            assert!(e.to_string().contains("outside the exposure"), "{e}");
        }
        other => panic!("flash outside the exposure was not refused: {other:?}"),
    }
    // Refused means nothing was configured.
    assert_eq!(link.status().expect("status").state, BoardState::Idle);
    assert!(matches!(
        link.arm(),
        Err(LinkError::Rejected {
            reason: RejectReason::NotConfigured,
            ..
        })
    ));
}

fn free_run_capture(link: &TriggerLink, ctx: &str) -> (Vec<PulseEvent>, Vec<Edge>) {
    link.configure(CAPTURE).expect("valid capture accepted");
    link.arm().expect("arm");
    link.start().expect("start");
    let (mut pulses, mut edges) = (Vec::new(), Vec::new());
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match link.events().recv_timeout(left) {
            Ok(LinkEvent::Pulse { event, .. }) => pulses.push(event),
            Ok(LinkEvent::Edge(edge)) => edges.push(edge),
            Ok(LinkEvent::Status(s)) if s.state == BoardState::Configured => break,
            Ok(LinkEvent::Status(_)) => {}
            Ok(LinkEvent::Fault { fault, .. }) => panic!("board fault during capture: {fault:?}"),
            Ok(LinkEvent::Disconnected { reason }) => panic!("link lost: {reason}; {ctx}"),
            Err(e) => panic!(
                "capture incomplete after 20 s ({e}): {} pulses, {} edges; {ctx}",
                pulses.len(),
                edges.len()
            ),
        }
    }
    (pulses, edges)
}

fn check_pulses_and_edges(pulses: &[PulseEvent], edges: &[Edge]) {
    let tol = u64::from(SequencerTiming::DEFAULT.late_tolerance_us);
    let (e, d, w) = (
        u64::from(CAPTURE.exposure_us),
        u64::from(CAPTURE.flash_delay_us),
        u64::from(CAPTURE.flash_duration_us),
    );
    let within = |what: &str, got: u64, want: u64| {
        assert!(
            (want..=want + tol).contains(&got),
            "{what}: {got} µs, configured {want} µs (+{tol} µs tolerance)"
        );
    };
    assert_eq!(pulses.len(), PULSES as usize, "every pulse reported");
    assert_eq!(edges.len(), 4 * PULSES as usize, "four edges per pulse");
    let seq0 = pulses[0].seq;
    for (k, (p, quad)) in pulses.iter().zip(edges.chunks(4)).enumerate() {
        assert_eq!(p.seq, seq0 + k as u64, "consecutive sequence numbers");
        assert_eq!(p.flags, 0, "pulse {} flagged {:#04x}", p.seq, p.flags);
        let order: Vec<(Output, bool, u64)> =
            quad.iter().map(|x| (x.output, x.high, x.seq)).collect();
        assert_eq!(
            order,
            [
                (Output::CameraTrigger, true, p.seq),
                (Output::Flash, true, p.seq),
                (Output::Flash, false, p.seq),
                (Output::CameraTrigger, false, p.seq),
            ]
        );
        // The pulse event carries the executed edge times.
        assert_eq!(quad[0].t_device_us, p.t_trigger_us);
        assert_eq!(quad[1].t_device_us, p.t_flash_on_us);
        assert_eq!(quad[2].t_device_us, p.t_flash_off_us);
        let t0 = p.t_trigger_us;
        within("flash delay", p.t_flash_on_us - t0, d);
        within("flash duration", p.t_flash_off_us - p.t_flash_on_us, w);
        within("exposure", quad[3].t_device_us - t0, e);
        if k > 0 {
            within(
                "frame period",
                t0 - pulses[k - 1].t_trigger_us,
                u64::from(CAPTURE.frame_period_us),
            );
        }
    }
}

/// A bracket with a step too short to realise is refused naming the step; a 1, 1/4, 1/16 bracket
/// of a 5 ms flash then fires in turn, each pulse lit for its step's planned on-time
/// (`round(5000 · q / 32768)`: 5000, 1250, 313 µs) within one tick, as its edges and its report say.
fn bracketed_capture(link: &TriggerLink, name: &str, ctx: &str) {
    let bracket = Bracket::from_relative(&[1.0, 0.25, 0.0625]).unwrap();
    let config = CaptureConfig {
        exposure_us: 6_000,
        flash_delay_us: 100,
        flash_duration_us: 5_000,
        frame_period_us: 50_000,
        pulses: PulseCount::Count(BRACKET_PULSES),
        bracket,
        ..CAPTURE
    };
    let too_short = CaptureConfig {
        flash_duration_us: 7, // 7 µs / 16 rounds to 0
        ..config
    };
    assert!(matches!(
        link.configure(too_short),
        Err(LinkError::Rejected {
            reason: RejectReason::BracketStepTooShort { step: 2 },
            ..
        })
    ));
    link.configure(config).expect("bracket accepted");
    link.arm().expect("arm");
    // Status replies to earlier requests may still be queued as events.
    while link.events().try_recv().is_ok() {}
    link.start().expect("start");
    let (mut pulses, mut edges) = (Vec::new(), Vec::new());
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match link.events().recv_timeout(left) {
            Ok(LinkEvent::Pulse { event, .. }) => pulses.push(event),
            Ok(LinkEvent::Edge(edge)) => edges.push(edge),
            Ok(LinkEvent::Status(s))
                if s.state == BoardState::Configured && pulses.len() == BRACKET_PULSES as usize =>
            {
                break;
            }
            Ok(LinkEvent::Status(_)) => {}
            other => panic!("during the bracketed capture: {other:?}; {ctx}"),
        }
    }
    assert_eq!(pulses.len(), BRACKET_PULSES as usize);
    let planned = [5_000i64, 1_250, 313];
    let mut worst = 0i64;
    for (k, (p, quad)) in pulses.iter().zip(edges.chunks(4)).enumerate() {
        assert_eq!(p.flags, 0, "pulse {} flagged {:#04x}", p.seq, p.flags);
        assert_eq!(usize::from(p.bracket_step), k % 3);
        let width = (quad[2].t_device_us - quad[1].t_device_us) as i64;
        assert_eq!(
            i64::from(p.flash_on_us),
            width,
            "the report is the edges' on-time"
        );
        assert_eq!(
            p.t_flash_on_us - p.t_trigger_us,
            100,
            "same delay for every step"
        );
        let error = width - planned[k % 3];
        assert!(
            error.abs() <= 1,
            "pulse {k}: {width} µs lit for a planned {} µs",
            planned[k % 3]
        );
        worst = worst.max(error.abs());
    }
    eprintln!(
        "{name}: bracketed pulse widths within {worst} µs of the plan over {} pulses",
        pulses.len()
    );
}

/// The pins really moved, in the same order: the last `4 · PULSES` BSRR stores are the pulses,
/// and every store before them only drove outputs low (boot, Arm).
fn check_gpio_writes(board: &QemuBoard) {
    let writes = board.gpioa_bsrr_writes().expect("unimp log readable");
    let n = 4 * PULSES as usize;
    assert!(
        writes.len() >= n,
        "only {} GPIOA BSRR writes logged",
        writes.len()
    );
    let (before, capture) = writes.split_at(writes.len() - n);
    for (k, quad) in capture.chunks(4).enumerate() {
        assert_eq!(quad, PULSE_BSRR, "pulse {k} pin writes {quad:#x?}");
    }
    assert!(!before.is_empty(), "boot drives the outputs low");
    assert!(
        before.iter().all(|v| v & 0xFFFF == 0),
        "a pin was set outside a pulse: {before:#x?}"
    );
}

fn check_clock_sync(link: &TriggerLink) {
    let first = link.ping().expect("ping");
    let fit = link
        .sync_clock(10)
        .expect("pings")
        .expect("a clock fit from 11 samples");
    let last = link.ping().expect("ping");
    assert!(
        last.t_device > first.t_device,
        "device clock advances between pings"
    );
    assert!(fit.n_samples >= 5);
    // Emulated time runs at whatever rate QEMU executes, but it runs forward.
    assert!(fit.gain.is_finite() && fit.gain > 0.0, "gain {}", fit.gain);
}

/// Line noise before the handshake is counted and answered with a fault, never fatal; a
/// continuous capture stops on command with both outputs low, pins included.
#[test]
fn noise_and_stop_mid_capture_over_a_unix_socket() {
    let Some(elf) = firmware_or_skip("noise_and_stop_mid_capture_over_a_unix_socket") else {
        return;
    };
    let mut board = QemuBoard::spawn(&elf, Serial::UnixSocket).expect("QEMU starts");
    // A frame with a broken CRC: COBS-valid bytes, delimiter-terminated.
    let link = board
        .open_link_after_raw_bytes(link_config(), &[0x05, 0x11, 0x22, 0x33, 0x44, 0x00])
        .expect("handshake after noise");
    let ctx = board.stderr_tail();
    let fault = link
        .events()
        .recv_timeout(Duration::from_secs(5))
        .expect("the board reports the bad frame");
    assert!(
        matches!(
            fault,
            LinkEvent::Fault {
                fault: ellipso_protocol::Fault::BadFrame(_),
                ..
            }
        ),
        "{fault:?}"
    );

    link.configure(CaptureConfig {
        pulses: PulseCount::Continuous,
        ..CAPTURE
    })
    .expect("configure");
    link.arm().expect("arm");
    link.start().expect("start");
    let mut pulses = 0;
    let deadline = Instant::now() + Duration::from_secs(20);
    while pulses < 3 {
        let left = deadline.saturating_duration_since(Instant::now());
        match link.events().recv_timeout(left) {
            Ok(LinkEvent::Pulse { .. }) => pulses += 1,
            Ok(LinkEvent::Edge(_) | LinkEvent::Status(_)) => {}
            other => panic!("while running: {other:?}; {ctx}"),
        }
    }
    link.stop().expect("stop");
    let status = link.status().expect("status");
    assert_eq!(status.state, BoardState::Configured);
    assert_eq!(status.faults.bad_frames, 1);
    assert_eq!(status.faults.late_edges, 0);
    assert!(status.pulses_fired >= 3);

    // The last stores to the pins drove both low: Stop writes the flash off, then the trigger.
    let writes = board.gpioa_bsrr_writes().expect("unimp log readable");
    let last_for = |bit: u32| {
        writes
            .iter()
            .rev()
            .find(|v| *v & (1 << bit | 1 << (bit + 16)) != 0)
    };
    assert_eq!(
        last_for(0),
        Some(&(1 << 16)),
        "trigger left high: {writes:#x?}"
    );
    assert_eq!(last_for(1), Some(&(1 << 17)), "flash left on: {writes:#x?}");
    assert_eq!(writes[writes.len() - 2..], [1 << 17, 1 << 16]);
}
