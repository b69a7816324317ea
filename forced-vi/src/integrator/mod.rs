//! The integrator: a model, a scheme and a step size, with the options of a run, and the
//! ways to run it (collect, stream, iterate).
//!
//! | piece | module |
//! |---|---|
//! | [`Integrator`], its builder and its steppers; [`StepOptions`] | this one |
//! | [`LinearPath`]: the choice of the dense or the sparse step | `path` |
//! | what a run gives back: records, final state, samples, a stream, derivatives | [`output`] |
//! | [`Integrator::solve`] and its shorthands | `run` |

pub mod output;
mod path;
mod run;

use crate::backend::Backend;
use crate::control::Tolerance;
use crate::error::Error;
use crate::initial::InitialState;
use crate::model::ForcedLagrangian;
use crate::newton::NewtonOptions;
use crate::scheme::Scheme;
use crate::stepper::{RunSetup, Stepper};

pub use crate::stepper::StepOptions;
pub use path::LinearPath;
pub use run::Runs;

/// The deepest stack the integrator provides for a model's node kernels (4 GiB, mapped
/// lazily: only the pages the kernels touch use memory).
pub const MAX_KERNEL_STACK: usize = 4 << 30;

/// The largest tangent the forward sensitivities (`output::Tangents`) carry: `2N × (2N + P)`
/// numbers, kept twice while a step is subdivided (1 GiB, about 5800 coordinates without
/// parameters). Past it a run is [`Error::TangentTooLarge`]; the adjoint has no such bound.
pub const MAX_TANGENT_BYTES: usize = 1 << 30;

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
///     .solve(InitialState::from_velocity([1.0], [0.0]), 1.0, output::Records)
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
    /// Adaptive runs: the scheme of the error estimate ([`Scheme::error_reference`]).
    pub(crate) reference: Option<Scheme>,
    /// Adaptive runs with pairs (see [`Self::paired_estimates`]): the scheme of their
    /// estimate ([`Scheme::pair_error_reference`]).
    pub(crate) pair_reference: Option<Scheme>,
    /// Adaptive runs: choose the first step from the initial data instead of `h`.
    pub(crate) auto_first_step: bool,
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
            reference: self.reference.clone(),
            pair_reference: self.pair_reference.clone(),
            auto_first_step: self.auto_first_step,
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
    pub const MAX_SUBDIVISION_LEVELS: u32 = StepOptions::MAX_SUBDIVISION_LEVELS;

    /// An integrator with step `h`. Defaults: [`StepOptions::default`], fixed steps,
    /// [`LinearPath::Auto`].
    ///
    /// Fails if the model has no coordinates, `h` is not finite and at least
    /// [`StepOptions::SMALLEST_STEP`], a model parameter
    /// is not finite, the model's own check fails ([`ForcedLagrangian::check_model`]), it
    /// declares constraints while promising none ([`ForcedLagrangian::CONSTRAINED`]), or its
    /// kernels need more than [`MAX_KERNEL_STACK`] bytes of stack (for a model with sparse
    /// kernels, only when a run takes the dense path).
    pub fn new(model: &'m M, scheme: Scheme, h: f64) -> Result<Self, Error> {
        if N == 0 {
            return Err(Error::InvalidModel {
                message: "the model has no coordinates (N = 0)".into(),
            });
        }
        if !(h.is_finite() && h >= StepOptions::SMALLEST_STEP) {
            return Err(Error::InvalidStepSize { h });
        }
        if model.sparse_node().is_none() {
            path::check_dense::<M, N>()?;
        }
        model
            .check_parameters()
            .map_err(|name| Error::NonFiniteParameter { name })?;
        model
            .check_model()
            .map_err(|message| Error::InvalidModel { message })?;
        if !M::CONSTRAINED && model.constraint_count() > 0 {
            return Err(Error::InvalidModel {
                message: format!(
                    "constraint_count() is {} but CONSTRAINED is false",
                    model.constraint_count()
                ),
            });
        }
        Ok(Integrator {
            model,
            scheme,
            h,
            options: StepOptions::default(),
            tolerance: None,
            reference: None,
            pair_reference: None,
            auto_first_step: false,
            linear_path: LinearPath::Auto,
        })
    }

    /// An adaptive integrator that needs no step size: steps keep the error within
    /// `rtol · |y| + atol` (see [`Self::tolerances`]), and the first step is chosen from the
    /// initial data (Hairer, Nørsett & Wanner's starting-step algorithm, see
    /// [`crate::control`]).
    ///
    /// ```
    /// use forced_vi::prelude::*;
    /// # struct Oscillator;
    /// # impl ForcedLagrangian<1> for Oscillator {
    /// #     fn lagrangian<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> D {
    /// #         (v[0] * v[0] - q[0] * q[0]) * 0.5
    /// #     }
    /// # }
    /// let end = Integrator::adaptive(&Oscillator, Scheme::lobatto(4)?, 1e-9, 1e-9)?
    ///     .final_state(InitialState::from_velocity([1.0], [0.0]), 10.0)
    ///     .map_err(|f| f.error)?;
    /// assert!((end.q[0] - 10f64.cos()).abs() < 1e-8);
    /// # Ok::<(), forced_vi::Error>(())
    /// ```
    pub fn adaptive(model: &'m M, scheme: Scheme, rtol: f64, atol: f64) -> Result<Self, Error> {
        let mut integ = Self::new(model, scheme, 1.0)?.tolerances(rtol, atol)?;
        integ.auto_first_step = true;
        Ok(integ)
    }

    /// An adaptive integrator that chooses its order too: the Lobatto scheme of
    /// [`Scheme::for_tolerance`] for the tighter of `rtol` and `atol` (the positive one if the
    /// other is zero): its sparse column for a model with sparse kernels and at least
    /// [`Scheme::AUTO_SPARSE_MIN_DOF`] coordinates, which the sparse backend runs, its dense
    /// column otherwise (a model of [`LinearPath::SPARSE_MIN_DOF`] to 31 coordinates with
    /// sparse kernels runs on the sparse backend with the dense column's order); then as
    /// [`Self::adaptive`].
    ///
    /// ```
    /// use forced_vi::prelude::*;
    /// # struct Oscillator;
    /// # impl ForcedLagrangian<1> for Oscillator {
    /// #     fn lagrangian<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> D {
    /// #         (v[0] * v[0] - q[0] * q[0]) * 0.5
    /// #     }
    /// # }
    /// let integrator = Integrator::auto(&Oscillator, 1e-10, 1e-10)?;
    /// assert_eq!(integrator.scheme().order(), 14);
    /// let end = integrator
    ///     .final_state(InitialState::from_velocity([1.0], [0.0]), 10.0)
    ///     .map_err(|f| f.error)?;
    /// assert!((end.q[0] - 10f64.cos()).abs() < 1e-9);
    /// # Ok::<(), forced_vi::Error>(())
    /// ```
    pub fn auto(model: &'m M, rtol: f64, atol: f64) -> Result<Self, Error> {
        let tol = match (rtol > 0.0, atol > 0.0) {
            (true, true) => rtol.min(atol),
            (true, false) => rtol,
            _ => atol,
        };
        // The sparse column from `AUTO_SPARSE_MIN_DOF` coordinates only (a model on the
        // sparse backend below them runs the dense column faster; see there).
        let sparse = N >= LinearPath::SPARSE_MIN_DOF.max(Scheme::AUTO_SPARSE_MIN_DOF)
            && model.sparse_node().is_some();
        Self::adaptive(model, Scheme::for_tolerance(tol, sparse), rtol, atol)
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
    ///     .solve(InitialState::from_velocity([1.0], [0.0]), 10.0, output::Records)
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
    /// Tolerances that [`Tolerance::per_component`] would refuse (built from the public
    /// fields, or deserialized) make every run fail with [`Error::InvalidTolerance`] before
    /// its first step.
    #[must_use]
    pub fn tolerance(mut self, tolerance: Tolerance<N>) -> Self {
        self.tolerance = Some(tolerance);
        self.reference = Some(self.scheme.error_reference());
        self.pair_reference = Some(self.scheme.pair_error_reference());
        self
    }

    /// Adaptive runs: whether the local error is estimated once over two steps of one size
    /// instead of once per step (see [`crate::control`], "Pairs"). By default it is, on the
    /// dense path ([`LinearPath`]), and not on the sparse one, where a lobatto3 pair's
    /// larger reference system (lobatto5's) can cost more than the pair saves (the FPU
    /// chain at n = 1024: 17 % fewer instructions at tol 1e-6, 32 % more at 1e-8). The two
    /// steps are accepted or retried together. Pairs are taken by lobatto2, lobatto3 and
    /// the midpoint scheme (others ignore the option: for lobatto4 and up the reference
    /// over two steps is too close to them in order), away from output times, the run's
    /// end, a rejected step, a constrained model, a sensitivity or adjoint run, and steps
    /// that do not resolve the model's fastest rates (a stiff stretch). Measured
    /// (callgrind, whole runs, against one estimate per step): 13 to 28 % fewer
    /// instructions on four report models at tol 1e-6 to 1e-7, with 7 % fewer to 5 % more
    /// steps.
    #[must_use]
    pub fn paired_estimates(mut self, on: bool) -> Self {
        self.options.paired_estimates = Some(on);
        self
    }

    /// Adaptive runs: the largest step (default `∞`). Fails unless it is positive and at
    /// least [`StepOptions::min_step`]. A force that acts only between a step's nodes (a
    /// pulse shorter than the step) is invisible to the step and to its error estimate:
    /// bound the steps by such a feature's width (see the
    /// [guide](crate::guide#what-an-ok-promises)).
    pub fn max_step(mut self, h: f64) -> Result<Self, Error> {
        self.options.max_step = h;
        self.options.check_step_bounds()?;
        Ok(self)
    }

    /// Adaptive runs: the smallest step (default 0). A run that needs a smaller one (other
    /// than to end on `t_final` or on an output time of
    /// [`output::Samples`]) stops with [`Error::StepSizeTooSmall`]. Fails unless it is
    /// finite, non-negative and at most [`StepOptions::max_step`].
    pub fn min_step(mut self, h: f64) -> Result<Self, Error> {
        self.options.min_step = h;
        self.options.check_step_bounds()?;
        Ok(self)
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

    /// The streaming stepper from `init` to `t_final`: an iterator of records, initial state
    /// first, that holds only the current state. It runs on the backend that
    /// [`LinearPath`] chooses (see [`Self::path_for`]), like every run method.
    pub fn stepper(&self, init: InitialState<N>, t_final: f64) -> Result<Stepper<'_, M, N>, Error> {
        let init = &init;
        crate::stack::with_run_stack::<N, _>(move || self.stepper_here(*init, t_final))
    }

    /// [`Self::stepper`] on the current stack.
    fn stepper_here(
        &self,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<Stepper<'_, M, N>, Error> {
        // Tolerances made without their constructors (public fields, or deserialized) are
        // checked here, before any step, as `Tolerance::per_component` checks them.
        if let Some(tol) = &self.tolerance {
            tol.check()?;
        }
        let newton = self.options.newton;
        let backend = self.backend(&init, &self.scheme, newton)?;
        // The error estimate's one Newton iteration (see `crate::control`).
        // Pairs (see `Self::paired_estimates`), by default on the dense path.
        let mut options = self.options;
        let paired = options
            .paired_estimates
            .unwrap_or(matches!(backend, Backend::Dense(_)));
        options.paired_estimates = Some(paired);
        let reference = match paired {
            true => &self.pair_reference,
            false => &self.reference,
        };
        let reference = match (&self.tolerance, reference) {
            (Some(_), Some(sch)) => Some(self.backend(&init, sch, newton.max_iterations(1))?),
            _ => None,
        };
        let setup = RunSetup {
            model: self.model,
            scheme: &self.scheme,
            h: self.h,
            auto_first_step: self.auto_first_step,
            options,
            tolerance: self.tolerance,
        };
        Stepper::new(setup, backend, reference, init, t_final)
    }
}
