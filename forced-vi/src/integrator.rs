//! The integrator: a model, a scheme and a step size, with the options of a run, and the
//! ways to run it (collect, stream, iterate).

use crate::control::Tolerance;
use crate::error::Error;
use crate::initial::InitialState;
use crate::model::ForcedLagrangian;
use crate::newton::NewtonOptions;
use crate::scheme::Scheme;
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
            .finish()
    }
}

impl<'m, M: ForcedLagrangian<N>, const N: usize> Integrator<'m, M, N> {
    /// The most subdivision levels a step may use: 2²⁰ substeps.
    pub const MAX_SUBDIVISION_LEVELS: u32 = 20;

    /// An integrator with step `h`. Defaults: [`StepOptions::default`].
    ///
    /// Fails if `h` is not positive and finite (with `1/h` finite too), a model parameter
    /// is not finite, the model's own check fails ([`ForcedLagrangian::check_model`]), or its
    /// kernels need more than [`MAX_KERNEL_STACK`] bytes of stack.
    pub fn new(model: &'m M, scheme: Scheme, h: f64) -> Result<Self, Error> {
        if !(h.is_finite() && h > 0.0 && (1.0 / h).is_finite()) {
            return Err(Error::InvalidStepSize { h });
        }
        if M::KERNEL_STACK_BYTES > MAX_KERNEL_STACK {
            return Err(Error::ModelTooLarge {
                stack_bytes: M::KERNEL_STACK_BYTES,
                max: MAX_KERNEL_STACK,
            });
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

    /// A streaming stepper from `init` to `t_final`: an iterator of records, initial state
    /// first, that holds only the current state.
    pub fn stepper(&self, init: InitialState<N>, t_final: f64) -> Result<Stepper<'_, M, N>, Error> {
        Stepper::new(self, init, t_final)
    }

    /// Streams every record to `f` and returns the totals. Memory use does not grow with
    /// the number of steps. On failure the totals up to it come back with the error.
    pub fn for_each_step(
        &self,
        init: InitialState<N>,
        t_final: f64,
        mut f: impl FnMut(&StepRecord<N>),
    ) -> Result<RunStats, StreamFailure> {
        let mut stepper = self.stepper(init, t_final).map_err(|error| StreamFailure {
            error,
            stats: RunStats::default(),
        })?;
        for rec in stepper.by_ref() {
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
        let mut stepper = self
            .stepper(init, t_final)
            .map_err(|e| fail(e, RunStats::default()))?;
        stepper.set_lean(true);
        for rec in stepper.by_ref() {
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
        let mut stepper = self
            .stepper(init, t_final)
            .map_err(|e| fail(e, Vec::new()))?;
        let mut out = Vec::with_capacity(times.len());
        let mut prev: Option<StepRecord<N>> = None;
        for rec in stepper.by_ref() {
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
    }

    /// Runs to `t_final` and collects every record. On failure the records computed so far
    /// come back with the error.
    pub fn run(&self, init: InitialState<N>, t_final: f64) -> Result<Trajectory<N>, RunFailure<N>> {
        let mut traj = Trajectory::default();
        let mut stepper = match self.stepper(init, t_final) {
            Ok(s) => s,
            Err(error) => {
                return Err(RunFailure {
                    error,
                    trajectory: traj,
                })
            }
        };
        // A fixed-step run reserves all its records up front, so that a run that cannot
        // hold them fails before its first step rather than aborting in the middle; an
        // adaptive one grows its storage fallibly.
        let records = stepper.total_steps().saturating_add(1);
        let reserve = if self.tolerance.is_some() {
            records.min(1024)
        } else {
            records
        };
        if traj.records.try_reserve_exact(reserve).is_err() {
            return Err(RunFailure {
                error: Error::TooManyRecords { records },
                trajectory: traj,
            });
        }
        for rec in stepper.by_ref() {
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
}
