//! Property test of the whole board through its byte path: random command streams (valid and
//! invalid configurations, every command in every state, a wrong protocol version now and then),
//! garbage bytes, button presses and time advancing with on-time polls.
//!
//! Properties:
//! - every intact command frame gets exactly one reply of its kind (`Ack`/`Rejected` naming the
//!   command, `HelloReply`, `Pong` with the nonce and the device time, `Status`), whatever state
//!   and whatever garbage came before it (the link never dies on a bad frame);
//! - every garbage burst yields only `BadFrame` faults, and `Status` counters equal the
//!   `Rejected` replies and `BadFrame` faults actually sent;
//! - on the pin timeline the flash is only ever lit while the trigger is high, and with on-time
//!   polls it is on for exactly its bracket step's on-time unless a `Stop` cut it short, and the
//!   pulse event reports that on-time;
//! - pulse sequence numbers are consecutive from 0 across all captures.

use super::super::*;
use crate::config::LED_RIG_LIMITS;
use crate::outputs::RecordingOutputs;
use ellipso_protocol::{
    Bracket, CaptureConfig, ENERGY_ONE_Q15, MAX_BRACKET_STEPS, MAX_FRAME_LEN, Output,
    PULSE_FLASH_SKIPPED, PULSE_NO_FLASH, PulseCount, encode,
};
use proptest::prelude::*;
use proptest::test_runner::RngSeed;

#[derive(Debug, Clone)]
enum Event {
    Command(HostMessage),
    Garbage(Vec<u8>),
    Advance(u64),
    Button,
}

fn trigger() -> impl Strategy<Value = TriggerSource> {
    prop_oneof![
        Just(TriggerSource::FreeRun),
        Just(TriggerSource::HostCommand),
        Just(TriggerSource::GripButton),
    ]
}

/// Mostly plausible configurations (about half valid), some arbitrary.
fn capture_config() -> impl Strategy<Value = CaptureConfig> {
    let plausible = (
        20u32..5_000,
        0u32..3_000,
        0u32..6_000,
        15_000u32..80_000,
        prop_oneof![
            Just(PulseCount::Continuous),
            (0u32..4).prop_map(PulseCount::Count)
        ],
        trigger(),
        any::<bool>(),
        bracket(),
    )
        .prop_map(
            |(e, d, w, p, pulses, trigger, report_edges, bracket)| CaptureConfig {
                exposure_us: e,
                flash_delay_us: d.min(e),
                flash_duration_us: w.min(e - d.min(e)),
                frame_period_us: p,
                pulses,
                trigger,
                report_edges,
                bracket,
            },
        );
    let arbitrary = (
        any::<[u32; 4]>(),
        any::<u32>(),
        trigger(),
        any::<bool>(),
        proptest::collection::vec(any::<u16>(), 0..=MAX_BRACKET_STEPS),
    )
        .prop_map(
            |([e, d, w, p], n, trigger, report_edges, steps)| CaptureConfig {
                exposure_us: e,
                flash_delay_us: d,
                flash_duration_us: w,
                frame_period_us: p,
                pulses: PulseCount::Count(n),
                trigger,
                report_edges,
                bracket: Bracket::from_q15(&steps).expect("≤ 8 steps"),
            },
        );
    prop_oneof![4 => plausible, 1 => arbitrary]
}

/// A configuration that passes every check against [`LED_RIG_LIMITS`].
fn valid_config() -> impl Strategy<Value = CaptureConfig> {
    let l = LED_RIG_LIMITS;
    (
        l.min_exposure_us..10_000u32,
        0u32..=1000,
        0u32..=l.max_flash_on_us,
        0u32..40_000,
        prop_oneof![
            Just(PulseCount::Continuous),
            (1u32..5).prop_map(PulseCount::Count)
        ],
        trigger(),
        any::<bool>(),
        bracket(),
    )
        .prop_map(
            move |(e, start, w, extra, pulses, trigger, report_edges, bracket)| {
                let w = w.min(e);
                let duty_min = (1000 * w).div_ceil(u32::from(l.max_flash_duty_permille));
                CaptureConfig {
                    exposure_us: e,
                    flash_delay_us: (e - w) * start / 1000,
                    flash_duration_us: w,
                    frame_period_us: (e + l.readout_us).max(duty_min) + extra,
                    pulses,
                    trigger,
                    report_edges,
                    bracket,
                }
            },
        )
        .prop_filter("the plan accepts it", move |c| {
            CapturePlan::new(*c, &l).is_ok()
        })
}

/// No bracket half of the time, else 1–3 steps of any energy in (0, 1].
fn bracket() -> impl Strategy<Value = Bracket> {
    prop_oneof![
        Just(Bracket::NONE),
        proptest::collection::vec(1u16..=ENERGY_ONE_Q15, 1..=3)
            .prop_map(|steps| Bracket::from_q15(&steps).expect("≤ 8 steps")),
    ]
}

fn command() -> impl Strategy<Value = HostMessage> {
    prop_oneof![
        1 => prop_oneof![9 => Just(PROTOCOL_VERSION), 1 => any::<u16>()]
            .prop_map(|v| HostMessage::Hello { protocol_version: v }),
        2 => capture_config().prop_map(HostMessage::Configure),
        2 => valid_config().prop_map(HostMessage::Configure),
        3 => Just(HostMessage::Arm),
        3 => Just(HostMessage::Start),
        3 => Just(HostMessage::FireOne),
        1 => Just(HostMessage::Stop),
        1 => any::<u32>().prop_map(|nonce| HostMessage::Ping { nonce }),
        1 => Just(HostMessage::StatusRequest),
    ]
}

/// One event, or a whole valid capture set-up (Configure, Arm, Start, FireOne).
fn events() -> impl Strategy<Value = Vec<Event>> {
    prop_oneof![
        5 => event().prop_map(|e| vec![e]),
        1 => valid_config().prop_map(|c| {
            [HostMessage::Configure(c), HostMessage::Arm, HostMessage::Start, HostMessage::FireOne]
                .into_iter()
                .map(Event::Command)
                .collect()
        }),
    ]
}

fn event() -> impl Strategy<Value = Event> {
    prop_oneof![
        6 => command().prop_map(Event::Command),
        1 => proptest::collection::vec(any::<u8>(), 1..2 * MAX_FRAME_LEN).prop_map(Event::Garbage),
        4 => prop_oneof![0u64..2_000, 0u64..200_000].prop_map(Event::Advance),
        1 => Just(Event::Button),
    ]
}

fn is_reply(m: &BoardMessage) -> bool {
    matches!(
        m,
        BoardMessage::HelloReply(_)
            | BoardMessage::Ack(_)
            | BoardMessage::Rejected { .. }
            | BoardMessage::Pong { .. }
            | BoardMessage::Status(_)
    )
}

fn reply_matches(cmd: &HostMessage, reply: &BoardMessage, now: u64) -> bool {
    match (cmd, reply) {
        (HostMessage::Hello { .. }, BoardMessage::HelloReply(info)) => {
            info.protocol_version == PROTOCOL_VERSION
        }
        (
            HostMessage::Ping { nonce },
            BoardMessage::Pong {
                nonce: n,
                t_device_us,
            },
        ) => n == nonce && *t_device_us == now,
        (HostMessage::StatusRequest, BoardMessage::Status(s)) => s.t_device_us == now,
        (_, BoardMessage::Ack(k)) | (_, BoardMessage::Rejected { command: k, .. }) => {
            *k == cmd.kind()
                && !matches!(
                    cmd,
                    HostMessage::Hello { .. }
                        | HostMessage::Ping { .. }
                        | HostMessage::StatusRequest
                )
        }
        _ => false,
    }
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 128,
        rng_seed: RngSeed::Fixed(0x00b0_a4d5),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn any_command_stream_gets_one_reply_each_and_keeps_the_flash_safe(
        events in proptest::collection::vec(events(), 1..40),
    ) {
        let events: Vec<Event> = events.into_iter().flatten().collect();
        let mut board = Board::new(crate::BoardConfig::new("prop", 1_000_000)).unwrap();
        let mut out = RecordingOutputs::<2048>::new();
        let mut all = Vec::new();
        let mut now = 0u64;
        let mut stops = Vec::new();
        // Flash durations of every capture seen running (sampled after each event).
        let mut running_durations = Vec::new();
        for ev in &events {
            if let Some(p) = board.sequencer().plan() {
                let steps = p.bracket().cycle_len() as u8;
                running_durations.extend((0..steps).map(|i| u64::from(p.step_on_time_us(i))));
            }
            match ev {
                Event::Command(cmd) => {
                    let mut buf = [0u8; MAX_FRAME_LEN];
                    let n = encode(cmd, &mut buf).unwrap();
                    let mut got = Vec::new();
                    for &b in &buf[..n] {
                        board.feed_rx_byte(b, now, &mut out, &mut |m| got.push(m));
                    }
                    let replies: Vec<_> = got.iter().filter(|m| is_reply(m)).collect();
                    prop_assert_eq!(replies.len(), 1, "{:?} got {:?}", cmd, got);
                    prop_assert!(reply_matches(cmd, replies[0], now), "{:?} -> {:?}", cmd, replies[0]);
                    if *cmd == HostMessage::Stop {
                        prop_assert!(!out.flash_high() && !out.camera_high());
                        stops.push(now);
                    }
                    all.extend(got);
                }
                Event::Garbage(bytes) => {
                    let mut got = Vec::new();
                    for &b in bytes.iter().chain(&[0]) {
                        board.feed_rx_byte(b, now, &mut out, &mut |m| got.push(m));
                    }
                    prop_assert!(
                        got.iter().all(|m| matches!(m, BoardMessage::Fault(Fault::BadFrame(_)))),
                        "garbage produced {:?}", got
                    );
                    all.extend(got);
                }
                Event::Advance(dt) => {
                    let until = now + dt;
                    while let Some(t) = board.next_deadline().filter(|&t| t <= until) {
                        now = now.max(t);
                        board.poll(now, &mut out, &mut |m| all.push(m));
                    }
                    now = until;
                }
                Event::Button => {
                    let _ = board.button_pressed(now);
                }
            }
            if let Some(p) = board.sequencer().plan() {
                let steps = p.bracket().cycle_len() as u8;
                running_durations.extend((0..steps).map(|i| u64::from(p.step_on_time_us(i))));
            }
        }
        // Finish any capture on time, then stop.
        for _ in 0..10_000 {
            let Some(t) = board.next_deadline() else { break };
            if let Some(PulseCount::Continuous) = board.sequencer().plan().map(|p| p.config().pulses) {
                break;
            }
            now = now.max(t);
            board.poll(now, &mut out, &mut |m| all.push(m));
        }
        board.handle(HostMessage::Stop, now, &mut out, &mut |m| all.push(m));
        stops.push(now);
        prop_assert_eq!(out.dropped(), 0);

        // Counters agree with what was sent.
        let status = board.status(now);
        let rejected = all.iter().filter(|m| matches!(m, BoardMessage::Rejected { .. })).count();
        let bad = all.iter().filter(|m| matches!(m, BoardMessage::Fault(Fault::BadFrame(_)))).count();
        prop_assert_eq!(status.faults.rejected_commands as usize, rejected);
        prop_assert_eq!(status.faults.bad_frames as usize, bad);
        prop_assert_eq!(status.faults.late_edges, 0, "polls were on time");

        // Pulses: consecutive sequence numbers across captures.
        let seqs: Vec<u64> = all.iter().filter_map(|m| match m {
            BoardMessage::Pulse(p) => Some(p.seq),
            _ => None,
        }).collect();
        prop_assert_eq!(seqs.len() as u64, status.pulses_fired);
        prop_assert!(seqs.iter().enumerate().all(|(i, &s)| s == i as u64));

        // Pin timeline: flash only inside the trigger; on-time exact unless stopped.
        let mut camera = false;
        let mut lit: Option<u64> = None;
        let mut durations = all.iter().filter_map(|m| match m {
            BoardMessage::Pulse(p) if p.flags & (PULSE_FLASH_SKIPPED | PULSE_NO_FLASH) == 0 => {
                Some((p.t_flash_off_us - p.t_flash_on_us, u64::from(p.flash_on_us)))
            }
            _ => None,
        });
        for e in out.edges() {
            match (e.output, e.high) {
                (Output::CameraTrigger, high) => {
                    prop_assert!(lit.is_none(), "trigger changed with the flash lit");
                    camera = high;
                }
                (Output::Flash, true) => {
                    prop_assert!(camera, "flash lit with the trigger low");
                    lit = Some(e.t_device_us);
                }
                (Output::Flash, false) => {
                    let on = lit.take().unwrap();
                    let on_for = e.t_device_us - on;
                    prop_assert_eq!(durations.next(), Some((on_for, on_for)));
                    prop_assert!(on_for <= u64::from(LED_RIG_LIMITS.max_flash_on_us));
                    prop_assert!(
                        stops.contains(&e.t_device_us) || running_durations.contains(&on_for),
                        "flash on {} µs, planned {:?}", on_for, running_durations
                    );
                }
            }
        }
        prop_assert!(!camera && lit.is_none());
    }
}
