//! The model's numbers at one input, for `ellipso model`: Fresnel terms ([`fresnel`]), the
//! diffuse degree of polarisation ([`dop`]) and the Mueller matrices of the three lobes at one
//! geometry ([`mueller`]), each returned typed for the binary to print or serialise.
//!
//! Contract: every input is checked against documented ranges and a bad one is refused in one
//! error naming its flag and the range (the scene files' ranges where they have one):
//! η ∈ [1, [`MAX_ETA`]]; θ ∈ [0°, 90°]; σ_s, σ_ss ∈ [0, 1] with σ_s ≤ σ_ss; ρ_s and each ρ_ss ∈
//! [0, [`MAX_LOBE_ALBEDO`]]; each ρ_d ∈ [0, 1]; direction vectors finite and non-zero, of any
//! length (normalised after scaling by their largest component, so 1e-300 and 1e300 both work).
//! A result that is not finite anyway is an error, never returned. Frames of [`mueller`]: light
//! frame z = −to_light, camera frame z = to_camera, y = the given up vector (default world +y)
//! orthogonalised against z, x = y × z; when the up vector is parallel to z the world axis least
//! aligned with z is used instead.

use super::OpticsError;

use super::measure::dop_diffuse_with_d_eta;
use super::pbrdf::{Geometry, PbrdfParams, evaluate};
use super::{Frame, FresnelTerms, Vec3};

/// Why the model's numbers cannot be given for these inputs.
#[derive(Debug, thiserror::Error)]
pub enum InspectError {
    /// An input out of its range (the message names the flag and the range), or a result that
    /// is not finite.
    #[error("{0}")]
    Input(String),
    /// The optics refused the geometry or the parameters.
    #[error(transparent)]
    Optics(#[from] OpticsError),
}

/// Returns an [`InspectError::Input`] made like `format!`.
macro_rules! bail {
    ($($arg:tt)*) => {
        return Err(InspectError::Input(format!($($arg)*)))
    };
}

/// Largest refractive index (the scene files' limit: no dielectric exceeds it).
pub const MAX_ETA: f64 = 5.0;

/// Largest specular and single-scattering albedo a material may have (far above any real
/// surface; it keeps every rendered value finite). The scene files' limit too.
pub const MAX_LOBE_ALBEDO: f64 = 1_000.0;

/// `ellipso model fresnel`: the Fresnel amplitudes and Mueller quantities of a dielectric.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct FresnelTable {
    /// s amplitude r_s.
    pub rs: f64,
    /// p amplitude r_p.
    pub rp: f64,
    /// R+ = (r_s² + r_p²)/2.
    pub r_plus: f64,
    /// R− = (r_s² − r_p²)/2.
    pub r_minus: f64,
    /// R× = r_s·r_p.
    pub r_cross: f64,
    /// T+.
    pub t_plus: f64,
    /// T−.
    pub t_minus: f64,
}

/// `ellipso model dop`: the diffuse degree of polarisation and its η-derivative.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct DopTable {
    /// DoP_d(θ, η).
    pub dop: f64,
    /// ∂DoP_d/∂η.
    pub d_dop_d_eta: f64,
}

/// The inputs of `ellipso model mueller` (world directions of any non-zero length).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MuellerInputs {
    /// The material (checked against the flags' ranges before the model's own validation).
    pub params: PbrdfParams<f64>,
    /// Surface normal.
    pub normal: [f64; 3],
    /// Direction surface → light.
    pub to_light: [f64; 3],
    /// Direction surface → camera.
    pub to_camera: [f64; 3],
    /// Light-frame up vector (default world +y).
    pub light_up: Option<[f64; 3]>,
    /// Camera-frame up vector (default world +y).
    pub camera_up: Option<[f64; 3]>,
}

/// A frame's axes in the world.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct FrameAxes {
    /// x axis.
    pub x: [f64; 3],
    /// y axis.
    pub y: [f64; 3],
    /// z axis.
    pub z: [f64; 3],
}

/// The cosines of the geometry.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct CosTheta {
    /// n·ω_i.
    pub i: f64,
    /// n·ω_o.
    pub o: f64,
    /// n·h.
    pub h: f64,
    /// ω_i·h.
    pub d: f64,
}

/// A Mueller matrix, row-major.
pub type Matrix = [[f64; 4]; 4];

/// `ellipso model mueller`: the lobes per channel (light frame → camera frame) and the frames.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct MuellerTables {
    /// P^d per channel (R, G, B).
    pub diffuse: Vec<Matrix>,
    /// P^s (monochrome).
    pub specular: Matrix,
    /// P^ss per channel.
    pub single_scattering: Vec<Matrix>,
    /// P = P^d + P^s + P^ss per channel.
    pub total: Vec<Matrix>,
    /// The light frame.
    pub light_frame: FrameAxes,
    /// The camera frame.
    pub camera_frame: FrameAxes,
    /// The geometry's cosines.
    pub cos_theta: CosTheta,
    /// Whether light and camera are both above the surface.
    pub front_facing: bool,
}

fn check_eta(eta: f64) -> Result<(), InspectError> {
    if !(1.0..=MAX_ETA).contains(&eta) {
        bail!(
            "--eta must be in [1, {MAX_ETA}] (a dielectric in air; none exceeds {MAX_ETA}), got {eta}"
        );
    }
    Ok(())
}

fn check_theta(theta_deg: f64) -> Result<(), InspectError> {
    if !theta_deg.is_finite() || !(0.0..=90.0).contains(&theta_deg) {
        bail!("--theta-deg must be in [0, 90], got {theta_deg}");
    }
    Ok(())
}

/// Every number is finite.
fn check_finite<'a>(values: impl IntoIterator<Item = &'a f64>) -> Result<(), InspectError> {
    if values.into_iter().any(|v| !v.is_finite()) {
        bail!("the model has no finite value for these inputs");
    }
    Ok(())
}

/// A direction flag: finite, non-zero, any length; normalised after scaling by the largest
/// component so neither 1e300 nor 1e-300 overflows.
fn direction(flag: &str, v: [f64; 3]) -> Result<Vec3<f64>, InspectError> {
    let largest = v.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
    if !largest.is_finite() {
        bail!("{flag} must be finite, got {v:?}");
    }
    if largest == 0.0 {
        bail!("{flag} must be a non-zero vector, got {v:?}");
    }
    Vec3::from_f64(v.map(|x| x / largest))
        .normalized_or_none(1e-24)
        .ok_or_else(|| InspectError::Input(format!("{flag} must be a non-zero vector, got {v:?}")))
}

/// The Fresnel terms of a dielectric of index `eta` at `theta_deg` from the normal.
pub fn fresnel(eta: f64, theta_deg: f64) -> Result<FresnelTable, InspectError> {
    check_eta(eta)?;
    check_theta(theta_deg)?;
    let f = FresnelTerms::dielectric(theta_deg.to_radians().cos(), eta);
    let t = FresnelTable {
        rs: f.r_s,
        rp: f.r_p,
        r_plus: f.r_plus(),
        r_minus: f.r_minus(),
        r_cross: f.r_cross(),
        t_plus: f.t_plus(),
        t_minus: f.t_minus(),
    };
    check_finite(&[
        t.rs, t.rp, t.r_plus, t.r_minus, t.r_cross, t.t_plus, t.t_minus,
    ])?;
    Ok(t)
}

/// The diffuse DoP at exit angle `theta_deg` and index `eta`, with its η-derivative.
pub fn dop(eta: f64, theta_deg: f64) -> Result<DopTable, InspectError> {
    check_eta(eta)?;
    check_theta(theta_deg)?;
    let (dop, d_dop_d_eta) = dop_diffuse_with_d_eta(theta_deg.to_radians().cos(), eta);
    check_finite(&[dop, d_dop_d_eta])?;
    Ok(DopTable { dop, d_dop_d_eta })
}

/// The Mueller matrices of the three lobes at one geometry (module doc: ranges, frames).
pub fn mueller(inputs: &MuellerInputs) -> Result<MuellerTables, InspectError> {
    let a = &inputs.params;
    check_eta(a.eta)?;
    for (flag, v) in [("--sigma-s", a.sigma_s), ("--sigma-ss", a.sigma_ss)] {
        if !v.is_finite() || !(0.0..=1.0).contains(&v) {
            bail!("{flag} must be in [0, 1], got {v}");
        }
    }
    if a.sigma_s > a.sigma_ss {
        bail!(
            "--sigma-s ({}) must not exceed --sigma-ss ({})",
            a.sigma_s,
            a.sigma_ss
        );
    }
    if !(a.rho_s >= 0.0 && a.rho_s <= MAX_LOBE_ALBEDO) {
        bail!("--rho-s must be in [0, {MAX_LOBE_ALBEDO}], got {}", a.rho_s);
    }
    for (flag, v, max) in [
        ("--rho-ss", a.rho_ss, MAX_LOBE_ALBEDO),
        ("--rho-d", a.rho_d, 1.0),
    ] {
        if v.iter().any(|x| !(*x >= 0.0 && *x <= max)) {
            bail!("{flag} components must be in [0, {max}], got {v:?}");
        }
    }
    let normal = direction("--normal", inputs.normal)?;
    let to_light = direction("--to-light", inputs.to_light)?;
    let to_camera = direction("--to-camera", inputs.to_camera)?;
    let default_up = [0.0, 1.0, 0.0];
    let light_up = direction("--light-up", inputs.light_up.unwrap_or(default_up))?;
    let camera_up = direction("--camera-up", inputs.camera_up.unwrap_or(default_up))?;
    let light_frame = Frame::light(to_light, light_up)?;
    let camera_frame = Frame::camera(to_camera, camera_up)?;
    let g = Geometry::new(normal, to_light, to_camera, light_frame, camera_frame)?;
    a.validate()?;
    let lobes = evaluate(&g, a);
    let axes = |f: &Frame<f64>| FrameAxes {
        x: f.x.re(),
        y: f.y.re(),
        z: f.z.re(),
    };
    let t = MuellerTables {
        diffuse: lobes.diffuse.iter().map(|m| m.m).collect(),
        specular: lobes.specular.m,
        single_scattering: lobes.single_scattering.iter().map(|m| m.m).collect(),
        total: (0..3).map(|c| lobes.total(c).m).collect(),
        light_frame: axes(&g.light_frame),
        camera_frame: axes(&g.camera_frame),
        cos_theta: CosTheta {
            i: g.cos_theta_i,
            o: g.cos_theta_o,
            h: g.cos_theta_h,
            d: g.cos_theta_d,
        },
        front_facing: g.front_facing,
    };
    let matrices = t
        .diffuse
        .iter()
        .chain(&t.single_scattering)
        .chain(&t.total)
        .chain(std::iter::once(&t.specular));
    let frames = [t.light_frame, t.camera_frame];
    let c = t.cos_theta;
    check_finite(
        matrices
            .flatten()
            .flatten()
            .chain(frames.iter().flat_map(|f| [&f.x, &f.y, &f.z]).flatten())
            .chain(&[c.i, c.o, c.h, c.d]),
    )?;
    Ok(t)
}

#[cfg(test)]
mod tests;
