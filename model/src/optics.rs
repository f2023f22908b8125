//! Polarimetric optics: the model the simulator renders with and the fit inverts.
//!
//! One model, never two copies: every function is generic over the scalar [`Real`]
//! (`f32`, `f64`, or the dual number [`Dual<N>`] for exact derivatives). Equations and
//! conventions, each with its published source, are in `docs/model.md`.
//!
//! # Conventions (documented once)
//! - Stokes vectors `[s0, s1, s2, s3]` live in a right-handed [`Frame`] whose z is the
//!   propagation direction (Mitsuba 3 `mueller.h`); [`Rotator`] is C(θ).
//! - Light frame: z = −ω_i, y = flash up. Camera frame: z = ω_o (toward the camera),
//!   x = image right, y = image up. ω_i, ω_o point away from the surface.
//! - P includes the foreshortening n·ω_i: s_cam = P·s_light / d².
//!
//! # API
//! Renderer (`f32`/`f64`):
//! - [`pbrdf::Geometry::from_up_vectors`]`(normal, to_light, to_camera, light_up, camera_up)`
//!   or [`pbrdf::Geometry::new`] with prebuilt frames;
//! - [`pbrdf::evaluate`]`(&g, &params) -> Lobes` (4×4 per lobe, per RGB channel), or single
//!   lobes [`pbrdf::diffuse`], [`pbrdf::specular`], [`pbrdf::single_scattering`];
//! - [`pbrdf::apply`]`(&g, &params, s_light) -> [Stokes; 3]` (s_cam directly, no 4×4 built);
//! - [`pbrdf::evaluate_s0`] (intensity only, any polarised light) and [`pbrdf::scalar_brdf`]
//!   (M00: unpolarised light, no rotations).
//!
//! Fit (`f64` + [`Dual`]):
//! - [`measure::observe`]`(&g, &params, flash) -> [ObservationChannels; 3]` (I^d, I^s, I^α);
//! - [`measure::observe_unit_lobes`] (the unit-albedo lobes: observations are linear in ρ_d,
//!   ρ_ss, ρ_s);
//! - [`measure::dop_diffuse`] / [`measure::dop_diffuse_with_d_eta`] (closed-form ∂/∂η);
//! - [`coaxial::terms`] (DS, SS, DPα, DPβ) for the coaxial approximation.
//!
//! Inspection (`ellipso model`): [`inspect`] (Fresnel terms, diffuse DoP and the lobes' Mueller
//! matrices at one input, range-checked, typed).

pub mod coaxial;
mod dual;
mod frame;
pub mod fresnel;
pub mod inspect;
pub mod measure;
pub mod microfacet;
pub mod pbrdf;
mod real;
pub mod staged;
mod stokes;
mod vec3;

#[cfg(test)]
mod tests;

pub use dual::Dual;
pub use frame::{Frame, camera_up_from_opencv};
pub use fresnel::FresnelTerms;
pub use real::Real;
pub use stokes::{Mueller, Rotator, Stokes};
pub use vec3::Vec3;

/// Errors of the optics model: bad inputs, each message naming what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OpticsError {
    /// A direction vector was zero, non-finite or too short to define a direction.
    #[error("{0} is zero or not finite: it does not define a direction")]
    ZeroDirection(&'static str),
    /// A frame does not propagate along the direction it was given for.
    #[error("frame mismatch: {0}")]
    FrameMismatch(&'static str),
    /// A parameter was NaN or infinite.
    #[error("{0} is not finite")]
    NonFinite(&'static str),
    /// η below 1 (this model has light arriving from air into a denser dielectric).
    #[error("eta must be >= 1 (dielectric in air), got {0}")]
    EtaBelowOne(f64),
    /// A roughness outside [0, 1].
    #[error("{0} must be in [0, 1], got {1}")]
    RoughnessOutOfRange(&'static str, f64),
    /// σ_s > σ_ss.
    #[error("sigma_s ({0}) must not exceed sigma_ss ({1})")]
    RoughnessOrder(f64, f64),
    /// A negative albedo.
    #[error("{0} must be >= 0, got {1}")]
    Negative(&'static str, f64),
}
