//! The start of a run: the checks of the run and of the initial data, `p_0` or `v_0` from
//! the other (DESIGN §3), and the stepper's first state.

use super::checks::{
    check_constraint_time_flag, check_finite, check_force_flag, check_run, check_structure_flags,
    check_time_flag, non_finite, step_count,
};
use super::state::State;
use super::{RunSetup, Stepper, step_stack_bytes, with_stack};
use crate::backend::{Backend, StepBackend};
use crate::buffers::zeros;
use crate::control::{BAND, Controller, LINEAR_BAND};
use crate::error::Error;
use crate::initial::InitialState;
use crate::model::ForcedLagrangian;
use crate::trajectory::{RunStats, energy};

impl<'a, M: ForcedLagrangian<N>, const N: usize> Stepper<'a, M, N> {
    /// Checks the run and its initial data and makes the stepper at the initial state, on
    /// `backend`.
    pub(crate) fn new(
        setup: RunSetup<'a, M, N>,
        backend: Backend<'a, M, N>,
        reference: Option<Backend<'a, M, N>>,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<Self, Error> {
        let constrained = setup.model.constraint_count() > 0;
        let stack = step_stack_bytes::<M, N>(backend.deep_stack(), constrained);
        let auto = setup.auto_first_step;
        with_stack(stack, || {
            let mut stepper = Self::start(setup, backend, reference, init, t_final, stack)?;
            if auto && stepper.tolerance.is_some() {
                stepper.choose_first_step()?;
            }
            Ok(stepper)
        })
    }

    /// Starts a new run from `init` to `t_final` on this stepper's buffers, as
    /// [`Stepper::new`] would with the same set-up: the same checks, the same records.
    /// Returns `Ok(false)`, and changes nothing, where the backend cannot be kept (the sparse
    /// one: [`Backend::can_restart`]); the caller then makes a new stepper. After an error
    /// the stepper must not be stepped (its state is part reset).
    pub(crate) fn restart(&mut self, init: InitialState<N>, t_final: f64) -> Result<bool, Error> {
        let keeps =
            self.backend.can_restart() && self.reference.as_ref().is_none_or(|r| r.can_restart());
        if !keeps {
            return Ok(false);
        }
        self.backend.restart();
        if let Some(r) = self.reference.as_mut() {
            r.restart();
        }
        with_stack(self.stack, || {
            self.begin(init, t_final)?;
            if self.auto_first_step && self.tolerance.is_some() {
                self.choose_first_step()?;
            }
            Ok(true)
        })
    }

    fn start(
        setup: RunSetup<'a, M, N>,
        mut backend: Backend<'a, M, N>,
        reference: Option<Backend<'a, M, N>>,
        init: InitialState<N>,
        t_final: f64,
        stack: usize,
    ) -> Result<Self, Error> {
        let RunSetup {
            model,
            scheme,
            h,
            options,
            tolerance,
            ..
        } = setup;
        // A model with sparse kernels, large enough for the sparse backend: the same rule on
        // either backend, so that a run takes the same steps on both.
        let large = model.sparse_node().is_some() && N >= crate::LinearPath::SPARSE_MIN_DOF;
        let mut reference = reference;
        if let Some(r) = reference.as_mut() {
            r.set_costly_factors(large);
        }
        // A linear model (`STRUCTURE.linear`) has the same step Jacobian at every step of one
        // size: its adaptive steps keep their size in the band too, and carry their factors.
        let band = if large {
            Some(BAND)
        } else if M::STRUCTURE.linear {
            Some(LINEAR_BAND)
        } else {
            None
        };
        // Fixed steps of one size reuse the step Jacobian's factors while they pay (see
        // `crate::newton`); adaptive steps, whose error estimate reads the step's node
        // blocks, make fresh ones, except a linear model's, whose blocks do not change.
        backend.factors_across_steps(tolerance.is_none() || M::STRUCTURE.linear);
        // The step polynomial (and its node blocks, or a constrained step's multipliers)
        // at the error reference's points: tables of the scheme, made once.
        let (mut lift, mut block_weights, mut lift_lambda): (&[f64], &[f64], &[f64]) =
            (&[], &[], &[]);
        let mut pair_lift: (&[f64], &[bool]) = (&[], &[]);
        if reference.is_some() {
            // Pairs (see `crate::control`): their reference's tables, also for the steps
            // taken alone (the integrator has resolved the default).
            let paired = setup.options.paired_estimates == Some(true);
            let e = match paired {
                true => scheme.pair_estimate_tables(),
                false => scheme.estimate_tables(),
            };
            lift = &e.lift;
            if model.constraint_count() == 0 {
                block_weights = &e.block_weights;
                if paired && scheme.stages() <= 3 {
                    pair_lift = (&e.pair_lift, &e.pair_second);
                }
            } else {
                lift_lambda = &e.lift_lambda;
            }
        }
        let unknowns = backend.z().len();
        let mut stepper = Stepper {
            model,
            scheme,
            backend,
            reference,
            lift,
            block_weights,
            round_off_sq: 0.0,
            unresolved: 0.0,
            unresolved_step: 0.0,
            resolution: 0.0,
            lift_lambda,
            pair_lift,
            pair: None,
            pending: None,
            options,
            h,
            h_setup: h,
            auto_first_step: setup.auto_first_step,
            t_final,
            n_steps: 0,
            k: 0,
            state: State::new(N, unknowns),
            // Filled (and allocated) when first needed: by every adaptive step, and by a
            // fixed step only if it is subdivided.
            saved: State::empty(),
            energy0: 0.0,
            mass_sign: 1.0,
            q_end: zeros(N),
            v_end: zeros(N),
            dp: zeros(N),
            basis: zeros(scheme.stages()),
            extrapolated: zeros(unknowns),
            extrapolated_near: false,
            err: (zeros(2 * N), zeros(2 * N)),
            t: 0.0,
            tolerance,
            controller: Controller::new(scheme.order()),
            h_next: h.min(options.max_step),
            pace: Default::default(),
            estimate: 0.0,
            err_last: 0.0,
            band,
            lean: false,
            tangent: None,
            tape: None,
            cforce: zeros(N),
            stack,
            stats: RunStats::default(),
            stop: None,
            started: false,
            done: false,
        };
        stepper.begin(init, t_final)?;
        Ok(stepper)
    }

    /// The start of a run from `init` to `t_final` on buffers that [`Stepper::start`] made
    /// (and a past run may have used): the checks of the run and of the initial data, the
    /// initial state, and every field a run changes back to its start. Every field is
    /// named, so that a field added later must be decided on here.
    fn begin(&mut self, init: InitialState<N>, t_final: f64) -> Result<(), Error> {
        check_run(&self.options, t_final)?;
        self.options.check_step_bounds()?;
        let h = self.h_setup;
        let n_steps = match self.tolerance {
            // Adaptive: the count is not known; the cap is checked as the run goes.
            Some(_) => step_count(t_final, h, usize::MAX)?,
            None => step_count(t_final, h, self.options.max_steps)?,
        };
        let Stepper {
            model: _,
            scheme,
            backend: _,
            reference: _,
            lift: _,
            block_weights: _,
            round_off_sq,
            unresolved,
            unresolved_step,
            resolution,
            lift_lambda: _,
            pair_lift: _,
            // Scratch, filled before it is read.
            pair: _,
            pending,
            options,
            h: step,
            h_setup: _,
            auto_first_step: _,
            t_final: end,
            n_steps: count,
            k,
            state,
            // Read only after a copy into it (`State::copy_from`).
            saved: _,
            energy0: _,
            mass_sign: _,
            q_end,
            v_end,
            dp,
            basis,
            extrapolated,
            extrapolated_near,
            err,
            t,
            tolerance: _,
            controller,
            h_next,
            pace,
            estimate,
            err_last,
            band: _,
            lean,
            tangent,
            tape,
            cforce,
            stack: _,
            stats,
            stop,
            started,
            done,
        } = self;
        *pending = None;
        *round_off_sq = 0.0;
        *unresolved = 0.0;
        *unresolved_step = 0.0;
        *resolution = 0.0;
        *step = h;
        *end = t_final;
        *count = n_steps;
        *k = 0;
        state.reset();
        for x in [
            q_end,
            v_end,
            dp,
            basis,
            extrapolated,
            &mut err.0,
            &mut err.1,
            cforce,
        ] {
            x.fill(0.0);
        }
        *extrapolated_near = false;
        *t = 0.0;
        *controller = Controller::new(scheme.order());
        *h_next = h.min(options.max_step);
        *pace = Default::default();
        *estimate = 0.0;
        *err_last = 0.0;
        *lean = false;
        *tangent = None;
        *tape = None;
        *stats = RunStats::default();
        *stop = None;
        *started = false;
        *done = false;
        // The initial state, and the checks of the initial data.
        let model = self.model;
        let state = &mut self.state;
        self.mass_sign = initial_state(&mut self.backend, state, init.parts())?;
        if model.constraint_count() > 0 {
            let at = (0.0, &state.q.sum[..], &state.v[..]);
            let residuals = self.backend.constraint_residuals(at)?;
            crate::initial::check_constraints(&state.q.sum, residuals)?;
        }
        check_time_flag(model, &state.q.sum, &state.v)?;
        check_constraint_time_flag(model, &state.q.sum)?;
        check_force_flag(model, &state.q.sum, &state.v)?;
        check_structure_flags(model, &state.q.sum, &state.v)?;
        let (q0, v0, p0) = (&state.q.sum, &state.v, &state.p.sum);
        self.energy0 = energy(model, 0.0, q0, v0, p0)
            .ok_or_else(|| non_finite(state.size(), 0, 0.0, "energy"))?;
        state.h_prev = h;
        Ok(())
    }
}

/// Checks the initial data and fills `(q, v, p)` of `state` from it: `p_0 = L_v(q_0, v_0)`
/// from an initial velocity, `v_0` by the velocity solve from an initial momentum; and the
/// force scale `|L_q + F|` at the start; `(q, w, from_velocity)` is the initial data, `w`
/// the velocity or the momentum. Returns the sign of the mass matrix's determinant. Not
/// generic: one copy serves every model.
fn initial_state(
    backend: &mut dyn StepBackend,
    state: &mut State,
    (q, w, from_velocity): (&[f64], &[f64], bool),
) -> Result<f64, Error> {
    let n = q.len();
    let (q0, p0, v0) = (&mut state.q.sum, &mut state.p.sum, &mut state.v);
    let mut fq = vec![0.0; n];
    let sign = if from_velocity {
        check_finite("q", q)?;
        check_finite("v", w)?;
        q0.copy_from_slice(q);
        v0.copy_from_slice(w);
        backend.gradient((0.0, q0, v0), &mut fq, p0)?;
        backend.mass_sign((0.0, q0, v0))?
    } else {
        check_finite("q", q)?;
        check_finite("p", w)?;
        q0.copy_from_slice(q);
        p0.copy_from_slice(w);
        backend.velocity((0.0, q0, p0), v0, 0)?;
        let sign = backend.mass_sign((0.0, q0, v0))?;
        let mut lv = vec![0.0; n];
        backend.gradient((0.0, q0, v0), &mut fq, &mut lv)?;
        sign
    };
    state.scale_f = fq.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    for (f, x) in state.force.iter_mut().zip(&fq) {
        *f = x.abs();
    }
    Ok(sign)
}
