//! The extraction itself ([`extract_from`]): the posed frames checked and chosen, read
//! `frames_in_flight` at a time, every owned vertex sampled in each, and the outcomes tallied
//! into the sample set and the report (the contract is [`super`]'s).

use ellipso_model::geometry::TriangleMesh;
use ellipso_model::mosaic::SensorLayout;
use nalgebra::Isometry3;
use rayon::prelude::*;

use super::image::PixelRect;
use super::sampler::{self, FrameSampler, Outcome, SessionContext, VertexRings};
use super::{
    Extraction, FrameImages, NO_FLASH_REASON, ObserveConfig, ObserveError, ObserveReport,
    SessionRadiometry, SkippedFrame, camera_of, sensor_noise_of, view_of,
};
use crate::data::{GateCounts, Sample, SampleSet, VertexSamples, ViewGeometry};
use crate::shard::Shard;
use ellipso_session::reader::{FrameEntry, Session};

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
        let f = match session.readable_frame(*frame_id) {
            Ok(f) => f,
            Err(why) => {
                report.skipped.push(skip(&why.to_string()));
                continue;
            }
        };
        let entry = f.entry;
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
            exposure_us: f.exposure_us,
            gain_db: f.gain_db,
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
