use super::*;
use ellipso_sim::geometry::procedural::icosphere;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn unit_sphere(subdivisions: u32) -> TriangleMesh {
    let (dirs, faces) = icosphere(subdivisions);
    let positions = dirs.iter().map(|d| Point3::from(d.into_inner())).collect();
    TriangleMesh::new(positions, None, None, faces).expect("icosphere is valid")
}

fn radial_rms(positions: &[Point3<f64>]) -> f64 {
    (positions.iter().map(|p| (p.coords.norm() - 1.0).powi(2)).sum::<f64>() / positions.len() as f64).sqrt()
}

/// RMS radial error after removing the best r0 + t·d (scale and translation, first order).
fn shape_rms(positions: &[Point3<f64>]) -> f64 {
    let mut ata = nalgebra::Matrix4::<f64>::zeros();
    let mut atb = nalgebra::Vector4::<f64>::zeros();
    for p in positions {
        let d = p.coords.normalize();
        let row = nalgebra::Vector4::new(1.0, d.x, d.y, d.z);
        ata += row * row.transpose();
        atb += row * (p.coords.norm() - 1.0);
    }
    let x = ata.lu().solve(&atb).unwrap();
    (positions.iter().map(|p| { let d = p.coords.normalize(); (p.coords.norm() - 1.0 - x[0] - x[1]*d.x - x[2]*d.y - x[3]*d.z).powi(2)}).sum::<f64>() / positions.len() as f64).sqrt()
}

fn radial_normals(positions: &[Point3<f64>], noise_deg: f64, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    positions.iter().map(|p| {
        let s = noise_deg.to_radians() / 3f64.sqrt();
        let j = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)) * s * 3f64.sqrt();
        (p.coords.normalize() + j).normalize().into()
    }).collect()
}

#[test]
fn explore() {
    for sub in [4u32] {
        let sphere = unit_sphere(sub);
        let noisy = perturb_mesh(&sphere, 0.01, 1);
        let before = radial_rms(noisy.positions());
        println!("before radial {before:.5} shape {:.5}", shape_rms(noisy.positions()));
        for noise in [0.0, 1.0, 3.0] {
        for (lp, ls) in [(0.001, 0.02), (0.003, 0.02), (0.01, 0.02), (0.03, 0.02), (0.01, 0.1), (0.01, 0.3)] {
            let cfg = ShapeConfig { lambda_position: lp, lambda_smooth: ls, max_displacement_m: f64::INFINITY, ..ShapeConfig::default() };
            let n = radial_normals(noisy.positions(), noise, 5);
            let c = vec![1.0; n.len()];
            let u = refine_positions(&noisy, &n, &c, &cfg).unwrap();
            let n2 = radial_normals(&u.positions, noise, 6);
            let u2 = refine_positions(&mesh_with_positions(&noisy, u.positions.clone()).unwrap(), &n2, &c, &cfg).unwrap();
            println!("noise {noise} lp {lp} ls {ls}: radial {:.5} (x{:.1}) shape {:.5} | twice radial {:.5} (x{:.1}) shape {:.5} iters {}",
                radial_rms(&u.positions), before / radial_rms(&u.positions), shape_rms(&u.positions), radial_rms(&u2.positions), before/radial_rms(&u2.positions), shape_rms(&u2.positions), u.cg_iterations);
        }
        }
    }
}
