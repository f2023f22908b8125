//! The fitted material for the browser: `fit.ply` → one binary buffer and a JSON summary.
//!
//! Contract:
//! - Reads `FIT_DIR/fit.ply` (or a `.ply` path) through the fit's own reader
//!   ([`ellipso_fit::export::ply::read_fit_ply`]) for the per-vertex values and the simulator's PLY
//!   parser for the faces, so the viewer sees exactly what the export wrote.
//! - Fitted values may be wild while the fit is being reworked: a vertex whose parameters are
//!   non-finite or outside the model's domain (η < 1, σ outside [0, 1], σ_s > σ_ss, a negative
//!   albedo) gets status bit [`STATUS_INVALID`]; its parameters are clamped into the domain for the
//!   shader and the page draws it grey. The fit's identifiability rule
//!   ([`ellipso_fit::data::Identifiable`], the one the PNG maps and `maps.exr` apply) sets
//!   [`STATUS_WITHHELD`] (no parameter is a measurement: grey in every display, as in the
//!   pictures) and [`STATUS_ETA_WITHHELD`] (grey in the η displays); the user may grey more
//!   flags. Nothing here panics on bad numbers.
//! - Display ranges of each parameter and standard error are the fit's shared
//!   [`ellipso_fit::export::colour::MapRanges`] (the PNG maps' ranges) over the valid vertices.
//! - [`MaterialMesh::to_bytes`] layout (little-endian, every section 4-byte aligned):
//!   `u32 n_vertices, u32 n_triangles`, then `f32` positions `3n`, normals `3n`, parameters `10n`
//!   (clamped, [`PARAMS`] order), standard errors `10n` (as read, +inf kept), normal σ (deg) `n`,
//!   `u32` samples `n`, `u32` status `n` (fit flags in bits 0–15, [`FLAG_BITS`] order;
//!   [`STATUS_INVALID`], [`STATUS_WITHHELD`], [`STATUS_ETA_WITHHELD`] in bits 16–18),
//!   `u32` triangle indices `3t`.

use std::path::{Path, PathBuf};

use ellipso_fit::export::colour::MapRanges;
use ellipso_fit::export::ply::{FLAG_BITS, FitVertex, PARAMS, read_fit_ply};

/// Status bit: the stored parameters were non-finite or outside the model's domain.
pub const STATUS_INVALID: u32 = 1 << 16;
/// Status bit: the identifiability rule withholds every parameter of the vertex.
pub const STATUS_WITHHELD: u32 = 1 << 17;
/// Status bit: the identifiability rule withholds η.
pub const STATUS_ETA_WITHHELD: u32 = 1 << 18;
/// Fit flags occupy the bits below this.
const FLAG_BITS_MASK: u32 = 0xffff;

/// The fitted mesh, sanitised for display.
#[derive(Clone, Debug)]
pub struct MaterialMesh {
    /// The file read.
    pub path: PathBuf,
    /// Per-vertex values as read.
    pub vertices: Vec<FitVertex>,
    /// Parameters clamped into the model's domain (what the shader evaluates).
    pub params_clamped: Vec<[f32; 10]>,
    /// Fit flags (bits 0–15), [`STATUS_INVALID`] and the rule's bits.
    pub status: Vec<u32>,
    /// Triangles.
    pub triangles: Vec<[u32; 3]>,
}

/// Errors loading the fitted material; each names the file.
#[derive(Debug, thiserror::Error)]
pub enum MaterialError {
    /// Reading the per-vertex values.
    #[error(transparent)]
    Ply(#[from] ellipso_fit::export::ply::PlyError),
    /// The faces could not be read.
    #[error("{path}: {what}")]
    Mesh {
        /// The file.
        path: String,
        /// What is wrong.
        what: String,
    },
    /// Neither a fit directory nor a PLY file.
    #[error("{0}: no fit.ply there (expected a directory written by `ellipso fit` or a fit.ply)")]
    NotFound(String),
}

/// Finds `fit.ply` for a path given on the command line (the directory or the file).
pub fn locate(path: &Path) -> Option<PathBuf> {
    if path.is_file() && path.extension().is_some_and(|e| e == "ply") {
        return Some(path.to_path_buf());
    }
    [path.join("fit.ply"), path.join("fit").join("fit.ply")]
        .into_iter()
        .find(|p| p.is_file())
}

/// Clamps one vertex's parameters into the model's domain; `true` when they were already in it.
pub fn sanitise(params: &[f32; 10]) -> ([f32; 10], bool) {
    let mut p = *params;
    let mut ok = p.iter().all(|v| v.is_finite());
    for v in &mut p {
        if !v.is_finite() {
            *v = 0.0;
        }
    }
    fn clamp(v: &mut f32, lo: f32, hi: f32) -> bool {
        let inside = (lo..=hi).contains(v);
        *v = v.clamp(lo, hi);
        inside
    }
    ok &= clamp(&mut p[0], 1.0, 4.0);
    let ordered = p[1] <= p[2];
    ok &= clamp(&mut p[1], 0.0, 1.0);
    ok &= clamp(&mut p[2], 0.0, 1.0);
    if !ordered {
        ok = false;
        p[2] = p[1].max(p[2]);
    }
    for v in &mut p[3..] {
        ok &= clamp(v, 0.0, f32::MAX);
    }
    (p, ok)
}

impl MaterialMesh {
    /// Loads `fit.ply` at `path` (a fit directory or the file).
    pub fn load(path: &Path) -> Result<Self, MaterialError> {
        let file =
            locate(path).ok_or_else(|| MaterialError::NotFound(path.display().to_string()))?;
        let vertices = read_fit_ply(&file)?;
        let bytes = ellipso_model::file_io::read_bounded(&file, ellipso_model::file_io::caps::MESH)
            .map_err(|e| MaterialError::Mesh {
                path: file.display().to_string(),
                what: e.to_string(),
            })?;
        let mesh =
            ellipso_model::geometry::ply::parse_ply(&bytes).map_err(|e| MaterialError::Mesh {
                path: file.display().to_string(),
                what: e.to_string(),
            })?;
        if mesh.positions().len() != vertices.len() {
            return Err(MaterialError::Mesh {
                path: file.display().to_string(),
                what: format!(
                    "{} vertices with fitted values but {} in the mesh",
                    vertices.len(),
                    mesh.positions().len()
                ),
            });
        }
        let (params_clamped, status) = vertices
            .iter()
            .map(|v| {
                let (p, ok) = sanitise(&v.params);
                let geometry_ok = v.position.iter().chain(&v.normal).all(|x| x.is_finite());
                let invalid = if ok && geometry_ok { 0 } else { STATUS_INVALID };
                let rule = v.identifiable();
                let withheld = if rule.vertex { 0 } else { STATUS_WITHHELD };
                let eta_withheld = if rule.eta { 0 } else { STATUS_ETA_WITHHELD };
                (
                    p,
                    (v.flags & FLAG_BITS_MASK) | invalid | withheld | eta_withheld,
                )
            })
            .unzip();
        Ok(Self {
            path: file,
            vertices,
            params_clamped,
            status,
            triangles: mesh.triangles().to_vec(),
        })
    }

    /// The binary buffer the page draws (layout in the module doc).
    pub fn to_bytes(&self) -> Vec<u8> {
        let n = self.vertices.len();
        let mut out = Vec::with_capacity(8 + n * 4 * 30 + self.triangles.len() * 12);
        out.extend((n as u32).to_le_bytes());
        out.extend((self.triangles.len() as u32).to_le_bytes());
        let mut put = |v: f32| out.extend(v.to_le_bytes());
        for v in &self.vertices {
            v.position
                .iter()
                .for_each(|&x| put(if x.is_finite() { x } else { 0.0 }));
        }
        for v in &self.vertices {
            let len = v.normal.iter().map(|x| x * x).sum::<f32>().sqrt();
            let n = if len.is_finite() && len > 1e-6 {
                v.normal.map(|x| x / len)
            } else {
                [0.0, 0.0, 1.0]
            };
            n.iter().for_each(|&x| put(x));
        }
        self.params_clamped.iter().flatten().for_each(|&x| put(x));
        self.vertices
            .iter()
            .flat_map(|v| v.std_error)
            .for_each(&mut put);
        self.vertices.iter().for_each(|v| put(v.normal_std_deg));
        for v in &self.vertices {
            out.extend(v.samples.to_le_bytes());
        }
        for s in &self.status {
            out.extend(s.to_le_bytes());
        }
        for t in &self.triangles {
            for i in t {
                out.extend(i.to_le_bytes());
            }
        }
        out
    }

    /// The summary the page needs before the buffer: counts, bounds, names, ranges.
    pub fn info(&self) -> serde_json::Value {
        let rows: Vec<_> = (0..self.vertices.len())
            .filter(|&i| self.status[i] & STATUS_INVALID == 0)
            .map(|i| {
                let v = &self.vertices[i];
                (
                    self.params_clamped[i].map(f64::from),
                    v.std_error.map(f64::from),
                    v.identifiable(),
                )
            })
            .collect();
        let shared = MapRanges::of(&rows);
        let ranges: Vec<[f64; 2]> = shared.params.iter().map(|r| [r.0, r.1]).collect();
        let std_ranges: Vec<[f64; 2]> = shared.std_error.iter().map(|r| [r.0, r.1]).collect();
        let (centre, radius) = bounding_sphere(&self.vertices);
        let mut flag_names: Vec<String> = FLAG_BITS.iter().map(|f| format!("{f:?}")).collect();
        flag_names.push("Invalid (outside the model's domain)".into());
        let bits: Vec<u32> = (0..FLAG_BITS.len())
            .map(|b| 1 << b)
            .chain([STATUS_INVALID])
            .collect();
        let flag_counts: Vec<usize> = bits
            .iter()
            .map(|bit| self.status.iter().filter(|s| *s & bit != 0).count())
            .collect();
        let unflagged = self
            .status
            .iter()
            .filter(|s| *s & (FLAG_BITS_MASK | STATUS_INVALID) == 0)
            .count();
        serde_json::json!({
            "file": self.path.display().to_string(),
            "vertices": self.vertices.len(),
            "triangles": self.triangles.len(),
            "centre": centre,
            "radius": radius,
            "params": PARAMS,
            "ranges": ranges,
            "std_ranges": std_ranges,
            "flags": flag_names,
            "flag_bits": bits,
            "flag_counts": flag_counts,
            "unflagged": unflagged,
            "invalid_bit": STATUS_INVALID.trailing_zeros(),
            "withheld_bit": STATUS_WITHHELD.trailing_zeros(),
            "eta_withheld_bit": STATUS_ETA_WITHHELD.trailing_zeros(),
        })
    }
}

/// Centre of the bounding box and the largest distance from it (finite vertices only).
fn bounding_sphere(vertices: &[FitVertex]) -> ([f32; 3], f32) {
    let finite = || {
        vertices
            .iter()
            .filter(|v| v.position.iter().all(|x| x.is_finite()))
    };
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for v in finite() {
        for ((l, h), x) in lo.iter_mut().zip(hi.iter_mut()).zip(v.position) {
            *l = l.min(x);
            *h = h.max(x);
        }
    }
    if !lo[0].is_finite() {
        return ([0.0; 3], 1.0);
    }
    let c = [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k]));
    let r = finite()
        .map(|v| {
            (0..3)
                .map(|k| (v.position[k] - c[k]).powi(2))
                .sum::<f32>()
                .sqrt()
        })
        .fold(0f32, f32::max);
    (c, r.max(1e-6))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wild_values_are_clamped_and_marked_invalid() {
        let good = [1.5, 0.1, 0.3, 1.0, 0.1, 0.1, 0.1, 0.5, 0.4, 0.3];
        assert_eq!(sanitise(&good), (good, true));
        for (k, bad) in [
            (0, f32::NAN),
            (0, 0.2),
            (0, 1e9),
            (1, -1.0),
            (2, 7.0),
            (3, -0.5),
            (9, f32::INFINITY),
        ] {
            let mut p = good;
            p[k] = bad;
            let (c, ok) = sanitise(&p);
            assert!(!ok, "param {k} = {bad} must be invalid");
            assert!(c.iter().all(|v| v.is_finite()));
            assert!((1.0..=4.0).contains(&c[0]) && c[1] <= c[2] && c[2] <= 1.0);
        }
        let mut order = good;
        order[1] = 0.5;
        assert!(!sanitise(&order).1, "σs > σss is outside the domain");
    }
}
