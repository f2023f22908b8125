//! End-to-end tests of the polar pipeline on synthetic mosaics with known Stokes fields.

use std::f64::consts::PI;

use ellipso_model::mosaic::{Channel, SensorLayout};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::synthetic::mosaic_from_stokes;
use super::*;

const MONO: SensorLayout = SensorLayout::MonoPolar;
const COLOUR: SensorLayout = SensorLayout::ColourPolar;
const FULL_12: f64 = 4095.0;

fn config(method: DemosaicMethod) -> PolarConfig {
    PolarConfig {
        demosaic: method,
        ..PolarConfig::default()
    }
}

fn expected_aolp(s: [f64; 3]) -> f64 {
    (0.5 * s[2].atan2(s[1])).rem_euclid(PI)
}

/// Distance between two axial angles (period π), in radians.
fn axial_distance(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(PI);
    d.min(PI - d)
}

/// Asserts that `band` at pixel `i` holds Stokes `s_dn` (in DN of a 12-bit frame).
fn assert_stokes_at(band: &StokesBand, i: usize, s_dn: [f64; 3], tol: f64) {
    let s = s_dn.map(|v| v / FULL_12);
    let got = [band.s0.data()[i], band.s1.data()[i], band.s2.data()[i]].map(f64::from);
    for k in 0..3 {
        assert!(
            (got[k] - s[k]).abs() < tol,
            "pixel {i}: s{k} {got:?} vs {s:?}"
        );
    }
    let dolp = (s[1].hypot(s[2]) / s[0]).min(1.0);
    assert!(
        (f64::from(band.dolp.data()[i]) - dolp).abs() < tol * 10.0,
        "DoLP at {i}"
    );
    if dolp > 0.01 {
        let a = f64::from(band.aolp_rad.data()[i]);
        assert!(
            axial_distance(a, expected_aolp(s)) < 1e-4,
            "AoLP at {i}: {a}"
        );
    }
}

#[test]
fn constant_field_is_recovered_exactly_by_both_methods_and_layouts() {
    // whole-DN intensities: I0 = 1300, I45 = 800, I90 = 700, I135 = 1200
    let s_dn = [2000.0, 600.0, -400.0];
    for layout in SensorLayout::ALL {
        let frame = mosaic_from_stokes(layout, 16, 12, 12, |_, _, _| s_dn).expect("frame");
        for method in [DemosaicMethod::Superpixel, DemosaicMethod::Bilinear] {
            let img = process(&frame, &config(method)).expect("process");
            assert_eq!(img.method, method);
            let expect_bands = if layout == MONO { 1 } else { 3 };
            assert_eq!(img.bands.len(), expect_bands);
            for band in &img.bands {
                for i in 0..band.s0.data().len() {
                    assert_stokes_at(band, i, s_dn, 1e-6);
                    assert!(band.mask.data()[i].is_valid(), "{layout:?} {method:?} {i}");
                    assert!(band.residual.data()[i].abs() < 1e-6);
                }
            }
        }
    }
}

#[test]
fn malus_law_in_the_demosaiced_analyser_planes() {
    // fully polarised light at φ: I_θ = s0·cos²(θ − φ)
    for phi_deg in [0.0f64, 17.0, 45.0, 90.0, 133.0] {
        let phi = phi_deg.to_radians();
        let s0 = 3000.0;
        let s = [s0, s0 * (2.0 * phi).cos(), s0 * (2.0 * phi).sin()];
        let frame = mosaic_from_stokes(MONO, 8, 8, 12, |_, _, _| s).expect("frame");
        let cfg = config(DemosaicMethod::Superpixel);
        let levels = cfg.levels(&frame).expect("levels");
        let planes = demosaic(&frame, &levels, DemosaicMethod::Superpixel);
        for (k, theta_deg) in [0.0f64, 45.0, 90.0, 135.0].iter().enumerate() {
            let malus = s0 * (theta_deg.to_radians() - phi).cos().powi(2) / FULL_12;
            let got = f64::from(planes.bands[0].intensity[k].data()[0]);
            assert!(
                (got - malus).abs() < 0.6 / FULL_12,
                "φ={phi_deg} θ={theta_deg}"
            );
        }
        let img = process(&frame, &cfg).expect("process");
        let band = &img.bands[0];
        assert!(band.dolp.data()[0] > 0.999, "fully polarised");
        let a = f64::from(band.aolp_rad.data()[0]);
        assert!(axial_distance(a, phi) < 1e-3, "φ={phi_deg}: AoLP {a}");
    }
}

#[test]
fn aolp_wraps_at_pi() {
    for (phi_deg, near_pi) in [(179.9f64, true), (0.1, false), (180.0, false)] {
        let phi = phi_deg.to_radians();
        let s = [
            60000.0,
            60000.0 * (2.0 * phi).cos(),
            60000.0 * (2.0 * phi).sin(),
        ];
        let frame = mosaic_from_stokes(MONO, 4, 4, 16, |_, _, _| [s[0], s[1], s[2]]).expect("f");
        let img = process(&frame, &PolarConfig::default()).expect("process");
        let a = f64::from(img.bands[0].aolp_rad.data()[0]);
        assert!((0.0..PI).contains(&a), "{a}");
        assert_eq!(a > PI / 2.0, near_pi, "φ={phi_deg}: {a}");
        assert!(axial_distance(a, phi) < 1e-4, "φ={phi_deg}: {a}");
    }
}

/// Stokes in a frame rotated by θ (Mueller rotator C(θ) acting on the linear part).
fn rotate(s: [f64; 3], theta: f64) -> [f64; 3] {
    let (sin2, cos2) = (2.0 * theta).sin_cos();
    [s[0], s[1] * cos2 + s[2] * sin2, -s[1] * sin2 + s[2] * cos2]
}

fn stokes_via_analysers(s: [f64; 3]) -> [f32; 3] {
    let i =
        [0.0f64, 45.0, 90.0, 135.0].map(|d| intensity_behind_analyser(s, d.to_radians()) as f32);
    stokes_from_intensities(i)
}

#[test]
fn rotation_shifts_aolp_and_keeps_dolp() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for _ in 0..200 {
        let s0: f64 = rng.random_range(0.1..2.0);
        let p: f64 = rng.random_range(0.05..1.0);
        let phi: f64 = rng.random_range(0.0..PI);
        let theta: f64 = rng.random_range(-PI..PI);
        let s = [s0, s0 * p * (2.0 * phi).cos(), s0 * p * (2.0 * phi).sin()];
        let [a0, a1, a2] = stokes_via_analysers(s);
        let [b0, b1, b2] = stokes_via_analysers(rotate(s, theta));
        let (aolp_s, aolp_r) = (f64::from(aolp_rad(a1, a2)), f64::from(aolp_rad(b1, b2)));
        assert!(axial_distance(aolp_r, aolp_s - theta) < 1e-4, "θ={theta}");
        assert!((dolp(a0, a1, a2) - dolp(b0, b1, b2)).abs() < 1e-5);
    }
}

#[test]
fn saturated_raw_pixel_masks_its_superpixel_only_and_breaks_consistency() {
    let s_dn = [2000.0, 600.0, -400.0];
    let frame = mosaic_from_stokes(MONO, 8, 8, 12, |_, _, _| s_dn).expect("frame");
    let mut data = frame.into_data();
    data[3 * 8 + 5] = 4095; // raw (5, 3): the 0° pixel of superpixel (2, 1) clips
    let frame = RawFrame::new(8, 8, 12, MONO, data).expect("frame");
    let img = process(&frame, &PolarConfig::default()).expect("process");
    let band = &img.bands[0];
    let bad = 4 + 2;
    for (i, m) in band.mask.data().iter().enumerate() {
        assert_eq!(m.has(MaskReason::Saturated), i == bad, "pixel {i}: {m:?}");
    }
    assert!(band.residual.data()[bad].abs() > 0.5, "I0 clipped high");
    assert!(band.residual.data()[0].abs() < 1e-6, "ideal elsewhere");
    // with a residual limit, the same pixel is also flagged inconsistent
    let strict = PolarConfig {
        max_residual: Some(0.01),
        ..PolarConfig::default()
    };
    let img = process(&frame, &strict).expect("process");
    assert!(img.bands[0].mask.data()[bad].has(MaskReason::Inconsistent));
    assert_eq!(MaskSummary::of(img.bands[0].mask.data()).valid, 15);
}

#[test]
fn bilinear_never_averages_in_a_saturated_sample() {
    let s_dn = [2000.0, 600.0, -400.0];
    let frame = mosaic_from_stokes(MONO, 12, 12, 12, |_, _, _| s_dn).expect("frame");
    let mut data = frame.into_data();
    let (sx, sy) = (5usize, 5usize); // a 0° sample
    data[sy * 12 + sx] = 4095;
    let frame = RawFrame::new(12, 12, 12, MONO, data).expect("frame");
    let img = process(&frame, &config(DemosaicMethod::Bilinear)).expect("process");
    let band = &img.bands[0];
    for y in 0..12usize {
        for x in 0..12usize {
            let i = y * 12 + x;
            let in_footprint = x.abs_diff(sx) <= 1 && y.abs_diff(sy) <= 1;
            let m = band.mask.data()[i];
            assert_eq!(
                m.has(MaskReason::Saturated),
                in_footprint,
                "({x},{y}) {m:?}"
            );
            // neighbours of the clipped sample still get the true value from the others,
            // except the clipped pixel itself, whose only 0° sample was dropped
            if (x, y) != (sx, sy) {
                assert_stokes_at(band, i, s_dn, 1e-6);
            }
            assert!(band.s0.data()[i].is_finite() && band.dolp.data()[i].is_finite());
        }
    }
}

#[test]
fn dark_pixels_are_masked_with_dolp_guarded() {
    let frame = mosaic_from_stokes(MONO, 4, 2, 12, |x, _, _| {
        if x < 2 {
            [4.0, 2.0, 0.0]
        } else {
            [2000.0, 0.0, 0.0]
        }
    })
    .expect("frame");
    let img = process(&frame, &PolarConfig::default()).expect("process");
    let band = &img.bands[0];
    assert_eq!(band.mask.data()[0], PixelMask::only(MaskReason::Dark));
    assert!(band.mask.data()[1].is_valid());
    // all-black frame: nothing divides by zero
    let black = RawFrame::new(4, 4, 12, MONO, vec![0; 16]).expect("frame");
    let img = process(&black, &PolarConfig::default()).expect("process");
    let band = &img.bands[0];
    assert!(band.dolp.data().iter().all(|&d| d == 0.0));
    assert!(band.aolp_rad.data().iter().all(|&a| a == 0.0));
    assert!(band.mask.data().iter().all(|m| m.has(MaskReason::Dark)));
}

#[test]
fn dark_level_subtraction_shifts_s0_but_not_polarisation() {
    let frame =
        mosaic_from_stokes(MONO, 4, 4, 12, |_, _, _| [2200.0, 600.0, -400.0]).expect("frame");
    // add a 100 DN pedestal to every pixel: s0 += 200 DN
    let data: Vec<u16> = frame.data_dn().iter().map(|v| v + 100).collect();
    let frame = RawFrame::new(4, 4, 12, MONO, data).expect("frame");
    let cfg = PolarConfig {
        dark_level_dn: 100.0,
        ..PolarConfig::default()
    };
    let img = process(&frame, &cfg).expect("process");
    let band = &img.bands[0];
    let span = 4095.0 - 100.0;
    assert!((f64::from(band.s0.data()[0]) - 2200.0 / span).abs() < 1e-6);
    let dolp = 600.0f64.hypot(400.0) / 2200.0;
    assert!((f64::from(band.dolp.data()[0]) - dolp).abs() < 1e-5);
}

#[test]
fn colour_bands_are_separated() {
    let per_colour = |c: Option<Channel>| match c {
        Some(Channel::Red) => [2000.0, 600.0, -400.0],
        Some(Channel::Green) => [1000.0, -200.0, 100.0],
        Some(Channel::Blue) => [3000.0, 0.0, 1000.0],
        None => [0.0; 3],
    };
    let frame = mosaic_from_stokes(COLOUR, 16, 16, 12, |_, _, c| per_colour(c)).expect("frame");
    for method in [DemosaicMethod::Superpixel, DemosaicMethod::Bilinear] {
        let img = process(&frame, &config(method)).expect("process");
        assert_eq!(
            img.width(),
            if method == DemosaicMethod::Bilinear {
                16
            } else {
                4
            }
        );
        for band in &img.bands {
            for i in 0..band.s0.data().len() {
                assert_stokes_at(band, i, per_colour(band.colour), 1e-6);
            }
        }
    }
}

#[test]
fn colour_superpixel_uses_the_unsaturated_green_block() {
    let frame =
        mosaic_from_stokes(COLOUR, 8, 4, 12, |_, _, _| [2000.0, 600.0, -400.0]).expect("frame");
    let mut data = frame.into_data();
    data[3] = 4095; // (3, 0): 45° pixel of the first tile's top-right G block
    let frame = RawFrame::new(8, 4, 12, COLOUR, data).expect("frame");
    let img = process(&frame, &PolarConfig::default()).expect("process");
    let g = &img.bands[Channel::Green.index()];
    assert!(g.mask.data()[0].is_valid(), "other G block still good");
    assert_stokes_at(g, 0, [2000.0, 600.0, -400.0], 1e-6);
    // saturate the other G block too: now the G output is masked, R and B untouched
    data = frame.into_data();
    data[2 * 8] = 4095; // (0, 2): the bottom-left G block
    data[8 + 1] = 4095; // (1, 1): the R block
    let frame = RawFrame::new(8, 4, 12, COLOUR, data).expect("frame");
    let img = process(&frame, &PolarConfig::default()).expect("process");
    assert!(img.bands[Channel::Green.index()].mask.data()[0].has(MaskReason::Saturated));
    assert!(img.bands[Channel::Red.index()].mask.data()[0].has(MaskReason::Saturated));
    assert!(img.bands[Channel::Blue.index()].mask.data()[0].is_valid());
}

#[test]
fn bilinear_reproduces_affine_fields_in_the_interior() {
    // even coefficients keep every intensity a whole DN, so the data is exact
    let field = |x: u32, y: u32| {
        let (x, y) = (f64::from(x), f64::from(y));
        [
            4000.0 + 8.0 * x + 4.0 * y,
            200.0 + 2.0 * x - 2.0 * y,
            -300.0 + 4.0 * x + 2.0 * y,
        ]
    };
    for layout in SensorLayout::ALL {
        let (w, h) = (24u32, 20u32);
        let frame = mosaic_from_stokes(layout, w, h, 16, |x, y, _| field(x, y)).expect("frame");
        let img = process(&frame, &config(DemosaicMethod::Bilinear)).expect("process");
        let margin = layout.tile_px() - 1;
        for band in &img.bands {
            for y in margin..h - margin {
                for x in margin..w - margin {
                    let i = (y * w + x) as usize;
                    let s = field(x, y).map(|v| v / 65535.0);
                    let got = [band.s0.data()[i], band.s1.data()[i], band.s2.data()[i]];
                    for k in 0..3 {
                        assert!(
                            (f64::from(got[k]) - s[k]).abs() < 2e-6,
                            "{layout:?} {:?} ({x},{y}) s{k}: {got:?} vs {s:?}",
                            band.colour
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn fused_rows_equal_demosaic_then_stokes_for_both_methods() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for layout in SensorLayout::ALL {
        let data: Vec<u16> = (0..16 * 8).map(|_| rng.random_range(0..4096)).collect();
        let frame = RawFrame::new(16, 8, 12, layout, data).expect("frame");
        for method in [DemosaicMethod::Superpixel, DemosaicMethod::Bilinear] {
            let cfg = config(method);
            let fused = process(&frame, &cfg).expect("fused");
            let levels = cfg.levels(&frame).expect("levels");
            let planes = demosaic(&frame, &levels, method);
            let split = stokes_from_analysers(&planes, levels, &cfg).expect("split");
            assert_eq!(fused, split, "{layout:?} {method:?}");
            // random data exercises every mask path; outputs stay finite and in range
            for band in &fused.bands {
                assert!(band.dolp.data().iter().all(|d| (0.0..=1.0).contains(d)));
                assert!(
                    band.aolp_rad
                        .data()
                        .iter()
                        .all(|a| (0.0..std::f32::consts::PI).contains(a))
                );
            }
        }
    }
}

#[test]
fn process_into_reuses_buffers_across_sizes() {
    let small = mosaic_from_stokes(MONO, 4, 4, 12, |_, _, _| [2000.0, 600.0, -400.0]).expect("f");
    let big = mosaic_from_stokes(COLOUR, 8, 8, 12, |_, _, _| [2000.0, 600.0, -400.0]).expect("f");
    let mut out = PolarImage::empty();
    process_into(&big, &PolarConfig::default(), &mut out).expect("big");
    process_into(&small, &PolarConfig::default(), &mut out).expect("small");
    assert_eq!(
        out,
        process(&small, &PolarConfig::default()).expect("fresh")
    );
}

#[test]
fn bad_configurations_name_the_problem() {
    let frame = RawFrame::new(2, 2, 12, MONO, vec![0; 4]).expect("frame");
    let bad = [
        PolarConfig {
            saturation_dn: Some(5000),
            ..PolarConfig::default()
        },
        PolarConfig {
            saturation_dn: Some(0),
            ..PolarConfig::default()
        },
        PolarConfig {
            dark_level_dn: 4095.0,
            ..PolarConfig::default()
        },
        PolarConfig {
            dark_level_dn: f32::NAN,
            ..PolarConfig::default()
        },
        PolarConfig {
            dark_intensity: -1.0,
            ..PolarConfig::default()
        },
        PolarConfig {
            max_residual: Some(f32::INFINITY),
            ..PolarConfig::default()
        },
    ];
    for cfg in bad {
        let err = process(&frame, &cfg).unwrap_err();
        assert!(!err.to_string().is_empty());
    }
    let err = process(&frame, &bad[0]).unwrap_err().to_string();
    assert!(err.contains("5000") && err.contains("4095"), "{err}");
}

proptest! {
    #[test]
    fn dolp_of_physical_stokes_is_in_unit_interval(
        s0 in 1.0f64..4000.0,
        p in 0.0f64..=1.0,
        phi in 0.0f64..PI,
    ) {
        let s = [s0, s0 * p * (2.0 * phi).cos(), s0 * p * (2.0 * phi).sin()];
        let [a0, a1, a2] = stokes_via_analysers(s);
        let d = dolp(a0, a1, a2);
        prop_assert!((0.0..=1.0).contains(&d));
        prop_assert!((f64::from(d) - p).abs() < 1e-4);
        let frame = mosaic_from_stokes(MONO, 2, 2, 12, |_, _, _| s).expect("frame");
        let img = process(&frame, &PolarConfig::default()).expect("process");
        let d = img.bands[0].dolp.data()[0];
        prop_assert!((0.0..=1.0).contains(&d));
        prop_assert!(img.bands[0].aolp_rad.data()[0].is_finite());
    }
}

#[test]
fn stored_and_derived_channels_match_their_definitions() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let data: Vec<u16> = (0..16 * 8).map(|_| rng.random_range(0..4096)).collect();
    let frame = RawFrame::new(16, 8, 12, MONO, data).expect("frame");
    let cfg = PolarConfig::default();
    let levels = cfg.levels(&frame).expect("levels");
    let planes = demosaic(&frame, &levels, DemosaicMethod::Superpixel);
    let img = process(&frame, &cfg).expect("process");
    let band = &img.bands[0];
    let owned = band.observation_channels();
    let [p0, p45, p90, p135] = &planes.bands[0].intensity;
    for i in 0..band.s0.data().len() {
        let (i0, i45, i90, i135) = (p0.data()[i], p45.data()[i], p90.data()[i], p135.data()[i]);
        assert_eq!(band.i_d.data()[i], 2.0 * i90);
        assert_eq!(band.i_s().data()[i], i0 - i90);
        assert_eq!(band.i_alpha_at(i), i135 - i45, "bit-exact −s2");
        assert_eq!(owned.i_alpha.data()[i], i135 - i45);
        assert_eq!(owned.i_s.data()[i], i0 - i90);
    }
    assert_eq!(band.i_alpha_at(usize::MAX), 0.0);
}

#[test]
fn handedness_polariser_at_plus_30_reads_30_not_150() {
    // docs/polar.md "Handedness check", on the ideal sensor: a linear polariser whose axis is 30°
    // counter-clockwise from image-right (toward image-up). Malus per analyser θ:
    // I_θ = I·cos²(θ − 30°), with θ taken from the mosaic definition.
    let frame = mosaic_from_stokes(MONO, 4, 4, 12, |_, _, _| {
        let phi = 30f64.to_radians();
        [
            3000.0,
            3000.0 * (2.0 * phi).cos(),
            3000.0 * (2.0 * phi).sin(),
        ]
    })
    .expect("frame");
    // I45 (cos² 15°) must be bright and I135 (cos² 105°) dark: the raw pixels say so directly
    let (x45, y45) = (1, 0); // mosaic: row 0 = 90° 45°
    let (x135, y135) = (0, 1); // row 1 = 135° 0°
    assert!(frame.get(x45, y45) > frame.get(x135, y135));
    let img = process(&frame, &PolarConfig::default()).expect("process");
    let aolp_deg = f64::from(img.bands[0].aolp_rad.data()[0]).to_degrees();
    assert!((aolp_deg - 30.0).abs() < 0.05, "{aolp_deg}");
}

proptest! {
    #[test]
    fn any_valid_frame_gives_finite_in_range_outputs(
        seed in any::<u64>(),
        colour in any::<bool>(),
        bilinear in any::<bool>(),
        dark in 0.0f32..50.0,
    ) {
        let layout = if colour { COLOUR } else { MONO };
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let data: Vec<u16> = (0..8 * 8).map(|_| rng.random_range(0..1024)).collect();
        let frame = RawFrame::new(8, 8, 10, layout, data).expect("frame");
        let cfg = PolarConfig {
            demosaic: if bilinear { DemosaicMethod::Bilinear } else { DemosaicMethod::Superpixel },
            dark_level_dn: dark,
            ..PolarConfig::default()
        };
        let img = process(&frame, &cfg).expect("process");
        for band in &img.bands {
            for plane in [&band.s0, &band.s1, &band.s2, &band.residual, &band.i_d] {
                prop_assert!(plane.data().iter().all(|v| v.is_finite()));
            }
            prop_assert!(band.dolp.data().iter().all(|d| (0.0..=1.0).contains(d)));
            prop_assert!(band
                .aolp_rad
                .data()
                .iter()
                .all(|a| (0.0..std::f32::consts::PI).contains(a)));
        }
    }
}

#[test]
fn mosaic_phase_errors_are_invisible_to_the_residual_but_corrupt_aolp() {
    // Why odd ROI offsets are refused: reading the mosaic one pixel off permutes the analysers.
    // Every permutation a shift produces keeps |I0 + I90 − I45 − I135| (so the residual cannot
    // catch it on smooth scenes) but maps AoLP φ to 135° − φ, 45° − φ or φ + 90°.
    let phi_deg = 30.0f64;
    let phi = phi_deg.to_radians();
    let s = [
        3000.0,
        1500.0 * (2.0 * phi).cos(),
        1500.0 * (2.0 * phi).sin(),
    ];
    let full = mosaic_from_stokes(MONO, 10, 10, 12, |_, _, _| s).expect("frame");
    for ((dx, dy), expect_deg) in [
        ((1, 0), 135.0 - phi_deg),
        ((0, 1), 45.0 - phi_deg),
        ((1, 1), phi_deg + 90.0),
    ] {
        let data: Vec<u16> = (0..8u32)
            .flat_map(|y| (0..8u32).map(move |x| (x + dx, y + dy)))
            .map(|(x, y)| full.get(x, y).unwrap_or(0))
            .collect();
        let shifted = RawFrame::new(8, 8, 12, MONO, data).expect("frame");
        let img = process(&shifted, &PolarConfig::default()).expect("process");
        let band = &img.bands[0];
        assert!(
            band.residual.data().iter().all(|r| r.abs() < 1e-3),
            "residual blind"
        );
        let aolp = f64::from(band.aolp_rad.data()[0]);
        let want = expect_deg.to_radians().rem_euclid(PI);
        assert!(
            axial_distance(aolp, want) < 1e-3,
            "shift ({dx},{dy}): {aolp}"
        );
        assert!(axial_distance(aolp, phi) > 0.2, "a visible AoLP error");
    }
}

/// A frame over borrowed samples (a camera's or numpy's buffer) is checked like an owned one and
/// processes to the same bits, for both layouts and methods: the Python binding relies on it.
#[test]
fn a_borrowed_frame_processes_bit_identically_to_an_owned_one() {
    let mut rng = ChaCha8Rng::seed_from_u64(48);
    for layout in [MONO, COLOUR] {
        let (w, h) = (24u32, 16u32);
        // a few saturated samples so the mask paths run too
        let data: Vec<u16> = (0..w * h)
            .map(|_| {
                if rng.random_bool(0.02) {
                    4095
                } else {
                    rng.random_range(0..4096)
                }
            })
            .collect();
        let owned = RawFrame::new(w, h, 12, layout, data.clone()).expect("owned");
        let view = RawFrameView::new(w, h, 12, layout, &data[..]).expect("borrowed");
        assert_eq!(owned.view(), view);
        for method in [DemosaicMethod::Superpixel, DemosaicMethod::Bilinear] {
            let a = process(&owned, &config(method)).expect("owned");
            let b = process(&view, &config(method)).expect("borrowed");
            for (x, y) in a.bands.iter().zip(&b.bands) {
                let bits =
                    |p: &Plane<f32>| p.data().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&x.s0), bits(&y.s0));
                assert_eq!(bits(&x.s1), bits(&y.s1));
                assert_eq!(bits(&x.s2), bits(&y.s2));
                assert_eq!(bits(&x.aolp_rad), bits(&y.aolp_rad));
                assert_eq!(x.mask, y.mask);
            }
            assert_eq!(a.bands.len(), b.bands.len());
        }
    }
    // the same checks, the same errors
    let mut bad = vec![0u16; 8];
    bad[5] = 4096;
    assert_eq!(
        RawFrameView::new(4, 2, 12, MONO, &bad[..]).unwrap_err(),
        RawFrame::new(4, 2, 12, MONO, bad.clone()).unwrap_err()
    );
    assert!(RawFrameView::new(4, 2, 12, MONO, &bad[..7]).is_err());
}
