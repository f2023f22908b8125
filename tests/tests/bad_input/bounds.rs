//! The second probe's unbounded inputs (issue 28, case 8): endless sources and special files
//! (`/dev/zero`, FIFOs, links to devices) refused before they are read, and numeric flags of
//! `mesh` bounded.

use std::path::Path;

use super::support::{Case, Expect, case, damaged, ellipso, fifo, fit, mesh, s};

/// Case 8: endless sources and special files are refused before they are read; numeric flags
/// are bounded.
pub fn bound_cases() -> Vec<Case> {
    let mut cases = vec![
        case(
            "unbounded inputs",
            "fit --mesh /dev/zero (grew to 15.7 GB)",
            Expect::Refuse("character device"),
            |dir| {
                let session = damaged(dir, |_| {});
                (fit(dir, &session, Path::new("/dev/zero")), vec![session])
            },
        ),
        case(
            "unbounded inputs",
            "fit-merge /dev/zero as a part file",
            Expect::Refuse("character device"),
            |dir| {
                let mut c = ellipso(&["fit-merge", "/dev/zero", "--out"]);
                c.arg(dir.join("out"));
                (c, vec![])
            },
        ),
        case(
            "unbounded inputs",
            "polar on a FIFO",
            Expect::Refuse("FIFO"),
            |dir| {
                let p = dir.join("frame.png");
                fifo(&p);
                let mut c = ellipso(&["polar", &s(&p), "--out"]);
                c.arg(dir.join("out"));
                (c, vec![])
            },
        ),
        case(
            "unbounded inputs",
            "a frame that is a FIFO (fit)",
            Expect::Warn("skipped"),
            |dir| {
                let session = damaged(dir, |s| fifo(&s.join("frames").join("00000003.png")));
                (fit(dir, &session, &mesh(dir, 0.0)), vec![])
            },
        ),
    ];
    type Damage = fn(&Path);
    let special: Vec<(&str, Damage, &'static str)> = vec![
        (
            "manifest a FIFO",
            |s| fifo(&s.join("manifest.json")),
            "FIFO",
        ),
        (
            "event log a FIFO",
            |s| fifo(&s.join("events.jsonl")),
            "FIFO",
        ),
        (
            "manifest a link to /dev/zero",
            |s| {
                std::fs::remove_file(s.join("manifest.json")).unwrap();
                std::os::unix::fs::symlink("/dev/zero", s.join("manifest.json")).unwrap();
            },
            "character device",
        ),
        (
            "event log a link to /dev/zero",
            |s| {
                std::fs::remove_file(s.join("events.jsonl")).unwrap();
                std::os::unix::fs::symlink("/dev/zero", s.join("events.jsonl")).unwrap();
            },
            "character device",
        ),
    ];
    for (name, damage, needle) in special {
        for command in ["fit", "replay"] {
            cases.push(case(
                "unbounded inputs",
                format!("{name} ({command})"),
                Expect::Refuse(needle),
                move |dir| {
                    let session = damaged(dir, damage);
                    let c = if command == "fit" {
                        fit(dir, &session, &mesh(dir, 0.0))
                    } else {
                        let mut c = ellipso(&["replay"]);
                        c.arg(&session).arg("--out").arg(dir.join("r"));
                        c
                    };
                    (c, vec![])
                },
            ));
        }
    }
    for (flag, value, needle) in [
        ("--threads", "100000", "1..=256"),
        ("--vertices", "10000000", "100..=2000000"),
        ("--vertices", "0", "100..=2000000"),
        ("--votes", "0", "1..=100"),
    ] {
        cases.push(case(
            "unbounded inputs",
            format!("mesh {flag} {value}"),
            Expect::Refuse(needle),
            move |dir| {
                let session = damaged(dir, |_| {});
                let mut c = ellipso(&["mesh"]);
                c.arg(&session)
                    .args([flag, value, "--out"])
                    .arg(dir.join("m.ply"));
                (c, vec![session])
            },
        ));
    }
    cases
}
