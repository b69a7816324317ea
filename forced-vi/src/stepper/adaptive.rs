//! Adaptive steps: step doubling, accepted when the error norm is at most one (see
//! [`crate::control`]). The same on every backend.

use super::Stepper;
use crate::backend::StepFailure;
use crate::control::Tolerance;
use crate::error::Error;
use crate::model::ForcedLagrangian;
use crate::trajectory::StepRecord;

impl<M: ForcedLagrangian<N>, const N: usize> Stepper<'_, M, N> {
    /// One adaptive step from `t`: step doubling, accepted when the error norm is at most
    /// one, retried with a smaller step otherwise (see [`crate::control`]).
    pub(super) fn step_adaptive(&mut self, tol: &Tolerance<N>) -> Result<StepRecord<N>, Error> {
        let t0 = self.t;
        self.saved.copy_from(&self.state);
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
            match self.doubled(h, &mut iters) {
                Ok(res) => {
                    let err = tol.error_norm(
                        self.scheme.order(),
                        span / h,
                        (&self.whole.0, &self.whole.1),
                        (&self.state.q.sum, &self.state.p.sum),
                    );
                    if err <= 1.0 {
                        self.h_next = self.controller.accept(h, err);
                        self.t = if last { self.t_final } else { t0 + h };
                        return self.finish_step(iters, res, 2);
                    }
                    self.h_next = self.controller.reject(h, err);
                }
                Err(StepFailure::OutsidePattern) => {
                    self.state.copy_from(&self.saved);
                    return Err(Error::outside_pattern());
                }
                Err(f) => {
                    last_failure = Some(f);
                    self.h_next = self.controller.reject(h, f64::INFINITY);
                }
            }
            self.stats.rejected_steps += 1;
            self.state.copy_from(&self.saved);
        }
    }

    /// A step of `h` and two of `h/2` from the same state; leaves the state after the
    /// halves, the whole step's `(q, p)` in `self.whole`, and returns the halves' last
    /// residual.
    fn doubled(&mut self, h: f64, iters: &mut usize) -> Result<f64, StepFailure> {
        self.attempt(h, iters)?;
        self.whole.0.copy_from_slice(&self.state.q.sum);
        self.whole.1.copy_from_slice(&self.state.p.sum);
        self.state.copy_from(&self.saved);
        self.attempt(0.5 * h, iters)?;
        self.attempt(0.5 * h, iters)
    }
}
