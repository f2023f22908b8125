//! Render cost per 5 MP (2448×2048) raw frame: the S0-only scene (scalar BRDF, no polarisation,
//! no sensor effects) against the full scene (`multi_material.toml`: colour mosaic, Stokes path,
//! every lobe, shadows, vignetting, extinction, motion blur, noise, saturation, quantisation),
//! both at the default 2×2 supersampling, in one run, with their ratio.
//!
//! `cargo bench -p ellipso-sim --bench render` (release). `ELLIPSO_BENCH_REPEATS` (default 2)
//! sets the repeats per scene; the best time is reported. Threads: rayon's default pool
//! (`RAYON_NUM_THREADS` to pin).

use ellipso_sim::effects::Stage;
use ellipso_sim::render::{RenderOptions, Renderer};
use ellipso_sim::scene::Scene;
use std::path::Path;
use std::time::Instant;

struct Row {
    name: &'static str,
    seconds: f64,
    rays: u64,
    stages: usize,
}

fn bench(name: &'static str, file: &str, repeats: usize) -> Row {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(file);
    let scene = Scene::load(&path).expect("shipped scene loads");
    let options = RenderOptions {
        resolution_px: Some([2448, 2048]),
        ..RenderOptions::default()
    };
    let renderer = Renderer::new(&scene, options).expect("renderer builds");
    let mut best = f64::INFINITY;
    let mut rays = 0;
    for _ in 0..repeats {
        let t = Instant::now();
        let f = renderer.render_frame(0).expect("frame renders");
        best = best.min(t.elapsed().as_secs_f64());
        // Flash falloff runs once per shaded, unshadowed ray sample.
        rays = f.counts.get(Stage::FlashFalloff);
        std::hint::black_box(&f.dn);
    }
    Row {
        name,
        seconds: best,
        rays,
        stages: renderer.plan().stages.len(),
    }
}

fn main() {
    let repeats = std::env::var("ELLIPSO_BENCH_REPEATS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2usize)
        .max(1);
    let threads = rayon::current_num_threads();
    println!(
        "render: one 2448×2048 raw frame, 2×2 supersampling, {threads} threads, best of {repeats}"
    );
    let s0 = bench("s0_only (scalar)", "s0_only.toml", repeats);
    let full = bench("multi_material (full)", "multi_material.toml", repeats);
    println!(
        "{:<24} {:>8} {:>10} {:>16} {:>14}",
        "scene", "stages", "s/frame", "lit samples", "ns/lit sample"
    );
    for r in [&s0, &full] {
        println!(
            "{:<24} {:>8} {:>10.3} {:>16} {:>14.1}",
            r.name,
            r.stages,
            r.seconds,
            r.rays,
            r.seconds * 1e9 / r.rays.max(1) as f64
        );
    }
    println!(
        "full / s0_only time per frame: {:.1}×",
        full.seconds / s0.seconds
    );
}
