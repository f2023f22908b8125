//! The fitted mesh as Mitsuba 3 loads it: vertices split per face, per-vertex scalars under
//! names its PLY loader keeps, and the RGB parameters baked into a texture atlas that
//! reproduces barycentric interpolation exactly.
//!
//! Why: Mitsuba's `pplastic` takes per-vertex `eta` and `alpha` through `mesh_attribute`
//! textures, but refuses them for `diffuse_reflectance` and `specular_reflectance` (its
//! sampling weights need the texture's mean, which a mesh attribute does not implement). So
//! those two become bitmaps. Each triangle owns a 2×2-texel cell; its vertices sit on three
//! texel centres and the fourth texel holds the affine extension (v1 + v2 − v0). Bilinear
//! filtering of an affine function is exact, so inside the triangle the bitmap returns exactly
//! the barycentric interpolation of the three vertex values — what ellipso's own renderer does.
//!
//! Contract of [`SplitMesh::ply_bytes`]: binary little-endian PLY with `x y z nx ny nz u v`
//! and the scalar properties `eta_0` and `alpha_0`, which Mitsuba's loader exposes as the mesh
//! attributes `vertex_eta` and `vertex_alpha` (a bare `eta`, or a name starting with a
//! postfix letter such as `sigma_s`, is dropped by it with a warning). `v` is measured from the
//! top row of the bitmap, as Mitsuba's bitmap texture reads it. The bytes are written by the
//! model's one PLY writer (`ellipso_model::geometry::ply::write_table`); this module owns the
//! schema.

use ellipso_model::geometry::ply::{PlyColumn, PlyFormat, PlyScalar, write_table};

/// A mesh with its vertices split per face (vertex `3f + k` is corner `k` of face `f`).
pub struct SplitMesh {
    /// Positions, world, metres.
    pub positions: Vec<[f32; 3]>,
    /// Unit shading normals.
    pub normals: Vec<[f32; 3]>,
    /// Texture coordinates in the atlas.
    pub uv: Vec<[f32; 2]>,
    /// Relative refractive index per vertex.
    pub eta: Vec<f32>,
    /// GGX α per vertex.
    pub alpha: Vec<f32>,
}

/// A float RGB bitmap, row-major from the top-left.
pub struct Atlas {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// R, G, B planes.
    pub rgb: [Vec<f32>; 3],
}

/// The cell grid of `faces` triangles: (cells per row, rows).
fn grid(faces: usize) -> (usize, usize) {
    let cols = (faces as f64).sqrt().ceil().max(1.0) as usize;
    (cols, faces.div_ceil(cols).max(1))
}

/// The texel (column, row) of corner `k` of face `f` (corner 3: the extension texel).
fn texel(f: usize, k: usize, cols: usize) -> (usize, usize) {
    let (cx, cy) = (2 * (f % cols), 2 * (f / cols));
    match k {
        0 => (cx, cy),
        1 => (cx + 1, cy),
        2 => (cx, cy + 1),
        _ => (cx + 1, cy + 1),
    }
}

/// Splits `faces` over `positions`/`normals` and the per-vertex scalars (see the module doc).
pub fn split(
    positions: &[[f32; 3]],
    normals: &[[f32; 3]],
    faces: &[[u32; 3]],
    eta: &[f32],
    alpha: &[f32],
) -> SplitMesh {
    let (cols, rows) = grid(faces.len());
    let (w, h) = (2 * cols, 2 * rows);
    let mut m = SplitMesh {
        positions: Vec::with_capacity(3 * faces.len()),
        normals: Vec::with_capacity(3 * faces.len()),
        uv: Vec::with_capacity(3 * faces.len()),
        eta: Vec::with_capacity(3 * faces.len()),
        alpha: Vec::with_capacity(3 * faces.len()),
    };
    for (f, face) in faces.iter().enumerate() {
        for (k, &v) in face.iter().enumerate() {
            let v = v as usize;
            let (tx, ty) = texel(f, k, cols);
            m.positions.push(positions[v]);
            m.normals.push(normals[v]);
            m.uv.push([
                ((tx as f64 + 0.5) / w as f64) as f32,
                ((ty as f64 + 0.5) / h as f64) as f32,
            ]);
            m.eta.push(eta[v]);
            m.alpha.push(alpha[v]);
        }
    }
    m
}

/// Bakes per-vertex RGB `values` into the atlas of `faces` (see the module doc).
pub fn bake(faces: &[[u32; 3]], values: &[[f32; 3]]) -> Atlas {
    let (cols, rows) = grid(faces.len());
    let (w, h) = (2 * cols, 2 * rows);
    let mut rgb = [
        vec![0.0f32; w * h],
        vec![0.0f32; w * h],
        vec![0.0f32; w * h],
    ];
    for (f, face) in faces.iter().enumerate() {
        let [a, b, c] = face.map(|v| values[v as usize]);
        let d: [f32; 3] = std::array::from_fn(|i| b[i] + c[i] - a[i]);
        for (k, value) in [a, b, c, d].into_iter().enumerate() {
            let (tx, ty) = texel(f, k, cols);
            for (plane, x) in rgb.iter_mut().zip(value) {
                plane[ty * w + tx] = x;
            }
        }
    }
    Atlas {
        width: w,
        height: h,
        rgb,
    }
}

impl SplitMesh {
    /// The PLY file of the split mesh (module doc).
    pub fn ply_bytes(&self) -> Vec<u8> {
        let names = [
            "x", "y", "z", "nx", "ny", "nz", "u", "v", "eta_0", "alpha_0",
        ];
        let columns: Vec<PlyColumn> = names
            .into_iter()
            .map(|n| PlyColumn::new(n, PlyScalar::Float))
            .collect();
        let faces: Vec<[u32; 3]> = (0..self.positions.len() as u32 / 3)
            .map(|f| [3 * f, 3 * f + 1, 3 * f + 2])
            .collect();
        write_table(
            PlyFormat::BinaryLittleEndian,
            "ellipso fit for Mitsuba 3: vertices split per face; eta_0 = relative refractive index, alpha_0 = GGX alpha; diffuse and specular albedo in the bitmaps",
            &columns,
            self.positions.len(),
            |i, row| {
                let values = self.positions[i]
                    .iter()
                    .chain(&self.normals[i])
                    .chain(&self.uv[i])
                    .chain([&self.eta[i], &self.alpha[i]]);
                for (r, &v) in row.iter_mut().zip(values) {
                    *r = f64::from(v);
                }
            },
            &faces,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bilinear lookup as Mitsuba's bitmap does it (texel centres at (i + ½)/size, clamped).
    fn bilinear(atlas: &Atlas, u: f64, v: f64, ch: usize) -> f64 {
        let x = u * atlas.width as f64 - 0.5;
        let y = v * atlas.height as f64 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let at = |i: f64, j: f64| {
            let i = (i.max(0.0) as usize).min(atlas.width - 1);
            let j = (j.max(0.0) as usize).min(atlas.height - 1);
            f64::from(atlas.rgb[ch][j * atlas.width + i])
        };
        at(x0, y0) * (1.0 - fx) * (1.0 - fy)
            + at(x0 + 1.0, y0) * fx * (1.0 - fy)
            + at(x0, y0 + 1.0) * (1.0 - fx) * fy
            + at(x0 + 1.0, y0 + 1.0) * fx * fy
    }

    #[test]
    fn the_atlas_reproduces_barycentric_interpolation_inside_every_triangle() {
        let faces = [[0, 1, 2], [2, 1, 3], [3, 4, 2], [0, 2, 4], [1, 0, 4]];
        let values: Vec<[f32; 3]> = (0..5)
            .map(|v| [0.1 * v as f32, 1.0 - 0.2 * v as f32, (v * v) as f32])
            .collect();
        let positions = vec![[0.0; 3]; 5];
        let normals = vec![[0.0, 0.0, 1.0]; 5];
        let scalars: Vec<f32> = (0..5).map(|v| 1.3 + 0.1 * v as f32).collect();
        let mesh = split(&positions, &normals, &faces, &scalars, &scalars);
        let atlas = bake(&faces, &values);
        assert_eq!((atlas.width, atlas.height), (6, 4), "3 × 2 cells of 2 × 2");
        for (f, face) in faces.iter().enumerate() {
            for bary in [
                [1.0, 0.0, 0.0],
                [0.2, 0.3, 0.5],
                [0.0, 0.5, 0.5],
                [0.6, 0.4, 0.0],
            ] {
                let uv: [f64; 2] = std::array::from_fn(|i| {
                    (0..3)
                        .map(|k| bary[k] * f64::from(mesh.uv[3 * f + k][i]))
                        .sum()
                });
                let corners = face.map(|v| values[v as usize]);
                for ch in 0..3 {
                    let want: f64 = bary
                        .iter()
                        .zip(&corners)
                        .map(|(b, c)| b * f64::from(c[ch]))
                        .sum();
                    let got = bilinear(&atlas, uv[0], uv[1], ch);
                    assert!(
                        (got - want).abs() < 1e-5,
                        "face {f} {bary:?} ch {ch}: {got} vs {want}"
                    );
                }
            }
            assert_eq!(mesh.eta[3 * f + 1], scalars[face[1] as usize]);
        }
    }

    fn fixture() -> SplitMesh {
        let positions = [
            [0.0, 0.0, 0.0],
            [0.01, 0.0, 0.0],
            [0.0, 0.02, 0.0],
            [0.013, 0.017, 0.004],
        ];
        let normals = [
            [0.0, 0.0, 1.0],
            [0.0, 0.6, 0.8],
            [0.6, 0.0, 0.8],
            [0.36, 0.48, 0.8],
        ];
        split(
            &positions,
            &normals,
            &[[0, 1, 2], [2, 1, 3]],
            &[1.5, 1.45, 1.61, 1.333],
            &[0.2, 0.05, 0.31, 0.125],
        )
    }

    /// The bytes of a small split mesh as `ply_bytes` wrote them itself before it became a
    /// schema over the model's PLY writer (captured at commit f22c554).
    #[test]
    fn ply_bytes_are_those_the_previous_writer_wrote() {
        let got = fixture().ply_bytes();
        assert!(
            got == include_bytes!("../testdata/mitsuba_small.ply"),
            "PLY bytes changed"
        );
    }

    #[test]
    fn the_ply_names_the_properties_mitsuba_keeps() {
        let mesh = split(
            &[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            &[[0.0, 0.0, 1.0]; 3],
            &[[0, 1, 2]],
            &[1.5; 3],
            &[0.2; 3],
        );
        let bytes = mesh.ply_bytes();
        let end = bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .expect("header")
            + 11;
        let header = std::str::from_utf8(&bytes[..end]).expect("text");
        assert!(header.contains("property float eta_0\nproperty float alpha_0\n"));
        assert!(!header.contains("property float eta\n"));
        assert_eq!(bytes.len() - end, 3 * 10 * 4 + (1 + 3 * 4));
    }
}
