//! Cross-module tests of the optics model: physics invariants of the full pBRDF, independent
//! re-derivations (Jones calculus, angle-based rotators), whole-domain property sweeps with
//! adversarial values, and derivative checks of the dual-number path.

mod derivatives;
mod invariants;
mod jacobian;
mod properties;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::pbrdf::{Geometry, PbrdfParams};
use super::{Real, Vec3};

pub(super) fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// Uniform random unit vector.
pub(super) fn unit(r: &mut impl Rng) -> [f64; 3] {
    loop {
        let v: [f64; 3] = [
            r.random_range(-1.0..1.0),
            r.random_range(-1.0..1.0),
            r.random_range(-1.0..1.0),
        ];
        let n2: f64 = v.iter().map(|x| x * x).sum();
        if n2 > 1e-4 && n2 <= 1.0 {
            return v.map(|x| x / n2.sqrt());
        }
    }
}

pub(super) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(super) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub(super) fn normalize(a: [f64; 3]) -> [f64; 3] {
    let n = dot(a, a).sqrt();
    a.map(|x| x / n)
}

/// A unit tangent perpendicular to `n`, in a random direction.
pub(super) fn tangent(r: &mut impl Rng, n: [f64; 3]) -> [f64; 3] {
    loop {
        let t = cross(n, unit(r));
        if dot(t, t) > 1e-6 {
            return normalize(t);
        }
    }
}

/// The direction at cosine `c` to `n`, toward tangent `t`.
pub(super) fn at_cos(n: [f64; 3], t: [f64; 3], c: f64) -> [f64; 3] {
    let s = (1.0 - c * c).max(0.0).sqrt();
    [0, 1, 2].map(|k| c * n[k] + s * t[k])
}

/// Rotates `v` about unit `axis` by `angle` (Rodrigues).
pub(super) fn rotate(v: [f64; 3], axis: [f64; 3], angle: f64) -> [f64; 3] {
    let (s, c) = angle.sin_cos();
    let kxv = cross(axis, v);
    let kdv = dot(axis, v);
    [0, 1, 2].map(|i| v[i] * c + kxv[i] * s + axis[i] * kdv * (1.0 - c))
}

/// Geometry from plain arrays (up vectors: world +y for both).
pub(super) fn geometry<T: Real>(n: [f64; 3], wi: [f64; 3], wo: [f64; 3]) -> Geometry<T> {
    geometry_up(n, wi, wo, [0.0, 1.0, 0.0], [0.0, 1.0, 0.0])
}

pub(super) fn geometry_up<T: Real>(
    n: [f64; 3],
    wi: [f64; 3],
    wo: [f64; 3],
    light_up: [f64; 3],
    camera_up: [f64; 3],
) -> Geometry<T> {
    Geometry::from_up_vectors(
        Vec3::from_f64(n),
        Vec3::from_f64(wi),
        Vec3::from_f64(wo),
        Vec3::from_f64(light_up),
        Vec3::from_f64(camera_up),
    )
    .expect("test geometry is valid")
}

/// Random valid parameters with σ in [sigma_min, 1].
pub(super) fn params(r: &mut impl Rng, sigma_min: f64) -> PbrdfParams<f64> {
    let a: f64 = r.random_range(sigma_min..=1.0);
    let b: f64 = r.random_range(sigma_min..=1.0);
    PbrdfParams {
        eta: r.random_range(1.1..2.5),
        sigma_s: a.min(b),
        sigma_ss: a.max(b),
        rho_s: r.random_range(0.0..2.0),
        rho_ss: [(); 3].map(|_| r.random_range(0.0..1.0)),
        rho_d: [(); 3].map(|_| r.random_range(0.0..1.0)),
    }
}
