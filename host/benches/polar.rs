//! Throughput of the polarisation pipeline on a full IMX250MZR frame, single core.
//!
//! Measures, in one run on one core (no rayon anywhere in the measured path):
//! - `memcpy`: copying the raw 2448×2048 u16 frame into a preallocated buffer (the floor);
//! - `superpixel`: demosaic + s0/s1/s2 + DoLP + AoLP + residual + I^d/I^s/I^α + mask, into reused
//!   buffers (`process_into`), the streaming path;
//! - `bilinear`: the same at full resolution (fewer iterations; not a line-rate path).
//!
//! Prints frames/s and the ratio to memcpy. Target: superpixel ≥ 75 frames/s (USB3 line rate of
//! the IMX250MZR at 5 MP). Run: `cargo bench -p ellipso-host --bench polar`.

use std::hint::black_box;
use std::time::{Duration, Instant};

use ellipso_host::polar::synthetic::mosaic_from_stokes;
use ellipso_host::polar::{DemosaicMethod, PolarConfig, PolarImage, process_into};
use ellipso_sim::mosaic::SensorLayout;

const WIDTH: u32 = 2448;
const HEIGHT: u32 = 2048;
const LINE_RATE_FPS: f64 = 75.0;

/// Runs `f` repeatedly for at least `budget` (after one warm-up call); returns frames/s.
fn frames_per_s(budget: Duration, min_iters: u32, mut f: impl FnMut()) -> (f64, u32) {
    f();
    let start = Instant::now();
    let mut iters = 0u32;
    while iters < min_iters || start.elapsed() < budget {
        f();
        iters += 1;
    }
    (f64::from(iters) / start.elapsed().as_secs_f64(), iters)
}

fn main() {
    // A textured 12-bit scene: smooth s0, varying DoLP and AoLP, a few saturated highlights.
    let frame = mosaic_from_stokes(SensorLayout::MonoPolar, WIDTH, HEIGHT, 12, |x, y, _| {
        let (xf, yf) = (
            f64::from(x) / f64::from(WIDTH),
            f64::from(y) / f64::from(HEIGHT),
        );
        let s0 = 600.0 + 5000.0 * xf * yf;
        let p = 0.05 + 0.9 * yf;
        let phi = 3.0 * xf + yf;
        [s0, s0 * p * (2.0 * phi).cos(), s0 * p * (2.0 * phi).sin()]
    })
    .expect("valid synthetic frame");

    let src = frame.data_dn();
    let mut dst = vec![0u16; src.len()];
    let budget = Duration::from_secs(2);
    let (copy_fps, copy_n) = frames_per_s(budget, 20, || {
        dst.copy_from_slice(black_box(src));
        black_box(&mut dst);
    });

    let mut out = PolarImage::empty();
    let superpixel = PolarConfig::default();
    let (sp_fps, sp_n) = frames_per_s(budget, 20, || {
        process_into(black_box(&frame), &superpixel, &mut out).expect("process");
        black_box(&out);
    });

    let bilinear = PolarConfig {
        demosaic: DemosaicMethod::Bilinear,
        ..PolarConfig::default()
    };
    let (bl_fps, bl_n) = frames_per_s(Duration::from_secs(1), 3, || {
        process_into(black_box(&frame), &bilinear, &mut out).expect("process");
        black_box(&out);
    });

    let mpix = f64::from(WIDTH) * f64::from(HEIGHT) / 1e6;
    println!("polar pipeline, {WIDTH}x{HEIGHT} 12-bit mono frame ({mpix:.2} MP), single core");
    println!(
        "{:<46} {:>8} {:>10} {:>10}",
        "path", "frames", "frames/s", "vs memcpy"
    );
    for (name, n, fps) in [
        ("memcpy of the raw frame (floor)", copy_n, copy_fps),
        ("superpixel Stokes+DoLP+AoLP+channels+mask", sp_n, sp_fps),
        ("bilinear Stokes+DoLP+AoLP+channels+mask", bl_n, bl_fps),
    ] {
        println!("{name:<46} {n:>8} {fps:>10.1} {:>10.3}", fps / copy_fps);
    }
    let verdict = if sp_fps >= LINE_RATE_FPS {
        "meets"
    } else {
        "MISSES"
    };
    println!(
        "superpixel {sp_fps:.1} frames/s {verdict} the {LINE_RATE_FPS} frames/s USB3 line-rate target \
         ({:.2} ms/frame)",
        1e3 / sp_fps
    );
}
