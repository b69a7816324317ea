//! The integrator: a model, a scheme and a step size, with the options of a run, and the
//! ways to run it (collect, stream, iterate).

use crate::control::Tolerance;
use crate::error::Error;
use crate::initial::InitialState;
use crate::model::ForcedLagrangian;
use crate::newton::NewtonOptions;
use crate::scheme::Scheme;
#[cfg(feature = "sparse")]
use crate::sparse::{record_node_pattern, NodePattern, SparseNode, SparseStepper};
use crate::stepper::Stepper;
use crate::trajectory::{
    hermite, DenseState, FinalState, RunFailure, RunStats, SampleFailure, StepRecord,
    StreamFailure, Trajectory,
};

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
}

impl StepOptions {
    /// The default cap on steps per run: 10⁹.
    pub const DEFAULT_MAX_STEPS: usize = 1_000_000_000;
}

impl Default for StepOptions {
    fn default() -> Self {
        StepOptions {
            newton: NewtonOptions::default(),
            max_subdivisions: 0,
            max_steps: Self::DEFAULT_MAX_STEPS,
        }
    }
}

/// The deepest stack the integrator provides for a model's node kernels (4 GiB, mapped
/// lazily: only the pages the kernels touch use memory).
pub const MAX_KERNEL_STACK: usize = 4 << 30;

/// Which linear algebra a run uses: the dense step with `N × N` node blocks, or the sparse
/// step of DESIGN §9 on the model's [`SparseNode`] kernels.
///
/// [`LinearPath::Auto`] (the default) takes the sparse path when the model has sparse
/// kernels ([`ForcedLagrangian::sparse_node`]), at least [`LinearPath::SPARSE_MIN_DOF`]
/// coordinates, and a node pattern (the union of the blocks `A, B, C, E`, recorded at the
/// initial state) with at most [`LinearPath::SPARSE_MAX_DENSITY`] `· N²` entries; otherwise
/// the dense one. The sparse path steps with a fixed `h` only: an adaptive run that would
/// take it fails with [`Error::SparsePathUnavailable`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum LinearPath {
    /// By size and density (see above).
    #[default]
    Auto,
    /// Always the dense step.
    Dense,
    /// Always the sparse step; a model without sparse kernels is an error.
    Sparse,
}

impl LinearPath {
    /// The fewest coordinates for which [`LinearPath::Auto`] takes the sparse path.
    ///
    /// Measured on the hand-written FPU chain (3 entries per row, lobatto3, release, medians;
    /// `examples/large_chain.rs --scaling`): dense 15.5, 46.5, 256 and 1941 µs per step at
    /// n = 4, 8, 16 and 32, sparse 4.0, 6.0, 10.2 and 21.8 µs. The sparse step wins from
    /// n = 4 against general dense kernels; the macro's specialised dense kernels of small
    /// models take a few µs, so below n = 8 the dense path is kept.
    pub const SPARSE_MIN_DOF: usize = 8;
    /// The densest node pattern, as a fraction of `N²`, for which [`LinearPath::Auto`] takes
    /// the sparse path.
    pub const SPARSE_MAX_DENSITY: f64 = 0.25;
}

/// A fixed-step variational integrator for one model and one scheme.
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
///
/// let run = Integrator::new(&Oscillator, Scheme::lobatto(3)?, 0.01)?
///     .run(InitialState::from_velocity([1.0], [0.0]), 1.0)
///     .map_err(|f| f.error)?;
/// let end = run.last().unwrap();
/// assert!((end.q[0] - 1f64.cos()).abs() < 1e-9);
/// # Ok::<(), forced_vi::Error>(())
/// ```
pub struct Integrator<'m, M, const N: usize> {
    pub(crate) model: &'m M,
    pub(crate) scheme: Scheme,
    pub(crate) h: f64,
    pub(crate) options: StepOptions,
    /// With tolerances the run is adaptive and `h` is only its first step.
    pub(crate) tolerance: Option<Tolerance<N>>,
    pub(crate) linear_path: LinearPath,
}

// By hand: the model is borrowed, so neither needs `M: Clone` or `M: Debug`.
impl<M, const N: usize> Clone for Integrator<'_, M, N> {
    fn clone(&self) -> Self {
        Integrator {
            model: self.model,
            scheme: self.scheme.clone(),
            h: self.h,
            options: self.options,
            tolerance: self.tolerance,
            linear_path: self.linear_path,
        }
    }
}

impl<M, const N: usize> std::fmt::Debug for Integrator<'_, M, N> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Integrator")
            .field("model", &std::any::type_name::<M>())
            .field("scheme", &self.scheme.id())
            .field("h", &self.h)
            .field("options", &self.options)
            .field("tolerance", &self.tolerance)
            .field("linear_path", &self.linear_path)
            .finish()
    }
}

impl<'m, M: ForcedLagrangian<N>, const N: usize> Integrator<'m, M, N> {
    /// The most subdivision levels a step may use: 2²⁰ substeps.
    pub const MAX_SUBDIVISION_LEVELS: u32 = 20;

    /// An integrator with step `h`. Defaults: [`StepOptions::default`], fixed steps,
    /// [`LinearPath::Auto`].
    ///
    /// Fails if `h` is not positive and finite (with `1/h` finite too), a model parameter
    /// is not finite, the model's own check fails ([`ForcedLagrangian::check_model`]), or its
    /// kernels need more than [`MAX_KERNEL_STACK`] bytes of stack (for a model with sparse
    /// kernels, only when a run takes the dense path).
    pub fn new(model: &'m M, scheme: Scheme, h: f64) -> Result<Self, Error> {
        if !(h.is_finite() && h > 0.0 && (1.0 / h).is_finite()) {
            return Err(Error::InvalidStepSize { h });
        }
        if model.sparse_node().is_none() {
            check_kernel_stack::<M, N>()?;
        }
        model
            .check_parameters()
            .map_err(|name| Error::NonFiniteParameter { name })?;
        model
            .check_model()
            .map_err(|message| Error::InvalidModel { message })?;
        Ok(Integrator {
            model,
            scheme,
            h,
            options: StepOptions::default(),
            tolerance: None,
            linear_path: LinearPath::Auto,
        })
    }

    /// Replaces the Newton options.
    #[must_use]
    pub fn newton(mut self, newton: NewtonOptions) -> Self {
        self.options.newton = newton;
        self
    }

    /// Allows a failed step to be retried as up to `2^levels` substeps; `levels` is capped
    /// at [`Self::MAX_SUBDIVISION_LEVELS`].
    #[must_use]
    pub fn max_subdivisions(mut self, levels: u32) -> Self {
        self.options.max_subdivisions = levels.min(Self::MAX_SUBDIVISION_LEVELS);
        self
    }

    /// Makes the run adaptive: steps are chosen to keep the error within `rtol · |y| + atol`
    /// (positions and momenta), and `h` becomes the first step. See [`crate::control`] for
    /// the estimate and the controller. Fails unless both are finite, non-negative and not
    /// both zero.
    ///
    /// ```
    /// use forced_vi::prelude::*;
    /// # struct Oscillator;
    /// # impl ForcedLagrangian<1> for Oscillator {
    /// #     fn lagrangian<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> D {
    /// #         (v[0] * v[0] - q[0] * q[0]) * 0.5
    /// #     }
    /// # }
    /// let run = Integrator::new(&Oscillator, Scheme::lobatto(3)?, 0.1)?
    ///     .tolerances(1e-8, 1e-8)?
    ///     .run(InitialState::from_velocity([1.0], [0.0]), 10.0)
    ///     .map_err(|f| f.error)?;
    /// let end = run.last().unwrap();
    /// assert!((end.q[0] - 10f64.cos()).abs() < 1e-6);
    /// // Dense output between the steps.
    /// let mid = run.at(5.0).unwrap();
    /// assert!((mid.q[0] - 5f64.cos()).abs() < 1e-6);
    /// # Ok::<(), forced_vi::Error>(())
    /// ```
    pub fn tolerances(self, rtol: f64, atol: f64) -> Result<Self, Error> {
        Ok(self.tolerance(Tolerance::scalar(rtol, atol)?))
    }

    /// Makes the run adaptive with tolerances per coordinate (see [`Self::tolerances`]).
    #[must_use]
    pub fn tolerance(mut self, tolerance: Tolerance<N>) -> Self {
        self.tolerance = Some(tolerance);
        self
    }

    /// Chooses the linear algebra of the runs (default [`LinearPath::Auto`]).
    #[must_use]
    pub fn linear_path(mut self, path: LinearPath) -> Self {
        self.linear_path = path;
        self
    }

    /// Caps the steps of a run ([`StepOptions::DEFAULT_MAX_STEPS`] by default).
    #[must_use]
    pub fn max_steps(mut self, steps: usize) -> Self {
        self.options.max_steps = steps;
        self
    }

    /// The scheme.
    pub fn scheme(&self) -> &Scheme {
        &self.scheme
    }

    /// The step size.
    pub fn step_size(&self) -> f64 {
        self.h
    }

    /// The dense path's streaming stepper from `init` to `t_final`: an iterator of records,
    /// initial state first, that holds only the current state. The run methods choose the
    /// path by [`LinearPath`]; see [`Self::sparse_stepper`] for the sparse one.
    pub fn stepper(&self, init: InitialState<N>, t_final: f64) -> Result<Stepper<'_, M, N>, Error> {
        check_kernel_stack::<M, N>()?;
        Stepper::new(self, init, t_final)
    }

    /// The sparse path's streaming stepper (DESIGN §9), for a model with sparse kernels.
    /// Fails with [`Error::SparsePathUnavailable`] without them or with tolerances set.
    #[cfg(feature = "sparse")]
    pub fn sparse_stepper(
        &self,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<SparseStepper<'_, M, N>, Error> {
        let node = self
            .model
            .sparse_node()
            .ok_or(Error::SparsePathUnavailable {
                reason: "the model has no sparse node kernels",
            })?;
        let pattern = self.record_pattern(node, &init)?;
        self.open_sparse(node, pattern, init, t_final)
    }

    /// The path a run from `init` takes ([`LinearPath::Dense`] or [`LinearPath::Sparse`]),
    /// or why it cannot run.
    pub fn path_for(&self, init: &InitialState<N>) -> Result<LinearPath, Error> {
        Ok(match self.choose(init)? {
            Some(_) => LinearPath::Sparse,
            None => LinearPath::Dense,
        })
    }

    /// The sparse kernels and their pattern if the run takes the sparse path.
    #[cfg(feature = "sparse")]
    fn choose(
        &self,
        init: &InitialState<N>,
    ) -> Result<Option<(&'m dyn SparseNode, NodePattern)>, Error> {
        let node = self.model.sparse_node();
        let node = match (self.linear_path, node) {
            (LinearPath::Dense, _) => return Ok(None),
            (LinearPath::Sparse, None) => {
                return Err(Error::SparsePathUnavailable {
                    reason: "the model has no sparse node kernels",
                })
            }
            (LinearPath::Auto, Some(_)) if N < LinearPath::SPARSE_MIN_DOF => return Ok(None),
            (LinearPath::Auto, None) => return Ok(None),
            (_, Some(node)) => node,
        };
        let pattern = self.record_pattern(node, init)?;
        let dense_enough = pattern.nnz() as f64 > LinearPath::SPARSE_MAX_DENSITY * (N * N) as f64;
        if self.linear_path == LinearPath::Auto && dense_enough {
            return Ok(None);
        }
        Ok(Some((node, pattern)))
    }

    /// Without the `sparse` feature every run takes the dense path.
    #[cfg(not(feature = "sparse"))]
    fn choose(&self, _init: &InitialState<N>) -> Result<Option<std::convert::Infallible>, Error> {
        match self.linear_path {
            LinearPath::Sparse => Err(Error::SparsePathUnavailable {
                reason: "forced-vi was built without its `sparse` feature",
            }),
            LinearPath::Auto | LinearPath::Dense => Ok(None),
        }
    }

    /// Records the node pattern at the initial state (at `v = 0` for initial momenta).
    #[cfg(feature = "sparse")]
    fn record_pattern(
        &self,
        node: &dyn SparseNode,
        init: &InitialState<N>,
    ) -> Result<NodePattern, Error> {
        if self.tolerance.is_some() {
            return Err(Error::SparsePathUnavailable {
                reason: "adaptive step control is not implemented on the sparse path",
            });
        }
        match init {
            InitialState::Velocity { q, v } => record_node_pattern(node, 0.0, q, v),
            InitialState::Momentum { q, .. } => record_node_pattern(node, 0.0, q, &vec![0.0; N]),
        }
    }

    #[cfg(feature = "sparse")]
    fn open_sparse(
        &self,
        node: &'m dyn SparseNode,
        pattern: NodePattern,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<SparseStepper<'_, M, N>, Error> {
        SparseStepper::new(self, node, pattern, init, t_final)
    }

    /// Opens the run's stepper on the chosen path and hands it to `visit`.
    fn open<R>(
        &self,
        init: InitialState<N>,
        t_final: f64,
        visit: impl FnOnce(&mut dyn Steps<N>) -> R,
    ) -> Result<R, Error> {
        match self.choose(&init)? {
            #[cfg(feature = "sparse")]
            Some((node, pattern)) => {
                let mut s = self.open_sparse(node, pattern, init, t_final)?;
                Ok(visit(&mut s))
            }
            #[cfg(not(feature = "sparse"))]
            Some(never) => match never {},
            None => {
                let mut s = self.stepper(init, t_final)?;
                Ok(visit(&mut s))
            }
        }
    }

    /// Streams every record to `f` and returns the totals. Memory use does not grow with
    /// the number of steps. On failure the totals up to it come back with the error.
    pub fn for_each_step(
        &self,
        init: InitialState<N>,
        t_final: f64,
        mut f: impl FnMut(&StepRecord<N>),
    ) -> Result<RunStats, StreamFailure> {
        let streamed = self.open(init, t_final, |stepper| {
            while let Some(rec) = Iterator::next(stepper) {
                match rec {
                    Ok(r) => f(&r),
                    Err(error) => {
                        return Err(StreamFailure {
                            error,
                            stats: stepper.stats(),
                        })
                    }
                }
            }
            Ok(stepper.stats())
        });
        streamed.unwrap_or_else(|error| {
            Err(StreamFailure {
                error,
                stats: RunStats::default(),
            })
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
    ) -> Result<FinalState<N>, StreamFailure> {
        let fail = |error, stats| StreamFailure { error, stats };
        let finished = self.open(init, t_final, |stepper| {
            stepper.set_lean(true);
            while let Some(rec) = Iterator::next(stepper) {
                if let Err(e) = rec {
                    return Err(fail(e, stepper.stats()));
                }
            }
            let stats = stepper.stats();
            let end = stepper.finish().map_err(|e| fail(e, stats))?;
            Ok(FinalState {
                t: end.t,
                q: end.q,
                p: end.p,
                v: end.v,
                energy: end.energy,
                stats,
            })
        });
        finished.unwrap_or_else(|e| Err(fail(e, RunStats::default())))
    }

    /// Runs to the last of `times` and returns the dense output at each of them (see
    /// [`DenseState`]), so that the step grid, fixed or adaptive, is free of the output grid.
    /// Only the last step is held, so memory grows with the samples, not the steps. The
    /// times must be finite, non-negative and non-decreasing.
    pub fn sample(
        &self,
        init: InitialState<N>,
        times: &[f64],
    ) -> Result<Vec<DenseState<N>>, SampleFailure<N>> {
        let fail = |error, samples| SampleFailure { error, samples };
        let ordered = times.windows(2).all(|w| w[0] <= w[1]);
        if let Some(&t) = times.iter().find(|t| !(t.is_finite() && **t >= 0.0)) {
            return Err(fail(Error::InvalidFinalTime { t_final: t }, Vec::new()));
        }
        if !ordered {
            return Err(fail(Error::UnorderedTimes, Vec::new()));
        }
        let t_final = times.last().copied().unwrap_or(0.0);
        let sampled = self.open(init, t_final, |stepper| {
            let mut out = Vec::with_capacity(times.len());
            let mut prev: Option<StepRecord<N>> = None;
            while let Some(rec) = Iterator::next(stepper) {
                let rec = match rec {
                    Ok(r) => r,
                    Err(e) => return Err(fail(e, out)),
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
        });
        sampled.unwrap_or_else(|e| Err(fail(e, Vec::new())))
    }

    /// Runs to `t_final` and collects every record. On failure the records computed so far
    /// come back with the error.
    pub fn run(&self, init: InitialState<N>, t_final: f64) -> Result<Trajectory<N>, RunFailure<N>> {
        let adaptive = self.tolerance.is_some();
        let collected = self.open(init, t_final, |stepper| collect(stepper, adaptive));
        collected.unwrap_or_else(|error| {
            Err(RunFailure {
                error,
                trajectory: Trajectory::default(),
            })
        })
    }
}

/// Collects a run's records. A fixed-step run reserves all its records up front, so that a
/// run that cannot hold them fails before its first step rather than aborting in the
/// middle; an adaptive one grows its storage fallibly.
fn collect<const N: usize>(
    stepper: &mut dyn Steps<N>,
    adaptive: bool,
) -> Result<Trajectory<N>, RunFailure<N>> {
    let mut traj = Trajectory::default();
    let records = stepper.total_steps().saturating_add(1);
    let reserve = if adaptive { records.min(1024) } else { records };
    if traj.records.try_reserve_exact(reserve).is_err() {
        return Err(RunFailure {
            error: Error::TooManyRecords { records },
            trajectory: traj,
        });
    }
    while let Some(rec) = Iterator::next(stepper) {
        match rec {
            Ok(r) => {
                if traj.records.len() == traj.records.capacity()
                    && traj.records.try_reserve(traj.records.len()).is_err()
                {
                    traj.stats = stepper.stats();
                    let records = traj.records.len() * 2;
                    return Err(RunFailure {
                        error: Error::TooManyRecords { records },
                        trajectory: traj,
                    });
                }
                traj.records.push(r)
            }
            Err(error) => {
                traj.stats = stepper.stats();
                return Err(RunFailure {
                    error,
                    trajectory: traj,
                });
            }
        }
    }
    traj.stats = stepper.stats();
    Ok(traj)
}

/// Refuses a model whose dense kernels need more stack than [`MAX_KERNEL_STACK`].
fn check_kernel_stack<M: ForcedLagrangian<N>, const N: usize>() -> Result<(), Error> {
    if M::KERNEL_STACK_BYTES > MAX_KERNEL_STACK {
        return Err(Error::ModelTooLarge {
            stack_bytes: M::KERNEL_STACK_BYTES,
            max: MAX_KERNEL_STACK,
        });
    }
    Ok(())
}

/// A run's stepper on either path, as the run methods drive it.
trait Steps<const N: usize>: Iterator<Item = Result<StepRecord<N>, Error>> {
    fn stats(&self) -> RunStats;
    fn total_steps(&self) -> usize;
    fn set_lean(&mut self, lean: bool);
    fn finish(&mut self) -> Result<StepRecord<N>, Error>;
}

impl<M: ForcedLagrangian<N>, const N: usize> Steps<N> for Stepper<'_, M, N> {
    fn stats(&self) -> RunStats {
        Stepper::stats(self)
    }
    fn total_steps(&self) -> usize {
        Stepper::total_steps(self)
    }
    fn set_lean(&mut self, lean: bool) {
        Stepper::set_lean(self, lean)
    }
    fn finish(&mut self) -> Result<StepRecord<N>, Error> {
        Stepper::finish(self)
    }
}

#[cfg(feature = "sparse")]
impl<M: ForcedLagrangian<N>, const N: usize> Steps<N> for SparseStepper<'_, M, N> {
    fn stats(&self) -> RunStats {
        SparseStepper::stats(self)
    }
    fn total_steps(&self) -> usize {
        SparseStepper::total_steps(self)
    }
    fn set_lean(&mut self, lean: bool) {
        SparseStepper::set_lean(self, lean)
    }
    fn finish(&mut self) -> Result<StepRecord<N>, Error> {
        SparseStepper::finish(self)
    }
}
