//! Samples against the model: a noise-free render divided by N must give
//! `optics::measure::observe` of the true material at the vertex's geometry.

use ellipso_model::geometry::Ray;
use ellipso_model::optics::Vec3;
use ellipso_model::optics::measure::observe;
use ellipso_sim::render::{RenderOptions, Renderer};
use ellipso_sim::scene::{Scene, SurfaceKind};
use nalgebra::{Point3, Vector3};

use super::{CENTRE, RADIUS_M, SceneSpec, make_session, open, segment_distance, sphere_and_board};
use ellipso_fit::data::SampleSet;
use ellipso_fit::observe::{ObserveConfig, SamplePoint, extract};

/// Errors of one comparison: per sample the largest |observed − predicted| of the three
/// channels relative to the predicted I^d of that colour.
#[derive(Debug, Default)]
struct Errors {
    compared: usize,
    max: f64,
    sum: f64,
}

impl Errors {
    fn add(&mut self, e: f64) {
        self.compared += 1;
        self.max = self.max.max(e);
        self.sum += e;
    }
    fn mean(&self) -> f64 {
        self.sum / self.compared.max(1) as f64
    }
}

/// Compares every sphere sample viewed within 60° of its normal with the model.
fn sphere_errors(set: &SampleSet, sphere_vertices: usize, scene: &Scene) -> Errors {
    let params = scene.materials[0].params.to_pbrdf();
    let mut errors = Errors::default();
    for vs in &set.vertices[..sphere_vertices] {
        let p = Point3::from(vs.position_world);
        let n = Vector3::from(vs.normal_world);
        for s in &vs.samples {
            let view = &set.views[s.view as usize];
            let g = view.geometry_at(&p).unwrap();
            if n.dot(&Vector3::from(g.to_camera)) < 0.5 {
                continue;
            }
            let model = g.model(Vec3::new(n.x, n.y, n.z)).unwrap();
            let pred = observe(&model, &params, view.flash_polariser());
            let pred: Vec<[f64; 3]> = if set.colour {
                pred.iter()
                    .map(|c| [c.diffuse, c.specular, c.alpha])
                    .collect()
            } else {
                // A mono pixel weighs R, G, B equally (the renderer's mono response).
                let mean = |f: &dyn Fn(usize) -> f64| (0..3).map(f).sum::<f64>() / 3.0;
                vec![[
                    mean(&|c| pred[c].diffuse),
                    mean(&|c| pred[c].specular),
                    mean(&|c| pred[c].alpha),
                ]]
            };
            for (c, want) in pred.iter().enumerate() {
                let got = s.channels[c].map(f64::from);
                let e = (0..3)
                    .map(|k| (got[k] - want[k]).abs() / want[0])
                    .fold(0.0, f64::max);
                errors.add(e);
            }
        }
    }
    errors
}

#[test]
fn mono_sphere_samples_match_the_model_within_one_percent() {
    let dir = tempfile::tempdir().unwrap();
    let (session_dir, scene, poses) = make_session(dir.path(), &SceneSpec::paint_mono());
    let session = open(&session_dir);
    let (mesh, sphere) = sphere_and_board(3, 0.1, 21);
    let out = extract(
        &session,
        &mesh,
        &poses,
        &ObserveConfig::default(),
        &|_, _| {},
    )
    .unwrap();
    assert!(!out.samples.colour);
    assert_eq!(out.report.frames_used, poses.len());
    for vs in &out.samples.vertices {
        for s in &vs.samples {
            assert_eq!(s.channels[0], s.channels[1], "mono entries are equal");
            assert_eq!(s.channels[0], s.channels[2]);
        }
    }
    let e = sphere_errors(&out.samples, sphere, &scene);
    eprintln!(
        "mono sphere: {} samples, error max {:.4} mean {:.5}",
        e.compared,
        e.max,
        e.mean()
    );
    assert!(e.compared > 500, "{} samples compared", e.compared);
    assert!(e.max < 0.01, "max error {:.4}", e.max);
}

#[test]
fn board_samples_give_the_print_albedo_and_no_polarisation() {
    let dir = tempfile::tempdir().unwrap();
    let (session_dir, scene, poses) = make_session(dir.path(), &SceneSpec::paint_mono());
    let session = open(&session_dir);
    let (mesh, sphere) = sphere_and_board(2, 0.1, 41);
    let out = extract(
        &session,
        &mesh,
        &poses,
        &ObserveConfig::default(),
        &|_, _| {},
    )
    .unwrap();
    // The print's albedo straight below a point (None when a tag edge lies within 5 mm: a 1 mm
    // probe grid, finer than the tag bits and the bilinear footprint).
    let albedo = |p: &Point3<f64>| {
        let probe = |dx: f64, dy: f64| {
            let ray = Ray::new(Point3::new(p.x + dx, p.y + dy, 0.01), -Vector3::z());
            match scene.intersect(&ray, 0.0, 1.0).map(|h| h.kind) {
                Some(SurfaceKind::Board { albedo, .. }) => Some(albedo),
                _ => None,
            }
        };
        let a = probe(0.0, 0.0)?;
        let steps = -5..=5;
        steps
            .clone()
            .flat_map(|i| steps.clone().map(move |j| (i, j)))
            .all(|(i, j)| probe(f64::from(i) * 1e-3, f64::from(j) * 1e-3) == Some(a))
            .then_some(f64::from(a))
    };
    let mut compared = 0;
    let mut worst: f64 = 0.0;
    for vs in &out.samples.vertices[sphere..] {
        let p = Point3::from(vs.position_world);
        let Some(a) = albedo(&p) else { continue };
        for s in &vs.samples {
            let view = &out.samples.views[s.view as usize];
            // Only where the whole neighbourhood sees the board lit: no sphere pixels or
            // shadow edge inside the bilinear footprint.
            let cam = Point3::from(view.camera_position_world);
            let flash = Point3::from(view.flash_position_world);
            let centre = Point3::from(CENTRE);
            let clear = [
                (0.0, 0.0),
                (0.004, 0.0),
                (-0.004, 0.0),
                (0.0, 0.004),
                (0.0, -0.004),
            ]
            .iter()
            .all(|&(dx, dy)| {
                let q = Point3::new(p.x + dx, p.y + dy, 0.0);
                segment_distance(&cam, &q, &centre) > 1.05 * RADIUS_M
                    && segment_distance(&q, &flash, &centre) > 1.05 * RADIUS_M
            });
            if !clear {
                continue;
            }
            let g = view.geometry_at(&p).unwrap();
            // Matte paper: I^d = s0 = albedo · cos θ_i, I^s = I^α = 0.
            let want = a * g.to_light[2];
            let [d, sp, al, _] = s.channels[0].map(f64::from);
            // Raw frames hold whole DN: each channel is a difference of two values rounded to
            // ±0.5 DN, so 1 DN / N of quantisation comes on top of 1 % interpolation error.
            let err = (d - want).abs().max(sp.abs()).max(al.abs());
            let quantisation = 1.0 / f64::from(s.normaliser);
            worst = worst.max((err - quantisation).max(0.0) / want);
            compared += 1;
        }
    }
    eprintln!("board: {compared} samples, worst relative error beyond 1 DN {worst:.4}");
    assert!(compared > 500, "{compared} board samples compared");
    assert!(worst < 0.01, "worst {worst}");
}

#[test]
fn normalisers_are_the_renderers() {
    let dir = tempfile::tempdir().unwrap();
    let (session_dir, scene, poses) = make_session(dir.path(), &SceneSpec::paint_mono());
    let session = open(&session_dir);
    let (mesh, _) = sphere_and_board(2, 0.1, 21);
    let out = extract(
        &session,
        &mesh,
        &poses,
        &ObserveConfig::default(),
        &|_, _| {},
    )
    .unwrap();
    let renderer = Renderer::new(&scene, RenderOptions::default()).unwrap();
    let mut checked = 0;
    for vs in &out.samples.vertices {
        let p = Point3::from(vs.position_world);
        for s in &vs.samples {
            let view = &out.samples.views[s.view as usize];
            let pose = poses
                .iter()
                .find(|q| q.0 == view.frame_id)
                .map(|q| q.1)
                .unwrap();
            let flash = scene.rig.flash.position_world(&pose);
            let axis = scene.rig.flash.axis_world(&pose);
            let to_point = p - flash;
            let d = to_point.norm();
            let angle = (to_point / d).dot(&axis).clamp(-1.0, 1.0).acos();
            let p_cam = pose.inverse() * p;
            let field = (p_cam.z / p_cam.coords.norm()).acos();
            let want = renderer.radiometry().normaliser(d, angle, field);
            let got = f64::from(s.normaliser);
            assert!(
                (got / want - 1.0).abs() < 1e-6,
                "vertex {} view {}: {got} vs {want}",
                vs.vertex,
                s.view
            );
            checked += 1;
        }
    }
    assert!(checked > 1000, "{checked}");
}

#[test]
fn colour_sensor_samples_match_the_model_per_channel() {
    let dir = tempfile::tempdir().unwrap();
    let spec = SceneSpec {
        sensor: "colour_polar",
        material: "eta = 1.6\nsigma_s = 0.3\nsigma_ss = 0.45\nrho_s = 0.4\n\
                   rho_ss = [0.08, 0.05, 0.03]\nrho_d = [0.6, 0.35, 0.15]",
        k1: 0.0,
        ..SceneSpec::paint_mono()
    };
    let (session_dir, scene, poses) = make_session(dir.path(), &spec);
    let session = open(&session_dir);
    let (mesh, sphere) = sphere_and_board(3, 0.1, 11);
    let out = extract(
        &session,
        &mesh,
        &poses,
        &ObserveConfig::default(),
        &|_, _| {},
    )
    .unwrap();
    assert!(out.samples.colour);
    let e = sphere_errors(&out.samples, sphere, &scene);
    eprintln!(
        "colour sphere: {} channel samples, error max {:.4} mean {:.5}",
        e.compared,
        e.max,
        e.mean()
    );
    assert!(e.compared > 300, "{}", e.compared);
    // Colour superpixels are 4×4 raw pixels: twice the mono lattice period.
    assert!(e.max < 0.03, "max error {:.4}", e.max);
    assert!(e.mean() < 0.01, "mean error {:.4}", e.mean());
}

#[test]
fn lattice_positions_remove_the_superpixel_misregistration() {
    let dir = tempfile::tempdir().unwrap();
    let (session_dir, scene, poses) = make_session(dir.path(), &SceneSpec::paint_mono());
    let session = open(&session_dir);
    let (mesh, sphere) = sphere_and_board(3, 0.1, 5);
    let run = |point| {
        let config = ObserveConfig {
            sample_point: point,
            ..ObserveConfig::default()
        };
        let out = extract(&session, &mesh, &poses, &config, &|_, _| {}).unwrap();
        sphere_errors(&out.samples, sphere, &scene)
    };
    let lattice = run(SamplePoint::Lattice);
    let centre = run(SamplePoint::SuperpixelCentre);
    eprintln!(
        "mean error: lattice {:.5} (max {:.4}), superpixel centre {:.5} (max {:.4})",
        lattice.mean(),
        lattice.max,
        centre.mean(),
        centre.max
    );
    assert_eq!(lattice.compared, centre.compared);
    assert!(lattice.mean() < 0.5 * centre.mean());
}
