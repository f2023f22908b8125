//! One frame's observations: the demosaiced frame in DN, sampled at every vertex's projection,
//! with visibility (view frustum, facing, occlusion, flash shadow), the shared sample gates and
//! the normaliser.
//!
//! Contract:
//! - The image is read through [`AnalyserPixels`] (the recorded mosaic's
//!   [`super::image::DnImage`], or an ideal sensor's), at the vertex's projection only. A
//!   sample is saturated when any superpixel its value draws on is at or above the gate's
//!   saturation level, so a clipped neighbour never leaks into an interpolated
//!   value that looks unclipped. Every gate judges the frame's own DN, before the division by
//!   the (flash-energy-scaled) normaliser: a highlight that clips at full energy is dropped in
//!   that frame and kept in a shorter-pulse frame where it does not clip.
//! - Occlusion and shadow rays ignore the triangles incident to the vertex (a ray ending on a
//!   vertex cannot be blocked by a triangle that contains it; this is exact) and hits within
//!   [`RAY_T_EPS`] of either end (relative to the segment length: 50 nm at 0.5 m), which absorbs
//!   coincident duplicate vertices of unwelded meshes.

use ellipso_model::camera::CameraModel;
use ellipso_model::geometry::{Intersect, Ray, TriangleMesh};
use nalgebra::{Isometry3, Point3, Vector3};

use super::footprint::Footprint;
use super::image::AnalyserPixels;
use super::radiometry::{PointNormaliser, SessionRadiometry};
use crate::data::{OBSERVATION_CHANNELS, Sample, ViewGeometry};
use crate::gate::{GateConfig, SampleGate};

/// Ray parameter margin at both ends of an occlusion or shadow segment (relative to its length).
pub const RAY_T_EPS: f64 = 1e-7;

/// The label of a vertex whose material is unknown ([`SessionContext::labels`]): it mixes with
/// nothing.
pub const UNLABELLED: u32 = u32::MAX;

/// cos 85°: the footprint test's stretch 1/cos θ is capped there (a footprint seen more
/// obliquely than that reaches the silhouette anyway).
const COS_85_DEG: f64 = 0.087_155_742_747_658_17;

/// What one (vertex, view) pair gave.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outcome {
    /// A kept sample (its `view` index is filled in by the caller).
    Kept(Sample),
    /// Behind the camera, outside the image, or back-facing.
    NotInView,
    /// Another part of the mesh hides the vertex.
    Occluded,
    /// Not lit by the flash (blocked, facing away from it, or outside its emission profile).
    Shadowed,
    /// The image footprint of the sample's value reaches off the vertex's visible surface or
    /// onto another material ([`AnalyserPixels::footprint`],
    /// `FrameSampler::footprint_on_surface`).
    Mixed,
    /// A sample whose own footprint is [`Outcome::Mixed`] but whose value from the image's
    /// narrower kernel ([`AnalyserPixels::narrow`]) draws on the vertex's surface alone: kept
    /// only for a vertex that has too few samples otherwise (`extract`), counted as mixed
    /// elsewhere.
    KeptNarrow(Sample),
    /// A shared sample gate (non-finite, grazing, saturated, dark).
    Gate(SampleGate),
}

/// Vertex → incident triangles (compressed rows).
#[derive(Clone, Debug)]
pub struct VertexRings {
    offsets: Vec<u32>,
    triangles: Vec<u32>,
}

impl VertexRings {
    /// The rings of `mesh`.
    pub fn new(mesh: &TriangleMesh) -> VertexRings {
        let n = mesh.positions().len();
        let mut counts = vec![0u32; n + 1];
        for t in mesh.triangles() {
            for &v in t {
                counts[v as usize + 1] += 1;
            }
        }
        for k in 0..n {
            counts[k + 1] += counts[k];
        }
        let mut fill = counts.clone();
        let mut triangles = vec![0u32; counts[n] as usize];
        for (f, t) in mesh.triangles().iter().enumerate() {
            for &v in t {
                let slot = &mut fill[v as usize];
                triangles[*slot as usize] = f as u32;
                *slot += 1;
            }
        }
        VertexRings {
            offsets: counts,
            triangles,
        }
    }

    fn ring(&self, v: usize) -> &[u32] {
        &self.triangles[self.offsets[v] as usize..self.offsets[v + 1] as usize]
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        (self.offsets.len() + self.triangles.len()) * 4
    }
}

/// What stays fixed across the frames of one extraction.
pub struct SessionContext<'a> {
    /// The mesh (world frame).
    pub mesh: &'a TriangleMesh,
    /// Its vertex rings.
    pub rings: &'a VertexRings,
    /// The camera model.
    pub camera: &'a CameraModel,
    /// Largest squared normalised radius inside the image ([`max_radius_sq`]): beyond it the
    /// distortion polynomial may fold a point back into the frame.
    pub max_radius_sq: f64,
    /// The session's radiometry and analyser model.
    pub radiometry: &'a SessionRadiometry,
    /// Gates.
    pub gate: &'a GateConfig,
    /// Full scale minus the dark level, DN (what the gates compare against).
    pub full_scale_dn: f64,
    /// A material label per vertex (`None`: unknown): a footprint that meets a point whose
    /// nearest vertex has another label ([`UNLABELLED`] matches every label) mixes materials.
    pub labels: Option<&'a [u32]>,
    /// Taps of the sampling kernel lighter than this do not count to a sample's footprint
    /// ([`min_tap_weight`]).
    pub min_tap_weight: f64,
}

/// The lightest kernel tap that counts to a sample's footprint: the relative shot noise of a
/// pixel at half the sensor's full well, 1/√(full well / 2) (1.4 % for the IMX250's 10 500 e⁻
/// at 0 dB; `sensor.dn_per_electron` already carries the gain). A lighter tap on a
/// contaminant no brighter than the sample's own level moves the value by less than one noise
/// σ of a mid-scale pixel, so it cannot make the sample mixed.
pub fn min_tap_weight(full_scale_dn: f64, sensor: &crate::solve::SensorNoiseModel) -> f64 {
    let full_well_e = full_scale_dn / sensor.dn_per_electron.max(f64::MIN_POSITIVE);
    if full_well_e.is_finite() && full_well_e > 2.0 {
        (0.5 * full_well_e).sqrt().recip()
    } else {
        0.0
    }
}

/// Everything needed to observe every vertex in one frame.
pub struct FrameSampler<'a> {
    session: &'a SessionContext<'a>,
    view: &'a ViewGeometry,
    camera_from_world: Isometry3<f64>,
    world_from_camera: Isometry3<f64>,
    image: &'a dyn AnalyserPixels,
    normaliser: PointNormaliser,
}

/// The largest squared normalised (undistorted) radius of the image border, with 5 % margin;
/// infinity when the border cannot be undistorted (then only the pixel test applies).
pub fn max_radius_sq(camera: &CameraModel) -> f64 {
    let (w, h) = (f64::from(camera.width), f64::from(camera.height));
    let mut worst: f64 = 0.0;
    for k in 0..=8 {
        let f = f64::from(k) / 8.0;
        for p in [
            [f * w - 0.5, -0.5],
            [f * w - 0.5, h - 0.5],
            [-0.5, f * h - 0.5],
            [w - 0.5, f * h - 0.5],
        ] {
            match camera.undistort_pixel(p) {
                Ok([x, y]) => worst = worst.max(x * x + y * y),
                Err(_) => return f64::INFINITY,
            }
        }
    }
    worst * 1.05 * 1.05
}

impl<'a> FrameSampler<'a> {
    /// The sampler of one frame: its view and pose, its image, its exposure and gain, and the
    /// flash energy that lit it relative to a full pulse (> 0; the normaliser is scaled by it,
    /// module `radiometry`).
    pub fn new(
        session: &'a SessionContext<'a>,
        view: &'a ViewGeometry,
        world_from_camera: &Isometry3<f64>,
        image: &'a dyn AnalyserPixels,
        exposure_us: f64,
        gain_db: f64,
        flash_energy_rel: f64,
    ) -> Self {
        Self {
            session,
            view,
            camera_from_world: world_from_camera.inverse(),
            world_from_camera: *world_from_camera,
            image,
            normaliser: PointNormaliser::new(
                session.radiometry.for_frame(exposure_us, gain_db),
                &session.radiometry.flash,
                world_from_camera,
            )
            .with_flash_energy(flash_energy_rel),
        }
    }

    /// Whether the segment `from → to` is blocked by a triangle not incident to vertex `v`.
    fn blocked(&self, v: usize, from: &Point3<f64>, to: &Point3<f64>) -> bool {
        let ray = Ray::new(*from, to - from);
        let t_max = 1.0 - RAY_T_EPS;
        if !self.session.mesh.occluded(&ray, RAY_T_EPS, t_max) {
            return false;
        }
        let ring = self.session.rings.ring(v);
        let mut t_min = RAY_T_EPS;
        // Each incident triangle is met at most once (t strictly increases).
        for _ in 0..=ring.len() {
            match self.session.mesh.intersect(&ray, t_min, t_max) {
                None => return false,
                Some(hit) if ring.contains(&hit.primitive) => t_min = hit.t,
                Some(_) => return true,
            }
        }
        false
    }

    /// Whether the sample's footprint — the raw pixels its value draws on at this pixel
    /// ([`AnalyserPixels::footprint`], taps of weight |w_x·w_y| ≥
    /// [`SessionContext::min_tap_weight`]) — lies on the vertex's visible surface and material:
    /// the rays through its probe points (the corners of the taps' bounding octagon,
    /// [`Footprint`]) each meet the mesh within the distance a footprint of that size can
    /// cover on the vertex's tangent plane (the farthest probe's image distance
    /// at depth `depth_m`, stretched by 1/cos of the view angle, capped at 85°, plus the
    /// unstretched distance again as room for curvature), at a point of the vertex's own
    /// material. A ray that misses the mesh has left the object past a silhouette (or onto the
    /// board below a contact); one that meets it farther away crossed an occlusion boundary;
    /// one that meets another material (the label of the hit triangle's nearest corner: a
    /// material's region is its vertices' Voronoi cells on the surface, as the renderer's
    /// `region_blend = "nearest"` draws it) mixes materials. Either way the value holds light
    /// the vertex's model cannot explain. A point sample (an empty footprint) always passes.
    fn footprint_on_surface(
        &self,
        v: usize,
        position: &Point3<f64>,
        pixel: [f64; 2],
        footprint: &Footprint,
        depth_m: f64,
        cos_view: f64,
    ) -> bool {
        let far_px = footprint.reach_px(pixel);
        if far_px <= 0.0 {
            return true;
        }
        let px_m = depth_m / self.session.camera.intrinsics.fx.abs().max(1e-9);
        // On the tangent plane an image distance stretches by at most 1/cos θ.
        let reach_m = far_px * px_m * (1.0 + 1.0 / cos_view.max(COS_85_DEG));
        let origin = Point3::from(self.view.camera_position_world);
        // Corners first: they reach farthest, so a mixed footprint fails in fewer rays (every
        // ray must pass, so the order does not change the verdict).
        for &p in footprint.points() {
            let Ok(dir) = self.session.camera.unproject_to_ray(p) else {
                return false;
            };
            let ray = Ray::new(origin, self.world_from_camera.rotation * dir.into_inner());
            match self.session.mesh.intersect(&ray, 0.0, f64::INFINITY) {
                Some(hit) if (ray.at(hit.t) - position).norm() <= reach_m => {
                    if let Some(labels) = self.session.labels {
                        let own = labels[v];
                        let tri = self.session.mesh.triangles()[hit.primitive as usize];
                        let nearest = (0..3)
                            .max_by(|&i, &j| hit.barycentric[i].total_cmp(&hit.barycentric[j]))
                            .unwrap_or(0);
                        let there = labels[tri[nearest] as usize];
                        if own != UNLABELLED && there != UNLABELLED && there != own {
                            return false;
                        }
                    }
                }
                _ => return false,
            }
        }
        true
    }

    /// Observes vertex `v` in this frame.
    pub fn observe(&self, v: usize) -> Outcome {
        let position = self.session.mesh.positions()[v];
        let normal = self.session.mesh.normals()[v].into_inner();
        let p_cam = self.camera_from_world * position;
        let Some(pixel) = self.session.camera.project(&p_cam) else {
            return Outcome::NotInView;
        };
        let r2 = (p_cam.x * p_cam.x + p_cam.y * p_cam.y) / (p_cam.z * p_cam.z);
        if !(r2 <= self.session.max_radius_sq && self.session.camera.contains_pixel(pixel)) {
            return Outcome::NotInView;
        }
        let Some(g) = self.view.geometry_at(&position) else {
            return Outcome::NotInView;
        };
        let to_camera = Vector3::from(g.to_camera);
        let to_light = Vector3::from(g.to_light);
        let cos_view = normal.dot(&to_camera);
        if cos_view <= 0.0 {
            return Outcome::NotInView;
        }
        let camera_centre = Point3::from(self.view.camera_position_world);
        if self.blocked(v, &camera_centre, &position) {
            return Outcome::Occluded;
        }
        if normal.dot(&to_light) <= 0.0 {
            return Outcome::Shadowed;
        }
        let flash = Point3::from(self.view.flash_position_world);
        if self.blocked(v, &position, &flash) {
            return Outcome::Shadowed;
        }
        let min_weight = self.session.min_tap_weight;
        let footprint = self.image.footprint(pixel, min_weight);
        let on_surface =
            |f: &Footprint| self.footprint_on_surface(v, &position, pixel, f, p_cam.z, cos_view);
        let ((values, peaks), narrow) = if on_surface(&footprint) {
            (self.image.sample(pixel), false)
        } else {
            // Near a silhouette or a border the image's kernel reaches across, a narrower one
            // may not: its value draws on the vertex's own surface alone.
            match self.image.narrow(pixel, min_weight) {
                Some((footprint, value)) if on_surface(&footprint) => (value, true),
                _ => return Outcome::Mixed,
            }
        };
        let bands = self.image.band_count();
        let full_scale_dn = self.session.full_scale_dn;
        let gate = self.session.gate;
        let verdict = gate.check_sample(&values, bands, full_scale_dn, cos_view);
        if let Err(g @ (SampleGate::NonFinite | SampleGate::Grazing)) = verdict {
            return Outcome::Gate(g);
        }
        // Saturation over the whole bilinear footprint, then the remaining gates (dark).
        let saturation_dn = gate.saturation_fraction * full_scale_dn;
        if peaks[..bands]
            .iter()
            .flatten()
            .any(|&p| f64::from(p) >= saturation_dn)
        {
            return Outcome::Gate(SampleGate::Saturated);
        }
        if let Err(g) = verdict {
            return Outcome::Gate(g);
        }

        match self.in_model_units(&position, &values, bands) {
            Some(Ok(sample)) if narrow => Outcome::KeptNarrow(sample),
            Some(Ok(sample)) => Outcome::Kept(sample),
            Some(Err(gate)) => Outcome::Gate(gate),
            // Outside the flash's emission profile: not lit.
            None => Outcome::Shadowed,
        }
    }

    /// The sample of analyser values `values` (DN, `bands` bands) at `position` in model units:
    /// the observation channels divided by the normaliser N (its geometry exactly as the
    /// renderer's, `PointNormaliser`). `None` outside the flash's emission profile (N ≤ 0), the
    /// non-finite gate where N or a channel is not finite.
    fn in_model_units(
        &self,
        position: &Point3<f64>,
        values: &[[f32; 4]; 3],
        bands: usize,
    ) -> Option<Result<Sample, SampleGate>> {
        let n = self.normaliser.at(position);
        if !n.is_finite() {
            return Some(Err(SampleGate::NonFinite));
        }
        if n <= 0.0 {
            return None;
        }
        let mut channels = [[0f32; OBSERVATION_CHANNELS]; 3];
        for (c, out) in channels.iter_mut().enumerate() {
            let a = values[c.min(bands - 1)].map(f64::from);
            *out = self.session.radiometry.channels(a).map(|v| (v / n) as f32);
        }
        if channels.iter().flatten().any(|v| !v.is_finite()) || !(n as f32).is_finite() {
            return Some(Err(SampleGate::NonFinite));
        }
        Some(Ok(Sample {
            view: 0,
            channels,
            normaliser: n as f32,
        }))
    }
}
