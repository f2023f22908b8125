//! Exact Jacobians of the model's observations (test harness of the derivative tests).
//!
//! Contract: the fit's unknowns are laid out in one vector of [`N_FIT_PARAMS`] slots (see
//! [`slot`]); [`seed_params`] and [`seed_normal`] turn `f64` values into [`FitDual`]s whose
//! partials are the unit vectors of those slots, and [`observe_with_jacobian`] returns the
//! observation channels with every partial derivative. The normal is differentiated as given
//! (before the model normalises it), so the derivative along the normal itself is zero and
//! the fit can use any tangent-plane parameterisation by the chain rule.
//! No finite differences anywhere.

use super::super::measure::{FlashPolariser, ObservationChannels, observe};
use super::super::pbrdf::{Geometry, PbrdfParams};
use super::super::{Dual, Frame, OpticsError, Vec3};

/// Number of differentiable fit inputs: η, σ_s, σ_ss, ρ_s, ρ_ss (3), ρ_d (3), normal (3).
pub const N_FIT_PARAMS: usize = 13;

/// The dual number type of the fit.
pub type FitDual = Dual<N_FIT_PARAMS>;

/// Slot index of each fit input in the partials array.
pub mod slot {
    /// η.
    pub const ETA: usize = 0;
    /// σ_s.
    pub const SIGMA_S: usize = 1;
    /// σ_ss.
    pub const SIGMA_SS: usize = 2;
    /// ρ_s.
    pub const RHO_S: usize = 3;
    /// ρ_ss R, G, B.
    pub const RHO_SS: [usize; 3] = [4, 5, 6];
    /// ρ_d R, G, B.
    pub const RHO_D: [usize; 3] = [7, 8, 9];
    /// Normal x, y, z (world).
    pub const NORMAL: [usize; 3] = [10, 11, 12];
}

/// The parameters as independent variables in their slots.
pub fn seed_params(p: &PbrdfParams<f64>) -> PbrdfParams<FitDual> {
    PbrdfParams {
        eta: Dual::variable(p.eta, slot::ETA),
        sigma_s: Dual::variable(p.sigma_s, slot::SIGMA_S),
        sigma_ss: Dual::variable(p.sigma_ss, slot::SIGMA_SS),
        rho_s: Dual::variable(p.rho_s, slot::RHO_S),
        rho_ss: core::array::from_fn(|c| Dual::variable(p.rho_ss[c], slot::RHO_SS[c])),
        rho_d: core::array::from_fn(|c| Dual::variable(p.rho_d[c], slot::RHO_D[c])),
    }
}

/// The normal as independent variables in its slots.
pub fn seed_normal(normal: [f64; 3]) -> Vec3<FitDual> {
    Vec3::new(
        Dual::variable(normal[0], slot::NORMAL[0]),
        Dual::variable(normal[1], slot::NORMAL[1]),
        Dual::variable(normal[2], slot::NORMAL[2]),
    )
}

/// Observation channels (I^d, I^s, I^α per RGB channel) and their derivatives with respect to
/// all [`N_FIT_PARAMS`] inputs, for one sample's geometry.
pub fn observe_with_jacobian(
    normal: [f64; 3],
    to_light: Vec3<f64>,
    to_camera: Vec3<f64>,
    light_frame: &Frame<f64>,
    camera_frame: &Frame<f64>,
    params: &PbrdfParams<f64>,
    flash: FlashPolariser,
) -> Result<[ObservationChannels<FitDual>; 3], OpticsError> {
    let g = Geometry::new(
        seed_normal(normal),
        to_light.cast(),
        to_camera.cast(),
        light_frame.cast(),
        camera_frame.cast(),
    )?;
    Ok(observe(&g, &seed_params(params), flash))
}
