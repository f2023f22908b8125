//! Observation extraction: a recorded session + camera poses + a triangle mesh → the fit's
//! [`SampleSet`] (docs/model.md §11 "Inputs and the normaliser N", "Sample gating"): per
//! (vertex, view) the observation channels `[I^d, I^s, I^α]` per colour channel divided by the
//! normaliser N, with visibility and the shared sample gates applied.
//!
//! Contract:
//! - **Inputs.** The session (`ellipso_session::reader::open`), poses `(frame id,
//!   world_from_camera)` (from `Session::poses`, tracking, or ground truth), a mesh in the
//!   world (= board) frame in metres with unit vertex normals. The camera model is the
//!   manifest's `rig.camera`, the flash `rig.flash` ([`radiometry::flash_of`]); exposure and gain
//!   are each frame's recorded values.
//! - **Views** ([`views_of`]) are built exactly as the renderer builds its shading frames
//!   (sim/src/render/shade.rs): camera centre, image up = −(camera y) in the world, flash at
//!   `FlashSpec::position_world`, polariser axis `FlashSpec::polariser_axis_world`.
//! - **Per (vertex, view)**, in this order ([`sampler::FrameSampler::observe`]): projection with
//!   distortion (behind the camera, outside the image or back-facing: `not_in_view`); a ray from
//!   the camera centre to the vertex (`occluded`); facing away from the flash or a ray from the
//!   vertex to the flash blocked (`shadowed`); bilinear sampling of the superpixel demosaic; the
//!   shared gates (`GateConfig::check_sample`, saturation over the bilinear footprint); N from
//!   [`radiometry::SessionRadiometry`]. After all views, `GateConfig::reject_colour_outliers`.
//! - **Streaming.** Frames are read, demosaiced, sampled and dropped; at most
//!   [`ObserveConfig::frames_in_flight`] frames are held at once, vertices of a frame are sampled
//!   in parallel. Every (vertex, view) result is a pure function of its inputs and results are
//!   merged in frame-id order, so the output is identical for any thread count.
//! - **Flash energy.** Every sample of a frame is divided by `E·N`, `E` the frame's recorded
//!   relative pulse energy ([`FrameEntry::flash_energy_rel`], 1 without a bracket), so frames
//!   of every bracket step give samples in the same model units; the stored normaliser is `E·N`,
//!   so the fit's noise model gives a short pulse's sample its larger relative noise
//!   (`radiometry` module doc). Every unsaturated sample of every step is kept, each with its
//!   own noise weight: no per-vertex exposure selection (docs/fit-observe.md says why).
//! - **Robustness.** A posed frame that is missing, flagged incomplete at capture, without its
//!   `frame` event (exposure unknown), unlit (recorded pulse energy 0: the flash did not fire,
//!   [`NO_FLASH_REASON`], also counted in [`ObserveReport::frames_unlit`]) or unreadable
//!   (corrupt PNG, wrong size, values beyond the bit depth) is skipped and reported in
//!   [`ObserveReport::skipped`]; it never aborts the extraction. Nothing in the session is
//!   written.
//! - **Output.** [`SampleSet::views`] holds the views of the frames actually read, in frame-id
//!   order; [`SampleSet::vertices`] one entry per mesh vertex in mesh order with samples ordered
//!   by view. [`ObserveReport::peak_bytes`] accounts the largest memory held at once (samples +
//!   frames in flight + a frame cache + per-frame results + mesh rings).

mod extract;
pub mod footprint;
pub mod frames;
pub mod image;
pub mod radiometry;
pub mod rect;
pub mod sampler;

use std::path::PathBuf;

use ellipso_model::camera::CameraModel;
use ellipso_model::geometry::TriangleMesh;
use ellipso_model::rig::FlashSpec;
use nalgebra::Isometry3;

use crate::data::{GateCounts, SampleSet, ViewGeometry};
use crate::gate::GateConfig;
use crate::shard::Shard;
use ellipso_session::reader::Session;

pub use extract::extract_from;
pub use frames::{FrameImages, MosaicFrames};
pub use image::SampleKernel;
pub use radiometry::{
    PointNormaliser, SessionRadiometry, flash_of, radiometry_of, sensor_noise_of,
};

/// Where in its superpixel tile each analyser sample is taken to sit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SamplePoint {
    /// At its real raw position (per colour and analyser lattice): no misregistration between
    /// the four analysers for smooth shading.
    #[default]
    Lattice,
    /// At the tile centre `t·u + (t − 1)/2` for all samples (the plain superpixel convention).
    SuperpixelCentre,
}

/// Settings of an extraction.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ObserveConfig {
    /// The sample gates (shared with the synthetic generator).
    pub gate: GateConfig,
    /// Worker threads (`None`: rayon's global pool).
    pub threads: Option<usize>,
    /// Frames held at once (≥ 1; each costs about 5.6 × its raw size on a mono sensor: raw,
    /// demosaic and DN planes, see docs/fit-observe.md).
    pub frames_in_flight: usize,
    /// Sample positions inside a superpixel.
    pub sample_point: SamplePoint,
    /// Black level subtracted from every raw sample, DN.
    pub dark_level_dn: f32,
    /// Interpolation of the analyser planes at a sample.
    #[serde(default)]
    pub sample_kernel: SampleKernel,
    /// A material label per mesh vertex (`None`: unknown): samples whose footprint reaches
    /// another label's triangles are gated as mixed.
    #[serde(skip)]
    pub vertex_labels: Option<Vec<u32>>,
    /// Byte budget of the frame cache a fit's outer loop keeps between its extractions
    /// ([`MosaicFrames::caching`]: each frame's sampled part; 0 decodes every frame at every
    /// extraction).
    #[serde(default = "default_frame_cache_bytes")]
    pub frame_cache_bytes: u64,
    /// The sensor calibration [`MosaicFrames`] reads the frames with (its black level, not
    /// `dark_level_dn`); `None`: an ideal sensor.
    #[serde(skip)]
    pub sensor_calibration:
        Option<std::sync::Arc<ellipso_polar::sensor_calibration::SensorCalibration>>,
}

/// 2 GiB: the object's part of a few hundred full-resolution frames.
fn default_frame_cache_bytes() -> u64 {
    2 << 30
}

impl Default for ObserveConfig {
    fn default() -> Self {
        Self {
            gate: GateConfig::default(),
            threads: None,
            frames_in_flight: 2,
            sample_point: SamplePoint::Lattice,
            dark_level_dn: 0.0,
            sample_kernel: SampleKernel::default(),
            vertex_labels: None,
            frame_cache_bytes: default_frame_cache_bytes(),
            sensor_calibration: None,
        }
    }
}

/// Why an extraction cannot run at all (per-frame problems are skipped, not errors).
#[derive(Debug, thiserror::Error)]
pub enum ObserveError {
    /// The manifest lacks something or holds it malformed.
    #[error("{}: {what}", path.display())]
    Manifest {
        /// The manifest file.
        path: PathBuf,
        /// What is missing or wrong.
        what: String,
    },
    /// The manifest records no flash, so light positions and polarisation are unknown.
    #[error(
        "{}: `rig.flash` is empty: the flash position and polariser are unknown, so no sample \
         geometry can be built; record the flash in the rig description",
        path.display()
    )]
    MissingFlash {
        /// The manifest file.
        path: PathBuf,
    },
    /// A pose is not a finite rigid transform, or a frame has two poses.
    #[error("pose of frame {frame_id}: {what}")]
    Pose {
        /// The frame.
        frame_id: u64,
        /// What is wrong.
        what: String,
    },
    /// The mesh cannot be indexed by the sample format.
    #[error("mesh: {0}")]
    Mesh(String),
    /// The worker pool could not start.
    #[error("thread pool: {0}")]
    Threads(String),
}

/// A posed frame that gave no samples, and why.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct SkippedFrame {
    /// Frame id.
    pub frame_id: u64,
    /// What was wrong.
    pub reason: String,
}

/// The [`SkippedFrame::reason`] of a posed frame whose recorded pulse energy is 0.
pub const NO_FLASH_REASON: &str =
    "flash energy 0: the flash did not fire, the frame holds no flash signal";

/// What an extraction did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ObserveReport {
    /// Poses given.
    pub frames_posed: usize,
    /// Frames read and sampled.
    pub frames_used: usize,
    /// Posed frames skipped, by frame id.
    pub skipped: Vec<SkippedFrame>,
    /// Of the skipped frames, those unlit by the flash (recorded pulse energy 0,
    /// [`NO_FLASH_REASON`]).
    #[serde(default)]
    pub frames_unlit: usize,
    /// Gate counts over all vertices.
    pub gates: GateCounts,
    /// Of the kept samples, those read with the narrower kernel where the image's own
    /// footprint crossed a silhouette or a border, admitted for vertices that had fewer than
    /// `min_views` samples otherwise (`extract::admit_narrow`, docs/fit-observe.md).
    #[serde(default)]
    pub narrow_admitted: u64,
    /// Samples kept.
    pub samples: u64,
    /// Largest memory held at once, bytes (accounted, see the module doc).
    pub peak_bytes: u64,
    /// Bytes of the kept samples.
    pub sample_bytes: u64,
}

/// The samples and the report of one extraction.
#[derive(Clone, Debug, PartialEq)]
pub struct Extraction {
    /// The fit's input.
    pub samples: SampleSet,
    /// What happened.
    pub report: ObserveReport,
}

fn manifest_path(session: &Session) -> PathBuf {
    session.dir.join(ellipso_session::paths::MANIFEST)
}

/// The camera model recorded in the session (`rig.camera`), checked against the frame size.
pub fn camera_of(session: &Session) -> Result<CameraModel, ObserveError> {
    let rig = session
        .manifest
        .rig
        .as_ref()
        .ok_or_else(|| ObserveError::Manifest {
            path: manifest_path(session),
            what: "`rig` is not recorded: no camera model".into(),
        })?;
    let s = &session.manifest.sensor;
    if (rig.camera.width, rig.camera.height) != (s.width, s.height) {
        return Err(ObserveError::Manifest {
            path: manifest_path(session),
            what: format!(
                "the camera model is {}×{} but the sensor records {}×{} frames",
                rig.camera.width, rig.camera.height, s.width, s.height
            ),
        });
    }
    Ok(rig.camera)
}

/// The view of a camera pose with `flash` (see the module doc).
pub fn view_of(
    flash: &FlashSpec,
    frame_id: u64,
    world_from_camera: &Isometry3<f64>,
) -> ViewGeometry {
    ViewGeometry::from_rig(frame_id, world_from_camera, flash)
}

/// One view per pose, in the order given, with the session's recorded flash.
pub fn views_of(
    session: &Session,
    poses: &[(u64, Isometry3<f64>)],
) -> Result<Vec<ViewGeometry>, ObserveError> {
    let flash = flash_of(session)?;
    Ok(poses
        .iter()
        .map(|(id, p)| view_of(&flash, *id, p))
        .collect())
}

/// The normaliser of recorded frame `frame_id` seen from `world_from_camera` at any world point
/// (its exposure and gain from its `frame` event, its recorded flash energy), for pictures of
/// that frame. An unlit frame (energy 0) has none.
pub fn point_normaliser(
    session: &Session,
    frame_id: u64,
    world_from_camera: &Isometry3<f64>,
) -> Result<PointNormaliser, ObserveError> {
    let radiometry = radiometry_of(session)?;
    let entry = session.frames.iter().find(|f| f.frame_id == frame_id);
    let flash_energy_rel = entry.map_or(1.0, |f| f.flash_energy_rel);
    let lit = flash_energy_rel > 0.0;
    if !lit {
        return Err(ObserveError::Manifest {
            path: session.dir.join(ellipso_session::paths::EVENTS),
            what: format!("frame {frame_id}: {NO_FLASH_REASON}"),
        });
    }
    let Some([exposure_us, gain_db]) = entry.and_then(|f| f.recorded_exposure_gain()) else {
        return Err(ObserveError::Manifest {
            path: session.dir.join(ellipso_session::paths::EVENTS),
            what: format!("frame {frame_id} has no `frame` event: exposure and gain unknown"),
        });
    };
    Ok(PointNormaliser::new(
        radiometry.for_frame(exposure_us, gain_db),
        &radiometry.flash,
        world_from_camera,
    )
    .with_flash_energy(flash_energy_rel))
}

/// Extracts the samples of `mesh` from `session` seen from `poses` with the session's own
/// radiometry ([`radiometry_of`]). `progress(frames done, frames total)` is called on the
/// calling thread.
pub fn extract(
    session: &Session,
    mesh: &TriangleMesh,
    poses: &[(u64, Isometry3<f64>)],
    config: &ObserveConfig,
    progress: &dyn Fn(usize, usize),
) -> Result<Extraction, ObserveError> {
    let radiometry = radiometry_of(session)?;
    extract_with(session, &radiometry, mesh, poses, config, progress)
}

/// [`extract`] with an explicit radiometry (e.g. a scene loaded from another path).
pub fn extract_with(
    session: &Session,
    radiometry: &SessionRadiometry,
    mesh: &TriangleMesh,
    poses: &[(u64, Isometry3<f64>)],
    config: &ObserveConfig,
    progress: &dyn Fn(usize, usize),
) -> Result<Extraction, ObserveError> {
    extract_shard(
        session,
        radiometry,
        mesh,
        poses,
        config,
        Shard::ALL,
        progress,
    )
}

/// [`extract_with`] for the vertices `shard` owns ([`Shard::owns`]): the set's `vertices` hold
/// those only, ascending, each exactly as the unsharded extraction gives it (visibility and
/// shadows are still tested against the whole mesh); the report counts those vertices' gates
/// and samples, and every frame as the unsharded one does.
pub fn extract_shard(
    session: &Session,
    radiometry: &SessionRadiometry,
    mesh: &TriangleMesh,
    poses: &[(u64, Isometry3<f64>)],
    config: &ObserveConfig,
    shard: Shard,
    progress: &dyn Fn(usize, usize),
) -> Result<Extraction, ObserveError> {
    let frames = MosaicFrames::new(session, config)?;
    extract_from(
        session, radiometry, mesh, poses, config, shard, &frames, progress,
    )
}
