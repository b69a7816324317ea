//! One step of the dense stepper: the Newton solve of the step equations, the compensated
//! update of `(q, p)` and of the ledger, the mass check at the step's end, and the
//! subdivision of a step that fails.

use nalgebra::SVector;

use super::checks::{newton_error, record_error};
use super::state::kahan_add;
use super::Stepper;
use crate::error::{Error, NewtonFailure};
use crate::initial::{mass_factor, solve_velocity, MIN_MASS_RCOND};
use crate::integrator::Integrator;
use crate::model::ForcedLagrangian;
use crate::newton::NewtonReport;
use crate::trajectory::StepRecord;

/// Why one attempt at a step failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum StepFailure {
    Newton(NewtonFailure),
    /// The step ended at a singular mass matrix or across one.
    SingularMass {
        rcond: f64,
    },
}

/// The sums over the quadrature nodes of a solved step.
struct NodeSums<const N: usize> {
    /// The momentum update `h Σ_i b_i (L_q + F)_i`.
    dp: SVector<f64, N>,
    /// The ledger's increment `h Σ_i b_i (F·v − ∂L/∂t)_i`.
    dw: f64,
    /// The largest `|L_q + F|` at a node.
    fmax: f64,
}

impl<M: ForcedLagrangian<N>, const N: usize> Stepper<'_, M, N> {
    /// One step of size `h` from the current state.
    pub(super) fn advance(&mut self, h: f64) -> Result<(usize, f64), StepFailure> {
        let rep = self.solve_step(h)?;
        // The last residual evaluation was at the accepted iterate, so the node gradients in
        // `prob` belong to the solution.
        let sums = self.node_sums(h);
        let s = self.prob.scheme.stages();
        let dq: SVector<f64, N> = self.z.fixed_rows::<N>((s - 2) * N).into_owned();
        let vguess = self.end_velocity(h);
        if !M::STRUCTURE.constant_mass {
            self.check_mass_at_end(h, &dq, &vguess)?;
        }
        self.commit(h, &dq, &sums, vguess);
        Ok((rep.iterations, rep.residual))
    }

    /// Predicts and solves the step equations of a step of size `h` for `z`.
    #[inline]
    fn solve_step(&mut self, h: f64) -> Result<NewtonReport, StepFailure> {
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
        self.newton
            .solve(&mut self.prob, &mut self.z, scale)
            .map_err(StepFailure::Newton)
    }

    /// The node sums of the solved step. `Σ_j G_j = h Σ_i b_i (L_q + F)_i` gives the
    /// momentum update as a small increment, which keeps round-off low (DESIGN §3); the
    /// ledger's increment is left out (zero) in a lean run.
    #[inline]
    fn node_sums(&self, h: f64) -> NodeSums<N> {
        let sch = self.prob.scheme;
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
        NodeSums { dp, dw, fmax }
    }

    /// The velocity guess: the step polynomial's slope at the end of the step.
    #[inline]
    fn end_velocity(&self, h: f64) -> SVector<f64, N> {
        let sch = self.prob.scheme;
        let mut vguess = SVector::<f64, N>::zeros();
        for m in 1..sch.stages() {
            let zm = self.z.fixed_rows::<N>((m - 1) * N);
            vguess.axpy(sch.end_slope(m) / h, &zm, 1.0);
        }
        vguess
    }

    /// A step may not end where the mass matrix is singular or has changed the sign of its
    /// determinant: the path crossed a singular mass, where the Euler–Lagrange equations
    /// stop being an ODE.
    fn check_mass_at_end(
        &self,
        h: f64,
        dq: &SVector<f64, N>,
        vguess: &SVector<f64, N>,
    ) -> Result<(), StepFailure> {
        let q_end = self.q.sum + dq;
        let e = self
            .prob
            .model
            .mass_matrix_at(self.t_state + h, &q_end, vguess);
        match mass_factor(&e) {
            Some((rcond, sign)) if rcond >= MIN_MASS_RCOND && sign == self.mass_sign => Ok(()),
            other => {
                // A change of sign means a singular mass was crossed: condition 0.
                let rcond = match other {
                    Some((rc, sign)) if sign == self.mass_sign => rc,
                    _ => 0.0,
                };
                Err(StepFailure::SingularMass { rcond })
            }
        }
    }

    /// Takes the solved step: the compensated updates, the predictor's polynomial, the time.
    #[inline]
    fn commit(&mut self, h: f64, dq: &SVector<f64, N>, sums: &NodeSums<N>, v: SVector<f64, N>) {
        let s = self.prob.scheme.stages();
        self.q.add(dq);
        self.p.add(&sums.dp);
        let (w, c) = &mut self.work;
        kahan_add(w, c, sums.dw);
        self.z_prev[0] = SVector::zeros();
        for m in 1..s {
            self.z_prev[m] = self.z.fixed_rows::<N>((m - 1) * N).into_owned();
        }
        self.has_prev = true;
        self.h_prev = h;
        self.t_state += h;
        self.scale_f = sums.fmax;
        self.v = v;
    }

    /// One attempt at a step of size `h`: its residual, with the linear solves it took
    /// added to `iters`, converged or not.
    pub(super) fn attempt(&mut self, h: f64, iters: &mut usize) -> Result<f64, StepFailure> {
        match self.advance(h) {
            Ok((it, res)) => {
                *iters += it;
                Ok(res)
            }
            Err(f) => {
                *iters += self.newton.last_iterations();
                Err(f)
            }
        }
    }

    /// Advances over `[t_k, t_{k+1}]`, subdividing on failure if allowed.
    pub(super) fn step(&mut self) -> Result<StepRecord<N>, Error> {
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
                outcome = self.attempt(hs, &mut iters);
                if outcome.is_err() {
                    break;
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
    pub(super) fn finish_step(
        &mut self,
        iters: usize,
        residual: f64,
        substeps: usize,
    ) -> Result<StepRecord<N>, Error> {
        self.k += 1;
        let t = self.t;
        // Substeps add up to the step only to round-off: the step's end is exact.
        self.t_state = t;
        self.stats.count_step(iters);
        if self.lean {
            // The state only; the velocity, energy and balance are left out (and checked
            // once at the end, `finish`).
            return Ok(self.raw_record(iters, residual, substeps));
        }
        self.v = solve_velocity(self.prob.model, &self.q.sum, &self.p.sum, self.v, self.k, t)?;
        let rec = self.record(iters, residual, substeps);
        let size = || rec.q.amax().max(rec.p.amax()).max(rec.v.amax());
        if let Some(error) = record_error(&rec, size, self.k, t) {
            return Err(error);
        }
        Ok(rec)
    }

    /// The error for a step from `t0` that could not be taken.
    pub(super) fn failure_error(&self, failure: StepFailure, t0: f64) -> Error {
        let step = self.k + 1;
        let failure = match failure {
            StepFailure::SingularMass { rcond } => {
                return Error::SingularMassMatrix { step, t: t0, rcond }
            }
            StepFailure::Newton(f) => f,
        };
        let size = self.q.sum.amax().max(self.p.sum.amax()).max(self.v.amax());
        newton_error(failure, size, step, t0)
    }
}
