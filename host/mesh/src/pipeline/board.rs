//! The board stages of [`build_mesh`](super::build_mesh): the texel grid on the board plane
//! (the region rays through the volume reach, texels sized from the views' footprints), the
//! board's appearance learned from every frame, and each frame's silhouette against it.
//!
//! Contract: frames are streamed in chunks of `frames_in_flight` (unreadable ones are recorded
//! as skipped, not fatal); the report gets the texel size and count, the fraction learned, the
//! median board fraction of the silhouettes, the frames used and the peak memory held.

use nalgebra::Point3;

use crate::appearance::{Agreement, Board, Reservoirs, TexelGrid, pixel_sample};
use crate::silhouette::{Silhouette, classify};
use crate::volume::plane_hit;
use crate::{MeshConfig, MeshReport};

use super::{Setup, stream};

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

pub(super) fn learn_board(
    setup: &Setup<'_>,
    config: &MeshConfig,
    report: &mut MeshReport,
) -> Board {
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
    let each = |i: usize, image: &crate::frames::FeatureImage| {
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
    let mut board = reservoirs.learn(&rule, a.min_support);
    let (lo, hi) = (setup.volume.min_m, setup.volume.max_m);
    board.print = crate::print::PrintedArea::new(
        &grid,
        &setup.tag_squares_m,
        &board.texels,
        [[lo.x, lo.y], [hi.x, hi.y]],
    );
    if let Some(dir) = &config.debug_dir {
        let _ = std::fs::create_dir_all(dir);
        let _ = crate::debug::write_board(dir, &board);
    }
    report.texel_m = grid.texel_m;
    report.texels = grid.len();
    report.texels_learned = board.learned as f64 / grid.len().max(1) as f64;
    board
}

pub(super) fn silhouettes(
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
    let each = |i: usize, image: &crate::frames::FeatureImage| {
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
            let _ = crate::debug::write_silhouette(dir, s);
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
