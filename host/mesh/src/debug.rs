//! Diagnostic pictures of a carving (`MeshConfig::debug_dir`, `ellipso mesh --debug DIR`):
//! every view's board pixels (white: shows the board as learned; black: disagrees with a
//! learned texel, evidence of an object; dark grey: a tag's print, ambiguous; grey: neither)
//! and horizontal slices of a
//! grid field (grey: distance outside, dark red: inside, white on the zero crossing).

use std::path::Path;

use super::carve::Grid;
use super::silhouette::Silhouette;

/// Writes `board-FRAMEID.png` for a silhouette.
pub fn write_silhouette(dir: &Path, s: &Silhouette) -> std::io::Result<()> {
    let pixels: Vec<u8> = (0..s.width * s.height)
        .map(|k| {
            let (x, y) = ((k % s.width) as isize, (k / s.width) as isize);
            if s.is_board(x, y) {
                255
            } else if s.disagrees(x, y) {
                0
            } else if s.is_print(x, y) {
                // a tag's print as a mix of ink and paper could give it
                80
            } else {
                // neither: unknown board, a dark pixel near a dim ramp, a ray off the board
                128
            }
        })
        .collect();
    save(
        &dir.join(format!("board-{:08}.png", s.frame_id)),
        &pixels,
        s.width,
        s.height,
        image::ExtendedColorType::L8,
    )
}

/// Writes `NAME-zMM.png` slices of `field` at `slices` heights spread over the grid.
pub fn write_slices(
    dir: &Path,
    name: &str,
    grid: &Grid,
    field: &[f32],
    truncation: f32,
    slices: usize,
) -> std::io::Result<()> {
    let [nx, ny, nz] = grid.n;
    for s in 0..slices {
        let k = (s * (nz - 1)) / slices.max(2).saturating_sub(1).max(1);
        let k = k.min(nz - 1);
        let mut rgb = Vec::with_capacity(nx * ny * 3);
        // image rows top to bottom = +y to −y
        for j in (0..ny).rev() {
            for i in 0..nx {
                let v = field[grid.index(i, j, k)] / truncation.max(1e-9);
                let px = if v.abs() < 0.05 {
                    [255, 255, 255]
                } else if v > 0.0 {
                    let g = (60.0 + 195.0 * v.min(1.0)) as u8;
                    [g, g, g]
                } else {
                    [(120.0 + 100.0 * (-v).min(1.0)) as u8, 20, 20]
                };
                rgb.extend_from_slice(&px);
            }
        }
        let z_mm = grid.point([0, 0, k]).z * 1e3;
        save(
            &dir.join(format!("{name}-z{z_mm:05.1}mm.png")),
            &rgb,
            nx,
            ny,
            image::ExtendedColorType::Rgb8,
        )?;
    }
    Ok(())
}

fn save(
    path: &Path,
    pixels: &[u8],
    w: usize,
    h: usize,
    kind: image::ExtendedColorType,
) -> std::io::Result<()> {
    image::save_buffer(path, pixels, w as u32, h as u32, kind)
        .map_err(|e| std::io::Error::other(format!("{}: {e}", path.display())))
}

/// Writes `board-appearance.png`: each texel's learned band-0 value (grey, scaled by the 99th
/// percentile), unknown texels red.
pub fn write_board(dir: &Path, board: &super::appearance::Board) -> std::io::Result<()> {
    let g = board.grid;
    let mut values: Vec<f32> = board.texels.iter().flatten().map(|t| t.value[0]).collect();
    values.sort_by(f32::total_cmp);
    let top = values
        .get(values.len().saturating_sub(1) * 99 / 100)
        .copied()
        .unwrap_or(1.0)
        .max(1e-12);
    let mut rgb = Vec::with_capacity(g.len() * 3);
    for j in (0..g.ny).rev() {
        for i in 0..g.nx {
            rgb.extend_from_slice(&match &board.texels[j * g.nx + i] {
                Some(t) => {
                    let v = ((t.value[0] / top).clamp(0.0, 1.0) * 255.0) as u8;
                    [v, v, v]
                }
                None => [160, 0, 0],
            });
        }
    }
    save(
        &dir.join("board-appearance.png"),
        &rgb,
        g.nx,
        g.ny,
        image::ExtendedColorType::Rgb8,
    )
}
