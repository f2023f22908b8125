//! The second probe's impossible inputs (issue 28, case 7): degenerate meshes and sessions whose
//! poses, camera or exposures cannot be, each refused with its cause instead of fitted into a
//! confident answer.

use std::path::{Path, PathBuf};

use ellipso_model::geometry::TriangleMesh;
use ellipso_model::geometry::ply::{PlyFormat, write_ply};
use ellipso_model::geometry::procedural::icosphere;
use nalgebra::Point3;

use super::support::{Case, Expect, case, damaged, edit_log, edit_manifest, ellipso, fit, mesh};

/// A mesh file of the sphere's icosphere with positions mapped by `at` and faces by `face`.
fn sphere_like(
    dir: &Path,
    at: impl Fn(Point3<f64>) -> Point3<f64>,
    face: impl Fn([u32; 3]) -> [u32; 3],
) -> PathBuf {
    let (dirs, faces) = icosphere(1);
    let pos = dirs
        .iter()
        .map(|d| at(Point3::new(0.0, 0.0, 0.04) + d.into_inner() * 0.04))
        .collect();
    let faces = faces.into_iter().map(face).collect();
    let m = TriangleMesh::new(pos, None, None, faces).unwrap();
    let p = dir.join("m.ply");
    std::fs::write(&p, write_ply(&m, PlyFormat::BinaryLittleEndian, false)).unwrap();
    p
}

/// Case 7: impossible inputs are refused with their cause instead of fitted.
pub fn impossible_cases() -> Vec<Case> {
    type MakeMesh = fn(&Path) -> PathBuf;
    let meshes: Vec<(&str, MakeMesh, &'static str)> = vec![
        (
            "mesh collapsed to one point",
            |d| sphere_like(d, |_| Point3::new(0.0, 0.0, 0.04), |f| f),
            "0 m across",
        ),
        (
            "mesh of zero area (flattened onto a line)",
            |d| sphere_like(d, |p| Point3::new(p.x, 0.0, 0.04), |f| f),
            "have no area",
        ),
        (
            "mesh scaled by 1e-40",
            |d| sphere_like(d, |p| Point3::from(p.coords * 1e-40), |f| f),
            "px in the median view",
        ),
        (
            "mesh with its winding flipped",
            |d| sphere_like(d, |p| p, |f| [f[0], f[2], f[1]]),
            "wind clockwise",
        ),
    ];
    let mut cases: Vec<Case> = meshes
        .into_iter()
        .map(|(name, make, needle)| {
            case(
                "impossible inputs",
                name,
                Expect::Refuse(needle),
                move |dir| {
                    let session = damaged(dir, |_| {});
                    let m = make(dir);
                    (fit(dir, &session, &m), vec![session])
                },
            )
        })
        .collect();
    type Damage = fn(&Path);
    let sessions: Vec<(&str, Damage, &[&str], &'static str)> = vec![
        (
            "every pose identical",
            |s| {
                let first = std::cell::RefCell::new(None);
                edit_log(s, |mut v| {
                    if v["type"] == "pose" {
                        let mut f = first.borrow_mut();
                        let keep = f.get_or_insert_with(|| {
                            (
                                v["rotation_camera_from_world"].clone(),
                                v["translation_camera_from_world_m"].clone(),
                            )
                        });
                        v["rotation_camera_from_world"] = keep.0.clone();
                        v["translation_camera_from_world_m"] = keep.1.clone();
                    }
                    Some(v)
                })
            },
            &["fit"],
            "one and the same pose",
        ),
        (
            "a camera 1e308 m from the board",
            |s| {
                edit_log(s, |mut v| {
                    if v["type"] == "pose" && v["frame_id"] == 2 {
                        v["translation_camera_from_world_m"][0] = 1e308.into();
                    }
                    Some(v)
                })
            },
            &["fit", "mesh", "colmap"],
            "m from the board origin",
        ),
        (
            "fx = 1e308",
            |s| edit_manifest(s, |v| v["rig"]["camera"]["fx"] = 1e308.into()),
            &["fit", "mesh", "colmap"],
            "fx = 1e308",
        ),
        (
            "k1 = 1e308",
            |s| edit_manifest(s, |v| v["rig"]["camera"]["k1"] = 1e308.into()),
            &["fit", "colmap"],
            "k1 = 1e308",
        ),
        (
            "two pose events for one frame that disagree",
            |s| {
                let p = s.join("events.jsonl");
                let text = std::fs::read_to_string(&p).unwrap();
                let pose = text
                    .lines()
                    .find(|l| l.contains("\"type\":\"pose\""))
                    .unwrap();
                let mut v: serde_json::Value = serde_json::from_str(pose).unwrap();
                v["translation_camera_from_world_m"][0] = 0.3.into();
                std::fs::write(&p, format!("{text}{v}\n")).unwrap();
            },
            &["fit"],
            "pose events disagree",
        ),
        (
            "gain −400 dB",
            |s| {
                edit_log(s, |mut v| {
                    if v["type"] == "frame" {
                        v["gain_db"] = (-400.0).into();
                    }
                    Some(v)
                })
            },
            &["fit"],
            "gain_db",
        ),
        (
            "exposure 0 µs (was blamed on 23753 samples in shadow)",
            |s| {
                edit_log(s, |mut v| {
                    if v["type"] == "frame" {
                        v["exposure_us"] = 0.into();
                    }
                    Some(v)
                })
            },
            &["fit"],
            "exposure_us",
        ),
        (
            "flash energy 1e308 (was blamed as non-finite)",
            |s| {
                edit_log(s, |mut v| {
                    if v["type"] == "pairing" {
                        v["flash_energy_rel"] = 1e308.into();
                    }
                    Some(v)
                })
            },
            &["fit"],
            "flash_energy_rel",
        ),
    ];
    for (name, damage, commands, needle) in sessions {
        for &command in commands {
            cases.push(case(
                "impossible inputs",
                format!("{name} ({command})"),
                Expect::Refuse(needle),
                move |dir| {
                    let session = damaged(dir, damage);
                    let c = match command {
                        "fit" => fit(dir, &session, &mesh(dir, 0.0)),
                        "mesh" => {
                            let mut c = ellipso(&["mesh"]);
                            c.arg(&session).arg("--out").arg(dir.join("m.ply"));
                            c
                        }
                        _ => {
                            let mut c = ellipso(&["export", "colmap"]);
                            c.arg(&session).arg("--out").arg(dir.join("colmap"));
                            c
                        }
                    };
                    (c, vec![session])
                },
            ));
        }
    }
    cases.push(case(
        "impossible inputs",
        "two pose events for one frame that disagree (replay)",
        Expect::Warn("pose events that disagree"),
        |dir| {
            let session = damaged(dir, |s| {
                let p = s.join("events.jsonl");
                let text = std::fs::read_to_string(&p).unwrap();
                let pose = text
                    .lines()
                    .find(|l| l.contains("\"type\":\"pose\""))
                    .unwrap();
                let mut v: serde_json::Value = serde_json::from_str(pose).unwrap();
                v["translation_camera_from_world_m"][0] = 0.3.into();
                std::fs::write(&p, format!("{text}{v}\n")).unwrap();
            });
            let mut c = ellipso(&["replay"]);
            c.arg(&session).arg("--out").arg(dir.join("r"));
            (c, vec![session])
        },
    ));
    cases
}
