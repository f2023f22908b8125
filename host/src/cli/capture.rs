//! `ellipso capture --sim SCENE --out DIR`: a capture on the simulated rig, recorded as a session.
//!
//! The simulated rig is assembled from the same parts as a hardware capture: the trigger board is
//! the real firmware core running in a virtual board behind a **real pseudo-terminal**, driven by
//! the host's real serial code; the camera is the simulator's camera behind the [`Camera`] trait,
//! exposing on the board's trigger edges and rendering with the polarimetric renderer. With
//! `--trigger PTY --wire SOCKET` the board is an external `ellipso sim serve` process instead.
//! After recording, poses are tracked and appended to the session (unless `--no-track`).
//!
//! [`Camera`]: crate::camera::Camera

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use anyhow::Context;
use ellipso_protocol::{CaptureConfig, PulseCount, TriggerSource};
use ellipso_sim::render::{RenderOptions, Renderer};
use ellipso_sim::rig::{
    self, FrameSource, SimCamera, SimCameraConfig, VirtualBoard, VirtualBoardConfig,
};
use ellipso_sim::scene::Scene;
use indicatif::{ProgressBar, ProgressStyle};
use serialport::{SerialPort, TTYPort};

use crate::acquire::capture::{CapturePlan, CaptureReport, capture};
use crate::acquire::pairing::PairingConfig;
use crate::camera::sim::SimCameraBackend;
use crate::camera::{CameraInfo, CameraSettings};
use crate::link::time::HostClock;
use crate::link::{LinkConfig, TriggerLink};
use crate::process::{self, RigRecord};
use crate::session::manifest::{Manifest, SensorInfo, SessionSource};
use crate::session::writer::SessionWriter;
use crate::track::{TrackConfig, TrackedBoard};

/// Arguments of `ellipso capture`.
#[derive(Debug, Clone, clap::Args)]
#[command(group(clap::ArgGroup::new("source").required(true).args(["sim", "rig"])))]
pub struct Args {
    /// Scene file of the simulated rig (`sim/scenes/*.toml`).
    #[arg(long, value_name = "SCENE")]
    pub sim: Option<PathBuf>,
    /// Rig file of the physical rig (trigger port, camera backend and address, camera model,
    /// capture, boards; see `host/src/rig_file.rs`).
    #[arg(long, value_name = "RIG")]
    pub rig: Option<PathBuf>,
    /// Session directory to create.
    #[arg(long)]
    pub out: PathBuf,
    /// External trigger board (pty of `ellipso sim serve`, a serial device, or `unix:PATH`)
    /// instead of the in-process virtual board.
    #[arg(long, requires = "wire")]
    pub trigger: Option<String>,
    /// Trigger-wire socket of `ellipso sim serve --wire` (with `--trigger`).
    #[arg(long, requires = "trigger")]
    pub wire: Option<PathBuf>,
    /// Take only this many photos (default: the scene's capture path).
    #[arg(long)]
    pub photos: Option<u32>,
    /// Render at WIDTHxHEIGHT instead of the scene's resolution (intrinsics scaled).
    #[arg(long, value_parser = parse_resolution)]
    pub resolution: Option<[u32; 2]>,
    /// Rays per raw pixel per axis (N×N).
    #[arg(long, default_value_t = 2)]
    pub supersampling: u32,
    /// Time between photos, ms (default: the scene's `capture.interval_ms`).
    #[arg(long)]
    pub interval_ms: Option<f64>,
    /// Skip pose tracking after recording.
    #[arg(long)]
    pub no_track: bool,
    /// Show the live view in the browser while capturing (prints its URL; `docs/view.md`).
    #[arg(long)]
    pub view: bool,
    /// Object mesh for the live view's coverage (with `--view`; default: a dome proxy).
    #[arg(long, value_name = "MESH", requires = "view")]
    pub view_mesh: Option<PathBuf>,
}

pub fn parse_resolution(s: &str) -> Result<[u32; 2], String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or("expected WIDTHxHEIGHT, e.g. 1224x1024")?;
    let p = |v: &str| v.trim().parse::<u32>().map_err(|e| format!("'{v}': {e}"));
    Ok([p(w)?, p(h)?])
}

/// Renders capture poses for the simulated camera.
struct RenderSource {
    renderer: Renderer<'static>,
    size: (u32, u32),
}

impl FrameSource for RenderSource {
    fn frame_size(&self) -> (u32, u32) {
        self.size
    }

    fn render(&self, pose_index: usize, _frame_seed: u64) -> Vec<u16> {
        // The renderer derives each frame's noise from the scene seed and the pose index, so a
        // pose renders identically whenever it is exposed: captures are reproducible.
        match self.renderer.render_frame(pose_index) {
            Ok(f) => f.raw(),
            Err(e) => {
                tracing::error!("render of pose {pose_index} failed: {e}");
                vec![0; self.size.0 as usize * self.size.1 as usize]
            }
        }
    }
}

/// The board timing for a scene: its exposure, a flash inside it, its photo interval.
pub fn board_config(scene: &Scene, photos: u32, interval_ms: Option<f64>) -> CaptureConfig {
    let exposure_us = scene.rig.camera.exposure_us.round().max(1.0) as u32;
    let flash_delay_us = if exposure_us > 400 { 100 } else { 0 };
    let flash_duration_us = (exposure_us - 2 * flash_delay_us).min(5_000);
    CaptureConfig {
        exposure_us,
        flash_delay_us,
        flash_duration_us,
        frame_period_us: (interval_ms.unwrap_or(scene.capture.interval_ms) * 1e3).round() as u32,
        pulses: PulseCount::Count(photos),
        trigger: TriggerSource::FreeRun,
        report_edges: false,
    }
}

/// Records a simulated capture into `args.out`; returns the report and the session directory.
pub fn capture_sim(
    args: &Args,
    quiet: bool,
) -> anyhow::Result<(CaptureReport, PathBuf, Option<Vec<process::TrackedFrame>>)> {
    let scene_path = args
        .sim
        .as_ref()
        .context("--sim SCENE is required for a simulated capture")?;
    let scene = Scene::load(scene_path)?;
    // The renderer borrows the scene for the whole process (the capture threads outlive scopes).
    let scene: &'static Scene = Box::leak(Box::new(scene));
    let options = RenderOptions {
        supersampling: args.supersampling,
        resolution_px: args.resolution,
        ..RenderOptions::default()
    };
    let renderer = Renderer::new(scene, options)?;
    let camera_model = *renderer.camera();
    let layout = renderer.layout();
    let size = (camera_model.width, camera_model.height);
    let photos = args
        .photos
        .unwrap_or(scene.camera_poses.len() as u32)
        .min(scene.camera_poses.len() as u32);
    anyhow::ensure!(
        photos > 0,
        "{}: the capture path has no poses",
        scene_path.display()
    );
    let source: Arc<dyn FrameSource> = Arc::new(RenderSource { renderer, size });

    let clock = HostClock::new();
    // trigger board: in-process virtual board on a real pty, or an external one
    let (link, board, edges, board_clock) = match (&args.trigger, &args.wire) {
        (Some(port), Some(wire)) => {
            let link = TriggerLink::open(port, clock, LinkConfig::default())?;
            let edges = rig::connect_wire(wire)?;
            // The simulated camera places exposures in host time from the edges' device times;
            // across processes it learns the board's clock the way the host does, by ping/pong.
            // Only the offset is taken: a few milliseconds of pings cannot resolve a crystal's
            // ppm drift (a loaded machine made the slope absurd), and ignoring 25 ppm costs
            // 250 µs over 10 s, far inside the camera's latency jitter.
            let fit = link
                .sync_clock(20)?
                .context("the trigger board's clock did not settle")?;
            let now = clock.now().0 as f64;
            let device_now = (now - fit.offset_us) / fit.gain;
            let device_at_epoch = (device_now - now).max(0.0).round() as u64;
            let board_clock = rig::LinearClock::new(clock.epoch(), device_at_epoch, 0.0)?;
            (link, None, edges, Some(board_clock))
        }
        _ => {
            let (host_end, board_end) =
                TTYPort::pair().context("opening a pseudo-terminal pair")?;
            let board_reader = board_end.try_clone_native().context("cloning the pty")?;
            let (edges_tx, edges_rx) = rig::wire::wire();
            let config = VirtualBoardConfig::from_scene(scene);
            let board = VirtualBoard::spawn(
                config,
                Box::new(board_reader),
                Box::new(board_end),
                Some(edges_tx),
            )?;
            let mut host_end = host_end;
            host_end
                .set_timeout(Duration::from_millis(20))
                .context("pty timeout")?;
            let reader = host_end.try_clone_native().context("cloning the pty")?;
            let link = TriggerLink::connect(
                Box::new(reader),
                Box::new(host_end),
                clock,
                LinkConfig::default(),
            )?;
            let board_clock = board.device_clock();
            (link, Some(board), edges_rx, Some(board_clock))
        }
    };
    let board_clock = board_clock.context("no board clock")?;
    let mut cam_config = SimCameraConfig::from_scene(scene, board_clock);
    cam_config.pose_count = photos as usize;
    let sim_camera = SimCamera::spawn(cam_config, source, edges)?;
    let info = CameraInfo {
        backend: "sim",
        model: scene
            .name
            .clone()
            .unwrap_or_else(|| "simulated IMX250MZR".into()),
        width: size.0,
        height: size.1,
        layout: serde_json::to_value(layout)?
            .as_str()
            .unwrap_or_default()
            .to_string(),
        bit_depth: scene.rig.camera.bit_depth,
    };
    let camera = Box::new(SimCameraBackend::new(sim_camera, clock, info.clone()));

    let mut manifest = Manifest::new(
        SessionSource::Simulator {
            scene: scene_path.display().to_string(),
            seed: scene.seed,
        },
        SensorInfo {
            layout: info.layout.clone(),
            width: size.0,
            height: size.1,
            bit_depth: info.bit_depth,
        },
        clock.wall_at_epoch_unix_us(),
    );
    manifest.rig = serde_json::to_value(RigRecord {
        camera: camera_model,
        flash: serde_json::to_value(&scene.rig.flash).unwrap_or_default(),
    })?;
    manifest.boards = scene
        .boards
        .iter()
        .map(|b| serde_json::to_value(TrackedBoard::from_placed(b)))
        .collect::<Result<_, _>>()?;
    let session = SessionWriter::create(&args.out, manifest)?;

    let board_cfg = board_config(scene, photos, args.interval_ms);
    let settings = CameraSettings {
        exposure_us: board_cfg.exposure_us,
        gain_db: scene.rig.camera.gain_db as f32,
        bit_depth: info.bit_depth,
        external_trigger: true,
    };
    let plan = capture_plan(board_cfg, settings, photos);
    let result = run_with_progress(&link, camera, session, &plan, photos, quiet);
    drop(link);
    if let Some(board) = board {
        board.shutdown();
    }
    let (report, dir) = result?;
    let tracked = if args.no_track {
        None
    } else {
        Some(track_and_append(&dir)?)
    };
    Ok((report, dir, tracked))
}

/// The capture plan for a board timing: 20 clock pings, a 150 ms transfer budget for pairing,
/// 16 frames of queue, 2 PNG writers, and a time limit of the capture's length plus 10 minutes.
fn capture_plan(board: CaptureConfig, camera: CameraSettings, photos: u32) -> CapturePlan {
    CapturePlan {
        board,
        camera,
        clock_sync_pings: 20,
        pairing: PairingConfig::for_capture(board.exposure_us, board.frame_period_us, 150_000),
        frame_queue: 16,
        writer_threads: 2,
        max_duration: Duration::from_secs(
            u64::from(photos) * u64::from(board.frame_period_us) / 1_000_000 + 600,
        ),
    }
}

/// Runs the capture with a progress bar (hidden when quiet or not on a terminal).
fn run_with_progress(
    link: &TriggerLink,
    camera: Box<dyn crate::camera::Camera>,
    session: SessionWriter,
    plan: &CapturePlan,
    photos: u32,
    quiet: bool,
) -> Result<(CaptureReport, PathBuf), crate::acquire::capture::CaptureError> {
    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(u64::from(photos))
    };
    bar.set_style(
        ProgressStyle::with_template("{spinner} capture [{bar:30}] {pos}/{len} frames · {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let stop = AtomicBool::new(false);
    let result = capture(link, camera, session, plan, &stop, |p| {
        bar.set_position(p.frames);
        bar.set_message(format!(
            "{:.1} fps · paired {} · pairing errors {} · flagged {}",
            p.fps, p.paired, p.pairing_errors, p.camera_drops
        ));
    });
    bar.finish_and_clear();
    result
}

/// Records a capture on the physical rig described by `--rig`.
pub fn capture_hw(
    args: &Args,
) -> anyhow::Result<(CaptureReport, PathBuf, Option<Vec<process::TrackedFrame>>)> {
    let rig_path = args
        .rig
        .as_ref()
        .context("--rig RIG.toml is required for a hardware capture")?;
    let rig = crate::rig_file::RigFile::load(rig_path)?;
    let boards = rig.boards()?;
    let clock = HostClock::new();
    let camera = open_camera(&rig, clock)?;
    let info = camera.info();
    anyhow::ensure!(
        (info.width, info.height) == (rig.camera.width, rig.camera.height),
        "{}: the camera delivers {}×{} but the rig's camera model is {}×{}; recalibrate or fix [camera]",
        rig_path.display(),
        info.width,
        info.height,
        rig.camera.width,
        rig.camera.height
    );
    let link = TriggerLink::open(&rig.trigger.port, clock, LinkConfig::default())?;
    let mut manifest = Manifest::new(
        SessionSource::Hardware {
            trigger_port: rig.trigger.port.clone(),
            camera: format!("{}:{}", info.backend, rig.sensor.address),
        },
        SensorInfo {
            layout: serde_json::to_value(rig.sensor.layout)?
                .as_str()
                .unwrap_or_default()
                .to_string(),
            width: info.width,
            height: info.height,
            bit_depth: rig.sensor.bit_depth,
        },
        clock.wall_at_epoch_unix_us(),
    );
    manifest.rig = serde_json::to_value(RigRecord {
        camera: rig.camera,
        // The flash as `ellipso calibrate --sphere` measured it (the fit needs it); the rest of
        // the flash description takes the rig's defaults (polarised parallel to the 0° analyser).
        flash: rig
            .flash
            .map(|f| serde_json::json!({ "offset_m": f.offset_m }))
            .unwrap_or(serde_json::Value::Null),
    })?;
    manifest.boards = boards
        .iter()
        .map(serde_json::to_value)
        .collect::<Result<_, _>>()?;
    let session = SessionWriter::create(&args.out, manifest)?;
    let board_cfg = rig.board_config();
    let settings = CameraSettings {
        exposure_us: rig.sensor.exposure_us,
        gain_db: rig.sensor.gain_db,
        bit_depth: rig.sensor.bit_depth,
        external_trigger: true,
    };
    let plan = capture_plan(board_cfg, settings, rig.capture.photos);
    let (report, dir) =
        run_with_progress(&link, camera, session, &plan, rig.capture.photos, false)?;
    let tracked = if args.no_track || boards.is_empty() {
        None
    } else {
        Some(track_and_append(&dir)?)
    };
    Ok((report, dir, tracked))
}

/// Opens the rig's camera through its backend (features permitting).
fn open_camera(
    rig: &crate::rig_file::RigFile,
    clock: HostClock,
) -> anyhow::Result<Box<dyn crate::camera::Camera>> {
    use crate::rig_file::Backend;
    match rig.sensor.backend {
        #[cfg(feature = "aravis")]
        Backend::Aravis => {
            let options = crate::camera::aravis::AravisOptions {
                layout: serde_json::to_value(rig.sensor.layout)?
                    .as_str()
                    .unwrap_or_default()
                    .to_string(),
                ..Default::default()
            };
            Ok(Box::new(crate::camera::aravis::AravisCamera::open(
                &rig.sensor.address,
                options,
                clock,
            )?))
        }
        #[cfg(feature = "v4l")]
        Backend::V4l => Ok(Box::new(crate::camera::v4l::V4lCamera::open(
            &rig.sensor.address,
            clock,
        )?)),
        #[cfg(not(feature = "aravis"))]
        Backend::Aravis => missing_backend(rig, "aravis", clock),
        #[cfg(not(feature = "v4l"))]
        Backend::V4l => missing_backend(rig, "v4l", clock),
    }
}

#[cfg(not(all(feature = "aravis", feature = "v4l")))]
fn missing_backend(
    rig: &crate::rig_file::RigFile,
    feature: &str,
    _clock: HostClock,
) -> anyhow::Result<Box<dyn crate::camera::Camera>> {
    anyhow::bail!(
        "{}: camera backend `{feature}` is not in this build; rebuild with `--features {feature}`",
        rig.path.display()
    )
}

/// Tracks the poses of a recorded session and appends them to its log.
pub fn track_and_append(dir: &Path) -> anyhow::Result<Vec<process::TrackedFrame>> {
    let session = crate::session::reader::open(dir)?;
    let tracked = process::track_session(&session, &TrackConfig::default())?;
    process::append_poses(dir, &tracked, HostClock::new().now())?;
    Ok(tracked)
}

/// Prints the capture summary.
pub fn print_report(r: &CaptureReport) {
    println!("capture      {} in {:.1} s", r.end_reason, r.duration_s);
    println!(
        "frames       {} written ({} flagged), {} pulses",
        r.frames, r.flagged, r.pulses
    );
    let p = &r.pairing;
    println!(
        "pairing      {} paired · {} frames without pulse · {} pulses without frame · {} duplicates",
        p.paired,
        p.frame_without_pulse,
        p.pulse_without_frame,
        p.duplicate_frames + p.duplicate_pulses
    );
    println!(
        "link         {} frames ok · {} bad frames dropped",
        r.link.frames_ok,
        r.link.bad_frames()
    );
    if let Some(c) = &r.clock {
        println!(
            "clock        drift {:+.1} ppm · residual rms {:.0} µs",
            c.drift_ppm(),
            c.rms_us
        );
    }
}

/// Runs `ellipso capture`.
pub fn run(args: Args) -> anyhow::Result<()> {
    // The live view follows the session directory from its own threads (read-only).
    let view = if args.view {
        let v = crate::cli::view::start_live(
            args.out.clone(),
            args.view_mesh.clone(),
            true,
            &Default::default(),
        )?;
        println!("live view    open {}", v.server.url());
        Some(v)
    } else {
        None
    };
    let (report, dir, tracked) = if args.rig.is_some() {
        capture_hw(&args)?
    } else {
        capture_sim(&args, false)?
    };
    print_report(&report);
    if let Some(tracked) = tracked {
        let summary = crate::cli::replay::report(&dir, Some(&tracked))?;
        crate::cli::replay::print_summary(&summary);
    }
    println!("session      {}", dir.display());
    if view.is_some() && std::io::IsTerminal::is_terminal(&std::io::stdin()) {
        println!("live view    still open; press Enter to close it");
        let _ = std::io::stdin().read_line(&mut String::new());
    }
    Ok(())
}
