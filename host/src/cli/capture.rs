//! `ellipso capture --sim SCENE --out DIR`: a capture on the simulated rig, recorded as a session.
//!
//! The simulated rig is assembled from the same parts as a hardware capture: the trigger board is
//! the real firmware core running in a virtual board behind a **real pseudo-terminal**, driven by
//! the host's real serial code; the camera is the simulator's camera behind the [`Camera`] trait,
//! exposing on the board's trigger edges and rendering with the polarimetric renderer. With
//! `--trigger PTY --wire SOCKET` the board is an external `ellipso sim serve` process instead.
//! After recording, poses are tracked and appended to the session (unless `--no-track`).
//!
//! `--bracket 1,0.25,0.0625` asks the trigger board for a flash-energy bracket: frame `k` is lit
//! by step `k mod len` of the full pulse (the same exposure, a shorter LED on-time). 1 to 8
//! steps, each in (0, 1], in any order (they fire in the order given; start with the full pulse to
//! make the first frame of each cycle the brightest). `--photos` counts frames, so 600 photos with
//! a 3-step bracket are 200 per step. A simulated capture takes the scene's `capture.bracket`
//! unless `--bracket` is given; its camera renders every frame at the energy it really received.
//!
//! [`Camera`]: ellipso_rig::camera::Camera

use ellipso_session::manifest::layout_name;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Duration;

use super::progress::Progress;
use anyhow::Context;
use ellipso_protocol::{Bracket, CaptureConfig, PulseCount, TriggerSource};
use ellipso_sim::render::{RenderOptions, Renderer};
use ellipso_sim::rig::{
    self, FrameSource, SimCamera, SimCameraConfig, VirtualBoard, VirtualBoardConfig,
};
use ellipso_sim::scene::Scene;
use serialport::{SerialPort, TTYPort};

use ellipso_rig::acquire::capture::{CapturePlan, CaptureReport, capture};
use ellipso_rig::acquire::pairing::PairingConfig;
use ellipso_rig::camera::sim::SimCameraBackend;
use ellipso_rig::camera::{CameraInfo, CameraSettings};
use ellipso_rig::link::{LinkConfig, TriggerLink};
use ellipso_session::manifest::{Manifest, SensorInfo, SessionSource};
use ellipso_session::rig::RigRecord;
use ellipso_session::time::HostClock;
use ellipso_session::writer::SessionWriter;
use ellipso_vision::process;
use ellipso_vision::track::TrackConfig;

/// Arguments of `ellipso capture`.
#[derive(Debug, Clone, clap::Args)]
#[command(group(clap::ArgGroup::new("source").required(true).args(["sim", "rig"])))]
pub struct Args {
    /// Scene file of the simulated rig (`sim/scenes/*.toml`).
    #[arg(long, value_name = "SCENE")]
    pub sim: Option<PathBuf>,
    /// Rig file of the physical rig (trigger port, camera backend and address, camera model,
    /// capture, boards; see `host/vision/src/rig_file.rs`).
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
    /// Take only this many photos, ≥ 1 (default: the scene's capture path).
    #[arg(long, value_parser = super::limits::count::<u32>)]
    pub photos: Option<u32>,
    /// Render at WIDTHxHEIGHT instead of the scene's resolution (intrinsics scaled): even
    /// sides in 2..=16384, as in scene files.
    #[arg(long, value_parser = super::limits::resolution)]
    pub resolution: Option<[u32; 2]>,
    /// Rays per raw pixel per axis (N×N), 1..=8.
    #[arg(long, default_value_t = 2, value_parser = super::limits::supersampling)]
    pub supersampling: u32,
    /// Time between photos, ms, in (0, 3600000] (default: the scene's `capture.interval_ms`);
    /// the board checks it against the exposure before anything is recorded.
    #[arg(long, value_parser = super::limits::interval_ms)]
    pub interval_ms: Option<f64>,
    /// Skip pose tracking after recording.
    #[arg(long)]
    pub no_track: bool,
    /// Flash-energy bracket: relative energies in (0, 1], 1 to 8, comma-separated, fired in turn
    /// (e.g. `1,0.25,0.0625`). Default: the scene's `capture.bracket` (simulator), none (rig).
    #[arg(long, value_name = "E1,E2,…", value_parser = parse_bracket)]
    pub bracket: Option<Bracket>,
    /// Show the live view in the browser while capturing (prints its URL; `docs/view.md`).
    #[arg(long)]
    pub view: bool,
    /// Object mesh for the live view's coverage (with `--view`; default: a dome proxy).
    #[arg(long, value_name = "MESH", requires = "view")]
    pub view_mesh: Option<PathBuf>,
}

/// Parses `--bracket`: 1 to 8 comma-separated relative energies, each in (0, 1].
pub fn parse_bracket(s: &str) -> Result<Bracket, String> {
    let energies = s
        .split(',')
        .map(|v| {
            let v = v.trim();
            v.parse::<f64>()
                .map_err(|e| format!("'{v}' is not a number: {e}"))
        })
        .collect::<Result<Vec<f64>, String>>()?;
    let bracket = Bracket::from_relative(&energies).map_err(|e| e.to_string())?;
    if bracket.is_empty() {
        return Err("a bracket needs at least one step".into());
    }
    Ok(bracket)
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

    fn render(&self, pose_index: usize, _frame_seed: u64, flash_energy_rel: f64) -> Vec<u16> {
        // The renderer derives each frame's noise from the scene seed and the pose index, so a
        // pose renders identically whenever it is exposed at the same energy: captures are
        // reproducible.
        match self.renderer.render_frame_lit(pose_index, flash_energy_rel) {
            Ok(f) => f.raw(),
            Err(e) => {
                tracing::error!("render of pose {pose_index} failed: {e}");
                vec![0; self.size.0 as usize * self.size.1 as usize]
            }
        }
    }
}

/// The board timing for a scene: its exposure, a flash inside it, its photo interval, and its
/// flash-energy bracket (`capture.bracket`; `bracket` overrides it).
pub fn board_config(
    scene: &Scene,
    photos: u32,
    interval_ms: Option<f64>,
    bracket: Option<Bracket>,
) -> CaptureConfig {
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
        // Validated with the scene; an unrepresentable one would have been refused there.
        bracket: bracket.unwrap_or_else(|| {
            Bracket::from_relative(&scene.capture.bracket).unwrap_or(Bracket::NONE)
        }),
    }
}

/// Records a simulated capture into `args.out`; returns the report and the session directory.
pub fn capture_sim(args: &Args, quiet: bool) -> anyhow::Result<Captured> {
    let scene_path = args
        .sim
        .as_ref()
        .context("--sim SCENE is required for a simulated capture")?;
    let scene = Scene::load(scene_path)?;
    ellipso_session::writer::check_fresh(&args.out)?;
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
    let board_cfg = board_config(scene, photos, args.interval_ms, args.bracket);
    let mut cam_config = SimCameraConfig::from_scene(scene, board_clock);
    cam_config.pose_count = photos as usize;
    // The scene's flash is the full pulse: the camera meters each exposure's on-time against it.
    cam_config.flash_reference_us =
        (board_cfg.flash_duration_us > 0).then_some(board_cfg.flash_duration_us);
    let sim_camera = SimCamera::spawn(cam_config, source, edges)?;
    let info = CameraInfo {
        backend: "sim",
        model: scene
            .name
            .clone()
            .unwrap_or_else(|| "simulated IMX250MZR".into()),
        width: size.0,
        height: size.1,
        layout: layout_name(layout).to_string(),
        bit_depth: scene.rig.camera.bit_depth,
    };
    let camera = Box::new(SimCameraBackend::new(sim_camera, clock, info.clone()));

    let mut manifest = Manifest::new(
        SessionSource::Simulator {
            // resolved, so the session's fit finds the scene from any working directory
            scene: std::fs::canonicalize(scene_path)
                .unwrap_or_else(|_| scene_path.clone())
                .display()
                .to_string(),
            seed: scene.seed,
        },
        SensorInfo {
            layout,
            width: size.0,
            height: size.1,
            bit_depth: info.bit_depth,
        },
        clock.wall_at_epoch_unix_us(),
    );
    // the record the fit reads instead of the scene file: flash, radiometry, noise
    manifest.rig = Some(process::rig_record_of_scene(scene, camera_model));
    manifest.boards = process::boards_of_scene(scene);
    check_plan(&link, board_cfg)?;
    let session = SessionWriter::create(&args.out, manifest)?;

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
    let (report, dir, signal) = result?;
    // after a stop by signal the user wants the process to end: poses can be tracked later
    let tracked = if args.no_track || signal.is_some() {
        None
    } else {
        Some(track_and_append(&dir)?)
    };
    Ok(Captured {
        report,
        dir,
        tracked,
        signal,
    })
}

/// A finished capture.
pub struct Captured {
    /// What happened.
    pub report: CaptureReport,
    /// The session directory.
    pub dir: PathBuf,
    /// Poses tracked after recording (unless `--no-track` or stopped by a signal).
    pub tracked: Option<Vec<process::TrackedFrame>>,
    /// The signal (SIGINT, SIGTERM) that stopped the capture, if one did.
    pub signal: Option<i32>,
}

/// A capture stopped by SIGINT or SIGTERM (the session is complete up to the stop); the process
/// exits with 128 + the signal number.
#[derive(Debug, thiserror::Error)]
#[error("capture stopped by signal {signal}; the session in {} is complete up to the stop (poses not tracked: run `ellipso replay` on it)", dir.display())]
pub struct Interrupted {
    /// The signal number.
    pub signal: i32,
    /// The session directory.
    pub dir: PathBuf,
}

/// Refuses a board timing the connected board would refuse, before anything is recorded (the
/// board checks it again when configured).
fn check_plan(link: &TriggerLink, config: CaptureConfig) -> anyhow::Result<()> {
    ellipso_firmware::CapturePlan::new(config, &link.board().limits).map_err(|reason| {
        anyhow::anyhow!(
            "the trigger board would refuse this capture (exposure {} µs, interval {} µs): {}",
            config.exposure_us,
            config.frame_period_us,
            ellipso_rig::link::describe_reject(&reason)
        )
    })?;
    Ok(())
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
    camera: Box<dyn ellipso_rig::camera::Camera>,
    session: SessionWriter,
    plan: &CapturePlan,
    photos: u32,
    quiet: bool,
) -> anyhow::Result<(CaptureReport, PathBuf, Option<i32>)> {
    let bar = if quiet {
        Progress::hidden()
    } else {
        Progress::bar("capture", u64::from(photos), "frames")
    };
    let stop = StopOnSignal::install()?;
    let result = capture(link, camera, session, plan, stop.flag(), |p| {
        bar.set_position(p.frames);
        bar.set_message(format!(
            "{:.1} fps · paired {} · pairing errors {} · flagged {}",
            p.fps, p.paired, p.pairing_errors, p.camera_drops
        ));
    });
    match &result {
        Ok((report, _)) => bar.finish(format!("{} frames", report.frames)),
        Err(_) => drop(bar),
    }
    let signal = stop.signal();
    drop(stop);
    let (report, dir) = result?;
    Ok((report, dir, signal))
}

/// SIGINT and SIGTERM stop a running capture cleanly: the stop flag is set, the board is told
/// to stop, frames in flight are drained and the end record written. A second SIGINT while it
/// winds down ends the process at once. Dropping this restores the default handling.
struct StopOnSignal {
    stop: Arc<AtomicBool>,
    signal: Arc<AtomicUsize>,
    ids: Vec<signal_hook::SigId>,
    /// The process-wide watcher leaves the signals to this capture (dropped after `ids`).
    _deferred: super::interrupt::Deferred,
}

impl StopOnSignal {
    fn install() -> anyhow::Result<Self> {
        use signal_hook::consts::{SIGINT, SIGTERM};
        let deferred = super::interrupt::Deferred::take();
        let stop = Arc::new(AtomicBool::new(false));
        let signal = Arc::new(AtomicUsize::new(0));
        let mut ids = Vec::new();
        for sig in [SIGINT, SIGTERM] {
            let context = || format!("cannot install the handler for signal {sig}");
            // registered first, so it sees the flag as it was before this signal
            ids.push(
                signal_hook::flag::register_conditional_shutdown(sig, 130, stop.clone())
                    .with_context(context)?,
            );
            ids.push(
                signal_hook::flag::register_usize(sig, signal.clone(), sig as usize)
                    .with_context(context)?,
            );
            ids.push(signal_hook::flag::register(sig, stop.clone()).with_context(context)?);
        }
        Ok(Self {
            stop,
            signal,
            ids,
            _deferred: deferred,
        })
    }

    fn flag(&self) -> &AtomicBool {
        &self.stop
    }

    /// The signal that stopped the capture, if one did.
    fn signal(&self) -> Option<i32> {
        match self.signal.load(Ordering::Acquire) {
            0 => None,
            s => i32::try_from(s).ok(),
        }
    }
}

impl Drop for StopOnSignal {
    fn drop(&mut self) {
        for id in self.ids.drain(..) {
            signal_hook::low_level::unregister(id);
        }
    }
}

/// Records a capture on the physical rig described by `--rig`.
pub fn capture_hw(args: &Args) -> anyhow::Result<Captured> {
    let rig_path = args
        .rig
        .as_ref()
        .context("--rig RIG.toml is required for a hardware capture")?;
    let rig = ellipso_vision::rig_file::RigFile::load(rig_path)?;
    ellipso_session::writer::check_fresh(&args.out)?;
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
            layout: rig.sensor.layout,
            width: info.width,
            height: info.height,
            bit_depth: rig.sensor.bit_depth,
        },
        clock.wall_at_epoch_unix_us(),
    );
    manifest.rig = Some(RigRecord::relative(
        rig.camera,
        // The flash as `ellipso calibrate --sphere` measured it (the fit needs it); the rest of
        // the flash description takes the rig's defaults (polarised parallel to the 0° analyser).
        rig.flash.map(|f| ellipso_model::rig::FlashSpec {
            offset_m: f.offset_m,
            ..Default::default()
        }),
    ));
    manifest.boards = boards.clone();
    let mut board_cfg = rig.board_config();
    if let Some(bracket) = args.bracket {
        board_cfg.bracket = bracket;
    }
    check_plan(&link, board_cfg)?;
    let session = SessionWriter::create(&args.out, manifest)?;
    let settings = CameraSettings {
        exposure_us: rig.sensor.exposure_us,
        gain_db: rig.sensor.gain_db,
        bit_depth: rig.sensor.bit_depth,
        external_trigger: true,
    };
    let plan = capture_plan(board_cfg, settings, rig.capture.photos);
    let (report, dir, signal) =
        run_with_progress(&link, camera, session, &plan, rig.capture.photos, false)?;
    let tracked = if args.no_track || boards.is_empty() || signal.is_some() {
        None
    } else {
        Some(track_and_append(&dir)?)
    };
    Ok(Captured {
        report,
        dir,
        tracked,
        signal,
    })
}

/// Opens the rig's camera through its backend (features permitting).
fn open_camera(
    rig: &ellipso_vision::rig_file::RigFile,
    clock: HostClock,
) -> anyhow::Result<Box<dyn ellipso_rig::camera::Camera>> {
    use ellipso_vision::rig_file::Backend;
    match rig.sensor.backend {
        #[cfg(feature = "aravis")]
        Backend::Aravis => {
            let options = ellipso_rig::camera::aravis::AravisOptions {
                layout: layout_name(rig.sensor.layout).to_string(),
                ..Default::default()
            };
            Ok(Box::new(ellipso_rig::camera::aravis::AravisCamera::open(
                &rig.sensor.address,
                options,
                clock,
            )?))
        }
        #[cfg(feature = "v4l")]
        Backend::V4l => Ok(Box::new(ellipso_rig::camera::v4l::V4lCamera::open(
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
    rig: &ellipso_vision::rig_file::RigFile,
    feature: &str,
    _clock: HostClock,
) -> anyhow::Result<Box<dyn ellipso_rig::camera::Camera>> {
    anyhow::bail!(
        "{}: camera backend `{feature}` is not in this build; rebuild with `--features {feature}`",
        rig.path.display()
    )
}

/// Tracks the poses of a recorded session and appends them to its log; short-pulse frames of a
/// bracketed capture that tracking refused borrow a pose from their tracked neighbours
/// ([`ellipso_vision::short_pulse_poses`]), logged as `pose_interpolated`.
pub fn track_and_append(dir: &Path) -> anyhow::Result<Vec<process::TrackedFrame>> {
    let session = ellipso_session::reader::open(dir)?;
    let tracked = process::track_session(&session, &TrackConfig::default())?;
    let now = HostClock::new().now();
    process::append_poses(dir, &tracked, now)?;
    let borrowed = ellipso_vision::short_pulse_poses::borrow_short_pulse_poses(&session, &tracked);
    ellipso_vision::short_pulse_poses::append_borrowed_poses(dir, &borrowed, now)?;
    if !borrowed.is_empty() {
        crate::outln!(
            "poses        {} short-pulse frames posed from their tracked neighbours",
            borrowed.len()
        );
    }
    Ok(tracked)
}

/// Prints the capture summary.
pub fn print_report(r: &CaptureReport) {
    crate::outln!("capture      {} in {:.1} s", r.end_reason, r.duration_s);
    crate::outln!(
        "frames       {} written ({} flagged), {} pulses",
        r.frames,
        r.flagged,
        r.pulses
    );
    let p = &r.pairing;
    crate::outln!(
        "pairing      {} paired · {} frames without pulse · {} pulses without frame · {} duplicates",
        p.paired,
        p.frame_without_pulse,
        p.pulse_without_frame,
        p.duplicate_frames + p.duplicate_pulses
    );
    crate::outln!(
        "link         {} frames ok · {} bad frames dropped",
        r.link.frames_ok,
        r.link.bad_frames()
    );
    if let Some(c) = &r.clock {
        crate::outln!(
            "clock        drift {:+.1} ppm · residual rms {:.0} µs",
            c.drift_ppm(),
            c.rms_us
        );
    }
    if r.paired_per_step.len() > 1 {
        let steps: Vec<String> = r.paired_per_step.iter().map(u64::to_string).collect();
        crate::outln!("bracket      paired frames per step {}", steps.join(" / "));
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
        crate::outln!("live view    open {}", v.server.url());
        Some(v)
    } else {
        None
    };
    let captured = if args.rig.is_some() {
        capture_hw(&args)?
    } else {
        capture_sim(&args, false)?
    };
    print_report(&captured.report);
    if let Some(tracked) = &captured.tracked {
        let summary = ellipso_vision::replay::report(&captured.dir, Some(tracked))
            .map_err(super::out::failed)?;
        crate::cli::replay::print_summary(&summary);
    }
    crate::outln!("session      {}", captured.dir.display());
    if let Some(signal) = captured.signal {
        return Err(Interrupted {
            signal,
            dir: captured.dir,
        }
        .into());
    }
    if view.is_some() && std::io::IsTerminal::is_terminal(&std::io::stdin()) {
        crate::outln!("live view    still open; press Enter to close it");
        let _ = std::io::stdin().read_line(&mut String::new());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bracket_argument_keeps_its_order_and_names_what_is_wrong() {
        let b = parse_bracket("1, 0.25,0.0625").unwrap();
        assert_eq!(b.steps_q15(), [0x8000, 0x2000, 0x0800]);
        let any_order = parse_bracket("0.25,1,0.5").unwrap();
        assert_eq!(any_order.steps_q15(), [0x2000, 0x8000, 0x4000]);
        for (bad, fragment) in [
            ("", "not a number"),
            ("1,,0.5", "not a number"),
            ("1,x", "'x' is not a number"),
            ("1,0", "step 1 is 0"),
            ("1.5", "(0, 1]"),
            ("-0.5", "(0, 1]"),
            ("nan", "(0, 1]"),
            ("1,1,1,1,1,1,1,1,1", "at most 8"),
            ("0.00001", "1/65536"),
        ] {
            let e = parse_bracket(bad).unwrap_err();
            assert!(e.contains(fragment), "{bad:?}: {e}");
        }
    }

    use ellipso_model::mosaic::SensorLayout;

    #[test]
    fn manifests_name_layouts_as_the_session_format_does() {
        assert_eq!(super::layout_name(SensorLayout::MonoPolar), "mono_polar");
        assert_eq!(
            super::layout_name(SensorLayout::ColourPolar),
            "colour_polar"
        );
    }
}
