//! GigE Vision throughput of the aravis backend against aravis' in-process fake camera, on
//! loopback inside a private network namespace (re-executes itself under `unshare -rn`; never
//! touches a real interface), plus the cost of unpacking a full 2448×2048 frame to `u16`.
//!
//! `cargo bench -p ellipso-rig --features aravis --bench gige`
//!
//! Rows: pixel format × GVSP packet size × link (`lo` unshaped, and `lo` shaped to 1 Gbit/s with
//! `tc tbf` to model a GigE link). Prints frames per second and payload rate.

use std::process::Command;
use std::time::{Duration, Instant};

use ellipso_rig::camera::aravis::fake::{FakeGigeCamera, FakeGigeOptions, FillRequest};
use ellipso_rig::camera::aravis::format::{PFNC_MONO8, PFNC_MONO12, PFNC_MONO12_PACKED};
use ellipso_rig::camera::aravis::{AravisCamera, AravisOptions};
use ellipso_rig::camera::unpack::{RawEncoding, unpack_into};
use ellipso_rig::camera::{Camera, CameraSettings, FrameStatus};
use ellipso_session::time::HostClock;

const IN_NETNS: &str = "ELLIPSO_IN_NETNS";
const SHAPED: &str = "ELLIPSO_BENCH_SHAPED";
const WIDTH: u32 = 2448;
const HEIGHT: u32 = 2048;
const FRAMES: usize = 30;

fn reexec(shaped: bool) {
    let shell = if shaped {
        r#"ip link set lo up && tc qdisc add dev lo root tbf rate 1gbit burst 256kb latency 50ms && exec "$@""#
    } else {
        r#"ip link set lo up && exec "$@""#
    };
    let status = Command::new("unshare")
        .args(["-rn", "--", "sh", "-c", shell, "sh"])
        .arg(std::env::current_exe().expect("bench executable"))
        .args(std::env::args().skip(1))
        .env(IN_NETNS, "1")
        .env(SHAPED, if shaped { "1" } else { "0" })
        .status()
        .expect("spawn unshare");
    assert!(
        status.success(),
        "bench failed in the network namespace: {status}"
    );
}

fn fill(req: FillRequest<'_>) {
    // cheap content: the transport is what is measured
    let b = (req.block_id & 0x0f) as u8;
    req.data.fill(b);
}

fn grab_row(pixel_format: u32, name: &str, packet_size: u32, link: &str) {
    let _fake = FakeGigeCamera::serve_on_loopback(
        &FakeGigeOptions {
            pixel_format,
            ..FakeGigeOptions::default()
        },
        Some(Box::new(fill)),
    )
    .expect("fake camera");
    let options = AravisOptions {
        region: Some((0, 0, WIDTH, HEIGHT)),
        packet_size_bytes: Some(packet_size),
        frame_rate_hz: Some(200.0),
        datasheet_fps: 200.0,
        pool_span_s: 0.1,
        ..AravisOptions::default()
    };
    let mut camera = AravisCamera::open("127.0.0.1", options, HostClock::new()).expect("open");
    let bits = match pixel_format {
        PFNC_MONO8 => 8,
        _ => 12,
    };
    camera
        .configure(&CameraSettings {
            exposure_us: 1_000,
            gain_db: 0.0,
            bit_depth: bits,
            external_trigger: false,
        })
        .expect("configure");
    camera.start().expect("start");
    // let the stream settle, then time FRAMES frames
    let _ = camera.next_frame(Duration::from_secs(3));
    let t0 = Instant::now();
    let mut complete = 0;
    let mut got = 0;
    while got < FRAMES && t0.elapsed() < Duration::from_secs(30) {
        if let Ok(Some(f)) = camera.next_frame(Duration::from_secs(3)) {
            got += 1;
            complete += usize::from(f.meta.status == FrameStatus::Complete);
        }
    }
    let secs = t0.elapsed().as_secs_f64();
    camera.stop().expect("stop");
    let payload_mb =
        f64::from(WIDTH * HEIGHT) * f64::from(if name == "Mono12" { 16 } else { bits }) / 8.0 / 1e6;
    let fps = got as f64 / secs;
    println!(
        "| {name:<12} | {packet_size:>5} | {link:<14} | {got:>3} ({complete} complete) | {fps:>6.1} | {:>6.0} |",
        fps * payload_mb
    );
}

fn unpack_rows() {
    let n = (WIDTH * HEIGHT) as usize;
    let mut out = Vec::with_capacity(n);
    for enc in [
        RawEncoding::Mono8,
        RawEncoding::Mono12,
        RawEncoding::Mono12Packed,
        RawEncoding::Mono12p,
    ] {
        let bytes: Vec<u8> = (0..enc.bytes_for(n)).map(|i| (i * 7) as u8).collect();
        let reps = 20;
        let t0 = Instant::now();
        for _ in 0..reps {
            unpack_into(enc, &bytes, WIDTH, HEIGHT, &mut out).expect("unpack");
            std::hint::black_box(&out);
        }
        let ms = t0.elapsed().as_secs_f64() * 1e3 / f64::from(reps);
        println!("| {:<12} | {ms:>8.2} |", enc.name());
    }
}

fn main() {
    if std::env::var_os(IN_NETNS).is_none() {
        println!("unpack {WIDTH}×{HEIGHT} to u16 (this host):\n");
        println!("| encoding     | ms/frame |\n|---|---|");
        unpack_rows();
        println!("\nfake GigE camera → AravisCamera, {WIDTH}×{HEIGHT}, {FRAMES} frames per row:\n");
        println!(
            "| format       | packet B | link         | frames | fps | MB/s |\n|---|---|---|---|---|---|"
        );
        reexec(false);
        reexec(true);
        return;
    }
    let link = if std::env::var(SHAPED).as_deref() == Ok("1") {
        "lo, tbf 1 Gbit/s"
    } else {
        "lo"
    };
    for (pf, name) in [
        (PFNC_MONO8, "Mono8"),
        (PFNC_MONO12_PACKED, "Mono12Packed"),
        (PFNC_MONO12, "Mono12"),
    ] {
        for packet in [1400, 8000] {
            grab_row(pf, name, packet, link);
        }
    }
}
