//! The bracket in the sequencer: step order, per-step on-times, their reports, and the safety
//! rules applied per step.

use super::super::tests::{LEAD, faults, plan, pulses, run_on_time, started};
use super::super::*;
use crate::outputs::RecordingOutputs;
use ellipso_protocol::{Bracket, ENERGY_ONE_Q15, Fault, PULSE_LATE, PulseCount};

const QUARTER: u16 = 0x2000;
const SIXTEENTH: u16 = 0x0800;

/// 1, 1/4, 1/16 of the 500 µs flash of the test plan: 500, 125 and 31 µs (31.25 rounds down).
fn three_steps() -> Bracket {
    Bracket::from_q15(&[ENERGY_ONE_Q15, QUARTER, SIXTEENTH]).unwrap()
}

#[test]
fn pulses_cycle_through_the_steps_with_their_on_times() {
    let mut out = RecordingOutputs::<32>::new();
    let mut seq = started(
        plan(|c| {
            c.pulses = PulseCount::Count(5);
            c.bracket = three_steps();
        }),
        0,
    );
    let (msgs, last) = run_on_time(&mut seq, &mut out, 100);
    assert_eq!(last, PollOutcome::Complete);
    let p = pulses(&msgs);
    let got: Vec<(u64, u8, u32)> = p
        .iter()
        .map(|e| (e.seq, e.bracket_step, e.flash_on_us))
        .collect();
    assert_eq!(
        got,
        [
            (0, 0, 500),
            (1, 1, 125),
            (2, 2, 31),
            (3, 0, 500),
            (4, 1, 125)
        ]
    );
    for (k, e) in p.iter().enumerate() {
        let t0 = LEAD + 50_000 * k as u64;
        assert_eq!(e.t_trigger_us, t0);
        assert_eq!(
            e.t_flash_on_us,
            t0 + 100,
            "every step starts at the same delay"
        );
        assert_eq!(e.t_flash_off_us - e.t_flash_on_us, u64::from(e.flash_on_us));
        assert_eq!(e.flags, 0);
    }
    // The pin timeline agrees with the reports.
    let widths: Vec<u64> = out
        .edges()
        .filter(|e| e.output == Output::Flash)
        .collect::<Vec<_>>()
        .chunks(2)
        .map(|pair| pair[1].t_device_us - pair[0].t_device_us)
        .collect();
    assert_eq!(widths, [500, 125, 31, 500, 125]);
    assert!(faults(&msgs).is_empty());
}

#[test]
fn each_capture_starts_at_step_zero_and_a_cancelled_pulse_takes_no_step() {
    let mut out = RecordingOutputs::<32>::new();
    let p = plan(|c| {
        c.pulses = PulseCount::Continuous;
        c.bracket = three_steps();
    });
    let mut seq = started(p, 0);
    let mut msgs = Vec::new();
    // Two pulses, then a stop before the third trigger rises.
    for _ in 0..8 {
        let t = seq.next_deadline().unwrap();
        let _ = seq.poll(t, &mut out, &mut |m| msgs.push(m));
    }
    seq.stop(LEAD + 60_000, &mut out, &mut |m| msgs.push(m));
    seq.start(p, 200_000).unwrap();
    let (more, _) = {
        let mut v = Vec::new();
        for _ in 0..4 {
            let t = seq.next_deadline().unwrap();
            let _ = seq.poll(t, &mut out, &mut |m| v.push(m));
        }
        (v, ())
    };
    msgs.extend(more);
    let steps: Vec<(u64, u8)> = pulses(&msgs)
        .iter()
        .map(|e| (e.seq, e.bracket_step))
        .collect();
    assert_eq!(steps, [(0, 0), (1, 1), (2, 0)]);
}

#[test]
fn the_skip_rule_uses_the_pulse_own_on_time() {
    // 1 ms exposure, flash due at +100: a 800 µs step polled at +300 would end at +1100 and is
    // skipped; a 200 µs step polled equally late ends at +500 and lights for its full 200 µs.
    let mut out = RecordingOutputs::<16>::new();
    let mut seq = started(
        plan(|c| {
            c.flash_duration_us = 800;
            c.pulses = PulseCount::Count(2);
            c.bracket = Bracket::from_q15(&[ENERGY_ONE_Q15, QUARTER]).unwrap();
        }),
        0,
    );
    let mut msgs = Vec::new();
    for t0 in [LEAD, LEAD + 50_000] {
        let _ = seq.poll(t0, &mut out, &mut |m| msgs.push(m));
        let _ = seq.poll(t0 + 300, &mut out, &mut |m| msgs.push(m));
        while let Some(t) = seq.next_deadline().filter(|&t| t < t0 + 50_000) {
            let _ = seq.poll(t, &mut out, &mut |m| msgs.push(m));
        }
    }
    let p = pulses(&msgs);
    assert_eq!(p[0].flags, PULSE_FLASH_SKIPPED);
    assert_eq!((p[0].bracket_step, p[0].flash_on_us), (0, 0));
    assert_eq!(p[1].flags, PULSE_LATE, "lit late, but whole");
    assert_eq!((p[1].bracket_step, p[1].flash_on_us), (1, 200));
    assert_eq!(p[1].t_flash_on_us, LEAD + 50_300);
    assert_eq!(
        faults(&msgs),
        [
            Fault::FlashSkipped { seq: 0 },
            Fault::DeadlineMissed {
                seq: 1,
                late_by_us: 200
            }
        ]
    );
}

#[test]
fn a_stop_mid_flash_reports_the_truncated_on_time() {
    let mut out = RecordingOutputs::<16>::new();
    let mut seq = started(
        plan(|c| {
            c.pulses = PulseCount::Count(3);
            c.bracket = three_steps();
        }),
        0,
    );
    let mut msgs = Vec::new();
    let _ = seq.poll(LEAD, &mut out, &mut |m| msgs.push(m));
    let _ = seq.poll(LEAD + 100, &mut out, &mut |m| msgs.push(m));
    seq.stop(LEAD + 140, &mut out, &mut |m| msgs.push(m));
    let p = pulses(&msgs)[0];
    assert_eq!((p.bracket_step, p.flash_on_us), (0, 40));
    assert_eq!(p.flags, PULSE_STOPPED);
}
