//! The scene file's top level, materials, objects, poses and board references as plain serde
//! structs (`deny_unknown_fields` everywhere), plus their semantic validation.
//!
//! Contract: these types are exactly what the TOML says; [`super::Scene`] is built from them after
//! validation. Units are in the field names (`_m`, `_deg`). Every check here reports the dotted key
//! path of the offending value so [`super::error::Located`] can point at its line.

use super::capture::CaptureSpec;
use super::effects::EffectsSpec;
pub use super::error::positive;
use super::error::{Located, SceneError};
pub use super::pose::PoseSpec;
use super::rig::RigSpec;
use ellipso_model::tags::BoardSpec;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The whole scene file.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// The one seed every random choice derives from (capture path, noise, faults).
    pub seed: u64,
    /// Free-form name.
    #[serde(default)]
    pub name: Option<String>,
    /// Free-form description.
    #[serde(default)]
    pub description: Option<String>,
    /// Named materials (`[materials.<name>]`).
    #[serde(default)]
    pub materials: BTreeMap<String, MaterialSpec>,
    /// Objects (`[[objects]]`).
    #[serde(default)]
    pub objects: Vec<ObjectSpec>,
    /// AprilTag boards (`[[boards]]`).
    #[serde(default)]
    pub boards: Vec<BoardRefSpec>,
    /// Camera and flash.
    pub rig: RigSpec,
    /// Where the photos are taken from.
    pub capture: CaptureSpec,
    /// Sensor and fault effects the scene asks for (`[effects]`); absent = none.
    #[serde(default)]
    pub effects: EffectsSpec,
}

/// Largest specular and single-scattering albedo a material may have (far above any real
/// surface; it keeps every rendered value finite): the model's, which `ellipso model` checks too.
pub use ellipso_model::optics::inspect::MAX_LOBE_ALBEDO;

/// Polarimetric BRDF parameters of one material ([`MaterialSpec::to_pbrdf`] gives the optics
/// model's `PbrdfParams`).
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    /// Refractive index η (dimensionless, ≥ 1).
    pub eta: f64,
    /// Specular roughness σs (GGX width, dimensionless, in (0, 1]).
    pub sigma_s: f64,
    /// Single-scattering roughness σss (in (0, 1], ≥ σs).
    pub sigma_ss: f64,
    /// Specular albedo ρs (≥ 0).
    pub rho_s: f64,
    /// Single-scattering albedo ρss per RGB channel (≥ 0).
    pub rho_ss: [f64; 3],
    /// Diffuse albedo ρd per RGB channel (in [0, 1]).
    pub rho_d: [f64; 3],
}

impl MaterialSpec {
    /// The optics model's parameter struct (same fields, same units).
    pub fn to_pbrdf(&self) -> ellipso_model::optics::pbrdf::PbrdfParams<f64> {
        ellipso_model::optics::pbrdf::PbrdfParams {
            eta: self.eta,
            sigma_s: self.sigma_s,
            sigma_ss: self.sigma_ss,
            rho_s: self.rho_s,
            rho_ss: self.rho_ss,
            rho_d: self.rho_d,
        }
    }

    /// Linear blend `Σ wᵢ mᵢ` (weights should sum to 1).
    pub fn blend(items: &[(MaterialSpec, f64)]) -> MaterialSpec {
        let mut out = MaterialSpec {
            eta: 0.0,
            sigma_s: 0.0,
            sigma_ss: 0.0,
            rho_s: 0.0,
            rho_ss: [0.0; 3],
            rho_d: [0.0; 3],
        };
        for (m, w) in items {
            out.eta += w * m.eta;
            out.sigma_s += w * m.sigma_s;
            out.sigma_ss += w * m.sigma_ss;
            out.rho_s += w * m.rho_s;
            for c in 0..3 {
                out.rho_ss[c] += w * m.rho_ss[c];
                out.rho_d[c] += w * m.rho_d[c];
            }
        }
        out
    }

    /// Checks physical ranges; `key` is the material's table path.
    pub fn validate(&self, key: &str, loc: &Located<'_>) -> Result<(), SceneError> {
        let k = |f: &str| format!("{key}.{f}");
        if !(self.eta.is_finite() && self.eta >= 1.0) {
            return Err(loc.invalid(
                k("eta"),
                format!("refractive index must be ≥ 1, got {}", self.eta),
            ));
        }
        if self.eta > 5.0 {
            return Err(loc.invalid(
                k("eta"),
                format!(
                    "refractive index {} is beyond any dielectric (≤ 5)",
                    self.eta
                ),
            ));
        }
        for (f, v) in [("sigma_s", self.sigma_s), ("sigma_ss", self.sigma_ss)] {
            if !(v.is_finite() && v > 0.0 && v <= 1.0) {
                return Err(loc.invalid(k(f), format!("roughness must be in (0, 1], got {v}")));
            }
        }
        if self.sigma_s > self.sigma_ss {
            return Err(loc.invalid(
                k("sigma_s"),
                format!(
                    "specular roughness σs = {} exceeds single-scattering roughness σss = {} \
                     (the model needs σs ≤ σss)",
                    self.sigma_s, self.sigma_ss
                ),
            ));
        }
        if !(self.rho_s >= 0.0 && self.rho_s <= MAX_LOBE_ALBEDO) {
            return Err(loc.invalid(
                k("rho_s"),
                format!("must be in [0, {MAX_LOBE_ALBEDO}], got {}", self.rho_s),
            ));
        }
        for c in 0..3 {
            if !(self.rho_ss[c] >= 0.0 && self.rho_ss[c] <= MAX_LOBE_ALBEDO) {
                return Err(loc.invalid(
                    k(&format!("rho_ss[{c}]")),
                    format!("must be in [0, {MAX_LOBE_ALBEDO}], got {}", self.rho_ss[c]),
                ));
            }
            if !(0.0..=1.0).contains(&self.rho_d[c]) {
                return Err(loc.invalid(
                    k(&format!("rho_d[{c}]")),
                    format!("diffuse albedo must be in [0, 1], got {}", self.rho_d[c]),
                ));
            }
        }
        Ok(())
    }
}

/// Which kind of geometry an object is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ShapeKind {
    /// Analytic sphere (`radius_m`).
    Sphere,
    /// Analytic plane `z = 0` of the object frame (optional `size_m`).
    Plane,
    /// Triangle mesh from a PLY or OBJ file (`mesh`).
    Mesh,
}

/// How region materials are evaluated between vertices.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RegionBlend {
    /// The material of the nearest vertex (largest barycentric weight): sharp borders.
    #[default]
    Nearest,
    /// Parameters blended by barycentric weights: per-vertex materials.
    Barycentric,
}

/// Per-axis or uniform scale.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum ScaleSpec {
    /// Same factor on every axis.
    Uniform(f64),
    /// `[sx, sy, sz]`.
    PerAxis([f64; 3]),
}

/// One `[[objects]]` entry. Which size field applies depends on `shape`.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectSpec {
    /// Unique name.
    pub name: String,
    /// Geometry kind.
    pub shape: ShapeKind,
    /// Sphere radius, metres (sphere only).
    #[serde(default)]
    pub radius_m: Option<f64>,
    /// Plane rectangle `[w, h]`, metres (plane only; absent = infinite).
    #[serde(default)]
    pub size_m: Option<[f64; 2]>,
    /// Mesh file, relative to the scene file (mesh only).
    #[serde(default)]
    pub mesh: Option<String>,
    /// Object frame to world.
    #[serde(default)]
    pub pose: PoseSpec,
    /// Scale applied in the object frame before the pose (default 1).
    #[serde(default)]
    pub scale: Option<ScaleSpec>,
    /// Uniform material name.
    #[serde(default)]
    pub material: Option<String>,
    /// Region id (or OBJ `usemtl` name) → material name.
    #[serde(default)]
    pub regions: Option<BTreeMap<String, String>>,
    /// How region materials blend (default `nearest`).
    #[serde(default)]
    pub region_blend: RegionBlend,
}

/// One `[[boards]]` entry: a board file or an inline board, and its pose in the world.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct BoardRefSpec {
    /// Board TOML file, relative to the scene file.
    #[serde(default)]
    pub file: Option<String>,
    /// Inline board (`[boards.inline]`).
    #[serde(default)]
    pub inline: Option<BoardSpec>,
    /// Board frame to world (`world_from_board`).
    #[serde(default)]
    pub pose: PoseSpec,
}
