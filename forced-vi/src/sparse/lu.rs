//! A square sparse matrix on a fixed pattern and its LU factors, with no allocation per
//! factorisation once the matrix is made.
//!
//! faer's sparse LU with partial pivoting finds the structure of its factors while it factors
//! (the pivots decide the fill). Its supernodal numeric phase allocates as it goes: each call
//! collects a fresh list of contribution blocks and, per supernode, allocates the block, its
//! column list and its activity marks (337 allocations per factorisation of a 32 × 32
//! lattice's lobatto3 step matrix, about 1300 at 64 × 64). Its simplicial phase keeps its
//! storage but is 4 to 7 times slower on 2-D patterns, and no warm-up or option removes the
//! supernodal allocations.
//!
//! So the numeric factorisation here is our own, on a structure fixed by the analysis: the
//! pattern of `A + Aᵀ` is ordered by faer's AMD and split into supernodes by faer's symbolic
//! Cholesky, whose `L` holds the structure of `L` and of `Uᵀ` when rows are exchanged only
//! inside a supernode's diagonal block. A supernode is one panel, its diagonal block and the
//! rows of `U` right of it, factored by one call of faer's dense LU with partial pivoting,
//! and the columns of `L` below it; the updates from earlier supernodes are dense products
//! gathered left-looking, in buffers sized by the analysis.
//!
//! Pivots restricted to the diagonal blocks can grow the factors where partial pivoting would
//! not. The singularity probe (a solve of `A x = 1`) measures it: a probe whose backward
//! error exceeds [`MAX_BACKWARD_ERROR`], or a zero pivot, sends the factorisation to faer's
//! sparse LU with full partial pivoting (which allocates), and the next few factorisations
//! too (see [`SparseLu::factor`]). The step matrices of the schemes (mass over `h` in each
//! coordinate's dense diagonal block) have not needed it, soft or stiff (`h² k / m` from
//! `10⁻⁴` to `100` on the 2-D lattice).
//!
//! After [`SparseLu::new`], `factor` and `solve_in_place` allocate nothing (but for the first
//! factorisation on another thread, where faer's dense kernels may set up a buffer) unless
//! faer's LU is needed.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::sparse::linalg::lu::{LuRef, NumericLu, SymbolicLu, factorize_symbolic_lu};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par};

use super::supernodal::Supernodal;
use crate::error::NewtonFailure;

/// A sparse `n × n` matrix in compressed columns (rows sorted within a column) and its LU
/// factors.
pub(crate) struct SparseLu {
    n: usize,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    /// The values, one per stored entry, in the order of `row_idx`.
    pub(crate) values: Vec<f64>,
    /// The factorisation on the fixed structure (`None` if the analysis could not make one).
    supernodal: Option<Supernodal>,
    /// faer's LU with partial pivoting, made when first needed.
    general: Option<Box<General>>,
    /// Which factors hold the current values.
    factors: Factors,
    /// Factorisations left to faer before the supernodal one is tried again, and the length
    /// of the last such wait.
    skip: u32,
    backoff: u32,
    /// Scratch for the singularity probe: its solution, residual and `|A| |x|`.
    probe: Vec<f64>,
    residual: Vec<f64>,
    scale: Vec<f64>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Factors {
    None,
    Supernodal,
    General,
}

/// A factored matrix whose condition is at least this is singular to working precision (the
/// dense LU's pivot test, a pivot below `10⁻³ ε` of its row, in terms of the condition).
const MAX_CONDITION: f64 = 1e3 / f64::EPSILON;

/// The largest backward error of the probe solve, `‖1 − A x‖∞ / (‖|A| |x|‖∞ + 1)`, for
/// which the supernodal factors are kept (about `5·10³ ε`; a stable LU gives `ε` to
/// `100 ε`).
const MAX_BACKWARD_ERROR: f64 = 1e-12;

/// The longest run of factorisations left to faer after the supernodal one was declined.
const MAX_BACKOFF: u32 = 64;

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
        let supernodal = Supernodal::new(n, &col_ptr, &row_idx);
        let general = match supernodal {
            Some(_) => None,
            None => Some(Box::new(General::new(n, &col_ptr, &row_idx)?)),
        };
        let nnz = row_idx.len();
        let mut lu = SparseLu {
            n,
            col_ptr,
            row_idx,
            values: vec![0.0; nnz],
            supernodal,
            general,
            factors: Factors::None,
            skip: 0,
            backoff: 0,
            probe: vec![0.0; n],
            residual: vec![0.0; n],
            scale: vec![0.0; n],
        };
        lu.warm_up();
        Ok(lu)
    }

    /// Factors and solves once (the identity on the pattern's diagonal) before the run: the
    /// dense kernels may set up buffers of their own on their first call.
    fn warm_up(&mut self) {
        for c in 0..self.n {
            let rows = &self.row_idx[self.col_ptr[c]..self.col_ptr[c + 1]];
            if let Ok(k) = rows.binary_search(&c) {
                self.values[self.col_ptr[c] + k] = 1.0;
            }
        }
        // A failure here (a diagonal outside the pattern) shows again on the real values.
        let _ = self.factor();
        self.values.fill(0.0);
        self.factors = Factors::None;
        (self.skip, self.backoff) = (0, 0);
    }

    /// A solver for a matrix of the same pattern (zero values).
    pub(crate) fn with_same_pattern(&self) -> Result<SparseLu, AnalysisFailed> {
        SparseLu::new(self.n, self.col_ptr.clone(), self.row_idx.clone())
    }

    /// A solver for the transposed matrix (zero values), and where each of this matrix's
    /// values goes in it ([`SparseLu::fill_transposed`]).
    pub(crate) fn transposed(&self) -> Result<(SparseLu, Vec<usize>), AnalysisFailed> {
        let n = self.n;
        let mut col_ptr = vec![0usize; n + 1];
        for &r in &self.row_idx {
            col_ptr[r + 1] += 1;
        }
        for c in 0..n {
            col_ptr[c + 1] += col_ptr[c];
        }
        let mut next = col_ptr.clone();
        let mut row_idx = vec![0usize; self.row_idx.len()];
        let mut map = vec![0usize; self.row_idx.len()];
        // Columns are visited in order, so the rows of each transposed column come out
        // sorted.
        for c in 0..n {
            let range = self.col_ptr[c]..self.col_ptr[c + 1];
            for (slot, &r) in map[range.clone()].iter_mut().zip(&self.row_idx[range]) {
                row_idx[next[r]] = c;
                *slot = next[r];
                next[r] += 1;
            }
        }
        Ok((SparseLu::new(n, col_ptr, row_idx)?, map))
    }

    /// Writes the transpose of this matrix's values into `other` (made by
    /// [`SparseLu::transposed`] with `map`).
    pub(crate) fn fill_transposed(&self, other: &mut SparseLu, map: &[usize]) {
        for (&x, &k) in self.values.iter().zip(map) {
            other.values[k] = x;
        }
    }

    /// The order of the matrix.
    pub(crate) fn n(&self) -> usize {
        self.n
    }

    /// The largest absolute value.
    pub(crate) fn max_abs(&self) -> f64 {
        self.values.iter().fold(0.0f64, |m, x| m.max(x.abs()))
    }

    /// `max_b |J_ab|` for each row `a` into `out`, with the current values.
    pub(crate) fn row_max(&self, out: &mut [f64]) {
        out.fill(0.0);
        for (&r, &x) in self.row_idx.iter().zip(&self.values) {
            if let Some(o) = out.get_mut(r) {
                let a = x.abs();
                *o = if a > *o { a } else { *o };
            }
        }
    }

    /// Factors the current values (numeric phase only).
    ///
    /// The supernodal factorisation is tried first; when it is declined (a zero pivot, an
    /// inaccurate probe, or a probe that finds the matrix singular), faer's LU factors these
    /// values and the next 1, 2, 4, … (up to [`MAX_BACKOFF`]) factorisations, so that a
    /// matrix that needs partial pivoting does not pay for both each time.
    pub(crate) fn factor(&mut self) -> Result<(), NewtonFailure> {
        self.factors = Factors::None;
        if self.values.iter().any(|x| !x.is_finite()) {
            return Err(NewtonFailure::NonFinite);
        }
        if self.skip > 0 {
            self.skip -= 1;
        } else if let Some(sn) = &mut self.supernodal {
            if sn.factor(&self.values) {
                self.factors = Factors::Supernodal;
                let size = self.probe_solve();
                // A singular verdict is faer's to give, as before.
                if size.is_finite()
                    && self.probe_backward_error() <= MAX_BACKWARD_ERROR
                    && self.condition_test(size).is_ok()
                {
                    self.backoff = 0;
                    return Ok(());
                }
            }
            self.backoff = (2 * self.backoff).clamp(1, MAX_BACKOFF);
            self.skip = self.backoff;
        }
        if self.general.is_none() {
            let general = General::new(self.n, &self.col_ptr, &self.row_idx)
                .map_err(|_| NewtonFailure::SingularJacobian)?;
            self.general = Some(Box::new(general));
        }
        let Some(general) = self.general.as_mut() else {
            return Err(NewtonFailure::SingularJacobian);
        };
        general.factor(self.n, &self.col_ptr, &self.row_idx, &self.values)?;
        self.factors = Factors::General;
        let size = self.probe_solve();
        self.condition_test(size)
    }

    /// Solves `A x = 1` into `probe` with the current factors; returns `‖x‖∞` (infinite if
    /// `x` has a NaN).
    fn probe_solve(&mut self) -> f64 {
        let mut probe = std::mem::take(&mut self.probe);
        probe.fill(1.0);
        self.solve_in_place(&mut probe);
        self.probe = probe;
        self.probe.iter().fold(0.0f64, |m, x| {
            if x.is_nan() {
                f64::INFINITY
            } else {
                m.max(x.abs())
            }
        })
    }

    /// `‖1 − A x‖∞ / (‖|A| |x|‖∞ + 1)` for the probe's solution `x`.
    fn probe_backward_error(&mut self) -> f64 {
        self.residual.fill(1.0);
        self.scale.fill(0.0);
        for (c, &x) in self.probe.iter().enumerate() {
            let range = self.col_ptr[c]..self.col_ptr[c + 1];
            for (&r, &a) in self.row_idx[range.clone()].iter().zip(&self.values[range]) {
                self.residual[r] -= a * x;
                self.scale[r] += (a * x).abs();
            }
        }
        let max = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let error = max(&self.residual) / (max(&self.scale) + 1.0);
        if error.is_nan() { f64::INFINITY } else { error }
    }

    /// A zero pivot may come through (faer takes one as it comes); the probe finds it (and a
    /// pivot negligible against the matrix, as the dense LU's test does): `|A| |A⁻¹ 1|`
    /// bounds the condition number from below.
    fn condition_test(&mut self, probe_size: f64) -> Result<(), NewtonFailure> {
        let condition = probe_size * self.max_abs();
        if condition.is_nan() || condition >= MAX_CONDITION {
            self.factors = Factors::None;
            return Err(NewtonFailure::SingularJacobian);
        }
        Ok(())
    }

    /// Solves `A x = b` in place with the last factors; without factors, `x` becomes NaN
    /// (a caller's defect, which the solvers report as a non-finite step).
    pub(crate) fn solve_in_place(&mut self, x: &mut [f64]) {
        if x.len() != self.n {
            x.iter_mut().for_each(|v| *v = f64::NAN);
            return;
        }
        match (self.factors, &mut self.supernodal, &mut self.general) {
            (Factors::Supernodal, Some(sn), _) => sn.solve_in_place(x),
            (Factors::General, _, Some(general)) => general.solve_in_place(x),
            _ => x.iter_mut().for_each(|v| *v = f64::NAN),
        }
    }

    /// [`Self::solve_in_place`] for [`super::supernodal::BLOCK`] right-hand sides,
    /// interleaved (entry `i` of right-hand side `b` at `x[i * BLOCK + b]`); the same results
    /// as one solve each.
    pub(crate) fn solve_block_in_place(&mut self, x: &mut [f64]) {
        use super::supernodal::BLOCK;
        if x.len() != self.n * BLOCK {
            x.iter_mut().for_each(|v| *v = f64::NAN);
            return;
        }
        match (self.factors, &mut self.supernodal, &mut self.general) {
            (Factors::Supernodal, Some(sn), _) => sn.solve_block_in_place(x),
            (Factors::General, _, Some(general)) => {
                // One column at a time, through the probe's scratch.
                let col = &mut self.probe;
                col.resize(self.n, 0.0);
                for b in 0..BLOCK {
                    for (c, v) in col.iter_mut().zip(x.iter().skip(b).step_by(BLOCK)) {
                        *c = *v;
                    }
                    general.solve_in_place(col);
                    for (v, c) in x.iter_mut().skip(b).step_by(BLOCK).zip(col.iter()) {
                        *v = *c;
                    }
                }
            }
            _ => x.iter_mut().for_each(|v| *v = f64::NAN),
        }
    }
}

/// faer's sparse LU with partial pivoting (column order by COLAMD, structure found as it
/// factors).
struct General {
    symbolic: SymbolicLu<usize>,
    numeric: NumericLu<usize, f64>,
    mem: MemBuffer,
}

impl General {
    fn new(n: usize, col_ptr: &[usize], row_idx: &[usize]) -> Result<Self, AnalysisFailed> {
        let pattern = SymbolicSparseColMatRef::new_checked(n, n, col_ptr, None, row_idx);
        let symbolic =
            factorize_symbolic_lu(pattern, Default::default()).map_err(|_| AnalysisFailed)?;
        let req = StackReq::any_of(&[
            symbolic.factorize_numeric_lu_scratch::<f64>(Par::Seq, Default::default()),
            symbolic.solve_in_place_scratch::<f64>(1, Par::Seq),
        ]);
        let mem = MemBuffer::try_new(req).map_err(|_| AnalysisFailed)?;
        Ok(General {
            symbolic,
            numeric: NumericLu::new(),
            mem,
        })
    }

    fn factor(
        &mut self,
        n: usize,
        col_ptr: &[usize],
        row_idx: &[usize],
        values: &[f64],
    ) -> Result<(), NewtonFailure> {
        let pattern = SymbolicSparseColMatRef::new_checked(n, n, col_ptr, None, row_idx);
        let a = SparseColMatRef::new(pattern, values);
        self.symbolic
            .factorize_numeric_lu(
                &mut self.numeric,
                a,
                Par::Seq,
                MemStack::new(&mut self.mem),
                Default::default(),
            )
            .map_err(|_| NewtonFailure::SingularJacobian)?;
        Ok(())
    }

    fn solve_in_place(&mut self, x: &mut [f64]) {
        let n = x.len();
        let lu = LuRef::new_unchecked(&self.symbolic, &self.numeric);
        let rhs = MatMut::from_column_major_slice_mut(x, n, 1);
        lu.solve_in_place_with_conj(Conj::No, rhs, Par::Seq, MemStack::new(&mut self.mem));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::alloc::{GlobalAlloc, Layout, System};
    use std::cell::Cell;

    /// The unit tests' allocator: [`System`], counting each thread's allocations (tests run
    /// on threads of their own, so a test counts only its own).
    struct PerThread;

    thread_local! {
        static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
    }

    fn count() {
        // `try_with`: the count is lost, not a panic, while the thread is torn down.
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
    }

    // SAFETY: every call is forwarded unchanged to `System`.
    unsafe impl GlobalAlloc for PerThread {
        unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
            count();
            // SAFETY: the caller upholds `GlobalAlloc::alloc`'s contract.
            unsafe { System.alloc(layout) }
        }
        unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
            count();
            // SAFETY: as above.
            unsafe { System.alloc_zeroed(layout) }
        }
        unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
            count();
            // SAFETY: as above.
            unsafe { System.realloc(ptr, layout, new_size) }
        }
        unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
            // SAFETY: as above.
            unsafe { System.dealloc(ptr, layout) }
        }
    }

    #[global_allocator]
    static ALLOC: PerThread = PerThread;

    /// Allocations made by this thread so far.
    fn allocations() -> u64 {
        ALLOCATIONS.with(|c| c.get())
    }

    /// `‖A x − b‖∞ / (‖A‖max ‖x‖∞)`.
    fn relative_residual(lu: &SparseLu, x: &[f64], b: &[f64]) -> f64 {
        let mut r = b.to_vec();
        for (c, &xc) in x.iter().enumerate() {
            for p in lu.col_ptr[c]..lu.col_ptr[c + 1] {
                r[lu.row_idx[p]] -= lu.values[p] * xc;
            }
        }
        let max = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        max(&r) / (lu.max_abs() * max(x))
    }

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
        let mut empty = SparseLu::new(0, vec![0], vec![]).unwrap();
        empty.factor().unwrap();
        empty.solve_in_place(&mut []);
    }

    /// The step matrix of lobatto3 (two unknowns per coordinate, `a·2 + j`) on a `w × w`
    /// lattice whose coordinates are coupled to their 4 neighbours: a dense 2 × 2 block at
    /// each entry of the lattice's pattern. Returns `(col_ptr, row_idx, (a, b, j, m) per
    /// entry)`.
    #[allow(clippy::type_complexity)]
    fn lattice_step_pattern(
        w: usize,
    ) -> (Vec<usize>, Vec<usize>, Vec<(usize, usize, usize, usize)>) {
        let (mut col_ptr, mut row_idx, mut who) = (vec![0], vec![], vec![]);
        for b in 0..w * w {
            let (x, y) = (b % w, b / w);
            let mut node = vec![b];
            node.extend((x > 0).then(|| b - 1));
            node.extend((x + 1 < w).then_some(b + 1));
            node.extend((y > 0).then(|| b - w));
            node.extend((y + 1 < w).then_some(b + w));
            node.sort_unstable();
            for m in 0..2 {
                for &a in &node {
                    for j in 0..2 {
                        row_idx.push(a * 2 + j);
                        who.push((a, b, j, m));
                    }
                }
                col_ptr.push(row_idx.len());
            }
        }
        (col_ptr, row_idx, who)
    }

    /// A lobatto3 step Jacobian's values on the lattice: `(m/h) K` (K the kinetic block of
    /// the quadratic Lagrange basis) in each coordinate's block, the springs' `h k W` (`W`
    /// the quadrature weights) on the lattice's Laplacian, a little damping, `k` varying a
    /// little from site to site and `h` from call to call.
    fn lattice_step_values(who: &[(usize, usize, usize, usize)], h: f64, k: f64, out: &mut [f64]) {
        let kinetic = [[16.0 / 3.0, -8.0 / 3.0], [-8.0 / 3.0, 1.0 / 3.0]];
        let weight = [[2.0 / 3.0, 0.0], [0.0, 1.0 / 6.0]];
        let damping = [[0.0, 0.05], [-0.05, 0.05]];
        for (v, &(a, b, j, m)) in out.iter_mut().zip(who) {
            let k_ab = k * (1.0 + 0.1 * ((3 * a + 7 * b) % 11) as f64);
            *v = if a == b {
                kinetic[j][m] / h + 4.0 * h * k_ab * weight[j][m] + damping[j][m]
            } else {
                -h * k_ab * weight[j][m]
            };
        }
    }

    #[test]
    fn a_lattice_step_matrix_factors_accurately_without_allocating() {
        let w = 32;
        let (col_ptr, row_idx, who) = lattice_step_pattern(w);
        let n = 2 * w * w;
        let before = allocations();
        let mut lu = SparseLu::new(n, col_ptr, row_idx).unwrap();
        assert!(allocations() > before, "the allocator counts");
        let b: Vec<f64> = (0..n)
            .map(|i| ((i * 37) % 101) as f64 / 50.0 - 1.0)
            .collect();
        let mut x = vec![0.0; n];
        let mut values = vec![0.0; who.len()];
        // Soft to stiff springs (h²k from 10⁻⁴ to 3), the step size changing too.
        for (i, k) in [1.0, 1.0, 30.0, 300.0, 300.0, 3000.0, 30000.0]
            .into_iter()
            .enumerate()
        {
            let h = 0.01 * (1.0 + 0.1 * i as f64);
            lattice_step_values(&who, h, k, &mut values);
            lu.values.copy_from_slice(&values);
            x.copy_from_slice(&b);
            let before = allocations();
            lu.factor().unwrap();
            lu.solve_in_place(&mut x);
            assert_eq!(allocations() - before, 0, "factorisation {i}");
            assert_eq!(lu.factors, Factors::Supernodal, "factorisation {i}");
            let r = relative_residual(&lu, &x, &b);
            assert!(r < 1e-14, "factorisation {i}: residual {r:e}");
        }
    }

    /// `δ I + S` with `S` the cyclic shift (`S e_i = e_{i+1}`): the diagonal blocks of the
    /// supernodes (parts of the cycle) are `δ I` plus a nilpotent shift, so a pivot `δ` is
    /// forced on them, while partial pivoting takes the shift's ones.
    fn shifted_cycle(n: usize, delta: f64) -> SparseLu {
        let mut col_ptr = vec![0];
        let mut row_idx = vec![];
        for c in 0..n {
            let mut rows = vec![c, (c + 1) % n];
            rows.sort_unstable();
            row_idx.extend(rows);
            col_ptr.push(row_idx.len());
        }
        let mut lu = SparseLu::new(n, col_ptr.clone(), row_idx.clone()).unwrap();
        for c in 0..n {
            let range = col_ptr[c]..col_ptr[c + 1];
            for (v, &r) in lu.values[range.clone()].iter_mut().zip(&row_idx[range]) {
                *v = if r == c { delta } else { 1.0 };
            }
        }
        lu
    }

    #[test]
    fn a_matrix_that_needs_partial_pivoting_falls_back_to_faer() {
        let n = 64;
        let b: Vec<f64> = (0..n).map(|i| (i % 7) as f64 - 3.0).collect();
        // A zero pivot in a diagonal block; then a tiny one, whose growth the probe's
        // backward error shows.
        for delta in [0.0, 1e-13] {
            let mut lu = shifted_cycle(n, delta);
            lu.factor().unwrap();
            assert_eq!(lu.factors, Factors::General, "δ = {delta}");
            let mut x = b.clone();
            lu.solve_in_place(&mut x);
            let r = relative_residual(&lu, &x, &b);
            assert!(r < 1e-15, "δ = {delta}: residual {r:e}");
            // The next factorisation goes to faer directly, the one after that tries again.
            assert_eq!((lu.skip, lu.backoff), (1, 1));
            lu.factor().unwrap();
            assert_eq!((lu.skip, lu.backoff), (0, 1));
            lu.factor().unwrap();
            assert_eq!((lu.skip, lu.backoff), (2, 2));
        }
        // A regular value for δ: the supernodal factors are kept.
        let mut lu = shifted_cycle(n, 4.0);
        lu.factor().unwrap();
        assert_eq!(lu.factors, Factors::Supernodal);
        let mut x = b.clone();
        lu.solve_in_place(&mut x);
        assert!(relative_residual(&lu, &x, &b) < 1e-15);
    }
}
