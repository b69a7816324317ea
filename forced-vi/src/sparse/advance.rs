//! One sparse step: the Newton solve, the compensated update of `(q, p)`, the ledger's
//! increment, subdivision on failure, and the record.

use crate::error::{Error, NewtonFailure};
use crate::integrator::Integrator;
use crate::model::ForcedLagrangian;
use crate::scalar::lift;
use crate::sparse::state::StepFailure;
use crate::sparse::stepper::SparseStepper;
use crate::sparse::velocity::outside_pattern;
use crate::stepper::{newton_error, record_error};
use crate::trajectory::StepRecord;

impl<M: ForcedLagrangian<N>, const N: usize> SparseStepper<'_, M, N> {
    /// One step of size `h` from the current state.
    pub(super) fn advance(&mut self, h: f64) -> Result<(usize, f64), StepFailure> {
        self.predict(h);
        let prob = &mut self.prob;
        let st = &mut self.state;
        prob.h = h;
        prob.t0 = st.t_state;
        prob.q0.copy_from_slice(&st.q.sum);
        prob.p0.copy_from_slice(&st.p.sum);
        self.newton.invalidate();
        let pmax = st.p.sum.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let scale = pmax.max(h * st.scale_f).max(f64::MIN_POSITIVE);
        let rep = self.newton.solve(prob, &mut self.z, scale).map_err(|f| {
            if prob.outside {
                StepFailure::OutsidePattern
            } else {
                StepFailure::Newton(f)
            }
        })?;
        // The last residual evaluation was at the accepted iterate: the node values in
        // `prob` belong to the solution (as in the dense stepper).
        let sch = prob.scheme;
        let s1 = sch.stages() - 1;
        let dw = if self.lean {
            0.0
        } else {
            self.ledger_increment()
        };
        let (prob, st) = (&self.prob, &mut self.state);
        let mut fmax = 0.0f64;
        for a in 0..N {
            fmax = (0..sch.quadrature_nodes()).fold(fmax, |m, i| m.max(prob.fq[i * N + a].abs()));
            let za = &self.z[a * s1..(a + 1) * s1];
            // Velocity guess: the polynomial's slope at the end of the step.
            st.v[a] = za
                .iter()
                .enumerate()
                .map(|(m, zm)| sch.end_slope(m + 1) / h * zm)
                .sum();
            st.q.add(a, za[s1 - 1]);
            st.p.add(a, prob.momentum_increment(a));
        }
        st.add_work(dw);
        st.z_prev.copy_from_slice(&self.z);
        st.has_prev = true;
        st.h_prev = h;
        st.t_state += h;
        st.scale_f = fmax;
        Ok((rep.iterations, rep.residual))
    }

    /// The ledger's increment over the step just solved: the work `h Σ b_i F·v` less
    /// `h Σ b_i ∂L/∂t` (DESIGN §4, §7), from the model's own force and Lagrangian.
    fn ledger_increment(&self) -> f64 {
        let s = M::STRUCTURE;
        if !(s.has_force || s.uses_time) {
            return 0.0;
        }
        let prob = &self.prob;
        let mut dw = 0.0;
        for i in 0..prob.scheme.quadrature_nodes() {
            let range = i * N..(i + 1) * N;
            let (Ok(x), Ok(v)) = (
                <&[f64; N]>::try_from(&prob.xs[range.clone()]),
                <&[f64; N]>::try_from(&prob.vs[range]),
            ) else {
                return f64::NAN;
            };
            let (ti, hb) = (prob.node_time(i), prob.h * prob.scheme.b()[i]);
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

    /// Advances over `[t_k, t_{k+1}]`, subdividing on failure if allowed.
    pub(super) fn step(&mut self) -> Result<StepRecord<N>, Error> {
        let t0 = self.time_of(self.k);
        let h = self.time_of(self.k + 1) - t0;
        self.saved.copy_from(&self.state);
        let mut iters = 0;
        let mut last_failure = StepFailure::Newton(NewtonFailure::NonFinite);
        let levels =
            (self.options.max_subdivisions).min(Integrator::<M, N>::MAX_SUBDIVISION_LEVELS);
        for level in 0..=levels {
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
                        self.state.has_prev = false;
                    }
                    self.t = self.time_of(self.k + 1);
                    return self.finish_step(iters, res, parts);
                }
                Err(StepFailure::OutsidePattern) => {
                    self.state.copy_from(&self.saved);
                    return Err(outside_pattern());
                }
                Err(f) => {
                    last_failure = f;
                    self.state.copy_from(&self.saved);
                    self.state.has_prev = false;
                }
            }
        }
        self.state.copy_from(&self.saved);
        Err(self.failure_error(last_failure, t0))
    }

    /// Completes an accepted step that ends at `self.t`.
    fn finish_step(
        &mut self,
        iters: usize,
        residual: f64,
        substeps: usize,
    ) -> Result<StepRecord<N>, Error> {
        self.k += 1;
        let t = self.t;
        self.state.t_state = t;
        self.stats.count_step(iters);
        if self.lean {
            return Ok(self.record(iters, residual, substeps, false));
        }
        self.solve_velocity()?;
        let rec = self.record(iters, residual, substeps, true);
        let size = || {
            [&rec.q, &rec.p, &rec.v]
                .iter()
                .fold(0.0f64, |m, x| m.max(x.amax()))
        };
        if let Some(error) = record_error(&rec, size, self.k, t) {
            return Err(error);
        }
        Ok(rec)
    }

    /// The error for a step from `t0` that could not be taken.
    fn failure_error(&self, failure: StepFailure, t0: f64) -> Error {
        let step = self.k + 1;
        let failure = match failure {
            StepFailure::OutsidePattern => return outside_pattern(),
            StepFailure::Newton(f) => f,
        };
        let st = &self.state;
        let size = [&st.q.sum, &st.p.sum, &st.v]
            .iter()
            .flat_map(|x| x.iter())
            .fold(0.0f64, |m, x| m.max(x.abs()));
        newton_error(failure, size, step, t0)
    }
}

impl<M: ForcedLagrangian<N>, const N: usize> Iterator for SparseStepper<'_, M, N> {
    type Item = Result<StepRecord<N>, Error>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        if !self.started {
            self.started = true;
            return Some(Ok(self.record(0, 0.0, 1, true)));
        }
        if self.k >= self.n_steps {
            self.done = true;
            return None;
        }
        let out = self.step();
        if out.is_err() {
            self.done = true;
        }
        Some(out)
    }
}
