//! A square sparse matrix on a fixed pattern, with faer's sparse LU: the symbolic analysis
//! (a fill-reducing column order) is done once, when the pattern is made; each numeric
//! factorisation reuses it and the workspace made with it.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::sparse::linalg::lu::{factorize_symbolic_lu, LuRef, NumericLu, SymbolicLu};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par};

use crate::error::NewtonFailure;

/// A sparse `n × n` matrix in compressed columns (rows sorted within a column) and its LU
/// factors.
pub(crate) struct SparseLu {
    n: usize,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    /// The values, one per stored entry, in the order of `row_idx`.
    pub(crate) values: Vec<f64>,
    symbolic: SymbolicLu<usize>,
    numeric: NumericLu<usize, f64>,
    mem: MemBuffer,
    factored: bool,
    /// Scratch for the singularity probe.
    probe: Vec<f64>,
}

/// Factorisations of pseudo-random values made when the matrix is created (see
/// [`SparseLu::warm_up`]).
const WARM_UP_FACTORISATIONS: usize = 3;

/// A factored matrix whose condition is at least this is singular to working precision (the
/// dense LU's pivot test, a pivot below `10⁻³ ε` of its row, in terms of the condition).
const MAX_CONDITION: f64 = 1e3 / f64::EPSILON;

/// Why a pattern could not be analysed.
#[derive(Debug)]
pub(crate) struct AnalysisFailed;

impl SparseLu {
    /// The matrix with pattern `(col_ptr, row_idx)` and zero values, analysed for LU. The
    /// pattern must be valid (checked: a bad one is an `Err`, not a panic).
    pub(crate) fn new(
        n: usize,
        col_ptr: Vec<usize>,
        row_idx: Vec<usize>,
    ) -> Result<Self, AnalysisFailed> {
        let valid = col_ptr.len() == n + 1
            && col_ptr.first() == Some(&0)
            && col_ptr.last() == Some(&row_idx.len())
            && col_ptr.windows(2).all(|w| w[0] <= w[1])
            && (0..n).all(|c| {
                let rows = &row_idx[col_ptr[c]..col_ptr[c + 1]];
                rows.windows(2).all(|w| w[0] < w[1]) && rows.iter().all(|&r| r < n)
            });
        if !valid {
            return Err(AnalysisFailed);
        }
        let pattern = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
        let symbolic =
            factorize_symbolic_lu(pattern, Default::default()).map_err(|_| AnalysisFailed)?;
        let req = StackReq::any_of(&[
            symbolic.factorize_numeric_lu_scratch::<f64>(Par::Seq, Default::default()),
            symbolic.solve_in_place_scratch::<f64>(1, Par::Seq),
        ]);
        let mem = MemBuffer::try_new(req).map_err(|_| AnalysisFailed)?;
        let nnz = row_idx.len();
        let mut lu = SparseLu {
            n,
            col_ptr,
            row_idx,
            values: vec![0.0; nnz],
            symbolic,
            numeric: NumericLu::new(),
            mem,
            factored: false,
            probe: vec![1.0; n],
        };
        lu.warm_up();
        Ok(lu)
    }

    /// Grows the factors' storage before the run. faer sizes `L` and `U` as it factors, and
    /// partial pivoting can change their fill from one factorisation to the next; a few
    /// factorisations of pseudo-random values on the pattern (pivots far from the physical
    /// ones, so more fill) leave room for what the steps need, so that they do not allocate.
    fn warm_up(&mut self) {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..WARM_UP_FACTORISATIONS {
            for v in self.values.iter_mut() {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                *v = (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            }
            // A failure here (a structurally singular pattern) shows again on the real values.
            let _ = self.factor();
        }
        self.values.fill(0.0);
        self.factored = false;
    }

    /// The order of the matrix.
    pub(crate) fn n(&self) -> usize {
        self.n
    }

    /// The largest absolute value.
    pub(crate) fn max_abs(&self) -> f64 {
        self.values.iter().fold(0.0f64, |m, x| m.max(x.abs()))
    }

    /// Factors the current values (numeric phase only).
    pub(crate) fn factor(&mut self) -> Result<(), NewtonFailure> {
        self.factored = false;
        if self.values.iter().any(|x| !x.is_finite()) {
            return Err(NewtonFailure::NonFinite);
        }
        let pattern = SymbolicSparseColMatRef::new_checked(
            self.n,
            self.n,
            &self.col_ptr,
            None,
            &self.row_idx,
        );
        let a = SparseColMatRef::new(pattern, &self.values);
        self.symbolic
            .factorize_numeric_lu(
                &mut self.numeric,
                a,
                Par::Seq,
                MemStack::new(&mut self.mem),
                Default::default(),
            )
            .map_err(|_| NewtonFailure::SingularJacobian)?;
        self.factored = true;
        // faer takes a zero pivot as it comes; a solve with a probe right-hand side finds
        // it (and a pivot negligible against the matrix, as the dense LU's test does):
        // `|A| |A⁻¹ 1|` bounds the condition number from below.
        let mut probe = std::mem::take(&mut self.probe);
        probe.fill(1.0);
        self.solve_in_place(&mut probe);
        let size = probe.iter().fold(0.0f64, |m, x| {
            if x.is_nan() {
                f64::INFINITY
            } else {
                m.max(x.abs())
            }
        });
        self.probe = probe;
        let condition = size * self.max_abs();
        if condition.is_nan() || condition >= MAX_CONDITION {
            self.factored = false;
            return Err(NewtonFailure::SingularJacobian);
        }
        Ok(())
    }

    /// Solves `A x = b` in place with the last factors; without factors, `x` becomes NaN
    /// (a caller's defect, which the solvers report as a non-finite step).
    pub(crate) fn solve_in_place(&mut self, x: &mut [f64]) {
        if !self.factored || x.len() != self.n {
            x.iter_mut().for_each(|v| *v = f64::NAN);
            return;
        }
        let lu = LuRef::new_unchecked(&self.symbolic, &self.numeric);
        let rhs = MatMut::from_column_major_slice_mut(x, self.n, 1);
        lu.solve_in_place_with_conj(Conj::No, rhs, Par::Seq, MemStack::new(&mut self.mem));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_tridiagonal_system() {
        // [[2, -1, 0], [-1, 2, -1], [0, -1, 2]] in compressed columns.
        let col_ptr = vec![0, 2, 5, 7];
        let row_idx = vec![0, 1, 0, 1, 2, 1, 2];
        let mut lu = SparseLu::new(3, col_ptr, row_idx).unwrap();
        lu.values
            .copy_from_slice(&[2.0, -1.0, -1.0, 2.0, -1.0, -1.0, 2.0]);
        lu.factor().unwrap();
        let mut x = [1.0, 0.0, 1.0];
        lu.solve_in_place(&mut x);
        for v in x {
            assert!((v - 1.0).abs() < 1e-15, "{x:?}");
        }
        lu.values.fill(0.0);
        assert_eq!(lu.factor(), Err(NewtonFailure::SingularJacobian));
        assert!(SparseLu::new(2, vec![0, 1], vec![0]).is_err());
    }
}
