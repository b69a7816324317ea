//! Checks of a run's final time and options, of initial data, of a model's time flag; the
//! step count; the errors for a non-finite value and a failed solve.

use super::StepOptions;
use crate::error::{Error, NewtonFailure};
use crate::model::ForcedLagrangian;
use crate::trajectory::{StepRecord, non_finite_field};

/// Refuses a final time that is negative, not finite or positive below
/// [`StepOptions::SMALLEST_STEP`], and invalid Newton options.
pub(crate) fn check_run(options: &StepOptions, t_final: f64) -> Result<(), Error> {
    if !(t_final.is_finite() && (t_final == 0.0 || t_final >= StepOptions::SMALLEST_STEP)) {
        return Err(Error::InvalidFinalTime { t_final });
    }
    options
        .newton
        .validate()
        .map_err(|(field, value)| Error::InvalidNewtonOptions { field, value })
}

/// Refuses initial data `what` (`"q"`, `"v"` or `"p"`) with a component that is not finite.
pub(crate) fn check_finite(what: &'static str, x: &[f64]) -> Result<(), Error> {
    match x.iter().position(|c| !c.is_finite()) {
        Some(index) => Err(Error::NonFiniteInitialData { what, index }),
        None => Ok(()),
    }
}

/// Refuses a model that depends on time but says it does not (`STRUCTURE.uses_time`
/// false while `lagrangian_at` or `force_at` change with `t`): its kernels would be
/// evaluated without time.
pub(super) fn check_time_flag<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    q: &[f64],
    v: &[f64],
) -> Result<(), Error> {
    if M::STRUCTURE.uses_time {
        return Ok(());
    }
    let (Ok(qa), Ok(va)) = (<&[f64; N]>::try_from(q), <&[f64; N]>::try_from(v)) else {
        return Ok(());
    };
    let l = model.lagrangian::<f64>(qa, va);
    let f = model.force::<f64>(qa, va);
    for t in [0.7390851332151607, -2.5, 1e3] {
        let same_l = model.lagrangian_at::<f64>(t, qa, va).to_bits() == l.to_bits();
        let ft = model.force_at::<f64>(t, qa, va);
        let same_f = ft.iter().zip(&f).all(|(a, b)| a.to_bits() == b.to_bits());
        if !(same_l && same_f) {
            return Err(Error::InvalidModel {
                message: "lagrangian_at or force_at depends on t, but STRUCTURE.uses_time is false"
                    .into(),
            });
        }
    }
    Ok(())
}

/// Refuses a constrained model that promises fixed constraints
/// (`CONSTRAINTS_READ_TIME` false) while `constraints` changes with `t`: the rate `∂g/∂t`
/// would be left out of its velocity-level constraint and its ledger. Checked, like the time
/// flag, at the initial positions and at times beside 0: a dependence that vanishes there
/// is not caught.
pub(super) fn check_constraint_time_flag<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    q: &[f64],
) -> Result<(), Error> {
    let m = model.constraint_count();
    if !M::CONSTRAINED || M::CONSTRAINTS_READ_TIME || m == 0 {
        return Ok(());
    }
    let Ok(qa) = <&[f64; N]>::try_from(q) else {
        return Ok(());
    };
    let (mut g0, mut gt) = (vec![0.0; m], vec![0.0; m]);
    model.constraints(0.0, qa, &mut g0);
    for t in [0.7390851332151607, -2.5, 1e3] {
        model.constraints(t, qa, &mut gt);
        if gt.iter().zip(&g0).any(|(a, b)| a.to_bits() != b.to_bits()) {
            return Err(Error::InvalidModel {
                message: "constraints depend on t, but CONSTRAINTS_READ_TIME is false".into(),
            });
        }
    }
    Ok(())
}

/// Refuses a model that has a force but says it has none (`STRUCTURE.has_force` false
/// while `force` or `force_at` is not zero): the integrator would leave the force out and
/// return the conservative motion (measured on a hand-written damped model: an `Ok` at
/// q = -1.20 where the damped motion is at -0.83). Checked, like the time flag, at the
/// initial state and at states and times beside it: a force that vanishes there and
/// nowhere else is not caught.
pub(super) fn check_force_flag<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    q: &[f64],
    v: &[f64],
) -> Result<(), Error> {
    if M::STRUCTURE.has_force {
        return Ok(());
    }
    let (Ok(qa), Ok(va)) = (<&[f64; N]>::try_from(q), <&[f64; N]>::try_from(v)) else {
        return Ok(());
    };
    let beside: [f64; N] = std::array::from_fn(|i| 0.75 * qa[i] + 0.5);
    let moving: [f64; N] = std::array::from_fn(|i| va[i] + 1.0);
    for (qs, vs) in [(qa, va), (&beside, &moving)] {
        let mut forces = vec![model.force::<f64>(qs, vs)];
        if M::STRUCTURE.uses_time {
            forces.extend([0.7390851332151607, -2.5].map(|t| model.force_at::<f64>(t, qs, vs)));
        }
        // Finite values only: a model defined on a domain may not be beside its state.
        if forces.iter().flatten().any(|f| f.is_finite() && *f != 0.0) {
            return Err(Error::InvalidModel {
                message: "force is not zero, but STRUCTURE.has_force is false".into(),
            });
        }
    }
    Ok(())
}

/// Refuses a model whose other flags promise what its code does not hold, where the promise
/// changes more than the Newton iteration's Jacobian: `force_uses_velocity: false` (the
/// sensitivities leave `∂F/∂v` out) under a force that changes with `v`, and
/// `constant_mass: true` (the velocities are taken in one linear step, the sensitivities
/// leave `C` out) under a mass `∂²L/∂v²` that changes or a `C = ∂²L/∂v∂q` that is not
/// zero. Checked like the time flag, at the initial state and beside it, along one
/// direction (hyper-dual numbers: `uᵀEu` and `uᵀCu` with `u` all ones), so a claim that
/// fails only elsewhere or only across that direction is not caught.
pub(super) fn check_structure_flags<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    q: &[f64],
    v: &[f64],
) -> Result<(), Error> {
    use num_dual::HyperDual64;
    let s = M::STRUCTURE;
    let (Ok(qa), Ok(va)) = (<&[f64; N]>::try_from(q), <&[f64; N]>::try_from(v)) else {
        return Ok(());
    };
    let beside: [f64; N] = std::array::from_fn(|i| 0.75 * qa[i] + 0.5);
    let moving: [f64; N] = std::array::from_fn(|i| va[i] + 1.0);
    let invalid = |message: &str| Error::InvalidModel {
        message: message.into(),
    };
    if s.has_force && !s.force_uses_velocity {
        for qs in [qa, &beside] {
            let (f0, f1) = (
                model.force_at::<f64>(0.0, qs, va),
                model.force_at::<f64>(0.0, qs, &moving),
            );
            // Finite values only: a model defined on a domain may not be beside its state.
            let differ = |(a, b): (&f64, &f64)| a.is_finite() && b.is_finite() && a != b;
            if f0.iter().zip(&f1).any(differ) {
                return Err(invalid(
                    "force changes with the velocities, but STRUCTURE.force_uses_velocity is false",
                ));
            }
        }
    }
    if s.constant_mass {
        // (uᵀEu, uᵀCu) at (q, v): L along (q + ε₁u·[mixed], v + ε₂u + ε₁u·[mass]).
        let second = |qs: &[f64; N], vs: &[f64; N], mixed: bool| -> f64 {
            let dq = if mixed { 1.0 } else { 0.0 };
            let qd: [HyperDual64; N] =
                std::array::from_fn(|i| HyperDual64::new(qs[i], dq, 0.0, 0.0));
            let vd: [HyperDual64; N] =
                std::array::from_fn(|i| HyperDual64::new(vs[i], 1.0 - dq, 1.0, 0.0));
            model
                .lagrangian_at(HyperDual64::from(0.0), &qd, &vd)
                .eps1eps2
        };
        let (e0, e1) = (second(qa, va, false), second(&beside, &moving, false));
        let (c0, c1) = (second(qa, va, true), second(&beside, &moving, true));
        let scale = e0.abs().max(e1.abs());
        // Finite values only, as above.
        let off = |x: f64| scale.is_finite() && x.is_finite() && x.abs() > 1e-12 * scale;
        if off(e1 - e0) || off(c0) || off(c1) {
            return Err(invalid(
                "the mass matrix changes (or L mixes q and v), but STRUCTURE.constant_mass is true",
            ));
        }
    }
    if s.linear && !linear_at_both(model, (qa, va), (&beside, &moving)) {
        return Err(invalid(
            "the second derivatives of L or the first of F change with the state or the time, but STRUCTURE.linear is true",
        ));
    }
    Ok(())
}

/// The `linear` flag's check: along the directions `w = (u, u), (u, 0), (0, u)` in
/// `(q, v)` (`u` all ones), the second derivative `wᵀ ∂²L w` and the force's derivative
/// `∂F · w` are the same at `(t, q, v) = (0, a)` and `(0.74, b)` (hyper-dual and dual
/// numbers: no `N × N` block is formed, whatever the model's size). Finite values only, as
/// for the other flags.
fn linear_at_both<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    a: (&[f64; N], &[f64; N]),
    b: (&[f64; N], &[f64; N]),
) -> bool {
    use num_dual::{Dual64, HyperDual64};
    let second = |t: f64, (qs, vs): (&[f64; N], &[f64; N]), (wq, wv): (f64, f64)| -> f64 {
        let qd: [HyperDual64; N] = std::array::from_fn(|i| HyperDual64::new(qs[i], wq, wq, 0.0));
        let vd: [HyperDual64; N] = std::array::from_fn(|i| HyperDual64::new(vs[i], wv, wv, 0.0));
        model.lagrangian_at(HyperDual64::from(t), &qd, &vd).eps1eps2
    };
    let first = |t: f64, (qs, vs): (&[f64; N], &[f64; N]), (wq, wv): (f64, f64)| {
        let qd: [Dual64; N] = std::array::from_fn(|i| Dual64::new(qs[i], wq));
        let vd: [Dual64; N] = std::array::from_fn(|i| Dual64::new(vs[i], wv));
        model.force_at(Dual64::from(t), &qd, &vd).map(|f| f.eps)
    };
    let same = |x: f64, y: f64| {
        let scale = x.abs().max(y.abs());
        !(x.is_finite() && y.is_finite()) || (x - y).abs() <= 1e-12 * scale
    };
    [(1.0, 1.0), (1.0, 0.0), (0.0, 1.0)].into_iter().all(|w| {
        let (fa, fb) = (first(0.0, a, w), first(0.7390851332151607, b, w));
        same(second(0.0, a, w), second(0.7390851332151607, b, w))
            && fa.iter().zip(&fb).all(|(&x, &y)| same(x, y))
    })
}

/// The model's parameter values `θ`, one per name of
/// [`ForcedLagrangian::parameter_names`]: a hand-written model whose two lists differ in
/// length is refused (its derivatives would have as many columns as values, named by
/// fewer or more names).
pub(super) fn parameter_values<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
) -> Result<Vec<f64>, Error> {
    let (names, theta) = (model.parameter_names(), model.parameter_values());
    if names.len() != theta.len() {
        return Err(Error::InvalidModel {
            message: format!(
                "parameter_names has {} entries but parameter_values {}: one value per name",
                names.len(),
                theta.len()
            ),
        });
    }
    Ok(theta)
}

/// The number of steps of size `h` (the last one shortened) that reach `t_final`.
///
/// A ratio within 1e-10 of an integer is that integer, so that `t_final = n·h` does not
/// end with a sliver of a step; any positive `t_final` takes at least one step.
pub(crate) fn step_count(t_final: f64, h: f64, max: usize) -> Result<usize, Error> {
    let ratio = t_final / h;
    let steps = if (ratio - ratio.round()).abs() <= 1e-10 * ratio.max(1.0) {
        ratio.round()
    } else {
        ratio.ceil()
    };
    let steps = if t_final > 0.0 { steps.max(1.0) } else { 0.0 };
    if steps > max as f64 {
        return Err(Error::TooManySteps { steps, max });
    }
    // Exact: steps ≤ max ≤ usize::MAX, and the float is an integer.
    Ok(steps as usize)
}

/// The error for a non-finite value computed from a state of max-norm `size`.
///
/// Past `√f64::MAX`, products of two state components overflow: the model is not at
/// fault, the solution has left the range of `f64` ([`Error::Overflow`]). Below, the model
/// returned a non-finite value at a representable point ([`Error::NonFiniteModel`]).
pub(crate) fn non_finite(size: f64, step: usize, t: f64, quantity: &'static str) -> Error {
    if size >= f64::MAX.sqrt() {
        Error::Overflow { step, t, quantity }
    } else {
        Error::NonFiniteModel { step, t }
    }
}

/// The error for a record of step `step` at `t` with a field that is not finite, if it has
/// one; `size` gives the max-norm of its state. A NaN energy at a representable state is the
/// model's (a Lagrangian that is NaN there); an infinity from a huge state is an overflow.
pub(crate) fn record_error<const N: usize>(
    rec: &StepRecord<N>,
    size: impl FnOnce() -> f64,
    step: usize,
    t: f64,
) -> Option<Error> {
    let quantity = non_finite_field(rec)?;
    let size = size();
    let nan = rec.energy.is_nan() || rec.energy_balance.is_nan();
    Some(if nan && size.is_finite() && size < f64::MAX.sqrt() {
        Error::NonFiniteModel { step, t }
    } else {
        Error::Overflow { step, t, quantity }
    })
}

/// The error for a Newton solve that failed on step `step` from `t0`, from a state of
/// max-norm `size`.
pub(crate) fn newton_error(failure: NewtonFailure, size: f64, step: usize, t0: f64) -> Error {
    let residual = match failure {
        NewtonFailure::MaxIterations { residual }
        | NewtonFailure::Diverged { residual }
        | NewtonFailure::Stagnated { residual } => residual,
        _ => f64::NAN,
    };
    if failure == NewtonFailure::NonFinite {
        return non_finite(size, step, t0, "state");
    }
    Error::NewtonFailed {
        step,
        t: t0,
        residual,
        failure,
    }
}
