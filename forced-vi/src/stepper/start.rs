//! The start of a dense run: the checks of the run and of the initial data, `p_0` or `v_0`
//! from the other (DESIGN §3), and the stepper's first state.

use nalgebra::{DMatrix, DVector, SMatrix, SVector};

use super::checks::{check_finite, check_run, check_time_flag, non_finite, step_count};
use super::state::Kahan;
use super::Stepper;
use crate::control::Controller;
use crate::error::Error;
use crate::initial::{mass_check, solve_velocity, InitialState};
use crate::integrator::Integrator;
use crate::model::{ForcedLagrangian, NodeJacobian};
use crate::newton::Newton;
use crate::step_equations::{all_finite, StepProblem};
use crate::trajectory::{energy, RunStats};

/// `(q_0, v_0, p_0)`.
type Start<const N: usize> = (SVector<f64, N>, SVector<f64, N>, SVector<f64, N>);

impl<'a, M: ForcedLagrangian<N>, const N: usize> Stepper<'a, M, N> {
    /// Checks the run and its initial data and makes the stepper at the initial state.
    pub(super) fn start(
        integ: &'a Integrator<'a, M, N>,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<Self, Error> {
        check_run(&integ.options, t_final)?;
        let n_steps = match integ.tolerance {
            // Adaptive: the count is not known; the cap is checked as the run goes.
            Some(_) => step_count(t_final, integ.h, usize::MAX)?,
            None => step_count(t_final, integ.h, integ.options.max_steps)?,
        };
        let model = integ.model;
        let (q0, v0, p0) = initial_state(model, init)?;
        let mass_sign = mass_check(model, &q0, &v0, 0, 0.0)?;
        check_time_flag(model, &q0, &v0)?;
        let energy0 = energy(model, 0.0, &q0, &v0, &p0)
            .ok_or_else(|| non_finite(q0.amax().max(v0.amax()).max(p0.amax()), 0, 0.0, "energy"))?;
        Ok(Self::at_start(
            integ,
            (t_final, n_steps),
            (q0, v0, p0),
            energy0,
            mass_sign,
        ))
    }

    /// The stepper at the (checked) initial state, with its buffers: a run of `n_steps`
    /// to `t_final` whose initial energy is `energy0`.
    fn at_start(
        integ: &'a Integrator<'a, M, N>,
        (t_final, n_steps): (f64, usize),
        (q0, v0, p0): Start<N>,
        energy0: f64,
        mass_sign: f64,
    ) -> Self {
        let (model, scheme, h) = (integ.model, &integ.scheme, integ.h);
        let (s, r) = (scheme.stages(), scheme.quadrature_nodes());
        let g0 = model.node_gradient_at(0.0, &q0, &v0);
        let zero_jac = NodeJacobian {
            grad: g0,
            a: SMatrix::zeros(),
            b: SMatrix::zeros(),
            c: SMatrix::zeros(),
            e: SMatrix::zeros(),
        };
        Stepper {
            prob: StepProblem {
                model,
                scheme,
                h,
                t0: 0.0,
                q0,
                p0,
                xs: vec![q0; r],
                vs: vec![v0; r],
                grads: vec![g0; r],
                jacs: vec![zero_jac; r],
                base: DMatrix::zeros((s - 1) * N, (s - 1) * N),
                base_h: f64::NAN,
            },
            newton: Newton::new((s - 1) * N, integ.options.newton),
            options: integ.options,
            h,
            t_final,
            n_steps,
            k: 0,
            q: Kahan::new(q0),
            p: Kahan::new(p0),
            v: v0,
            energy0,
            work: (0.0, 0.0),
            z: DVector::zeros((s - 1) * N),
            z_prev: vec![SVector::zeros(); s],
            z_saved: vec![SVector::zeros(); s],
            has_prev: false,
            h_prev: h,
            scale_f: g0.fq.amax(),
            mass_sign,
            t: 0.0,
            t_state: 0.0,
            tolerance: integ.tolerance,
            controller: Controller::new(scheme.order()),
            h_next: h,
            lean: false,
            stats: RunStats::default(),
            started: false,
            done: false,
        }
    }
}

/// The checked initial `(q_0, v_0, p_0)`: `p_0 = L_v(q_0, v_0)` from an initial velocity,
/// `v_0` by the velocity solve from an initial momentum.
fn initial_state<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    init: InitialState<N>,
) -> Result<Start<N>, Error> {
    match init {
        InitialState::Velocity { q, v } => {
            check_finite("q", &q)?;
            check_finite("v", &v)?;
            let (q, v) = (SVector::from(q), SVector::from(v));
            let g = model.node_gradient_at(0.0, &q, &v);
            if !(all_finite(&g.lv) && all_finite(&g.fq)) {
                return Err(Error::NonFiniteModel { step: 0, t: 0.0 });
            }
            Ok((q, v, g.lv))
        }
        InitialState::Momentum { q, p } => {
            check_finite("q", &q)?;
            check_finite("p", &p)?;
            let (q, p) = (SVector::from(q), SVector::from(p));
            let v = solve_velocity(model, &q, &p, SVector::zeros(), 0, 0.0)?;
            Ok((q, v, p))
        }
    }
}
