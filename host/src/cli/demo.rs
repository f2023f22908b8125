//! `ellipso demo`: the main job on the simulated rig, end to end, in a few minutes on 2 cores.
//!
//! 1. Capture a shipped scene (a four-material object on an AprilTag board) on the simulated rig:
//!    the real firmware core behind a real pty, the host's real link, pairing and session code.
//! 2. Track the camera pose of every frame from the AprilTags and score it against the
//!    simulator's ground truth.
//! 3. Build the object's mesh from the posed frames alone (`ellipso mesh`: a visual hull carved
//!    with the learned board), fit the polarimetric SVBRDF and shape per vertex of it from the
//!    recorded frames and the tracked poses (`ellipso fit`), write its pictures — and only then
//!    read the simulator's truth to score the mesh (before and after the fit's shape refinement)
//!    and the fitted parameters and normals.
//! 4. Pictures: the polarisation images of one frame (s0, DoLP, AoLP, I^d, I^s, I^α) and a plot of
//!    the tracked camera path against the truth.
//! 5. A summary (`summary.json`) and the list of where everything is.

use std::path::{Path, PathBuf};

use anyhow::Context;
use ellipso_sim::scene::Scene;

use super::capture::{self, print_report};
use ellipso_report::plot::{LegendPosition, LinePlot};
use ellipso_vision::process::TrackedFrame;

/// Arguments of `ellipso demo`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Where to put the session and the results.
    #[arg(long, default_value = "ellipso-demo")]
    pub out: PathBuf,
    /// Scene to capture (default: the shipped four-material demo scene).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Smaller and shorter: for a smoke test (the glass sphere scene unless --scene, quarter
    /// resolution, 24 photos).
    #[arg(long)]
    pub quick: bool,
}

pub use ellipso_sim::scene::shipped_scene;

/// Pose error statistics against the simulator's truth.
#[derive(Debug, Clone, serde::Serialize)]
pub struct PoseAccuracy {
    /// Frames posed.
    pub posed: usize,
    /// Frames tracked.
    pub frames: usize,
    /// Median rotation error, degrees.
    pub median_rotation_deg: f64,
    /// Median translation error, mm.
    pub median_translation_mm: f64,
    /// 90th percentile rotation error, degrees.
    pub p90_rotation_deg: f64,
    /// 90th percentile translation error, mm.
    pub p90_translation_mm: f64,
}

/// Scores tracked poses against the scene's capture path (frame k ↔ pose k of a clean capture;
/// frames are matched through their pairing to pulses, pulse seq k ↔ pose k).
pub fn pose_accuracy(
    scene: &Scene,
    tracked: &[TrackedFrame],
    pose_of_frame: &dyn Fn(u64) -> Option<usize>,
) -> PoseAccuracy {
    let mut rot = Vec::new();
    let mut trans = Vec::new();
    for t in tracked {
        let (Ok(p), Some(k)) = (&t.result, pose_of_frame(t.frame_id)) else {
            continue;
        };
        let Some(truth) = scene.camera_poses.get(k) else {
            continue;
        };
        let delta = truth.world_from_camera.inverse() * p.world_from_camera;
        rot.push(delta.rotation.angle().to_degrees());
        trans.push(delta.translation.vector.norm() * 1e3);
    }
    PoseAccuracy {
        posed: rot.len(),
        frames: tracked.len(),
        median_rotation_deg: ellipso_report::percentile(&mut rot, 0.5),
        median_translation_mm: ellipso_report::percentile(&mut trans, 0.5),
        p90_rotation_deg: ellipso_report::percentile(&mut rot, 0.9),
        p90_translation_mm: ellipso_report::percentile(&mut trans, 0.9),
    }
}

/// Runs `ellipso demo`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let scene_path = args
        .scene
        .clone()
        // The quick run takes the monochrome sphere scene: the colour sensor's 4×4 tiles leave
        // too few pixels per tag at quarter resolution to track the poses.
        .unwrap_or_else(|| {
            shipped_scene(if args.quick {
                "sphere.toml"
            } else {
                "demo.toml"
            })
        });
    anyhow::ensure!(
        scene_path.is_file(),
        "scene {} not found: run the demo from the source tree, or pass --scene",
        scene_path.display()
    );
    let scene = Scene::load(&scene_path)?;
    let [w, h] = scene.rig.camera.resolution_px;
    let (resolution, photos) = if args.quick {
        ([w / 4 / 2 * 2, h / 4 / 2 * 2], Some(24))
    } else {
        ([w / 2, h / 2], None)
    };
    // the demo owns its output: a new or empty directory, or an earlier demo's (marker and
    // all); everything is written beside it and swapped in whole at the end
    let out = ellipso_report::output::OutputDir::claim(&args.out, "demo", &[&scene_path])?;
    let root = out.path().to_path_buf();
    let session_dir = root.join("session");
    crate::outln!(
        "ellipso demo: scene {} at {}×{}",
        scene_path.display(),
        resolution[0],
        resolution[1]
    );
    crate::outln!(
        "[1/4] capturing on the simulated rig (firmware core behind a pty, real link and pairing)…"
    );
    let capture_args = capture::Args {
        sim: Some(scene_path.clone()),
        rig: None,
        out: session_dir.clone(),
        trigger: None,
        wire: None,
        photos,
        resolution: Some(resolution),
        supersampling: 2,
        interval_ms: None,
        no_track: true,
        // The demo scene's own bracket, if it has one.
        bracket: None,
        view: false,
        view_mesh: None,
    };
    let captured = capture::capture_sim(&capture_args, false)?;
    let (report, dir) = (captured.report, captured.dir);
    print_report(&report);
    if let Some(signal) = captured.signal {
        // the partial demo goes with its staging directory; an earlier demo stays
        return Err(super::interrupt::Stopped { signal }.into());
    }

    crate::outln!("[2/4] tracking camera poses from the AprilTags…");
    let tracked = ellipso_vision::process::track_and_append(&dir, &super::out::Printed)
        .map_err(super::out::failed)?;
    let session = ellipso_session::reader::open(&dir)?;
    let pairs: std::collections::BTreeMap<u64, u64> = session
        .frames
        .iter()
        .filter_map(|f| f.pulse_seq.map(|s| (f.frame_id, s)))
        .collect();
    let first_seq = pairs.values().min().copied().unwrap_or(0);
    let accuracy = pose_accuracy(&scene, &tracked, &|id| {
        pairs.get(&id).map(|s| (s - first_seq) as usize)
    });
    crate::outln!(
        "poses        {}/{} frames · median error {:.3}° / {:.3} mm (90th percentile {:.3}° / {:.3} mm)",
        accuracy.posed,
        accuracy.frames,
        accuracy.median_rotation_deg,
        accuracy.median_translation_mm,
        accuracy.p90_rotation_deg,
        accuracy.p90_translation_mm
    );

    crate::outln!(
        "[3/4] carving the mesh from the frames, fitting the polarimetric SVBRDF and shape per vertex…"
    );
    let fit = fit_and_score(&scene, &session, &out, args.quick)?;

    crate::outln!("[4/4] pictures…");
    let pictures = root.join("pictures");
    std::fs::create_dir_all(&pictures)?;
    let first = session
        .frames
        .iter()
        .find(|f| f.complete)
        .context("no complete frame was captured")?;
    // the polarisation pictures of the first frame, listed once below (not file by file)
    let polar = ellipso_polar::convert::write(
        &ellipso_polar::convert::Args {
            frame: first.path.clone(),
            out: pictures.join("frame0-polarisation"),
            layout: Some(match scene.rig.camera.sensor {
                ellipso_sim::scene::SensorKind::MonoPolar => {
                    ellipso_model::mosaic::SensorLayout::MonoPolar
                }
                ellipso_sim::scene::SensorKind::ColourPolar => {
                    ellipso_model::mosaic::SensorLayout::ColourPolar
                }
            }),
            bit_depth: Some(session.manifest.sensor.bit_depth),
            demosaic: ellipso_polar::demosaic::DemosaicMethod::Superpixel,
            dark_level: 0.0,
            saturation: None,
            dark_intensity: ellipso_polar::DEFAULT_DARK_INTENSITY,
            max_residual: None,
            npy: false,
            calibration: None,
        },
        &super::out::Printed,
    )
    .map_err(super::out::failed)?;
    crate::outln!(
        "  {} ({} files: s0, DoLP, AoLP, I^d/I^s/I^α, mask per band, stokes.exr)",
        out.published(&pictures.join("frame0-polarisation"))
            .display(),
        polar.files.len()
    );
    let path_plot = pictures.join("camera-path.png");
    plot_path(&scene, report.pulses as usize, &tracked, &path_plot)?;
    crate::outln!("  {}", out.published(&path_plot).display());

    let mut summary = serde_json::json!({
        "scene": scene_path.display().to_string(),
        "resolution": resolution,
        "capture": report,
        "pose_accuracy": accuracy,
        "fit": fit.summary,
    });
    let summary_path = root.join("summary.json");
    // every path in the summary is relative to its own folder (the staging folder moves whole)
    crate::cli::out::paths_relative_to(&mut summary, &root);
    ellipso_report::atomic_file::write(&summary_path, serde_json::to_vec_pretty(&summary)?)?;
    let shown = |p: &Path| out.published(p).display().to_string();
    let lines = [
        ("session (raw frames + event log) ", shown(&dir)),
        (
            "polarisation images of frame 0   ",
            shown(&pictures.join("frame0-polarisation")),
        ),
        ("camera path plot                 ", shown(&path_plot)),
        ("fitted model (PLY, per vertex)   ", shown(&fit.ply)),
        (
            "fit pictures (maps, Mueller grid, relit, novel view) ",
            shown(&fit.dir),
        ),
        ("summary                          ", shown(&summary_path)),
    ];
    let published = out.commit()?;
    crate::outln!("\nresults in {}:", published.display());
    for (what, path) in lines {
        crate::outln!("  {what} {path}");
    }
    Ok(())
}

/// Top view of the camera path: truth (line) and tracked positions (points).
fn plot_path(
    scene: &Scene,
    photos: usize,
    tracked: &[TrackedFrame],
    out: &Path,
) -> anyhow::Result<()> {
    let truth: Vec<(f64, f64)> = scene
        .camera_poses
        .iter()
        .take(photos)
        .map(|p| {
            let t = p.world_from_camera.translation.vector;
            (t.x * 1e3, t.y * 1e3)
        })
        .collect();
    let tracked_xy: Vec<(f64, f64)> = tracked
        .iter()
        .filter_map(|t| t.result.as_ref().ok())
        .map(|p| {
            let t = p.world_from_camera.translation.vector;
            (t.x * 1e3, t.y * 1e3)
        })
        .collect();
    LinePlot::new("camera path, top view: simulator truth vs AprilTag tracking")
        .x_label("x (mm)")
        .y_label("y (mm)")
        .legend(LegendPosition::TopRight)
        .series("truth", truth)
        .series("tracked", tracked_xy)
        .save_png(out)?;
    Ok(())
}

/// The demo's fit: where it went and its scores.
struct DemoFit {
    dir: PathBuf,
    ply: PathBuf,
    summary: serde_json::Value,
}

/// Builds the object's mesh from the session's frames (`ellipso mesh`), fits it (`ellipso fit`)
/// and only then compares with the simulator's truth: the mesh's distance to the true surface
/// before and after the fit's shape refinement, and each fitted vertex's parameters and normal
/// against the truth at the closest point of the true surface.
fn fit_and_score(
    scene: &Scene,
    session: &ellipso_session::reader::Session,
    out: &ellipso_report::output::OutputDir,
    quick: bool,
) -> anyhow::Result<DemoFit> {
    let dir = out.path().join("fit");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let started = std::time::Instant::now();
    let progress = super::progress::Progress::spinner("mesh");
    let (mesh, mesh_report, hull) = ellipso_mesh::output::mesh_of_session(
        session,
        None,
        &ellipso_mesh::MeshConfig::default(),
        &super::out::Printed,
        &mut |stage| progress.set_message(stage),
    )
    .map_err(super::out::failed)?;
    progress.finish(format!(
        "{} vertices from {} frames",
        mesh_report.vertices, mesh_report.frames_used
    ));
    let mesh_s = started.elapsed().as_secs_f64();
    let mesh_path = dir.join("mesh.ply");
    ellipso_mesh::output::write_mesh(&mesh, &mesh_report, &mesh_path)
        .map_err(super::out::failed)?;
    crate::outln!(
        "mesh         {} vertices carved from {} frames in {mesh_s:.1} s",
        mesh.positions().len(),
        mesh_report.frames_used,
    );
    let config = ellipso_fit::session::SessionFitConfig {
        outer_iterations: if quick {
            1
        } else {
            ellipso_fit::session::SessionFitConfig::default().outer_iterations
        },
        hull: Some(std::sync::Arc::new(hull)),
        ..Default::default()
    };
    let to = ellipso_fit::output::OutputTo {
        dir: &dir,
        publish: &|p| out.published(p),
    };
    let (steps, say) = (
        &mut super::progress::Spinners::default(),
        &super::out::Printed,
    );
    let run =
        ellipso_mesh::fit_run::fit_and_export(session, &mesh, None, to, None, &config, steps, say)
            .map_err(super::out::failed)?;
    let config = ellipso_fit::session::with_session_sensor(session, &config);

    // Only now the truth.
    let truth = ellipso_bench::chain::truth_for_scoring(scene)?;
    let at = ellipso_bench::truth_map::truth_at(&truth, run.fit.mesh.positions());
    let fits = &run.fit.outcome.fits;
    let score =
        ellipso_bench::score::score_fit(fits, &at, &truth.material_names, run.fit.set.colour);
    let held_out = run.fit.held_out_set.as_ref().map(|held| {
        ellipso_bench::score::holdout_beside_truth(
            held,
            fits,
            &at,
            ellipso_bench::accuracy::full_scale_dn(scene),
        )
    });
    crate::outln!("scoring: the same session fitted on the true mesh, for η beside it…");
    let scores =
        super::bench::mesh::mesh_scores(scene, session, &mesh, &run.fit, run.wall_s, &config)?;
    // the carved and refined meshes against the truth, as the mesh bench scores them
    let (before, after) = (&scores.distance_before, &scores.distance_after);
    let summary = serde_json::json!({
        "vertices": fits.len(),
        "fitted": score.scored,
        "mesh_s": mesh_s,
        "wall_s": run.wall_s,
        "times_s": run.fit.outcome.times,
        "mesh_before_fit": before,
        "mesh_after_fit": after,
        "materials": score.materials,
        "eta_material_mean_abs_error_pct": score.eta_material_mean_pct,
        "eta_material_max_abs_error_pct": score.eta_material_max_pct,
        "eta_vertex_median_error_pct": score.eta_vertex_median_pct,
        "eta_vertex_unpooled_median_error_pct": score.eta_vertex_unpooled_median_pct,
        "normal_median_error_deg": score.normal_median_deg,
        "normal_p90_error_deg": score.normal_p90_deg,
        "rho_d_median_error_pct": score.rho_d_median_pct,
        "held_out_beside_truth": held_out,
        "input_mesh": "fit/mesh.ply",
        "surface": {
            "before": scores.before,
            "after": scores.after,
            "update": scores.surface_update,
        },
        "eta_carved_vs_true_mesh": scores.eta,
        "true_mesh_fit_s": scores.true_mesh_fit_s,
    });
    crate::outln!(
        "mesh vs truth  Chamfer {:.3} mm before the fit, {:.3} mm after its shape refinement (Hausdorff {:.2} → {:.2} mm)",
        before.chamfer_m * 1e3,
        after.chamfer_m * 1e3,
        before.hausdorff_m * 1e3,
        after.hausdorff_m * 1e3,
    );
    crate::outln!(
        "surface      observed {} vertices: {:.3} mm mean from the truth before the fit, {:.3} mm after (p90 {:.3} mm); unobserved {}: {:.3} → {:.3} mm; normals {:.2}° median (mesh before {:.2}°)",
        scores.after.observed_vertices,
        scores.before.observed_mean_m * 1e3,
        scores.after.observed_mean_m * 1e3,
        scores.after.observed_p90_m * 1e3,
        scores.after.unobserved_vertices,
        scores.before.unobserved_mean_m * 1e3,
        scores.after.unobserved_mean_m * 1e3,
        scores.after.fit_normal_median_deg.unwrap_or(f64::NAN),
        scores.before.mesh_normal_median_deg,
    );
    for m in &scores.eta {
        crate::outln!(
            "η            {:<15} carved mesh {:+.2} %, true mesh {:+.2} % (difference {:.2} points)",
            m.name,
            m.carved_pct,
            m.true_mesh_pct,
            (m.carved_pct - m.true_mesh_pct).abs()
        );
    }
    crate::outln!(
        "fit          {}/{} vertices in {:.1} s · normal error median {:.2}° (90th percentile {:.2}°) · ρd error median {:.1} %",
        score.scored,
        fits.len(),
        run.wall_s,
        score.normal_median_deg,
        score.normal_p90_deg,
        score.rho_d_median_pct,
    );
    crate::outln!("η per material (median over the vertices that report η, against the truth):");
    for m in &score.materials {
        let verdict = if m.vertices == 0 {
            "unidentified: no vertex's data fix η".to_string()
        } else {
            format!(
                "{:.4} (true {:.4}, {:+.2} %; before pooling {:+.2} %)",
                m.eta_median, m.eta_true, m.eta_error_pct, m.eta_unpooled_error_pct
            )
        };
        crate::outln!(
            "  {:16} {verdict} · {} vertices report η, {} withheld",
            m.name,
            m.vertices,
            m.unidentified_vertices
        );
    }
    crate::outln!(
        "η per vertex  median error {:.2} % (before pooling {:.2} %)",
        score.eta_vertex_median_pct,
        score.eta_vertex_unpooled_median_pct
    );
    if let Some(h) = &held_out {
        crate::outln!(
            "held-out     re-render relative RMSE, fit / the truth's own on the same samples: s0 {:.3} / {:.3} · I^s {:.3} / {:.3} · I^α {:.3} / {:.3}",
            h.fit.s0.relative_rmse,
            h.truth.s0.relative_rmse,
            h.fit.specular.relative_rmse,
            h.truth.specular.relative_rmse,
            h.fit.alpha.relative_rmse,
            h.truth.alpha.relative_rmse,
        );
    }
    Ok(DemoFit {
        ply: dir.join("fit.ply"),
        dir,
        summary,
    })
}
