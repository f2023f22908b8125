//! Noise weights of samples from short flash pulses: a frame lit by a fraction E of the full
//! pulse stores the normaliser E·N (observation extraction), and the measurement-mode weights
//! must then give its sample the noise of the E-times-smaller DN it was divided from.

use super::super::tests::{material, synth};
use super::super::*;
use crate::model::observed_pixels;

/// Relative pulse energy of the short frame.
const ENERGY: f64 = 0.25;

/// A noiseless vertex and the same normalised samples as a quarter-pulse frame would give them
/// (same model-unit channels, normaliser × 1/4).
fn full_and_quarter() -> (Vec<ViewGeometry>, VertexSamples, VertexSamples) {
    let views = super::super::tests::views();
    let full = synth(&views, [0.0, 0.0, 1.0], &material("ceramic"), None, 1.0, 5);
    let mut quarter = full.clone();
    for s in &mut quarter.samples {
        s.normaliser *= ENERGY as f32;
    }
    (views, full, quarter)
}

/// 1/σ of every analyser pixel of every sample, under `sensor`.
fn inverse_sigmas(
    views: &[ViewGeometry],
    vertex: &VertexSamples,
    sensor: SensorNoiseModel,
) -> Vec<[[f64; 4]; 3]> {
    let config = SolverConfig {
        sensor,
        ..SolverConfig::default()
    };
    assert_eq!(config.loss, LossMode::Measurement);
    Problem::new(views, vertex, true, &VertexGuide::default(), &config).inv_sigma
}

#[test]
fn a_short_pulse_sample_has_the_noise_of_its_smaller_dn() {
    let (views, full, quarter) = full_and_quarter();
    assert!(full.samples.len() > 40);
    let sensor = SensorNoiseModel::default();
    let (g, f) = (
        sensor.dn_per_electron,
        sensor.read_noise_dn.powi(2) + 1.0 / 12.0,
    );
    let a = inverse_sigmas(&views, &full, sensor);
    let b = inverse_sigmas(&views, &quarter, sensor);
    assert_eq!(a.len(), b.len());
    for ((s, wa), wb) in full.samples.iter().zip(&a).zip(&b) {
        let n = f64::from(s.normaliser);
        for c in 0..3 {
            let pixels = observed_pixels(s.channels[c].map(f64::from));
            for j in 0..4 {
                // σ in model units = σ_DN / (E·N) with σ_DN² = g·(E·N·I) + floor.
                let i = pixels[j].max(0.0);
                let var = |e: f64| (g * e * n * i + f) / (e * n).powi(2);
                let want = (var(1.0) / var(ENERGY)).sqrt();
                let got = wb[c][j] / wa[c][j];
                assert!((got / want - 1.0).abs() < 1e-5, "{got} vs {want}");
                // Between 1/√E (shot-noise limited) and 1/E (read-noise limited) times the
                // full pulse's σ.
                assert!(
                    got >= ENERGY * (1.0 - 1e-6) && got <= ENERGY.sqrt() * (1.0 + 1e-6),
                    "{got}"
                );
            }
        }
    }
}

#[test]
fn the_noise_weight_scales_as_e_read_limited_and_root_e_shot_limited() {
    let (views, full, quarter) = full_and_quarter();
    let ratios = |sensor: SensorNoiseModel| -> Vec<f64> {
        let a = inverse_sigmas(&views, &full, sensor);
        let b = inverse_sigmas(&views, &quarter, sensor);
        a.iter()
            .zip(&b)
            .flat_map(|(wa, wb)| (0..4).map(move |j| wb[0][j] / wa[0][j]))
            .collect()
    };
    // Read noise only (a vanishing gain): 1/σ scales by E exactly.
    let read = SensorNoiseModel {
        dn_per_electron: 0.0,
        read_noise_dn: 5.0,
    };
    for r in ratios(read) {
        assert!((r - ENERGY).abs() < 1e-6, "{r}");
    }
    // Shot noise dominant (a large gain, no read noise): 1/σ scales by √E.
    let shot = SensorNoiseModel {
        dn_per_electron: 50.0,
        read_noise_dn: 0.0,
    };
    let mut r = ratios(shot);
    let median = ellipso_report::percentile(&mut r, 0.5);
    assert!((median - ENERGY.sqrt()).abs() < 0.01, "{median}");
}
