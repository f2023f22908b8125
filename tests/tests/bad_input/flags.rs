//! The cases of the bad-input table on CLI flags: every numeric flag outside its limits is
//! refused with the range, and a reader that goes away does not cost the results.

use std::process::Command;

use ellipso_tests::{ellipso_bin, shipped_scene};

use super::support::{Case, Expect, case, damaged, mesh, s};

pub fn flag_cases() -> Vec<Case> {
    let flags: Vec<(&str, Vec<&'static str>, &'static str)> = vec![
        (
            "render --width 100000",
            vec![
                "sim", "render", "SCENE", "--out", "OUT", "--width", "100000", "--height", "100000",
            ],
            "2..=16384",
        ),
        (
            "render --width 321 (odd)",
            vec![
                "sim", "render", "SCENE", "--out", "OUT", "--width", "321", "--height", "256",
            ],
            "odd",
        ),
        (
            "render --frames 0",
            vec!["sim", "render", "SCENE", "--out", "OUT", "--frames", "0"],
            "1..=",
        ),
        (
            "render --frame 10000",
            vec!["sim", "render", "SCENE", "--out", "OUT", "--frame", "10000"],
            "--frame 10000",
        ),
        (
            "render --supersampling 0",
            vec![
                "sim",
                "render",
                "SCENE",
                "--out",
                "OUT",
                "--supersampling",
                "0",
            ],
            "1..=8",
        ),
        (
            "capture --resolution 100000x100000",
            vec![
                "capture",
                "--sim",
                "SCENE",
                "--out",
                "OUT",
                "--resolution",
                "100000x100000",
            ],
            "2..=16384",
        ),
        (
            "capture --resolution 0x0",
            vec![
                "capture",
                "--sim",
                "SCENE",
                "--out",
                "OUT",
                "--resolution",
                "0x0",
            ],
            "2..=16384",
        ),
        (
            "capture --photos 0",
            vec!["capture", "--sim", "SCENE", "--out", "OUT", "--photos", "0"],
            "1..=",
        ),
        (
            "capture --interval-ms 0",
            vec![
                "capture",
                "--sim",
                "SCENE",
                "--out",
                "OUT",
                "--interval-ms",
                "0",
            ],
            "longer than 0",
        ),
        (
            "capture --interval-ms nan",
            vec![
                "capture",
                "--sim",
                "SCENE",
                "--out",
                "OUT",
                "--interval-ms",
                "nan",
            ],
            "outside",
        ),
        (
            "capture --interval-ms 1e300",
            vec![
                "capture",
                "--sim",
                "SCENE",
                "--out",
                "OUT",
                "--interval-ms",
                "1e300",
            ],
            "outside",
        ),
        (
            "capture --interval-ms 1 (< exposure)",
            vec![
                "capture",
                "--sim",
                "SCENE",
                "--out",
                "OUT",
                "--interval-ms",
                "1",
            ],
            "would refuse",
        ),
        (
            "capture --supersampling 9",
            vec![
                "capture",
                "--sim",
                "SCENE",
                "--out",
                "OUT",
                "--supersampling",
                "9",
            ],
            "1..=8",
        ),
        (
            "fit --outer 4294967295",
            vec!["fit", "OUT", "--mesh", "SCENE", "--outer", "4294967295"],
            "1..=20",
        ),
        (
            "fit --outer 0",
            vec!["fit", "OUT", "--mesh", "SCENE", "--outer", "0"],
            "1..=20",
        ),
        (
            "fit --view 999999 (no such frame)",
            vec![
                "fit", "SESSION", "--mesh", "MESH", "--outer", "1", "--out", "OUT", "--view",
                "999999",
            ],
            "frame 999999",
        ),
        (
            "bench pose --frames 0",
            vec!["bench", "pose", "SCENE", "--frames", "0"],
            "1..=",
        ),
        (
            "bench pose --resolution 3x3",
            vec!["bench", "pose", "SCENE", "--resolution", "3x3"],
            "odd",
        ),
        (
            "bench calibration --frames 0",
            vec!["bench", "calibration", "SCENE", "--frames", "0"],
            "1..=",
        ),
        (
            "polar --dark-intensity nan",
            vec!["polar", "SCENE", "--out", "OUT", "--dark-intensity", "nan"],
            "outside",
        ),
        (
            "polar --dark-level 1e9",
            vec!["polar", "SCENE", "--out", "OUT", "--dark-level", "1e9"],
            "outside",
        ),
        (
            "polar --bit-depth 14",
            vec!["polar", "SCENE", "--out", "OUT", "--bit-depth", "14"],
            "8, 10, 12, 16",
        ),
        (
            "sim serve --ber 2",
            vec!["sim", "serve", "SCENE", "--pty", "--ber", "2"],
            "outside",
        ),
        (
            "sim serve --drift-ppm inf",
            vec!["sim", "serve", "SCENE", "--pty", "--drift-ppm", "inf"],
            "outside",
        ),
        (
            "model dop --eta 1e78",
            vec!["model", "dop", "--eta", "1e78", "--theta-deg", "30"],
            "[1, 5]",
        ),
        (
            "model fresnel --eta 1e155",
            vec!["model", "fresnel", "--eta", "1e155", "--theta-deg", "30"],
            "[1, 5]",
        ),
        (
            "model fresnel --theta-deg 91",
            vec!["model", "fresnel", "--eta", "1.5", "--theta-deg", "91"],
            "--theta-deg",
        ),
        (
            "model mueller --eta 1e200",
            vec![
                "model",
                "mueller",
                "--eta",
                "1e200",
                "--sigma-s",
                "0.2",
                "--sigma-ss",
                "0.5",
                "--rho-s",
                "1",
                "--rho-ss",
                "0,0,0",
                "--rho-d",
                "0,0,0",
                "--normal",
                "0,0,1",
                "--to-light",
                "0,0,1",
                "--to-camera",
                "0,0,1",
            ],
            "[1, 5]",
        ),
        (
            "model mueller --rho-s 1e308",
            vec![
                "model",
                "mueller",
                "--eta",
                "1.5",
                "--sigma-s",
                "0.2",
                "--sigma-ss",
                "0.5",
                "--rho-s",
                "1e308",
                "--rho-ss",
                "0,0,0",
                "--rho-d",
                "0,0,0",
                "--normal",
                "0,0,1",
                "--to-light",
                "0,0,1",
                "--to-camera",
                "0,0,1",
            ],
            "[0, 1000]",
        ),
        (
            "model mueller --normal 0,0,0",
            vec![
                "model",
                "mueller",
                "--eta",
                "1.5",
                "--sigma-s",
                "0.2",
                "--sigma-ss",
                "0.5",
                "--rho-s",
                "1",
                "--rho-ss",
                "0,0,0",
                "--rho-d",
                "0,0,0",
                "--normal",
                "0,0,0",
                "--to-light",
                "0,0,1",
                "--to-camera",
                "0,0,1",
            ],
            "non-zero",
        ),
    ];
    let mut cases: Vec<Case> = flags
        .into_iter()
        .map(|(name, args, needle)| {
            case("CLI flags", name, Expect::Refuse(needle), move |dir| {
                let session = if args.contains(&"SESSION") {
                    Some(damaged(dir, |_| {}))
                } else {
                    None
                };
                let scene = shipped_scene("sphere.toml");
                let m = dir.join("mesh.ply");
                let args: Vec<String> = args
                    .iter()
                    .map(|a| match *a {
                        "SCENE" => s(&scene),
                        "OUT" => s(&dir.join("out")),
                        "SESSION" => s(session.as_ref().unwrap()),
                        "MESH" => s(&mesh(dir, 0.0)),
                        other => other.to_string(),
                    })
                    .collect();
                let _ = m;
                let mut c = Command::new(ellipso_bin());
                c.args(&args);
                (c, session.into_iter().collect())
            })
        })
        .collect();
    // a reader that goes away is no reason to die, nor to skip the results
    cases.push(case("CLI flags", "stdout closed (fit | head -0)", Expect::Warn("results in"), |dir| {
        let s = damaged(dir, |_| {});
        let m = mesh(dir, 0.0);
        let script = format!(
            "\"$0\" fit '{}' --mesh '{}' --outer 1 --out '{}' | head -c 0; test -f '{}' && echo results in >&2",
            s.display(),
            m.display(),
            dir.join("fit").display(),
            dir.join("fit").join("fit.ply").display()
        );
        let mut c = Command::new("sh");
        c.arg("-c").arg(script).arg(ellipso_bin());
        (c, vec![s])
    }));
    cases
}
