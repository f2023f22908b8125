//! Helpers of the `gige` tests: the network-namespace re-execution (Pattern A), the block-id
//! scene pattern written by the fake camera and checked on every frame, and the rig that serves
//! and opens the fake camera on 127.0.0.1.

use std::process::Command;
use std::time::Duration;

use ellipso_rig::camera::aravis::fake::{FakeGigeCamera, FakeGigeOptions, FillRequest};
use ellipso_rig::camera::aravis::format::{PFNC_MONO12, PFNC_MONO12_PACKED};
use ellipso_rig::camera::aravis::{AravisCamera, AravisOptions};
use ellipso_rig::camera::{Camera, CameraSettings, Frame, FrameStatus};
use ellipso_session::time::HostClock;

pub const IN_NETNS: &str = "ELLIPSO_IN_NETNS";
pub const CHILD: &str = "ELLIPSO_GIGE_CHILD";

/// Outer run: re-executes this test binary, filtered to `name`, inside a new network namespace
/// whose only interface is `lo`, and returns true. Inner run: returns false and the body runs.
pub fn reexec_in_netns(name: &str) -> bool {
    if std::env::var_os(IN_NETNS).is_some() {
        return false;
    }
    let exe = std::env::current_exe().expect("path of this test executable");
    let status = Command::new("unshare")
        .args([
            "-rn",
            "--",
            "sh",
            "-c",
            r#"ip link set lo up && exec "$@""#,
            "sh",
        ])
        .arg(exe)
        .args([name, "--exact", "--nocapture", "--test-threads=1"])
        .env(IN_NETNS, "1")
        .status()
        .unwrap_or_else(|e| panic!("cannot spawn unshare for {name}: {e} (util-linux needed)"));
    assert!(
        status.success(),
        "{name} failed inside the private network namespace (or unshare -rn is not permitted): \
         {status}"
    );
    true
}

/// Pixel `i` of the frame with GVSP block id `block`: pixels 0 and 1 carry the id's low and high
/// 12 bits, the rest a ramp offset by the id, so two different ids never share a frame.
pub fn pattern(block: u64, i: usize) -> u16 {
    match i {
        0 => (block & 0xfff) as u16,
        1 => ((block >> 12) & 0xfff) as u16,
        _ => ((i as u64 * 31 + block * 977) % 4096) as u16,
    }
}

/// Writes the pattern in the request's format (Mono12 or GigE Mono12Packed).
pub fn fill(req: FillRequest<'_>) {
    let n = req.width as usize * req.height as usize;
    match req.pixel_format {
        PFNC_MONO12 => {
            for (i, px) in req.data.chunks_exact_mut(2).take(n).enumerate() {
                px.copy_from_slice(&pattern(req.block_id, i).to_le_bytes());
            }
        }
        PFNC_MONO12_PACKED => {
            for (k, b) in req.data.chunks_exact_mut(3).take(n / 2).enumerate() {
                let p0 = pattern(req.block_id, 2 * k);
                let p1 = pattern(req.block_id, 2 * k + 1);
                b[0] = (p0 >> 4) as u8;
                b[1] = ((p1 & 0xf) << 4 | (p0 & 0xf)) as u8;
                b[2] = (p1 >> 4) as u8;
            }
        }
        other => panic!("fill: unexpected pixel format {other:#x}"),
    }
}

/// The block id a frame's pixels carry, if every pixel matches that id's pattern.
pub fn content_block(frame: &Frame) -> Option<u64> {
    let px = &frame.pixels;
    let block = u64::from(*px.first()?) | u64::from(*px.get(1)?) << 12;
    px.iter()
        .enumerate()
        .all(|(i, &v)| v == pattern(block, i))
        .then_some(block)
}

/// Forward distance between two block ids on the 1..=65535 cycle.
pub fn block_distance(from: u64, to: u64) -> u64 {
    (to + 65_535 - from) % 65_535
}

pub struct Rig {
    // the camera is declared first so it is dropped (stream stopped) before the server
    pub camera: AravisCamera,
    pub fake: FakeGigeCamera,
}

pub fn rig(width: u32, height: u32, pixel_format: u32, packet_size: u32, fps: f64) -> Rig {
    let fake = FakeGigeCamera::serve_on_loopback(
        &FakeGigeOptions {
            pixel_format,
            ..FakeGigeOptions::default()
        },
        Some(Box::new(fill)),
    )
    .expect("fake camera on 127.0.0.1");
    let options = AravisOptions {
        region: Some((0, 0, width, height)),
        packet_size_bytes: Some(packet_size),
        frame_rate_hz: Some(fps),
        datasheet_fps: fps,
        pool_span_s: 0.5,
        ..AravisOptions::default()
    };
    let mut camera =
        AravisCamera::open("127.0.0.1", options, HostClock::new()).expect("open by IP");
    camera
        .configure(&CameraSettings {
            exposure_us: 1_000,
            gain_db: 0.0,
            bit_depth: 12,
            external_trigger: false,
        })
        .expect("configure 12-bit free-running");
    Rig { camera, fake }
}

pub fn grab(camera: &mut AravisCamera, n: usize) -> Vec<Frame> {
    camera.start().expect("start");
    let t0 = std::time::Instant::now();
    let mut frames = Vec::with_capacity(n);
    while frames.len() < n {
        if let Some(f) = camera.next_frame(Duration::from_secs(3)).expect("stream") {
            frames.push(f);
        } else {
            assert!(
                t0.elapsed() < Duration::from_secs(60),
                "only {} of {n} frames: {:?}",
                frames.len(),
                camera.counters()
            );
        }
    }
    let secs = t0.elapsed().as_secs_f64();
    camera.stop().expect("stop");
    println!(
        "grabbed {n} frames in {secs:.2} s ({:.0} fps), counters {:?}",
        n as f64 / secs,
        camera.counters()
    );
    frames
}

/// All frames complete, ids consecutive, content matching ids.
pub fn assert_clean(frames: &[Frame]) {
    let first_block = content_block(&frames[0]).expect("first frame content");
    for (k, f) in frames.iter().enumerate() {
        assert_eq!(f.meta.status, FrameStatus::Complete, "frame {k}");
        assert_eq!(
            f.meta.frame_id,
            frames[0].meta.frame_id + k as u64,
            "ids consecutive"
        );
        let block =
            content_block(f).unwrap_or_else(|| panic!("frame {k}: content is not a pattern"));
        assert_eq!(
            block_distance(first_block, block),
            f.meta.frame_id - frames[0].meta.frame_id,
            "frame {k}: content belongs to another id"
        );
    }
}
