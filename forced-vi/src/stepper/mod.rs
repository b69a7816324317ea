//! The one stepping loop of every model size (DESIGN §10): predictor, Newton solve of the
//! step equations on a `StepBackend` (the `backend` module), compensated update, subdivision on
//! failure, adaptive steps, diagnostics on request, and the checks that make every `Ok` step
//! trustworthy. What differs between a small and a large model is the backend's linear
//! algebra; everything here is written once, over slices.
//!
//! **What each model compiles.** The stepper is generic over the model, so every model type
//! gets its own copy of what is generic, compiled by LLVM at each user's build. The work that
//! does not call the model's kernels is therefore kept out of the generic code: the Newton
//! iteration runs on a `dyn NonlinearSystem`, and the initial state of a run, the first step, the
//! error estimate's lift and comparison, the tangent's propagation, the sparse backend's set-up
//! and a constrained step's projection are functions over slices and `dyn StepBackend`
//! (one copy for every model) or generic over the number of coordinates only (one copy per
//! `N`). Where the indirection showed in a small model's step (the predictor, the update)
//! the code stays generic. A model that promises no constraints
//! ([`ForcedLagrangian::CONSTRAINED`] `= false`, which the macro sets) compiles none of the
//! constrained step's code: it sits behind that constant, which the compiler resolves
//! before it generates code. Measured (`cargo llvm-lines`, lines of LLVM IR): the test binary
//! `models_suite` (43 models run end to end) 3.00M before, 2.72M after (−9.6 %); the report's
//! library (39 models) 2.61M before, 2.15M after (−17.7 %). Instructions (callgrind, coupled
//! van der Pol and Kepler): −0.3 % for fixed lobatto3 steps, −0.1 % for lobatto5, +0.3 to
//! +0.6 % for adaptive runs. Fewer lines did not make the whole test build measurably
//! faster: 532 s before and 543 s after, one fresh build each on a shared machine whose
//! speed varies by ±15 %.
//!
//! | piece | module |
//! |---|---|
//! | the [`Stepper`] type, its records, its iterator, its stack guard; [`StepOptions`] | this one |
//! | the start of a run: the checks, the initial state, the first record's data | `start` |
//! | one step: Newton solve, update, the mass check; subdivision on failure | `advance` |
//! | adaptive steps: the reference-scheme estimate, the controller, the first step (DESIGN §8) | `adaptive` |
//! | compensated sums and the state saved for retries | `state` |
//! | the tangent of the flow for sensitivities (DESIGN §12) | `tangent` |
//! | the discrete adjoint: the tape and the backward pass (DESIGN §12) | `adjoint` |
//! | the predictor from the previous step's polynomial | `predict` |
//! | checks of a run, of initial data, of the time flag; step counts; non-finite values | `checks` |

mod adaptive;
mod adjoint;
mod advance;
mod checks;
pub(crate) use checks::non_finite;
mod linearized;
mod predict;
mod start;
mod state;
mod tangent;
mod tangent_constrained;

use nalgebra::SVector;

use crate::backend::{Backend, StepBackend};
use crate::control::{Controller, Tolerance};
use crate::error::Error;
use crate::model::{ForcedLagrangian, NodeJacobian};
use crate::newton::NewtonOptions;
use crate::scheme::Scheme;
use crate::trajectory::{RunFailure, RunStats, StepRecord, energy};

use state::State;

/// Options of the stepper. `Default`: default [`NewtonOptions`], no subdivision, at most
/// [`StepOptions::DEFAULT_MAX_STEPS`] steps.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub struct StepOptions {
    /// The Newton solver's options.
    pub newton: NewtonOptions,
    /// A failed step is retried as 2, 4, …, `2^max_subdivisions` substeps (default 0: off).
    pub max_subdivisions: u32,
    /// The most steps a run may take; a longer run is refused before it starts
    /// ([`Error::TooManySteps`]).
    pub max_steps: usize,
    /// Adaptive runs: the largest step (default `∞`).
    pub max_step: f64,
    /// Adaptive runs: the smallest step other than the last one (default 0).
    pub min_step: f64,
    /// Adaptive runs: estimate the local error once over two steps where that is sound
    /// (`None`, the default: on the dense path, off on the sparse one; see
    /// [`Integrator::paired_estimates`](crate::Integrator::paired_estimates)).
    pub paired_estimates: Option<bool>,
}

impl StepOptions {
    /// The smallest step size, and the smallest positive final time, a run accepts:
    /// `2⁻⁹⁷⁰ ≈ 1.0e-292` (`f64::MIN_POSITIVE / ε`). A step's equations hold `1 / h` times
    /// the scheme's coefficients and the model's mass, and a velocity is an increment over
    /// `h`: below this they may leave the range of `f64` (measured: `h = 2.3e-308` made
    /// them overflow), while every step above it keeps 16 digits of headroom.
    pub const SMALLEST_STEP: f64 = f64::MIN_POSITIVE / f64::EPSILON;
    /// The default cap on steps per run: 10⁹.
    pub const DEFAULT_MAX_STEPS: usize = 1_000_000_000;
    /// The most subdivision levels a step may use: 2²⁰ substeps.
    pub const MAX_SUBDIVISION_LEVELS: u32 = 20;

    /// Checks `0 ≤ min_step ≤ max_step`, `min_step` finite, `max_step` positive.
    pub fn check_step_bounds(&self) -> Result<(), Error> {
        let (lo, hi) = (self.min_step, self.max_step);
        if lo.is_finite() && lo >= 0.0 && hi > 0.0 && lo <= hi {
            Ok(())
        } else {
            Err(Error::InvalidStepBounds {
                min_step: lo,
                max_step: hi,
            })
        }
    }
}

impl Default for StepOptions {
    fn default() -> Self {
        StepOptions {
            newton: NewtonOptions::default(),
            max_subdivisions: 0,
            max_steps: Self::DEFAULT_MAX_STEPS,
            max_step: f64::INFINITY,
            min_step: 0.0,
            paired_estimates: None,
        }
    }
}

/// What a run is: the model, the scheme, the step, the options and the tolerances.
pub(crate) struct RunSetup<'a, M, const N: usize> {
    pub(crate) model: &'a M,
    pub(crate) scheme: &'a Scheme,
    pub(crate) h: f64,
    /// Adaptive runs: the first step from the initial data, not `h`.
    pub(crate) auto_first_step: bool,
    pub(crate) options: StepOptions,
    pub(crate) tolerance: Option<Tolerance<N>>,
}

/// The stack a step of the model needs, in bytes: on the dense backend, the node kernels'
/// own ([`ForcedLagrangian::KERNEL_STACK_BYTES`]) and a few `N × N` node blocks, which the
/// kernels return by value; on either, a few records of `N`-vectors.
/// A constrained model on the dense backend needs the general constraint kernels' stack
/// too ([`crate::model::general::constraint_stack_bytes`]).
pub(crate) const fn step_stack_bytes<M: ForcedLagrangian<N>, const N: usize>(
    dense: bool,
    constrained: bool,
) -> usize {
    let records = 16 * std::mem::size_of::<StepRecord<N>>() + 256 * 1024;
    if dense {
        let blocks = 8 * std::mem::size_of::<NodeJacobian<N>>();
        let kernels = if constrained {
            let c = crate::model::general::constraint_stack_bytes::<N>();
            if c > M::KERNEL_STACK_BYTES {
                c
            } else {
                M::KERNEL_STACK_BYTES
            }
        } else {
            M::KERNEL_STACK_BYTES
        };
        records.saturating_add(blocks).saturating_add(kernels)
    } else {
        records
    }
}

pub(crate) use crate::stack::with_stack;

/// Steps a model through time; an iterator over [`StepRecord`]s, initial state first.
///
/// The same stepper runs every model size, on the dense or the sparse backend (see
/// [`LinearPath`](crate::LinearPath)), with fixed or adaptive steps. After an error the
/// iterator yields that error once and then ends.
pub struct Stepper<'a, M, const N: usize> {
    model: &'a M,
    scheme: &'a Scheme,
    backend: Backend<'a, M, N>,
    /// Adaptive runs: the error estimate's backend, on [`Scheme::error_reference`], and
    /// `ℓ_m(d'_j)`, the step polynomial at its control points (row `j − 1`, column
    /// `m − 1`).
    reference: Option<Backend<'a, M, N>>,
    lift: &'a [f64],
    /// Adaptive runs of a Lobatto scheme: the Lagrange basis of the step's quadrature nodes
    /// at the reference's (row `j`: its node `j`), which interpolates the step's node blocks
    /// into the reference's Jacobian (see [`crate::control`]); empty where the reference
    /// evaluates its own.
    block_weights: &'a [f64],
    /// Adaptive runs: the accumulated round-off, squared, in the tolerance's norm (see
    /// [`crate::control`]).
    round_off_sq: f64,
    /// Adaptive runs: the differences left out of the accepted steps' estimates as their
    /// round-off, added up, in the tolerance's norm; and the last estimate's (see
    /// [`crate::control`]).
    unresolved: f64,
    unresolved_step: f64,
    /// The resolution of the last estimate (see `adaptive::local_error`).
    resolution: f64,
    options: StepOptions,
    /// The step size: `h_setup`, or the first step chosen from the initial data.
    h: f64,
    /// The run set-up's step size, and whether an adaptive run chooses its first step
    /// instead (kept for a restart, [`Stepper::restart`]).
    h_setup: f64,
    auto_first_step: bool,
    t_final: f64,
    n_steps: usize,
    k: usize,
    state: State,
    saved: State,
    energy0: f64,
    /// Sign of the mass matrix's determinant at the start: a step that changes it has
    /// crossed a singular mass.
    mass_sign: f64,
    /// Scratch of `N` entries: the end of a step's positions, its velocity, and the
    /// estimated local error of `(q, p)`.
    q_end: Vec<f64>,
    v_end: Vec<f64>,
    /// Scratch: the momentum update of a step.
    dp: Vec<f64>,
    /// Scratch: the predictor's basis values at one control point (entry `m = 1 … s − 1`).
    basis: Vec<f64>,
    /// The predictor's extrapolation for the step being solved, before the correction by
    /// the last step's `pred_delta`, and whether it was made at a step size near the last one.
    extrapolated: Vec<f64>,
    extrapolated_near: bool,
    err: (Vec<f64>, Vec<f64>),
    /// The time of the record last handed out.
    t: f64,
    /// Adaptive runs: the tolerances, the controller and the next step to try.
    tolerance: Option<Tolerance<N>>,
    controller: Controller,
    h_next: f64,
    /// Adaptive runs: the pace of the run (see [`crate::control`], "The pace of a run").
    pace: adaptive::Pace,
    /// The last accepted step's [`StepRecord::error_estimate`].
    estimate: f64,
    /// The last accepted step's estimate per unit step, in the tolerance's norm (0 before
    /// the first): it bounds the next step's Newton error (see `crate::control`, "Newton's
    /// stop").
    err_last: f64,
    /// Adaptive runs of a model whose factors cost most of a step, or a linear model's (see
    /// [`crate::control`]'s step-size bands): a step that the controller would resize by a
    /// factor within the band (`crate::control::BAND` or `LINEAR_BAND`) keeps its size, and
    /// so its factors.
    band: Option<crate::control::Band>,
    /// Final state only: no velocity solve, energy, work or record per step.
    lean: bool,
    /// Sensitivity runs: the tangent of the flow (DESIGN §12).
    tangent: Option<Box<linearized::Tangent>>,
    /// A constrained model: the step's multipliers interpolated to the reference's control
    /// points `0 … r − 2` (row `j`: the Lagrange basis of the step's control points there).
    lift_lambda: &'a [f64],
    /// Adaptive runs of a model without constraints: the tables of a reference step over
    /// two steps (`EstimateTables::pair_lift`, `pair_second`; empty otherwise), the first
    /// step of a pair kept while the second is solved, and an accepted pair's second step,
    /// handed out at the next call (see [`crate::control`], "Pairs").
    pair_lift: (&'a [f64], &'a [bool]),
    pair: Option<Box<adaptive::PairFirst>>,
    pending: Option<adaptive::Pending>,
    /// A constrained model: the mean constraint force over the last step (DESIGN §11).
    cforce: Vec<f64>,
    /// Adjoint runs: the steps kept for the backward pass (DESIGN §12).
    tape: Option<Box<adjoint::Tape>>,
    /// Adaptive runs with [`output::Samples`](crate::output::Samples): the next output
    /// time, on which a step ends.
    stop: Option<f64>,
    /// The stack a step needs ([`step_stack_bytes`]).
    stack: usize,
    stats: RunStats,
    started: bool,
    done: bool,
}

impl<M: ForcedLagrangian<N>, const N: usize> Stepper<'_, M, N> {
    /// Number of steps the run will take (for an adaptive run, the number it would take
    /// with its first step size).
    pub fn total_steps(&self) -> usize {
        self.n_steps
    }

    /// Totals so far.
    pub fn stats(&self) -> RunStats {
        self.stats
    }

    /// The backend the run steps on: [`LinearPath::Dense`](crate::LinearPath::Dense) or
    /// [`LinearPath::Sparse`](crate::LinearPath::Sparse).
    pub fn path(&self) -> crate::LinearPath {
        match self.backend {
            Backend::Dense(_) => crate::LinearPath::Dense,
            #[cfg(feature = "sparse")]
            Backend::Sparse(_) => crate::LinearPath::Sparse,
        }
    }

    fn time_of(&self, k: usize) -> f64 {
        if k >= self.n_steps {
            self.t_final
        } else {
            k as f64 * self.h
        }
    }

    /// The record of the current state; with `diagnostics`, its energy and balance too
    /// (else zero, and `v` is the step polynomial's end slope in a lean run).
    fn record_state(
        &self,
        newton_iterations: usize,
        residual: f64,
        substeps: usize,
        diagnostics: bool,
    ) -> StepRecord<N> {
        let st = &self.state;
        let (energy, energy_balance) = if diagnostics {
            let e = energy(self.model, self.t, &st.q.sum, &st.v, &st.p.sum).unwrap_or(f64::NAN);
            (e, e - self.energy0 - st.work.0)
        } else {
            (0.0, 0.0)
        };
        StepRecord {
            step: self.k,
            t: self.t,
            q: SVector::from_column_slice(&st.q.sum),
            p: SVector::from_column_slice(&st.p.sum),
            v: SVector::from_column_slice(&st.v),
            energy,
            energy_balance,
            newton_iterations,
            residual,
            substeps,
            error_estimate: self.estimate,
            constraint_force: SVector::from_column_slice(&self.cforce),
            constraint_residual: 0.0,
        }
    }

    /// [`Self::record_state`], with the constraint residual `max(|g|, |G v + ∂g/∂t|)` among the
    /// diagnostics.
    fn record(
        &mut self,
        newton_iterations: usize,
        residual: f64,
        substeps: usize,
        diagnostics: bool,
    ) -> StepRecord<N> {
        let mut rec = self.record_state(newton_iterations, residual, substeps, diagnostics);
        if diagnostics && self.model.constraint_count() > 0 {
            let st = &self.state;
            let at = (self.t, &st.q.sum[..], &st.v[..]);
            rec.constraint_residual = match self.backend.constraint_residuals(at) {
                Ok([g, gv, _, _]) => g.max(gv),
                Err(_) => f64::NAN,
            };
        }
        rec
    }

    /// Leaves out the per-step diagnostics (velocity solve, energy, work, balance): the
    /// iterator's records then hold the state alone until [`Stepper::finish`].
    pub(crate) fn set_lean(&mut self, lean: bool) {
        self.lean = lean;
    }

    /// The next output time of the run, if any: an adaptive step over it ends on it (see
    /// [`crate::control`], "Output times").
    pub(crate) fn set_next_output(&mut self, t: Option<f64>) {
        self.stop = t;
    }

    /// The full record of the current state: the velocity solve and the energy. In a lean
    /// run the work was not summed, so the balance is not known: it is reported as zero.
    pub(crate) fn finish(&mut self) -> Result<StepRecord<N>, Error> {
        with_stack(self.stack, || {
            if self.lean && self.k > 0 {
                self.solve_velocity()?;
            }
            let mut rec = self.record(0, 0.0, 1, true);
            if self.lean {
                rec.energy_balance = 0.0;
            }
            // As for every record: a NaN energy at a representable state is the model's
            // (a Lagrangian that is NaN there, with finite derivatives), not an overflow.
            let size = || rec.q.amax().max(rec.p.amax()).max(rec.v.amax());
            match checks::record_error(&rec, size, self.k, self.t) {
                Some(error) => Err(error),
                None => Ok(rec),
            }
        })
    }

    /// The failure of this run with `error`: the totals, and the last state the run
    /// reached (its `q` and `p`; `v` is the step polynomial's end slope and the energy
    /// fields are zero in a lean run).
    pub(crate) fn failure(&self, error: Error) -> RunFailure<N> {
        let last = self
            .started
            .then(|| Box::new(self.record_state(0, 0.0, 1, false)));
        RunFailure::after(error, self.stats, last)
    }

    /// Solves `L_v(q, v) = p` at the current state, from the current `v`.
    fn solve_velocity(&mut self) -> Result<(), Error> {
        let st = &mut self.state;
        let at = (self.t, &st.q.sum[..], &st.p.sum[..]);
        self.backend.velocity(at, &mut st.v, self.k)
    }
}

/// What an accepted step took: its linear solves, its last residual and its substeps.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Stepped {
    iters: usize,
    residual: f64,
    substeps: usize,
}

impl<M: ForcedLagrangian<N>, const N: usize> Stepper<'_, M, N> {
    /// The next step of the run, if any, without its record: `Some(Ok(()))` after a step
    /// (or at the start), `None` at the end. A run that keeps only its final state steps
    /// with this, and makes the one record it needs at the end ([`Stepper::finish`]).
    pub(crate) fn advance_quietly(&mut self) -> Option<Result<(), Error>> {
        self.next_step().map(|out| out.map(|_| ()))
    }

    fn next_step(&mut self) -> Option<Result<Option<Stepped>, Error>> {
        if self.done {
            return None;
        }
        if !self.started {
            self.started = true;
            return Some(Ok(None));
        }
        if self.k >= self.n_steps && self.tolerance.is_none() {
            self.done = true;
            return None;
        }
        let out = match self.tolerance {
            Some(tol) if self.t < self.t_final => {
                with_stack(self.stack, || self.step_adaptive(&tol))
            }
            Some(_) => {
                self.done = true;
                return None;
            }
            None => with_stack(self.stack, || self.step()),
        };
        if out.is_err() {
            self.done = true;
        }
        Some(out.map(Some))
    }
}

impl<M: ForcedLagrangian<N>, const N: usize> Iterator for Stepper<'_, M, N> {
    type Item = Result<StepRecord<N>, Error>;

    fn next(&mut self) -> Option<Self::Item> {
        // A step and its record hold `[f64; N]` values: the stack a run takes, for a
        // stepper driven from any thread.
        crate::stack::with_run_stack::<N, _>(|| {
            let out = match self.next_step()? {
                Ok(Some(done)) => with_stack(self.stack, || self.emit(done)),
                Ok(None) => with_stack(self.stack, || Ok(self.record(0, 0.0, 1, true))),
                Err(e) => Err(e),
            };
            if out.is_err() {
                self.done = true;
            }
            Some(out)
        })
    }
}
