//! Newton's method on a sparse Jacobian with a fixed pattern.
//!
//! The iteration, its tests and its reuse of factors are those of the dense
//! [`Newton`](crate::Newton) (simplified Newton: factors kept while the contraction rate stays
//! below 1e-2, convergence on both the estimated error and the residual, a line search on the
//! residual norm); only the linear algebra differs: the Jacobian is filled on its pattern and
//! factored by faer's sparse LU. Like the dense solver it knows nothing of steps or schemes.

use crate::error::NewtonFailure;
use crate::newton::{
    error_estimate, round_off_floor, wants_fresh_jacobian, NewtonOptions, NewtonReport,
};
use crate::sparse::lu::SparseLu;

/// A square nonlinear system `R(z) = 0` whose Jacobian has a fixed sparse pattern.
pub(crate) trait SparseSystem {
    /// The residual at `z`.
    fn residual(&mut self, z: &[f64], r: &mut [f64]) -> Result<(), NewtonFailure>;
    /// The Jacobian's values at `z`, on the pattern the solver was made with.
    fn jacobian(&mut self, z: &[f64], values: &mut [f64]) -> Result<(), NewtonFailure>;
}

/// The solver and its buffers, made once.
pub(crate) struct SparseNewton {
    opts: NewtonOptions,
    lu: SparseLu,
    r: Vec<f64>,
    r_trial: Vec<f64>,
    dz: Vec<f64>,
    z_trial: Vec<f64>,
    have_factors: bool,
    last_iterations: usize,
}

fn max_norm(x: &[f64]) -> f64 {
    let mut m = 0.0f64;
    for &v in x {
        let a = v.abs();
        m = if a > m || a.is_nan() { a } else { m };
    }
    m
}

impl SparseNewton {
    /// A solver whose Jacobian lives in `lu`.
    pub(crate) fn new(lu: SparseLu, opts: NewtonOptions) -> Self {
        let n = lu.n();
        SparseNewton {
            opts,
            lu,
            r: vec![0.0; n],
            r_trial: vec![0.0; n],
            dz: vec![0.0; n],
            z_trial: vec![0.0; n],
            have_factors: false,
            last_iterations: 0,
        }
    }

    /// Forgets the factors.
    pub(crate) fn invalidate(&mut self) {
        self.have_factors = false;
    }

    /// Linear solves done by the last call to [`SparseNewton::solve`].
    pub(crate) fn last_iterations(&self) -> usize {
        self.last_iterations
    }

    fn refresh<S: SparseSystem>(&mut self, sys: &mut S, z: &[f64]) -> Result<f64, NewtonFailure> {
        sys.jacobian(z, &mut self.lu.values)?;
        self.lu.factor()?;
        self.have_factors = true;
        Ok(self.lu.max_abs())
    }

    /// Solves `R(z) = 0` from the guess in `z`; see [`crate::Newton::solve`] for the tests
    /// and the bound an `Ok` iterate meets.
    pub(crate) fn solve<S: SparseSystem>(
        &mut self,
        sys: &mut S,
        z: &mut Vec<f64>,
        residual_scale: f64,
    ) -> Result<NewtonReport, NewtonFailure> {
        let o = self.opts;
        let scale = residual_scale.max(f64::MIN_POSITIVE);
        let res_tol = o.residual_tol * scale;
        let mut jac_scale = 0.0f64;
        sys.residual(z, &mut self.r)?;
        let mut rnorm = max_norm(&self.r);
        if !rnorm.is_finite() {
            return Err(NewtonFailure::NonFinite);
        }
        let (mut prev_step, mut backtracks, mut growth) = (f64::INFINITY, 0, 0);
        self.last_iterations = 0;
        for it in 1..=o.max_iterations {
            self.last_iterations = it;
            if !(o.simplified && self.have_factors) {
                jac_scale = self.refresh(sys, z)?;
            }
            let res_floor = round_off_floor(scale, jac_scale, max_norm(z));
            self.dz.copy_from_slice(&self.r);
            self.lu.solve_in_place(&mut self.dz);
            self.dz.iter_mut().for_each(|x| *x = -*x);
            let full = max_norm(&self.dz);
            if !full.is_finite() {
                return Err(NewtonFailure::NonFinite);
            }
            let Some((lambda, halvings, trial_norm)) =
                self.line_search(sys, z, rnorm, res_floor, full)?
            else {
                continue;
            };
            backtracks += halvings;
            std::mem::swap(z, &mut self.z_trial);
            std::mem::swap(&mut self.r, &mut self.r_trial);
            let step = lambda * full;
            let theta = step / prev_step;
            if trial_norm > rnorm && it > 1 {
                growth += 1;
                if growth >= 3 {
                    return Err(NewtonFailure::Diverged {
                        residual: trial_norm,
                    });
                }
            }
            rnorm = trial_norm;
            prev_step = step;
            let err_estimate = error_estimate(it, step, theta);
            let znorm = max_norm(z);
            let tol = o.rtol * znorm + o.atol;
            let at_floor = it > 1 && rnorm <= round_off_floor(scale, jac_scale, znorm);
            if (err_estimate <= tol && rnorm <= res_tol && halvings == 0) || at_floor {
                return Ok(NewtonReport {
                    iterations: it,
                    residual: rnorm,
                    backtracks,
                    residual_bound: res_tol.max(round_off_floor(scale, jac_scale, znorm)),
                });
            }
            if o.simplified && wants_fresh_jacobian(it, theta, step, znorm) {
                self.have_factors = false;
            }
        }
        Err(NewtonFailure::MaxIterations { residual: rnorm })
    }

    /// The line search along `dz`: `Some((λ, halvings, |R|))` with the trial in `z_trial`
    /// and `r_trial`, or `None` when stale factors must be refreshed and the iteration
    /// retried.
    fn line_search<S: SparseSystem>(
        &mut self,
        sys: &mut S,
        z: &[f64],
        rnorm: f64,
        res_floor: f64,
        full: f64,
    ) -> Result<Option<(f64, usize, f64)>, NewtonFailure> {
        let o = self.opts;
        let (mut lambda, mut halvings) = (1.0, 0);
        loop {
            for ((t, x), d) in self.z_trial.iter_mut().zip(z).zip(&self.dz) {
                *t = x + lambda * d;
            }
            let tn = match sys.residual(&self.z_trial, &mut self.r_trial) {
                Ok(()) => max_norm(&self.r_trial),
                Err(_) => f64::NAN,
            };
            if tn.is_finite() && (tn <= rnorm * (1.0 - 1e-4 * lambda) || tn <= res_floor) {
                return Ok(Some((lambda, halvings, tn)));
            }
            // Next to the solution a full step that grows the residual is accepted once.
            if tn.is_finite() && halvings == 0 && full <= o.rtol * max_norm(z) + o.atol {
                return Ok(Some((lambda, halvings, tn)));
            }
            halvings += 1;
            if halvings > o.max_backtracks {
                if o.simplified && self.have_factors {
                    self.have_factors = false;
                    return Ok(None);
                }
                return Err(NewtonFailure::Stagnated { residual: rnorm });
            }
            lambda *= 0.5;
        }
    }
}
