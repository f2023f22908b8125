//! Throughput of the polarimetric model: full pBRDF and coaxial form, value only and value +
//! Jacobian (forward-mode duals over the 13 fit inputs). Prints evaluations per second.
//!
//! Run: `cargo bench -p ellipso-sim --bench optics`.

use std::hint::black_box;
use std::time::{Duration, Instant};

use ellipso_model::optics::coaxial::{self, CoaxialGeometry};
use ellipso_model::optics::measure::{FlashPolariser, observe};
use ellipso_model::optics::pbrdf::{Geometry, PbrdfParams, evaluate, scalar_brdf};
use ellipso_model::optics::{Frame, Vec3};

/// One prepared sample: geometry in f64 and the raw inputs.
struct Sample {
    normal: [f64; 3],
    to_light: Vec3<f64>,
    to_camera: Vec3<f64>,
    light_frame: Frame<f64>,
    camera_frame: Frame<f64>,
    params: PbrdfParams<f64>,
}

/// Deterministic xorshift so the bench needs no extra dependencies.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

fn samples(n: usize) -> Vec<Sample> {
    let mut r = Rng(0x9E37_79B9_7F4A_7C15);
    (0..n)
        .map(|_| {
            let (t, p) = (r.range(0.0, 1.2), r.range(0.0, std::f64::consts::TAU));
            let normal = [t.sin() * p.cos(), t.sin() * p.sin(), t.cos()];
            let to_camera = Vec3::from_f64([0.0, 0.0, 1.0]);
            let to_light = Vec3::from_f64([0.061, 0.0, 0.998]); // ~3.5° flash offset
            let up = Vec3::from_f64([0.0, 1.0, 0.0]);
            let light_frame = Frame::light(to_light, up).expect("valid");
            let camera_frame = Frame::camera(to_camera, up).expect("valid");
            let s = r.range(0.05, 0.5);
            let params = PbrdfParams {
                eta: r.range(1.2, 2.0),
                sigma_s: s,
                sigma_ss: r.range(s, 1.0),
                rho_s: r.range(0.0, 1.0),
                rho_ss: [r.range(0.0, 0.3); 3],
                rho_d: [r.range(0.0, 1.0), r.range(0.0, 1.0), r.range(0.0, 1.0)],
            };
            Sample {
                normal,
                to_light,
                to_camera,
                light_frame,
                camera_frame,
                params,
            }
        })
        .collect()
}

/// Runs `f` over all samples repeatedly for about `budget`; returns evaluations per second.
fn rate(samples: &[Sample], budget: Duration, mut f: impl FnMut(&Sample) -> f64) -> f64 {
    let mut evals = 0usize;
    let mut acc = 0.0;
    let start = Instant::now();
    while start.elapsed() < budget {
        for s in samples {
            acc += f(s);
        }
        evals += samples.len();
    }
    black_box(acc);
    evals as f64 / start.elapsed().as_secs_f64()
}

fn geometry<T: ellipso_model::optics::Real>(s: &Sample) -> Geometry<T> {
    Geometry::new(
        Vec3::from_f64(s.normal),
        s.to_light.cast(),
        s.to_camera.cast(),
        s.light_frame.cast(),
        s.camera_frame.cast(),
    )
    .expect("valid")
}

fn main() {
    let set = samples(4096);
    let budget = Duration::from_millis(700);
    let flash = FlashPolariser::default();
    let rows: Vec<(&str, f64)> = vec![
        (
            "full 3 lobes x RGB, 4x4 (f64)",
            rate(&set, budget, |s| {
                evaluate(&geometry::<f64>(s), &s.params).total(1).m[1][2]
            }),
        ),
        (
            "full 3 lobes x RGB, 4x4 (f32)",
            rate(&set, budget, |s| {
                f64::from(
                    evaluate(&geometry::<f32>(s), &s.params.cast::<f32>())
                        .total(1)
                        .m[1][2],
                )
            }),
        ),
        (
            "scalar BRDF M00 (f64)",
            rate(&set, budget, |s| {
                scalar_brdf(&geometry::<f64>(s), &s.params)[0]
            }),
        ),
        (
            "observation channels (f64)",
            rate(&set, budget, |s| {
                observe(&geometry::<f64>(s), &s.params, flash)[0].alpha
            }),
        ),
        (
            "coaxial DS/SS/DPa/DPb (f64)",
            rate(&set, budget, |s| {
                let g = CoaxialGeometry::from_world(Vec3::from_f64(s.normal), &s.camera_frame);
                coaxial::terms(&g, &s.params)[0].dp_alpha
            }),
        ),
    ];
    println!(
        "{:<46} {:>16} {:>12}",
        "path (per call: all RGB channels)", "evaluations/s", "ns/eval"
    );
    for (name, r) in &rows {
        println!("{name:<46} {r:>16.0} {:>12.1}", 1e9 / r);
    }
    let full = rows[0].1;
    println!("\nratios to the full f64 model (same run):");
    for (name, r) in &rows[1..] {
        println!("  {name:<44} {:>8.2}x", r / full);
    }
}
