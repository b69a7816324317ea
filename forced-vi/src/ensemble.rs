//! Ensembles: many initial states (or parameter sets) through one model and scheme.
//!
//! Each member runs independently and keeps its own result: a member that fails (bad
//! initial data, a Newton failure, ...) gives its typed error in its slot while the others
//! run to the end. Results come back in the order of the members.
//!
//! With the cargo feature `rayon` (on by default) the members run in parallel on the current
//! rayon thread pool (the global one, or the pool of an enclosing
//! [`ThreadPool::install`](https://docs.rs/rayon/latest/rayon/struct.ThreadPool.html#method.install)).
//! Without it they run one after another; the results are the same either way, since every
//! member is computed by the same sequential code.
//!
//! ```
//! use forced_vi::prelude::*;
//!
//! struct Oscillator;
//! impl ForcedLagrangian<1> for Oscillator {
//!     fn lagrangian<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> D {
//!         (v[0] * v[0] - q[0] * q[0]) * 0.5
//!     }
//!     fn force<D: Scalar>(&self, _q: &[D; 1], v: &[D; 1]) -> [D; 1] {
//!         [v[0] * -0.1]
//!     }
//! }
//!
//! let members: Vec<_> = (0..8)
//!     .map(|i| InitialState::from_velocity([i as f64 * 0.1], [0.0]))
//!     .collect();
//! let integrator = Integrator::new(&Oscillator, Scheme::lobatto(3)?, 0.01)?;
//! let ends = integrator.ensemble(&members, 1.0, output::Final);
//! assert_eq!(ends.len(), 8);
//! assert!(ends.iter().all(|end| end.as_ref().is_ok_and(|e| e.stats.steps == 100)));
//! # Ok::<(), forced_vi::Error>(())
//! ```

use crate::initial::InitialState;
use crate::integrator::Integrator;
use crate::integrator::output::{self, Output};
use crate::model::ForcedLagrangian;
use crate::trajectory::{FinalState, RunFailure, Trajectory};

/// Applies `f` to every member, in parallel with the feature `rayon`, and returns the
/// results in the members' order. The building block of the ensemble runs, public for
/// ensembles over parameter sets (one model per member):
///
/// ```
/// # use forced_vi::prelude::*;
/// # struct Oscillator { k: f64 }
/// # impl ForcedLagrangian<1> for Oscillator {
/// #     fn lagrangian<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> D {
/// #         (v[0] * v[0] - q[0] * q[0] * self.k) * 0.5
/// #     }
/// #     fn force<D: Scalar>(&self, _q: &[D; 1], v: &[D; 1]) -> [D; 1] { [v[0] * 0.0] }
/// # }
/// let models: Vec<_> = [1.0, 4.0, 9.0].map(|k| Oscillator { k }).into();
/// let ends = forced_vi::ensemble::map(&models, |m| {
///     Integrator::new(m, Scheme::lobatto(3)?, 0.01)?
///         .solve(InitialState::from_velocity([1.0], [0.0]), 1.0, output::Final)
///         .map_err(|f| f.error)
/// });
/// assert!(ends.iter().all(Result::is_ok));
/// ```
pub fn map<T, R>(members: &[T], f: impl Fn(&T) -> R + Sync + Send) -> Vec<R>
where
    T: Sync,
    R: Send,
{
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        members.par_iter().map(f).collect()
    }
    #[cfg(not(feature = "rayon"))]
    {
        members.iter().map(f).collect()
    }
}

impl<M, const N: usize> Integrator<'_, M, N>
where
    M: ForcedLagrangian<N> + Sync,
{
    /// Runs every initial state to `t_final`, each with [`Integrator::solve`] and the same
    /// `output` (every record, the final state, samples, derivatives, ...), and keeps each
    /// member's value or its [`RunFailure`], in the members' order.
    ///
    /// The model must be `Sync` (shared by the worker threads), with or without the
    /// feature `rayon`, so that turning the feature on cannot break a build.
    pub fn ensemble<O>(
        &self,
        members: &[InitialState<N>],
        t_final: f64,
        output: O,
    ) -> Vec<Result<O::Value, RunFailure<N>>>
    where
        O: Output<N> + Clone + Sync,
        O::Value: Send,
    {
        // Each worker runs its members on one stepper, restarted member to member
        // (`Integrator::runs`): the same results as a new stepper per member.
        // Each value is boxed on the run's own stack (see `run_stack_bytes`): on its way
        // through the workers' collection it is a pointer, not `[f64; N]` arrays copied on
        // a worker's stack (a final state of 16384 coordinates overflowed one).
        let one = |runs: &mut super::Runs<'_, '_, M, N>, init: &InitialState<N>| {
            crate::stack::with_run_stack::<N, _>(|| {
                Box::new(runs.solve(*init, t_final, output.clone()))
            })
        };
        #[cfg(feature = "rayon")]
        let boxed: Vec<_> = {
            use rayon::prelude::*;
            members
                .par_iter()
                .map_init(|| self.runs(), |runs, init| one(runs, init))
                .collect()
        };
        #[cfg(not(feature = "rayon"))]
        let boxed: Vec<_> = {
            let mut runs = self.runs();
            members.iter().map(|init| one(&mut runs, init)).collect()
        };
        boxed.into_iter().map(|value| *value).collect()
    }

    /// `ensemble(members, t_final, output::Records)`.
    #[doc(hidden)]
    #[deprecated(note = "use `ensemble(members, t_final, output::Records)`")]
    pub fn run_ensemble(
        &self,
        members: &[InitialState<N>],
        t_final: f64,
    ) -> Vec<Result<Trajectory<N>, RunFailure<N>>> {
        self.ensemble(members, t_final, output::Records)
    }

    /// `ensemble(members, t_final, output::Final)`.
    #[doc(hidden)]
    #[deprecated(note = "use `ensemble(members, t_final, output::Final)`")]
    pub fn run_ensemble_final(
        &self,
        members: &[InitialState<N>],
        t_final: f64,
    ) -> Vec<Result<FinalState<N>, RunFailure<N>>> {
        self.ensemble(members, t_final, output::Final)
    }
}
