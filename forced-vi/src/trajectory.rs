//! What a run hands back: records with their diagnostics (DESIGN §4), run totals,
//! trajectories and failures that keep what was computed.

use nalgebra::{DMatrix, DVector, SVector};

use crate::error::Error;
use crate::model::ForcedLagrangian;
use crate::scalar::all_finite;

/// The state after one step, with its diagnostics (DESIGN §4).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct StepRecord<const N: usize> {
    /// Step index; 0 is the initial state.
    pub step: usize,
    /// Time `t_k`.
    pub t: f64,
    /// Positions `q_k`.
    pub q: SVector<f64, N>,
    /// Momenta `p_k`.
    pub p: SVector<f64, N>,
    /// Velocities, solving `L_v(q_k, v_k) = p_k`.
    pub v: SVector<f64, N>,
    /// Energy `v · L_v − L`.
    pub energy: f64,
    /// Energy-balance error `E(t_k) − E(0) − W_k + ∫₀^{t_k} ∂L/∂t`, with the work `W_k` of the
    /// force and the integral of `∂L/∂t` (zero for an autonomous model) summed with the
    /// scheme's own quadrature (DESIGN §4, §7). `W` includes the work `∫ λᵀ ∂g/∂t` of the
    /// forces of constraints that read the time (zero for fixed ones).
    pub energy_balance: f64,
    /// Newton iterations (linear solves) this step took, over all attempts.
    pub newton_iterations: usize,
    /// Max-norm of the final Newton residual.
    pub residual: f64,
    /// Substeps used: 1 normally, 2, 4, … when the step was subdivided to recover.
    pub substeps: usize,
    /// Adaptive runs: the estimated local error of this step, as the weighted RMS norm of
    /// [`crate::control`] in units of the tolerance (per step, not per unit step); 0 for the
    /// initial state and for fixed steps.
    pub error_estimate: f64,
    /// A constrained model (DESIGN §11): the constraint force `Gᵀλ` averaged over the
    /// step that ended here (its impulse over the step size); zero without constraints.
    pub constraint_force: SVector<f64, N>,
    /// A constrained model: `max(|g(t, q)|, |G(q) v + ∂g/∂t|)` at this record (max-norms;
    /// `∂g/∂t = 0` for constraints that do not read the time); zero without constraints and
    /// in a lean run.
    pub constraint_residual: f64,
}

/// Totals over a run.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct RunStats {
    /// Steps completed.
    pub steps: usize,
    /// Newton iterations over all steps.
    pub newton_iterations: usize,
    /// Steps that needed subdivision.
    pub subdivided_steps: usize,
    /// Largest Newton iteration count of one step.
    pub max_newton_iterations: usize,
    /// Adaptive runs: step attempts rejected by the error test or by a failed solve.
    pub rejected_steps: usize,
}

impl RunStats {
    /// Counts an accepted step that took `newton_iterations` iterations.
    pub(crate) fn count_step(&mut self, newton_iterations: usize) {
        self.steps += 1;
        self.newton_iterations += newton_iterations;
        self.max_newton_iterations = self.max_newton_iterations.max(newton_iterations);
    }
}

/// A finished run: every record, initial state first.
#[derive(Clone, Debug, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Trajectory<const N: usize> {
    /// The records, `records[0]` being the initial state.
    pub records: Vec<StepRecord<N>>,
    /// Totals.
    pub stats: RunStats,
}

impl<const N: usize> Trajectory<N> {
    /// The last record, if any.
    pub fn last(&self) -> Option<&StepRecord<N>> {
        self.records.last()
    }

    /// Dense output at `t` (see [`DenseState`]); `None` outside the run's time span.
    pub fn at(&self, t: f64) -> Option<DenseState<N>> {
        let recs = &self.records;
        let (first, last) = (recs.first()?, recs.last()?);
        if !(t >= first.t && t <= last.t) {
            return None;
        }
        // The first record at or after t.
        let k = recs.partition_point(|r| r.t < t);
        match k {
            0 => Some(DenseState::from_record(first)),
            _ => recs.get(k).map(|b| hermite(&recs[k - 1], b, t)),
        }
    }

    /// Dense output at each of `times`, in order; `None` if one lies outside the run.
    pub fn sample(&self, times: &[f64]) -> Option<Vec<DenseState<N>>> {
        times.iter().map(|&t| self.at(t)).collect()
    }
}

/// The end of a run without per-step diagnostics ([`crate::Integrator::final_state`]).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct FinalState<const N: usize> {
    /// The final time.
    pub t: f64,
    /// Positions.
    pub q: SVector<f64, N>,
    /// Momenta.
    pub p: SVector<f64, N>,
    /// Velocities, solving `L_v(q, v) = p`.
    pub v: SVector<f64, N>,
    /// Energy `v · L_v − L`.
    pub energy: f64,
    /// Totals.
    pub stats: RunStats,
}

/// The end of a sensitivity run ([`crate::output::Tangents`]): the final state and
/// the derivatives of the discrete flow (DESIGN §12).
///
/// The derivatives are those of the scheme's map itself, carried through every accepted
/// step with the factored step Jacobian (the implicit function theorem), not finite
/// differences. In an adaptive run the step sequence is held fixed: the derivative is that
/// of the same sequence of steps from perturbed data, not of the controller's choices.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Sensitivities<const N: usize> {
    /// The final time.
    pub t: f64,
    /// Final positions.
    pub q: SVector<f64, N>,
    /// Final velocities.
    pub v: SVector<f64, N>,
    /// Final momenta.
    pub p: SVector<f64, N>,
    /// `∂(q_T, v_T)/∂(q_0, v_0)`, `2N × 2N`: rows `q_T` then `v_T`, columns `q_0` then `v_0`.
    /// The initial data is taken as velocities (through `p_0 = L_v(q_0, v_0)`) and the
    /// final velocities through the velocity solve `L_v(q_T, v_T) = p_T`, whichever form
    /// the run was started from.
    pub wrt_initial: DMatrix<f64>,
    /// `∂(q_T, v_T)/∂θ`, `2N × P`, for the model's parameters `θ`.
    pub wrt_parameters: DMatrix<f64>,
    /// Totals.
    pub stats: RunStats,
}

/// The gradient of a loss of the final state by the discrete adjoint
/// ([`crate::output::adjoint`]).
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct AdjointGradient<const N: usize> {
    /// The final time.
    pub t: f64,
    /// Final positions.
    pub q: SVector<f64, N>,
    /// Final velocities.
    pub v: SVector<f64, N>,
    /// Final momenta.
    pub p: SVector<f64, N>,
    /// `∂ℓ/∂(q_0, v_0)`, `2N` entries: positions, then velocities.
    pub wrt_initial: DVector<f64>,
    /// `∂ℓ/∂θ`, one entry per parameter
    /// ([`ForcedLagrangian::parameter_names`]).
    pub wrt_parameters: DVector<f64>,
    /// The memory the forward run kept for the backward pass, in bytes (each step's start,
    /// size and solution).
    pub tape_bytes: usize,
    /// Totals of the forward run.
    pub stats: RunStats,
}

/// A state between the steps of a run, from its dense output.
///
/// The dense output is the cubic Hermite interpolant of the positions and velocities at
/// the two ends of the step: `q` is accurate to `O(h^min(4, p))` and `v` to
/// `O(h^min(3, p))` for a scheme of order `p` (measured in the `dense_` tests). The
/// Galerkin path itself is only `O(h^s)` between its control points.
///
/// So with a scheme of order 4 or more and long steps, the interpolant is less accurate
/// than the steps' ends. An adaptive run with [`output::Samples`](crate::output::Samples)
/// keeps its outputs to the tolerance by ending a step on every output time, up to one step
/// more per output time (see [`crate::control`], "Output times"). A fixed-step run
/// interpolates at the step the caller chose.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct DenseState<const N: usize> {
    /// The time.
    pub t: f64,
    /// Positions.
    pub q: SVector<f64, N>,
    /// Velocities.
    pub v: SVector<f64, N>,
}

impl<const N: usize> DenseState<N> {
    fn from_record(r: &StepRecord<N>) -> Self {
        DenseState {
            t: r.t,
            q: r.q,
            v: r.v,
        }
    }
}

/// The cubic Hermite interpolant between two records at `t ∈ [a.t, b.t]`.
pub(crate) fn hermite<const N: usize>(
    a: &StepRecord<N>,
    b: &StepRecord<N>,
    t: f64,
) -> DenseState<N> {
    let h = b.t - a.t;
    if h <= 0.0 || t >= b.t {
        return DenseState::from_record(b);
    }
    let s = (t - a.t) / h;
    let (s2, s3) = (s * s, s * s * s);
    let (h00, h10, h01, h11) = (
        2.0 * s3 - 3.0 * s2 + 1.0,
        s3 - 2.0 * s2 + s,
        3.0 * s2 - 2.0 * s3,
        s3 - s2,
    );
    let (d01, d10, d11) = (
        6.0 * s - 6.0 * s2,
        3.0 * s2 - 4.0 * s + 1.0,
        3.0 * s2 - 2.0 * s,
    );
    // The velocity's divided difference `(q_b − q_a) / h` carries the round-off of the
    // positions over `h`: over a short interval (a last step of 1e-9, an output a few ulps
    // past a step) that is more than the change of the velocity across it, and then the
    // trapezoid's `(v_a + v_b) / 2`, off by `O(h²)`, stands in for it (measured: h = 1e-9
    // at |q| = 1 gave velocities 1e-6 off; an interval of 1e-14 at |q| = 10, 4.5e-4).
    let slope = |i: usize| {
        let (x, y, va, vb) = (a.q[i], b.q[i], a.v[i], b.v[i]);
        let round_off = 4.0 * f64::EPSILON * (x.abs() + y.abs()) / h;
        if round_off > (vb - va).abs() {
            0.5 * (va + vb)
        } else {
            (y - x) / h
        }
    };
    DenseState {
        t,
        q: a.q * h00 + a.v * (h10 * h) + b.q * h01 + b.v * (h11 * h),
        v: SVector::from_fn(|i, _| slope(i) * d01 + a.v[i] * d10 + b.v[i] * d11),
    }
}

/// A run that stopped early, from any run method: the error and everything computed
/// before it.
///
/// [`output::Records`](crate::output::Records) keeps its records in
/// [`RunFailure::trajectory`]; [`output::Samples`](crate::Integrator::sample) its samples
/// in [`RunFailure::samples`]; every method the totals (`trajectory.stats`) and the last
/// record it computed ([`RunFailure::last`]). It converts into the [`Error`], so `?` works
/// in a function that returns `Result<_, forced_vi::Error>`.
///
/// ```
/// use forced_vi::prelude::*;
/// # struct Oscillator;
/// # impl ForcedLagrangian<1> for Oscillator {
/// #     fn lagrangian<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> D {
/// #         (v[0] * v[0] - q[0] * q[0]) * 0.5
/// #     }
/// # }
/// fn end(t: f64) -> Result<f64, forced_vi::Error> {
///     let integ = Integrator::new(&Oscillator, Scheme::lobatto(3)?, 0.01)?.max_steps(500);
///     let end = integ.final_state(InitialState::from_velocity([1.0], [0.0]), t)?;
///     Ok(end.q[0])
/// }
/// assert!((end(1.0)? - 1f64.cos()).abs() < 1e-9);
/// assert!(matches!(end(10.0), Err(forced_vi::Error::TooManySteps { .. })));
/// # Ok::<(), forced_vi::Error>(())
/// ```
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[error("{error} (after {} steps)", stats.steps)]
pub struct RunFailure<const N: usize> {
    /// What stopped the run.
    #[source]
    pub error: Error,
    /// The records up to the failure (kept by [`output::Records`](crate::output::Records);
    /// empty for the other methods), with the totals.
    pub trajectory: Trajectory<N>,
    /// The totals up to the failure (the same as `trajectory.stats`).
    pub stats: RunStats,
    /// The last record computed before the failure, if any (boxed: a record holds three
    /// `N`-vectors).
    pub last: Option<Box<StepRecord<N>>>,
    /// The samples before the failure ([`output::Samples`](crate::Integrator::sample)).
    pub samples: Vec<DenseState<N>>,
}

impl<const N: usize> RunFailure<N> {
    /// A run that failed before its first record.
    pub(crate) fn new(error: Error) -> Self {
        Self::after(error, RunStats::default(), None)
    }

    /// A run that failed after `stats`, its last record being `last`.
    pub(crate) fn after(error: Error, stats: RunStats, last: Option<Box<StepRecord<N>>>) -> Self {
        RunFailure {
            error,
            trajectory: Trajectory {
                records: Vec::new(),
                stats,
            },
            stats,
            last,
            samples: Vec::new(),
        }
    }
}

/// A run that failed before its first step.
impl<const N: usize> From<Error> for RunFailure<N> {
    fn from(error: Error) -> Self {
        RunFailure::new(error)
    }
}

impl<const N: usize> From<RunFailure<N>> for Error {
    fn from(f: RunFailure<N>) -> Error {
        f.error
    }
}

/// `E = v · p − L(q, v)` with `p = L_v`; `None` if not finite.
pub(crate) fn energy<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    t: f64,
    q: &[f64],
    v: &[f64],
    p: &[f64],
) -> Option<f64> {
    let (qa, va) = (
        <&[f64; N]>::try_from(q).ok()?,
        <&[f64; N]>::try_from(v).ok()?,
    );
    let vp: f64 = v.iter().zip(p).map(|(a, b)| a * b).sum();
    let e = vp - model.lagrangian_at::<f64>(t, qa, va);
    e.is_finite().then_some(e)
}

/// The first field of a record that is not finite, by name.
pub(crate) fn non_finite_field<const N: usize>(r: &StepRecord<N>) -> Option<&'static str> {
    [
        ("q", all_finite(&r.q)),
        ("p", all_finite(&r.p)),
        ("v", all_finite(&r.v)),
        ("energy", r.energy.is_finite()),
        ("energy_balance", r.energy_balance.is_finite()),
        ("residual", r.residual.is_finite()),
    ]
    .into_iter()
    .find(|(_, ok)| !ok)
    .map(|(name, _)| name)
}
