//! One forward evaluation of a whole sample set at given fits (f64, no derivatives, no
//! weights): the unit of work the benchmark divides fit time by ([`forward_cost_all`]).
//!
//! Contract: samples whose view index is out of range, whose geometry is degenerate or that the
//! normal makes back-facing are skipped and not counted; per-vertex sums are added in vertex
//! order, so the result does not depend on the thread count.

use rayon::prelude::*;

use super::super::data::{SampleSet, VertexFit};
use super::super::model::{SampleFrames, unit_sample_at};

/// One forward evaluation of the whole set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForwardCost {
    /// Σ over observations of the squared differences of I^d, I^s, I^α (model units).
    pub sum_squared: f64,
    /// Observations evaluated (samples × colour channels).
    pub observations: u64,
}

/// Evaluates the model (f64, no derivatives) once for every observation of `set` at `fits`
/// (indexed like `set.vertices`): the unit of work the benchmark divides fit time by. Per-vertex
/// sums are added in vertex order, so the result does not depend on the thread count.
pub fn forward_cost_all(set: &SampleSet, fits: &[VertexFit]) -> ForwardCost {
    let channels = if set.colour { 3 } else { 1 };
    let per_vertex: Vec<(f64, u64)> = set
        .vertices
        .par_iter()
        .zip(fits.par_iter())
        .map(|(v, fit)| {
            let p = &fit.params;
            let mut sum = 0.0;
            let mut count = 0u64;
            for s in &v.samples {
                let Some(view) = set.views.get(s.view as usize) else {
                    continue;
                };
                let Some(f) = SampleFrames::new(view, v.position_world) else {
                    continue;
                };
                let Some(u) = unit_sample_at(&f, fit.normal_world, p.eta, p.sigma_s, p.sigma_ss)
                else {
                    continue;
                };
                for c in 0..channels {
                    let pred = u.predict(p.rho_d[c], p.rho_ss[c], p.rho_s);
                    for (pk, ok) in pred.iter().zip(s.channels[c]) {
                        let d = pk - f64::from(ok);
                        sum += d * d;
                    }
                    count += 1;
                }
            }
            (sum, count)
        })
        .collect();
    let mut out = ForwardCost {
        sum_squared: 0.0,
        observations: 0,
    };
    for (s, c) in per_vertex {
        out.sum_squared += s;
        out.observations += c;
    }
    out
}
