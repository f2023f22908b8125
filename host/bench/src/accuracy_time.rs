//! `ellipso bench accuracy`: what accuracy costs in time — sweeps of photo count, solver effort
//! and vertex count on simulated captures with known truth (the sphere and the four-material
//! blob, 12-bit, shot + read noise), each run timed and scored against the truth, plus one large
//! run (100 000 vertices × 150 views) for throughput. Writes the report (Markdown table + two
//! PNG plots of error against seconds + JSON) — by default to `docs/accuracy-vs-time.md`.
//!
//! The `bracket` sweep (issue 18) compares, on the four-material blob and one photo budget in
//! seconds, one exposure (`multi_material.toml`, 200 photos at 500 ms) with the 3-step
//! flash-energy bracket (`multi_material_bracket.toml`, 600 photos, 1, ¼, 1⁄16 in turn), plus
//! the bracket scene's 600 views all at full energy (more views without the bracket), and scores
//! the clusters' σs and the samples kept at the lobe peak ([`crate::accuracy::specular`]).
//!
//! Every figure in one report comes from one run of this command on one machine, so ratios
//! between rows are meaningful even on a shared, noisy machine; absolute seconds are not
//! portable. The fit time is also reported divided by the time of one forward evaluation of
//! every observation, measured right after it in the same run.

use ellipso_report::output::{FileFormat, OutputFile};
use std::path::{Path, PathBuf};
use std::time::Instant;

use ellipso_run_error::{Context, RunError, Say};
use ellipso_run_error::{ensure, say};

pub mod report;

/// The commands' result.
type Result<T> = std::result::Result<T, RunError>;
use ellipso_sim::scene::Scene;

use crate::accuracy::specular::LobeScores;
use crate::accuracy::{CaptureCase, Scores, evaluate, forward_all, simulate};
use ellipso_fit::pipeline::{FitConfig, fit_sample_set};
use ellipso_report::plot::{LegendPosition, LinePlot};

/// Photo counts of the end-to-end sweep (the demo scene's capture path; 150 is its own).
const END_TO_END_PHOTOS: [usize; 3] = [50, 100, 150];

/// What `ellipso bench accuracy` runs (its flags, parsed by the binary).
#[derive(Debug, Clone)]
pub struct AccuracyOptions {
    /// Scenes to sweep (default: the shipped sphere and multi-material scenes).
    pub scenes: Vec<PathBuf>,
    /// Report file (Markdown); plots and JSON are written beside it (plots under `img/`).
    pub report: PathBuf,
    /// Small sweep for a smoke test (few vertices and photos; no large run).
    pub quick: bool,
    /// Skip the large runs (100 000 vertices × 150 and × 300 views, 500 000 × 60).
    pub no_large: bool,
    /// Noise and normal-tilt seed.
    pub seed: u64,
    /// Work directory of the end-to-end sweep's rendered sessions (kept and reused; shared with
    /// `ellipso bench chain`).
    pub work: PathBuf,
    /// Which sweeps to run (default all): photos, solver, vertices, bracket, large,
    /// end_to_end (rendered frames of the demo scene through tracking, carving and the fit).
    pub sweeps: Vec<String>,
    /// Photos of the solver and vertex sweeps (default 100; 25 with --quick).
    pub photos: Option<usize>,
    /// Fraction of the views held out of every fit and scored as a re-render (default 0.1).
    pub holdout: f64,
}

/// One timed, scored run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RunResult {
    /// Scene name.
    pub scene: String,
    /// Which sweep the run belongs to.
    pub sweep: String,
    /// Solver setting label.
    pub solver: String,
    /// Photos.
    pub photos: usize,
    /// Views used by the fit (= photos).
    pub views: usize,
    /// Simulation wall time, s (not part of the fit).
    pub simulate_s: f64,
    /// Fit wall time (steps A + B + C), s.
    pub fit_s: f64,
    /// Stage times.
    pub times: ellipso_fit::pipeline::StageTimes,
    /// One forward evaluation of every observation, s.
    pub forward_s: f64,
    /// fit_s / forward_s.
    pub fit_over_forward: f64,
    /// The run's resident-memory high-water mark (simulation, fit, scoring), bytes (Linux).
    pub peak_rss_bytes: Option<u64>,
    /// Scores against the truth.
    pub scores: Scores,
    /// Re-render errors on the held-out views (`None` when none were held out).
    pub holdout: Option<ellipso_fit::holdout::FrameScore>,
    /// The clusters (when step B ran).
    pub clusters: Vec<ellipso_fit::augment::ClusterModel>,
    /// The uncertainty of η before and after pooling (when step B ran).
    pub pooling: Option<ellipso_fit::pipeline::PoolingSummary>,
    /// Vertices with virtual samples / with a pooled η prior (when step B ran).
    pub guided: Option<(usize, usize)>,
    /// Flash energies fired in turn (empty: one exposure).
    pub bracket: Vec<f64>,
    /// Cluster σs per material and samples kept at the lobe peak.
    pub lobes: LobeScores,
}

/// A solver setting of the effort sweep.
struct SolverSetting {
    label: &'static str,
    config: FitConfig,
}

fn solver_settings() -> Vec<SolverSetting> {
    let joint_only = |iterations: u32| {
        let mut c = FitConfig::joint_only();
        c.solver.max_iterations = iterations;
        c
    };
    vec![
        SolverSetting {
            label: "A, 12 iterations",
            config: joint_only(12),
        },
        SolverSetting {
            label: "A alone",
            config: FitConfig::joint_only(),
        },
        SolverSetting {
            label: "A, fast preset",
            config: FitConfig {
                solver: ellipso_fit::solve::SolverConfig::fast(),
                ..FitConfig::joint_only()
            },
        },
        SolverSetting {
            label: "A + B + C, 1 final pass (default)",
            config: FitConfig::default(),
        },
        SolverSetting {
            label: "A + B + C, 3 final passes",
            config: FitConfig::with_augmentation(3),
        },
    ]
}

/// The large runs (vertices, photos): the throughput target's 100 000 × 150, and 100 000 × 300
/// and 500 000 × 60, from which 500 000 × 300 is extrapolated.
pub const LARGE_RUNS: [(usize, usize); 3] = [(100_000, 150), (100_000, 300), (500_000, 60)];

/// Runs `ellipso bench accuracy`.
pub fn run(args: AccuracyOptions, say: &dyn Say) -> Result<()> {
    // the report's files are claimed before the hour of fitting, not after it
    let files = ReportFiles::claim(&args.report)?;
    let scenes = if args.scenes.is_empty() {
        vec![
            ellipso_sim::scene::shipped_scene("sphere.toml"),
            ellipso_sim::scene::shipped_scene("multi_material.toml"),
        ]
    } else {
        args.scenes.clone()
    };
    let (photo_sweep, subdivision_sweep, effort_photos): (Vec<usize>, Vec<u32>, usize) =
        if args.quick {
            (vec![25, 50], vec![2], args.photos.unwrap_or(25))
        } else {
            (
                vec![25, 50, 100, 200],
                vec![3, 4, 5],
                args.photos.unwrap_or(100),
            )
        };
    let wants = |sweep: &str| args.sweeps.is_empty() || args.sweeps.iter().any(|s| s == sweep);
    for s in &args.sweeps {
        ensure!(
            [
                "photos",
                "solver",
                "vertices",
                "bracket",
                "large",
                "end_to_end"
            ]
            .contains(&s.as_str()),
            "--sweeps: unknown sweep `{s}` (photos, solver, vertices, bracket, large, end_to_end)"
        );
    }
    ensure!(
        (0.0..0.9).contains(&args.holdout),
        "--holdout {}: must be in [0, 0.9)",
        args.holdout
    );
    let holdout = args.holdout;
    let base_subdivisions = if args.quick { Some(2) } else { None };
    let mut results = Vec::new();
    let started = Instant::now();
    for path in &scenes {
        let scene = Scene::load(path).with_context(|| format!("loading {}", path.display()))?;
        let name = scene
            .name
            .clone()
            .unwrap_or_else(|| path.display().to_string());
        let default = FitConfig::default();
        for &photos in photo_sweep.iter().filter(|_| wants("photos")) {
            let case = CaptureCase {
                photos,
                subdivisions: base_subdivisions,
                seed: args.seed,
                ..CaptureCase::default()
            };
            results.push(one_run(
                &scene, &name, "photos", "default", &case, &default, holdout, say,
            )?);
        }
        for setting in solver_settings().into_iter().filter(|_| wants("solver")) {
            let case = CaptureCase {
                photos: effort_photos,
                subdivisions: base_subdivisions,
                seed: args.seed,
                ..CaptureCase::default()
            };
            results.push(one_run(
                &scene,
                &name,
                "solver",
                setting.label,
                &case,
                &setting.config,
                holdout,
                say,
            )?);
        }
        for &s in subdivision_sweep.iter().filter(|_| wants("vertices")) {
            let case = CaptureCase {
                photos: effort_photos,
                subdivisions: Some(s),
                seed: args.seed,
                ..CaptureCase::default()
            };
            results.push(one_run(
                &scene, &name, "vertices", "default", &case, &default, holdout, say,
            )?);
        }
    }
    if wants("bracket") {
        results.extend(bracket_sweep(&args, base_subdivisions, holdout, say)?);
    }
    if !args.quick && !args.no_large && wants("large") {
        // Throughput and scale (issue 19): 100 000 × 150, then the two runs the 500 000 × 300
        // extrapolation rests on (report::scale_section).
        let scene = Scene::load(&ellipso_sim::scene::shipped_scene("sphere.toml"))?;
        for (vertices, photos) in LARGE_RUNS {
            let case = CaptureCase {
                photos,
                // Icosphere levels 7 and 8: 163 842 and 655 362 vertices, cut to `vertices`.
                subdivisions: Some(if vertices > 163_842 { 8 } else { 7 }),
                max_vertices: Some(vertices),
                seed: args.seed,
                ..CaptureCase::default()
            };
            results.push(one_run(
                &scene,
                "sphere",
                "large",
                "default",
                &case,
                &FitConfig::default(),
                holdout,
                say,
            )?);
        }
    }
    // What a capture really gives: rendered frames through the whole chain (not in --quick:
    // each capture renders 50–150 frames at 1224×1024).
    let end_to_end = if !args.quick && wants("end_to_end") {
        let scene_path = ellipso_sim::scene::shipped_scene("demo.toml");
        let scene = Scene::load(&scene_path)?;
        let [w, h] = scene.rig.camera.resolution_px;
        let bench = crate::chain::Bench {
            scene_path,
            scene,
            work: args.work.clone(),
            resolution: Some([w / 2, h / 2]),
            fit: ellipso_fit::session::SessionFitConfig::default(),
        };
        crate::chain::photo_sweep(&bench, &END_TO_END_PHOTOS, &mut |stage| {
            say.err(format_args!("  end to end: {stage}"))
        })?
    } else {
        Vec::new()
    };
    write_report(
        &files,
        &results,
        &end_to_end,
        started.elapsed().as_secs_f64(),
        &command_line(&args),
        say,
    )?;
    Ok(())
}

/// The `bracket` sweep (module doc): one exposure against the 3-step bracket on the same photo
/// budget in seconds, and the bracket scene's views at full energy. Each scene keeps its own
/// photo count (a third of it with `--quick`).
fn bracket_sweep(
    args: &AccuracyOptions,
    subdivisions: Option<u32>,
    holdout: f64,
    say: &dyn Say,
) -> Result<Vec<RunResult>> {
    let load = |name: &str| -> Result<Scene> {
        let path = ellipso_sim::scene::shipped_scene(name);
        Scene::load(&path).with_context(|| format!("loading {}", path.display()))
    };
    let single = load("multi_material.toml")?;
    let bracketed = load("multi_material_bracket.toml")?;
    let photos = |scene: &Scene| {
        let n = scene.camera_poses.len();
        if args.quick { n.div_ceil(3) } else { n }
    };
    let runs: [(&Scene, &str, Option<Vec<f64>>); 3] = [
        (&single, "one exposure", None),
        (&bracketed, "bracket", None),
        (&bracketed, "same views, full energy", Some(Vec::new())),
    ];
    let mut results = Vec::new();
    for (scene, label, bracket) in runs {
        let case = CaptureCase {
            photos: photos(scene),
            subdivisions,
            seed: args.seed,
            bracket,
            ..CaptureCase::default()
        };
        results.push(one_run(
            scene,
            "multi_material",
            "bracket",
            label,
            &case,
            &FitConfig::default(),
            holdout,
            say,
        )?);
    }
    Ok(results)
}

#[allow(clippy::too_many_arguments)] // the run's labels, its case and settings, and the printer
fn one_run(
    scene: &Scene,
    name: &str,
    sweep: &str,
    solver: &str,
    case: &CaptureCase,
    config: &FitConfig,
    holdout: f64,
    say: &dyn Say,
) -> Result<RunResult> {
    // The run's own peak memory: the simulated capture (what a session's samples would be),
    // the fit and its scoring.
    let rss_reset = ellipso_report::memory::reset_peak_rss();
    let t = Instant::now();
    let full = simulate(scene, case).map_err(|e| RunError::from_boxed(e.into()))?;
    let simulate_s = t.elapsed().as_secs_f64();
    // The held-out views are taken out before the fit sees anything.
    let (train, held) = ellipso_fit::holdout::split_set(&full.set, holdout);
    let capture = crate::accuracy::SimulatedCapture {
        truth: full.truth,
        set: train,
        flash_energy_rel: full.flash_energy_rel,
        near_mirror: full.near_mirror,
    };
    let mut config = config.clone();
    config.solver.sensor = crate::accuracy::sensor_model(scene);
    let outcome = fit_sample_set(&capture.set, None, &config, &mut |_| {});
    let full_scale = crate::accuracy::full_scale_dn(scene);
    let holdout = (!held.views.is_empty())
        .then(|| ellipso_fit::holdout::score(&held, &outcome.fits, full_scale).overall);
    let fit_s = outcome.times.fit_s();
    // The forward pass is short (tens of milliseconds): its fastest of at least 3 repetitions
    // and 0.25 s in all, so one scheduling hiccup does not move the ratio.
    let mut forward_s = f64::INFINITY;
    let mut spent_s = 0.0;
    let mut repetitions = 0;
    while repetitions < 3 || spent_s < 0.25 {
        let t = Instant::now();
        let checksum = forward_all(&capture.set, &outcome.fits);
        let s = t.elapsed().as_secs_f64().max(1e-9);
        ensure!(
            checksum.is_finite(),
            "forward evaluation produced a non-finite value"
        );
        forward_s = forward_s.min(s);
        spent_s += s;
        repetitions += 1;
    }
    let scores = evaluate(&capture, &outcome.fits);
    let peak_rss_bytes = ellipso_report::memory::peak_rss_bytes().filter(|_| rss_reset);
    let lobes = crate::accuracy::specular::score(&capture, outcome.augmentation.as_ref());
    let bracket = case
        .bracket
        .clone()
        .unwrap_or_else(|| scene.capture.bracket.clone());
    let r = RunResult {
        scene: name.to_string(),
        sweep: sweep.to_string(),
        solver: solver.to_string(),
        photos: case.photos,
        views: capture.set.views.len(),
        simulate_s,
        fit_s,
        times: outcome.times,
        forward_s,
        fit_over_forward: fit_s / forward_s,
        peak_rss_bytes,
        scores,
        holdout,
        clusters: outcome
            .augmentation
            .as_ref()
            .map(|a| a.clusters.clone())
            .unwrap_or_default(),
        pooling: outcome.pooling,
        guided: outcome
            .augmentation
            .as_ref()
            .map(|a| (a.vertices_with_virtual_samples, a.vertices_with_eta_prior)),
        bracket,
        lobes,
    };
    say!(
        say,
        "{:<15} {:<8} {:<36} {:>4} photos {:>6} vertices ({:.3} of the observed scored) {:>8} samples  fit {:>7.2} s ({:>6.0}× forward)  η {:>6.2} % (median {:>5.2} %, material {:>5.2} %)  normal {:>5.2}°/{:>5.2}°  ρd {:>5.2} % (median {:>4.2} %)  re-render {:.4}  held-out s0 {}",
        r.scene,
        r.sweep,
        r.solver,
        r.photos,
        r.scores.vertices,
        r.scores.coverage,
        r.scores.samples,
        r.fit_s,
        r.fit_over_forward,
        r.scores.eta_mean_pct,
        r.scores.eta_median_pct,
        r.scores.eta_material_pct,
        r.scores.normal_median_deg,
        r.scores.normal_p90_deg,
        r.scores.rho_d_mean_pct,
        r.scores.rho_d_median_pct,
        r.scores.rerender_rmse,
        r.holdout
            .as_ref()
            .map_or("n/a".into(), |h| format!("{:.4}", h.s0.relative_rmse))
    );
    if let (Some(p), Some((virt, prior))) = (&r.pooling, r.guided) {
        say!(
            say,
            "    {} clusters, {virt} vertices with virtual samples, {prior} with a pooled η prior; median η se {:.4} → {:.4}",
            r.clusters.len(),
            p.median_eta_se_before,
            p.median_eta_se_after
        );
    }
    for c in &r.clusters {
        say!(
            say,
            "    cluster ({} members): η {:.4} (pooled {:.4} ± {:.4}, median {:.4}, τ {:.4}, {} used, {} trimmed)  σs {:.3}  σss {:.3}  ρs {:.3}",
            c.members,
            c.eta,
            c.eta_pooled.mean,
            c.eta_pooled.se,
            c.eta_pooled.median,
            c.eta_pooled.tau,
            c.eta_pooled.vertices,
            c.eta_pooled.trimmed,
            c.sigma_s,
            c.sigma_ss,
            c.rho_s
        );
    }
    for c in &r.lobes.clusters {
        say!(
            say,
            "    {:<16} cluster σs {:.4} (true {:.3}, {:+.1} %, {:.0} % of its vertices in that cluster)",
            c.material,
            c.sigma_s_cluster,
            c.sigma_s_true,
            c.sigma_s_error_pct,
            100.0 * c.share
        );
    }
    for p in &r.lobes.peaks {
        say!(
            say,
            "    {:<16} lobe peak: {} of {} vertices with a near-mirror view kept a peak sample ({} of {} near-mirror samples kept)",
            p.material,
            p.vertices_with_peak_kept,
            p.vertices_with_near_mirror_view,
            p.peak_samples_kept,
            p.near_mirror_views
        );
        for (energy, views, kept) in &p.by_energy {
            say!(say, "        at energy {energy}: {kept} of {views} kept");
        }
    }
    for m in &r.scores.materials {
        say!(
            say,
            "    {:<16} η {:.4} (true {:.3}, {:+.3} %; vertex median {:.2} %)  σs {:.3}  σss {:.3}  normal {:.2}°",
            m.name,
            m.eta_median,
            m.eta_true,
            100.0 * (m.eta_median - m.eta_true) / m.eta_true,
            m.eta_vertex_median_pct,
            m.sigma_s_median,
            m.sigma_ss_median,
            m.normal_median_deg
        );
    }
    Ok(r)
}

/// The command that reproduces a report made with `args` (options at their defaults left out).
fn command_line(args: &AccuracyOptions) -> String {
    let mut c = String::from("bench accuracy");
    let list = |v: &[String]| v.join(",");
    if !args.scenes.is_empty() {
        let scenes: Vec<String> = args
            .scenes
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        c += &format!(" --scenes {}", list(&scenes));
    }
    if args.quick {
        c += " --quick";
    }
    if args.no_large {
        c += " --no-large";
    }
    if !args.sweeps.is_empty() {
        c += &format!(" --sweeps {}", list(&args.sweeps));
    }
    if args.seed != 7 {
        c += &format!(" --seed {}", args.seed);
    }
    if let Some(p) = args.photos {
        c += &format!(" --photos {p}");
    }
    if args.holdout != 0.1 {
        c += &format!(" --holdout {}", args.holdout);
    }
    if args.report != Path::new("docs/accuracy-vs-time.md") {
        c += &format!(" --report {}", args.report.display());
    }
    c
}

/// The report's files: the Markdown report, its JSON data and its two plots in `img/`.
struct ReportFiles {
    markdown: OutputFile,
    json: OutputFile,
    /// The end-to-end rows' JSON (`<stem>-end-to-end.json`), written when they ran.
    end_to_end_json: OutputFile,
    eta_png: OutputFile,
    normal_png: OutputFile,
}

impl ReportFiles {
    fn claim(path: &Path) -> Result<Self> {
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let stem = path.file_stem().map_or("accuracy-vs-time".into(), |s| {
            s.to_string_lossy().to_string()
        });
        let claim = |p: &Path, f| OutputFile::claim(p, "bench-accuracy", f, &[], None);
        Ok(Self {
            markdown: claim(path, FileFormat::MARKDOWN)?,
            json: claim(&dir.join(format!("{stem}.json")), FileFormat::JSON)?,
            end_to_end_json: claim(
                &dir.join(format!("{stem}-end-to-end.json")),
                FileFormat::JSON,
            )?,
            eta_png: claim(
                &dir.join("img").join(format!("{stem}-eta.png")),
                FileFormat::PNG,
            )?,
            normal_png: claim(
                &dir.join("img").join(format!("{stem}-normal.png")),
                FileFormat::PNG,
            )?,
        })
    }
}

fn write_report(
    files: &ReportFiles,
    results: &[RunResult],
    end_to_end: &[crate::chain::RunResult],
    total_s: f64,
    command: &str,
    say: &dyn Say,
) -> Result<()> {
    let path = files.markdown.shown();
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let eta_png = files.eta_png.shown().to_path_buf();
    let normal_png = files.normal_png.shown().to_path_buf();
    // The plots draw the sweeps; a report of the large run alone has none to draw.
    let plotted = results.iter().any(|r| r.sweep != "large");
    if plotted {
        plot(
            results,
            &eta_png,
            "η error vs fit time",
            "mean per-vertex η error (%)",
            |s| s.eta_mean_pct,
            end_to_end
                .iter()
                .map(|r| (r.times.fit_s, r.scores.eta_vertex_mean_pct)),
        )?;
        plot(
            results,
            &normal_png,
            "normal error vs fit time",
            "median normal error (°)",
            |s| s.normal_median_deg,
            end_to_end
                .iter()
                .map(|r| (r.times.fit_s, r.scores.normal_median_deg)),
        )?;
    }
    let json = files.json.shown();
    files.json.write(serde_json::to_vec_pretty(results)?)?;
    if !end_to_end.is_empty() {
        files
            .end_to_end_json
            .write(serde_json::to_vec_pretty(end_to_end)?)?;
    }
    let plots = plotted.then_some((eta_png.as_path(), normal_png.as_path()));
    let md = report::markdown(results, end_to_end, total_s, command, plots, dir);
    files.markdown.write(md)?;
    say!(say, "\nreport  {}", path.display());
    if plotted {
        say!(
            say,
            "plots   {}\n        {}",
            eta_png.display(),
            normal_png.display()
        );
    }
    say!(say, "data    {}", json.display());
    Ok(())
}

fn plot(
    results: &[RunResult],
    out: &Path,
    title: &str,
    y_label: &str,
    metric: impl Fn(&Scores) -> f64,
    end_to_end: impl Iterator<Item = (f64, f64)>,
) -> Result<()> {
    let points = results.iter().filter(|r| r.sweep != "large").map(|r| {
        (
            r.scene.as_str(),
            r.sweep.as_str(),
            r.fit_s,
            metric(&r.scores),
        )
    });
    let end_to_end = end_to_end.map(|(s, v)| ("demo", "end to end (rendered frames)", s, v));
    plot_points(points.chain(end_to_end), out, title, y_label)
}

/// The accuracy-vs-time plot of `(scene, sweep, fit seconds, metric)` points: one line per
/// scene and sweep, in order of fit time, on a log time axis.
fn plot_points<'a>(
    points: impl Iterator<Item = (&'a str, &'a str, f64, f64)>,
    out: &Path,
    title: &str,
    y_label: &str,
) -> Result<()> {
    let mut p = LinePlot::new(title)
        .x_label("fit wall time (s, log scale)")
        .y_label(y_label)
        .log_x(true)
        .legend(LegendPosition::TopRight);
    let mut groups: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for (scene, sweep, fit_s, value) in points {
        let key = format!("{scene} – {sweep}");
        let point = (fit_s.max(1e-3), value);
        match groups.iter_mut().find(|(k, _)| *k == key) {
            Some((_, pts)) => pts.push(point),
            None => groups.push((key, vec![point])),
        }
    }
    for (k, mut pts) in groups {
        pts.retain(|p| p.1.is_finite());
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        p = p.series(k, pts);
    }
    p.save_png(out)?;
    Ok(())
}

/// The committed report's plots redrawn from its JSON (`ELLIPSO_DOCS_IMG=docs/img cargo test
/// -p ellipso-bench redraw_committed`), so a change of drawing needs no re-run of the benchmark.
#[cfg(test)]
mod redraw {
    #[test]
    fn redraw_committed_accuracy_plots() {
        let Some(img) = std::env::var_os("ELLIPSO_DOCS_IMG") else {
            return;
        };
        let docs = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs");
        for stem in ["accuracy-vs-time", "accuracy-bracket"] {
            let text = std::fs::read_to_string(docs.join(format!("{stem}.json"))).unwrap();
            let runs: Vec<serde_json::Value> = serde_json::from_str(&text).unwrap();
            let points = |metric: &'static str| {
                runs.iter().filter(|r| r["sweep"] != "large").map(move |r| {
                    (
                        r["scene"].as_str().unwrap_or("?"),
                        r["sweep"].as_str().unwrap_or("?"),
                        r["fit_s"].as_f64().unwrap_or(f64::NAN),
                        r["scores"][metric].as_f64().unwrap_or(f64::NAN),
                    )
                })
            };
            let img = std::path::Path::new(&img);
            super::plot_points(
                points("eta_mean_pct"),
                &img.join(format!("{stem}-eta.png")),
                "η error vs fit time",
                "mean per-vertex η error (%)",
            )
            .unwrap();
            super::plot_points(
                points("normal_median_deg"),
                &img.join(format!("{stem}-normal.png")),
                "normal error vs fit time",
                "median normal error (°)",
            )
            .unwrap();
        }
    }
}
