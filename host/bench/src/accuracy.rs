//! Accuracy against the simulator's truth: simulated captures at the observation level and
//! the error metrics of a fit (the engine behind `ellipso bench accuracy`).
//!
//! Contract:
//! - [`simulate`] builds a capture of a scene's object with known truth without rendering
//!   whole frames: for every vertex of the [`TruthObject`] and every view of the scene's capture
//!   path (with `photos` poses), the four analyser intensities come from the same optics the
//!   renderer uses, through the scene's radiometry (the renderer's normaliser N) and sensor
//!   (full well, read noise, bit depth: 12-bit shot + read noise for the shipped scenes),
//!   quantised and clipped, then gated by the shared rules ([`ellipso_fit::gate`]) —
//!   [`ellipso_fit::synthetic::synthesize_vertex`] does one vertex. Visibility: the view must see
//!   the vertex's front side, and no other part of the object may block the camera or the flash
//!   (ray cast against the truth mesh). The fit starts from normals perturbed by
//!   `normal_noise_deg` (an imperfect scanned mesh).
//! - **Flash-energy bracket.** View k of a scene with a `capture.bracket` (or
//!   [`CaptureCase::bracket`]) is lit by `bracket[k mod len]` of the full pulse, as the trigger
//!   board fires the steps in turn: its normaliser is E·N, so its DN are E times the full
//!   pulse's before noise, clipping and the gates, and its samples are divided by E·N — what
//!   observation extraction does with a recorded frame's energy. [`specular`] scores what the
//!   bracket is for: the clusters' σs per material and the samples kept at the lobe peak.
//! - [`evaluate`] scores fitted vertices against the truth: η error (mean % per material and
//!   overall), normal error (median, 90th percentile, degrees), ρd error (mean relative %, RGB),
//!   roughness errors (mean absolute σs, σss), and the re-render RMSE: the model with the fitted
//!   parameters re-evaluated at every kept observation, RMS of (model − observed) over the RMS of
//!   the observations, all channels. Vertices flagged `TooFewViews` are left out of the errors
//!   and counted.
//! - [`forward_all`] evaluates the model once at every observation (no derivatives): the unit
//!   against which the fit's time is reported.

use ellipso_model::geometry::{Intersect, Ray};
use ellipso_model::optics::Vec3;
use ellipso_model::optics::measure::observe;
use ellipso_model::optics::pbrdf::PbrdfParams;
use ellipso_sim::render::radiometry::Radiometry;
use ellipso_sim::scene::Scene;
use nalgebra::{Point3, Unit, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use ellipso_fit::data::{SampleGeometry, SampleSet, VertexFit, VertexSamples, ViewGeometry};
use ellipso_fit::gate::GateConfig;
use ellipso_fit::synthetic::{SensorNoise, synthesize_vertex};

use crate::BenchError;
use crate::truth::{TruthObject, views_of_scene};

mod scores;
pub mod specular;

pub use scores::{MaterialErrors, Scores, evaluate};

/// Relative offset along a ray before occlusion tests (avoids self-hits on the start triangle).
const RAY_EPS_M: f64 = 1e-6;

/// One simulated capture's settings.
#[derive(Clone, Debug)]
pub struct CaptureCase {
    /// Photos along the scene's capture path.
    pub photos: usize,
    /// Sphere / blob refinement (None: the scene's own mesh, icosphere 4 for spheres).
    pub subdivisions: Option<u32>,
    /// Keep only the first N vertices (large timing runs on a sphere).
    pub max_vertices: Option<usize>,
    /// Per-vertex random tilt of the initial normals, degrees.
    pub normal_noise_deg: f64,
    /// Sensor noise on (shot + read, as the scene's camera) or off.
    pub noise: bool,
    /// Seed of the noise and the normal tilts.
    pub seed: u64,
    /// Sample gates.
    pub gate: GateConfig,
    /// Relative flash energies fired in turn (`None`: the scene's `capture.bracket`; empty:
    /// one exposure, every view at full energy).
    pub bracket: Option<Vec<f64>>,
}

impl Default for CaptureCase {
    fn default() -> Self {
        Self {
            photos: 100,
            subdivisions: None,
            max_vertices: None,
            normal_noise_deg: 5.0,
            noise: true,
            seed: 7,
            gate: GateConfig::default(),
            bracket: None,
        }
    }
}

/// A simulated capture with its truth.
pub struct SimulatedCapture {
    /// The object with true parameters (its mesh normals are the true normals).
    pub truth: TruthObject,
    /// The observations the fit sees (initial normals perturbed).
    pub set: SampleSet,
    /// Relative flash energy of every view, by frame id (all 1 without a bracket).
    pub flash_energy_rel: Vec<f64>,
    /// Per vertex, the frame ids of its near-mirror views (visible, and the half vector inside
    /// the true lobe's half maximum, [`specular::is_near_mirror`]), before any gate.
    pub near_mirror: Vec<Vec<u64>>,
}

/// The solver's noise model for a scene's camera (DN per electron with its gain, read noise).
pub fn sensor_model(scene: &Scene) -> ellipso_fit::solve::SensorNoiseModel {
    let vignetting = scene.effects.vignetting.as_ref().map(|v| v.exponent);
    let r = Radiometry::new(&scene.rig.camera, &scene.rig.flash, vignetting);
    ellipso_fit::solve::SensorNoiseModel {
        dn_per_electron: r.dn_per_electron(),
        read_noise_dn: read_noise_e(scene) * r.dn_per_electron(),
    }
}

/// The scene camera's largest code, DN.
pub fn full_scale_dn(scene: &Scene) -> f64 {
    let vignetting = scene.effects.vignetting.as_ref().map(|v| v.exponent);
    Radiometry::new(&scene.rig.camera, &scene.rig.flash, vignetting).full_scale_dn()
}

/// The scene camera's read noise, electrons RMS (0 when the scene simulates none).
fn read_noise_e(scene: &Scene) -> f64 {
    scene.effects.read_noise.as_ref().map_or(0.0, |n| n.sigma_e)
}

/// Simulates `case` on `scene` (see the module doc).
pub fn simulate(scene: &Scene, case: &CaptureCase) -> Result<SimulatedCapture, BenchError> {
    let truth = TruthObject::from_scene(scene, case.subdivisions)
        .map_err(|e| BenchError::stage("truth", e))?;
    simulate_with_truth(scene, case, truth)
}

/// [`simulate`] of an object given as `truth` (its mesh in the world frame, its parameters
/// and materials per vertex — e.g. the scene's object with materials of its own), photographed
/// along `scene`'s capture path with its radiometry and sensor.
pub fn simulate_with_truth(
    scene: &Scene,
    case: &CaptureCase,
    mut truth: TruthObject,
) -> Result<SimulatedCapture, BenchError> {
    let scene = with_photo_count(scene, case.photos)?;
    let views = views_of_scene(&scene, &scene.camera_poses);
    let vignetting = scene.effects.vignetting.as_ref().map(|v| v.exponent);
    let radiometry = Radiometry::new(&scene.rig.camera, &scene.rig.flash, vignetting);
    let noise = case.noise.then(|| {
        SensorNoise::from_radiometry(
            &radiometry,
            read_noise_e(&scene),
            scene.effects.shot_noise.is_some(),
        )
    });
    let camera = scene.rig.camera.camera_model();
    let flash = scene.rig.flash.clone();
    let poses: Vec<_> = scene
        .camera_poses
        .iter()
        .map(|p| p.world_from_camera)
        .collect();
    let normaliser = |view: &ViewGeometry, g: &SampleGeometry| -> f64 {
        let pose = &poses[view.frame_id as usize];
        let axis = flash.axis_world(pose);
        let cos_flash = -Vector3::from(g.to_light).dot(&axis);
        let to_point_cam = pose.inverse_transform_vector(&-Vector3::from(g.to_camera));
        let cos_field = to_point_cam.z.clamp(-1.0, 1.0);
        radiometry.normaliser(
            g.light_distance_m,
            cos_flash.clamp(-1.0, 1.0).acos(),
            cos_field.acos(),
        )
    };
    let bracket = case
        .bracket
        .clone()
        .unwrap_or_else(|| scene.capture.bracket.clone());
    let flash_energy_rel: Vec<f64> = (0..views.len())
        .map(|k| {
            if bracket.is_empty() {
                1.0
            } else {
                bracket[k % bracket.len()]
            }
        })
        .collect();
    let lit_normaliser = |view: &ViewGeometry, g: &SampleGeometry| -> f64 {
        flash_energy_rel[view.frame_id as usize] * normaliser(view, g)
    };
    let colour = scene.rig.camera.sensor == ellipso_sim::scene::SensorKind::ColourPolar;
    let n_vertices = case
        .max_vertices
        .map_or(truth.len(), |m| m.min(truth.len()));
    truth.params.truncate(n_vertices);
    truth.material.truncate(n_vertices);
    let mesh = &truth.mesh;
    let vertices: Vec<(VertexSamples, Vec<u64>)> = (0..n_vertices)
        .into_par_iter()
        .map(|v| {
            let mut rng = ChaCha8Rng::seed_from_u64(
                case.seed ^ (v as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            );
            let p = mesh.positions()[v];
            let n = mesh.normals()[v];
            // Views that see the front side unblocked by the object, flash unblocked too.
            let visible: Vec<usize> = (0..views.len())
                .filter(|&k| {
                    let cam = Point3::from(views[k].camera_position_world);
                    let flash_p = Point3::from(views[k].flash_position_world);
                    let in_image = camera
                        .project(&poses[k].inverse_transform_point(&p))
                        .is_some_and(|px| camera.contains_pixel(px));
                    in_image
                        && n.dot(&(cam - p)) > 0.0
                        && n.dot(&(flash_p - p)) > 0.0
                        && (truth.convex
                            || (!blocked(mesh, &p, &cam) && !blocked(mesh, &p, &flash_p)))
                })
                .collect();
            let near_mirror: Vec<u64> = visible
                .iter()
                .filter(|&&k| {
                    views[k].geometry_at(&p).is_some_and(|g| {
                        let half = Vector3::from(g.to_light) + Vector3::from(g.to_camera);
                        let cos_h = n.dot(&half) / half.norm().max(1e-12);
                        specular::is_near_mirror(cos_h, truth.params[v].sigma_s)
                    })
                })
                .map(|&k| k as u64)
                .collect();
            let subset: Vec<ViewGeometry> = visible.iter().map(|&k| views[k].clone()).collect();
            let mut vs = synthesize_vertex(
                &subset,
                v as u32,
                p.coords.into(),
                n.into_inner().into(),
                &truth.params[v],
                &lit_normaliser,
                noise.as_ref(),
                colour,
                &case.gate,
                &mut rng,
            );
            for s in &mut vs.samples {
                s.view = visible[s.view as usize] as u32;
            }
            vs.gates.not_in_view += (views.len() - visible.len()) as u64;
            vs.normal_world = tilt(n.into_inner(), case.normal_noise_deg, &mut rng).into();
            (vs, near_mirror)
        })
        .collect();
    let (vertices, near_mirror): (Vec<VertexSamples>, Vec<Vec<u64>>) = vertices.into_iter().unzip();
    let rings = if vertices.len() == truth.mesh.positions().len() {
        ellipso_fit::neighbours::rings(&truth.mesh)
    } else {
        Vec::new()
    };
    Ok(SimulatedCapture {
        truth,
        set: SampleSet {
            views,
            colour,
            vertices,
            rings,
        },
        flash_energy_rel,
        near_mirror,
    })
}

/// Whether the object blocks the segment from `from` (on the surface) to `to`.
fn blocked(
    mesh: &ellipso_model::geometry::TriangleMesh,
    from: &Point3<f64>,
    to: &Point3<f64>,
) -> bool {
    let d = to - from;
    let len = d.norm();
    // A zero-length segment is blocked by nothing.
    if len < RAY_EPS_M {
        return false;
    }
    let dir = d / len;
    let scale = from.coords.norm().max(1.0);
    let start = from + dir * (RAY_EPS_M * scale * 10.0);
    mesh.occluded(&Ray::new(start, dir), 0.0, len - RAY_EPS_M * 20.0)
}

/// `n` turned by `deg` degrees about a random axis perpendicular to it.
fn tilt(n: Vector3<f64>, deg: f64, rng: &mut ChaCha8Rng) -> Vector3<f64> {
    if deg <= 0.0 {
        return n;
    }
    let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
    let helper = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let t1 = n.cross(&helper).normalize();
    let t2 = n.cross(&t1);
    let axis = Unit::new_normalize(t1 * a.cos() + t2 * a.sin());
    UnitQuaternion::from_axis_angle(&axis, deg.to_radians()) * n
}

/// The scene with `photos` poses along its capture path (same path, denser or sparser).
pub fn with_photo_count(scene: &Scene, photos: usize) -> Result<Scene, BenchError> {
    if photos == scene.camera_poses.len() {
        return Ok(scene.clone());
    }
    let bad = |what: String| BenchError::Scene {
        path: scene.source.clone(),
        what,
    };
    let text =
        std::fs::read_to_string(&scene.source).map_err(|e| BenchError::io(&scene.source, e))?;
    let mut table: toml::Table = toml::from_str(&text).map_err(|e| bad(e.to_string()))?;
    let capture = table
        .get_mut("capture")
        .and_then(|c| c.as_table_mut())
        .ok_or_else(|| bad("no [capture] table".into()))?;
    capture.insert("photo_count".into(), toml::Value::Integer(photos as i64));
    // Link faults are indexed by frame and play no part in observation-level captures.
    if let Some(effects) = table.get_mut("effects").and_then(|e| e.as_table_mut()) {
        effects.remove("link_disconnect");
        effects.remove("link_corruption");
        effects.remove("frame_drops");
    }
    let text = toml::to_string(&table).map_err(|e| bad(e.to_string()))?;
    Scene::from_toml_str(&text, &scene.source).map_err(|e| bad(e.to_string()))
}

/// Model prediction at every kept observation of `vertex` with `params`/`normal`: one
/// `[I^d, I^s, I^α]` per colour channel per sample (`None` where the geometry degenerates).
pub fn predict_vertex(
    views: &[ViewGeometry],
    vertex: &VertexSamples,
    params: &PbrdfParams<f64>,
    normal: [f64; 3],
) -> Vec<Option<[[f64; 3]; 3]>> {
    let position = Point3::from(vertex.position_world);
    vertex
        .samples
        .iter()
        .map(|s| {
            let view = &views[s.view as usize];
            let g = view.geometry_at(&position)?;
            let model = g.model::<f64>(Vec3::from_f64(normal)).ok()?;
            let obs = observe(&model, params, view.flash_polariser());
            Some(obs.map(|o| [o.diffuse, o.specular, o.alpha]))
        })
        .collect()
}

/// One forward evaluation of every observation with the fitted parameters; returns the sum of
/// predicted channels (so the work cannot be optimised away).
pub fn forward_all(set: &SampleSet, fits: &[VertexFit]) -> f64 {
    set.vertices
        .par_iter()
        .zip(fits)
        .map(|(v, f)| {
            predict_vertex(&set.views, v, &f.params, f.normal_world)
                .into_iter()
                .flatten()
                .map(|p| p.iter().flatten().sum::<f64>())
                .sum::<f64>()
        })
        .sum()
}
