//! Sequencer unit tests in simulated time: exact edge times and order, counts, stop, pulse
//! spacing, request refusals and the hardware flash cutoff; the flash safety rules under injected
//! lateness, the bracket and the property tests are in `tests/`.

use super::*;
use crate::config::LED_RIG_LIMITS;
use crate::outputs::{OutputEdge, PinOutputs, RecordingOutputs};
use ellipso_protocol::{Bracket, CaptureConfig, Fault, PULSE_NO_FLASH, PulseCount, PulseEvent};
use embedded_hal_mock::eh1::digital::{Mock as PinMock, State, Transaction as T};

pub(super) const LEAD: u64 = SequencerTiming::DEFAULT.lead_us as u64;

/// 1 ms exposure, flash 100..600 µs, 50 ms period, free run, 2 pulses.
fn config() -> CaptureConfig {
    CaptureConfig {
        exposure_us: 1_000,
        flash_delay_us: 100,
        flash_duration_us: 500,
        frame_period_us: 50_000,
        pulses: PulseCount::Count(2),
        trigger: TriggerSource::FreeRun,
        report_edges: false,
        bracket: Bracket::NONE,
    }
}

pub(super) fn plan(f: impl FnOnce(&mut CaptureConfig)) -> CapturePlan {
    let mut c = config();
    f(&mut c);
    CapturePlan::new(c, &LED_RIG_LIMITS).unwrap()
}

pub(super) fn started(plan: CapturePlan, now_us: u64) -> Sequencer {
    let mut seq = Sequencer::new(SequencerTiming::DEFAULT);
    seq.start(plan, now_us).unwrap();
    seq
}

/// Jumps simulated time to each deadline until idle (or `max_polls`); returns the messages.
pub(super) fn run_on_time(
    seq: &mut Sequencer,
    out: &mut impl Outputs,
    max_polls: usize,
) -> (Vec<BoardMessage>, PollOutcome) {
    let mut msgs = Vec::new();
    let mut last = PollOutcome::Idle;
    for _ in 0..max_polls {
        let Some(t) = seq.next_deadline() else { break };
        last = seq.poll(t, out, &mut |m| msgs.push(m));
    }
    (msgs, last)
}

pub(super) fn pulses(msgs: &[BoardMessage]) -> Vec<PulseEvent> {
    msgs.iter()
        .filter_map(|m| match m {
            BoardMessage::Pulse(p) => Some(*p),
            _ => None,
        })
        .collect()
}

pub(super) fn faults(msgs: &[BoardMessage]) -> Vec<Fault> {
    msgs.iter()
        .filter_map(|m| match m {
            BoardMessage::Fault(f) => Some(*f),
            _ => None,
        })
        .collect()
}

pub(super) fn edge(output: Output, high: bool, t_device_us: u64) -> OutputEdge {
    OutputEdge {
        output,
        high,
        t_device_us,
    }
}

use Output::{CameraTrigger as Cam, Flash as Fl};

#[test]
fn mock_pins_see_exactly_two_pulses_in_order() {
    let two = [
        T::set(State::High),
        T::set(State::Low),
        T::set(State::High),
        T::set(State::Low),
    ];
    let mut out = PinOutputs::new(PinMock::new(&two), PinMock::new(&two));
    let mut seq = started(plan(|_| {}), 0);
    let (msgs, last) = run_on_time(&mut seq, &mut out, 100);
    assert_eq!(last, PollOutcome::Complete);
    assert_eq!(out.write_errors(), 0);
    let (mut cam, mut flash) = out.release();
    cam.done();
    flash.done();
    let p = pulses(&msgs);
    assert_eq!(
        p,
        [
            PulseEvent {
                seq: 0,
                t_trigger_us: LEAD,
                t_flash_on_us: LEAD + 100,
                t_flash_off_us: LEAD + 600,
                flags: 0,
                bracket_step: 0,
                flash_on_us: 500,
            },
            PulseEvent {
                seq: 1,
                t_trigger_us: LEAD + 50_000,
                t_flash_on_us: LEAD + 50_100,
                t_flash_off_us: LEAD + 50_600,
                flags: 0,
                bracket_step: 0,
                flash_on_us: 500,
            },
        ]
    );
    assert!(faults(&msgs).is_empty());
}

#[test]
fn recorded_timeline_has_exact_times() {
    let mut out = RecordingOutputs::<16>::new();
    let mut seq = started(plan(|_| {}), 7);
    let _ = run_on_time(&mut seq, &mut out, 100);
    let t0 = 7 + LEAD;
    let got: Vec<_> = out.edges().copied().collect();
    let mut want = Vec::new();
    for k in 0..2 {
        let t = t0 + k * 50_000;
        want.extend([
            edge(Cam, true, t),
            edge(Fl, true, t + 100),
            edge(Fl, false, t + 600),
            edge(Cam, false, t + 1_000),
        ]);
    }
    assert_eq!(got, want);
    assert!(!seq.is_running());
    assert_eq!(seq.next_deadline(), None);
    assert_eq!(seq.pulses_fired(), 2);
}

#[test]
fn coincident_deadlines_run_camera_on_flash_on_flash_off_camera_off() {
    // Flash from 0 to the full exposure: trigger/flash rise together and fall together.
    let p = plan(|c| {
        c.flash_delay_us = 0;
        c.flash_duration_us = 1_000;
        c.pulses = PulseCount::Count(1);
    });
    let mut out = RecordingOutputs::<8>::new();
    let mut seq = started(p, 0);
    // One poll at the trigger time runs two edges; one poll at the end runs two more.
    let mut msgs = Vec::new();
    assert_eq!(
        seq.poll(LEAD, &mut out, &mut |m| msgs.push(m)),
        PollOutcome::Running
    );
    assert_eq!(seq.next_deadline(), Some(LEAD + 1_000));
    assert_eq!(
        seq.poll(LEAD + 1_000, &mut out, &mut |m| msgs.push(m)),
        PollOutcome::Complete
    );
    let got: Vec<_> = out.edges().copied().collect();
    assert_eq!(
        got,
        [
            edge(Cam, true, LEAD),
            edge(Fl, true, LEAD),
            edge(Fl, false, LEAD + 1_000),
            edge(Cam, false, LEAD + 1_000),
        ]
    );
    assert_eq!(pulses(&msgs)[0].flags, 0);
}

#[test]
fn polls_before_a_deadline_do_nothing() {
    let mut out = RecordingOutputs::<8>::new();
    let mut seq = started(plan(|_| {}), 0);
    let mut msgs = Vec::new();
    for t in [0, 1, LEAD - 1] {
        assert_eq!(
            seq.poll(t, &mut out, &mut |m| msgs.push(m)),
            PollOutcome::Running
        );
    }
    assert_eq!(out.edges().count(), 0);
    assert!(msgs.is_empty());
    assert_eq!(seq.next_deadline(), Some(LEAD));
}

#[test]
fn counted_capture_fires_exactly_n_with_consecutive_seqs() {
    let mut out = RecordingOutputs::<64>::new();
    let mut seq = started(plan(|c| c.pulses = PulseCount::Count(7)), 0);
    let (msgs, last) = run_on_time(&mut seq, &mut out, 1_000);
    assert_eq!(last, PollOutcome::Complete);
    let seqs: Vec<u64> = pulses(&msgs).iter().map(|p| p.seq).collect();
    assert_eq!(seqs, (0..7).collect::<Vec<_>>());
    // A second capture continues the numbering: sequence numbers are never reused.
    seq.start(plan(|c| c.pulses = PulseCount::Count(2)), 1_000_000)
        .unwrap();
    let (msgs, _) = run_on_time(&mut seq, &mut out, 1_000);
    let seqs: Vec<u64> = pulses(&msgs).iter().map(|p| p.seq).collect();
    assert_eq!(seqs, [7, 8]);
}

#[test]
fn continuous_runs_until_stopped() {
    let mut out = RecordingOutputs::<8>::new();
    let mut seq = started(plan(|c| c.pulses = PulseCount::Continuous), 0);
    let (msgs, last) = run_on_time(&mut seq, &mut out, 4 * 250);
    assert_eq!(last, PollOutcome::Running);
    assert_eq!(pulses(&msgs).len(), 250);
    assert!(seq.is_running());
    let now = seq.next_deadline().unwrap();
    seq.stop(now, &mut out, &mut |_| {});
    assert_eq!(seq.next_deadline(), None);
    assert_eq!(
        seq.poll(now + 1_000_000, &mut out, &mut |_| {}),
        PollOutcome::Idle
    );
}

#[test]
fn stop_with_the_flash_lit_turns_it_off_at_once_and_ends_the_capture() {
    let p = plan(|c| {
        c.pulses = PulseCount::Continuous;
        c.report_edges = true;
    });
    let mut out = RecordingOutputs::<16>::new();
    let mut seq = started(p, 0);
    let mut msgs = Vec::new();
    let _ = seq.poll(LEAD, &mut out, &mut |m| msgs.push(m));
    let _ = seq.poll(LEAD + 100, &mut out, &mut |m| msgs.push(m));
    assert!(out.flash_high() && seq.flash_on());
    seq.stop(LEAD + 300, &mut out, &mut |m| msgs.push(m));
    assert!(!out.flash_high() && !out.camera_high());
    assert!(!seq.flash_on() && !seq.camera_high());
    let tail: Vec<_> = out.edges().skip(2).copied().collect();
    assert_eq!(
        tail,
        [edge(Fl, false, LEAD + 300), edge(Cam, false, LEAD + 300)]
    );
    // The truncated pulse is reported with its real times.
    let p = pulses(&msgs);
    assert_eq!(p.len(), 1);
    assert_eq!(
        (p[0].t_flash_on_us, p[0].t_flash_off_us),
        (LEAD + 100, LEAD + 300)
    );
    // Edge reports in order, the pulse last.
    let kinds: Vec<_> = msgs
        .iter()
        .map(|m| match m {
            BoardMessage::Edge(e) => (Some((e.output, e.high)), false),
            BoardMessage::Pulse(_) => (None, true),
            _ => (None, false),
        })
        .collect();
    assert_eq!(
        kinds,
        [
            (Some((Cam, true)), false),
            (Some((Fl, true)), false),
            (Some((Fl, false)), false),
            (Some((Cam, false)), false),
            (None, true)
        ]
    );
    // Nothing more, ever.
    assert_eq!(seq.next_deadline(), None);
    let _ = seq.poll(10_000_000, &mut out, &mut |m| msgs.push(m));
    assert_eq!(out.edges().count(), 4);
}

#[test]
fn stop_before_the_flash_lit_flags_skip_without_a_fault() {
    let mut out = RecordingOutputs::<8>::new();
    let mut seq = started(plan(|_| {}), 0);
    let mut msgs = Vec::new();
    let _ = seq.poll(LEAD, &mut out, &mut |m| msgs.push(m));
    seq.stop(LEAD + 50, &mut out, &mut |m| msgs.push(m));
    let p = pulses(&msgs);
    assert_eq!(p[0].flags, PULSE_FLASH_SKIPPED | PULSE_STOPPED);
    assert_eq!(
        (p[0].t_flash_on_us, p[0].t_flash_off_us),
        (LEAD + 50, LEAD + 50)
    );
    assert!(faults(&msgs).is_empty());
    assert_eq!(seq.counters(), SequencerCounters::default());
}

#[test]
fn stop_before_the_trigger_cancels_the_pulse_without_a_number() {
    let mut out = RecordingOutputs::<8>::new();
    let mut seq = started(plan(|_| {}), 0);
    let mut msgs = Vec::new();
    seq.stop(LEAD - 1, &mut out, &mut |m| msgs.push(m));
    assert!(msgs.is_empty());
    assert_eq!(out.edges().count(), 0);
    assert_eq!(seq.pulses_fired(), 0);
}

#[test]
fn a_config_without_flash_never_touches_the_flash() {
    let p = plan(|c| {
        c.flash_delay_us = 0;
        c.flash_duration_us = 0;
        c.pulses = PulseCount::Count(2);
    });
    let mut out = RecordingOutputs::<8>::new();
    let mut seq = started(p, 0);
    let (msgs, _) = run_on_time(&mut seq, &mut out, 100);
    assert!(out.edges().all(|e| e.output == Cam));
    for p in pulses(&msgs) {
        assert_eq!(p.flags, PULSE_NO_FLASH);
        assert_eq!(
            (p.t_flash_on_us, p.t_flash_off_us),
            (p.t_trigger_us, p.t_trigger_us)
        );
    }
}

#[test]
fn requests_fire_after_the_lead_and_too_soon_names_the_exact_wait() {
    let p = plan(|c| {
        c.trigger = TriggerSource::HostCommand;
        c.pulses = PulseCount::Continuous;
    });
    let mut out = RecordingOutputs::<16>::new();
    let mut seq = started(p, 0);
    assert_eq!(seq.next_deadline(), None, "a request capture waits");
    assert_eq!(seq.request_pulse(5_000), Ok(5_000 + LEAD));
    // A second request 10 ms later would rise 40 ms too early.
    assert_eq!(
        seq.request_pulse(15_000),
        Err(RejectReason::TooSoon { wait_us: 40_000 })
    );
    let _ = run_on_time(&mut seq, &mut out, 10);
    assert_eq!(
        seq.request_pulse(55_000 - 1),
        Err(RejectReason::TooSoon { wait_us: 1 })
    );
    assert_eq!(seq.request_pulse(55_000), Ok(55_000 + LEAD));
}

#[test]
fn request_refusals() {
    let mut seq = Sequencer::new(SequencerTiming::DEFAULT);
    assert_eq!(seq.request_pulse(0), Err(RejectReason::NotArmed));
    seq.start(plan(|_| {}), 0).unwrap();
    assert_eq!(seq.request_pulse(0), Err(RejectReason::WrongTriggerSource));
    assert_eq!(seq.start(plan(|_| {}), 0), Err(RejectReason::Busy));
    let mut seq = started(
        plan(|c| {
            c.trigger = TriggerSource::GripButton;
            c.pulses = PulseCount::Count(1);
        }),
        0,
    );
    assert!(seq.request_pulse(0).is_ok());
    assert_eq!(
        seq.request_pulse(1_000_000),
        Err(RejectReason::Busy),
        "count used up"
    );
}

#[test]
fn the_sensor_readout_is_respected_across_captures() {
    let mut out = RecordingOutputs::<8>::new();
    let mut seq = started(plan(|c| c.pulses = PulseCount::Count(1)), 0);
    let _ = run_on_time(&mut seq, &mut out, 10);
    // Camera fell at LEAD + 1000; a new free run started right away waits for the readout.
    seq.start(plan(|_| {}), LEAD + 1_000).unwrap();
    assert_eq!(seq.next_deadline(), Some(LEAD + 1_000 + 20_000));
}

#[test]
fn time_near_the_end_of_u64_saturates_instead_of_wrapping() {
    let mut out = RecordingOutputs::<8>::new();
    let mut seq = started(plan(|_| {}), u64::MAX - 10);
    let (msgs, _) = run_on_time(&mut seq, &mut out, 10);
    // Every deadline saturates at u64::MAX; the edges still run in order, flash inside trigger.
    let got: Vec<_> = out.edges().map(|e| (e.output, e.high)).collect();
    assert_eq!(
        got[..4],
        [(Cam, true), (Fl, true), (Fl, false), (Cam, false)]
    );
    assert!(!pulses(&msgs).is_empty());
}

/// A board with a one-pulse timer: the flash cuts itself off after the `max_on_us` it was armed
/// with, whatever the software does (safety rule 5).
struct OnePulseFlash {
    armed_max_on_us: Vec<u32>,
    cut_at: Option<u64>,
}

impl Outputs for OnePulseFlash {
    fn set_camera(&mut self, _high: bool, _t: u64) {}
    fn flash_on(&mut self, t: u64, max_on_us: u32) {
        self.armed_max_on_us.push(max_on_us);
        self.cut_at = Some(t + u64::from(max_on_us));
    }
    fn flash_off(&mut self, _t: u64) {
        self.cut_at = None;
    }
}

#[test]
fn flash_on_arms_the_hardware_cutoff_with_the_boards_cap() {
    let mut out = OnePulseFlash {
        armed_max_on_us: Vec::new(),
        cut_at: None,
    };
    let mut seq = started(plan(|_| {}), 0);
    let _ = seq.poll(LEAD, &mut out, &mut |_| {});
    let _ = seq.poll(LEAD + 100, &mut out, &mut |_| {});
    // The CPU hangs here; the hardware would cut the flash at on + 5 ms.
    assert_eq!(
        out.cut_at,
        Some(LEAD + 100 + u64::from(LED_RIG_LIMITS.max_flash_on_us))
    );
    let _ = run_on_time(&mut seq, &mut out, 100);
    assert_eq!(out.armed_max_on_us, [LED_RIG_LIMITS.max_flash_on_us; 2]);
}

mod bracket;

mod lateness;

mod proptests;
