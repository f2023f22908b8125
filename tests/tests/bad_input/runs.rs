//! The second probe's runs that a single command cannot show (issue 28, cases 4 and 6, and the
//! concurrent fits of case 9): a run interrupted while it replaces an earlier output, an export
//! repeated into its old output, the demo stopped after its capture, two fits of one unposed
//! session at once. Each returns its verdict.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use super::Verdict;
use super::support::{damaged, ellipso, fit, mesh};

/// Every file under `dir` with its bytes, by relative path.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(
                    p.strip_prefix(dir).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                );
            }
        }
    }
    out
}

/// Whether `out` is one run's whole output: its marker lists exactly the files it holds.
fn whole_output(out: &Path) -> bool {
    let Ok(bytes) = std::fs::read(out.join(".ellipso-output.json")) else {
        return false;
    };
    let marker: serde_json::Value = serde_json::from_slice(&bytes).unwrap_or_default();
    let listed: std::collections::BTreeSet<String> = marker["files"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|f| f.as_str().map(str::to_string))
        .collect();
    let held: std::collections::BTreeSet<String> = snapshot(out)
        .into_keys()
        .map(|p| p.to_string_lossy().into_owned())
        .filter(|p| p != ".ellipso-output.json")
        .collect();
    listed == held && out.join("fit.ply").is_file()
}

/// Names in `dir` that are a run's leftovers (`.NAME.ellipso-…`).
fn leftovers(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.') && n.contains(".ellipso-"))
        .collect()
}

fn wait(child: &mut std::process::Child, limit: Duration) -> Option<std::process::ExitStatus> {
    let deadline = Instant::now() + limit;
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return Some(s);
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            return None;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn send(child: &std::process::Child, signal: i32) {
    let pid = i32::try_from(child.id()).unwrap();
    // SAFETY: our own child, not yet waited for; kill only sends it a signal.
    unsafe { libc::kill(pid, signal) };
}

/// Case 4: `fit` into an earlier fit's output, stopped by `signal` while it works (as soon as it
/// has written a result file, or after 1.5 s). The earlier output must be left byte for byte;
/// after SIGINT/SIGTERM nothing else is left, after SIGKILL the next run clears the leftover
/// and replaces the output whole.
pub fn fit_replacing_an_output_interrupted(dir: &Path, signal: i32) -> Verdict {
    let session = damaged(dir, |_| {});
    let m = mesh(dir, 0.0);
    let out = dir.join("fit");
    if !fit(dir, &session, &m).output().unwrap().status.success() {
        return Verdict::Unexpected;
    }
    let before = snapshot(&out);
    let mut child = fit(dir, &session, &m)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // stopped once it has written three result files — into its staging directory, or (a
    // build without one) into the output itself — mid-way through the export, or after 10 s
    let started = Instant::now();
    let since = std::time::SystemTime::now();
    let mut written = Vec::new();
    while started.elapsed() < Duration::from_secs(10) {
        let staged = std::fs::read_dir(dir)
            .unwrap()
            .flatten()
            .filter(|e| {
                e.file_name()
                    .to_string_lossy()
                    .starts_with(".fit.ellipso-new")
            })
            .flat_map(|e| std::fs::read_dir(e.path()).into_iter().flatten().flatten());
        let in_place = std::fs::read_dir(&out)
            .into_iter()
            .flatten()
            .flatten()
            .filter(|e| {
                e.metadata()
                    .and_then(|m| m.modified())
                    .is_ok_and(|t| t > since)
            });
        written = staged
            .chain(in_place)
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        if written.len() >= 3 || child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    send(&child, signal);
    let Some(status) = wait(&mut child, Duration::from_secs(60)) else {
        return Verdict::Hang;
    };
    // a run that finished (or committed) before the signal replaced the output whole: also
    // allowed — what is never allowed is a mix
    let finished = status.success() || (snapshot(&out) != before && whole_output(&out));
    println!(
        "fit replacing an output, signal {signal} after {:.2} s with {written:?} written: {}",
        started.elapsed().as_secs_f64(),
        if finished {
            "it had finished"
        } else {
            "stopped it"
        }
    );
    if !finished && snapshot(&out) != before {
        println!("the earlier output changed under an interrupted run");
        return Verdict::DataChanged;
    }
    if signal != libc::SIGKILL {
        let exited = status.success() || status.code() == Some(128 + signal);
        if !(exited && leftovers(dir).is_empty()) {
            println!("exit {status:?}, leftovers {:?}", leftovers(dir));
            return Verdict::Unexpected;
        }
        return Verdict::Handled;
    }
    let o = fit(dir, &session, &m).output().unwrap();
    let replaced = o.status.success() && out.join("fit.ply").is_file();
    if replaced && leftovers(dir).is_empty() {
        Verdict::Handled
    } else {
        println!("next run: {:?}, leftovers {:?}", o.status, leftovers(dir));
        Verdict::Unexpected
    }
}

/// Case 4: `export colmap` into an earlier export, now with three frames gone: the output lists
/// every image it holds and holds every image it lists (the probe found 39 images, 20 listed).
pub fn colmap_export_repeated_with_fewer_frames(dir: &Path) -> Verdict {
    let session = damaged(dir, |_| {});
    let out = dir.join("colmap");
    let export = |s: &Path| {
        ellipso(&["export", "colmap"])
            .arg(s)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap()
            .status
            .success()
    };
    if !export(&session) {
        return Verdict::Unexpected;
    }
    let fewer = dir.join("fewer");
    super::support::copy_dir(&session, &fewer);
    for id in [5, 6, 7] {
        std::fs::remove_file(fewer.join("frames").join(format!("{id:08}.png"))).unwrap();
    }
    if !export(&fewer) {
        return Verdict::Unexpected;
    }
    let mut images: Vec<String> = std::fs::read_dir(out.join("images"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    images.sort();
    let listed_text = std::fs::read_to_string(out.join("sparse").join("images.txt")).unwrap();
    let mut listed: Vec<String> = listed_text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .filter_map(|l| l.split_whitespace().nth(9).map(str::to_string))
        .collect();
    listed.sort();
    if images == listed && images.len() == 5 && leftovers(dir).is_empty() {
        Verdict::Handled
    } else {
        println!("images {images:?}, listed {listed:?}");
        Verdict::Unexpected
    }
}

/// Case 6: Ctrl-C after the demo's capture, while it carves and fits: it stops at once with 130
/// and keeps no partial output (the probe: it finished and exited 0).
pub fn demo_interrupted_after_its_capture(dir: &Path) -> Verdict {
    let out = dir.join("demo");
    let mut child = ellipso(&["demo", "--quick", "--out"])
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if line.starts_with("[3/4]") {
                let _ = tx.send(());
            }
        }
    });
    if rx.recv_timeout(Duration::from_secs(300)).is_err() {
        let _ = child.kill();
        let _ = child.wait();
        return Verdict::Hang;
    }
    std::thread::sleep(Duration::from_millis(300));
    send(&child, libc::SIGINT);
    let Some(status) = wait(&mut child, Duration::from_secs(30)) else {
        return Verdict::Hang;
    };
    if status.code() == Some(130) && !out.exists() && leftovers(dir).is_empty() {
        Verdict::Handled
    } else {
        println!(
            "exit {status:?}, out exists {}, leftovers {:?}",
            out.exists(),
            leftovers(dir)
        );
        Verdict::Unexpected
    }
}

/// Case 9: two fits at once of a session without poses: one tracks and records the poses, the
/// other waits and takes them — every frame gets one pose event, not two.
pub fn two_fits_of_an_unposed_session_at_once(dir: &Path) -> Verdict {
    let session = damaged(dir, |s| {
        super::support::edit_log(s, |v| {
            let t = v["type"].as_str().unwrap_or("");
            (t != "pose" && t != "pose_rejected").then_some(v)
        })
    });
    let m = mesh(dir, 0.0);
    let run = |out: &str| {
        let mut c = Command::new(ellipso_tests::ellipso_bin());
        c.arg("fit")
            .arg(&session)
            .arg("--mesh")
            .arg(&m)
            .args(["--outer", "1", "--out"])
            .arg(dir.join(out))
            .stdout(Stdio::null())
            .stderr(Stdio::null());
        c.spawn().unwrap()
    };
    let (mut a, mut b) = (run("a"), run("b"));
    let (sa, sb) = (
        wait(&mut a, Duration::from_secs(180)),
        wait(&mut b, Duration::from_secs(180)),
    );
    let (Some(sa), Some(sb)) = (sa, sb) else {
        return Verdict::Hang;
    };
    let text = std::fs::read_to_string(session.join("events.jsonl")).unwrap();
    let mut per_frame: BTreeMap<u64, usize> = BTreeMap::new();
    for l in text.lines() {
        let v: serde_json::Value = serde_json::from_str(l).unwrap_or_default();
        if matches!(v["type"].as_str(), Some("pose" | "pose_rejected")) {
            *per_frame
                .entry(v["frame_id"].as_u64().unwrap())
                .or_insert(0) += 1;
        }
    }
    if sa.success() && sb.success() && !per_frame.is_empty() && per_frame.values().all(|&n| n == 1)
    {
        Verdict::Handled
    } else {
        println!("exits {sa:?} {sb:?}; pose events per frame {per_frame:?}");
        Verdict::Unexpected
    }
}
