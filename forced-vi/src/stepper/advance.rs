//! One step: the Newton solve of the step equations, the compensated update of `(q, p)`
//! and of the ledger, the mass check at the step's end, and the subdivision of a step that
//! fails.

use super::checks::{newton_error, record_error};
use super::{Stepped, Stepper};
use crate::backend::{StepBackend, StepFailure};
use crate::error::{Error, NewtonFailure};
use crate::model::ForcedLagrangian;
use crate::scalar::lift;
use crate::trajectory::StepRecord;

impl<M: ForcedLagrangian<N>, const N: usize> Stepper<'_, M, N> {
    /// One step of size `h` from the current state.
    pub(super) fn advance(&mut self, h: f64) -> Result<(usize, f64), StepFailure> {
        self.predict(h);
        let st = &self.state;
        let pmax = st.p.sum.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let scale = pmax.max(h * st.scale_f).max(f64::MIN_POSITIVE);
        let rep = self
            .backend
            .solve(h, st.t_state, (&st.q.sum, &st.p.sum), (scale, &st.force))?;
        // The last residual evaluation was at the accepted iterate, so the node values of
        // the backend belong to the solution.
        let sch = self.scheme;
        let s1 = sch.stages() - 1;
        let lay = self.backend.layout();
        let z = self.backend.z();
        for a in 0..N {
            // The velocity guess: the step polynomial's slope at the end of the step.
            self.v_end[a] = (1..=s1)
                .map(|m| sch.end_slope(m) / h * z[lay.at(m, a)])
                .sum();
            self.q_end[a] = self.state.q.sum[a] + z[lay.at(s1, a)];
        }
        if !M::STRUCTURE.constant_mass {
            let at = (self.state.t_state + h, &self.q_end[..], &self.v_end[..]);
            self.backend.mass_at_end(at, self.mass_sign)?;
        }
        let dw = if self.lean {
            0.0
        } else {
            self.ledger_increment(h)
        };
        self.commit(h, dw, rep.iterations);
        Ok((rep.iterations, rep.residual))
    }

    /// Takes the solved step: the compensated updates of `q`, `p` (by `Σ_j G_j =
    /// h Σ_i b_i (L_q + F)_i`, a small increment, which keeps round-off low: DESIGN §3) and
    /// the ledger, the predictor's polynomial, the time.
    #[inline]
    fn commit(&mut self, h: f64, dw: f64, iterations: usize) {
        let sch = self.scheme;
        let (s1, r) = (sch.stages() - 1, sch.quadrature_nodes());
        let lay = self.backend.layout();
        let (backend, st, dp) = (&self.backend, &mut self.state, &mut self.dp);
        let cforce = &mut self.cforce;
        let z = backend.z();
        let mut fmax = 0.0f64;
        dp.fill(0.0);
        st.force.fill(0.0);
        for i in 0..r {
            let (hb, fq) = (h * sch.b()[i], backend.node_fq(i));
            for ((d, &f), fa) in dp.iter_mut().zip(fq).zip(st.force.iter_mut()) {
                *d += hb * f;
                fmax = fmax.max(f.abs());
                *fa = fa.max(f.abs());
            }
        }
        if let Some(imp) = backend.constraint_impulse() {
            dp.iter_mut().zip(imp).for_each(|(d, i)| *d -= i);
            cforce.iter_mut().zip(imp).for_each(|(f, i)| *f = -i / h);
        }
        for (a, &d) in dp.iter().enumerate() {
            st.q.add(a, z[lay.at(s1, a)]);
            st.p.add(a, d);
        }
        st.v.copy_from_slice(&self.v_end);
        st.add_work(dw);
        st.z_prev.copy_from_slice(z);
        // The extrapolation's errors are kept from a step that took more than one Newton
        // iteration on, while correcting by them helps (see `Stepper::predict`).
        if self.extrapolated_near && (iterations > 1 || st.deltas > 0) {
            // The error of the extrapolation at this step, and what the correction by the
            // last two steps' errors left of it (applied or not), in one pass that also
            // keeps the new error.
            let n = lay.increments();
            let (ext, d1) = (&self.extrapolated[..n], &st.pred_delta[..n]);
            let (mut plain, mut corrected) = (0.0f64, 0.0f64);
            for (((x, e), d), c) in z[..n]
                .iter()
                .zip(ext)
                .zip(d1)
                .zip(&mut st.pred_delta_prev[..n])
            {
                let new = x - e;
                let (a, b) = (new.abs(), (new - (2.0 * d - *c)).abs());
                plain = if a > plain { a } else { plain };
                corrected = if b > corrected { b } else { corrected };
                *c = new;
            }
            std::mem::swap(&mut st.pred_delta, &mut st.pred_delta_prev);
            // Measured before it is used: not until two errors are kept.
            st.delta_helps = st.deltas == 2 && corrected <= 0.5 * plain;
            st.deltas = if st.deltas == 2 && !st.delta_helps {
                0
            } else {
                (st.deltas + 1).min(2)
            };
        } else {
            st.deltas = 0;
        }
        st.has_prev = true;
        st.h_prev = h;
        st.t_state += h;
        st.scale_f = fmax;
    }

    /// The ledger's increment over the step just solved: the work `h Σ b_i F·v` less
    /// `h Σ b_i ∂L/∂t` (DESIGN §4, §7), from the model's own force and Lagrangian, plus the
    /// work of the forces of constraints that read the time ([`Self::constraint_work`]).
    fn ledger_increment(&self, h: f64) -> f64 {
        let s = M::STRUCTURE;
        let moving =
            M::CONSTRAINED && M::CONSTRAINTS_READ_TIME && self.model.constraint_count() > 0;
        if !(s.has_force || s.uses_time || moving) {
            return 0.0;
        }
        let mut dw = if moving { self.constraint_work(h) } else { 0.0 };
        if !(s.has_force || s.uses_time) {
            return dw;
        }
        let sch = self.scheme;
        for i in 0..sch.quadrature_nodes() {
            let (Ok(x), Ok(v)) = (
                <&[f64; N]>::try_from(self.backend.node_x(i)),
                <&[f64; N]>::try_from(self.backend.node_v(i)),
            ) else {
                return f64::NAN;
            };
            let (ti, hb) = (self.state.t_state + sch.c()[i] * h, h * sch.b()[i]);
            if s.has_force {
                let f = self.model.force_at::<f64>(ti, x, v);
                dw += hb * f.iter().zip(v).map(|(f, v)| f * v).sum::<f64>();
            }
            if s.uses_time {
                let t = num_dual::Dual64::new(ti, 1.0);
                dw -= hb * self.model.lagrangian_at(t, &lift(x), &lift(v)).eps;
            }
        }
        dw
    }

    /// The work of the constraint forces `−Gᵀλ` over the step just solved, `h Σ_j b_j λ_jᵀ
    /// ∂g/∂t(t_j, x_j)`: along a motion on `g(t, q) = 0`, `G v = −∂g/∂t`, so their power
    /// `−λᵀ G v` is `λᵀ ∂g/∂t`, zero for a fixed constraint (DESIGN §11). The multipliers are
    /// the step's `ŵ_j = h² λ_j` at its control points (the quadrature nodes of a Lobatto
    /// scheme) and its end multipliers.
    fn constraint_work(&self, h: f64) -> f64 {
        let sch = self.scheme;
        let (s, m) = (sch.stages(), self.model.constraint_count());
        let (lay, z, end) = (
            self.backend.layout(),
            self.backend.z(),
            self.backend.end_multipliers(),
        );
        let mut rate = vec![0.0; m];
        let mut w = 0.0;
        for j in 0..s {
            let tj = self.state.t_state + sch.c()[j] * h;
            let x = self.backend.node_x(j);
            crate::model::general::constraint_rate_at(self.model, tj, x, &mut rate);
            for (k, r) in rate.iter().enumerate() {
                let wk = if j + 1 < s {
                    z[lay.multiplier(j, k)]
                } else {
                    end.get(k).copied().unwrap_or(0.0)
                };
                w += sch.b()[j] / h * wk * r;
            }
        }
        w
    }

    /// What a sensitivity or adjoint run carries past a solved step: the tangent, then the
    /// tape. A failed tangent changes nothing; a tape out of memory ends the run.
    pub(super) fn carry(&mut self) -> Result<(), StepFailure> {
        self.tangent_step()?;
        self.tape_step()
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
                *iters += self.backend.last_iterations();
                Err(f)
            }
        }
    }

    /// Advances over `[t_k, t_{k+1}]`, subdividing on failure if allowed.
    pub(super) fn step(&mut self) -> Result<Stepped, Error> {
        let t0 = self.time_of(self.k);
        let h = self.time_of(self.k + 1) - t0;
        let mut iters = 0;
        let mut last_failure = StepFailure::Newton(NewtonFailure::NonFinite);
        let levels =
            (self.options.max_subdivisions).min(super::StepOptions::MAX_SUBDIVISION_LEVELS);
        // A failed attempt changes nothing of the state (only a solved step commits), so
        // the state needs saving only for substeps, which commit one by one: when the first
        // of them is tried. A sensitivity or adjoint run saves it first, since its step can
        // fail after the commit (in `carry`).
        let eager = levels > 0 && (self.tangent.is_some() || self.tape.is_some());
        if eager {
            self.saved.copy_from(&self.state);
        }
        for level in 0..=levels {
            let parts = 1usize << level;
            let hs = h / parts as f64;
            if level == 1 {
                if !eager {
                    self.saved.copy_from(&self.state);
                }
                if let Some(tg) = self.tangent.as_mut() {
                    tg.save();
                }
                if let Some(tape) = self.tape.as_mut() {
                    tape.save();
                }
            }
            let mut outcome = Ok(0.0);
            for _ in 0..parts {
                outcome = self
                    .attempt(hs, &mut iters)
                    .and_then(|res| self.carry().map(|()| res));
                if outcome.is_err() {
                    break;
                }
            }
            match outcome {
                Ok(res) => {
                    if parts > 1 {
                        self.stats.subdivided_steps += 1;
                        // The predictor's polynomial covered a substep; start afresh.
                        self.state.has_prev = false;
                    }
                    self.t = self.time_of(self.k + 1);
                    return self.finish_step(iters, res, parts);
                }
                Err(f) => {
                    if level > 0 || eager {
                        self.state.copy_from(&self.saved);
                    }
                    if level > 0 {
                        if let Some(tg) = self.tangent.as_mut() {
                            tg.restore();
                        }
                        if let Some(tape) = self.tape.as_mut() {
                            tape.restore();
                        }
                    }
                    if f.is_fatal() {
                        return Err(self.failure_error(f, t0));
                    }
                    last_failure = f;
                    // Retry without the (possibly bad) extrapolation.
                    self.state.has_prev = false;
                }
            }
        }
        Err(self.failure_error(last_failure, t0))
    }

    /// Completes an accepted step that ends at `self.t`: the step count and the totals.
    /// Its record, if the run keeps one, is made by [`Self::emit`].
    pub(super) fn finish_step(
        &mut self,
        iters: usize,
        residual: f64,
        substeps: usize,
    ) -> Result<Stepped, Error> {
        self.k += 1;
        // Substeps add up to the step only to round-off: the step's end is exact.
        self.state.t_state = self.t;
        self.stats.count_step(iters);
        Ok(Stepped {
            iters,
            residual,
            substeps,
        })
    }

    /// The record of a step just finished: in a lean run the state only (the velocity,
    /// energy and balance are left out, and checked once at the end, `finish`); else with
    /// the velocity solve and the diagnostics, every field of which must be finite.
    pub(super) fn emit(&mut self, done: Stepped) -> Result<StepRecord<N>, Error> {
        let Stepped {
            iters,
            residual,
            substeps,
        } = done;
        if self.lean {
            return Ok(self.record(iters, residual, substeps, false));
        }
        self.solve_velocity()?;
        let rec = self.record(iters, residual, substeps, true);
        let size = || rec.q.amax().max(rec.p.amax()).max(rec.v.amax());
        if let Some(error) = record_error(&rec, size, self.k, self.t) {
            return Err(error);
        }
        Ok(rec)
    }

    /// The error for a step from `t0` that could not be taken.
    pub(super) fn failure_error(&self, failure: StepFailure, t0: f64) -> Error {
        let step = self.k + 1;
        match failure {
            StepFailure::SingularMass { rcond } => Error::SingularMassMatrix { step, t: t0, rcond },
            StepFailure::OutsidePattern => Error::outside_pattern(),
            StepFailure::Memory { records } => Error::TooManyRecords { records },
            StepFailure::Newton(f) => newton_error(f, self.state.size(), step, t0),
            StepFailure::TangentOverflow => Error::Overflow {
                step,
                t: t0,
                quantity: "tangent",
            },
        }
    }
}
