//! The surface update on a sphere: started 2 mm too large, with the true normals (an offset
//! sphere has the same ones, so they cannot shrink it) and the visual hull of a ring of views,
//! it converges onto the sphere where the views see it; a step that folds a triangle is
//! shortened until it does not (down to not moving its corners at all); a step that diverges
//! is refused; a vertex is held on a silhouette only where as many views as the hull has votes
//! are tangent to it; its hold gives way inward, never outward.

use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::procedural::icosphere;
use nalgebra::{Isometry3, Point3, Vector3};

use super::super::hull::{GridGeometry, HullField};
use super::super::tests::fit;
use super::{SurfaceConfig, SurfaceState, left_hull_by, on_silhouette, turned_over, unfolded_step};

const RADIUS: f64 = 0.02;

fn centre() -> Vector3<f64> {
    Vector3::new(0.0, 0.0, RADIUS)
}

/// Camera centres on two rings around the sphere (elevations 25° and 55°), 0.45 m away.
fn cameras() -> Vec<Vector3<f64>> {
    let mut c = Vec::new();
    for (e, count) in [(25.0f64, 24), (55.0, 16)] {
        for k in 0..count {
            let a = (k as f64 / count as f64) * std::f64::consts::TAU;
            let e = e.to_radians();
            c.push(centre() + 0.45 * Vector3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin()));
        }
    }
    c
}

/// The visual hull of the sphere seen from `cameras()`: per node the largest over views of the
/// metric distance outside the view's silhouette cone (the classic hull's field), the board
/// under it.
fn hull() -> HullField {
    let h = 0.0005;
    let lo = Vector3::new(-0.03, -0.03, -0.002);
    let n = [121, 121, 105];
    let grid = GridGeometry {
        origin_m: lo.into(),
        spacing_m: h,
        n,
    };
    let cams = cameras();
    let mut values = vec![0.0f32; grid.len()];
    for k in 0..n[2] {
        for j in 0..n[1] {
            for i in 0..n[0] {
                let p = lo + Vector3::new(i as f64, j as f64, k as f64) * h;
                let phi = cams
                    .iter()
                    .map(|c| {
                        let (to_p, to_s) = (p - c, centre() - c);
                        let angle = to_p.angle(&to_s);
                        let cone = (RADIUS / to_s.norm()).asin();
                        (angle - cone).sin() * to_p.norm()
                    })
                    .fold(f64::NEG_INFINITY, f64::max);
                values[grid.index(i, j, k)] = phi.max(-p.z) as f32;
            }
        }
    }
    HullField::new(Isometry3::identity(), grid, values, 0.01, 1).unwrap()
}

#[test]
fn a_sphere_started_2_mm_too_large_converges_onto_it() {
    let (dirs, triangles) = icosphere(4);
    let start: Vec<Point3<f64>> = dirs
        .iter()
        .map(|d| Point3::from(centre() + d.into_inner() * (RADIUS + 0.002)))
        .collect();
    let mut mesh = TriangleMesh::new(start, None, None, triangles).unwrap();
    // seen: normals a view at 25° or more sees within 80° of its axis
    let observed: Vec<bool> = dirs
        .iter()
        .map(|d| d.z > -(55f64.to_radians().sin()))
        .collect();
    let fits: Vec<_> = dirs
        .iter()
        .enumerate()
        .filter(|(v, _)| observed[*v])
        .map(|(v, d)| fit(v as u32, d.into_inner().into(), 0.5, vec![]))
        .collect();
    let hull = hull();
    let config = SurfaceConfig::default();
    let mut state = SurfaceState::new(&mesh);
    let error = |m: &TriangleMesh| {
        let e: Vec<f64> = m
            .positions()
            .iter()
            .zip(&observed)
            .filter(|(_, o)| **o)
            .map(|(p, _)| ((p.coords - centre()).norm() - RADIUS).abs())
            .collect();
        e.iter().sum::<f64>() / e.len() as f64
    };
    let before = error(&mesh);
    for _ in 0..6 {
        match state
            .step(
                &mesh,
                &fits,
                &observed,
                &cameras()
                    .into_iter()
                    .map(nalgebra::Point3::from)
                    .collect::<Vec<_>>(),
                Some(&hull),
                &config,
            )
            .unwrap()
        {
            Some(m) => mesh = m,
            None => break,
        }
    }
    let after = error(&mesh);
    eprintln!(
        "mean |r − R| over the observed surface: {:.4} mm → {:.4} mm",
        before * 1e3,
        after * 1e3
    );
    let steps = &state.iterations;
    for s in steps {
        eprintln!("{}", s.describe());
    }
    assert!((before - 0.002).abs() < 1e-4, "{before}");
    assert!(
        after < 1e-4,
        "mean |r − R| over the observed surface {after} m after {} steps",
        steps.len()
    );
    // the first step does the work, later ones move less and less until convergence
    assert!(steps.len() >= 2);
    assert!(steps.iter().all(|s| s.applied));
    assert!(steps.windows(2).all(|w| w[1].rms_move_m < w[0].rms_move_m));
    assert!(state.done() && state.stopped().is_some_and(|s| s.starts_with("converged")));
    // nothing left the hull or went below the board
    assert!(
        mesh.positions()
            .iter()
            .all(|p| hull.value_world(p).0 < config.hull_tolerance_m)
    );
}

#[test]
fn what_the_penalty_cannot_hold_is_projected_onto_the_hull() {
    // A sphere 1 mm inside its hull with normals that push it 3 mm out: with a penalty too weak
    // to hold it (κ = 0.01) the solve ends outside, and the step still stays inside the hull.
    let (dirs, triangles) = icosphere(3);
    let start: Vec<Point3<f64>> = dirs
        .iter()
        .map(|d| Point3::from(centre() + d.into_inner() * (RADIUS - 0.001)))
        .collect();
    let mesh = TriangleMesh::new(start, None, None, triangles).unwrap();
    let hull = hull();
    let mut config = SurfaceConfig::default();
    config.integrate.hull_weight = 0.01;
    config.integrate.weights.lambda_position = 1e4;
    // anchors 3 mm out: the screening pulls the surface out through the hull
    let anchors: Vec<Point3<f64>> = dirs
        .iter()
        .map(|d| Point3::from(centre() + d.into_inner() * (RADIUS + 0.002)))
        .collect();
    let normals: Vec<[f64; 3]> = dirs.iter().map(|d| d.into_inner().into()).collect();
    let confidence = vec![1.0; dirs.len()];
    let screening = vec![1.0; dirs.len()];
    let solved = super::super::integrate::integrate(
        mesh.positions(),
        mesh.triangles(),
        &super::super::integrate::Targets {
            normals_world: &normals,
            confidence: &confidence,
            anchors: &anchors,
            screening: &screening,
            on_silhouette: &[],
        },
        Some(&hull),
        &config.integrate,
    )
    .unwrap();
    assert!(
        solved.projected_vertices > 0,
        "moved {} m RMS, {} active, {} m outside",
        solved.rms_displacement_m,
        solved.active_vertices,
        solved.max_outside_m
    );
    assert!(
        solved.max_outside_m <= 0.0,
        "left outside by {} m",
        solved.max_outside_m
    );
}

#[test]
fn a_step_that_folds_a_triangle_is_shortened_until_it_does_not() {
    let triangles = [[0u32, 1, 2]];
    let before = [
        Point3::new(0.0, 0.0, 0.0),
        Point3::new(1.0, 0.0, 0.0),
        Point3::new(0.0, 1.0, 0.0),
    ];
    // Vertex 2 crosses the opposite edge: folded at 1 and ½, not at ¼.
    let mut after = before;
    after[2] = Point3::new(0.0, -1.5, 0.0);
    assert_eq!(turned_over(&triangles, &before, &after), 1);
    let u = unfolded_step(&triangles, &before, &after, None);
    assert_eq!(u.fraction, 0.25);
    assert_eq!(u.shortened, 3);
    assert!((u.positions[2].y - 0.375).abs() < 1e-12);
    assert_eq!(turned_over(&triangles, &before, &u.positions), 0);
    // So far across that every fraction but the last folds it: its corners stay where they
    // were, and the step goes on without folding it.
    after[2] = Point3::new(0.0, -100.0, 0.0);
    let u = unfolded_step(&triangles, &before, &after, None);
    assert_eq!(u.fraction, 0.0);
    assert_eq!(u.positions, before);
    assert_eq!(turned_over(&triangles, &before, &u.positions), 0);
}

#[test]
fn a_corner_that_cannot_move_without_folding_stays_exactly_where_it_was_even_outside_the_hull() {
    // A sliver whose corners lie 0.2 mm outside a sphere's hull: projecting them onto the hull
    // would be a move, and the step asks vertex 2 to cross the opposite edge. The corners held
    // by the last fraction are not projected (they are the last good mesh's), and the other
    // triangle still moves the whole step, projected.
    let hull = crate::shape::hull::tests::sphere_hull(Vector3::zeros(), 0.01, 5e-4);
    let r = 0.0102;
    let before = [
        Point3::new(r, 0.0, 0.0),
        Point3::new(r, 1e-3, 0.0),
        Point3::new(r, 0.0, 1e-3),
        Point3::new(-r, 0.0, 0.0),
        Point3::new(-r, 0.0, 1e-3),
        Point3::new(-r, 1e-3, 0.0),
    ];
    let triangles = [[0u32, 1, 2], [3, 4, 5]];
    let mut after = before;
    after[2] = Point3::new(r, 0.0, -1.0);
    for p in &mut after[3..] {
        p.x += 1e-4;
    }
    let u = unfolded_step(&triangles, &before, &after, Some(&hull));
    assert_eq!(u.fraction, 0.0);
    assert_eq!(u.positions[..3], before[..3], "held exactly, not projected");
    for p in &u.positions[3..] {
        assert!(hull.value_world(p).0 <= 0.0, "the rest projected inside");
    }
    assert_eq!(turned_over(&triangles, &before, &u.positions), 0);
    // What was outside before and stays there is not the step leaving the hull.
    assert!(left_hull_by(&hull, &before, &u.positions) <= 0.0);
    let mut out = u.positions.clone();
    out[0].x += 1e-3;
    assert!((left_hull_by(&hull, &before, &out) - 1e-3).abs() < 5e-5);
}

#[test]
fn only_the_corners_of_a_folding_triangle_are_cut_back() {
    // Two triangles sharing no vertex: the first folds at the full step, the second moves
    // 1 m sideways and must move all of it.
    let triangles = [[0u32, 1, 2], [3, 4, 5]];
    let before = [
        Point3::new(0.0, 0.0, 0.0),
        Point3::new(1.0, 0.0, 0.0),
        Point3::new(0.0, 1.0, 0.0),
        Point3::new(5.0, 0.0, 0.0),
        Point3::new(6.0, 0.0, 0.0),
        Point3::new(5.0, 1.0, 0.0),
    ];
    let mut after = before;
    after[2] = Point3::new(0.0, -1.5, 0.0);
    for p in &mut after[3..] {
        p.x += 1.0;
    }
    let u = unfolded_step(&triangles, &before, &after, None);
    assert_eq!(u.fraction, 0.25);
    assert_eq!(u.shortened, 3);
    assert!((u.positions[2].y - 0.375).abs() < 1e-12);
    assert_eq!(
        u.positions[3..],
        after[3..],
        "the second triangle moved the whole step"
    );
    assert_eq!(turned_over(&triangles, &before, &u.positions), 0);
}

#[test]
fn a_vertex_is_held_on_a_silhouette_only_where_as_many_views_as_the_hull_has_votes_touch_it() {
    let (dirs, _) = icosphere(4);
    let cameras: Vec<Point3<f64>> = cameras().into_iter().map(Point3::from).collect();
    let config = SurfaceConfig::default();
    let mut hull = hull();
    let mut held = |votes: usize| {
        hull.votes = votes;
        dirs.iter()
            .filter(|d| {
                let p = Point3::from(centre() + d.into_inner() * RADIUS);
                on_silhouette(&hull, &p, &d.into_inner(), &cameras, &config)
            })
            .count()
    };
    let (one, two, all) = (held(1), held(2), held(cameras.len() + 1));
    // The classic hull (one vote) touches the sphere on every view's silhouette.
    assert!(one > 100, "{one} vertices held with one vote");
    // Where a single view is tangent, a hull of two votes stands outside: fewer are held.
    assert!(
        two < one && two > 0,
        "{two} held with two votes, {one} with one"
    );
    assert_eq!(all, 0);
}

#[test]
fn a_silhouette_hold_gives_way_inward_to_consistent_normals_but_never_outward() {
    // Every vertex of the sphere marked as on a silhouette, a strong screening pulling it 0.5 mm in
    // (anchors inside) or out (anchors outside), the true normals: inward the hold gives way
    // (κ_sil), outward it is the hull's full weight.
    let (dirs, triangles) = icosphere(3);
    let on_sphere: Vec<Point3<f64>> = dirs
        .iter()
        .map(|d| Point3::from(centre() + d.into_inner() * RADIUS))
        .collect();
    let hull = hull();
    let normals: Vec<[f64; 3]> = dirs.iter().map(|d| d.into_inner().into()).collect();
    let confidence = vec![1.0; dirs.len()];
    let screening = vec![1.0; dirs.len()];
    let held = vec![true; dirs.len()];
    let solve = |offset_m: f64, config: &super::super::integrate::IntegrateConfig| {
        let anchors: Vec<Point3<f64>> = dirs
            .iter()
            .map(|d| Point3::from(centre() + d.into_inner() * (RADIUS + offset_m)))
            .collect();
        let solved = super::super::integrate::integrate(
            &on_sphere,
            &triangles,
            &super::super::integrate::Targets {
                normals_world: &normals,
                confidence: &confidence,
                anchors: &anchors,
                screening: &screening,
                on_silhouette: &held,
            },
            Some(&hull),
            config,
        )
        .unwrap();
        let radial: Vec<f64> = solved
            .positions
            .iter()
            .map(|p| (p.coords - centre()).norm() - RADIUS)
            .collect();
        (radial.iter().sum::<f64>() / radial.len() as f64, solved)
    };
    let mut config = SurfaceConfig::default().integrate;
    config.weights.lambda_position = 1e4;
    let (inward, _) = solve(-0.0005, &config);
    let (outward, out) = solve(0.0005, &config);
    let mut rigid = config.clone();
    rigid.silhouette_hold_weight = rigid.hull_weight;
    let (inward_rigid, _) = solve(-0.0005, &rigid);
    eprintln!(
        "mean radial move: inward {:.4} mm (rigid hold {:.4} mm), outward {:.4} mm",
        inward * 1e3,
        inward_rigid * 1e3,
        outward * 1e3
    );
    assert!(inward < -0.1e-3, "the hold gave way only {inward} m");
    assert!(inward_rigid > 0.25 * inward, "{inward_rigid} vs {inward}");
    assert!(
        out.max_outside_m <= SurfaceConfig::default().hull_tolerance_m,
        "left the hull by {} m",
        out.max_outside_m
    );
    assert!(outward < 0.05e-3, "moved out {outward} m");
}

#[test]
fn a_step_that_diverges_is_refused_and_the_last_good_mesh_stays() {
    // A sphere 0.1 mm outside its hull with its true normals: the first step brings it onto the
    // hull. Then normals tilted by a seeded ±25° field ask for a crumpled surface far larger
    // than that step: refused as diverging, with the reason in words, and no mesh comes back.
    let (dirs, triangles) = icosphere(3);
    let start: Vec<Point3<f64>> = dirs
        .iter()
        .map(|d| Point3::from(centre() + d.into_inner() * (RADIUS + 1e-4)))
        .collect();
    let mesh = TriangleMesh::new(start, None, None, triangles).unwrap();
    let observed = vec![true; dirs.len()];
    let fits_with = |normal: &dyn Fn(usize, Vector3<f64>) -> Vector3<f64>| -> Vec<_> {
        dirs.iter()
            .enumerate()
            .map(|(v, d)| fit(v as u32, normal(v, d.into_inner()).into(), 0.5, vec![]))
            .collect()
    };
    let hull = hull();
    let cameras: Vec<Point3<f64>> = cameras().into_iter().map(Point3::from).collect();
    let config = SurfaceConfig::default();
    let mut state = SurfaceState::new(&mesh);
    let first = state
        .step(
            &mesh,
            &fits_with(&|_, n| n),
            &observed,
            &cameras,
            Some(&hull),
            &config,
        )
        .unwrap()
        .expect("the first step applies");
    assert!(!state.done());
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(7);
    let tilts: Vec<Vector3<f64>> = (0..dirs.len())
        .map(|_| {
            use rand::Rng;
            Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ) * 25f64.to_radians().tan()
        })
        .collect();
    let crumpled = fits_with(&|v, n| (n + tilts[v] - n * n.dot(&tilts[v])).normalize());
    let second = state
        .step(&first, &crumpled, &observed, &cameras, Some(&hull), &config)
        .unwrap();
    assert!(second.is_none(), "a diverging step came back as a mesh");
    assert!(state.done());
    let why = state.stopped().unwrap();
    assert!(why.starts_with("stopped: diverging"), "{why}");
    assert!(why.ends_with("the last good mesh is kept"), "{why}");
    for s in &state.iterations {
        eprintln!("{}", s.describe());
    }
    let report = state.iterations.last().unwrap();
    assert!(!report.applied);
    // no later step runs
    assert!(
        state
            .step(&first, &crumpled, &observed, &cameras, Some(&hull), &config)
            .unwrap()
            .is_none()
    );
    assert_eq!(state.iterations.len(), 2);
}
