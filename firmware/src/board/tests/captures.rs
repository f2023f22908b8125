//! Captures through the board's command path: Arm on real pins, a counted free run that completes
//! by itself, a continuous one until Stop, FireOne and grip-button triggers with their refusals,
//! and the Status of a capture whose loop stalled.

use super::super::tests::{LEAD, Rig, ack, config, pulses, rejected};
use super::super::*;
use crate::outputs::{OutputEdge, PinOutputs};
use ellipso_protocol::{Output, PulseCount};
use embedded_hal_mock::eh1::digital::{Mock as PinMock, State, Transaction as T};

#[test]
fn arm_drives_both_outputs_low_on_real_pins() {
    let mut board = Board::new(BoardConfig::new("pins", 1_000_000)).unwrap();
    let mut out = PinOutputs::new(
        PinMock::new(&[T::set(State::Low), T::set(State::High), T::set(State::Low)]),
        PinMock::new(&[T::set(State::Low), T::set(State::High), T::set(State::Low)]),
    );
    let mut sink = |_| {};
    let c = config(TriggerSource::FreeRun, PulseCount::Count(1));
    board.handle(HostMessage::Configure(c), 0, &mut out, &mut sink);
    board.handle(HostMessage::Arm, 0, &mut out, &mut sink);
    board.handle(HostMessage::Start, 0, &mut out, &mut sink);
    while let Some(t) = board.next_deadline() {
        board.poll(t, &mut out, &mut sink);
    }
    let (mut cam, mut flash) = out.release();
    cam.done();
    flash.done();
}

#[test]
fn a_counted_free_run_completes_by_itself_and_sends_a_status() {
    let mut rig = Rig::armed(config(TriggerSource::FreeRun, PulseCount::Count(3)));
    rig.send(HostMessage::Start, 0);
    let got = rig.run_until(u64::MAX);
    assert_eq!(
        pulses(&got).iter().map(|p| p.seq).collect::<Vec<_>>(),
        [0, 1, 2]
    );
    let end = LEAD + 2 * 50_000 + 1_000;
    assert_eq!(
        got.last(),
        Some(&BoardMessage::Status(Status {
            state: BoardState::Configured,
            pulses_fired: 3,
            t_device_us: end,
            faults: FaultCounters::default(),
        }))
    );
    assert_eq!(rig.board.next_deadline(), None);
    assert_eq!(
        rig.send(HostMessage::Start, end),
        [rejected(CommandKind::Start, RejectReason::NotArmed)]
    );
}

#[test]
fn a_continuous_capture_runs_until_stop_and_stop_turns_the_flash_off_first() {
    let mut rig = Rig::armed(config(TriggerSource::FreeRun, PulseCount::Continuous));
    rig.send(HostMessage::Start, 0);
    let got = rig.run_until(10 * 50_000 + LEAD + 100);
    assert_eq!(pulses(&got).len(), 10);
    assert!(rig.out.flash_high(), "pulse 10's flash is lit");
    let got = rig.send(HostMessage::Stop, 10 * 50_000 + LEAD + 200);
    assert!(!rig.out.flash_high() && !rig.out.camera_high());
    // The truncated pulse is reported before the Ack.
    assert_eq!(pulses(&got).len(), 1);
    assert_eq!(got.last(), Some(&ack(CommandKind::Stop)));
    let n = rig.out.edges().count();
    assert!(rig.run_until(u64::MAX).is_empty());
    assert_eq!(rig.out.edges().count(), n, "no edge after Stop");
    let last: Vec<_> = rig.out.edges().skip(n - 2).copied().collect();
    let t = 10 * 50_000 + LEAD + 200;
    assert_eq!(
        last,
        [
            OutputEdge {
                output: Output::Flash,
                high: false,
                t_device_us: t
            },
            OutputEdge {
                output: Output::CameraTrigger,
                high: false,
                t_device_us: t
            },
        ]
    );
}

#[test]
fn fire_one_starts_from_armed_and_refuses_too_soon_with_the_wait() {
    let mut rig = Rig::armed(config(TriggerSource::HostCommand, PulseCount::Count(2)));
    assert_eq!(
        rig.send(HostMessage::FireOne, 1_000),
        [ack(CommandKind::FireOne)]
    );
    assert_eq!(rig.board.state(), BoardState::Running);
    assert_eq!(rig.board.next_deadline(), Some(1_000 + LEAD));
    assert_eq!(
        rig.send(HostMessage::FireOne, 31_000),
        [rejected(
            CommandKind::FireOne,
            RejectReason::TooSoon { wait_us: 20_000 }
        )]
    );
    let first = rig.run_until(40_000);
    assert_eq!(pulses(&first)[0].t_trigger_us, 1_000 + LEAD);
    assert_eq!(
        rig.send(HostMessage::FireOne, 51_000),
        [ack(CommandKind::FireOne)]
    );
    let got = rig.run_until(u64::MAX);
    assert_eq!(pulses(&got)[0].seq, 1);
    assert!(
        matches!(got.last(), Some(BoardMessage::Status(s)) if s.state == BoardState::Configured)
    );
}

#[test]
fn a_refused_fire_one_from_armed_stays_armed() {
    // The sensor is still reading out the previous capture's last frame.
    let mut rig = Rig::armed(config(TriggerSource::HostCommand, PulseCount::Count(1)));
    rig.send(HostMessage::FireOne, 0);
    rig.run_until(u64::MAX); // trigger falls at LEAD + 1000; readout until LEAD + 21 000
    rig.send(HostMessage::Arm, LEAD + 1_000);
    assert_eq!(
        rig.send(HostMessage::FireOne, LEAD + 1_000),
        [rejected(
            CommandKind::FireOne,
            RejectReason::TooSoon { wait_us: 19_000 }
        )]
    );
    assert_eq!(rig.board.state(), BoardState::Armed);
    assert_eq!(rig.board.next_deadline(), None);
}

#[test]
fn the_grip_button_fires_debounced_by_the_frame_period() {
    let mut rig = Rig::armed(config(TriggerSource::GripButton, PulseCount::Continuous));
    assert_eq!(
        rig.board.button_pressed(0),
        ButtonOutcome::Ignored,
        "not started"
    );
    rig.send(HostMessage::Start, 0);
    assert_eq!(rig.board.next_deadline(), None, "waits for the button");
    assert_eq!(
        rig.board.button_pressed(5_000),
        ButtonOutcome::Fired {
            t_trigger_us: 5_000 + LEAD
        }
    );
    // Contact bounce and a hasty second press within the 50 ms period are ignored.
    for t in [5_001, 5_300, 20_000, 54_999] {
        assert_eq!(rig.board.button_pressed(t), ButtonOutcome::Debounced);
    }
    let got = rig.run_until(u64::MAX);
    assert_eq!(pulses(&got).len(), 1);
    assert_eq!(
        rig.board.button_pressed(55_000),
        ButtonOutcome::Fired {
            t_trigger_us: 55_000 + LEAD
        }
    );
    assert_eq!(
        rig.send(HostMessage::FireOne, 60_000),
        [rejected(
            CommandKind::FireOne,
            RejectReason::WrongTriggerSource
        )]
    );
    rig.send(HostMessage::Stop, 60_000);
    assert_eq!(
        rig.board.button_pressed(200_000),
        ButtonOutcome::Ignored,
        "stopped"
    );
}

#[test]
fn status_request_reports_state_pulses_and_faults() {
    let mut rig = Rig::armed(config(TriggerSource::FreeRun, PulseCount::Count(1)));
    rig.send(HostMessage::Start, 0);
    // Stall the loop so the flash is forced off.
    rig.board.poll(LEAD, &mut rig.out, &mut |_| {});
    rig.board.poll(LEAD + 100, &mut rig.out, &mut |_| {});
    rig.board
        .poll(LEAD + 100 + 6_000, &mut rig.out, &mut |_| {});
    rig.board.on_bad_frame(FrameError::BadCrc, &mut |_| {});
    let got = rig.send(HostMessage::StatusRequest, 9_999);
    let BoardMessage::Status(s) = got[0] else {
        panic!("{got:?}")
    };
    assert_eq!(
        (s.state, s.pulses_fired, s.t_device_us),
        (BoardState::Configured, 1, 9_999)
    );
    assert_eq!(
        s.faults,
        FaultCounters {
            bad_frames: 1,
            late_edges: 2,
            flash_forced_off: 1,
            flash_skipped: 0,
            tx_overflows: 0,
            rejected_commands: 0,
        }
    );
}
