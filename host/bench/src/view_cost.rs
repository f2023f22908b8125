//! `ellipso bench view [SCENE]`: what the live view costs a capture.
//!
//! Runs the same simulated capture (`ellipso capture --sim SCENE --no-track`, child processes of
//! this binary or of `--bin`) without and with `--view`, alternating which goes first in each
//! round. Each `--view` run has a page-like client: it reads the event stream and fetches the
//! three pictures after every update, as the page does. Per run it reads the session back and
//! reports the frames written, the frame rate (frames' host timestamps), the delivery latency
//! (a frame's arrival minus the trigger of the pulse with its number, mapped to host time by the
//! capture's clock fit: the simulator numbers frames and pulses alike from 0), pairs, wrong pairs
//! (frame id ≠ pulse number), pairing errors, the CPU seconds of the capture process, and the
//! load average before the run. Writes `view-bench.json` and prints a table; the figures to quote
//! are the ratios between the two modes of one run of the bench, on one machine.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use ellipso_run_error::{Context, RunError, Say};
use ellipso_run_error::{ensure, say};

/// The command's result.
type Result<T> = std::result::Result<T, RunError>;

use ellipso_session::events::SessionEvent;
use ellipso_session::time::DeviceTimeUs;

/// What `ellipso bench view` runs (its flags, parsed by the binary).
#[derive(Debug, Clone)]
pub struct ViewOptions {
    /// Scene file.
    pub scene: PathBuf,
    /// Photos per capture.
    pub photos: u32,
    /// Time between photos, ms (50: 20 fps).
    pub interval_ms: u32,
    /// Frame size.
    pub resolution: [u32; 2],
    /// Rounds (each: one capture without and one with the view).
    pub runs: usize,
    /// The `ellipso` binary that captures (default: this one), e.g. an older build to compare.
    pub bin: Option<PathBuf>,
    /// Keep the recorded sessions (under OUT/view-bench-sessions).
    pub keep_sessions: bool,
    /// Where to write view-bench.json.
    pub out: PathBuf,
    /// CPU seconds (user + system) of this process's waited-for children: the binary's
    /// `getrusage` (this crate has no unsafe code).
    pub children_cpu_s: fn() -> f64,
}

/// One capture's figures.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RunResult {
    /// Round.
    pub round: usize,
    /// With `--view` and a streaming client.
    pub view: bool,
    /// 1-minute load average before the run.
    pub load_before: f64,
    /// Frames written.
    pub frames: usize,
    /// Frames the camera flagged.
    pub flagged: usize,
    /// Frames per second between the first and the last frame.
    pub fps: f64,
    /// Delivery latency, ms: median, 95th percentile, largest.
    pub latency_ms: [f64; 3],
    /// Pairs recorded.
    pub paired: usize,
    /// Pairs whose pulse number is not the frame id.
    pub wrong_pairs: usize,
    /// Pairing errors recorded.
    pub pairing_errors: usize,
    /// CPU seconds (user + system) of the capture process.
    pub cpu_s: f64,
    /// Wall seconds of the capture process.
    pub wall_s: f64,
    /// Event-stream updates the client received.
    pub view_updates: usize,
    /// Pictures the client fetched.
    pub view_pictures: usize,
    /// Frames the view had posed itself when the stream ended.
    pub view_posed: u64,
}

/// Runs `ellipso bench view`.
pub fn run(args: ViewOptions, say: &dyn Say) -> Result<()> {
    let bin = match &args.bin {
        Some(b) => b.clone(),
        None => std::env::current_exe().context("locating this binary")?,
    };
    let report_file = ellipso_report::output::OutputFile::claim(
        &args.out.join("view-bench.json"),
        "bench-view",
        ellipso_report::output::FileFormat::JSON,
        &[&args.scene],
        None,
    )?;
    // the captures' sessions: a directory this bench owns, kept (swapped in whole) only with
    // --keep-sessions
    let claimed = ellipso_report::output::OutputDir::claim(
        &args.out.join("view-bench-sessions"),
        "bench-view",
        &[&args.scene],
    )?;
    let sessions = claimed.path().to_path_buf();
    let mut results = Vec::new();
    for round in 0..args.runs {
        // alternate the order so that a drift in the machine's load favours neither
        let order = if round % 2 == 0 {
            [false, true]
        } else {
            [true, false]
        };
        for view in order {
            let dir = sessions.join(format!("{round}-{}", if view { "view" } else { "plain" }));
            if dir.exists() {
                std::fs::remove_dir_all(&dir).with_context(|| dir.display().to_string())?;
            }
            let r = capture(&bin, &args, &dir, round, view)?;
            say!(
                say,
                "round {round} {:<13} load {:>5.2}  {} frames  {:.2} fps  latency p50 {:.1} / p95 {:.1} / max {:.1} ms  paired {} (wrong {})  pairing errors {}  cpu {:.2} s{}",
                if view { "with view" } else { "without view" },
                r.load_before,
                r.frames,
                r.fps,
                r.latency_ms[0],
                r.latency_ms[1],
                r.latency_ms[2],
                r.paired,
                r.wrong_pairs,
                r.pairing_errors,
                r.cpu_s,
                if view {
                    format!(
                        "  view: {} updates, {} pictures, {} posed live",
                        r.view_updates, r.view_pictures, r.view_posed
                    )
                } else {
                    String::new()
                }
            );
            if !args.keep_sessions {
                std::fs::remove_dir_all(&dir).with_context(|| dir.display().to_string())?;
            }
            results.push(r);
        }
    }
    if args.keep_sessions {
        claimed.commit()?;
    }
    let summary = summary(&results);
    say!(say, "{summary}");
    let report = serde_json::json!({
        "scene": args.scene.display().to_string(),
        "photos": args.photos,
        "interval_ms": args.interval_ms,
        "resolution": args.resolution,
        "cpus": std::thread::available_parallelism().map_or(0, |n| n.get()),
        "runs": results,
        "summary": summary,
    });
    report_file.write(serde_json::to_string_pretty(&report)?)?;
    say!(say, "wrote {}", report_file.shown().display());
    Ok(())
}

fn capture(
    bin: &Path,
    args: &ViewOptions,
    dir: &Path,
    round: usize,
    view: bool,
) -> Result<RunResult> {
    let load_before = load_average();
    let mut cmd = Command::new(bin);
    cmd.args(["capture", "--sim"])
        .arg(&args.scene)
        .args(["--photos", &args.photos.to_string()])
        .args([
            "--resolution",
            &format!("{}x{}", args.resolution[0], args.resolution[1]),
        ])
        .args(["--supersampling", "1", "--no-track"])
        .args(["--interval-ms", &args.interval_ms.to_string()])
        .arg("--out")
        .arg(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    if view {
        cmd.arg("--view");
    }
    let cpu_before = (args.children_cpu_s)();
    let started = Instant::now();
    let mut child = cmd
        .spawn()
        .with_context(|| format!("starting {}", bin.display()))?;
    let stderr = child.stderr.take().map(|mut e| {
        std::thread::spawn(move || {
            let mut s = String::new();
            let _ = e.read_to_string(&mut s);
            s
        })
    });
    let mut lines = BufReader::new(child.stdout.take().context("capture stdout")?).lines();
    let done = Arc::new(AtomicBool::new(false));
    let mut client = None;
    if view {
        for line in lines.by_ref() {
            let line = line?;
            if let Some(at) = line.find("open http://") {
                let url = line[at + "open http://".len()..].trim().to_string();
                let done = done.clone();
                client = Some(std::thread::spawn(move || page_client(&url, &done)));
                break;
            }
        }
    }
    for line in lines.map_while(std::result::Result::ok) {
        // the capture's last line before it closes the view: let go of the stream, as a page
        // closed at the end would (older builds waited for every open stream before exiting)
        if line.starts_with("session ") {
            done.store(true, Ordering::Release);
        }
    }
    let status = child.wait()?;
    let wall_s = started.elapsed().as_secs_f64();
    let cpu_s = (args.children_cpu_s)() - cpu_before;
    done.store(true, Ordering::Release);
    let (view_updates, view_pictures, view_posed) = client
        .map(|c| c.join().unwrap_or_default())
        .unwrap_or_default();
    let err = stderr.and_then(|h| h.join().ok()).unwrap_or_default();
    ensure!(status.success(), "capture failed ({status}): {err}");
    let mut r = read_session(dir)?;
    r.round = round;
    r.view = view;
    r.load_before = load_before;
    r.cpu_s = cpu_s;
    r.wall_s = wall_s;
    r.view_updates = view_updates;
    r.view_pictures = view_pictures;
    r.view_posed = view_posed;
    Ok(r)
}

/// A page-like client of `addr/?token=…`: the event stream, and the three pictures after each
/// update, until the stream says the capture ended. Returns (updates, pictures fetched, frames
/// posed by the view in the last update).
fn page_client(url: &str, done: &AtomicBool) -> (usize, usize, u64) {
    let Some((addr, query)) = url.split_once("/?") else {
        return (0, 0, 0);
    };
    let Ok(mut s) = TcpStream::connect(addr) else {
        return (0, 0, 0);
    };
    let _ = s.set_read_timeout(Some(Duration::from_millis(300)));
    if write!(
        s,
        "GET /api/live/events?{query} HTTP/1.1\r\nHost: {addr}\r\n\r\n"
    )
    .is_err()
    {
        return (0, 0, 0);
    }
    let (mut updates, mut pictures, mut posed) = (0, 0, 0);
    let mut text = String::new();
    let mut buf = vec![0u8; 1 << 16];
    let mut ended = false;
    while !done.load(Ordering::Acquire) && !ended {
        match s.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => text.push_str(&String::from_utf8_lossy(&buf[..n])),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                continue;
            }
            Err(_) => break,
        }
        // complete events end with a blank line
        while let Some(end) = text.find("\n\n") {
            let event: String = text.drain(..end + 2).collect();
            let Some(data) = event.lines().find_map(|l| l.strip_prefix("data: ")) else {
                continue;
            };
            if !event.contains("event: state") {
                continue;
            }
            updates += 1;
            if let Ok(v) = serde_json::from_str::<serde_json::Value>(data) {
                posed = v["tracking"]["posed_by_view"].as_u64().unwrap_or(posed);
                // the capture is over: let go of the stream (older builds' servers waited for
                // every open stream before they let the capture exit)
                ended |= v["state"] == "ended";
            }
            for kind in ["s0", "dolp", "aolp"] {
                pictures += usize::from(get(addr, &format!("/api/live/image/{kind}?{query}")));
            }
        }
    }
    (updates, pictures, posed)
}

/// One GET; whether it answered 200.
fn get(addr: &str, path: &str) -> bool {
    let Ok(mut s) = TcpStream::connect(addr) else {
        return false;
    };
    let _ = s.set_read_timeout(Some(Duration::from_secs(10)));
    if write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .is_err()
    {
        return false;
    }
    let mut out = Vec::new();
    let _ = s.read_to_end(&mut out);
    out.starts_with(b"HTTP/1.1 200")
}

fn read_session(dir: &Path) -> Result<RunResult> {
    let s = ellipso_session::reader::open(dir).with_context(|| dir.display().to_string())?;
    let mut fits: Vec<(u64, f64, f64)> = Vec::new();
    let mut triggers = std::collections::BTreeMap::new();
    let mut arrivals = Vec::new();
    let (mut paired, mut wrong, mut errors, mut flagged) = (0, 0, 0, 0);
    for e in &s.events {
        match e {
            SessionEvent::ClockFit {
                t_host_us,
                gain,
                offset_us,
                ..
            } => fits.push((t_host_us.0, *gain, *offset_us)),
            SessionEvent::Pulse {
                seq,
                t_trigger_device_us,
                ..
            } => {
                triggers.insert(*seq, *t_trigger_device_us);
            }
            SessionEvent::Frame {
                frame_id,
                t_host_us,
                status,
                ..
            } => {
                arrivals.push((*frame_id, t_host_us.0));
                flagged += usize::from(!matches!(
                    status,
                    ellipso_session::events::FrameStatus::Complete
                ));
            }
            SessionEvent::Pairing { frame_id, seq, .. } => {
                paired += 1;
                wrong += usize::from(frame_id != seq);
            }
            SessionEvent::PairingError { .. } => errors += 1,
            _ => {}
        }
    }
    ensure!(!fits.is_empty(), "{}: no clock fit recorded", dir.display());
    // the latest fit made before the frame arrived (the first one for earlier frames)
    let host_us = |t: DeviceTimeUs, at: u64| {
        let (_, gain, offset) = fits.iter().rev().find(|f| f.0 <= at).unwrap_or(&fits[0]);
        gain * t.0 as f64 + offset
    };
    let mut latency_ms: Vec<f64> = arrivals
        .iter()
        .filter_map(|(id, t)| {
            triggers
                .get(id)
                .map(|&trig| (*t as f64 - host_us(trig, *t)) * 1e-3)
        })
        .collect();
    let times: Vec<u64> = arrivals.iter().map(|a| a.1).collect();
    let fps = match (times.iter().min(), times.iter().max()) {
        (Some(&a), Some(&b)) if b > a => (times.len() - 1) as f64 / ((b - a) as f64 * 1e-6),
        _ => 0.0,
    };
    Ok(RunResult {
        round: 0,
        view: false,
        load_before: 0.0,
        frames: s.frames.len(),
        flagged,
        fps,
        latency_ms: [0.5, 0.95, 1.0].map(|q| ellipso_model::stats::percentile(&mut latency_ms, q)),
        paired,
        wrong_pairs: wrong,
        pairing_errors: errors,
        cpu_s: 0.0,
        wall_s: 0.0,
        view_updates: 0,
        view_pictures: 0,
        view_posed: 0,
    })
}

/// A summary row: its name and the figure it reads from a run.
type Row<'a> = (&'a str, &'a dyn Fn(&RunResult) -> f64);

/// Medians per mode and the ratios with/without.
fn summary(results: &[RunResult]) -> String {
    let median = |view: bool, f: &dyn Fn(&RunResult) -> f64| {
        let mut v: Vec<f64> = results.iter().filter(|r| r.view == view).map(f).collect();
        ellipso_model::stats::median(&mut v)
    };
    let rows: [Row; 8] = [
        ("frames", &|r| r.frames as f64),
        ("fps", &|r| r.fps),
        ("latency p50 ms", &|r| r.latency_ms[0]),
        ("latency p95 ms", &|r| r.latency_ms[1]),
        ("latency max ms", &|r| r.latency_ms[2]),
        ("wrong pairs", &|r| r.wrong_pairs as f64),
        ("pairing errors", &|r| r.pairing_errors as f64),
        ("capture cpu s", &|r| r.cpu_s),
    ];
    let mut out = String::from("median of the rounds   without view   with view   ratio\n");
    for (name, f) in rows {
        let (a, b) = (median(false, f), median(true, f));
        out.push_str(&format!(
            "{name:<22} {a:>12.2}   {b:>9.2}   {}\n",
            if a > 0.0 {
                format!("{:.2}", b / a)
            } else {
                "–".into()
            }
        ));
    }
    out
}

/// The 1-minute load average (`/proc/loadavg`), NaN where there is none.
fn load_average() -> f64 {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .unwrap_or(f64::NAN)
}
