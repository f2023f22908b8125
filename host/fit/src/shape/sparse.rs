//! The linear algebra of the shape update: a symmetric sparse matrix of 3×3 blocks in CSR
//! layout (one block row per vertex) and a block-Jacobi preconditioned conjugate gradient.
//!
//! Contract:
//! - [`BlockCsr::from_edges`] builds the pattern of a mesh's vertex graph: every vertex row
//!   holds its diagonal block and one block per neighbour, columns ascending. Values start at
//!   zero and are accumulated with [`BlockCsr::add_diagonal`] / [`BlockCsr::add_edge`].
//! - [`pcg`] solves `A x = b` for a symmetric positive definite `A` from `x` as given (the warm
//!   start), preconditioned by the inverses of the 3×3 diagonal blocks. It is deterministic:
//!   rows of the matrix–vector product are computed independently (parallel over rows, each row
//!   summed in column order) and every dot product is summed sequentially, so the result is
//!   bit-identical for any thread count.
//! - It stops when `‖b − A x‖ ≤ tolerance · ‖b‖` or after `max_iterations`, and reports the
//!   true (recomputed, not recursively updated) relative residual.

use rayon::prelude::*;

/// A 3×3 block, row-major.
pub(crate) type Block = [[f64; 3]; 3];

/// Below this many block rows the matrix–vector product runs on one thread (rayon's split
/// overhead dominates for small meshes).
const PARALLEL_MIN_ROWS: usize = 4096;

/// A symmetric block-sparse matrix over `n` vertices (3 unknowns each).
#[derive(Clone, Debug)]
pub(crate) struct BlockCsr {
    /// Start of each block row in `cols`/`blocks`; length `n + 1`.
    row_start: Vec<usize>,
    /// Block column per stored block, ascending within a row.
    cols: Vec<u32>,
    /// The stored blocks.
    blocks: Vec<Block>,
    /// Index of each row's diagonal block in `blocks`.
    diagonal: Vec<usize>,
}

impl BlockCsr {
    /// The pattern of the graph with `n` vertices and the undirected `edges` (`u < v`, sorted,
    /// unique, in range — the caller guarantees this).
    pub(crate) fn from_edges(n: usize, edges: &[(u32, u32)]) -> Self {
        let mut degree = vec![1usize; n];
        for &(u, v) in edges {
            degree[u as usize] += 1;
            degree[v as usize] += 1;
        }
        let mut row_start = Vec::with_capacity(n + 1);
        row_start.push(0);
        for d in &degree {
            let last = *row_start.last().unwrap_or(&0);
            row_start.push(last + d);
        }
        let total = row_start[n];
        let mut cols = vec![0u32; total];
        let mut fill: Vec<usize> = row_start[..n].to_vec();
        for (i, f) in fill.iter_mut().enumerate() {
            cols[*f] = i as u32;
            *f += 1;
        }
        for &(u, v) in edges {
            cols[fill[u as usize]] = v;
            fill[u as usize] += 1;
            cols[fill[v as usize]] = u;
            fill[v as usize] += 1;
        }
        let mut diagonal = Vec::with_capacity(n);
        for i in 0..n {
            let row = &mut cols[row_start[i]..row_start[i + 1]];
            row.sort_unstable();
            // The diagonal is always present (inserted above), so the search succeeds.
            let k = row.binary_search(&(i as u32)).unwrap_or(0);
            diagonal.push(row_start[i] + k);
        }
        Self {
            row_start,
            cols,
            blocks: vec![[[0.0; 3]; 3]; total],
            diagonal,
        }
    }

    /// Number of block rows (vertices).
    pub(crate) fn rows(&self) -> usize {
        self.diagonal.len()
    }

    /// Index of block (row, col) in `blocks`; `None` if the pattern has no such block.
    fn find(&self, row: u32, col: u32) -> Option<usize> {
        let (a, b) = (
            self.row_start[row as usize],
            self.row_start[row as usize + 1],
        );
        self.cols[a..b].binary_search(&col).ok().map(|k| a + k)
    }

    /// Adds `m` to the diagonal block of vertex `v`.
    pub(crate) fn add_diagonal(&mut self, v: u32, m: &Block) {
        let k = self.diagonal[v as usize];
        add_into(&mut self.blocks[k], m, 1.0);
    }

    /// Adds the coupling of the quadratic `(xᵤ − xᵥ)ᵀ M (xᵤ − xᵥ)` (gradient halved): `+M` on both
    /// diagonal blocks, `−M` on both off-diagonal blocks. `M` must be symmetric.
    pub(crate) fn add_edge(&mut self, u: u32, v: u32, m: &Block) {
        self.add_diagonal(u, m);
        self.add_diagonal(v, m);
        for (r, c) in [(u, v), (v, u)] {
            // Edges come from the pattern's own edge list, so the block exists.
            if let Some(k) = self.find(r, c) {
                add_into(&mut self.blocks[k], m, -1.0);
            }
        }
    }

    /// `y = A x` (`x`, `y` hold 3 entries per vertex).
    pub(crate) fn mul(&self, x: &[f64], y: &mut [f64]) {
        let row = |i: usize, out: &mut [f64]| {
            let mut acc = [0.0; 3];
            for k in self.row_start[i]..self.row_start[i + 1] {
                let c = self.cols[k] as usize;
                let b = &self.blocks[k];
                let xc = [x[3 * c], x[3 * c + 1], x[3 * c + 2]];
                for (r, a) in acc.iter_mut().enumerate() {
                    *a += b[r][0] * xc[0] + b[r][1] * xc[1] + b[r][2] * xc[2];
                }
            }
            out.copy_from_slice(&acc);
        };
        if self.rows() >= PARALLEL_MIN_ROWS {
            y.par_chunks_mut(3)
                .enumerate()
                .for_each(|(i, out)| row(i, out));
        } else {
            y.chunks_mut(3).enumerate().for_each(|(i, out)| row(i, out));
        }
    }

    /// The inverses of the diagonal blocks (block-Jacobi preconditioner); a singular block
    /// (impossible with a positive position weight) falls back to the identity.
    fn diagonal_inverses(&self) -> Vec<Block> {
        self.diagonal
            .iter()
            .map(|&k| invert_symmetric(&self.blocks[k]).unwrap_or(IDENTITY))
            .collect()
    }
}

/// The 3×3 identity.
pub(crate) const IDENTITY: Block = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// `a += s·m`.
fn add_into(a: &mut Block, m: &Block, s: f64) {
    for r in 0..3 {
        for c in 0..3 {
            a[r][c] += s * m[r][c];
        }
    }
}

/// Inverse of a 3×3 matrix by cofactors; `None` when the determinant is not safely positive
/// relative to the matrix scale (an SPD block always has a positive determinant).
fn invert_symmetric(m: &Block) -> Option<Block> {
    let c00 = m[1][1] * m[2][2] - m[1][2] * m[2][1];
    let c01 = m[1][2] * m[2][0] - m[1][0] * m[2][2];
    let c02 = m[1][0] * m[2][1] - m[1][1] * m[2][0];
    let det = m[0][0] * c00 + m[0][1] * c01 + m[0][2] * c02;
    let scale = m.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
    // Guard the division: the determinant must be positive and not lost in rounding.
    if det.is_nan() || det <= 1e-12 * scale * scale * scale {
        return None;
    }
    let inv = 1.0 / det;
    Some([
        [
            c00 * inv,
            (m[0][2] * m[2][1] - m[0][1] * m[2][2]) * inv,
            (m[0][1] * m[1][2] - m[0][2] * m[1][1]) * inv,
        ],
        [
            c01 * inv,
            (m[0][0] * m[2][2] - m[0][2] * m[2][0]) * inv,
            (m[0][2] * m[1][0] - m[0][0] * m[1][2]) * inv,
        ],
        [
            c02 * inv,
            (m[0][1] * m[2][0] - m[0][0] * m[2][1]) * inv,
            (m[0][0] * m[1][1] - m[0][1] * m[1][0]) * inv,
        ],
    ])
}

/// Sequential dot product (fixed summation order: deterministic).
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// What a [`pcg`] run did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct CgReport {
    /// Iterations run.
    pub iterations: u32,
    /// `‖b − A x‖ / ‖b‖` at the warm start (0 when `b = 0`).
    pub relative_residual_start: f64,
    /// `‖b − A x‖ / ‖b‖` at the end, recomputed from the final `x` (0 when `b = 0`).
    pub relative_residual_end: f64,
    /// The tolerance was reached.
    pub converged: bool,
}

/// Block-Jacobi preconditioned conjugate gradient for SPD `a`; `x` is the warm start and the
/// result.
pub(crate) fn pcg(
    a: &BlockCsr,
    b: &[f64],
    x: &mut [f64],
    max_iterations: u32,
    tolerance: f64,
) -> CgReport {
    let n = b.len();
    let b_norm = dot(b, b).sqrt();
    let mut r = vec![0.0; n];
    a.mul(x, &mut r);
    for (ri, bi) in r.iter_mut().zip(b) {
        *ri = bi - *ri;
    }
    // Guard: a zero right-hand side has the solution x = 0 exactly; relative residuals are
    // reported against ‖b‖ only when it is positive.
    let relative = |r: &[f64]| {
        let rn = dot(r, r).sqrt();
        if b_norm > 0.0 { rn / b_norm } else { rn }
    };
    let start = relative(&r);
    if b_norm == 0.0 {
        x.fill(0.0);
        return CgReport {
            iterations: 0,
            relative_residual_start: start,
            relative_residual_end: 0.0,
            converged: true,
        };
    }
    let inverses = a.diagonal_inverses();
    let precondition = |r: &[f64], z: &mut [f64]| {
        for ((zi, ri), m) in z.chunks_mut(3).zip(r.chunks(3)).zip(&inverses) {
            for row in 0..3 {
                zi[row] = m[row][0] * ri[0] + m[row][1] * ri[1] + m[row][2] * ri[2];
            }
        }
    };
    let mut z = vec![0.0; n];
    precondition(&r, &mut z);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let mut ap = vec![0.0; n];
    let mut iterations = 0;
    let mut converged = start <= tolerance;
    while !converged && iterations < max_iterations {
        a.mul(&p, &mut ap);
        let pap = dot(&p, &ap);
        // Guard: p·Ap ≤ 0 means A is not SPD in this direction (or p vanished); stop rather
        // than divide by it.
        if pap.is_nan() || pap <= 0.0 {
            break;
        }
        let alpha = rz / pap;
        for i in 0..n {
            x[i] += alpha * p[i];
            r[i] -= alpha * ap[i];
        }
        iterations += 1;
        if dot(&r, &r).sqrt() <= tolerance * b_norm {
            converged = true;
            break;
        }
        precondition(&r, &mut z);
        let rz_next = dot(&r, &z);
        // rz > 0 for an SPD preconditioner and r ≠ 0 (checked above).
        let beta = rz_next / rz;
        rz = rz_next;
        for i in 0..n {
            p[i] = z[i] + beta * p[i];
        }
    }
    // Report the true residual, not the recursively updated one.
    a.mul(x, &mut r);
    for (ri, bi) in r.iter_mut().zip(b) {
        *ri = bi - *ri;
    }
    let end = relative(&r);
    CgReport {
        iterations,
        relative_residual_start: start,
        relative_residual_end: end,
        converged: converged || end <= tolerance,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A path graph 0–1–2–3 with an identity anchor: A = I + L ⊗ M, solved against a dense
    /// reference.
    #[test]
    fn pcg_solves_a_small_spd_system_to_tolerance() {
        let edges = [(0u32, 1u32), (1, 2), (2, 3)];
        let mut a = BlockCsr::from_edges(4, &edges);
        for v in 0..4 {
            a.add_diagonal(v, &IDENTITY);
        }
        let m = [[2.0, 0.5, 0.0], [0.5, 1.0, 0.2], [0.0, 0.2, 3.0]];
        for &(u, v) in &edges {
            a.add_edge(u, v, &m);
        }
        let b: Vec<f64> = (0..12).map(|i| (i as f64 * 0.7).sin()).collect();
        let mut x = vec![0.0; 12];
        let report = pcg(&a, &b, &mut x, 100, 1e-12);
        assert!(report.converged, "{report:?}");
        assert!(report.relative_residual_end < 1e-11);
        assert!((report.relative_residual_start - 1.0).abs() < 1e-15);
        // Dense check of A x = b.
        let mut ax = vec![0.0; 12];
        a.mul(&x, &mut ax);
        for (l, r) in ax.iter().zip(&b) {
            assert!((l - r).abs() < 1e-10);
        }
        // Symmetry of the assembled matrix: eᵢᵀ A eⱼ = eⱼᵀ A eᵢ.
        let column = |j: usize| {
            let mut e = vec![0.0; 12];
            e[j] = 1.0;
            let mut out = vec![0.0; 12];
            a.mul(&e, &mut out);
            out
        };
        for i in 0..12 {
            let ci = column(i);
            for (j, cij) in ci.iter().enumerate() {
                assert!((cij - column(j)[i]).abs() < 1e-15);
            }
        }
    }

    #[test]
    fn block_inverse_inverts_and_rejects_singular_blocks() {
        let m = [[4.0, 1.0, 0.5], [1.0, 3.0, 0.2], [0.5, 0.2, 2.0]];
        let inv = invert_symmetric(&m).expect("SPD");
        for r in 0..3 {
            for c in 0..3 {
                let v: f64 = (0..3).map(|k| m[r][k] * inv[k][c]).sum();
                assert!((v - IDENTITY[r][c]).abs() < 1e-14);
            }
        }
        let singular = [[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert!(invert_symmetric(&singular).is_none());
    }

    #[test]
    fn zero_right_hand_side_gives_zero() {
        let mut a = BlockCsr::from_edges(2, &[(0, 1)]);
        a.add_diagonal(0, &IDENTITY);
        a.add_diagonal(1, &IDENTITY);
        let mut x = vec![1.0; 6];
        let report = pcg(&a, &[0.0; 6], &mut x, 10, 1e-10);
        assert_eq!(x, vec![0.0; 6]);
        assert_eq!(report.iterations, 0);
    }
}
