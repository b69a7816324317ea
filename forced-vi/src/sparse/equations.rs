//! The step equations of DESIGN §3 on sparse storage: the residual `G_j` and the Jacobian
//! `∂G_j/∂x_m` in the increments `Z_j = x_j − q_k`, from sparse node kernels. The scheme's
//! coefficients, and the chain-rule terms of the Jacobian, are the dense path's
//! ([`Scheme`], [`Scheme::jacobian_terms`]); only the storage differs.

use crate::error::NewtonFailure;
use crate::model::{NodeBlocks, NodePattern, NodeSink, SparseNode};
use crate::scheme::Scheme;
use crate::sparse::constraints::StepConstraints;
use crate::sparse::newton::SparseSystem;
use crate::sparse::pattern::StepPattern;

/// The node kernels of a run: the model's own, or an adapter the run owns (such as
/// [`crate::model::DualConstraints`]).
pub(crate) enum NodeRef<'a> {
    /// The model's kernels.
    Borrowed(&'a dyn SparseNode),
    /// Kernels made for the run.
    Owned(Box<dyn SparseNode + 'a>),
}

impl NodeRef<'_> {
    /// The kernels.
    #[inline(always)]
    pub(crate) fn get(&self) -> &dyn SparseNode {
        match self {
            NodeRef::Borrowed(n) => *n,
            NodeRef::Owned(n) => n.as_ref(),
        }
    }
}

/// The nonlinear system of one sparse step. Vectors of unknowns and residuals are
/// coordinate-major (see [`crate::sparse::pattern`]); node vectors are `r` blocks of `n`.
pub(crate) struct SparseStep<'a> {
    pub(crate) node: NodeRef<'a>,
    pub(crate) scheme: &'a Scheme,
    pub(crate) n: usize,
    pub(crate) h: f64,
    /// The step's start time; node `i` is at `t0 + c_i h` (DESIGN §7).
    pub(crate) t0: f64,
    pub(crate) q0: Vec<f64>,
    pub(crate) p0: Vec<f64>,
    /// Positions, velocities, `L_q + F` and `L_v` at the quadrature nodes.
    pub(crate) xs: Vec<f64>,
    pub(crate) vs: Vec<f64>,
    pub(crate) fq: Vec<f64>,
    pub(crate) lv: Vec<f64>,
    pub(crate) pattern: NodePattern,
    pub(crate) blocks: Vec<NodeBlocks>,
    pub(crate) step_pattern: StepPattern,
    /// A kernel wrote outside the recorded pattern (a defect of the model).
    pub(crate) outside: bool,
    /// Holonomic constraints (DESIGN §11), with their unknowns and rows after the
    /// increments' (see [`StepPattern`]).
    pub(crate) cons: Option<StepConstraints>,
    /// Scratch: the multipliers of one control point.
    lam: Vec<f64>,
    /// `h |A| |x|` at the last Jacobian ([`SparseSystem::residual_noise`]), and that `h`.
    noise: f64,
    noise_h: f64,
    /// The same per coordinate: `h max_i Σ_b |A_i|_ab |x_i|_b` over the nodes `i`.
    noise_rows: Vec<f64>,
    /// The residual's scale for this solve: the whole step's (the constraint rows'), and
    /// each coordinate's (its gradient rows'; [`crate::backend::coordinate_scales`]).
    pub(crate) scale: f64,
    pub(crate) coord_scale: Vec<f64>,
    /// The model promises a constant mass matrix (`E` the same at every node and step, and
    /// `C ≡ 0`): the `E` part of the Jacobian is assembled once, for a unit step, into
    /// `e_part` (on the first Jacobian, `e_built`; the buffer is made with the others, so
    /// that no step allocates), and each Jacobian scales it by `1/h` and adds only the terms
    /// on `A` and `B` (see [`SparseSystem::jacobian`]).
    constant_mass: bool,
    e_part: Vec<f64>,
    e_built: bool,
    /// The largest row sums of `|A|` and `|B|` over the node blocks ([`Self::force_gain`]),
    /// made on the first call after the blocks change: an adaptive step asks twice, and the
    /// blocks change only with the Jacobian (on a 256-coordinate chain, adaptive lobatto4,
    /// the scan was 4.5 % of the run's instructions with 90 scans for 7 Jacobians).
    gain: std::cell::Cell<Option<(f64, f64)>>,
}

impl<'a> SparseStep<'a> {
    /// `|A| |x|` as of the last Jacobian (see [`crate::newton::force_round_off_rate`]), plus
    /// `|B| |v|` with the node velocities of the last residual.
    pub(crate) fn force_round_off_rate(&self) -> f64 {
        let velocities = crate::newton::force_round_off(
            1.0,
            self.blocks.iter().map(|b| b.b.as_slice()),
            [self.vs.as_slice()],
        );
        crate::newton::force_round_off_rate(self.noise, self.noise_h) + velocities
    }

    /// `h |A| + |B|` over the node blocks of the last Jacobian, in row sums (see
    /// [`crate::backend::StepBackend::force_gain`]).
    pub(crate) fn force_gain(&self, h: f64) -> f64 {
        if let Some((a, b)) = self.gain.get() {
            return h * a + b;
        }
        // The blocks' values are stored row by row, in the pattern's compressed rows.
        let largest_row = |vals: &[f64]| {
            let (mut best, mut k) = (0.0f64, 0);
            for r in 0..self.pattern.n() {
                let len = self.pattern.row(r).len();
                let sum: f64 = vals
                    .get(k..k + len)
                    .map_or(0.0, |row| row.iter().map(|v| v.abs()).sum());
                best = best.max(sum);
                k += len;
            }
            best
        };
        let (a, b) = self.blocks.iter().fold((0.0f64, 0.0f64), |(a, b), blk| {
            (a.max(largest_row(&blk.a)), b.max(largest_row(&blk.b)))
        });
        self.gain.set(Some((a, b)));
        h * a + b
    }

    /// Buffers for `node` and `scheme` on a recorded pattern; for a constrained model, with
    /// the pattern of `G` (whose curvature entries the node pattern holds).
    pub(crate) fn new(
        node: NodeRef<'a>,
        scheme: &'a Scheme,
        pattern: NodePattern,
        g_pattern: Option<NodePattern>,
        constant_mass: bool,
    ) -> Self {
        let (n, r, s) = (pattern.n(), scheme.quadrature_nodes(), scheme.stages());
        let step_pattern = StepPattern::new(&pattern, s, g_pattern.as_ref());
        // The entries of the step Jacobian.
        let values_len = step_pattern.row_idx.len();
        let cons = g_pattern.map(|g| StepConstraints::new(g, s, pattern.nnz()));
        let lam = vec![0.0; cons.as_ref().map_or(0, |c| c.m)];
        SparseStep {
            node,
            scheme,
            n,
            h: 1.0,
            t0: 0.0,
            q0: vec![0.0; n],
            p0: vec![0.0; n],
            xs: vec![0.0; r * n],
            vs: vec![0.0; r * n],
            fq: vec![0.0; r * n],
            lv: vec![0.0; r * n],
            blocks: (0..r).map(|_| NodeBlocks::zeros(pattern.nnz())).collect(),
            pattern,
            step_pattern,
            outside: false,
            cons,
            lam,
            noise: 0.0,
            noise_h: 0.0,
            noise_rows: vec![0.0; n],
            scale: 0.0,
            coord_scale: vec![0.0; n],
            e_part: vec![0.0; if constant_mass { values_len } else { 0 }],
            constant_mass,
            e_built: false,
            gain: std::cell::Cell::new(None),
        }
    }

    /// The control point `j`'s position: `q_k` or quadrature node `j` (Lobatto schemes).
    fn control_x(&self, j: usize) -> &[f64] {
        let n = self.n;
        if j == 0 {
            &self.q0
        } else {
            &self.xs[j * n..(j + 1) * n]
        }
    }

    /// `g` and `G` at every control point; with `curvature`, the curvature at control point
    /// `j` (`1 ≤ j ≤ s − 2`) is added to the Jacobian `values` as each is evaluated.
    fn eval_constraints(
        &mut self,
        z: &[f64],
        mut values: Option<&mut [f64]>,
    ) -> Result<(), NewtonFailure> {
        let Some(mut cons) = self.cons.take() else {
            return Ok(());
        };
        let (sch, n, h) = (self.scheme, self.n, self.h);
        let (s, s1, m) = (sch.stages(), sch.stages() - 1, cons.m);
        let nz = n * s1;
        let mut out = Ok(());
        for j in 0..s {
            let t = self.t0 + sch.c()[j] * h;
            let curv = values.is_some() && j >= 1 && j + 1 < s;
            if curv {
                for k in 0..m {
                    self.lam[k] = z[nz + k * s1 + j];
                }
            }
            let lam: &[f64] = if curv { &self.lam } else { &[] };
            let x = self.control_x(j);
            if let Err(e) = cons.eval(self.node.get(), &self.pattern, (j, t, x), lam) {
                self.outside |= cons.outside;
                out = Err(e);
                break;
            }
            if let (true, Some(vals)) = (curv, values.as_deref_mut()) {
                let hb = sch.b()[j] / h;
                let base = &self.step_pattern.base;
                for (k, c) in cons.curvature.iter().enumerate() {
                    vals[base[k * s1 + j - 1] + j] -= hb * c;
                }
            }
        }
        self.cons = Some(cons);
        out
    }

    /// The node positions and velocities of the step polynomial with increments `z`.
    fn nodes(&mut self, z: &[f64]) {
        let (sch, n) = (self.scheme, self.n);
        let s1 = sch.stages() - 1;
        let inv_h = 1.0 / self.h;
        for i in 0..sch.quadrature_nodes() {
            // Node `i`'s row of `Φ` and `Ψ` for the control points `1 … s − 1`, taken once
            // (not entry by entry for every coordinate).
            let (phi, psi) = sch.basis_rows(i);
            let (phi, psi) = (&phi[1..=s1], &psi[1..=s1]);
            let (x, v) = (
                &mut self.xs[i * n..(i + 1) * n],
                &mut self.vs[i * n..(i + 1) * n],
            );
            let coords = x.iter_mut().zip(v.iter_mut()).zip(z.chunks_exact(s1));
            for (((xa, va), za), &q0a) in coords.zip(&self.q0) {
                let (mut xs, mut vs) = (q0a, 0.0);
                for ((&zm, &ph), &ps) in za.iter().zip(phi).zip(psi) {
                    xs += ph * zm;
                    vs += ps * zm;
                }
                *xa = xs;
                *va = vs * inv_h;
            }
        }
    }

    /// The time of quadrature node `i`.
    pub(crate) fn node_time(&self, i: usize) -> f64 {
        self.t0 + self.scheme.c()[i] * self.h
    }

    /// Evaluates the node gradients (and, with `blocks`, the node blocks) at the nodes.
    fn eval_nodes(&mut self, blocks: bool) -> Result<(), NewtonFailure> {
        let n = self.n;
        if blocks {
            self.gain.set(None);
        }
        for i in 0..self.scheme.quadrature_nodes() {
            let t = self.node_time(i);
            let range = i * n..(i + 1) * n;
            let (x, v) = (&self.xs[range.clone()], &self.vs[range.clone()]);
            let (fq, lv) = (&mut self.fq[range.clone()], &mut self.lv[range]);
            let mut sink = if blocks {
                NodeSink::values(fq, lv, &self.pattern, &mut self.blocks[i])
            } else {
                NodeSink::gradient(fq, lv)
            };
            self.node.get().eval(t, x, v, &mut sink);
            if sink.outside() {
                self.outside = true;
                return Err(NewtonFailure::NonFinite);
            }
            let finite = |s: &[f64]| s.iter().all(|x| x.is_finite());
            if !(finite(&self.fq[i * n..(i + 1) * n]) && finite(&self.lv[i * n..(i + 1) * n])) {
                return Err(NewtonFailure::NonFinite);
            }
        }
        Ok(())
    }
}

impl SparseSystem for SparseStep<'_> {
    fn residual(&mut self, z: &[f64], r: &mut [f64]) -> Result<(), NewtonFailure> {
        self.nodes(z);
        self.eval_nodes(false)?;
        let (sch, n, h) = (self.scheme, self.n, self.h);
        let s1 = sch.stages() - 1;
        let nodes = sch.quadrature_nodes();
        let (fq, lv) = (&self.fq[..nodes * n], &self.lv[..nodes * n]);
        // As on the dense path: row `j` weighs node `i`'s `L_q + F` by `h b_i Φ_ij` and its
        // `L_v` by `b_i Ψ_ij` (the scheme's residual weights, taken once per row).
        for (a, ra) in r.chunks_exact_mut(s1).take(n).enumerate() {
            for (j, rj) in ra.iter_mut().enumerate() {
                let (wf, wl) = sch.residual_weights(j);
                let mut g = if j == 0 { self.p0[a] } else { 0.0 };
                for (i, (&f, &l)) in wf.iter().zip(wl).enumerate() {
                    g += f * h * fq[i * n + a] + l * lv[i * n + a];
                }
                *rj = g;
            }
        }
        if self.cons.is_some() {
            self.eval_constraints(z, None)?;
            let Some(cons) = &self.cons else {
                return Ok(());
            };
            let (m, nz) = (cons.m, n * s1);
            for j in 0..s1 {
                // `−h b_j G(x_j)ᵀ λ_j = −(b_j/h) G(x_j)ᵀ ŵ_j` in the gradient rows.
                let hb = sch.b()[j] / h;
                for (e, (k, a)) in cons.pattern.entries().enumerate() {
                    r[a * s1 + j] -= hb * cons.jac_at(j)[e] * z[nz + k * s1 + j];
                }
                // The rows `g(x_{j+1})`.
                for k in 0..m {
                    r[nz + k * s1 + j] = cons.g_at(j + 1)[k];
                }
            }
        }
        Ok(())
    }

    fn jacobian(&mut self, z: &[f64], values: &mut [f64]) -> Result<(), NewtonFailure> {
        self.nodes(z);
        self.eval_nodes(true)?;
        let (h, s1) = (self.h, self.scheme.stages() - 1);
        self.noise = crate::newton::force_round_off(
            h,
            self.blocks.iter().map(|b| b.a.as_slice()),
            [self.xs.as_slice(), self.q0.as_slice()],
        );
        self.noise_h = h;
        self.noise_rows.fill(0.0);
        let n = self.n;
        for (blk, x) in self.blocks.iter().zip(self.xs.chunks(n.max(1))) {
            // Row sums of `|A_i| |x_i|`, each kept as the row's largest over the nodes.
            let mut row = usize::MAX;
            let mut sum = 0.0;
            for (k, (r, c)) in self.pattern.entries().enumerate() {
                if r != row {
                    if let Some(m) = self.noise_rows.get_mut(row) {
                        *m = m.max(h * sum);
                    }
                    (row, sum) = (r, 0.0);
                }
                sum += blk.a.get(k).map_or(0.0, |a| a.abs()) * x.get(c).map_or(0.0, |x| x.abs());
            }
            if let Some(m) = self.noise_rows.get_mut(row) {
                *m = m.max(h * sum);
            }
        }
        let base = &self.step_pattern.base;
        let nnz = self.pattern.nnz();
        if self.constant_mass {
            // As on the dense path: `E` is the same at every node and every step, so its
            // part (every term's `E` coefficient) is built once and scaled by `1/h`, and
            // `C ≡ 0`, so the terms left are those on `A` (`s − 1` of them for Lobatto) and
            // on `B` (`(s − 1)²`), one block each, instead of four blocks in all `s (s − 1)²`
            // terms.
            if !self.e_built || self.e_part.len() != values.len() {
                // `values` holds the pattern's entries, as `e_part` already does: the
                // resize changes nothing (and does not allocate).
                self.e_part.resize(values.len(), 0.0);
                self.e_part.fill(0.0);
                self.e_built = true;
                let e = &self.blocks[0].e;
                for t in self.scheme.jacobian_terms() {
                    for (k, &ek) in e.iter().enumerate().take(nnz) {
                        self.e_part[base[k * s1 + t.m - 1] + t.j] += t.e * ek;
                    }
                }
            }
            let inv_h = 1.0 / h;
            for (v, e) in values.iter_mut().zip(&self.e_part) {
                *v = e * inv_h;
            }
            let (a_terms, b_terms) = self.scheme.force_jacobian_terms();
            for (t, blk, coef) in a_terms
                .iter()
                .map(|t| (t, &self.blocks[t.i].a, t.a * h))
                .chain(b_terms.iter().map(|t| (t, &self.blocks[t.i].b, t.b)))
            {
                for (k, &x) in blk.iter().enumerate().take(nnz) {
                    values[base[k * s1 + t.m - 1] + t.j] += coef * x;
                }
            }
        } else {
            values.fill(0.0);
            for t in self.scheme.jacobian_terms() {
                let blk = &self.blocks[t.i];
                let (ca, cb, cc, ce) = (t.a * h, t.b, t.c, t.e / h);
                for k in 0..nnz {
                    let x = ca * blk.a[k] + cb * blk.b[k] + cc * blk.c[k] + ce * blk.e[k];
                    values[base[k * s1 + t.m - 1] + t.j] += x;
                }
            }
        }
        if self.cons.is_some() {
            self.eval_constraints(z, Some(values))?;
            let Some(cons) = &self.cons else {
                return Ok(());
            };
            let sp = &self.step_pattern;
            for j in 0..s1 {
                let hb = self.scheme.b()[j] / h;
                let (gt, g) = (cons.jac_at(j), cons.jac_at(j + 1));
                for e in 0..cons.pattern.nnz() {
                    values[sp.g_cols[e * s1 + j]] = -hb * gt[e];
                    values[sp.g_rows[e * s1 + j]] = g[e];
                }
            }
        }
        Ok(())
    }

    fn residual_noise(&self) -> f64 {
        self.noise
    }

    /// A constrained model's rows share one floor, the largest: the constraint forces
    /// `G(x)ᵀ λ` are computed from absolute positions, and their round-off (on a chain,
    /// `ε |x| / ℓ` relative, with `ℓ` a link's length: 150 ε of the row's linear terms on
    /// the 256-link chain, lobatto3) is not in the row's own terms.
    fn rows_apart(&self) -> bool {
        self.cons.is_none()
    }

    /// The rows of one coordinate (at every control point, together in this layout)
    /// form a group.
    fn group_max(&self, out: &mut [f64]) {
        let s1 = (self.scheme.stages() - 1).max(1);
        for rows in out.chunks_mut(s1) {
            let largest = rows.iter().fold(0.0f64, |m, x| m.max(*x));
            rows.fill(largest);
        }
    }

    /// Each coordinate's gradient rows get its own scale, the constraint rows the step's
    /// (a constrained model: every row the step's; see [`SparseSystem::rows_apart`]).
    fn row_scales(&self, scale: f64, out: &mut [f64]) {
        if self.cons.is_some() {
            out.fill(scale);
            return;
        }
        let s1 = self.scheme.stages() - 1;
        let nz = s1 * self.n;
        let (grad, cons) = out.split_at_mut(nz.min(out.len()));
        for (rows, c) in grad.chunks_mut(s1).zip(&self.coord_scale) {
            rows.fill(*c);
        }
        cons.fill(self.scale);
    }

    /// Each coordinate's gradient rows get its own forces' round-off, the constraint rows
    /// the largest.
    fn add_row_noise(&self, out: &mut [f64]) {
        if self.cons.is_some() {
            out.iter_mut().for_each(|x| *x += self.noise);
            return;
        }
        let s1 = self.scheme.stages() - 1;
        let nz = s1 * self.n;
        let (grad, cons) = out.split_at_mut(nz.min(out.len()));
        for (rows, n) in grad.chunks_mut(s1).zip(&self.noise_rows) {
            rows.iter_mut().for_each(|x| *x += n);
        }
        cons.iter_mut().for_each(|x| *x += self.noise);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Block, NodeSink};
    use crate::sparse::pattern::record_node_pattern;

    /// A damped chain with cubic springs and masses `1 + i / 4`: a constant mass matrix
    /// (`C ≡ 0`), and `A`, `B`, `E` all nonzero.
    struct Chain(usize);

    impl SparseNode for Chain {
        fn dof(&self) -> usize {
            self.0
        }
        fn eval(&self, _t: f64, q: &[f64], v: &[f64], sink: &mut NodeSink<'_>) {
            let n = self.0;
            for (i, &vi) in v.iter().enumerate().take(n) {
                let m = 1.0 + i as f64 / 4.0;
                sink.add_lv(i, m * vi);
                sink.add(Block::E, i, i, m);
                sink.add_lq_f(i, -0.3 * vi);
                sink.add(Block::B, i, i, -0.3);
            }
            for i in 0..n - 1 {
                // V = d²/2 + d⁴/4 with d = q_{i+1} − q_i: L_q = −∂V/∂q.
                let d = q[i + 1] - q[i];
                let (f, k) = (d + d * d * d, 1.0 + 3.0 * d * d);
                sink.add_lq_f(i, f);
                sink.add_lq_f(i + 1, -f);
                for (r, c, s) in [
                    (i, i, -1.0),
                    (i, i + 1, 1.0),
                    (i + 1, i, 1.0),
                    (i + 1, i + 1, -1.0),
                ] {
                    sink.add(Block::A, r, c, s * k);
                }
            }
        }
        fn lagrangian_value(&self, _t: f64, _q: &[f64], _v: &[f64]) -> f64 {
            0.0
        }
    }

    /// The constant-mass assembly (the `E` part built once and scaled, then the terms on
    /// `A` and `B`) gives the Jacobian of the general one (four blocks in every term), for
    /// steps of different sizes with the same `E` part.
    #[test]
    fn constant_mass_jacobian_matches_the_general_assembly() {
        let chain = Chain(6);
        let q: Vec<f64> = (0..6).map(|i| 0.1 * i as f64 - 0.2).collect();
        let v: Vec<f64> = (0..6).map(|i| 0.3 - 0.05 * i as f64).collect();
        for s in 2..=6 {
            let scheme = Scheme::lobatto(s).expect("scheme");
            let pattern = record_node_pattern(&chain, 0.0, &q, &v).expect("pattern");
            let step = |constant_mass| {
                let node = NodeRef::Borrowed(&chain);
                let mut st = SparseStep::new(node, &scheme, pattern.clone(), None, constant_mass);
                st.q0.copy_from_slice(&q);
                st
            };
            let (mut fast, mut general) = (step(true), step(false));
            let dim = fast.step_pattern.dim;
            let z: Vec<f64> = (0..dim)
                .map(|k| 0.01 * ((k * 7 % 5) as f64 - 2.0))
                .collect();
            let nnz = fast.step_pattern.row_idx.len();
            for h in [0.3, 0.05, 0.3] {
                fast.h = h;
                general.h = h;
                let (mut a, mut b) = (vec![0.0; nnz], vec![0.0; nnz]);
                fast.jacobian(&z, &mut a).expect("jacobian");
                general.jacobian(&z, &mut b).expect("jacobian");
                let size = b.iter().fold(0.0f64, |m, x| m.max(x.abs()));
                let diff = a
                    .iter()
                    .zip(&b)
                    .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
                assert!(size > 1.0, "lobatto{s}: empty Jacobian");
                assert!(
                    diff <= 8.0 * f64::EPSILON * size,
                    "lobatto{s}, h = {h}: {diff:e} of {size:e}"
                );
            }
        }
    }
}
