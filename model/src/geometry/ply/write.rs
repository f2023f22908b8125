//! The one PLY writer: a vertex table of named, typed scalar properties and triangle faces.
//! Every PLY ellipso writes goes through [`write_table`] with its own schema — the mesh's
//! ([`write_ply`]: `x y z nx ny nz [region]`), the fit's `fit.ply` (`ellipso_fit::export::ply`)
//! and the Mitsuba export's split mesh (`ellipso_fit::export::mitsuba::atlas`).
//!
//! Contract of [`write_table`]:
//! - Header: `ply`, `format {ascii|binary_little_endian} 1.0`, one `comment` line, `element
//!   vertex N`, one `property {type} {name}` line per column in order, `element face M`,
//!   `property list uchar int vertex_indices`, `end_header`, each line ended by `\n`.
//! - Binary little-endian body: per vertex the columns' values converted to their type
//!   ([`PlyScalar::put`]: `float` rounds to f32, `int` and `uint` truncate toward zero
//!   (saturating), `uchar` clamps to [0, 255] first), then per face the count byte 3 and three
//!   `int` indices.
//! - ASCII body (kept byte-for-byte as the mesh writer has always written it): a `float` or
//!   `double` value is written as the f64's shortest round-trip decimal (Rust `Display`)
//!   followed by one space; an integer value as its decimal digits, followed by a space unless
//!   it is the row's last column; each vertex row ends with `\n`; faces as `3 a b c\n`.
//!
//! Not a crate dependency: `ply-rs` writes through its own dynamic property maps, and the exact
//! bytes of the files already written (the demo's `fit.ply`, the meshes) are part of the
//! contract (byte-identity tests in `tests.rs`).

use std::fmt::Write as _;

use super::super::TriangleMesh;

/// PLY body encodings this module writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlyFormat {
    /// Human-readable text.
    Ascii,
    /// Binary little-endian.
    BinaryLittleEndian,
}

/// The scalar types written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlyScalar {
    /// `float` (f32).
    Float,
    /// `double` (f64).
    Double,
    /// `int` (i32; Open3D drops unsigned properties).
    Int,
    /// `uint` (u32).
    Uint,
    /// `uchar` (u8).
    Uchar,
}

impl PlyScalar {
    /// The type's name in a PLY header.
    pub fn name(self) -> &'static str {
        match self {
            Self::Float => "float",
            Self::Double => "double",
            Self::Int => "int",
            Self::Uint => "uint",
            Self::Uchar => "uchar",
        }
    }

    /// Appends `v` as this type, binary little-endian (module contract).
    pub fn put(self, v: f64, out: &mut Vec<u8>) {
        match self {
            Self::Float => out.extend((v as f32).to_le_bytes()),
            Self::Double => out.extend(v.to_le_bytes()),
            Self::Int => out.extend((v as i32).to_le_bytes()),
            Self::Uint => out.extend((v as u32).to_le_bytes()),
            Self::Uchar => out.push(v.clamp(0.0, 255.0) as u8),
        }
    }

    /// Appends `v` as this type in ASCII (module contract); `last` = the row's last column.
    fn put_ascii(self, v: f64, last: bool, out: &mut Vec<u8>) {
        let text = match self {
            Self::Float | Self::Double => format!("{v} "),
            Self::Int => (v as i32).to_string(),
            Self::Uint => (v as u32).to_string(),
            Self::Uchar => (v.clamp(0.0, 255.0) as u8).to_string(),
        };
        out.extend_from_slice(text.as_bytes());
        if !last && !matches!(self, Self::Float | Self::Double) {
            out.push(b' ');
        }
    }
}

/// One vertex column: its name and type.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlyColumn {
    /// Property name in the header.
    pub name: String,
    /// Its type.
    pub ty: PlyScalar,
}

impl PlyColumn {
    /// A column `name` of type `ty`.
    pub fn new(name: impl Into<String>, ty: PlyScalar) -> Self {
        Self {
            name: name.into(),
            ty,
        }
    }
}

/// A PLY file of `vertices` rows over `columns` and the triangles `faces` (module contract).
/// `row(v, values)` fills `values` (one per column, cleared and sized for it) for vertex `v`.
pub fn write_table(
    format: PlyFormat,
    comment: &str,
    columns: &[PlyColumn],
    vertices: usize,
    mut row: impl FnMut(usize, &mut [f64]),
    faces: &[[u32; 3]],
) -> Vec<u8> {
    let mut h = String::from("ply\n");
    let _ = writeln!(
        h,
        "format {} 1.0",
        match format {
            PlyFormat::Ascii => "ascii",
            PlyFormat::BinaryLittleEndian => "binary_little_endian",
        }
    );
    let _ = writeln!(h, "comment {comment}");
    let _ = writeln!(h, "element vertex {vertices}");
    for c in columns {
        let _ = writeln!(h, "property {} {}", c.ty.name(), c.name);
    }
    let _ = writeln!(h, "element face {}", faces.len());
    h.push_str("property list uchar int vertex_indices\nend_header\n");
    let mut out = h.into_bytes();
    let mut values = vec![0.0; columns.len()];
    for v in 0..vertices {
        values.fill(0.0);
        row(v, &mut values);
        for (k, (c, &x)) in columns.iter().zip(&values).enumerate() {
            match format {
                PlyFormat::Ascii => c.ty.put_ascii(x, k + 1 == columns.len(), &mut out),
                PlyFormat::BinaryLittleEndian => c.ty.put(x, &mut out),
            }
        }
        if format == PlyFormat::Ascii {
            out.push(b'\n');
        }
    }
    for t in faces {
        match format {
            PlyFormat::Ascii => {
                out.extend_from_slice(format!("3 {} {} {}\n", t[0], t[1], t[2]).as_bytes());
            }
            PlyFormat::BinaryLittleEndian => {
                out.push(3);
                for &i in t {
                    out.extend_from_slice(&(i as i32).to_le_bytes());
                }
            }
        }
    }
    out
}

/// The mesh schema: `x y z nx ny nz` as `float` (`f32`) or `double`, the region id as `uint
/// region` when present, faces as `uchar`-counted `int` lists ([`super::parse_ply`] reads it
/// back).
pub fn write_ply(mesh: &TriangleMesh, format: PlyFormat, double: bool) -> Vec<u8> {
    let ty = if double {
        PlyScalar::Double
    } else {
        PlyScalar::Float
    };
    let mut columns: Vec<PlyColumn> = ["x", "y", "z", "nx", "ny", "nz"]
        .into_iter()
        .map(|n| PlyColumn::new(n, ty))
        .collect();
    let regions = mesh.regions();
    if regions.is_some() {
        columns.push(PlyColumn::new("region", PlyScalar::Uint));
    }
    let (positions, normals) = (mesh.positions(), mesh.normals());
    write_table(
        format,
        "written by ellipso-sim",
        &columns,
        positions.len(),
        |v, row| {
            for k in 0..3 {
                row[k] = positions[v][k];
                row[3 + k] = normals[v][k];
            }
            if let Some(r) = regions {
                row[6] = f64::from(r[v]);
            }
        },
        mesh.triangles(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::ply::{parse_ply, read_vertex_table};
    use crate::geometry::procedural::icosphere;
    use nalgebra::Point3;

    /// The 12-vertex icosahedron, radii 50–61 mm, regions 0, 1, 2, 0, … when asked.
    fn fixture_mesh(regions: bool) -> TriangleMesh {
        let (dirs, faces) = icosphere(0);
        let positions = dirs
            .iter()
            .enumerate()
            .map(|(i, d)| Point3::from(d.into_inner() * (0.05 + 0.001 * i as f64)))
            .collect();
        let regions = regions.then(|| (0..dirs.len() as u32).map(|i| i % 3).collect());
        TriangleMesh::new(positions, None, regions, faces).unwrap()
    }

    /// The bytes the mesh writer wrote before it became a schema over [`write_table`]
    /// (captured from the previous writer, commit f22c554), for every format and option.
    #[test]
    fn mesh_bytes_are_those_the_previous_writer_wrote() {
        let cases: [(&[u8], PlyFormat, bool, bool); 5] = [
            (
                include_bytes!("testdata/mesh_ascii_float_regions.ply"),
                PlyFormat::Ascii,
                false,
                true,
            ),
            (
                include_bytes!("testdata/mesh_ascii_double.ply"),
                PlyFormat::Ascii,
                true,
                false,
            ),
            (
                include_bytes!("testdata/mesh_binary_float_regions.ply"),
                PlyFormat::BinaryLittleEndian,
                false,
                true,
            ),
            (
                include_bytes!("testdata/mesh_binary_double.ply"),
                PlyFormat::BinaryLittleEndian,
                true,
                false,
            ),
            (
                include_bytes!("testdata/mesh_binary_double_regions.ply"),
                PlyFormat::BinaryLittleEndian,
                true,
                true,
            ),
        ];
        for (want, format, double, regions) in cases {
            let mesh = fixture_mesh(regions);
            let got = write_ply(&mesh, format, double);
            assert!(got == want, "{format:?} double {double} regions {regions}");
            let back = parse_ply(&got).unwrap();
            assert_eq!(back.regions(), mesh.regions());
        }
    }

    #[test]
    fn a_table_writes_every_type_and_reads_back() {
        let columns = [
            PlyColumn::new("a", PlyScalar::Float),
            PlyColumn::new("b", PlyScalar::Double),
            PlyColumn::new("c", PlyScalar::Int),
            PlyColumn::new("d", PlyScalar::Uint),
            PlyColumn::new("e", PlyScalar::Uchar),
        ];
        let values = [
            [0.1, -2.5, -7.0, 9.0, 300.0],
            [1.0, 1e-300, 42.9, 0.0, -4.0],
        ];
        for format in [PlyFormat::Ascii, PlyFormat::BinaryLittleEndian] {
            let bytes = write_table(
                format,
                "test",
                &columns,
                2,
                |v, row| row.copy_from_slice(&values[v]),
                &[[0, 1, 1]],
            );
            let table = read_vertex_table(&bytes).unwrap();
            assert_eq!(table.names, ["a", "b", "c", "d", "e"]);
            assert!(
                (table.rows[0][0] - 0.1).abs() < 1e-7,
                "float within f32 rounding"
            );
            assert_eq!(table.rows[0][1..], [-2.5, -7.0, 9.0, 255.0]);
            assert_eq!(table.rows[1][1..], [1e-300, 42.0, 0.0, 0.0]);
        }
    }
}
