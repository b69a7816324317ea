//! Newton's method on a sparse Jacobian with a fixed pattern.
//!
//! The iteration, its tests and its reuse of factors are those of the dense
//! [`Newton`](crate::Newton): both run the one loop of `newton::iteration`. Only the linear
//! algebra differs: the Jacobian is filled on its pattern and factored by faer's sparse LU.
//! Like the dense solver it knows nothing of steps or schemes.

use crate::error::NewtonFailure;
use crate::newton::{Iteration, LinearSolver, NewtonOptions, NewtonReport};
use crate::sparse::lu::SparseLu;

/// A square nonlinear system `R(z) = 0` whose Jacobian has a fixed sparse pattern.
pub(crate) trait SparseSystem {
    /// The residual at `z`.
    fn residual(&mut self, z: &[f64], r: &mut [f64]) -> Result<(), NewtonFailure>;
    /// The Jacobian's values at `z`, on the pattern the solver was made with.
    fn jacobian(&mut self, z: &[f64], values: &mut [f64]) -> Result<(), NewtonFailure>;
    /// As [`crate::NonlinearSystem::residual_noise`] (default 0).
    fn residual_noise(&self) -> f64 {
        0.0
    }
    /// As [`crate::NonlinearSystem::row_scales`] (default: `scale` for every row).
    fn row_scales(&self, scale: f64, out: &mut [f64]) {
        out.fill(scale);
    }
    /// As [`crate::NonlinearSystem::rows_apart`] (default: false).
    fn rows_apart(&self) -> bool {
        false
    }
    /// As [`crate::NonlinearSystem::group_max`] (default: one group).
    fn group_max(&self, out: &mut [f64]) {
        let m = out.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        out.fill(m);
    }
    /// As [`crate::NonlinearSystem::add_row_noise`] (default: the noise to every row).
    fn add_row_noise(&self, out: &mut [f64]) {
        let noise = self.residual_noise();
        out.iter_mut().for_each(|x| *x += noise);
    }
}

impl<S: SparseSystem + ?Sized> LinearSolver<S> for SparseLu {
    type Vector = Vec<f64>;
    const COSTLY_FACTORS: bool = true;

    #[inline(always)]
    fn residual(sys: &mut S, z: &Vec<f64>, r: &mut Vec<f64>) -> Result<(), NewtonFailure> {
        sys.residual(z, r)
    }

    #[inline]
    fn refresh(&mut self, sys: &mut S, z: &Vec<f64>) -> Result<f64, NewtonFailure> {
        sys.jacobian(z, &mut self.values)?;
        self.factor()?;
        Ok(self.max_abs())
    }

    #[inline(always)]
    fn solve_in_place(&mut self, b: &mut Vec<f64>) {
        SparseLu::solve_in_place(self, b);
    }

    #[inline(always)]
    fn row_scales(sys: &S, scale: f64, out: &mut [f64]) {
        sys.row_scales(scale, out)
    }

    #[inline(always)]
    fn add_row_noise(sys: &S, out: &mut [f64]) {
        sys.add_row_noise(out)
    }

    #[inline(always)]
    fn rows_apart(sys: &S) -> bool {
        sys.rows_apart()
    }

    #[inline(always)]
    fn group_max(sys: &S, out: &mut [f64]) {
        sys.group_max(out)
    }

    #[inline]
    fn row_max(&self, out: &mut [f64]) {
        SparseLu::row_max(self, out)
    }
}

/// The solver and its buffers, made once.
pub(crate) struct SparseNewton {
    /// The iteration; the error estimate's backend reaches its carried factors
    /// (`Iteration::carry_factors`) here.
    pub(crate) iteration: Iteration<Vec<f64>>,
    lu: SparseLu,
}

impl SparseNewton {
    /// A solver whose Jacobian lives in `lu`.
    pub(crate) fn new(lu: SparseLu, opts: NewtonOptions) -> Self {
        let n = lu.n();
        SparseNewton {
            iteration: Iteration::new(opts, vec![0.0; n]),
            lu,
        }
    }

    /// The options in use.
    pub(crate) fn options(&self) -> &NewtonOptions {
        &self.iteration.opts
    }

    /// The size of the correction that would follow the last solve's iterate (see the
    /// iteration's `next_correction`).
    pub(crate) fn next_correction<S: SparseSystem>(&mut self) -> (f64, f64, bool) {
        self.iteration.next_correction::<S, _>(&mut self.lu)
    }

    /// Forgets the factors.
    pub(crate) fn invalidate(&mut self) {
        self.iteration.have_factors = false;
        self.iteration.jrow_valid = false;
    }

    /// Linear solves done by the last call to [`SparseNewton::solve`].
    pub(crate) fn last_iterations(&self) -> usize {
        self.iteration.last_iterations
    }

    /// Evaluates and factors the Jacobian of `sys` at `z` (for tangents, DESIGN §12).
    pub(crate) fn factor_at<S: SparseSystem>(
        &mut self,
        sys: &mut S,
        z: &Vec<f64>,
    ) -> Result<(), NewtonFailure> {
        self.iteration.have_factors = false;
        self.iteration.jrow_valid = false;
        LinearSolver::<S>::refresh(&mut self.lu, sys, z).map(|_| ())
    }

    /// Evaluates the Jacobian at `z` into [`Self::lu`]'s values without factoring it: for a
    /// caller that factors its transpose alone (the adjoint's backward pass).
    pub(crate) fn assemble_at<S: SparseSystem>(
        &mut self,
        sys: &mut S,
        z: &[f64],
    ) -> Result<(), NewtonFailure> {
        self.iteration.have_factors = false;
        self.iteration.jrow_valid = false;
        sys.jacobian(z, &mut self.lu.values)
    }

    /// The Jacobian and its factors.
    pub(crate) fn lu(&self) -> &SparseLu {
        &self.lu
    }

    /// Solves `J x = b` in place with the factors of [`SparseNewton::factor_at`].
    pub(crate) fn solve_factored(&mut self, b: &mut [f64]) {
        self.lu.solve_in_place(b);
    }

    /// [`Self::solve_factored`] for a block of interleaved right-hand sides (see
    /// [`SparseLu::solve_block_in_place`]).
    pub(crate) fn solve_factored_block(&mut self, b: &mut [f64]) {
        self.lu.solve_block_in_place(b);
    }

    /// Solves `R(z) = 0` from the guess in `z`; see [`crate::Newton::solve`] for the tests
    /// and the bound an `Ok` iterate meets.
    pub(crate) fn solve<S: SparseSystem>(
        &mut self,
        sys: &mut S,
        z: &mut Vec<f64>,
        residual_scale: f64,
    ) -> Result<NewtonReport, NewtonFailure> {
        self.iteration.solve(&mut self.lu, sys, z, residual_scale)
    }
}
