//! `ellipso capture --view` keeps up with a 20 fps simulated capture: with the live view following
//! the session and a page-like client streaming its events and fetching the frame pictures, every
//! photo is recorded and paired, and none is dropped by the capture.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Duration;

use ellipso_host::session::events::SessionEvent;
use ellipso_tests::{ellipso_bin, shipped_scene};

fn get(addr: &str, path: &str) -> Vec<u8> {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut out = Vec::new();
    let _ = s.read_to_end(&mut out);
    out
}

#[test]
fn live_view_keeps_up_with_a_20_fps_capture_without_dropping_frames() {
    let tmp = tempfile::tempdir().unwrap();
    let session = tmp.path().join("session");
    let photos = 60u64;
    let mut child = Command::new(ellipso_bin())
        .args(["capture", "--sim"])
        .arg(shipped_scene("sphere.toml"))
        .args([
            "--photos",
            &photos.to_string(),
            "--resolution",
            "306x256",
            "--supersampling",
            "1",
            "--interval-ms",
            "50",
            "--no-track",
            "--view",
        ])
        .arg("--out")
        .arg(&session)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let url = loop {
        let line = lines.next().expect("capture printed no view URL").unwrap();
        if let Some(at) = line.find("open http://") {
            break line[at + 12..].trim().to_string();
        }
    };
    let (addr, query) = url.split_once("/?").unwrap();
    let (addr, query) = (addr.to_string(), query.to_string());
    let done = Arc::new(AtomicBool::new(false));
    let events = Arc::new(AtomicUsize::new(0));
    // a page-like client: the event stream, and the pictures of each new frame
    let client = {
        let (addr, query, done, events) =
            (addr.clone(), query.clone(), done.clone(), events.clone());
        std::thread::spawn(move || {
            let mut s = TcpStream::connect(&addr).unwrap();
            s.set_read_timeout(Some(Duration::from_millis(300)))
                .unwrap();
            write!(
                s,
                "GET /api/live/events?{query} HTTP/1.1\r\nHost: {addr}\r\n\r\n"
            )
            .unwrap();
            let mut buf = [0u8; 65536];
            while !done.load(Ordering::Acquire) {
                if let Ok(n) = s.read(&mut buf) {
                    if n == 0 {
                        break;
                    }
                    let text = String::from_utf8_lossy(&buf[..n]);
                    let k = text.matches("event: state").count();
                    if k > 0 {
                        events.fetch_add(k, Ordering::AcqRel);
                        for kind in ["s0", "dolp", "aolp"] {
                            get(&addr, &format!("/api/live/image/{kind}?{query}"));
                        }
                    }
                }
            }
        })
    };
    let rest: Vec<String> = lines.map_while(Result::ok).collect();
    let status = child.wait().unwrap();
    done.store(true, Ordering::Release);
    client.join().unwrap();
    assert!(status.success(), "{rest:?}");
    let s = ellipso_host::session::reader::open(&session).unwrap();
    let frames = s.frames.len() as u64;
    let paired = s
        .events
        .iter()
        .filter(|e| matches!(e, SessionEvent::Pairing { .. }))
        .count() as u64;
    let errors: Vec<_> = s
        .events
        .iter()
        .filter(|e| matches!(e, SessionEvent::PairingError { .. }))
        .collect();
    assert_eq!(frames, photos, "{rest:?}");
    assert_eq!(paired, photos, "{errors:?}");
    assert!(errors.is_empty(), "{errors:?}");
    assert!(s.frames.iter().all(|f| f.complete));
    let n = events.load(Ordering::Acquire);
    assert!(
        n >= 3,
        "the client saw the view update during the capture ({n} events)"
    );
}
