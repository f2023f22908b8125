//! `ellipso demo`: the main job on the simulated rig, end to end, in a few minutes on 2 cores.
//!
//! 1. Capture a shipped scene (a four-material object on an AprilTag board) on the simulated rig
//!    ([`crate::rig_capture`]): the real firmware core behind a real pty, the host's real link,
//!    pairing and session code.
//! 2. Track the camera pose of every frame from the AprilTags and score it against the
//!    simulator's ground truth ([`pose_accuracy`]).
//! 3. Build the object's mesh from the posed frames alone (`ellipso mesh`: a visual hull carved
//!    with the learned board), fit the polarimetric SVBRDF and shape per vertex of it from the
//!    recorded frames and the tracked poses (`ellipso fit`), write its pictures — and only then
//!    read the simulator's truth to score the mesh (before and after the fit's shape refinement)
//!    and the fitted parameters and normals ([`fit_score`]).
//! 4. Pictures: the polarisation images of one frame (s0, DoLP, AoLP, I^d, I^s, I^α) and a plot of
//!    the tracked camera path against the truth.
//! 5. A summary (`summary.json`) and the list of where everything is ([`DemoReport`]).
//!
//! Contract: the demo owns its output folder (a new or empty one, or an earlier demo's), writes
//! everything beside it and swaps it in whole at the end; a capture stopped by a signal keeps
//! nothing ([`DemoRun::Stopped`]). Nothing here prints: the capture is recorded by the caller's
//! [`Recorder`], long steps go to its [`Steps`], every line to its [`Say`].

pub mod fit_score;

use std::path::{Path, PathBuf};

use ellipso_model::geometry::pose_error;
use ellipso_pipeline::steps::Steps;
use ellipso_report::plot::{LegendPosition, LinePlot};
use ellipso_rig::acquire::capture::CaptureReport;
use ellipso_rig::acquire::ready::{Recorded, Recorder, report_lines};
use ellipso_run_error::{Context, RunError, Say};
use ellipso_run_error::{ensure, say};
use ellipso_sim::scene::{Scene, shipped_scene};
use ellipso_vision::process::TrackedFrame;

/// What `ellipso demo` is asked (its flags).
#[derive(Debug, Clone)]
pub struct DemoRequest {
    /// Where to put the session and the results.
    pub out: PathBuf,
    /// Scene to capture (default: the shipped four-material demo scene; `sphere.toml` quick).
    pub scene: Option<PathBuf>,
    /// Smaller and shorter, for a smoke test: quarter resolution, 24 photos, one outer
    /// iteration of the fit.
    pub quick: bool,
    /// Pace the photos at the scene's interval (a hand-held walk round the object) instead of
    /// the fastest the rig allows ([`ellipso_rig::acquire::sim_rig::fastest_interval_ms`]).
    pub real_time: bool,
}

/// How the demo ended.
#[derive(Debug)]
pub enum DemoRun {
    /// Everything written and published.
    Done(Box<DemoReport>),
    /// The capture was stopped by this signal: nothing was kept (an earlier demo stays).
    Stopped {
        /// The signal number.
        signal: i32,
    },
}

/// Where the demo's results are (as published) and its headline figures.
#[derive(Debug)]
pub struct DemoReport {
    /// The output folder.
    pub published: PathBuf,
    /// The session (raw frames and event log).
    pub session: PathBuf,
    /// The polarisation images of the first frame.
    pub polarisation: PathBuf,
    /// The camera path plot.
    pub camera_path: PathBuf,
    /// The fitted model (PLY, per vertex).
    pub fit_ply: PathBuf,
    /// The fit's folder (maps, Mueller grid, relit, novel view).
    pub fit_dir: PathBuf,
    /// `summary.json`.
    pub summary: PathBuf,
    /// The capture.
    pub capture: CaptureReport,
    /// The tracked poses against the truth.
    pub pose_accuracy: PoseAccuracy,
}

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
/// frames are matched through their pairing to pulses, pulse seq k ↔ pose k), each with
/// [`pose_error()`].
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
        let e = pose_error(&p.world_from_camera, &truth.world_from_camera);
        rot.push(e.rotation_deg);
        trans.push(e.translation_mm);
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

/// Runs the demo (module doc).
pub fn run(
    request: &DemoRequest,
    recorder: &mut dyn Recorder,
    steps: &mut dyn Steps,
    say: &dyn Say,
) -> Result<DemoRun, RunError> {
    let setup = setup(request)?;
    let (scene_path, scene, resolution) = (&setup.scene_path, &setup.scene, setup.resolution);
    // the demo owns its output: a new or empty directory, or an earlier demo's (marker and
    // all); everything is written beside it and swapped in whole at the end
    let out = ellipso_report::output::OutputDir::claim(&request.out, "demo", &[scene_path])?;
    let root = out.path().to_path_buf();
    let session_dir = root.join("session");
    say!(
        say,
        "ellipso demo: scene {} at {}×{}",
        scene_path.display(),
        resolution[0],
        resolution[1]
    );
    say!(
        say,
        "[1/4] capturing on the simulated rig (firmware core behind a pty, real link and pairing)…"
    );
    let captured = capture(request, &setup, &session_dir, recorder, say)?;
    let (report, dir) = (captured.report, captured.dir);
    if let Some(signal) = captured.signal {
        // the partial demo goes with its staging directory; an earlier demo stays
        return Ok(DemoRun::Stopped { signal });
    }

    say!(say, "[2/4] tracking camera poses from the AprilTags…");
    let (tracked, session, accuracy) = track(scene, &dir, say)?;

    say!(
        say,
        "[3/4] carving the mesh from the frames, fitting the polarimetric SVBRDF and shape per vertex…"
    );
    let fit = fit_score::fit_and_score(scene, &session, &out, request.quick, steps, say)?;

    say!(say, "[4/4] pictures…");
    let (polarisation, path_plot) =
        pictures(scene, &session, &out, report.pulses as usize, &tracked, say)?;

    let mut summary = serde_json::json!({
        "scene": scene_path.display().to_string(),
        "resolution": resolution,
        "capture": report,
        "pose_accuracy": accuracy,
        "fit": fit.summary,
    });
    let summary_path = root.join("summary.json");
    // every path in the summary is relative to its own folder (the staging folder moves whole)
    ellipso_report::paths::paths_relative_to(&mut summary, &root);
    ellipso_report::atomic_file::write(&summary_path, serde_json::to_vec_pretty(&summary)?)?;
    let shown = |p: &Path| out.published(p);
    let report = DemoReport {
        published: PathBuf::new(),
        session: shown(&dir),
        polarisation: shown(&polarisation),
        camera_path: shown(&path_plot),
        fit_ply: shown(&fit.ply),
        fit_dir: shown(&fit.dir),
        summary: shown(&summary_path),
        capture: report,
        pose_accuracy: accuracy,
    };
    let published = out.commit()?;
    Ok(DemoRun::Done(Box::new(DemoReport {
        published,
        ..report
    })))
}

/// The scene the demo captures and at what size.
struct Setup {
    /// The scene file.
    scene_path: PathBuf,
    /// The scene.
    scene: Scene,
    /// The capture's resolution, pixels (half the scene camera's sides; a quarter when quick).
    resolution: [u32; 2],
    /// Photos taken (`None`: the scene's whole path).
    photos: Option<u32>,
}

/// Loads the requested scene (or the shipped one) and sizes the capture.
fn setup(request: &DemoRequest) -> Result<Setup, RunError> {
    let scene_path = request
        .scene
        .clone()
        // The quick run takes the monochrome sphere scene: the colour sensor's 4×4 tiles leave
        // too few pixels per tag at quarter resolution to track the poses.
        .unwrap_or_else(|| {
            shipped_scene(if request.quick {
                "sphere.toml"
            } else {
                "demo.toml"
            })
        });
    ensure!(
        scene_path.is_file(),
        "scene {} not found: run the demo from the source tree, or pass --scene",
        scene_path.display()
    );
    let scene = Scene::load(&scene_path)?;
    let [w, h] = scene.rig.camera.resolution_px;
    let (resolution, photos) = if request.quick {
        ([w / 4 / 2 * 2, h / 4 / 2 * 2], Some(24))
    } else {
        ([w / 2, h / 2], None)
    };
    Ok(Setup {
        scene_path,
        scene,
        resolution,
        photos,
    })
}

/// Captures the scene on the simulated rig into `session_dir`, paced as asked, and says the
/// capture's summary.
fn capture(
    request: &DemoRequest,
    setup: &Setup,
    session_dir: &Path,
    recorder: &mut dyn Recorder,
    say: &dyn Say,
) -> Result<Recorded, RunError> {
    let (scene, resolution) = (&setup.scene, setup.resolution);
    // the photos as fast as the rig honestly takes them (the flash's duty limit, the sensor's
    // readout, the camera link), unless asked for the scene's hand-held pace
    let interval_ms = if request.real_time {
        scene.capture.interval_ms
    } else {
        ellipso_rig::acquire::sim_rig::fastest_interval_ms(scene, resolution)
    };
    say!(
        say,
        "pacing       {interval_ms:.0} ms between photos ({})",
        if request.real_time {
            "the scene's hand-held pace, --real-time".to_string()
        } else {
            format!(
                "the fastest the rig allows: flash duty, sensor readout, camera link; \
                 --real-time for the scene's {:.0} ms",
                scene.capture.interval_ms
            )
        }
    );
    let captured = crate::rig_capture::capture_on_sim_rig(
        &setup.scene_path,
        session_dir,
        setup.photos,
        resolution,
        Some(interval_ms),
        recorder,
    )?;
    for line in report_lines(&captured.report) {
        say!(say, "{line}");
    }
    Ok(captured)
}

/// Tracks the camera poses of the session in `dir` from the AprilTags, opens it, and scores the
/// poses against the scene's truth ([`pose_accuracy`]), said in one line.
fn track(
    scene: &Scene,
    dir: &Path,
    say: &dyn Say,
) -> Result<
    (
        Vec<TrackedFrame>,
        ellipso_session::reader::Session,
        PoseAccuracy,
    ),
    RunError,
> {
    let tracked = ellipso_vision::process::track_and_append(dir, say)?;
    let session = ellipso_session::reader::open(dir)?;
    let pairs: std::collections::BTreeMap<u64, u64> = session
        .frames
        .iter()
        .filter_map(|f| f.pulse_seq.map(|s| (f.frame_id, s)))
        .collect();
    let first_seq = pairs.values().min().copied().unwrap_or(0);
    let accuracy = pose_accuracy(scene, &tracked, &|id| {
        pairs.get(&id).map(|s| (s - first_seq) as usize)
    });
    say!(
        say,
        "poses        {}/{} frames · median error {:.3}° / {:.3} mm (90th percentile {:.3}° / {:.3} mm)",
        accuracy.posed,
        accuracy.frames,
        accuracy.median_rotation_deg,
        accuracy.median_translation_mm,
        accuracy.p90_rotation_deg,
        accuracy.p90_translation_mm
    );
    Ok((tracked, session, accuracy))
}

/// Writes the pictures: the polarisation images of the first complete frame and the camera path
/// of the first `photos` poses; returns their paths (the polarisation folder, the plot).
fn pictures(
    scene: &Scene,
    session: &ellipso_session::reader::Session,
    out: &ellipso_report::output::OutputDir,
    photos: usize,
    tracked: &[TrackedFrame],
    say: &dyn Say,
) -> Result<(PathBuf, PathBuf), RunError> {
    let pictures = out.path().join("pictures");
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
        say,
    )?;
    say!(
        say,
        "  {} ({} files: s0, DoLP, AoLP, I^d/I^s/I^α, mask per band, stokes.exr)",
        out.published(&pictures.join("frame0-polarisation"))
            .display(),
        polar.files.len()
    );
    let path_plot = pictures.join("camera-path.png");
    plot_path(scene, photos, tracked, &path_plot)?;
    say!(say, "  {}", out.published(&path_plot).display());
    Ok((pictures.join("frame0-polarisation"), path_plot))
}

/// Top view of the camera path: truth (line) and tracked positions (points).
fn plot_path(
    scene: &Scene,
    photos: usize,
    tracked: &[TrackedFrame],
    out: &Path,
) -> Result<(), RunError> {
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
