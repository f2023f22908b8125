//! Sharded `ellipso fit` across processes (docs/scale.md): three shards run as separate
//! processes — one from `--shard I/N`, one from a Slurm array's environment, one from a
//! Kubernetes Indexed Job's — and `ellipso fit-merge` of their parts writes a `fit.ply`
//! byte-identical to an unsharded `ellipso fit --outer 1`, with the same summary figures. A merge
//! with a shard missing, and shard settings that are absent, malformed or inconsistent, fail with
//! one line naming what is wrong.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use ellipso_model::geometry::TriangleMesh;
use ellipso_tests::fit_fixture::sphere_mesh;
use ellipso_tests::{ellipso_bin, shipped_scene as scene};

const ARRAY_VARS: [&str; 7] = [
    "SLURM_ARRAY_TASK_ID",
    "SLURM_ARRAY_TASK_MIN",
    "SLURM_ARRAY_TASK_MAX",
    "SLURM_ARRAY_TASK_COUNT",
    "SLURM_ARRAY_TASK_STEP",
    "JOB_COMPLETION_INDEX",
    "AWS_BATCH_JOB_ARRAY_INDEX",
];

/// `ellipso ARGS` with no job-array variable inherited, plus `env`.
fn ellipso(args: &[&std::ffi::OsStr], env: &[(&str, &str)]) -> Output {
    let mut c = Command::new(ellipso_bin());
    for v in ARRAY_VARS {
        c.env_remove(v);
    }
    c.args(args).envs(env.iter().copied()).output().unwrap()
}

fn ok(o: Output, what: &str) -> String {
    let text = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(
        o.status.success(),
        "{what}: {}\n{text}",
        String::from_utf8_lossy(&o.stderr)
    );
    text
}

fn failure(o: Output) -> String {
    assert!(
        !o.status.success(),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    let e = String::from_utf8_lossy(&o.stderr).trim().to_string();
    assert_eq!(e.lines().count(), 1, "{e}");
    e
}

/// The figures of `fit-summary.json` that must not depend on sharding (times, wall clock,
/// peak memory and paths may).
fn figures(dir: &Path) -> serde_json::Value {
    let mut s: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("fit-summary.json")).unwrap()).unwrap();
    let o = s.as_object_mut().unwrap();
    for k in ["session", "times_s", "wall_s", "export", "peak_rss_bytes"] {
        o.remove(k);
    }
    o.get_mut("observe")
        .and_then(|v| v.as_object_mut())
        .map(|v| v.remove("peak_bytes"));
    s
}

#[test]
fn three_shard_processes_merge_bit_identical_to_one_run() {
    let tmp = tempfile::tempdir().unwrap();
    let session = tmp.path().join("session");
    ok(
        ellipso(
            &[
                "capture".as_ref(),
                "--interval-ms".as_ref(),
                "50".as_ref(),
                "--sim".as_ref(),
                scene("sphere.toml").as_os_str(),
                "--photos".as_ref(),
                "16".as_ref(),
                "--resolution".as_ref(),
                "612x512".as_ref(),
                "--supersampling".as_ref(),
                "1".as_ref(),
                "--out".as_ref(),
                session.as_os_str(),
            ],
            &[],
        ),
        "capture",
    );
    let mesh = sphere_mesh(tmp.path());
    let whole = tmp.path().join("whole");
    let fit = |extra: &[&std::ffi::OsStr], env: &[(&str, &str)]| {
        let mut args: Vec<&std::ffi::OsStr> = vec![
            "fit".as_ref(),
            session.as_os_str(),
            "--mesh".as_ref(),
            mesh.as_os_str(),
        ];
        args.extend_from_slice(extra);
        ellipso(&args, env)
    };
    ok(
        fit(
            &[
                "--outer".as_ref(),
                "1".as_ref(),
                "--out".as_ref(),
                whole.as_os_str(),
            ],
            &[],
        ),
        "whole fit",
    );
    let parts: Vec<PathBuf> = (0..3)
        .map(|i| tmp.path().join("parts").join(format!("{i}.part")))
        .collect();
    ok(
        fit(
            &[
                "--shard".as_ref(),
                "0/3".as_ref(),
                "--out".as_ref(),
                parts[0].as_os_str(),
            ],
            &[],
        ),
        "shard 0",
    );
    // A Slurm array `--array=1-3`: task id 2 is shard 1.
    ok(
        fit(
            &[
                "--shard".as_ref(),
                "env".as_ref(),
                "--out".as_ref(),
                parts[1].as_os_str(),
            ],
            &[
                ("SLURM_ARRAY_TASK_ID", "2"),
                ("SLURM_ARRAY_TASK_MIN", "1"),
                ("SLURM_ARRAY_TASK_MAX", "3"),
                ("SLURM_ARRAY_TASK_COUNT", "3"),
            ],
        ),
        "shard 1 (Slurm)",
    );
    let text = ok(
        fit(
            &[
                "--shard".as_ref(),
                "env".as_ref(),
                "--shard-count".as_ref(),
                "3".as_ref(),
                "--out".as_ref(),
                parts[2].as_os_str(),
            ],
            &[("JOB_COMPLETION_INDEX", "2")],
        ),
        "shard 2 (Kubernetes)",
    );
    assert!(text.contains("shard 2/3"), "{text}");

    // Missing shard: named, and nothing merged.
    let merged = tmp.path().join("merged");
    let e = failure(ellipso(
        &[
            "fit-merge".as_ref(),
            parts[0].as_os_str(),
            parts[2].as_os_str(),
            "--out".as_ref(),
            merged.as_os_str(),
        ],
        &[],
    ));
    assert!(e.contains("shard 1/3 missing"), "{e}");
    assert!(!merged.join("fit.ply").exists());

    // Parts in any order.
    ok(
        ellipso(
            &[
                "fit-merge".as_ref(),
                parts[2].as_os_str(),
                parts[0].as_os_str(),
                parts[1].as_os_str(),
                "--out".as_ref(),
                merged.as_os_str(),
            ],
            &[],
        ),
        "merge",
    );
    let a = std::fs::read(whole.join("fit.ply")).unwrap();
    let b = std::fs::read(merged.join("fit.ply")).unwrap();
    assert!(
        a == b,
        "fit.ply of the merged shards differs from the single run's"
    );
    assert_eq!(figures(&whole), figures(&merged));
    assert_eq!(
        TriangleMesh::load(&merged.join("fit.ply"))
            .unwrap()
            .positions()
            .len(),
        162
    );
}

#[test]
fn bad_shard_settings_fail_with_one_line_naming_them() {
    let tmp = tempfile::tempdir().unwrap();
    let mesh = sphere_mesh(tmp.path());
    let part = tmp.path().join("p.part");
    let run = |extra: &[&str], env: &[(&str, &str)]| {
        let mut args: Vec<&std::ffi::OsStr> = vec![
            "fit".as_ref(),
            tmp.path().as_os_str(),
            "--mesh".as_ref(),
            mesh.as_os_str(),
            "--out".as_ref(),
            part.as_os_str(),
        ];
        args.extend(extra.iter().map(|s| std::ffi::OsStr::new(*s)));
        failure(ellipso(&args, env))
    };
    let e = run(&["--shard", "3/3"], &[]);
    assert!(
        e.contains("\"3/3\"") && e.contains("not below the count"),
        "{e}"
    );
    let e = run(&["--shard", "env", "--shard-count", "4"], &[]);
    assert!(e.contains("no job-array index"), "{e}");
    let e = run(&["--shard", "env"], &[("AWS_BATCH_JOB_ARRAY_INDEX", "1")]);
    assert!(
        e.contains("AWS_BATCH_JOB_ARRAY_INDEX") && e.contains("--shard-count"),
        "{e}"
    );
    let e = run(
        &["--shard", "env", "--shard-count", "8"],
        &[
            ("SLURM_ARRAY_TASK_ID", "1"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
        ],
    );
    assert!(e.contains("inconsistent") && e.contains("COUNT=4"), "{e}");
    let e = run(&["--shard", "0/2", "--outer", "2"], &[]);
    assert!(e.contains("--outer 2 with --shard"), "{e}");
    // Not a part file.
    let e = failure(ellipso(
        &[
            "fit-merge".as_ref(),
            mesh.as_os_str(),
            "--out".as_ref(),
            tmp.path().join("m").as_os_str(),
        ],
        &[],
    ));
    assert!(e.contains("sphere.ply") && e.contains("magic"), "{e}");
}
