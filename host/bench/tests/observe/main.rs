//! Tests of observation extraction on small sessions rendered by the simulator with known
//! poses, materials and radiometry.

mod accuracy;
mod energy;
mod gating;
mod robustness;

use std::path::{Path, PathBuf};

use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::procedural::icosphere;
use ellipso_sim::render::{RenderOptions, Renderer};
use ellipso_sim::scene::Scene;
use nalgebra::{Isometry3, Point3, Vector3};

use ellipso_session::events::SessionEvent;
use ellipso_session::manifest::{Manifest, SensorInfo, SessionSource};
use ellipso_session::reader::{self, Session};
use ellipso_session::time::HostTimeUs;
use ellipso_session::writer::{FrameRecord, SessionWriter};
use ellipso_sim::record::rig_record_of_scene;

/// Sphere centre and radius of every test scene, world metres.
pub const CENTRE: [f64; 3] = [0.0, 0.0, 0.04];
pub const RADIUS_M: f64 = 0.04;

/// What a test scene varies.
#[derive(Clone, Debug)]
pub struct SceneSpec {
    pub sensor: &'static str,
    pub material: &'static str,
    pub flash_offset_m: [f64; 3],
    pub exposure_us: f64,
    pub k1: f64,
    /// Camera positions (all look at the sphere centre).
    pub cameras: Vec<[f64; 3]>,
}

impl SceneSpec {
    /// A painted (broad-lobe, bright diffuse) sphere, mono sensor, mild distortion, 5 views.
    pub fn paint_mono() -> Self {
        Self {
            sensor: "mono_polar",
            material: "eta = 1.5\nsigma_s = 0.25\nsigma_ss = 0.4\nrho_s = 0.3\n\
                       rho_ss = [0.05, 0.05, 0.05]\nrho_d = [0.5, 0.5, 0.5]",
            flash_offset_m: [0.0, -0.03, 0.0],
            exposure_us: 2000.0,
            k1: 0.02,
            cameras: vec![
                [0.21, 0.0, 0.25],
                [0.0, 0.21, 0.25],
                [-0.21, 0.0, 0.25],
                [0.0, -0.21, 0.25],
                [0.05, 0.02, 0.33],
            ],
        }
    }
}

/// Renders `spec` into a new session under `dir`; returns the session directory, the scene
/// and the truth poses `(frame id, world_from_camera)` (frame ids start at 100).
pub fn make_session(dir: &Path, spec: &SceneSpec) -> (PathBuf, Scene, Vec<(u64, Isometry3<f64>)>) {
    make_session_lit(dir, spec, None)
}

/// [`make_session`] with frame `k` lit by `flash_energy_rel[k]` of the full flash pulse and a
/// `pairing` event recording that energy (`None`: every frame at full energy, no pairing).
pub fn make_session_lit(
    dir: &Path,
    spec: &SceneSpec,
    flash_energy_rel: Option<&[f64]>,
) -> (PathBuf, Scene, Vec<(u64, Isometry3<f64>)>) {
    let boards = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../sim/boards/base_a4.toml");
    let poses: String = spec
        .cameras
        .iter()
        .map(|p| {
            format!(
                "[[capture.poses]]\nposition_m = [{}, {}, {}]\nlook_at_m = [{}, {}, {}]\n",
                p[0], p[1], p[2], CENTRE[0], CENTRE[1], CENTRE[2]
            )
        })
        .collect();
    let f = spec.flash_offset_m;
    let text = format!(
        r#"seed = 3
name = "observe_test"
[materials.m]
{material}
[[objects]]
name = "ball"
shape = "sphere"
radius_m = {RADIUS_M}
pose = {{ translation_m = [{cx}, {cy}, {cz}] }}
material = "m"
[[boards]]
file = "{boards}"
pose = {{}}
[rig.camera]
resolution_px = [256, 200]
fx_px = 420.0
fy_px = 420.0
cx_px = 127.5
cy_px = 99.5
k1 = {k1}
sensor = "{sensor}"
bit_depth = 12
exposure_us = {exposure}
[rig.flash]
offset_m = [{f0}, {f1}, {f2}]
[capture]
path = "explicit"
{poses}
[effects]
saturation = {{}}
{distortion}
"#,
        distortion = if spec.k1 != 0.0 {
            "lens_distortion = {}"
        } else {
            ""
        },
        material = spec.material,
        cx = CENTRE[0],
        cy = CENTRE[1],
        cz = CENTRE[2],
        boards = boards.display(),
        k1 = spec.k1,
        sensor = spec.sensor,
        exposure = spec.exposure_us,
        f0 = f[0],
        f1 = f[1],
        f2 = f[2],
    );
    std::fs::create_dir_all(dir).unwrap();
    let scene_path = dir.join("scene.toml");
    std::fs::write(&scene_path, text).unwrap();
    let scene = Scene::load(&scene_path).unwrap();
    let renderer = Renderer::new(
        &scene,
        RenderOptions {
            supersampling: 1,
            ..RenderOptions::default()
        },
    )
    .unwrap();
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
            bit_depth: 12,
        },
        0,
    );
    manifest.rig = Some(rig_record_of_scene(&scene, camera));
    let session_dir = dir.join("session");
    let mut writer = SessionWriter::create(&session_dir, manifest).unwrap();
    let mut poses = Vec::new();
    for k in 0..renderer.frame_count() {
        let energy = flash_energy_rel.map(|e| e[k]);
        let frame = renderer.render_frame_lit(k, energy.unwrap_or(1.0)).unwrap();
        let frame_id = 100 + k as u64;
        writer
            .write_frame(FrameRecord {
                t_host_us: HostTimeUs(k as u64 * 1000),
                frame_id,
                t_camera_ns: None,
                exposure_us: scene.rig.camera.exposure_us as u32,
                gain_db: scene.rig.camera.gain_db as f32,
                width: frame.width,
                height: frame.height,
                pixels: &frame.raw(),
                flagged: None,
            })
            .unwrap();
        if let Some(energy) = energy {
            writer
                .log(&SessionEvent::Pairing {
                    t_host_us: HostTimeUs(k as u64 * 1000 + 1),
                    frame_id,
                    seq: k as u64,
                    latency_us: None,
                    bracket_step: Some(k as u8),
                    flash_on_us: Some((energy * 5000.0).round() as u32),
                    flash_energy_rel: Some(energy),
                    basis: None,
                })
                .unwrap();
        }
        poses.push((frame_id, scene.camera_poses[k].world_from_camera));
    }
    writer.finish(HostTimeUs(1_000_000), "completed").unwrap();
    (session_dir, scene, poses)
}

/// Opens a test session.
pub fn open(dir: &Path) -> Session {
    reader::open(dir).unwrap()
}

/// The sphere (icosphere, `subdivisions`) and a flat board grid (z = 0, ±`half_m`, `n × n`
/// vertices) as one world mesh; returns the mesh and the number of sphere vertices (they come
/// first).
pub fn sphere_and_board(subdivisions: u32, half_m: f64, n: usize) -> (TriangleMesh, usize) {
    let (dirs, tris) = icosphere(subdivisions);
    let centre = Vector3::from(CENTRE);
    let mut positions: Vec<Point3<f64>> = dirs
        .iter()
        .map(|d| Point3::from(centre + d.into_inner() * RADIUS_M))
        .collect();
    let mut normals: Vec<Vector3<f64>> = dirs.iter().map(|d| d.into_inner()).collect();
    let mut triangles = tris;
    let sphere = positions.len();
    let step = 2.0 * half_m / (n - 1) as f64;
    for j in 0..n {
        for i in 0..n {
            positions.push(Point3::new(
                -half_m + i as f64 * step,
                -half_m + j as f64 * step,
                0.0,
            ));
            normals.push(Vector3::z());
        }
    }
    let at = |i: usize, j: usize| (sphere + j * n + i) as u32;
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            // counter-clockwise seen from +z
            triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    (
        TriangleMesh::new(positions, Some(normals), None, triangles).unwrap(),
        sphere,
    )
}

/// Distance from `c` to the segment `a → b`.
pub fn segment_distance(a: &Point3<f64>, b: &Point3<f64>, c: &Point3<f64>) -> f64 {
    let ab = b - a;
    let t = ((c - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0);
    (a + ab * t - c).norm()
}
