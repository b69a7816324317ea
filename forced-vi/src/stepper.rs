//! The stepping loop: predictor, Newton solve of the step equations, compensated update,
//! subdivision on failure, and the checks that make every `Ok` step trustworthy.

use nalgebra::{DMatrix, DVector, SMatrix, SVector};

use crate::control::{Controller, Tolerance};
use crate::error::{Error, NewtonFailure};
use crate::initial::{mass_check, mass_factor, solve_velocity, InitialState, MIN_MASS_RCOND};
use crate::integrator::{Integrator, StepOptions};
use crate::model::{ForcedLagrangian, NodeJacobian};
use crate::newton::Newton;
use crate::step_equations::{all_finite, StepProblem};
use crate::trajectory::{energy, non_finite_field, RunStats, StepRecord};

/// Runs `f` on a stack with room for the model's node kernels: the caller's own stack when
/// it has `M::KERNEL_STACK_BYTES` to spare, else a fresh one on the heap (`stacker`).
#[inline]
pub(crate) fn with_kernel_stack<M: ForcedLagrangian<N>, const N: usize, R>(
    f: impl FnOnce() -> R,
) -> R {
    // The stepper's own frames: a few records, snapshots and matrices of the model's size.
    let own = 64 * std::mem::size_of::<StepRecord<N>>() + 256 * 1024;
    let need = M::KERNEL_STACK_BYTES.saturating_add(own);
    if need <= 256 * 1024 {
        f()
    } else {
        stacker::maybe_grow(need, need.saturating_mul(2), f)
    }
}

/// Compensated (Kahan) accumulation of a vector.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Kahan<const N: usize> {
    sum: SVector<f64, N>,
    comp: SVector<f64, N>,
}

impl<const N: usize> Kahan<N> {
    fn new(x: SVector<f64, N>) -> Self {
        Kahan {
            sum: x,
            comp: SVector::zeros(),
        }
    }
    fn add(&mut self, dx: &SVector<f64, N>) {
        for i in 0..N {
            let y = dx[i] - self.comp[i];
            let t = self.sum[i] + y;
            self.comp[i] = (t - self.sum[i]) - y;
            self.sum[i] = t;
        }
    }
}

/// Saved state for retrying a step as substeps.
#[derive(Clone, Copy, Debug)]
struct Snapshot<const N: usize> {
    q: Kahan<N>,
    p: Kahan<N>,
    work: (f64, f64),
    v: SVector<f64, N>,
    has_prev: bool,
    h_prev: f64,
    scale_f: f64,
    t_state: f64,
}

/// Steps a model through time; an iterator over [`StepRecord`]s, initial state first.
///
/// After an error the iterator yields that error once and then ends.
pub struct Stepper<'a, M, const N: usize> {
    prob: StepProblem<'a, M, N>,
    newton: Newton,
    options: StepOptions,
    h: f64,
    t_final: f64,
    n_steps: usize,
    k: usize,
    q: Kahan<N>,
    p: Kahan<N>,
    v: SVector<f64, N>,
    energy0: f64,
    work: (f64, f64),
    z: DVector<f64>,
    z_prev: Vec<SVector<f64, N>>,
    z_saved: Vec<SVector<f64, N>>,
    has_prev: bool,
    h_prev: f64,
    scale_f: f64,
    /// Sign of the mass matrix's determinant at the start: a step that changes it has
    /// crossed a singular mass.
    mass_sign: f64,
    /// The time of the record last handed out.
    t: f64,
    /// The time of the current state `(q, p)` (ahead of `t` between substeps).
    t_state: f64,
    /// Adaptive runs: the tolerances, the controller and the next step to try.
    tolerance: Option<Tolerance<N>>,
    controller: Controller,
    h_next: f64,
    /// Final state only: no velocity solve, energy, work or record per step.
    lean: bool,
    stats: RunStats,
    started: bool,
    done: bool,
}

impl<'a, M: ForcedLagrangian<N>, const N: usize> Stepper<'a, M, N> {
    pub(crate) fn new(
        integ: &'a Integrator<'a, M, N>,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<Self, Error> {
        with_kernel_stack::<M, N, _>(|| Self::start(integ, init, t_final))
    }

    fn start(
        integ: &'a Integrator<'a, M, N>,
        init: InitialState<N>,
        t_final: f64,
    ) -> Result<Self, Error> {
        if !(t_final.is_finite() && t_final >= 0.0) {
            return Err(Error::InvalidFinalTime { t_final });
        }
        integ
            .options
            .newton
            .validate()
            .map_err(|(field, value)| Error::InvalidNewtonOptions { field, value })?;
        let h = integ.h;
        let n_steps = match integ.tolerance {
            // Adaptive: the count is not known; the cap is checked as the run goes.
            Some(_) => step_count(t_final, h, usize::MAX)?,
            None => step_count(t_final, h, integ.options.max_steps)?,
        };
        let check = |what: &'static str, x: &[f64; N]| match x.iter().position(|c| !c.is_finite()) {
            Some(index) => Err(Error::NonFiniteInitialData { what, index }),
            None => Ok(()),
        };
        let model = integ.model;
        let (q0, v0, p0) = match init {
            InitialState::Velocity { q, v } => {
                check("q", &q)?;
                check("v", &v)?;
                let (q, v) = (SVector::from(q), SVector::from(v));
                let g = model.node_gradient_at(0.0, &q, &v);
                if !(all_finite(&g.lv) && all_finite(&g.fq)) {
                    return Err(Error::NonFiniteModel { step: 0, t: 0.0 });
                }
                (q, v, g.lv)
            }
            InitialState::Momentum { q, p } => {
                check("q", &q)?;
                check("p", &p)?;
                let (q, p) = (SVector::from(q), SVector::from(p));
                let v = solve_velocity(model, &q, &p, SVector::zeros(), 0, 0.0)?;
                (q, v, p)
            }
        };
        let mass_sign = mass_check(model, &q0, &v0, 0, 0.0)?;
        let scheme = &integ.scheme;
        let s = scheme.stages();
        let r = scheme.quadrature_nodes();
        check_time_flag(model, &q0, &v0)?;
        let energy0 = energy(model, 0.0, &q0, &v0, &p0)
            .ok_or_else(|| non_finite(q0.amax().max(v0.amax()).max(p0.amax()), 0, 0.0, "energy"))?;
        let g0 = model.node_gradient_at(0.0, &q0, &v0);
        let zero_jac = NodeJacobian {
            grad: g0,
            a: SMatrix::zeros(),
            b: SMatrix::zeros(),
            c: SMatrix::zeros(),
            e: SMatrix::zeros(),
        };
        Ok(Stepper {
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
        })
    }

    /// Number of steps the run will take (for an adaptive run, the number it would take
    /// with its first step size).
    pub fn total_steps(&self) -> usize {
        self.n_steps
    }

    /// Totals so far.
    pub fn stats(&self) -> RunStats {
        self.stats
    }

    fn time_of(&self, k: usize) -> f64 {
        if k >= self.n_steps {
            self.t_final
        } else {
            k as f64 * self.h
        }
    }

    fn record(&self, newton_iterations: usize, residual: f64, substeps: usize) -> StepRecord<N> {
        let (q, p, v) = (self.q.sum, self.p.sum, self.v);
        let e = energy(self.prob.model, self.t, &q, &v, &p).unwrap_or(f64::NAN);
        StepRecord {
            step: self.k,
            t: self.t,
            q,
            p,
            v,
            energy: e,
            energy_balance: e - self.energy0 - self.work.0,
            newton_iterations,
            residual,
            substeps,
        }
    }

    /// A record of the state alone (lean runs): `v` is the step polynomial's end slope,
    /// the energy fields are zero.
    fn raw_record(
        &self,
        newton_iterations: usize,
        residual: f64,
        substeps: usize,
    ) -> StepRecord<N> {
        StepRecord {
            step: self.k,
            t: self.t,
            q: self.q.sum,
            p: self.p.sum,
            v: self.v,
            energy: 0.0,
            energy_balance: 0.0,
            newton_iterations,
            residual,
            substeps,
        }
    }

    /// Leaves out the per-step diagnostics (velocity solve, energy, work, balance): the
    /// iterator's records then hold the state alone until [`Stepper::finish`].
    pub(crate) fn set_lean(&mut self, lean: bool) {
        self.lean = lean;
    }

    /// The full record of the current state: the velocity solve and the energy. In a lean
    /// run the work was not summed, so the balance is not known: it is reported as zero.
    pub(crate) fn finish(&mut self) -> Result<StepRecord<N>, Error> {
        let t = self.t;
        if self.lean && self.k > 0 {
            self.v = solve_velocity(self.prob.model, &self.q.sum, &self.p.sum, self.v, self.k, t)?;
        }
        let mut rec = self.record(0, 0.0, 1);
        if self.lean {
            rec.energy_balance = 0.0;
        }
        match non_finite_field(&rec) {
            Some(quantity) => Err(Error::Overflow {
                step: self.k,
                t,
                quantity,
            }),
            None => Ok(rec),
        }
    }

    fn snapshot(&mut self) -> Snapshot<N> {
        self.z_saved.copy_from_slice(&self.z_prev);
        Snapshot {
            q: self.q,
            p: self.p,
            work: self.work,
            v: self.v,
            has_prev: self.has_prev,
            h_prev: self.h_prev,
            scale_f: self.scale_f,
            t_state: self.t_state,
        }
    }

    fn restore(&mut self, s: &Snapshot<N>) {
        self.z_prev.copy_from_slice(&self.z_saved);
        self.q = s.q;
        self.p = s.p;
        self.work = s.work;
        self.v = s.v;
        self.has_prev = s.has_prev;
        self.h_prev = s.h_prev;
        self.scale_f = s.scale_f;
        self.t_state = s.t_state;
    }

    /// Fills `z` with the predictor: the previous step's polynomial extrapolated, or a
    /// straight line along `v` on the first step.
    fn predict(&mut self, h: f64) {
        let sch = self.prob.scheme;
        let s = sch.stages();
        let d = sch.d();
        for (j, &dj) in d.iter().enumerate().skip(1) {
            let zj = if self.has_prev && sch.extrapolates() {
                let same = h == self.h_prev;
                let tau = 1.0 + dj * h / self.h_prev;
                let mut x = -self.z_prev[s - 1];
                for m in 1..s {
                    let l = if same {
                        sch.extrapolation(j, m)
                    } else {
                        sch.basis_at(tau, m)
                    };
                    x += self.z_prev[m] * l;
                }
                x
            } else {
                self.v * (dj * h)
            };
            self.z.fixed_rows_mut::<N>((j - 1) * N).copy_from(&zj);
        }
    }

    /// One step of size `h` from the current state.
    fn advance(&mut self, h: f64) -> Result<(usize, f64), StepFailure> {
        self.predict(h);
        self.prob.h = h;
        self.prob.t0 = self.t_state;
        self.prob.q0 = self.q.sum;
        self.prob.p0 = self.p.sum;
        self.newton.invalidate();
        let scale = self
            .p
            .sum
            .amax()
            .max(h * self.scale_f)
            .max(f64::MIN_POSITIVE);
        let rep = self
            .newton
            .solve(&mut self.prob, &mut self.z, scale)
            .map_err(StepFailure::Newton)?;
        // The last residual evaluation was at the accepted iterate, so the node gradients in
        // `prob` belong to the solution. Σ_j G_j = h Σ_i b_i (L_q + F)_i gives the momentum
        // update as a small increment, which keeps round-off low (DESIGN §3).
        let sch = self.prob.scheme;
        let s = sch.stages();
        let mut dp = SVector::<f64, N>::zeros();
        let mut dw = 0.0;
        let mut fmax: f64 = 0.0;
        for i in 0..sch.quadrature_nodes() {
            let bi = sch.b()[i];
            dp.axpy(h * bi, &self.prob.grads[i].fq, 1.0);
            fmax = fmax.max(self.prob.grads[i].fq.amax());
            let (uses_time, lean) = (M::STRUCTURE.uses_time, self.lean);
            if (M::STRUCTURE.has_force || uses_time) && !lean {
                // The ledger's increment: the work h Σ b_i F·v, less h Σ b_i ∂L/∂t.
                let (x, v) = (self.prob.xs[i], self.prob.vs[i]);
                let ti = self.t_state + sch.c()[i] * h;
                let model = self.prob.model;
                if M::STRUCTURE.has_force {
                    let f = SVector::from(model.force_at::<f64>(ti, &x.into(), &v.into()));
                    dw += h * bi * f.dot(&v);
                }
                dw -= h * bi * model.lagrangian_dt(ti, &x, &v);
            }
        }
        let dq: SVector<f64, N> = self.z.fixed_rows::<N>((s - 2) * N).into_owned();
        // Velocity guess: the polynomial's slope at the end of the step.
        let mut vguess = SVector::<f64, N>::zeros();
        for m in 1..s {
            let zm = self.z.fixed_rows::<N>((m - 1) * N);
            vguess.axpy(sch.end_slope(m) / h, &zm, 1.0);
        }
        if !M::STRUCTURE.constant_mass {
            // A step may not end where the mass matrix is singular or has changed the sign
            // of its determinant: the path crossed a singular mass, where the
            // Euler–Lagrange equations stop being an ODE.
            let q_end = self.q.sum + dq;
            let e = self
                .prob
                .model
                .mass_matrix_at(self.t_state + h, &q_end, &vguess);
            match mass_factor(&e) {
                Some((rcond, sign)) if rcond >= MIN_MASS_RCOND && sign == self.mass_sign => {}
                other => {
                    // A change of sign means a singular mass was crossed: condition 0.
                    let rcond = match other {
                        Some((rc, sign)) if sign == self.mass_sign => rc,
                        _ => 0.0,
                    };
                    return Err(StepFailure::SingularMass { rcond });
                }
            }
        }
        self.q.add(&dq);
        self.p.add(&dp);
        let (w, c) = self.work;
        let y = dw - c;
        let t = w + y;
        self.work = (t, (t - w) - y);
        self.z_prev[0] = SVector::zeros();
        for m in 1..s {
            self.z_prev[m] = self.z.fixed_rows::<N>((m - 1) * N).into_owned();
        }
        self.has_prev = true;
        self.h_prev = h;
        self.t_state += h;
        self.scale_f = fmax;
        self.v = vguess;
        Ok((rep.iterations, rep.residual))
    }

    /// Advances over `[t_k, t_{k+1}]`, subdividing on failure if allowed.
    fn step(&mut self) -> Result<StepRecord<N>, Error> {
        let t0 = self.time_of(self.k);
        let h = self.time_of(self.k + 1) - t0;
        let snap = self.snapshot();
        let mut iters = 0;
        let mut last_failure = None;
        for level in 0..=self
            .options
            .max_subdivisions
            .min(Integrator::<M, N>::MAX_SUBDIVISION_LEVELS)
        {
            let parts = 1usize << level;
            let hs = h / parts as f64;
            let mut outcome = Ok(0.0);
            for _ in 0..parts {
                match self.advance(hs) {
                    Ok((it, res)) => {
                        iters += it;
                        outcome = Ok(res);
                    }
                    Err(f) => {
                        iters += self.newton.last_iterations();
                        outcome = Err(f);
                        break;
                    }
                }
            }
            match outcome {
                Ok(res) => {
                    if parts > 1 {
                        self.stats.subdivided_steps += 1;
                        // The predictor's polynomial covered a substep; start afresh.
                        self.has_prev = false;
                    }
                    self.t = self.time_of(self.k + 1);
                    return self.finish_step(iters, res, parts);
                }
                Err(f) => {
                    last_failure = Some(f);
                    self.restore(&snap);
                    // Retry without the (possibly bad) extrapolation.
                    self.has_prev = false;
                }
            }
        }
        self.restore(&snap);
        Err(self.failure_error(
            last_failure.unwrap_or(StepFailure::Newton(NewtonFailure::NonFinite)),
            t0,
        ))
    }

    /// Completes an accepted step that ends at `self.t`: the velocity solve, the totals and
    /// the record, every field of which must be finite.
    fn finish_step(
        &mut self,
        iters: usize,
        residual: f64,
        substeps: usize,
    ) -> Result<StepRecord<N>, Error> {
        self.k += 1;
        let t = self.t;
        // Substeps add up to the step only to round-off: the step's end is exact.
        self.t_state = t;
        self.stats.steps += 1;
        self.stats.newton_iterations += iters;
        self.stats.max_newton_iterations = self.stats.max_newton_iterations.max(iters);
        if self.lean {
            // The state only; the velocity, energy and balance are left out (and checked
            // once at the end, `finish`).
            return Ok(self.raw_record(iters, residual, substeps));
        }
        self.v = solve_velocity(self.prob.model, &self.q.sum, &self.p.sum, self.v, self.k, t)?;
        let rec = self.record(iters, residual, substeps);
        if let Some(quantity) = non_finite_field(&rec) {
            // A NaN is the model's (a Lagrangian that is NaN at a representable state); an
            // infinity from a huge state is an overflow.
            let size = rec.q.amax().max(rec.p.amax()).max(rec.v.amax());
            let nan = [rec.energy, rec.energy_balance].iter().any(|x| x.is_nan());
            return Err(if nan && size.is_finite() && size < f64::MAX.sqrt() {
                Error::NonFiniteModel { step: self.k, t }
            } else {
                Error::Overflow {
                    step: self.k,
                    t,
                    quantity,
                }
            });
        }
        Ok(rec)
    }

    /// The error for a step from `t0` that could not be taken.
    fn failure_error(&self, failure: StepFailure, t0: f64) -> Error {
        let step = self.k + 1;
        let failure = match failure {
            StepFailure::SingularMass { rcond } => {
                return Error::SingularMassMatrix { step, t: t0, rcond }
            }
            StepFailure::Newton(f) => f,
        };
        let residual = match failure {
            NewtonFailure::MaxIterations { residual }
            | NewtonFailure::Diverged { residual }
            | NewtonFailure::Stagnated { residual } => residual,
            _ => f64::NAN,
        };
        if failure == NewtonFailure::NonFinite {
            let size = self.q.sum.amax().max(self.p.sum.amax()).max(self.v.amax());
            return non_finite(size, step, t0, "state");
        }
        Error::NewtonFailed {
            step,
            t: t0,
            residual,
            failure,
        }
    }
}

impl<M: ForcedLagrangian<N>, const N: usize> Stepper<'_, M, N> {
    /// One adaptive step from `t`: step doubling, accepted when the error norm is at most
    /// one, retried with a smaller step otherwise (see [`crate::control`]).
    fn step_adaptive(&mut self, tol: &Tolerance<N>) -> Result<StepRecord<N>, Error> {
        let t0 = self.t;
        let snap = self.snapshot();
        let span = self.t_final;
        let h_min = 16.0 * f64::EPSILON * t0.abs().max(self.t_final.abs());
        let mut iters = 0;
        let mut last_failure = None;
        loop {
            let remaining = self.t_final - t0;
            let mut h = self.h_next.min(remaining);
            // No sliver of a step at the end.
            let last = h >= remaining * (1.0 - 1e-10);
            if last {
                h = remaining;
            }
            if h < h_min || !h.is_finite() {
                return Err(match last_failure {
                    Some(f) => self.failure_error(f, t0),
                    None => Error::StepSizeTooSmall { t: t0, h },
                });
            }
            if self.stats.steps >= self.options.max_steps {
                return Err(Error::MaxStepsReached {
                    t: t0,
                    steps: self.options.max_steps,
                });
            }
            match self.doubled(h, &snap, &mut iters) {
                Ok((res, (q1, p1))) => {
                    let err = tol.error_norm(
                        self.prob.scheme.order(),
                        span / h,
                        (&q1, &p1),
                        (&self.q.sum, &self.p.sum),
                    );
                    if err <= 1.0 {
                        self.h_next = self.controller.accept(h, err);
                        self.t = if last { self.t_final } else { t0 + h };
                        return self.finish_step(iters, res, 2);
                    }
                    self.h_next = self.controller.reject(h, err);
                }
                Err(f) => {
                    last_failure = Some(f);
                    self.h_next = self.controller.reject(h, f64::INFINITY);
                }
            }
            self.stats.rejected_steps += 1;
            self.restore(&snap);
        }
    }

    /// A step of `h` and two of `h/2` from the same state; leaves the state after the
    /// halves and returns their last residual and the whole step's `(q, p)`.
    #[allow(clippy::type_complexity)]
    fn doubled(
        &mut self,
        h: f64,
        snap: &Snapshot<N>,
        iters: &mut usize,
    ) -> Result<(f64, (SVector<f64, N>, SVector<f64, N>)), StepFailure> {
        let mut run = |this: &mut Self, h: f64| match this.advance(h) {
            Ok((it, res)) => {
                *iters += it;
                Ok(res)
            }
            Err(f) => {
                *iters += this.newton.last_iterations();
                Err(f)
            }
        };
        run(self, h)?;
        let whole = (self.q.sum, self.p.sum);
        self.restore(snap);
        run(self, 0.5 * h)?;
        let res = run(self, 0.5 * h)?;
        Ok((res, whole))
    }
}

impl<M: ForcedLagrangian<N>, const N: usize> Iterator for Stepper<'_, M, N> {
    type Item = Result<StepRecord<N>, Error>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        if !self.started {
            self.started = true;
            return Some(Ok(self.record(0, 0.0, 1)));
        }
        if self.k >= self.n_steps && self.tolerance.is_none() {
            self.done = true;
            return None;
        }
        let out = match self.tolerance {
            Some(tol) if self.t < self.t_final => {
                with_kernel_stack::<M, N, _>(|| self.step_adaptive(&tol))
            }
            Some(_) => {
                self.done = true;
                return None;
            }
            None => with_kernel_stack::<M, N, _>(|| self.step()),
        };
        if out.is_err() {
            self.done = true;
        }
        Some(out)
    }
}

/// Refuses a model that depends on time but says it does not (`STRUCTURE.uses_time`
/// false while `lagrangian_at` or `force_at` change with `t`): its kernels would be
/// evaluated without time.
fn check_time_flag<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    q: &SVector<f64, N>,
    v: &SVector<f64, N>,
) -> Result<(), Error> {
    if M::STRUCTURE.uses_time {
        return Ok(());
    }
    let (qa, va): ([f64; N], [f64; N]) = ((*q).into(), (*v).into());
    let l = model.lagrangian::<f64>(&qa, &va);
    let f = model.force::<f64>(&qa, &va);
    for t in [0.7390851332151607, -2.5, 1e3] {
        let same_l = model.lagrangian_at::<f64>(t, &qa, &va).to_bits() == l.to_bits();
        let ft = model.force_at::<f64>(t, &qa, &va);
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

/// Why one attempt at a step failed.
#[derive(Clone, Copy, Debug, PartialEq)]
enum StepFailure {
    Newton(NewtonFailure),
    /// The step ended at a singular mass matrix or across one.
    SingularMass {
        rcond: f64,
    },
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
fn non_finite(size: f64, step: usize, t: f64, quantity: &'static str) -> Error {
    if size >= f64::MAX.sqrt() {
        Error::Overflow { step, t, quantity }
    } else {
        Error::NonFiniteModel { step, t }
    }
}
