//! The sparse stepper's state on the heap: compensated positions and momenta, the velocity,
//! the work and the predictor's polynomial, with a copy made in place for retries.

use crate::error::NewtonFailure;
use crate::sparse::node::SparseNode;
use crate::stepper::kahan_add;

/// Compensated (Kahan) accumulation of a vector.
#[derive(Clone, Debug)]
pub(crate) struct KahanVec {
    pub(crate) sum: Vec<f64>,
    comp: Vec<f64>,
}

impl KahanVec {
    fn new(n: usize) -> Self {
        KahanVec {
            sum: vec![0.0; n],
            comp: vec![0.0; n],
        }
    }

    /// Adds `dx` to component `i`.
    #[inline]
    pub(crate) fn add(&mut self, i: usize, dx: f64) {
        kahan_add(&mut self.sum[i], &mut self.comp[i], dx);
    }

    fn copy_from(&mut self, other: &KahanVec) {
        self.sum.copy_from_slice(&other.sum);
        self.comp.copy_from_slice(&other.comp);
    }
}

/// What a step changes.
#[derive(Clone, Debug)]
pub(crate) struct State {
    pub(crate) q: KahanVec,
    pub(crate) p: KahanVec,
    pub(crate) v: Vec<f64>,
    /// The ledger `W − ∫L_t`, compensated: `(sum, compensation)`.
    pub(crate) work: (f64, f64),
    /// The last step's increments, in the step's coordinate-major layout.
    pub(crate) z_prev: Vec<f64>,
    pub(crate) has_prev: bool,
    pub(crate) h_prev: f64,
    pub(crate) scale_f: f64,
    /// The time of `(q, p)` (ahead of the last record between substeps).
    pub(crate) t_state: f64,
}

impl State {
    /// A zero state for `n` coordinates and `s` control points.
    pub(crate) fn new(n: usize, s: usize) -> Self {
        State {
            q: KahanVec::new(n),
            p: KahanVec::new(n),
            v: vec![0.0; n],
            work: (0.0, 0.0),
            z_prev: vec![0.0; n * (s - 1)],
            has_prev: false,
            h_prev: 1.0,
            scale_f: 0.0,
            t_state: 0.0,
        }
    }

    /// Copies `other` into `self` without allocating.
    pub(crate) fn copy_from(&mut self, other: &State) {
        self.q.copy_from(&other.q);
        self.p.copy_from(&other.p);
        self.v.copy_from_slice(&other.v);
        self.work = other.work;
        self.z_prev.copy_from_slice(&other.z_prev);
        self.has_prev = other.has_prev;
        self.h_prev = other.h_prev;
        self.scale_f = other.scale_f;
        self.t_state = other.t_state;
    }

    /// Adds `dw` to the ledger.
    pub(crate) fn add_work(&mut self, dw: f64) {
        let (w, c) = &mut self.work;
        kahan_add(w, c, dw);
    }
}

/// Why one attempt at a step failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum StepFailure {
    Newton(NewtonFailure),
    /// A kernel wrote outside the recorded pattern.
    OutsidePattern,
}

/// `E = v · p − L(t, q, v)`; `None` if not finite.
pub(crate) fn energy(
    node: &dyn SparseNode,
    t: f64,
    q: &[f64],
    v: &[f64],
    p: &[f64],
) -> Option<f64> {
    let vp: f64 = v.iter().zip(p).map(|(a, b)| a * b).sum();
    let e = vp - node.lagrangian_value(t, q, v);
    e.is_finite().then_some(e)
}
