//! A simulated world of triggers, frames and pulses with every kind of loss; the pairer must
//! never pair wrongly and must account for everything.

use std::collections::BTreeMap;

use proptest::prelude::*;
use rand::{Rng, SeedableRng};

use super::*;

const PERIOD_US: f64 = 250_000.0;
const EXPOSURE_US: u32 = 8_000;

fn clock() -> ClockFit {
    ClockFit {
        gain: 1.0 + 20e-6,
        offset_us: -4_000_000.0,
        residuals_us: vec![],
        rms_us: 30.0,
        n_samples: 20,
    }
}

#[derive(Clone, Copy, Debug, Default)]
struct Faults {
    pulse_lost: bool,
    frame_lost: bool,
    missed_trigger: bool,
    spurious_frame_after: bool,
}

enum Ev {
    Pulse(u64, DeviceTimeUs),
    Frame(u64),
}

/// Runs the world; returns outcomes and the truth (frame id → seq).
fn run(
    faults: &[Faults],
    seed: u64,
    with_clock: bool,
) -> (Vec<PairingOutcome>, BTreeMap<u64, u64>) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let c = clock();
    let mut timeline: Vec<(f64, Ev)> = Vec::new();
    let mut truth = BTreeMap::new();
    let mut frame_id = 1_000u64;
    for (k, f) in faults.iter().enumerate() {
        let seq = 7 + k as u64;
        let trig = DeviceTimeUs(5_000_000 + (k as f64 * PERIOD_US) as u64);
        let host_trig = c.host_us(trig);
        if !f.pulse_lost {
            timeline.push((
                host_trig + 10_000.0 + rng.random_range(0.0..2_000.0),
                Ev::Pulse(seq, trig),
            ));
        }
        if !f.missed_trigger {
            if !f.frame_lost {
                timeline.push((
                    host_trig + 30_000.0 + rng.random_range(-5_000.0..5_000.0),
                    Ev::Frame(frame_id),
                ));
                if !f.pulse_lost {
                    truth.insert(frame_id, seq);
                }
            }
            frame_id += 1;
        }
        if f.spurious_frame_after {
            // a stray trigger well after the real one: outside the a-priori latency window
            let t = host_trig + rng.random_range(70_000.0..240_000.0);
            timeline.push((t, Ev::Frame(frame_id)));
            frame_id += 1;
        }
    }
    timeline.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut p = Pairer::new(PairingConfig::for_capture(
        EXPOSURE_US,
        PERIOD_US as u32,
        50_000,
    ));
    let cl = with_clock.then_some(&c);
    let mut out = Vec::new();
    for (t, ev) in timeline {
        let now = HostTimeUs(t as u64);
        out.extend(p.expire(now, cl));
        out.extend(match ev {
            Ev::Pulse(seq, trig) => p.add_pulse(seq, trig, now, cl),
            Ev::Frame(id) => p.add_frame(id, now, cl),
        });
    }
    out.extend(p.finish());
    (out, truth)
}

fn check(out: &[PairingOutcome], truth: &BTreeMap<u64, u64>, n_frames: usize, n_pulses: usize) {
    let mut frames_accounted = 0;
    let mut pulses_accounted = 0;
    for o in out {
        match o {
            PairingOutcome::Paired { frame_id, seq, .. } => {
                assert_eq!(
                    truth.get(frame_id),
                    Some(seq),
                    "frame {frame_id} paired with wrong pulse {seq}"
                );
                frames_accounted += 1;
                pulses_accounted += 1;
            }
            PairingOutcome::FrameWithoutPulse { .. } => frames_accounted += 1,
            PairingOutcome::PulseWithoutFrame { .. } => pulses_accounted += 1,
            other => panic!("unexpected {other:?}"),
        }
    }
    assert_eq!(frames_accounted, n_frames, "every frame accounted for once");
    assert_eq!(pulses_accounted, n_pulses, "every pulse accounted for once");
}

fn counts(faults: &[Faults]) -> (usize, usize) {
    let frames = faults
        .iter()
        .filter(|f| !f.missed_trigger && !f.frame_lost)
        .count()
        + faults.iter().filter(|f| f.spurious_frame_after).count();
    let pulses = faults.iter().filter(|f| !f.pulse_lost).count();
    (frames, pulses)
}

#[test]
fn clean_capture_pairs_everything_with_latency() {
    let faults = vec![Faults::default(); 50];
    let (out, truth) = run(&faults, 1, true);
    check(&out, &truth, 50, 50);
    assert!(out.iter().all(|o| matches!(o, PairingOutcome::Paired { latency_us: Some(l), .. } if (20_000.0..40_000.0).contains(l))));
}

#[test]
fn a_missed_trigger_shifts_ids_and_timing_catches_it() {
    let mut faults = vec![Faults::default(); 20];
    faults[5].missed_trigger = true;
    let (out, truth) = run(&faults, 2, true);
    check(&out, &truth, 19, 20);
    assert!(out.contains(&PairingOutcome::PulseWithoutFrame { seq: 12 }));
    assert_eq!(
        out.iter()
            .filter(|o| matches!(o, PairingOutcome::Paired { .. }))
            .count(),
        19
    );
}

#[test]
fn lost_frames_pulses_and_spurious_frames_are_reported_not_paired() {
    let mut faults = vec![Faults::default(); 30];
    faults[3].frame_lost = true;
    faults[9].pulse_lost = true;
    faults[14].spurious_frame_after = true;
    faults[20].frame_lost = true;
    faults[20].pulse_lost = true;
    let (out, truth) = run(&faults, 3, true);
    let (nf, np) = counts(&faults);
    check(&out, &truth, nf, np);
}

#[test]
fn duplicates_are_reported() {
    let c = clock();
    let mut p = Pairer::new(PairingConfig::for_capture(EXPOSURE_US, 250_000, 50_000));
    let trig = DeviceTimeUs(5_000_000);
    let t = HostTimeUs(c.host_us(trig) as u64);
    p.add_pulse(1, trig, t, Some(&c));
    assert_eq!(
        p.add_pulse(1, trig, t, Some(&c)),
        vec![PairingOutcome::DuplicatePulse { seq: 1 }]
    );
    let arrival = HostTimeUs(t.0 + 30_000);
    assert!(matches!(
        p.add_frame(9, arrival, Some(&c))[..],
        [PairingOutcome::Paired {
            frame_id: 9,
            seq: 1,
            ..
        }]
    ));
    assert_eq!(
        p.add_frame(9, arrival, Some(&c)),
        vec![PairingOutcome::DuplicateFrame { frame_id: 9 }]
    );
    assert_eq!(p.counts().duplicate_frames, 1);
}

#[test]
fn without_a_clock_ids_alone_pair_a_clean_capture() {
    let faults = vec![Faults::default(); 10];
    let (out, truth) = run(&faults, 4, false);
    check(&out, &truth, 10, 10);
    assert!(out.iter().all(|o| matches!(
        o,
        PairingOutcome::Paired {
            latency_us: None,
            ..
        }
    )));
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]
    /// Random losses of every kind: never a wrong pair, everything accounted for.
    #[test]
    fn never_a_wrong_pair(seed in any::<u64>(), n in 5usize..60) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let faults: Vec<Faults> = (0..n).map(|_| Faults {
            pulse_lost: rng.random_bool(0.08),
            frame_lost: rng.random_bool(0.08),
            missed_trigger: rng.random_bool(0.05),
            spurious_frame_after: rng.random_bool(0.05),
        }).collect();
        let (out, truth) = run(&faults, seed, true);
        let (nf, np) = counts(&faults);
        check(&out, &truth, nf, np);
    }
}

#[test]
fn an_outlier_first_latency_does_not_lock_out_every_later_frame() {
    // the first frame arrives 60 ms after its trigger, every later one at ~30 ms: the window
    // learned from the first pair excludes them until the pairer starts over
    let c = clock();
    let mut p = Pairer::new(PairingConfig::for_capture(
        EXPOSURE_US,
        PERIOD_US as u32,
        100_000,
    ));
    let mut out = Vec::new();
    for k in 0..40u64 {
        let trig = DeviceTimeUs(5_000_000 + k * PERIOD_US as u64);
        let host_trig = c.host_us(trig);
        let latency = if k == 0 { 60_000.0 } else { 30_000.0 };
        out.extend(p.expire(HostTimeUs((host_trig + 10_000.0) as u64), Some(&c)));
        out.extend(p.add_pulse(
            7 + k,
            trig,
            HostTimeUs((host_trig + 10_000.0) as u64),
            Some(&c),
        ));
        out.extend(p.add_frame(
            1_000 + k,
            HostTimeUs((host_trig + latency) as u64),
            Some(&c),
        ));
    }
    out.extend(p.finish());
    for o in &out {
        if let PairingOutcome::Paired { frame_id, seq, .. } = o {
            assert_eq!(seq - 7, frame_id - 1_000, "wrong pair {o:?}");
        }
    }
    let paired = out
        .iter()
        .filter(|o| matches!(o, PairingOutcome::Paired { .. }))
        .count();
    assert!(
        paired >= 35,
        "only {paired} of 40 paired after an outlier first frame"
    );
}

#[test]
fn a_camera_lagging_behind_real_time_loses_nothing() {
    // pulses arrive in real time; the camera delivers each frame (stamped with its true arrival)
    // 5 s of wall time later — a renderer or a slow stack; expiry runs at wall time throughout
    let c = clock();
    let mut p = Pairer::new(PairingConfig::for_capture(
        EXPOSURE_US,
        PERIOD_US as u32,
        50_000,
    ));
    let mut out = Vec::new();
    let n = 30u64;
    let lag_us = 5_000_000.0;
    let trig = |k: u64| DeviceTimeUs(5_000_000 + k * PERIOD_US as u64);
    for k in 0..n + 20 {
        let wall = c.host_us(trig(k)) + 10_000.0;
        out.extend(p.expire(HostTimeUs(wall as u64), Some(&c)));
        if k < n {
            out.extend(p.add_pulse(7 + k, trig(k), HostTimeUs(wall as u64), Some(&c)));
        }
        // the frame of the trigger `lag` ago is delivered now
        let behind = (lag_us / PERIOD_US) as u64;
        if k >= behind && k - behind < n {
            let j = k - behind;
            out.extend(p.add_frame(
                1_000 + j,
                HostTimeUs((c.host_us(trig(j)) + 30_000.0) as u64),
                Some(&c),
            ));
        }
    }
    out.extend(p.finish());
    let paired = out
        .iter()
        .filter(|o| matches!(o, PairingOutcome::Paired { .. }))
        .count();
    assert_eq!(paired as u64, n, "{out:?}");
}
