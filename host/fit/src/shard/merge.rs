//! The merge of a sharded fit's parts: checks that they belong together and assembles every
//! vertex's observations and step-A results in mesh order, exactly as an unsharded run holds
//! them (the caller then runs the global steps, `crate::session::finish_from_joint`).
//!
//! Checks, each failure naming the part files concerned: every part has the same shard count N
//! and each index 0…N−1 appears exactly once (missing and repeated shards are listed); session
//! hash, mesh hash, configuration hash, program version and vertex count agree; every part read
//! the same frames (same views and skipped frames); each part holds exactly its own vertices.

use std::path::PathBuf;

use super::Shard;
use super::part::PartFile;
use crate::data::{SampleSet, VertexFit};
use crate::observe::{Extraction, ObserveReport};
use crate::session::SessionFitConfig;

/// Why parts cannot be merged.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MergeError {
    /// No part given.
    #[error("no part files given")]
    NoParts,
    /// Shards are missing or repeated, or the counts differ.
    #[error("{0}")]
    Shards(String),
    /// Two parts disagree on something that must be equal: what, both parts (file and shard)
    /// with their values, and what it usually means.
    #[error("{0}")]
    Mismatch(String),
    /// A part holds something other than its own vertices.
    #[error("{0}")]
    Vertices(String),
}

/// Every vertex's observations and step-A results, assembled from the parts.
#[derive(Clone, Debug, PartialEq)]
pub struct Merged {
    /// Shard 0's part header (paths, hashes, config) with its samples and fits taken out.
    pub first: PartFile,
    /// All vertices' observations of the fitted frames, in mesh order, and the summed report.
    pub extraction: Extraction,
    /// Step A's results in mesh order.
    pub fits: Vec<VertexFit>,
    /// All vertices' held-out observations (`None`: no frame held out).
    pub held_out: Option<SampleSet>,
    /// The shards' extraction and step-A seconds, by shard index.
    pub shard_seconds: Vec<(f64, f64)>,
}

impl Merged {
    /// The fit's settings (equal in every part).
    pub fn config(&self) -> &SessionFitConfig {
        &self.first.config
    }
}

fn name(path: &std::path::Path, shard: Shard) -> String {
    format!("{} (shard {shard})", path.display())
}

/// Checks `parts` (file, contents) and assembles them (see the module doc).
pub fn merge_parts(parts: Vec<(PathBuf, PartFile)>) -> Result<Merged, MergeError> {
    if parts.is_empty() {
        return Err(MergeError::NoParts);
    }
    let slot = shard_slots(&parts)?;
    check_agreement(&parts)?;
    check_own_vertices(&parts)?;
    Ok(assemble(parts, &slot))
}

/// Checks the shard counts and indices of non-empty `parts` and returns, by shard index, which
/// part holds that shard (every slot filled).
fn shard_slots(parts: &[(PathBuf, PartFile)]) -> Result<Vec<Option<usize>>, MergeError> {
    let (first_path, first) = &parts[0];
    let n = first.shard.count;
    for (path, p) in &parts[1..] {
        if p.shard.count != n {
            return Err(MergeError::Shards(format!(
                "{} is one of {} shards but {} is one of {n}: the parts come from different runs",
                name(path, p.shard),
                p.shard.count,
                name(first_path, first.shard)
            )));
        }
    }
    // a shard index outside its count never comes from `--shard`; refused, never indexed
    if let Some((path, p)) = parts.iter().find(|(_, p)| p.shard.index >= n) {
        return Err(MergeError::Shards(format!(
            "{}: shard index {} is not below its count {n}: not a part `ellipso fit --shard` wrote",
            path.display(),
            p.shard.index
        )));
    }
    // more shards than parts: some are missing (said without a slot per shard of a huge count)
    if n as usize > parts.len() && n as usize > 4096 {
        return Err(MergeError::Shards(format!(
            "the parts are {} of {n} shards: shards missing (every shard must finish before the merge)",
            parts.len()
        )));
    }
    let mut slot: Vec<Option<usize>> = vec![None; n as usize];
    for (k, (path, p)) in parts.iter().enumerate() {
        let i = p.shard.index as usize;
        if let Some(other) = slot[i] {
            return Err(MergeError::Shards(format!(
                "shard {} is given twice: {} and {}",
                p.shard,
                parts[other].0.display(),
                path.display()
            )));
        }
        slot[i] = Some(k);
    }
    let missing: Vec<String> = (0..n)
        .filter(|&i| slot[i as usize].is_none())
        .map(|i| format!("{i}/{n}"))
        .collect();
    if !missing.is_empty() {
        let have: Vec<String> = parts
            .iter()
            .map(|(path, p)| format!("{} from {}", p.shard, path.display()))
            .collect();
        return Err(MergeError::Shards(format!(
            "shard{} {} missing (have {}): every shard must finish before the merge",
            if missing.len() > 1 { "s" } else { "" },
            missing.join(", "),
            have.join("; ")
        )));
    }
    Ok(slot)
}

/// Checks that every part of non-empty `parts` agrees with the first on hashes, version, vertex
/// count and the frames read.
fn check_agreement(parts: &[(PathBuf, PartFile)]) -> Result<(), MergeError> {
    let (first_path, first) = &parts[0];
    let agree = |what: &'static str,
                 hint: &'static str,
                 value: &dyn Fn(&PartFile) -> String|
     -> Result<(), MergeError> {
        let a_value = value(first);
        for (path, p) in &parts[1..] {
            let b_value = value(p);
            if b_value != a_value {
                return Err(MergeError::Mismatch(format!(
                    "{what} differs: {} has {a_value} but {} has {b_value} — {hint}",
                    name(first_path, first.shard),
                    name(path, p.shard)
                )));
            }
        }
        Ok(())
    };
    agree(
        "session hash",
        "the shards fitted different sessions, or the session changed between them",
        &|p| format!("{:016x}", p.session_hash),
    )?;
    agree("mesh hash", "the shards fitted different meshes", &|p| {
        format!("{:016x}", p.mesh_hash)
    })?;
    agree(
        "configuration hash",
        "the shards ran with different settings: give every shard the same flags",
        &|p| format!("{:016x}", p.config_hash),
    )?;
    agree(
        "program version",
        "every shard and the merge must run the same ellipso",
        &|p| p.program_version.clone(),
    )?;
    agree("vertex count", "the shards fitted different meshes", &|p| {
        p.mesh_vertices.to_string()
    })?;
    agree(
        "frames read",
        "a frame was unreadable in one shard but not another (shared storage trouble?): rerun \
         the shard that differs",
        &|p| frames_key(&p.report, &p.set),
    )?;
    agree(
        "held-out frames read",
        "a held-out frame was unreadable in one shard but not another: rerun the shard that \
         differs",
        &|p| {
            p.held_out
                .as_ref()
                .map_or("none".into(), |h| format!("{:?}", h.views))
        },
    )
}

/// Checks that each part of non-empty `parts` holds exactly its own shard's vertices (samples,
/// held-out samples and fits).
fn check_own_vertices(parts: &[(PathBuf, PartFile)]) -> Result<(), MergeError> {
    let vertices = parts[0].1.mesh_vertices as usize;
    for (path, p) in parts {
        let own: Vec<u32> = p.shard.vertices(vertices).map(|v| v as u32).collect();
        let holds: Vec<u32> = p.set.vertices.iter().map(|v| v.vertex).collect();
        let held_ok = p
            .held_out
            .as_ref()
            .is_none_or(|h| h.vertices.iter().map(|v| v.vertex).eq(own.iter().copied()));
        let fits_ok = p.fits.iter().map(|f| f.vertex).eq(own.iter().copied());
        if holds != own || !held_ok || !fits_ok {
            return Err(MergeError::Vertices(format!(
                "{} holds other vertices than shard {} of a {vertices}-vertex mesh owns",
                name(path, p.shard),
                p.shard
            )));
        }
    }
    Ok(())
}

/// Assembles checked `parts` in mesh order: vertex v is entry v / N of shard v % N (`slot`: the
/// part holding each shard, from [`shard_slots`]).
fn assemble(parts: Vec<(PathBuf, PartFile)>, slot: &[Option<usize>]) -> Merged {
    let n = slot.len();
    let vertices = parts[0].1.mesh_vertices as usize;
    let mut ordered: Vec<PartFile> = Vec::with_capacity(n);
    let mut parts: Vec<Option<PartFile>> = parts.into_iter().map(|(_, p)| Some(p)).collect();
    for s in slot {
        ordered.push(parts[s.expect("checked above")].take().expect("each once"));
    }
    let shard_seconds = ordered.iter().map(|p| (p.observe_s, p.joint_s)).collect();
    let mut report = ObserveReport {
        gates: Default::default(),
        samples: 0,
        narrow_admitted: 0,
        peak_bytes: 0,
        sample_bytes: 0,
        ..ordered[0].report.clone()
    };
    for p in &ordered {
        report.gates.add(&p.report.gates);
        report.samples += p.report.samples;
        report.narrow_admitted += p.report.narrow_admitted;
        report.sample_bytes += p.report.sample_bytes;
        report.peak_bytes = report.peak_bytes.max(p.report.peak_bytes);
    }
    let mut set = SampleSet {
        views: ordered[0].set.views.clone(),
        colour: ordered[0].set.colour,
        vertices: Vec::with_capacity(vertices),
        rings: Vec::new(),
    };
    let mut held = ordered[0].held_out.as_ref().map(|h| SampleSet {
        views: h.views.clone(),
        colour: h.colour,
        vertices: Vec::with_capacity(vertices),
        rings: Vec::new(),
    });
    let mut fits = Vec::with_capacity(vertices);
    let mut samples: Vec<_> = ordered
        .iter_mut()
        .map(|p| std::mem::take(&mut p.set.vertices).into_iter())
        .collect();
    let mut part_fits: Vec<_> = ordered
        .iter_mut()
        .map(|p| std::mem::take(&mut p.fits).into_iter())
        .collect();
    let mut held_parts: Vec<_> = ordered
        .iter_mut()
        .map(|p| {
            p.held_out
                .as_mut()
                .map(|h| std::mem::take(&mut h.vertices))
                .unwrap_or_default()
                .into_iter()
        })
        .collect();
    for v in 0..vertices {
        let s = v % n;
        set.vertices
            .push(samples[s].next().expect("counts checked above"));
        fits.push(part_fits[s].next().expect("counts checked above"));
        if let Some(h) = held.as_mut() {
            h.vertices
                .push(held_parts[s].next().expect("counts checked above"));
        }
    }
    let mut first = ordered.swap_remove(0);
    first.held_out = None;
    Merged {
        first,
        extraction: Extraction {
            samples: set,
            report,
        },
        fits,
        held_out: held,
        shard_seconds,
    }
}

/// What every shard must have read alike: the views and the skipped frames.
fn frames_key(report: &ObserveReport, set: &SampleSet) -> String {
    format!(
        "{} views (frames {:?}), {} skipped {:?}",
        set.views.len(),
        set.views.iter().map(|v| v.frame_id).collect::<Vec<_>>(),
        report.skipped.len(),
        report
            .skipped
            .iter()
            .map(|s| s.frame_id)
            .collect::<Vec<_>>()
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shard::part::tests::part;

    fn parts(n: u32) -> Vec<(PathBuf, PartFile)> {
        (0..n)
            .map(|i| {
                (
                    PathBuf::from(format!("p{i}.part")),
                    part(Shard::new(i, n).unwrap()),
                )
            })
            .collect()
    }

    #[test]
    fn a_shard_index_outside_its_count_is_refused_not_indexed() {
        let mut given = parts(2);
        given[1].1.shard = Shard { index: 7, count: 2 };
        let e = merge_parts(given).unwrap_err().to_string();
        assert!(
            e.contains("p1.part: shard index 7 is not below its count 2"),
            "{e}"
        );
        // a count no run has: refused without a slot per shard
        let mut given = parts(1);
        given[0].1.shard = Shard {
            index: 0,
            count: u32::MAX,
        };
        let e = merge_parts(given).unwrap_err().to_string();
        assert!(e.contains("shards missing"), "{e}");
    }

    #[test]
    fn parts_in_any_order_assemble_in_mesh_order() {
        let whole = part(Shard::ALL);
        let mut p = parts(3);
        p.reverse();
        let m = merge_parts(p).unwrap();
        assert_eq!(m.extraction.samples, whole.set);
        assert_eq!(m.fits, whole.fits);
        assert_eq!(m.shard_seconds.len(), 3);
    }

    #[test]
    fn missing_and_repeated_shards_are_named() {
        let mut p = parts(4);
        p.remove(2);
        p.remove(0);
        let e = merge_parts(p).unwrap_err().to_string();
        assert!(e.contains("shards 0/4, 2/4 missing"), "{e}");
        assert!(e.contains("1/4 from p1.part"), "{e}");
        let mut p = parts(2);
        p.push(p[1].clone());
        let e = merge_parts(p).unwrap_err().to_string();
        assert!(e.contains("shard 1/2 is given twice"), "{e}");
        let mut p = parts(2);
        p[1].1.shard = Shard::new(1, 3).unwrap();
        let e = merge_parts(p).unwrap_err().to_string();
        assert!(
            e.contains("one of 3 shards") && e.contains("one of 2"),
            "{e}"
        );
        assert_eq!(merge_parts(vec![]), Err(MergeError::NoParts));
    }

    #[test]
    fn disagreeing_parts_are_refused_naming_both() {
        type Spoil = fn(&mut PartFile);
        let cases: Vec<(&str, Spoil)> = vec![
            ("session hash", |p| p.session_hash = 99),
            ("mesh hash", |p| p.mesh_hash = 99),
            ("configuration hash", |p| p.config_hash ^= 1),
            ("program version", |p| p.program_version = "other".into()),
            ("frames read", |p| p.set.views[0].frame_id = 8),
        ];
        for (what, spoil) in cases {
            let mut p = parts(3);
            spoil(&mut p[2].1);
            let e = merge_parts(p).unwrap_err().to_string();
            assert!(e.starts_with(what), "{what}: {e}");
            assert!(
                e.contains("p0.part (shard 0/3)") && e.contains("p2.part (shard 2/3)"),
                "{e}"
            );
        }
    }

    #[test]
    fn a_part_with_foreign_vertices_is_refused() {
        let mut p = parts(2);
        p[1].1.set.vertices[0].vertex = 0;
        let e = merge_parts(p).unwrap_err().to_string();
        assert!(
            e.contains("p1.part (shard 1/2) holds other vertices"),
            "{e}"
        );
    }
}
