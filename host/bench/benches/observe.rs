//! Benchmark: observation extraction (`fit::observe::extract`) on sessions rendered from the
//! shipped sphere scene (noise on) at two resolutions, for a sphere + board mesh: ms per view
//! per 1000 vertices, samples per second, and the accounted peak memory, on 1 and 2 threads.
//!
//! Run: `cargo bench -p ellipso-bench --bench observe`. Prints a table; no assertions.

use std::path::Path;
use std::time::Instant;

use ellipso_fit::observe::{ObserveConfig, extract};
use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::procedural::icosphere;
use ellipso_session::manifest::{Manifest, SensorInfo, SessionSource};
use ellipso_session::reader;
use ellipso_session::time::HostTimeUs;
use ellipso_session::writer::{FrameRecord, SessionWriter};
use ellipso_sim::render::{RenderOptions, Renderer};
use ellipso_sim::scene::Scene;
use nalgebra::{Isometry3, Point3, Vector3};

const VIEWS: usize = 8;

/// Renders the first `VIEWS` poses of the sphere scene at `resolution` into a session.
fn session(dir: &Path, resolution: [u32; 2]) -> Vec<(u64, Isometry3<f64>)> {
    let scene_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../sim/scenes/sphere.toml");
    let scene = Scene::load(&scene_path).expect("sphere scene");
    let options = RenderOptions {
        supersampling: 1,
        resolution_px: Some(resolution),
        ..RenderOptions::default()
    };
    let renderer = Renderer::new(&scene, options).expect("renderer");
    let camera = *renderer.camera();
    let mut manifest = Manifest::new(
        SessionSource::Simulator {
            scene: scene_path.display().to_string(),
            seed: scene.seed,
        },
        SensorInfo {
            layout: renderer.layout(),
            width: camera.width,
            height: camera.height,
            bit_depth: scene.rig.camera.bit_depth,
        },
        0,
    );
    manifest.rig = Some(ellipso_sim::record::rig_record_of_scene(&scene, camera));
    let mut writer = SessionWriter::create(dir, manifest).expect("session");
    let mut poses = Vec::new();
    // Every 19th pose of the two-turn orbit: views spread around the sphere.
    for k in 0..VIEWS {
        let index = (k * 19) % renderer.frame_count();
        let frame = renderer.render_frame(index).expect("render");
        writer
            .write_frame(FrameRecord {
                t_host_us: HostTimeUs(k as u64),
                frame_id: k as u64,
                t_camera_ns: None,
                exposure_us: scene.rig.camera.exposure_us as u32,
                gain_db: scene.rig.camera.gain_db as f32,
                width: frame.width,
                height: frame.height,
                pixels: &frame.raw(),
                flagged: None,
            })
            .expect("frame");
        poses.push((k as u64, scene.camera_poses[index].world_from_camera));
    }
    writer.finish(HostTimeUs(1), "completed").expect("finish");
    poses
}

/// The scene's sphere (icosphere) and an `n × n` grid over the board's central 0.2 m.
fn mesh(subdivisions: u32, n: usize) -> TriangleMesh {
    let (dirs, mut triangles) = icosphere(subdivisions);
    let centre = Vector3::new(0.0, 0.0, 0.04);
    let mut positions: Vec<Point3<f64>> = dirs
        .iter()
        .map(|d| Point3::from(centre + d.into_inner() * 0.04))
        .collect();
    let mut normals: Vec<Vector3<f64>> = dirs.iter().map(|d| d.into_inner()).collect();
    let base = positions.len();
    let step = 0.2 / (n - 1) as f64;
    for j in 0..n {
        for i in 0..n {
            positions.push(Point3::new(
                -0.1 + i as f64 * step,
                -0.1 + j as f64 * step,
                0.0,
            ));
            normals.push(Vector3::z());
        }
    }
    let at = |i: usize, j: usize| (base + j * n + i) as u32;
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    TriangleMesh::new(positions, Some(normals), None, triangles).expect("mesh")
}

fn main() {
    println!(
        "{:>11} {:>8} {:>7} {:>16} {:>12} {:>10} {:>11}",
        "resolution", "vertices", "threads", "ms/view/1k vert", "samples/s", "samples", "peak MiB"
    );
    for resolution in [[256, 200], [1224, 1024]] {
        let dir = tempfile::tempdir().expect("tempdir");
        let session_dir = dir.path().join("session");
        let poses = session(&session_dir, resolution);
        let session = reader::open(&session_dir).expect("open");
        for (subdivisions, n) in [(4, 101), (5, 201)] {
            let mesh = mesh(subdivisions, n);
            let vertices = mesh.positions().len();
            for threads in [1, 2] {
                let config = ObserveConfig {
                    threads: Some(threads),
                    ..ObserveConfig::default()
                };
                // One warm-up, then the best of three.
                let mut best = f64::INFINITY;
                let mut out = None;
                for _ in 0..4 {
                    let t = Instant::now();
                    let e = extract(&session, &mesh, &poses, &config, &|_, _| {}).expect("extract");
                    best = best.min(t.elapsed().as_secs_f64());
                    out = Some(e);
                }
                let Some(out) = out else { continue };
                let per = best * 1e3 / VIEWS as f64 / (vertices as f64 / 1e3);
                println!(
                    "{:>11} {:>8} {:>7} {:>16.3} {:>12.0} {:>10} {:>11.1}",
                    format!("{}x{}", resolution[0], resolution[1]),
                    vertices,
                    threads,
                    per,
                    out.report.samples as f64 / best,
                    out.report.samples,
                    out.report.peak_bytes as f64 / (1 << 20) as f64
                );
            }
        }
    }
}
