//! Scene objects: geometry + placement + material binding, built and validated from
//! [`ObjectSpec`]s, and their world-space intersection with material lookup.
//!
//! Contract: a built [`SceneObject`] always has a resolvable material at every hit: uniform, or a
//! region table covering every region id the mesh uses. Meshes referenced by several objects are
//! loaded once and shared.

use super::error::{Located, SceneError};
use super::spec::{MaterialSpec, ObjectSpec, RegionBlend, ScaleSpec, ShapeKind, positive};
use ellipso_model::geometry::{
    BoundingSphere, Intersect, ObjectTransform, Plane, Ray, Sphere, SurfaceHit, TriangleMesh,
};
use nalgebra::Vector3;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Index into [`super::Scene::materials`].
pub type MaterialId = usize;

/// Object geometry in its own frame.
#[derive(Clone, Debug)]
pub enum ObjectGeometry {
    /// Analytic sphere.
    Sphere(Sphere),
    /// Analytic plane.
    Plane(Plane),
    /// Triangle mesh (shared between objects using the same file).
    Mesh(Arc<TriangleMesh>),
}

impl ObjectGeometry {
    fn as_intersect(&self) -> &dyn Intersect {
        match self {
            Self::Sphere(s) => s,
            Self::Plane(p) => p,
            Self::Mesh(m) => m.as_ref(),
        }
    }
}

/// How an object's surface maps to materials.
#[derive(Clone, Debug, PartialEq)]
pub enum MaterialBinding {
    /// One material everywhere.
    Uniform(MaterialId),
    /// Per mesh region: `by_region[id]` is the material of region `id`.
    Regions {
        /// Material of each region id.
        by_region: Vec<MaterialId>,
        /// Nearest-vertex or barycentric blending.
        blend: RegionBlend,
    },
}

/// The material at a surface point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MaterialSample {
    /// One material.
    Uniform(MaterialId),
    /// Barycentric blend of the three vertices' materials (weights sum to 1).
    Blend([(MaterialId, f64); 3]),
}

/// A placed object.
#[derive(Clone, Debug)]
pub struct SceneObject {
    /// Unique name.
    pub name: String,
    /// Geometry in the object frame.
    pub geometry: ObjectGeometry,
    /// Placement.
    pub transform: ObjectTransform,
    /// Material binding.
    pub material: MaterialBinding,
    /// The world sphere around the placed geometry, which rejects most rays before they are
    /// mapped into the object's frame (`None`: unbounded geometry). Derived from `geometry` and
    /// `transform` by [`SceneObject::new`]; the only constructor, so it cannot go stale.
    bound: Option<BoundingSphere>,
}

impl SceneObject {
    /// A placed object (its world bound computed here).
    pub fn new(
        name: String,
        geometry: ObjectGeometry,
        transform: ObjectTransform,
        material: MaterialBinding,
    ) -> Self {
        let bound = match &geometry {
            ObjectGeometry::Mesh(mesh) => {
                BoundingSphere::around_points(&transform, mesh.positions())
            }
            other => BoundingSphere::around(&transform, &other.as_intersect().bounds()),
        };
        Self {
            name,
            geometry,
            transform,
            material,
            bound,
        }
    }

    /// Whether the world ray can come near the object at all (conservative: a `false` is
    /// exactly what the exact test would say).
    fn may_hit(&self, ray_world: &Ray, t_min: f64) -> bool {
        self.bound.is_none_or(|b| b.may_hit(ray_world, t_min))
    }

    /// Nearest world-space hit with its material.
    pub fn intersect(
        &self,
        ray_world: &Ray,
        t_min: f64,
        t_max: f64,
    ) -> Option<(SurfaceHit, MaterialSample)> {
        if !self.may_hit(ray_world, t_min) {
            return None;
        }
        let ray_obj = self.transform.ray_to_object(ray_world);
        let hit = self
            .geometry
            .as_intersect()
            .intersect(&ray_obj, t_min, t_max)?;
        let sample = self.material_at(&hit);
        Some((self.transform.hit_to_world(ray_world, &hit), sample))
    }

    /// Whether the object blocks the world-space segment.
    pub fn occluded(&self, ray_world: &Ray, t_min: f64, t_max: f64) -> bool {
        if !self.may_hit(ray_world, t_min) {
            return false;
        }
        let ray_obj = self.transform.ray_to_object(ray_world);
        self.geometry
            .as_intersect()
            .occluded(&ray_obj, t_min, t_max)
    }

    /// Material at an object-space hit.
    pub fn material_at(&self, hit: &SurfaceHit) -> MaterialSample {
        match (&self.material, &self.geometry) {
            (MaterialBinding::Uniform(m), _) => MaterialSample::Uniform(*m),
            (MaterialBinding::Regions { by_region, blend }, ObjectGeometry::Mesh(mesh)) => {
                let Some(regions) = mesh.triangle_regions(hit.primitive) else {
                    // Validation guarantees region data whenever regions are bound.
                    return MaterialSample::Uniform(by_region.first().copied().unwrap_or(0));
                };
                let m = regions.map(|r| by_region.get(r as usize).copied().unwrap_or(0));
                match blend {
                    RegionBlend::Nearest => {
                        let b = hit.barycentric;
                        let k = (0..3).fold(0, |k, i| if b[i] > b[k] { i } else { k });
                        MaterialSample::Uniform(m[k])
                    }
                    RegionBlend::Barycentric => MaterialSample::Blend([
                        (m[0], hit.barycentric[0]),
                        (m[1], hit.barycentric[1]),
                        (m[2], hit.barycentric[2]),
                    ]),
                }
            }
            (MaterialBinding::Regions { by_region, .. }, _) => {
                MaterialSample::Uniform(by_region.first().copied().unwrap_or(0))
            }
        }
    }
}

/// Builds all objects; `materials` maps names to ids; `base` is the scene file's folder.
pub fn build_objects(
    specs: &[ObjectSpec],
    materials: &BTreeMap<String, MaterialSpec>,
    base: &Path,
    loc: &Located<'_>,
) -> Result<Vec<SceneObject>, SceneError> {
    let ids: HashMap<&str, MaterialId> = materials
        .keys()
        .enumerate()
        .map(|(i, n)| (n.as_str(), i))
        .collect();
    let mut names: HashMap<&str, usize> = HashMap::new();
    let mut meshes: HashMap<PathBuf, Arc<TriangleMesh>> = HashMap::new();
    let mut out = Vec::with_capacity(specs.len());
    for (i, spec) in specs.iter().enumerate() {
        let key = format!("objects[{i}]");
        let k = |f: &str| format!("{key}.{f}");
        if spec.name.trim().is_empty() {
            return Err(loc.invalid(k("name"), "must not be empty"));
        }
        if let Some(prev) = names.insert(&spec.name, i) {
            return Err(loc.invalid(
                k("name"),
                format!("`{}` is already used by objects[{prev}]", spec.name),
            ));
        }
        let only = |f: &str, present: bool, shape: &str| -> Result<(), SceneError> {
            if present {
                Err(loc.invalid(k(f), format!("only applies to shape = \"{shape}\"")))
            } else {
                Ok(())
            }
        };
        only(
            "radius_m",
            spec.radius_m.is_some() && spec.shape != ShapeKind::Sphere,
            "sphere",
        )?;
        only(
            "size_m",
            spec.size_m.is_some() && spec.shape != ShapeKind::Plane,
            "plane",
        )?;
        only(
            "mesh",
            spec.mesh.is_some() && spec.shape != ShapeKind::Mesh,
            "mesh",
        )?;
        only(
            "regions",
            spec.regions.is_some() && spec.shape != ShapeKind::Mesh,
            "mesh",
        )?;
        let geometry = match spec.shape {
            ShapeKind::Sphere => {
                let r = spec
                    .radius_m
                    .ok_or_else(|| loc.invalid(k("radius_m"), "required for a sphere"))?;
                positive(loc, &k("radius_m"), r)?;
                ObjectGeometry::Sphere(Sphere { radius_m: r })
            }
            ShapeKind::Plane => {
                if let Some([w, h]) = spec.size_m {
                    positive(loc, &k("size_m[0]"), w)?;
                    positive(loc, &k("size_m[1]"), h)?;
                }
                ObjectGeometry::Plane(Plane {
                    size_m: spec.size_m,
                })
            }
            ShapeKind::Mesh => {
                let rel = spec
                    .mesh
                    .as_ref()
                    .ok_or_else(|| loc.invalid(k("mesh"), "required for a mesh"))?;
                let path = base.join(rel);
                if !path.is_file() {
                    return Err(loc.invalid(k("mesh"), super::not_a_file("mesh file", &path)));
                }
                let canonical = path.canonicalize().unwrap_or_else(|_| path.clone());
                let mesh = match meshes.get(&canonical) {
                    Some(m) => m.clone(),
                    None => {
                        let m = Arc::new(
                            TriangleMesh::load(&path)
                                .map_err(|e| loc.mesh(k("mesh"), path.clone(), e))?,
                        );
                        meshes.insert(canonical, m.clone());
                        m
                    }
                };
                ObjectGeometry::Mesh(mesh)
            }
        };
        let pose = spec.pose.to_isometry(&k("pose"), loc)?;
        let scale = match spec.scale {
            None => Vector3::repeat(1.0),
            Some(ScaleSpec::Uniform(s)) => Vector3::repeat(s),
            Some(ScaleSpec::PerAxis(s)) => Vector3::from(s),
        };
        if !scale.iter().all(|s| s.is_finite() && *s > 0.0) {
            return Err(loc.invalid(
                k("scale"),
                format!("scale factors must be positive and finite, got {scale:?}"),
            ));
        }
        let material = bind_material(spec, &geometry, &ids, &key, loc)?;
        out.push(SceneObject::new(
            spec.name.clone(),
            geometry,
            ObjectTransform::new(pose, scale),
            material,
        ));
    }
    Ok(out)
}

fn bind_material(
    spec: &ObjectSpec,
    geometry: &ObjectGeometry,
    ids: &HashMap<&str, MaterialId>,
    key: &str,
    loc: &Located<'_>,
) -> Result<MaterialBinding, SceneError> {
    let k = |f: &str| format!("{key}.{f}");
    let lookup = |name: &str, at: String| {
        ids.get(name).copied().ok_or_else(|| {
            let mut known: Vec<&str> = ids.keys().copied().collect();
            known.sort_unstable();
            loc.invalid(
                at,
                format!("unknown material `{name}` (defined: {})", known.join(", ")),
            )
        })
    };
    match (&spec.material, &spec.regions) {
        (Some(_), Some(_)) => {
            Err(loc.invalid(k("regions"), "give either material or regions, not both"))
        }
        (None, None) => Err(loc.invalid(k("material"), "every object needs material or regions")),
        (Some(name), None) => Ok(MaterialBinding::Uniform(lookup(name, k("material"))?)),
        (None, Some(map)) => {
            let ObjectGeometry::Mesh(mesh) = geometry else {
                return Err(loc.invalid(k("regions"), "only meshes have regions"));
            };
            if mesh.regions().is_none() {
                return Err(loc.invalid(
                    k("regions"),
                    "the mesh file has no region ids (PLY vertex property `region` or OBJ usemtl)",
                ));
            }
            let count = mesh.region_count();
            let mut by_region: Vec<Option<MaterialId>> = vec![None; count];
            for (region_key, material) in map {
                let at = k(&format!(
                    "regions.{}",
                    super::error::key_segment(region_key)
                ));
                let id = match mesh.region_names().iter().position(|n| n == region_key) {
                    Some(id) => id,
                    None => {
                        match region_key.parse::<usize>() {
                            Ok(id) if id < count => id,
                            _ => {
                                return Err(loc.invalid(
                                at,
                                format!("`{region_key}` is not a region of the mesh (ids 0..{count})"),
                            ));
                            }
                        }
                    }
                };
                if by_region[id].is_some() {
                    return Err(loc.invalid(at, format!("region {id} is mapped twice")));
                }
                by_region[id] = Some(lookup(material, at)?);
            }
            let used: std::collections::BTreeSet<u32> =
                mesh.regions().into_iter().flatten().copied().collect();
            let missing: Vec<String> = used
                .iter()
                .filter(|&&r| by_region[r as usize].is_none())
                .map(|r| r.to_string())
                .collect();
            if !missing.is_empty() {
                return Err(loc.invalid(
                    k("regions"),
                    format!("mesh regions without a material: {}", missing.join(", ")),
                ));
            }
            Ok(MaterialBinding::Regions {
                // Unused ids (gaps) never occur at hits; map them to the first material.
                by_region: by_region.into_iter().map(|m| m.unwrap_or(0)).collect(),
                blend: spec.region_blend,
            })
        }
    }
}
