//! The bracket through the board's command path: its plan check's rejections, and host-command
//! and grip-button captures stepping through it.

use super::super::tests::{Rig, ack, config, pulses, rejected};
use super::super::*;
use ellipso_protocol::{Bracket, ENERGY_ONE_Q15, PulseCount};

fn bracketed(trigger: TriggerSource, n: u32, steps: &[u16]) -> ellipso_protocol::CaptureConfig {
    ellipso_protocol::CaptureConfig {
        bracket: Bracket::from_q15(steps).unwrap(),
        ..config(trigger, PulseCount::Count(n))
    }
}

#[test]
fn a_bad_bracket_is_refused_naming_its_step_and_changes_nothing() {
    let mut rig = Rig::armed(bracketed(TriggerSource::FreeRun, 3, &[ENERGY_ONE_Q15]));
    // 500 µs · 1/1024 = 0.49 µs: rounds to 0 ticks.
    let tiny = bracketed(TriggerSource::FreeRun, 3, &[ENERGY_ONE_Q15, 0x2000, 32]);
    assert_eq!(
        rig.send(HostMessage::Configure(tiny), 0),
        [rejected(
            CommandKind::Configure,
            RejectReason::BracketStepTooShort { step: 2 }
        )]
    );
    let above_one = bracketed(TriggerSource::FreeRun, 3, &[ENERGY_ONE_Q15 + 1]);
    assert_eq!(
        rig.send(HostMessage::Configure(above_one), 0),
        [rejected(
            CommandKind::Configure,
            RejectReason::BracketStepOutOfRange { step: 0 }
        )]
    );
    assert_eq!(rig.board.state(), BoardState::Armed, "still armed");
    assert_eq!(rig.board.faults().rejected_commands, 2);
}

#[test]
fn host_command_and_button_pulses_step_through_the_bracket() {
    let steps = [ENERGY_ONE_Q15, 0x2000, 0x0800];
    for trigger in [TriggerSource::HostCommand, TriggerSource::GripButton] {
        let mut rig = Rig::armed(bracketed(trigger, 4, &steps));
        if trigger == TriggerSource::GripButton {
            assert_eq!(rig.send(HostMessage::Start, 0), [ack(CommandKind::Start)]);
        }
        let mut got = Vec::new();
        for k in 0..4u64 {
            let now = 1_000 + 60_000 * k;
            match trigger {
                TriggerSource::HostCommand => {
                    assert_eq!(
                        rig.send(HostMessage::FireOne, now),
                        [ack(CommandKind::FireOne)]
                    );
                }
                _ => assert!(matches!(
                    rig.board.button_pressed(now),
                    ButtonOutcome::Fired { .. }
                )),
            }
            got.extend(rig.run_until(now + 50_000));
        }
        let seen: Vec<(u8, u32)> = pulses(&got)
            .iter()
            .map(|p| (p.bracket_step, p.flash_on_us))
            .collect();
        assert_eq!(seen, [(0, 500), (1, 125), (2, 31), (0, 500)], "{trigger:?}");
    }
}
