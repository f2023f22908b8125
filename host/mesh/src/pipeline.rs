//! [`build_mesh`]: the stages of `crate` in order, with the checks that turn bad input
//! into a [`MeshError`] naming the frames involved.

use std::time::Instant;

use ellipso_model::camera::CameraModel;
use ellipso_model::geometry::TriangleMesh;
use nalgebra::{Isometry3, Point3, Vector3};
use rayon::prelude::*;

use super::appearance::{Agreement, Board, Reservoirs, TexelGrid, pixel_sample};
use super::carve::{self, Grid, TopK, Voter};
use super::components::{self, Part};
use super::coverage::coverage;
use super::error::{frame_list, skipped_list};
use super::extract::marching_tetrahedra;
use super::frames::{PosedFrame, RayTable, View, load_features, posed_frames};
use super::halfedge::HalfEdgeMesh;
use super::implicit::Implicit;
use super::remesh::remesh;
use super::silhouette::{Silhouette, classify};
use super::volume::{Volume, plane_hit};
use super::{MeshConfig, MeshError, MeshReport};
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

/// The part of the board plane that rays through the box can reach, capped at the footprint
/// grown by its own size on every side.
fn texel_region(setup: &Setup<'_>) -> ([f64; 2], [f64; 2]) {
    let (lo, hi) = (setup.volume.min_m, setup.volume.max_m);
    let (w, h) = (hi.x - lo.x, hi.y - lo.y);
    let cap_lo = [lo.x - w, lo.y - h];
    let cap_hi = [hi.x + w, hi.y + h];
    let mut a = [lo.x, lo.y];
    let mut b = [hi.x, hi.y];
    for view in &setup.views {
        for corner in setup.volume.corners() {
            if let Some(p) = plane_hit(&view.centre, &(corner - view.centre)) {
                for k in 0..2 {
                    a[k] = a[k].min(p[k].max(cap_lo[k]));
                    b[k] = b[k].max(p[k].min(cap_hi[k]));
                }
            }
        }
    }
    (a, b)
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

/// 1.5 × the median length of a superpixel's footprint on the board (along the slope, where it
/// is longest), so every texel is hit by a pixel of most views that see it.
fn texel_from_footprint(setup: &Setup<'_>) -> f64 {
    let f = setup.camera.intrinsics.fx.min(setup.camera.intrinsics.fy) / setup.rays.tile as f64;
    let centre = nalgebra::center(&setup.volume.min_m, &setup.volume.max_m);
    let mut lengths: Vec<f64> = setup
        .views
        .iter()
        .map(|v| {
            let d = (v.centre - Point3::new(centre.x, centre.y, 0.0)).norm();
            // sin(elevation) ≥ 0.1: a grazing view's footprint is unbounded
            d / f / (v.centre.z / d).max(0.1)
        })
        .collect();
    1.5 * ellipso_report::percentile(&mut lengths, 0.5)
}

fn learn_board(setup: &Setup<'_>, config: &MeshConfig, report: &mut MeshReport) -> Board {
    let (lo, hi) = texel_region(setup);
    let a = &config.appearance;
    let grid = TexelGrid::covering(
        lo,
        hi,
        a.min_texel_m.max(texel_from_footprint(setup)),
        a.max_texels,
    );
    let mut reservoirs = Reservoirs::new(grid, a.reservoir);
    let bands = match setup.layout {
        ellipso_model::mosaic::SensorLayout::MonoPolar => 1,
        ellipso_model::mosaic::SensorLayout::ColourPolar => 3,
    };
    let rule = Agreement::new(a, bands, setup.full_scale_dn);
    let each = |i: usize, image: &super::frames::FeatureImage| {
        (0..image.width * image.height)
            .filter_map(|k| {
                pixel_sample(
                    &grid,
                    &setup.rays,
                    &setup.views[i],
                    image,
                    k,
                    setup.floor_dn,
                )
            })
            .collect::<Vec<_>>()
    };
    let mut held = 0usize;
    stream(setup, config, report, &each, &mut |i, samples| {
        held = held.max(samples.len() * 32 * config.frames_in_flight.max(1));
        reservoirs.add(i as u32, &samples);
    });
    report.peak_bytes = report.peak_bytes.max((reservoirs.bytes() + held) as u64);
    let board = reservoirs.learn(&rule, a.min_support);
    if let Some(dir) = &config.debug_dir {
        let _ = std::fs::create_dir_all(dir);
        let _ = super::debug::write_board(dir, &board);
    }
    report.texel_m = grid.texel_m;
    report.texels = grid.len();
    report.texels_learned = board.learned as f64 / grid.len().max(1) as f64;
    board
}

fn silhouettes(
    setup: &Setup<'_>,
    board: &Board,
    config: &MeshConfig,
    report: &mut MeshReport,
) -> Vec<(usize, Silhouette)> {
    let bands = match setup.layout {
        ellipso_model::mosaic::SensorLayout::MonoPolar => 1,
        ellipso_model::mosaic::SensorLayout::ColourPolar => 3,
    };
    let a = &config.appearance;
    let rule = Agreement::new(a, bands, setup.full_scale_dn);
    let each = |i: usize, image: &super::frames::FeatureImage| {
        classify(
            board,
            &rule,
            &setup.rays,
            &setup.views[i],
            image,
            setup.floor_dn,
            config.min_island_px,
            config.max_enclosed_board,
        )
    };
    let mut out = Vec::new();
    stream(setup, config, report, &each, &mut |i, s| out.push((i, s)));
    if let Some(dir) = &config.debug_dir {
        let _ = std::fs::create_dir_all(dir);
        for (_, s) in &out {
            let _ = super::debug::write_silhouette(dir, s);
        }
    }
    let mut fractions: Vec<f64> = out
        .iter()
        .map(|(_, s)| s.board_px as f64 / (s.width * s.height).max(1) as f64)
        .collect();
    report.board_pixels_median = ellipso_report::percentile(&mut fractions, 0.5);
    report.frames_used = out.len();
    report.skipped.sort_by_key(|s| s.frame_id);
    let bits: usize = out.iter().map(|(_, s)| s.bytes()).sum();
    report.peak_bytes = report.peak_bytes.max((bits + board.bytes()) as u64);
    out
}

/// Votes of every view on `grid` (streamed in chunks of views).
fn carve_grid(
    setup: &Setup<'_>,
    silhouettes: &[(usize, Silhouette)],
    grid: &Grid,
    active: Option<&[bool]>,
    truncation_m: f64,
    config: &MeshConfig,
    report: &mut MeshReport,
) -> TopK {
    let mut top = TopK::new(grid.len(), config.votes);
    let (lo, hi) = (grid.point([0, 0, 0]), grid.max_point());
    for chunk in silhouettes.chunks(8) {
        let voters: Vec<Voter> = chunk
            .par_iter()
            .filter_map(|(i, s)| {
                carve::voter(
                    &setup.camera,
                    &setup.rays,
                    setup.views[*i].clone(),
                    s,
                    [lo, hi],
                    truncation_m,
                    config.edge_inset_px,
                )
            })
            .collect();
        let held: usize = voters.iter().map(|v| v.distance.values.len() * 4).sum();
        report.peak_bytes = report.peak_bytes.max((held + top.bytes()) as u64);
        carve::vote(
            grid,
            &setup.camera,
            &setup.rays,
            &voters,
            active,
            truncation_m,
            &mut top,
        );
    }
    top
}

/// The views in which `p` (volume frame) projects inside the image.
fn frames_seeing(
    setup: &Setup<'_>,
    silhouettes: &[(usize, Silhouette)],
    p: Point3<f64>,
) -> Vec<u64> {
    views_seeing(setup, silhouettes, p)
        .map(|i| setup.views[i].frame_id)
        .collect()
}

/// Indices into `setup.views` of the views in which `p` projects inside the image.
fn views_seeing<'s>(
    setup: &'s Setup<'_>,
    silhouettes: &'s [(usize, Silhouette)],
    p: Point3<f64>,
) -> impl Iterator<Item = usize> + 's {
    silhouettes
        .iter()
        .filter(move |(i, _)| {
            let c = setup.views[*i].camera_from_volume * p;
            setup
                .camera
                .project(&c)
                .is_some_and(|px| setup.camera.contains_pixel(px))
        })
        .map(|(i, _)| *i)
}

/// [`MeshError::UnderViewed`] for the hull's `what`, when the views that see `p` (a part's
/// centre) leave its far side unseen (`crate::coverage`): the capture is short of views there, whatever the
/// object's placement.
fn under_viewed(
    setup: &Setup<'_>,
    silhouettes: &[(usize, Silhouette)],
    p: Point3<f64>,
    what: String,
    votes: usize,
) -> Option<MeshError> {
    let seeing: Vec<usize> = views_seeing(setup, silhouettes, p).collect();
    let cover = coverage(p, seeing.iter().map(|&i| setup.views[i].centre));
    cover.one_sided(votes).then(|| {
        let ids: Vec<u64> = seeing.iter().map(|&i| setup.views[i].frame_id).collect();
        MeshError::UnderViewed {
            what,
            why: cover.describe(votes),
            frames: frame_list(&ids, 10),
        }
    })
}

fn coarse_pass(
    setup: &Setup<'_>,
    silhouettes: &[(usize, Silhouette)],
    config: &MeshConfig,
    report: &mut MeshReport,
) -> Result<(Grid, Vec<f32>, Part), MeshError> {
    let (lo, hi) = (setup.volume.min_m, setup.volume.max_m);
    let v = (hi - lo).product();
    let h = (v / config.coarse_nodes.max(8) as f64).cbrt().max(1e-3);
    // nodes from half a spacing above the board
    let grid = Grid::covering(lo + Vector3::new(0.0, 0.0, h / 2.0), hi, h);
    let truncation = 4.0 * h;
    let top = carve_grid(setup, silhouettes, &grid, None, truncation, config, report);
    let (mut field, unseen) = carve::field(&top, truncation);
    let unjudged = carve::unjudged(&top);
    drop(top);
    report.nodes_unseen = unseen;
    report.coarse = Some(grid);
    if let Some(dir) = &config.debug_dir {
        let _ = super::debug::write_slices(dir, "coarse", &grid, &field, truncation as f32, 6);
    }
    let occupied: Vec<bool> = field.iter().map(|v| *v < 0.0).collect();
    let (labels, all_parts) = components::label(&grid, &occupied);
    // parts that do not rise above the first layers, or too small to be an object, are
    // board-level residue
    let (parts, residue): (Vec<Part>, Vec<Part>) = all_parts.into_iter().partition(|p| {
        p.max[2] + 1 >= config.min_part_layers.max(1) && p.volume_m3(&grid) >= config.min_part_m3
    });
    report.parts_dropped = residue.len();
    report.parts_dropped_m3 = residue.iter().map(|p| p.volume_m3(&grid)).sum();
    let Some(main) = parts.first().cloned() else {
        let ids: Vec<u64> = silhouettes
            .iter()
            .map(|(i, _)| setup.views[*i].frame_id)
            .collect();
        return Err(MeshError::HullEmpty {
            board: setup.volume.board,
            views: ids.len(),
            frames: frame_list(&ids, 8),
            votes: config.votes,
        });
    };
    // sides and top: the object must stand inside the footprint, below the box's lid
    let faces: Vec<usize> = (0..6).filter(|&f| f != 4 && main.touches[f]).collect();
    if !faces.is_empty() {
        return Err(off_board(setup, silhouettes, &grid, &main, &faces, config));
    }
    // An object that runs off the board ends where the learned board ends: beyond it no view can
    // judge the space (its background is unknown), so that part is neither carved nor solid.
    // Object and unjudged space together reaching a side of the box is the same error.
    let reach: Vec<bool> = occupied
        .iter()
        .zip(&unjudged)
        .map(|(o, u)| *o || *u)
        .collect();
    let (reach_labels, reach_parts) = components::label(&grid, &reach);
    let main_node = labels.iter().position(|l| *l == main.label);
    if let Some(region) = main_node
        .map(|n| reach_labels[n])
        .and_then(|l| reach_parts.iter().find(|p| p.label == l))
    {
        let sides: Vec<usize> = (0..4).filter(|&f| region.touches[f]).collect();
        if !sides.is_empty() {
            return Err(off_board(setup, silhouettes, &grid, &main, &sides, config));
        }
    }
    if let Some(second) = parts.get(1)
        && second.volume_m3(&grid) >= config.max_second_part * main.volume_m3(&grid)
    {
        let mm = |p: &Part| {
            let c = p.centroid_m;
            format!("({:.0}, {:.0}, {:.0})", c[0] * 1e3, c[1] * 1e3, c[2] * 1e3)
        };
        let what = format!(
            "falls apart: besides the main part there is a separate part of {:.1} cm³ at {} \
             (board frame, mm)",
            second.volume_m3(&grid) * 1e6,
            mm(second)
        );
        // either part seen from one side only: the other can be its unseen far side's shadow
        let one_sided = [components::centroid(second), components::centroid(&main)]
            .into_iter()
            .find_map(|p| under_viewed(setup, silhouettes, p, what.clone(), config.votes));
        if let Some(e) = one_sided {
            return Err(e);
        }
        return Err(MeshError::HullDisconnected {
            main_cm3: main.volume_m3(&grid) * 1e6,
            main_at: mm(&main),
            second_cm3: second.volume_m3(&grid) * 1e6,
            second_at: mm(second),
            frames: frame_list(
                &frames_seeing(setup, silhouettes, components::centroid(second)),
                10,
            ),
        });
    }
    report.parts_dropped += parts.len() - 1;
    report.parts_dropped_m3 += parts[1..].iter().map(|p| p.volume_m3(&grid)).sum::<f64>();
    components::keep_only(
        &grid,
        &mut field,
        &labels,
        main.label,
        truncation as f32,
        -truncation as f32,
    );
    Ok((grid, field, main))
}

/// [`MeshError::ObjectOffBoard`] for `main` reaching the box faces `faces` (indices into
/// [`components::FACES`]), naming the frames that see the main part's edge on the first of them;
/// [`MeshError::UnderViewed`] instead when those frames leave that edge's far side unseen.
fn off_board(
    setup: &Setup<'_>,
    silhouettes: &[(usize, Silhouette)],
    grid: &Grid,
    main: &Part,
    faces: &[usize],
    config: &MeshConfig,
) -> MeshError {
    let face = faces[0];
    let axis = face / 2;
    let ijk: [usize; 3] = std::array::from_fn(|a| match a {
        a if a == axis && face % 2 == 0 => main.min[a],
        a if a == axis => main.max[a],
        a => (main.min[a] + main.max[a]) / 2,
    });
    let (lo, hi) = (setup.volume.min_m, setup.volume.max_m);
    let face_names = faces
        .iter()
        .map(|&f| components::FACES[f])
        .collect::<Vec<_>>()
        .join(", ");
    let what = format!(
        "reaches the {face_names} face(s) of the volume above board {}",
        setup.volume.board
    );
    // judged at the object's centre, not at the face: a point at the box's edge is out of the
    // nearest views' images whatever the capture
    if let Some(e) = under_viewed(
        setup,
        silhouettes,
        components::centroid(main),
        what,
        config.votes,
    ) {
        return e;
    }
    MeshError::ObjectOffBoard {
        faces: face_names,
        board: setup.volume.board,
        x0: lo.x,
        x1: hi.x,
        y0: lo.y,
        y1: hi.y,
        height: hi.z,
        frames: frame_list(&frames_seeing(setup, silhouettes, grid.point(ijk)), 10),
    }
}

fn fine_pass(
    setup: &Setup<'_>,
    silhouettes: &[(usize, Silhouette)],
    coarse: &Grid,
    coarse_field: &[f32],
    main: &Part,
    config: &MeshConfig,
    report: &mut MeshReport,
) -> (Grid, Vec<f32>) {
    let hc = coarse.spacing_m;
    let lo_c = coarse.point(main.min) - Vector3::repeat(2.0 * hc);
    let hi_c = coarse.point(main.max) + Vector3::repeat(2.0 * hc);
    let extent = (hi_c - lo_c).max();
    let h = (extent / config.fine_cells.max(8) as f64).max(config.min_fine_spacing_m);
    // first layer half a spacing below the board: the bottom closes on the plane
    let lo = Point3::new(lo_c.x, lo_c.y, -h / 2.0);
    let grid = Grid::covering(lo, hi_c, h);
    let truncation = 3.0 * h;
    let coarse_surface = Implicit::new(coarse, coarse_field, 4.0 * hc);
    let coarse_value: Vec<f64> = (0..grid.len())
        .map(|n| coarse_surface.value(grid.point(grid.ijk(n)).coords).0)
        .collect();
    let active: Vec<bool> = (0..grid.len())
        .map(|n| grid.point(grid.ijk(n)).z > 0.0 && coarse_value[n].abs() < 2.0 * hc)
        .collect();
    report.fine_nodes_voted = active.iter().filter(|a| **a).count();
    let top = carve_grid(
        setup,
        silhouettes,
        &grid,
        Some(&active),
        truncation,
        config,
        report,
    );
    let tau = truncation as f32;
    let mut field: Vec<f32> = (0..grid.len())
        .map(|n| {
            let z = grid.point(grid.ijk(n)).z;
            // the fine pass is near the object, where the coarse pass found evidence of it:
            // the k-th vote alone decides (no solid-evidence rule, which white-on-white views
            // would riddle with holes)
            let v = if active[n] {
                top.kth(n).unwrap_or(tau)
            } else if coarse_value[n] < 0.0 {
                -tau
            } else {
                tau
            };
            // below the board is outside (module contract of `implicit`)
            v.max(-z as f32)
        })
        .collect();
    drop(top);
    // two passes of a 3-tap box filter per axis: single-node specks and one-node tunnels of
    // the vote field go, the zero crossing of a smooth surface stays within a node
    for _ in 0..2 {
        field = box_filter(&grid, &field);
    }
    report.fine = Some(grid);
    if let Some(dir) = &config.debug_dir {
        let _ = super::debug::write_slices(dir, "fine", &grid, &field, tau, 8);
    }
    let occupied: Vec<bool> = field.iter().map(|v| *v < 0.0).collect();
    let (labels, parts) = components::label(&grid, &occupied);
    if !parts.is_empty() {
        report.parts_dropped += parts.len() - 1;
        report.parts_dropped_m3 += parts[1..].iter().map(|p| p.volume_m3(&grid)).sum::<f64>();
        let (_, filled) = components::keep_only(&grid, &mut field, &labels, 0, tau, -tau);
        report.cavity_nodes_filled = filled;
    }
    (grid, field)
}

/// A separable 3-tap box filter of a grid field (edges clamped).
fn box_filter(grid: &Grid, field: &[f32]) -> Vec<f32> {
    let mut out = field.to_vec();
    for axis in 0..3 {
        let src = out.clone();
        for (n, v) in out.iter_mut().enumerate() {
            let ijk = grid.ijk(n);
            let mut sum = src[n];
            for d in [-1isize, 1] {
                let mut m = ijk;
                m[axis] = (ijk[axis] as isize + d).clamp(0, grid.n[axis] as isize - 1) as usize;
                sum += src[grid.index(m[0], m[1], m[2])];
            }
            *v = sum / 3.0;
        }
    }
    out
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
