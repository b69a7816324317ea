//! What a step changes and how it is saved: compensated positions, momenta and ledger, the
//! velocity, the predictor's polynomial, with a copy for retries, made in place. Every
//! vector lives on the heap, made at most once per run (the copy's when first needed),
//! whatever the model's size.
use crate::buffers::zeros;

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
#[derive(Clone, Debug)]
pub(crate) struct KahanVec {
    pub(crate) sum: Vec<f64>,
    comp: Vec<f64>,
}

impl KahanVec {
    fn new(n: usize) -> Self {
        KahanVec {
            sum: zeros(n),
            comp: zeros(n),
        }
    }

    /// Adds `dx` to component `i`.
    #[inline(always)]
    pub(crate) fn add(&mut self, i: usize, dx: f64) {
        kahan_add(&mut self.sum[i], &mut self.comp[i], dx);
    }

    fn copy_from(&mut self, other: &KahanVec) {
        self.sum.clone_from(&other.sum);
        self.comp.clone_from(&other.comp);
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
    /// The last step's increments, in the backend's layout of the unknowns.
    pub(crate) z_prev: Vec<f64>,
    pub(crate) has_prev: bool,
    pub(crate) h_prev: f64,
    /// The last two steps' increments less the predictor's extrapolation, at an unchanged
    /// step size (see `Stepper::predict`); `deltas` of them are valid (0, 1 or 2), and
    /// whether correcting the extrapolation by them helped at the last step.
    pub(crate) pred_delta: Vec<f64>,
    pub(crate) pred_delta_prev: Vec<f64>,
    pub(crate) deltas: u8,
    pub(crate) delta_helps: bool,
    /// The largest `|L_q + F|` at a node of the last step: the residual's force scale.
    pub(crate) scale_f: f64,
    /// The same per coordinate: `|L_q + F|_a` (the largest over the nodes).
    pub(crate) force: Vec<f64>,
    /// The time of `(q, p)` (ahead of the last record between substeps).
    pub(crate) t_state: f64,
}

impl State {
    /// A zero state for `n` coordinates and `unknowns` step unknowns.
    pub(crate) fn new(n: usize, unknowns: usize) -> Self {
        State {
            q: KahanVec::new(n),
            p: KahanVec::new(n),
            v: zeros(n),
            work: (0.0, 0.0),
            z_prev: zeros(unknowns),
            has_prev: false,
            h_prev: 1.0,
            pred_delta: zeros(unknowns),
            pred_delta_prev: zeros(unknowns),
            deltas: 0,
            delta_helps: false,
            scale_f: 0.0,
            force: zeros(n),
            t_state: 0.0,
        }
    }

    /// Back to [`State::new`]'s zeros, keeping the vectors (a new run on the same buffers).
    /// Every field is named, so that a field added later must be decided on here.
    pub(crate) fn reset(&mut self) {
        let State {
            q,
            p,
            v,
            work,
            z_prev,
            has_prev,
            h_prev,
            pred_delta,
            pred_delta_prev,
            deltas,
            delta_helps,
            scale_f,
            force,
            t_state,
        } = self;
        for x in [&mut q.sum, &mut q.comp, &mut p.sum, &mut p.comp, v] {
            x.fill(0.0);
        }
        for x in [z_prev, pred_delta, pred_delta_prev] {
            x.fill(0.0);
        }
        *work = (0.0, 0.0);
        *has_prev = false;
        *h_prev = 1.0;
        *deltas = 0;
        *delta_helps = false;
        *scale_f = 0.0;
        force.fill(0.0);
        *t_state = 0.0;
    }

    /// A state with no vectors yet (none allocated), for [`State::copy_from`] to fill.
    pub(crate) fn empty() -> Self {
        State::new(0, 0)
    }

    /// Copies `other` into `self`, allocating only into an [`State::empty`] one.
    pub(crate) fn copy_from(&mut self, other: &State) {
        self.q.copy_from(&other.q);
        self.p.copy_from(&other.p);
        self.v.clone_from(&other.v);
        self.work = other.work;
        self.z_prev.clone_from(&other.z_prev);
        self.has_prev = other.has_prev;
        self.h_prev = other.h_prev;
        self.pred_delta.clone_from(&other.pred_delta);
        self.pred_delta_prev.clone_from(&other.pred_delta_prev);
        self.deltas = other.deltas;
        self.delta_helps = other.delta_helps;
        self.scale_f = other.scale_f;
        self.force.clone_from(&other.force);
        self.t_state = other.t_state;
    }

    /// Adds `dw` to the ledger.
    #[inline]
    pub(crate) fn add_work(&mut self, dw: f64) {
        let (w, c) = &mut self.work;
        kahan_add(w, c, dw);
    }

    /// The largest `|q|`, `|p|`, `|v|`.
    pub(crate) fn size(&self) -> f64 {
        [&self.q.sum, &self.p.sum, &self.v]
            .iter()
            .flat_map(|x| x.iter())
            .fold(0.0f64, |m, x| m.max(x.abs()))
    }
}
