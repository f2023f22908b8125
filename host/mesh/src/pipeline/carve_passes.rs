//! The carving passes of [`build_mesh`](super::build_mesh): every view's votes on a grid, the
//! coarse pass over the whole volume (which finds the object as one part and rejects a hull that
//! is empty, off the board or falls apart), and the fine pass on a grid around that part
//! (filtered, cavities filled).
//!
//! Contract: the coarse pass returns the main part only, or a [`MeshError`] naming the frames
//! involved (`blame`); the fine field is the k-th vote where the coarse surface is near, the
//! coarse side elsewhere, box-filtered, with only the main part kept and its cavities filled.

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use crate::carve::{self, Grid, TopK, Voter};
use crate::components::{self, Part};
use crate::error::frame_list;
use crate::implicit::Implicit;
use crate::silhouette::Silhouette;
use crate::{MeshConfig, MeshError, MeshReport};

use super::Setup;
use super::blame::{frames_seeing, off_board, under_viewed};

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

pub(super) fn coarse_pass(
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
        let _ = crate::debug::write_slices(dir, "coarse", &grid, &field, truncation as f32, 6);
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

pub(super) fn fine_pass(
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
        let _ = crate::debug::write_slices(dir, "fine", &grid, &field, tau, 8);
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
