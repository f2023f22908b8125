//! Pairs camera frames with the flash pulses that lit them — or says why it cannot. Never guesses.
//!
//! Frames (64-bit frame id, host arrival time) and pulses (sequence number, trigger time on the
//! device clock) arrive in any order. Two pieces of evidence link them:
//! - **ids**: while nothing is lost between trigger and frame, `seq − frame_id` is a constant
//!   offset;
//! - **time**: with a device→host [`ClockFit`], a frame's arrival minus its pulse's trigger (mapped
//!   to host time) must lie in `[min_latency_us, max_latency_us]` (exposure + readout + transfer).
//!
//! The latency window narrows as pairs are confirmed: it is the range of the last 32 confirmed
//! latencies widened by `latency_tolerance_us` on each side, clipped to the configured window, so
//! a spurious frame arriving at an unusual delay cannot take a pulse whose own frame was lost.
//!
//! Rules:
//! 1. With a known offset, a frame pairs with pulse `frame_id + offset` if that pulse's timing is
//!    consistent (or no clock fit exists yet).
//! 2. With no offset yet, a frame pairs with the **unique** pending pulse inside the window
//!    (learned once any latency is known, configured before), which sets the offset. When the timing contradicts a known offset (the camera missed
//!    a trigger or fired a spurious frame), the offset is re-learned only from the unique pulse
//!    inside the *learned* window. Several candidates: ambiguous, no pair. After three unpaired
//!    frames in a row the offset and the learned window are forgotten and learned afresh.
//! 3. Without any clock fit, the first frame and first pulse define the offset (the acquisition
//!    syncs the clock before starting, so this is a fallback; missed triggers are then undetectable
//!    and the outcome says so by carrying no latency).
//! 4. Before any pair is confirmed, the configured window is the only timing evidence: a spurious
//!    frame inside it at the very start of a capture, while the real frame of that pulse is lost,
//!    cannot be told from a real one. Keep the configured window realistic (`for_capture`).
//! 5. A frame still unpaired `max_latency_us` after arriving is a `FrameWithoutPulse`; a pulse
//!    still unpaired when the camera has delivered frames from `pulse_timeout_us` after its
//!    trigger is a `PulseWithoutFrame` (so a camera lagging behind real time loses nothing); a repeated id
//!    or sequence number is a duplicate. Every such outcome is reported, none silently dropped.

use std::collections::{BTreeMap, BTreeSet, VecDeque};

use crate::link::clock::ClockFit;
use crate::link::time::{DeviceTimeUs, HostTimeUs};

/// Timing windows of the pairing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairingConfig {
    /// Shortest trigger→frame-arrival delay, µs (≥ the exposure).
    pub min_latency_us: f64,
    /// Longest trigger→frame-arrival delay, µs (exposure + readout + transfer + jitter). Keep it
    /// below one frame period so at most one pulse fits a frame.
    pub max_latency_us: f64,
    /// How long after its trigger a pulse may wait for its frame, µs.
    pub pulse_timeout_us: f64,
    /// Smallest half-width of the learned latency window, µs.
    pub latency_tolerance_us: f64,
}

impl PairingConfig {
    /// Windows for a capture: a frame arrives between half the exposure and
    /// `exposure + transfer_budget_us` after its trigger (readout + link transfer + host jitter;
    /// e.g. ~150 ms for a 5 MP 12-bit frame over GigE), capped below one frame period.
    pub fn for_capture(exposure_us: u32, frame_period_us: u32, transfer_budget_us: u32) -> Self {
        let period = f64::from(frame_period_us);
        let exposure = f64::from(exposure_us);
        Self {
            min_latency_us: exposure * 0.5,
            max_latency_us: (exposure + f64::from(transfer_budget_us))
                .min(period * 0.9)
                .max(exposure + 1_000.0),
            pulse_timeout_us: (period * 4.0).max(2_000_000.0),
            latency_tolerance_us: 10_000.0,
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
        /// Pulse sequence number.
        seq: u64,
        /// Arrival minus trigger (host µs), when a clock fit exists.
        latency_us: Option<f64>,
    },
    /// The frame matches no pulse.
    FrameWithoutPulse {
        /// Frame id.
        frame_id: u64,
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

#[derive(Debug, Clone, Copy)]
struct PendingPulse {
    t_trigger: DeviceTimeUs,
    t_host_recv: HostTimeUs,
}

/// Counts of every outcome so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct PairingCounts {
    /// Frames paired.
    pub paired: u64,
    /// Frames without pulse.
    pub frame_without_pulse: u64,
    /// Pulses without frame.
    pub pulse_without_frame: u64,
    /// Duplicate frames.
    pub duplicate_frames: u64,
    /// Duplicate pulses.
    pub duplicate_pulses: u64,
}

/// The pairing state machine.
#[derive(Debug, Clone)]
pub struct Pairer {
    config: PairingConfig,
    pulses: BTreeMap<u64, PendingPulse>,
    frames: BTreeMap<u64, HostTimeUs>,
    seen_pulses: BTreeSet<u64>,
    seen_frames: BTreeSet<u64>,
    offset: Option<i128>,
    latencies: VecDeque<f64>,
    expired_in_a_row: u32,
    frontier: Option<HostTimeUs>,
    counts: PairingCounts,
}

/// Consecutive unpaired frames after which the id offset is forgotten and re-learned from timing.
const RESET_AFTER_UNPAIRED: u32 = 3;

/// Confirmed latencies kept for the learned window.
const LATENCY_HISTORY: usize = 32;

impl Pairer {
    /// An empty pairer.
    pub fn new(config: PairingConfig) -> Self {
        Self {
            config,
            pulses: BTreeMap::new(),
            frames: BTreeMap::new(),
            seen_pulses: BTreeSet::new(),
            seen_frames: BTreeSet::new(),
            offset: None,
            latencies: VecDeque::with_capacity(LATENCY_HISTORY),
            expired_in_a_row: 0,
            frontier: None,
            counts: PairingCounts::default(),
        }
    }

    /// Counts so far.
    pub fn counts(&self) -> PairingCounts {
        self.counts
    }

    /// A pulse arrived.
    pub fn add_pulse(
        &mut self,
        seq: u64,
        t_trigger: DeviceTimeUs,
        t_host_recv: HostTimeUs,
        clock: Option<&ClockFit>,
    ) -> Vec<PairingOutcome> {
        if !self.seen_pulses.insert(seq) {
            return self.record(vec![PairingOutcome::DuplicatePulse { seq }]);
        }
        self.pulses.insert(
            seq,
            PendingPulse {
                t_trigger,
                t_host_recv,
            },
        );
        self.match_pending(clock)
    }

    /// A frame arrived.
    pub fn add_frame(
        &mut self,
        frame_id: u64,
        t_host_arrival: HostTimeUs,
        clock: Option<&ClockFit>,
    ) -> Vec<PairingOutcome> {
        if !self.seen_frames.insert(frame_id) {
            return self.record(vec![PairingOutcome::DuplicateFrame { frame_id }]);
        }
        self.frames.insert(frame_id, t_host_arrival);
        self.frontier = Some(
            self.frontier
                .map_or(t_host_arrival, |f| f.max(t_host_arrival)),
        );
        self.match_pending(clock)
    }

    /// Declares frames and pulses that waited too long as unpaired.
    pub fn expire(&mut self, now: HostTimeUs, clock: Option<&ClockFit>) -> Vec<PairingOutcome> {
        let mut out = Vec::new();
        let now_f = now.0 as f64;
        let max_latency = self.config.max_latency_us;
        let stale_frames: Vec<u64> = self
            .frames
            .iter()
            .filter(|(_, t)| now_f - t.0 as f64 > max_latency)
            .map(|(&id, _)| id)
            .collect();
        for frame_id in stale_frames {
            self.frames.remove(&frame_id);
            out.push(PairingOutcome::FrameWithoutPulse { frame_id });
            self.expired_in_a_row += 1;
        }
        if self.expired_in_a_row >= RESET_AFTER_UNPAIRED {
            // ids and timing keep disagreeing: start over — the learned window too, since an
            // outlier among the first confirmed latencies would otherwise exclude every frame
            self.offset = None;
            self.latencies.clear();
            self.expired_in_a_row = 0;
        }
        // A pulse is frameless once the camera has delivered frames from well after it: the
        // frontier is the latest frame arrival seen (cameras deliver in order). Using it rather
        // than `now` keeps a camera that lags behind real time (a slow USB stack, a simulator
        // rendering) from having its pulses expired before their frames arrive. If the camera
        // delivers nothing more, `finish` reports the pulses still pending.
        let timeout = self.config.pulse_timeout_us;
        let frontier = self.frontier.map_or(f64::NEG_INFINITY, |t| t.0 as f64);
        let stale_pulses: Vec<u64> = self
            .pulses
            .iter()
            .filter(|(_, p)| {
                let t0 = clock.map_or(p.t_host_recv.0 as f64, |c| c.host_us(p.t_trigger));
                frontier - t0 > timeout
            })
            .map(|(&s, _)| s)
            .collect();
        for seq in stale_pulses {
            self.pulses.remove(&seq);
            out.push(PairingOutcome::PulseWithoutFrame { seq });
        }
        self.record(out)
    }

    /// Ends the capture: everything still pending is unpaired.
    pub fn finish(&mut self) -> Vec<PairingOutcome> {
        let mut out: Vec<PairingOutcome> = std::mem::take(&mut self.frames)
            .into_keys()
            .map(|frame_id| PairingOutcome::FrameWithoutPulse { frame_id })
            .collect();
        out.extend(
            std::mem::take(&mut self.pulses)
                .into_keys()
                .map(|seq| PairingOutcome::PulseWithoutFrame { seq }),
        );
        self.record(out)
    }

    fn latency(
        &self,
        arrival: HostTimeUs,
        pulse: &PendingPulse,
        clock: Option<&ClockFit>,
    ) -> Option<f64> {
        clock.map(|c| arrival.0 as f64 - c.host_us(pulse.t_trigger))
    }

    /// The configured latency window.
    fn configured(&self) -> (f64, f64) {
        (self.config.min_latency_us, self.config.max_latency_us)
    }

    /// The window learned from confirmed pairs: their range widened by the tolerance, clipped to
    /// the configured window; `None` before any pair carried a latency.
    fn learned(&self) -> Option<(f64, f64)> {
        if self.latencies.is_empty() {
            return None;
        }
        let (lo, hi) = self.configured();
        let seen_lo = self.latencies.iter().copied().fold(f64::INFINITY, f64::min);
        let seen_hi = self
            .latencies
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        let tol = self.config.latency_tolerance_us;
        Some(((seen_lo - tol).max(lo), (seen_hi + tol).min(hi)))
    }

    fn inside(latency: Option<f64>, (lo, hi): (f64, f64)) -> bool {
        latency.is_none_or(|l| l >= lo && l <= hi)
    }

    /// Pending pulses whose timing puts them inside `window` for a frame arriving at `arrival`.
    fn candidates(
        &self,
        arrival: HostTimeUs,
        clock: Option<&ClockFit>,
        window: (f64, f64),
    ) -> Vec<(u64, Option<f64>)> {
        self.pulses
            .iter()
            .map(|(&s, p)| (s, self.latency(arrival, p, clock)))
            .filter(|(_, l)| Self::inside(*l, window))
            .collect()
    }

    /// Pairs whatever can be paired now.
    fn match_pending(&mut self, clock: Option<&ClockFit>) -> Vec<PairingOutcome> {
        let mut out = Vec::new();
        let frame_ids: Vec<u64> = self.frames.keys().copied().collect();
        for frame_id in frame_ids {
            let Some(&arrival) = self.frames.get(&frame_id) else {
                continue;
            };
            let window = self.learned().unwrap_or(self.configured());
            let Some(off) = self.offset else {
                // no offset yet: the unique pulse inside the window — learned if any latency is
                // known, else configured (rule 2) — or without a clock the first pulse (rule 3)
                let first = match clock {
                    Some(_) => match self.candidates(arrival, clock, window)[..] {
                        [one] => Some(one),
                        _ => None,
                    },
                    None => self.pulses.keys().next().map(|&s| (s, None)),
                };
                if let Some((seq, latency)) = first {
                    self.offset = Some(seq as i128 - frame_id as i128);
                    self.pair(frame_id, seq, latency, &mut out);
                }
                continue;
            };
            // rule 1: the offset's pulse, if its timing agrees
            if let Ok(seq) = u64::try_from(frame_id as i128 + off) {
                match self.pulses.get(&seq) {
                    Some(p) => {
                        let latency = self.latency(arrival, p, clock);
                        if Self::inside(latency, window) {
                            self.pair(frame_id, seq, latency, &mut out);
                            continue;
                        }
                    }
                    // not here yet: wait for it rather than take another pulse
                    None if !self.seen_pulses.contains(&seq) => continue,
                    None => {}
                }
            }
            // the ids contradict the timing (a missed trigger or a spurious frame): re-learn the
            // offset from the unique pulse inside the *learned* window only; before any latency
            // is known, never re-learn (the frame will expire unpaired instead)
            if let Some(learned) = self.learned()
                && let [(seq, latency)] = self.candidates(arrival, clock, learned)[..]
            {
                self.offset = Some(seq as i128 - frame_id as i128);
                self.pair(frame_id, seq, latency, &mut out);
            }
        }
        self.record(out)
    }

    fn pair(
        &mut self,
        frame_id: u64,
        seq: u64,
        latency_us: Option<f64>,
        out: &mut Vec<PairingOutcome>,
    ) {
        if let Some(l) = latency_us {
            if self.latencies.len() == LATENCY_HISTORY {
                self.latencies.pop_front();
            }
            self.latencies.push_back(l);
        }
        self.expired_in_a_row = 0;
        self.frames.remove(&frame_id);
        self.pulses.remove(&seq);
        out.push(PairingOutcome::Paired {
            frame_id,
            seq,
            latency_us,
        });
    }

    fn record(&mut self, out: Vec<PairingOutcome>) -> Vec<PairingOutcome> {
        for o in &out {
            match o {
                PairingOutcome::Paired { .. } => self.counts.paired += 1,
                PairingOutcome::FrameWithoutPulse { .. } => self.counts.frame_without_pulse += 1,
                PairingOutcome::PulseWithoutFrame { .. } => self.counts.pulse_without_frame += 1,
                PairingOutcome::DuplicateFrame { .. } => self.counts.duplicate_frames += 1,
                PairingOutcome::DuplicatePulse { .. } => self.counts.duplicate_pulses += 1,
            }
        }
        out
    }
}

#[cfg(test)]
mod tests;
