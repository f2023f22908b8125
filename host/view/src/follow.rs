//! The live follower: watches a session directory as a capture writes it and keeps a snapshot
//! for the page — counters, the latest frame's pictures, per-frame pose status, the camera path
//! on the dome, and coverage.
//!
//! Contract:
//! - Read-only: it never writes into the session. It reads the manifest, the new bytes of
//!   `events.jsonl` (complete lines only; a half-written last line waits for its end) and the
//!   frame PNGs the log names, so it follows a capture in this process (`ellipso capture --view`)
//!   or in another one (`ellipso view SESSION`) the same way, and shows a finished session too.
//! - It stays out of the capture's way: it runs on its own thread at the lowest priority
//!   ([`super::priority`]), polls every [`FollowConfig::poll`], and reads the log on every poll,
//!   but while the capture runs its heavy work (the newest frame's pictures, at most
//!   [`FRAME_RENDERS_PER_S`] a second; the newest frame's pose, one per poll; coverage) is paced
//!   to [`FollowConfig::capture_share`] of wall time. Frames it skipped are tracked once the
//!   capture has ended or paused (its log quiet for [`CAPTURE_QUIET`]: a crashed capture never
//!   writes its end), newest first, within [`FollowConfig::track_budget`] per poll. Poses the
//!   session's log records (`pose`, `pose_rejected`) win over its own.
//! - The frame's pictures are read with the sensor calibration the session recorded, where it
//!   records one (a file that cannot be used is shown as the frame's error, by name).
//! - Each change yields a new [`Snapshot`] through a `tokio::sync::watch` channel; the server
//!   pushes it to pages at most `server::LIVE_MAX_HZ` times a second.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use ellipso_model::camera::CameraModel;
use ellipso_model::geometry::TriangleMesh;
use nalgebra::{Isometry3, Point3, Vector3};

use super::coverage::{CoverageModel, PosedView};
use super::frame_view;
use super::priority::{self, Pacer};
use ellipso_polar::frame::RawFrame;
use ellipso_session::manifest::Manifest;
use ellipso_session::{frame_png, paths};
use ellipso_vision::process::RigRecord;
use ellipso_vision::track::{TrackConfig, TrackedBoard, Tracker};

mod json;
mod log;

/// Most latest-frame renders per second.
pub const FRAME_RENDERS_PER_S: f64 = 4.0;

/// A capture whose log has not grown for this long counts as paused: the follower catches up.
pub const CAPTURE_QUIET: Duration = Duration::from_secs(2);

/// What to follow and how.
#[derive(Clone, Debug)]
pub struct FollowConfig {
    /// The session directory (it may not exist yet).
    pub session: PathBuf,
    /// A mesh of the object (OBJ or PLY) for coverage; `None`: the proxy dome.
    pub mesh: Option<PathBuf>,
    /// Track poses of frames the log has none for.
    pub track: bool,
    /// Poll interval.
    pub poll: Duration,
    /// Time per poll spent tracking at most once the capture has ended.
    pub track_budget: Duration,
    /// Share of wall time the heavy work (pictures, tracking, coverage) may take while the
    /// capture runs.
    pub capture_share: f64,
}

impl FollowConfig {
    /// Defaults for `session`: tracking on, 150 ms polls, heavy work paced to 20 % of wall time
    /// while the capture runs, 120 ms of tracking per poll after it ended.
    pub fn new(session: PathBuf) -> Self {
        Self {
            session,
            mesh: None,
            track: true,
            poll: Duration::from_millis(150),
            track_budget: Duration::from_millis(120),
            capture_share: 0.2,
        }
    }
}

/// One state of the live view.
#[derive(Clone, Debug, Default)]
pub struct Snapshot {
    /// Everything but the pictures (with `version`, which increments on every change) (what the event stream sends).
    pub json: serde_json::Value,
    /// `s0`, `dolp`, `aolp` PNGs of the latest rendered frame.
    pub images: HashMap<&'static str, Arc<Vec<u8>>>,
    /// One category byte per coverage element.
    pub coverage: Arc<Vec<u8>>,
}

/// Shared between the follower and the server.
pub struct LiveHub {
    tx: tokio::sync::watch::Sender<Arc<Snapshot>>,
    mesh: Option<Arc<Vec<u8>>>,
}

impl LiveHub {
    /// The latest snapshot.
    pub fn current(&self) -> Arc<Snapshot> {
        self.tx.borrow().clone()
    }
    /// A receiver of every new snapshot.
    pub fn subscribe(&self) -> tokio::sync::watch::Receiver<Arc<Snapshot>> {
        self.tx.subscribe()
    }
    /// The coverage mesh for the page (`u32 n, u32 t`, `f32` positions and normals, `u32`
    /// indices), when a mesh was given.
    pub fn mesh_bytes(&self) -> Option<Arc<Vec<u8>>> {
        self.mesh.clone()
    }
}

/// Errors starting the follower.
#[derive(Debug, thiserror::Error)]
pub enum FollowError {
    /// The mesh could not be loaded.
    #[error("{path}: {what}")]
    Mesh {
        /// The file.
        path: String,
        /// What is wrong.
        what: String,
    },
    /// The thread could not start.
    #[error("cannot start the live follower: {0}")]
    Thread(std::io::Error),
}

/// The running follower; dropping it stops it.
pub struct Follower {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Drop for Follower {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Starts following `config.session`.
pub fn spawn(config: FollowConfig) -> Result<(Arc<LiveHub>, Follower), FollowError> {
    let mesh = match &config.mesh {
        Some(p) => Some(TriangleMesh::load(p).map_err(|e| FollowError::Mesh {
            path: p.display().to_string(),
            what: e.to_string(),
        })?),
        None => None,
    };
    let mesh_bytes = mesh.as_ref().map(|m| Arc::new(mesh_to_bytes(m)));
    let (tx, _) = tokio::sync::watch::channel(Arc::new(Snapshot::default()));
    let hub = Arc::new(LiveHub {
        tx,
        mesh: mesh_bytes,
    });
    let stop = Arc::new(AtomicBool::new(false));
    let thread = {
        let (hub, stop) = (hub.clone(), stop.clone());
        std::thread::Builder::new()
            .name("view-follow".into())
            .spawn(move || {
                priority::lower_this_thread_or_log("follower");
                // built here: the tag detector it creates is not Send
                let mut state = FollowState::new(config, mesh);
                let mut version = 0u64;
                while !stop.load(Ordering::Acquire) {
                    let started = Instant::now();
                    if state.poll() || version == 0 {
                        version += 1;
                        hub.tx.send_replace(Arc::new(state.snapshot(version)));
                    }
                    let poll = state.config.poll;
                    std::thread::sleep(poll.saturating_sub(started.elapsed()));
                }
            })
            .map_err(FollowError::Thread)?
    };
    Ok((
        hub,
        Follower {
            stop,
            thread: Some(thread),
        },
    ))
}

fn mesh_to_bytes(mesh: &TriangleMesh) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend((mesh.positions().len() as u32).to_le_bytes());
    out.extend((mesh.triangles().len() as u32).to_le_bytes());
    for p in mesh.positions() {
        p.coords
            .iter()
            .for_each(|v| out.extend((*v as f32).to_le_bytes()));
    }
    for n in mesh.normals() {
        n.iter().for_each(|v| out.extend((*v as f32).to_le_bytes()));
    }
    for t in mesh.triangles() {
        t.iter().for_each(|i| out.extend(i.to_le_bytes()));
    }
    out
}

#[derive(Clone, Debug)]
enum PoseStatus {
    Pending,
    Posed {
        world_from_camera: Isometry3<f64>,
        /// tracked by the view (not yet in the log)
        live: bool,
    },
    Rejected(String),
}

#[derive(Clone, Debug)]
struct FrameInfo {
    file: String,
    t_host_us: u64,
    flagged: Option<String>,
    pose: PoseStatus,
}

#[derive(Default)]
struct Counters {
    pulses: u64,
    paired: u64,
    pairing_errors: BTreeMap<String, u64>,
    link_ok: u64,
    link_bad: u64,
    clock_rms_us: Option<f64>,
    clock_drift_ppm: Option<f64>,
    faults: Vec<String>,
    disconnected: Option<String>,
    ended: Option<String>,
}

struct FollowState {
    config: FollowConfig,
    manifest: Option<Manifest>,
    manifest_checked: Option<Instant>,
    log_offset: u64,
    partial: Vec<u8>,
    bad_lines: u64,
    frames: BTreeMap<u64, FrameInfo>,
    /// The poses the log holds so far (the session's one fold of its pose events).
    log_poses: ellipso_session::SessionPoses,
    counters: Counters,
    tracker: Option<Result<Tracker, String>>,
    camera: Option<CameraModel>,
    flash_offset_m: Vector3<f64>,
    boards: Vec<TrackedBoard>,
    mesh: Option<TriangleMesh>,
    coverage: Option<CoverageModel>,
    covered: std::collections::BTreeSet<u64>,
    latest_view: Option<frame_view::FrameView>,
    latest_error: Option<String>,
    /// The sensor calibration the session names (read once with the manifest; `Err`: why it
    /// cannot be used, shown instead of the frame).
    sensor: Result<Option<Arc<ellipso_polar::sensor_calibration::SensorCalibration>>, String>,
    last_render: Option<Instant>,
    /// When the log last grew.
    log_grew: Option<Instant>,
    pacer: Pacer,
}

impl FollowState {
    fn new(config: FollowConfig, mesh: Option<TriangleMesh>) -> Self {
        let pacer = Pacer::new(config.capture_share);
        Self {
            config,
            manifest: None,
            manifest_checked: None,
            log_offset: 0,
            partial: Vec::new(),
            bad_lines: 0,
            frames: BTreeMap::new(),
            log_poses: Default::default(),
            counters: Counters::default(),
            tracker: None,
            camera: None,
            flash_offset_m: Vector3::new(0.0, -0.03, 0.0),
            boards: Vec::new(),
            mesh,
            coverage: None,
            covered: Default::default(),
            latest_view: None,
            latest_error: None,
            sensor: Ok(None),
            last_render: None,
            log_grew: None,
            pacer,
        }
    }

    /// One round; `true` when anything changed.
    fn poll(&mut self) -> bool {
        let mut changed = self.read_manifest();
        if self.manifest.is_none() {
            return changed;
        }
        changed |= self.read_log();
        // the heavy work, paced while the capture runs
        let capturing = self.capturing();
        if capturing && !self.pacer.ready(Instant::now()) {
            return changed;
        }
        let started = Instant::now();
        changed |= self.render_latest();
        changed |= self.track_some();
        changed |= self.update_coverage();
        if capturing {
            let now = Instant::now();
            self.pacer.spent(now - started, now);
        }
        changed
    }

    /// Whether the capture is still running: it has not logged its end, and its log grew within
    /// [`CAPTURE_QUIET`].
    fn capturing(&self) -> bool {
        self.counters.ended.is_none() && self.log_grew.is_some_and(|t| t.elapsed() < CAPTURE_QUIET)
    }

    fn read_manifest(&mut self) -> bool {
        let ended = self.manifest.as_ref().is_some_and(|m| m.end.is_some());
        let recent = self
            .manifest_checked
            .is_some_and(|t| t.elapsed() < Duration::from_secs(1));
        if ended || (self.manifest.is_some() && recent) {
            return false;
        }
        self.manifest_checked = Some(Instant::now());
        let path = self.config.session.join(paths::MANIFEST);
        let Ok(text) = ellipso_model::file_io::read_bounded_text(
            &path,
            ellipso_model::file_io::caps::MANIFEST,
        ) else {
            return false;
        };
        let Ok(manifest) = serde_json::from_str::<Manifest>(&text) else {
            return false;
        };
        let first = self.manifest.is_none();
        if first {
            self.setup_rig(&manifest);
        }
        let changed = first || manifest.end.is_some();
        if let Some(end) = &manifest.end {
            self.counters.ended.get_or_insert(end.reason.clone());
        }
        self.manifest = Some(manifest);
        changed
    }

    fn setup_rig(&mut self, manifest: &Manifest) {
        let rig: Option<&RigRecord> = manifest.rig.as_ref();
        self.boards = manifest.boards.clone();
        self.sensor = ellipso_polar::sensor_calibration::for_session(manifest, None)
            .map(|c| c.map(Arc::new))
            .map_err(|e| e.to_string());
        if let Some(rig) = rig {
            self.camera = Some(rig.camera);
            if let Some(flash) = &rig.flash {
                self.flash_offset_m = Vector3::from(flash.offset_m);
            }
        }
        if self.config.track {
            self.tracker = Some(match (rig, self.boards.is_empty()) {
                (None, _) => Err("no camera model in the manifest".into()),
                (_, true) => Err("no AprilTag boards in the manifest".into()),
                (Some(rig), false) => {
                    Tracker::new(rig.camera, self.boards.clone(), TrackConfig::default())
                        .map_err(|e| e.to_string())
                }
            });
        }
    }

    fn load_raw(&self, frame_id: u64) -> Result<RawFrame, String> {
        let manifest = self.manifest.as_ref().ok_or("no manifest")?;
        let file = self
            .frames
            .get(&frame_id)
            .map_or_else(|| paths::frame_file(frame_id), |f| f.file.clone());
        let path = self.config.session.join(paths::FRAMES).join(file);
        let (w, h, px) = frame_png::read(&path).map_err(|e| e.to_string())?;
        let layout = manifest.sensor.layout;
        RawFrame::new(w, h, manifest.sensor.bit_depth, layout, px).map_err(|e| e.to_string())
    }

    fn render_latest(&mut self) -> bool {
        let Some((&id, _)) = self.frames.iter().rev().find(|(_, f)| f.t_host_us > 0) else {
            return false;
        };
        if self.latest_view.as_ref().is_some_and(|v| v.frame_id == id) {
            return false;
        }
        let gap = Duration::from_secs_f64(1.0 / FRAME_RENDERS_PER_S);
        if self.last_render.is_some_and(|t| t.elapsed() < gap) {
            return false;
        }
        self.last_render = Some(Instant::now());
        let sensor = self.sensor.clone();
        match sensor.and_then(|cal| {
            self.load_raw(id)
                .and_then(|raw| frame_view::render(id, &raw, cal.as_deref()))
        }) {
            Ok(v) => {
                self.latest_view = Some(v);
                self.latest_error = None;
            }
            Err(e) => self.latest_error = Some(format!("frame {id}: {e}")),
        }
        true
    }

    fn track_some(&mut self) -> bool {
        let Some(Ok(_)) = &self.tracker else {
            return false;
        };
        let trackable = |f: &FrameInfo| f.flagged.is_none() && f.t_host_us > 0;
        if self.capturing() {
            // the newest frame only (what the operator points at now); the rest after the end
            let newest = self.frames.iter().rev().find(|(_, f)| trackable(f));
            return match newest {
                Some((&id, f)) if matches!(f.pose, PoseStatus::Pending) => {
                    self.track_one(id);
                    true
                }
                _ => false,
            };
        }
        let started = Instant::now();
        let mut changed = false;
        while started.elapsed() < self.config.track_budget {
            // newest pending frame first
            let Some(id) = self
                .frames
                .iter()
                .rev()
                .find(|(_, f)| matches!(f.pose, PoseStatus::Pending) && trackable(f))
                .map(|(id, _)| *id)
            else {
                break;
            };
            self.track_one(id);
            changed = true;
        }
        changed
    }

    fn track_one(&mut self, id: u64) {
        let raw = self.load_raw(id);
        let Some(Ok(tracker)) = &mut self.tracker else {
            return;
        };
        let pose = match raw {
            Err(e) => PoseStatus::Rejected(format!("frame not readable: {e}")),
            Ok(raw) => match tracker.track(&raw) {
                Ok(p) => PoseStatus::Posed {
                    world_from_camera: p.world_from_camera,
                    live: true,
                },
                Err(r) => PoseStatus::Rejected(r.to_string()),
            },
        };
        if let Some(f) = self.frames.get_mut(&id) {
            f.pose = pose;
        }
    }

    fn posed(&self) -> impl Iterator<Item = (u64, Isometry3<f64>)> + '_ {
        self.frames.iter().filter_map(|(id, f)| match f.pose {
            PoseStatus::Posed {
                world_from_camera, ..
            } => Some((*id, world_from_camera)),
            _ => None,
        })
    }

    /// The proxy's centre: the point nearest every posed camera's optical axis (≥ 3 views),
    /// else the middle of the boards' tags.
    fn proxy_centre(&self) -> Point3<f64> {
        let (mut a, mut b, mut n) = (nalgebra::Matrix3::zeros(), Vector3::zeros(), 0);
        for (_, w) in self.posed() {
            let d = w.rotation * Vector3::z();
            let m = nalgebra::Matrix3::identity() - d * d.transpose();
            a += m;
            b += m * w.translation.vector;
            n += 1;
        }
        if n >= 3
            && let Some(inv) = a.try_inverse()
            && a.determinant().abs() > 1e-6 * (n as f64).powi(3)
        {
            return Point3::from(inv * b);
        }
        let corners: Vec<Point3<f64>> = self
            .boards
            .iter()
            .flat_map(|board| {
                let w = board.world_from_board();
                board
                    .corners_board_m
                    .values()
                    .flatten()
                    .map(move |c| w * Point3::new(c[0], c[1], c[2]))
                    .collect::<Vec<_>>()
            })
            .collect();
        if corners.is_empty() {
            return Point3::origin();
        }
        Point3::from(corners.iter().map(|p| p.coords).sum::<Vector3<f64>>() / corners.len() as f64)
    }

    fn update_coverage(&mut self) -> bool {
        let Some(camera) = self.camera else {
            return false;
        };
        let posed: Vec<(u64, Isometry3<f64>)> = self.posed().collect();
        if self.coverage.is_none() || self.coverage.as_ref().is_some_and(CoverageModel::is_proxy) {
            // the proxy follows the estimated centre; rebuild when it moved by > 5 mm
            let centre = self.proxy_centre();
            let moved = self
                .coverage
                .as_ref()
                .is_none_or(|c| (c.centre() - centre).norm() > 5e-3);
            if moved {
                self.coverage = Some(match &self.mesh {
                    Some(m) => CoverageModel::on_mesh(m.clone(), camera, self.flash_offset_m),
                    None => {
                        let mut d: Vec<f64> = posed
                            .iter()
                            .map(|(_, w)| (w.translation.vector - centre.coords).norm())
                            .collect();
                        d.sort_by(f64::total_cmp);
                        let radius = d.get(d.len() / 2).map_or(0.02, |m| 0.08 * m);
                        CoverageModel::proxy(centre, radius, 400, camera, self.flash_offset_m)
                    }
                });
                self.covered.clear();
            }
        }
        let Some(coverage) = &mut self.coverage else {
            return false;
        };
        let mut changed = false;
        for (id, w) in posed {
            if self.covered.insert(id) {
                coverage.add_view(PosedView {
                    world_from_camera: w,
                });
                changed = true;
            }
        }
        changed
    }

    fn snapshot(&self, version: u64) -> Snapshot {
        let mut images = HashMap::new();
        if let Some(v) = &self.latest_view {
            for (name, png) in ["s0", "dolp", "aolp"].into_iter().zip(&v.pngs) {
                images.insert(name, Arc::new(png.clone()));
            }
        }
        Snapshot {
            json: self.json(version),
            images,
            coverage: Arc::new(
                self.coverage
                    .as_ref()
                    .map(CoverageModel::categories)
                    .unwrap_or_default(),
            ),
        }
    }
}

/// Whether `dir` looks like a session (has a manifest) or may become one.
pub fn is_session(dir: &Path) -> bool {
    dir.join(paths::MANIFEST).is_file()
}
