//! `ellipso bench pose SCENE`: pose-tracking accuracy and speed on rendered frames with known
//! truth — per detection image (I90 cross-polarised, I0 co-polarised, s0), the median and 90th
//! percentile rotation/translation errors against the simulator's camera poses, flipped poses,
//! rejections by reason, and milliseconds per frame for detection + pose (one thread).
//!
//! Frames are rendered once and tracked with each detection image, so the comparison is on the
//! same pixels. Writes `pose-bench.json` and prints a table.
//!
//! `ellipso bench calibration` ([`crate::calibration`]) checks the camera calibration the same
//! way on frames rendered by [`render_raw`]; `ellipso bench view` ([`crate::view_cost`])
//! measures what the live view costs a capture.
//! `--seed S` replaces the scene's seed: the poses of seeded capture paths (orbit phase, hand-held
//! walk) and the sensor noise both change.

use std::path::{Path, PathBuf};
use std::time::Instant;

use ellipso_sim::render::{RenderOptions, Renderer};
use ellipso_sim::scene::Scene;
use ellipso_sim::scene::error::Located;

use ellipso_polar::frame::RawFrame;

use crate::table::{self, Align::Left as L};
use ellipso_run_error::{RunError, Say};
use ellipso_run_error::{ensure, say};
use ellipso_vision::track::{DetectImage, TrackConfig, TrackedBoard, Tracker};

/// What `ellipso bench pose` runs (its flags, parsed by the binary).
#[derive(Debug, Clone)]
pub struct PoseOptions {
    /// Scene file.
    pub scene: PathBuf,
    /// Frames to render (spread over the capture path), ≥ 1.
    pub frames: usize,
    /// Render at WIDTHxHEIGHT instead of the scene's resolution (even sides, 2..=16384).
    pub resolution: Option<[u32; 2]>,
    /// Scene seed (capture poses of seeded paths and sensor noise); default the scene's.
    pub seed: Option<u64>,
    /// Where to write pose-bench.json.
    pub out: PathBuf,
}

/// One detection image's results.
#[derive(Debug, serde::Serialize)]
pub struct ImageResult {
    /// Detection image.
    pub image: DetectImage,
    /// Frames tracked.
    pub frames: usize,
    /// Frames posed.
    pub posed: usize,
    /// Median rotation error, degrees.
    pub median_rotation_deg: f64,
    /// 90th percentile rotation error, degrees.
    pub p90_rotation_deg: f64,
    /// Median translation error, mm.
    pub median_translation_mm: f64,
    /// 90th percentile translation error, mm.
    pub p90_translation_mm: f64,
    /// Poses more than 10° from the truth (a flipped planar solution).
    pub flipped: usize,
    /// Mean detection + pose time per frame, ms (one thread).
    pub ms_per_frame: f64,
    /// Rejections by reason.
    pub rejected: std::collections::BTreeMap<String, usize>,
}

/// Loads a scene; with `seed`, recomputes its capture poses and noise seed from that seed.
pub fn load_scene(path: &Path, seed: Option<u64>) -> Result<Scene, RunError> {
    let mut scene = Scene::load(path)?;
    if let Some(seed) = seed {
        let text =
            ellipso_model::file_io::read_bounded_text(path, ellipso_model::file_io::caps::SCENE)?;
        let loc = Located::new(&text, path);
        scene.camera_poses = scene.capture.camera_poses(seed, &loc)?;
        scene.seed = seed;
    }
    Ok(scene)
}

/// `frames` indices spread evenly over `n` poses (all of them for `None`).
pub fn spread(n: usize, frames: Option<usize>) -> Vec<usize> {
    let frames = frames.unwrap_or(n).clamp(1, n.max(1));
    // floor(i·n/frames): distinct, increasing, first 0, covering the whole path
    (0..frames.min(n)).map(|i| i * n / frames).collect()
}

/// The renderer of `scene` (at `resolution` when given) and the scene's AprilTag boards as
/// tracking sees them; an error names `path` when the scene has no board.
pub fn renderer_and_boards<'s>(
    scene: &'s Scene,
    resolution: Option<[u32; 2]>,
    path: &std::path::Path,
) -> Result<(Renderer<'s>, Vec<TrackedBoard>), RunError> {
    let options = RenderOptions {
        resolution_px: resolution,
        ..RenderOptions::default()
    };
    let renderer = Renderer::new(scene, options)?;
    let boards: Vec<TrackedBoard> = scene.boards.iter().map(TrackedBoard::from_placed).collect();
    ensure!(
        !boards.is_empty(),
        "{}: the scene has no AprilTag boards",
        path.display()
    );
    Ok((renderer, boards))
}

/// Pose `k` of the scene rendered as the camera delivers it.
pub fn render_raw(renderer: &Renderer<'_>, scene: &Scene, k: usize) -> Result<RawFrame, RunError> {
    let f = renderer.render_frame(k)?;
    Ok(RawFrame::new(
        f.width,
        f.height,
        scene.rig.camera.bit_depth,
        renderer.layout(),
        f.raw(),
    )?)
}

/// Runs `ellipso bench pose`: renders, tracks with each detection image, writes
/// `pose-bench.json` and says the table.
pub fn run(args: &PoseOptions, say: &dyn Say) -> Result<(), RunError> {
    let out = ellipso_report::output::OutputFile::claim(
        &args.out.join("pose-bench.json"),
        "bench-pose",
        ellipso_report::output::FileFormat::JSON,
        &[&args.scene],
        None,
    )?;
    let scene = load_scene(&args.scene, args.seed)?;
    let (renderer, boards) = renderer_and_boards(&scene, args.resolution, &args.scene)?;
    let camera = *renderer.camera();
    let indices = spread(scene.camera_poses.len(), Some(args.frames));
    say!(
        say,
        "rendering {} frames of {} at {}×{}, seed {}…",
        indices.len(),
        args.scene.display(),
        camera.width,
        camera.height,
        scene.seed
    );
    let mut frames = Vec::new();
    for &k in &indices {
        frames.push((k, render_raw(&renderer, &scene, k)?));
    }
    let mut results = Vec::new();
    for image in [DetectImage::I90, DetectImage::I0, DetectImage::S0] {
        let mut config = TrackConfig {
            image,
            ..TrackConfig::default()
        };
        config.detector.threads = 1;
        let mut tracker = Tracker::new(camera, boards.clone(), config)?;
        let (mut rot, mut trans) = (Vec::new(), Vec::new());
        let mut rejected = std::collections::BTreeMap::new();
        let mut flipped = 0;
        let started = Instant::now();
        for (k, raw) in &frames {
            match tracker.track(raw) {
                Ok(p) => {
                    let truth = scene.camera_poses[*k].world_from_camera;
                    let e = ellipso_model::geometry::pose_error(&p.world_from_camera, &truth);
                    if e.rotation_deg > 10.0 {
                        flipped += 1;
                    }
                    rot.push(e.rotation_deg);
                    trans.push(e.translation_mm);
                }
                Err(e) => *rejected.entry(e.to_string()).or_insert(0) += 1,
            }
        }
        let ms = started.elapsed().as_secs_f64() * 1e3 / frames.len().max(1) as f64;
        results.push(ImageResult {
            image,
            frames: frames.len(),
            posed: rot.len(),
            median_rotation_deg: ellipso_report::percentile(&mut rot, 0.5),
            p90_rotation_deg: ellipso_report::percentile(&mut rot, 0.9),
            median_translation_mm: ellipso_report::percentile(&mut trans, 0.5),
            p90_translation_mm: ellipso_report::percentile(&mut trans, 0.9),
            flipped,
            ms_per_frame: ms,
            rejected,
        });
    }
    for line in table::head(&[
        ("image", L),
        ("posed", L),
        ("median rot (°)", L),
        ("p90 rot (°)", L),
        ("median trans (mm)", L),
        ("p90 trans (mm)", L),
        ("flipped", L),
        ("ms/frame", L),
    ])
    .lines()
    {
        say!(say, "{line}");
    }
    for r in &results {
        say!(
            say,
            "| {:?} | {}/{} | {:.4} | {:.4} | {:.3} | {:.3} | {} | {:.1} |",
            r.image,
            r.posed,
            r.frames,
            r.median_rotation_deg,
            r.p90_rotation_deg,
            r.median_translation_mm,
            r.p90_translation_mm,
            r.flipped,
            r.ms_per_frame
        );
        for (why, count) in &r.rejected {
            say!(say, "|   rejected: {why} ({count}) |||||||");
        }
    }
    out.write(serde_json::to_vec_pretty(&results)?)?;
    let path = out.shown();
    say!(say, "written {}", path.display());
    Ok(())
}
