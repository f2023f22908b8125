//! The polarisation-camera measurement model: analysers, the flash polariser, the four sensor
//! intensities, the fit's observation channels, and the diffuse degree of polarisation.
//!
//! Contract (docs/model.md §6):
//! - An ideal linear analyser at angle θ (from camera x toward camera y) measures
//!   I_θ = ½(s0 + s1 cos2θ + s2 sin2θ) (Hagen et al. 2019; Malus' law).
//! - The flash polariser at angle ψ in the light frame emits s_light = [1, cos2ψ, sin2ψ, 0]
//!   (unit intensity after the polariser; ψ = 0 is parallel to the 0° analyser, the rig's setup).
//! - Observation channels per RGB channel: I^d = 2·I90, I^s = I0 − I90, I^α = I135 − I45.
//! - DoP_d(θ, η) in closed form (docs/model.md §6 "Diffuse DoP and its η-derivative"),
//!   rewritten without cancellation:
//!   f = (η² − 1)² sin²θ, g = (η² + 1)(2η² cos²θ + (η² − 1) sin²θ) + 4η² cosθ √(η² − sin²θ),
//!   DoP = f/g, equal to |T−|/T+ at the exit angle; ∂DoP/∂η = (f′g − f g′)/g².

use super::pbrdf::{Geometry, PbrdfParams, apply, apply_unit_lobes};
use super::{Mueller, Real, Stokes};

/// An ideal linear analyser (polariser in front of a pixel) at `angle_rad` from camera x
/// (image right) toward camera y (image up).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Analyser {
    /// Transmission-axis angle in the camera frame, radians.
    pub angle_rad: f64,
}

impl Analyser {
    /// The sensor's four analyser angles in degrees (IMX250MZR/MYR).
    pub const SENSOR_ANGLES_DEG: [f64; 4] = [0.0, 45.0, 90.0, 135.0];

    /// An analyser at `angle_deg` degrees.
    pub fn from_deg(angle_deg: f64) -> Self {
        Self {
            angle_rad: angle_deg.to_radians(),
        }
    }
    /// Measured intensity ½(s0 + s1 cos2θ + s2 sin2θ).
    pub fn intensity<T: Real>(&self, s: Stokes<T>) -> T {
        let two = 2.0 * self.angle_rad;
        (s.s0 + s.s1 * T::from_f64(two.cos()) + s.s2 * T::from_f64(two.sin())) * T::from_f64(0.5)
    }
    /// The analyser's Mueller matrix (an ideal linear polariser).
    pub fn mueller<T: Real>(&self) -> Mueller<T> {
        Mueller::linear_polariser(T::from_f64(self.angle_rad))
    }
}

/// The four analysers' effective transmission angles for one ray, as cos 2ψ and sin 2ψ in the
/// ray's camera frame ([`super::Frame::camera`]: z = ω_o, y = image up made perpendicular to the
/// ray, x = y × z).
///
/// Physics (docs/model.md, "Analysers off the optical axis"): each analyser is a wire grid lying
/// in the sensor plane. A grid passes the field component perpendicular to its wires, so for a
/// ray arriving along −ω_o its effective transmission axis is ω_o × w (w the wire direction,
/// i.e. the nominal transmission axis turned by 90° in the sensor plane) — perpendicular to the
/// ray and to the wires (the dipole model of a thin polariser at oblique incidence, Chipman,
/// Lam & Young, *Polarized Light and Optical Systems*, CRC 2018). Projecting each nominal
/// transmission axis onto the ray's transverse plane instead differs at second order in the
/// field angle: by up to ~5° at the corners of a 1224×1024 frame with f = 1739 px. On the
/// optical axis both give the nominal 0/45/90/135°.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnalyserAngles {
    /// cos 2ψ of the analysers at nominal 0°, 45°, 90°, 135°.
    pub cos2: [f64; 4],
    /// sin 2ψ of the same analysers.
    pub sin2: [f64; 4],
}

impl AnalyserAngles {
    /// The nominal angles (a ray along the optical axis).
    pub fn ideal() -> Self {
        Self {
            cos2: [1.0, 0.0, -1.0, 0.0],
            sin2: [0.0, 1.0, 0.0, -1.0],
        }
    }

    /// The effective angles of the sensor's four analysers for a ray leaving the surface along
    /// `to_camera`, with the sensor's image-right and image-up axes (all three in one frame,
    /// e.g. the world or the OpenCV camera frame with right = +x, up = −y).
    pub fn for_ray(image_right: [f64; 3], image_up: [f64; 3], to_camera: [f64; 3]) -> Self {
        let mut out = Self::ideal();
        for (k, deg) in Analyser::SENSOR_ANGLES_DEG.iter().enumerate() {
            let (c, s) = effective_cos_sin_2(deg.to_radians(), image_right, image_up, to_camera);
            out.cos2[k] = c;
            out.sin2[k] = s;
        }
        out
    }

    /// The four pixel intensities ½(s0 + s1 cos2ψ + s2 sin2ψ), nominal order 0/45/90/135°.
    pub fn intensities<T: Real>(&self, s: Stokes<T>) -> SensorIntensities<T> {
        let at = |k: usize| {
            (s.s0 + s.s1 * T::from_f64(self.cos2[k]) + s.s2 * T::from_f64(self.sin2[k]))
                * T::from_f64(0.5)
        };
        SensorIntensities {
            i0: at(0),
            i45: at(1),
            i90: at(2),
            i135: at(3),
        }
    }
}

/// (cos 2ψ, sin 2ψ) of one wire-grid analyser at nominal angle `theta` (from image right toward
/// image up) for a ray along −`to_camera` (see [`AnalyserAngles`]). A degenerate input (a ray in
/// the sensor plane, zero vectors) gives the nominal angle.
pub fn effective_cos_sin_2(
    theta: f64,
    image_right: [f64; 3],
    image_up: [f64; 3],
    to_camera: [f64; 3],
) -> (f64, f64) {
    effective_cos_sin_2_of(theta, theta.sin_cos(), image_right, image_up, to_camera)
}

/// [`effective_cos_sin_2`] with `theta.sin_cos()` taken by the caller: a renderer asks for one
/// pixel's analyser along several rays (its supersampling), and the sine and cosine are the
/// same for all of them (two of the three trigonometric calls per ray, 4 % of a frame).
pub fn effective_cos_sin_2_of(
    theta: f64,
    theta_sin_cos: (f64, f64),
    image_right: [f64; 3],
    image_up: [f64; 3],
    to_camera: [f64; 3],
) -> (f64, f64) {
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let z = to_camera;
    // The ray frame's y: image up made perpendicular to the ray (as `Frame::camera` builds it).
    let uz = dot(image_up, z);
    let y = [
        image_up[0] - uz * z[0],
        image_up[1] - uz * z[1],
        image_up[2] - uz * z[2],
    ];
    let x = cross(y, z);
    let (s, c) = theta_sin_cos;
    let wire = [
        -s * image_right[0] + c * image_up[0],
        -s * image_right[1] + c * image_up[1],
        -s * image_right[2] + c * image_up[2],
    ];
    let t = cross(z, wire);
    let (a, b) = (dot(t, x), dot(t, y));
    let norm = a * a + b * b;
    // Only a ray grazing the sensor plane along the wires has no transverse component.
    if norm.is_nan() || norm <= 1e-24 || !norm.is_finite() {
        return ((2.0 * theta).cos(), (2.0 * theta).sin());
    }
    ((a * a - b * b) / norm, 2.0 * a * b / norm)
}

/// The linear polariser on the flash.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct FlashPolariser {
    /// Transmission-axis angle in the light frame (from light x toward light y), radians.
    pub angle_rad: f64,
}

impl FlashPolariser {
    /// The Stokes vector leaving the flash, light frame, intensity `s0`.
    pub fn stokes<T: Real>(&self, s0: T) -> Stokes<T> {
        let two = 2.0 * self.angle_rad;
        Stokes::new(
            s0,
            s0 * T::from_f64(two.cos()),
            s0 * T::from_f64(two.sin()),
            T::zero(),
        )
    }
}

/// The four analyser intensities of one superpixel (one colour channel).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorIntensities<T> {
    /// I at 0°.
    pub i0: T,
    /// I at 45°.
    pub i45: T,
    /// I at 90°.
    pub i90: T,
    /// I at 135°.
    pub i135: T,
}

impl<T: Real> SensorIntensities<T> {
    /// What ideal analysers at 0/45/90/135° measure for `s` (camera frame).
    pub fn from_stokes(s: Stokes<T>) -> Self {
        let h = T::from_f64(0.5);
        Self {
            i0: (s.s0 + s.s1) * h,
            i45: (s.s0 + s.s2) * h,
            i90: (s.s0 - s.s1) * h,
            i135: (s.s0 - s.s2) * h,
        }
    }
    /// Linear Stokes from the four intensities: s0 = ½ΣI, s1 = I0 − I90, s2 = I45 − I135.
    pub fn to_stokes(&self) -> Stokes<T> {
        let s0 = (self.i0 + self.i45 + self.i90 + self.i135) * T::from_f64(0.5);
        Stokes::new(s0, self.i0 - self.i90, self.i45 - self.i135, T::zero())
    }
    /// The fit's observation channels.
    pub fn observation(&self) -> ObservationChannels<T> {
        ObservationChannels {
            diffuse: self.i90 + self.i90,
            specular: self.i0 - self.i90,
            alpha: self.i135 - self.i45,
        }
    }
}

/// Observation channels of one colour channel (docs/model.md §6 "Observation channels").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObservationChannels<T> {
    /// I^d = 2·I90 = s0 − s1 (≈ DS, diffuse shading).
    pub diffuse: T,
    /// I^s = I0 − I90 = s1 (≈ SS − DPβ).
    pub specular: T,
    /// I^α = I135 − I45 = −s2 (≈ DPα).
    pub alpha: T,
}

/// Model prediction of the observation channels per RGB channel for one geometry, with the
/// flash at unit intensity (multiply by the radiometric normaliser outside).
pub fn observe<T: Real>(
    g: &Geometry<T>,
    p: &PbrdfParams<T>,
    flash: FlashPolariser,
) -> [ObservationChannels<T>; 3] {
    let s_cam = apply(g, p, flash.stokes(T::one()));
    s_cam.map(|s| SensorIntensities::from_stokes(s).observation())
}

/// Observation channels of the three lobes with unit albedo (ρ_d = ρ_ss = ρ_s = 1), for the
/// fit's linear structure (docs/model.md §11 "Unknowns"): per colour channel c,
/// `observe(g, p, flash)[c] = ρ_d[c]·diffuse + ρ_ss[c]·single_scattering + ρ_s·specular`
/// (to rounding).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnitLobeObservations<T> {
    /// The diffuse lobe with ρ_d = 1.
    pub diffuse: ObservationChannels<T>,
    /// The single-scattering lobe (roughness σ_ss) with ρ_ss = 1.
    pub single_scattering: ObservationChannels<T>,
    /// The specular lobe (roughness σ_s) with ρ_s = 1.
    pub specular: ObservationChannels<T>,
}

/// The unit-albedo lobes' observation channels for one geometry (see [`UnitLobeObservations`])
/// and the flash's Stokes vector in the light frame (`FlashPolariser::stokes(1)` for the rig,
/// `Stokes::unpolarised(1)` for a bare flash).
pub fn observe_unit_lobes<T: Real>(
    g: &Geometry<T>,
    eta: T,
    sigma_s: T,
    sigma_ss: T,
    s_light: Stokes<T>,
) -> UnitLobeObservations<T> {
    let u = apply_unit_lobes(g, eta, sigma_s, sigma_ss, s_light);
    let obs = |s: Stokes<T>| SensorIntensities::from_stokes(s).observation();
    let refl = obs(u.reflection);
    let scale = |o: ObservationChannels<T>, k: T| ObservationChannels {
        diffuse: o.diffuse * k,
        specular: o.specular * k,
        alpha: o.alpha * k,
    };
    UnitLobeObservations {
        diffuse: obs(u.diffuse),
        single_scattering: scale(refl, u.weight_ss),
        specular: scale(refl, u.weight_s),
    }
}

/// The pieces f, g, f′, g′ of DoP_d = f/g (see the module doc), with the clamps:
/// cosθ ∈ [0, 1], η ≥ 1; the q′ term is dropped where q = 0 (only η = 1 at grazing).
fn dop_parts<T: Real>(cos_theta_o: T, eta: T) -> [T; 4] {
    let c = cos_theta_o.clamp_re(0.0, 1.0);
    let eta = eta.max_re(T::one());
    let one = T::one();
    let s2 = (one - c) * (one + c);
    let e2 = eta.sq();
    let e2m1 = (eta - one) * (eta + one);
    let q = (e2m1 + c.sq()).sqrt_clamped(); // √(η² − sin²θ)
    let k = T::from_f64;
    let f = e2m1.sq() * s2;
    let inner = k(2.0) * e2 * c.sq() + e2m1 * s2;
    let g = (e2 + one) * inner + k(4.0) * e2 * c * q;
    let df = k(4.0) * eta * e2m1 * s2;
    let q_term = if q.re() > 0.0 {
        k(4.0) * e2 * eta * c / q
    } else {
        T::zero()
    };
    let dg = k(2.0) * eta * inner
        + (e2 + one) * (k(4.0) * eta * c.sq() + k(2.0) * eta * s2)
        + k(8.0) * eta * c * q
        + q_term;
    [f, g, df, dg]
}

/// Diffuse degree of polarisation DoP_d(θ_o, η) for unpolarised or depolarised light leaving a
/// dielectric at exterior angle θ_o. 0 where g = 0 (η = 1 at grazing: no interface).
pub fn dop_diffuse<T: Real>(cos_theta_o: T, eta: T) -> T {
    let [f, g, _, _] = dop_parts(cos_theta_o, eta);
    if g.re() > 0.0 { f / g } else { T::zero() }
}

/// (DoP_d, ∂DoP_d/∂η) in closed form (docs/model.md §6 "Diffuse DoP and its η-derivative").
pub fn dop_diffuse_with_d_eta<T: Real>(cos_theta_o: T, eta: T) -> (T, T) {
    let [f, g, df, dg] = dop_parts(cos_theta_o, eta);
    if g.re() > 0.0 {
        (f / g, (df * g - f * dg) / g.sq())
    } else {
        (T::zero(), T::zero())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::{Dual, FresnelTerms};

    /// The OpenCV camera frame's image axes: right = +x, up = −y.
    const RIGHT: [f64; 3] = [1.0, 0.0, 0.0];
    const UP: [f64; 3] = [0.0, -1.0, 0.0];

    fn ray(u_over_f: f64, v_over_f: f64) -> [f64; 3] {
        let l = (u_over_f * u_over_f + v_over_f * v_over_f + 1.0).sqrt();
        // Surface → camera is minus the pinhole ray.
        [-u_over_f / l, -v_over_f / l, -1.0 / l]
    }

    #[test]
    fn analysers_on_axis_are_nominal_and_malus_holds_off_axis() {
        let on = AnalyserAngles::for_ray(RIGHT, UP, ray(0.0, 0.0));
        let ideal = AnalyserAngles::ideal();
        for k in 0..4 {
            assert!((on.cos2[k] - ideal.cos2[k]).abs() < 1e-15);
            assert!((on.sin2[k] - ideal.sin2[k]).abs() < 1e-15);
        }
        // Along the image axes the 0° and 90° grids stay at 0° and 90°: one of their wires
        // lies in the plane of incidence.
        for r in [ray(0.4, 0.0), ray(0.0, 0.3)] {
            let a = AnalyserAngles::for_ray(RIGHT, UP, r);
            for k in [0, 2] {
                assert!((a.cos2[k] - ideal.cos2[k]).abs() < 1e-12, "{a:?}");
            }
        }
        // A corner ray (field angle ~25°): every effective axis is a unit direction (Malus:
        // fully polarised light along it passes entirely, across it not at all), and the
        // diagonal analysers move by degrees.
        let a = AnalyserAngles::for_ray(RIGHT, UP, ray(0.35, 0.29));
        let mut worst: f64 = 0.0;
        for k in 0..4 {
            assert!((a.cos2[k].hypot(a.sin2[k]) - 1.0).abs() < 1e-12);
            let along = Stokes::new(1.0, a.cos2[k], a.sin2[k], 0.0);
            let across = Stokes::new(1.0, -a.cos2[k], -a.sin2[k], 0.0);
            let pass = |s| match k {
                0 => a.intensities(s).i0,
                1 => a.intensities(s).i45,
                2 => a.intensities(s).i90,
                _ => a.intensities(s).i135,
            };
            assert!((pass(along) - 1.0).abs() < 1e-12);
            assert!(pass(across).abs() < 1e-12);
            let psi = 0.5 * a.sin2[k].atan2(a.cos2[k]);
            let nominal = (45.0 * k as f64).to_radians();
            let mut d = (psi - nominal).rem_euclid(std::f64::consts::PI);
            if d > std::f64::consts::FRAC_PI_2 {
                d -= std::f64::consts::PI;
            }
            worst = worst.max(d.abs().to_degrees());
        }
        assert!(worst > 1.0 && worst < 10.0, "{worst}");
    }

    #[test]
    fn dop_table_and_closed_form_equals_fresnel_ratio() {
        // docs/model.md §8 "Fresnel and diffuse DoP values".
        let table = [
            (1.3, [0.008319, 0.022271, 0.051436, 0.150383]),
            (1.5, [0.016978, 0.043983, 0.095941, 0.246434]),
            (1.7, [0.025539, 0.064817, 0.136754, 0.327138]),
        ];
        for (eta, row) in table {
            for (deg, want) in [30.0f64, 45.0, 60.0, 80.0].iter().zip(row) {
                let got: f64 = dop_diffuse(deg.to_radians().cos(), eta);
                assert!((got - want).abs() < 1e-6, "η={eta} θ={deg}: {got}");
            }
        }
        for k in 0..=200 {
            for eta in [1.0, 1.1, 1.5, 2.3, 3.0] {
                let c = k as f64 / 200.0;
                let f = FresnelTerms::dielectric(c, eta);
                if f.t_plus() > 1e-3 {
                    let ratio = -f.t_minus() / f.t_plus();
                    assert!((dop_diffuse(c, eta) - ratio).abs() < 1e-14, "η={eta} c={c}");
                }
            }
        }
    }

    #[test]
    fn d_eta_matches_dual_and_sensitivity_table() {
        // docs/model.md §6 "Diffuse DoP and its η-derivative": ∂DoP/∂η at η = 1.464.
        for (deg, want) in [
            (30.0f64, 0.044),
            (45.0, 0.109),
            (60.0, 0.219),
            (75.0, 0.387),
        ] {
            let (_, d) = dop_diffuse_with_d_eta(deg.to_radians().cos(), 1.464);
            assert!((d - want).abs() < 6e-4, "θ={deg}: {d}");
        }
        let (_, d23) = dop_diffuse_with_d_eta(45f64.to_radians().cos(), 2.3);
        assert!((d23 - 0.071).abs() < 6e-4);
        for k in 0..100 {
            let c = 0.005 + 0.99 * k as f64 / 100.0;
            let eta = 1.01 + 0.02 * k as f64;
            let (v, d) = dop_diffuse_with_d_eta(c, eta);
            let dual = dop_diffuse(Dual::<1>::constant(c), Dual::variable(eta, 0));
            assert!(
                (dual.re - v).abs() < 1e-15 && (dual.du[0] - d).abs() < 1e-12 * (1.0 + d.abs())
            );
        }
    }

    #[test]
    fn channel_identities() {
        // docs/model.md §8 "Camera channel identities".
        let s = Stokes::new(0.7, 0.2, -0.31, 0.05);
        let i = SensorIntensities::from_stokes(s);
        assert!((i.i0 + i.i90 - i.i45 - i.i135).abs() < 1e-15);
        let o = i.observation();
        assert!((o.specular - s.s1).abs() < 1e-15);
        assert!((o.alpha + s.s2).abs() < 1e-15);
        assert!((o.diffuse - (s.s0 - s.s1)).abs() < 1e-15);
        let back = i.to_stokes();
        assert!((back.s0 - s.s0).abs() < 1e-15 && (back.s2 - s.s2).abs() < 1e-15);
        for deg in Analyser::SENSOR_ANGLES_DEG {
            let a = Analyser::from_deg(deg);
            let via_matrix = a.mueller::<f64>().apply(s).s0;
            assert!((a.intensity(s) - via_matrix).abs() < 1e-15);
        }
    }

    #[test]
    #[expect(clippy::needless_range_loop, reason = "parallel per-channel arrays")]
    fn unit_lobes_recombine_to_observe() {
        use crate::optics::Vec3;
        let v = Vec3::<f64>::from_f64;
        let p = PbrdfParams {
            eta: 1.6,
            sigma_s: 0.15,
            sigma_ss: 0.4,
            rho_s: 0.8,
            rho_ss: [0.2, 0.1, 0.05],
            rho_d: [0.6, 0.3, 0.1],
        };
        for k in 0..50 {
            let t = k as f64 * 0.37;
            let n = v([0.3 * t.sin(), 0.2 * t.cos(), 1.0]);
            let to_light = v([0.1 + 0.5 * (1.3 * t).sin(), 0.4 * t.cos(), 1.0]);
            let to_camera = v([0.12 + 0.5 * (1.3 * t).sin(), 0.37 * t.cos(), 1.0]);
            let up = v([0.0, 1.0, 0.0]);
            let g = Geometry::from_up_vectors(n, to_light, to_camera, up, up).unwrap();
            let flash = FlashPolariser { angle_rad: 0.0 };
            let full = observe(&g, &p, flash);
            let u = observe_unit_lobes(&g, p.eta, p.sigma_s, p.sigma_ss, flash.stokes(1.0));
            for c in 0..3 {
                let comb = |f: fn(&ObservationChannels<f64>) -> f64| {
                    p.rho_d[c] * f(&u.diffuse)
                        + p.rho_ss[c] * f(&u.single_scattering)
                        + p.rho_s * f(&u.specular)
                };
                let pairs = [
                    (full[c].diffuse, comb(|o| o.diffuse)),
                    (full[c].specular, comb(|o| o.specular)),
                    (full[c].alpha, comb(|o| o.alpha)),
                ];
                for (a, b) in pairs {
                    assert!((a - b).abs() <= 1e-13 * (1.0 + a.abs()), "{a} vs {b}");
                }
            }
        }
    }

    #[test]
    fn malus_law_through_flash_and_analyser() {
        for k in 0..36 {
            let psi = (k as f64 * 5.0).to_radians();
            let s = FlashPolariser { angle_rad: psi }.stokes(1.0);
            for deg in [0.0, 30.0, 45.0, 90.0, 135.0] {
                let a = Analyser::from_deg(deg);
                assert!((a.intensity(s) - (psi - a.angle_rad).cos().powi(2)).abs() < 1e-14);
            }
        }
    }
}
