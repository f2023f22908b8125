//! Visibility and gates: each rejected (vertex, view) is counted under its own reason, checked
//! against analytic sphere geometry independent of the mesh and its BVH.

use std::f64::consts::SQRT_2;

use nalgebra::{Point3, Vector3};

use super::{CENTRE, RADIUS_M, SceneSpec, make_session, open, segment_distance, sphere_and_board};
use ellipso_fit::data::FitFlag;
use ellipso_fit::observe::{ObserveConfig, camera_of, extract};

#[test]
fn hidden_back_facing_and_shadowed_vertices_are_gated_with_their_reason() {
    let dir = tempfile::tempdir().unwrap();
    // One view, flash 8 cm to the side so the sphere's shadow on the board is in view.
    let spec = SceneSpec {
        flash_offset_m: [0.08, 0.0, 0.0],
        cameras: vec![[0.21, 0.0, 0.25]],
        k1: 0.0,
        ..SceneSpec::paint_mono()
    };
    let (session_dir, _, poses) = make_session(dir.path(), &spec);
    let session = open(&session_dir);
    let (mesh, sphere) = sphere_and_board(3, 0.1, 81);
    let out = extract(
        &session,
        &mesh,
        &poses,
        &ObserveConfig::default(),
        &|_, _| {},
    )
    .unwrap();
    let set = &out.samples;
    assert_eq!(set.views.len(), 1);
    let view = &set.views[0];
    let camera = camera_of(&session).unwrap();
    let pose = poses[0].1;
    let cam = Point3::from(view.camera_position_world);
    let flash = Point3::from(view.flash_position_world);
    let centre = Point3::from(CENTRE);
    let (w, h, raw) = session.load_frame(&session.frames[0]).unwrap();

    // Sphere: the far side is back-facing.
    let mut back = 0;
    for vs in &set.vertices[..sphere] {
        let p = Point3::from(vs.position_world);
        let cos_view = Vector3::from(vs.normal_world).dot(&(cam - p).normalize());
        if cos_view < -0.05 {
            assert_eq!(vs.gates.not_in_view, 1, "vertex {}", vs.vertex);
            back += 1;
        } else if cos_view > 0.05 {
            assert_eq!(vs.gates.not_in_view, 0, "vertex {}", vs.vertex);
        }
    }
    // Board: occluded by the sphere, in its flash shadow, or seen and lit.
    let (mut occluded, mut shadowed, mut seen, mut mixed) = (0, 0, 0, 0);
    for vs in &set.vertices[sphere..] {
        let p = Point3::from(vs.position_world);
        let Some(px) = camera.project(&(pose.inverse() * p)) else {
            continue;
        };
        let margin = 4.0;
        if !(px[0] > margin
            && px[1] > margin
            && px[0] < f64::from(w) - margin
            && px[1] < f64::from(h) - margin)
        {
            continue;
        }
        let to_camera = segment_distance(&cam, &p, &centre) / RADIUS_M;
        let to_flash = segment_distance(&p, &flash, &centre) / RADIUS_M;
        let g = &vs.gates;
        if to_camera < 0.9 {
            assert_eq!((g.occluded, g.kept), (1, 0), "vertex {}", vs.vertex);
            occluded += 1;
        } else if to_camera > 1.1 && to_flash < 0.9 {
            assert_eq!((g.shadowed, g.kept), (1, 0), "vertex {}", vs.vertex);
            // The renderer agrees: no light reaches the raw pixels there.
            let (x, y) = (px[0].round() as usize, px[1].round() as usize);
            assert_eq!(raw[y * w as usize + x], 0, "lit shadow at {px:?}");
            shadowed += 1;
        } else if to_camera > 1.1 && to_flash > 1.1 {
            // Seen and lit: kept, or — near the silhouette, where the pixels its value is
            // interpolated from reach past the sphere — gated as mixed; a board vertex on a
            // tag's black ink may read dark.
            let on_board = vs.vertex as usize >= sphere;
            let dark = if on_board { g.dark } else { 0 };
            assert_eq!(
                g.kept + g.mixed + dark,
                1,
                "vertex {} gates {g:?}",
                vs.vertex
            );
            if g.mixed == 1 {
                // On the sphere: seen obliquely; on the board: just outside the sphere's
                // outline (its footprint reaching onto the sphere) or within the footprint's
                // reach (4.5 px: the cubic kernel on the mono tile, ×√2 at a corner, + 1 px) of the
                // board mesh's own border in the image (reaching off the mesh).
                let cos_view = Vector3::from(vs.normal_world).dot(&(cam - p).normalize());
                let on_sphere = (vs.vertex as usize) < sphere;
                let border_px = board_border_distance_px(&camera, &pose, px);
                assert!(
                    (on_sphere && cos_view < 0.6)
                        || (!on_sphere && (to_camera < 1.3 || border_px < 4.5 * SQRT_2 + 1.0)),
                    "vertex {}: mixed at cos θ {cos_view}, {to_camera} radii from the sphere, \
                     {border_px} px from the board's border",
                    vs.vertex
                );
                mixed += 1;
            }
            seen += 1;
        }
    }
    eprintln!(
        "back-facing {back}, occluded {occluded}, shadowed {shadowed}, seen {seen} ({mixed} mixed)"
    );
    assert!(back > 100 && occluded > 20 && shadowed > 20 && seen > 1000);
    assert!(
        mixed < seen / 4,
        "{mixed} of {seen} seen vertices gated as mixed"
    );
    let total = &out.report.gates;
    assert_eq!(
        total.not_in_view
            + total.occluded
            + total.shadowed
            + total.mixed
            + total.grazing
            + total.saturated
            + total.dark
            + total.non_finite
            + total.colour_outlier
            + total.kept,
        mesh.positions().len() as u64,
        "one view: every vertex counted exactly once"
    );
}

#[test]
fn saturated_highlights_are_gated_as_saturated() {
    let dir = tempfile::tempdir().unwrap();
    // The shipped sphere scene's glass: a sharp, bright highlight that clips.
    let spec = SceneSpec {
        material: "eta = 1.5\nsigma_s = 0.05\nsigma_ss = 0.15\nrho_s = 1.0\n\
                   rho_ss = [0.05, 0.05, 0.05]\nrho_d = [0.02, 0.02, 0.02]",
        exposure_us: 8000.0,
        cameras: vec![[0.21, 0.0, 0.25], [0.0, 0.21, 0.25]],
        k1: 0.0,
        ..SceneSpec::paint_mono()
    };
    let (session_dir, _, poses) = make_session(dir.path(), &spec);
    let session = open(&session_dir);
    let (mesh, sphere) = sphere_and_board(4, 0.1, 5);
    let out = extract(
        &session,
        &mesh,
        &poses,
        &ObserveConfig::default(),
        &|_, _| {},
    )
    .unwrap();
    let set = &out.samples;
    for (k, view) in set.views.iter().enumerate() {
        // The vertex whose normal is closest to the half vector carries the highlight peak.
        let peak = set.vertices[..sphere]
            .iter()
            .max_by(|a, b| {
                let cos_h = |vs: &ellipso_fit::data::VertexSamples| {
                    let g = view.geometry_at(&Point3::from(vs.position_world)).unwrap();
                    let h = (Vector3::from(g.to_light) + Vector3::from(g.to_camera)).normalize();
                    Vector3::from(vs.normal_world).dot(&h)
                };
                cos_h(a).total_cmp(&cos_h(b))
            })
            .unwrap();
        assert!(
            peak.samples.iter().all(|s| s.view as usize != k),
            "view {k}: highlight vertex {} kept",
            peak.vertex
        );
        assert!(peak.gates.saturated >= 1, "{:?}", peak.gates);
    }
    assert!(
        out.report.gates.saturated >= 2 * 3,
        "{:?}",
        out.report.gates
    );
    let kept_max = set
        .vertices
        .iter()
        .flat_map(|vs| &vs.samples)
        .map(|s| s.channels[0][0] * s.normaliser)
        .fold(0f32, f32::max);
    assert!(f64::from(kept_max) < 2.0 * 0.98 * 4095.0);
}

/// Distance in pixels from `px` to the image of the board mesh's border (the square of half-side
/// 0.1 m at z = 0 that `sphere_and_board` builds), the border projected point by point (lens
/// distortion bends its image).
fn board_border_distance_px(
    camera: &ellipso_model::camera::CameraModel,
    world_from_camera: &nalgebra::Isometry3<f64>,
    px: [f64; 2],
) -> f64 {
    let corners = [[-0.1, -0.1], [0.1, -0.1], [0.1, 0.1], [-0.1, 0.1]];
    let steps = 400;
    (0..4)
        .flat_map(|k| {
            let (a, b) = (corners[k], corners[(k + 1) % 4]);
            (0..steps).map(move |i| {
                let t = f64::from(i) / f64::from(steps);
                [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
            })
        })
        .filter_map(|[x, y]| {
            camera.project(&(world_from_camera.inverse() * Point3::new(x, y, 0.0)))
        })
        .map(|q| (q[0] - px[0]).hypot(q[1] - px[1]))
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn vertices_no_view_sees_are_labelled_unobserved() {
    let dir = tempfile::tempdir().unwrap();
    // The sphere rests on the board (contact at z = 0); five views from 50° elevation and above.
    let spec = SceneSpec::paint_mono();
    let (session_dir, _, poses) = make_session(dir.path(), &spec);
    let session = open(&session_dir);
    let (sphere_mesh, sphere) = sphere_and_board(3, 0.1, 2);
    let positions = sphere_mesh.positions()[..sphere].to_vec();
    let triangles: Vec<[u32; 3]> = sphere_mesh
        .triangles()
        .iter()
        .filter(|t| t.iter().all(|&i| (i as usize) < sphere))
        .copied()
        .collect();
    let mesh =
        ellipso_model::geometry::TriangleMesh::new(positions, None, None, triangles).unwrap();
    let out = extract(
        &session,
        &mesh,
        &poses,
        &ObserveConfig::default(),
        &|_, _| {},
    )
    .unwrap();
    let set = &out.samples;
    let observed = ellipso_fit::shape::surface::observed_vertices(set, mesh.positions().len());
    let fits = ellipso_fit::solve::fit_all(
        set,
        None,
        None,
        &ellipso_fit::solve::SolverConfig::default(),
    );
    let cameras: Vec<Point3<f64>> = set
        .views
        .iter()
        .map(|v| Point3::from(v.camera_position_world))
        .collect();
    let (mut underside, mut seen) = (0, 0);
    for (v, fit) in fits.iter().enumerate() {
        let p = mesh.positions()[v];
        let n = mesh.normals()[v].into_inner();
        let unobserved = fit.flags.contains(&FitFlag::Unobserved);
        // the flag, the samples and the gates say the same: unobserved is no sample and no
        // frame that saw the vertex lit; a vertex with a kept sample is observed
        let gates = &set.vertices[v].gates;
        assert_eq!(
            unobserved,
            set.vertices[v].samples.is_empty() && gates.seen_lit() == 0,
            "vertex {v}: {gates:?}"
        );
        assert_eq!(
            observed[v],
            !set.vertices[v].samples.is_empty(),
            "vertex {v}"
        );
        assert!(!(observed[v] && unobserved), "vertex {v}");
        if unobserved {
            assert!(fit.flags.contains(&FitFlag::TooFewViews));
        }
        // geometry: a vertex facing away from every camera, or at the board contact, is never
        // observed; one that every camera sees well above the board is
        let facing = cameras
            .iter()
            .filter(|c| n.dot(&(*c - p).normalize()) > 0.05)
            .count();
        if facing == 0 || p.z < 0.005 {
            assert!(
                unobserved,
                "vertex {v} at z = {:.4} m faces {facing} views",
                p.z
            );
            underside += 1;
        } else if n.z > 0.5 {
            assert!(!unobserved, "vertex {v}: {:?}", set.vertices[v].gates);
            seen += 1;
        }
    }
    eprintln!("underside {underside}, seen from above {seen}");
    assert!(underside > 50 && seen > 150);
}
