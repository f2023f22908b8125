//! Property tests: random valid configurations driven by polls with random lateness (and random
//! extra early polls, requests and stops), checked on the recorded pin timeline.
//!
//! Properties:
//! - pulse `k` fires bracket step `k mod len` and its event reports that step and the flash's
//!   actual on-time (`t_flash_off_us − t_flash_on_us`);
//! - the flash goes off at the first poll at or after `t_on + w` (or at the stop), `w` the on-time
//!   of the pulse's step, never later; so when every poll is at most `max_flash_on_us − w_max` late the
//!   flash is never on longer than `max_flash_on_us`, and when it was on longer the pulse is
//!   flagged `PULSE_FLASH_FORCED_OFF` with a matching `FlashForcedOff` fault;
//! - the flash is never on while the camera trigger is low;
//! - the flash never lights outside `[t_trigger, t_trigger + exposure_us]`;
//! - sequence numbers are consecutive from 0, one `PulseEvent` per trigger edge, and each event's
//!   times are the recorded edge times;
//! - triggers are at least `frame_period_us` apart and at least `readout_us` after the previous
//!   trigger fell; every exposure is at least `exposure_us` long;
//! - `TooSoon { wait_us }` is exact: the same request `wait_us` later succeeds.

use super::super::*;
use crate::config::LED_RIG_LIMITS;
use crate::outputs::RecordingOutputs;
use ellipso_protocol::{
    Bracket, CaptureConfig, ENERGY_ONE_Q15, Fault, PULSE_FLASH_FORCED_OFF, PULSE_NO_FLASH,
    PulseCount, PulseEvent,
};
use proptest::prelude::*;
use proptest::test_runner::RngSeed;

const L: ellipso_protocol::BoardLimits = LED_RIG_LIMITS;

/// No bracket half of the time, else 1–4 steps of any energy in (0, 1].
fn bracket() -> impl Strategy<Value = Bracket> {
    prop_oneof![
        Just(Bracket::NONE),
        proptest::collection::vec(1u16..=ENERGY_ONE_Q15, 1..=4)
            .prop_map(|steps| Bracket::from_q15(&steps).expect("≤ 8 steps")),
    ]
}

/// A valid configuration: flash inside the exposure, within on-time and duty limits.
fn valid_config() -> impl Strategy<Value = CaptureConfig> {
    (
        L.min_exposure_us..=30_000u32,
        0u32..=1000, // flash start, ‰ of the free exposure
        0u32..=L.max_flash_on_us,
        0u32..=30_000, // extra period
        1u32..=6,      // pulses
        prop_oneof![
            Just(TriggerSource::FreeRun),
            Just(TriggerSource::HostCommand)
        ],
        any::<bool>(),
        bracket(),
    )
        .prop_map(
            |(exposure_us, start_permille, duration, extra, n, trigger, report_edges, bracket)| {
                let flash_duration_us = duration.min(exposure_us);
                let free = exposure_us - flash_duration_us;
                let flash_delay_us = free * start_permille / 1000;
                let duty_min =
                    (1000 * flash_duration_us).div_ceil(u32::from(L.max_flash_duty_permille));
                let frame_period_us = (exposure_us + L.readout_us)
                    .max(duty_min)
                    .max(L.min_frame_period_us)
                    + extra;
                CaptureConfig {
                    exposure_us,
                    flash_delay_us,
                    flash_duration_us,
                    frame_period_us,
                    pulses: PulseCount::Count(n),
                    trigger,
                    report_edges,
                    bracket,
                }
            },
        )
        // A tiny flash with a small step rounds to 0 µs: refused by the plan, not generated.
        .prop_filter("the plan accepts it", |c| CapturePlan::new(*c, &L).is_ok())
}

/// Lateness of one poll after its deadline, µs: mostly on time, sometimes a little or very late.
fn lateness() -> impl Strategy<Value = u64> {
    prop_oneof![
        4 => Just(0u64),
        3 => 0u64..200,
        2 => 0u64..6_000,
        1 => 0u64..80_000,
    ]
}

struct Run {
    edges: Vec<crate::outputs::OutputEdge>,
    polls: Vec<u64>,
    msgs: Vec<BoardMessage>,
    stopped_at: Option<u64>,
}

/// Drives one capture: each step polls at `deadline + lateness` (capped by `bound`), sometimes
/// after an extra early poll; request captures request as soon as allowed; an optional stop.
fn drive(plan: CapturePlan, lates: &[u64], bound: Option<u64>, stop_after: Option<usize>) -> Run {
    let mut seq = Sequencer::new(SequencerTiming::DEFAULT);
    let mut out = RecordingOutputs::<256>::new();
    let mut msgs = Vec::new();
    let mut polls = Vec::new();
    let mut now = 0u64;
    let mut stopped_at = None;
    seq.start(plan, now).unwrap();
    for (i, &late) in lates.iter().cycle().take(400).enumerate() {
        let late = bound.map_or(late, |b| late.min(b));
        if Some(i) == stop_after {
            now += late;
            seq.stop(now, &mut out, &mut |m| msgs.push(m));
            stopped_at = Some(now);
            break;
        }
        let deadline = match seq.next_deadline() {
            Some(d) => d,
            None if seq.is_running() => {
                // A request capture waiting for its next request: ask `late` µs from now.
                now += late;
                match seq.request_pulse(now) {
                    Ok(t) => assert_eq!(t, now + u64::from(seq.timing().lead_us)),
                    Err(RejectReason::TooSoon { wait_us }) => {
                        assert!(seq.request_pulse(now + u64::from(wait_us) - 1).is_err());
                        now += u64::from(wait_us);
                        assert!(seq.request_pulse(now).is_ok(), "TooSoon's wait is exact");
                    }
                    Err(e) => panic!("unexpected refusal {e:?}"),
                }
                continue;
            }
            None => break,
        };
        if late % 3 == 1 && deadline > now + 1 {
            // An extra early poll must change nothing.
            let early = now + (deadline - now) / 2;
            let before = out.edges().count();
            polls.push(early);
            let _ = seq.poll(early, &mut out, &mut |m| msgs.push(m));
            assert_eq!(out.edges().count(), before);
        }
        now = now.max(deadline) + late;
        polls.push(now);
        let _ = seq.poll(now, &mut out, &mut |m| msgs.push(m));
    }
    assert_eq!(out.dropped(), 0);
    Run {
        edges: out.edges().copied().collect(),
        polls,
        msgs,
        stopped_at,
    }
}

fn check(plan: &CapturePlan, run: &Run, bounded: bool) -> Result<(), TestCaseError> {
    let max_on = u64::from(plan.max_flash_on_us());
    let mut camera = false;
    let mut flash_on_at: Option<u64> = None;
    let mut trigger_at = 0u64;
    let mut triggers = Vec::new(); // (rise, fall)
    let mut risen = 0u64;
    let mut flashes = Vec::new(); // (on, off)
    for e in &run.edges {
        match (e.output, e.high) {
            (Output::CameraTrigger, true) => {
                trigger_at = e.t_device_us;
                camera = true;
                risen += 1;
            }
            (Output::CameraTrigger, false) => {
                prop_assert!(
                    flash_on_at.is_none(),
                    "trigger fell with the flash on at {e:?}"
                );
                triggers.push((trigger_at, e.t_device_us));
                camera = false;
            }
            (Output::Flash, true) => {
                prop_assert!(camera, "flash lit with the trigger low at {e:?}");
                // This pulse's own on-time: pulse `risen − 1` of the capture.
                let w = plan.step_on_time_us(plan.step_of_pulse(risen - 1));
                prop_assert!(
                    e.t_device_us + u64::from(w) <= trigger_at + u64::from(plan.exposure_us()),
                    "flash planned past the exposure"
                );
                flash_on_at = Some(e.t_device_us);
            }
            (Output::Flash, false) => {
                let on = flash_on_at.take().expect("flash off without on");
                flashes.push((on, e.t_device_us));
            }
        }
    }
    prop_assert!(flash_on_at.is_none() && !camera, "outputs left high");

    let events: Vec<PulseEvent> = run
        .msgs
        .iter()
        .filter_map(|m| {
            if let BoardMessage::Pulse(p) = m {
                Some(*p)
            } else {
                None
            }
        })
        .collect();
    prop_assert_eq!(events.len(), triggers.len());
    for (k, (ev, &(rise, _))) in events.iter().zip(&triggers).enumerate() {
        prop_assert_eq!(ev.seq, k as u64, "consecutive sequence numbers");
        prop_assert_eq!(ev.t_trigger_us, rise);
        prop_assert_eq!(
            ev.bracket_step,
            plan.step_of_pulse(k as u64),
            "step k mod len"
        );
        prop_assert_eq!(
            u64::from(ev.flash_on_us),
            ev.t_flash_off_us - ev.t_flash_on_us,
            "the reported on-time is the edges' difference"
        );
    }
    if run.stopped_at.is_none() {
        prop_assert_eq!(Some(events.len() as u32), plan.pulse_count());
    }

    // Flash-off timing against the poll times.
    let fired: Vec<&PulseEvent> = events
        .iter()
        .filter(|e| e.flags & (PULSE_NO_FLASH | PULSE_FLASH_SKIPPED) == 0)
        .collect();
    prop_assert_eq!(fired.len(), flashes.len());
    for (ev, &(on, off)) in fired.iter().zip(&flashes) {
        prop_assert_eq!((ev.t_flash_on_us, ev.t_flash_off_us), (on, off));
        let w = u64::from(plan.step_on_time_us(ev.bracket_step));
        prop_assert!(w > 0, "a fired flash has a planned on-time");
        let due = on + w.min(max_on);
        let first_poll = run.polls.iter().copied().find(|&p| p >= due);
        let by_stop = run
            .stopped_at
            .filter(|&s| s <= first_poll.unwrap_or(u64::MAX));
        prop_assert_eq!(
            Some(off),
            by_stop.or(first_poll),
            "off at the first poll after due"
        );
        let on_for = off - on;
        if bounded {
            prop_assert!(on_for <= max_on, "on {on_for} µs > cap {max_on} µs");
        }
        let forced = ev.flags & PULSE_FLASH_FORCED_OFF != 0;
        prop_assert_eq!(forced, on_for > max_on);
        let fault = Fault::FlashForcedOff {
            seq: ev.seq,
            on_for_us: on_for as u32,
        };
        prop_assert_eq!(forced, run.msgs.contains(&BoardMessage::Fault(fault)));
    }

    // Spacing and exposure length.
    for w in triggers.windows(2) {
        let ((rise0, fall0), (rise1, _)) = (w[0], w[1]);
        prop_assert!(rise1 >= rise0 + u64::from(plan.frame_period_us()));
        prop_assert!(rise1 >= fall0 + u64::from(plan.readout_us()));
    }
    for (k, &(rise, fall)) in triggers.iter().enumerate() {
        let stopped_last = run.stopped_at.is_some() && k + 1 == triggers.len();
        prop_assert!(stopped_last || fall - rise >= u64::from(plan.exposure_us()));
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 256,
        rng_seed: RngSeed::Fixed(0x0e11_1950),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn flash_safety_holds_under_random_poll_lateness(
        config in valid_config(),
        lates in proptest::collection::vec(lateness(), 1..40),
        stop_after in proptest::option::weighted(0.2, 0usize..30),
    ) {
        let plan = CapturePlan::new(config, &L).expect("strategy makes valid configs");
        let run = drive(plan, &lates, None, stop_after);
        check(&plan, &run, false)?;
        // Bounded lateness: no poll later than the flash's margin under its cap.
        let margin = u64::from(plan.max_flash_on_us() - plan.longest_on_time_us());
        let run = drive(plan, &lates, Some(margin), stop_after);
        check(&plan, &run, true)?;
    }
}
