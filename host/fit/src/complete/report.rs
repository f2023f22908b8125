//! What a completion says: its per-material report lines and its one-line progress message.

use super::Completion;

impl Completion {
    /// The per-material coverage as report lines (material η, observed vertices and how they
    /// were answered), then the whole.
    pub fn report_lines(&self) -> Vec<String> {
        let mut lines =
            vec!["materials (step B's clusters) over the surface the views see:".to_string()];
        for m in &self.materials {
            let eta = match (m.eta, m.eta_se, m.eta_withheld_se) {
                (Some(e), Some(se), _) => format!("η {e:.4} ± {se:.4}"),
                (_, _, Some([se, pull])) => format!(
                    "η withheld (its pool's σ {se:.3}, of which the default prior's possible \
                     pull {pull:.3}, is above what a vertex may report)"
                ),
                _ => "η not identified".to_string(),
            };
            lines.push(format!(
                "  material {:<2} {eta} · {} vertices observed: {} from their own samples, {} \
                 from the material, {} withheld (coverage {:.3})",
                m.cluster, m.observed, m.own, m.from_material, m.withheld, m.coverage
            ));
        }
        lines.push(format!(
            "  all         {} of {} observed vertices with a full parameter set (coverage {:.3}){}",
            self.full_set,
            self.observed,
            self.coverage,
            if self.unassigned > 0 {
                format!(
                    "; {} without a material to take values from",
                    self.unassigned
                )
            } else {
                String::new()
            }
        ));
        lines
    }

    /// One line for progress output.
    pub fn describe(&self) -> String {
        format!(
            "completion: {} vertices the views see but their samples do not identify took their \
             material's values ({} with their own ρd), {} their material's η; {} of all these lie \
             between materials of different η their data cannot tell apart (η's σ widened){}{}{}",
            self.completed,
            self.own_rho_d,
            self.eta_from_material,
            self.material_open,
            if self.eta_local > 0 {
                format!(
                    "; {} whose surroundings' own samples contradict their material's η took \
                     those samples' η (σ spanning both)",
                    self.eta_local
                )
            } else {
                String::new()
            },
            if self.eta_withheld > 0 {
                format!(
                    "; {} without η, their material having none identified",
                    self.eta_withheld
                )
            } else {
                String::new()
            },
            if self.unassigned > 0 {
                format!("; {} had no material to take it from", self.unassigned)
            } else {
                String::new()
            }
        )
    }
}
