//! The figures of `ellipso bench generalize` over a set of scenes, and its Markdown report
//! (docs/generalize.md); the scenes' own figures come from [`crate::generalize`].
//!
//! Contract: [`summarise`] pools as `crate::generalize`'s module doc says; every figure is NaN
//! (JSON `null`) when nothing was measured for it. [`markdown`] states the rule, the command,
//! the summaries (held-out first) and one row per scene.

use serde::Serialize;

use crate::coverage::CoverageScores;
use crate::surface::VisibleDistance;

/// One material of a generated scene as the report lists it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SceneMaterial {
    /// Name (the table row's).
    pub name: String,
    /// True η.
    pub eta: f64,
    /// Specular roughness σs.
    pub sigma_s: f64,
    /// Share of the surface area, as grown.
    pub area_fraction: f64,
}

/// One scene's result ([`crate::generalize`]'s module doc).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SceneResult {
    /// The seed.
    pub seed: u64,
    /// Whether the seed is held out (≥ 1000).
    pub held_out: bool,
    /// What the seed drew, one line.
    pub description: String,
    /// Shape kind.
    pub shape: String,
    /// Capture path (`orbit`, `hand_held`).
    pub path: String,
    /// Materials.
    pub materials: Vec<SceneMaterial>,
    /// A same-colour pair was drawn.
    pub same_colour_pair: bool,
    /// Dark object.
    pub dark_object: bool,
    /// Dark board.
    pub dark_board: bool,
    /// Why the chain failed (no figures then).
    pub error: Option<String>,
    /// Frames posed by tracking.
    pub frames_posed: usize,
    /// Frames in the session.
    pub frames: usize,
    /// Carved mesh vertices.
    pub vertices: usize,
    /// Mean over the scene's materials of |η error|, % (materials reporting η).
    pub eta_material_mean_pct: f64,
    /// 90th percentile of the same.
    pub eta_material_p90_pct: f64,
    /// Largest of the same.
    pub eta_material_worst_pct: f64,
    /// Materials with visible vertices but none reporting η.
    pub materials_unreported: usize,
    /// Coverage and accuracy ([`crate::coverage`], the scorer of `ellipso bench score`).
    pub coverage: Option<CoverageScores>,
    /// Distance of the visible fitted vertices to the true surface.
    pub visible_distance: Option<VisibleDistance>,
    /// Stage times, s: render, track, mesh, fit.
    pub times_s: [f64; 4],
}

/// The report's JSON (docs/generalize.json).
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// The rule the figures follow ([`crate::generalize`]'s module doc).
    pub rule: String,
    /// The command that made it.
    pub command: String,
    /// Image size, px.
    pub resolution_px: [u32; 2],
    /// Photos per scene.
    pub photos: u32,
    /// Every scene run, by seed.
    pub scenes: Vec<SceneResult>,
    /// Over the held-out seeds (≥ 1000); `None` when none was run.
    pub summary: Option<Summary>,
    /// Over the development seeds (< 1000); `None` when none was run.
    pub development_summary: Option<Summary>,
    /// Wall time of the whole run, s.
    pub total_s: f64,
}

/// Figures over a set of scenes (module doc of `crate::generalize`).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Summary {
    /// Scenes in the set.
    pub scenes: usize,
    /// Of those, whose chain failed (no figures).
    pub failed: usize,
    /// Their seeds.
    pub seeds: Vec<u64>,
    /// Materials with a reported η, over all scenes.
    pub materials: usize,
    /// Materials with visible vertices but no reported η.
    pub materials_unreported: usize,
    /// Mean per-material |η error|, %.
    pub eta_material_mean_pct: f64,
    /// 90th percentile of the per-material |η error|, %.
    pub eta_material_p90_pct: f64,
    /// Worst per-material |η error|, %.
    pub eta_material_worst_pct: f64,
    /// Visible vertices with a full parameter set / visible vertices, pooled.
    pub coverage_visible: f64,
    /// Smallest per-material coverage of any scene.
    pub coverage_material_min: f64,
    /// Median over scenes of the scenes' median normal error, degrees.
    pub normal_median_deg: f64,
    /// Mean over scenes of the visible vertices' mean distance to the true surface, m.
    pub visible_distance_mean_m: f64,
    /// Share of η cases within 1σ, own-fit and from-material together.
    pub sigma_within_1_fraction: f64,
    /// The same, own-fit vertices.
    pub sigma_within_1_own: f64,
    /// The same, from-material vertices.
    pub sigma_within_1_from_material: f64,
    /// η cases counted, own-fit / from-material.
    pub sigma_cases: [usize; 2],
}

/// |η error| of every material of `c` that reports η, %.
pub fn material_errors(c: &CoverageScores) -> Vec<f64> {
    c.materials
        .iter()
        .map(|m| m.eta_error_pct.abs())
        .filter(|e| e.is_finite())
        .collect()
}

/// Materials of `c` with visible vertices but no reported η.
pub fn unreported(c: &CoverageScores) -> usize {
    c.materials
        .iter()
        .filter(|m| m.visible > 0 && !m.eta_error_pct.is_finite())
        .count()
}

/// Mean, 90th percentile and largest of `v` (NaN when empty).
pub fn mean_p90_worst(v: &[f64]) -> [f64; 3] {
    if v.is_empty() {
        return [f64::NAN; 3];
    }
    let mut sorted = v.to_vec();
    [
        v.iter().sum::<f64>() / v.len() as f64,
        ellipso_model::stats::percentile(&mut sorted, 0.9),
        v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    ]
}

fn ratio(k: f64, n: f64) -> f64 {
    if n > 0.0 { k / n } else { f64::NAN }
}

/// The summary of `scenes` (module doc of `crate::generalize`).
pub fn summarise(scenes: &[&SceneResult]) -> Summary {
    let ok: Vec<(&SceneResult, &CoverageScores)> = scenes
        .iter()
        .filter_map(|s| s.coverage.as_ref().map(|c| (*s, c)))
        .collect();
    let errors: Vec<f64> = ok.iter().flat_map(|(_, c)| material_errors(c)).collect();
    let [mean, p90, worst] = mean_p90_worst(&errors);
    let visible: usize = ok.iter().map(|(_, c)| c.visible).sum();
    let full: usize = ok.iter().map(|(_, c)| c.full_set).sum();
    let mut normals: Vec<f64> = ok
        .iter()
        .map(|(_, c)| c.normal_median_deg)
        .filter(|v| v.is_finite())
        .collect();
    let distances: Vec<f64> = ok
        .iter()
        .filter_map(|(s, _)| s.visible_distance.map(|d| d.mean_m))
        .filter(|v| v.is_finite())
        .collect();
    let within = |frac: f64, n: usize| if n == 0 { 0.0 } else { frac * n as f64 };
    let (mut own_k, mut own_n, mut mat_k, mut mat_n) = (0.0, 0, 0.0, 0);
    for (_, c) in &ok {
        own_k += within(c.sigma_eta.own, c.sigma_eta.own_cases);
        own_n += c.sigma_eta.own_cases;
        mat_k += within(c.sigma_eta.from_material, c.sigma_eta.from_material_cases);
        mat_n += c.sigma_eta.from_material_cases;
    }
    Summary {
        scenes: scenes.len(),
        failed: scenes.len() - ok.len(),
        seeds: scenes.iter().map(|s| s.seed).collect(),
        materials: errors.len(),
        materials_unreported: ok.iter().map(|(_, c)| unreported(c)).sum(),
        eta_material_mean_pct: mean,
        eta_material_p90_pct: p90,
        eta_material_worst_pct: worst,
        coverage_visible: ratio(full as f64, visible as f64),
        coverage_material_min: ok
            .iter()
            .map(|(_, c)| c.coverage_material_min)
            .filter(|v| v.is_finite())
            .fold(f64::NAN, f64::min),
        normal_median_deg: if normals.is_empty() {
            f64::NAN
        } else {
            ellipso_model::stats::median(&mut normals)
        },
        visible_distance_mean_m: mean_p90_worst(&distances)[0],
        sigma_within_1_fraction: ratio(own_k + mat_k, (own_n + mat_n) as f64),
        sigma_within_1_own: ratio(own_k, own_n as f64),
        sigma_within_1_from_material: ratio(mat_k, mat_n as f64),
        sigma_cases: [own_n, mat_n],
    }
}

fn f(v: f64, digits: usize) -> String {
    if v.is_finite() {
        format!("{v:.digits$}")
    } else {
        "—".into()
    }
}

fn summary_table(s: &Summary) -> String {
    format!(
        "| figure | value |\n|---|---|\n\
         | scenes (failed) | {} ({}) |\n\
         | materials reporting η (unreported) | {} ({}) |\n\
         | η error per material: mean / p90 / worst | {} / {} / {} % |\n\
         | coverage of the visible surface (pooled) | {} |\n\
         | smallest per-material coverage | {} |\n\
         | normal error, median of the scenes' medians | {}° |\n\
         | visible vertices' distance to the true surface, mean | {} mm |\n\
         | η within 1σ: all / own fit / from material (cases) | {} / {} / {} ({} / {}) |\n",
        s.scenes,
        s.failed,
        s.materials,
        s.materials_unreported,
        f(s.eta_material_mean_pct, 2),
        f(s.eta_material_p90_pct, 2),
        f(s.eta_material_worst_pct, 2),
        f(s.coverage_visible, 3),
        f(s.coverage_material_min, 3),
        f(s.normal_median_deg, 2),
        f(s.visible_distance_mean_m * 1e3, 3),
        f(s.sigma_within_1_fraction, 3),
        f(s.sigma_within_1_own, 3),
        f(s.sigma_within_1_from_material, 3),
        s.sigma_cases[0],
        s.sigma_cases[1],
    )
}

/// The report (module doc).
pub fn markdown(r: &Report) -> String {
    let [w, h] = r.resolution_px;
    let mut md = format!(
        "# Generalisation bench\n\n\
         Written by `{}` ({} scenes, {w}×{h}, {} photos each, {:.0} s). The whole chain per \
         scene: rendered raw frames, tracked poses, carved mesh, fit, scored against the \
         scene's truth by the scorer of `ellipso bench score`.\n\n**Rule.** {}\n\n",
        r.command,
        r.scenes.len(),
        r.photos,
        r.total_s,
        r.rule
    );
    match &r.summary {
        Some(s) => {
            md += "## Held-out seeds (≥ 1000): the figures that count\n\n";
            md += &summary_table(s);
            md += "\n";
        }
        None => {
            md += "## Held-out seeds (≥ 1000)\n\nNot run in this report: no figure here \
                   counts as the bench's result.\n\n";
        }
    }
    if let Some(s) = &r.development_summary {
        md += "## Development seeds (< 1000): looked at while developing, not a result\n\n";
        md += &summary_table(s);
        md += "\n";
    }
    md += "## Scenes\n\n\
           | seed | scene | posed | coverage (material min) | η/material mean / p90 / worst % \
           | normals ° | distance mm | η within 1σ own / from material |\n\
           |---|---|---|---|---|---|---|---|\n";
    for s in &r.scenes {
        if let Some(e) = &s.error {
            md += &format!(
                "| {} | {} | failed: {} | | | | | |\n",
                s.seed,
                s.description,
                e.replace('|', "/")
            );
            continue;
        }
        let c = s.coverage.clone().unwrap_or_default();
        let d = s.visible_distance.unwrap_or_default();
        md += &format!(
            "| {} | {} | {}/{} | {} ({}) | {} / {} / {} | {} | {} | {} / {} |\n",
            s.seed,
            s.description,
            s.frames_posed,
            s.frames,
            f(c.coverage_visible, 3),
            f(c.coverage_material_min, 3),
            f(s.eta_material_mean_pct, 2),
            f(s.eta_material_p90_pct, 2),
            f(s.eta_material_worst_pct, 2),
            f(c.normal_median_deg, 2),
            f(d.mean_m * 1e3, 3),
            f(c.sigma_eta.own, 2),
            f(c.sigma_eta.from_material, 2),
        );
    }
    md += "\nPer material (η error is the median signed error over the material's visible \
           vertices that report η; coverage is their share of its visible vertices):\n\n";
    for s in r.scenes.iter().filter(|s| s.coverage.is_some()) {
        let c = s
            .coverage
            .as_ref()
            .map(|c| c.materials.clone())
            .unwrap_or_default();
        let parts: Vec<String> = c
            .iter()
            .map(|m| {
                format!(
                    "{} (η {:.3}) {} % cov {}",
                    m.name,
                    m.eta_true,
                    f(m.eta_error_pct, 2),
                    f(m.coverage, 2)
                )
            })
            .collect();
        md += &format!("- seed {}: {}\n", s.seed, parts.join(" · "));
    }
    md += "\n## How the scenes are drawn\n\n\
           Each seed draws (`ellipso_sim::generate`, deterministic per seed): a shape (bumpy \
           blob; creased solid — a rounded box with flat faces cut by one plane; blob with a \
           concave bowl), 2–8 distinct materials of the table below (η measured, cited), a \
           specular roughness σs log-uniform in 0.05–0.5, a diffuse colour from an \
           eight-colour palette, a same-colour pair (p = ½), one patch of 2–4 % of the \
           surface (p = 0.6; every patch ≥ 2 %), a dark object (p = 0.15), a dark board \
           (p = 0.2) and the capture path (spiral orbit or hand-held walk). The camera is \
           the demo's, its focal length scaled to the resolution; the sensor effects are the \
           demo's (shot and read noise, 12-bit quantisation, saturation, polariser \
           extinction).\n\n| material | η | source |\n|---|---|---|\n";
    for m in ellipso_sim::generate::materials::TABLE {
        md += &format!("| {} | {:.3} | {} |\n", m.name, m.eta, m.source);
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::coverage::{MaterialCoverage, SigmaCalibration};

    fn scene(seed: u64, errors: &[f64], visible: usize, full: usize) -> SceneResult {
        let materials = errors
            .iter()
            .map(|&e| MaterialCoverage {
                name: "m".into(),
                eta_true: 1.5,
                visible: 10,
                full_set: if e.is_finite() { 10 } else { 0 },
                eta_error_pct: e,
                ..Default::default()
            })
            .collect();
        SceneResult {
            seed,
            held_out: seed >= 1000,
            description: String::new(),
            shape: String::new(),
            path: String::new(),
            materials: vec![],
            same_colour_pair: false,
            dark_object: false,
            dark_board: false,
            error: None,
            frames_posed: 0,
            frames: 0,
            vertices: 0,
            eta_material_mean_pct: f64::NAN,
            eta_material_p90_pct: f64::NAN,
            eta_material_worst_pct: f64::NAN,
            materials_unreported: 0,
            coverage: Some(CoverageScores {
                visible,
                full_set: full,
                materials,
                normal_median_deg: seed as f64,
                coverage_material_min: 0.5,
                sigma_eta: SigmaCalibration {
                    own: 0.5,
                    own_cases: 10,
                    from_material: 1.0,
                    from_material_cases: 30,
                },
                ..Default::default()
            }),
            visible_distance: None,
            times_s: [0.0; 4],
        }
    }

    #[test]
    fn summary_pools_materials_vertices_and_cases() {
        let a = scene(1000, &[0.1, -0.3], 100, 90);
        let b = scene(1001, &[f64::NAN, 0.2], 300, 150);
        let mut failed = scene(1002, &[], 0, 0);
        failed.coverage = None;
        failed.error = Some("tracking: no frame posed".into());
        let s = summarise(&[&a, &b, &failed]);
        assert_eq!(
            (s.scenes, s.failed, s.materials, s.materials_unreported),
            (3, 1, 3, 1)
        );
        assert!((s.eta_material_mean_pct - 0.2).abs() < 1e-12);
        assert!((s.eta_material_worst_pct - 0.3).abs() < 1e-12);
        assert!((s.coverage_visible - 240.0 / 400.0).abs() < 1e-12);
        // (5 + 30) + (5 + 30) within of 80 cases.
        assert!((s.sigma_within_1_fraction - 70.0 / 80.0).abs() < 1e-12);
        assert!((s.sigma_within_1_own - 0.5).abs() < 1e-12);
        assert_eq!(s.sigma_cases, [20, 60]);
        // The project's median of an even count is its upper middle sample (`stats::median`).
        assert_eq!(s.normal_median_deg, 1001.0);
        // The names a script checks the held-out summary by (issue 42).
        let json = serde_json::to_value(&s).expect("serialises");
        for key in [
            "eta_material_mean_pct",
            "eta_material_p90_pct",
            "coverage_visible",
            "normal_median_deg",
            "sigma_within_1_fraction",
        ] {
            assert!(json[key].is_number(), "{key}");
        }
        let md = markdown(&Report {
            rule: crate::generalize::RULE.into(),
            command: "x".into(),
            resolution_px: [612, 512],
            photos: 50,
            scenes: vec![a, b, failed],
            summary: Some(s),
            development_summary: None,
            total_s: 1.0,
        });
        assert!(md.contains("figures that count") && md.contains("failed: tracking"));
    }
}
