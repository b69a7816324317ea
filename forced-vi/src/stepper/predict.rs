//! The predictor: the previous step's polynomial extrapolated to the new step (rescaled
//! when `h` changes; above nine stages the polynomial through a subset of its control
//! points, see `Scheme::predictor_degree`), or a straight line along `v` on a first step.
//!
//! The extrapolation is also corrected by its own error. That error, the solved increments
//! less the extrapolated ones, is `O(h^(s+1))` and, over steps of one size, a smooth function
//! of time: the errors of the last two steps, extrapolated linearly (`2 δ_n − δ_{n−1}`),
//! leave `O(h^(s+3))`. A step measures what the correction would have left of its own error;
//! the correction is used while that is at most half the uncorrected error, and the errors
//! are only kept from a step that took more than one Newton iteration on, so a run whose
//! predictor already suffices pays nothing for them. The predictor is only a starting
//! guess: the solve's tests decide, as before.
//!
//! Measured (coupled van der Pol, fixed steps, instructions for 100 runs): lobatto3 at
//! `h = 0.01`, 64.4M → 54.1M (Newton iterations per step 1.78 → 1.04); at `h = 1/38`,
//! 30.9M → 26.7M; lobatto5 at `h = 1/38`, 44.6M → 41.2M (1.63 → 1.11 iterations), at
//! `h = 0.01` (one iteration either way, at the time: the step-cost report now counts 2.00
//! per step there, after the stale-factor rule for 6 unknowns or more) 99.2M → 99.9M. Where the steps are too long for
//! the errors to be smooth (Kepler, 24 lobatto7 steps over `T = 20`) the correction is
//! measured not to help and is not used: 73.4M → 74.3M, the same 53 iterations.
//!
//! Adaptive steps change size at every step, by a few per cent where the controller has
//! settled, so the same correction is made while `h / h_prev` is within 0.5–2, unscaled:
//! the errors then change with the step size as well as with time, and the measurement above
//! still decides whether the correction helps. Scaling it by `(h / h_prev)^s` or
//! `^(s+1)` (the extrapolation error's leading power) was measured and helped less. Measured
//! (callgrind, whole adaptive runs to T = 20 at rtol = atol, against equal steps only; the
//! same steps): coupled van der Pol lobatto3 at 1e-6, 12.0M → 10.7M instructions (Newton
//! iterations 1863 → 1400), lobatto4 at 1e-10 12.8M → 11.9M (1759 → 1225); the double
//! pendulum with friction lobatto3 at 1e-6 61.5M → 55.1M (6164 → 4188), lobatto4 at 1e-10
//! 86.6M → 81.9M; Kepler with drag lobatto4 at 1e-10 −2.4 %; where one iteration and its
//! check already suffice (the damped oscillator, lobatto5 runs) within +0.2 %.

use super::Stepper;
use crate::backend::StepBackend;
use crate::model::ForcedLagrangian;

/// The step-size ratios `h / h_prev` at which the extrapolation's errors are kept and added
/// back, besides equal steps (see the module docs).
const NEAR_MIN: f64 = 0.5;
const NEAR_MAX: f64 = 2.0;

impl<M: ForcedLagrangian<N>, const N: usize> Stepper<'_, M, N> {
    /// Fills the backend's unknowns with the predictor for a step of size `h`.
    pub(super) fn predict(&mut self, h: f64) {
        let sch = self.scheme;
        let s1 = sch.stages() - 1;
        let lay = self.backend.layout();
        let st = &self.state;
        let extrapolate = st.has_prev && sch.extrapolates();
        // Equal steps use the table made once; sizes that differ by round-off (a fixed step
        // between grid times `k h`) count as equal, the predictor being only a guess.
        let same = (h - st.h_prev).abs() <= 1e-8 * h;
        // The extrapolation's error is a smooth function of time, `O(h^(s+1))`: its values
        // over the last two steps, extrapolated linearly, are added back where that has
        // been measured to help (see `Stepper::commit`), at an unchanged step size and at
        // one within a factor of two of the last (adaptive steps).
        let ratio = h / st.h_prev;
        let near = same || (NEAR_MIN..=NEAR_MAX).contains(&ratio);
        self.extrapolated_near = extrapolate && near;
        let correct = self.extrapolated_near && st.deltas == 2 && st.delta_helps;
        let (basis, ext) = (&mut self.basis, &mut self.extrapolated);
        let z = self.backend.z_mut();
        for j in 1..=s1 {
            let dj = sch.d()[j];
            if !extrapolate {
                for a in 0..N {
                    z[lay.at(j, a)] = st.v[a] * (dj * h);
                }
                continue;
            }
            // Equal steps read the table's row in place.
            let row: &[f64] = if same {
                sch.extrapolation_row(j)
            } else {
                sch.predictor_basis_at(1.0 + dj * h / st.h_prev, basis);
                basis
            };
            for a in 0..N {
                let mut x = -st.z_prev[lay.at(s1, a)];
                for (m, l) in row.iter().enumerate().skip(1) {
                    x += st.z_prev[lay.at(m, a)] * l;
                }
                let i = lay.at(j, a);
                (z[i], ext[i]) = (x, x);
            }
        }
        if correct {
            let n = lay.increments();
            let (d1, d0) = (&st.pred_delta[..n], &st.pred_delta_prev[..n]);
            for ((x, d), e) in z[..n].iter_mut().zip(d1).zip(d0) {
                *x += 2.0 * d - e;
            }
        }
    }
}
