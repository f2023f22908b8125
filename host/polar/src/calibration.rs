//! Non-ideal micro-polarisers: a per-analyser calibration and the Stokes estimator it implies.
//!
//! Real microgrid analysers are rotated slightly off 0/45/90/135°, leak the crossed polarisation
//! (extinction ratio ER, often below 30 on older microgrids, Hagen, Shibata & Otani, Opt. Eng.
//! 58(8) 082408, 2019) and differ in gain. Analyser k then measures
//!
//! ```text
//! I_k = g_k · ½ (s0 + d_k (s1 cos2θ_k + s2 sin2θ_k)),     d_k = (ER_k − 1)/(ER_k + 1)
//! ```
//!
//! i.e. `I = A s` with a 4×3 measurement matrix A. The least-squares Stokes estimate is
//! `s = A⁺ I` with the pseudo-inverse `A⁺ = (AᵀA)⁻¹Aᵀ` (as polanalyser's `calcStokes` does for
//! arbitrary analysers; Hagen et al., Opt. Eng. 58(8) 080501, 2019). With four measurements and
//! three unknowns, one direction `n` (the left null vector, `nᵀA = 0`) carries no signal: the
//! consistency residual is `nᵀI`, which for ideal analysers is `I0 − I45 + I90 − I135`.
//!
//! Contract: [`AnalyserCalibration::stokes_matrix`] either returns a finite estimator or an error
//! naming why the calibration cannot be inverted; for [`AnalyserCalibration::IDEAL`] it returns
//! exactly the textbook rows and `n = [1, −1, 1, −1]`. This module covers one global calibration
//! per sensor; the per-pixel calibration of [`crate::sensor_calibration`] builds one
//! [`StokesMatrix`] per superpixel with [`StokesMatrix::of_measurement`].

use serde::{Deserialize, Serialize};

/// Per-analyser parameters, indexed like `Analyser::index` (0°, 45°, 90°, 135° nominal).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AnalyserCalibration {
    /// Actual transmission-axis angles in degrees (same convention as the nominal angles).
    pub angle_deg: [f64; 4],
    /// Extinction ratios (transmittance along / across the axis), > 1; `f64::INFINITY` is ideal.
    pub extinction_ratio: [f64; 4],
    /// Relative gains (pixel response × analyser transmittance), > 0; 1 is nominal.
    pub gain: [f64; 4],
}

/// Why a calibration cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CalibrationError {
    /// A parameter is not finite or out of range.
    #[error("analyser {index} ({nominal_deg}° nominal): {what}")]
    Parameter {
        /// Analyser index (0..4).
        index: usize,
        /// Its nominal angle.
        nominal_deg: u32,
        /// What is wrong.
        what: String,
    },
    /// The four analysers do not determine s1 and s2 (e.g. all at one angle).
    #[error(
        "the analysers cannot separate s0, s1 and s2 (det AᵀA = {determinant:e}); angles or extinction ratios are degenerate"
    )]
    Singular {
        /// Determinant of AᵀA.
        determinant: f64,
    },
}

/// The linear Stokes estimator of a calibration: `s = rows · I`, residual `= null · I`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StokesMatrix {
    /// Rows of A⁺ for s0, s1, s2 (columns in 0°, 45°, 90°, 135° order).
    pub rows: [[f32; 4]; 3],
    /// Left null vector of A, scaled to norm 2 (the ideal `[1, −1, 1, −1]`).
    pub null: [f32; 4],
}

impl AnalyserCalibration {
    /// Ideal analysers at exactly 0/45/90/135°, infinite extinction, unit gain.
    pub const IDEAL: AnalyserCalibration = AnalyserCalibration {
        angle_deg: [0.0, 45.0, 90.0, 135.0],
        extinction_ratio: [f64::INFINITY; 4],
        gain: [1.0; 4],
    };

    /// Diattenuation `d = (ER − 1)/(ER + 1)` of analyser `k` (1 for an infinite ratio).
    pub fn diattenuation(&self, k: usize) -> f64 {
        let er = self.extinction_ratio[k];
        if er.is_infinite() {
            1.0
        } else {
            (er - 1.0) / (er + 1.0)
        }
    }

    /// The 4×3 measurement matrix A (`I = A s`).
    pub fn measurement_matrix(&self) -> [[f64; 3]; 4] {
        std::array::from_fn(|k| {
            let (sin2, cos2) = (2.0 * self.angle_deg[k].to_radians()).sin_cos();
            let (g, d) = (self.gain[k], self.diattenuation(k));
            [0.5 * g, 0.5 * g * d * cos2, 0.5 * g * d * sin2]
        })
    }

    /// Intensity analyser `k` records for Stokes `s` (the forward model of this calibration).
    pub fn intensity(&self, k: usize, s: [f64; 3]) -> f64 {
        let row = self.measurement_matrix()[k];
        row[0] * s[0] + row[1] * s[1] + row[2] * s[2]
    }

    /// Checks the parameters (finite angles, ER > 1, finite gain > 0).
    pub fn validate(&self) -> Result<(), CalibrationError> {
        for k in 0..4 {
            let bad = |what: String| CalibrationError::Parameter {
                index: k,
                nominal_deg: 45 * k as u32,
                what,
            };
            if !self.angle_deg[k].is_finite() {
                return Err(bad(format!("angle {} is not finite", self.angle_deg[k])));
            }
            let er = self.extinction_ratio[k];
            if er.is_nan() || er <= 1.0 {
                return Err(bad(format!("extinction ratio {er} must be > 1")));
            }
            let g = self.gain[k];
            if !g.is_finite() || g <= 0.0 {
                return Err(bad(format!("gain {g} must be finite and > 0")));
            }
        }
        Ok(())
    }

    /// The least-squares estimator `A⁺` and the residual direction (see the module doc).
    pub fn stokes_matrix(&self) -> Result<StokesMatrix, CalibrationError> {
        self.validate()?;
        StokesMatrix::of_measurement(self.measurement_matrix())
    }
}

impl StokesMatrix {
    /// The estimator of any 4×3 measurement matrix `a` (`I = A s`, rows in 0°, 45°, 90°, 135°
    /// order): one global calibration's, or one superpixel's of a per-pixel sensor
    /// calibration ([`crate::sensor_calibration`]).
    pub fn of_measurement(a: [[f64; 3]; 4]) -> Result<StokesMatrix, CalibrationError> {
        // AᵀA (3×3, symmetric)
        let mut ata = [[0.0f64; 3]; 3];
        for row in &a {
            for i in 0..3 {
                for j in 0..3 {
                    ata[i][j] += row[i] * row[j];
                }
            }
        }
        let inv = invert3(ata)?;
        let mut rows = [[0.0f32; 4]; 3];
        for (i, out_row) in rows.iter_mut().enumerate() {
            for (k, a_row) in a.iter().enumerate() {
                let v: f64 = (0..3).map(|j| inv[i][j] * a_row[j]).sum();
                out_row[k] = v as f32;
            }
        }
        // left null vector: n_k = (−1)^k det(A without row k) (4-D generalised cross product)
        let mut null = [0.0f64; 4];
        for (k, n) in null.iter_mut().enumerate() {
            let minor: Vec<[f64; 3]> = (0..4).filter(|&r| r != k).map(|r| a[r]).collect();
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            *n = sign * det3([minor[0], minor[1], minor[2]]);
        }
        let norm = null.iter().map(|v| v * v).sum::<f64>().sqrt();
        // orient like the ideal [1, −1, 1, −1]; norm > 0 whenever AᵀA is invertible
        let orientation = null[0] - null[1] + null[2] - null[3];
        let scale = if orientation < 0.0 { -2.0 } else { 2.0 } / norm;
        Ok(StokesMatrix {
            rows,
            null: null.map(|v| (v * scale) as f32),
        })
    }
}

impl Default for AnalyserCalibration {
    fn default() -> Self {
        AnalyserCalibration::IDEAL
    }
}

pub(crate) fn det3(m: [[f64; 3]; 3]) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

/// Inverse of a 3×3 matrix by cofactors; singular when |det| is below 1e-12 of the scale.
fn invert3(m: [[f64; 3]; 3]) -> Result<[[f64; 3]; 3], CalibrationError> {
    let determinant = det3(m);
    let scale = m
        .iter()
        .flatten()
        .map(|v| v.abs())
        .fold(0.0f64, f64::max)
        .powi(3);
    if !determinant.is_finite() || determinant.abs() <= 1e-12 * scale.max(f64::MIN_POSITIVE) {
        return Err(CalibrationError::Singular { determinant });
    }
    Ok(adjugate_over(m, determinant))
}

/// The adjugate of `m` (its cofactor matrix transposed) divided by `det`: `m`'s inverse when
/// `det` is its determinant ([`det3`]) and the caller has judged it far enough from 0.
pub(crate) fn adjugate_over(m: [[f64; 3]; 3], det: f64) -> [[f64; 3]; 3] {
    let c =
        |r0: usize, r1: usize, c0: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let cof = [
        [c(1, 2, 1, 2), -c(1, 2, 0, 2), c(1, 2, 0, 1)],
        [-c(0, 2, 1, 2), c(0, 2, 0, 2), -c(0, 2, 0, 1)],
        [c(0, 1, 1, 2), -c(0, 1, 0, 2), c(0, 1, 0, 1)],
    ];
    std::array::from_fn(|i| std::array::from_fn(|j| cof[j][i] / det))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ideal_calibration_gives_the_textbook_estimator() {
        let m = AnalyserCalibration::IDEAL
            .stokes_matrix()
            .expect("invertible");
        let expect = [
            [0.5, 0.5, 0.5, 0.5],
            [1.0, 0.0, -1.0, 0.0],
            [0.0, 1.0, 0.0, -1.0],
        ];
        for (row, want) in m.rows.iter().zip(expect) {
            for (v, w) in row.iter().zip(want) {
                assert!((v - w).abs() < 1e-6, "{:?}", m.rows);
            }
        }
        for (v, w) in m.null.iter().zip([1.0, -1.0, 1.0, -1.0]) {
            assert!((v - w).abs() < 1e-6, "{:?}", m.null);
        }
    }

    #[test]
    fn estimator_inverts_a_non_ideal_sensor_and_null_vector_sees_no_signal() {
        let cal = AnalyserCalibration {
            angle_deg: [1.5, 44.0, 91.0, 136.2],
            extinction_ratio: [25.0, 30.0, 18.0, 40.0],
            gain: [1.03, 0.97, 1.0, 0.95],
        };
        let m = cal.stokes_matrix().expect("invertible");
        for s in [[1.0, 0.3, -0.4], [0.7, -0.2, 0.1], [2.0, 0.0, 1.9]] {
            let i: [f64; 4] = std::array::from_fn(|k| cal.intensity(k, s));
            for (r, want) in m.rows.iter().zip(s) {
                let got: f64 = r.iter().zip(i).map(|(a, b)| f64::from(*a) * b).sum();
                assert!((got - want).abs() < 1e-5, "{got} vs {want}");
            }
            let residual: f64 = m.null.iter().zip(i).map(|(a, b)| f64::from(*a) * b).sum();
            assert!(residual.abs() < 1e-5, "{residual}");
        }
        let norm: f32 = m.null.iter().map(|v| v * v).sum::<f32>().sqrt();
        assert!((norm - 2.0).abs() < 1e-5);
    }

    #[test]
    fn degenerate_and_invalid_calibrations_are_refused() {
        let same_angle = AnalyserCalibration {
            angle_deg: [0.0; 4],
            ..AnalyserCalibration::IDEAL
        };
        assert!(matches!(
            same_angle.stokes_matrix(),
            Err(CalibrationError::Singular { .. })
        ));
        let leaky = AnalyserCalibration {
            extinction_ratio: [1.0, 30.0, 30.0, 30.0],
            ..AnalyserCalibration::IDEAL
        };
        let e = leaky.stokes_matrix().unwrap_err().to_string();
        assert!(e.contains("analyser 0") && e.contains("> 1"), "{e}");
        let bad_gain = AnalyserCalibration {
            gain: [1.0, 1.0, f64::NAN, 1.0],
            ..AnalyserCalibration::IDEAL
        };
        assert!(
            bad_gain
                .stokes_matrix()
                .unwrap_err()
                .to_string()
                .contains("90°")
        );
    }

    #[test]
    fn calibration_reads_from_json() {
        let text =
            r#"{"angle_deg":[0.5,45,90,135],"extinction_ratio":[30,30,30,30],"gain":[1,1,1,1]}"#;
        let cal: AnalyserCalibration = serde_json::from_str(text).expect("json");
        assert!((cal.diattenuation(0) - 29.0 / 31.0).abs() < 1e-15);
        assert!(cal.stokes_matrix().is_ok());
    }
}

/// End-to-end: calibrated processing of raw frames.
#[cfg(test)]
mod pipeline_tests {
    use std::f64::consts::PI;

    use ellipso_model::mosaic::SensorLayout;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::AnalyserCalibration;
    use crate::*;

    const MONO: SensorLayout = SensorLayout::MonoPolar;

    fn axial_distance(a: f64, b: f64) -> f64 {
        let d = (a - b).rem_euclid(PI);
        d.min(PI - d)
    }

    fn expected_aolp(s: [f64; 3]) -> f64 {
        (0.5 * s[2].atan2(s[1])).rem_euclid(PI)
    }

    #[test]
    fn calibration_recovers_stokes_that_ideal_formulas_get_wrong() {
        let cal = AnalyserCalibration {
            angle_deg: [2.0, 44.0, 91.5, 133.0],
            extinction_ratio: [20.0, 25.0, 15.0, 30.0],
            gain: [1.04, 0.96, 1.0, 0.98],
        };
        let s_true = [40000.0, 12000.0, -9000.0]; // DN, 16-bit frame
        let data: Vec<u16> = (0..8u32 * 8)
            .map(|i| {
                let a = MONO.analyser_at(i % 8, i / 8);
                cal.intensity(a.index(), s_true).round() as u16
            })
            .collect();
        let frame = RawFrame::new(8, 8, 16, MONO, data).expect("frame");
        let calibrated = PolarConfig {
            calibration: Some(cal),
            max_residual: Some(1e-3),
            ..PolarConfig::default()
        };
        let img = process(&frame, &calibrated).expect("calibrated");
        let band = &img.bands[0];
        let s = s_true.map(|v| v / 65535.0);
        let dolp_true = s[1].hypot(s[2]) / s[0];
        for i in 0..band.s0.data().len() {
            assert!((f64::from(band.s0.data()[i]) - s[0]).abs() < 1e-4);
            assert!((f64::from(band.dolp.data()[i]) - dolp_true).abs() < 1e-4);
            let a = f64::from(band.aolp_rad.data()[i]);
            assert!(axial_distance(a, expected_aolp(s)) < 1e-3);
            assert!(
                band.residual.data()[i].abs() < 1e-4,
                "model-consistent data"
            );
            assert!(band.mask.data()[i].is_valid());
            // I^d of ideal analysers = s0 − s1
            assert!((f64::from(band.i_d.data()[i]) - (s[0] - s[1])).abs() < 1e-4);
        }
        // the same data through the ideal formulas: DoLP biased low by the leaky analysers
        let ideal = process(&frame, &PolarConfig::default()).expect("ideal");
        let d_ideal = f64::from(ideal.bands[0].dolp.data()[0]);
        assert!(
            dolp_true - d_ideal > 0.02,
            "ideal {d_ideal} vs true {dolp_true}"
        );
    }

    #[test]
    fn ideal_calibration_matches_the_exact_fast_path() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let data: Vec<u16> = (0..16 * 8).map(|_| rng.random_range(0..4096)).collect();
        let frame = RawFrame::new(16, 8, 12, MONO, data).expect("frame");
        let fast = process(&frame, &PolarConfig::default()).expect("fast");
        let general = PolarConfig {
            calibration: Some(AnalyserCalibration::IDEAL),
            ..PolarConfig::default()
        };
        let general = process(&frame, &general).expect("general");
        let (a, b) = (&fast.bands[0], &general.bands[0]);
        let close = |x: &Plane<f32>, y: &Plane<f32>| {
            x.data()
                .iter()
                .zip(y.data())
                .all(|(p, q)| (p - q).abs() < 1e-5)
        };
        assert!(close(&a.s0, &b.s0) && close(&a.s1, &b.s1) && close(&a.s2, &b.s2));
        assert!(close(&a.dolp, &b.dolp) && close(&a.residual, &b.residual));
        // I^d differs by design only where the data is inconsistent: 2·I90 vs s0 − s1
        let levels = PolarConfig::default().levels(&frame).expect("levels");
        let planes = demosaic(&frame, &levels, DemosaicMethod::Superpixel);
        for i in 0..a.i_d.data().len() {
            let r = a.residual.data()[i];
            assert!((a.i_d.data()[i] - b.i_d.data()[i] - 0.5 * r).abs() < 1e-5);
            assert_eq!(
                a.i_d.data()[i],
                2.0 * planes.bands[0].intensity[2].data()[i]
            );
        }
    }

    #[test]
    fn unusable_calibration_is_a_config_error() {
        let frame = RawFrame::new(2, 2, 12, MONO, vec![0; 4]).expect("frame");
        let cfg = PolarConfig {
            calibration: Some(AnalyserCalibration {
                angle_deg: [0.0; 4],
                ..AnalyserCalibration::IDEAL
            }),
            ..PolarConfig::default()
        };
        let e = process(&frame, &cfg).unwrap_err();
        assert!(matches!(e, PolarError::Calibration(_)), "{e}");
    }
}
