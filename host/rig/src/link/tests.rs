//! The link against a scripted board on a real pseudo-terminal pair.

use std::io::{Read, Write};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use ellipso_protocol::*;
use serialport::{SerialPort, TTYPort};

use super::*;

/// How the scripted board misbehaves.
#[derive(Clone, Copy, Default)]
struct Script {
    protocol_version: u16,
    /// Garbage and a corrupted frame before every reply.
    noisy: bool,
    /// Close the port when `Stop` arrives.
    hang_up_on_stop: bool,
    /// Swallow the first reply to this command (as if a bit error had destroyed it), but act on it.
    lose_first_reply_to: Option<CommandKind>,
}

fn board_info(version: u16) -> BoardInfo {
    BoardInfo {
        protocol_version: version,
        firmware_version: FirmwareVersion {
            major: 0,
            minor: 1,
            patch: 0,
        },
        board_name: heapless::String::try_from("scripted").unwrap(),
        timer_clock_hz: 1_000_000,
        limits: BoardLimits {
            min_exposure_us: 20,
            max_exposure_us: 1_000_000,
            max_flash_on_us: 5_000,
            max_flash_duty_permille: 100,
            readout_us: 20_000,
            min_frame_period_us: 10_000,
            max_frame_period_us: 10_000_000,
            max_pulse_count: 100_000,
        },
    }
}

fn send(port: &mut TTYPort, msg: &BoardMessage, noisy: bool) {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = encode(msg, &mut buf).unwrap();
    if noisy {
        port.write_all(&[0x11, 0x22, 0x00]).unwrap(); // broken COBS
        let mut bad = buf[..n].to_vec();
        bad[1] ^= 0x40; // a corrupted copy of the real frame
        if bad[1] == 0 {
            bad[1] = 0x33;
        }
        port.write_all(&bad).unwrap();
    }
    port.write_all(&buf[..n]).unwrap();
}

/// Runs a scripted board on the device end of a pty; returns the host end and the board thread.
fn scripted(script: Script) -> (TTYPort, std::thread::JoinHandle<()>) {
    let (host, mut dev) = TTYPort::pair().expect("openpty");
    dev.set_timeout(Duration::from_millis(20)).unwrap();
    let start = Instant::now();
    let h = std::thread::spawn(move || {
        let mut dec = Decoder::<HostMessage>::new();
        let mut buf = [0u8; 256];
        let mut seq = 0u64;
        let mut lost_one = false;
        let mut running = false;
        let deadline = Instant::now() + Duration::from_secs(20);
        while Instant::now() < deadline {
            let n = match dev.read(&mut buf) {
                Ok(n) => n,
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => continue,
                Err(_) => return,
            };
            let msgs: Vec<_> = dec.feed(&buf[..n]).filter_map(Result::ok).collect();
            for m in msgs {
                let t = start.elapsed().as_micros() as u64 + 1_000_000;
                let reply = match m {
                    HostMessage::Hello { .. } => {
                        BoardMessage::HelloReply(board_info(script.protocol_version))
                    }
                    HostMessage::Configure(c) if c.exposure_us == 0 => BoardMessage::Rejected {
                        command: CommandKind::Configure,
                        reason: RejectReason::ExposureOutOfRange,
                    },
                    HostMessage::Ping { nonce } => BoardMessage::Pong {
                        nonce,
                        t_device_us: t,
                    },
                    HostMessage::StatusRequest => BoardMessage::Status(Status {
                        state: BoardState::Armed,
                        pulses_fired: seq,
                        t_device_us: t,
                        faults: FaultCounters::default(),
                    }),
                    HostMessage::Stop if script.hang_up_on_stop => return, // drops the port
                    HostMessage::Start if running => BoardMessage::Rejected {
                        command: CommandKind::Start,
                        reason: RejectReason::Busy,
                    },
                    other => BoardMessage::Ack(other.kind()),
                };
                if m == HostMessage::Start {
                    running = true;
                }
                if m == HostMessage::Stop {
                    running = false;
                }
                if !lost_one && script.lose_first_reply_to == Some(m.kind()) {
                    lost_one = true;
                    continue;
                }
                send(&mut dev, &reply, script.noisy);
                if m == HostMessage::Start && seq == 0 {
                    for _ in 0..3 {
                        let pulse = PulseEvent {
                            seq,
                            t_trigger_us: t + seq * 1000,
                            t_flash_on_us: t + seq * 1000 + 10,
                            t_flash_off_us: t + seq * 1000 + 20,
                            flags: 0,
                            bracket_step: 0,
                            flash_on_us: 10,
                        };
                        send(&mut dev, &BoardMessage::Pulse(pulse), script.noisy);
                        seq += 1;
                    }
                }
            }
        }
    });
    (host, h)
}

fn connect(host: TTYPort) -> Result<TriggerLink, LinkError> {
    let mut host = host;
    host.set_timeout(Duration::from_millis(20)).unwrap();
    let reader = host.try_clone_native().unwrap();
    TriggerLink::connect(
        Box::new(reader),
        Box::new(host),
        HostClock::new(),
        LinkConfig::default(),
    )
}

fn config(exposure_us: u32) -> CaptureConfig {
    CaptureConfig {
        exposure_us,
        flash_delay_us: 100,
        flash_duration_us: 1_000,
        frame_period_us: 100_000,
        pulses: PulseCount::Count(3),
        trigger: TriggerSource::FreeRun,
        report_edges: false,
        bracket: ellipso_protocol::Bracket::NONE,
    }
}

fn pulses(link: &TriggerLink, n: usize) -> Vec<u64> {
    let (tx, rx) = mpsc::channel();
    let events = link.events().clone();
    std::thread::spawn(move || {
        let mut seqs = Vec::new();
        while seqs.len() < n {
            match events.recv_timeout(Duration::from_secs(5)) {
                Ok(LinkEvent::Pulse { event, .. }) => seqs.push(event.seq),
                Ok(_) => {}
                Err(_) => break,
            }
        }
        let _ = tx.send(seqs);
    });
    rx.recv().unwrap()
}

#[test]
fn handshake_commands_pulses_and_clock_over_a_pty() {
    let (host, board) = scripted(Script {
        protocol_version: PROTOCOL_VERSION,
        ..Script::default()
    });
    let link = connect(host).expect("handshake");
    assert_eq!(link.board().board_name.as_str(), "scripted");
    link.configure(config(8_000)).unwrap();
    link.arm().unwrap();
    link.start().unwrap();
    assert_eq!(pulses(&link, 3), vec![0, 1, 2]);
    let fit = link
        .sync_clock(10)
        .unwrap()
        .expect("10 accepted samples settle the model");
    // ten pings span only milliseconds, so gain is loose; the mapping must still land each
    // device time inside (or within a millisecond of) the bracket it was observed in
    let s = link.ping().unwrap();
    let mapped = fit.host_us(s.t_device);
    assert!(
        mapped > s.t_send.0 as f64 - 1_000.0 && mapped < s.t_recv.0 as f64 + 1_000.0,
        "{mapped} outside [{}, {}]",
        s.t_send.0,
        s.t_recv.0
    );
    assert_eq!(link.status().unwrap().pulses_fired, 3);
    link.stop().unwrap();
    assert_eq!(link.counters().bad_frames(), 0);
    drop(link);
    let _ = board;
}

#[test]
fn refusals_carry_the_boards_reason() {
    let (host, _board) = scripted(Script {
        protocol_version: PROTOCOL_VERSION,
        ..Script::default()
    });
    let link = connect(host).unwrap();
    let err = link.configure(config(0)).unwrap_err();
    assert!(matches!(
        err,
        LinkError::Rejected {
            command: CommandKind::Configure,
            reason: RejectReason::ExposureOutOfRange
        }
    ));
    assert!(err.to_string().contains("exposure outside"), "{err}");
}

#[test]
fn version_mismatch_names_both_versions() {
    let (host, _board) = scripted(Script {
        protocol_version: PROTOCOL_VERSION + 1,
        ..Script::default()
    });
    let err = connect(host).unwrap_err();
    let text = err.to_string();
    assert!(matches!(err, LinkError::VersionMismatch { .. }), "{text}");
    assert!(
        text.contains(&format!("v{}", PROTOCOL_VERSION + 1))
            && text.contains(&format!("v{PROTOCOL_VERSION}"))
    );
}

#[test]
fn bad_frames_are_counted_and_skipped() {
    let (host, _board) = scripted(Script {
        protocol_version: PROTOCOL_VERSION,
        noisy: true,
        ..Script::default()
    });
    let link = connect(host).expect("handshake through noise");
    link.configure(config(8_000)).unwrap();
    link.arm().unwrap();
    link.start().unwrap();
    assert_eq!(pulses(&link, 3), vec![0, 1, 2]);
    let c = link.counters();
    // every reply and pulse was preceded by one broken-COBS run and one corrupted copy
    assert!(c.bad_cobs >= 6, "{c:?}");
    assert!(c.bad_frames() >= 12, "{c:?}");
}

#[test]
fn a_hang_up_is_reported_and_later_commands_fail_cleanly() {
    let (host, board) = scripted(Script {
        protocol_version: PROTOCOL_VERSION,
        hang_up_on_stop: true,
        ..Script::default()
    });
    let link = connect(host).unwrap();
    link.configure(config(8_000)).unwrap();
    link.arm().unwrap();
    link.start().unwrap();
    assert_eq!(
        pulses(&link, 3),
        vec![0, 1, 2],
        "pulses before the hang-up are kept"
    );
    assert!(matches!(
        link.stop(),
        Err(LinkError::Timeout { .. } | LinkError::Disconnected(_))
    ));
    board.join().unwrap();
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut saw = false;
    while Instant::now() < deadline && !saw {
        if let Ok(LinkEvent::Disconnected { .. }) =
            link.events().recv_timeout(Duration::from_millis(100))
        {
            saw = true;
        }
    }
    assert!(saw, "a Disconnected event arrives");
    assert!(!link.is_connected());
    assert!(matches!(link.arm(), Err(LinkError::Disconnected(_))));
}

#[test]
fn a_lost_reply_is_retried_for_idempotent_commands() {
    for lost in [
        CommandKind::Hello,
        CommandKind::Configure,
        CommandKind::Arm,
        CommandKind::Start,
    ] {
        let (host, _board) = scripted(Script {
            protocol_version: PROTOCOL_VERSION,
            lose_first_reply_to: Some(lost),
            ..Script::default()
        });
        let link = connect(host).unwrap_or_else(|e| panic!("{lost:?}: {e}"));
        link.configure(config(8_000))
            .unwrap_or_else(|e| panic!("{lost:?}: {e}"));
        link.arm().unwrap_or_else(|e| panic!("{lost:?}: {e}"));
        // a repeated Start meets Busy: the first one took
        link.start().unwrap_or_else(|e| panic!("{lost:?}: {e}"));
        assert_eq!(pulses(&link, 3), vec![0, 1, 2], "{lost:?}");
    }
}

#[test]
fn fire_one_is_never_repeated() {
    let (host, _board) = scripted(Script {
        protocol_version: PROTOCOL_VERSION,
        lose_first_reply_to: Some(CommandKind::FireOne),
        ..Script::default()
    });
    let link = connect(host).unwrap();
    assert!(matches!(
        link.fire_one(),
        Err(LinkError::Timeout {
            command: CommandKind::FireOne,
            ..
        })
    ));
}
