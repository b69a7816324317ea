//! What a step changes and how it is saved: compensated sums, the snapshot for retries, and
//! the predictor built from the previous step's polynomial.

use nalgebra::SVector;

use super::Stepper;
use crate::model::ForcedLagrangian;

/// One compensated (Kahan) addition of `dx` to `sum`, whose running compensation is `comp`.
/// Every compensated sum of the crate (DESIGN §3: `q`, `p` and the ledger) goes through it.
#[inline(always)]
pub(crate) fn kahan_add(sum: &mut f64, comp: &mut f64, dx: f64) {
    let y = dx - *comp;
    let t = *sum + y;
    *comp = (t - *sum) - y;
    *sum = t;
}

/// Compensated (Kahan) accumulation of a vector.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Kahan<const N: usize> {
    pub(super) sum: SVector<f64, N>,
    comp: SVector<f64, N>,
}

impl<const N: usize> Kahan<N> {
    pub(super) fn new(x: SVector<f64, N>) -> Self {
        Kahan {
            sum: x,
            comp: SVector::zeros(),
        }
    }
    pub(super) fn add(&mut self, dx: &SVector<f64, N>) {
        for i in 0..N {
            kahan_add(&mut self.sum[i], &mut self.comp[i], dx[i]);
        }
    }
}

/// Saved state for retrying a step as substeps.
#[derive(Clone, Copy, Debug)]
pub(super) struct Snapshot<const N: usize> {
    q: Kahan<N>,
    p: Kahan<N>,
    work: (f64, f64),
    v: SVector<f64, N>,
    has_prev: bool,
    h_prev: f64,
    scale_f: f64,
    t_state: f64,
}

impl<M: ForcedLagrangian<N>, const N: usize> Stepper<'_, M, N> {
    pub(super) fn snapshot(&mut self) -> Snapshot<N> {
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

    pub(super) fn restore(&mut self, s: &Snapshot<N>) {
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
    pub(super) fn predict(&mut self, h: f64) {
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
}
