//! [`build_mesh`]: the stages of `crate` in order, with the checks that turn bad input
//! into a [`MeshError`] naming the frames involved. Setup, frame streaming and the surface are
//! here; the board stages in `board`, the carving passes in `carve_passes`, and the frames a
//! rejected hull names in `blame`.

mod blame;
mod board;
mod carve_passes;

use std::time::Instant;

use ellipso_model::camera::CameraModel;
use ellipso_model::geometry::TriangleMesh;
use nalgebra::{Isometry3, Point3, Vector3};
use rayon::prelude::*;

use super::carve::Grid;
use super::error::{frame_list, skipped_list};
use super::extract::marching_tetrahedra;
use super::frames::{PosedFrame, RayTable, View, load_features, posed_frames};
use super::halfedge::HalfEdgeMesh;
use super::implicit::Implicit;
use super::remesh::remesh;
use super::volume::Volume;
use super::{MeshConfig, MeshError, MeshReport};
use board::{learn_board, silhouettes};
use carve_passes::{coarse_pass, fine_pass};
use ellipso_fit::observe::radiometry::radiometry_of;
use ellipso_fit::observe::{SkippedFrame, camera_of};
use ellipso_fit::shape::hull::HullField;
use ellipso_session::reader::Session;

/// A mesh and how it was made.
#[derive(Clone, Debug)]
pub struct MeshResult {
    /// The mesh, world (board) coordinates, metres.
    pub mesh: TriangleMesh,
    /// What happened.
    pub report: MeshReport,
    /// The carved hull with the board plane under it, world-placed: the constraint the fit's
    /// surface update keeps the surface inside.
    pub hull: HullField,
}

/// Everything the passes share.
struct Setup<'a> {
    session: &'a Session,
    camera: CameraModel,
    layout: ellipso_model::mosaic::SensorLayout,
    rays: RayTable,
    volume: Volume,
    frames: Vec<PosedFrame<'a>>,
    views: Vec<View>,
    /// The base board's tag squares (their four corners), volume frame x–y, metres.
    tag_squares_m: Vec<[[f64; 2]; 4]>,
    floor_dn: f64,
    full_scale_dn: f64,
    /// The calibrated demosaic where the frames are read with a sensor calibration.
    calibrated: Option<ellipso_polar::sensor_calibration::CalibratedDemosaic>,
}

fn session_error(e: impl std::fmt::Display) -> MeshError {
    MeshError::Session(e.to_string())
}

/// Runs `f` on the configured pool.
fn on_pool<T: Send>(config: &MeshConfig, f: impl FnOnce() -> T + Send) -> Result<T, MeshError> {
    match config.threads {
        None => Ok(f()),
        Some(n) => Ok(rayon::ThreadPoolBuilder::new()
            .num_threads(n.max(1))
            .build()
            .map_err(|e| MeshError::Session(format!("thread pool: {e}")))?
            .install(f)),
    }
}

/// Builds the mesh of the object in `session` from the frames posed in `poses` (see the module
/// doc of `crate`). `progress` hears the name of each stage.
pub fn build_mesh(
    session: &Session,
    poses: &[(u64, Isometry3<f64>)],
    config: &MeshConfig,
    progress: &mut (dyn FnMut(&str) + Send),
) -> Result<MeshResult, MeshError> {
    on_pool(config, || run(session, poses, config, progress))?
}

fn run(
    session: &Session,
    poses: &[(u64, Isometry3<f64>)],
    config: &MeshConfig,
    progress: &mut (dyn FnMut(&str) + Send),
) -> Result<MeshResult, MeshError> {
    let mut report = MeshReport {
        frames_posed: poses.len(),
        ..MeshReport::default()
    };
    let mut clock = Instant::now();
    let mut lap = |report: &mut MeshReport, name: &str| {
        report
            .times_s
            .push((name.to_string(), clock.elapsed().as_secs_f64()));
        clock = Instant::now();
    };
    let setup = setup(session, poses, config, &mut report)?;
    lap(&mut report, "setup");

    progress("learning the board's appearance");
    let board = learn_board(&setup, config, &mut report);
    lap(&mut report, "board appearance");

    progress("finding the board in every view");
    let silhouettes = silhouettes(&setup, &board, config, &mut report);
    drop(board);
    lap(&mut report, "silhouettes");

    progress("carving (coarse)");
    let (coarse, coarse_field, main) = coarse_pass(&setup, &silhouettes, config, &mut report)?;
    lap(&mut report, "coarse carving");

    progress("carving (fine)");
    let (fine, field) = fine_pass(
        &setup,
        &silhouettes,
        &coarse,
        &coarse_field,
        &main,
        config,
        &mut report,
    );
    drop(silhouettes);
    lap(&mut report, "fine carving");

    progress("surface and remeshing");
    let mesh = surface(&setup, &fine, &field, config, &mut report)?;
    lap(&mut report, "surface");
    let hull = HullField::new(
        setup.volume.world_from_volume,
        fine.geometry(),
        field,
        3.0 * fine.spacing_m,
        config.votes,
    )
    .map_err(|e| MeshError::Surface(e.to_string()))?;
    Ok(MeshResult { mesh, report, hull })
}

fn setup<'a>(
    session: &'a Session,
    poses: &[(u64, Isometry3<f64>)],
    config: &MeshConfig,
    report: &mut MeshReport,
) -> Result<Setup<'a>, MeshError> {
    let camera = camera_of(session).map_err(session_error)?;
    let boards = ellipso_vision::process::boards_of(session).map_err(session_error)?;
    let layout = session.manifest.sensor.layout;
    let radiometry = radiometry_of(session).map_err(session_error)?;
    let (frames, skipped) = posed_frames(session, poses);
    report.skipped = skipped;
    let needed = config.min_posed_frames.max(config.votes);
    if frames.len() < needed {
        return Err(too_few(
            session,
            &frames,
            &report.skipped,
            needed,
            config.votes,
        ));
    }
    let cameras: Vec<Isometry3<f64>> = frames.iter().map(|f| f.world_from_camera).collect();
    let volume = Volume::new(&boards, &cameras).map_err(session_error)?;
    report.board = volume.board;
    report.board_name = volume.board_name.clone();
    report.volume_min_m = volume.min_m.coords.into();
    report.volume_max_m = volume.max_m.coords.into();
    let volume_from_board =
        volume.world_from_volume.inverse() * boards[volume.board].world_from_board();
    let tag_squares_m = boards[volume.board]
        .corners_board_m
        .values()
        .map(|corners| {
            corners.map(|c| {
                let p = volume_from_board * nalgebra::Point3::from(c);
                [p.x, p.y]
            })
        })
        .collect();
    let tile = layout.tile_px() as usize;
    let rays = RayTable::new(&camera, tile);
    let views = frames
        .iter()
        .map(|f| View::new(f, &volume, &radiometry))
        .collect();
    // the agreement noise floor, in DN of this session's bit depth
    let floor_dn = config.appearance.tolerance_dn * radiometry.full_scale_dn / 4095.0;
    Ok(Setup {
        session,
        camera,
        layout,
        rays,
        volume,
        frames,
        views,
        tag_squares_m,
        floor_dn,
        full_scale_dn: radiometry.full_scale_dn,
        calibrated: config.sensor_calibration.as_ref().map(|cal| {
            let modelled = session
                .manifest
                .rig
                .as_ref()
                .and_then(|r| r.analyser_extinction_ratio);
            ellipso_polar::sensor_calibration::CalibratedDemosaic::new(
                std::sync::Arc::clone(cal),
                modelled,
            )
        }),
    })
}

fn too_few(
    session: &Session,
    frames: &[PosedFrame<'_>],
    skipped: &[SkippedFrame],
    needed: usize,
    votes: usize,
) -> MeshError {
    let rejected: Vec<SkippedFrame> = session
        .poses()
        .rejected()
        .map(|(frame_id, reason)| SkippedFrame {
            frame_id,
            reason: reason.to_string(),
        })
        .collect();
    let ids: Vec<u64> = frames.iter().map(|f| f.frame_id).collect();
    MeshError::TooFewPosedFrames {
        usable: frames.len(),
        needed,
        votes,
        posed: frame_list(&ids, 12),
        unusable: skipped_list(skipped, 6),
        rejected: skipped_list(&rejected, 6),
    }
}

/// Frames in chunks of `frames_in_flight`, loaded in parallel; `each` runs per loaded frame and
/// `merge` on the calling thread in frame order. Unreadable frames are recorded as skipped.
fn stream<T: Send>(
    setup: &Setup<'_>,
    config: &MeshConfig,
    report: &mut MeshReport,
    each: &(dyn Fn(usize, &super::frames::FeatureImage) -> T + Sync),
    merge: &mut dyn FnMut(usize, T),
) {
    let indices: Vec<usize> = (0..setup.frames.len()).collect();
    for chunk in indices.chunks(config.frames_in_flight.max(1)) {
        let results: Vec<Result<T, String>> = chunk
            .par_iter()
            .map(|&i| {
                let image = load_features(
                    setup.session,
                    setup.layout,
                    &setup.frames[i],
                    setup.calibrated.as_ref(),
                )?;
                if (image.width, image.height) != (setup.rays.width, setup.rays.height) {
                    return Err(format!(
                        "{}×{} superpixels but the camera model gives {}×{}",
                        image.width, image.height, setup.rays.width, setup.rays.height
                    ));
                }
                Ok(each(i, &image))
            })
            .collect();
        for (&i, r) in chunk.iter().zip(results) {
            match r {
                Ok(t) => merge(i, t),
                Err(reason) => {
                    let id = setup.frames[i].frame_id;
                    if !report.skipped.iter().any(|s| s.frame_id == id) {
                        report.skipped.push(SkippedFrame {
                            frame_id: id,
                            reason,
                        });
                    }
                }
            }
        }
    }
}

fn surface(
    setup: &Setup<'_>,
    grid: &Grid,
    field: &[f32],
    config: &MeshConfig,
    report: &mut MeshReport,
) -> Result<TriangleMesh, MeshError> {
    let tau = 3.0 * grid.spacing_m;
    let soup = marching_tetrahedra(grid, field, tau as f32);
    report.extracted_vertices = soup.positions.len();
    if soup.triangles.is_empty() {
        let ids: Vec<u64> = setup.frames.iter().map(|f| f.frame_id).collect();
        return Err(MeshError::HullEmpty {
            board: setup.volume.board,
            views: ids.len(),
            frames: frame_list(&ids, 8),
            votes: config.votes,
        });
    }
    let he = HalfEdgeMesh::new(
        soup.positions.iter().map(|p| p.coords).collect(),
        &soup.triangles,
    )
    .map_err(|e| MeshError::Surface(e.to_string()))?;
    let implicit = Implicit::new(grid, field, tau);
    let project = |p: Vector3<f64>| implicit.project(p);
    let he = remesh(he, &config.remesh, &project);
    let (positions, triangles) = he.compact();
    let world = setup.volume.world_from_volume;
    let positions: Vec<Point3<f64>> = positions
        .iter()
        .map(|p| world * Point3::new(p.x, p.y, p.z.max(0.0)))
        .collect();
    report.volume_m3 = triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| positions[i as usize].coords);
            a.dot(&b.cross(&c)) / 6.0
        })
        .sum();
    report.vertices = positions.len();
    report.triangles = triangles.len();
    TriangleMesh::new(positions, None, None, triangles)
        .map_err(|e| MeshError::Surface(e.to_string()))
}
