//! PLY reading (ascii, binary little- and big-endian) and writing (ascii, binary little-endian):
//! ellipso's one PLY module. Its schemas: the mesh (`x y z [nx ny nz] [region]` + faces; read by
//! [`parse_ply`], written by [`write_ply`]) here, and the fit's `fit.ply` and the Mitsuba split
//! mesh in `ellipso-fit`, which write through [`write_table`] and read through
//! [`read_vertex_table`]. The writer's contract is in [`write`].
//!
//! Read contract: the `vertex` element must have `x y z`; `nx ny nz` are used when all three are
//! present; the first of the properties `region`, `region_id`, `material`, `material_index`,
//! `material_id` becomes the per-vertex region id (a non-negative integer; −1, the fit's
//! "no material" in `fit.ply`'s `material`, at any vertex leaves the whole mesh without region
//! ids, since a region id is needed at every vertex or none). The `face` element's
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

/// What a reader does with the body's elements ([`walk`]).
trait Visit {
    /// Called at the start of each element (before its rows); an error ends the walk.
    fn start(&mut self, el: &Element) -> Result<(), MeshError>;
    /// One row: `scalars[k]` is scalar property `k` (list positions hold 0) and `indices` the
    /// values of the row's `vertex_indices` (or `vertex_index`) list, empty without one.
    fn row(
        &mut self,
        el: &Element,
        row: usize,
        scalars: &[f64],
        indices: &[f64],
    ) -> Result<(), MeshError>;
    /// Whether the walk ends after this element's rows.
    fn done_after(&mut self, _el: &Element) -> bool {
        false
    }
}

/// The one body reader under both schemas: parses the header, then reads every element's rows
/// in order (any encoding), handing them to `visit`. Truncated or malformed values are
/// [`MeshError::Ply`] naming the element, row and property; elements without properties take
/// no bytes and are skipped whatever their claimed count (a hostile count must not spin the
/// row loop).
fn walk(bytes: &[u8], visit: &mut impl Visit) -> Result<(), MeshError> {
    let (encoding, elements, start) = parse_header(bytes)?;
    let mut body = Body {
        bytes: &bytes[start..],
        pos: 0,
        encoding,
    };
    for el in &elements {
        visit.start(el)?;
        if el.properties.is_empty() {
            continue;
        }
        let index_col = el
            .properties
            .iter()
            .position(|p| p.name == "vertex_indices")
            .or_else(|| el.properties.iter().position(|p| p.name == "vertex_index"));
        let mut scalars = vec![0.0; el.properties.len()];
        let mut indices: Vec<f64> = Vec::new();
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
                        if Some(k) == index_col {
                            indices = values?;
                        } else {
                            values?;
                        }
                    }
                }
            }
            visit.row(el, row, &scalars, &indices)?;
        }
        if visit.done_after(el) {
            return Ok(());
        }
    }
    Ok(())
}

/// The mesh schema's reader state ([`parse_ply`]).
#[derive(Default)]
struct MeshReader {
    /// Columns of the current element: x y z, the normal's, the region's.
    xyz: [usize; 3],
    normal_cols: Option<[usize; 3]>,
    region_col: Option<usize>,
    positions: Vec<Point3<f64>>,
    normals: Option<Vec<Vector3<f64>>>,
    regions: Option<Vec<u32>>,
    /// A vertex had region id −1 (none): the mesh has no region ids.
    region_missing: bool,
    triangles: Vec<[u32; 3]>,
    saw_vertex: bool,
    saw_face: bool,
    /// The body's size: a row needs at least one byte, so preallocation is capped by it
    /// against hostile counts.
    body_len: usize,
}

impl Visit for MeshReader {
    fn start(&mut self, el: &Element) -> Result<(), MeshError> {
        let col = |name: &str| el.properties.iter().position(|p| p.name == name);
        let cap = el.count.min(self.body_len);
        match el.name.as_str() {
            "vertex" => {
                self.saw_vertex = true;
                let (Some(x), Some(y), Some(z)) = (col("x"), col("y"), col("z")) else {
                    return Err(err("element `vertex` lacks one of the properties x, y, z"));
                };
                self.xyz = [x, y, z];
                self.normal_cols = match (col("nx"), col("ny"), col("nz")) {
                    (Some(a), Some(b), Some(c)) => Some([a, b, c]),
                    _ => None,
                };
                self.region_col = REGION_PROPERTY_NAMES.iter().find_map(|n| col(n));
                self.positions.reserve(cap);
                if self.normal_cols.is_some() {
                    self.normals = Some(Vec::with_capacity(cap));
                }
                if self.region_col.is_some() {
                    self.regions = Some(Vec::with_capacity(cap));
                }
            }
            "face" => {
                self.saw_face = true;
                if col("vertex_indices")
                    .or_else(|| col("vertex_index"))
                    .is_none()
                {
                    return Err(err("element `face` lacks the list property vertex_indices"));
                }
            }
            _ => {}
        }
        Ok(())
    }

    fn row(
        &mut self,
        el: &Element,
        row: usize,
        scalars: &[f64],
        list: &[f64],
    ) -> Result<(), MeshError> {
        match el.name.as_str() {
            "vertex" => {
                let [x, y, z] = self.xyz;
                self.positions
                    .push(Point3::new(scalars[x], scalars[y], scalars[z]));
                if let (Some(n), Some([a, b, c])) = (self.normals.as_mut(), self.normal_cols) {
                    n.push(Vector3::new(scalars[a], scalars[b], scalars[c]));
                }
                if let (Some(r), Some(c)) = (self.regions.as_mut(), self.region_col) {
                    let v = scalars[c];
                    if v == -1.0 {
                        self.region_missing = true;
                        r.push(0);
                    } else if !(v >= 0.0 && v.fract() == 0.0 && v <= u32::MAX as f64) {
                        return Err(err(format!(
                            "vertex {row}: region id {v} is not a non-negative integer"
                        )));
                    } else {
                        r.push(v as u32);
                    }
                }
            }
            "face" => {
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
                    self.triangles
                        .push([list[0] as u32, list[i] as u32, list[i + 1] as u32]);
                }
            }
            _ => {}
        }
        Ok(())
    }
}

/// Parses a PLY file into a mesh (the mesh schema, module doc).
pub fn parse_ply(bytes: &[u8]) -> Result<TriangleMesh, MeshError> {
    let mut reader = MeshReader {
        body_len: bytes.len(),
        ..MeshReader::default()
    };
    walk(bytes, &mut reader)?;
    if !reader.saw_vertex || !reader.saw_face {
        return Err(err("file needs both a `vertex` and a `face` element"));
    }
    TriangleMesh::new(
        reader.positions,
        reader.normals,
        reader.regions.filter(|_| !reader.region_missing),
        reader.triangles,
    )
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

/// The vertex table's reader state ([`read_vertex_table`]): the first `vertex` element with
/// properties, once it starts.
impl Visit for Option<VertexTable> {
    fn start(&mut self, el: &Element) -> Result<(), MeshError> {
        if el.name == "vertex" && !el.properties.is_empty() {
            let scalar = |p: &&Property| p.list_count.is_none();
            *self = Some(VertexTable {
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
                rows: Vec::new(),
            });
        }
        Ok(())
    }

    fn row(
        &mut self,
        el: &Element,
        _row: usize,
        scalars: &[f64],
        _list: &[f64],
    ) -> Result<(), MeshError> {
        let Some(table) = self.as_mut().filter(|_| el.name == "vertex") else {
            return Ok(());
        };
        table.rows.push(
            el.properties
                .iter()
                .zip(scalars)
                .filter(|(p, _)| p.list_count.is_none())
                .map(|(_, &v)| v)
                .collect(),
        );
        Ok(())
    }

    fn done_after(&mut self, el: &Element) -> bool {
        el.name == "vertex"
    }
}

/// Reads every scalar property of the `vertex` element (any encoding), for files whose
/// per-vertex properties carry more than geometry (the fit's `fit.ply`); the elements after it
/// are not read. Errors as [`parse_ply`].
pub fn read_vertex_table(bytes: &[u8]) -> Result<VertexTable, MeshError> {
    let mut table: Option<VertexTable> = None;
    walk(bytes, &mut table)?;
    table.ok_or_else(|| err("file has no `vertex` element"))
}

#[cfg(test)]
mod tests;
