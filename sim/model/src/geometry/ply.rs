//! PLY reading (ascii, binary little- and big-endian) and writing (ascii, binary little-endian):
//! ellipso's one PLY module. Its schemas: the mesh (`x y z [nx ny nz] [region]` + faces; read by
//! [`parse_ply`], written by [`write_ply`]) here, and the fit's `fit.ply` and the Mitsuba split
//! mesh in `ellipso-fit`, which write through [`write_table`] and read through
//! [`read_vertex_table`]. The writer's contract is in [`write`].
//!
//! Read contract: the `vertex` element must have `x y z`; `nx ny nz` are used when all three are
//! present; the first of the properties `region`, `region_id`, `material`, `material_index`,
//! `material_id` becomes the per-vertex region id (a non-negative integer). The `face` element's
//! list property `vertex_indices` (or `vertex_index`) gives polygons, fan-triangulated. Any other
//! elements and properties are parsed and skipped. Truncated or malformed data gives
//! [`MeshError::Ply`] naming the element, row and property.

use super::{MeshError, TriangleMesh};
use nalgebra::{Point3, Vector3};

pub mod write;

pub use write::{PlyColumn, PlyFormat, PlyScalar, write_ply, write_table};

/// Names accepted for the per-vertex region id property, in priority order.
pub const REGION_PROPERTY_NAMES: [&str; 5] = [
    "region",
    "region_id",
    "material",
    "material_index",
    "material_id",
];

#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }
}

#[derive(Debug)]
struct Property {
    name: String,
    /// `Some(count type)` for list properties.
    list_count: Option<Scalar>,
    value: Scalar,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Encoding {
    Ascii,
    Binary { little_endian: bool },
}

/// Reads values sequentially from the PLY body.
struct Body<'a> {
    bytes: &'a [u8],
    pos: usize,
    encoding: Encoding,
}

impl Body<'_> {
    fn next_token(&mut self) -> Option<&str> {
        while self.pos < self.bytes.len() && self.bytes[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        let start = self.pos;
        while self.pos < self.bytes.len() && !self.bytes[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        (self.pos > start).then(|| std::str::from_utf8(&self.bytes[start..self.pos]).ok())?
    }

    fn read(&mut self, ty: Scalar) -> Option<f64> {
        match self.encoding {
            Encoding::Ascii => {
                // Integers are exact in f64 up to 2^53, far beyond any PLY integer type.
                let _ = ty;
                self.next_token()?.parse::<f64>().ok()
            }
            Encoding::Binary { little_endian } => {
                let n = ty.size();
                let raw = self.bytes.get(self.pos..self.pos + n)?;
                self.pos += n;
                let mut buf = [0u8; 8];
                buf[..n].copy_from_slice(raw);
                if !little_endian {
                    buf[..n].reverse();
                }
                Some(match ty {
                    Scalar::I8 => buf[0] as i8 as f64,
                    Scalar::U8 => buf[0] as f64,
                    Scalar::I16 => i16::from_le_bytes([buf[0], buf[1]]) as f64,
                    Scalar::U16 => u16::from_le_bytes([buf[0], buf[1]]) as f64,
                    Scalar::I32 => i32::from_le_bytes([buf[0], buf[1], buf[2], buf[3]]) as f64,
                    Scalar::U32 => u32::from_le_bytes([buf[0], buf[1], buf[2], buf[3]]) as f64,
                    Scalar::F32 => f32::from_le_bytes([buf[0], buf[1], buf[2], buf[3]]) as f64,
                    Scalar::F64 => f64::from_le_bytes(buf),
                })
            }
        }
    }
}

fn err(msg: impl Into<String>) -> MeshError {
    MeshError::Ply(msg.into())
}

/// Parses the header; returns the encoding, the elements and the body offset.
fn parse_header(bytes: &[u8]) -> Result<(Encoding, Vec<Element>, usize), MeshError> {
    const END: &[u8] = b"end_header";
    let end = bytes
        .windows(END.len())
        .position(|w| w == END)
        .ok_or_else(|| err("no `end_header` line (not a PLY file or truncated header)"))?;
    let mut body = end + END.len();
    if bytes.get(body) == Some(&b'\r') {
        body += 1;
    }
    if bytes.get(body) == Some(&b'\n') {
        body += 1;
    }
    let header = std::str::from_utf8(&bytes[..end]).map_err(|_| err("header is not UTF-8"))?;
    let mut lines = header.lines().map(str::trim);
    if lines.next() != Some("ply") {
        return Err(err("file does not start with `ply`"));
    }
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    for (i, line) in lines.enumerate() {
        let lineno = i + 2;
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            [] | ["comment", ..] | ["obj_info", ..] => {}
            ["format", fmt, _version] => {
                encoding = Some(match *fmt {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::Binary {
                        little_endian: true,
                    },
                    "binary_big_endian" => Encoding::Binary {
                        little_endian: false,
                    },
                    other => {
                        return Err(err(format!(
                            "header line {lineno}: unknown format `{other}`"
                        )));
                    }
                });
            }
            ["element", name, count] => {
                let count = count.parse().map_err(|_| {
                    err(format!(
                        "header line {lineno}: element count `{count}` is not a number"
                    ))
                })?;
                elements.push(Element {
                    name: (*name).into(),
                    count,
                    properties: Vec::new(),
                });
            }
            ["property", "list", count_ty, value_ty, name] => {
                let el = elements.last_mut().ok_or_else(|| {
                    err(format!("header line {lineno}: property before any element"))
                })?;
                let bad = |t: &str| err(format!("header line {lineno}: unknown type `{t}`"));
                el.properties.push(Property {
                    name: (*name).into(),
                    list_count: Some(Scalar::parse(count_ty).ok_or_else(|| bad(count_ty))?),
                    value: Scalar::parse(value_ty).ok_or_else(|| bad(value_ty))?,
                });
            }
            ["property", ty, name] => {
                let el = elements.last_mut().ok_or_else(|| {
                    err(format!("header line {lineno}: property before any element"))
                })?;
                el.properties.push(Property {
                    name: (*name).into(),
                    list_count: None,
                    value: Scalar::parse(ty)
                        .ok_or_else(|| err(format!("header line {lineno}: unknown type `{ty}`")))?,
                });
            }
            _ => return Err(err(format!("header line {lineno}: cannot parse `{line}`"))),
        }
    }
    let encoding = encoding.ok_or_else(|| err("header has no `format` line"))?;
    Ok((encoding, elements, body))
}

/// Parses a PLY file into a mesh.
pub fn parse_ply(bytes: &[u8]) -> Result<TriangleMesh, MeshError> {
    let (encoding, elements, start) = parse_header(bytes)?;
    let mut body = Body {
        bytes: &bytes[start..],
        pos: 0,
        encoding,
    };
    let mut positions = Vec::new();
    let mut normals: Option<Vec<Vector3<f64>>> = None;
    let mut regions: Option<Vec<u32>> = None;
    let mut triangles = Vec::new();
    let mut saw_vertex = false;
    let mut saw_face = false;
    // A row needs at least one byte: cap preallocation by the body size against hostile counts.
    let cap = |n: usize| n.min(bytes.len());
    for el in &elements {
        let col = |name: &str| el.properties.iter().position(|p| p.name == name);
        let (vx, vy, vz) = (col("x"), col("y"), col("z"));
        let normal_cols = match (col("nx"), col("ny"), col("nz")) {
            (Some(a), Some(b), Some(c)) => Some([a, b, c]),
            _ => None,
        };
        let region_col = REGION_PROPERTY_NAMES.iter().find_map(|n| col(n));
        let face_col = col("vertex_indices").or_else(|| col("vertex_index"));
        let is_vertex = el.name == "vertex";
        let is_face = el.name == "face";
        if is_vertex {
            saw_vertex = true;
            if vx.is_none() || vy.is_none() || vz.is_none() {
                return Err(err("element `vertex` lacks one of the properties x, y, z"));
            }
            positions.reserve(cap(el.count));
            if normal_cols.is_some() {
                normals = Some(Vec::with_capacity(cap(el.count)));
            }
            if region_col.is_some() {
                regions = Some(Vec::with_capacity(cap(el.count)));
            }
        }
        if is_face {
            saw_face = true;
            if face_col.is_none() {
                return Err(err("element `face` lacks the list property vertex_indices"));
            }
        }
        // An element without properties occupies no bytes: skip it whatever its claimed count
        // (a hostile count must not spin the row loop).
        if el.properties.is_empty() {
            continue;
        }
        let mut scalars = vec![0.0; el.properties.len()];
        let mut list: Vec<f64> = Vec::new();
        for row in 0..el.count {
            for (k, p) in el.properties.iter().enumerate() {
                let missing = || {
                    err(format!(
                        "element `{}` row {row} property `{}`: missing or malformed value",
                        el.name, p.name
                    ))
                };
                match p.list_count {
                    None => scalars[k] = body.read(p.value).ok_or_else(missing)?,
                    Some(count_ty) => {
                        let n = body.read(count_ty).ok_or_else(missing)?;
                        if n.is_nan() || n < 0.0 {
                            return Err(missing());
                        }
                        let values: Result<Vec<f64>, _> = (0..n as usize)
                            .map(|_| body.read(p.value).ok_or_else(missing))
                            .collect();
                        if Some(k) == face_col {
                            list = values?;
                        } else {
                            values?;
                        }
                    }
                }
            }
            if is_vertex {
                let (x, y, z) = (vx.unwrap_or(0), vy.unwrap_or(0), vz.unwrap_or(0));
                positions.push(Point3::new(scalars[x], scalars[y], scalars[z]));
                if let (Some(n), Some([a, b, c])) = (normals.as_mut(), normal_cols) {
                    n.push(Vector3::new(scalars[a], scalars[b], scalars[c]));
                }
                if let (Some(r), Some(c)) = (regions.as_mut(), region_col) {
                    let v = scalars[c];
                    if !(v >= 0.0 && v.fract() == 0.0 && v <= u32::MAX as f64) {
                        return Err(err(format!(
                            "vertex {row}: region id {v} is not a non-negative integer"
                        )));
                    }
                    r.push(v as u32);
                }
            } else if is_face {
                if list.len() < 3 {
                    return Err(err(format!(
                        "face {row} has {} vertices (need ≥ 3)",
                        list.len()
                    )));
                }
                if list.iter().any(|&v| !(v >= 0.0 && v <= u32::MAX as f64)) {
                    return Err(err(format!(
                        "face {row} has a negative or huge vertex index"
                    )));
                }
                for i in 1..list.len() - 1 {
                    triangles.push([list[0] as u32, list[i] as u32, list[i + 1] as u32]);
                }
            }
        }
    }
    if !saw_vertex || !saw_face {
        return Err(err("file needs both a `vertex` and a `face` element"));
    }
    TriangleMesh::new(positions, normals, regions, triangles)
}

/// The scalar properties of a PLY file's `vertex` element, by name, as f64 (integers exact).
#[derive(Clone, Debug, PartialEq)]
pub struct VertexTable {
    /// Property names in file order (list properties are left out).
    pub names: Vec<String>,
    /// The scalar type of each property as read (`f32`, `f64`, `i32`, `u32`, `u8`, …).
    pub types: Vec<String>,
    /// Row-major values: `rows[v][k]` is property `names[k]` of vertex `v`.
    pub rows: Vec<Vec<f64>>,
}

impl VertexTable {
    /// The column of property `name`, if the file has it.
    pub fn column(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }
}

/// Reads every scalar property of the `vertex` element (any encoding), for files whose
/// per-vertex properties carry more than geometry (the fit's `fit.ply`). Errors as
/// [`parse_ply`].
pub fn read_vertex_table(bytes: &[u8]) -> Result<VertexTable, MeshError> {
    let (encoding, elements, start) = parse_header(bytes)?;
    let mut body = Body {
        bytes: &bytes[start..],
        pos: 0,
        encoding,
    };
    for el in &elements {
        let is_vertex = el.name == "vertex";
        let mut rows = Vec::new();
        if el.properties.is_empty() {
            continue;
        }
        for row in 0..el.count {
            let mut values = Vec::new();
            for p in &el.properties {
                let missing = || {
                    err(format!(
                        "element `{}` row {row} property `{}`: missing or malformed value",
                        el.name, p.name
                    ))
                };
                match p.list_count {
                    None => values.push(body.read(p.value).ok_or_else(missing)?),
                    Some(count_ty) => {
                        let n = body.read(count_ty).ok_or_else(missing)?;
                        if n.is_nan() || n < 0.0 {
                            return Err(missing());
                        }
                        for _ in 0..n as usize {
                            body.read(p.value).ok_or_else(missing)?;
                        }
                    }
                }
            }
            if is_vertex {
                rows.push(values);
            }
        }
        if is_vertex {
            let scalar = |p: &&Property| p.list_count.is_none();
            return Ok(VertexTable {
                names: el
                    .properties
                    .iter()
                    .filter(scalar)
                    .map(|p| p.name.clone())
                    .collect(),
                types: el
                    .properties
                    .iter()
                    .filter(scalar)
                    .map(|p| format!("{:?}", p.value).to_lowercase())
                    .collect(),
                rows,
            });
        }
    }
    Err(err("file has no `vertex` element"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::procedural::bumpy_icosphere;

    fn assert_same(a: &TriangleMesh, b: &TriangleMesh, tol: f64) {
        assert_eq!(a.triangles(), b.triangles());
        assert_eq!(a.regions(), b.regions());
        for (p, q) in a.positions().iter().zip(b.positions()) {
            assert!((p - q).norm() <= tol, "{p} vs {q} tol {tol}");
        }
        for (p, q) in a.normals().iter().zip(b.normals()) {
            assert!((p.into_inner() - q.into_inner()).norm() <= tol * 10.0 + 1e-15);
        }
    }

    #[test]
    fn round_trips_ascii_and_binary() {
        let mesh = bumpy_icosphere(2, 0.1, 3, 5);
        for (fmt, double, tol) in [
            (PlyFormat::Ascii, true, 0.0),
            (PlyFormat::BinaryLittleEndian, true, 0.0),
            (PlyFormat::BinaryLittleEndian, false, 1e-6),
        ] {
            let back = parse_ply(&write_ply(&mesh, fmt, double)).expect("round trip parses");
            assert_same(&mesh, &back, tol);
        }
    }

    #[test]
    fn reads_quads_extra_elements_and_big_endian() {
        let text = "ply\nformat ascii 1.0\ncomment a quad\nelement vertex 4\nproperty float x\n\
            property float y\nproperty float z\nproperty uchar material_index\nproperty float u\n\
            element face 1\nproperty list uchar int vertex_index\nelement edge 1\n\
            property int v1\nproperty int v2\nend_header\n\
            0 0 0 0 0.1\n1 0 0 1 0.2\n1 1 0 1 0.3\n0 1 0 2 0.4\n4 0 1 2 3\n0 1\n";
        let m = parse_ply(text.as_bytes()).expect("parses");
        assert_eq!(m.triangles(), vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.regions(), Some(&[0, 1, 1, 2][..]));
        assert!(
            (m.normals()[0].z - 1.0).abs() < 1e-12,
            "computed normal is +z"
        );

        let mut be = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty double x\n\
            property double y\nproperty double z\nelement face 1\n\
            property list uchar uint vertex_indices\nend_header\n"
            .to_vec();
        for v in [0.0f64, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 3.0, 0.0] {
            be.extend_from_slice(&v.to_be_bytes());
        }
        be.push(3);
        for i in [0u32, 1, 2] {
            be.extend_from_slice(&i.to_be_bytes());
        }
        let m = parse_ply(&be).expect("big endian parses");
        assert_eq!(m.positions()[2], Point3::new(0.0, 3.0, 0.0));
    }

    #[test]
    fn malformed_files_name_the_problem() {
        let cases: [(&[u8], &str); 6] = [
            (b"obj\n", "end_header"),
            (
                b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n",
                "x, y, z",
            ),
            (
                b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
                  property float z\nelement face 0\nproperty list uchar int vertex_indices\n\
                  end_header\n0 0 0\n1 1\n",
                "row 1 property `z`",
            ),
            (b"ply\nformat ebcdic 1.0\nend_header\n", "unknown format"),
            (
                b"ply\nformat ascii 1.0\nelement junk 18446744073709551615\nend_header\n",
                "both a `vertex` and a `face`",
            ),
            (
                b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n\
                  property float y\nproperty float z\nelement face 1\n\
                  property list uchar int vertex_indices\nend_header\n\x00\x00",
                "row 0 property `x`",
            ),
        ];
        for (bytes, needle) in cases {
            let e = parse_ply(bytes).expect_err("must fail").to_string();
            assert!(e.contains(needle), "`{e}` should mention `{needle}`");
        }
    }
}

#[cfg(test)]
mod robustness {
    use super::*;
    use crate::geometry::procedural::bumpy_icosphere;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Corrupted or truncated PLY bytes give an error or a valid mesh, never a panic.
        #[test]
        fn corrupted_ply_never_panics(
            cut in 0usize..4000,
            flips in proptest::collection::vec((0usize..4000, any::<u8>()), 0..8),
            ascii in any::<bool>(),
        ) {
            let mesh = bumpy_icosphere(1, 0.05, 2, 1);
            let fmt = if ascii { PlyFormat::Ascii } else { PlyFormat::BinaryLittleEndian };
            let mut bytes = write_ply(&mesh, fmt, false);
            for (at, b) in flips {
                let n = bytes.len();
                bytes[at % n] = b;
            }
            bytes.truncate(cut.max(1).min(bytes.len()));
            if let Ok(m) = parse_ply(&bytes) {
                prop_assert!(m.triangles().iter().flatten().all(|&i| (i as usize) < m.positions().len()));
            }
        }

        /// Arbitrary text never panics the OBJ reader.
        #[test]
        fn arbitrary_obj_never_panics(text in "(v( -?[0-9]{1,2}(\\.[0-9])?){3}\n|vn 0 0 1\n|f( -?[0-9]{1,2}(/[0-9]?(/[0-9])?)?){2,5}\n|usemtl [ab]\n|# x\n){0,30}") {
            let _ = crate::geometry::obj::parse_obj(text.as_bytes());
        }
    }
}
