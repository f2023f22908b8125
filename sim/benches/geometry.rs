//! Geometry throughput: BVH build, BVH vs brute-force ray casting, board albedo lookups and
//! whole-scene queries. Prints a table; figures are ratios within one run on one machine.
//!
//! Run: `cargo bench -p ellipso-sim --bench geometry`

use ellipso_model::geometry::procedural::bumpy_icosphere;
use ellipso_model::geometry::{Intersect, Ray, TriangleMesh};
use ellipso_sim::scene::Scene;
use nalgebra::{Point2, Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

fn random_rays(n: usize, seed: u64) -> Vec<Ray> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let o = Point3::new(
                rng.random_range(-3.0..3.0),
                rng.random_range(-3.0..3.0),
                3.0,
            );
            let t = Point3::new(
                rng.random_range(-1.2..1.2),
                rng.random_range(-1.2..1.2),
                0.0,
            );
            Ray::new(o, t - o)
        })
        .collect()
}

fn rate(count: usize, seconds: f64) -> String {
    format!("{:>12.3} M/s", count as f64 / seconds / 1e6)
}

fn main() {
    println!("| case | triangles | mesh + BVH build ms | throughput |");
    println!("|---|---|---|---|");
    for subdiv in [4u32, 6] {
        let generated = bumpy_icosphere(subdiv, 0.06, 4, 1);
        // Time construction alone: normals check + BVH build from the generated arrays.
        let t0 = Instant::now();
        let mesh = TriangleMesh::new(
            generated.positions().to_vec(),
            Some(generated.normals().iter().map(|n| n.into_inner()).collect()),
            generated.regions().map(<[u32]>::to_vec),
            generated.triangles().to_vec(),
        )
        .expect("valid mesh");
        let build_ms = t0.elapsed().as_secs_f64() * 1e3;
        let rays = random_rays(200_000, 2);
        let t0 = Instant::now();
        let hits = rays
            .iter()
            .filter(|r| mesh.intersect(r, 0.0, f64::INFINITY).is_some())
            .count();
        let bvh_s = t0.elapsed().as_secs_f64();
        println!(
            "| BVH nearest hit ({hits} of {} rays hit) | {} | {build_ms:.1} | {} |",
            rays.len(),
            mesh.triangles().len(),
            rate(rays.len(), bvh_s)
        );
        let t0 = Instant::now();
        let occ = rays
            .iter()
            .filter(|r| mesh.occluded(r, 0.0, f64::INFINITY))
            .count();
        let occ_s = t0.elapsed().as_secs_f64();
        assert_eq!(occ, hits);
        println!(
            "| BVH any hit (shadow) | {} | | {} |",
            mesh.triangles().len(),
            rate(rays.len(), occ_s)
        );
        if subdiv == 4 {
            let few = &rays[..2_000];
            let t0 = Instant::now();
            let n = few
                .iter()
                .filter(|r| mesh.intersect_brute_force(r, 0.0, f64::INFINITY).is_some())
                .count();
            let brute_s = t0.elapsed().as_secs_f64();
            black_box(n);
            let brute_per_ray = brute_s / few.len() as f64;
            let bvh_per_ray = bvh_s / rays.len() as f64;
            println!(
                "| brute force nearest hit | {} | | {} (BVH is {:.0}× faster) |",
                mesh.triangles().len(),
                rate(few.len(), brute_s),
                brute_per_ray / bvh_per_ray
            );
        }
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let scene = Scene::load(&root.join("scenes/multi_material.toml")).expect("shipped scene loads");
    let board = &scene.boards[0].board;
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let pts: Vec<Point2<f64>> = (0..1_000_000)
        .map(|_| {
            Point2::new(
                rng.random_range(-0.15..0.15),
                rng.random_range(-0.105..0.105),
            )
        })
        .collect();
    let t0 = Instant::now();
    let sum: f64 = pts.iter().map(|p| board.albedo_at(p) as f64).sum();
    let s = t0.elapsed().as_secs_f64();
    black_box(sum);
    println!(
        "| Board::albedo_at (16 tags) | | | {} |",
        rate(pts.len(), s)
    );
    let pose = scene.camera_poses[0];
    let eye = pose.world_from_camera * Point3::origin();
    let cam = &scene.rig.camera;
    let (w, h) = (
        cam.resolution_px[0] as usize / 4,
        cam.resolution_px[1] as usize / 4,
    );
    let t0 = Instant::now();
    let mut hits = 0usize;
    for v in 0..h {
        for u in 0..w {
            let x = (u as f64 * 4.0 + 1.5 - cam.intrinsics.cx) / cam.intrinsics.fx;
            let y = (v as f64 * 4.0 + 1.5 - cam.intrinsics.cy) / cam.intrinsics.fy;
            let dir = pose.world_from_camera * Vector3::new(x, y, 1.0);
            hits += usize::from(
                scene
                    .intersect(&Ray::new(eye, dir), 0.0, f64::INFINITY)
                    .is_some(),
            );
        }
    }
    let s = t0.elapsed().as_secs_f64();
    println!(
        "| Scene::intersect, multi_material, camera 0 ({hits} of {} hit) | 5120 | | {} |",
        w * h,
        rate(w * h, s)
    );
}
