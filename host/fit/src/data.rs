//! The data contract of the fit: what observation extraction produces and the solver,
//! the shape update and export consume.
//!
//! Contract:
//! - World frame = board frame (metres). Every view carries the camera centre, the camera's
//!   image-up axis and the flash position and polariser axis in the world, so the model's
//!   light and camera frames are rebuilt exactly as the renderer builds them
//!   ([`ViewGeometry::geometry_at`]): light frame z = −ω_i with x along the flash polariser
//!   (light up = (−ω_i) × axis), or the camera's up for an unpolarised flash; camera frame
//!   z = ω_o, y = image up. The flash Stokes vector is then `[1, 1, 0, 0]` (polarised) or
//!   `[1, 0, 0, 0]` ([`ViewGeometry::flash_polariser`]).
//! - A [`Sample`] holds the observation channels (I^d, I^s, I^α and I^t = I45 + I135 per RGB
//!   channel, docs/model.md "Measurement") already divided by the radiometric normaliser N (`ellipso_model::radiometry`), i.e. in
//!   the units of `ellipso_model::optics::measure::observe` with a unit flash. On a monochrome
//!   sensor all three colour entries are equal and [`SampleSet::colour`] is false.
//! - `normaliser` (DN per model unit) is kept so the solver can weight by expected noise; it is
//!   always > 0 and finite in a valid sample.
//! - Samples reference their view by index into [`SampleSet::views`]; per sample only 56 bytes
//!   are stored, so 100 000 vertices × 150 views fit in well under 1 GB.

use ellipso_model::optics::OpticsError;
use ellipso_model::optics::Vec3;
use ellipso_model::optics::measure::{AnalyserAngles, FlashPolariser};
use ellipso_model::optics::pbrdf::{Geometry, PbrdfParams};
use nalgebra::{Point3, Vector3};

mod flags;

pub use flags::{FitFlag, Identifiable, MAX_REPORTED_ANGLE_STD_DEG};

/// One view: where the camera and the flash were, in the world.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ViewGeometry {
    /// The session's frame id of this view.
    pub frame_id: u64,
    /// Camera centre, world, metres.
    pub camera_position_world: [f64; 3],
    /// Image-up axis of the camera (−y of the OpenCV camera frame), world, unit.
    pub camera_up_world: [f64; 3],
    /// Flash (light) position, world, metres.
    pub flash_position_world: [f64; 3],
    /// Flash polariser transmission axis, world, unit (`None`: unpolarised flash).
    pub polariser_axis_world: Option<[f64; 3]>,
    /// Optical axis of the camera (+z of the OpenCV camera frame), world, unit. With it the
    /// analysers' effective angles of an off-axis ray follow the wire-grid model
    /// ([`ellipso_model::optics::measure::AnalyserAngles::for_ray`]); `None` takes the on-axis
    /// (ideal 0/45/90/135°) angles for every ray.
    #[serde(default)]
    pub camera_axis_world: Option<[f64; 3]>,
}

/// The model geometry of one (vertex, view) pair: unit directions away from the surface and
/// the up vectors that fix the light and camera frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleGeometry {
    /// Unit vector from the surface point to the flash, world.
    pub to_light: [f64; 3],
    /// Unit vector from the surface point to the camera, world.
    pub to_camera: [f64; 3],
    /// Light-frame up vector, world (not necessarily unit or orthogonal to `to_light`).
    pub light_up: [f64; 3],
    /// Camera-frame up vector, world.
    pub camera_up: [f64; 3],
    /// Distance surface → flash, metres.
    pub light_distance_m: f64,
    /// Distance surface → camera, metres.
    pub camera_distance_m: f64,
}

impl SampleGeometry {
    /// The optics model's [`Geometry`] for a `normal` (any scalar, e.g. dual numbers).
    pub fn model<T: ellipso_model::optics::Real>(
        &self,
        normal: Vec3<T>,
    ) -> Result<Geometry<T>, OpticsError> {
        let v = |a: [f64; 3]| Vec3::new(T::from_f64(a[0]), T::from_f64(a[1]), T::from_f64(a[2]));
        Geometry::from_up_vectors(
            normal,
            v(self.to_light),
            v(self.to_camera),
            v(self.light_up),
            v(self.camera_up),
        )
    }
}

impl ViewGeometry {
    /// The view of a rig at `world_from_camera` (OpenCV camera axes): camera up = −y of the
    /// camera frame, the flash rigidly offset from the camera and its polariser axis, exactly as
    /// the renderer places them (`FlashSpec::position_world`, `FlashSpec::polariser_axis_world`).
    pub fn from_rig(
        frame_id: u64,
        world_from_camera: &nalgebra::Isometry3<f64>,
        flash: &ellipso_model::rig::FlashSpec,
    ) -> Self {
        let up = world_from_camera.transform_vector(&Vector3::new(0.0, -1.0, 0.0));
        let axis = world_from_camera.transform_vector(&Vector3::z());
        Self {
            frame_id,
            camera_position_world: world_from_camera.translation.vector.into(),
            camera_up_world: up.into(),
            camera_axis_world: Some(axis.into()),
            flash_position_world: flash.position_world(world_from_camera).coords.into(),
            polariser_axis_world: flash
                .polariser_axis_world(world_from_camera)
                .map(|a| a.into_inner().into()),
        }
    }

    /// The flash polariser in the light frame [`ViewGeometry::geometry_at`] builds (angle 0:
    /// the light frame's x is the polariser axis).
    pub fn flash_polariser(&self) -> FlashPolariser {
        FlashPolariser { angle_rad: 0.0 }
    }

    /// The analysers' effective angles for the ray of `g` (wire-grid model,
    /// [`AnalyserAngles::for_ray`]); nominal without [`ViewGeometry::camera_axis_world`].
    pub fn analyser_angles(&self, g: &SampleGeometry) -> AnalyserAngles {
        match self.camera_axis_world {
            Some(axis) => {
                let up = self.camera_up_world;
                // Image right = (−up) × optical axis (OpenCV: x = y × z with y = −up).
                let right = [
                    axis[1] * up[2] - axis[2] * up[1],
                    axis[2] * up[0] - axis[0] * up[2],
                    axis[0] * up[1] - axis[1] * up[0],
                ];
                AnalyserAngles::for_ray(right, up, g.to_camera)
            }
            None => AnalyserAngles::ideal(),
        }
    }

    /// Whether the flash is polarised in this view.
    pub fn polarised(&self) -> bool {
        self.polariser_axis_world.is_some()
    }

    /// The geometry of this view at `position_world`, or `None` when the point coincides with
    /// the camera or the flash (closer than 1 µm: no direction is defined) or the light frame
    /// degenerates (ω_i parallel to the polariser axis, impossible for a flash that faces
    /// the scene).
    pub fn geometry_at(&self, position_world: &Point3<f64>) -> Option<SampleGeometry> {
        const MIN_DISTANCE_M: f64 = 1e-6;
        let to_light = Point3::from(self.flash_position_world) - position_world;
        let to_camera = Point3::from(self.camera_position_world) - position_world;
        let light_distance_m = to_light.norm();
        let camera_distance_m = to_camera.norm();
        if !(light_distance_m > MIN_DISTANCE_M && camera_distance_m > MIN_DISTANCE_M) {
            return None;
        }
        let to_light = to_light / light_distance_m;
        let to_camera = to_camera / camera_distance_m;
        let camera_up = Vector3::from(self.camera_up_world);
        let light_up = match self.polariser_axis_world {
            Some(axis) => {
                let up = (-to_light).cross(&Vector3::from(axis));
                // A polariser axis along the beam defines no frame.
                if up.norm() < 1e-9 {
                    return None;
                }
                up
            }
            None => camera_up,
        };
        Some(SampleGeometry {
            to_light: to_light.into(),
            to_camera: to_camera.into(),
            light_up: light_up.into(),
            camera_up: camera_up.into(),
            light_distance_m,
            camera_distance_m,
        })
    }
}

/// Observation channels per colour channel of a [`Sample`]: I^d = 2·I90, I^s = I0 − I90,
/// I^α = I135 − I45 (the paper's three, optics of docs/model.md) and I^t = I45 + I135, the sum the
/// paper's channels drop (≈ s0; with it all four analyser pixels reach the fit: about 25 % more
/// information on η than the three channels alone).
pub const OBSERVATION_CHANNELS: usize = 4;

/// One (vertex, view) observation, in model units (divided by the normaliser N).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sample {
    /// Index into [`SampleSet::views`].
    pub view: u32,
    /// Per colour channel (R, G, B): [I^d, I^s, I^α, I^t] divided by N
    /// ([`OBSERVATION_CHANNELS`]).
    pub channels: [[f32; OBSERVATION_CHANNELS]; 3],
    /// N: digital numbers per model unit at this (vertex, view) (exposure, gain, 1/d², flash
    /// profile, vignetting). > 0.
    pub normaliser: f32,
}

/// One virtual specular sample of the paper's augmentation (docs/fit-augment.md "Virtual profile
/// and kernel"): the value of the vertex's cluster two-lobe model at an exactly coaxial geometry
/// (θ_i = θ_o = θ_h, Fresnel at normal incidence), compared with the vertex's own model at the
/// same geometry.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct VirtualSample {
    /// cos θ_h of the coaxial geometry (θ_h ∈ [0°, 89.5°]).
    pub cos_theta_h: f64,
    /// I^s per colour channel (R, G, B), model units (as a real sample divided by N).
    pub specular: [f64; 3],
    /// Weight; a vertex's virtual weights sum to λ_g (0.1 by default), the real samples'
    /// specular residuals to 1 − λ_g.
    pub weight: f64,
}

/// What the shared steps (clusters, docs/fit-augment.md) hand one vertex's final solve: the
/// paper's virtual samples and σs floor (docs/model.md §11 "Steps A, B, C and the outer loop")
/// and a pooled prior on η.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct VertexGuide {
    /// Virtual coaxial specular samples (empty: none).
    pub virtual_samples: Vec<VirtualSample>,
    /// Lower bound of σs (the cluster's σs/2; 0: the solver's own floor).
    pub sigma_s_floor: f64,
    /// Pooled prior on η, (mean, standard deviation) (`None`: the solver's weak default prior).
    pub eta_prior: Option<[f64; 2]>,
    /// The cluster's lobe (σs, σss, ρs): a start of the final solve beside the vertex's own.
    pub lobe_start: Option<[f64; 3]>,
}

/// Why samples or vertices were gated out; counted per reason (docs/model.md §11 "Sample
/// gating").
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct GateCounts {
    /// Behind the camera, outside the image, or the vertex faces away.
    pub not_in_view: u64,
    /// Another part of the mesh hides the vertex from the camera.
    pub occluded: u64,
    /// The vertex is in the flash's shadow.
    pub shadowed: u64,
    /// The pixels the sample's value is interpolated from reach off the vertex's visible
    /// surface (past a silhouette, across an occlusion boundary, onto the board under a
    /// contact): they mix light the vertex's model cannot explain.
    #[serde(default)]
    pub mixed: u64,
    /// View direction beyond the grazing cut-off.
    pub grazing: u64,
    /// Any analyser pixel at or above the saturation level.
    pub saturated: u64,
    /// Normalised intensity below the dark threshold.
    pub dark: u64,
    /// A non-finite value in the sampled pixels.
    pub non_finite: u64,
    /// Rejected by the colour-outlier test.
    pub colour_outlier: u64,
    /// Samples kept.
    pub kept: u64,
}

impl GateCounts {
    /// Samples of frames that saw the vertex lit (kept, or gated for what the pixels showed:
    /// mixed, grazing, saturated, dark, non-finite, colour outlier); the rest had it out of
    /// view, occluded or in the flash's shadow.
    pub fn seen_lit(&self) -> u64 {
        self.kept
            + self.mixed
            + self.grazing
            + self.saturated
            + self.dark
            + self.non_finite
            + self.colour_outlier
    }

    /// Adds `other` to `self`, reason by reason.
    pub fn add(&mut self, other: &GateCounts) {
        self.not_in_view += other.not_in_view;
        self.occluded += other.occluded;
        self.shadowed += other.shadowed;
        self.mixed += other.mixed;
        self.grazing += other.grazing;
        self.saturated += other.saturated;
        self.dark += other.dark;
        self.non_finite += other.non_finite;
        self.colour_outlier += other.colour_outlier;
        self.kept += other.kept;
    }
}

/// The samples of one vertex.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct VertexSamples {
    /// Vertex index in the mesh.
    pub vertex: u32,
    /// Vertex position, world, metres.
    pub position_world: [f64; 3],
    /// Current (initial) unit normal, world.
    pub normal_world: [f64; 3],
    /// The kept samples, ordered by view index.
    pub samples: Vec<Sample>,
    /// What was gated out for this vertex, per reason.
    pub gates: GateCounts,
}

/// Everything the solver needs: the views and every vertex's samples.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SampleSet {
    /// The views, indexed by [`Sample::view`].
    pub views: Vec<ViewGeometry>,
    /// Colour sensor (three independent channels) or monochrome (three equal entries).
    pub colour: bool,
    /// One entry per mesh vertex, in mesh order.
    pub vertices: Vec<VertexSamples>,
    /// The mesh's edge neighbours of every vertex (`crate::neighbours::rings`), where the set
    /// holds every vertex of a mesh (empty otherwise, e.g. a shard's part): the shared steps
    /// judge a vertex's η beside its surroundings' with them.
    #[serde(skip)]
    pub rings: Vec<Vec<u32>>,
}

/// The fitted parameters of one vertex, with standard errors.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct VertexFit {
    /// Vertex index in the mesh.
    pub vertex: u32,
    /// Fitted parameters (always finite and inside the model's domain).
    pub params: PbrdfParams<f64>,
    /// Refined unit normal, world.
    pub normal_world: [f64; 3],
    /// Standard errors from the Gauss–Newton covariance at the solution (σ²·(JᵀJ)⁻¹), in
    /// parameter units: η, σ_s, σ_ss, ρ_s, ρ_ss RGB, ρ_d RGB; `f64::INFINITY` where the
    /// parameter is not identifiable.
    pub std_error: [f64; 10],
    /// Normal uncertainty, degrees (1σ cone half-angle).
    pub normal_std_error_deg: f64,
    /// Samples used.
    pub samples_used: u32,
    /// Final cost (sum of weighted squared residuals).
    pub cost: f64,
    /// Solver iterations (last pass).
    pub iterations: u32,
    /// Reasons not to trust the result as is (empty: fine).
    pub flags: Vec<FitFlag>,
    /// The vertex's own η and its standard error before its material's pool entered
    /// ([`FitFlag::EtaPooled`]: step A's estimate); `None` where no pool did.
    #[serde(default)]
    pub eta_unpooled: Option<[f64; 2]>,
    /// The vertex's data carry less information on η than the solver's default prior: its
    /// whitened rows, the prior's included, leave η more than half the prior's variance
    /// (`solve/finish.rs`, measurement loss without a pooled prior; also flagged
    /// [`FitFlag::EtaUnidentifiable`]). Unlike the standard error it does not shrink when the
    /// recorded noise is inflated uniformly, so the material pool judges with it whether the
    /// data moved η at all (`crate::augment::pool_eta`).
    #[serde(default)]
    pub eta_prior_only: bool,
    /// What the gates removed of the vertex's (vertex, view) pairs, per reason, and what they
    /// kept (the extraction's counts for this vertex).
    #[serde(default)]
    pub gates: GateCounts,
}

/// Whether any albedo of `params` sits at the solver's cap `albedo_cap` (within 0.1 %): the
/// condition of [`FitFlag::AlbedoAtCap`].
pub fn albedo_at_cap(params: &PbrdfParams<f64>, albedo_cap: f64) -> bool {
    [params.rho_s]
        .iter()
        .chain(&params.rho_ss)
        .chain(&params.rho_d)
        .any(|v| *v >= albedo_cap * (1.0 - 1e-3))
}

impl VertexFit {
    /// Whether η of this vertex is a measurement (the rule's `eta`, [`VertexFit::identifiable`]).
    pub fn eta_identified(&self) -> bool {
        self.identifiable().eta
    }

    /// The flags every output writes: the fit's own, plus [`FitFlag::NormalUnconstrained`]
    /// where the normal's standard error exceeds [`MAX_REPORTED_ANGLE_STD_DEG`] or is not
    /// finite.
    pub fn output_flags(&self) -> Vec<FitFlag> {
        let mut flags = self.flags.clone();
        // NaN counts as unconstrained
        if self.normal_std_error_deg.is_nan()
            || self.normal_std_error_deg > MAX_REPORTED_ANGLE_STD_DEG
        {
            flags.push(FitFlag::NormalUnconstrained);
        }
        flags.sort();
        flags.dedup();
        flags
    }

    /// The bitmask of [`VertexFit::output_flags`].
    pub fn output_mask(&self) -> u32 {
        FitFlag::mask(&self.output_flags())
    }

    /// The identifiability rule applied to this vertex's output flags.
    pub fn identifiable(&self) -> Identifiable {
        Identifiable::of_mask(self.output_mask())
    }

    /// Standard errors as every output reports them ([`Identifiable::std_error`]).
    pub fn reported_std_error(&self) -> [f64; 10] {
        self.identifiable().std_error(&self.std_error)
    }

    /// The normal's standard error as outputs report it: at most
    /// [`MAX_REPORTED_ANGLE_STD_DEG`] (flagged [`FitFlag::NormalUnconstrained`] beyond).
    pub fn reported_normal_std_deg(&self) -> f64 {
        if self.normal_std_error_deg <= MAX_REPORTED_ANGLE_STD_DEG {
            self.normal_std_error_deg
        } else {
            MAX_REPORTED_ANGLE_STD_DEG
        }
    }

    /// Whether the outputs draw and re-render this vertex's parameters (the rule's `vertex`:
    /// seen from enough views and no albedo at the solver's cap — an albedo there means the
    /// data fixed only a product like ρ·σ², not the lobe). The pictures interpolate untrusted
    /// vertices from trusted neighbours; the held-out score reports them apart.
    pub fn is_reliable(&self) -> bool {
        self.identifiable().vertex
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view() -> ViewGeometry {
        ViewGeometry {
            frame_id: 0,
            camera_position_world: [0.0, 0.0, 0.5],
            camera_up_world: [0.0, 1.0, 0.0],
            flash_position_world: [0.0, -0.03, 0.5],
            polariser_axis_world: Some([1.0, 0.0, 0.0]),
            camera_axis_world: Some([0.0, 0.0, -1.0]),
        }
    }

    #[test]
    fn geometry_directions_are_unit_and_point_away_from_the_surface() {
        let g = view().geometry_at(&Point3::new(0.01, 0.02, 0.0)).unwrap();
        for d in [g.to_light, g.to_camera] {
            let n = Vector3::from(d).norm();
            assert!((n - 1.0).abs() < 1e-12);
            assert!(d[2] > 0.9);
        }
        assert!(
            (g.camera_distance_m - (0.01f64.powi(2) + 0.02f64.powi(2) + 0.25).sqrt()).abs() < 1e-12
        );
        // Light up is perpendicular to the beam and to the polariser axis.
        let up = Vector3::from(g.light_up);
        assert!(up.dot(&Vector3::from(g.to_light)).abs() < 1e-12);
        assert!(up.dot(&Vector3::x()).abs() < 1e-12);
    }

    #[test]
    fn degenerate_positions_have_no_geometry() {
        let v = view();
        assert!(
            v.geometry_at(&Point3::from(v.camera_position_world))
                .is_none()
        );
        assert!(
            v.geometry_at(&Point3::from(v.flash_position_world))
                .is_none()
        );
        // A point along the polariser axis from the flash: the beam is parallel to the axis.
        let p = Point3::new(1.0, -0.03, 0.5);
        assert!(v.geometry_at(&p).is_none());
    }

    #[test]
    fn model_geometry_builds_for_a_front_facing_normal() {
        let g = view().geometry_at(&Point3::new(0.0, 0.0, 0.0)).unwrap();
        let n = Vec3::new(0.0, 0.0, 1.0);
        assert!(g.model::<f64>(n).is_ok());
    }
}
