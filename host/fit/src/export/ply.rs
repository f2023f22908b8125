//! `fit.ply`: the fitted mesh with every per-vertex parameter, its standard error and flags.
//!
//! Contract: binary little-endian PLY 1.0 whose vertex properties are the table [`schema`] (one
//! entry per property: name, PLY type, value; adding a property is one line there):
//! `double x y z` (refined position, world, metres, exact), `float nx ny nz` (refined unit
//! normal), `float eta sigma_s sigma_ss rho_s rho_ss_r rho_ss_g rho_ss_b rho_d_r rho_d_g
//! rho_d_b`, their standard errors `float std_eta … std_rho_d_b` (same order; +inf where the
//! identifiability rule [`crate::data::Identifiable`] withholds the parameter),
//! `float eta_unpooled std_eta_unpooled` (the vertex's own η and standard error before its
//! material's pooled η entered — flag `EtaPooled` — and its final ones where none did),
//! `float normal_std_deg` (≤ 180°, [`crate::data::MAX_REPORTED_ANGLE_STD_DEG`]), `int samples`,
//! `int flags` (bit k set = [`FitFlag::ALL`]`[k]`, the output flags of
//! [`VertexFit::output_flags`]), `int material` (the vertex's material: the index of step B's
//! cluster, `fit-summary.json`'s `clusters`/`materials` order, that
//! [`crate::complete::Completion::labels`] gives it — its own cluster where the fit identified
//! it, the one it was completed from otherwise; [`NO_MATERIAL`] = −1 where it has none or the
//! fit ran without step B), `int seen_lit gated_mixed gated_grazing gated_saturated
//! gated_dark gated_colour_outlier gated_non_finite` (the frames that saw the vertex lit and
//! what each pixel gate removed of them, [`GATE_COLUMNS`]) and `uchar red green blue` (the diffuse albedo π·ρ_d, sRGB, grey
//! where the rule withholds the vertex), so Open3D, plyfile, trimesh and MeshLab read every
//! property and show the object in its colours. Faces: `uchar`-counted `int` lists, so
//! `fit.ply` also loads as a plain mesh. [`read_fit_ply`] reads back what [`write_fit_ply`]
//! wrote, by property name (older files with `float` positions and `uint` flags too, and without
//! `material`).
//!
//! This module is the fit's schema only: the bytes are written by the model's one PLY writer
//! (`ellipso_model::geometry::ply::write_table`) and read by its one reader
//! (`read_vertex_table`).

use std::path::Path;

use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::ply::{PlyColumn, PlyFormat, read_vertex_table, write_table};
use nalgebra::Point3;

use crate::data::{FitFlag, GateCounts, Identifiable, VertexFit};

/// Flag bit order of the `flags` property (every output's bitmask).
pub const FLAG_BITS: [FitFlag; FitFlag::ALL.len()] = FitFlag::ALL;

/// Parameter property names in `VertexFit::std_error` order.
pub const PARAMS: [&str; 10] = [
    "eta", "sigma_s", "sigma_ss", "rho_s", "rho_ss_r", "rho_ss_g", "rho_ss_b", "rho_d_r",
    "rho_d_g", "rho_d_b",
];

/// One count of a vertex's [`GateCounts`].
pub type GateCount = fn(&GateCounts) -> u64;

/// The per-vertex gate counts `fit.ply` carries: frames that saw the vertex lit
/// ([`GateCounts::seen_lit`]) and, of those, what each pixel gate removed.
pub const GATE_COLUMNS: [(&str, GateCount); 7] = [
    ("seen_lit", GateCounts::seen_lit),
    ("gated_mixed", |g| g.mixed),
    ("gated_grazing", |g| g.grazing),
    ("gated_saturated", |g| g.saturated),
    ("gated_dark", |g| g.dark),
    ("gated_colour_outlier", |g| g.colour_outlier),
    ("gated_non_finite", |g| g.non_finite),
];

/// The `material` value of a vertex without a material (module contract).
pub const NO_MATERIAL: i32 = -1;

/// Grey of the vertex colour where the rule withholds the vertex (the pictures' no-data grey).
const WITHHELD_GREY: u8 = ellipso_report::figure::NO_DATA[0];

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
    /// One material label per mesh vertex is required.
    #[error("{0} material labels for {1} mesh vertices")]
    MaterialCount(usize, usize),
    /// Not a file this module wrote.
    #[error("{path}: {what}")]
    Format {
        /// The file.
        path: String,
        /// What is wrong.
        what: String,
    },
}

/// The bitmask of `flags` ([`FitFlag::ALL`] order).
pub fn flag_mask(flags: &[FitFlag]) -> u32 {
    FitFlag::mask(flags)
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

/// The PLY scalar types `fit.ply` uses: the model's PLY module's.
pub use ellipso_model::geometry::ply::PlyScalar as PlyType;

/// What one vertex row is computed from.
pub struct Row<'a> {
    /// Refined position, world, metres.
    pub position: Point3<f64>,
    /// The vertex's fit.
    pub fit: &'a VertexFit,
    /// [`VertexFit::output_mask`].
    pub mask: u32,
    /// The rule applied to `mask`.
    pub identifiable: Identifiable,
    /// [`Identifiable::std_error`] of the fit's standard errors.
    pub std_error: [f64; 10],
    /// The vertex's material (cluster index), `None`: none.
    pub material: Option<usize>,
}

/// One vertex property: its name, type and value.
pub struct Property {
    /// Property name in the header.
    pub name: String,
    /// PLY type.
    pub ty: PlyType,
    /// The value of a row.
    pub value: Box<dyn Fn(&Row) -> f64>,
}

fn property(
    name: impl Into<String>,
    ty: PlyType,
    value: impl Fn(&Row) -> f64 + 'static,
) -> Property {
    Property {
        name: name.into(),
        ty,
        value: Box::new(value),
    }
}

/// The vertex properties of `fit.ply`, in file order (module contract).
pub fn schema() -> Vec<Property> {
    use PlyType::{Double, Float, Int, Uchar};
    let mut s = Vec::new();
    for (k, name) in ["x", "y", "z"].into_iter().enumerate() {
        s.push(property(name, Double, move |r| r.position[k]));
    }
    for (k, name) in ["nx", "ny", "nz"].into_iter().enumerate() {
        s.push(property(name, Float, move |r| r.fit.normal_world[k]));
    }
    for (k, name) in PARAMS.into_iter().enumerate() {
        s.push(property(name, Float, move |r| params_of(r.fit)[k]));
    }
    for (k, name) in PARAMS.into_iter().enumerate() {
        s.push(property(format!("std_{name}"), Float, move |r| {
            r.std_error[k]
        }));
    }
    // The vertex's own η before its material's pool entered (its final η where none did).
    s.push(property("eta_unpooled", Float, |r| {
        r.fit.eta_unpooled.map_or(r.fit.params.eta, |u| u[0])
    }));
    s.push(property("std_eta_unpooled", Float, |r| {
        match r.fit.eta_unpooled {
            _ if !r.identifiable.vertex => f64::INFINITY,
            Some(u) => u[1],
            None => r.std_error[0],
        }
    }));
    s.push(property("normal_std_deg", Float, |r| {
        r.fit.reported_normal_std_deg()
    }));
    s.push(property("samples", Int, |r| f64::from(r.fit.samples_used)));
    s.push(property("flags", Int, |r| f64::from(r.mask)));
    s.push(property("material", Int, |r| {
        r.material.map_or(f64::from(NO_MATERIAL), |m| m as f64)
    }));
    // What the gates removed of the frames that saw the vertex lit, per reason (module doc).
    for (name, count) in GATE_COLUMNS {
        s.push(property(name, Int, move |r| count(&r.fit.gates) as f64));
    }
    for (k, name) in ["red", "green", "blue"].into_iter().enumerate() {
        s.push(property(name, Uchar, move |r| {
            if r.identifiable.vertex {
                let albedo = std::f64::consts::PI * r.fit.params.rho_d[k];
                f64::from(ellipso_model::colour::srgb_u8(albedo))
            } else {
                f64::from(WITHHELD_GREY)
            }
        }));
    }
    s
}

/// Writes `mesh` (refined positions) with `fits` (one per vertex, in order) and each vertex's
/// material (`material`, one per vertex: [`crate::complete::Completion::labels`]; `None`: a fit
/// without materials, every vertex [`NO_MATERIAL`]) to `path`.
pub fn write_fit_ply(
    path: &Path,
    mesh: &TriangleMesh,
    fits: &[VertexFit],
    material: Option<&[Option<usize>]>,
) -> Result<(), PlyError> {
    let n = mesh.positions().len();
    if fits.len() != n {
        return Err(PlyError::Count(fits.len(), n));
    }
    if let Some(labels) = material
        && labels.len() != n
    {
        return Err(PlyError::MaterialCount(labels.len(), n));
    }
    let schema = schema();
    let columns: Vec<PlyColumn> = schema
        .iter()
        .map(|p| PlyColumn::new(p.name.clone(), p.ty))
        .collect();
    let bytes = write_table(
        PlyFormat::BinaryLittleEndian,
        "ellipso fit: per-vertex polarimetric SVBRDF",
        &columns,
        n,
        |v, values| {
            let f = &fits[v];
            let mask = f.output_mask();
            let identifiable = Identifiable::of_mask(mask);
            let row = Row {
                position: mesh.positions()[v],
                fit: f,
                mask,
                identifiable,
                std_error: identifiable.std_error(&f.std_error),
                material: material.and_then(|m| m[v]),
            };
            for (value, prop) in values.iter_mut().zip(&schema) {
                *value = (prop.value)(&row);
            }
        },
        mesh.triangles(),
    );
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
    /// The vertex's material (cluster index); `None` where it has none ([`NO_MATERIAL`]) or
    /// the file predates the `material` property.
    pub material: Option<u32>,
}

impl FitVertex {
    /// The identifiability rule applied to this vertex's flags.
    pub fn identifiable(&self) -> Identifiable {
        Identifiable::of_mask(self.flags)
    }
}

/// Reads the vertices of a `fit.ply` written by [`write_fit_ply`].
pub fn read_fit_ply(path: &Path) -> Result<Vec<FitVertex>, PlyError> {
    let err = |what: String| PlyError::Format {
        path: path.display().to_string(),
        what,
    };
    let bytes = ellipso_model::file_io::read_bounded(path, ellipso_model::file_io::caps::MESH)
        .map_err(|source| PlyError::Io {
            path: path.display().to_string(),
            source,
        })?;
    let table = read_vertex_table(&bytes).map_err(|e| err(e.to_string()))?;
    let col = |name: &str| {
        table.column(name).ok_or_else(|| {
            err(format!(
                "not an ellipso fit.ply (no vertex property `{name}`)"
            ))
        })
    };
    let cols = |names: &[&str]| names.iter().map(|n| col(n)).collect::<Result<Vec<_>, _>>();
    let position = cols(&["x", "y", "z"])?;
    let normal = cols(&["nx", "ny", "nz"])?;
    let params = cols(&PARAMS)?;
    let std_names: Vec<String> = PARAMS.iter().map(|p| format!("std_{p}")).collect();
    let std = cols(&std_names.iter().map(String::as_str).collect::<Vec<_>>())?;
    let normal_std = col("normal_std_deg")?;
    let samples = col("samples")?;
    let flags = col("flags")?;
    // absent from files written before the property existed: no material
    let material = table.column("material");
    Ok(table
        .rows
        .iter()
        .map(|r| {
            let f = |k: usize| r[k] as f32;
            FitVertex {
                position: std::array::from_fn(|i| f(position[i])),
                normal: std::array::from_fn(|i| f(normal[i])),
                params: std::array::from_fn(|i| f(params[i])),
                std_error: std::array::from_fn(|i| f(std[i])),
                normal_std_deg: f(normal_std),
                samples: r[samples].max(0.0) as u32,
                flags: r[flags].max(0.0) as u32,
                material: material
                    .map(|k| r[k])
                    .filter(|&m| m >= 0.0)
                    .map(|m| m as u32),
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

    fn fixture(subdivisions: u32) -> (TriangleMesh, Vec<VertexFit>) {
        let (dirs, faces) = icosphere(subdivisions);
        let pos: Vec<_> = dirs
            .iter()
            .map(|d| Point3::from(d.into_inner() * 0.05))
            .collect();
        let mesh = TriangleMesh::new(pos, None, None, faces).unwrap();
        let mut fits: Vec<VertexFit> = (0..mesh.positions().len())
            .map(|v| VertexFit {
                vertex: v as u32,
                params: PbrdfParams {
                    eta: 1.4 + 0.01 * v as f64,
                    sigma_s: 0.1,
                    sigma_ss: 0.3,
                    rho_s: 0.5,
                    rho_ss: [0.1, 0.2, 0.3],
                    rho_d: [0.4, 0.5 - 0.03 * v as f64, 0.06],
                },
                normal_world: mesh.normals()[v].into_inner().into(),
                std_error: [0.01; 10].map(|x| if v == 3 { f64::INFINITY } else { x }),
                normal_std_error_deg: 0.5,
                samples_used: 40 + v as u32,
                cost: 1.0,
                iterations: 5,
                flags: match v {
                    3 => vec![FitFlag::EtaUnidentifiable, FitFlag::AtBound],
                    4 => vec![FitFlag::AlbedoAtCap],
                    _ => vec![],
                },
                eta_unpooled: (v == 6).then_some([1.52, 0.04]),
                eta_prior_only: false,
                gates: Default::default(),
            })
            .collect();
        fits[5].normal_std_error_deg = 500.0;
        (mesh, fits)
    }

    /// The bytes of a small `fit.ply` as the fit's own writer wrote them before `fit.ply`
    /// became a schema over the model's PLY writer (captured at commit f22c554; re-captured
    /// when the per-vertex gate counts, [`GATE_COLUMNS`], were added before the colours, and
    /// when `material` was added after `flags`: the only change, checked below against the
    /// file before it).
    #[test]
    fn fit_ply_bytes_are_those_the_previous_writer_wrote() {
        let (mesh, fits) = fixture(0);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fit.ply");
        write_fit_ply(&path, &mesh, &fits, None).unwrap();
        let got = std::fs::read(&path).unwrap();
        assert!(
            got == include_bytes!("testdata/fit_small.ply"),
            "fit.ply bytes changed"
        );
        // the file before `material`: the same table with that one column fewer, and it still
        // reads (no material)
        let before: &[u8] = include_bytes!("testdata/fit_small_before_material.ply");
        let (now, then) = (
            read_vertex_table(&got).unwrap(),
            read_vertex_table(before).unwrap(),
        );
        let k = now.column("material").unwrap();
        assert!(then.column("material").is_none());
        for (a, b) in now.rows.iter().zip(&then.rows) {
            assert_eq!(a[k], f64::from(NO_MATERIAL));
            let without: Vec<f64> = a
                .iter()
                .enumerate()
                .filter(|(i, _)| *i != k)
                .map(|(_, v)| *v)
                .collect();
            assert_eq!(&without, b);
        }
        assert_eq!(now.rows.len(), then.rows.len());
        let old = dir.path().join("old.ply");
        std::fs::write(&old, before).unwrap();
        let back = read_fit_ply(&old).unwrap();
        assert!(back.iter().all(|v| v.material.is_none()));
        assert_eq!(back.len(), fits.len());
    }

    #[test]
    fn round_trip_and_loads_as_a_plain_mesh() {
        let (mesh, fits) = fixture(1);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fit.ply");
        // materials 0, 1, 2 in turn, none at every fifth vertex
        let labels: Vec<Option<usize>> = (0..fits.len())
            .map(|v| (v % 5 != 0).then_some(v % 3))
            .collect();
        write_fit_ply(&path, &mesh, &fits, Some(&labels)).unwrap();
        let back = read_fit_ply(&path).unwrap();
        assert_eq!(back.len(), fits.len());
        for ((b, f), label) in back.iter().zip(&fits).zip(&labels) {
            assert!((f64::from(b.params[0]) - f.params.eta).abs() < 1e-6);
            assert_eq!(b.samples, f.samples_used);
            assert_eq!(b.flags, f.output_mask());
            assert_eq!(b.material, label.map(|m| m as u32));
        }
        assert!(back[3].std_error[0].is_infinite());
        assert_eq!(back[3].flags, (1 << 4) | (1 << 6));
        // One rule: η withheld at vertex 3 only; every parameter at the capped vertex 4; the
        // normal's 500° reported as 180° and flagged.
        assert!(back[2].std_error.iter().all(|s| s.is_finite()));
        assert!(back[4].std_error.iter().all(|s| s.is_infinite()));
        assert!(!back[4].identifiable().vertex && back[0].identifiable().eta);
        assert_eq!(back[5].normal_std_deg, 180.0);
        assert_ne!(back[5].flags & FitFlag::NormalUnconstrained.bit(), 0);
        let bytes = std::fs::read(&path).unwrap();
        let header = String::from_utf8_lossy(&bytes[..bytes.len().min(2000)]).to_string();
        for want in [
            "property double x",
            "property int samples",
            "property int flags",
            "property int material",
            "property uchar red",
        ] {
            assert!(header.contains(want), "{want}");
        }
        let table = read_vertex_table(&bytes).unwrap();
        let red = table.column("red").unwrap();
        // π·ρd_r = π·0.4 > 1: full red; the withheld vertex is grey
        assert_eq!(table.rows[0][red], 255.0);
        assert_eq!(table.rows[4][red], f64::from(WITHHELD_GREY));
        let plain = parse_ply(&bytes).unwrap();
        assert_eq!(plain.triangles(), mesh.triangles());
        // a vertex without a material (−1): no region ids in the plain mesh (model's reader)
        assert_eq!(plain.regions(), None);
        // positions are exact (double): a fit on this mesh sees the same geometry
        assert_eq!(plain.positions()[5], mesh.positions()[5]);
        // Wrong count and unwritable paths are named.
        assert!(matches!(
            write_fit_ply(&path, &mesh, &fits[1..], None),
            Err(PlyError::Count(..))
        ));
        let e = write_fit_ply(&path, &mesh, &fits, Some(&labels[1..])).unwrap_err();
        assert!(matches!(e, PlyError::MaterialCount(..)), "{e}");
        assert!(e.to_string().contains("material labels"), "{e}");
        let bad = dir.path().join("missing").join("fit.ply");
        let e = write_fit_ply(&bad, &mesh, &fits, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing"), "{e}");
    }
}
