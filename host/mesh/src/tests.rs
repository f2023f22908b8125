//! Tests of the carving on small sessions rendered by the simulator (low resolution, a ring of
//! explicit views) and of each bad input.

use std::path::{Path, PathBuf};

use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::procedural::icosphere;
use ellipso_sim::test_support::render_session;
use nalgebra::Point3;

use super::halfedge::HalfEdgeMesh;
use super::{MeshConfig, MeshError, build_mesh};
use ellipso_model::geometry::distance::mesh_distance;
use ellipso_session::reader::{self, Session};

fn open(dir: &Path) -> Session {
    reader::open(dir).unwrap()
}

fn sphere_mesh(centre: [f64; 3], radius: f64) -> TriangleMesh {
    let (dirs, tris) = icosphere(5);
    let pos = dirs
        .iter()
        .map(|d| Point3::from(centre) + d.into_inner() * radius)
        .collect();
    TriangleMesh::new(pos, None, None, tris).unwrap()
}

fn small_config() -> MeshConfig {
    let mut c = MeshConfig {
        fine_cells: 90,
        ..MeshConfig::default()
    };
    c.remesh.target_vertices = 600;
    c
}

#[test]
fn carves_a_white_sphere_on_white_paper_into_a_closed_mesh_near_the_truth() {
    let tmp = tempfile::tempdir().unwrap();
    let (centre, radius) = ([0.0, 0.0, 0.03], 0.03);
    let (dir, _, poses) = render_session(tmp.path(), &[(centre, radius)], 16, 480, 384);
    let session = open(&dir);
    let mut config = small_config();
    config.debug_dir = std::env::var_os("MESH_TEST_DEBUG").map(PathBuf::from);
    let result = build_mesh(&session, &poses, &config, &mut |_| {}).unwrap();
    let r = &result.report;
    assert_eq!(r.frames_used, 16);
    assert!(r.board_pixels_median > 0.5, "{r:?}");
    // closed 2-manifold, near the target size
    let he = HalfEdgeMesh::new(
        result.mesh.positions().iter().map(|p| p.coords).collect(),
        result.mesh.triangles(),
    );
    assert!(he.is_ok(), "not a closed manifold: {he:?}");
    let genus = 1 - (r.vertices as i64 - r.triangles as i64 / 2) / 2;
    assert_eq!(genus, 0, "a sphere's hull has no handles: {r:?}");
    assert!(
        (r.vertices as f64 / 600.0 - 1.0).abs() < 0.2,
        "{} vertices",
        r.vertices
    );
    // near the truth: the pixel footprint here is ~0.7 mm, 16 views leave the hull's corners
    let d = mesh_distance(&result.mesh, &sphere_mesh(centre, radius), 4000, 1);
    println!("16 views 480×384: {d:?}, report {r:?}");
    assert!(d.chamfer_m < 1.5e-3, "{d:?}");
    assert!(r.volume_m3 > 0.0);
    // every vertex on or above the board
    assert!(result.mesh.positions().iter().all(|p| p.z >= -1e-9));

    // the naive test — anything within 60 % of the board's value counts as board — carves
    // into the white sphere: its volume or its distance to the truth gets much worse
    let mut naive = config.clone();
    naive.appearance.tolerance_rel = 0.6;
    naive.appearance.tolerance_polarisation = 1.0;
    match build_mesh(&session, &poses, &naive, &mut |_| {}) {
        Ok(bad) => {
            let dn = mesh_distance(&bad.mesh, &sphere_mesh(centre, radius), 4000, 1);
            println!("naive: {dn:?}, volume {}", bad.report.volume_m3);
            assert!(dn.chamfer_m > 1.5 * d.chamfer_m, "{dn:?} vs {d:?}");
        }
        Err(e) => println!("naive: {e}"),
    }
}

#[test]
fn too_few_posed_frames_is_an_error_naming_them() {
    let tmp = tempfile::tempdir().unwrap();
    let (dir, _, poses) = render_session(tmp.path(), &[([0.0, 0.0, 0.03], 0.03)], 4, 160, 128);
    let session = open(&dir);
    let e = build_mesh(&session, &poses[..3], &MeshConfig::default(), &mut |_| {}).unwrap_err();
    let text = e.to_string();
    assert!(
        matches!(e, MeshError::TooFewPosedFrames { usable: 3, .. }),
        "{text}"
    );
    assert!(text.contains("100, 101, 102"), "{text}");
    // a pose of a frame that is not in the session is named with its reason
    let mut more = poses.clone();
    more.push((999, poses[0].1));
    let e = build_mesh(&session, &more, &MeshConfig::default(), &mut |_| {}).unwrap_err();
    assert!(
        e.to_string().contains("999 (no frame file in the session)"),
        "{e}"
    );
}

#[test]
fn an_object_off_the_board_is_an_error_naming_the_face_and_frames() {
    let tmp = tempfile::tempdir().unwrap();
    // the base board's tags span x ±0.1335 m: a sphere at x = 0.12 reaches past it
    let (dir, _, poses) = render_session(tmp.path(), &[([0.12, 0.0, 0.03], 0.03)], 12, 320, 256);
    let session = open(&dir);
    let e = build_mesh(&session, &poses, &small_config(), &mut |_| {}).unwrap_err();
    let text = e.to_string();
    assert!(matches!(e, MeshError::ObjectOffBoard { .. }), "{text}");
    assert!(text.contains("+x"), "{text}");
    assert!(text.contains("frames 1"), "{text}");
}

#[test]
fn a_bare_board_is_an_empty_hull() {
    let tmp = tempfile::tempdir().unwrap();
    let (dir, _, poses) = render_session(tmp.path(), &[], 12, 320, 256);
    let session = open(&dir);
    let mut config = small_config();
    config.debug_dir = std::env::var_os("MESH_TEST_DEBUG").map(PathBuf::from);
    let e = build_mesh(&session, &poses, &config, &mut |_| {}).unwrap_err();
    assert!(matches!(e, MeshError::HullEmpty { views: 12, .. }), "{e}");
    assert!(e.to_string().contains("100, 101"), "{e}");
}

#[test]
fn two_objects_are_a_disconnected_hull() {
    let tmp = tempfile::tempdir().unwrap();
    let (dir, _, poses) = render_session(
        tmp.path(),
        &[([-0.05, 0.0, 0.02], 0.02), ([0.05, 0.0, 0.02], 0.02)],
        12,
        320,
        256,
    );
    let session = open(&dir);
    let e = build_mesh(&session, &poses, &small_config(), &mut |_| {}).unwrap_err();
    let text = e.to_string();
    assert!(matches!(e, MeshError::HullDisconnected { .. }), "{text}");
    assert!(text.contains("frames 10"), "{text}");
}
