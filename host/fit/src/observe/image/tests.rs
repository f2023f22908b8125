//! Tests of the analyser images: crops, the kernels' footprints, the narrower kernel.

use super::*;
use ellipso_polar::PolarConfig;
use ellipso_polar::demosaic::{DemosaicMethod, demosaic};

/// A colour-polarisation frame of seeded noise (every superpixel differs).
fn image(kernel: SampleKernel) -> DnImage {
    let (w, h) = (96u32, 64u32);
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let px: Vec<u16> = (0..w * h)
        .map(|_| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            ((state >> 33) % 4000) as u16 + 50
        })
        .collect();
    let raw = RawFrame::new(w, h, 12, SensorLayout::ColourPolar, px).unwrap();
    let polar = PolarConfig {
        demosaic: DemosaicMethod::Superpixel,
        ..PolarConfig::default()
    };
    let levels = polar.levels(&raw).unwrap();
    let analysers = demosaic(&raw, &levels, DemosaicMethod::Superpixel);
    DnImage::new(&raw, &analysers, &levels, SamplePoint::Lattice, kernel)
}

fn same(a: ([[f32; 4]; 3], [[f32; 4]; 3]), b: ([[f32; 4]; 3], [[f32; 4]; 3])) -> bool {
    let bits = |v: ([[f32; 4]; 3], [[f32; 4]; 3])| {
        v.0.iter()
            .chain(v.1.iter())
            .flatten()
            .map(|x| x.to_bits())
            .collect::<Vec<_>>()
    };
    bits(a) == bits(b)
}

#[test]
fn a_crop_samples_its_rectangle_bit_identically_and_nothing_else() {
    for kernel in [SampleKernel::Bilinear, SampleKernel::CatmullRom] {
        let whole = image(kernel);
        let rect = PixelRect {
            min: [30.3, 20.7],
            max: [61.9, 41.2],
        };
        let crop = whole.crop(&rect);
        assert!(crop.bytes() < whole.bytes() / 2, "{kernel:?}: not cropped");
        assert!(crop.covers(&rect) && whole.covers(&rect));
        // Every point of the rectangle, its corners included, as the whole frame has it.
        for i in 0..=20 {
            for j in 0..=20 {
                let p = [
                    rect.min[0] + (rect.max[0] - rect.min[0]) * f64::from(i) / 20.0,
                    rect.min[1] + (rect.max[1] - rect.min[1]) * f64::from(j) / 20.0,
                ];
                assert!(same(crop.sample(p), whole.sample(p)), "{kernel:?} at {p:?}");
            }
        }
        // Far outside: NaN, never a neighbour's value.
        let (values, peaks) = crop.sample([2.0, 2.0]);
        assert!(values[0].iter().chain(&peaks[0]).all(|v| v.is_nan()));
        assert!(!crop.covers(&rect.grown(12.0)));
    }
}

#[test]
fn a_crop_at_the_frame_border_clamps_as_the_whole_frame_does() {
    let whole = image(SampleKernel::CatmullRom);
    // Reaches past the top-left corner: the taps clamp to the edge superpixels.
    let rect = PixelRect {
        min: [-3.0, -2.0],
        max: [10.0, 9.0],
    };
    let crop = whole.crop(&rect);
    assert!(crop.covers(&rect));
    for p in [[-3.0, -2.0], [0.0, 0.0], [0.4, 8.9], [10.0, 9.0]] {
        assert!(same(crop.sample(p), whole.sample(p)), "at {p:?}");
    }
    // A crop of a crop keeps what it holds.
    let inner = crop.crop(&PixelRect {
        min: [2.0, 2.0],
        max: [4.0, 4.0],
    });
    assert!(same(inner.sample([3.0, 3.0]), whole.sample([3.0, 3.0])));
}

#[test]
fn a_cubic_footprint_is_a_cross_and_a_lattice_point_reads_one_tile() {
    let min_weight = 0.014;
    let cubic = image(SampleKernel::CatmullRom);
    // Between lattice samples: the corner taps (≤ 0.4 %) do not count, so the square's
    // corners are cut and the farthest probe is nearer than the square's corner.
    let p = [41.3, 29.7];
    let f = cubic.footprint(p, min_weight);
    let rect = f.rect().unwrap();
    let corner = (rect.max[0] - rect.min[0]).hypot(rect.max[1] - rect.min[1]) / 2.0;
    assert!(f.points().len() == 8, "{:?}", f.points());
    assert!(
        f.reach_px(p) < 0.95 * corner,
        "{} vs {corner}",
        f.reach_px(p)
    );
    // Every tap's block lies within the kernel's whole reach.
    let r = cubic.footprint_radius_px;
    for q in f.points() {
        assert!((q[0] - p[0]).abs() <= r + 1e-9 && (q[1] - p[1]).abs() <= r + 1e-9);
    }
    // A bilinear value reaches less far than the cubic one.
    let linear = image(SampleKernel::Bilinear);
    assert!(linear.footprint(p, min_weight).reach_px(p) < f.reach_px(p));
}

#[test]
fn the_narrow_value_is_the_bilinear_one_and_reaches_less_far() {
    let min_weight = 0.014;
    let cubic = image(SampleKernel::CatmullRom);
    let linear = image(SampleKernel::Bilinear);
    for p in [[41.3, 29.7], [40.0, 30.0], [50.6, 21.2]] {
        let (footprint, value) = cubic.narrow(p, min_weight).expect("a cubic image has one");
        // Bit for bit what an image read bilinearly gives, footprint and value.
        assert!(same(value, linear.sample(p)), "at {p:?}");
        assert_eq!(footprint, linear.footprint(p, min_weight), "at {p:?}");
        assert!(footprint.reach_px(p) < cubic.footprint(p, min_weight).reach_px(p));
    }
    // An image read bilinearly has nothing narrower.
    assert!(linear.narrow([41.3, 29.7], min_weight).is_none());
}
