//! Cost of the per-vertex solver (`fit::solve::fit_vertex`), single thread, in CPU-milliseconds
//! per vertex at ~75 and ~150 samples per vertex, for each solver preset, plus the accuracy the
//! preset reaches on the same vertices (η error, normal error) so speed is never quoted without
//! its price.
//!
//! Vertices: the four materials of `sim/scenes/multi_material.toml` × 4 normals, synthesised
//! through the same optics as the simulator with the scene's 12-bit sensor (shot + 2.3 e⁻ read
//! noise), orbit views at 0.5 m (elevation 20–70°), cold start (no `init`) from a normal tilted
//! by 5°. Presets are measured in interleaved rounds and reported as the median round, so a
//! burst of load from other processes hits them alike; CPU time comes from
//! `/proc/thread-self/schedstat` where available (wall time otherwise).
//! Run: `cargo bench -p ellipso-bench --bench solver`.

use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use ellipso_fit::data::{SampleGeometry, VertexGuide, VertexSamples, ViewGeometry};
use ellipso_fit::gate::GateConfig;
use ellipso_fit::solve::{SolverConfig, fit_vertex};
use ellipso_fit::synthetic::{SensorNoise, orbit_views, synthesize_vertex};
use ellipso_sim::render::radiometry::Radiometry;
use ellipso_sim::scene::Scene;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

const ROUNDS: usize = 3;

fn thread_cpu_ns() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    text.split_whitespace().next()?.parse().ok()
}

fn presets() -> Vec<(&'static str, SolverConfig)> {
    vec![
        ("reference", SolverConfig::reference()),
        ("paper", SolverConfig::paper()),
        ("default", SolverConfig::default()),
        ("fast", SolverConfig::fast()),
    ]
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|x| x / l)
}

/// Rotates `n` by `deg` about an axis perpendicular to it (the perturbed start normal).
fn tilt(n: [f64; 3], deg: f64) -> [f64; 3] {
    let a = if n[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let d = a[0] * n[0] + a[1] * n[1] + a[2] * n[2];
    let t = unit([a[0] - d * n[0], a[1] - d * n[1], a[2] - d * n[2]]);
    let (s, c) = deg.to_radians().sin_cos();
    unit([
        c * n[0] + s * t[0],
        c * n[1] + s * t[1],
        c * n[2] + s * t[2],
    ])
}

struct Case {
    views: Vec<ViewGeometry>,
    vertices: Vec<VertexSamples>,
    truth: Vec<(f64, [f64; 3])>,
}

fn case(scene: &Scene, view_count: usize) -> Case {
    let views = orbit_views(
        view_count,
        0.5,
        [20.0, 70.0],
        1.5,
        [0.0; 3],
        [0.0, 0.03, 0.0],
    );
    let radiometry = Radiometry::new(&scene.rig.camera, &scene.rig.flash, None);
    let noise = SensorNoise::from_radiometry(&radiometry, 2.3, true);
    let n = move |_: &ViewGeometry, g: &SampleGeometry| {
        radiometry.normaliser(g.light_distance_m, 0.0, 0.0)
    };
    let normals = [
        [0.0, 0.0, 1.0],
        [0.3, -0.2, 0.93],
        [-0.25, 0.35, 0.9],
        [0.1, 0.4, 0.9],
    ];
    let mut vertices = Vec::new();
    let mut truth = Vec::new();
    for (k, m) in scene.materials.iter().enumerate() {
        let p = m.params.to_pbrdf();
        for (j, normal) in normals.iter().enumerate() {
            let seed = (k * 10 + j) as u64;
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let mut v = synthesize_vertex(
                &views,
                seed as u32,
                [0.0; 3],
                unit(*normal),
                &p,
                &n,
                Some(&noise),
                true,
                &GateConfig::default(),
                &mut rng,
            );
            v.normal_world = tilt(unit(*normal), 5.0);
            vertices.push(v);
            truth.push((p.eta, unit(*normal)));
        }
    }
    Case {
        views,
        vertices,
        truth,
    }
}

fn main() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../sim/scenes/multi_material.toml");
    let scene = Scene::load(&path).expect("multi_material scene loads");
    for view_count in [77, 154] {
        let c = case(&scene, view_count);
        let samples = c.vertices.iter().map(|v| v.samples.len()).sum::<usize>() as f64
            / c.vertices.len() as f64;
        println!(
            "\n{view_count} views, {samples:.0} samples per vertex, {} vertices",
            c.vertices.len()
        );
        let presets = presets();
        let mut times: Vec<Vec<f64>> = vec![Vec::new(); presets.len()];
        let mut accuracy = vec![(0.0, 0.0, 0u32); presets.len()];
        for _ in 0..ROUNDS {
            for (p, (_, config)) in presets.iter().enumerate() {
                let cpu = thread_cpu_ns();
                let wall = Instant::now();
                let mut eta_err = 0.0;
                let mut normal_err = 0.0;
                let mut iterations = 0;
                for (v, (eta, normal)) in c.vertices.iter().zip(&c.truth) {
                    let fit = black_box(fit_vertex(
                        &c.views,
                        v,
                        true,
                        None,
                        &VertexGuide::default(),
                        config,
                    ));
                    eta_err += (fit.params.eta - eta).abs() / eta;
                    let d: f64 = (0..3).map(|i| fit.normal_world[i] * normal[i]).sum();
                    normal_err += d.clamp(-1.0, 1.0).acos().to_degrees();
                    iterations += fit.iterations;
                }
                let wall_s = wall.elapsed().as_secs_f64();
                let s = cpu
                    .zip(thread_cpu_ns())
                    .map(|(a, b)| b.saturating_sub(a) as f64 * 1e-9)
                    .filter(|s| *s > 0.0)
                    .unwrap_or(wall_s);
                times[p].push(1e3 * s / c.vertices.len() as f64);
                let n = c.vertices.len() as f64;
                accuracy[p] = (
                    100.0 * eta_err / n,
                    normal_err / n,
                    iterations / c.vertices.len() as u32,
                );
            }
        }
        for (p, (name, _)) in presets.iter().enumerate() {
            let mut t = times[p].clone();
            t.sort_by(f64::total_cmp);
            let (e, n, it) = accuracy[p];
            println!(
                "  {name:<12} {:>7.2} ms/vertex/thread (median of {ROUNDS})   mean |Δη| {e:>5.2} %   mean normal {n:>5.2}°   last-pass iterations {it}",
                t[ROUNDS / 2]
            );
        }
    }
}
