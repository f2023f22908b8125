//! The `ellipso` binary's user-facing contract: every subcommand is listed, results are printed,
//! and every error is one line that names the file, field or device.
//!
//! (Being an integration test of this package also makes `cargo test --workspace` build the
//! binary that the cross-process scenarios in `ellipso-tests` run.)

use std::process::Command;

fn ellipso(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_ellipso"))
        .args(args)
        .output()
        .expect("run ellipso")
}

#[test]
fn help_lists_every_subcommand() {
    let o = ellipso(&["--help"]);
    assert!(o.status.success());
    let text = String::from_utf8_lossy(&o.stdout);
    for cmd in [
        "demo",
        "capture",
        "replay",
        "calibrate",
        "polar",
        "model",
        "sim",
        "devices",
        "bench",
    ] {
        assert!(text.contains(cmd), "`{cmd}` missing from --help:\n{text}");
    }
}

#[test]
fn model_fresnel_prints_the_reference_numbers() {
    let o = ellipso(&[
        "model",
        "fresnel",
        "--eta",
        "1.5",
        "--theta-deg",
        "45",
        "--json",
    ]);
    assert!(o.status.success());
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    // docs/model.md §8 "Fresnel and diffuse DoP values", η = 1.5 at 45°
    assert!((v["rs"].as_f64().unwrap() + 0.303337).abs() < 1e-6);
    assert!((v["r_cross"].as_f64().unwrap() + 0.027911).abs() < 1e-6);
}

#[test]
fn errors_are_one_line_naming_what_is_wrong() {
    for (args, needle) in [
        (vec!["replay", "/nonexistent-session"], "manifest.json"),
        (
            vec!["polar", "/nonexistent.png", "--out", "/tmp/x"],
            "nonexistent.png",
        ),
        (
            vec!["model", "fresnel", "--eta", "0.5", "--theta-deg", "10"],
            "eta",
        ),
        (
            vec![
                "capture",
                "--rig",
                "/nonexistent-rig.toml",
                "--out",
                "/tmp/x",
            ],
            "nonexistent-rig.toml",
        ),
    ] {
        let o = ellipso(&args);
        assert!(!o.status.success(), "{args:?} should fail");
        let err = String::from_utf8_lossy(&o.stderr);
        let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
        assert_eq!(lines.len(), 1, "{args:?}: one line, got:\n{err}");
        assert!(
            lines[0].contains(needle),
            "{args:?}: names {needle}: {}",
            lines[0]
        );
    }
}

#[test]
fn polar_json_prints_one_object_on_stdout() {
    let dir = tempfile::tempdir().expect("tempdir");
    let frame = dir.path().join("frame.png");
    image::ImageBuffer::<image::Luma<u16>, _>::from_raw(8, 8, vec![2000u16; 64])
        .expect("buffer")
        .save(&frame)
        .expect("write frame");
    let out = dir.path().join("out");
    let (frame, out) = (frame.to_str().expect("utf-8"), out.to_str().expect("utf-8"));
    // A uniform frame cannot say which mosaic it is (docs/polar.md): the layout is given.
    let o = ellipso(&["polar", frame, "--out", out, "--json", "--layout", "mono"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert_eq!(text.lines().count(), 1, "{text}");
    let v: serde_json::Value = serde_json::from_str(&text).expect("one JSON object");
    assert_eq!(v["summary"]["output"]["width"], 4, "{v}");
    assert!(
        v["summary"]["files"]
            .as_array()
            .is_some_and(|f| f.len() >= 8)
    );
    // without --json the same run prints the text report
    let o = ellipso(&["polar", frame, "--out", out, "--layout", "mono"]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("wrote") && serde_json::from_str::<serde_json::Value>(&text).is_err());
}
