//! The flash as the simulated camera sees it: how much of a pulse's light fell inside each
//! exposure, and so how bright the frame is rendered.
//!
//! Contract:
//! - The meter sees every wire edge in order: camera-trigger edges with the [`FramePlan`] the
//!   [`CameraCore`](super::CameraCore) made of them (a rising edge that exposed), and flash edges
//!   (the light turning on and off, device µs).
//! - An exposure's window is `[start, start + exposure_us]` in device µs, `start` the plan's
//!   [`FramePlan::exposure_start_device_us`] (edge + trigger delay + jitter). Its lit time is the
//!   overlap of every flash-on interval with that window; its relative energy is
//!   `lit / reference_on_us` (the on-time of a full-energy pulse, the one the scene's radiometry
//!   describes). The LED's output is taken as proportional to its on-time (constant current, no
//!   turn-on ramp).
//! - A plan is released when its energy is final: at the trigger's falling edge (the firmware
//!   never has the flash on after the trigger falls), at the next rising edge, or at
//!   [`FlashMeter::finish`] when the wire ends. A flash still on at that moment counts up to it.
//! - Without a reference the meter is transparent: plans pass at once with energy 1, flash edges
//!   are ignored (captures without a flash model keep their old timing exactly).

use ellipso_protocol::Output;

use super::camera::FramePlan;
use super::wire::TriggerEdge;

/// Meters the flash for the exposures of one camera; see the [module docs](self).
#[derive(Debug, Clone)]
pub struct FlashMeter {
    reference_on_us: Option<f64>,
    exposure_us: f64,
    /// When the flash last turned on, if it is on.
    lit_since: Option<u64>,
    /// The exposure being metered.
    open: Option<Open>,
}

#[derive(Debug, Clone)]
struct Open {
    plan: FramePlan,
    start: f64,
    end: f64,
    lit_us: f64,
}

impl Open {
    fn add(&mut self, on: u64, off: u64) {
        let overlap = (off as f64).min(self.end) - (on as f64).max(self.start);
        self.lit_us += overlap.max(0.0);
    }
}

impl FlashMeter {
    /// A meter for exposures of `exposure_us`; `reference_on_us` is the full-energy on-time
    /// (`None`: no metering).
    pub fn new(reference_on_us: Option<u32>, exposure_us: u32) -> Self {
        Self {
            reference_on_us: reference_on_us.filter(|&r| r > 0).map(f64::from),
            exposure_us: f64::from(exposure_us),
            lit_since: None,
            open: None,
        }
    }

    /// One wire edge, with the plan the camera made of it (rising trigger edges that exposed);
    /// returns the plans whose energy is now final, in exposure order (at most two).
    pub fn on_edge(&mut self, edge: TriggerEdge, plan: Option<FramePlan>) -> Vec<FramePlan> {
        let mut out = Vec::new();
        if self.reference_on_us.is_none() {
            out.extend(plan);
            return out;
        }
        let t = edge.t_device_us;
        match (edge.output, edge.rising) {
            (Output::Flash, true) => {
                self.lit_since.get_or_insert(t);
            }
            (Output::Flash, false) => {
                if let (Some(on), Some(open)) = (self.lit_since.take(), self.open.as_mut()) {
                    open.add(on, t);
                }
            }
            (Output::CameraTrigger, rising) => {
                out.extend(self.close(t));
                if rising && let Some(plan) = plan {
                    let start = plan.exposure_start_device_us;
                    self.open = Some(Open {
                        plan,
                        start,
                        end: start + self.exposure_us,
                        lit_us: 0.0,
                    });
                }
            }
        }
        out
    }

    /// The wire ended: releases the exposure still open, its flash counted up to its window.
    pub fn finish(&mut self) -> Option<FramePlan> {
        let end = self.open.as_ref().map(|o| o.end)?;
        self.close(end.ceil().max(0.0) as u64)
    }

    /// Closes the open exposure at device time `t` (a flash still on counts up to `t`).
    fn close(&mut self, t: u64) -> Option<FramePlan> {
        let reference = self.reference_on_us?;
        let mut open = self.open.take()?;
        if let Some(on) = self.lit_since {
            open.add(on, t);
            // The light goes on; its next part belongs to whatever exposure comes next.
            self.lit_since = Some(t);
        }
        let mut plan = open.plan;
        plan.flash_lit_us = Some(open.lit_us);
        plan.flash_energy_rel = open.lit_us / reference;
        Some(plan)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::camera::{CameraCore, CameraFaults, SimCameraConfig};
    use crate::rig::clock::LinearClock;

    fn core() -> CameraCore {
        let clock = LinearClock::new(std::time::Instant::now(), 1_000_000, 0.0).unwrap();
        let mut config = SimCameraConfig::new(3, 4, clock);
        config.faults = CameraFaults::default();
        config.timing.exposure_us = 6_000;
        CameraCore::new(config, 64).unwrap()
    }

    /// Feeds a 6 ms exposure at `t0` with a flash from `t0 + on` to `t0 + off`.
    fn pulse(
        meter: &mut FlashMeter,
        core: &mut CameraCore,
        t0: u64,
        on: u64,
        off: u64,
    ) -> Vec<FramePlan> {
        let mut out = Vec::new();
        let rise = TriggerEdge::trigger(t0, true);
        out.extend(meter.on_edge(rise, core.on_edge(rise)));
        for edge in [
            TriggerEdge::flash(t0 + on, true),
            TriggerEdge::flash(t0 + off, false),
            TriggerEdge::trigger(t0 + 6_000, false),
        ] {
            out.extend(meter.on_edge(edge, core.on_edge(edge)));
        }
        out
    }

    #[test]
    fn the_energy_is_the_lit_time_inside_the_exposure_over_the_reference() {
        let mut meter = FlashMeter::new(Some(5_000), 6_000);
        let mut core = core();
        let t0 = 2_000_000;
        // Full pulse, a quarter, a sixteenth (313 µs of a 5000 µs reference).
        let full = pulse(&mut meter, &mut core, t0, 100, 5_100);
        let quarter = pulse(&mut meter, &mut core, t0 + 50_000, 100, 1_350);
        let sixteenth = pulse(&mut meter, &mut core, t0 + 100_000, 100, 413);
        for (plans, lit) in [(full, 5_000.0), (quarter, 1_250.0), (sixteenth, 313.0)] {
            assert_eq!(plans.len(), 1, "released at the trigger's fall");
            assert_eq!(plans[0].flash_lit_us, Some(lit));
            assert_eq!(plans[0].flash_energy_rel, lit / 5_000.0);
        }
        assert!(meter.finish().is_none());
    }

    #[test]
    fn light_outside_the_window_does_not_count() {
        let mut meter = FlashMeter::new(Some(1_000), 6_000);
        let mut core = core();
        // The exposure starts 6 µs after the edge (trigger delay): a flash lit at the edge
        // loses its first 6 µs; light after the trigger fell cannot reach a closed exposure.
        let plans = pulse(&mut meter, &mut core, 1_000, 0, 1_000);
        assert_eq!(plans[0].flash_lit_us, Some(994.0));
        // A skipped flash (no edges): energy 0.
        let rise = TriggerEdge::trigger(60_000, true);
        let mut out = meter.on_edge(rise, core.on_edge(rise));
        assert!(out.is_empty());
        out.extend(meter.finish());
        assert_eq!(out[0].flash_energy_rel, 0.0);
    }

    #[test]
    fn without_a_reference_plans_pass_at_once_at_full_energy() {
        let mut meter = FlashMeter::new(None, 6_000);
        let mut core = core();
        let rise = TriggerEdge::trigger(1_000, true);
        let out = meter.on_edge(rise, core.on_edge(rise));
        assert_eq!(out.len(), 1);
        assert_eq!((out[0].flash_energy_rel, out[0].flash_lit_us), (1.0, None));
    }

    #[test]
    fn an_exposure_left_open_is_released_by_the_next_rising_edge_or_the_end() {
        let mut meter = FlashMeter::new(Some(500), 6_000);
        let mut core = core();
        let first = TriggerEdge::trigger(1_000, true);
        assert!(meter.on_edge(first, core.on_edge(first)).is_empty());
        assert!(
            meter
                .on_edge(TriggerEdge::flash(1_100, true), None)
                .is_empty()
        );
        // The trigger's fall never came (lost): the next exposure releases the first, counting
        // the light up to then, clipped to the first exposure's window.
        let second = TriggerEdge::trigger(50_000, true);
        let out = meter.on_edge(second, core.on_edge(second));
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].flash_lit_us, Some(7_006.0 - 1_100.0));
        let last = meter.finish().unwrap();
        assert_eq!(last.exposure_index, 1);
        assert_eq!(
            last.flash_lit_us,
            Some(6_000.0),
            "on through its whole window"
        );
    }
}
