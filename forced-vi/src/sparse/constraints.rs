//! Holonomic constraints on sparse storage (DESIGN §11): the patterns of `G = ∂g/∂q` and of
//! the multipliers' curvature, recorded once per run; `g`, `G` and the curvature at the
//! control points of a step; and the saddle-point solve `[[E, Gᵀ], [G, 0]]` that ends a
//! step (and projects initial data), by the sparse LU on a fixed pattern.

use crate::error::{Error, NewtonFailure};
use crate::model::{ConstraintSink, NodeBlocks, NodePattern, NodeSink, SparseNode};
use crate::sparse::lu::SparseLu;
use crate::sparse::pattern::{record_node_pattern, transpose};

/// Records the pattern of `G` (`m × n`) and the entries of the curvature, by one evaluation
/// of the constraint kernels at `(t, q)` in recording mode.
pub(crate) fn record_constraint_patterns(
    node: &dyn SparseNode,
    t: f64,
    q: &[f64],
) -> Result<(NodePattern, Vec<(usize, usize)>), Error> {
    let (n, m) = (node.dof(), node.sparse_constraint_count());
    let mut g = vec![0.0; m];
    let (mut g_pairs, mut curvature_pairs) = (Vec::new(), Vec::new());
    let mut sink = ConstraintSink::record(&mut g, &mut g_pairs, &mut curvature_pairs);
    node.eval_constraints(t, q, &mut sink);
    let outside = sink.outside()
        || g_pairs.iter().any(|&(k, a)| k >= m || a >= n)
        || curvature_pairs.iter().any(|&(a, c)| a >= n || c >= n);
    if outside {
        return Err(Error::InvalidModel {
            message:
                "the sparse constraint kernels write outside the model's constraints or coordinates"
                    .into(),
        });
    }
    if !g.iter().all(|x| x.is_finite()) {
        return Err(Error::NonFiniteModel { step: 0, t });
    }
    Ok((NodePattern::rectangular(m, n, g_pairs), curvature_pairs))
}

/// `g`, `G` and the curvature at the `s` control points of a step.
pub(crate) struct StepConstraints {
    /// The number of constraints.
    pub(crate) m: usize,
    /// The pattern of `G`.
    pub(crate) pattern: NodePattern,
    /// `g(x_j)`: `m` values per control point.
    pub(crate) g: Vec<f64>,
    /// `G(x_j)` on [`Self::pattern`]: `nnz` values per control point.
    pub(crate) jac: Vec<f64>,
    /// `Σ_k λ_k ∂²g_k` on the node pattern at the last point asked for.
    pub(crate) curvature: Vec<f64>,
    /// Scratch: `G v`.
    gv: Vec<f64>,
    /// The kernels wrote outside the recorded patterns (a defect of the model, or an entry
    /// of `G` that the recording did not see).
    pub(crate) outside: bool,
}

impl StepConstraints {
    /// Buffers for `s` control points.
    pub(crate) fn new(pattern: NodePattern, s: usize, node_nnz: usize) -> Self {
        let m = pattern.n();
        StepConstraints {
            m,
            g: vec![0.0; m * s],
            jac: vec![0.0; pattern.nnz() * s],
            curvature: vec![0.0; node_nnz],
            gv: vec![0.0; m],
            outside: false,
            pattern,
        }
    }

    /// `G(x_j)`'s values.
    pub(crate) fn jac_at(&self, j: usize) -> &[f64] {
        let e = self.pattern.nnz();
        &self.jac[j * e..(j + 1) * e]
    }

    /// `g(x_j)`.
    pub(crate) fn g_at(&self, j: usize) -> &[f64] {
        &self.g[j * self.m..(j + 1) * self.m]
    }

    /// Evaluates `g` and `G` at control point `j`, `(t, x)`; with `lambda`, the curvature
    /// weighted by it too.
    pub(crate) fn eval(
        &mut self,
        node: &dyn SparseNode,
        node_pattern: &NodePattern,
        (j, t, x): (usize, f64, &[f64]),
        lambda: &[f64],
    ) -> Result<(), NewtonFailure> {
        let (m, e) = (self.m, self.pattern.nnz());
        let g = &mut self.g[j * m..(j + 1) * m];
        let jac = &mut self.jac[j * e..(j + 1) * e];
        let mut sink = ConstraintSink::jacobian(
            g,
            (&self.pattern, jac),
            node_pattern,
            lambda,
            &mut self.curvature,
        );
        node.eval_constraints(t, x, &mut sink);
        if sink.outside() {
            self.outside = true;
            return Err(NewtonFailure::NonFinite);
        }
        let finite = |s: &[f64]| s.iter().all(|x| x.is_finite());
        if !(finite(self.g_at(j)) && finite(self.jac_at(j)) && finite(&self.curvature)) {
            return Err(NewtonFailure::NonFinite);
        }
        Ok(())
    }

    /// `|g|`, `|G v + ∂g/∂t|` and the size of that sum's terms, `|G| |v| + |∂g/∂t|`
    /// (max-norms), at `(t, q, v)` with `rate = ∂g/∂t` there, for the checks of initial data
    /// and the records (control point 0's buffers are overwritten).
    pub(crate) fn residuals(
        &mut self,
        node: &dyn SparseNode,
        node_pattern: &NodePattern,
        (t, q, v): (f64, &[f64], &[f64]),
        rate: &[f64],
    ) -> Result<[f64; 4], Error> {
        self.eval(node, node_pattern, (0, t, q), &[])
            .map_err(|_| Error::NonFiniteModel { step: 0, t })?;
        let g_max = max_norm(self.g_at(0));
        let e = self.pattern.nnz();
        let jac = &self.jac[..e];
        self.gv.copy_from_slice(rate);
        for (i, (k, a)) in self.pattern.entries().enumerate() {
            self.gv[k] += jac[i] * v[a];
        }
        let size = max_norm(jac) * max_norm(v) + max_norm(rate);
        Ok([g_max, max_norm(&self.gv), size, max_norm(jac)])
    }
}

fn max_norm(x: &[f64]) -> f64 {
    x.iter().fold(0.0f64, |m, v| m.max(v.abs()))
}

/// The saddle-point matrix `[[E, Gᵀ], [G, 0]]` (`E` on the node pattern) and its LU factors,
/// with the scratch of the Newton iteration that ends a constrained step.
pub(crate) struct Saddle {
    n: usize,
    m: usize,
    lu: SparseLu,
    /// Where node entry `k`, `G` entry `e` and `Gᵀ` entry `e` sit in `lu`'s values.
    e_pos: Vec<usize>,
    g_pos: Vec<usize>,
    gt_pos: Vec<usize>,
    rhs: Vec<f64>,
    lq_f: Vec<f64>,
    lv: Vec<f64>,
    blocks: NodeBlocks,
    /// The velocity and the impulse `μ̂ = h b_{s−1} μ` of the last solve.
    pub(crate) v: Vec<f64>,
    pub(crate) mu: Vec<f64>,
}

impl Saddle {
    /// The matrix on the node pattern and `G`'s pattern, analysed.
    pub(crate) fn new(node_pattern: &NodePattern, g_pattern: &NodePattern) -> Result<Self, Error> {
        let (n, m) = (node_pattern.n(), g_pattern.n());
        let tr = transpose(node_pattern);
        let gt = transpose(g_pattern);
        let mut col_ptr = vec![0usize];
        let mut row_idx = Vec::with_capacity(node_pattern.nnz() + 2 * g_pattern.nnz());
        let mut e_pos = vec![0usize; node_pattern.nnz()];
        let mut g_pos = vec![0usize; g_pattern.nnz()];
        let mut gt_pos = vec![0usize; g_pattern.nnz()];
        // CSR index of each CSC entry.
        let csr_of = |csc_of: &[usize]| {
            let mut out = vec![0usize; csc_of.len()];
            for (k, &p) in csc_of.iter().enumerate() {
                out[p] = k;
            }
            out
        };
        let (node_csr, g_csr) = (csr_of(&tr.csc_of), csr_of(&gt.csc_of));
        for b in 0..n {
            for p in tr.col_ptr[b]..tr.col_ptr[b + 1] {
                e_pos[node_csr[p]] = row_idx.len();
                row_idx.push(tr.row_idx[p]);
            }
            for p in gt.col_ptr[b]..gt.col_ptr[b + 1] {
                g_pos[g_csr[p]] = row_idx.len();
                row_idx.push(n + gt.row_idx[p]);
            }
            col_ptr.push(row_idx.len());
        }
        let mut e = 0;
        for k in 0..m {
            for &a in g_pattern.row(k) {
                gt_pos[e] = row_idx.len();
                row_idx.push(a);
                e += 1;
            }
            col_ptr.push(row_idx.len());
        }
        let lu = SparseLu::new(n + m, col_ptr, row_idx).map_err(|_| Error::InvalidModel {
            message: "the sparse constraint pattern cannot be analysed".into(),
        })?;
        Ok(Saddle {
            n,
            m,
            lu,
            e_pos,
            g_pos,
            gt_pos,
            rhs: vec![0.0; n + m],
            lq_f: vec![0.0; n],
            lv: vec![0.0; n],
            blocks: NodeBlocks::zeros(node_pattern.nnz()),
            v: vec![0.0; n],
            mu: vec![0.0; m],
        })
    }

    /// Writes `G`'s values (both blocks) and factors with `E` from `e` (node-pattern values,
    /// or the identity with `None`).
    fn factor(
        &mut self,
        node_pattern: &NodePattern,
        e: Option<&[f64]>,
        g: &[f64],
    ) -> Result<(), NewtonFailure> {
        match e {
            Some(e) => {
                for (&p, &x) in self.e_pos.iter().zip(e) {
                    self.lu.values[p] = x;
                }
            }
            None => {
                for (k, (r, c)) in node_pattern.entries().enumerate() {
                    self.lu.values[self.e_pos[k]] = if r == c { 1.0 } else { 0.0 };
                }
            }
        }
        for ((&p, &pt), &x) in self.g_pos.iter().zip(&self.gt_pos).zip(g) {
            self.lu.values[p] = x;
            self.lu.values[pt] = x;
        }
        self.lu.factor()
    }

    /// Factors `[[E, Gᵀ], [G, 0]]` with `E` and `G` given on their patterns, for solves with
    /// other right-hand sides ([`Self::solve`]): the end projection of a step, linearised
    /// for its tangent.
    pub(crate) fn factor_with(
        &mut self,
        node_pattern: &NodePattern,
        e: &[f64],
        g: &[f64],
    ) -> Result<(), NewtonFailure> {
        self.factor(node_pattern, Some(e), g)
    }

    /// Solves with the last factors, in place (`n + m` values: the velocity's rows, then
    /// the constraints').
    pub(crate) fn solve(&mut self, rhs: &mut [f64]) {
        self.lu.solve_in_place(rhs);
    }

    /// The end of a constrained step: `v` and `μ̂` with `L_v(t, q, v) + Gᵀ μ̂ = p̃` and
    /// `G v + ∂g/∂t = 0` (`rate = ∂g/∂t` at `(t, q)`), by Newton from the guess in
    /// [`Self::v`] and `μ̂ = 0`, to the round-off of the terms.
    pub(crate) fn end_of_step(
        &mut self,
        node: &dyn SparseNode,
        node_pattern: &NodePattern,
        (g_pattern, g, rate): (&NodePattern, &[f64], &[f64]),
        (t, q, ptil): (f64, &[f64], &[f64]),
    ) -> Result<(), NewtonFailure> {
        let (n, m) = (self.n, self.m);
        self.mu.fill(0.0);
        let noise = 16.0 * f64::EPSILON * (n + m) as f64;
        for it in 0..30 {
            let mut sink =
                NodeSink::values(&mut self.lq_f, &mut self.lv, node_pattern, &mut self.blocks);
            node.eval(t, q, &self.v, &mut sink);
            if sink.outside() {
                return Err(NewtonFailure::NonFinite);
            }
            // rhs = −(L_v + Gᵀ μ̂ − p̃, G v + ∂g/∂t), and the sizes of their terms.
            let mut size = (0.0f64, 0.0f64);
            let gt_mu = &mut self.rhs[..n];
            gt_mu.fill(0.0);
            for (e, (k, a)) in g_pattern.entries().enumerate() {
                gt_mu[a] += g[e] * self.mu[k];
            }
            for a in 0..n {
                let x = gt_mu[a];
                size.0 = size.0.max(self.lv[a].abs() + x.abs() + ptil[a].abs());
                gt_mu[a] = -(self.lv[a] + x - ptil[a]);
            }
            let tail = &mut self.rhs[n..];
            for (x, r) in tail.iter_mut().zip(rate) {
                *x = -r;
                size.1 = size.1.max(r.abs());
            }
            for (e, (k, a)) in g_pattern.entries().enumerate() {
                tail[k] -= g[e] * self.v[a];
                size.1 = size.1.max((g[e] * self.v[a]).abs());
            }
            let r1 = max_norm(&self.rhs[..n]);
            let r2 = max_norm(&self.rhs[n..]);
            if !(r1.is_finite() && r2.is_finite()) {
                return Err(NewtonFailure::NonFinite);
            }
            if it > 0 && r1 <= noise * size.0 && r2 <= noise * size.1.max(f64::MIN_POSITIVE) {
                return Ok(());
            }
            let e = std::mem::take(&mut self.blocks.e);
            let factored = self.factor(node_pattern, Some(&e), g);
            self.blocks.e = e;
            factored?;
            self.lu.solve_in_place(&mut self.rhs);
            if !self.rhs.iter().all(|x| x.is_finite()) {
                return Err(NewtonFailure::NonFinite);
            }
            for (v, d) in self.v.iter_mut().zip(&self.rhs[..n]) {
                *v += d;
            }
            for (mu, d) in self.mu.iter_mut().zip(&self.rhs[n..]) {
                *mu += d;
            }
        }
        Err(NewtonFailure::MaxIterations {
            residual: max_norm(&self.rhs),
        })
    }

    /// The least-change correction of `x` onto `G x = rhs_g`: `x ← x − Gᵀ y` with
    /// `[[I, Gᵀ], [G, 0]] (d, y) = (0, G x − rhs_g)` solved as one system (DESIGN §11,
    /// initial data).
    pub(crate) fn least_change(
        &mut self,
        node_pattern: &NodePattern,
        g: &[f64],
        residual: &[f64],
        x: &mut [f64],
    ) -> Result<(), NewtonFailure> {
        let n = self.n;
        self.factor(node_pattern, None, g)?;
        self.rhs[..n].fill(0.0);
        self.rhs[n..].copy_from_slice(residual);
        self.lu.solve_in_place(&mut self.rhs);
        // `(d, y)` with `d = −Gᵀ y` and `G d = G x − rhs_g`: `x − d` satisfies the rows.
        for (xa, d) in x.iter_mut().zip(&self.rhs[..n]) {
            *xa -= d;
        }
        if x.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(NewtonFailure::NonFinite)
        }
    }
}

/// [`InitialState::projected`](crate::InitialState::projected) on sparse storage: Gauss–Newton
/// steps of least change onto `g(0, q) = 0`, then `v` onto `G v + ∂g/∂t = 0` (`rate` writes
/// `∂g/∂t` at `(0, q)`), each a solve with `[[I, Gᵀ], [G, 0]]`; `tol` is the initial-data
/// check's relative tolerance ([`crate::initial::CONSTRAINT_TOL`]).
pub(crate) fn project_initial(
    node: &dyn SparseNode,
    (q, v): (&mut [f64], &mut [f64]),
    tol: f64,
    rate: &dyn Fn(&[f64], &mut [f64]),
) -> Result<(), Error> {
    let pattern = record_node_pattern(node, 0.0, q, v)?;
    let (g_pattern, _) = record_constraint_patterns(node, 0.0, q)?;
    let mut cons = StepConstraints::new(g_pattern, 1, pattern.nnz());
    let mut saddle = Saddle::new(&pattern, &cons.pattern)?;
    let singular = |_| Error::UnsupportedConstraints {
        message: "the constraints are singular (G Gᵀ not invertible) at the initial state",
    };
    let non_finite = |_| Error::NonFiniteModel { step: 0, t: 0.0 };
    let (mut done, mut last) = (false, f64::INFINITY);
    for _ in 0..50 {
        cons.eval(node, &pattern, (0, 0.0, q), &[])
            .map_err(non_finite)?;
        let size = 1.0 + max_norm(q);
        let g = max_norm(cons.g_at(0));
        // As a distance from the constraints, in the units of `q` (see
        // `crate::initial::check_constraints`).
        let gs = max_norm(&cons.jac[..cons.pattern.nnz()]);
        done = (if gs > 0.0 { g / gs } else { g }) <= 0.01 * tol * size;
        // Quadratic convergence until round-off stops it (a step that no longer halves `g`).
        if g == 0.0 || (done && g > 0.5 * last) {
            break;
        }
        last = g;
        saddle
            .least_change(&pattern, cons.jac_at(0), cons.g_at(0), q)
            .map_err(singular)?;
    }
    cons.eval(node, &pattern, (0, 0.0, q), &[])
        .map_err(non_finite)?;
    if !done {
        let gs = max_norm(&cons.jac[..cons.pattern.nnz()]);
        let g = max_norm(cons.g_at(0));
        return Err(Error::InconsistentInitialState {
            what: "position",
            residual: if gs > 0.0 { g / gs } else { g },
            tol: tol * (1.0 + max_norm(q)),
        });
    }
    let e = cons.pattern.nnz();
    let jac = &cons.jac[..e];
    let mut gv = vec![0.0; cons.m];
    rate(q, &mut gv);
    for (i, (k, a)) in cons.pattern.entries().enumerate() {
        gv[k] += jac[i] * v[a];
    }
    saddle.least_change(&pattern, jac, &gv, v).map_err(singular)
}
