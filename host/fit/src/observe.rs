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

pub mod frames;
pub mod image;
pub mod radiometry;
pub mod sampler;

use std::path::PathBuf;

use ellipso_model::camera::CameraModel;
use ellipso_model::geometry::TriangleMesh;
use ellipso_model::mosaic::SensorLayout;
use ellipso_model::rig::FlashSpec;
use nalgebra::Isometry3;
use rayon::prelude::*;

use crate::data::{GateCounts, Sample, SampleSet, VertexSamples, ViewGeometry};
use crate::gate::GateConfig;
use crate::shard::Shard;
use ellipso_session::events::SessionEvent;
use ellipso_session::reader::{FrameEntry, Session};

pub use frames::{FrameImages, MosaicFrames};
use image::PixelRect;
pub use image::SampleKernel;
pub use radiometry::{
    PointNormaliser, SessionRadiometry, flash_of, radiometry_of, sensor_noise_of,
};
use sampler::{FrameSampler, Outcome, SessionContext, VertexRings};

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
    let event = entry.and_then(|f| f.event.as_ref());
    let Some(SessionEvent::Frame {
        exposure_us,
        gain_db,
        ..
    }) = event
    else {
        return Err(ObserveError::Manifest {
            path: session.dir.join(ellipso_session::paths::EVENTS),
            what: format!("frame {frame_id} has no `frame` event: exposure and gain unknown"),
        });
    };
    Ok(PointNormaliser::new(
        radiometry.for_frame(f64::from(*exposure_us), f64::from(*gain_db)),
        &radiometry.flash,
        world_from_camera,
    )
    .with_flash_energy(flash_energy_rel))
}

/// A posed frame to read.
struct Job<'a> {
    frame_id: u64,
    pose: Isometry3<f64>,
    entry: &'a FrameEntry,
    exposure_us: f64,
    gain_db: f64,
    /// Relative pulse energy that lit the frame, > 0.
    flash_energy_rel: f64,
}

/// Result of one frame: the view and per-vertex outcomes, and the bytes it held.
type FrameResult = Result<(ViewGeometry, Vec<Outcome>, usize), String>;

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

/// [`extract_shard`] with the analyser pixels of each posed frame from `frames` (the recorded
/// mosaic, [`MosaicFrames`], or another sensor's images of the same frames): the session
/// still supplies the camera, the flash, each frame's exposure, gain and flash energy, and
/// which frames are complete and lit.
#[expect(
    clippy::too_many_arguments,
    reason = "extract_shard's inputs plus the frame source, named"
)]
pub fn extract_from(
    session: &Session,
    radiometry: &SessionRadiometry,
    mesh: &TriangleMesh,
    poses: &[(u64, Isometry3<f64>)],
    config: &ObserveConfig,
    shard: Shard,
    frames: &dyn FrameImages,
    progress: &dyn Fn(usize, usize),
) -> Result<Extraction, ObserveError> {
    let camera = camera_of(session)?;
    let layout = session.manifest.sensor.layout;
    let poses = checked_poses(mesh, poses)?;

    let mut report = ObserveReport {
        frames_posed: poses.len(),
        ..ObserveReport::default()
    };
    let jobs = frame_jobs(session, &poses, &mut report);

    let owned: Vec<usize> = shard.vertices(mesh.positions().len()).collect();
    let rings = VertexRings::new(mesh);
    let context = SessionContext {
        mesh,
        rings: &rings,
        camera: &camera,
        max_radius_sq: sampler::max_radius_sq(&camera),
        radiometry,
        gate: &config.gate,
        full_scale_dn: (radiometry.full_scale_dn - f64::from(config.dark_level_dn)).max(1.0),
        labels: config
            .vertex_labels
            .as_deref()
            .filter(|l| l.len() == mesh.positions().len()),
        min_tap_weight: sampler::min_tap_weight(
            radiometry.full_scale_dn,
            &sensor_noise_of(session).unwrap_or_default(),
        ),
    };
    let run_frame = |job: &Job<'_>| -> FrameResult {
        // Every pixel the sampler can read: the projections inside the image
        // (`FrameSampler::observe` samples there and nowhere else).
        let camera_from_world = job.pose.inverse();
        let region = PixelRect::around(owned.iter().filter_map(|&v| {
            let pixel = camera.project(&(camera_from_world * mesh.positions()[v]))?;
            camera.contains_pixel(pixel).then_some(pixel)
        }));
        let (image, bytes) = frames.load(job.entry, region.as_ref())?;
        let view = view_of(&radiometry.flash, job.frame_id, &job.pose);
        let sampler = FrameSampler::new(
            &context,
            &view,
            &job.pose,
            image.as_ref(),
            job.exposure_us,
            job.gain_db,
            job.flash_energy_rel,
        );
        let outcomes: Vec<Outcome> = owned.par_iter().map(|&v| sampler.observe(v)).collect();
        let bytes = bytes + outcomes.len() * std::mem::size_of::<Outcome>();
        Ok((view, outcomes, bytes))
    };

    let mut vertices: Vec<VertexSamples> = owned
        .iter()
        .map(|&v| VertexSamples {
            vertex: v as u32,
            position_world: mesh.positions()[v].coords.into(),
            normal_world: mesh.normals()[v].into_inner().into(),
            samples: Vec::new(),
            gates: GateCounts::default(),
        })
        .collect();
    let mut views = Vec::new();
    let mut kept: u64 = 0;
    let sample_size = std::mem::size_of::<Sample>() as u64;
    let base_bytes = rings.bytes() as u64;
    let in_flight = config.frames_in_flight.max(1);
    let total = jobs.len();
    let pool = thread_pool(config.threads)?;
    progress(0, total);
    for (c, chunk) in jobs.chunks(in_flight).enumerate() {
        let work = || {
            chunk
                .par_iter()
                .map(&run_frame)
                .collect::<Vec<FrameResult>>()
        };
        let results = match &pool {
            Some(pool) => pool.install(work),
            None => work(),
        };
        let held: usize = results
            .iter()
            .map(|r| r.as_ref().map_or(0, |r| r.2))
            .sum::<usize>()
            + frames.held_bytes();
        report.peak_bytes = report
            .peak_bytes
            .max(base_bytes + kept * sample_size + held as u64);
        for (job, result) in chunk.iter().zip(results) {
            let (view, outcomes) = match result {
                Ok((view, outcomes, _)) => (view, outcomes),
                Err(reason) => {
                    report.skipped.push(SkippedFrame {
                        frame_id: job.frame_id,
                        reason,
                    });
                    continue;
                }
            };
            let index = views.len() as u32;
            views.push(view);
            kept += tally(&mut vertices, outcomes, index);
        }
        progress(((c + 1) * in_flight).min(total), total);
    }

    let colour = layout == SensorLayout::ColourPolar;
    for vs in &mut vertices {
        config
            .gate
            .reject_colour_outliers(&mut vs.samples, colour, &mut vs.gates);
        report.gates.add(&vs.gates);
    }
    report.skipped.sort_by_key(|s| s.frame_id);
    report.frames_used = views.len();
    report.samples = report.gates.kept;
    report.sample_bytes = report.samples * sample_size;
    report.peak_bytes = report.peak_bytes.max(base_bytes + kept * sample_size);
    // A set of every vertex carries the mesh's rings (a shard's part does not).
    let rings = if vertices.len() == mesh.positions().len() {
        crate::neighbours::rings(mesh)
    } else {
        Vec::new()
    };
    Ok(Extraction {
        samples: SampleSet {
            views,
            colour,
            vertices,
            rings,
        },
        report,
    })
}

/// `poses` sorted by frame id, each frame once and finite; `mesh` small enough for the
/// sample format's u32 vertex index.
fn checked_poses(
    mesh: &TriangleMesh,
    poses: &[(u64, Isometry3<f64>)],
) -> Result<Vec<(u64, Isometry3<f64>)>, ObserveError> {
    if u32::try_from(mesh.positions().len()).is_err() {
        return Err(ObserveError::Mesh(format!(
            "{} vertices exceed the sample format's u32 index",
            mesh.positions().len()
        )));
    }
    let mut poses = poses.to_vec();
    poses.sort_by_key(|p| p.0);
    for w in poses.windows(2) {
        if w[0].0 == w[1].0 {
            return Err(ObserveError::Pose {
                frame_id: w[0].0,
                what: "given twice".into(),
            });
        }
    }
    for (id, p) in &poses {
        let finite = p.translation.vector.iter().all(|v| v.is_finite())
            && p.rotation.coords.iter().all(|v| v.is_finite());
        if !finite {
            return Err(ObserveError::Pose {
                frame_id: *id,
                what: "not finite".into(),
            });
        }
    }
    Ok(poses)
}

/// The frames of `poses` to read (complete, with a `frame` event, lit); the others are listed
/// in `report` with the reason.
fn frame_jobs<'s>(
    session: &'s Session,
    poses: &[(u64, Isometry3<f64>)],
    report: &mut ObserveReport,
) -> Vec<Job<'s>> {
    let mut jobs = Vec::new();
    for (frame_id, pose) in poses {
        let skip = |reason: &str| SkippedFrame {
            frame_id: *frame_id,
            reason: reason.into(),
        };
        let Ok(k) = session
            .frames
            .binary_search_by_key(frame_id, |f| f.frame_id)
        else {
            report.skipped.push(skip("no frame file in the session"));
            continue;
        };
        let entry = &session.frames[k];
        if !entry.complete {
            report.skipped.push(skip("flagged incomplete at capture"));
            continue;
        }
        let Some(SessionEvent::Frame {
            exposure_us,
            gain_db,
            ..
        }) = &entry.event
        else {
            report
                .skipped
                .push(skip("no `frame` event: exposure and gain unknown"));
            continue;
        };
        // The reader turns a non-finite or negative recorded energy into "not recorded" (1.0),
        // so anything not > 0 here is a pulse that did not light the frame.
        let lit = entry.flash_energy_rel > 0.0;
        if !lit {
            report.skipped.push(skip(NO_FLASH_REASON));
            report.frames_unlit += 1;
            continue;
        }
        jobs.push(Job {
            frame_id: *frame_id,
            pose: *pose,
            entry,
            exposure_us: f64::from(*exposure_us),
            gain_db: f64::from(*gain_db),
            flash_energy_rel: entry.flash_energy_rel,
        });
    }
    jobs
}

/// A pool of `threads` workers, or `None` for rayon's global pool.
fn thread_pool(threads: Option<usize>) -> Result<Option<rayon::ThreadPool>, ObserveError> {
    Ok(match threads {
        None => None,
        Some(n) => Some(
            rayon::ThreadPoolBuilder::new()
                .num_threads(n.max(1))
                .build()
                .map_err(|e| ObserveError::Threads(e.to_string()))?,
        ),
    })
}

/// Adds one frame's `outcomes` (one per vertex of `vertices`, in order) to the vertices: a
/// kept sample with its view `index`, every other outcome to its gate count. Returns the
/// number of samples kept.
fn tally(vertices: &mut [VertexSamples], outcomes: Vec<Outcome>, index: u32) -> u64 {
    let mut kept = 0;
    for (vs, outcome) in vertices.iter_mut().zip(outcomes) {
        let g = &mut vs.gates;
        match outcome {
            Outcome::Kept(mut s) => {
                s.view = index;
                vs.samples.push(s);
                g.kept += 1;
                kept += 1;
            }
            Outcome::NotInView => g.not_in_view += 1,
            Outcome::Occluded => g.occluded += 1,
            Outcome::Mixed => g.mixed += 1,
            Outcome::Shadowed => g.shadowed += 1,
            Outcome::Gate(r) => r.count(g),
        }
    }
    kept
}
