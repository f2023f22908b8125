//! The simulator's ground truth as the fit sees it: a scene's object as a world-space triangle
//! mesh with the true pBRDF parameters of every vertex, and the scene's capture as fit views.
//!
//! Contract:
//! - [`TruthObject::from_scene`] takes the scene's first object. A triangle-mesh object keeps
//!   its own vertices (or, with `subdivisions`, a regenerated procedural blob of the same seed
//!   and shape when the mesh is the shipped `bumpy_blob.ply`); an analytic sphere becomes an
//!   icosphere with `subdivisions` 4-to-1 splits (default 4: 2562 vertices) whose vertices lie
//!   exactly on the sphere. Positions and normals are in the world (board) frame, metres.
//! - Each vertex gets the material of its region (region-bound meshes) or the object's one
//!   material; [`TruthObject::params`] are those materials' [`PbrdfParams`].
//! - [`views_of_scene`] turns the scene's camera poses into [`ViewGeometry`]s exactly as the
//!   renderer places camera, flash and flash polariser.

use ellipso_model::geometry::procedural::{
    BLOB_AMPLITUDE, BLOB_REGIONS, BLOB_SEED, bumpy_icosphere, icosphere,
};
use ellipso_model::geometry::{MeshError, TriangleMesh};
use ellipso_model::optics::pbrdf::PbrdfParams;
use ellipso_sim::scene::{CameraPose, MaterialBinding, ObjectGeometry, Scene};
use nalgebra::{Point3, Vector3};

use ellipso_fit::data::ViewGeometry;

use crate::BenchError;

/// Why a scene has no usable truth object.
#[derive(Debug, thiserror::Error)]
pub enum TruthError {
    /// The scene has no objects.
    #[error("{0}: the scene has no objects to fit")]
    NoObject(String),
    /// The object's geometry is a plane (nothing to fit as a closed object).
    #[error("{0}: object '{1}' is a plane; the fit needs a sphere or a mesh")]
    Unsupported(String, String),
    /// Building the mesh failed.
    #[error("{0}: {1}")]
    Mesh(String, MeshError),
}

/// A scene object with per-vertex truth.
#[derive(Clone, Debug)]
pub struct TruthObject {
    /// The object as a world-space mesh (vertex normals = true surface normals where known).
    pub mesh: TriangleMesh,
    /// True parameters per vertex.
    pub params: Vec<PbrdfParams<f64>>,
    /// Material id per vertex (index into `material_names`).
    pub material: Vec<usize>,
    /// Material names (the scene's).
    pub material_names: Vec<String>,
    /// The true surface is convex (an analytic sphere): a front-facing point is never blocked.
    pub convex: bool,
}

impl TruthObject {
    /// The first object of `scene` (see the module doc); `subdivisions` refines spheres and the
    /// shipped blob.
    pub fn from_scene(scene: &Scene, subdivisions: Option<u32>) -> Result<Self, TruthError> {
        let name = scene.source.display().to_string();
        let object = scene
            .objects
            .first()
            .ok_or_else(|| TruthError::NoObject(name.clone()))?;
        let (positions, normals, regions, triangles) = match &object.geometry {
            ObjectGeometry::Sphere(s) => {
                let (dirs, faces) = icosphere(subdivisions.unwrap_or(4));
                let pos = dirs
                    .iter()
                    .map(|d| Point3::from(d.into_inner() * s.radius_m))
                    .collect::<Vec<_>>();
                let nrm = dirs.iter().map(|d| d.into_inner()).collect::<Vec<_>>();
                (pos, nrm, None, faces)
            }
            ObjectGeometry::Mesh(m) => {
                let regenerated;
                let m = match subdivisions {
                    Some(s) => {
                        regenerated = bumpy_icosphere(s, BLOB_AMPLITUDE, BLOB_REGIONS, BLOB_SEED);
                        &regenerated
                    }
                    None => m.as_ref(),
                };
                (
                    m.positions().to_vec(),
                    m.normals().iter().map(|n| n.into_inner()).collect(),
                    m.regions().map(<[u32]>::to_vec),
                    m.triangles().to_vec(),
                )
            }
            ObjectGeometry::Plane(_) => {
                return Err(TruthError::Unsupported(name, object.name.clone()));
            }
        };
        let convex = matches!(object.geometry, ObjectGeometry::Sphere(_));
        let t = &object.transform;
        let positions_world: Vec<Point3<f64>> =
            positions.iter().map(|p| t.point_to_world(p)).collect();
        let normals_world: Vec<Vector3<f64>> = normals
            .iter()
            .map(|n| {
                t.normal_to_world(&nalgebra::Unit::new_normalize(*n))
                    .into_inner()
            })
            .collect();
        let material: Vec<usize> = (0..positions_world.len())
            .map(|v| match &object.material {
                MaterialBinding::Uniform(m) => *m,
                MaterialBinding::Regions { by_region, .. } => regions
                    .as_ref()
                    .and_then(|r| by_region.get(r[v] as usize).copied())
                    .unwrap_or_else(|| by_region.first().copied().unwrap_or(0)),
            })
            .collect();
        let params = material
            .iter()
            .map(|&m| scene.materials[m].params.to_pbrdf())
            .collect();
        let mesh = TriangleMesh::new(positions_world, Some(normals_world), regions, triangles)
            .map_err(|e| TruthError::Mesh(name, e))?;
        Ok(Self {
            mesh,
            params,
            material,
            material_names: scene.materials.iter().map(|m| m.name.clone()).collect(),
            convex,
        })
    }

    /// Vertex count.
    pub fn len(&self) -> usize {
        self.params.len()
    }

    /// Whether the object has no vertices (never true for a built object).
    pub fn is_empty(&self) -> bool {
        self.params.is_empty()
    }
}

/// The fit views of `poses` (frame id = pose index).
pub fn views_of_scene(scene: &Scene, poses: &[CameraPose]) -> Vec<ViewGeometry> {
    poses
        .iter()
        .enumerate()
        .map(|(k, p)| ViewGeometry::from_rig(k as u64, &p.world_from_camera, &scene.rig.flash))
        .collect()
}

/// The truth object the bench scores against: the scene object's own mesh (a sphere refined to
/// icosphere 6 for the closest-point search).
pub fn truth_for_scoring(scene: &Scene) -> Result<TruthObject, BenchError> {
    let sphere = matches!(
        scene.objects.first().map(|o| &o.geometry),
        Some(ObjectGeometry::Sphere(_))
    );
    TruthObject::from_scene(scene, sphere.then_some(6)).map_err(|e| BenchError::stage("truth", e))
}

/// The true mesh the fit runs on with [`MeshSource::True`](crate::chain::MeshSource::True): the object's own mesh (icosphere 4
/// for a sphere).
pub fn true_mesh(scene: &Scene) -> Result<TriangleMesh, BenchError> {
    Ok(TruthObject::from_scene(scene, None)
        .map_err(|e| BenchError::stage("truth", e))?
        .mesh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_sim::scene::shipped_scene;

    fn scene(name: &str) -> Scene {
        Scene::load(&shipped_scene(name)).unwrap()
    }

    #[test]
    fn sphere_truth_lies_on_the_scene_sphere_with_radial_normals() {
        let s = scene("sphere.toml");
        let t = TruthObject::from_scene(&s, Some(2)).unwrap();
        assert_eq!(t.len(), 162);
        let centre = Point3::new(0.0, 0.0, 0.04);
        for (p, n) in t.mesh.positions().iter().zip(t.mesh.normals()) {
            assert!(((p - centre).norm() - 0.04).abs() < 1e-12);
            assert!((n.into_inner() - (p - centre) / 0.04).norm() < 1e-9);
        }
        assert!(t.params.iter().all(|p| (p.eta - 1.517).abs() < 1e-12));
    }

    #[test]
    fn blob_vertices_carry_their_region_materials() {
        let s = scene("multi_material.toml");
        let t = TruthObject::from_scene(&s, None).unwrap();
        let used: std::collections::BTreeSet<usize> = t.material.iter().copied().collect();
        assert_eq!(used.len(), 4, "four regions, four materials");
        for (v, &m) in t.material.iter().enumerate() {
            assert_eq!(t.params[v], s.materials[m].params.to_pbrdf());
        }
    }

    #[test]
    fn views_place_the_flash_like_the_rig() {
        let s = scene("sphere.toml");
        let views = views_of_scene(&s, &s.camera_poses[..3]);
        for (v, p) in views.iter().zip(&s.camera_poses) {
            let cam = Point3::from(v.camera_position_world);
            let flash = Point3::from(v.flash_position_world);
            assert!(((flash - cam).norm() - 0.03).abs() < 1e-9);
            // Camera up is −y of the OpenCV camera frame.
            let up_cam = p
                .world_from_camera
                .inverse_transform_vector(&Vector3::from(v.camera_up_world));
            assert!((up_cam - Vector3::new(0.0, -1.0, 0.0)).norm() < 1e-9);
        }
    }
}
