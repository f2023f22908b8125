//! The rig's observation channels I^d, I^s, I^α (docs/model.md §6 "Observation channels").
//!
//! With the flash polariser parallel to the 0° analyser (light Stokes [1, 1, 0] in the light
//! frame), the four analyser images separate into:
//!
//! ```text
//! I^d = 2·I90        diffuse shading                         (= s0 − s1 for consistent data)
//! I^s = I0 − I90     specular + single scattering − DP·cos2φ (= s1)
//! I^α = I135 − I45   diffuse-polarisation sine part, DP·sin2φ (= −s2)
//! ```
//!
//! I^d ≥ 0 for unclipped data; I^s and I^α are signed. I^s = s1 and I^α = −s2 hold bit for bit
//! (same subtraction), so a [`super::StokesBand`] stores only I^d and serves I^s as its s1 plane
//! and I^α as −s2 ([`super::StokesBand::i_s`], [`super::StokesBand::i_alpha_at`]); this type is
//! the owned copy for consumers that want three planes. I^d = s0 − s1 holds only when the
//! consistency residual I0 + I90 − I45 − I135 is 0; I^d is computed from I90 itself, so it stays
//! the cross-polarised measurement even where the residual is not 0.

use super::plane::Plane;

/// Observation channel planes of one band, in the band's normalised units.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ObservationChannels {
    /// I^d = 2·I90 (cross-polarised: diffuse shading).
    pub i_d: Plane<f32>,
    /// I^s = I0 − I90 (signed).
    pub i_s: Plane<f32>,
    /// I^α = I135 − I45 (signed).
    pub i_alpha: Plane<f32>,
}

/// `[I^d, I^s, I^α]` from intensities `[I0, I45, I90, I135]`.
pub fn observation_channels(i: [f32; 4]) -> [f32; 3] {
    let [i0, i45, i90, i135] = i;
    [2.0 * i90, i0 - i90, i135 - i45]
}

#[cfg(test)]
mod tests {
    use super::super::stokes::{intensity_behind_analyser, stokes_from_intensities};
    use super::*;

    #[test]
    fn channels_match_stokes_identities_for_physical_light() {
        for s in [
            [1.0, 0.2, -0.3],
            [0.5, -0.5, 0.0],
            [2.0, 0.1, 1.2],
            [0.8, 0.0, 0.0],
        ] {
            let i = [0.0f64, 45.0, 90.0, 135.0]
                .map(|d| intensity_behind_analyser(s, d.to_radians()) as f32);
            let [s0, s1, s2] = stokes_from_intensities(i);
            let [i_d, i_s, i_alpha] = observation_channels(i);
            assert!((i_s - s1).abs() < 1e-6, "I^s = s1");
            assert!((i_alpha + s2).abs() < 1e-6, "I^α = −s2");
            assert!((i_d - (s0 - s1)).abs() < 1e-6, "I^d = s0 − s1");
        }
    }

    #[test]
    fn co_polarised_flash_lands_in_i_s_not_i_d() {
        // light polarised along the 0° analyser (like an unscattered specular flash return)
        let i = [1.0, 0.5, 0.0, 0.5];
        let [i_d, i_s, i_alpha] = observation_channels(i);
        assert_eq!((i_d, i_s, i_alpha), (0.0, 1.0, 0.0));
    }
}
