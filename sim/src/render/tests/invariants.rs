//! Physics invariants of the renderer: the per-lobe shading paths equal the optics module's
//! reference functions, analyser consistency I0 + I90 = I45 + I135, the S0-only camera sees the
//! same value behind every analyser, and the co-/cross-polarised highlight of a glossy sphere
//! (docs/model.md §6 "Observation channels", rig check).

use super::super::shade::{PixelSensor, PoseContext};
use super::super::tests::{scene_edited, scene_path, small, without_effects};
use super::super::*;
use crate::effects::LightTransport;
use crate::scene::{Scene, SurfaceKind};
use ellipso_model::optics::measure::Analyser;
use ellipso_model::optics::pbrdf::{self, Geometry};
use ellipso_model::optics::{Stokes, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const MONO: [f64; 3] = [1.0 / 3.0; 3];

fn v3(v: &Vector3<f64>) -> Vec3<f64> {
    Vec3::new(v.x, v.y, v.z)
}

/// Random rays from frame 0's camera that hit an object, with their hits.
fn object_hits(scene: &Scene, n: usize) -> Vec<(Ray, crate::scene::SceneHit)> {
    let pose = scene.camera_poses[0].world_from_camera;
    let model = scene.rig.camera.camera_model();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut out = Vec::new();
    for _ in 0..200_000 {
        if out.len() == n {
            break;
        }
        let u = rng.random_range(0.0..f64::from(model.width));
        let v = rng.random_range(0.0..f64::from(model.height));
        let d = model.unproject_to_ray([u, v]).unwrap().into_inner();
        let ray = Ray::new(pose.translation.vector.into(), pose.rotation * d);
        if let Some(hit) = scene.intersect(&ray, 0.0, f64::INFINITY)
            && matches!(hit.kind, SurfaceKind::Object { .. })
        {
            out.push((ray, hit));
        }
    }
    assert_eq!(out.len(), n, "too few object hits");
    out
}

/// A scene whose sphere has every lobe, under each (analysers, polarised flash) combination.
fn lobed_scene(analysers: bool, polarised: bool) -> Scene {
    scene_edited("s0_only.toml", |t| {
        t.replace("rho_ss = [0.0, 0.0, 0.0]", "rho_ss = [0.3, 0.2, 0.1]")
            .replace("rho_d = [0.5, 0.5, 0.5]", "rho_d = [0.5, 0.3, 0.2]")
            .replace("analysers = false", &format!("analysers = {analysers}"))
            .replace("polarised = false", &format!("polarised = {polarised}"))
    })
}

#[test]
fn lobe_paths_equal_the_optics_reference_functions() {
    for (analysers, polarised, transport) in [
        (true, true, LightTransport::Stokes),
        (true, false, LightTransport::Stokes),
        (false, true, LightTransport::IntensityOfPolarised),
        (false, false, LightTransport::Scalar),
    ] {
        let scene = lobed_scene(analysers, polarised);
        let r = Renderer::new(&scene, small(64, 48)).unwrap();
        assert_eq!(r.plan().transport, transport);
        let shader = r.shader();
        let ctx = PoseContext::new(&scene, scene.camera_poses[0].world_from_camera);
        let params = r.materials[0];
        for (ray, hit) in object_hits(&scene, 40) {
            let n = hit.hit.normal_shading.into_inner();
            let to_light = (ctx.flash_world - hit.hit.point).normalize();
            let to_camera = -ray.dir;
            let light_up = match ctx.polariser_axis_world {
                Some(a) => (-to_light).cross(&a),
                None => ctx.camera_up_world,
            };
            let g = Geometry::from_up_vectors(
                v3(&n),
                v3(&to_light),
                v3(&to_camera),
                v3(&light_up),
                v3(&ctx.camera_up_world),
            )
            .unwrap();
            let s_light = Stokes::new(1.0, if polarised { 1.0 } else { 0.0 }, 0.0, 0.0);
            for angle in Analyser::SENSOR_ANGLES_DEG {
                let pixel = PixelSensor::new(angle.to_radians(), MONO);
                let got = shader.object(
                    &ctx,
                    n,
                    to_light,
                    to_camera,
                    &params,
                    &pixel,
                    &mut StageCounts::default(),
                );
                let reference: f64 = match transport {
                    LightTransport::Stokes => pbrdf::apply(&g, &params, s_light)
                        .iter()
                        .map(|s| Analyser::from_deg(angle).intensity(*s) / 3.0)
                        .sum(),
                    LightTransport::IntensityOfPolarised => {
                        pbrdf::evaluate_s0(&g, &params, s_light).iter().sum::<f64>() / 3.0
                    }
                    LightTransport::Scalar => {
                        pbrdf::scalar_brdf(&g, &params).iter().sum::<f64>() / 3.0
                    }
                };
                assert!(
                    (got - reference).abs() <= 1e-12 * reference.abs().max(1.0),
                    "{transport:?} at {angle}°: {got} vs {reference}"
                );
            }
        }
    }
}

#[test]
fn analysers_are_consistent_and_an_s0_camera_sees_one_value_behind_all_four() {
    for analysers in [true, false] {
        let scene = lobed_scene(analysers, true);
        let mut r = Renderer::new(&scene, small(64, 48)).unwrap();
        // With extinction too, the consistency sum holds.
        r.set = r.set.with(crate::effects::Stage::PolariserExtinction);
        let shader = r.shader();
        let ctx = PoseContext::new(&scene, scene.camera_poses[0].world_from_camera);
        let mut polarised_seen = 0;
        for (ray, hit) in object_hits(&scene, 40) {
            let i: Vec<f64> = Analyser::SENSOR_ANGLES_DEG
                .iter()
                .map(|a| {
                    let px = PixelSensor::new(a.to_radians(), MONO);
                    shader.sample(&ctx, &ray, &hit, &px, &mut StageCounts::default())
                })
                .collect();
            let scale = i.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-300);
            assert!((i[0] + i[2] - i[1] - i[3]).abs() <= 1e-12 * scale, "{i:?}");
            if analysers {
                polarised_seen += usize::from((i[0] - i[2]).abs() > 1e-3 * scale);
            } else {
                assert!(i.iter().all(|v| *v == i[0]), "S0 camera: {i:?}");
            }
        }
        if analysers {
            assert!(polarised_seen > 10, "analysers saw no polarisation");
        }
    }
}

#[test]
fn rendered_board_superpixels_obey_the_consistency_sum() {
    let scene = scene_edited("sphere.toml", without_effects);
    let opts = RenderOptions {
        pixel_truth: true,
        ..small(128, 96)
    };
    let f = Renderer::new(&scene, opts)
        .unwrap()
        .render_frame(0)
        .unwrap();
    let truth = f.pixels.as_ref().unwrap();
    let mut checked = 0;
    for sy in 0..48usize {
        for sx in 0..64usize {
            let idx = |dx: usize, dy: usize| (2 * sy + dy) * 128 + 2 * sx + dx;
            let all = [idx(0, 0), idx(1, 0), idx(0, 1), idx(1, 1)];
            if all
                .iter()
                .any(|&i| truth.material[i] != BOARD_MATERIAL_BASE)
            {
                continue;
            }
            let v = all.map(|i| f64::from(f.dn[i]));
            // Only uniform print areas (all four within 3 % of each other).
            let (lo, hi) = (
                v.iter().copied().fold(f64::MAX, f64::min),
                v.iter().copied().fold(0.0, f64::max),
            );
            if lo < 50.0 || hi > 1.03 * lo {
                continue;
            }
            // (I90, I45, I135, I0) at (0,0), (1,0), (0,1), (1,1).
            let residual = v[3] + v[0] - v[1] - v[2];
            assert!(
                residual.abs() <= 2.0 + 0.01 * hi,
                "superpixel ({sx}, {sy}): {v:?}"
            );
            checked += 1;
        }
    }
    assert!(checked > 200, "only {checked} white superpixels");
}

#[test]
fn glossy_highlight_is_co_polarised() {
    // The sphere scene's glass ball: ρ_s = 1, σ_s = 0.05, flash polariser parallel to 0°.
    let scene = scene_edited("sphere.toml", |t| {
        without_effects(t)
            + "\n[effects]\nquantisation = {}\npolariser_extinction = { ratio = 300.0 }\n"
    });
    let opts = RenderOptions {
        pixel_truth: true,
        supersampling: 2,
        resolution_px: Some([256, 214]),
        ..RenderOptions::default()
    };
    let f = Renderer::new(&scene, opts)
        .unwrap()
        .render_frame(0)
        .unwrap();
    let truth = f.pixels.as_ref().unwrap();
    let (mut best_i0, mut best_i90) = (0.0f32, 0.0f32);
    for sy in 0..107usize {
        for sx in 0..128usize {
            let i90 = (2 * sy) * 256 + 2 * sx;
            let i0 = (2 * sy + 1) * 256 + 2 * sx + 1;
            if truth.material[i0] != 0 || truth.material[i90] != 0 {
                continue;
            }
            if f.dn[i0] > best_i0 {
                (best_i0, best_i90) = (f.dn[i0], f.dn[i90]);
            }
        }
    }
    assert!(best_i0 > 500.0, "no highlight: {best_i0}");
    assert!(
        best_i90 * 10.0 < best_i0,
        "highlight I0 {best_i0}, I90 {best_i90}"
    );
    let _ = scene_path("sphere.toml");
}
