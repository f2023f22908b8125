//! `ellipso bench mesh`: how close the built-in mesh (`ellipso mesh`) comes to the simulator's
//! true object on the shipped scenes, and what it costs — Chamfer and Hausdorff distance to the
//! truth, wall time and peak memory of `ellipso mesh` run as its own process; with `--fit`,
//! also the distance after the fit's shape refinement on that mesh ([`mesh_scores`], which the
//! demo scores its fit with too); with `--scale-vertices`, `ellipso fit --vertices N` as its own
//! process on the demo session; with `--seeds`, each scene captured again with those scene
//! seeds and benched as its own row, so one capture's figures can be told from the method's.
//!
//! Sessions are captured on the simulated rig (real pty link, pairing, tracking:
//! [`crate::rig_capture`]) into the work folder, once: an existing session there is reused, so
//! the report can be re-made without re-rendering. Writes `mesh-bench.json` and a Markdown
//! report ([`markdown`]).
//!
//! Contract: the report and its JSON are claimed before any capture; the processes run are the
//! request's executable; a capture that cannot be made, meshed or fitted is a row of the
//! report's failures (with its error) and the others still run — the report and its JSON are
//! written, and then the run ends in an error naming the failed captures; nothing here prints
//! (lines to the caller's [`Say`], the fit's mesh step to its [`Steps`], the captures recorded
//! by its [`Recorder`]).

pub mod markdown;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use ellipso_fit::session::{SessionFit, SessionFitConfig};
use ellipso_mesh::MeshReport;
use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::distance::{MeshDistance, mesh_distance};
use ellipso_pipeline::steps::Steps;
use ellipso_report::output::{FileFormat, OutputFile};
use ellipso_rig::acquire::ready::Recorder;
use ellipso_run_error::{Context, RunError, Say};
use ellipso_run_error::{ensure, say};
use ellipso_sim::scene::{Scene, shipped_scene};

use crate::surface::{EtaBeside, SurfaceScore, eta_beside, surface_score};
use crate::truth::TruthObject;

/// What `ellipso bench mesh` is asked (its flags, parsed), and the binary to run as its own
/// process.
#[derive(Debug, Clone)]
pub struct MeshBenchRequest {
    /// Shipped scenes (`sim/scenes/NAME.toml`).
    pub scenes: Vec<String>,
    /// Capture resolution.
    pub resolution: [u32; 2],
    /// Photos per capture (default: each scene's path).
    pub photos: Option<u32>,
    /// Where sessions are captured (and reused from).
    pub work: PathBuf,
    /// Worker threads given to `ellipso mesh`.
    pub threads: usize,
    /// Also fit each session on its built-in mesh and score the refined shape.
    pub fit: bool,
    /// `ellipso fit --vertices N` runs on the demo session, one per count.
    pub scale_vertices: Vec<usize>,
    /// Each scene is also captured with these scene seeds (another capture path where the
    /// scene's is seeded, other sensor noise) and benched as its own row: how much of a
    /// difference one capture shows is that capture's.
    pub seeds: Vec<u64>,
    /// The Markdown report.
    pub report: PathBuf,
    /// The `ellipso` executable that `ellipso mesh` and `ellipso fit` run as (the binary passes
    /// its own, `std::env::current_exe`).
    pub exe: PathBuf,
}

/// The files written, as shown to the user.
#[derive(Debug, Clone)]
pub struct MeshBenchFiles {
    /// The Markdown report.
    pub report: PathBuf,
    /// `mesh-bench.json`.
    pub json: PathBuf,
}

/// One scene's result.
#[derive(Debug, serde::Serialize)]
pub struct SceneResult {
    /// Row label: the scene name, with ` seed N` for a capture with another seed.
    pub scene: String,
    /// The shipped scene's name (rows of one scene share it).
    pub base_scene: String,
    /// Frames carved from.
    pub frames: usize,
    /// Vertices of the mesh.
    pub vertices: usize,
    /// Distance of the built-in mesh to the truth.
    pub before_fit: MeshDistance,
    /// Wall time of `ellipso mesh`, s.
    pub mesh_s: f64,
    /// Peak resident memory of `ellipso mesh`, bytes (Linux).
    pub peak_rss_bytes: Option<u64>,
    /// The mesh's own report.
    pub report: MeshReport,
    /// The fit's scores (with `--fit`).
    pub fit: Option<MeshScores>,
}

/// A fit on the carved mesh scored against the truth (`ellipso bench mesh --fit` and the demo).
#[derive(Debug, Clone, serde::Serialize)]
pub struct MeshScores {
    /// The carved mesh (before the surface update).
    pub before: SurfaceScore,
    /// The refined mesh (after it).
    pub after: SurfaceScore,
    /// Chamfer/Hausdorff of the carved mesh.
    pub distance_before: MeshDistance,
    /// Chamfer/Hausdorff of the refined mesh.
    pub distance_after: MeshDistance,
    /// The surface update, step by step.
    pub surface_update: Vec<ellipso_fit::shape::surface::SurfaceIteration>,
    /// Per-material η on the carved-and-refined mesh beside the true mesh's fit.
    pub eta: Vec<EtaBeside>,
    /// What share of the visible surface the carved mesh's fit covers, per material, and how
    /// honest its σ are (`crate::coverage`).
    pub coverage: crate::coverage::CoverageScores,
    /// Wall time of the fit on the carved mesh, s.
    pub fit_s: f64,
    /// Wall time of the fit on the true mesh, s.
    pub true_mesh_fit_s: f64,
    /// The same session fitted on the true mesh: its refined normals against the truth at its
    /// observed vertices, median, degrees — what the data give without any shape error.
    pub true_mesh_normal_median_deg: f64,
}

/// A capture the bench could not make, mesh or fit.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FailedCapture {
    /// Row label (as [`SceneResult::scene`]).
    pub scene: String,
    /// The error, in words.
    pub error: String,
}

/// The scenes `ellipso bench mesh` runs when none are named.
pub const DEFAULT_SCENES: [&str; 3] = ["sphere", "multi_material", "demo"];

/// The report `ellipso bench mesh` writes when none is named.
pub const DEFAULT_REPORT: &str = "docs/mesh-bench.md";

/// One `ellipso fit --vertices N` run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ScaleResult {
    /// Target vertex count.
    pub target_vertices: usize,
    /// Vertices of the carved mesh.
    pub vertices: usize,
    /// Wall time of the whole `ellipso fit` (carving included), s.
    pub wall_s: f64,
    /// The fit's own stage times.
    pub times_s: serde_json::Value,
    /// Peak resident memory of the process, bytes.
    pub peak_rss_bytes: Option<u64>,
    /// Mean distance of the observed vertices of the refined mesh to the truth, m.
    pub observed_mean_m: f64,
    /// Vertices observed.
    pub observed: usize,
}

/// Runs `ellipso bench mesh` (module doc).
pub fn run(
    args: &MeshBenchRequest,
    recorder: &mut dyn Recorder,
    steps: &mut dyn Steps,
    say: &dyn Say,
) -> Result<MeshBenchFiles, RunError> {
    let started = Instant::now();
    // the report and its data are claimed first (the work directory is a cache of sessions
    // that each capture creates fresh and later runs reuse)
    let json = OutputFile::claim(
        &args.work.join("mesh-bench.json"),
        "bench-mesh",
        FileFormat::JSON,
        &[],
        None,
    )?;
    let report = OutputFile::claim(&args.report, "bench-mesh", FileFormat::MARKDOWN, &[], None)?;
    let mut results = Vec::new();
    let mut failed = Vec::new();
    for name in &args.scenes {
        let scene_path = shipped_scene(&format!("{name}.toml"));
        ensure!(
            scene_path.is_file(),
            "scene {} not found",
            scene_path.display()
        );
        let scene = Scene::load(&scene_path)?;
        let session_dir = args.work.join(name);
        let result = ensure_captured(name, &scene_path, &session_dir, args, recorder, say)
            .and_then(|()| bench_scene(name, name, &scene, &session_dir, args, steps, say));
        keep(result, name.clone(), &mut results, &mut failed, say);
        for &seed in &args.seeds {
            let label = format!("{name}-seed{seed}");
            let variant = args.work.join(format!("{label}.toml"));
            let edit = crate::variant::SceneEdit {
                seed: Some(seed),
                ..Default::default()
            };
            let scene = crate::variant::write_variant(&scene_path, &edit, &variant)?;
            let session_dir = args.work.join(&label);
            let row = format!("{name} seed {seed}");
            let result = ensure_captured(&label, &variant, &session_dir, args, recorder, say)
                .and_then(|()| bench_scene(&label, name, &scene, &session_dir, args, steps, say))
                .map(|r| SceneResult {
                    scene: row.clone(),
                    ..r
                });
            keep(result, row, &mut results, &mut failed, say);
        }
    }
    let mut scale = Vec::new();
    for &n in &args.scale_vertices {
        let scene = Scene::load(&shipped_scene("demo.toml"))?;
        let session_dir = args.work.join("demo");
        ensure!(
            session_dir.join("manifest.json").is_file(),
            "--scale-vertices runs on the demo session: add demo to --scenes"
        );
        scale.push(scale_run(&scene, &session_dir, n, args, say)?);
    }
    json.write(serde_json::to_vec_pretty(
        &serde_json::json!({"scenes": results, "failed": failed, "scale": scale}),
    )?)?;
    report.write(markdown::markdown(
        &results,
        &failed,
        &scale,
        args,
        started.elapsed().as_secs_f64(),
    ))?;
    ensure!(
        failed.is_empty(),
        "{} of {} captures failed ({}); {} lists them with their errors",
        failed.len(),
        failed.len() + results.len(),
        failed
            .iter()
            .map(|f| f.scene.as_str())
            .collect::<Vec<_>>()
            .join(", "),
        report.shown().display()
    );
    Ok(MeshBenchFiles {
        report: report.shown().to_path_buf(),
        json: json.shown().to_path_buf(),
    })
}

/// A capture's row, or its failure (said at once, and kept for the report).
fn keep(
    result: Result<SceneResult, RunError>,
    scene: String,
    results: &mut Vec<SceneResult>,
    failed: &mut Vec<FailedCapture>,
    say: &dyn Say,
) {
    match result {
        Ok(r) => results.push(r),
        Err(e) => {
            say!(say, "[{scene}] failed: {e}");
            failed.push(FailedCapture {
                scene,
                error: e.to_string(),
            });
        }
    }
}

/// Captures `scene_path` into `session_dir` unless a session is there already (then reused).
fn ensure_captured(
    label: &str,
    scene_path: &Path,
    session_dir: &Path,
    args: &MeshBenchRequest,
    recorder: &mut dyn Recorder,
    say: &dyn Say,
) -> Result<(), RunError> {
    if session_dir.join("manifest.json").is_file() {
        say!(say, "[{label}] reusing {}", session_dir.display());
        return Ok(());
    }
    say!(
        say,
        "[{label}] capturing at {}×{}…",
        args.resolution[0],
        args.resolution[1]
    );
    capture_session(scene_path, session_dir, args, recorder, say)
}

/// Captures `scene` into the new session `dir` on the simulated rig, quietly, and tracks it.
fn capture_session(
    scene: &Path,
    dir: &Path,
    args: &MeshBenchRequest,
    recorder: &mut dyn Recorder,
    say: &dyn Say,
) -> Result<(), RunError> {
    crate::rig_capture::capture_on_sim_rig(
        scene,
        dir,
        args.photos,
        args.resolution,
        None,
        recorder,
    )?;
    ellipso_vision::process::track_and_append(dir, say)?;
    Ok(())
}

/// The simulator's true object to score a mesh against: the analytic sphere as a fine
/// icosphere (40 962 vertices), meshes as rendered.
pub fn truth_object(scene: &Scene) -> Result<TruthObject, RunError> {
    let sphere = matches!(
        scene.objects.first().map(|o| &o.geometry),
        Some(ellipso_sim::scene::ObjectGeometry::Sphere(_))
    );
    Ok(TruthObject::from_scene(scene, sphere.then_some(6))?)
}

fn bench_scene(
    name: &str,
    base_scene: &str,
    scene: &Scene,
    session_dir: &Path,
    args: &MeshBenchRequest,
    steps: &mut dyn Steps,
    say: &dyn Say,
) -> Result<SceneResult, RunError> {
    let out = args.work.join(format!("{name}-mesh.ply"));
    say!(say, "[{name}] ellipso mesh --threads {}…", args.threads);
    let t0 = Instant::now();
    let o = Command::new(&args.exe)
        .arg("mesh")
        .arg(session_dir)
        .arg("--out")
        .arg(&out)
        .args(["--threads", &args.threads.to_string()])
        .output()
        .context("running ellipso mesh")?;
    let mesh_s = t0.elapsed().as_secs_f64();
    ensure!(
        o.status.success(),
        "ellipso mesh failed on {name}: {}",
        String::from_utf8_lossy(&o.stderr).trim()
    );
    let report_path = ellipso_pipeline::mesh::report_path(&out);
    let report: MeshReport = serde_json::from_slice(&std::fs::read(&report_path)?)
        .with_context(|| format!("reading {}", report_path.display()))?;
    let peak_rss_bytes = report.peak_rss_bytes;
    let mesh = TriangleMesh::load(&out)?;
    let truth = truth_object(scene)?.mesh;
    let before_fit = mesh_distance(&mesh, &truth, 50_000, 1);
    say!(
        say,
        "[{name}] {} vertices · Chamfer {:.3} mm · Hausdorff {:.3} mm · {:.1} s · peak {:.0} MB",
        mesh.positions().len(),
        before_fit.chamfer_m * 1e3,
        before_fit.hausdorff_m * 1e3,
        mesh_s,
        peak_rss_bytes.unwrap_or(0) as f64 / 1e6
    );
    let fit = if args.fit {
        let session = ellipso_session::reader::open(session_dir)?;
        // taken once for the carving and the fit (their warnings said once)
        let poses = ellipso_pipeline::poses::poses_of(&session, say)?;
        let (_, _, hull) = ellipso_pipeline::mesh::mesh_of_session(
            &session,
            Some(&poses[..]),
            &ellipso_mesh::MeshConfig::default(),
            say,
            steps,
        )?;
        let config = SessionFitConfig {
            hull: Some(std::sync::Arc::new(hull)),
            ..SessionFitConfig::default()
        };
        let config = ellipso_fit::session::with_session_sensor(&session, &config);
        let t0 = Instant::now();
        let fit = ellipso_fit::session::fit_session(&session, &mesh, &poses, &config, &mut |_| {})?;
        let fit_s = t0.elapsed().as_secs_f64();
        let scores = mesh_scores(scene, &session, &mesh, &fit, fit_s, &config, say)?;
        say!(
            say,
            "[{name}] observed surface {:.3} → {:.3} mm mean, normals {:.2}° median (true mesh {:.2}°); Chamfer {:.3} → {:.3} mm ({:.0} s)",
            scores.before.observed_mean_m * 1e3,
            scores.after.observed_mean_m * 1e3,
            scores.after.fit_normal_median_deg.unwrap_or(f64::NAN),
            scores.true_mesh_normal_median_deg,
            scores.distance_before.chamfer_m * 1e3,
            scores.distance_after.chamfer_m * 1e3,
            fit_s
        );
        Some(scores)
    } else {
        None
    };
    Ok(SceneResult {
        scene: name.into(),
        base_scene: base_scene.into(),
        frames: report.frames_used,
        vertices: mesh.positions().len(),
        before_fit,
        mesh_s,
        peak_rss_bytes,
        report,
        fit,
    })
}

/// Scores `fit` (of `session` on the carved mesh `carved`, `fit_s` seconds, settings
/// `config`) against the scene's truth (lines to `say`), and fits the same session on the true mesh for the
/// per-material η beside it (the same settings, no hull).
pub fn mesh_scores(
    scene: &Scene,
    session: &ellipso_session::reader::Session,
    carved: &TriangleMesh,
    fit: &SessionFit,
    fit_s: f64,
    config: &SessionFitConfig,
    say: &dyn Say,
) -> Result<MeshScores, RunError> {
    let truth = crate::truth::truth_for_scoring(scene)?;
    let poses = ellipso_pipeline::poses::poses_of(session, say)?;
    let true_config = SessionFitConfig {
        hull: None,
        ..config.clone()
    };
    let true_mesh = crate::truth::true_mesh(scene)?;
    let t0 = Instant::now();
    let on_truth =
        ellipso_fit::session::fit_session(session, &true_mesh, &poses, &true_config, &mut |_| {})?;
    let true_mesh_fit_s = t0.elapsed().as_secs_f64();
    let per_material = |f: &SessionFit| {
        let at = crate::truth_map::truth_at(&truth, f.mesh.positions());
        crate::score::score_fit(&f.outcome.fits, &at, &truth.material_names, f.set.colour)
    };
    let (coverage, _) = crate::coverage::score_session_fit(scene, session, fit)?;
    Ok(MeshScores {
        coverage,
        before: surface_score(&truth, carved, None, &fit.observed),
        after: surface_score(&truth, &fit.mesh, Some(&fit.outcome.fits), &fit.observed),
        distance_before: mesh_distance(carved, &truth.mesh, 50_000, 1),
        distance_after: mesh_distance(&fit.mesh, &truth.mesh, 50_000, 1),
        surface_update: fit.surface.clone(),
        eta: eta_beside(&per_material(fit), &per_material(&on_truth)),
        fit_s,
        true_mesh_fit_s,
        true_mesh_normal_median_deg: surface_score(
            &truth,
            &on_truth.mesh,
            Some(&on_truth.outcome.fits),
            &on_truth.observed,
        )
        .fit_normal_median_deg
        .unwrap_or(f64::NAN),
    })
}

/// `ellipso fit SESSION --vertices N` as its own process: time, memory, observed surface.
fn scale_run(
    scene: &Scene,
    session_dir: &Path,
    vertices: usize,
    args: &MeshBenchRequest,
    say: &dyn Say,
) -> Result<ScaleResult, RunError> {
    let out = args.work.join(format!("demo-fit-{vertices}"));
    say!(say, "[scale] ellipso fit --vertices {vertices}…");
    let t0 = Instant::now();
    let o = Command::new(&args.exe)
        .arg("fit")
        .arg(session_dir)
        .arg("--out")
        .arg(&out)
        .args(["--vertices", &vertices.to_string(), "--json"])
        .output()
        .context("running ellipso fit")?;
    let wall_s = t0.elapsed().as_secs_f64();
    ensure!(
        o.status.success(),
        "ellipso fit --vertices {vertices} failed: {}",
        String::from_utf8_lossy(&o.stderr).trim()
    );
    let json: serde_json::Value = serde_json::from_slice(&o.stdout)
        .with_context(|| format!("reading the JSON of ellipso fit --vertices {vertices}"))?;
    let summary = &json["summary"];
    let fitted = ellipso_fit::export::ply::read_fit_ply(&out.join("fit.ply"))?;
    // observed as the other rows count it: a kept sample (`shape::surface::observed_vertices`)
    let observed: Vec<bool> = fitted.iter().map(|v| v.samples > 0).collect();
    let positions: Vec<nalgebra::Point3<f64>> = fitted
        .iter()
        .map(|v| {
            nalgebra::Point3::new(
                v.position[0].into(),
                v.position[1].into(),
                v.position[2].into(),
            )
        })
        .collect();
    let truth = crate::truth::truth_for_scoring(scene)?;
    let at = crate::truth_map::truth_at(&truth, &positions);
    let d: Vec<f64> = at
        .iter()
        .zip(&observed)
        .filter(|(_, o)| **o)
        .filter_map(|(t, _)| t.map(|t| t.distance_m))
        .collect();
    let result = ScaleResult {
        target_vertices: vertices,
        vertices: fitted.len(),
        wall_s,
        times_s: summary["times_s"].clone(),
        peak_rss_bytes: summary["peak_rss_bytes"].as_u64(),
        observed_mean_m: d.iter().sum::<f64>() / d.len().max(1) as f64,
        observed: d.len(),
    };
    say!(
        say,
        "[scale] {} vertices: {:.0} s, peak {:.0} MB, observed surface {:.3} mm",
        result.vertices,
        wall_s,
        result.peak_rss_bytes.unwrap_or(0) as f64 / 1e6,
        result.observed_mean_m * 1e3
    );
    Ok(result)
}
