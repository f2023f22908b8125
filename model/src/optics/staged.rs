//! The unit-albedo lobes of the pBRDF (docs/model.md §4) split by what each piece depends on,
//! for callers that evaluate one light–surface–camera configuration many times under a changing
//! normal and material (the fit re-evaluates every (vertex, view) pair at every solver step).
//!
//! Contract: these functions are the only implementation of the unit lobes —
//! [`super::pbrdf::apply_unit_lobes`] is composed of them, so a staged caller gets the renderer's
//! numbers bit for bit. The pieces:
//! - [`Directions`]: ω_i, ω_o and their Stokes frames, the configuration's fixed part.
//! - [`NormalCosines`]: the unit normal and the clamped cosines n·ω_i, n·ω_o, n·h — the only
//!   place the normal enters besides the diffuse lobe's frames.
//! - [`ReflectionFrames`]: the microfacet reflection's rotations, C_{i→h}·s_light and C_{h→o}.
//!   They depend on ω_i, ω_o, the two Stokes frames and s_light only — not on the normal (the
//!   reflection's s-axis is ω_i × ω_o, docs/model.md §4) nor on the material — so they can be
//!   prepared once per configuration; [`ReflectionFrames::reflect`] then needs only the Fresnel
//!   reflection terms at θ_d (h·ω_i, also normal-free) for η.
//! - [`diffuse_stokes`]: P^d·s_light with ρ_d = 1 (normal, frames, η).
//! - The lobes' scalar weights are [`super::microfacet::microfacet_weight`] of the cosines.

use super::frame::DIRECTION_EPS_SQ;
use super::fresnel::FresnelTerms;
use super::{Frame, Real, Rotator, Stokes, Vec3};

/// The fixed part of one configuration: the unit directions to the light and to the camera and
/// their Stokes frames (light frame z = −ω_i, camera frame z = ω_o).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Directions<T> {
    /// Unit direction surface → light, ω_i.
    pub to_light: Vec3<T>,
    /// Unit direction surface → camera, ω_o.
    pub to_camera: Vec3<T>,
    /// Light frame (z = −ω_i).
    pub light_frame: Frame<T>,
    /// Camera frame (z = ω_o).
    pub camera_frame: Frame<T>,
}

impl Directions<f64> {
    /// The same directions as constants of another scalar type.
    pub fn cast<U: Real>(&self) -> Directions<U> {
        Directions {
            to_light: self.to_light.cast(),
            to_camera: self.to_camera.cast(),
            light_frame: self.light_frame.cast(),
            camera_frame: self.camera_frame.cast(),
        }
    }
}

/// The unit normal and its clamped cosines with ω_i, ω_o and the half vector h.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NormalCosines<T> {
    /// Unit surface normal n.
    pub normal: Vec3<T>,
    /// n·ω_i clamped to [0, 1].
    pub cos_theta_i: T,
    /// n·ω_o clamped to [0, 1].
    pub cos_theta_o: T,
    /// n·h clamped to [0, 1].
    pub cos_theta_h: T,
    /// False when n·ω_i < 0 or n·ω_o < 0: every lobe is zero.
    pub front_facing: bool,
}

impl<T: Real> NormalCosines<T> {
    /// From a normal of any non-zero length and the unit `to_light`, `to_camera` and `half`;
    /// `None` for a zero or non-finite normal.
    pub fn new(
        normal: Vec3<T>,
        to_light: Vec3<T>,
        to_camera: Vec3<T>,
        half: Vec3<T>,
    ) -> Option<Self> {
        let normal = normal.normalized_or_none(DIRECTION_EPS_SQ)?;
        Some(Self::from_unit(normal, to_light, to_camera, half))
    }

    /// From a unit normal (not normalised again).
    pub fn from_unit(
        normal: Vec3<T>,
        to_light: Vec3<T>,
        to_camera: Vec3<T>,
        half: Vec3<T>,
    ) -> Self {
        let raw_i = normal.dot(to_light);
        let raw_o = normal.dot(to_camera);
        Self {
            normal,
            cos_theta_i: raw_i.clamp_re(0.0, 1.0),
            cos_theta_o: raw_o.clamp_re(0.0, 1.0),
            cos_theta_h: normal.dot(half).clamp_re(0.0, 1.0),
            front_facing: raw_i.re() >= 0.0 && raw_o.re() >= 0.0,
        }
    }
}

/// The unit half vector h = (ω_i + ω_o)/|ω_i + ω_o|, `None` when ω_i = −ω_o.
pub fn half_vector<T: Real>(to_light: Vec3<T>, to_camera: Vec3<T>) -> Option<Vec3<T>> {
    (to_light + to_camera).normalized_or_none(DIRECTION_EPS_SQ)
}

/// The s-axis of the microfacet reflection (specular and single scattering): ω_i × ω_o, or the
/// camera x axis when ω_i ∥ ω_o (exactly coaxial: F^R(θ_d = 0) composed with rotations about one
/// shared s-axis is the same for every choice, docs/model.md §4).
pub fn reflection_axis<T: Real>(
    to_light: Vec3<T>,
    to_camera: Vec3<T>,
    camera_frame: &Frame<T>,
) -> Vec3<T> {
    let s = to_light.cross(to_camera);
    if s.norm_squared().re() > DIRECTION_EPS_SQ {
        s
    } else {
        camera_frame.x
    }
}

/// The microfacet reflection's two Stokes rotations, (C_{i→h}, C_{h→o}): from the light frame
/// into the reflection's s/p frame (s-axis [`reflection_axis`]) and from it into the camera
/// frame.
pub fn reflection_rotators<T: Real>(d: &Directions<T>) -> (Rotator<T>, Rotator<T>) {
    let axis = reflection_axis(d.to_light, d.to_camera, &d.camera_frame);
    let rot_in = d
        .light_frame
        .rotator_to_axis(axis)
        .unwrap_or_else(Rotator::identity);
    let rot_out = d
        .camera_frame
        .rotator_to_axis(axis)
        .unwrap_or_else(Rotator::identity)
        .inverse();
    (rot_in, rot_out)
}

/// The microfacet reflection's Stokes rotations for one configuration (module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReflectionFrames<T> {
    /// C_{i→h}·s_light: the light's Stokes vector in the reflection's s/p frame.
    pub local: Stokes<T>,
    /// C_{h→o}: from the reflection's s/p frame into the camera frame.
    pub rotate_out: Rotator<T>,
}

impl<T: Real> ReflectionFrames<T> {
    /// The rotations for the configuration `d` and the light's Stokes vector in the light frame.
    pub fn new(d: &Directions<T>, s_light: Stokes<T>) -> Self {
        let (rot_in, rotate_out) = reflection_rotators(d);
        Self {
            local: rot_in.apply(s_light),
            rotate_out,
        }
    }

    /// C_{h→o} F^R C_{i→h}·s_light for the Fresnel reflection terms `[R+, R−, R×]`
    /// ([`FresnelTerms::reflection_terms`] at θ_d): the reflection without its scalar weight.
    pub fn reflect(&self, terms: [T; 3]) -> Stokes<T> {
        let [a, b, c] = terms;
        let l = self.local;
        self.rotate_out.apply(Stokes::new(
            a * l.s0 + b * l.s1,
            b * l.s0 + a * l.s1,
            c * l.s2,
            c * l.s3,
        ))
    }
}

impl ReflectionFrames<f64> {
    /// The same rotations as constants of another scalar type.
    pub fn cast<U: Real>(&self) -> ReflectionFrames<U> {
        let c = U::from_f64;
        let l = self.local;
        ReflectionFrames {
            local: Stokes::new(c(l.s0), c(l.s1), c(l.s2), c(l.s3)),
            rotate_out: Rotator {
                cos2: c(self.rotate_out.cos2),
                sin2: c(self.rotate_out.sin2),
            },
        }
    }
}

/// The diffuse lobe's column and row, C_{n→o}[T_o+, T_o−, 0, 0]ᵀ and [T_i+, T_i−, 0, 0]C_{i→n}
/// (docs/model.md §4: P^d = ρ_d cosθ_i · column · row), for a unit normal with the cosines of
/// `cosines` in the configuration `d`.
pub fn diffuse_factors<T: Real>(
    cosines: &NormalCosines<T>,
    d: &Directions<T>,
    eta: T,
) -> ([T; 4], [T; 4]) {
    let z = T::zero();
    let [ti_plus, ti_minus] = FresnelTerms::transmission_terms(cosines.cos_theta_i, eta);
    let [to_plus, to_minus] = FresnelTerms::transmission_terms(cosines.cos_theta_o, eta);
    let rot_in = d
        .light_frame
        .rotator_to_axis(d.to_light.cross(cosines.normal))
        .unwrap_or_else(Rotator::identity);
    let rot_out = d
        .camera_frame
        .rotator_to_axis(d.to_camera.cross(cosines.normal))
        .unwrap_or_else(Rotator::identity)
        .inverse();
    let row = rot_in.apply_row([ti_plus, ti_minus, z, z]);
    let col = rot_out
        .apply(Stokes::new(to_plus, to_minus, z, z))
        .to_array();
    (col, row)
}

/// P^d·s_light with ρ_d = 1 (no 1/d²): the diffuse column scaled by (row·s_light)·cosθ_i.
/// Zero when back-facing.
pub fn diffuse_stokes<T: Real>(
    cosines: &NormalCosines<T>,
    d: &Directions<T>,
    eta: T,
    s_light: Stokes<T>,
) -> Stokes<T> {
    if !cosines.front_facing {
        return Stokes::unpolarised(T::zero());
    }
    let s = s_light.to_array();
    let (col, row) = diffuse_factors(cosines, d, eta);
    let k = (row[0] * s[0] + row[1] * s[1] + row[2] * s[2] + row[3] * s[3]) * cosines.cos_theta_i;
    Stokes::from_array(col).scale(k)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_pieces_equal_the_full_terms_bit_for_bit() {
        for eta in [1.0, 1.0001, 1.33, 1.5, 2.4, 3.0] {
            for k in 0..=40 {
                let c = k as f64 / 40.0;
                let f = FresnelTerms::dielectric(c, eta);
                assert_eq!(
                    FresnelTerms::reflection_terms(c, eta),
                    [f.r_plus(), f.r_minus(), f.r_cross()]
                );
                assert_eq!(
                    FresnelTerms::transmission_terms(c, eta),
                    [f.t_plus(), f.t_minus()]
                );
            }
        }
    }
}
