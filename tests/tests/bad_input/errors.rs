//! The second probe's errors (issue 28, cases 5 and 9): inputs that panicked, and errors that
//! blamed the wrong thing or said their cause twice, each now refused with the right cause once.

use std::path::{Path, PathBuf};
use std::process::Command;

use ellipso_fit::shard::part::PartFile;
use ellipso_tests::ellipso_bin;

use super::support::{Case, Expect, case, damaged, ellipso, fit, mesh};

/// A real part file of the 8-frame fixture (`fit --shard 0/1`), at `dir/p.part`.
fn part_file(dir: &Path) -> (PathBuf, PathBuf) {
    let session = damaged(dir, |_| {});
    let m = mesh(dir, 0.0);
    let p = dir.join("p.part");
    let o = ellipso(&["fit"])
        .arg(&session)
        .arg("--mesh")
        .arg(&m)
        .args(["--shard", "0/1", "--out"])
        .arg(&p)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    (p, session)
}

/// Case 5 and 9: no panic on any input; errors that name the right cause, once.
pub fn error_cases() -> Vec<Case> {
    vec![
        case(
            "errors",
            "fit-merge: a part whose shard index ≥ count, checksum valid (panicked)",
            Expect::Refuse("impossible"),
            |dir| {
                let (p, session) = part_file(dir);
                let mut part = PartFile::read(&p).unwrap();
                part.shard.index = 5;
                part.shard.count = 2;
                part.write(&p).unwrap();
                let mut c = ellipso(&["fit-merge"]);
                c.arg(&p).arg("--out").arg(dir.join("out"));
                (c, vec![session, p])
            },
        ),
        case(
            "errors",
            "fit-merge: parts whose text holds terminal escapes",
            Expect::Refuse("\\u{1b}"),
            |dir| {
                let (p, session) = part_file(dir);
                let mut part = PartFile::read(&p).unwrap();
                part.session_dir = dir.join("\u{1b}[2J\u{1b}[31mgone");
                part.write(&p).unwrap();
                let mut c = ellipso(&["fit-merge"]);
                c.arg(&p).arg("--out").arg(dir.join("out"));
                (c, vec![session, p])
            },
        ),
        case(
            "errors",
            "fit --shard 0/2 --out out/ (said 'Not a directory')",
            Expect::Refuse("names a directory"),
            |dir| {
                let session = damaged(dir, |_| {});
                let mut c = ellipso(&["fit"]);
                c.arg(&session)
                    .arg("--mesh")
                    .arg(mesh(dir, 0.0))
                    .args(["--shard", "0/2", "--out"])
                    .arg(format!("{}/out/", dir.display()));
                (c, vec![session])
            },
        ),
        case(
            "errors",
            "fit --mesh absent.ply: the OS message said once",
            Expect::RefuseOnce("No such file or directory"),
            |dir| {
                let session = damaged(dir, |_| {});
                (fit(dir, &session, &dir.join("absent.ply")), vec![session])
            },
        ),
        case(
            "errors",
            "fit --out into the session with --view 999999: refused at once, before any work",
            Expect::Refuse("recorded session"),
            |dir| {
                let session = damaged(dir, |_| {});
                let mut c = ellipso(&["fit"]);
                c.arg(&session)
                    .arg("--mesh")
                    .arg(mesh(dir, 0.0))
                    .args(["--view", "999999", "--out"])
                    .arg(session.join("fit"));
                (c, vec![session])
            },
        ),
        case(
            "errors",
            "fit 2>&1 | head -1 (panicked writing to the closed pipe)",
            Expect::Warn("results in"),
            |dir| {
                let session = damaged(dir, |_| {});
                let out = dir.join("fit");
                let script = format!(
                    "\"$0\" fit '{}' --mesh '{}' --outer 1 --out '{}' 2>&1 | head -1 >/dev/null; \
                     s=${{PIPESTATUS[0]}}; echo \"ellipso exited $s\" >&2; \
                     test \"$s\" = 0 && test -f '{}' && echo results in >&2",
                    session.display(),
                    mesh(dir, 0.0).display(),
                    out.display(),
                    out.join("fit.ply").display()
                );
                let mut c = Command::new("bash");
                c.arg("-c").arg(script).arg(ellipso_bin());
                (c, vec![session])
            },
        ),
    ]
}
