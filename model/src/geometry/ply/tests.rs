//! The PLY reader's tests: round trips, other writers' files, malformed input, and
//! corrupted bytes (property tests).

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

/// `fit.ply`'s `material` is a region alias: −1 (no material) at one vertex leaves the mesh
/// without regions (ids are needed at every vertex), every vertex with one gives them; other
/// negatives are still refused.
#[test]
fn minus_one_region_means_no_regions() {
    let file = |ids: [&str; 3]| {
        format!(
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
             property float z\nproperty int material\nelement face 1\n\
             property list uchar int vertex_indices\nend_header\n\
             0 0 0 {}\n1 0 0 {}\n0 1 0 {}\n3 0 1 2\n",
            ids[0], ids[1], ids[2]
        )
    };
    let all = parse_ply(file(["0", "2", "1"]).as_bytes()).expect("parses");
    assert_eq!(all.regions(), Some(&[0, 2, 1][..]));
    let some = parse_ply(file(["0", "-1", "1"]).as_bytes()).expect("parses");
    assert_eq!(some.regions(), None);
    assert_eq!(some.triangles(), vec![[0, 1, 2]]);
    let e = parse_ply(file(["0", "-2", "1"]).as_bytes()).unwrap_err();
    assert!(e.to_string().contains("region id -2"), "{e}");
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
