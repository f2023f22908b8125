//! docs/first-real-capture.md cannot drift from the code: its `sh sim-walkthrough` block is run
//! here line by line on the simulated rig — `$PTY` is a virtual trigger board served by
//! `ellipso sim serve --pty`, `$WIRE` its trigger-wire socket (`--wire`, where `rig check
//! --fire --sim-camera` hangs the simulated camera), `$FW` a firmware-shaped image (vector table and seeded bytes)
//! that `board flash --model` writes to the DfuSe device model — in a scratch folder where
//! `sim/` is the repository's. Every line must succeed.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use ellipso_tests::ellipso_bin;

struct Guard(Child);

impl Drop for Guard {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The lines of the doc's `sh sim-walkthrough` block.
fn walkthrough() -> Vec<String> {
    let doc = std::fs::read_to_string(repo().join("docs/first-real-capture.md")).expect("doc");
    let start = doc
        .find("```sh sim-walkthrough\n")
        .expect("the doc has the block")
        + 22;
    let end = start + doc[start..].find("```").expect("the block ends");
    doc[start..end]
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(String::from)
        .collect()
}

fn firmware(dir: &Path) -> PathBuf {
    // a vector table (stack in SRAM, reset handler inside the image) and seeded bytes
    let mut v: Vec<u8> = (0..20_000u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 24) as u8)
        .collect();
    v[0..4].copy_from_slice(&0x2002_0000u32.to_le_bytes());
    v[4..8].copy_from_slice(&0x0800_0199u32.to_le_bytes());
    let p = dir.join("ellipso-board.bin");
    std::fs::write(&p, v).expect("write image");
    p
}

#[test]
fn the_walkthrough_runs_on_the_simulated_rig() {
    let lines = walkthrough();
    assert!(lines.len() >= 10, "{lines:?}");
    assert!(
        lines[0].starts_with("ellipso board"),
        "starts at the boards"
    );
    let dir = tempfile::tempdir().expect("tempdir");
    std::os::unix::fs::symlink(repo().join("sim"), dir.path().join("sim")).expect("link sim/");
    let fw = firmware(dir.path());
    let mut serve = Command::new(ellipso_bin())
        .args([
            "sim",
            "serve",
            "sim/scenes/sphere.toml",
            "--pty",
            "--wire",
            "wire.sock",
        ])
        .current_dir(dir.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn sim serve");
    let stdout = serve.stdout.take().expect("stdout");
    let _guard = Guard(serve);
    let mut out = BufReader::new(stdout).lines();
    let first = out.next().expect("a first line").expect("utf-8");
    let pty = first
        .strip_prefix("pty: ")
        .expect("pty line")
        .trim()
        .to_string();
    std::thread::spawn(move || for _ in out {});
    for line in &lines {
        let line = line
            .replace("$PTY", &pty)
            .replace("$FW", fw.to_str().expect("utf-8"))
            .replace("$WIRE", "wire.sock");
        let words: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(words[0], "ellipso", "{line}");
        if words.get(1) == Some(&"view") {
            view(dir.path(), &words[1..]);
            continue;
        }
        let o = Command::new(ellipso_bin())
            .args(&words[1..])
            .current_dir(dir.path())
            .output()
            .expect("run ellipso");
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(
            o.status.success(),
            "`{line}` failed:\n{text}\n{}",
            String::from_utf8_lossy(&o.stderr)
        );
        if line.starts_with("ellipso devices") && line.ends_with("--json") {
            let v: serde_json::Value = serde_json::from_str(&text).expect("--json is JSON");
            assert_eq!(v["trigger_boards"], 1, "{text}");
        }
        if line.starts_with("ellipso rig check") {
            assert!(text.contains("accepts the capture timing"), "{text}");
            if line.contains("--fire 3") {
                assert!(
                    text.contains("flashes: 3 of 3 paired with a frame"),
                    "{text}"
                );
                assert!(text.contains("flash inside the exposure"), "{text}");
            } else {
                // without --fire it says that no flash was fired, never silently nothing
                assert!(text.contains("flashes: none fired"), "{text}");
            }
        }
    }
    for f in ["calib.pdf", "base_a4.png", "rig.toml", "camera.toml"] {
        assert!(dir.path().join(f).is_file(), "{f} missing");
    }
}

/// `ellipso view …` serves until stopped: start it, fetch the page its URL names, stop it.
fn view(dir: &Path, args: &[&str]) {
    use std::io::{Read, Write};
    let mut child = Command::new(ellipso_bin())
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("spawn view");
    let stdout = child.stdout.take().expect("stdout");
    let _guard = Guard(child);
    let url = BufReader::new(stdout)
        .lines()
        .map_while(Result::ok)
        .find_map(|l| l.trim().strip_prefix("open ").map(String::from))
        .expect("view prints the page's URL");
    let rest = url.strip_prefix("http://").expect("http URL");
    let (addr, query) = rest.split_once('/').expect("a path");
    let mut s = std::net::TcpStream::connect(addr).expect("connect to view");
    s.set_read_timeout(Some(std::time::Duration::from_secs(30)))
        .expect("timeout");
    write!(
        s,
        "GET /{query} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .expect("send");
    let mut resp = String::new();
    s.read_to_string(&mut resp).expect("read");
    assert!(
        resp.starts_with("HTTP/1.1 200"),
        "{}",
        &resp[..resp.len().min(200)]
    );
}

#[test]
fn devices_on_a_machine_with_nothing_attached_says_so_and_a_missing_port_is_an_error() {
    let o = Command::new(ellipso_bin())
        .args(["devices", "--json"])
        .output()
        .expect("run");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    // CI machines and this test's machine have no trigger board on USB
    if v["trigger_boards"] == 0 && v["v4l2"].as_array().is_some_and(|a| a.is_empty()) {
        assert_eq!(v["nothing_attached"], true, "{v}");
        let o = Command::new(ellipso_bin())
            .arg("devices")
            .output()
            .expect("run");
        assert!(o.status.success());
        assert!(String::from_utf8_lossy(&o.stdout).contains("nothing attached"));
    }
    let o = Command::new(ellipso_bin())
        .args(["devices", "--port", "/dev/ellipso-no-such-port"])
        .output()
        .expect("run");
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("/dev/ellipso-no-such-port") && err.contains("no such device"),
        "{err}"
    );
}

#[test]
fn rig_files_with_a_missing_or_absurd_field_or_device_name_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rig = dir.path().join("rig.toml");
    let o = Command::new(ellipso_bin())
        .args([
            "rig",
            "init",
            "--out",
            rig.to_str().expect("utf-8"),
            "--trigger",
            "/dev/ellipso-no-such-port",
        ])
        .output()
        .expect("run");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let good = std::fs::read_to_string(&rig).expect("written");
    assert!(
        !good.contains("\n[camera]"),
        "camera stays optional until calibrated"
    );
    let check = |text: &str| {
        std::fs::write(&rig, text).expect("write");
        let o = Command::new(ellipso_bin())
            .args(["rig", "check", rig.to_str().expect("utf-8")])
            .output()
            .expect("run");
        assert!(!o.status.success(), "{text}");
        String::from_utf8_lossy(&o.stderr).to_string()
    };
    let e = check(&good);
    assert!(
        e.contains("trigger.port") && e.contains("/dev/ellipso-no-such-port"),
        "{e}"
    );
    let e = check(&good.replace("bit_depth = 12", "bit_depth = 13"));
    assert!(e.contains("sensor.bit_depth"), "{e}");
    let e = check(&good.replace("photos = 150", "photos = 0"));
    assert!(e.contains("capture.photos"), "{e}");
    let e = check(&good.replace("exposure_us = 8000 ", "# "));
    assert!(e.contains("exposure_us"), "{e}");
    // every shipped example loads
    for entry in std::fs::read_dir(repo().join("examples")).expect("examples/") {
        let path = entry.expect("entry").path();
        if path.extension().is_some_and(|e| e == "toml") {
            ellipso_capture::rig_file::RigFile::load(&path)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        }
    }
}
