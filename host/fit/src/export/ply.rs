//! `fit.ply`: the fitted mesh with every per-vertex parameter, its standard error and flags.
//!
//! Contract: binary little-endian PLY 1.0. Vertex properties, all `float` (f32) unless noted:
//! `x y z` (refined position, world, metres), `nx ny nz` (refined unit normal), `eta sigma_s
//! sigma_ss rho_s rho_ss_r rho_ss_g rho_ss_b rho_d_r rho_d_g rho_d_b`, their standard errors
//! `std_eta … std_rho_d_b` (same order; +inf where not identifiable), `normal_std_deg`,
//! `uint samples`, `uint flags` (bit k set = [`FLAG_BITS`]`[k]`; bit 9: unobserved, no fitted view
//! sees the vertex). Faces: `uchar`-counted `int`
//! lists, as the simulator's PLY reader expects, so `fit.ply` also loads as a plain mesh.
//! [`read_fit_ply`] reads back exactly what [`write_fit_ply`] wrote (f32 precision).

use std::path::Path;

use ellipso_model::geometry::TriangleMesh;

use crate::data::{FitFlag, VertexFit};

/// Flag bit order of the `flags` property.
pub const FLAG_BITS: [FitFlag; 10] = [
    FitFlag::TooFewViews,
    FitFlag::UnderDetermined,
    FitFlag::Dark,
    FitFlag::Saturated,
    FitFlag::EtaUnidentifiable,
    FitFlag::GrazingOnly,
    FitFlag::AtBound,
    FitFlag::NotConverged,
    FitFlag::EtaPooled,
    FitFlag::Unobserved,
];

/// Parameter property names in `VertexFit::std_error` order.
pub const PARAMS: [&str; 10] = [
    "eta", "sigma_s", "sigma_ss", "rho_s", "rho_ss_r", "rho_ss_g", "rho_ss_b", "rho_d_r",
    "rho_d_g", "rho_d_b",
];

/// Float properties per vertex: position 3, normal 3, params 10, std 10, normal_std 1.
const FLOATS: usize = 27;

/// Errors writing or reading `fit.ply`.
#[derive(Debug, thiserror::Error)]
pub enum PlyError {
    /// I/O on the file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// One fit per mesh vertex is required.
    #[error("{0} fits for {1} mesh vertices")]
    Count(usize, usize),
    /// Not a file this module wrote.
    #[error("{path}: {what}")]
    Format {
        /// The file.
        path: String,
        /// What is wrong.
        what: String,
    },
}

/// The bitmask of `flags`.
pub fn flag_mask(flags: &[FitFlag]) -> u32 {
    FLAG_BITS
        .iter()
        .enumerate()
        .filter(|(_, f)| flags.contains(f))
        .fold(0, |m, (k, _)| m | (1 << k))
}

/// A fit's parameters in [`PARAMS`] order.
pub fn params_of(f: &VertexFit) -> [f64; 10] {
    let p = &f.params;
    [
        p.eta,
        p.sigma_s,
        p.sigma_ss,
        p.rho_s,
        p.rho_ss[0],
        p.rho_ss[1],
        p.rho_ss[2],
        p.rho_d[0],
        p.rho_d[1],
        p.rho_d[2],
    ]
}

/// Writes `mesh` (refined positions) with `fits` (one per vertex, in order) to `path`.
pub fn write_fit_ply(path: &Path, mesh: &TriangleMesh, fits: &[VertexFit]) -> Result<(), PlyError> {
    let n = mesh.positions().len();
    if fits.len() != n {
        return Err(PlyError::Count(fits.len(), n));
    }
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment ellipso fit: per-vertex polarimetric SVBRDF\nelement vertex {n}\n"
    );
    for name in ["x", "y", "z", "nx", "ny", "nz"] {
        header += &format!("property float {name}\n");
    }
    for name in PARAMS {
        header += &format!("property float {name}\n");
    }
    for name in PARAMS {
        header += &format!("property float std_{name}\n");
    }
    header += "property float normal_std_deg\nproperty uint samples\nproperty uint flags\n";
    header += &format!(
        "element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.triangles().len()
    );
    let mut bytes = header.into_bytes();
    for (p, f) in mesh.positions().iter().zip(fits) {
        let mut floats = Vec::with_capacity(FLOATS);
        floats.extend([p.x, p.y, p.z]);
        floats.extend(f.normal_world);
        floats.extend(params_of(f));
        floats.extend(f.std_error);
        floats.push(f.normal_std_error_deg);
        for v in floats {
            bytes.extend((v as f32).to_le_bytes());
        }
        bytes.extend(f.samples_used.to_le_bytes());
        bytes.extend(flag_mask(&f.flags).to_le_bytes());
    }
    for t in mesh.triangles() {
        bytes.push(3);
        for &i in t {
            bytes.extend((i as i32).to_le_bytes());
        }
    }
    ellipso_report::atomic_file::write(path, bytes).map_err(|source| PlyError::Io {
        path: path.display().to_string(),
        source,
    })
}

/// One vertex of a `fit.ply`.
#[derive(Clone, Debug, PartialEq)]
pub struct FitVertex {
    /// Position, world, metres.
    pub position: [f32; 3],
    /// Unit normal.
    pub normal: [f32; 3],
    /// Parameters in [`PARAMS`] order.
    pub params: [f32; 10],
    /// Standard errors in [`PARAMS`] order.
    pub std_error: [f32; 10],
    /// Normal uncertainty, degrees.
    pub normal_std_deg: f32,
    /// Samples used.
    pub samples: u32,
    /// Flag bitmask ([`FLAG_BITS`]).
    pub flags: u32,
}

/// Reads the vertices of a `fit.ply` written by [`write_fit_ply`].
pub fn read_fit_ply(path: &Path) -> Result<Vec<FitVertex>, PlyError> {
    let err = |what: String| PlyError::Format {
        path: path.display().to_string(),
        what,
    };
    let bytes = std::fs::read(path).map_err(|source| PlyError::Io {
        path: path.display().to_string(),
        source,
    })?;
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .ok_or_else(|| err("no end_header".into()))?;
    let header =
        std::str::from_utf8(&bytes[..end]).map_err(|_| err("header is not text".into()))?;
    if !header.contains("property float normal_std_deg") {
        return Err(err(
            "not an ellipso fit.ply (no normal_std_deg property)".into()
        ));
    }
    let n: usize = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .and_then(|s| s.trim().parse().ok())
        .ok_or_else(|| err("no vertex count".into()))?;
    let stride = FLOATS * 4 + 8;
    let body = &bytes[end + 11..];
    if body.len() < n * stride {
        return Err(err(format!(
            "truncated: {n} vertices need {} bytes, {} present",
            n * stride,
            body.len()
        )));
    }
    let f32_at = |o: usize| f32::from_le_bytes([body[o], body[o + 1], body[o + 2], body[o + 3]]);
    let u32_at = |o: usize| u32::from_le_bytes([body[o], body[o + 1], body[o + 2], body[o + 3]]);
    Ok((0..n)
        .map(|v| {
            let o = v * stride;
            let f = |k: usize| f32_at(o + 4 * k);
            FitVertex {
                position: [f(0), f(1), f(2)],
                normal: [f(3), f(4), f(5)],
                params: std::array::from_fn(|k| f(6 + k)),
                std_error: std::array::from_fn(|k| f(16 + k)),
                normal_std_deg: f(26),
                samples: u32_at(o + FLOATS * 4),
                flags: u32_at(o + FLOATS * 4 + 4),
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_model::geometry::ply::parse_ply;
    use ellipso_model::geometry::procedural::icosphere;
    use ellipso_model::optics::pbrdf::PbrdfParams;
    use nalgebra::Point3;

    #[test]
    fn round_trip_and_loads_as_a_plain_mesh() {
        let (dirs, faces) = icosphere(1);
        let pos: Vec<_> = dirs
            .iter()
            .map(|d| Point3::from(d.into_inner() * 0.05))
            .collect();
        let mesh = TriangleMesh::new(pos, None, None, faces).unwrap();
        let fits: Vec<VertexFit> = (0..mesh.positions().len())
            .map(|v| VertexFit {
                vertex: v as u32,
                params: PbrdfParams {
                    eta: 1.4 + 0.01 * v as f64,
                    sigma_s: 0.1,
                    sigma_ss: 0.3,
                    rho_s: 0.5,
                    rho_ss: [0.1, 0.2, 0.3],
                    rho_d: [0.4, 0.5, 0.6],
                },
                normal_world: mesh.normals()[v].into_inner().into(),
                std_error: [0.01; 10].map(|x| if v == 3 { f64::INFINITY } else { x }),
                normal_std_error_deg: 0.5,
                samples_used: 40 + v as u32,
                cost: 1.0,
                iterations: 5,
                flags: if v == 3 {
                    vec![FitFlag::EtaUnidentifiable, FitFlag::AtBound]
                } else {
                    vec![]
                },
                eta_unpooled: None,
            })
            .collect();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fit.ply");
        write_fit_ply(&path, &mesh, &fits).unwrap();
        let back = read_fit_ply(&path).unwrap();
        assert_eq!(back.len(), fits.len());
        for (b, f) in back.iter().zip(&fits) {
            assert!((f64::from(b.params[0]) - f.params.eta).abs() < 1e-6);
            assert_eq!(b.samples, f.samples_used);
            assert_eq!(b.flags, flag_mask(&f.flags));
        }
        assert!(back[3].std_error[0].is_infinite());
        assert_eq!(back[3].flags, (1 << 4) | (1 << 6));
        let plain = parse_ply(&std::fs::read(&path).unwrap()).unwrap();
        assert_eq!(plain.triangles(), mesh.triangles());
        assert!((plain.positions()[5] - mesh.positions()[5]).norm() < 1e-7);
        // Wrong count and unwritable paths are named.
        assert!(matches!(
            write_fit_ply(&path, &mesh, &fits[1..]),
            Err(PlyError::Count(..))
        ));
        let bad = dir.path().join("missing").join("fit.ply");
        let e = write_fit_ply(&bad, &mesh, &fits).unwrap_err().to_string();
        assert!(e.contains("missing"), "{e}");
    }
}
