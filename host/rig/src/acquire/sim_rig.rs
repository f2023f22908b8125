//! The simulated rig of `ellipso capture --sim SCENE` ([`prepare`]), assembled from the same
//! parts as a hardware capture: the trigger board is the real firmware core running in a virtual
//! board behind a **real pseudo-terminal**, driven by the host's real serial code; the camera is
//! the simulator's camera behind the [`Camera`](crate::camera::Camera) trait, exposing on the
//! board's trigger edges and rendering with the polarimetric renderer. With an
//! [`ExternalBoard`] the board is an `ellipso sim serve` process instead (its pty and trigger
//! wire).
//!
//! Contract: the scene's capture path gives the photos (at most its poses); its `capture.bracket`
//! the flash-energy bracket unless one is given; the camera renders every frame at the energy it
//! really received. The session records the resolved scene path and seed, and the rig record and
//! boards the caller makes from the scene (`ellipso_sim::record::rig_record_of_scene` and
//! `boards_of_scene`: this crate does not link the tracker). Errors read as the command line
//! printed them when this lived in the binary; nothing here prints.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use ellipso_model::camera::CameraModel;
use ellipso_protocol::{Bracket, CaptureConfig, PulseCount, TriggerSource};
use ellipso_run_error::{Context, RunError};
use ellipso_session::manifest::{Manifest, SensorInfo, SessionSource, layout_name};
use ellipso_session::rig::{RigRecord, TrackedBoard};
use ellipso_session::time::HostClock;
use ellipso_session::writer::SessionWriter;
use ellipso_sim::render::{RenderOptions, Renderer};
use ellipso_sim::rig::{
    self, FrameSource, SimCamera, SimCameraConfig, VirtualBoard, VirtualBoardConfig,
};
use ellipso_sim::scene::Scene;
use serialport::{SerialPort, TTYPort};

use super::ready::{ReadyCapture, capture_plan, check_plan};
use crate::camera::sim::SimCameraBackend;
use crate::camera::{CameraInfo, CameraSettings};
use crate::link::{LinkConfig, TriggerLink};

/// What `ellipso capture --sim` records (its flags, parsed by the binary).
#[derive(Debug, Clone)]
pub struct SimCaptureOptions {
    /// Scene file.
    pub scene: PathBuf,
    /// Session directory to create.
    pub out: PathBuf,
    /// An external trigger board instead of the in-process virtual board.
    pub external: Option<ExternalBoard>,
    /// Take only this many photos (default, and at most: the scene's capture path).
    pub photos: Option<u32>,
    /// Render at WIDTHxHEIGHT instead of the scene's resolution.
    pub resolution: Option<[u32; 2]>,
    /// Rays per raw pixel per axis.
    pub supersampling: u32,
    /// Time between photos, ms (default: the scene's `capture.interval_ms`).
    pub interval_ms: Option<f64>,
    /// Flash-energy bracket (default: the scene's `capture.bracket`).
    pub bracket: Option<Bracket>,
}

/// The trigger board of an `ellipso sim serve` process.
#[derive(Debug, Clone)]
pub struct ExternalBoard {
    /// Its pty (or a serial device, or `unix:PATH`).
    pub trigger: String,
    /// Its trigger-wire socket.
    pub wire: PathBuf,
}

/// Loads the scene, connects the board and the simulated camera, and creates the session: a
/// capture ready to run. `describe` makes what the session records of the rig besides the
/// sensor — the rig record (from the scene and the rendered camera model) and the boards.
pub fn prepare(
    options: &SimCaptureOptions,
    describe: impl FnOnce(&Scene, CameraModel) -> (RigRecord, Vec<TrackedBoard>),
) -> Result<ReadyCapture, RunError> {
    let scene_path = &options.scene;
    let scene = Scene::load(scene_path)?;
    ellipso_session::writer::check_fresh(&options.out)?;
    // The renderer borrows the scene for the whole process (the capture threads outlive scopes).
    let scene: &'static Scene = Box::leak(Box::new(scene));
    let render_options = RenderOptions {
        supersampling: options.supersampling,
        resolution_px: options.resolution,
        ..RenderOptions::default()
    };
    let renderer = Renderer::new(scene, render_options)?;
    let camera_model = *renderer.camera();
    let layout = renderer.layout();
    let size = (camera_model.width, camera_model.height);
    let photos = options
        .photos
        .unwrap_or(scene.camera_poses.len() as u32)
        .min(scene.camera_poses.len() as u32);
    ellipso_run_error::ensure!(
        photos > 0,
        "{}: the capture path has no poses",
        scene_path.display()
    );
    let source: Arc<dyn FrameSource> = Arc::new(RenderSource { renderer, size });

    let clock = HostClock::new();
    // trigger board: in-process virtual board on a real pty, or an external one
    let (link, board, edges, board_clock) = match &options.external {
        Some(ExternalBoard {
            trigger: port,
            wire,
        }) => {
            let link = TriggerLink::open(port, clock, LinkConfig::default())?;
            let edges = rig::connect_wire(wire)?;
            let board_clock = external_board_clock(&link, clock)?;
            (link, None, edges, Some(board_clock))
        }
        None => {
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
    let board_cfg = board_config(scene, photos, options.interval_ms, options.bracket);
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
    let (rig_record, boards) = describe(scene, camera_model);
    manifest.rig = Some(rig_record);
    manifest.boards = boards;
    check_plan(&link, board_cfg)?;
    let session = SessionWriter::create(&options.out, manifest)?;

    let settings = CameraSettings {
        exposure_us: board_cfg.exposure_us,
        gain_db: scene.rig.camera.gain_db as f32,
        bit_depth: info.bit_depth,
        external_trigger: true,
    };
    Ok(ReadyCapture {
        link,
        camera,
        session,
        plan: capture_plan(board_cfg, settings, photos),
        photos,
        board,
    })
}

/// The clock of an external board (`ellipso sim serve`) as the simulated camera uses it: the
/// simulated camera places exposures in host time from the edges' device times; across
/// processes it learns the board's clock the way the host does, by ping/pong. Only the offset
/// is taken: a few milliseconds of pings cannot resolve a crystal's ppm drift (a loaded machine
/// made the slope absurd), and ignoring 25 ppm costs 250 µs over 10 s, far inside the camera's
/// latency jitter.
fn external_board_clock(
    link: &TriggerLink,
    clock: HostClock,
) -> Result<rig::LinearClock, RunError> {
    let fit = link
        .sync_clock(20)?
        .context("the trigger board's clock did not settle")?;
    let now = clock.now().0 as f64;
    let device_now = (now - fit.offset_us) / fit.gain;
    let device_at_epoch = (device_now - now).max(0.0).round() as u64;
    Ok(rig::LinearClock::new(clock.epoch(), device_at_epoch, 0.0)?)
}

/// The simulated camera of a scene standing in for a rig file's camera, on the trigger wire of
/// an external `ellipso sim serve` board (`ellipso rig check --fire --sim-camera`).
#[derive(Debug, Clone)]
pub struct StandInCamera {
    /// Scene file: what the camera sees, its sensor (layout, bit depth) and its faults.
    pub scene: PathBuf,
    /// The board's trigger-wire socket.
    pub wire: PathBuf,
    /// Render at WIDTHxHEIGHT instead of the scene's resolution.
    pub resolution: Option<[u32; 2]>,
    /// Exposure, µs: the rig file's, so the camera exposes for what it was told.
    pub exposure_us: u32,
    /// The rig's full flash pulse, µs (the camera meters each exposure's on-time against it).
    pub flash_duration_us: u32,
    /// Analogue gain, dB: the rig file's `sensor.gain_db`, so the camera amplifies by what it
    /// was told (the scene's own gain is replaced).
    pub gain_db: f64,
}

/// Opens the stand-in camera `cam` on the board behind `link` (whose clock it learns by
/// ping/pong, as [`prepare`] does for an external board); renders at 1 ray per pixel.
pub fn stand_in_camera(
    cam: &StandInCamera,
    link: &TriggerLink,
    clock: HostClock,
) -> Result<Box<dyn crate::camera::Camera>, RunError> {
    let mut scene = Scene::load(&cam.scene)?;
    // the simulated camera's gain range is a scene file's (the IMX250's 0–48 dB)
    if !(cam.gain_db.is_finite() && ellipso_sim::scene::rig::GAIN_RANGE_DB.contains(&cam.gain_db)) {
        return Err(RunError::msg(format!(
            "sensor.gain_db = {} dB: the simulated camera amplifies 0 to 48 dB (the IMX250's \
             range)",
            cam.gain_db
        )));
    }
    scene.rig.camera.gain_db = cam.gain_db;
    let scene: &'static Scene = Box::leak(Box::new(scene));
    let render_options = RenderOptions {
        supersampling: 1,
        resolution_px: cam.resolution,
        ..RenderOptions::default()
    };
    let renderer = Renderer::new(scene, render_options)?;
    let camera_model = *renderer.camera();
    let layout = renderer.layout();
    let size = (camera_model.width, camera_model.height);
    let source: Arc<dyn FrameSource> = Arc::new(RenderSource { renderer, size });
    let edges = rig::connect_wire(&cam.wire)?;
    let board_clock = external_board_clock(link, clock)?;
    let mut config = SimCameraConfig::from_scene(scene, board_clock);
    config.timing.exposure_us = cam.exposure_us.max(1);
    config.flash_reference_us = (cam.flash_duration_us > 0).then_some(cam.flash_duration_us);
    let sim_camera = SimCamera::spawn(config, source, edges)?;
    let info = CameraInfo {
        backend: "sim",
        model: format!("simulated camera of {}", cam.scene.display()),
        width: size.0,
        height: size.1,
        layout: layout_name(layout).to_string(),
        bit_depth: scene.rig.camera.bit_depth,
    };
    Ok(Box::new(SimCameraBackend::new(sim_camera, clock, info)))
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

/// Sustained payload of a GigE Vision link, bytes per second: 1 Gb/s less Ethernet, IP, UDP and
/// GVSP headers (≈ 8 % at jumbo frames), the rate `ellipso_firmware::config` quotes (≈ 23 fps
/// for 8-bit 5 MP).
pub const GIGE_PAYLOAD_BYTES_PER_S: f64 = 115e6;

/// The shortest photo interval, ms, the rig allows for `scene`'s timing at `resolution` (the
/// frame size the camera sends): the longest of the board's own rules for
/// [`board_config`]'s exposure and flash (`ellipso_firmware::plan` rule 9, the exposure plus the
/// sensor's readout; rule 8, the flash LED's duty limit; the board's shortest period) and the
/// time the camera link takes to carry one frame ([`GIGE_PAYLOAD_BYTES_PER_S`], 1 byte per
/// sample up to 8 bits, 2 above). The board accepts it exactly: it is the honest free-run
/// pace of the rig, what a real capture at full speed would take.
pub fn fastest_interval_ms(scene: &Scene, resolution: [u32; 2]) -> f64 {
    let limits = ellipso_firmware::config::LED_RIG_LIMITS;
    let board = board_config(scene, 1, None, None);
    let flash_us = u64::from(board.flash_duration_us);
    let duty_us = (1000 * flash_us).div_ceil(u64::from(limits.max_flash_duty_permille));
    let readout_us = u64::from(board.exposure_us) + u64::from(limits.readout_us);
    let bytes = f64::from(resolution[0])
        * f64::from(resolution[1])
        * if scene.rig.camera.bit_depth > 8 {
            2.0
        } else {
            1.0
        };
    let link_us = (bytes / GIGE_PAYLOAD_BYTES_PER_S * 1e6).ceil() as u64;
    let period_us = duty_us
        .max(readout_us)
        .max(link_us)
        .max(u64::from(limits.min_frame_period_us));
    period_us as f64 / 1e3
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fastest_pace_is_the_flash_duty_limit_for_the_demo() {
        let scene = Scene::load(&ellipso_sim::scene::shipped_scene("demo.toml")).unwrap();
        // 6 ms exposure, 5 ms flash: the LED's 10 % duty needs 50 ms; the readout 26 ms; the
        // link 22 ms for a 1224 × 1024 12-bit frame
        assert_eq!(fastest_interval_ms(&scene, [1224, 1024]), 50.0);
        // the board accepts it
        let config = board_config(&scene, 150, Some(50.0), None);
        ellipso_firmware::plan::CapturePlan::new(config, &ellipso_firmware::config::LED_RIG_LIMITS)
            .expect("the board accepts the fastest pace");
        // a full-size 12-bit frame takes the link longer than the flash needs
        let full = fastest_interval_ms(&scene, [2448, 2048]);
        assert!(full > 80.0 && full < 90.0, "{full}");
    }
}
