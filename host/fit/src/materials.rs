//! Per material, what a fit says of η: the text report's per-material lines (`ellipso fit`,
//! `fit-merge`) and `fit-summary.json`'s `materials` — the summary the demo prints, without the
//! truth the demo scores against.
//!
//! Contract: a material is one of step B's clusters; a vertex belongs to the material
//! [`Completion::labels`] gives it (its own cluster where the fit identified it, the one it was
//! completed from otherwise). Over the material's *observed* vertices (the views see them,
//! [`Completion`]'s count): `own_eta` of them report an η measured from their own samples (the
//! identifiability rule reports it and it is not [`FitFlag::FromMaterial`]), and the median and
//! the 10th–90th percentiles are over those; `from_material` carry the material's values;
//! `withheld` have no full parameter set. The pooled η and its standard error are step B's
//! (`null` where the material has no pool). Nothing here changes a fit.

use crate::complete::Completion;
use crate::data::{FitFlag, VertexFit};

/// One material's η as the fit reports it (module contract).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct MaterialEta {
    /// Cluster index (step B's order).
    pub cluster: usize,
    /// The pooled η (`null`: no pool, or a weak one).
    pub eta_pooled: Option<f64>,
    /// Its standard error.
    pub eta_pooled_se: Option<f64>,
    /// Median η of the vertices reporting their own (`null` where none does).
    pub eta_median: Option<f64>,
    /// 10th and 90th percentiles of those η (`null` where none does).
    pub eta_p10_p90: Option<[f64; 2]>,
    /// Observed vertices of the material.
    pub observed: usize,
    /// Of those, reporting an η measured from their own samples.
    pub own_eta: usize,
    /// Of those, carrying the material's values.
    pub from_material: usize,
    /// Of those, without a full parameter set.
    pub withheld: usize,
    /// Share of the observed vertices with a full parameter set.
    pub coverage: f64,
}

/// The materials of a fit (module contract), in step B's order; empty without step B.
pub fn material_eta(fits: &[VertexFit], completion: Option<&Completion>) -> Vec<MaterialEta> {
    let Some(completion) = completion else {
        return Vec::new();
    };
    completion
        .materials
        .iter()
        .map(|m| {
            let mut etas: Vec<f64> = fits
                .iter()
                .zip(&completion.labels)
                .filter(|(f, label)| {
                    **label == Some(m.cluster)
                        && f.eta_identified()
                        && !f.flags.contains(&FitFlag::FromMaterial)
                })
                .map(|(f, _)| f.params.eta)
                .filter(|e| e.is_finite())
                .collect();
            let own_eta = etas.len();
            let (median, p10, p90) = (
                ellipso_model::stats::median(&mut etas),
                ellipso_model::stats::percentile(&mut etas, 0.1),
                ellipso_model::stats::percentile(&mut etas, 0.9),
            );
            MaterialEta {
                cluster: m.cluster,
                eta_pooled: m.eta,
                eta_pooled_se: m.eta_se,
                eta_median: (own_eta > 0).then_some(median),
                eta_p10_p90: (own_eta > 0).then_some([p10, p90]),
                observed: m.observed,
                own_eta,
                from_material: m.from_material,
                withheld: m.withheld,
                coverage: m.coverage,
            }
        })
        .collect()
}

/// The text report's lines: a heading, one line per material, and the whole's coverage.
pub fn report_lines(materials: &[MaterialEta], completion: &Completion) -> Vec<String> {
    let mut lines =
        vec!["η per material (step B's clusters, over the vertices the views see):".into()];
    for m in materials {
        let pooled = match (m.eta_pooled, m.eta_pooled_se) {
            (Some(e), Some(se)) => format!("pooled η {e:.4} ± {se:.4}"),
            _ => "no pooled η".into(),
        };
        let own = match (m.eta_median, m.eta_p10_p90) {
            (Some(median), Some([lo, hi])) => format!(
                "median {median:.4} over the {} vertices that report their own η (10–90 %: \
                 {lo:.4}–{hi:.4})",
                m.own_eta
            ),
            _ => "no vertex reports its own η".into(),
        };
        lines.push(format!(
            "  material {:<2} {pooled} · {own} · {} observed: {} from the material, {} withheld \
             (coverage {:.3})",
            m.cluster, m.observed, m.from_material, m.withheld, m.coverage
        ));
    }
    lines.push(format!(
        "  all         {} of {} observed vertices with a full parameter set (coverage {:.3}){}",
        completion.full_set,
        completion.observed,
        completion.coverage,
        if completion.unassigned > 0 {
            format!(
                "; {} without a material to take values from",
                completion.unassigned
            )
        } else {
            String::new()
        }
    ));
    lines
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::complete::MaterialCoverage;

    #[test]
    fn own_eta_counts_exclude_completed_and_other_materials() {
        let fit = |eta: f64, flags: Vec<FitFlag>| VertexFit {
            vertex: 0,
            params: ellipso_model::optics::pbrdf::PbrdfParams {
                eta,
                sigma_s: 0.1,
                sigma_ss: 0.2,
                rho_s: 1.0,
                rho_ss: [0.1; 3],
                rho_d: [0.5; 3],
            },
            normal_world: [0.0, 0.0, 1.0],
            std_error: [0.01; 10],
            normal_std_error_deg: 1.0,
            samples_used: 50,
            cost: 0.0,
            iterations: 1,
            flags,
            eta_unpooled: None,
            eta_prior_only: false,
            gates: Default::default(),
        };
        let fits = vec![
            fit(1.50, vec![]),
            fit(1.52, vec![]),
            fit(1.49, vec![FitFlag::FromMaterial]),
            fit(1.70, vec![]),
        ];
        let completion = Completion {
            observed: 4,
            full_set: 4,
            coverage: 1.0,
            materials: vec![
                MaterialCoverage {
                    cluster: 0,
                    eta: Some(1.505),
                    eta_se: Some(0.002),
                    observed: 3,
                    own: 2,
                    from_material: 1,
                    withheld: 0,
                    coverage: 1.0,
                    ..Default::default()
                },
                MaterialCoverage {
                    cluster: 1,
                    observed: 1,
                    own: 1,
                    coverage: 1.0,
                    ..Default::default()
                },
            ],
            labels: vec![Some(0), Some(0), Some(0), Some(1)],
            ..Default::default()
        };
        let m = material_eta(&fits, Some(&completion));
        assert_eq!(m[0].own_eta, 2);
        assert_eq!(m[0].eta_median, Some(1.52));
        assert_eq!(m[1].own_eta, 1);
        assert_eq!(m[1].eta_median, Some(1.70));
        let lines = report_lines(&m, &completion);
        assert_eq!(lines.len(), 4);
        assert!(lines[1].contains("pooled η 1.5050") && lines[1].contains("2 vertices"));
        assert!(lines[2].contains("no pooled η"), "{}", lines[2]);
        assert!(material_eta(&fits, None).is_empty());
    }
}
