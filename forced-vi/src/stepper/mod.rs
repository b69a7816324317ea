//! The stepping loop: predictor, Newton solve of the step equations, compensated update,
//! subdivision on failure, and the checks that make every `Ok` step trustworthy.
//!
//! | piece | module |
//! |---|---|
//! | the [`Stepper`] type, its records and its iterator | this one |
//! | the start of a run: the initial state and the first record's data | `start` |
//! | one step: Newton solve, update, the mass check; subdivision on failure | `advance` |
//! | adaptive steps by step doubling (DESIGN §8) | `adaptive` |
//! | compensated sums, snapshots for retries, the predictor | `state` |
//! | checks of a run, of initial data, of the time flag; step counts; non-finite values | `checks` |

mod adaptive;
mod advance;
mod checks;
mod start;
mod state;

use nalgebra::{DVector, SVector};

use crate::control::{Controller, Tolerance};
use crate::error::Error;
use crate::initial::{solve_velocity, InitialState};
use crate::integrator::{Integrator, StepOptions};
use crate::model::ForcedLagrangian;
use crate::newton::Newton;
use crate::step_equations::StepProblem;
use crate::trajectory::{energy, non_finite_field, RunStats, StepRecord};

#[cfg(feature = "sparse")]
pub(crate) use checks::{check_finite, check_run, newton_error, record_error, step_count};
#[cfg(feature = "sparse")]
pub(crate) use state::kahan_add;
use state::Kahan;

/// Runs `f` on a stack with room for the model's node kernels: the caller's own stack when
/// it has `M::KERNEL_STACK_BYTES` to spare, else a fresh one on the heap (`stacker`).
#[inline]
pub(crate) fn with_kernel_stack<M: ForcedLagrangian<N>, const N: usize, R>(
    f: impl FnOnce() -> R,
) -> R {
    // The stepper's own frames: a few records, snapshots and matrices of the model's size.
    let own = 64 * std::mem::size_of::<StepRecord<N>>() + 256 * 1024;
    let need = M::KERNEL_STACK_BYTES.saturating_add(own);
    if need <= 256 * 1024 {
        f()
    } else {
        stacker::maybe_grow(need, need.saturating_mul(2), f)
    }
}

/// Steps a model through time; an iterator over [`StepRecord`]s, initial state first.
///
/// After an error the iterator yields that error once and then ends.
pub struct Stepper<'a, M, const N: usize> {
    prob: StepProblem<'a, M, N>,
    newton: Newton,
    options: StepOptions,
    h: f64,
    t_final: f64,
    n_steps: usize,
    k: usize,
    q: Kahan<N>,
    p: Kahan<N>,
    v: SVector<f64, N>,
    energy0: f64,
    work: (f64, f64),
    z: DVector<f64>,
    z_prev: Vec<SVector<f64, N>>,
    z_saved: Vec<SVector<f64, N>>,
    has_prev: bool,
    h_prev: f64,
    scale_f: f64,
    /// Sign of the mass matrix's determinant at the start: a step that changes it has
    /// crossed a singular mass.
    mass_sign: f64,
    /// The time of the record last handed out.
    t: f64,
    /// The time of the current state `(q, p)` (ahead of `t` between substeps).
    t_state: f64,
    /// Adaptive runs: the tolerances, the controller and the next step to try.
    tolerance: Option<Tolerance<N>>,
    controller: Controller,
    h_next: f64,
    /// Final state only: no velocity solve, energy, work or record per step.
    lean: bool,
    stats: RunStats,
    started: bool,
    done: bool,
}

impl<'a, M: ForcedLagrangian<N>, const N: usize> Stepper<'a, M, N> {
    pub(crate) fn new(
        integ: &'a Integrator<'a, M, N>,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<Self, Error> {
        with_kernel_stack::<M, N, _>(|| Self::start(integ, init, t_final))
    }

    /// Number of steps the run will take (for an adaptive run, the number it would take
    /// with its first step size).
    pub fn total_steps(&self) -> usize {
        self.n_steps
    }

    /// Totals so far.
    pub fn stats(&self) -> RunStats {
        self.stats
    }

    fn time_of(&self, k: usize) -> f64 {
        if k >= self.n_steps {
            self.t_final
        } else {
            k as f64 * self.h
        }
    }

    fn record(&self, newton_iterations: usize, residual: f64, substeps: usize) -> StepRecord<N> {
        let (q, p, v) = (self.q.sum, self.p.sum, self.v);
        let e = energy(self.prob.model, self.t, &q, &v, &p).unwrap_or(f64::NAN);
        StepRecord {
            step: self.k,
            t: self.t,
            q,
            p,
            v,
            energy: e,
            energy_balance: e - self.energy0 - self.work.0,
            newton_iterations,
            residual,
            substeps,
        }
    }

    /// A record of the state alone (lean runs): `v` is the step polynomial's end slope,
    /// the energy fields are zero.
    fn raw_record(
        &self,
        newton_iterations: usize,
        residual: f64,
        substeps: usize,
    ) -> StepRecord<N> {
        StepRecord {
            step: self.k,
            t: self.t,
            q: self.q.sum,
            p: self.p.sum,
            v: self.v,
            energy: 0.0,
            energy_balance: 0.0,
            newton_iterations,
            residual,
            substeps,
        }
    }

    /// Leaves out the per-step diagnostics (velocity solve, energy, work, balance): the
    /// iterator's records then hold the state alone until [`Stepper::finish`].
    pub(crate) fn set_lean(&mut self, lean: bool) {
        self.lean = lean;
    }

    /// The full record of the current state: the velocity solve and the energy. In a lean
    /// run the work was not summed, so the balance is not known: it is reported as zero.
    pub(crate) fn finish(&mut self) -> Result<StepRecord<N>, Error> {
        let t = self.t;
        if self.lean && self.k > 0 {
            self.v = solve_velocity(self.prob.model, &self.q.sum, &self.p.sum, self.v, self.k, t)?;
        }
        let mut rec = self.record(0, 0.0, 1);
        if self.lean {
            rec.energy_balance = 0.0;
        }
        match non_finite_field(&rec) {
            Some(quantity) => Err(Error::Overflow {
                step: self.k,
                t,
                quantity,
            }),
            None => Ok(rec),
        }
    }
}

impl<M: ForcedLagrangian<N>, const N: usize> Iterator for Stepper<'_, M, N> {
    type Item = Result<StepRecord<N>, Error>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        if !self.started {
            self.started = true;
            return Some(Ok(self.record(0, 0.0, 1)));
        }
        if self.k >= self.n_steps && self.tolerance.is_none() {
            self.done = true;
            return None;
        }
        let out = match self.tolerance {
            Some(tol) if self.t < self.t_final => {
                with_kernel_stack::<M, N, _>(|| self.step_adaptive(&tol))
            }
            Some(_) => {
                self.done = true;
                return None;
            }
            None => with_kernel_stack::<M, N, _>(|| self.step()),
        };
        if out.is_err() {
            self.done = true;
        }
        Some(out)
    }
}
