//! Pairs camera frames with the flash pulses that lit them — or says why it cannot. Never guesses.
//!
//! Frames ([`FrameArrival`]: 64-bit id, host arrival time, the camera's exposure timestamp if it
//! has one) and pulses ([`Pulse`]: sequence number, trigger time on the board's clock) arrive in
//! any order. A device→host [`ClockFit`] puts every trigger on the host clock; without one no
//! timing can be checked and nothing is paired. Two kinds of timing evidence exist:
//!
//! - **Exposure time** (`basis: camera_time`). When the camera stamps its frames and its counter
//!   has been latched against the host clock ([`Pairer::add_camera_clock_sample`]), a frame's
//!   exposure start maps to host time within a small, known uncertainty
//!   ([`camera_time::CameraTimeMap`]). Its pulse is the one pulse whose trigger lies in
//!   `[exposure − tol − max_exposure_delay, exposure + tol]`. This is used only while that
//!   interval is shorter than half the pulse spacing, so at most one pulse can fall in it whatever
//!   the frame rate or delivery delay. Each pair re-anchors the map on the pulse's trigger.
//! - **Arrival time** (`basis: arrival_time`). Otherwise the frame's arrival minus a trigger must
//!   lie in the latency window: the range of the last 32 **measured** latencies (of confirmed
//!   pairs) widened by a tolerance, or before any measurement the configured a-priori bounds
//!   (exposure/2 … exposure + transfer budget, never derived from the interval). The window is used
//!   only while it is **narrower than the pulse spacing**, so at most one pulse — received or
//!   lost — can fall in it; when it is wider, frames are reported `ambiguous`, never guessed.
//!   Ids back the timing up: a frame pairs with the unique pulse in the window when
//!   `seq − frame_id` equals the current id offset, or when another pending frame independently
//!   implies the same new offset (a missed trigger shifts every later frame; a frame delayed on
//!   the host shifts only itself, which then stays unpaired).
//!
//! Outcomes: a frame still unpaired once frames from `4 × spacing` later have arrived is a
//! [`PairingOutcome::FrameWithoutPulse`] with its [`Unpaired`] reason; a pulse still unpaired once
//! frames from `pulse_timeout_us` after its trigger have arrived is a
//! [`PairingOutcome::PulseWithoutFrame`] (the camera's own arrival stamps are the clock, so a
//! camera lagging behind real time loses nothing); a repeated id or sequence number is a
//! duplicate; [`Pairer::finish`] reports everything still pending. Every frame and every pulse is
//! accounted for exactly once.
//!
//! API: a [`Pulse`] goes in whole and comes back whole in [`PairingOutcome::Paired`], so a field
//! added to it reaches the session without touching the pairing rules.

pub mod camera_time;

use std::collections::{BTreeMap, BTreeSet, VecDeque};

use camera_time::CameraTimeMap;

use crate::camera::CameraClockSample;
use crate::link::clock::ClockFit;
use ellipso_session::time::{DeviceTimeUs, HostTimeUs};

/// Timing bounds of the pairing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairingConfig {
    /// A-priori shortest trigger → frame-arrival delay, µs (≤ the exposure).
    pub min_latency_us: f64,
    /// A-priori longest trigger → frame-arrival delay, µs (exposure + readout + transfer +
    /// jitter): an honest bound for the camera and link, independent of the frame rate.
    pub max_latency_us: f64,
    /// Closest two pulses can be, µs (the board's frame period).
    pub min_pulse_spacing_us: f64,
    /// Longest trigger edge → exposure start, µs (camera trigger delay and jitter).
    pub max_exposure_delay_us: f64,
    /// How long after its trigger a pulse may wait for its frame, µs (≥ `max_latency_us`).
    pub pulse_timeout_us: f64,
    /// Margin around the measured latencies, µs (capped at a fifth of the pulse spacing).
    pub latency_tolerance_us: f64,
}

impl PairingConfig {
    /// Bounds for a capture: a frame arrives between half the exposure and
    /// `exposure + transfer_budget_us` after its trigger (readout + link transfer + host jitter;
    /// e.g. ~150 ms for a 5 MP 12-bit frame over GigE), pulses are `frame_period_us` apart, and
    /// an exposure starts within 2 ms of its trigger edge.
    pub fn for_capture(exposure_us: u32, frame_period_us: u32, transfer_budget_us: u32) -> Self {
        let period = f64::from(frame_period_us.max(1));
        let exposure = f64::from(exposure_us);
        let max_latency_us = exposure + f64::from(transfer_budget_us).max(1_000.0);
        Self {
            min_latency_us: exposure * 0.5,
            max_latency_us,
            min_pulse_spacing_us: period,
            max_exposure_delay_us: 2_000.0,
            pulse_timeout_us: (period * 4.0).max(2.0 * max_latency_us).max(2_000_000.0),
            latency_tolerance_us: 10_000.0,
        }
    }
}

/// One flash pulse as the board reported it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pulse {
    /// Sequence number.
    pub seq: u64,
    /// Trigger rising edge, board clock.
    pub t_trigger: DeviceTimeUs,
    /// When its report was decoded on the host.
    pub t_host_recv: HostTimeUs,
}

/// One frame as the camera delivered it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameArrival {
    /// Monotonic frame id.
    pub frame_id: u64,
    /// When it was complete on the host.
    pub t_host_arrival: HostTimeUs,
    /// Exposure start on the camera's own counter, ns, if the camera stamps frames.
    pub t_camera_ns: Option<u64>,
}

/// Which evidence a pair rests on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PairBasis {
    /// The frame's exposure timestamp, through the camera clock map.
    CameraTime,
    /// The frame's arrival time inside the latency window, backed by ids.
    ArrivalTime,
}

/// Why a frame was not paired.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unpaired {
    /// No clock model of the trigger board: no timing can be checked.
    NoClock,
    /// No pulse was triggered at its exposure (or within its latency window).
    NoPulse,
    /// Its timing fits several pulses: no usable exposure timestamp, and the latency window is
    /// not narrower than the pulse spacing.
    Ambiguous,
    /// The one pulse at its time already has a frame (a duplicate or stray exposure).
    PulseTaken,
    /// Its arrival time points at one pulse, but the id offset that implies was not confirmed
    /// by a second frame (a frame delayed on the host, or too few frames).
    Unconfirmed,
}

impl Unpaired {
    /// Stable snake_case name (session logs).
    pub fn as_str(self) -> &'static str {
        match self {
            Unpaired::NoClock => "no_clock",
            Unpaired::NoPulse => "no_pulse",
            Unpaired::Ambiguous => "ambiguous",
            Unpaired::PulseTaken => "pulse_taken",
            Unpaired::Unconfirmed => "unconfirmed",
        }
    }
}

/// One decision of the pairer.
#[derive(Debug, Clone, PartialEq)]
pub enum PairingOutcome {
    /// The frame was lit by the pulse.
    Paired {
        /// Frame id.
        frame_id: u64,
        /// The pulse, as it was added.
        pulse: Pulse,
        /// Arrival minus trigger (host µs).
        latency_us: f64,
        /// The evidence.
        basis: PairBasis,
    },
    /// The frame matches no pulse.
    FrameWithoutPulse {
        /// Frame id.
        frame_id: u64,
        /// Why.
        reason: Unpaired,
    },
    /// The pulse produced no frame.
    PulseWithoutFrame {
        /// Pulse sequence number.
        seq: u64,
    },
    /// A frame id seen before.
    DuplicateFrame {
        /// Frame id.
        frame_id: u64,
    },
    /// A pulse sequence number seen before.
    DuplicatePulse {
        /// Pulse sequence number.
        seq: u64,
    },
}

/// Counts of every outcome so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct PairingCounts {
    /// Frames paired.
    pub paired: u64,
    /// Of those, on exposure timestamps.
    pub paired_on_camera_time: u64,
    /// Frames without pulse.
    pub frame_without_pulse: u64,
    /// Pulses without frame.
    pub pulse_without_frame: u64,
    /// Duplicate frames.
    pub duplicate_frames: u64,
    /// Duplicate pulses.
    pub duplicate_pulses: u64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PulseStatus {
    Pending,
    Paired,
    Expired,
}

#[derive(Debug, Clone, Copy)]
struct KnownPulse {
    pulse: Pulse,
    status: PulseStatus,
}

#[derive(Debug, Clone, Copy)]
struct PendingFrame {
    frame: FrameArrival,
    why: Unpaired,
}

enum Decision {
    Pair(u64, PairBasis),
    Wait(Unpaired),
    Reject(Unpaired),
}

/// Confirmed latencies kept for the measured window.
const LATENCY_HISTORY: usize = 32;
/// Floor of the exposure-time tolerance, µs (clock-fit bias the residuals cannot show).
const EXPOSURE_TOLERANCE_FLOOR_US: f64 = 500.0;
/// A frame waits for its pulse (or a confirming frame) until frames this many pulse spacings
/// later have arrived.
const HOLD_SPACINGS: f64 = 4.0;

/// The pairing state machine.
#[derive(Debug, Clone)]
pub struct Pairer {
    config: PairingConfig,
    pulses: BTreeMap<u64, KnownPulse>,
    seen_pulses: BTreeSet<u64>,
    frames: BTreeMap<u64, PendingFrame>,
    seen_frames: BTreeSet<u64>,
    offset: Option<i128>,
    latencies: VecDeque<f64>,
    camera: CameraTimeMap,
    frontier: Option<HostTimeUs>,
    counts: PairingCounts,
}

impl Pairer {
    /// An empty pairer.
    pub fn new(config: PairingConfig) -> Self {
        Self {
            config,
            pulses: BTreeMap::new(),
            seen_pulses: BTreeSet::new(),
            frames: BTreeMap::new(),
            seen_frames: BTreeSet::new(),
            offset: None,
            latencies: VecDeque::with_capacity(LATENCY_HISTORY),
            camera: CameraTimeMap::default(),
            frontier: None,
            counts: PairingCounts::default(),
        }
    }

    /// Counts so far.
    pub fn counts(&self) -> PairingCounts {
        self.counts
    }

    /// The latency window in force, µs: measured (see the module doc) or a-priori.
    pub fn latency_window_us(&self) -> (f64, f64) {
        if self.latencies.is_empty() {
            return (self.config.min_latency_us, self.config.max_latency_us);
        }
        let seen_lo = self.latencies.iter().copied().fold(f64::INFINITY, f64::min);
        let seen_hi = self
            .latencies
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        let tol = self
            .config
            .latency_tolerance_us
            .min(0.2 * self.config.min_pulse_spacing_us);
        ((seen_lo - tol).max(0.0), seen_hi + tol)
    }

    /// A reading of the camera's timestamp counter against the host clock.
    pub fn add_camera_clock_sample(&mut self, sample: &CameraClockSample) {
        self.camera.add_latch(sample);
    }

    /// A pulse arrived.
    pub fn add_pulse(&mut self, pulse: Pulse, clock: Option<&ClockFit>) -> Vec<PairingOutcome> {
        if !self.seen_pulses.insert(pulse.seq) {
            return self.record(vec![PairingOutcome::DuplicatePulse { seq: pulse.seq }]);
        }
        self.pulses.insert(
            pulse.seq,
            KnownPulse {
                pulse,
                status: PulseStatus::Pending,
            },
        );
        self.match_pending(clock)
    }

    /// A frame arrived.
    pub fn add_frame(
        &mut self,
        frame: FrameArrival,
        clock: Option<&ClockFit>,
    ) -> Vec<PairingOutcome> {
        if !self.seen_frames.insert(frame.frame_id) {
            return self.record(vec![PairingOutcome::DuplicateFrame {
                frame_id: frame.frame_id,
            }]);
        }
        self.frames.insert(
            frame.frame_id,
            PendingFrame {
                frame,
                why: Unpaired::NoPulse,
            },
        );
        self.frontier = Some(
            self.frontier
                .map_or(frame.t_host_arrival, |f| f.max(frame.t_host_arrival)),
        );
        self.match_pending(clock)
    }

    /// Declares frames and pulses that waited too long as unpaired (see the module doc).
    pub fn expire(&mut self, clock: Option<&ClockFit>) -> Vec<PairingOutcome> {
        let mut out = Vec::new();
        let Some(frontier) = self.frontier.map(|t| t.0 as f64) else {
            return out;
        };
        let hold = HOLD_SPACINGS * self.config.min_pulse_spacing_us;
        let stale: Vec<u64> = self
            .frames
            .iter()
            .filter(|(_, f)| frontier - f.frame.t_host_arrival.0 as f64 > hold)
            .map(|(&id, _)| id)
            .collect();
        for frame_id in stale {
            if let Some(f) = self.frames.remove(&frame_id) {
                out.push(PairingOutcome::FrameWithoutPulse {
                    frame_id,
                    reason: f.why,
                });
            }
        }
        let timeout = self.config.pulse_timeout_us;
        for p in self.pulses.values_mut() {
            if p.status == PulseStatus::Pending
                && frontier - host_trigger(&p.pulse, clock) > timeout
            {
                p.status = PulseStatus::Expired;
                out.push(PairingOutcome::PulseWithoutFrame { seq: p.pulse.seq });
            }
        }
        // pulses long settled are only needed for duplicate detection (`seen_pulses`)
        let keep_after = frontier - 4.0 * timeout;
        self.pulses.retain(|_, p| {
            p.status == PulseStatus::Pending || host_trigger(&p.pulse, clock) > keep_after
        });
        self.record(out)
    }

    /// Ends the capture: a last matching pass, then everything still pending is unpaired.
    pub fn finish(&mut self, clock: Option<&ClockFit>) -> Vec<PairingOutcome> {
        let mut out = self.match_pending(clock);
        let mut rest: Vec<PairingOutcome> = std::mem::take(&mut self.frames)
            .into_iter()
            .map(|(frame_id, f)| PairingOutcome::FrameWithoutPulse {
                frame_id,
                reason: f.why,
            })
            .collect();
        for p in self.pulses.values_mut() {
            if p.status == PulseStatus::Pending {
                p.status = PulseStatus::Expired;
                rest.push(PairingOutcome::PulseWithoutFrame { seq: p.pulse.seq });
            }
        }
        out.extend(self.record(rest));
        out
    }

    /// Pulses (any status) whose mapped trigger lies in `[lo, hi]`, host µs.
    fn triggered_in(&self, lo: f64, hi: f64, clock: &ClockFit) -> Vec<KnownPulse> {
        self.pulses
            .values()
            .filter(|p| {
                let t = clock.host_us(p.pulse.t_trigger);
                t >= lo && t <= hi
            })
            .copied()
            .collect()
    }

    /// The exposure-time decision, `None` when the frame has no usable exposure timestamp.
    fn decide_on_camera_time(&self, frame: &FrameArrival, clock: &ClockFit) -> Option<Decision> {
        let (exposure, uncertainty) = self.camera.host_us(frame.t_camera_ns?)?;
        let tol = uncertainty + 3.0 * clock.rms_us + EXPOSURE_TOLERANCE_FLOOR_US;
        let (lo, hi) = (
            exposure - tol - self.config.max_exposure_delay_us,
            exposure + tol,
        );
        if hi - lo >= 0.5 * self.config.min_pulse_spacing_us {
            return None;
        }
        Some(match self.triggered_in(lo, hi, clock)[..] {
            [] => Decision::Wait(Unpaired::NoPulse),
            [p] if p.status == PulseStatus::Pending => {
                Decision::Pair(p.pulse.seq, PairBasis::CameraTime)
            }
            [p] if p.status == PulseStatus::Paired => Decision::Reject(Unpaired::PulseTaken),
            [_] => Decision::Reject(Unpaired::NoPulse),
            _ => Decision::Reject(Unpaired::Ambiguous),
        })
    }

    /// The unique pending pulse inside the latency window of `frame`, or why there is none.
    fn arrival_candidate(&self, frame: &FrameArrival, clock: &ClockFit) -> Result<u64, Decision> {
        let (wlo, whi) = self.latency_window_us();
        if whi - wlo >= self.config.min_pulse_spacing_us {
            return Err(Decision::Wait(Unpaired::Ambiguous));
        }
        let arrival = frame.t_host_arrival.0 as f64;
        match self.triggered_in(arrival - whi, arrival - wlo, clock)[..] {
            [] => Err(Decision::Wait(Unpaired::NoPulse)),
            [p] if p.status == PulseStatus::Pending => Ok(p.pulse.seq),
            [p] if p.status == PulseStatus::Paired => Err(Decision::Reject(Unpaired::PulseTaken)),
            [_] => Err(Decision::Reject(Unpaired::NoPulse)),
            _ => Err(Decision::Wait(Unpaired::Ambiguous)),
        }
    }

    fn decide(&self, frame: &FrameArrival, clock: Option<&ClockFit>) -> Decision {
        let Some(clock) = clock else {
            return Decision::Wait(Unpaired::NoClock);
        };
        if let Some(d) = self.decide_on_camera_time(frame, clock) {
            return d;
        }
        let seq = match self.arrival_candidate(frame, clock) {
            Ok(seq) => seq,
            Err(d) => return d,
        };
        let implied = seq as i128 - frame.frame_id as i128;
        if self.offset == Some(implied) {
            return Decision::Pair(seq, PairBasis::ArrivalTime);
        }
        // a new offset needs a second frame that implies it independently
        let confirmed = self.frames.values().any(|g| {
            g.frame.frame_id != frame.frame_id
                && self
                    .arrival_candidate(&g.frame, clock)
                    .is_ok_and(|s| s as i128 - g.frame.frame_id as i128 == implied)
        });
        if confirmed {
            Decision::Pair(seq, PairBasis::ArrivalTime)
        } else {
            Decision::Wait(Unpaired::Unconfirmed)
        }
    }

    /// Pairs whatever can be paired now.
    fn match_pending(&mut self, clock: Option<&ClockFit>) -> Vec<PairingOutcome> {
        let mut out = Vec::new();
        let ids: Vec<u64> = self.frames.keys().copied().collect();
        for frame_id in ids {
            let Some(pending) = self.frames.get(&frame_id).copied() else {
                continue;
            };
            match self.decide(&pending.frame, clock) {
                Decision::Pair(seq, basis) => {
                    if let Some(clock) = clock {
                        self.pair(&pending.frame, seq, basis, clock, &mut out);
                    }
                }
                Decision::Wait(why) => {
                    if let Some(f) = self.frames.get_mut(&frame_id) {
                        f.why = why;
                    }
                }
                Decision::Reject(reason) => {
                    self.frames.remove(&frame_id);
                    out.push(PairingOutcome::FrameWithoutPulse { frame_id, reason });
                }
            }
        }
        self.record(out)
    }

    fn pair(
        &mut self,
        frame: &FrameArrival,
        seq: u64,
        basis: PairBasis,
        clock: &ClockFit,
        out: &mut Vec<PairingOutcome>,
    ) {
        let Some(known) = self.pulses.get_mut(&seq) else {
            return;
        };
        known.status = PulseStatus::Paired;
        let pulse = known.pulse;
        let trigger = clock.host_us(pulse.t_trigger);
        let latency_us = frame.t_host_arrival.0 as f64 - trigger;
        if self.latencies.len() == LATENCY_HISTORY {
            self.latencies.pop_front();
        }
        self.latencies.push_back(latency_us);
        self.offset = Some(seq as i128 - frame.frame_id as i128);
        // Only exposure-time pairs re-anchor the camera clock: they are derived from the map
        // itself, so an error can never exceed the tolerance (module doc).
        if basis == PairBasis::CameraTime
            && let Some(ns) = frame.t_camera_ns
        {
            let half_delay = 0.5 * self.config.max_exposure_delay_us;
            self.camera.add_exposure(
                ns,
                trigger + half_delay,
                half_delay + 3.0 * clock.rms_us + EXPOSURE_TOLERANCE_FLOOR_US * 0.5,
            );
        }
        self.frames.remove(&frame.frame_id);
        out.push(PairingOutcome::Paired {
            frame_id: frame.frame_id,
            pulse,
            latency_us,
            basis,
        });
    }

    fn record(&mut self, out: Vec<PairingOutcome>) -> Vec<PairingOutcome> {
        for o in &out {
            match o {
                PairingOutcome::Paired { basis, .. } => {
                    self.counts.paired += 1;
                    if *basis == PairBasis::CameraTime {
                        self.counts.paired_on_camera_time += 1;
                    }
                }
                PairingOutcome::FrameWithoutPulse { .. } => self.counts.frame_without_pulse += 1,
                PairingOutcome::PulseWithoutFrame { .. } => self.counts.pulse_without_frame += 1,
                PairingOutcome::DuplicateFrame { .. } => self.counts.duplicate_frames += 1,
                PairingOutcome::DuplicatePulse { .. } => self.counts.duplicate_pulses += 1,
            }
        }
        out
    }
}

/// A pulse's trigger on the host clock (its receive time without a clock fit).
fn host_trigger(p: &Pulse, clock: Option<&ClockFit>) -> f64 {
    clock.map_or(p.t_host_recv.0 as f64, |c| c.host_us(p.t_trigger))
}

#[cfg(test)]
mod tests;
