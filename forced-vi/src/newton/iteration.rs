//! The Newton iteration itself, generic over its linear algebra: the dense [`Newton`] and the
//! sparse Newton of [`crate::sparse`] run this one loop (simplified Newton with factors kept
//! while the contraction rate stays below 1e-2, convergence on both the estimated error and
//! the residual, a line search on the residual norm) and differ only in how the Jacobian is
//! stored, factored and solved.
//!
//! [`Newton`]: super::Newton

use nalgebra::DVector;

use super::{NewtonOptions, NewtonReport};
use crate::error::NewtonFailure;

/// Simplified Newton refreshes its Jacobian when the contraction rate exceeds this.
const THETA_REFRESH: f64 = 1e-2;

/// A first correction above this (relative to the iterate) marks a poor initial guess.
const FAR_START: f64 = 1e-3;

/// A first correction up to this (relative to the iterate), though above [`FAR_START`],
/// keeps the factors made for it for one more iteration, which measures their contraction
/// (see [`Iteration::solve`]); a farther one (a stiff step, a poor guess) refreshes them.
const FAR_KEPT: f64 = 1e-2;

/// Systems below this many unknowns refresh their factors after a far first correction
/// anyway: their Jacobian and LU cost about two residuals and solves, what keeping them
/// saves (measured on coupled van der Pol, lobatto3 with 4 unknowns: the same instructions
/// within 0.5 %, and on the stiff van der Pol, adaptive lobatto3 took 2–3 % more steps).
const FAR_KEPT_MIN_UNKNOWNS: usize = 6;

/// Factors carried over from an earlier solve (see [`Iteration::carry_factors`]) are kept
/// when their correction leaves at most this fraction of the residual.
const CARRY_THETA: f64 = 0.01;

/// After carried factors fail, the solves that make fresh ones before the next attempt to
/// carry them: doubled (plus one) after each failure, up to this many.
const CARRY_BACKOFF_MAX: u32 = 16;

/// A vector of the iteration: the unknowns, the residual and the buffers.
pub(crate) trait Buffer {
    /// The entries.
    fn entries(&self) -> &[f64];
    /// The entries, to write.
    fn entries_mut(&mut self) -> &mut [f64];
}

impl Buffer for DVector<f64> {
    #[inline(always)]
    fn entries(&self) -> &[f64] {
        self.as_slice()
    }
    #[inline(always)]
    fn entries_mut(&mut self) -> &mut [f64] {
        self.as_mut_slice()
    }
}

impl Buffer for Vec<f64> {
    #[inline(always)]
    fn entries(&self) -> &[f64] {
        self
    }
    #[inline(always)]
    fn entries_mut(&mut self) -> &mut [f64] {
        self
    }
}

/// The linear algebra of a Newton solver for systems `S`: the Jacobian's storage and
/// factors.
pub(crate) trait LinearSolver<S: ?Sized> {
    /// The vectors of the systems.
    type Vector: Buffer;
    /// Whether a factorisation costs many solves (a large sparse LU). Simplified Newton then
    /// keeps its factors until it has measured a slow contraction, instead of refreshing
    /// them after a large first correction (see [`wants_fresh_jacobian`]).
    const COSTLY_FACTORS: bool = false;
    /// The residual of `sys` at `z`.
    fn residual(sys: &mut S, z: &Self::Vector, r: &mut Self::Vector) -> Result<(), NewtonFailure>;
    /// The Jacobian of `sys` at `z`, factored; returns its largest entry `|J|`.
    fn refresh(&mut self, sys: &mut S, z: &Self::Vector) -> Result<f64, NewtonFailure>;
    /// The residual of `sys` at `z` into `r`, then its Jacobian there, factored (as
    /// [`LinearSolver::refresh`]); a non-finite residual is [`NewtonFailure::NonFinite`].
    fn refresh_with_residual(
        &mut self,
        sys: &mut S,
        z: &Self::Vector,
        r: &mut Self::Vector,
    ) -> Result<f64, NewtonFailure> {
        Self::residual(sys, z, r)?;
        if !max_norm(r.entries()).is_finite() {
            return Err(NewtonFailure::NonFinite);
        }
        self.refresh(sys, z)
    }
    /// Solves `J x = b` in place with the last factors.
    fn solve_in_place(&mut self, b: &mut Self::Vector);
    /// [`super::NonlinearSystem::constant_jacobian`] of `sys`.
    fn constant_jacobian(_sys: &S) -> bool {
        false
    }
    /// [`super::NonlinearSystem::row_scales`] of `sys`.
    fn row_scales(sys: &S, scale: f64, out: &mut [f64]);
    /// [`super::NonlinearSystem::add_row_noise`] of `sys`.
    fn add_row_noise(sys: &S, out: &mut [f64]);
    /// [`super::NonlinearSystem::rows_apart`] of `sys`.
    fn rows_apart(sys: &S) -> bool;
    /// [`super::NonlinearSystem::group_max`] of `sys`.
    fn group_max(sys: &S, out: &mut [f64]);
    /// `max_b |J_ab|` for each row `a`, with the last Jacobian, into `out`.
    fn row_max(&self, out: &mut [f64]);
}

/// The state and buffers of the iteration, made once.
#[derive(Clone, Debug)]
pub(crate) struct Iteration<V> {
    pub(crate) opts: NewtonOptions,
    pub(crate) r: V,
    r_trial: V,
    /// Each row's scale (the system's [`LinearSolver::row_scales`]) and the size of its
    /// terms at the current iterate (see [`Iteration::row_sizes`]).
    rho: V,
    sigma: V,
    /// The parts of `sigma` that do not depend on the iterate (`ρ_a + ν_a`) and each row's
    /// largest Jacobian entry, the largest of its group (see [`Iteration::row_terms`]).
    base: V,
    jrow: V,
    /// `jrow` holds the current factors' Jacobian (see [`Iteration::row_terms`]).
    pub(crate) jrow_valid: bool,
    /// The rows' Jacobian term in `sigma`: `jrow_weight jrow_a |z|` with rows apart
    /// (`jrow_weight` 1, or 0 for carried factors' first correction), `jrow_weight |z|`
    /// otherwise (`jrow_weight` the largest Jacobian entry).
    rows_apart: bool,
    jrow_weight: f64,
    dz: V,
    z_trial: V,
    pub(crate) have_factors: bool,
    pub(crate) last_iterations: usize,
    /// The size (max-norm) of the last solve's last correction, and whether the residual
    /// at its last iterate was at its round-off floor.
    last_step: f64,
    last_at_floor: bool,
    /// Factors carried over from the last solve: the direction they give is scaled by
    /// this ratio of step sizes (see [`Iteration::carry_factors`]).
    carry: Option<f64>,
    /// The step size of the current solve and the one the factors were made at.
    step_h: f64,
    factors_h: f64,
    /// Solves left before factors are carried again, and the next such pause.
    carry_skip: u32,
    carry_backoff: u32,
    /// Factors cost far more than a residual and a solve (see
    /// [`Iteration::set_costly_factors`]): no pause after carried factors fail.
    costly_factors: bool,
    /// After a solve with carried factors: a bound on the error they left in the iterate
    /// (see [`Iteration::carried_error`]); zero otherwise.
    carried_error: f64,
    /// A second correction of carried factors at most this large is not applied (see
    /// [`Iteration::carry_factors`]).
    negligible: f64,
    /// For the next solve only: an iterate whose estimated error (max-norm, from a measured
    /// contraction) is at most this is accepted (see [`Iteration::solve_within`]); 0: off.
    within: f64,
    /// The largest entry of the Jacobian at the last refresh.
    jac_scale: f64,
    /// Solves left that make fresh factors before those of an earlier solve are tried
    /// again, and the next such pause (see [`Iteration::stale_outcome`]).
    stale_skip: u32,
    stale_backoff: u32,
}

/// A residual row at most this times its size `σ_a` (see [`Iteration::row_sizes`]) is at
/// round-off: `64 ε`, the factor of [`round_off_floor`].
const ROW_FLOOR: f64 = 64.0 * f64::EPSILON;

/// `max_a |r_a| / w_a`, NaN propagated (the weights are positive).
fn weighted_norm(r: &[f64], w: &[f64]) -> f64 {
    let (mut m, mut nan) = (0.0f64, false);
    for (&v, &w) in r.iter().zip(w) {
        let a = v.abs() / w;
        m = if a > m { a } else { m };
        nan |= a.is_nan();
    }
    if nan { f64::NAN } else { m }
}

/// Max-norm that propagates NaN (unlike `f64::max`).
fn max_norm(x: &[f64]) -> f64 {
    // The maximum and the NaN test in separate accumulators, without a branch on either.
    let (mut m, mut nan) = (0.0f64, false);
    for &v in x {
        let a = v.abs();
        m = if a > m { a } else { m };
        nan |= a.is_nan();
    }
    if nan { f64::NAN } else { m }
}

/// The round-off level of a residual whose terms, of size `scale` and `|J| · |z|`, cancel.
///
/// An iterate is resolved to `ε |z|`, but never below the smallest normal number: where the
/// solution's entries underflow (a step of `h = 1e-200` from rest moves `q` by `h² ≈ 0`),
/// a correction smaller than that is lost, so the floor counts `|z|` as at least
/// `f64::MIN_POSITIVE / ε` and the solve ends at the iterate the arithmetic can hold,
/// instead of failing to converge.
#[inline]
pub fn round_off_floor(scale: f64, jac_scale: f64, z_norm: f64) -> f64 {
    const Z_RESOLVED: f64 = f64::MIN_POSITIVE / f64::EPSILON;
    // A comparison, not `f64::max`, which would turn a NaN norm into a finite floor.
    let z = if z_norm < Z_RESOLVED {
        Z_RESOLVED
    } else {
        z_norm
    };
    64.0 * f64::EPSILON * (scale + jac_scale * z)
}

impl<V: Buffer + Clone> Iteration<V> {
    /// Buffers copied from `zero`, a vector of the systems' size.
    pub(crate) fn new(opts: NewtonOptions, zero: V) -> Self {
        Iteration {
            opts,
            r: zero.clone(),
            r_trial: zero.clone(),
            rho: zero.clone(),
            base: zero.clone(),
            jrow_valid: false,
            rows_apart: false,
            jrow_weight: 0.0,
            sigma: zero.clone(),
            jrow: zero.clone(),
            dz: zero.clone(),
            z_trial: zero,
            have_factors: false,
            last_iterations: 0,
            last_step: 0.0,
            last_at_floor: false,
            carry: None,
            step_h: f64::NAN,
            factors_h: f64::NAN,
            carry_skip: 0,
            carry_backoff: 0,
            costly_factors: false,
            carried_error: 0.0,
            negligible: 0.0,
            within: 0.0,
            jac_scale: 0.0,
            stale_skip: 0,
            stale_backoff: 0,
        }
    }
}

impl<V: Buffer> Iteration<V> {
    /// Back to the state [`Iteration::new`] made, keeping the buffers and the options (and
    /// `costly_factors`, which the run's set-up sets): a new run on the same buffers.
    /// Every field is named, so that a field added later must be decided on here.
    pub(crate) fn restart(&mut self) {
        let Iteration {
            opts: _,
            r,
            r_trial,
            rho,
            sigma,
            base,
            jrow,
            jrow_valid,
            rows_apart,
            jrow_weight,
            dz,
            z_trial,
            have_factors,
            last_iterations,
            last_step,
            last_at_floor,
            carry,
            step_h,
            factors_h,
            carry_skip,
            carry_backoff,
            costly_factors: _,
            carried_error,
            negligible,
            within,
            jac_scale,
            stale_skip,
            stale_backoff,
        } = self;
        for b in [r, r_trial, rho, sigma, base, jrow, dz, z_trial] {
            b.entries_mut().fill(0.0);
        }
        *have_factors = false;
        *jrow_valid = false;
        *rows_apart = false;
        *jrow_weight = 0.0;
        *last_iterations = 0;
        *last_step = 0.0;
        *last_at_floor = false;
        *carry = None;
        *step_h = f64::NAN;
        *factors_h = f64::NAN;
        *carry_skip = 0;
        *carry_backoff = 0;
        *carried_error = 0.0;
        *negligible = 0.0;
        *within = 0.0;
        *jac_scale = 0.0;
        *stale_skip = 0;
        *stale_backoff = 0;
    }

    /// Prepares the next solve, of a step of size `h`, to start from the factors of the
    /// last one instead of fresh ones, and returns whether it will. For the one Newton
    /// iteration of the error estimate (`crate::control`), whose iterate needs to be
    /// accurate to a fraction of the estimate, not to round-off.
    ///
    /// The step Jacobian is `K ⊗ E / h + O(1)` (the mass term dominates), so factors made
    /// at a step `h₀` give a direction off by `h₀ / h` to leading order: it is scaled by
    /// `h / h₀`. What is left is a relative error `O(h)` (the state and the other blocks
    /// have moved) and, on a stiff model, `h` times its stiffness. The solve measures it:
    /// the residual after the carried correction, over the residual before, bounds the
    /// relative error of the correction, so above [`CARRY_THETA`] the iteration is redone
    /// with fresh factors, and the next solves make fresh ones (1, 3, 7, … of them after
    /// successive failures, up to [`CARRY_BACKOFF_MAX`]) before carrying again.
    ///
    /// A kept correction is followed by a second one with the same factors (see
    /// [`Iteration::solve`]); where that second correction is at most `negligible`
    /// (max-norm), it is not applied and the residual is not evaluated again: the iterate
    /// is then off by about that much, which [`Iteration::carried_error`] reports.
    pub(crate) fn carry_factors(&mut self, h: f64, negligible: f64) -> bool {
        self.step_h = h;
        self.negligible = negligible;
        let ratio = h / self.factors_h;
        self.carry = None;
        if self.carry_skip > 0 {
            self.carry_skip -= 1;
        } else if self.opts.simplified && self.have_factors && ratio.is_finite() && ratio > 0.0 {
            self.carry = Some(ratio);
        }
        // Not carried: the next solve makes fresh factors.
        self.have_factors &= self.carry.is_some();
        self.carry.is_some()
    }

    /// After a solve that kept carried factors: the estimated error they left in the
    /// iterate (max-norm), `δ₂ θ / (1 − θ)` with `θ = |δ₂| / |δ₁|` the contraction of the
    /// two corrections `δ₁, δ₂` (as in simplified Newton); zero after any other solve. The
    /// error estimate compares it with the tolerance.
    pub(crate) fn carried_error(&self) -> f64 {
        self.carried_error
    }

    /// The size (max-norm) of the correction that would follow the last solve's iterate,
    /// `|J⁻¹ R(z)|` with its last factors and the residual evaluated at that iterate (the
    /// iterate's error to first order where the residual is smooth), the size of the last
    /// correction made, and whether the residual there was at its round-off floor (where
    /// the next correction is noise). Infinite without factors or where the solve
    /// overflows.
    pub(crate) fn next_correction<S: ?Sized, L: LinearSolver<S, Vector = V>>(
        &mut self,
        lin: &mut L,
    ) -> (f64, f64, bool) {
        if !self.have_factors {
            return (f64::INFINITY, self.last_step, self.last_at_floor);
        }
        let next = self.direction::<S, L>(lin).unwrap_or(f64::INFINITY);
        (next, self.last_step, self.last_at_floor)
    }

    /// Refuses the carried factors of the last solve after the fact: the next solves make
    /// fresh ones, as after a failed residual check.
    pub(crate) fn reject_carry(&mut self) {
        if !self.costly_factors {
            self.carry_skip = self.carry_backoff;
            self.carry_backoff = (2 * self.carry_backoff + 1).min(CARRY_BACKOFF_MAX);
        }
        self.have_factors = false;
    }

    /// Lets the next solve (only) stop at the first iterate whose estimated error, `δ θ /
    /// (1 − θ)` from the last correction `δ` and a measured contraction `θ` (from the
    /// second iteration on, with no halving), is at most `bound` (max-norm, in the
    /// unknowns), instead of at round-off. For the steps of an adaptive run, whose error
    /// estimate measures the step as solved, Newton's error included (see
    /// [`crate::control`], "Newton's stop").
    pub(crate) fn solve_within(&mut self, bound: f64) {
        self.within = if bound.is_finite() && bound > 0.0 {
            bound
        } else {
            0.0
        };
    }

    /// Where factors cost far more than what a failed attempt to carry them wastes (a
    /// residual and a solve: a large sparse model, whose LU is most of a step), the solve
    /// after a failure makes fresh factors and the next one carries those again, with no
    /// pause (measured on the 1024-coordinate chain, lobatto3, tol 1e-6: 2.23G instructions
    /// with the pauses, 1.72G without, with the step-size band of `crate::control`).
    pub(crate) fn set_costly_factors(&mut self, costly: bool) {
        self.costly_factors = costly;
    }

    /// Solves `R(z) = 0` from the guess in `z`; see [`super::Newton::solve`] for the tests
    /// and the bound an `Ok` iterate meets.
    pub(crate) fn solve<S: ?Sized, L: LinearSolver<S, Vector = V>>(
        &mut self,
        lin: &mut L,
        sys: &mut S,
        z: &mut V,
        residual_scale: f64,
    ) -> Result<NewtonReport, NewtonFailure> {
        let o = self.opts;
        let within = std::mem::take(&mut self.within);
        let scale = residual_scale.max(f64::MIN_POSITIVE);
        // Each row is tested against its own terms (see `row_sizes`): `rnorm` is the
        // largest `|R_a| / σ_a`, and the residual test is `|R_a| ≤ residual_tol ρ_a`.
        L::row_scales(sys, scale, self.rho.entries_mut());
        for x in self.rho.entries_mut() {
            *x = if *x > f64::MIN_POSITIVE {
                *x
            } else {
                f64::MIN_POSITIVE
            };
        }
        let mut jac_scale = 0.0f64;
        let (mut prev_step, mut backtracks, mut growth) = (f64::INFINITY, 0, 0);
        // Kept factors after a large first correction (see `wants_fresh_jacobian`): the
        // second iterate is accepted only when the contraction measured there bounds its
        // error; otherwise the iterate takes one contraction more, even at the residual's
        // round-off floor, so that it stays as exact as with refreshed factors (measured on
        // the 256-link chain: constraint residuals 8e-18, against 1.7e-17 without it). On
        // the 1024-coordinate chain (adaptive lobatto4, tol 1e-6) every step with kept
        // factors started far (first corrections 1.2e-3 to 6e-3 of the increments), and
        // its second correction was 1e-7 of the first, an estimated error of 1e-16 of the
        // increments: the third iteration changed them by round-off, and the run took 144
        // linear solves against 114 (1.22G instructions against 1.15G).
        let mut far_start = false;
        // Factors carried over from the last solve (see `carry_factors`).
        let mut carried = self.carry.take().filter(|_| self.have_factors);
        // Factors made for an earlier solve (simplified Newton across steps, where factors
        // are cheap next to a residual: the dense backend's fixed steps). Their first
        // correction leaves an error θ times itself, and a residual at its round-off floor
        // does not show that the iterate is as exact as a fresh Jacobian's first one: the
        // residual's floor counts the round-off of terms `|J| |z|` that a step of the same
        // size cancels, so an iterate accepted there moved the momentum by up to a few
        // hundred ulps per step (measured: Kepler with drag, lobatto7 at 256 steps, 7e-14
        // against 1e-15 off at T = 20; with fresh factors on every step or with the test
        // below, 1e-15 to 4e-15). Until they are refreshed, an iterate is accepted only
        // from the second iteration on, once its estimated error (θ / (1 − θ) times the last
        // correction) is below the round-off of the increments; a solve that needs more
        // than two iterations makes the next ones start from fresh factors (1, 3, 7, … of
        // them after successive failures), since the factors then cost more than they save.
        let mut stale = o.simplified
            && self.have_factors
            && carried.is_none()
            && !(L::COSTLY_FACTORS || self.costly_factors);
        if stale && self.stale_skip > 0 {
            self.stale_skip -= 1;
            self.have_factors = false;
            stale = false;
        }
        let began_stale = stale;
        if stale {
            jac_scale = self.jac_scale;
        }
        // The rows' terms and sizes at the guess, unless the first iteration makes fresh
        // factors and so makes them again before any use (every fixed step of a small
        // model: a tenth of the solve's own instructions on coupled van der Pol, lobatto3).
        let refresh_first = carried.is_none() && !(o.simplified && self.have_factors);
        // Where the first iteration makes fresh factors at the guess, the residual there
        // comes from the same evaluation (see `NonlinearSystem::residual_and_jacobian`).
        // Measured (callgrind, whole fixed-step runs, against a residual of its own):
        // coupled van der Pol lobatto3 at h = 0.01 −2.1 % instructions, Kepler with drag
        // lobatto3 at h = 0.05 −5.7 % and lobatto7 at h = 0.385 −3.3 %, the double pendulum
        // lobatto6 at h = 0.185 −4.0 %; where stale factors serve the first iteration
        // (lobatto5 at h = 0.01, a linear model) +0.1 to +0.2 %.
        let mut prefactored = refresh_first && o.max_iterations > 0;
        if prefactored {
            self.jrow_valid = false;
            jac_scale = lin.refresh_with_residual(sys, z, &mut self.r)?;
        } else {
            L::residual(sys, z, &mut self.r)?;
            if !max_norm(self.r.entries()).is_finite() {
                return Err(NewtonFailure::NonFinite);
            }
        }
        let mut rnorm = if prefactored {
            f64::NAN
        } else {
            self.row_terms(lin, sys, jac_scale);
            self.row_sizes(z)
        };
        self.carried_error = 0.0;
        self.last_iterations = 0;
        // The iteration whose factors were made at its start (0: none in this solve), and
        // whether the factors in use were kept past a contraction measured against another
        // set's correction (see below): their iterates are then judged as stale ones'.
        let (mut refreshed_at, mut relaxed) = (0, false);
        // The next correction, already in `dz` (see the first iterate's test below).
        let mut ahead: Option<f64> = None;
        let mut it = 0;
        while it < o.max_iterations {
            it += 1;
            self.last_iterations = it;
            // The factors made with the residual above serve the first iteration only.
            let factored = std::mem::take(&mut prefactored);
            if carried.is_none() && !(o.simplified && self.have_factors) {
                self.jrow_valid = false;
                if !factored {
                    jac_scale = lin.refresh(sys, z)?;
                }
                self.jac_scale = jac_scale;
                stale = false;
                relaxed = false;
                refreshed_at = it;
                self.have_factors = true;
                self.factors_h = self.step_h;
                self.row_terms(lin, sys, jac_scale);
                rnorm = self.row_sizes(z);
                ahead = None;
            }
            // Below this level residuals at the current iterate are round-off.
            let res_floor = ROW_FLOOR;
            let mut full = match ahead.take() {
                Some(full) => full,
                None => self.direction(lin)?,
            };
            if let Some(ratio) = carried {
                self.dz.entries_mut().iter_mut().for_each(|x| *x *= ratio);
                full *= ratio;
            }
            // Rows apart: the line search weighs each row by its size at the larger of
            // `|z|` and `|z + dz|` (at a start from rest, `z = 0`, a row with no scale of
            // its own would otherwise weigh its first nonzero residual as a growth).
            if L::rows_apart(sys) {
                let ends = z.entries().iter().zip(self.dz.entries());
                let (reach, now) = ends.fold((0.0f64, 0.0f64), |(m, n), (x, d)| {
                    (m.max((x + d).abs()), n.max(x.abs()))
                });
                let grown = reach - now;
                if grown > 0.0 {
                    let jg = self.jrow_weight * grown;
                    for (x, j) in self.sigma.entries_mut().iter_mut().zip(self.jrow.entries()) {
                        *x += j * jg;
                    }
                    rnorm = weighted_norm(self.r.entries(), self.sigma.entries());
                }
            }
            // Carried factors get the full step only: a step that needs halving means
            // they are off.
            let backtracks_allowed = if carried.is_some() {
                0
            } else {
                o.max_backtracks
            };
            let search =
                self.line_search::<S, L>(sys, z, (rnorm, res_floor), full, backtracks_allowed)?;
            // The ratio of carried factors that are kept: their second correction follows.
            let mut polish = None;
            if let Some(ratio) = carried.take() {
                let kept = matches!(search, Some((_, 0, tn)) if tn <= CARRY_THETA * rnorm || tn <= res_floor);
                if !kept {
                    // Redo this iteration from the same iterate with fresh factors.
                    self.reject_carry();
                    it -= 1;
                    continue;
                }
                self.carry_backoff = 0;
                polish = Some(ratio);
            }
            let Some((lambda, halvings, trial_norm)) = search else {
                continue;
            };
            backtracks += halvings;
            std::mem::swap(z, &mut self.z_trial);
            std::mem::swap(&mut self.r, &mut self.r_trial);
            if let Some(ratio) = polish {
                // Carried factors leave a relative error θ in the correction, spread over
                // all the unknowns: the interior control points' correction, far larger
                // than the estimate, would leak θ times itself into the end point, and
                // divided by h into the node velocities and so into the momentum. A
                // second correction with the same factors, from the residual just
                // evaluated, takes that to θ², and the residual is evaluated again for the
                // node values. Measured on the paper model: without the second correction,
                // lobatto2 took 33–108 % more steps (overestimates); without the new node
                // values, still 33 %.
                let second = ratio * self.direction(lin)?;
                if second <= self.negligible {
                    // Too small to matter to the estimate: the iterate and its node values
                    // stay those of the first correction, off by about `second`.
                    self.carried_error = second;
                } else {
                    for (x, d) in z.entries_mut().iter_mut().zip(self.dz.entries()) {
                        *x += ratio * d;
                    }
                    // What the corrections after it would add, at their contraction rate.
                    self.carried_error = error_estimate(2, second, second / full);
                    L::residual(sys, z, &mut self.r)?;
                }
            }
            let step = lambda * full;
            let theta = step / prev_step;
            // A residual that grows from below its round-off floor is noise, not divergence:
            // with kept factors, an iterate there whose estimated error is a hair above the
            // increments' round-off takes further corrections of noise (contraction near 1),
            // and counted as growth they ended a converged solve as diverged (a Cartesian
            // double pendulum, lobatto5 at h = 0.02: residuals 2e-17 to 7e-17, 700 times
            // below the floor). The contraction there refreshes the factors instead, and a
            // fresh iterate at the floor is accepted.
            if trial_norm > rnorm && it > 1 && rnorm > ROW_FLOOR {
                growth += 1;
                if growth >= 3 {
                    return Err(NewtonFailure::Diverged {
                        residual: max_norm(self.r.entries()),
                    });
                }
            }
            // The residual's contraction over this iteration: with factors of an earlier
            // solve, about the relative error θ of their correction.
            let contraction = trial_norm / rnorm;
            prev_step = step;
            self.last_step = step;
            let znorm = max_norm(z.entries());
            // The rows' sizes at the new iterate (the weights of the next line search).
            rnorm = self.row_sizes_at(znorm);
            let floor = ROW_FLOOR;
            // A residual at the round-off floor cannot be reduced further: the iterate is as
            // exact as the problem's conditioning allows, even if the increments are noise.
            // After the first correction, only a residual a sixteenth of the floor (four ε
            // of its terms) ends the solve: where a linear system lands in one correction
            // (measured: at most 0.5 ε on the damped oscillator), not the 13 ε and more of
            // a nonlinear one's first iterate, which a second correction still improves.
            self.last_at_floor = rnorm <= floor;
            let at_floor = rnorm <= if it > 1 { floor } else { floor / 16.0 };
            let small_error = error_estimate(it, step, theta) <= o.rtol * znorm + o.atol;
            // Made only where it decides (a weighted norm per iterate otherwise).
            let small_residual =
                || weighted_norm(self.r.entries(), self.rho.entries()) <= o.residual_tol;
            // After a far start the second iterate is accepted by the error test alone
            // (its contraction measured), not for a residual at the floor.
            let polished = !(far_start && it < 3)
                || (it == 2 && small_error && halvings == 0 && small_residual());
            // Factors of an earlier solve of a system whose Jacobian does not change (a
            // linear model at one step size) are exact: their iterates are judged as fresh
            // ones'.
            let exact = stale && L::constant_jacobian(sys);
            // Within the caller's bound (an adaptive step's share of its tolerance).
            let close = within > 0.0
                && it > 1
                && halvings == 0
                && error_estimate(it, step, theta) <= within;
            let accepted = close
                || if (stale && !exact) || relaxed {
                    it > 1
                        && halvings == 0
                        && error_estimate(it, step, theta) <= f64::EPSILON * znorm
                } else {
                    ((small_error && halvings == 0 && small_residual()) || at_floor) && polished
                };
            // The first iterate, whose contraction is not measured yet: accepted within the
            // bound where the correction that would follow (with the same factors, from the
            // residual just evaluated; kept for the next iteration otherwise) is at most half
            // of it and the residual contracted tenfold, so that those factors are good to
            // about 10 % and that correction is the iterate's error to about that.
            let accepted = accepted
                || if within > 0.0 && it == 1 && halvings == 0 && contraction <= 0.1 {
                    let next = self.direction(lin)?;
                    ahead = Some(next);
                    next <= 0.5 * within
                } else {
                    false
                };
            if accepted {
                if began_stale {
                    self.stale_outcome(stale && it <= 2);
                }
                return Ok(NewtonReport {
                    iterations: it,
                    residual: max_norm(self.r.entries()),
                    backtracks,
                    residual_bound: self.residual_bound(o.residual_tol),
                });
            }
            // Factors of an earlier solve get two iterations: an iterate they have not
            // brought below round-off by then (the increments themselves may be at the
            // round-off of the positions, a step from near rest) is finished with fresh
            // ones, by the tests above.
            if stale && it >= 2 {
                self.have_factors = false;
            }
            // After their first correction, the second leaves about θ² times the first:
            // where that will not be below round-off, fresh factors now save an iteration.
            if stale && it == 1 && contraction * contraction * step > f64::EPSILON * znorm {
                self.have_factors = false;
            }
            far_start |= it == 1 && o.simplified && L::COSTLY_FACTORS && step > FAR_START * znorm;
            // (After the last iteration there is none to refresh for; the factors may still
            // be carried to the next solve, which checks them.)
            let refresh = o.simplified
                && it < o.max_iterations
                && wants_fresh_jacobian(it, theta, step, znorm, L::COSTLY_FACTORS || stale);
            // Factors made at the start of this iteration, kept for the next one where the
            // rule above would refresh them, in two cases, and measured there:
            // - the first fresh factors after those of an earlier step (made at the start of
            //   the second iteration): θ compares their correction with the stale one's, so it
            //   does not measure their contraction;
            // - fresh factors after a far first correction (the far-start rule) of at most
            //   `FAR_KEPT`: in adaptive runs the predictor at a new step size starts 1e-3 to
            //   1e-2 of the increments off, and the factors there still contract by 1e-5 or
            //   less.
            // Their iterates are then accepted only once their estimated error is below
            // round-off, as stale factors' are (an iterate off by up to `rtol` on every step
            // adds up over a long run; see above), and they are refreshed once the measured
            // contraction predicts more than two further iterations to get there. Measured:
            // coupled van der Pol, lobatto7 at h = 0.25, after stale factors: the fresh
            // correction was 0.09 of the stale one, and refreshing again cost a second
            // Jacobian and LU on every step; kept, the next correction was 1e-5 of theirs.
            // Kepler with drag, adaptive lobatto6 at tol 1e-8: every step refreshed after
            // its first correction; kept, the second was 1e-6 of the first.
            let measured = relaxed && it > refreshed_at;
            let first_fresh = refreshed_at == it
                && if it == 1 {
                    !L::COSTLY_FACTORS
                        && o.simplified
                        && step <= FAR_KEPT * znorm
                        && z.entries().len() >= FAR_KEPT_MIN_UNKNOWNS
                } else {
                    began_stale && it == 2
                };
            if refresh && first_fresh && !relaxed {
                relaxed = true;
            } else if refresh || (measured && iterations_to_round_off(step, theta, znorm) > 2.0) {
                self.have_factors = false;
            }
        }
        if began_stale {
            self.stale_outcome(false);
        }
        Err(NewtonFailure::MaxIterations {
            residual: max_norm(self.r.entries()),
        })
    }

    /// The size of each row's terms at `z`, into `sigma`: `σ_a = ρ_a + ν_a + |J|_a |z|`,
    /// its scale `ρ_a` (`row_scales`), its round-off that does not shrink with `z` (`ν_a`,
    /// the system's noise) and the largest Jacobian entry of its group (`group_max`) times
    /// the largest unknown (at least `f64::MIN_POSITIVE / ε`; see [`round_off_floor`]). A
    /// residual row `|R_a| ≤ 64 ε σ_a` is at round-off.
    ///
    /// Without [`super::NonlinearSystem::rows_apart`], every row gets the largest of
    /// each term: `64 ε σ` is then [`round_off_floor`] itself. With it, a step's rows are
    /// grouped by coordinate (all control points of one), so that a coordinate whose terms
    /// are far smaller than another's is solved to its own round-off, not the other's.
    /// Measured: a Duffing oscillator beside an uncoupled mass of 1e12 (fixed lobatto4,
    /// h = 0.1) ended with its velocity 2.4e-7 off the oscillator alone with the largest
    /// row's terms, and 5.6e-17 with its own. Per row instead of per coordinate (or with
    /// `Σ_b |J_ab| |z_b|`, the sum of the row's linear terms), the stiff van der Pol at
    /// μ = 1e6 (adaptive lobatto8, tol 1e-9) took over 300 000 steps instead of 88 713:
    /// the rows of one coordinate share the round-off of its node values.
    fn row_sizes(&mut self, z: &V) -> f64 {
        self.row_sizes_at(max_norm(z.entries()))
    }

    /// [`Iteration::row_sizes`] with `znorm = |z|` already known; returns the residual's
    /// weighted norm `max_a |R_a| / σ_a` (NaN propagated), made in the same pass.
    fn row_sizes_at(&mut self, znorm: f64) -> f64 {
        const Z_RESOLVED: f64 = f64::MIN_POSITIVE / f64::EPSILON;
        let zr = if znorm < Z_RESOLVED {
            Z_RESOLVED
        } else {
            znorm
        };
        let jz = self.jrow_weight * zr;
        let (sigma, base, r) = (
            self.sigma.entries_mut(),
            self.base.entries(),
            self.r.entries(),
        );
        let (mut m, mut nan) = (0.0f64, false);
        if self.rows_apart {
            let terms = base.iter().zip(self.jrow.entries()).zip(r);
            for (x, ((b, j), v)) in sigma.iter_mut().zip(terms) {
                *x = b + j * jz;
                let a = v.abs() / *x;
                m = if a > m { a } else { m };
                nan |= a.is_nan();
            }
        } else {
            for (x, (b, v)) in sigma.iter_mut().zip(base.iter().zip(r)) {
                *x = b + jz;
                let a = v.abs() / *x;
                m = if a > m { a } else { m };
                nan |= a.is_nan();
            }
        }
        if nan { f64::NAN } else { m }
    }

    /// The terms of [`Iteration::row_sizes`] that change only with the system's scales, its
    /// noise and its Jacobian: `ρ_a + ν_a` into `base`, `|J|_a` into `jrow` (0 while
    /// `jac_scale` is: carried factors' first correction is judged without it). Made at a
    /// solve's start and after each refresh of the factors, not at every iterate (on the
    /// damped oscillator, adaptive lobatto5, the per-iterate scan of the Jacobian was a
    /// tenth of the run).
    fn row_terms<S: ?Sized, L: LinearSolver<S, Vector = V>>(
        &mut self,
        lin: &L,
        sys: &S,
        jac_scale: f64,
    ) {
        let base = self.base.entries_mut();
        self.rows_apart = L::rows_apart(sys);
        if self.rows_apart {
            // `ρ_a + ν_a`, the noise added onto the scales in place.
            base.copy_from_slice(self.rho.entries());
            L::add_row_noise(sys, base);
            // The Jacobian's rows are scanned once per set of factors.
            if jac_scale > 0.0 && !self.jrow_valid {
                let jrow = self.jrow.entries_mut();
                lin.row_max(jrow);
                L::group_max(sys, jrow);
                self.jrow_valid = true;
            }
            self.jrow_weight = if jac_scale > 0.0 { 1.0 } else { 0.0 };
        } else {
            base.fill(0.0);
            L::add_row_noise(sys, base);
            // One size for every row: the largest scale, noise and `|J| |z|`.
            let one = max_norm(self.rho.entries()) + max_norm(base);
            base.fill(one);
            self.jrow_weight = jac_scale;
        }
    }

    /// The bound an accepted iterate's residual met: the largest
    /// `max(residual_tol ρ_a, 64 ε σ_a)` (see [`Iteration::row_sizes`]).
    fn residual_bound(&self, residual_tol: f64) -> f64 {
        let mut b = 0.0f64;
        for (r, s) in self.rho.entries().iter().zip(self.sigma.entries()) {
            b = b.max((residual_tol * r).max(ROW_FLOOR * s));
        }
        b
    }

    /// After a solve that began with factors of an earlier one: on success (accepted by
    /// its second iteration) they are tried again on the next solve; otherwise the next
    /// solves make fresh factors first (1, 3, 7, … of them after successive failures).
    fn stale_outcome(&mut self, paid: bool) {
        if paid {
            self.stale_backoff = 0;
        } else {
            self.stale_skip = self.stale_backoff;
            self.stale_backoff = (2 * self.stale_backoff + 1).min(CARRY_BACKOFF_MAX);
        }
    }

    /// The Newton direction `dz = −J⁻¹ R` from the current factors; returns `|dz|`.
    #[inline]
    fn direction<S: ?Sized, L: LinearSolver<S, Vector = V>>(
        &mut self,
        lin: &mut L,
    ) -> Result<f64, NewtonFailure> {
        self.dz.entries_mut().copy_from_slice(self.r.entries());
        lin.solve_in_place(&mut self.dz);
        // Negated and measured in one pass (NaN propagated, as in `max_norm`).
        let (mut full, mut nan) = (0.0f64, false);
        for x in self.dz.entries_mut() {
            *x = -*x;
            let a = x.abs();
            full = if a > full { a } else { full };
            nan |= a.is_nan();
        }
        let full = if nan { f64::NAN } else { full };
        if !full.is_finite() {
            return Err(NewtonFailure::NonFinite);
        }
        Ok(full)
    }

    /// The line search on the residual norm along `dz`, whose norm is `full`:
    /// `Some((λ, halvings, |R|))` with the trial in `z_trial` and `r_trial`, or `None` when
    /// stale factors must be refreshed and the iteration retried.
    #[inline]
    fn line_search<S: ?Sized, L: LinearSolver<S, Vector = V>>(
        &mut self,
        sys: &mut S,
        z: &V,
        (rnorm, res_floor): (f64, f64),
        full: f64,
        max_backtracks: usize,
    ) -> Result<Option<(f64, usize, f64)>, NewtonFailure> {
        let o = self.opts;
        let (mut lambda, mut halvings) = (1.0, 0);
        loop {
            let trial = self.z_trial.entries_mut();
            for ((t, x), d) in trial.iter_mut().zip(z.entries()).zip(self.dz.entries()) {
                *t = x + lambda * d;
            }
            let tn = match L::residual(sys, &self.z_trial, &mut self.r_trial) {
                Ok(()) => weighted_norm(self.r_trial.entries(), self.sigma.entries()),
                Err(_) => f64::NAN,
            };
            if tn.is_finite() && (tn <= rnorm * (1.0 - 1e-4 * lambda) || tn <= res_floor) {
                return Ok(Some((lambda, halvings, tn)));
            }
            // A full step that grows the residual right next to the solution is still
            // accepted once: Newton's local convergence, not the norm, is then in charge.
            if tn.is_finite() && halvings == 0 && full <= o.rtol * max_norm(z.entries()) + o.atol {
                return Ok(Some((lambda, halvings, tn)));
            }
            halvings += 1;
            if halvings > max_backtracks {
                if o.simplified && self.have_factors {
                    // Stale factors: retry this iteration with a fresh Jacobian.
                    self.have_factors = false;
                    return Ok(None);
                }
                return Err(NewtonFailure::Stagnated {
                    residual: max_norm(self.r.entries()),
                });
            }
            lambda *= 0.5;
        }
    }
}

/// The estimated error of the iterate after a step of size `step` with contraction rate
/// `θ` (Hairer's `step · θ / (1 − θ)`; the step itself on the first iteration).
#[inline]
fn error_estimate(it: usize, step: f64, theta: f64) -> f64 {
    if it == 1 || !theta.is_finite() {
        step
    } else if theta < 1.0 {
        step * theta / (1.0 - theta)
    } else {
        f64::INFINITY
    }
}

/// The further iterations with factors that contract by `θ` after a correction of size
/// `step` until the estimated error `step θ / (1 − θ)` is below the round-off of `z` (of
/// max-norm `znorm`): infinite where they do not contract.
fn iterations_to_round_off(step: f64, theta: f64, znorm: f64) -> f64 {
    let floor = f64::EPSILON * znorm;
    let err = error_estimate(2, step, theta);
    if err <= floor {
        0.0
    } else if theta > 0.0 && theta < 1.0 {
        ((floor / err).ln() / theta.ln()).ceil()
    } else {
        f64::INFINITY
    }
}

/// Whether simplified Newton should refresh its factors after iteration `it`. Stale factors
/// contract slowly; a fresh Jacobian restores quadratic convergence, so the accepted iterate
/// is as exact as full Newton's. After the first iteration θ is unknown; a small first
/// correction means a good initial guess, so the factors taken there stay accurate, and a
/// large one refreshes them (unless the solve keeps them to measure θ: see
/// [`Iteration::solve`]), unless factoring is `costly`: then the second iteration
/// measures θ first, and the iterate is accepted no earlier than the third (a solve and a
/// residual cost little next to a large sparse LU; on the 2-D lattice at n = 256 the
/// first-correction rule refactored on every lobatto2 step, where θ stayed below 1e-2).
#[inline]
fn wants_fresh_jacobian(it: usize, theta: f64, step: f64, znorm: f64, costly: bool) -> bool {
    if it > 1 || costly {
        it > 1 && theta > THETA_REFRESH
    } else {
        step > FAR_START * znorm
    }
}
