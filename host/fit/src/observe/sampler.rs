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
    /// The image footprint of the sample's value reaches off the vertex's visible surface
    /// ([`AnalyserPixels::footprint_radius_px`], `FrameSampler::footprint_on_surface`).
    Mixed,
    /// A shared sample gate (non-finite, grazing, saturated, dark).
    Gate(SampleGate),
}

/// The demosaiced frame in dark-subtracted DN (see the module contract).
#[derive(Clone, Debug)]
pub struct DnImage {
    tile_px: f64,
    kernel: SampleKernel,
    /// Half-side of the square of raw pixels a sampled value draws on, px.
    footprint_radius_px: f64,
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
        kernel: SampleKernel,
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
        // A value interpolates lattice samples within one tile of the point (two for the
        // cubic kernel); a colour band's sample averages its blocks, which sit up to `spread`
        // raw pixels from their mean; every raw pixel covers ±½ px.
        let spread = match layout {
            SensorLayout::ColourPolar => ellipso_model::mosaic::Channel::ALL
                .iter()
                .map(|c| {
                    let b = c.blocks_in_tile();
                    let n = b.len() as f64;
                    let (mx, my) = (
                        b.iter().map(|b| 2.0 * b.0 as f64).sum::<f64>() / n,
                        b.iter().map(|b| 2.0 * b.1 as f64).sum::<f64>() / n,
                    );
                    b.iter()
                        .map(|b| {
                            (2.0 * b.0 as f64 - mx)
                                .abs()
                                .max((2.0 * b.1 as f64 - my).abs())
                        })
                        .fold(0.0, f64::max)
                })
                .fold(0.0, f64::max),
            SensorLayout::MonoPolar => 0.0,
        };
        let reach = match kernel {
            SampleKernel::Bilinear => 1.0,
            SampleKernel::CatmullRom => 2.0,
        };
        DnImage {
            tile_px: t as f64,
            kernel,
            footprint_radius_px: reach * t as f64 + spread + 0.5,
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

    /// Analyser DN `[I0, I45, I90, I135]` per band at raw pixel `(x, y)`, and per band and
    /// analyser the largest raw DN in the kernel's footprint.
    pub fn sample(&self, pixel: [f64; 2]) -> ([[f32; 4]; 3], [[f32; 4]; 3]) {
        let mut values = [[0f32; 4]; 3];
        let mut peaks = [[0f32; 4]; 3];
        let (w, h) = (self.width, self.height);
        for (b, band) in self.bands.iter().enumerate().take(3) {
            for k in 0..4 {
                let [ox, oy] = band.offset_px[k];
                let sx = (pixel[0] - ox) / self.tile_px;
                let sy = (pixel[1] - oy) / self.tile_px;
                let taps_x = self.kernel.taps(sx, w);
                let taps_y = self.kernel.taps(sy, h);
                let plane = &band.dn[k];
                let mut v = 0.0;
                let mut peak = f32::NEG_INFINITY;
                for &(y, wy) in taps_y.iter().filter(|t| t.1 != 0.0) {
                    for &(x, wx) in taps_x.iter().filter(|t| t.1 != 0.0) {
                        v += wx * wy * f64::from(plane[y * w + x]);
                        peak = peak.max(band.max_dn[y * w + x]);
                    }
                }
                values[b][k] = v as f32;
                peaks[b][k] = peak;
            }
        }
        (values, peaks)
    }
}

/// How the analyser planes are interpolated at a sample's lattice coordinate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SampleKernel {
    /// Bilinear (2 × 2 superpixels).
    #[default]
    Bilinear,
    /// Catmull–Rom cubic convolution (Keys 1981, a = −½; 4 × 4 superpixels): exact for
    /// quadratics, so a shading profile's curvature does not bias the value.
    CatmullRom,
}

impl SampleKernel {
    /// Up to four (index, weight) taps of lattice coordinate `s` in `0..n`; indices are clamped
    /// to the plane (the edge sample repeats), weights sum to 1.
    fn taps(self, s: f64, n: usize) -> [(usize, f64); 4] {
        let hi = n.saturating_sub(1);
        let s = s.clamp(0.0, hi as f64);
        let i = (s.floor() as usize).min(n.saturating_sub(2));
        let f = s - i as f64;
        let at = |d: isize| (i as isize + d).clamp(0, hi as isize) as usize;
        match self {
            SampleKernel::Bilinear => [(at(0), 1.0 - f), (at(1), f), (at(0), 0.0), (at(0), 0.0)],
            SampleKernel::CatmullRom => {
                let (f2, f3) = (f * f, f * f * f);
                [
                    (at(-1), 0.5 * (-f3 + 2.0 * f2 - f)),
                    (at(0), 0.5 * (3.0 * f3 - 5.0 * f2 + 2.0)),
                    (at(1), 0.5 * (-3.0 * f3 + 4.0 * f2 + f)),
                    (at(2), 0.5 * (f3 - f2)),
                ]
            }
        }
    }
}

/// A frame's analyser images as the sampler reads them (the recorded mosaic's [`DnImage`], or
/// an ideal sensor's in the error budget): per band, the four analysers' dark-subtracted DN at
/// a raw pixel position, and the largest raw DN of the pixels that value draws on (the
/// saturation test).
pub trait AnalyserPixels: Sync {
    /// Number of colour bands (1 mono, 3 colour).
    fn band_count(&self) -> usize;
    /// `[I0, I45, I90, I135]` per band at raw pixel `(x, y)`, and per band and analyser the
    /// largest raw DN in the footprint.
    fn sample(&self, pixel: [f64; 2]) -> ([[f32; 4]; 3], [[f32; 4]; 3]);
    /// Half-side of the square of raw pixels about the sampled point that a value draws on
    /// (its footprint), px; 0 for a point sample.
    fn footprint_radius_px(&self) -> f64;
}

impl AnalyserPixels for DnImage {
    fn band_count(&self) -> usize {
        DnImage::band_count(self)
    }

    fn sample(&self, pixel: [f64; 2]) -> ([[f32; 4]; 3], [[f32; 4]; 3]) {
        DnImage::sample(self, pixel)
    }

    fn footprint_radius_px(&self) -> f64 {
        self.footprint_radius_px
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
    /// A material label per vertex (`None`: unknown): a footprint that meets a triangle with
    /// a corner of another label mixes materials.
    pub labels: Option<&'a [u32]>,
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

    /// Whether the sample's footprint — the square of half-side
    /// [`AnalyserPixels::footprint_radius_px`] about its pixel — lies on the vertex's visible
    /// surface: the rays through its four corners and four edge midpoints each meet the mesh
    /// within the distance a footprint of that size can cover on the vertex's tangent plane
    /// (the corners' image distance at depth `depth_m`, stretched by 1/cos of the view angle,
    /// capped at 85°, plus the unstretched distance again as room for curvature). A ray that
    /// misses the mesh has left the object past a silhouette (or onto the board below a
    /// contact); one that meets it farther away crossed an occlusion boundary. Either way the
    /// value mixes in light the vertex's model cannot explain. A point sample (radius 0)
    /// always passes.
    fn footprint_on_surface(
        &self,
        v: usize,
        position: &Point3<f64>,
        pixel: [f64; 2],
        depth_m: f64,
        cos_view: f64,
    ) -> bool {
        let r = self.image.footprint_radius_px();
        if r <= 0.0 {
            return true;
        }
        let px_m = depth_m / self.session.camera.intrinsics.fx.abs().max(1e-9);
        // A corner is r·√2 px off; on the tangent plane that stretches by at most 1/cos θ.
        let reach_m = r * std::f64::consts::SQRT_2 * px_m * (1.0 + 1.0 / cos_view.max(COS_85_DEG));
        let origin = Point3::from(self.view.camera_position_world);
        for (dx, dy) in [
            (-1.0, -1.0),
            (0.0, -1.0),
            (1.0, -1.0),
            (-1.0, 0.0),
            (1.0, 0.0),
            (-1.0, 1.0),
            (0.0, 1.0),
            (1.0, 1.0),
        ] {
            let Ok(dir) = self
                .session
                .camera
                .unproject_to_ray([pixel[0] + dx * r, pixel[1] + dy * r])
            else {
                return false;
            };
            let ray = Ray::new(origin, self.world_from_camera.rotation * dir.into_inner());
            match self.session.mesh.intersect(&ray, 0.0, f64::INFINITY) {
                Some(hit) if (ray.at(hit.t) - position).norm() <= reach_m => {
                    if let Some(labels) = self.session.labels {
                        let tri = self.session.mesh.triangles()[hit.primitive as usize];
                        if tri.iter().any(|&c| labels[c as usize] != labels[v]) {
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
        if !self.footprint_on_surface(v, &position, pixel, p_cam.z, cos_view) {
            return Outcome::Mixed;
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
