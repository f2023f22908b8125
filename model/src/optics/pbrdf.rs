//! The polarimetric BRDF P = P^d + P^s + P^ss for arbitrary ω_i, ω_o, n (docs/model.md §4).
//!
//! Contract: [`evaluate`] returns the 4×4 Mueller matrices of the three lobes per RGB channel,
//! mapping a Stokes vector in the light frame to one in the camera frame, with the
//! foreshortening cosine n·ω_i folded in: s_cam = P·s_light / d² (docs/model.md §4). Each lobe is
//! also callable alone ([`diffuse_unit`], [`reflection_unit`] + [`microfacet_weight`],
//! [`specular`], [`single_scattering`]) and [`evaluate_s0`] / [`scalar_brdf`] compute only the
//! intensity row, so a caller pays only for what it uses.
//!
//! - Diffuse (talk): P^d = ρ_d cosθ_i · C_{n→o} F^T(θ_o) D F^T(θ_i) C_{i→n}, D = diag(1,0,0,0),
//!   which is the rank-one product C_{n→o}[T_o+, T_o−, 0, 0]ᵀ [T_i+, T_i−, 0, 0] C_{i→n}.
//! - Specular: P^s = ρ_s D(θ_h; σ_s) G1(θ_i) G1(θ_o)/(4 cosθ_o) · C_{h→o} F^R(θ_d) C_{i→h}.
//! - Single scattering: same structure with σ_ss and RGB ρ_ss. The rotation frame is the
//!   half-vector frame (as the reference renderer does; the talk slide writes the normal frame;
//!   the two agree under coaxial capture). The choice lives in [`reflection_axis`] only.
//!
//! Local s/p frames are built from 3-D s-axes (s ∝ ω_i × d on the way in, ω_o × d on the way
//! out, d = n or h), which is C(φ + 90°) of docs/model.md §1 "Local s/p frames" without any
//! angle. Degenerate s-axes:
//! - diffuse, n ∥ ω: T− ∝ sin²θ vanishes there, so any rotation is correct; identity is used;
//! - specular/SS, ω_i ∥ ω_o (exactly coaxial): F^R(θ_d = 0) composed with rotations about one
//!   shared s-axis is SS·diag(1, 1, −1, −1) for every choice, so the camera x axis is used as s.
//!
//! Back-facing geometry (n·ω_i < 0 or n·ω_o < 0) gives zero matrices.

use super::frame::DIRECTION_EPS_SQ;
use super::fresnel::FresnelTerms;
use super::microfacet::microfacet_weight;
use super::staged::{Directions, NormalCosines, ReflectionFrames, diffuse_stokes};
use super::{Frame, Mueller, OpticsError, Real, Rotator, Stokes, Vec3};

/// Material parameters of one surface point (docs/model.md §4; as fit unknowns, §11 "Unknowns").
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PbrdfParams<T> {
    /// Refractive index relative to air, η ≥ 1 (wavelength-independent).
    pub eta: T,
    /// GGX roughness of the specular lobe, σ_s ∈ [0, 1].
    pub sigma_s: T,
    /// GGX roughness of the single-scattering lobe, σ_s ≤ σ_ss ≤ 1.
    pub sigma_ss: T,
    /// Specular albedo (monochrome), ≥ 0.
    pub rho_s: T,
    /// Single-scattering albedo per RGB channel, ≥ 0.
    pub rho_ss: [T; 3],
    /// Diffuse albedo per RGB channel (1/π absorbed), ≥ 0.
    pub rho_d: [T; 3],
}

impl<T: Real> PbrdfParams<T> {
    /// Checks the physical domain: all finite, η ≥ 1, 0 ≤ σ_s ≤ σ_ss ≤ 1, albedos ≥ 0.
    /// The error names the offending field.
    pub fn validate(&self) -> Result<(), OpticsError> {
        let finite = |name: &'static str, v: T| {
            if v.re().is_finite() {
                Ok(())
            } else {
                Err(OpticsError::NonFinite(name))
            }
        };
        let non_negative = |name: &'static str, v: T| {
            finite(name, v)?;
            if v.re() >= 0.0 {
                Ok(())
            } else {
                Err(OpticsError::Negative(name, v.re()))
            }
        };
        finite("eta", self.eta)?;
        if self.eta.re() < 1.0 {
            return Err(OpticsError::EtaBelowOne(self.eta.re()));
        }
        for (name, s) in [("sigma_s", self.sigma_s), ("sigma_ss", self.sigma_ss)] {
            finite(name, s)?;
            if !(0.0..=1.0).contains(&s.re()) {
                return Err(OpticsError::RoughnessOutOfRange(name, s.re()));
            }
        }
        if self.sigma_s.re() > self.sigma_ss.re() {
            return Err(OpticsError::RoughnessOrder(
                self.sigma_s.re(),
                self.sigma_ss.re(),
            ));
        }
        non_negative("rho_s", self.rho_s)?;
        for v in self.rho_ss {
            non_negative("rho_ss", v)?;
        }
        for v in self.rho_d {
            non_negative("rho_d", v)?;
        }
        Ok(())
    }
}

impl PbrdfParams<f64> {
    /// The same parameters as constants of another scalar type.
    pub fn cast<T: Real>(&self) -> PbrdfParams<T> {
        let c = T::from_f64;
        PbrdfParams {
            eta: c(self.eta),
            sigma_s: c(self.sigma_s),
            sigma_ss: c(self.sigma_ss),
            rho_s: c(self.rho_s),
            rho_ss: self.rho_ss.map(c),
            rho_d: self.rho_d.map(c),
        }
    }
}

/// One shading configuration: unit directions, the two Stokes frames, and derived cosines.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Geometry<T> {
    /// Unit surface normal n.
    pub normal: Vec3<T>,
    /// Unit direction surface → light, ω_i.
    pub to_light: Vec3<T>,
    /// Unit direction surface → camera, ω_o.
    pub to_camera: Vec3<T>,
    /// Light frame (z = −ω_i).
    pub light_frame: Frame<T>,
    /// Camera frame (z = ω_o).
    pub camera_frame: Frame<T>,
    /// Unit half vector h = (ω_i + ω_o)/|ω_i + ω_o| (n when ω_i = −ω_o).
    pub half: Vec3<T>,
    /// n·ω_i clamped to [0, 1].
    pub cos_theta_i: T,
    /// n·ω_o clamped to [0, 1].
    pub cos_theta_o: T,
    /// n·h clamped to [0, 1].
    pub cos_theta_h: T,
    /// h·ω_i clamped to [0, 1] (the Fresnel angle of the microfacet reflection).
    pub cos_theta_d: T,
    /// False when n·ω_i < 0 or n·ω_o < 0: every lobe is zero.
    pub front_facing: bool,
}

impl<T: Real> Geometry<T> {
    /// Builds a geometry. `normal`, `to_light` and `to_camera` may have any non-zero length
    /// (they are normalised here, so derivatives w.r.t. an unnormalised normal are those of
    /// the normalised one). The frames must propagate along −ω_i and ω_o respectively.
    pub fn new(
        normal: Vec3<T>,
        to_light: Vec3<T>,
        to_camera: Vec3<T>,
        light_frame: Frame<T>,
        camera_frame: Frame<T>,
    ) -> Result<Self, OpticsError> {
        let unit = |v: Vec3<T>, name| {
            v.normalized_or_none(DIRECTION_EPS_SQ)
                .ok_or(OpticsError::ZeroDirection(name))
        };
        let unit_normal = unit(normal, "normal")?;
        let to_light = unit(to_light, "to_light")?;
        let to_camera = unit(to_camera, "to_camera")?;
        let mismatch = |a: Vec3<T>, b: Vec3<T>| (a - b).norm_squared().re() > 1e-10;
        if mismatch(light_frame.z, -to_light) {
            return Err(OpticsError::FrameMismatch(
                "light frame z must equal −to_light",
            ));
        }
        if mismatch(camera_frame.z, to_camera) {
            return Err(OpticsError::FrameMismatch(
                "camera frame z must equal to_camera",
            ));
        }
        // The half vector falls back to the unit normal when ω_i = −ω_o.
        let half = super::staged::half_vector(to_light, to_camera).unwrap_or(unit_normal);
        let c = NormalCosines::from_unit(unit_normal, to_light, to_camera, half);
        Ok(Self {
            normal: c.normal,
            to_light,
            to_camera,
            light_frame,
            camera_frame,
            half,
            cos_theta_i: c.cos_theta_i,
            cos_theta_o: c.cos_theta_o,
            cos_theta_h: c.cos_theta_h,
            cos_theta_d: half.dot(to_light).clamp_re(0.0, 1.0),
            front_facing: c.front_facing,
        })
    }

    /// The fixed part of this geometry (directions and frames).
    pub fn directions(&self) -> Directions<T> {
        Directions {
            to_light: self.to_light,
            to_camera: self.to_camera,
            light_frame: self.light_frame,
            camera_frame: self.camera_frame,
        }
    }

    /// The normal's part of this geometry (the unit normal and its cosines).
    pub fn cosines(&self) -> NormalCosines<T> {
        NormalCosines {
            normal: self.normal,
            cos_theta_i: self.cos_theta_i,
            cos_theta_o: self.cos_theta_o,
            cos_theta_h: self.cos_theta_h,
            front_facing: self.front_facing,
        }
    }

    /// Builds the frames from up vectors (see [`Frame::light`], [`Frame::camera`]) and then the
    /// geometry.
    pub fn from_up_vectors(
        normal: Vec3<T>,
        to_light: Vec3<T>,
        to_camera: Vec3<T>,
        light_up: Vec3<T>,
        camera_up: Vec3<T>,
    ) -> Result<Self, OpticsError> {
        let light_frame = Frame::light(to_light, light_up)?;
        let camera_frame = Frame::camera(to_camera, camera_up)?;
        Self::new(normal, to_light, to_camera, light_frame, camera_frame)
    }
}

/// The three lobes, per RGB channel where coloured, in light-frame → camera-frame form.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lobes<T> {
    /// P^d per channel.
    pub diffuse: [Mueller<T>; 3],
    /// P^s (monochrome).
    pub specular: Mueller<T>,
    /// P^ss per channel.
    pub single_scattering: [Mueller<T>; 3],
}

impl<T: Real> Lobes<T> {
    /// P = P^d + P^s + P^ss for one channel (0 = R, 1 = G, 2 = B; larger indices clamp to B).
    pub fn total(&self, channel: usize) -> Mueller<T> {
        let c = channel.min(2);
        self.diffuse[c]
            .add(&self.specular)
            .add(&self.single_scattering[c])
    }
    /// s_cam = P·s_light for one channel (without the 1/d² falloff).
    pub fn apply(&self, channel: usize, s_light: Stokes<T>) -> Stokes<T> {
        self.total(channel).apply(s_light)
    }
}

/// The s-axis of the microfacet reflection (specular and single scattering): ω_i × ω_o, or the
/// camera x axis when ω_i ∥ ω_o (see the module doc).
pub fn reflection_axis<T: Real>(g: &Geometry<T>) -> Vec3<T> {
    super::staged::reflection_axis(g.to_light, g.to_camera, &g.camera_frame)
}

/// C_out · [[a, b, 0, 0], [b, a, 0, 0], [0, 0, c, 0], [0, 0, 0, c]] · C_in, written out.
fn rotated_symmetric<T: Real>(
    a: T,
    b: T,
    c: T,
    rot_in: Rotator<T>,
    rot_out: Rotator<T>,
) -> Mueller<T> {
    let z = T::zero();
    let (ci, si, co, so) = (rot_in.cos2, rot_in.sin2, rot_out.cos2, rot_out.sin2);
    let row0 = [a, b * ci, b * si, z];
    let row1 = [b, a * ci, a * si, z];
    let row2 = [z, -c * si, c * ci, z];
    let mix = |p: T, q: T| {
        [
            p * row1[0] + q * row2[0],
            p * row1[1] + q * row2[1],
            p * row1[2] + q * row2[2],
            z,
        ]
    };
    Mueller {
        m: [row0, mix(co, so), mix(-so, co), [z, z, z, c]],
    }
}

/// C_{h→o} F^R(θ_d) C_{i→h}: the microfacet reflection without its scalar weight.
pub fn reflection_unit<T: Real>(g: &Geometry<T>, eta: T) -> Mueller<T> {
    if !g.front_facing {
        return Mueller::zero();
    }
    let [r_plus, r_minus, r_cross] = FresnelTerms::reflection_terms(g.cos_theta_d, eta);
    let (rot_in, rot_out) = super::staged::reflection_rotators(&g.directions());
    rotated_symmetric(r_plus, r_minus, r_cross, rot_in, rot_out)
}

/// The scalar weight of a reflection lobe of roughness `sigma` (albedo 1), foreshortening
/// included: D G1 G1/(4 cosθ_o). Zero when back-facing.
pub fn lobe_weight<T: Real>(g: &Geometry<T>, sigma: T) -> T {
    if !g.front_facing {
        return T::zero();
    }
    microfacet_weight(g.cos_theta_i, g.cos_theta_o, g.cos_theta_h, sigma)
}

/// The diffuse row and column: (C_{n→o}[T_o+, T_o−, 0, 0]ᵀ, [T_i+, T_i−, 0, 0] C_{i→n}).
fn diffuse_factors<T: Real>(g: &Geometry<T>, eta: T) -> ([T; 4], [T; 4]) {
    super::staged::diffuse_factors(&g.cosines(), &g.directions(), eta)
}

/// P^d with ρ_d = 1 (multiply by ρ_d per channel).
pub fn diffuse_unit<T: Real>(g: &Geometry<T>, eta: T) -> Mueller<T> {
    if !g.front_facing {
        return Mueller::zero();
    }
    let (col, row) = diffuse_factors(g, eta);
    Mueller::outer(col, row).scale(g.cos_theta_i)
}

/// P^d per channel.
pub fn diffuse<T: Real>(g: &Geometry<T>, p: &PbrdfParams<T>) -> [Mueller<T>; 3] {
    let unit = diffuse_unit(g, p.eta);
    p.rho_d.map(|r| unit.scale(r))
}

/// P^s.
pub fn specular<T: Real>(g: &Geometry<T>, p: &PbrdfParams<T>) -> Mueller<T> {
    reflection_unit(g, p.eta).scale(p.rho_s * lobe_weight(g, p.sigma_s))
}

/// P^ss per channel.
pub fn single_scattering<T: Real>(g: &Geometry<T>, p: &PbrdfParams<T>) -> [Mueller<T>; 3] {
    let unit = reflection_unit(g, p.eta).scale(lobe_weight(g, p.sigma_ss));
    p.rho_ss.map(|r| unit.scale(r))
}

/// All three lobes (the reflection Fresnel/rotation work is shared by P^s and P^ss).
pub fn evaluate<T: Real>(g: &Geometry<T>, p: &PbrdfParams<T>) -> Lobes<T> {
    let refl = reflection_unit(g, p.eta);
    let specular = refl.scale(p.rho_s * lobe_weight(g, p.sigma_s));
    let ss = refl.scale(lobe_weight(g, p.sigma_ss));
    let diff = diffuse_unit(g, p.eta);
    Lobes {
        diffuse: p.rho_d.map(|r| diff.scale(r)),
        specular,
        single_scattering: p.rho_ss.map(|r| ss.scale(r)),
    }
}

/// The three lobes of [`apply`] with unit albedos, before they are combined: what the fit needs
/// because observations are linear in ρ_d, ρ_ss and ρ_s (docs/model.md §11 "Unknowns").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnitLobeStokes<T> {
    /// P^d·s_light with ρ_d = 1.
    pub diffuse: Stokes<T>,
    /// C_{h→o} F^R(θ_d) C_{i→h}·s_light: the microfacet reflection without its scalar weight.
    pub reflection: Stokes<T>,
    /// [`lobe_weight`] at σ_s (P^s = ρ_s·`weight_s`·reflection).
    pub weight_s: T,
    /// [`lobe_weight`] at σ_ss (P^ss = ρ_ss·`weight_ss`·reflection).
    pub weight_ss: T,
}

/// s_cam of each lobe with unit albedo (see [`UnitLobeStokes`]); all zero when back-facing.
/// [`apply`] is exactly `diffuse·ρ_d + reflection·(ρ_s·weight_s + ρ_ss·weight_ss)`.
pub fn apply_unit_lobes<T: Real>(
    g: &Geometry<T>,
    eta: T,
    sigma_s: T,
    sigma_ss: T,
    s_light: Stokes<T>,
) -> UnitLobeStokes<T> {
    if !g.front_facing {
        let zero = Stokes::unpolarised(T::zero());
        return UnitLobeStokes {
            diffuse: zero,
            reflection: zero,
            weight_s: T::zero(),
            weight_ss: T::zero(),
        };
    }
    let d = g.directions();
    let diffuse = diffuse_stokes(&g.cosines(), &d, eta, s_light);
    let reflection = ReflectionFrames::new(&d, s_light)
        .reflect(FresnelTerms::reflection_terms(g.cos_theta_d, eta));
    UnitLobeStokes {
        diffuse,
        reflection,
        weight_s: lobe_weight(g, sigma_s),
        weight_ss: lobe_weight(g, sigma_ss),
    }
}

/// s_cam = P·s_light per RGB channel (no 1/d²), without forming any 4×4 matrix: the diffuse
/// lobe as u·(v·s), the reflection as C_out F C_in s shared by P^s and P^ss. This is the
/// cheapest full-polarisation path and what [`crate::optics::measure::observe`] uses.
pub fn apply<T: Real>(g: &Geometry<T>, p: &PbrdfParams<T>, s_light: Stokes<T>) -> [Stokes<T>; 3] {
    if !g.front_facing {
        return [Stokes::unpolarised(T::zero()); 3];
    }
    let u = apply_unit_lobes(g, p.eta, p.sigma_s, p.sigma_ss, s_light);
    let w_s = p.rho_s * u.weight_s;
    core::array::from_fn(|ch| {
        u.diffuse.scale(p.rho_d[ch]) + u.reflection.scale(w_s + p.rho_ss[ch] * u.weight_ss)
    })
}

/// Only the output intensity s0 of P·s_light per channel (row 0 of P): no outgoing rotation,
/// no 4×4 products.
pub fn evaluate_s0<T: Real>(g: &Geometry<T>, p: &PbrdfParams<T>, s_light: Stokes<T>) -> [T; 3] {
    if !g.front_facing {
        return [T::zero(); 3];
    }
    let s = s_light.to_array();
    let dot = |v: [T; 4]| v[0] * s[0] + v[1] * s[1] + v[2] * s[2] + v[3] * s[3];
    let fi = FresnelTerms::dielectric(g.cos_theta_i, p.eta);
    let t_o_plus = FresnelTerms::dielectric(g.cos_theta_o, p.eta).t_plus();
    let rot_d = g
        .light_frame
        .rotator_to_axis(g.to_light.cross(g.normal))
        .unwrap_or_else(Rotator::identity);
    let diffuse = dot(rot_d.apply_row([fi.t_plus(), fi.t_minus(), T::zero(), T::zero()]))
        * t_o_plus
        * g.cos_theta_i;
    let fd = FresnelTerms::dielectric(g.cos_theta_d, p.eta);
    let rot_h = g
        .light_frame
        .rotator_to_axis(reflection_axis(g))
        .unwrap_or_else(Rotator::identity);
    let refl = dot(rot_h.apply_row([fd.r_plus(), fd.r_minus(), T::zero(), T::zero()]));
    let w_s = p.rho_s * lobe_weight(g, p.sigma_s);
    let w_ss = lobe_weight(g, p.sigma_ss);
    core::array::from_fn(|c| p.rho_d[c] * diffuse + (w_s + p.rho_ss[c] * w_ss) * refl)
}

/// The scalar BRDF M00 per channel (response to unpolarised light, foreshortening included):
/// no rotations at all.
pub fn scalar_brdf<T: Real>(g: &Geometry<T>, p: &PbrdfParams<T>) -> [T; 3] {
    if !g.front_facing {
        return [T::zero(); 3];
    }
    let t = FresnelTerms::dielectric(g.cos_theta_i, p.eta).t_plus()
        * FresnelTerms::dielectric(g.cos_theta_o, p.eta).t_plus()
        * g.cos_theta_i;
    let r = FresnelTerms::dielectric(g.cos_theta_d, p.eta).r_plus();
    let w_s = p.rho_s * lobe_weight(g, p.sigma_s);
    let w_ss = lobe_weight(g, p.sigma_ss);
    core::array::from_fn(|c| p.rho_d[c] * t + (w_s + p.rho_ss[c] * w_ss) * r)
}

/// The lobe matrices with an explicit (unpolarised-in) symmetric Fresnel block, exposed for
/// tests that compare against a naive product of full matrices.
#[cfg(test)]
pub(crate) fn reflection_unit_naive(g: &Geometry<f64>, eta: f64) -> Mueller<f64> {
    let f = FresnelTerms::dielectric(g.cos_theta_d, eta);
    let fr = super::fresnel::symmetric_block(f.r_plus(), f.r_minus(), f.r_cross());
    let s = reflection_axis(g);
    let rin = g.light_frame.rotator_to_axis(s).unwrap().mueller();
    let rout = g
        .camera_frame
        .rotator_to_axis(s)
        .unwrap()
        .inverse()
        .mueller();
    rout.mul(&fr).mul(&rin)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> PbrdfParams<f64> {
        PbrdfParams {
            eta: 1.5,
            sigma_s: 0.2,
            sigma_ss: 0.5,
            rho_s: 1.0,
            rho_ss: [0.1; 3],
            rho_d: [0.5; 3],
        }
    }

    #[test]
    fn validation_names_the_bad_field() {
        assert_eq!(p().validate(), Ok(()));
        let cases = [
            (PbrdfParams { eta: 0.9, ..p() }, "eta"),
            (
                PbrdfParams {
                    eta: f64::NAN,
                    ..p()
                },
                "eta",
            ),
            (
                PbrdfParams {
                    sigma_s: -0.1,
                    ..p()
                },
                "sigma_s",
            ),
            (
                PbrdfParams {
                    sigma_ss: 1.5,
                    ..p()
                },
                "sigma_ss",
            ),
            (
                PbrdfParams {
                    sigma_s: 0.6,
                    ..p()
                },
                "sigma_s (0.6) must not exceed",
            ),
            (PbrdfParams { rho_s: -1.0, ..p() }, "rho_s"),
            (
                PbrdfParams {
                    rho_ss: [0.0, f64::INFINITY, 0.0],
                    ..p()
                },
                "rho_ss",
            ),
            (
                PbrdfParams {
                    rho_d: [0.0, 0.0, -0.1],
                    ..p()
                },
                "rho_d",
            ),
        ];
        for (params, name) in cases {
            let msg = params.validate().unwrap_err().to_string();
            assert!(msg.contains(name), "{msg} should name {name}");
        }
    }

    #[test]
    fn geometry_rejects_zero_directions_and_mismatched_frames() {
        let v = Vec3::<f64>::from_f64;
        let up = v([0.0, 1.0, 0.0]);
        let z = v([0.0, 0.0, 1.0]);
        let zero = v([0.0; 3]);
        assert_eq!(
            Geometry::from_up_vectors(zero, z, z, up, up).unwrap_err(),
            OpticsError::ZeroDirection("normal")
        );
        assert!(Geometry::from_up_vectors(z, v([f64::NAN, 0.0, 1.0]), z, up, up).is_err());
        let light = Frame::light(z, up).unwrap();
        let camera = Frame::camera(z, up).unwrap();
        let tilted = v([0.5, 0.0, 1.0]);
        assert!(matches!(
            Geometry::new(z, tilted, z, light, camera),
            Err(OpticsError::FrameMismatch(_))
        ));
        assert!(matches!(
            Geometry::new(z, z, tilted, light, camera),
            Err(OpticsError::FrameMismatch(_))
        ));
        // Unnormalised inputs are accepted and normalised.
        let g = Geometry::from_up_vectors(z.scale(3.0), tilted, z.scale(0.1), up, up).unwrap();
        assert!((g.normal.norm_squared() - 1.0).abs() < 1e-15);
        assert!((g.cos_theta_i - 1.0 / 1.25f64.sqrt()).abs() < 1e-15);
    }
}
