//! Headless Chromium driven over the DevTools protocol on a pipe (`--remote-debugging-pipe`:
//! commands on fd 3, replies and events on fd 4, NUL-separated JSON), with no crate beyond std.
//!
//! Contract:
//! - [`chromium_or_skip`] finds Debian's `chromium`. When it is missing it panics if
//!   `ELLIPSO_REQUIRE_CHROMIUM=1` (CI), otherwise prints a loud `skipped:` line and returns `None`.
//! - [`Browser::launch`] starts it headless with a fresh profile, no network beyond what the page
//!   asks for, and WebGL through SwiftShader (`--use-angle=swiftshader --enable-unsafe-swiftshader`,
//!   needed under `--disable-gpu`); the process is killed on drop.
//! - [`Page`] records every console error, uncaught exception and browser log error of the page,
//!   so a test can assert there were none.

use std::io::{self, BufRead, BufReader, Read, Write};
use std::os::fd::{FromRawFd, OwnedFd};
use std::os::unix::process::CommandExt;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{Receiver, RecvTimeoutError, channel};
use std::time::{Duration, Instant};

use serde_json::{Value, json};

/// Env var that turns a missing Chromium into a test failure (`1` in CI).
pub const ENV_REQUIRE: &str = "ELLIPSO_REQUIRE_CHROMIUM";

/// The Chromium binary, or `None` after printing why the test is skipped.
pub fn chromium_or_skip(test: &str) -> Option<PathBuf> {
    for name in ["chromium", "chromium-browser"] {
        if let Ok(out) = Command::new(name).arg("--version").output()
            && out.status.success()
        {
            return Some(PathBuf::from(name));
        }
    }
    let why = "chromium not found (apt-get install chromium)";
    if std::env::var(ENV_REQUIRE).as_deref() == Ok("1") {
        panic!("{test}: {why}; {ENV_REQUIRE}=1 requires it");
    }
    let _ = writeln!(io::stderr(), "\n*** {test} skipped: {why} ***\n");
    None
}

/// A running headless Chromium.
pub struct Browser {
    child: Child,
    to_browser: std::fs::File,
    from_browser: Receiver<Value>,
    next_id: u64,
    _profile: tempfile::TempDir,
    stderr_log: PathBuf,
}

fn pipe() -> (OwnedFd, OwnedFd) {
    let mut fds = [0; 2];
    // SAFETY: pipe2 writes two fresh descriptors into `fds`; each is owned exactly once below.
    let rc = unsafe { libc::pipe2(fds.as_mut_ptr(), libc::O_CLOEXEC) };
    assert_eq!(rc, 0, "pipe2: {}", io::Error::last_os_error());
    // SAFETY: the descriptors were just created and are not owned elsewhere.
    unsafe { (OwnedFd::from_raw_fd(fds[0]), OwnedFd::from_raw_fd(fds[1])) }
}

impl Browser {
    /// Starts Chromium (`bin`) headless, with artefacts (its stderr) under `artefacts`.
    pub fn launch(bin: &std::path::Path, artefacts: &std::path::Path) -> Self {
        let profile = tempfile::tempdir().expect("profile dir");
        let (cmd_read, cmd_write) = pipe();
        let (resp_read, resp_write) = pipe();
        let stderr_log = artefacts.join("chromium-stderr.log");
        let stderr = std::fs::File::create(&stderr_log).expect("stderr log");
        let mut command = Command::new(bin);
        command
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--use-angle=swiftshader",
                "--enable-unsafe-swiftshader",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--hide-scrollbars",
                "--remote-debugging-pipe",
                "--window-size=1280,900",
            ])
            .arg(format!("--user-data-dir={}", profile.path().display()))
            .arg("about:blank")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(stderr)
            .process_group(0);
        {
            use std::os::fd::AsRawFd;
            let (r, w) = (cmd_read.as_raw_fd(), resp_write.as_raw_fd());
            // SAFETY: only async-signal-safe dup2 calls between fork and exec; dup2 clears
            // CLOEXEC on the new descriptors 3 and 4, which Chromium reads and writes.
            unsafe {
                command.pre_exec(move || {
                    if libc::dup2(r, 3) < 0 || libc::dup2(w, 4) < 0 {
                        return Err(io::Error::last_os_error());
                    }
                    Ok(())
                });
            }
        }
        let child = command.spawn().expect("spawn chromium");
        drop((cmd_read, resp_write));
        let (tx, rx) = channel();
        let reader = std::fs::File::from(resp_read);
        std::thread::spawn(move || {
            let mut r = BufReader::new(reader);
            loop {
                let mut buf = Vec::new();
                match r.read_until(0, &mut buf) {
                    Ok(0) | Err(_) => break,
                    Ok(_) => {
                        if buf.last() == Some(&0) {
                            buf.pop();
                        }
                        if let Ok(v) = serde_json::from_slice::<Value>(&buf)
                            && tx.send(v).is_err()
                        {
                            break;
                        }
                    }
                }
            }
        });
        Self {
            child,
            to_browser: std::fs::File::from(cmd_write),
            from_browser: rx,
            next_id: 1,
            _profile: profile,
            stderr_log,
        }
    }

    /// Sends one command and waits for its reply; events seen meanwhile go to `events`.
    fn call(
        &mut self,
        session: Option<&str>,
        method: &str,
        params: Value,
        events: &mut Vec<Value>,
        timeout: Duration,
    ) -> Result<Value, String> {
        let id = self.next_id;
        self.next_id += 1;
        let mut msg = json!({"id": id, "method": method, "params": params});
        if let Some(s) = session {
            msg["sessionId"] = json!(s);
        }
        let mut bytes = serde_json::to_vec(&msg).map_err(|e| e.to_string())?;
        bytes.push(0);
        self.to_browser
            .write_all(&bytes)
            .map_err(|e| format!("{method}: writing to chromium: {e}"))?;
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.from_browser.recv_timeout(left) {
                Ok(v) if v["id"] == json!(id) => {
                    return match v.get("error") {
                        Some(e) => Err(format!("{method}: {e}")),
                        None => Ok(v["result"].clone()),
                    };
                }
                Ok(v) => events.push(v),
                Err(RecvTimeoutError::Timeout) => {
                    return Err(format!("{method}: no reply in {timeout:?}"));
                }
                Err(RecvTimeoutError::Disconnected) => {
                    let mut log = String::new();
                    let _ = std::fs::File::open(&self.stderr_log)
                        .and_then(|mut f| f.read_to_string(&mut log));
                    return Err(format!("{method}: chromium went away; its stderr:\n{log}"));
                }
            }
        }
    }

    /// Opens a tab of `width`×`height` CSS pixels at `url`.
    pub fn open(&mut self, url: &str, width: u32, height: u32) -> Page<'_> {
        let mut events = Vec::new();
        let t = Duration::from_secs(30);
        let target = self
            .call(
                None,
                "Target.createTarget",
                json!({"url": "about:blank"}),
                &mut events,
                t,
            )
            .expect("createTarget");
        let target_id = target["targetId"].as_str().expect("targetId").to_string();
        let attached = self
            .call(
                None,
                "Target.attachToTarget",
                json!({"targetId": target_id, "flatten": true}),
                &mut events,
                t,
            )
            .expect("attachToTarget");
        let session = attached["sessionId"]
            .as_str()
            .expect("sessionId")
            .to_string();
        let mut page = Page {
            browser: self,
            session,
            events,
        };
        for m in ["Runtime.enable", "Log.enable", "Page.enable"] {
            page.cmd(m, json!({}));
        }
        page.cmd(
            "Emulation.setDeviceMetricsOverride",
            json!({"width": width, "height": height, "deviceScaleFactor": 1, "mobile": false}),
        );
        page.cmd("Page.navigate", json!({ "url": url }));
        page
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        // SAFETY: kill(2) on the process group this struct started (process_group(0) above).
        unsafe {
            libc::kill(-(self.child.id() as i32), libc::SIGKILL);
        }
        let _ = self.child.wait();
    }
}

/// One tab.
pub struct Page<'a> {
    browser: &'a mut Browser,
    session: String,
    events: Vec<Value>,
}

impl Page<'_> {
    /// A DevTools command on this tab (panics on a protocol error).
    pub fn cmd(&mut self, method: &str, params: Value) -> Value {
        let s = self.session.clone();
        self.browser
            .call(
                Some(&s),
                method,
                params,
                &mut self.events,
                Duration::from_secs(60),
            )
            .unwrap_or_else(|e| panic!("{e}"))
    }

    /// Evaluates a JavaScript expression (promises awaited) and returns its value.
    pub fn eval(&mut self, expression: &str) -> Value {
        let r = self.cmd(
            "Runtime.evaluate",
            json!({"expression": expression, "returnByValue": true, "awaitPromise": true}),
        );
        if let Some(e) = r.get("exceptionDetails") {
            panic!("{expression}: {e}");
        }
        r["result"]["value"].clone()
    }

    /// Waits until `expression` is true; panics with the page's errors after `timeout`.
    pub fn wait_for(&mut self, expression: &str, timeout: Duration) {
        let deadline = Instant::now() + timeout;
        loop {
            if self.eval(&format!("!!({expression})")) == json!(true) {
                return;
            }
            let errors = self.console_errors();
            if Instant::now() > deadline || !errors.is_empty() {
                let page_errors =
                    self.eval("window.__ellipso ? window.__ellipso.errors : 'no __ellipso'");
                panic!(
                    "`{expression}` not true after {timeout:?}; console errors {errors:?}; page errors {page_errors}"
                );
            }
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    /// Console errors, uncaught exceptions and browser log errors seen so far.
    pub fn console_errors(&mut self) -> Vec<String> {
        // drain pending events
        while let Ok(v) = self.browser.from_browser.try_recv() {
            self.events.push(v);
        }
        self.events
            .iter()
            .filter(|e| e["sessionId"] == json!(self.session))
            .filter_map(|e| {
                let p = &e["params"];
                match e["method"].as_str()? {
                    "Runtime.consoleAPICalled" if p["type"] == json!("error") => {
                        Some(p["args"].to_string())
                    }
                    "Runtime.exceptionThrown" => Some(p["exceptionDetails"].to_string()),
                    "Log.entryAdded" if p["entry"]["level"] == json!("error") => {
                        Some(p["entry"]["text"].to_string())
                    }
                    _ => None,
                }
            })
            .collect()
    }

    /// A PNG screenshot of the viewport.
    pub fn screenshot(&mut self) -> Vec<u8> {
        let r = self.cmd("Page.captureScreenshot", json!({"format": "png"}));
        base64_decode(r["data"].as_str().expect("screenshot data"))
    }
}

/// Standard base64 (with padding) → bytes.
pub fn base64_decode(text: &str) -> Vec<u8> {
    let value = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        } as u32)
    };
    let mut out = Vec::with_capacity(text.len() * 3 / 4);
    let (mut acc, mut bits) = (0u32, 0);
    for c in text.bytes().filter_map(value) {
        acc = (acc << 6) | c;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    out
}

/// Starts `ellipso ARGS…` and returns it with the page URL it prints (`open http://…`).
pub fn spawn_with_url(mut command: Command) -> (Child, String) {
    command
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .process_group(0);
    let mut child = command.spawn().expect("spawn ellipso");
    let stdout = child.stdout.take().expect("stdout");
    let mut lines = BufReader::new(stdout).lines();
    let url = loop {
        match lines.next() {
            Some(Ok(line)) => {
                if let Some(at) = line.find("open http") {
                    break line[at + 5..].trim().to_string();
                }
            }
            _ => panic!("ellipso ended without printing a URL"),
        }
    };
    // keep draining stdout so the child never blocks on a full pipe
    std::thread::spawn(move || for _ in lines {});
    (child, url)
}

/// Kills its child's process group on drop (also when a test panics).
pub struct ChildGuard(pub Child);

impl Drop for ChildGuard {
    fn drop(&mut self) {
        kill_group(&mut self.0);
    }
}

/// Kills a child started with its own process group.
pub fn kill_group(child: &mut Child) {
    // SAFETY: kill(2) on the process group of a child this test started.
    unsafe {
        libc::kill(-(child.id() as i32), libc::SIGKILL);
    }
    let _ = child.wait();
}

#[cfg(test)]
mod tests {
    #[test]
    fn base64_round_trips_known_vectors() {
        assert_eq!(super::base64_decode("aGVsbG8="), b"hello");
        assert_eq!(super::base64_decode("iVBORw0KGgo="), b"\x89PNG\r\n\x1a\n");
    }
}
