//! The run methods of an [`Integrator`]: [`Integrator::solve`] with the output of
//! [`super::output`], on either backend, through the one [`Stepper`](crate::Stepper). Every
//! run fails with [`RunFailure`], which keeps what was computed before the failure.

use super::Integrator;
use super::output::{self, Output};
use crate::initial::InitialState;
use crate::model::ForcedLagrangian;
use crate::stack::with_run_stack;
use crate::trajectory::{
    AdjointGradient, DenseState, FinalState, RunFailure, RunStats, Sensitivities, StepRecord,
    Trajectory,
};
use nalgebra::SVector;

impl<M: ForcedLagrangian<N>, const N: usize> Integrator<'_, M, N> {
    /// Runs from `init` to `t_final` and gives back what `output` asks for (see
    /// [`output`]): every record ([`output::Records`]), the final state
    /// ([`output::Final`]), the dense output at given times ([`output::Samples`]), each
    /// record streamed to a closure ([`output::each_step`]), the derivatives of the flow
    /// ([`output::Tangents`]) or the gradient of a loss ([`output::adjoint`]).
    ///
    /// On failure the [`RunFailure`] carries the typed error and what was computed before
    /// it; it converts into [`crate::Error`], so `?` works.
    pub fn solve<O: Output<N>>(
        &self,
        init: InitialState<N>,
        t_final: f64,
        output: O,
    ) -> Result<O::Value, RunFailure<N>> {
        // On a stack deep enough for the run's copies of `[f64; N]` values, whichever
        // thread runs it (the initial state is copied there, not here).
        let init = &init;
        with_run_stack::<N, _>(move || output.drive(self, &mut None, *init, t_final))
    }

    /// A handle that runs this integrator again and again on one stepper: each
    /// [`Runs::solve`] restarts the last run's stepper from its new initial state instead of
    /// making a new one, so a run of a few steps does not pay for its buffers each time
    /// (about 30 allocations on a small model, and the Newton iteration's set-up). The
    /// results are those of [`Integrator::solve`], to the bit. Where the backend depends on
    /// the initial state, every run makes a new stepper: on the sparse backend, whose pattern
    /// is recorded there, and for a model with sparse kernels on
    /// [`LinearPath::Auto`](crate::LinearPath::Auto), which chooses its backend there.
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
    /// let integ = Integrator::new(&Oscillator, Scheme::lobatto(3)?, 0.1)?;
    /// let mut runs = integ.runs();
    /// for q0 in [0.5, 1.0, 2.0] {
    ///     let init = InitialState::from_velocity([q0], [0.0]);
    ///     let end = runs.solve(init, 1.0, output::Final)?;
    ///     assert_eq!(end.q, integ.solve(init, 1.0, output::Final)?.q);
    /// }
    /// # Ok::<(), forced_vi::Error>(())
    /// ```
    pub fn runs(&self) -> Runs<'_, '_, M, N> {
        Runs {
            integ: self,
            slot: None,
        }
    }

    /// Runs to `t_final` and returns the final state alone, the cheapest run: the same as
    /// `solve(init, t_final, output::Final)` (see [`output::Final`]).
    pub fn final_state(
        &self,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<FinalState<N>, RunFailure<N>> {
        self.solve(init, t_final, output::Final)
    }

    /// `solve(init, t_final, output::Records)`.
    #[doc(hidden)]
    #[deprecated(note = "use `solve(init, t_final, output::Records)`")]
    pub fn run(&self, init: InitialState<N>, t_final: f64) -> Result<Trajectory<N>, RunFailure<N>> {
        self.solve(init, t_final, output::Records)
    }

    /// `solve(init, t_final, output::each_step(f))`.
    #[doc(hidden)]
    #[deprecated(note = "use `solve(init, t_final, output::each_step(f))`")]
    pub fn for_each_step(
        &self,
        init: InitialState<N>,
        t_final: f64,
        f: impl FnMut(&StepRecord<N>),
    ) -> Result<RunStats, RunFailure<N>> {
        self.solve(init, t_final, output::each_step(f))
    }

    /// `solve(init, last time, output::Samples(times))`.
    #[doc(hidden)]
    #[deprecated(note = "use `solve(init, t_final, output::Samples(times))`")]
    pub fn sample(
        &self,
        init: InitialState<N>,
        times: &[f64],
    ) -> Result<Vec<DenseState<N>>, RunFailure<N>> {
        let t_final = times.last().copied().unwrap_or(0.0);
        self.solve(init, t_final, output::Samples(times))
    }

    /// `solve(init, t_final, output::Tangents)`.
    #[doc(hidden)]
    #[deprecated(note = "use `solve(init, t_final, output::Tangents)`")]
    pub fn sensitivities(
        &self,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<Sensitivities<N>, RunFailure<N>> {
        self.solve(init, t_final, output::Tangents)
    }

    /// `solve(init, t_final, output::adjoint(dloss))`.
    #[doc(hidden)]
    #[deprecated(note = "use `solve(init, t_final, output::adjoint(dloss))`")]
    pub fn adjoint_gradient(
        &self,
        init: InitialState<N>,
        t_final: f64,
        dloss: impl FnOnce(&FinalState<N>) -> (SVector<f64, N>, SVector<f64, N>),
    ) -> Result<AdjointGradient<N>, RunFailure<N>> {
        self.solve(init, t_final, output::adjoint(dloss))
    }
}

/// Runs of one [`Integrator`] on one stepper, made by [`Integrator::runs`].
pub struct Runs<'s, 'm, M, const N: usize> {
    integ: &'s Integrator<'m, M, N>,
    slot: output::Slot<'s, M, N>,
}

impl<M: ForcedLagrangian<N>, const N: usize> Runs<'_, '_, M, N> {
    /// [`Integrator::solve`] on the last run's stepper, restarted from `init` (see
    /// [`Integrator::runs`]). A failed run does not change the next one.
    pub fn solve<O: Output<N>>(
        &mut self,
        init: InitialState<N>,
        t_final: f64,
        output: O,
    ) -> Result<O::Value, RunFailure<N>> {
        let (integ, slot, init) = (self.integ, &mut self.slot, &init);
        with_run_stack::<N, _>(move || output.drive(integ, slot, *init, t_final))
    }
}
