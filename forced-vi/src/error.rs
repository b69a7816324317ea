//! Typed errors. Library code returns these; it does not panic on user input.

use thiserror::Error;

/// A scheme id or coefficient set that cannot be built.
#[derive(Clone, Debug, Error, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[non_exhaustive]
pub enum SchemeError {
    /// The id is not one of `midpoint`, `trapezoid`, `alpha(<value>)`, `lobatto<s>`.
    #[error("unknown scheme `{0}` (expected midpoint, trapezoid, alpha(<0..1>) or lobatto<s>)")]
    Unknown(String),
    /// Lobatto needs at least two control points.
    #[error("lobatto needs s >= 2 stages, got {0}")]
    TooFewStages(usize),
    /// More Lobatto stages than [`crate::scheme::MAX_STAGES`].
    #[error("lobatto supports at most {max} stages, got {requested}")]
    TooManyStages {
        /// The requested number of stages (saturated at `usize::MAX`).
        requested: usize,
        /// The cap.
        max: usize,
    },
    /// The α-rule needs `0 ≤ α ≤ 1`.
    #[error("alpha must be a finite number in [0, 1], got {0}")]
    AlphaOutOfRange(f64),
}

/// Why a Newton solve failed; the integrator adds the step and the time.
#[derive(Clone, Copy, Debug, Error, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[non_exhaustive]
pub enum NewtonFailure {
    /// The iteration cap was reached.
    #[error("no convergence within the iteration cap (residual {residual:.3e})")]
    MaxIterations {
        /// Max-norm of the last residual.
        residual: f64,
    },
    /// The residual kept growing.
    #[error("diverged (residual {residual:.3e})")]
    Diverged {
        /// Max-norm of the last residual.
        residual: f64,
    },
    /// The line search could not reduce the residual.
    #[error("stagnated: no step reduces the residual {residual:.3e}")]
    Stagnated {
        /// Max-norm of the residual where it stalled.
        residual: f64,
    },
    /// The Jacobian is singular to working precision.
    #[error("singular Jacobian")]
    SingularJacobian,
    /// The residual or Jacobian contained NaN or infinity.
    #[error("non-finite residual or Jacobian")]
    NonFinite,
}

impl NewtonFailure {
    /// A short, stable name for reports (`max_iterations`, `diverged`, ...).
    pub fn kind(&self) -> &'static str {
        match self {
            NewtonFailure::MaxIterations { .. } => "max_iterations",
            NewtonFailure::Diverged { .. } => "diverged",
            NewtonFailure::Stagnated { .. } => "stagnated",
            NewtonFailure::SingularJacobian => "singular_jacobian",
            NewtonFailure::NonFinite => "non_finite",
        }
    }
}

/// An integration that could not start or could not go on.
///
/// The errors of bad input that a new user meets first (a bad step size or tolerance, a
/// singular mass matrix, an initial state the model cannot start from) are shown with their
/// messages in the [guide](crate::guide#bad-input).
#[derive(Clone, Debug, Error, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[non_exhaustive]
pub enum Error {
    /// The step size is not a finite number of at least
    /// [`StepOptions::SMALLEST_STEP`](crate::StepOptions::SMALLEST_STEP).
    #[error("step size h = {h:?} must be positive and finite (and at least 1.0e-292)")]
    InvalidStepSize {
        /// The rejected step size.
        h: f64,
    },
    /// The final time is negative, not finite, or positive but below
    /// [`StepOptions::SMALLEST_STEP`](crate::StepOptions::SMALLEST_STEP).
    #[error(
        "final time {t_final:?} must be finite and non-negative (and zero or at least 1.0e-292)"
    )]
    InvalidFinalTime {
        /// The rejected final time.
        t_final: f64,
    },
    /// A model parameter is NaN or infinite.
    #[error("model parameter `{name}` is not finite")]
    NonFiniteParameter {
        /// The parameter's name.
        name: &'static str,
    },
    /// The model cannot be evaluated as written (for example, an array index out of range
    /// for this length); found by [`crate::ForcedLagrangian::check_model`].
    #[error("invalid model: {message}")]
    InvalidModel {
        /// What is wrong, in the model's own terms.
        message: String,
    },
    /// The Newton options are out of range (a negative or NaN tolerance, say).
    #[error("newton option `{field}` = {value} is out of range")]
    InvalidNewtonOptions {
        /// The field.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// The run would take more steps than the cap ([`crate::StepOptions::max_steps`]).
    #[error("the run needs {steps:e} steps, more than the cap of {max}")]
    TooManySteps {
        /// Steps the run needs (`t_final / h`, as a float: it may exceed `usize`).
        steps: f64,
        /// The cap.
        max: usize,
    },
    /// The records of a collecting run do not fit in memory; stream them instead
    /// ([`crate::output::each_step`]).
    #[error("cannot hold {records} records in memory; stream them with output::each_step")]
    TooManyRecords {
        /// Records the run needs.
        records: usize,
    },
    /// The model is too large for the dense backend: more coordinates than
    /// [`crate::LinearPath::DENSE_MAX_DOF`], or node kernels that need more stack than
    /// [`crate::MAX_KERNEL_STACK`]. A model with sparse kernels runs on the sparse backend
    /// instead ([`crate::LinearPath::Auto`] or [`crate::LinearPath::Sparse`]).
    #[error(
        "the model is too large for the dense path: {dof} coordinates (at most {max_dof}), node kernels needing {stack_bytes} bytes of stack (at most {max}); give it sparse kernels (a model `#[forced_lagrangian]` can split into local terms) and use LinearPath::Auto or Sparse"
    )]
    ModelTooLarge {
        /// The model's coordinates `N`.
        dof: usize,
        /// The dense backend's cap on them.
        max_dof: usize,
        /// The model's [`crate::ForcedLagrangian::KERNEL_STACK_BYTES`].
        stack_bytes: usize,
        /// The cap on them.
        max: usize,
    },
    /// A sensitivity run of a model with parameters whose dual numbers, over every
    /// coordinate and one parameter, would need more stack than
    /// [`crate::MAX_KERNEL_STACK`] (they grow like `N²`): refused before the first step.
    /// It applies to a model without the per-term parameter kernels
    /// ([`crate::model::SparseNode::eval_parameter`]): for the forward sensitivities
    /// (`output::Tangents`) always, for the adjoint (`output::adjoint`) only with constraints
    /// (its other parameter terms are scalar contractions).
    #[error(
        "the sensitivities in the parameters of a model of {dof} coordinates need {stack_bytes} bytes of stack for their dual numbers (at most {max})"
    )]
    SensitivitiesTooLarge {
        /// The model's coordinates `N`.
        dof: usize,
        /// The stack the parameters' kernels need.
        stack_bytes: usize,
        /// The cap on it.
        max: usize,
    },
    /// Forward sensitivities (`output::Tangents`) whose tangent, `2N` rows by `2N + P`
    /// columns, would take more than [`crate::MAX_TANGENT_BYTES`]: refused before the first
    /// step, where the run would have ended in an allocation failure. The adjoint
    /// (`output::adjoint`) gives the gradient of a loss at every model size.
    #[error(
        "the forward sensitivities of a model of {dof} coordinates carry a tangent of {columns} columns, {bytes} bytes (at most {max}); the adjoint (output::adjoint) gives the gradient of a loss at any size"
    )]
    TangentTooLarge {
        /// The model's coordinates `N`.
        dof: usize,
        /// The tangent's columns, `2N + P`.
        columns: usize,
        /// The bytes of the tangent.
        bytes: usize,
        /// The cap on them.
        max: usize,
    },
    /// A tolerance is negative, not finite, or zero together with its partner.
    #[error(
        "tolerance of coordinate {index} is invalid (rtol = {rtol}, atol = {atol}): both must be finite and non-negative, not both zero"
    )]
    InvalidTolerance {
        /// The coordinate.
        index: usize,
        /// Its relative tolerance.
        rtol: f64,
        /// Its absolute tolerance.
        atol: f64,
    },
    /// The step bounds of an adaptive run are not `0 ≤ min_step ≤ max_step`, with
    /// `min_step` finite and `max_step` positive.
    #[error(
        "step bounds min_step = {min_step}, max_step = {max_step} must satisfy 0 <= min_step <= max_step, min_step finite and max_step positive"
    )]
    InvalidStepBounds {
        /// The smallest step.
        min_step: f64,
        /// The largest step.
        max_step: f64,
    },
    /// An adaptive run needed a step below the smallest step that `f64` time can resolve,
    /// or below its [`crate::StepOptions::min_step`].
    #[error("step size {h:e} at t = {t} is too small for the tolerance")]
    StepSizeTooSmall {
        /// Where the run stopped.
        t: f64,
        /// The step it needed.
        h: f64,
    },
    /// An adaptive run that cannot show its error to be within a tolerance so close to `f64`
    /// round-off: the bounds on the rounding errors of its steps, added up as a random walk
    /// (`sqrt(Σ_k (2ε|y_k|)²)` in the tolerance's weighted norm), or the differences its
    /// error estimates left out as round-off, added up, would pass three times the
    /// tolerance. The run stops before that step, so that no `Ok` claims an accuracy the
    /// arithmetic may not give (see [`crate::control`]). Fewer steps (more stages) or a
    /// looser tolerance get further. These are bounds, summed as if nothing damped them:
    /// where the flow damps what the steps round (a stiff spring under heavy damping), the
    /// run's actual round-off can stay far below them, and a run that was accurate stops
    /// (measured on a held-out elastic pendulum with a radial spring of 10⁸ and a radial
    /// damper of 10⁶, T = 20: lobatto8 at tol 1e-7 stops after 4245 steps, at t = 13.9,
    /// where at 1e-5 and 1e-6 it ends within 3.6e-15 of fixed-step lobatto6 and lobatto8,
    /// which agree to 1.4e-15).
    #[error(
        "the round-off bounds of {steps} steps would reach {ratio:.2} times the tolerance at t = {t}: this run cannot tell its error from f64 round-off at this tolerance; loosen it or use more stages"
    )]
    ToleranceBelowRoundOff {
        /// Where the run stopped.
        t: f64,
        /// The steps accepted until then.
        steps: usize,
        /// The accumulated round-off with the next step, in units of the tolerance: the
        /// larger of the two sums.
        ratio: f64,
    },
    /// An adaptive run reached its step cap ([`crate::StepOptions::max_steps`]).
    #[error("step cap of {steps} steps reached at t = {t}")]
    MaxStepsReached {
        /// Where the run stopped.
        t: f64,
        /// The cap.
        steps: usize,
    },
    /// An adaptive run whose steps have shrunk, window after window of 65536 steps, 32
    /// windows in a row, to where reaching `t_final` at the largest step of the last window
    /// would take more steps than its cap ([`crate::StepOptions::max_steps`]) leaves: a
    /// finite-time singularity of the model, most likely (see [`crate::control`], "The pace
    /// of a run"). The steps before are kept; a larger cap lets such a run go on.
    #[error(
        "the steps have shrunk to {h:e} at t = {t}: the rest of the run would take about {needed:.1e} steps, more than the {left} the step cap leaves"
    )]
    PaceTooSlow {
        /// Where the run stopped.
        t: f64,
        /// The largest step of the last window.
        h: f64,
        /// The steps the rest of the run would take at that step.
        needed: f64,
        /// The steps the cap leaves.
        left: usize,
    },
    /// Initial data off the constraint manifold of a constrained model (DESIGN §11).
    #[error(
        "the initial {what} violates the constraints: residual {residual:.3e} (at most {tol:.1e}); InitialState::projected makes it consistent"
    )]
    InconsistentInitialState {
        /// `"position"` (`g(0, q_0) ≠ 0`) or `"velocity"` (`G(q_0) v_0 + ∂g/∂t ≠ 0`).
        what: &'static str,
        /// The largest residual.
        residual: f64,
        /// The tolerance it exceeds.
        tol: f64,
    },
    /// A constrained model that this run cannot take (see the message).
    #[error("constraints: {message}")]
    UnsupportedConstraints {
        /// What is not supported.
        message: &'static str,
    },
    /// Output times that decrease, or that lie past the end of the run.
    #[error("output times must be non-decreasing and no later than the final time")]
    UnorderedTimes,
    /// An output time is negative or not finite.
    #[error("output time {t:?} must be finite and non-negative")]
    InvalidOutputTime {
        /// The rejected time.
        t: f64,
    },
    /// The gradient of the loss that [`output::adjoint`](crate::output::adjoint) was given
    /// at the final state has a NaN or infinite component.
    #[error("the loss gradient's component {index} at the final state is not finite")]
    NonFiniteLossGradient {
        /// The component, in `(∂ℓ/∂q_T, ∂ℓ/∂v_T)` order.
        index: usize,
    },
    /// The initial data contain NaN or infinity.
    #[error("initial {what}[{index}] is not finite")]
    NonFiniteInitialData {
        /// `q`, `v` or `p`.
        what: &'static str,
        /// The component.
        index: usize,
    },
    /// The mass matrix `∂²L/∂v²` is singular or nearly so: `L` is degenerate there.
    #[error(
        "mass matrix is singular or nearly so at step {step}, t = {t} (reciprocal condition {rcond:.3e})"
    )]
    SingularMassMatrix {
        /// The step (0 for the initial data).
        step: usize,
        /// The time.
        t: f64,
        /// Estimated reciprocal condition number.
        rcond: f64,
    },
    /// The Lagrangian or the force returned NaN or infinity.
    #[error("model returned a non-finite value at step {step}, t = {t}")]
    NonFiniteModel {
        /// The step being computed.
        step: usize,
        /// Its start time.
        t: f64,
    },
    /// The velocity solve `L_v(q, v) = p` did not converge.
    #[error(
        "velocity solve L_v(q, v) = p failed at step {step}, t = {t} (residual {residual:.3e})"
    )]
    VelocitySolveFailed {
        /// The step (0 for the initial data).
        step: usize,
        /// The time.
        t: f64,
        /// Max-norm of the last residual `L_v(q, v) − p`.
        residual: f64,
    },
    /// A computed quantity exceeded the range of `f64` (the solution grew without bound,
    /// or its energy does not fit in a double), although the model's values were finite.
    #[error("{quantity} overflowed at step {step}, t = {t}")]
    Overflow {
        /// The step.
        step: usize,
        /// The time.
        t: f64,
        /// What overflowed: `q`, `p`, `v`, `energy`, `energy_balance` or `state`; in a
        /// sensitivity run, `tangent` (the derivatives of the flow) or `adjoint` (the
        /// backward pass of a loss's gradient).
        quantity: &'static str,
    },
    /// The Newton solve of a step failed (after any subdivisions). Besides a model that
    /// is singular or not smooth there, the usual cause is a step beyond the scheme's
    /// stability limit for the model's fastest mode (about `h ω ≤ 2` for `lobatto2`,
    /// larger with more stages): the message says so.
    #[error(
        "newton failed at step {step}, t = {t}: {failure} (a smaller step, tolerances or more stages may help: a step beyond the scheme's stability limit for the model's fastest mode does not converge)"
    )]
    NewtonFailed {
        /// The step being computed (1-based: step k goes from t_{k−1} to t_k).
        step: usize,
        /// Its start time.
        t: f64,
        /// Max-norm of the last residual, if one was computed.
        residual: f64,
        /// What went wrong.
        failure: NewtonFailure,
    },
    /// [`crate::LinearPath::Sparse`] was asked for, and the model has no sparse node kernels
    /// (or forced-vi was built without its `sparse` feature).
    #[error("the sparse backend cannot run this model: {reason}")]
    NoSparseKernels {
        /// Why.
        reason: &'static str,
    },
    /// [`crate::LinearPath::Sparse`] was asked for on a model whose node pattern is too
    /// dense for sparse storage to pay (see [`crate::LinearPath::SPARSE_FORCED_MAX_DENSITY`]).
    #[error(
        "the sparse backend refuses a node pattern with {nnz} entries for {n} coordinates: fill {fill:.2} of n², more than {max}"
    )]
    PatternTooDense {
        /// Stored entries of the node pattern.
        nnz: usize,
        /// Coordinates.
        n: usize,
        /// `nnz / n²`.
        fill: f64,
        /// The cap on the fill.
        max: f64,
    },
    /// A scheme could not be built.
    #[error(transparent)]
    Scheme(#[from] SchemeError),
}

impl Error {
    /// A short, stable name for reports (`newton_diverged`, `singular_mass_matrix`, ...).
    pub fn kind(&self) -> String {
        match self {
            Error::InvalidStepSize { .. } => "invalid_step_size".into(),
            Error::InvalidFinalTime { .. } => "invalid_final_time".into(),
            Error::NonFiniteParameter { .. } => "non_finite_parameter".into(),
            Error::NonFiniteInitialData { .. } => "non_finite_initial_data".into(),
            Error::InvalidModel { .. } => "invalid_model".into(),
            Error::InvalidTolerance { .. } => "invalid_tolerance".into(),
            Error::UnorderedTimes => "unordered_times".into(),
            Error::InvalidOutputTime { .. } => "invalid_output_time".into(),
            Error::NonFiniteLossGradient { .. } => "non_finite_loss_gradient".into(),
            Error::InconsistentInitialState { .. } => "inconsistent_initial_state".into(),
            Error::UnsupportedConstraints { .. } => "unsupported_constraints".into(),
            Error::StepSizeTooSmall { .. } => "step_size_too_small".into(),
            Error::ToleranceBelowRoundOff { .. } => "tolerance_below_round_off".into(),
            Error::InvalidStepBounds { .. } => "invalid_step_bounds".into(),
            Error::MaxStepsReached { .. } => "max_steps_reached".into(),
            Error::PaceTooSlow { .. } => "pace_too_slow".into(),
            Error::InvalidNewtonOptions { .. } => "invalid_newton_options".into(),
            Error::TooManySteps { .. } => "too_many_steps".into(),
            Error::TooManyRecords { .. } => "too_many_records".into(),
            Error::ModelTooLarge { .. } => "model_too_large".into(),
            Error::SensitivitiesTooLarge { .. } => "sensitivities_too_large".into(),
            Error::TangentTooLarge { .. } => "tangent_too_large".into(),
            Error::VelocitySolveFailed { .. } => "velocity_solve_failed".into(),
            Error::Overflow { .. } => "overflow".into(),
            Error::SingularMassMatrix { .. } => "singular_mass_matrix".into(),
            Error::NonFiniteModel { .. } => "non_finite_model".into(),
            Error::NewtonFailed { failure, .. } => format!("newton_{}", failure.kind()),
            Error::NoSparseKernels { .. } => "no_sparse_kernels".into(),
            Error::PatternTooDense { .. } => "pattern_too_dense".into(),
            Error::Scheme(_) => "invalid_scheme".into(),
        }
    }
}

impl Error {
    /// The error for sparse node kernels that wrote outside the pattern recorded at their
    /// first evaluation.
    pub(crate) fn outside_pattern() -> Error {
        Error::InvalidModel {
            message: "the sparse node or constraint kernels wrote outside the pattern recorded at the first evaluation (their entries must not depend on the state)".into(),
        }
    }

    /// This error at step `k`, for the errors of a computation that knew no step (made
    /// with step 0).
    pub(crate) fn at_step(self, k: usize) -> Error {
        match self {
            Error::Overflow { t, quantity, .. } => Error::Overflow {
                step: k,
                t,
                quantity,
            },
            Error::NonFiniteModel { t, .. } => Error::NonFiniteModel { step: k, t },
            Error::SingularMassMatrix { t, rcond, .. } => {
                Error::SingularMassMatrix { step: k, t, rcond }
            }
            other => other,
        }
    }
}
