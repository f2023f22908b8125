//! Wavefront OBJ reading: `v`, `vn`, `f` (forms `v`, `v/vt`, `v//vn`, `v/vt/vn`, negative relative
//! indices), polygons fan-triangulated, and `usemtl` groups as named regions.
//!
//! Contract: OBJ indexes positions and normals separately; vertices are de-duplicated by the
//! (position, normal, region) triple, so a face's three vertices always carry that face's `usemtl`
//! region and explicit normals survive. If any face corner lacks a normal the mesh computes all
//! normals itself (mixing supplied and computed normals would shade inconsistently). Texture
//! coordinates are parsed for validity and dropped. Other statements (`o`, `g`, `s`, `mtllib`, `vt`
//! …) are ignored. Errors carry the 1-based line number.

use super::{MeshError, TriangleMesh};
use nalgebra::{Point3, Vector3};
use std::collections::HashMap;

fn parse_floats<const N: usize>(words: &[&str], line: usize) -> Result<[f64; N], MeshError> {
    if words.len() < N {
        return Err(MeshError::Obj {
            line,
            message: format!("expected {N} numbers"),
        });
    }
    let mut out = [0.0; N];
    for (o, w) in out.iter_mut().zip(words) {
        *o = w.parse().map_err(|_| MeshError::Obj {
            line,
            message: format!("`{w}` is not a number"),
        })?;
    }
    Ok(out)
}

/// Resolves a 1-based (or negative, relative) OBJ index against `len` items.
fn resolve(word: &str, len: usize, what: &str, line: usize) -> Result<usize, MeshError> {
    let i: i64 = word.parse().map_err(|_| MeshError::Obj {
        line,
        message: format!("{what} index `{word}` is not an integer"),
    })?;
    let idx = if i > 0 { i - 1 } else { len as i64 + i };
    if i == 0 || idx < 0 || idx >= len as i64 {
        return Err(MeshError::Obj {
            line,
            message: format!("{what} index {i} out of range (have {len})"),
        });
    }
    Ok(idx as usize)
}

/// Parses an OBJ file into a mesh.
pub fn parse_obj(bytes: &[u8]) -> Result<TriangleMesh, MeshError> {
    let text = std::str::from_utf8(bytes).map_err(|e| MeshError::Obj {
        line: 0,
        message: format!("not UTF-8: {e}"),
    })?;
    let mut v: Vec<Point3<f64>> = Vec::new();
    let mut vn: Vec<Vector3<f64>> = Vec::new();
    let mut vt_count = 0usize;
    let mut region_names: Vec<String> = Vec::new();
    let mut region: u32 = 0;
    let mut any_usemtl = false;
    let mut map: HashMap<(usize, Option<usize>, u32), u32> = HashMap::new();
    let mut positions = Vec::new();
    let mut normals: Vec<Option<Vector3<f64>>> = Vec::new();
    let mut regions = Vec::new();
    let mut triangles = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let content = raw.split('#').next().unwrap_or("");
        let words: Vec<&str> = content.split_whitespace().collect();
        let Some((&head, rest)) = words.split_first() else {
            continue;
        };
        match head {
            "v" => v.push(Point3::from(parse_floats::<3>(rest, line)?)),
            "vn" => vn.push(Vector3::from(parse_floats::<3>(rest, line)?)),
            "vt" => {
                parse_floats::<1>(rest, line)?;
                vt_count += 1;
            }
            "usemtl" => {
                let name = rest.join(" ");
                any_usemtl = true;
                region = match region_names.iter().position(|n| *n == name) {
                    Some(k) => k as u32,
                    None => {
                        region_names.push(name);
                        (region_names.len() - 1) as u32
                    }
                };
            }
            "f" => {
                if rest.len() < 3 {
                    return Err(MeshError::Obj {
                        line,
                        message: format!("face has {} corners (need ≥ 3)", rest.len()),
                    });
                }
                let mut corners = Vec::with_capacity(rest.len());
                for corner in rest {
                    let parts: Vec<&str> = corner.split('/').collect();
                    if parts.len() > 3 || parts[0].is_empty() {
                        return Err(MeshError::Obj {
                            line,
                            message: format!("malformed face corner `{corner}`"),
                        });
                    }
                    let pi = resolve(parts[0], v.len(), "vertex", line)?;
                    if let Some(t) = parts.get(1).filter(|t| !t.is_empty()) {
                        resolve(t, vt_count, "texture", line)?;
                    }
                    let ni = match parts.get(2).filter(|n| !n.is_empty()) {
                        Some(n) => Some(resolve(n, vn.len(), "normal", line)?),
                        None => None,
                    };
                    let key = (pi, ni, region);
                    let id = *map.entry(key).or_insert_with(|| {
                        positions.push(v[pi]);
                        normals.push(ni.map(|k| vn[k]));
                        regions.push(region);
                        (positions.len() - 1) as u32
                    });
                    corners.push(id);
                }
                for k in 1..corners.len() - 1 {
                    triangles.push([corners[0], corners[k], corners[k + 1]]);
                }
            }
            _ => {}
        }
    }
    let normals = normals.iter().copied().collect::<Option<Vec<_>>>();
    let regions = any_usemtl.then_some(regions);
    let mut mesh = TriangleMesh::new(positions, normals, regions, triangles)?;
    mesh.set_region_names(region_names);
    Ok(mesh)
}

/// Writes a mesh as Wavefront OBJ text: `v` (17 significant digits, so positions round-trip
/// exactly), `vn` per vertex and `f v//vn` per triangle; regions are not written.
pub fn write_obj(mesh: &TriangleMesh) -> Vec<u8> {
    use std::fmt::Write;
    let mut s = String::from("# ellipso mesh, metres\n");
    for p in mesh.positions() {
        let _ = writeln!(s, "v {:e} {:e} {:e}", p.x, p.y, p.z);
    }
    for n in mesh.normals() {
        let _ = writeln!(s, "vn {:e} {:e} {:e}", n.x, n.y, n.z);
    }
    for t in mesh.triangles() {
        let [a, b, c] = t.map(|i| i + 1);
        let _ = writeln!(s, "f {a}//{a} {b}//{b} {c}//{c}");
    }
    s.into_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn written_obj_reads_back_exactly() {
        let (dirs, faces) = crate::geometry::procedural::icosphere(1);
        let pos = dirs
            .iter()
            .map(|d| Point3::from(d.into_inner() * 0.04))
            .collect();
        let m = TriangleMesh::new(pos, None, None, faces).unwrap();
        let back = parse_obj(&write_obj(&m)).unwrap();
        // the reader numbers vertices in the order faces first use them: compare by position
        let corners = |m: &TriangleMesh| -> Vec<[Point3<f64>; 3]> {
            m.triangles()
                .iter()
                .map(|t| t.map(|i| m.positions()[i as usize]))
                .collect()
        };
        assert_eq!(corners(&back), corners(&m));
        assert_eq!(back.positions().len(), m.positions().len());
    }

    #[test]
    fn reads_all_face_forms_and_regions() {
        let text = "# cube corner\nmtllib x.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\n\
            vt 0 0\nvn 0 0 1\nvn 0 0 -1\nusemtl gold\nf 1//1 2//1 3//1\nf 1/1/1 3/1/1 4/1/1\n\
            usemtl glass\nf 1 2 5\nf -5 -3 -2 -1\nusemtl gold\nf 1/1 2/1 3/1\n";
        let m = parse_obj(text.as_bytes()).expect("parses");
        assert_eq!(
            m.region_names(),
            vec!["gold".to_string(), "glass".to_string()]
        );
        // 2 + 1 + 2 (quad) + 1 triangles.
        assert_eq!(m.triangles().len(), 6);
        let r = m.regions().expect("regions");
        for (f, region) in [(0, 0), (1, 0), (2, 1), (3, 1), (4, 1), (5, 0)] {
            let t = m.triangles()[f];
            assert!(t.iter().all(|&i| r[i as usize] == region), "face {f}");
        }
        // Vertex 1 is used by both regions, so it is duplicated.
        let at_origin = m
            .positions()
            .iter()
            .filter(|p| p.coords.norm() == 0.0)
            .count();
        assert!(at_origin >= 2);
    }

    #[test]
    fn explicit_normals_survive_when_every_corner_has_one() {
        let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0.6 0 0.8\nf 1//1 2//1 3//1\n";
        let m = parse_obj(text.as_bytes()).expect("parses");
        assert!((m.normals()[0].x - 0.6).abs() < 1e-12);
        assert!(m.regions().is_none());
    }

    #[test]
    fn errors_carry_line_numbers() {
        for (text, needle) in [
            (
                "v 0 0 0\nv 1 0 0\nf 1 2 3\n",
                "line 3: vertex index 3 out of range",
            ),
            ("v 0 0\n", "line 1: expected 3 numbers"),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n",
                "line 4: face has 2 corners",
            ),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//1 2 3\n",
                "line 4: normal index 1 out of range",
            ),
            ("v 0 x 0\n", "`x` is not a number"),
        ] {
            let e = parse_obj(text.as_bytes())
                .expect_err("must fail")
                .to_string();
            assert!(e.contains(needle), "`{e}` should contain `{needle}`");
        }
    }
}
