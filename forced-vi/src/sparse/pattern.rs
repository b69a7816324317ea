//! Patterns: the node pattern, recorded once per run from the model's first evaluation, and
//! the pattern of the step Jacobian (DESIGN §3) that it induces.
//!
//! The unknowns are ordered coordinate-major, the stages of one coordinate together:
//! unknown `(b, m)` (coordinate `b`, control point `m = 1 … s − 1`) is column
//! `b (s − 1) + m − 1`, and residual `(a, j)` (`j = 0 … s − 2`) is row `a (s − 1) + j`. Node
//! entry `(a, b)` then fills, for every `m`, a run of `s − 1` consecutive rows of column
//! `(b, m)`, so a chain's step matrix is banded.

use crate::error::Error;
use crate::model::{NodePattern, NodeSink, SparseNode};

/// Records the node pattern: one evaluation of `node` at `(t, q, v)` in recording mode.
///
/// A kernel that writes outside `n` is [`Error::InvalidModel`]; so is a model whose
/// gradient is not finite there, or whose pattern misses a diagonal entry (its mass matrix
/// would be singular).
pub(crate) fn record_node_pattern(
    node: &dyn SparseNode,
    t: f64,
    q: &[f64],
    v: &[f64],
) -> Result<NodePattern, Error> {
    let n = node.dof();
    let invalid = |message: String| Error::InvalidModel { message };
    if q.len() != n || v.len() != n {
        return Err(invalid(format!(
            "the sparse node kernels have {n} degrees of freedom, the model {}",
            q.len()
        )));
    }
    let (mut lq_f, mut lv) = (vec![0.0; n], vec![0.0; n]);
    let mut pairs = Vec::new();
    let mut sink = NodeSink::record(&mut lq_f, &mut lv, &mut pairs);
    node.eval(t, q, v, &mut sink);
    let outside = sink.outside();
    if outside || pairs.iter().any(|&(r, c)| r >= n || c >= n) {
        return Err(invalid(
            "the sparse node kernels write outside the model's coordinates".into(),
        ));
    }
    let pattern = NodePattern::from_pairs(n, pairs);
    if let Some(a) = (0..n).find(|&a| pattern.position(a, a).is_none()) {
        return Err(invalid(format!(
            "the sparse node pattern has no diagonal entry for coordinate {a}"
        )));
    }
    Ok(pattern)
}

/// Column-compressed form of a node pattern: `csc_of[k]` is where CSR entry `k` goes.
pub(crate) struct Transposed {
    pub(crate) col_ptr: Vec<usize>,
    pub(crate) row_idx: Vec<usize>,
    pub(crate) csc_of: Vec<usize>,
}

/// A pattern in compressed columns (rows sorted within each column).
pub(crate) fn transpose(pattern: &NodePattern) -> Transposed {
    let n = pattern.width();
    let mut col_ptr = vec![0usize; n + 1];
    for (_, c) in pattern.entries() {
        col_ptr[c + 1] += 1;
    }
    for c in 0..n {
        col_ptr[c + 1] += col_ptr[c];
    }
    let mut next = col_ptr.clone();
    let mut row_idx = vec![0usize; pattern.nnz()];
    let mut csc_of = vec![0usize; pattern.nnz()];
    // Rows are visited in order, so each column's rows come out sorted.
    for (k, (r, c)) in pattern.entries().enumerate() {
        row_idx[next[c]] = r;
        csc_of[k] = next[c];
        next[c] += 1;
    }
    Transposed {
        col_ptr,
        row_idx,
        csc_of,
    }
}

/// The step Jacobian's pattern for `s` control points.
///
/// A constrained model (DESIGN §11) adds `m (s − 1)` unknowns after the increments, the
/// multipliers `ŵ_j = h² λ_j` (`j = 0 … s − 2`), unknown `(k, j)` at `n (s − 1) + k (s − 1) + j`,
/// and as many rows, `g_k(x_j)` (`j = 1 … s − 1`) at `n (s − 1) + k (s − 1) + j − 1`.
pub(crate) struct StepPattern {
    /// Unknowns: `(n + m)(s − 1)`.
    pub(crate) dim: usize,
    pub(crate) col_ptr: Vec<usize>,
    pub(crate) row_idx: Vec<usize>,
    /// `base[k (s − 1) + m − 1]`: where node entry `k = (a, b)` puts its row `(a, 0)` in
    /// column `(b, m)`; row `(a, j)` follows at `+ j`.
    pub(crate) base: Vec<usize>,
    /// `g_rows[e (s − 1) + m − 1]`: where entry `e = (k, b)` of `G(x_m)` sits, in row
    /// `g_k(x_m)` of column `(b, m)`.
    pub(crate) g_rows: Vec<usize>,
    /// `g_cols[e (s − 1) + j]`: where entry `e = (k, a)` of `G(x_j)ᵀ` sits, in row `(a, j)`
    /// of the multiplier column `(k, j)`.
    pub(crate) g_cols: Vec<usize>,
}

impl StepPattern {
    /// The pattern of `∂G_j/∂x_m` for every node entry and every `j`, `m`; with the
    /// constraint Jacobian's pattern `g` (`m × n`), the constraint rows and columns too.
    pub(crate) fn new(pattern: &NodePattern, s: usize, g: Option<&NodePattern>) -> StepPattern {
        let (n, s1) = (pattern.n(), s.saturating_sub(1).max(1));
        let m = g.map_or(0, |g| g.n());
        let tr = transpose(pattern);
        let g_tr = g.map(transpose);
        let g_nnz = g.map_or(0, |g| g.nnz());
        let nz = n * s1;
        let dim = (n + m) * s1;
        let nnz = (pattern.nnz() * s1 + 2 * g_nnz) * s1;
        let mut col_ptr = Vec::with_capacity(dim + 1);
        let mut row_idx = Vec::with_capacity(nnz);
        let mut base = vec![0usize; pattern.nnz() * s1];
        let mut g_rows = vec![0usize; g_nnz * s1];
        let mut g_cols = vec![0usize; g_nnz * s1];
        // CSR index of each CSC entry, to find `k` from a column walk.
        let csr_of = |t: &Transposed| {
            let mut out = vec![0usize; t.csc_of.len()];
            for (k, &p) in t.csc_of.iter().enumerate() {
                out[p] = k;
            }
            out
        };
        let node_csr = csr_of(&tr);
        let g_csr = g_tr.as_ref().map(csr_of).unwrap_or_default();
        col_ptr.push(0);
        for b in 0..n {
            for mm in 0..s1 {
                let range = tr.col_ptr[b]..tr.col_ptr[b + 1];
                for (&a, &k) in tr.row_idx[range.clone()].iter().zip(&node_csr[range]) {
                    base[k * s1 + mm] = row_idx.len();
                    row_idx.extend((0..s1).map(|j| a * s1 + j));
                }
                // The constraint rows `g_k(x_{mm+1})`, which read `x_{mm+1}` alone.
                if let Some(gt) = &g_tr {
                    let range = gt.col_ptr[b]..gt.col_ptr[b + 1];
                    for (&k, &e) in gt.row_idx[range.clone()].iter().zip(&g_csr[range]) {
                        g_rows[e * s1 + mm] = row_idx.len();
                        row_idx.push(nz + k * s1 + mm);
                    }
                }
                col_ptr.push(row_idx.len());
            }
        }
        if let Some(g) = g {
            let mut e = 0;
            for k in 0..m {
                let cols = g.row(k);
                for j in 0..s1 {
                    for (i, &a) in cols.iter().enumerate() {
                        g_cols[(e + i) * s1 + j] = row_idx.len();
                        row_idx.push(a * s1 + j);
                    }
                    col_ptr.push(row_idx.len());
                }
                e += cols.len();
            }
        }
        StepPattern {
            dim,
            col_ptr,
            row_idx,
            base,
            g_rows,
            g_cols,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_pattern_of_a_tridiagonal_node_pattern_is_banded() {
        let n: usize = 5;
        let pairs = (0..n)
            .flat_map(|a| [(a, a), (a, a.saturating_sub(1)), (a, (a + 1).min(n - 1))])
            .collect();
        let node = NodePattern::from_pairs(n, pairs);
        let sp = StepPattern::new(&node, 3, None);
        assert_eq!(sp.dim, 10);
        assert_eq!(sp.row_idx.len(), node.nnz() * 4);
        for c in 0..sp.dim {
            let rows = &sp.row_idx[sp.col_ptr[c]..sp.col_ptr[c + 1]];
            assert!(rows.windows(2).all(|w| w[0] < w[1]));
            // Bandwidth 3 (s − 1) − 1 at most.
            assert!(rows.iter().all(|&r| r.abs_diff(c) < 3 * 2), "{c}: {rows:?}");
        }
        // Entry (a, b) = (2, 1), m = 2: column 1·2 + 1, rows 4 and 5.
        let k = node.position(2, 1).unwrap();
        let at = sp.base[k * 2 + 1];
        assert_eq!(&sp.row_idx[at..at + 2], &[4, 5]);
        assert!(at >= sp.col_ptr[3] && at < sp.col_ptr[4]);
    }
}
