//! The run methods of an [`Integrator`]: every record collected, streamed, sampled at given
//! times, or the final state alone; on either backend, through the one [`Stepper`]. Every
//! method fails with [`RunFailure`], which keeps what was computed before the failure.

use super::Integrator;
use crate::error::Error;
use crate::initial::InitialState;
use crate::model::ForcedLagrangian;
use crate::stepper::Stepper;
use crate::trajectory::{
    hermite, AdjointGradient, DenseState, FinalState, RunFailure, RunStats, Sensitivities,
    StepRecord, Trajectory,
};
use nalgebra::SVector;

impl<M: ForcedLagrangian<N>, const N: usize> Integrator<'_, M, N> {
    /// The derivatives do not carry the multipliers of a constrained model yet: refused
    /// rather than wrong.
    fn refuse_constraints(&self) -> Result<(), RunFailure<N>> {
        if self.model.constraint_count() > 0 {
            return Err(RunFailure::new(Error::UnsupportedConstraints {
                message: "sensitivities of constrained models are not supported yet",
            }));
        }
        Ok(())
    }

    /// Opens the run's stepper and hands it to `visit`; a run that cannot start is a
    /// failure with nothing computed.
    fn open<R>(
        &self,
        init: InitialState<N>,
        t_final: f64,
        visit: impl FnOnce(&mut Stepper<'_, M, N>) -> Result<R, RunFailure<N>>,
    ) -> Result<R, RunFailure<N>> {
        let mut stepper = self.stepper(init, t_final).map_err(RunFailure::new)?;
        visit(&mut stepper)
    }

    /// Streams every record to `f` and returns the totals. Memory use does not grow with
    /// the number of steps. On failure the totals and the last record come back with the
    /// error.
    pub fn for_each_step(
        &self,
        init: InitialState<N>,
        t_final: f64,
        mut f: impl FnMut(&StepRecord<N>),
    ) -> Result<RunStats, RunFailure<N>> {
        self.open(init, t_final, |stepper| {
            while let Some(rec) = stepper.next() {
                match rec {
                    Ok(r) => f(&r),
                    Err(error) => return Err(stepper.failure(error)),
                }
            }
            Ok(stepper.stats())
        })
    }

    /// Runs to `t_final` and returns the final state alone: the cheapest run. No record is
    /// kept, and the per-step diagnostics are left out (the velocity solve, the energy and
    /// the work of the force); the final velocity and energy are computed once, at the end.
    /// Each step is solved and checked as in [`Self::run`].
    pub fn final_state(
        &self,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<FinalState<N>, RunFailure<N>> {
        self.open(init, t_final, |stepper| {
            stepper.set_lean(true);
            to_the_end(stepper)
        })
    }

    /// Runs to `t_final` like [`Self::final_state`] and returns the final state with the
    /// derivatives of the discrete flow: [`Sensitivities::wrt_initial`] and
    /// [`Sensitivities::wrt_parameters`] (DESIGN §12).
    ///
    /// Each accepted step carries the tangent through the step map by the implicit
    /// function theorem: its step Jacobian is evaluated and factored at the solution, and
    /// every column costs one more solve with those factors (no finite differences). The
    /// cost is about `2N + P` linear solves per step on top of the run, on either backend.
    /// With tolerances the step sequence is held fixed: the result is the derivative of the
    /// same steps from perturbed data.
    ///
    /// ```
    /// use forced_vi::prelude::*;
    ///
    /// struct Oscillator;
    /// impl ForcedLagrangian<1> for Oscillator {
    ///     fn lagrangian<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> D {
    ///         (v[0] * v[0] - q[0] * q[0]) * 0.5
    ///     }
    /// }
    /// let end = Integrator::new(&Oscillator, Scheme::lobatto(3)?, 0.01)?
    ///     .sensitivities(InitialState::from_velocity([1.0], [0.0]), 1.0)?;
    /// // q(T) = q0 cos T + v0 sin T: ∂q_T/∂q_0 = cos 1, ∂q_T/∂v_0 = sin 1.
    /// assert!((end.wrt_initial[(0, 0)] - 1f64.cos()).abs() < 1e-8);
    /// assert!((end.wrt_initial[(0, 1)] - 1f64.sin()).abs() < 1e-8);
    /// # Ok::<(), forced_vi::Error>(())
    /// ```
    pub fn sensitivities(
        &self,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<Sensitivities<N>, RunFailure<N>> {
        self.refuse_constraints()?;
        self.open(init, t_final, |stepper| {
            stepper.set_lean(true);
            stepper.track_tangent().map_err(|e| stepper.failure(e))?;
            let end = to_the_end(stepper)?;
            let stats = end.stats;
            let (wrt_initial, wrt_parameters) = stepper
                .tangent_in_velocities()
                .map_err(|e| stepper.failure(e))?;
            Ok(Sensitivities {
                t: end.t,
                q: end.q,
                v: end.v,
                p: end.p,
                wrt_initial,
                wrt_parameters,
                stats,
            })
        })
    }

    /// The gradient of a loss `ℓ(q_T, v_T)` of the final state by the discrete adjoint
    /// (DESIGN §12): `dloss` gives `(∂ℓ/∂q_T, ∂ℓ/∂v_T)` at the final state, and the result
    /// holds `∂ℓ/∂(q_0, v_0)` and `∂ℓ/∂θ` for the model's parameters.
    ///
    /// The forward run keeps each step's start, size and solution (the tape, its size in
    /// [`AdjointGradient::tape_bytes`]); the backward pass linearises each step again and
    /// takes one transposed solve per step, so that its cost does not grow with the number
    /// of parameters, beyond one hyper-dual evaluation of `L` per node and parameter. It
    /// equals `wrt_initialᵀ g` of [`Self::sensitivities`] to round-off (tested), at a
    /// fraction of its cost for large models. With tolerances the step sequence is held
    /// fixed.
    ///
    /// ```
    /// use forced_vi::prelude::*;
    /// # struct Oscillator;
    /// # impl ForcedLagrangian<1> for Oscillator {
    /// #     fn lagrangian<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> D {
    /// #         (v[0] * v[0] - q[0] * q[0]) * 0.5
    /// #     }
    /// # }
    /// // ℓ = q_T²/2: ∂ℓ/∂q_0 = q_T cos T.
    /// let integ = Integrator::new(&Oscillator, Scheme::lobatto(3)?, 0.01)?;
    /// let g = integ.adjoint_gradient(InitialState::from_velocity([1.0], [0.0]), 1.0, |end| {
    ///     (end.q, nalgebra::SVector::zeros())
    /// })?;
    /// assert!((g.wrt_initial[0] - 1f64.cos() * 1f64.cos()).abs() < 1e-8);
    /// # Ok::<(), forced_vi::Error>(())
    /// ```
    pub fn adjoint_gradient(
        &self,
        init: InitialState<N>,
        t_final: f64,
        dloss: impl FnOnce(&FinalState<N>) -> (SVector<f64, N>, SVector<f64, N>),
    ) -> Result<AdjointGradient<N>, RunFailure<N>> {
        self.refuse_constraints()?;
        self.open(init, t_final, |stepper| {
            stepper.set_lean(true);
            stepper.keep_tape();
            let end = to_the_end(stepper)?;
            let (stats, tape_bytes) = (end.stats, stepper.tape_bytes());
            let (gq, gv) = dloss(&end);
            let (wrt_initial, wrt_parameters) = stepper
                .adjoint((gq.as_slice(), gv.as_slice()))
                .map_err(|e| stepper.failure(e))?;
            Ok(AdjointGradient {
                t: end.t,
                q: end.q,
                v: end.v,
                p: end.p,
                wrt_initial,
                wrt_parameters,
                tape_bytes,
                stats,
            })
        })
    }

    /// Runs to the last of `times` and returns the dense output at each of them (see
    /// [`DenseState`]), so that the step grid, fixed or adaptive, is free of the output grid.
    /// Only the last step is held, so memory grows with the samples, not the steps. The
    /// times must be finite, non-negative and non-decreasing. On failure the samples before
    /// it come back with the error ([`RunFailure::samples`]).
    pub fn sample(
        &self,
        init: InitialState<N>,
        times: &[f64],
    ) -> Result<Vec<DenseState<N>>, RunFailure<N>> {
        if let Some(&t) = times.iter().find(|t| !(t.is_finite() && **t >= 0.0)) {
            return Err(RunFailure::new(Error::InvalidFinalTime { t_final: t }));
        }
        if !times.windows(2).all(|w| w[0] <= w[1]) {
            return Err(RunFailure::new(Error::UnorderedTimes));
        }
        let t_final = times.last().copied().unwrap_or(0.0);
        self.open(init, t_final, |stepper| {
            let mut out = Vec::with_capacity(times.len());
            let mut prev: Option<StepRecord<N>> = None;
            while let Some(rec) = stepper.next() {
                let rec = match rec {
                    Ok(r) => r,
                    Err(e) => {
                        let mut failure = stepper.failure(e);
                        failure.samples = out;
                        return Err(failure);
                    }
                };
                while let Some(&t) = times.get(out.len()).filter(|&&t| t <= rec.t) {
                    out.push(match &prev {
                        Some(a) => hermite(a, &rec, t),
                        None => hermite(&rec, &rec, t),
                    });
                }
                prev = Some(rec);
            }
            Ok(out)
        })
    }

    /// Runs to `t_final` and collects every record. On failure the records computed so far
    /// come back with the error.
    pub fn run(&self, init: InitialState<N>, t_final: f64) -> Result<Trajectory<N>, RunFailure<N>> {
        let adaptive = self.tolerance.is_some();
        self.open(init, t_final, |stepper| collect(stepper, adaptive))
    }
}

/// Steps a lean run to its end and returns its final state (the velocity solved once).
fn to_the_end<M: ForcedLagrangian<N>, const N: usize>(
    stepper: &mut Stepper<'_, M, N>,
) -> Result<FinalState<N>, RunFailure<N>> {
    while let Some(rec) = stepper.next() {
        if let Err(e) = rec {
            return Err(stepper.failure(e));
        }
    }
    let stats = stepper.stats();
    let end = stepper.finish().map_err(|e| stepper.failure(e))?;
    Ok(FinalState {
        t: end.t,
        q: end.q,
        p: end.p,
        v: end.v,
        energy: end.energy,
        stats,
    })
}

/// Collects a run's records. A fixed-step run reserves all its records up front, so that a
/// run that cannot hold them fails before its first step rather than aborting in the
/// middle; an adaptive one grows its storage fallibly.
fn collect<M: ForcedLagrangian<N>, const N: usize>(
    stepper: &mut Stepper<'_, M, N>,
    adaptive: bool,
) -> Result<Trajectory<N>, RunFailure<N>> {
    let mut traj = Trajectory::default();
    let records = stepper.total_steps().saturating_add(1);
    let reserve = if adaptive { records.min(1024) } else { records };
    let fail = |error, mut traj: Trajectory<N>, stats| {
        traj.stats = stats;
        let last = traj.records.last().map(|r| Box::new(*r));
        RunFailure {
            error,
            stats,
            trajectory: traj,
            last,
            samples: Vec::new(),
        }
    };
    if traj.records.try_reserve_exact(reserve).is_err() {
        return Err(fail(
            Error::TooManyRecords { records },
            traj,
            stepper.stats(),
        ));
    }
    while let Some(rec) = stepper.next() {
        match rec {
            Ok(r) => {
                if traj.records.len() == traj.records.capacity()
                    && traj.records.try_reserve(traj.records.len()).is_err()
                {
                    let records = traj.records.len() * 2;
                    return Err(fail(
                        Error::TooManyRecords { records },
                        traj,
                        stepper.stats(),
                    ));
                }
                traj.records.push(r)
            }
            Err(error) => return Err(fail(error, traj, stepper.stats())),
        }
    }
    traj.stats = stepper.stats();
    Ok(traj)
}
