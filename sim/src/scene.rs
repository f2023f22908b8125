//! Scene description files (TOML): objects, materials, AprilTag boards, rig, capture path and
//! the sensor/fault effects a simulation should apply. `docs/scene.md` documents every field.
//!
//! Contract:
//! - [`Scene::load`] reads a file, deserialises it with `deny_unknown_fields`, validates every value
//!   and resolves references (materials, mesh files, board files, relative to the scene file's
//!   folder). Any problem is a [`SceneError`] naming file, line, column and key path.
//! - A loaded [`Scene`] is immutable and self-consistent: every object has a material at every
//!   surface point, tag ids are unique across boards, the camera poses are computed
//!   deterministically from `seed`.
//! - World frame: right-handed, `capture.up` (default `+z`) up. Camera frame: OpenCV (x right,
//!   y down, z forward). Board and tag frames: see [`ellipso_model::tags::board`].
//! - Ray queries ([`Scene::intersect`], [`Scene::occluded`]) are in world space with the
//!   conventions of [`ellipso_model::geometry`].

pub mod boards;
pub mod capture;
pub mod effects;
pub mod error;
pub mod objects;
mod pose;
pub mod rig;
pub mod shipped;
pub mod spec;

pub use shipped::shipped_scene;

#[cfg(test)]
mod tests;

pub use boards::{board_from_toml_str, load_board_file};
pub use capture::{CameraPose, CapturePathKind, CaptureSpec, ExplicitPoseSpec, look_at};
pub use effects::{EffectKind, EffectsSpec};
pub use error::SceneError;
pub use objects::{MaterialBinding, MaterialId, MaterialSample, ObjectGeometry, SceneObject};
pub use rig::{CameraSpec, FlashProfileKind, FlashProfileSpec, FlashSpec, RigSpec, SensorKind};
pub use spec::{
    BoardRefSpec, MaterialSpec, ObjectSpec, PoseSpec, RegionBlend, ScaleSpec, SceneFile, ShapeKind,
};

use ellipso_model::geometry::{Ray, SurfaceHit};
use ellipso_model::tags::PlacedBoard;
use error::Located;
use nalgebra::Unit;
use std::path::{Path, PathBuf};

/// Why `path`, which should be a readable file, is not one: a directory, something else, or
/// nothing at all (`what` names it, e.g. "mesh file").
pub(crate) fn not_a_file(what: &str, path: &Path) -> String {
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => format!("{what} {} is a directory, not a file", path.display()),
        Ok(_) => format!("{what} {} is not a regular file", path.display()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            format!("{what} {} does not exist", path.display())
        }
        Err(e) => format!("{what} {}: {e}", path.display()),
    }
}

/// A named material.
#[derive(Clone, Debug, PartialEq)]
pub struct NamedMaterial {
    /// Name from `[materials.<name>]`.
    pub name: String,
    /// pBRDF parameters.
    pub params: MaterialSpec,
}

/// What a scene ray hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SurfaceKind {
    /// An object, with the material at the hit.
    Object {
        /// Index into [`Scene::objects`].
        index: usize,
        /// Material at the hit.
        material: MaterialSample,
    },
    /// A board's sheet.
    Board {
        /// Index into [`Scene::boards`].
        index: usize,
        /// Diffuse albedo of the print at the hit.
        albedo: f32,
        /// Whether the printed side was hit.
        front: bool,
    },
}

/// A world-space hit and what was hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneHit {
    /// Geometry of the hit (world frame).
    pub hit: SurfaceHit,
    /// Object or board.
    pub kind: SurfaceKind,
}

/// A loaded, validated scene.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The file it came from.
    pub source: PathBuf,
    /// The scene seed.
    pub seed: u64,
    /// Name.
    pub name: Option<String>,
    /// Description.
    pub description: Option<String>,
    /// Materials, sorted by name; [`MaterialId`] indexes this.
    pub materials: Vec<NamedMaterial>,
    /// Objects.
    pub objects: Vec<SceneObject>,
    /// Boards with their world poses.
    pub boards: Vec<PlacedBoard>,
    /// Camera and flash.
    pub rig: RigSpec,
    /// Capture path description.
    pub capture: CaptureSpec,
    /// Effects to simulate.
    pub effects: EffectsSpec,
    /// One pose per photo, from `capture` and `seed`.
    pub camera_poses: Vec<CameraPose>,
}

impl Scene {
    /// Reads and validates a scene file.
    pub fn load(path: &Path) -> Result<Self, SceneError> {
        let text =
            ellipso_model::file_io::read_bounded_text(path, ellipso_model::file_io::caps::SCENE)
                .map_err(|source| SceneError::Io {
                    path: path.to_owned(),
                    source,
                })?;
        Self::from_toml_str(&text, path)
    }

    /// Parses and validates scene TOML; `path` names it in errors and anchors relative paths.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Self, SceneError> {
        let loc = Located::new(text, path);
        let file: SceneFile = toml::from_str(text).map_err(|e| loc.parse_error(&e))?;
        Self::from_file(file, path, &loc)
    }

    fn from_file(file: SceneFile, path: &Path, loc: &Located<'_>) -> Result<Self, SceneError> {
        let base = path.parent().unwrap_or_else(|| Path::new("."));
        for (name, m) in &file.materials {
            m.validate(&format!("materials.{}", error::key_segment(name)), loc)?;
        }
        if file.objects.is_empty() && file.boards.is_empty() {
            return Err(loc.invalid("objects", "the scene has neither objects nor boards"));
        }
        let objects = objects::build_objects(&file.objects, &file.materials, base, loc)?;
        let boards = boards::build_boards(&file.boards, base, loc)?;
        file.rig.validate(loc)?;
        file.capture.validate(loc)?;
        if file.rig.camera.exposure_us > file.capture.interval_ms * 1e3 {
            return Err(loc.invalid(
                "capture.interval_ms",
                format!(
                    "{} ms between triggers is shorter than the {} µs exposure",
                    file.capture.interval_ms, file.rig.camera.exposure_us
                ),
            ));
        }
        let camera_poses = file.capture.camera_poses(file.seed, loc)?;
        if camera_poses.is_empty() {
            return Err(loc.invalid("capture", "the capture path produced no poses"));
        }
        file.effects
            .validate(&file.rig, camera_poses.len() as u32, loc)?;
        let materials = file
            .materials
            .into_iter()
            .map(|(name, params)| NamedMaterial { name, params })
            .collect();
        Ok(Self {
            source: path.to_owned(),
            seed: file.seed,
            name: file.name,
            description: file.description,
            materials,
            objects,
            boards,
            rig: file.rig,
            capture: file.capture,
            effects: file.effects,
            camera_poses,
        })
    }

    /// Material id by name.
    pub fn material_id(&self, name: &str) -> Option<MaterialId> {
        self.materials.iter().position(|m| m.name == name)
    }

    /// pBRDF parameters at a material sample (blends are linear in every parameter).
    pub fn material_params(&self, sample: &MaterialSample) -> MaterialSpec {
        match sample {
            MaterialSample::Uniform(m) => self.materials[*m].params,
            MaterialSample::Blend(items) => {
                MaterialSpec::blend(&items.map(|(m, w)| (self.materials[m].params, w)))
            }
        }
    }

    /// Nearest world-space hit over objects and boards with `t_min < t < t_max`.
    pub fn intersect(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<SceneHit> {
        let mut best: Option<SceneHit> = None;
        let mut t_best = t_max;
        for (index, o) in self.objects.iter().enumerate() {
            if let Some((hit, material)) = o.intersect(ray, t_min, t_best) {
                t_best = hit.t;
                best = Some(SceneHit {
                    hit,
                    kind: SurfaceKind::Object { index, material },
                });
            }
        }
        for (index, b) in self.boards.iter().enumerate() {
            if let Some(h) = b.intersect(ray, t_min, t_best) {
                t_best = h.t;
                let front_n = b.front_normal_world();
                let n = if h.front {
                    front_n
                } else {
                    Unit::new_unchecked(-front_n.into_inner())
                };
                let hit = SurfaceHit {
                    t: h.t,
                    point: ray.at(h.t),
                    normal_geometric: n,
                    normal_shading: n,
                    barycentric: [1.0, 0.0, 0.0],
                    primitive: 0,
                };
                best = Some(SceneHit {
                    hit,
                    kind: SurfaceKind::Board {
                        index,
                        albedo: h.albedo,
                        front: h.front,
                    },
                });
            }
        }
        best
    }

    /// Whether anything blocks the segment `t_min < t < t_max` (shadow rays).
    pub fn occluded(&self, ray: &Ray, t_min: f64, t_max: f64) -> bool {
        self.objects.iter().any(|o| o.occluded(ray, t_min, t_max))
            || self
                .boards
                .iter()
                .any(|b| b.intersect(ray, t_min, t_max).is_some())
    }
}
