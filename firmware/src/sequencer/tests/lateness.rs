//! The flash safety rules under injected lateness: a stuck loop forces the flash off, late edges
//! within the cap or the tolerance, a flash skipped or kept whole, a late trigger shifting the
//! pulse grid, and a late camera-off waiting for the sensor's readout.

use super::super::tests::{LEAD, edge, faults, plan, pulses, run_on_time, started};
use super::super::*;
use crate::outputs::RecordingOutputs;
use ellipso_protocol::{Fault, PULSE_FLASH_FORCED_OFF, PULSE_LATE, PulseCount};

use Output::{CameraTrigger as Cam, Flash as Fl};

#[test]
fn a_stuck_loop_past_the_off_deadline_forces_the_flash_off_at_the_first_poll() {
    let p = plan(|c| c.pulses = PulseCount::Count(1));
    let mut out = RecordingOutputs::<8>::new();
    let mut seq = started(p, 0);
    let mut msgs = Vec::new();
    let _ = seq.poll(LEAD, &mut out, &mut |m| msgs.push(m));
    let _ = seq.poll(LEAD + 100, &mut out, &mut |m| msgs.push(m));
    assert!(out.flash_high());
    // The loop stalls 40 ms: far past the 500 µs off-deadline and the 5 ms cap, and past the
    // camera-off deadline too.
    let late = LEAD + 100 + 40_000;
    assert_eq!(
        seq.poll(late, &mut out, &mut |m| msgs.push(m)),
        PollOutcome::Complete
    );
    let got: Vec<_> = out.edges().skip(2).copied().collect();
    assert_eq!(
        got,
        [edge(Fl, false, late), edge(Cam, false, late)],
        "flash off first"
    );
    let p = pulses(&msgs)[0];
    assert_eq!(p.flags, PULSE_FLASH_FORCED_OFF | PULSE_LATE);
    assert_eq!(p.t_flash_off_us, late);
    assert_eq!(
        faults(&msgs),
        [
            Fault::DeadlineMissed {
                seq: 0,
                late_by_us: 40_000 - 500
            },
            Fault::FlashForcedOff {
                seq: 0,
                on_for_us: 40_000
            },
            Fault::DeadlineMissed {
                seq: 0,
                late_by_us: 40_000 - 900
            },
        ]
    );
    let c = seq.counters();
    assert_eq!(
        (c.flash_forced_off, c.late_edges, c.flash_skipped),
        (1, 2, 0)
    );
}

#[test]
fn a_late_off_within_the_cap_is_late_but_not_forced() {
    let p = plan(|c| {
        c.exposure_us = 5_000;
        c.pulses = PulseCount::Count(1);
    });
    let mut out = RecordingOutputs::<8>::new();
    let mut seq = started(p, 0);
    let mut msgs = Vec::new();
    let _ = seq.poll(LEAD, &mut out, &mut |m| msgs.push(m));
    let _ = seq.poll(LEAD + 100, &mut out, &mut |m| msgs.push(m));
    // Off due at +600; polled at +2100: 1.5 ms late, on for 2 ms < 5 ms cap.
    let _ = seq.poll(LEAD + 2_100, &mut out, &mut |m| msgs.push(m));
    let _ = seq.poll(LEAD + 5_000, &mut out, &mut |m| msgs.push(m));
    assert_eq!(pulses(&msgs)[0].flags, PULSE_LATE);
    assert_eq!(
        faults(&msgs),
        [Fault::DeadlineMissed {
            seq: 0,
            late_by_us: 1_500
        }]
    );
}

#[test]
fn lateness_within_the_tolerance_is_not_reported() {
    let tol = SequencerTiming::DEFAULT.late_tolerance_us as u64;
    let mut out = RecordingOutputs::<8>::new();
    let mut seq = started(plan(|c| c.pulses = PulseCount::Count(1)), 0);
    let mut msgs = Vec::new();
    while let Some(t) = seq.next_deadline() {
        let _ = seq.poll(t + tol, &mut out, &mut |m| msgs.push(m));
    }
    assert_eq!(pulses(&msgs)[0].flags, 0);
    assert!(faults(&msgs).is_empty());
}

#[test]
fn a_flash_on_too_late_to_fit_the_exposure_is_skipped() {
    let mut out = RecordingOutputs::<8>::new();
    let mut seq = started(plan(|c| c.pulses = PulseCount::Count(1)), 0);
    let mut msgs = Vec::new();
    let _ = seq.poll(LEAD, &mut out, &mut |m| msgs.push(m));
    // On due at +100; +501 would end at +1001, after the exposure ends at +1000.
    let _ = seq.poll(LEAD + 501, &mut out, &mut |m| msgs.push(m));
    assert!(!out.flash_high());
    assert_eq!(
        seq.next_deadline(),
        Some(LEAD + 1_000),
        "the exposure still ends on time"
    );
    let _ = seq.poll(LEAD + 1_000, &mut out, &mut |m| msgs.push(m));
    assert!(out.edges().all(|e| e.output == Cam), "the flash never lit");
    let p = pulses(&msgs)[0];
    assert_eq!(p.flags, PULSE_FLASH_SKIPPED);
    assert_eq!(
        (p.t_flash_on_us, p.t_flash_off_us),
        (LEAD + 501, LEAD + 501)
    );
    assert_eq!(faults(&msgs), [Fault::FlashSkipped { seq: 0 }]);
    assert_eq!(seq.counters().flash_skipped, 1);
}

#[test]
fn a_late_flash_that_still_fits_keeps_its_full_duration() {
    let mut out = RecordingOutputs::<8>::new();
    let mut seq = started(plan(|c| c.pulses = PulseCount::Count(1)), 0);
    let mut msgs = Vec::new();
    let _ = seq.poll(LEAD, &mut out, &mut |m| msgs.push(m));
    let _ = seq.poll(LEAD + 500, &mut out, &mut |m| msgs.push(m)); // ends exactly at +1000
    assert_eq!(seq.next_deadline(), Some(LEAD + 1_000));
    let _ = run_on_time(&mut seq, &mut out, 10);
    let got: Vec<_> = out.edges().copied().collect();
    assert_eq!(
        got[1..3],
        [edge(Fl, true, LEAD + 500), edge(Fl, false, LEAD + 1_000)]
    );
    assert_eq!(
        faults(&msgs),
        [Fault::DeadlineMissed {
            seq: 0,
            late_by_us: 400
        }]
    );
}

#[test]
fn a_late_trigger_shifts_the_whole_pulse_and_missed_slots_are_not_burst() {
    let mut out = RecordingOutputs::<32>::new();
    let mut seq = started(plan(|c| c.pulses = PulseCount::Continuous), 0);
    let mut msgs = Vec::new();
    // The first trigger runs 10 periods late: one pulse fires now, not ten.
    let t = LEAD + 500_000;
    let _ = seq.poll(t, &mut out, &mut |m| msgs.push(m));
    assert_eq!(seq.pulses_fired(), 1);
    assert_eq!(seq.next_deadline(), Some(t + 100));
    for _ in 0..7 {
        let d = seq.next_deadline().unwrap();
        let _ = seq.poll(d, &mut out, &mut |m| msgs.push(m));
    }
    let got: Vec<_> = out.edges().copied().collect();
    assert_eq!(
        got[..4],
        [
            edge(Cam, true, t),
            edge(Fl, true, t + 100),
            edge(Fl, false, t + 600),
            edge(Cam, false, t + 1_000)
        ]
    );
    assert_eq!(
        got[4],
        edge(Cam, true, t + 50_000),
        "next on the shifted grid"
    );
    assert_eq!(pulses(&msgs)[0].flags, PULSE_LATE);
}

#[test]
fn a_late_camera_off_delays_the_next_trigger_until_the_sensor_has_read_out() {
    let mut out = RecordingOutputs::<32>::new();
    let mut seq = started(plan(|c| c.pulses = PulseCount::Continuous), 0);
    let _ = seq.poll(LEAD, &mut out, &mut |_| {});
    let _ = seq.poll(LEAD + 100, &mut out, &mut |_| {});
    let _ = seq.poll(LEAD + 600, &mut out, &mut |_| {});
    // Camera off due at +1000, runs at +40 000: readout ends at +60 000 > +50 000.
    let _ = seq.poll(LEAD + 40_000, &mut out, &mut |_| {});
    assert_eq!(seq.next_deadline(), Some(LEAD + 40_000 + 20_000));
}
