//! The second probe's cases (issue 28), each the reproduction of what the probe found and the
//! behaviour a user expects; here outputs that would have lost a user's files or written over an
//! input, and calibration from an orbit. Impossible inputs are in `impossible.rs`, unbounded and
//! special-file inputs in `bounds.rs`, errors that blamed the wrong thing in `errors.rs`; the runs
//! that need a signal or two processes at once are in `runs.rs`.

use std::path::{Path, PathBuf};
use std::process::Command;

use ellipso_tests::ellipso_bin;
use ellipso_tests::fit_fixture::write_fit_dir;

use super::support::{Case, Expect, case, copy_dir, damaged, ellipso, fixture, fixture40, mesh, s};

/// A shell running `script` with `$0` = the ellipso binary.
fn sh(script: String) -> Command {
    let mut c = Command::new("sh");
    c.arg("-c").arg(script).arg(ellipso_bin());
    c
}

/// A copy of the 40-frame orbit in `dir`.
fn orbit(dir: &Path) -> PathBuf {
    let s = dir.join("orbit");
    copy_dir(fixture40(), &s);
    s
}

/// Case 1 and 3: outputs never lose a user's files nor write over an input.
pub fn output_cases() -> Vec<Case> {
    let mut cases = vec![
        case(
            "outputs",
            "demo --out: a directory holding summary.json and the user's thesis.tex",
            Expect::Refuse("did not write"),
            |dir| {
                let d = dir.join("d");
                std::fs::create_dir(&d).unwrap();
                std::fs::write(d.join("summary.json"), b"{}").unwrap();
                std::fs::write(d.join("thesis.tex"), b"keep").unwrap();
                let mut c = ellipso(&["demo", "--quick", "--out"]);
                c.arg(&d);
                (c, vec![d])
            },
        ),
        case(
            "outputs",
            "demo --out: a directory holding session/manifest.json beside the user's files",
            Expect::Refuse("did not write"),
            |dir| {
                let d = dir.join("d");
                copy_dir(fixture(), &d.join("session"));
                std::fs::write(d.join("notes.txt"), b"keep").unwrap();
                let mut c = ellipso(&["demo", "--quick", "--out"]);
                c.arg(&d);
                (c, vec![d])
            },
        ),
        case(
            "outputs",
            "sim render --out: a directory with the user's file",
            Expect::Refuse("did not write"),
            |dir| {
                let d = dir.join("r");
                std::fs::create_dir(&d).unwrap();
                std::fs::write(d.join("frame_00000.png"), b"mine").unwrap();
                let mut c = ellipso(&["sim", "render"]);
                c.arg(ellipso_tests::shipped_scene("sphere.toml"))
                    .arg("--out")
                    .arg(&d)
                    .args(["--frames", "1", "--width", "64", "--height", "48"]);
                (c, vec![d])
            },
        ),
        case(
            "outputs",
            "replay --out: another command's output",
            Expect::Refuse("output of `ellipso fit`"),
            |dir| {
                let session = damaged(dir, |_| {});
                let d = dir.join("out");
                std::fs::create_dir(&d).unwrap();
                std::fs::write(
                    d.join(".ellipso-output.json"),
                    br#"{"command":"fit","software":"ellipso","files":["fit.ply"]}"#,
                )
                .unwrap();
                std::fs::write(d.join("fit.ply"), b"ply\n").unwrap();
                let mut c = ellipso(&["replay"]);
                c.arg(&session).arg("--out").arg(&d);
                (c, vec![session, d])
            },
        ),
        case(
            "outputs",
            "mesh --out x.ply over the user's text file",
            Expect::Refuse("not a PLY file"),
            |dir| {
                let session = damaged(dir, |_| {});
                let x = dir.join("x.ply");
                std::fs::write(&x, b"my notes").unwrap();
                let mut c = ellipso(&["mesh"]);
                c.arg(&session).arg("--out").arg(&x);
                (c, vec![session, x])
            },
        ),
        case(
            "outputs",
            "mesh --out x.obj writes OBJ, not PLY bytes",
            Expect::Warn("OBJ written"),
            |dir| {
                let session = orbit(dir);
                let x = dir.join("x.obj");
                let script = format!(
                    "\"$0\" mesh '{}' --out '{}' && head -c 14 '{}' | grep -q '# ellipso mesh' \
                     && echo OBJ written >&2",
                    session.display(),
                    x.display(),
                    x.display()
                );
                (sh(script), vec![session])
            },
        ),
    ];
    // an output equal to, inside or around an input, or inside a session
    type Args = fn(&Path, &Path) -> Vec<String>;
    let overlapping: Vec<(&str, Args, &'static str)> = vec![
        (
            "mesh --out SESSION/manifest.json",
            |_, s| {
                vec![
                    "mesh".into(),
                    str(s),
                    "--out".into(),
                    str(&s.join("manifest.json")),
                ]
            },
            "recorded session",
        ),
        (
            "model plot --out SESSION/frames/00000001.png",
            |_, s| {
                vec![
                    "model".into(),
                    "plot".into(),
                    "--out".into(),
                    str(&s.join("frames").join("00000001.png")),
                ]
            },
            "recorded session",
        ),
        (
            "fit --out SESSION",
            |d, s| fit_args(d, s, s),
            "this is the recorded session",
        ),
        (
            "fit --out SESSION/frames",
            |d, s| fit_args(d, s, &s.join("frames")),
            "recorded session",
        ),
        (
            "fit --out the directory holding the session",
            |d, s| fit_args(d, s, d),
            "contains",
        ),
        (
            "export colmap --out SESSION/colmap",
            |_, s| {
                vec![
                    "export".into(),
                    "colmap".into(),
                    str(s),
                    "--out".into(),
                    str(&s.join("colmap")),
                ]
            },
            "recorded session",
        ),
        (
            "calibrate --out SESSION/frames/camera.toml",
            |_, s| {
                vec![
                    "calibrate".into(),
                    str(s),
                    "--out".into(),
                    str(&s.join("frames").join("camera.toml")),
                ]
            },
            "recorded session",
        ),
        (
            "polar SESSION/frames/00000001.png --out SESSION/frames",
            |_, s| {
                vec![
                    "polar".into(),
                    str(&s.join("frames").join("00000001.png")),
                    "--out".into(),
                    str(&s.join("frames")),
                ]
            },
            "recorded session",
        ),
    ];
    for (name, args, needle) in overlapping {
        cases.push(case("outputs", name, Expect::Refuse(needle), move |dir| {
            let session = damaged(dir, |_| {});
            let mut c = Command::new(ellipso_bin());
            c.args(args(dir, &session));
            (c, vec![session])
        }));
    }
    cases.push(case(
        "outputs",
        "export mitsuba FIT --out FIT",
        Expect::Refuse("which this run reads"),
        |dir| {
            let f = write_fit_dir(&dir.join("fit"));
            let mut c = ellipso(&["export", "mitsuba"]);
            c.arg(&f).arg("--out").arg(&f);
            (c, vec![f])
        },
    ));
    cases
}

fn str(p: &Path) -> String {
    s(p)
}

/// `fit SESSION --mesh SPHERE --outer 1 --out OUT` as arguments.
fn fit_args(dir: &Path, session: &Path, out: &Path) -> Vec<String> {
    vec![
        "fit".into(),
        str(session),
        "--mesh".into(),
        str(&mesh(dir, 0.0)),
        "--outer".into(),
        "1".into(),
        "--out".into(),
        str(out),
    ]
}

/// Case 2 and 11: calibration from an orbit, and the orbit's poses with a tag cut by the sphere.
pub fn orbit_cases() -> Vec<Case> {
    vec![
        case(
            "calibration and tags",
            "calibrate on a 40-frame orbit of the sphere (the probe: fx 973 ± 4, fy 490 ± 15, cy −127 ± 10)",
            Expect::Refuse("take 15–30 calibration photos"),
            |dir| {
                let session = orbit(dir);
                let mut c = ellipso(&["calibrate"]);
                c.arg(&session).arg("--out").arg(dir.join("camera.toml"));
                (c, vec![session])
            },
        ),
        case(
            "calibration and tags",
            "re-tracking the orbit: a tag cut by the sphere costs the tag, not the frame",
            Expect::Warn("40 of 40 frames"),
            |dir| {
                let session = orbit(dir);
                let mut c = ellipso(&["replay"]);
                c.arg(&session).arg("--out").arg(dir.join("r"));
                (c, vec![session])
            },
        ),
    ]
}
