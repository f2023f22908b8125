//! What the test flashes of `ellipso rig check --fire` say about the rig, read back from the
//! temporary session the capture recorded: per flash, whether it paired with a frame (and why
//! not), where the flash fell in the exposure, the frame's black level and saturation; then the
//! fixes ([`FlashCheck::fixes`]).
//!
//! Timing. The board reports each pulse's trigger edge and flash on / off on its own clock, so
//! "flash on +100 µs for 2000 µs after the trigger" is exact. Where the exposure starts is the
//! camera's side: a camera that stamps its frames (GigE Vision, the simulator) gives the
//! exposure start on its counter, mapped to host time through its tightest latch sample
//! (`camera_clock` events), and the trigger edge maps to host time through the board's clock fit.
//! Their difference is the camera's trigger delay, uncertain by the latch's half-width, the clock
//! fit's rms, and [`DRIFT_BOUND`] times the camera time since the latch (the pairing's own bound,
//! `acquire::pairing::camera_time`). A flash is called outside the exposure only when it is
//! outside by more than that uncertainty; within it the flash is "inside (±U µs)".
//!
//! Thresholds, and why:
//! - black level: the 1st percentile of the raw samples. In a flash-lit scene the background
//!   and the shadows far from the flash get almost no light, so the darkest 1 % is the sensor's
//!   black level plus any ambient light. It reads 0 when the camera's offset clips the noise
//!   floor (the fit's noise model then sees truncated noise) — a note, as only the darkest
//!   surfaces suffer; above [`AMBIENT_SHARE`] of full scale the "dark" pixels are lit by
//!   something other than the flash — a fix.
//! - saturation: samples at full scale (`2^bit_depth − 1`). A flash highlight on a glossy object
//!   covers far less than 1 % of the frame (a 20 mm ball at 0.3 m: a few hundred pixels of 5 MP,
//!   under 0.01 %), so up to [`SATURATED_SHARE`] at full scale is a clipped highlight (a note:
//!   those pixels carry no polarisation), and more is an over-exposed frame (a fix).

use std::collections::BTreeMap;

use ellipso_rig::acquire::pairing::camera_time::DRIFT_BOUND;
use ellipso_rig::link::clock::ClockFit;
use ellipso_session::events::SessionEvent;
use ellipso_session::reader::Session;

/// Share of pixels at full scale above which a frame is over-exposed rather than showing a
/// clipped highlight (module doc).
pub const SATURATED_SHARE: f64 = 0.01;
/// Black level, as a share of full scale, above which the darkest pixels are lit by ambient
/// light (module doc): a quarter of the range is far above any sensor's offset (an IMX250 at
/// 12 bits sits near 240 DN, 6 %).
pub const AMBIENT_SHARE: f64 = 0.25;

/// Where a paired flash fell in its frame's exposure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timing {
    /// Flash on after the trigger edge, µs (board clock).
    pub flash_on_us: f64,
    /// Flash off after the trigger edge, µs (board clock).
    pub flash_off_us: f64,
    /// The frame's exposure, µs.
    pub exposure_us: f64,
    /// Trigger edge → exposure start, µs, and its uncertainty (`None` without camera
    /// timestamps).
    pub exposure_start_us: Option<(f64, f64)>,
}

impl Timing {
    /// Flash on before the exposure started (by more than the uncertainty).
    pub fn starts_early(&self) -> bool {
        self.exposure_start_us
            .is_some_and(|(d, u)| self.flash_on_us < d - u)
    }

    /// Flash still on after the exposure ended (by more than the uncertainty; the trigger high
    /// time when the exposure start is not measured).
    pub fn ends_late(&self) -> bool {
        let (d, u) = self.exposure_start_us.unwrap_or((0.0, 0.0));
        self.flash_off_us > d + self.exposure_us + u
    }
}

/// What one frame's samples say.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Levels {
    /// The 1st percentile of the samples, DN.
    pub black_dn: u16,
    /// Share of samples at full scale.
    pub saturated_share: f64,
    /// Full scale, DN.
    pub full_scale_dn: u16,
}

/// One fired flash.
#[derive(Debug, Clone, PartialEq)]
pub struct Flash {
    /// Pulse sequence number.
    pub seq: u64,
    /// Its frame, if paired.
    pub frame_id: Option<u64>,
    /// Where the flash fell (paired flashes).
    pub timing: Option<Timing>,
    /// The frame's levels (paired frames that could be read).
    pub levels: Option<Levels>,
    /// Why the frame could not be read, if it could not.
    pub unreadable: Option<String>,
}

/// Everything the test flashes said.
#[derive(Debug, Clone, PartialEq)]
pub struct FlashCheck {
    /// Flashes the check asked for.
    pub asked: u32,
    /// Every pulse the board reported, in order.
    pub flashes: Vec<Flash>,
    /// Frames that came without a flash: (frame id, why).
    pub frames_without_flash: Vec<(u64, String)>,
}

/// The 1st percentile and the full-scale share of `pixels` at `bit_depth` bits.
pub fn levels(pixels: &[u16], bit_depth: u8) -> Levels {
    let full_scale_dn = ((1u32 << bit_depth.clamp(1, 16)) - 1) as u16;
    let mut sorted = pixels.to_vec();
    sorted.sort_unstable();
    let black_dn = sorted.get(sorted.len() / 100).copied().unwrap_or(0);
    let saturated = pixels.iter().filter(|&&p| p >= full_scale_dn).count();
    Levels {
        black_dn,
        saturated_share: saturated as f64 / pixels.len().max(1) as f64,
        full_scale_dn,
    }
}

/// Reads the check out of `session`, with `clock` the capture's final board clock fit (the
/// session's `clock_fit` event when `None`).
pub fn read(session: &Session, asked: u32, clock: Option<&ClockFit>) -> FlashCheck {
    let mut fit = clock.map(|c| (c.gain, c.offset_us, c.rms_us));
    let mut latch: Option<(f64, f64, f64)> = None; // camera µs, host µs, half-width µs
    let mut pulses = BTreeMap::new();
    let mut frames = BTreeMap::new();
    let mut pairs = BTreeMap::new();
    let mut frames_without_flash = Vec::new();
    for e in &session.events {
        match e {
            SessionEvent::ClockFit {
                gain,
                offset_us,
                rms_us,
                ..
            } if clock.is_none() => fit = Some((*gain, *offset_us, *rms_us)),
            SessionEvent::CameraClock {
                t_camera_ns,
                t_host_before_us,
                t_host_after_us,
                ..
            } => {
                let half = t_host_after_us.0.saturating_sub(t_host_before_us.0) as f64 / 2.0;
                if latch.is_none_or(|(_, _, h)| half < h) {
                    latch = Some((
                        *t_camera_ns as f64 / 1e3,
                        t_host_before_us.0 as f64 + half,
                        half,
                    ));
                }
            }
            SessionEvent::Pulse {
                seq,
                t_trigger_device_us,
                t_flash_on_device_us,
                t_flash_off_device_us,
                ..
            } => {
                let on = t_flash_on_device_us.0.wrapping_sub(t_trigger_device_us.0);
                let off = t_flash_off_device_us.0.wrapping_sub(t_trigger_device_us.0);
                pulses.insert(*seq, (t_trigger_device_us.0, on as f64, off as f64));
            }
            SessionEvent::Frame {
                frame_id,
                t_camera_ns,
                exposure_us,
                ..
            } => {
                frames.insert(*frame_id, (*t_camera_ns, f64::from(*exposure_us)));
            }
            SessionEvent::Pairing { frame_id, seq, .. } => {
                pairs.insert(*seq, *frame_id);
            }
            SessionEvent::PairingError {
                kind,
                frame_id: Some(id),
                reason,
                ..
            } if kind == "frame_without_pulse" || kind == "duplicate_frame" => {
                let why = reason.clone().unwrap_or_else(|| kind.replace('_', " "));
                frames_without_flash.push((*id, why.replace('_', " ")));
            }
            _ => {}
        }
    }
    let entries: BTreeMap<u64, _> = session.frames.iter().map(|f| (f.frame_id, f)).collect();
    let bit_depth = session.manifest.sensor.bit_depth;
    let flashes = pulses
        .iter()
        .map(|(&seq, &(trigger_device_us, on, off))| {
            let frame_id = pairs.get(&seq).copied();
            let timing = frame_id
                .and_then(|id| frames.get(&id))
                .map(|&(t_cam, exp)| {
                    let exposure_start_us = match (t_cam, latch, fit) {
                        (Some(t_cam), Some((cam_us, host_us, half)), Some((gain, offset, rms))) => {
                            let cam = t_cam as f64 / 1e3;
                            let exposure_host = host_us + (cam - cam_us);
                            let trigger_host = gain * trigger_device_us as f64 + offset;
                            let u = half + rms + DRIFT_BOUND * (cam - cam_us).abs();
                            Some((exposure_host - trigger_host, u))
                        }
                        _ => None,
                    };
                    Timing {
                        flash_on_us: on,
                        flash_off_us: off,
                        exposure_us: exp,
                        exposure_start_us,
                    }
                });
            let (mut levels_of, mut unreadable) = (None, None);
            if let Some(entry) = frame_id.and_then(|id| entries.get(&id)) {
                match session.load_frame(entry) {
                    Ok((_, _, px)) => levels_of = Some(levels(&px, bit_depth)),
                    Err(e) => unreadable = Some(e.to_string()),
                }
            }
            Flash {
                seq,
                frame_id,
                timing,
                levels: levels_of,
                unreadable,
            }
        })
        .collect();
    FlashCheck {
        asked,
        flashes,
        frames_without_flash,
    }
}

impl FlashCheck {
    /// Flashes paired with a frame.
    pub fn paired(&self) -> usize {
        self.flashes.iter().filter(|f| f.frame_id.is_some()).count()
    }

    /// One line per flash, then one per frame without a flash.
    pub fn lines(&self) -> Vec<String> {
        let mut out = Vec::new();
        for f in &self.flashes {
            let Some(id) = f.frame_id else {
                out.push(format!("flash {}: no frame", f.seq));
                continue;
            };
            let mut line = format!("flash {}: frame {id}", f.seq);
            if let Some(t) = &f.timing {
                line.push_str(&format!(
                    "; flash on +{:.0}…+{:.0} µs after the trigger",
                    t.flash_on_us, t.flash_off_us
                ));
                match t.exposure_start_us {
                    Some((d, u)) => line.push_str(&format!(
                        ", exposure {d:+.0} ± {u:.0} µs for {:.0} µs: flash {}",
                        t.exposure_us,
                        if t.starts_early() {
                            "starts before the exposure"
                        } else if t.ends_late() {
                            "ends after the exposure"
                        } else {
                            "inside the exposure"
                        }
                    )),
                    None => line.push_str(&format!(
                        ", exposure {:.0} µs (start not measured: no camera timestamps)",
                        t.exposure_us
                    )),
                }
            }
            if let Some(l) = &f.levels {
                line.push_str(&format!(
                    "; black level {} DN ({:.1} % of full scale); {:.2} % of pixels at full scale",
                    l.black_dn,
                    100.0 * f64::from(l.black_dn) / f64::from(l.full_scale_dn),
                    100.0 * l.saturated_share
                ));
            }
            if let Some(why) = &f.unreadable {
                line.push_str(&format!("; frame unreadable: {why}"));
            }
            out.push(line);
        }
        for (id, why) in &self.frames_without_flash {
            out.push(format!("frame {id}: no flash ({why})"));
        }
        out
    }

    /// What to fix (empty: the flashes are fine) and notes that need no fix.
    pub fn fixes(&self) -> (Vec<String>, Vec<String>) {
        let (mut fixes, mut notes) = (Vec::new(), Vec::new());
        let n = self.flashes.len();
        if n < self.asked as usize {
            fixes.push(format!(
                "the board reported {n} of {} flashes: check the link (`ellipso devices`) and \
                 the board's faults above",
                self.asked
            ));
        }
        let unpaired = n - self.paired();
        if n > 0 && unpaired == n {
            fixes.push(
                "no flash got a frame: wire the board's camera trigger (PA2) to the camera's \
                 trigger input and set the camera to external trigger"
                    .into(),
            );
        } else if unpaired > 0 {
            fixes.push(format!(
                "{unpaired} of {n} flashes got no frame: frames lost in transfer or triggers \
                 missed; check the camera cable and link, and that capture.interval_ms leaves \
                 time for the readout"
            ));
        }
        if !self.frames_without_flash.is_empty() {
            fixes.push(format!(
                "{} frames came without a flash: the camera exposes on its own or on stray \
                 edges; set it to external trigger and check the trigger wire's ground",
                self.frames_without_flash.len()
            ));
        }
        let timings: Vec<&Timing> = self
            .flashes
            .iter()
            .filter_map(|f| f.timing.as_ref())
            .collect();
        let early = timings.iter().filter(|t| t.starts_early()).count();
        if early > 0 {
            fixes.push(format!(
                "on {early} of {} frames the flash fires before the exposure starts: raise \
                 capture.flash_delay_us above the camera's trigger delay",
                timings.len()
            ));
        }
        let late = timings.iter().filter(|t| t.ends_late()).count();
        if late > 0 {
            fixes.push(format!(
                "on {late} of {} frames the flash is still on after the exposure: raise \
                 sensor.exposure_us or shorten capture.flash_duration_us",
                timings.len()
            ));
        }
        if !timings.is_empty() && timings.iter().all(|t| t.exposure_start_us.is_none()) {
            notes.push(
                "the camera gives no exposure timestamps: the flash is inside the trigger's \
                 high time, but the camera's trigger delay is not measured"
                    .into(),
            );
        }
        let levels: Vec<&Levels> = self
            .flashes
            .iter()
            .filter_map(|f| f.levels.as_ref())
            .collect();
        let m = levels.len();
        let over = levels
            .iter()
            .filter(|l| l.saturated_share > SATURATED_SHARE)
            .count();
        if over > 0 {
            fixes.push(format!(
                "{over} of {m} frames saturated (over {:.0} % of pixels at full scale): lower \
                 sensor.gain_db or the flash (capture.flash_duration_us)",
                100.0 * SATURATED_SHARE
            ));
        }
        let clipped = levels
            .iter()
            .filter(|l| l.saturated_share > 0.0 && l.saturated_share <= SATURATED_SHARE)
            .count();
        if clipped > 0 {
            notes.push(format!(
                "the highlight clips in {clipped} of {m} frames: clipped pixels carry no \
                 polarisation; lower sensor.gain_db if the highlight matters"
            ));
        }
        let zero = levels.iter().filter(|l| l.black_dn == 0).count();
        if zero > 0 {
            notes.push(format!(
                "the darkest pixels read 0 in {zero} of {m} frames: the camera's black-level \
                 offset may clip the noise floor (dark pixels then read too bright on average); \
                 raise it if dark surfaces matter"
            ));
        }
        let ambient = levels
            .iter()
            .filter(|l| f64::from(l.black_dn) > AMBIENT_SHARE * f64::from(l.full_scale_dn))
            .count();
        if ambient > 0 {
            fixes.push(format!(
                "the darkest pixels read over {:.0} % of full scale in {ambient} of {m} frames: \
                 ambient light reaches the sensor; darken the room or shorten sensor.exposure_us",
                100.0 * AMBIENT_SHARE
            ));
        }
        if self.flashes.iter().any(|f| f.unreadable.is_some()) {
            fixes.push("some frames could not be read back (above): check the disk".into());
        }
        (fixes, notes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_take_the_first_percentile_and_count_full_scale() {
        // 1000 samples: 10 at 5 DN, then 980 at 1000 DN, then 10 at 4095 (12-bit full scale)
        let mut px = vec![5u16; 10];
        px.extend(std::iter::repeat_n(1000, 980));
        px.extend(std::iter::repeat_n(4095, 10));
        let l = levels(&px, 12);
        assert_eq!(l.full_scale_dn, 4095);
        assert_eq!(l.black_dn, 1000, "index 10 is the first of the 1000s");
        assert!((l.saturated_share - 0.01).abs() < 1e-12);
    }

    #[test]
    fn a_flash_past_the_exposure_is_late_only_beyond_the_uncertainty() {
        let t = Timing {
            flash_on_us: 100.0,
            flash_off_us: 2100.0,
            exposure_us: 2000.0,
            exposure_start_us: Some((6.0, 50.0)),
        };
        assert!(t.ends_late(), "2100 > 6 + 2000 + 50");
        let within = Timing {
            exposure_start_us: Some((6.0, 150.0)),
            ..t
        };
        assert!(!within.ends_late());
        let early = Timing {
            exposure_start_us: Some((400.0, 50.0)),
            exposure_us: 8000.0,
            ..t
        };
        assert!(early.starts_early() && !early.ends_late());
    }
}
