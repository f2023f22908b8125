//! One frame's observations: the demosaiced frame in DN, sampled at every vertex's projection,
//! with visibility (view frustum, facing, occlusion, flash shadow), the shared sample gates and
//! the normaliser.
//!
//! Contract:
//! - [`DnImage`] holds the SUPERPIXEL planes of `ellipso_polar::demosaic` (no demosaic
//!   interpolation) converted back to dark-subtracted DN, plus per superpixel and colour band the
//!   largest raw DN of its samples (the saturation test). A raw position `x` maps to superpixel
//!   coordinate `(x − o)/t` with `t` the tile size and `o` the raw offset of the sample inside
//!   its tile: with [`SamplePoint::Lattice`] (default) `o` is where that colour-analyser sample
//!   really sits (a 0° mono sample at raw `2u + 1`; colour G averages its two blocks, so its
//!   offset is their mean), with [`SamplePoint::SuperpixelCentre`] it is the tile centre
//!   `(t − 1)/2` for every sample (track.rs step 3). Values are bilinear in those coordinates,
//!   clamped to the edge superpixels at the border.
//! - A sample is saturated when any superpixel in its bilinear footprint has a raw DN at or
//!   above the gate's saturation level, so a clipped neighbour never leaks into an interpolated
//!   value that looks unclipped. Every gate judges the frame's own DN, before the division by
//!   the (flash-energy-scaled) normaliser: a highlight that clips at full energy is dropped in
//!   that frame and kept in a shorter-pulse frame where it does not clip.
//! - Occlusion and shadow rays ignore the triangles incident to the vertex (a ray ending on a
//!   vertex cannot be blocked by a triangle that contains it; this is exact) and hits within
//!   [`RAY_T_EPS`] of either end (relative to the segment length: 50 nm at 0.5 m), which absorbs
//!   coincident duplicate vertices of unwelded meshes.

use ellipso_model::camera::CameraModel;
use ellipso_model::geometry::{Intersect, Ray, TriangleMesh};
use ellipso_model::mosaic::{Analyser, SensorLayout};
use nalgebra::{Isometry3, Point3, Vector3};

use super::SamplePoint;
use super::radiometry::{PointNormaliser, SessionRadiometry};
use crate::data::{OBSERVATION_CHANNELS, Sample, ViewGeometry};
use crate::gate::{GateConfig, SampleGate};
use ellipso_polar::demosaic::{AnalyserImage, Levels};
use ellipso_polar::frame::RawFrame;

/// Ray parameter margin at both ends of an occlusion or shadow segment (relative to its length).
pub const RAY_T_EPS: f64 = 1e-7;

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
    /// A shared sample gate (non-finite, grazing, saturated, dark).
    Gate(SampleGate),
}

/// The demosaiced frame in dark-subtracted DN (see the module contract).
#[derive(Clone, Debug)]
pub struct DnImage {
    tile_px: f64,
    width: usize,
    height: usize,
    bands: Vec<DnBand>,
}

#[derive(Clone, Debug)]
struct DnBand {
    /// `[I0, I45, I90, I135]` planes, DN.
    dn: [Vec<f32>; 4],
    /// Raw offsets (x, y) of each analyser's sample inside the tile, px.
    offset_px: [[f64; 2]; 4],
    /// Largest dark-subtracted raw DN of the band's samples per superpixel.
    max_dn: Vec<f32>,
}

impl DnImage {
    /// From a superpixel demosaic of `raw` with `levels`.
    pub fn new(
        raw: &RawFrame,
        image: &AnalyserImage,
        levels: &Levels,
        point: SamplePoint,
    ) -> DnImage {
        let layout = raw.layout();
        let t = layout.tile_px() as usize;
        let (w, h) = (raw.width() as usize / t, raw.height() as usize / t);
        // DN per normalised unit, from the levels themselves (one definition of the scale).
        let dn_per_unit = 1.0 / (levels.normalise(1) - levels.normalise(0));
        let dark = levels.dark_dn();
        let data = raw.data_dn();
        let raw_w = raw.width() as usize;
        let bands = image
            .bands
            .iter()
            .map(|band| {
                let blocks: &[(usize, usize)] = match (layout, band.colour) {
                    (SensorLayout::ColourPolar, Some(c)) => c.blocks_in_tile(),
                    _ => &[(0, 0)],
                };
                let offset_px = Analyser::ALL.map(|a| match point {
                    SamplePoint::SuperpixelCentre => [(t as f64 - 1.0) / 2.0; 2],
                    SamplePoint::Lattice => {
                        let (ax, ay) = a.offset_in_block();
                        let n = blocks.len() as f64;
                        let mean = |f: &dyn Fn(&(usize, usize)) -> usize| {
                            blocks.iter().map(|b| f(b) as f64).sum::<f64>() / n
                        };
                        [mean(&|b| 2 * b.0 + ax), mean(&|b| 2 * b.1 + ay)]
                    }
                });
                let dn = std::array::from_fn(|k| {
                    band.intensity[k]
                        .data()
                        .iter()
                        .map(|&v| v * dn_per_unit)
                        .collect()
                });
                // Row by row: for each block of the tile, the two raw rows it covers, and the
                // largest of its 2×2 samples per tile column (the tiles lie inside the frame:
                // w·t ≤ raw width, h·t ≤ raw height).
                let mut max_dn = vec![0f32; w * h];
                let mut top = vec![0u16; w];
                for (j, row) in max_dn.chunks_exact_mut(w).enumerate() {
                    top.fill(0);
                    for &(bx, by) in blocks {
                        for dy in 0..2 {
                            let y = t * j + 2 * by + dy;
                            let Some(raw_row) = data.get(y * raw_w..(y + 1) * raw_w) else {
                                continue;
                            };
                            for (i, m) in top.iter_mut().enumerate() {
                                let x = t * i + 2 * bx;
                                if let Some(pair) = raw_row.get(x..x + 2) {
                                    *m = (*m).max(pair[0]).max(pair[1]);
                                }
                            }
                        }
                    }
                    for (m, &v) in row.iter_mut().zip(&top) {
                        *m = f32::from(v) - dark;
                    }
                }
                DnBand {
                    dn,
                    offset_px,
                    max_dn,
                }
            })
            .collect();
        DnImage {
            tile_px: t as f64,
            width: w,
            height: h,
            bands,
        }
    }

    /// Number of colour bands (1 mono, 3 colour).
    pub fn band_count(&self) -> usize {
        self.bands.len()
    }

    /// Bytes held by the planes.
    pub fn bytes(&self) -> usize {
        self.bands.len() * 5 * self.width * self.height * std::mem::size_of::<f32>()
    }

    /// Bilinear weights of lattice coordinate `s` in `0..n`: (index, fraction), clamped.
    fn axis(s: f64, n: usize) -> (usize, f64) {
        let hi = n.saturating_sub(1) as f64;
        let s = s.clamp(0.0, hi);
        let i = (s.floor() as usize).min(n.saturating_sub(2));
        (i, s - i as f64)
    }

    /// Analyser DN `[I0, I45, I90, I135]` per band at raw pixel `(x, y)`, and per band and
    /// analyser the largest raw DN in the bilinear footprint.
    pub fn sample(&self, pixel: [f64; 2]) -> ([[f32; 4]; 3], [[f32; 4]; 3]) {
        let mut values = [[0f32; 4]; 3];
        let mut peaks = [[0f32; 4]; 3];
        let (w, h) = (self.width, self.height);
        for (b, band) in self.bands.iter().enumerate().take(3) {
            for k in 0..4 {
                let [ox, oy] = band.offset_px[k];
                let (i, fx) = Self::axis((pixel[0] - ox) / self.tile_px, w);
                let (j, fy) = Self::axis((pixel[1] - oy) / self.tile_px, h);
                let i1 = (i + 1).min(w - 1);
                let j1 = (j + 1).min(h - 1);
                let plane = &band.dn[k];
                let at = |x: usize, y: usize| f64::from(plane[y * w + x]);
                let v = (1.0 - fy) * ((1.0 - fx) * at(i, j) + fx * at(i1, j))
                    + fy * ((1.0 - fx) * at(i, j1) + fx * at(i1, j1));
                values[b][k] = v as f32;
                let mut peak = f32::NEG_INFINITY;
                for (x, y, wgt) in [
                    (i, j, (1.0 - fx) * (1.0 - fy)),
                    (i1, j, fx * (1.0 - fy)),
                    (i, j1, (1.0 - fx) * fy),
                    (i1, j1, fx * fy),
                ] {
                    if wgt > 0.0 {
                        peak = peak.max(band.max_dn[y * w + x]);
                    }
                }
                peaks[b][k] = peak;
            }
        }
        (values, peaks)
    }
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
}

/// Everything needed to observe every vertex in one frame.
pub struct FrameSampler<'a> {
    session: &'a SessionContext<'a>,
    view: &'a ViewGeometry,
    camera_from_world: Isometry3<f64>,
    image: &'a DnImage,
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
        image: &'a DnImage,
        exposure_us: f64,
        gain_db: f64,
        flash_energy_rel: f64,
    ) -> Self {
        Self {
            session,
            view,
            camera_from_world: world_from_camera.inverse(),
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

        let (values, peaks) = self.image.sample(pixel);
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

        // Normaliser geometry exactly as the renderer's (`PointNormaliser`).
        let n = self.normaliser.at(&position);
        if !n.is_finite() {
            return Outcome::Gate(SampleGate::NonFinite);
        }
        if n <= 0.0 {
            // Outside the flash's emission profile: not lit.
            return Outcome::Shadowed;
        }
        let mut channels = [[0f32; OBSERVATION_CHANNELS]; 3];
        for (c, out) in channels.iter_mut().enumerate() {
            let a = values[c.min(bands - 1)].map(f64::from);
            *out = self.session.radiometry.channels(a).map(|v| (v / n) as f32);
        }
        if channels.iter().flatten().any(|v| !v.is_finite()) || !(n as f32).is_finite() {
            return Outcome::Gate(SampleGate::NonFinite);
        }
        Outcome::Kept(Sample {
            view: 0,
            channels,
            normaliser: n as f32,
        })
    }
}
