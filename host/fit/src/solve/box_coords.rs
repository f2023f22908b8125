//! The LM's box coordinates (η, ln σ_s, v, p, q; see `lm.rs`): their count and the fixed-size
//! dual-number, matrix and vector types over them, shared by the LM loop (`lm.rs`) and the
//! written-out normal equations (`jacobian.rs`).

use ellipso_model::optics::Dual;
use nalgebra::{SMatrix, SVector};

/// Box coordinates: η, ln σ_s, v (σ_ss fraction), tangent p, q.
pub(super) const N_RAW: usize = 5;
pub(super) type RawDual = Dual<N_RAW>;
pub(super) type Mat = SMatrix<f64, N_RAW, N_RAW>;
pub(super) type Vector = SVector<f64, N_RAW>;
