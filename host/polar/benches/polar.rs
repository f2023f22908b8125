//! Throughput of the polarisation pipeline on a full IMX250MZR frame, single core.
//!
//! Measures, in one run on one core (no rayon anywhere in the measured path):
//! - `memcpy`: copying the raw 2448×2048 u16 frame into a preallocated buffer (the floor);
//! - `superpixel`: demosaic + s0/s1/s2 + DoLP + AoLP + residual + I^d/I^s/I^α + mask, into reused
//!   buffers (`process_into`), the streaming path;
//! - `superpixel colour`: the same frame read as an IMX250MYR (R, G, B bands at quarter size);
//! - `bilinear`: the same at full resolution (not a line-rate path; measured once per round).
//!
//! The paths are measured in interleaved rounds and each is reported as the median over rounds,
//! so a burst of load from other processes hits all of them alike; the ratio to memcpy is the
//! figure to compare across machines. Target: superpixel ≥ 75 frames/s (USB3 line rate of the
//! IMX250MZR at 5 MP). Run: `cargo bench -p ellipso-polar --bench polar`.

use std::hint::black_box;
use std::time::{Duration, Instant};

use ellipso_model::mosaic::SensorLayout;
use ellipso_polar::synthetic::mosaic_from_stokes;
use ellipso_polar::{DemosaicMethod, PolarConfig, PolarImage, RawFrame, process_into};

const WIDTH: u32 = 2448;
const HEIGHT: u32 = 2048;
const LINE_RATE_FPS: f64 = 75.0;
const ROUNDS: usize = 5;

/// Nanoseconds this thread has spent on a CPU (Linux `/proc/thread-self/schedstat`), if known.
/// On a shared machine wall-clock rates drop when other processes take the core; frames per
/// CPU-second do not.
fn thread_cpu_ns() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    text.split_whitespace().next()?.parse().ok()
}

/// A measured rate: frames per wall-clock second and per CPU-second (when known).
#[derive(Clone, Copy)]
struct Rate {
    wall_fps: f64,
    cpu_fps: Option<f64>,
}

/// Runs `f` for at least `budget` and `min_iters` calls.
fn measure(budget: Duration, min_iters: u32, mut f: impl FnMut()) -> Rate {
    let cpu_start = thread_cpu_ns();
    let start = Instant::now();
    let mut iters = 0u32;
    while iters < min_iters || start.elapsed() < budget {
        f();
        iters += 1;
    }
    let wall_s = start.elapsed().as_secs_f64();
    let cpu_s = cpu_start
        .zip(thread_cpu_ns())
        .map(|(a, b)| b.saturating_sub(a) as f64 * 1e-9)
        .filter(|s| *s > 0.0);
    Rate {
        wall_fps: f64::from(iters) / wall_s,
        cpu_fps: cpu_s.map(|s| f64::from(iters) / s),
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    // A textured 12-bit scene: smooth s0, varying DoLP and AoLP, saturated corner.
    let frame = mosaic_from_stokes(SensorLayout::MonoPolar, WIDTH, HEIGHT, 12, |x, y, _| {
        let (xf, yf) = (
            f64::from(x) / f64::from(WIDTH),
            f64::from(y) / f64::from(HEIGHT),
        );
        let s0 = 600.0 + 9000.0 * xf * yf;
        let p = 0.05 + 0.9 * yf;
        let phi = 3.0 * xf + yf;
        [s0, s0 * p * (2.0 * phi).cos(), s0 * p * (2.0 * phi).sin()]
    })
    .expect("valid synthetic frame");

    // the same scene on the colour sensor (IMX250MYR), for the colour superpixel path
    let colour_frame = RawFrame::new(
        WIDTH,
        HEIGHT,
        12,
        SensorLayout::ColourPolar,
        frame.data_dn().to_vec(),
    )
    .expect("valid colour frame");

    let src = frame.data_dn();
    let mut dst = vec![0u16; src.len()];
    let mut out = PolarImage::empty();
    let superpixel = PolarConfig::default();
    let bilinear = PolarConfig {
        demosaic: DemosaicMethod::Bilinear,
        ..PolarConfig::default()
    };
    // warm-up: page in every buffer once
    dst.copy_from_slice(src);
    process_into(&frame, &superpixel, &mut out).expect("process");

    let (mut copy, mut sp, mut spc, mut bl) = (vec![], vec![], vec![], vec![]);
    for _ in 0..ROUNDS {
        copy.push(measure(Duration::from_millis(300), 10, || {
            dst.copy_from_slice(black_box(src));
            black_box(&mut dst);
        }));
        sp.push(measure(Duration::from_millis(600), 10, || {
            process_into(black_box(&frame), &superpixel, &mut out).expect("process");
            black_box(&out);
        }));
        spc.push(measure(Duration::from_millis(300), 5, || {
            process_into(black_box(&colour_frame), &superpixel, &mut out).expect("process");
            black_box(&out);
        }));
    }
    for _ in 0..3 {
        bl.push(measure(Duration::ZERO, 1, || {
            process_into(black_box(&frame), &bilinear, &mut out).expect("process");
            black_box(&out);
        }));
    }
    let ratio = median(
        sp.iter()
            .zip(&copy)
            .map(|(s, c)| s.wall_fps / c.wall_fps)
            .collect(),
    );
    let summarise = |rates: &[Rate]| {
        let wall = median(rates.iter().map(|r| r.wall_fps).collect());
        let cpu: Option<Vec<f64>> = rates.iter().map(|r| r.cpu_fps).collect();
        (wall, cpu.map(median))
    };
    let (copy, sp, spc, bl) = (
        summarise(&copy),
        summarise(&sp),
        summarise(&spc),
        summarise(&bl),
    );

    let mpix = f64::from(WIDTH) * f64::from(HEIGHT) / 1e6;
    println!(
        "polar pipeline, {WIDTH}x{HEIGHT} 12-bit mono frame ({mpix:.2} MP), single core, median of {ROUNDS} rounds"
    );
    println!(
        "{:<46} {:>10} {:>10} {:>10} {:>12}",
        "path", "frames/s", "ms/frame", "vs memcpy", "frames/CPU-s"
    );
    for (name, (wall, cpu)) in [
        ("memcpy of the raw frame (floor)", copy),
        ("superpixel Stokes+DoLP+AoLP+channels+mask", sp),
        ("  same, colour sensor (3 bands at W/4 x H/4)", spc),
        ("bilinear Stokes+DoLP+AoLP+channels+mask", bl),
    ] {
        let cpu = cpu.map_or("n/a".to_string(), |c| format!("{c:.1}"));
        println!(
            "{name:<46} {wall:>10.1} {:>10.2} {:>10.4} {cpu:>12}",
            1e3 / wall,
            wall / copy.0
        );
    }
    for (name, fps) in [("superpixel mono", sp.0), ("superpixel colour", spc.0)] {
        let verdict = if fps >= LINE_RATE_FPS {
            "meets"
        } else {
            "MISSES"
        };
        println!(
            "{name}: {fps:.1} frames/s {verdict} the {LINE_RATE_FPS} frames/s USB3 line-rate target"
        );
    }
    println!("superpixel mono: median per-round ratio to memcpy {ratio:.4}");
}
