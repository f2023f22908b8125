//! The generator's shapes: closed star-shaped meshes over an icosphere's directions, of three
//! kinds — a bumpy blob, a creased solid with flat faces, and a blob with a concave bowl — and
//! their material patches, grown to a given share of the surface area.
//!
//! Contract:
//! - [`radial_mesh`] places every icosphere direction `d` at `radius(d) · d`; every radius
//!   function here is positive and finite, so the mesh is closed, watertight and wound
//!   counter-clockwise from outside like the icosphere.
//! - [`ShapeKind::radius`] draws its parameters from the caller's generator (deterministic per
//!   seed). The unit shapes span radii of about 0.6–1.5.
//! - [`grow_patches`] labels every vertex with a patch id: patch `k` (but the last) is grown
//!   breadth-first over the mesh's edges from a seeded vertex until its vertex area (a third of
//!   every incident triangle's) reaches `fractions[k]` of the total, so it overshoots by less
//!   than one vertex's area; patches are grown smallest first so a small one stays one compact
//!   piece; the last patch takes what is left. A patch that runs out of room continues from a
//!   new seed (it may then be in several pieces).

use nalgebra::{Point3, Unit, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::collections::VecDeque;

use ellipso_model::geometry::procedural::icosphere;

/// A unit shape's radius along a unit direction.
pub type RadiusFn = Box<dyn Fn(&Vector3<f64>) -> f64>;

/// Which kind of shape a generated object has.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShapeKind {
    /// Smooth seeded bumps on a sphere.
    BumpyBlob,
    /// A rounded box (superellipsoid: flat faces meeting at rounded edges) cut by one plane (a
    /// flat face meeting the rest at a sharp crease).
    Creased,
    /// A gently bumpy blob with one deep bowl: a concave part whose rim shadows it.
    Concave,
}

impl ShapeKind {
    /// All kinds, in the order the generator draws them.
    pub const ALL: [ShapeKind; 3] = [ShapeKind::BumpyBlob, ShapeKind::Creased, ShapeKind::Concave];

    /// Name as the report writes it.
    pub fn name(self) -> &'static str {
        match self {
            ShapeKind::BumpyBlob => "bumpy_blob",
            ShapeKind::Creased => "creased",
            ShapeKind::Concave => "concave",
        }
    }

    /// A radius function of this kind with parameters drawn from `rng` (module doc).
    pub fn radius(self, rng: &mut ChaCha8Rng) -> RadiusFn {
        match self {
            ShapeKind::BumpyBlob => {
                // Eight bumps of relative height ≤ 0.09: the radius stays within 1 ± 0.72.
                let amplitude = rng.random_range(0.04..0.09);
                Box::new(bumps(rng, amplitude, 8))
            }
            ShapeKind::Creased => {
                let axes = [
                    rng.random_range(0.8..1.2),
                    rng.random_range(0.8..1.2),
                    rng.random_range(0.7..1.1),
                ];
                let exponent: f64 = rng.random_range(4.0..8.0);
                let cut = random_direction(rng);
                // The cut plane's distance from the centre, ≥ 0.55: it removes a cap, never the
                // centre, so the solid stays star-shaped about it.
                let cut_distance = rng.random_range(0.55..0.8);
                Box::new(move |d: &Vector3<f64>| {
                    let s: f64 = (0..3).map(|i| (d[i] / axes[i]).abs().powf(exponent)).sum();
                    let r = s.powf(-1.0 / exponent);
                    let c = cut.dot(d);
                    if c > 1e-9 { r.min(cut_distance / c) } else { r }
                })
            }
            ShapeKind::Concave => {
                let amplitude = rng.random_range(0.02..0.05);
                let base = bumps(rng, amplitude, 6);
                // The bowl faces sideways or up (z of its axis in [-0.2, 0.7]) so views from
                // 20–70° elevation look into it.
                let z: f64 = rng.random_range(-0.2..0.7);
                let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
                let r = (1.0 - z * z).sqrt();
                let axis = Vector3::new(r * a.cos(), r * a.sin(), z);
                // Depth 0.3–0.45 over a width of 0.4–0.6 rad: at the bowl's centre
                // r² + 2r'² − r·r'' < 0 (r'' = 2·depth/width²), i.e. the surface is concave.
                let depth = rng.random_range(0.3..0.45);
                let width: f64 = rng.random_range(0.4..0.6);
                Box::new(move |d: &Vector3<f64>| {
                    let angle = axis.dot(d).clamp(-1.0, 1.0).acos();
                    base(d) * (1.0 - depth * (-(angle / width).powi(2)).exp())
                })
            }
        }
    }
}

/// `1 + amplitude · Σ ±exp(−(angle/width)²)` over `count` seeded centres.
fn bumps(
    rng: &mut ChaCha8Rng,
    amplitude: f64,
    count: usize,
) -> impl Fn(&Vector3<f64>) -> f64 + use<> {
    let centres: Vec<(Vector3<f64>, f64, f64)> = (0..count)
        .map(|_| {
            let sign = if rng.random::<bool>() { 1.0 } else { -1.0 };
            (random_direction(rng), sign, rng.random_range(0.25f64..0.5))
        })
        .collect();
    move |d: &Vector3<f64>| {
        1.0 + amplitude
            * centres
                .iter()
                .map(|(c, s, w)| s * (-(c.dot(d).clamp(-1.0, 1.0).acos() / w).powi(2)).exp())
                .sum::<f64>()
    }
}

/// A uniformly distributed unit vector.
pub fn random_direction(rng: &mut ChaCha8Rng) -> Vector3<f64> {
    let z: f64 = rng.random_range(-1.0..1.0);
    let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vector3::new(r * a.cos(), r * a.sin(), z)
}

/// The icosphere of `subdivisions` with each direction moved to `radius(d)` (module doc).
pub fn radial_mesh(
    subdivisions: u32,
    radius: &dyn Fn(&Vector3<f64>) -> f64,
) -> (Vec<Point3<f64>>, Vec<[u32; 3]>) {
    let (dirs, faces) = icosphere(subdivisions);
    let positions = dirs
        .iter()
        .map(|d: &Unit<Vector3<f64>>| Point3::from(d.into_inner() * radius(d)))
        .collect();
    (positions, faces)
}

/// Per vertex, a third of the area of every incident triangle.
pub fn vertex_areas(positions: &[Point3<f64>], faces: &[[u32; 3]]) -> Vec<f64> {
    let mut area = vec![0.0; positions.len()];
    for f in faces {
        let [a, b, c] = f.map(|i| positions[i as usize]);
        let third = (b - a).cross(&(c - a)).norm() / 6.0;
        for &i in f {
            area[i as usize] += third;
        }
    }
    area
}

/// Patch id per vertex for the area `fractions` (module doc; they should sum to 1).
pub fn grow_patches(
    positions: &[Point3<f64>],
    faces: &[[u32; 3]],
    fractions: &[f64],
    rng: &mut ChaCha8Rng,
) -> Vec<u32> {
    let n = positions.len();
    let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); n];
    for f in faces {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            if !neighbours[a as usize].contains(&b) {
                neighbours[a as usize].push(b);
                neighbours[b as usize].push(a);
            }
        }
    }
    let area = vertex_areas(positions, faces);
    let total: f64 = area.iter().sum();
    let last = fractions.len().saturating_sub(1) as u32;
    let mut label: Vec<Option<u32>> = vec![None; n];
    let mut order: Vec<usize> = (0..fractions.len().saturating_sub(1)).collect();
    order.sort_by(|&a, &b| fractions[a].total_cmp(&fractions[b]));
    for k in order {
        let target = fractions[k] * total;
        let mut grown = 0.0;
        while grown < target {
            let free: Vec<usize> = (0..n).filter(|&v| label[v].is_none()).collect();
            if free.is_empty() {
                break;
            }
            let seed = free[rng.random_range(0..free.len())];
            let mut queue = VecDeque::from([seed]);
            label[seed] = Some(k as u32);
            grown += area[seed];
            while grown < target {
                let Some(v) = queue.pop_front() else { break };
                for &w in &neighbours[v] {
                    if grown >= target {
                        break;
                    }
                    if label[w as usize].is_none() {
                        label[w as usize] = Some(k as u32);
                        grown += area[w as usize];
                        queue.push_back(w as usize);
                    }
                }
            }
        }
    }
    label.into_iter().map(|l| l.unwrap_or(last)).collect()
}
