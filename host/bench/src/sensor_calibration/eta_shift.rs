//! The end-to-end figure of the sensor calibration: the demo scene captured with the real
//! sensor's effects and fitted with its calibration, against the same capture from the ideal
//! sensor — how far each material's η and the normals move.
//!
//! Contract: both sessions are rendered from the same scene, seed and poses (the demo's path
//! thinned to `photos` views, at the bench's resolution), without shot and read noise, so that
//! the only difference is [`super::REAL_SENSOR_EFFECTS`]' fixed pattern (vignetting is in both,
//! as the fit models it; the calibration itself is measured from noisy captures, so its own
//! noise is in the figure). With temporal noise the two captures would draw different noise
//! (the effects change every pixel's signal) and the figure would be the fit's noise, not the
//! sensor's. Each is fitted on the true mesh with the true poses, one outer iteration (no surface update:
//! only the sensor differs between the runs), no holdout, the session's recorded noise model,
//! and the per-vertex refined normals reported as fitted (not combined with the surface's).
//! The effects session is fitted twice: with the calibration (`eta_shift_calibrated_points_max`)
//! and without it (the frames read as an ideal sensor's: the uncalibrated cost). The η change of
//! a material is the change of its median η's error, in percentage points of the true η; the
//! normal change is the angle between the refined normals of each vertex reliable in both fits
//! (median, 95th percentile, largest: most vertices' normals agree to rounding, so the median
//! alone says nothing).

use std::path::Path;
use std::sync::Arc;

use ellipso_fit::session::{SessionFit, SessionFitConfig, fit_session, with_session_sensor};
use ellipso_polar::sensor_calibration::SensorCalibration;
use ellipso_run_error::{RunError, Say, say};
use ellipso_sim::scene::Scene;
use serde::Serialize;

/// What the end-to-end fits gave.
#[derive(Debug, Clone, Serialize)]
pub struct EtaShift {
    /// Views fitted per session.
    pub photos: usize,
    /// Largest per-material |Δ η error| with the calibration, percentage points.
    pub calibrated_points_max: f64,
    /// The same read as an ideal sensor (no calibration), percentage points.
    pub uncalibrated_points_max: f64,
    /// Normal change with the calibration.
    pub normals_calibrated: NormalShift,
    /// The same without it.
    pub normals_uncalibrated: NormalShift,
    /// Per material: name, η error of the ideal sensor, calibrated, uncalibrated (%).
    pub materials: Vec<(String, f64, f64, f64)>,
}

/// `scene` with its capture path thinned to `photos` evenly spaced views.
fn thinned(mut scene: Scene, photos: usize) -> Scene {
    let n = scene.camera_poses.len();
    if photos < n {
        let keep: Vec<_> = (0..photos)
            .map(|k| scene.camera_poses[k * n / photos])
            .collect();
        scene.camera_poses = keep;
    }
    scene
}

/// Runs the fits (module contract); sessions are written under `work`.
pub fn run(
    cal: &SensorCalibration,
    resolution: [u32; 2],
    photos: usize,
    work: &Path,
    say: &dyn Say,
) -> Result<EtaShift, RunError> {
    let effects = thinned(super::demo_with(super::REAL_SENSOR_EFFECTS, false)?, photos);
    let ideal = thinned(
        super::demo_with("vignetting = { exponent = 4.0 }\n", false)?,
        photos,
    );
    let scene_path = ellipso_sim::scene::shipped_scene("demo.toml");
    let truth = crate::truth::truth_for_scoring(&ideal)?;
    let mesh = crate::truth::true_mesh(&ideal)?;
    let base = SessionFitConfig {
        outer_iterations: 1,
        holdout_fraction: 0.0,
        combine_normals: false,
        ..SessionFitConfig::default()
    };
    let fit = |scene: &Scene, name: &str, cal: Option<&SensorCalibration>| {
        let dir = work.join(name);
        if !dir.join(ellipso_session::paths::MANIFEST).exists() {
            say!(
                say,
                "rendering the {name} session ({} views)",
                scene.camera_poses.len()
            );
            crate::capture::render_session(
                &scene_path,
                scene,
                super::options(resolution),
                &dir,
                &mut |_, _| {},
            )?;
        }
        let session = ellipso_session::reader::open(&dir)?;
        let poses = crate::capture::true_poses(&session, scene);
        let mut config = base.clone();
        config.observe.sensor_calibration = cal.map(|c| Arc::new(c.clone()));
        let config = with_session_sensor(&session, &config);
        let started = std::time::Instant::now();
        let fitted = fit_session(&session, &mesh, &poses, &config, &mut |_| {})?;
        say!(
            say,
            "  fitted {name}{} in {:.0} s",
            if cal.is_some() {
                " with the calibration"
            } else {
                ""
            },
            started.elapsed().as_secs_f64()
        );
        Ok::<SessionFit, RunError>(fitted)
    };
    let reference = fit(&ideal, "ideal", None)?;
    let calibrated = fit(&effects, "effects", Some(cal))?;
    let uncalibrated = fit(&effects, "effects", None)?;
    let score = |f: &SessionFit| {
        let at = crate::truth_map::truth_at(&truth, f.mesh.positions());
        crate::score::score_fit(&f.outcome.fits, &at, &truth.material_names, f.set.colour)
    };
    let (r, c, u) = (score(&reference), score(&calibrated), score(&uncalibrated));
    let (normals_calibrated, normals_uncalibrated) = (
        normal_shift(&reference, &calibrated),
        normal_shift(&reference, &uncalibrated),
    );
    for (name, n) in [
        ("calibrated", &normals_calibrated),
        ("uncalibrated", &normals_uncalibrated),
    ] {
        say!(
            say,
            "  normals, {name} vs ideal sensor over {} vertices: median {:.4}°, 95th percentile \
             {:.4}°, largest {:.4}°",
            n.vertices,
            n.median_deg,
            n.p95_deg,
            n.max_deg
        );
    }
    let mut materials = Vec::new();
    let (mut cal_max, mut uncal_max) = (0.0f64, 0.0f64);
    for m in &r.materials {
        let find = |s: &crate::score::FitScores| {
            s.materials
                .iter()
                .find(|x| x.name == m.name)
                .map_or(f64::NAN, |x| x.eta_error_pct)
        };
        let (ec, eu) = (find(&c), find(&u));
        cal_max = cal_max.max((ec - m.eta_error_pct).abs());
        uncal_max = uncal_max.max((eu - m.eta_error_pct).abs());
        materials.push((m.name.clone(), m.eta_error_pct, ec, eu));
    }
    Ok(EtaShift {
        photos: ideal.camera_poses.len(),
        calibrated_points_max: cal_max,
        uncalibrated_points_max: uncal_max,
        normals_calibrated,
        normals_uncalibrated,
        materials,
    })
}

/// How far the refined normals of the vertices reliable in both fits moved, degrees.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct NormalShift {
    /// Vertices compared.
    pub vertices: usize,
    /// Median angle.
    pub median_deg: f64,
    /// 95th percentile.
    pub p95_deg: f64,
    /// Largest.
    pub max_deg: f64,
}

fn normal_shift(a: &SessionFit, b: &SessionFit) -> NormalShift {
    let mut angles: Vec<f64> = a
        .outcome
        .fits
        .iter()
        .zip(&b.outcome.fits)
        .filter(|(x, y)| x.is_reliable() && y.is_reliable())
        .map(|(x, y)| {
            nalgebra::Vector3::from(x.normal_world)
                .angle(&nalgebra::Vector3::from(y.normal_world))
                .to_degrees()
        })
        .collect();
    NormalShift {
        vertices: angles.len(),
        max_deg: angles.iter().copied().fold(0.0, f64::max),
        p95_deg: ellipso_model::stats::percentile(&mut angles, 0.95),
        median_deg: ellipso_model::stats::median(&mut angles),
    }
}
