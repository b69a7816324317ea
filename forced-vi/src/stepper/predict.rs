//! The predictor: the previous step's polynomial extrapolated to the new step (rescaled
//! when `h` changes), or a straight line along `v` on a first step.

use super::Stepper;
use crate::backend::StepBackend;
use crate::model::ForcedLagrangian;

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
        let basis = &mut self.basis;
        let z = self.backend.z_mut();
        for j in 1..=s1 {
            let dj = sch.d()[j];
            if !extrapolate {
                for a in 0..N {
                    z[lay.at(j, a)] = st.v[a] * (dj * h);
                }
                continue;
            }
            if same {
                for (m, l) in basis.iter_mut().enumerate().skip(1) {
                    *l = sch.extrapolation(j, m);
                }
            } else {
                sch.basis_at(1.0 + dj * h / st.h_prev, basis);
            }
            for a in 0..N {
                let mut x = -st.z_prev[lay.at(s1, a)];
                for (m, l) in basis.iter().enumerate().skip(1) {
                    x += st.z_prev[lay.at(m, a)] * l;
                }
                z[lay.at(j, a)] = x;
            }
        }
    }
}
