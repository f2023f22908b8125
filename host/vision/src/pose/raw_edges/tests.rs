use super::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// A raw mosaic of one tag36h11-like square: side `side_px`, centre `centre`, rotated by
/// `angle`; black border cell and random data cells inside, white paper outside; per-phase
/// gains, a black level, 8×8 supersampling per pixel and Gaussian noise. Returns the image and
/// the true corners (in the order the sides are walked).
#[expect(
    clippy::too_many_arguments,
    reason = "a test scene: image size, tile, pose of the square, noise and seed"
)]
fn render(
    width: usize,
    height: usize,
    tile: usize,
    centre: [f64; 2],
    side_px: f64,
    angle: f64,
    noise_dn: f64,
    seed: u64,
) -> (Vec<u16>, [[f64; 2]; 4]) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let gains: Vec<f64> = (0..tile * tile)
        .map(|_| rng.random_range(0.4..1.0))
        .collect();
    let bits: Vec<bool> = (0..36).map(|_| rng.random_bool(0.5)).collect();
    let (c, s) = (angle.cos(), angle.sin());
    let to_local = |x: f64, y: f64| {
        let (dx, dy) = (x - centre[0], y - centre[1]);
        (c * dx + s * dy, -s * dx + c * dy)
    };
    let cell = side_px / 8.0;
    let reflectance = |x: f64, y: f64| -> f64 {
        let (u, v) = to_local(x, y);
        let h = side_px / 2.0;
        if u.abs() > h || v.abs() > h {
            return 0.9;
        }
        let (i, j) = (
            ((u + h) / cell).floor() as i64,
            ((v + h) / cell).floor() as i64,
        );
        if i <= 0 || j <= 0 || i >= 7 || j >= 7 {
            return 0.04;
        }
        if bits[((i - 1) * 6 + (j - 1)) as usize] {
            0.9
        } else {
            0.04
        }
    };
    let noise = Normal::new(0.0, noise_dn).unwrap();
    let mut data = vec![0u16; width * height];
    for y in 0..height {
        for x in 0..width {
            let mut acc = 0.0;
            for sy in 0..8 {
                for sx in 0..8 {
                    let px = x as f64 - 0.5 + (sx as f64 + 0.5) / 8.0;
                    let py = y as f64 - 0.5 + (sy as f64 + 0.5) / 8.0;
                    acc += reflectance(px, py);
                }
            }
            let g = gains[(y % tile) * tile + x % tile];
            let v = 64.0 + 3500.0 * g * acc / 64.0 + noise.sample(&mut rng);
            data[y * width + x] = v.clamp(0.0, 4095.0) as u16;
        }
    }
    let h = side_px / 2.0;
    let corners = [[-h, -h], [h, -h], [h, h], [-h, h]]
        .map(|[u, v]| [centre[0] + c * u - s * v, centre[1] + s * u + c * v]);
    (data, corners)
}

fn worst(a: &[[f64; 2]; 4], b: &[[f64; 2]; 4]) -> f64 {
    (0..4)
        .map(|k| (a[k][0] - b[k][0]).hypot(a[k][1] - b[k][1]))
        .fold(0.0, f64::max)
}

#[test]
fn corners_quantised_to_the_colour_tile_are_refined_to_a_twentieth_of_a_pixel() {
    let (w, h, tile) = (160, 160, 4);
    for seed in 0..4u64 {
        let angle = 0.2 + 0.35 * seed as f64;
        let (data, truth) = render(w, h, tile, [80.3, 79.6], 72.0, angle, 6.0, seed);
        let img = RawImage {
            data: &data,
            width: w,
            height: h,
            tile,
        };
        // The detection on the 4×4 superpixel image is within about half a tile.
        let mut rng = ChaCha8Rng::seed_from_u64(100 + seed);
        let detected = truth.map(|[x, y]| {
            [
                x + rng.random_range(-2.0..2.0),
                y + rng.random_range(-2.0..2.0),
            ]
        });
        let refined = refine_corners(&img, &detected, TagFamily::Tag36h11)
            .unwrap_or_else(|| panic!("seed {seed}: the refinement failed"));
        let (before, after) = (worst(&detected, &truth), worst(&refined, &truth));
        // Measured: 2.0–2.5 px → 0.005–0.010 px.
        assert!(after < 0.05, "seed {seed}: {before:.3} px → {after:.3} px");
    }
}

#[test]
fn a_tag_too_small_for_its_tile_or_a_flat_image_keeps_its_corners() {
    let (w, h, tile) = (64, 64, 4);
    // 20 px across: the border cell is 2.5 px, less than half a tile plus a pixel of reach.
    let (data, truth) = render(w, h, tile, [32.0, 32.0], 20.0, 0.3, 2.0, 7);
    let img = RawImage {
        data: &data,
        width: w,
        height: h,
        tile,
    };
    assert!(refine_corners(&img, &truth, TagFamily::Tag36h11).is_none());
    // No edge at all: nothing to fit, the detected corners stay.
    let flat = vec![1000u16; 160 * 160];
    let img = RawImage {
        data: &flat,
        width: 160,
        height: 160,
        tile,
    };
    let square = [[40.0, 40.0], [120.0, 40.0], [120.0, 120.0], [40.0, 120.0]];
    assert!(refine_corners(&img, &square, TagFamily::Tag36h11).is_none());
}

#[test]
fn the_step_is_the_logistic_to_the_bit_and_saturates_without_libm() {
    let logistic = |x: f64| 1.0 / (1.0 + (-x).exp());
    let mut x = -5000.0;
    while x <= 5000.0 {
        assert_eq!(step(x).to_bits(), logistic(x).to_bits(), "x = {x}");
        x += 0.37;
    }
    for x in [
        -746.5, -745.2, -709.9, -709.7, 708.0, 745.2, 746.5, 1e300, -1e300,
    ] {
        assert_eq!(step(x).to_bits(), logistic(x).to_bits(), "x = {x}");
    }
    assert_eq!(step(-1e6), 0.0);
    assert_eq!(step(1e6), 1.0);
    assert!(step(f64::NAN).is_nan());
}
