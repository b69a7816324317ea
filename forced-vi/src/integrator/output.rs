//! What a run gives back: the choice passed to [`Integrator::solve`] (and to
//! [`Integrator::ensemble`]).
//!
//! | output | [`Integrator::solve`] returns | memory | per-step diagnostics |
//! |---|---|---|---|
//! | [`Records`] | [`Trajectory`]: every record | grows with the steps | yes |
//! | [`Final`] | [`FinalState`]: the state at `t_final` | constant | left out (the cheapest run) |
//! | [`Samples`] | the dense output ([`DenseState`]) at given times | grows with the samples | yes |
//! | [`each_step`]`(closure)` | [`RunStats`], every record handed to the closure | constant | yes |
//! | [`Tangents`] | [`Sensitivities`]: the final state and the derivatives of the flow | constant | left out |
//! | [`adjoint`]`(dloss)` | [`AdjointGradient`]: the gradient of a loss of the final state | the tape | left out |
//!
//! Every output fails with the one [`RunFailure`], which keeps what was computed before the
//! failure and converts into [`Error`] for `?`.
//!
//! ```
//! use forced_vi::prelude::*;
//!
//! struct Oscillator;
//! impl ForcedLagrangian<1> for Oscillator {
//!     fn lagrangian<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> D {
//!         (v[0] * v[0] - q[0] * q[0]) * 0.5
//!     }
//! }
//! let integ = Integrator::new(&Oscillator, Scheme::lobatto(3)?, 0.01)?;
//! let init = InitialState::from_velocity([1.0], [0.0]);
//! let run = integ.solve(init, 1.0, output::Records)?;
//! let end = integ.solve(init, 1.0, output::Final)?;
//! let mid = integ.solve(init, 1.0, output::Samples(&[0.25, 0.5]))?;
//! let mut peak = 0.0_f64;
//! let stats = integ.solve(init, 1.0, output::each_step(|r| peak = peak.max(r.v[0].abs())))?;
//! assert_eq!(run.records.len(), 101);
//! assert_eq!(end.q, run.records[100].q);
//! assert!((mid[1].q[0] - 0.5f64.cos()).abs() < 1e-8);
//! assert!((peak - 1f64.sin()).abs() < 1e-8 && stats.steps == 100);
//! # Ok::<(), forced_vi::Error>(())
//! ```

use nalgebra::SVector;

use super::Integrator;
use crate::error::Error;
use crate::initial::InitialState;
use crate::model::ForcedLagrangian;
use crate::stepper::Stepper;
use crate::trajectory::{
    AdjointGradient, DenseState, FinalState, RunFailure, RunStats, Sensitivities, StepRecord,
    Trajectory, hermite,
};

mod sealed {
    pub trait Sealed {}
}

/// What a run gives back (see the [module docs](self)): one of [`Records`], [`Final`],
/// [`Samples`], [`each_step`], [`Tangents`] and [`adjoint`].
pub trait Output<const N: usize>: sealed::Sealed {
    /// The value of a run that reached `t_final`.
    type Value;

    /// Runs `integ` from `init` to `t_final` on the stepper in `slot` (restarted) or a new
    /// one left there, and gives this output back. Called by [`Integrator::solve`] and
    /// [`Runs::solve`](super::Runs::solve).
    #[doc(hidden)]
    fn drive<'s, M: ForcedLagrangian<N>>(
        self,
        integ: &'s Integrator<'_, M, N>,
        slot: &mut Slot<'s, M, N>,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<Self::Value, RunFailure<N>>;
}

/// Every record, initial state first: a [`Trajectory`]. On failure the records computed so
/// far come back in [`RunFailure::trajectory`].
#[derive(Clone, Copy, Debug, Default)]
pub struct Records;

/// The final state alone: a [`FinalState`], the cheapest run. No record is kept, and the
/// per-step diagnostics are left out (the velocity solve, the energy and the work of the
/// force); the final velocity and energy are computed once, at the end. Each step is solved
/// and checked as with [`Records`].
#[derive(Clone, Copy, Debug, Default)]
pub struct Final;

/// The dense output at each of the given times (see [`DenseState`]), so that the step grid,
/// fixed or adaptive, is free of the output grid. The times must be finite and non-negative
/// ([`Error::InvalidOutputTime`] otherwise), non-decreasing and at most `t_final`
/// ([`Error::UnorderedTimes`] otherwise). An adaptive run keeps the samples to its
/// tolerance by ending a step on every output time (up to one step more per output time;
/// see [`DenseState`]); a fixed-step run interpolates between its steps. Only the last step is
/// held, so memory grows with the samples, not the steps. On failure the samples before it
/// come back in [`RunFailure::samples`].
#[derive(Clone, Copy, Debug)]
pub struct Samples<'a>(pub &'a [f64]);

/// Every record handed to a closure as it is computed; the run gives back its
/// [`RunStats`]. Memory use does not grow with the number of steps. On failure the totals
/// and the last record come back with the error. Made by [`each_step`].
#[derive(Clone, Copy, Debug)]
pub struct EachStep<F>(F);

/// Hands every record to `f` as it is computed ([`EachStep`]). A function rather than the
/// type's constructor, so that the closure's argument type is inferred.
pub fn each_step<const N: usize, F: FnMut(&StepRecord<N>)>(f: F) -> EachStep<F> {
    EachStep(f)
}

/// The final state with the derivatives of the discrete flow: [`Sensitivities`], with
/// [`Sensitivities::wrt_initial`] and [`Sensitivities::wrt_parameters`] (DESIGN §12).
///
/// Each accepted step carries the tangent through the step map by the implicit function
/// theorem: its step Jacobian is evaluated and factored at the solution, and every column
/// costs one more solve with those factors (no finite differences). The cost is about
/// `2N + P` linear solves per step on top of the run, on either backend. With tolerances the
/// step sequence is held fixed: the result is the derivative of the same steps from
/// perturbed data. A constrained model carries its multipliers and its end projection
/// through the tangent too, on either backend (the sparse one from its own kernels: the
/// constraints' `G` and curvature, the end's blocks and saddle-point factors); only
/// directions of `(q_0, v_0)` that keep the initial data on the constraints are
/// derivatives of the flow.
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
///     .solve(InitialState::from_velocity([1.0], [0.0]), 1.0, output::Tangents)?;
/// // q(T) = q0 cos T + v0 sin T: ∂q_T/∂q_0 = cos 1, ∂q_T/∂v_0 = sin 1.
/// assert!((end.wrt_initial[(0, 0)] - 1f64.cos()).abs() < 1e-8);
/// assert!((end.wrt_initial[(0, 1)] - 1f64.sin()).abs() < 1e-8);
/// # Ok::<(), forced_vi::Error>(())
/// ```
#[derive(Clone, Copy, Debug, Default)]
pub struct Tangents;

/// The gradient of a loss `ℓ(q_T, v_T)` of the final state by the discrete adjoint
/// (DESIGN §12): the closure gives `(∂ℓ/∂q_T, ∂ℓ/∂v_T)` at the final state, and the run
/// gives back an [`AdjointGradient`] with `∂ℓ/∂(q_0, v_0)` and `∂ℓ/∂θ` for the model's
/// parameters.
///
/// The forward run keeps each step's start, size and solution (the tape, its size in
/// [`AdjointGradient::tape_bytes`]); the backward pass linearises each step again and takes
/// one transposed solve per step, so that its cost does not grow with the number of
/// parameters, beyond one hyper-dual evaluation of `L` per node and parameter. It equals
/// `wrt_initialᵀ g` of [`Tangents`] to round-off (tested), at a fraction of its cost for
/// large models. With tolerances the step sequence is held fixed. A constrained step also
/// keeps its end on the tape (its end momentum, multipliers and velocity), and the backward
/// pass takes the adjoint through its end projection and its constraint rows too, on
/// either backend.
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
/// let init = InitialState::from_velocity([1.0], [0.0]);
/// let g = integ.solve(init, 1.0, output::adjoint(|end| (end.q, nalgebra::SVector::zeros())))?;
/// assert!((g.wrt_initial[0] - 1f64.cos() * 1f64.cos()).abs() < 1e-8);
/// # Ok::<(), forced_vi::Error>(())
/// ```
///
/// Made by [`adjoint`].
#[derive(Clone, Copy, Debug)]
pub struct Adjoint<F>(F);

/// The gradient of a loss of the final state by the discrete adjoint ([`Adjoint`]): `dloss`
/// gives `(∂ℓ/∂q_T, ∂ℓ/∂v_T)` at the final state. A function rather than the type's
/// constructor, so that the closure's argument type is inferred.
pub fn adjoint<const N: usize, F>(dloss: F) -> Adjoint<F>
where
    F: FnOnce(&FinalState<N>) -> (SVector<f64, N>, SVector<f64, N>),
{
    Adjoint(dloss)
}

impl sealed::Sealed for Records {}
impl sealed::Sealed for Final {}
impl sealed::Sealed for Samples<'_> {}
impl<F> sealed::Sealed for EachStep<F> {}
impl sealed::Sealed for Tangents {}
impl<F> sealed::Sealed for Adjoint<F> {}

impl<const N: usize> Output<N> for Records {
    type Value = Trajectory<N>;

    fn drive<'s, M: ForcedLagrangian<N>>(
        self,
        integ: &'s Integrator<'_, M, N>,
        slot: &mut Slot<'s, M, N>,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<Trajectory<N>, RunFailure<N>> {
        let adaptive = integ.tolerance.is_some();
        open(integ, slot, init, t_final, |stepper| {
            collect(stepper, adaptive)
        })
    }
}

impl<const N: usize> Output<N> for Final {
    type Value = FinalState<N>;

    fn drive<'s, M: ForcedLagrangian<N>>(
        self,
        integ: &'s Integrator<'_, M, N>,
        slot: &mut Slot<'s, M, N>,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<FinalState<N>, RunFailure<N>> {
        open(integ, slot, init, t_final, |stepper| {
            stepper.set_lean(true);
            to_the_end(stepper)
        })
    }
}

impl<const N: usize> Output<N> for Samples<'_> {
    type Value = Vec<DenseState<N>>;

    fn drive<'s, M: ForcedLagrangian<N>>(
        self,
        integ: &'s Integrator<'_, M, N>,
        slot: &mut Slot<'s, M, N>,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<Vec<DenseState<N>>, RunFailure<N>> {
        let times = self.0;
        if let Some(&t) = times.iter().find(|t| !(t.is_finite() && **t >= 0.0)) {
            return Err(RunFailure::new(Error::InvalidOutputTime { t }));
        }
        let ordered = times.windows(2).all(|w| w[0] <= w[1]);
        if !ordered || times.last().is_some_and(|&t| t > t_final) {
            return Err(RunFailure::new(Error::UnorderedTimes));
        }
        open(integ, slot, init, t_final, |stepper| {
            let mut out = Vec::with_capacity(times.len());
            let mut prev: Option<StepRecord<N>> = None;
            stepper.set_next_output(times.first().copied());
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
                // The next output time a step can end on: those within the smallest step
                // of this one are its state, to round-off, and are served by the next
                // interpolation, which must not span the times after them (an output
                // 1e-14 after another hid the next one, which a step of 1 then passed
                // over: 1.4e-1 off at tol 1e-6).
                let gap = stepper.smallest_step(rec.t);
                let next = times[out.len()..].iter().find(|&&t| t - rec.t >= gap);
                stepper.set_next_output(next.copied());
                prev = Some(rec);
            }
            Ok(out)
        })
    }
}

impl<F: FnMut(&StepRecord<N>), const N: usize> Output<N> for EachStep<F> {
    type Value = RunStats;

    fn drive<'s, M: ForcedLagrangian<N>>(
        mut self,
        integ: &'s Integrator<'_, M, N>,
        slot: &mut Slot<'s, M, N>,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<RunStats, RunFailure<N>> {
        open(integ, slot, init, t_final, |stepper| {
            while let Some(rec) = stepper.next() {
                match rec {
                    Ok(r) => (self.0)(&r),
                    Err(error) => return Err(stepper.failure(error)),
                }
            }
            Ok(stepper.stats())
        })
    }
}

impl<const N: usize> Output<N> for Tangents {
    type Value = Sensitivities<N>;

    fn drive<'s, M: ForcedLagrangian<N>>(
        self,
        integ: &'s Integrator<'_, M, N>,
        slot: &mut Slot<'s, M, N>,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<Sensitivities<N>, RunFailure<N>> {
        if !per_term_parameters(integ) {
            refuse_large(integ)?;
        }
        refuse_large_tangent(integ)?;
        open(integ, slot, init, t_final, |stepper| {
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
}

impl<F, const N: usize> Output<N> for Adjoint<F>
where
    F: FnOnce(&FinalState<N>) -> (SVector<f64, N>, SVector<f64, N>),
{
    type Value = AdjointGradient<N>;

    fn drive<'s, M: ForcedLagrangian<N>>(
        self,
        integ: &'s Integrator<'_, M, N>,
        slot: &mut Slot<'s, M, N>,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<AdjointGradient<N>, RunFailure<N>> {
        // The backward pass takes the parameters' terms by contractions, whose dual numbers
        // are scalars; only a constrained step's terms take the general parameter kernels,
        // where the model has no per-term ones.
        if M::CONSTRAINED && integ.model.constraint_count() > 0 && !per_term_parameters(integ) {
            refuse_large(integ)?;
        }
        open(integ, slot, init, t_final, |stepper| {
            stepper.set_lean(true);
            stepper.keep_tape().map_err(|e| stepper.failure(e))?;
            let end = to_the_end(stepper)?;
            let (stats, tape_bytes) = (end.stats, stepper.tape_bytes());
            let (gq, gv) = (self.0)(&end);
            if let Some(index) = gq.iter().chain(gv.iter()).position(|x| !x.is_finite()) {
                return Err(stepper.failure(Error::NonFiniteLossGradient { index }));
            }
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
}

/// Whether the model's per-term kernels give its parameters' terms
/// ([`crate::model::SparseNode::eval_parameter`]), with no dual numbers over every coordinate.
fn per_term_parameters<M: ForcedLagrangian<N>, const N: usize>(
    integ: &Integrator<'_, M, N>,
) -> bool {
    (integ.model.sparse_node()).is_some_and(|node| node.has_parameter_kernels())
}

/// The forward sensitivities' tangent, `2N × (2N + P)` numbers: refused past
/// [`crate::MAX_TANGENT_BYTES`] before anything is allocated (an allocation that failed
/// would end the process; at 16384 coordinates it is 8.6 GB, kept twice).
fn refuse_large_tangent<M: ForcedLagrangian<N>, const N: usize>(
    integ: &Integrator<'_, M, N>,
) -> Result<(), RunFailure<N>> {
    let columns = (2 * N).saturating_add(integ.model.parameter_names().len());
    let bytes = (2 * N)
        .saturating_mul(columns)
        .saturating_mul(std::mem::size_of::<f64>());
    if bytes > crate::MAX_TANGENT_BYTES {
        return Err(RunFailure::new(Error::TangentTooLarge {
            dof: N,
            columns,
            bytes,
            max: crate::MAX_TANGENT_BYTES,
        }));
    }
    Ok(())
}

/// The general parameters' kernels take hyper-dual numbers over every coordinate (`N²`): a
/// stack that could not be mapped would end the process. Not asked of a model whose
/// per-term kernels give the parameters' terms.
fn refuse_large<M: ForcedLagrangian<N>, const N: usize>(
    integ: &Integrator<'_, M, N>,
) -> Result<(), RunFailure<N>> {
    let stack_bytes = crate::model::general::parameter_stack_bytes::<N>();
    if stack_bytes > crate::MAX_KERNEL_STACK && !integ.model.parameter_names().is_empty() {
        return Err(RunFailure::new(Error::SensitivitiesTooLarge {
            dof: N,
            stack_bytes,
            max: crate::MAX_KERNEL_STACK,
        }));
    }
    Ok(())
}

/// The stepper a run may start on: the last run's, kept by [`Runs`](super::Runs), or none.
#[doc(hidden)]
pub type Slot<'s, M, const N: usize> = Option<Box<Stepper<'s, M, N>>>;

/// Opens the run's stepper and hands it to `visit`: the one in `slot` restarted
/// ([`Stepper::restart`]) where the run takes the dense backend whatever its initial
/// state, else a new one, left in `slot` for the next run.
/// A run that cannot start is a failure with nothing computed, and leaves `slot` empty.
fn open<'s, M: ForcedLagrangian<N>, const N: usize, R>(
    integ: &'s Integrator<'_, M, N>,
    slot: &mut Slot<'s, M, N>,
    init: InitialState<N>,
    t_final: f64,
    visit: impl FnOnce(&mut Stepper<'s, M, N>) -> Result<R, RunFailure<N>>,
) -> Result<R, RunFailure<N>> {
    // Only where the backend does not depend on the initial state: a restart keeps it.
    let keep = integ.dense_for_every_start();
    if let Some(stepper) = slot.as_mut().filter(|_| keep) {
        match stepper.restart(init, t_final) {
            Ok(true) => return visit(stepper),
            Ok(false) => {}
            Err(e) => {
                *slot = None;
                return Err(RunFailure::new(e));
            }
        }
    }
    *slot = None;
    let stepper = slot.insert(Box::new(
        integ.stepper(init, t_final).map_err(RunFailure::new)?,
    ));
    visit(stepper)
}

/// Steps a lean run to its end and returns its final state (the velocity solved once).
fn to_the_end<M: ForcedLagrangian<N>, const N: usize>(
    stepper: &mut Stepper<'_, M, N>,
) -> Result<FinalState<N>, RunFailure<N>> {
    while let Some(step) = stepper.advance_quietly() {
        if let Err(e) = step {
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
