//! `ellipso bench calibration [SCENE]`: camera calibration against the simulator's truth.
//!
//! Renders the scene's capture (default `sim/scenes/calibration.toml`: the tag grid from listed
//! poses through a distorting lens), detects the tags on each frame's detection image, runs
//! [`ellipso_vision::calibrate::calibrate`] and compares every camera parameter with the renderer's true
//! camera (at the rendered resolution): true value, estimate, relative error, 1σ standard error
//! and |error|/σ, plus the reprojection RMS. The targets — fx, fy, cx, cy within 0.1 %
//! and k1 within 2 % — are checked and printed. Writes `calibration-bench.json`.

use std::path::PathBuf;

use ellipso_model::camera::{CAMERA_PARAM_COUNT, CAMERA_PARAM_NAMES, CameraModel};

use ellipso_vision::calibrate::views::{View, board_view};
use ellipso_vision::calibrate::{CalibConfig, Calibration, calibrate};
use ellipso_vision::pose::DetectorConfig;
use ellipso_vision::track::{DetectImage, FamilyDetectors};

use crate::table::{self, Align::Left as L};
use ellipso_run_error::say;
use ellipso_run_error::{RunError, Say};

/// Relative-error targets of issue 6: fx, fy, cx, cy.
pub const INTRINSIC_TARGET: f64 = 1e-3;
/// Relative-error target for k1.
pub const K1_TARGET: f64 = 2e-2;

/// What `ellipso bench calibration` runs (its flags, parsed by the binary).
#[derive(Debug, Clone)]
pub struct CalibrationOptions {
    /// Scene file (a board-only calibration capture).
    pub scene: PathBuf,
    /// Frames to use (spread over the capture path; default all), ≥ 1.
    pub frames: Option<usize>,
    /// Render at WIDTHxHEIGHT instead of the scene's resolution (even sides, 2..=16384).
    pub resolution: Option<[u32; 2]>,
    /// Scene seed (capture poses of seeded paths and sensor noise); default the scene's.
    pub seed: Option<u64>,
    /// Detection image.
    pub image: DetectImage,
    /// Also estimate k3.
    pub free_k3: bool,
    /// Where to write calibration-bench.json.
    pub out: PathBuf,
}

/// One camera parameter, truth against estimate.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ParamRow {
    /// Parameter name (`fx` … `k3`).
    pub name: &'static str,
    /// The renderer's value.
    pub truth: f64,
    /// The calibration's value.
    pub estimate: f64,
    /// |estimate − truth| / |truth| (NaN where the truth is 0).
    pub relative_error: f64,
    /// 1σ standard error (0 when held fixed).
    pub std_error: f64,
    /// |estimate − truth| / σ (NaN when fixed).
    pub error_sigmas: f64,
    /// Whether it was estimated.
    pub estimated: bool,
}

/// The whole benchmark result.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CalibrationBench {
    /// Scene file.
    pub scene: String,
    /// Seed used.
    pub seed: u64,
    /// Rendered resolution.
    pub resolution: [u32; 2],
    /// Frames rendered.
    pub frames: usize,
    /// Views kept by the calibration.
    pub views_used: usize,
    /// Corners in the kept views.
    pub points: usize,
    /// Reprojection RMS, px.
    pub rms_px: f64,
    /// Per parameter.
    pub params: Vec<ParamRow>,
    /// fx, fy, cx, cy within 0.1 % and k1 within 2 %.
    pub meets_targets: bool,
    /// Rejected views, with reasons.
    pub rejected: Vec<String>,
    /// Detected corners against the true projection of their board points.
    pub corner_error: CornerError,
}

/// Detected corners minus the truth (true camera, true pose), raw pixels.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct CornerError {
    /// Corners compared.
    pub count: usize,
    /// Mean error along x and y (a bias the calibration cannot tell from cx, cy), px.
    pub mean_px: [f64; 2],
    /// RMS of the error vector, px.
    pub rms_px: f64,
    /// Mean error along the outward radial direction from the principal point, px.
    pub mean_radial_px: f64,
    /// Mean error along the direction from the tag's centre to the corner (+ = tags come out
    /// larger), px.
    pub mean_outward_px: f64,
    /// Per frame: corners, RMS and largest error, px (frames without a view are skipped).
    pub per_view: Vec<ViewCornerError>,
}

/// One view's corner errors against the truth.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct ViewCornerError {
    /// Position in the rendered frame list.
    pub view: usize,
    /// Corners.
    pub count: usize,
    /// RMS error, px.
    pub rms_px: f64,
    /// Largest error, px.
    pub max_px: f64,
    /// Projected position of the corner with the largest error, px.
    pub worst_at_px: [f64; 2],
}

/// Compares each view's pixels with the true projection of its board points.
fn corner_error(
    truth: &CameraModel,
    views: &[(View, Option<nalgebra::Isometry3<f64>>)],
) -> CornerError {
    let mut e = CornerError::default();
    let (mut sx, mut sy, mut s2, mut sr, mut so) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (index, (view, pose)) in views.iter().enumerate() {
        let Some(camera_from_board) = pose else {
            continue;
        };
        let mut v = ViewCornerError {
            view: index,
            ..ViewCornerError::default()
        };
        let mut v2 = 0.0;
        let projected: Vec<Option<[f64; 2]>> = view
            .iter()
            .map(|(p, _)| truth.project(&(camera_from_board * p)))
            .collect();
        // corners come in fours per tag (assembly order)
        for (chunk, proj) in view.chunks(4).zip(projected.chunks(4)) {
            let Some(proj) = proj.iter().copied().collect::<Option<Vec<_>>>() else {
                continue;
            };
            let centre = proj
                .iter()
                .fold([0.0; 2], |c, q| [c[0] + q[0] / 4.0, c[1] + q[1] / 4.0]);
            for ((_, px), q) in chunk.iter().zip(&proj) {
                let d = [px.x - q[0], px.y - q[1]];
                let unit = |v: [f64; 2]| {
                    let n = v[0].hypot(v[1]).max(1e-9);
                    [v[0] / n, v[1] / n]
                };
                let radial = unit([q[0] - truth.intrinsics.cx, q[1] - truth.intrinsics.cy]);
                let outward = unit([q[0] - centre[0], q[1] - centre[1]]);
                sx += d[0];
                sy += d[1];
                s2 += d[0] * d[0] + d[1] * d[1];
                sr += d[0] * radial[0] + d[1] * radial[1];
                so += d[0] * outward[0] + d[1] * outward[1];
                e.count += 1;
                let n2 = d[0] * d[0] + d[1] * d[1];
                v2 += n2;
                v.count += 1;
                if n2.sqrt() > v.max_px {
                    v.max_px = n2.sqrt();
                    v.worst_at_px = *q;
                }
            }
        }
        v.rms_px = (v2 / v.count.max(1) as f64).sqrt();
        e.per_view.push(v);
    }
    let n = e.count.max(1) as f64;
    e.mean_px = [sx / n, sy / n];
    e.rms_px = (s2 / n).sqrt();
    e.mean_radial_px = sr / n;
    e.mean_outward_px = so / n;
    e
}

/// Compares a calibration with the true camera.
pub fn compare(truth: &CameraModel, cal: &Calibration) -> Vec<ParamRow> {
    let t = truth.params();
    let e = cal.camera.params();
    (0..CAMERA_PARAM_COUNT)
        .map(|k| {
            let err = (e[k] - t[k]).abs();
            // relative error undefined for a zero truth: NaN, printed as "—"
            let relative_error = if t[k] != 0.0 {
                err / t[k].abs()
            } else {
                f64::NAN
            };
            let std_error = cal.std_errors[k];
            let error_sigmas = if cal.estimated[k] && std_error > 0.0 {
                err / std_error
            } else {
                f64::NAN
            };
            ParamRow {
                name: CAMERA_PARAM_NAMES[k],
                truth: t[k],
                estimate: e[k],
                relative_error,
                std_error,
                error_sigmas,
                estimated: cal.estimated[k],
            }
        })
        .collect()
}

/// Whether the rows meet the targets.
pub fn meets_targets(rows: &[ParamRow]) -> bool {
    rows.iter().all(|r| match r.name {
        "fx" | "fy" | "cx" | "cy" => r.relative_error <= INTRINSIC_TARGET,
        "k1" => r.relative_error <= K1_TARGET,
        _ => true,
    })
}

/// Renders, detects and calibrates (see the module doc).
pub fn run_bench(args: &CalibrationOptions) -> Result<CalibrationBench, RunError> {
    let scene = crate::pose::load_scene(&args.scene, args.seed)?;
    let (renderer, boards) =
        crate::pose::renderer_and_boards(&scene, args.resolution, &args.scene)?;
    let truth = *renderer.camera();
    let indices = crate::pose::spread(scene.camera_poses.len(), args.frames);
    let mut detector = FamilyDetectors::new(&boards, DetectorConfig::default())?;
    let mut views: Vec<View> = Vec::new();
    let mut truth_views = Vec::new();
    for &k in &indices {
        let raw = crate::pose::render_raw(&renderer, &scene, k)?;
        let (view, board) = board_view(&mut detector, &raw, &boards, args.image)?;
        let camera_from_board = board.map(|b| {
            scene.camera_poses[k].world_from_camera.inverse() * boards[b].world_from_board()
        });
        truth_views.push((view.clone(), camera_from_board));
        views.push(view);
    }
    let config = CalibConfig {
        fix_k3: !args.free_k3,
        ..CalibConfig::default()
    };
    let cal = calibrate(&views, (truth.width, truth.height), &config)?;
    let params = compare(&truth, &cal);
    Ok(CalibrationBench {
        scene: args.scene.display().to_string(),
        seed: scene.seed,
        resolution: [truth.width, truth.height],
        frames: indices.len(),
        views_used: cal.views.len(),
        points: cal.views.iter().map(|v| v.points).sum(),
        rms_px: cal.rms_px,
        meets_targets: meets_targets(&params),
        params,
        rejected: cal
            .rejected
            .iter()
            .map(|r| format!("frame {}: {}", indices[r.index], r.reason))
            .collect(),
        corner_error: corner_error(&truth, &truth_views),
    })
}

/// Runs `ellipso bench calibration`.
pub fn run(args: &CalibrationOptions, say: &dyn Say) -> Result<(), RunError> {
    let out = ellipso_report::output::OutputFile::claim(
        &args.out.join("calibration-bench.json"),
        "bench-calibration",
        ellipso_report::output::FileFormat::JSON,
        &[&args.scene],
        None,
    )?;
    say!(
        say,
        "calibrating from rendered frames of {}…",
        args.scene.display()
    );
    let b = run_bench(args)?;
    say!(
        say,
        "{} frames at {}×{}, seed {}: {} views kept, {} corners, reprojection RMS {:.4} px",
        b.frames,
        b.resolution[0],
        b.resolution[1],
        b.seed,
        b.views_used,
        b.points,
        b.rms_px
    );
    for line in table::head(&[
        ("param", L),
        ("true", L),
        ("estimated", L),
        ("relative error", L),
        ("std error", L),
        ("error/σ", L),
    ])
    .lines()
    {
        say!(say, "{line}");
    }
    for r in &b.params {
        let rel = if r.relative_error.is_finite() {
            format!("{:.2e}", r.relative_error)
        } else {
            "—".into()
        };
        if r.estimated {
            say!(
                say,
                "| {} | {:.6} | {:.6} | {rel} | {:.2e} | {:.2} |",
                r.name,
                r.truth,
                r.estimate,
                r.std_error,
                r.error_sigmas
            );
        } else {
            say!(
                say,
                "| {} | {:.6} | {:.6} (fixed) | {rel} | — | — |",
                r.name,
                r.truth,
                r.estimate
            );
        }
    }
    let c = &b.corner_error;
    say!(
        say,
        "corners vs truth ({}): mean ({:+.3}, {:+.3}) px, RMS {:.3} px, mean radial {:+.3} px, \
         mean outward from tag centre {:+.3} px",
        c.count,
        c.mean_px[0],
        c.mean_px[1],
        c.rms_px,
        c.mean_radial_px,
        c.mean_outward_px
    );
    for why in &b.rejected {
        say!(say, "  rejected: {why}");
    }
    say!(
        say,
        "targets (fx, fy, cx, cy ≤ {:.1} %, k1 ≤ {:.0} %): {}",
        INTRINSIC_TARGET * 100.0,
        K1_TARGET * 100.0,
        if b.meets_targets { "met" } else { "MISSED" }
    );
    out.write(serde_json::to_vec_pretty(&b)?)?;
    say!(say, "written {}", out.shown().display());
    Ok(())
}

#[cfg(test)]
mod tests;
