//! Flags across processes: numeric flags checked against the files' limits, `mesh --debug`
//! refused inside the session, `model` on absurd input, and every flag the docs show accepted by
//! the CLI.

use std::path::Path;
use std::time::{Duration, Instant};

use ellipso_tests::shipped_scene as scene;

use super::{ellipso, snapshot, stderr};

#[test]
fn numeric_flags_are_checked_against_the_files_limits() {
    let tmp = tempfile::tempdir().unwrap();
    let sphere = scene("sphere.toml");
    let sphere = sphere.to_str().unwrap();
    let out = tmp.path().join("o");
    let out = out.to_str().unwrap();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "sim", "render", sphere, "--out", out, "--width", "100000", "--height", "100000",
            ],
            "2..=16384",
        ),
        (
            vec!["sim", "render", sphere, "--out", out, "--frames", "0"],
            "1..=",
        ),
        (
            vec![
                "sim", "render", sphere, "--out", out, "--width", "321", "--height", "256",
            ],
            "odd",
        ),
        (
            vec![
                "sim",
                "render",
                sphere,
                "--out",
                out,
                "--supersampling",
                "9",
            ],
            "1..=8",
        ),
        (
            vec![
                "capture",
                "--sim",
                sphere,
                "--out",
                out,
                "--resolution",
                "100000x100000",
            ],
            "2..=16384",
        ),
        (
            vec!["capture", "--sim", sphere, "--out", out, "--photos", "0"],
            "1..=",
        ),
        (
            vec![
                "capture",
                "--sim",
                sphere,
                "--out",
                out,
                "--interval-ms",
                "0",
            ],
            "longer than 0",
        ),
        (
            vec![
                "capture",
                "--sim",
                sphere,
                "--out",
                out,
                "--interval-ms",
                "nan",
            ],
            "outside",
        ),
        (
            vec!["capture", "--sim", sphere, "--out", out, "--interval-ms=-5"],
            "outside",
        ),
        // shorter than the scene's 8 ms exposure: the board's own rule, before anything is recorded
        (
            vec![
                "capture",
                "--sim",
                sphere,
                "--out",
                out,
                "--interval-ms",
                "1",
            ],
            "would refuse",
        ),
        (
            vec!["fit", out, "--mesh", sphere, "--outer", "4294967295"],
            "1..=20",
        ),
        (vec!["fit", out, "--mesh", sphere, "--outer", "0"], "1..=20"),
        (vec!["bench", "pose", sphere, "--frames", "0"], "1..="),
        (
            vec!["model", "dop", "--eta", "1e78", "--theta-deg", "30"],
            "[1, 5]",
        ),
        (
            vec!["model", "fresnel", "--eta", "1e155", "--theta-deg", "30"],
            "[1, 5]",
        ),
        (
            vec!["polar", "x.png", "--out", out, "--dark-intensity", "nan"],
            "outside",
        ),
        (
            vec!["sim", "serve", sphere, "--pty", "--ber", "2"],
            "outside",
        ),
    ];
    for (args, needle) in cases {
        let started = Instant::now();
        let o = ellipso(&args);
        let err = stderr(&o);
        assert!(!o.status.success(), "{args:?} exited 0");
        assert!(
            o.status.code().is_some()
                && !err.contains("panicked")
                && !err.contains("memory allocation"),
            "{args:?} died: {err}"
        );
        assert!(err.contains(needle), "{args:?}: `{needle}` not in {err}");
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "{args:?} took long"
        );
    }
    assert!(
        !Path::new(out).exists(),
        "a refused command left output behind"
    );
}

#[test]
fn mesh_debug_pictures_never_go_into_the_session() {
    let tmp = tempfile::tempdir().unwrap();
    let session = tmp.path().join("session");
    std::fs::create_dir_all(&session).unwrap();
    let before = snapshot(&session);
    let inside = session.join("pictures");
    let o = ellipso(&[
        "mesh",
        session.to_str().unwrap(),
        "--out",
        tmp.path().join("mesh.ply").to_str().unwrap(),
        "--debug",
        inside.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("inside the session") && stderr(&o).contains("--debug"),
        "{}",
        stderr(&o)
    );
    assert!(!inside.exists(), "the refused folder was created");
    assert_eq!(snapshot(&session), before);
}

#[test]
fn model_on_absurd_input_says_the_range_and_never_prints_nan() {
    let base = [
        "model",
        "mueller",
        "--sigma-s",
        "0.2",
        "--sigma-ss",
        "0.5",
        "--rho-ss",
        "0.1,0.1,0.1",
        "--rho-d",
        "0.5,0.4,0.3",
        "--to-light",
        "0.1,0,1",
        "--to-camera",
        "-0.1,0,1",
        "--json",
    ];
    let run = |extra: &[&str]| {
        let mut args = base.to_vec();
        args.extend_from_slice(extra);
        ellipso(&args)
    };
    let o = run(&["--eta", "1e200", "--rho-s", "1", "--normal", "0,0,1"]);
    assert!(!o.status.success() && stderr(&o).contains("--eta must be in [1, 5]"));
    let o = run(&["--eta", "1.5", "--rho-s", "1e308", "--normal", "0,0,1"]);
    assert!(!o.status.success() && stderr(&o).contains("--rho-s must be in [0, 1000]"));
    // a valid direction of any length is a direction
    let o = run(&["--eta", "1.5", "--rho-s", "1", "--normal", "0,0,1e300"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(!text.contains("null") && !text.contains("NaN"), "{text}");
}

/// Lines of the docs and README that show an `ellipso` command (continuation lines joined).
fn documented_commands() -> Vec<(String, String)> {
    let root = scene("..").join("..");
    let mut files: Vec<_> = std::fs::read_dir(root.join("docs"))
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    files.push(root.join("README.md"));
    let mut out = Vec::new();
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        let mut joined = String::new();
        for line in text.lines() {
            joined.push_str(line.trim_end_matches('\\'));
            if line.ends_with('\\') {
                joined.push(' ');
                continue;
            }
            let name = f.file_name().unwrap().to_string_lossy().into_owned();
            out.push((name, std::mem::take(&mut joined)));
        }
    }
    out
}

#[test]
fn every_flag_the_docs_show_exists() {
    // docs/fit.md showed `--no-augment`, which the CLI rejects
    const SUBCOMMANDS: [&str; 14] = [
        "board",
        "rig",
        "demo",
        "capture",
        "model",
        "polar",
        "calibrate",
        "fit",
        "bench",
        "devices",
        "replay",
        "sim",
        "mesh",
        "export",
    ];
    let mut help: std::collections::BTreeMap<String, String> = Default::default();
    let mut checked = 0;
    let mut missing = Vec::new();
    for (file, line) in documented_commands() {
        let tokens: Vec<&str> = line.split_whitespace().collect();
        for (i, t) in tokens.iter().enumerate() {
            let t = t.trim_start_matches('`');
            let after_cargo = t == "--" && i > 0 && tokens[i - 1] == "--release";
            if t != "ellipso" && !after_cargo {
                continue;
            }
            let Some(sub) = tokens.get(i + 1).map(|s| s.trim_end_matches('`')) else {
                continue;
            };
            if !SUBCOMMANDS.contains(&sub) {
                continue;
            }
            let mut path = vec![sub];
            // `pose\|calibration` (a table's alternatives): the first one
            if let Some(next) = tokens
                .get(i + 2)
                .and_then(|s| s.trim_end_matches('`').split("\\|").next())
                && ["model", "sim", "bench", "export", "board", "rig"].contains(&sub)
                && next.chars().all(|c| c.is_ascii_lowercase())
            {
                path.push(next);
            }
            let key = path.join(" ");
            let text = help.entry(key.clone()).or_insert_with(|| {
                let mut args = path.clone();
                args.push("--help");
                let o = ellipso(&args);
                assert!(o.status.success(), "ellipso {key} --help failed ({file})");
                String::from_utf8_lossy(&o.stdout).into_owned()
            });
            // every --flag up to the next command on the line, comments included
            let end = tokens[i + 1..]
                .iter()
                .position(|t| t.trim_matches('`') == "ellipso")
                .map_or(tokens.len(), |k| i + 1 + k);
            for flag in tokens[i + 1..end].iter().filter_map(|t| {
                let t = t.trim_start_matches(['[', '(', '`']);
                let t = t.split(['=', ']', ')', ',', '`', '|']).next().unwrap_or("");
                (t.starts_with("--") && t.len() > 2).then_some(t)
            }) {
                checked += 1;
                if !text.contains(&format!("{flag} ")) && !text.contains(&format!("{flag}\n")) {
                    missing.push(format!("{file}: ellipso {key} {flag}"));
                }
            }
        }
    }
    assert!(checked > 20, "only {checked} documented flags found");
    assert!(
        missing.is_empty(),
        "documented flags the CLI rejects: {missing:#?}"
    );
}
