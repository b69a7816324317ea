//! A damped Newton solver for square nonlinear systems, on nalgebra.
//!
//! It knows nothing about time, steps or schemes: a problem is anything that implements
//! [`NonlinearSystem`]. All buffers are made once in [`Newton::new`] and reused, so a solve
//! does not allocate.
//!
//! | piece | module |
//! |---|---|
//! | [`NonlinearSystem`], [`Newton`] and its iteration, [`NewtonReport`] | this one |
//! | [`NewtonOptions`] and their checks | `options` |
//! | dense LU: [`DenseLu`] for the step Jacobian, [`solve_small`] for `N × N` blocks | `lu` |

mod lu;
mod options;
#[cfg(test)]
mod tests;

use nalgebra::{DMatrix, DVector};

use crate::error::NewtonFailure;

pub use lu::{solve_small, DenseLu};
pub use options::NewtonOptions;

/// A square nonlinear system `R(z) = 0`.
pub trait NonlinearSystem {
    /// The residual at `z`. An `Err` means the residual could not be evaluated (for example,
    /// the model returned a non-finite value).
    fn residual(&mut self, z: &DVector<f64>, r: &mut DVector<f64>) -> Result<(), NewtonFailure>;

    /// The Jacobian `∂R/∂z` at `z`.
    fn jacobian(&mut self, z: &DVector<f64>, j: &mut DMatrix<f64>) -> Result<(), NewtonFailure>;
}

/// Simplified Newton refreshes its Jacobian when the contraction rate exceeds this.
const THETA_REFRESH: f64 = 1e-2;

/// What a successful solve reports.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NewtonReport {
    /// Linear solves performed.
    pub iterations: usize,
    /// Max-norm of the residual at the solution.
    pub residual: f64,
    /// Line-search halvings taken in total.
    pub backtracks: usize,
    /// The bound that `residual` met: `max(residual_tol · scale, 64 ε (scale + |J| · |z|))`
    /// at the accepted iterate (see [`Newton::solve`]).
    pub residual_bound: f64,
}

/// The Newton solver with its reusable buffers.
#[derive(Clone, Debug)]
pub struct Newton {
    opts: NewtonOptions,
    lu: DenseLu,
    jac: DMatrix<f64>,
    r: DVector<f64>,
    r_trial: DVector<f64>,
    dz: DVector<f64>,
    z_trial: DVector<f64>,
    have_factors: bool,
    last_iterations: usize,
}

/// The round-off level of a residual whose terms, of size `scale` and `|J| · |z|`, cancel.
#[inline]
pub fn round_off_floor(scale: f64, jac_scale: f64, z_norm: f64) -> f64 {
    64.0 * f64::EPSILON * (scale + jac_scale * z_norm)
}

/// Max-norm that propagates NaN (unlike `f64::max`).
fn max_norm(x: &DVector<f64>) -> f64 {
    let mut m = 0.0f64;
    for &v in x.as_slice() {
        let a = v.abs();
        m = if a > m || a.is_nan() { a } else { m };
    }
    m
}

impl Newton {
    /// A solver for systems of `n` unknowns.
    pub fn new(n: usize, opts: NewtonOptions) -> Self {
        Newton {
            opts,
            lu: DenseLu::new(n),
            jac: DMatrix::zeros(n, n),
            r: DVector::zeros(n),
            r_trial: DVector::zeros(n),
            dz: DVector::zeros(n),
            z_trial: DVector::zeros(n),
            have_factors: false,
            last_iterations: 0,
        }
    }

    /// The options in use.
    pub fn options(&self) -> &NewtonOptions {
        &self.opts
    }

    /// The residual at the last accepted iterate (valid after a successful solve).
    pub fn residual(&self) -> &DVector<f64> {
        &self.r
    }

    /// Linear solves done by the last call to [`Newton::solve`], converged or not.
    pub fn last_iterations(&self) -> usize {
        self.last_iterations
    }

    /// Forgets reusable Jacobian factors (call when the problem changes).
    pub fn invalidate(&mut self) {
        self.have_factors = false;
    }

    /// Solves `R(z) = 0` from the initial guess in `z`, overwriting it.
    ///
    /// `residual_scale` sets the units of the residual test. Convergence needs both a small
    /// estimated error in `z`, from the contraction rate `θ = |Δz_k| / |Δz_{k−1}|` as in
    /// Hairer's codes, and a small residual. A step that does not reduce the residual is
    /// halved (line search); repeated growth is divergence.
    ///
    /// An `Ok` iterate `z` (max-norms throughout) satisfies the stated bound
    ///
    /// `|R(z)| ≤ max(residual_tol · scale, 64 ε (scale + |J| · |z|))`
    ///
    /// where `|J|` is the largest entry of the last Jacobian. The second term is the
    /// round-off floor of a residual whose terms, of size `scale` and `|J|·|z|` at the
    /// solution, cancel. It is computed from the accepted iterate itself, never from the
    /// initial guess, so a huge guess cannot widen it. Unless the residual is at that floor,
    /// the estimated error of `z` is also below `rtol · |z| + atol`.
    pub fn solve<S: NonlinearSystem>(
        &mut self,
        sys: &mut S,
        z: &mut DVector<f64>,
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
            // Below this level residuals at the current iterate are round-off.
            let res_floor = round_off_floor(scale, jac_scale, max_norm(z));
            let full = self.direction()?;
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
            let znorm = max_norm(z);
            let floor = round_off_floor(scale, jac_scale, znorm);
            // A residual at the round-off floor cannot be reduced further: the iterate is as
            // exact as the problem's conditioning allows, even if the increments are noise.
            let at_floor = it > 1 && rnorm <= floor;
            let small_error = error_estimate(it, step, theta) <= o.rtol * znorm + o.atol;
            if (small_error && rnorm <= res_tol && halvings == 0) || at_floor {
                return Ok(NewtonReport {
                    iterations: it,
                    residual: rnorm,
                    backtracks,
                    residual_bound: res_tol.max(floor),
                });
            }
            if o.simplified && wants_fresh_jacobian(it, theta, step, znorm) {
                self.have_factors = false;
            }
        }
        Err(NewtonFailure::MaxIterations { residual: rnorm })
    }

    /// A fresh Jacobian at `z`, factored; returns its largest entry `|J|`.
    #[inline]
    fn refresh<S: NonlinearSystem>(
        &mut self,
        sys: &mut S,
        z: &DVector<f64>,
    ) -> Result<f64, NewtonFailure> {
        sys.jacobian(z, &mut self.jac)?;
        self.lu.factor(&self.jac)?;
        self.have_factors = true;
        Ok(self
            .jac
            .as_slice()
            .iter()
            .fold(0.0f64, |m, x| m.max(x.abs())))
    }

    /// The Newton direction `dz = −J⁻¹ R` from the current factors; returns `|dz|`.
    #[inline]
    fn direction(&mut self) -> Result<f64, NewtonFailure> {
        self.dz.as_mut_slice().copy_from_slice(self.r.as_slice());
        self.lu.solve_in_place(&mut self.dz);
        self.dz.neg_mut();
        let full = max_norm(&self.dz);
        if !full.is_finite() {
            return Err(NewtonFailure::NonFinite);
        }
        Ok(full)
    }

    /// The line search on the residual norm along `dz`, whose norm is `full`:
    /// `Some((λ, halvings, |R|))` with the trial in `z_trial` and `r_trial`, or `None` when
    /// stale factors must be refreshed and the iteration retried.
    #[inline]
    fn line_search<S: NonlinearSystem>(
        &mut self,
        sys: &mut S,
        z: &DVector<f64>,
        rnorm: f64,
        res_floor: f64,
        full: f64,
    ) -> Result<Option<(f64, usize, f64)>, NewtonFailure> {
        let o = self.opts;
        let (mut lambda, mut halvings) = (1.0, 0);
        loop {
            for ((t, x), d) in self
                .z_trial
                .as_mut_slice()
                .iter_mut()
                .zip(z.as_slice())
                .zip(self.dz.as_slice())
            {
                *t = x + lambda * d;
            }
            let tn = match sys.residual(&self.z_trial, &mut self.r_trial) {
                Ok(()) => max_norm(&self.r_trial),
                Err(_) => f64::NAN,
            };
            if tn.is_finite() && (tn <= rnorm * (1.0 - 1e-4 * lambda) || tn <= res_floor) {
                return Ok(Some((lambda, halvings, tn)));
            }
            // A full step that grows the residual right next to the solution is still
            // accepted once: Newton's local convergence, not the norm, is then in charge.
            if tn.is_finite() && halvings == 0 && full <= o.rtol * max_norm(z) + o.atol {
                return Ok(Some((lambda, halvings, tn)));
            }
            halvings += 1;
            if halvings > o.max_backtracks {
                if o.simplified && self.have_factors {
                    // Stale factors: retry this iteration with a fresh Jacobian.
                    self.have_factors = false;
                    return Ok(None);
                }
                return Err(NewtonFailure::Stagnated { residual: rnorm });
            }
            lambda *= 0.5;
        }
    }
}

/// The estimated error of the iterate after a step of size `step` with contraction rate
/// `θ` (Hairer's `step · θ / (1 − θ)`; the step itself on the first iteration).
#[inline]
pub(crate) fn error_estimate(it: usize, step: f64, theta: f64) -> f64 {
    if it == 1 || !theta.is_finite() {
        step
    } else if theta < 1.0 {
        step * theta / (1.0 - theta)
    } else {
        f64::INFINITY
    }
}

/// Whether simplified Newton should refresh its factors after iteration `it`. Stale factors
/// contract slowly; a fresh Jacobian restores quadratic convergence, so the accepted iterate
/// is as exact as full Newton's. After the first iteration θ is unknown; a small first
/// correction means a good initial guess, so the factors taken there stay accurate.
#[inline]
pub(crate) fn wants_fresh_jacobian(it: usize, theta: f64, step: f64, znorm: f64) -> bool {
    (it == 1 || theta > THETA_REFRESH) && (it > 1 || step > 1e-3 * znorm)
}
