//! Benchmark: the shape update (`fit::shape::refine_positions`) on unit icospheres of 2 562 to
//! 163 842 vertices perturbed by smooth noise of 1 % of the radius, given the true normals:
//! wall time per update, CG iterations and the radial-error reduction of one and two updates,
//! plus the mesh rebuild (normals + BVH) per update.
//!
//! Run: `cargo bench -p ellipso-fit --bench shape` (release) or add `--profile dev` for the
//! test profile. Prints a table; no assertions.

use std::time::Instant;

use ellipso_fit::shape::{ShapeConfig, mesh_with_positions, perturb_mesh, refine_positions};
use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::procedural::icosphere;
use nalgebra::Point3;

fn radial_rms(positions: &[Point3<f64>]) -> f64 {
    let sum: f64 = positions
        .iter()
        .map(|p| (p.coords.norm() - 1.0).powi(2))
        .sum();
    (sum / positions.len() as f64).sqrt()
}

fn main() {
    let config = ShapeConfig {
        max_displacement_m: f64::INFINITY,
        max_cg_iterations: 5000,
        ..ShapeConfig::default()
    };
    println!(
        "| vertices | update ms | rebuild ms | CG iterations | radial RMS 1 update | 2 updates |"
    );
    println!("|---:|---:|---:|---:|---:|---:|");
    for subdivisions in 4..=7 {
        let (dirs, faces) = icosphere(subdivisions);
        let positions = dirs.iter().map(|d| Point3::from(d.into_inner())).collect();
        let sphere = TriangleMesh::new(positions, None, None, faces).expect("valid icosphere");
        let mut mesh = perturb_mesh(&sphere, 0.01, 1);
        let before = radial_rms(mesh.positions());
        let ones = vec![1.0; mesh.positions().len()];
        let (mut update_ms, mut rebuild_ms, mut iterations, mut factors) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for _ in 0..2 {
            let normals: Vec<[f64; 3]> = mesh
                .positions()
                .iter()
                .map(|p| p.coords.normalize().into())
                .collect();
            let t = Instant::now();
            let update = refine_positions(&mesh, &normals, &ones, &config).expect("valid");
            update_ms.push(t.elapsed().as_secs_f64() * 1e3);
            iterations.push(update.cg_iterations);
            factors.push(before / radial_rms(&update.positions));
            let t = Instant::now();
            mesh = mesh_with_positions(&mesh, update.positions).expect("same size");
            rebuild_ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
        println!(
            "| {} | {:.1} | {:.1} | {} / {} | {:.1}× | {:.1}× |",
            ones.len(),
            update_ms[0],
            rebuild_ms[0],
            iterations[0],
            iterations[1],
            factors[0],
            factors[1]
        );
    }
}
