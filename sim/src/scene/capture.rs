//! The capture section: where the photos are taken from, turned into camera poses.
//!
//! Frames: the world is right-handed with `up` (default `+z`) pointing up; the board usually lies
//! in the world `z = 0` plane. Cameras use the OpenCV frame: x right, y down, z forward (optical
//! axis). A [`CameraPose`] holds `world_from_camera` and the nominal trigger time
//! `t_trigger_us = index × interval_ms` (the virtual rig adds trigger jitter when listed).
//!
//! Contract: [`CaptureSpec::camera_poses`] is a pure function of the spec and the scene seed
//! (ChaCha8 from `seed`), so the same scene always yields the same poses and a different seed
//! different ones. Paths:
//! - `orbit`: `photo_count` cameras on a sphere of `radius_m` around `look_at_m`, azimuth stepping
//!   evenly through `turns` revolutions from a seeded start angle, elevation rising linearly through
//!   the `elevation_deg` band (a spiral).
//! - `random_walk`: a hand-held operator: azimuth advances by a jittered even step, elevation and
//!   distance do reflected random walks inside `elevation_deg` and `distance_m`, the position is
//!   jittered by `position_jitter_m`, the aim by `aim_jitter_deg`, the roll by `roll_jitter_deg`;
//!   the camera–target distance is then clamped back into `distance_m`.
//! - `explicit`: the listed poses, each by `position_m` + `look_at_m` (+ `roll_deg`) or by
//!   `position_m` + a rotation (`rotation_deg` / `quaternion_wxyz`, the `world_from_camera`
//!   rotation).

use super::error::positive;
use super::error::{Located, SceneError};
use super::pose::PoseSpec;
use nalgebra::{
    Isometry3, Matrix3, Point3, Rotation3, Translation3, Unit, UnitQuaternion, Vector3,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

/// One photo's camera pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraPose {
    /// Photo index (0-based, capture order).
    pub index: u32,
    /// Nominal trigger time since the first photo, microseconds (`index × interval_ms`; trigger
    /// jitter, if listed, is applied later by the virtual rig).
    pub t_trigger_us: u64,
    /// Camera frame (OpenCV: x right, y down, z forward) to world.
    pub world_from_camera: Isometry3<f64>,
}

/// Capture path kinds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CapturePathKind {
    /// Spiral orbit.
    Orbit,
    /// Seeded hand-held walk.
    RandomWalk,
    /// Listed poses.
    Explicit,
}

/// One explicitly listed camera pose.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ExplicitPoseSpec {
    /// Camera centre in the world, metres.
    pub position_m: [f64; 3],
    /// Point the optical axis passes through (look-at form).
    #[serde(default)]
    pub look_at_m: Option<[f64; 3]>,
    /// Roll about the optical axis, degrees (look-at form; default 0 = image up is world up).
    #[serde(default)]
    pub roll_deg: f64,
    /// `world_from_camera` rotation as Euler angles (see `PoseSpec`).
    #[serde(default)]
    pub rotation_deg: Option<[f64; 3]>,
    /// `world_from_camera` rotation as a quaternion `[w, x, y, z]`.
    #[serde(default)]
    pub quaternion_wxyz: Option<[f64; 4]>,
}

fn default_interval() -> f64 {
    500.0
}

fn default_up() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

/// The `[capture]` table. Which fields apply depends on `path`.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CaptureSpec {
    /// Path kind.
    pub path: CapturePathKind,
    /// Number of photos (orbit and random_walk: required; explicit: optional, must match).
    #[serde(default)]
    pub photo_count: Option<u32>,
    /// Target point, metres (default origin).
    #[serde(default)]
    pub look_at_m: [f64; 3],
    /// Time between consecutive triggers, milliseconds (default 500: a hand-held flash capture
    /// at 2 photos per second).
    #[serde(default = "default_interval")]
    pub interval_ms: f64,
    /// World up direction (default `[0, 0, 1]`).
    #[serde(default = "default_up")]
    pub up: [f64; 3],
    /// Orbit radius, metres (orbit).
    #[serde(default)]
    pub radius_m: Option<f64>,
    /// `[low, high]` elevation above the horizontal, degrees (orbit, random_walk).
    #[serde(default)]
    pub elevation_deg: Option<[f64; 2]>,
    /// Revolutions around the target (orbit, random_walk; default 1).
    #[serde(default)]
    pub turns: Option<f64>,
    /// `[min, max]` camera–target distance, metres (random_walk).
    #[serde(default)]
    pub distance_m: Option<[f64; 2]>,
    /// Standard deviation of the position jitter, metres (random_walk; default 0.01).
    #[serde(default)]
    pub position_jitter_m: Option<f64>,
    /// Standard deviation of the aim error, degrees (random_walk; default 1).
    #[serde(default)]
    pub aim_jitter_deg: Option<f64>,
    /// Standard deviation of the roll, degrees (random_walk; default 3).
    #[serde(default)]
    pub roll_jitter_deg: Option<f64>,
    /// Poses (explicit), `[[capture.poses]]`.
    #[serde(default)]
    pub poses: Vec<ExplicitPoseSpec>,
    /// Flash-energy bracket: relative energies in (0, 1], at most 8, fired in turn by the
    /// trigger board's flash on-time inside the one exposure (photo `k` gets step `k mod len`).
    /// Empty (default): every photo at the full pulse.
    #[serde(default)]
    pub bracket: Vec<f64>,
}

/// `world_from_camera` rotation looking from `eye` at `target` with image-up along `up`, rolled
/// by `roll_rad` about the optical axis. `None` if `eye == target`.
pub fn look_at(
    eye: &Point3<f64>,
    target: &Point3<f64>,
    up: &Vector3<f64>,
    roll_rad: f64,
) -> Option<UnitQuaternion<f64>> {
    let z = Unit::try_new(target - eye, 1e-12)?;
    // Looking straight along ±up: pick any perpendicular reference so x stays defined.
    let x = Unit::try_new(z.cross(up), 1e-9).or_else(|| {
        let alt = if z.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        Unit::try_new(z.cross(&alt), 1e-9)
    })?;
    let y = z.cross(&x);
    let r = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[
        x.into_inner(),
        y,
        z.into_inner(),
    ]));
    Some(
        UnitQuaternion::from_rotation_matrix(&r)
            * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), roll_rad),
    )
}

impl CaptureSpec {
    /// Range and consistency checks; keys are under `capture`.
    pub fn validate(&self, loc: &Located<'_>) -> Result<(), SceneError> {
        let k = |f: &str| format!("capture.{f}");
        let only = |f: &str, present: bool, kinds: &str| -> Result<(), SceneError> {
            if present {
                Err(loc.invalid(k(f), format!("only applies to path = {kinds}")))
            } else {
                Ok(())
            }
        };
        if !self.look_at_m.iter().all(|v| v.is_finite()) {
            return Err(loc.invalid(k("look_at_m"), "must be finite"));
        }
        if !(self.interval_ms.is_finite() && self.interval_ms > 0.0 && self.interval_ms <= 3.6e6) {
            return Err(loc.invalid(
                k("interval_ms"),
                format!("{}: need 0 < interval ≤ 1 h", self.interval_ms),
            ));
        }
        let up = Vector3::from(self.up);
        if !(up.iter().all(|v| v.is_finite()) && up.norm() > 1e-9) {
            return Err(loc.invalid(k("up"), "must be a finite non-zero vector"));
        }
        if let Err(e) = ellipso_protocol::Bracket::from_relative(&self.bracket) {
            return Err(loc.invalid(k("bracket"), e.to_string()));
        }
        let is = |p| self.path == p;
        only(
            "radius_m",
            self.radius_m.is_some() && !is(CapturePathKind::Orbit),
            "\"orbit\"",
        )?;
        let walk_only = "\"random_walk\"";
        only(
            "distance_m",
            self.distance_m.is_some() && !is(CapturePathKind::RandomWalk),
            walk_only,
        )?;
        only(
            "position_jitter_m",
            self.position_jitter_m.is_some() && !is(CapturePathKind::RandomWalk),
            walk_only,
        )?;
        only(
            "aim_jitter_deg",
            self.aim_jitter_deg.is_some() && !is(CapturePathKind::RandomWalk),
            walk_only,
        )?;
        only(
            "roll_jitter_deg",
            self.roll_jitter_deg.is_some() && !is(CapturePathKind::RandomWalk),
            walk_only,
        )?;
        let generated = "\"orbit\" or \"random_walk\"";
        only(
            "elevation_deg",
            self.elevation_deg.is_some() && is(CapturePathKind::Explicit),
            generated,
        )?;
        only(
            "turns",
            self.turns.is_some() && is(CapturePathKind::Explicit),
            generated,
        )?;
        only(
            "poses",
            !self.poses.is_empty() && !is(CapturePathKind::Explicit),
            "\"explicit\"",
        )?;
        match self.photo_count {
            Some(0) => return Err(loc.invalid(k("photo_count"), "zero photos: need at least 1")),
            Some(n) if n > 100_000 => {
                return Err(loc.invalid(
                    k("photo_count"),
                    format!("{n} photos is beyond any session (≤ 100000)"),
                ));
            }
            None if !is(CapturePathKind::Explicit) => {
                return Err(
                    loc.invalid(k("photo_count"), "required for orbit and random_walk paths")
                );
            }
            _ => {}
        }
        if let Some([lo, hi]) = self.elevation_deg {
            if !(lo.is_finite() && hi.is_finite() && -90.0 <= lo && lo <= hi && hi <= 90.0) {
                return Err(loc.invalid(
                    k("elevation_deg"),
                    format!("[{lo}, {hi}]: need -90 ≤ low ≤ high ≤ 90"),
                ));
            }
        } else if !is(CapturePathKind::Explicit) {
            return Err(loc.invalid(
                k("elevation_deg"),
                "required for orbit and random_walk paths",
            ));
        }
        if let Some(t) = self.turns {
            if !(t.is_finite() && t > 0.0 && t <= 100.0) {
                return Err(loc.invalid(k("turns"), format!("{t}: need 0 < turns ≤ 100")));
            }
        }
        match self.path {
            CapturePathKind::Orbit => match self.radius_m {
                Some(r) => positive(loc, &k("radius_m"), r)?,
                None => return Err(loc.invalid(k("radius_m"), "required for path = \"orbit\"")),
            },
            CapturePathKind::RandomWalk => {
                let Some([lo, hi]) = self.distance_m else {
                    return Err(loc.invalid(k("distance_m"), "required for path = \"random_walk\""));
                };
                if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi) {
                    return Err(
                        loc.invalid(k("distance_m"), format!("[{lo}, {hi}]: need 0 < min ≤ max"))
                    );
                }
                for (f, v) in [
                    ("position_jitter_m", self.position_jitter_m),
                    ("aim_jitter_deg", self.aim_jitter_deg),
                    ("roll_jitter_deg", self.roll_jitter_deg),
                ] {
                    if let Some(v) = v {
                        if !(v.is_finite() && v >= 0.0) {
                            return Err(loc.invalid(k(f), format!("{v}: must be ≥ 0")));
                        }
                    }
                }
                if self.aim_jitter_deg.is_some_and(|a| a >= 45.0) {
                    return Err(loc.invalid(
                        k("aim_jitter_deg"),
                        "≥ 45° would point the camera away from the target",
                    ));
                }
            }
            CapturePathKind::Explicit => self.validate_explicit(loc)?,
        }
        Ok(())
    }

    fn validate_explicit(&self, loc: &Located<'_>) -> Result<(), SceneError> {
        if self.poses.is_empty() {
            return Err(loc.invalid(
                "capture.poses",
                "path = \"explicit\" needs at least one [[capture.poses]]",
            ));
        }
        if let Some(n) = self.photo_count {
            if n as usize != self.poses.len() {
                return Err(loc.invalid(
                    "capture.photo_count",
                    format!("{n} photos but {} poses listed", self.poses.len()),
                ));
            }
        }
        let up = Vector3::from(self.up);
        for (i, p) in self.poses.iter().enumerate() {
            self.explicit_pose(i, p, &up, loc)?;
        }
        Ok(())
    }

    fn explicit_pose(
        &self,
        i: usize,
        p: &ExplicitPoseSpec,
        up: &Vector3<f64>,
        loc: &Located<'_>,
    ) -> Result<Isometry3<f64>, SceneError> {
        let key = format!("capture.poses[{i}]");
        let eye = Point3::from(p.position_m);
        if !eye.iter().all(|v| v.is_finite()) {
            return Err(loc.invalid(format!("{key}.position_m"), "must be finite"));
        }
        let rotation = match p.look_at_m {
            Some(target) => {
                if p.rotation_deg.is_some() || p.quaternion_wxyz.is_some() {
                    return Err(loc.invalid(
                        format!("{key}.look_at_m"),
                        "give look_at_m or a rotation, not both",
                    ));
                }
                if !p.roll_deg.is_finite() {
                    return Err(loc.invalid(format!("{key}.roll_deg"), "must be finite"));
                }
                look_at(&eye, &Point3::from(target), up, p.roll_deg.to_radians()).ok_or_else(
                    || {
                        loc.invalid(
                            format!("{key}.look_at_m"),
                            "equals position_m: no viewing direction",
                        )
                    },
                )?
            }
            None => {
                if p.roll_deg != 0.0 {
                    return Err(loc.invalid(format!("{key}.roll_deg"), "only with look_at_m"));
                }
                if p.rotation_deg.is_none() && p.quaternion_wxyz.is_none() {
                    return Err(
                        loc.invalid(key, "needs look_at_m, rotation_deg or quaternion_wxyz")
                    );
                }
                let pose = PoseSpec {
                    translation_m: p.position_m,
                    rotation_deg: p.rotation_deg,
                    quaternion_wxyz: p.quaternion_wxyz,
                };
                pose.to_isometry(&key, loc)?.rotation
            }
        };
        Ok(Isometry3::from_parts(
            Translation3::from(eye.coords),
            rotation,
        ))
    }

    /// The camera poses (validate first; an invalid spec yields fewer or no poses, never a panic).
    pub fn camera_poses(
        &self,
        seed: u64,
        loc: &Located<'_>,
    ) -> Result<Vec<CameraPose>, SceneError> {
        let target = Point3::from(self.look_at_m);
        let up = Unit::try_new(Vector3::from(self.up), 1e-12).unwrap_or_else(Vector3::z_axis);
        // Horizontal basis perpendicular to `up`.
        let e1 = Unit::try_new(up.cross(&Vector3::x()), 1e-9)
            .or_else(|| Unit::try_new(up.cross(&Vector3::y()), 1e-9))
            .unwrap_or_else(Vector3::y_axis);
        let e1 = Unit::new_normalize(e1.cross(&up));
        let e2 = up.cross(&e1);
        let dir = |az: f64, el: f64| {
            e1.into_inner() * el.cos() * az.cos()
                + e2 * el.cos() * az.sin()
                + up.into_inner() * el.sin()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let n = self.photo_count.unwrap_or(self.poses.len() as u32);
        let [lo, hi] = self
            .elevation_deg
            .unwrap_or([0.0, 0.0])
            .map(f64::to_radians);
        let turns = self.turns.unwrap_or(1.0);
        let step = std::f64::consts::TAU * turns / n.max(1) as f64;
        // Rounded to whole microseconds; validated interval keeps this far inside u64.
        let trigger_us = |index: u32| (index as f64 * self.interval_ms * 1e3).round() as u64;
        let pose = |index: u32, eye: Point3<f64>, aim: Point3<f64>, roll: f64| {
            look_at(&eye, &aim, &up, roll).map(|r| CameraPose {
                index,
                t_trigger_us: trigger_us(index),
                world_from_camera: Isometry3::from_parts(Translation3::from(eye.coords), r),
            })
        };
        let mut out = Vec::with_capacity(n as usize);
        match self.path {
            CapturePathKind::Orbit => {
                let r = self.radius_m.unwrap_or(1.0);
                let phase: f64 = rng.random_range(0.0..std::f64::consts::TAU);
                for i in 0..n {
                    let el = lo + (hi - lo) * (i as f64 + 0.5) / n as f64;
                    let eye = target + dir(phase + step * i as f64, el) * r;
                    out.extend(pose(i, eye, target, 0.0));
                }
            }
            CapturePathKind::RandomWalk => {
                let [dmin, dmax] = self.distance_m.unwrap_or([0.5, 0.5]);
                let jitter = self.position_jitter_m.unwrap_or(0.01);
                let aim = self.aim_jitter_deg.unwrap_or(1.0).to_radians();
                let roll = self.roll_jitter_deg.unwrap_or(3.0).to_radians();
                let mut az: f64 = rng.random_range(0.0..std::f64::consts::TAU);
                let mut el = rng.random_range(lo..=hi);
                let mut d = rng.random_range(dmin..=dmax);
                let mut normal = || -> f64 { rng.sample(StandardNormal) };
                for i in 0..n {
                    let offset = Vector3::new(normal(), normal(), normal()) * jitter;
                    let mut eye = target + dir(az, el) * d + offset;
                    // Keep the camera–target distance inside the allowed range.
                    let v = eye - target;
                    let dist = v.norm();
                    if dist > 0.0 {
                        eye = target + v * (dist.clamp(dmin, dmax) / dist);
                    }
                    let dist = (eye - target).norm();
                    // Aim error: offset the aim point perpendicular to the view by tan(err)·dist.
                    let view = Unit::try_new(target - eye, 1e-12).unwrap_or(up);
                    let a = Unit::try_new(view.cross(&up), 1e-9).unwrap_or(e1);
                    let b = view.cross(&a);
                    let (ea, eb) = (normal() * aim, normal() * aim);
                    // Clamp the tangent argument below 90° so the aim point stays finite.
                    let aim_point = target
                        + a.into_inner() * dist * ea.clamp(-1.4, 1.4).tan()
                        + b * dist * eb.clamp(-1.4, 1.4).tan();
                    out.extend(pose(i, eye, aim_point, normal() * roll));
                    // Advance: jittered azimuth step, reflected elevation and distance walks.
                    az += step * (1.0 + 0.3 * normal());
                    el = reflect(el + (hi - lo) * 0.08 * normal(), lo, hi);
                    d = reflect(d + (dmax - dmin) * 0.08 * normal(), dmin, dmax);
                }
            }
            CapturePathKind::Explicit => {
                for (i, p) in self.poses.iter().enumerate() {
                    let world_from_camera = self.explicit_pose(i, p, &up, loc)?;
                    out.push(CameraPose {
                        index: i as u32,
                        t_trigger_us: trigger_us(i as u32),
                        world_from_camera,
                    });
                }
            }
        }
        Ok(out)
    }
}

/// Reflects `x` back into `[lo, hi]` (a random walk bouncing off the band edges).
fn reflect(x: f64, lo: f64, hi: f64) -> f64 {
    if hi <= lo {
        return lo;
    }
    let w = hi - lo;
    let m = (x - lo).rem_euclid(2.0 * w);
    lo + if m > w { 2.0 * w - m } else { m }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn look_at_gives_opencv_axes() {
        // Looking along world +x with z up: camera x (right) = -y, y (down) = -z.
        let r = look_at(
            &Point3::origin(),
            &Point3::new(1.0, 0.0, 0.0),
            &Vector3::z(),
            0.0,
        )
        .expect("defined");
        assert!((r * Vector3::x() - Vector3::new(0.0, -1.0, 0.0)).norm() < 1e-12);
        assert!((r * Vector3::y() - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-12);
        assert!((r * Vector3::z() - Vector3::x()).norm() < 1e-12);
        // Straight down along -up still works.
        let r = look_at(
            &Point3::new(0.0, 0.0, 1.0),
            &Point3::origin(),
            &Vector3::z(),
            0.0,
        )
        .expect("defined");
        assert!((r * Vector3::z() + Vector3::z()).norm() < 1e-12);
        assert!(look_at(&Point3::origin(), &Point3::origin(), &Vector3::z(), 0.0).is_none());
    }

    #[test]
    fn reflect_stays_in_band() {
        for x in [-3.7, -0.1, 0.0, 0.5, 1.0, 1.3, 9.9] {
            let y = reflect(x, 0.0, 1.0);
            assert!((0.0..=1.0).contains(&y), "{x} -> {y}");
        }
        assert!((reflect(1.25, 0.0, 1.0) - 0.75).abs() < 1e-12);
    }
}
