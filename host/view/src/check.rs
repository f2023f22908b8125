//! The shader port's check: a seeded grid of geometries and materials, with the Rust model's
//! Mueller matrices, for the page `check.html` to evaluate in GLSL and compare.
//!
//! Contract: [`cases`] is deterministic (seed [`SEED`]) and stays inside the domain where single
//! precision is conditioned (the same bounds as the simulator's f32-vs-f64 test, docs/model.md
//! §8): every cosine n·ω_i, n·ω_o ≥ 0.05, σ ≥ 0.05, η ∈ [1.01, 2.5]. It mixes random geometries
//! with the rig's hard cases: the 3.5° near-coaxial flash, a view at Brewster's angle, grazing
//! 87°, and normal incidence. [`reference`] evaluates `ellipso_model::optics::pbrdf::evaluate` in
//! f64 — the same function `ellipso model mueller` prints — and sums the lobes per colour channel.
//! [`relative_error`] is the measure the tolerance ([`TOLERANCE`]) applies to: the largest
//! element difference over the largest element of the reference matrix.

use ellipso_model::optics::Vec3;
use ellipso_model::optics::pbrdf::{Geometry, PbrdfParams, evaluate};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Seed of the grid.
pub const SEED: u64 = 21;

/// Agreement the shader port must reach: 1e-3 of the matrix's largest element.
pub const TOLERANCE: f64 = 1e-3;

/// One geometry and material.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CheckCase {
    /// Surface normal (world, unit).
    pub normal: [f64; 3],
    /// Surface → light (unit).
    pub to_light: [f64; 3],
    /// Surface → camera (unit).
    pub to_camera: [f64; 3],
    /// Light-frame up vector.
    pub light_up: [f64; 3],
    /// Camera-frame up vector (image up).
    pub camera_up: [f64; 3],
    /// η, σ_s, σ_ss, ρ_s, ρ_ss RGB, ρ_d RGB.
    pub params: [f64; 10],
}

impl CheckCase {
    /// The parameters as the model's struct.
    pub fn pbrdf(&self) -> PbrdfParams<f64> {
        let p = self.params;
        PbrdfParams {
            eta: p[0],
            sigma_s: p[1],
            sigma_ss: p[2],
            rho_s: p[3],
            rho_ss: [p[4], p[5], p[6]],
            rho_d: [p[7], p[8], p[9]],
        }
    }
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|x| x / n)
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// A direction at `theta` from +z with azimuth `phi` (radians).
fn polar(theta: f64, phi: f64) -> [f64; 3] {
    [
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    ]
}

/// The grid: `n_random` random cases plus the fixed hard ones.
pub fn cases(n_random: usize) -> Vec<CheckCase> {
    let mut rng = ChaCha8Rng::seed_from_u64(SEED);
    let mut out = Vec::with_capacity(n_random + 8);
    let material = |rng: &mut ChaCha8Rng| {
        let sigma_s: f64 = rng.random_range(0.05..0.6);
        let c = |rng: &mut ChaCha8Rng| rng.random_range(0.0..0.8);
        [
            rng.random_range(1.01..2.5),
            sigma_s,
            rng.random_range(sigma_s..1.0),
            rng.random_range(0.0..2.0),
            c(rng),
            c(rng),
            c(rng),
            c(rng),
            c(rng),
            c(rng),
        ]
    };
    let up = [0.0, 1.0, 0.0];
    // fixed hard cases: head-on coaxial-ish, the rig's 3.5° offset at several tilts, Brewster,
    // grazing
    let eta = 1.5f64;
    for (theta_o_deg, offset_deg) in [(0.0, 3.5), (30.0, 3.5), (60.0, 3.5), (80.0, 3.5)] {
        let to_camera = polar(f64::to_radians(theta_o_deg), 0.3);
        let to_light = polar(f64::to_radians(theta_o_deg + offset_deg), 0.3);
        out.push(CheckCase {
            normal: [0.0, 0.0, 1.0],
            to_light,
            to_camera,
            light_up: up,
            camera_up: up,
            params: [eta, 0.1, 0.3, 1.0, 0.1, 0.2, 0.3, 0.5, 0.4, 0.3],
        });
    }
    let brewster = eta.atan();
    out.push(CheckCase {
        normal: [0.0, 0.0, 1.0],
        to_light: polar(brewster, 0.0),
        to_camera: polar(brewster, std::f64::consts::PI),
        light_up: up,
        camera_up: [0.2, 0.9, 0.1],
        params: [eta, 0.2, 0.4, 1.0, 0.05, 0.05, 0.05, 0.3, 0.3, 0.3],
    });
    out.push(CheckCase {
        normal: [0.0, 0.0, 1.0],
        to_light: polar(f64::to_radians(87.0), 1.0),
        to_camera: polar(f64::to_radians(86.0), 1.2),
        light_up: [0.0, 0.0, 1.0],
        camera_up: [0.0, 0.0, 1.0],
        params: [1.3, 0.3, 0.5, 1.0, 0.2, 0.2, 0.2, 0.2, 0.3, 0.4],
    });
    while out.len() < n_random + 6 {
        let rand_dir = |rng: &mut ChaCha8Rng| {
            let z: f64 = rng.random_range(-1.0..1.0);
            let phi: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            let r = (1.0 - z * z).sqrt();
            [r * phi.cos(), r * phi.sin(), z]
        };
        let normal = rand_dir(&mut rng);
        let to_light = rand_dir(&mut rng);
        let to_camera = rand_dir(&mut rng);
        if dot(normal, to_light) < 0.05 || dot(normal, to_camera) < 0.05 {
            continue;
        }
        let light_up = unit(rand_dir(&mut rng));
        let camera_up = unit(rand_dir(&mut rng));
        let params = material(&mut rng);
        out.push(CheckCase {
            normal,
            to_light,
            to_camera,
            light_up,
            camera_up,
            params,
        });
    }
    out
}

/// The model's total Mueller matrix per colour channel (row-major 4×4), f64.
pub fn reference(case: &CheckCase) -> [[f64; 16]; 3] {
    let v = Vec3::<f64>::from_f64;
    let Ok(g) = Geometry::from_up_vectors(
        v(case.normal),
        v(case.to_light),
        v(case.to_camera),
        v(case.light_up),
        v(case.camera_up),
    ) else {
        return [[f64::NAN; 16]; 3];
    };
    let lobes = evaluate(&g, &case.pbrdf());
    std::array::from_fn(|c| {
        let m = lobes.total(c).m;
        std::array::from_fn(|k| m[k / 4][k % 4])
    })
}

/// max_ij |got − want| / max_ij |want| (0 when both are zero).
pub fn relative_error(got: &[f64; 16], want: &[f64; 16]) -> f64 {
    let scale = want.iter().fold(0f64, |m, x| m.max(x.abs()));
    let diff = got
        .iter()
        .zip(want)
        .fold(0f64, |m, (a, b)| m.max((a - b).abs()));
    if scale > 0.0 {
        diff / scale
    } else if diff == 0.0 {
        0.0
    } else {
        f64::INFINITY
    }
}

/// The grid with its reference values, as the check page fetches it.
pub fn payload(n_random: usize) -> serde_json::Value {
    let cases = cases(n_random);
    let reference: Vec<[[f64; 16]; 3]> = cases.iter().map(reference).collect();
    serde_json::json!({ "cases": cases, "reference": reference, "tolerance": TOLERANCE })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_is_deterministic_in_domain_and_finite() {
        let a = cases(64);
        let b = cases(64);
        assert_eq!(a.len(), 70);
        assert_eq!(
            serde_json::to_string(&a).unwrap(),
            serde_json::to_string(&b).unwrap()
        );
        for c in &a {
            assert!(dot(unit(c.normal), unit(c.to_light)) >= 0.049);
            assert!(dot(unit(c.normal), unit(c.to_camera)) >= 0.049);
            c.pbrdf().validate().unwrap();
            let r = reference(c);
            assert!(r.iter().flatten().all(|x| x.is_finite()));
            assert!(r[0][0] > 0.0, "front-facing cases reflect light");
        }
    }

    #[test]
    fn relative_error_is_scaled_by_the_largest_element() {
        let mut want = [0.0; 16];
        want[0] = 2.0;
        want[5] = -1.0;
        let mut got = want;
        got[5] = -1.002;
        assert!((relative_error(&got, &want) - 0.001).abs() < 1e-12);
        assert_eq!(relative_error(&[0.0; 16], &[0.0; 16]), 0.0);
    }
}
