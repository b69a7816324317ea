//! The sparse node kernel (DESIGN §9): a model whose Lagrangian is a sum of local terms, and
//! whose force entries each read a few coordinates, adds each term's small dense gradient and
//! Hessian into sparse node blocks `A, B, C, E`.
//!
//! `#[forced_lagrangian]` implements [`SparseNode`] for models it can split into terms; a
//! hand-written model may implement it too. The integrator finds it through
//! [`ForcedLagrangian::sparse_node`](crate::ForcedLagrangian::sparse_node).

/// One of the four node blocks (see [`NodeJacobian`](crate::NodeJacobian)).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Block {
    /// `∂(L_q + F)/∂q`.
    A,
    /// `∂(L_q + F)/∂v`.
    B,
    /// `∂L_v/∂q`.
    C,
    /// `∂L_v/∂v`, the mass matrix.
    E,
}

/// The node pattern: the union of the nonzero patterns of `A, B, C, E`, an `n × n` pattern in
/// compressed rows (columns sorted within a row, no repeats).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NodePattern {
    n: usize,
    /// Columns: `n`, but for the `m × n` pattern of a constraint Jacobian.
    width: usize,
    row_start: Vec<usize>,
    cols: Vec<usize>,
}

impl NodePattern {
    /// The pattern of the `(row, col)` pairs, in any order and with repeats.
    ///
    /// Pairs outside `n × n` are dropped; [`NodePattern::from_pairs`]'s caller checks them
    /// with [`NodeSink::outside`] when it records.
    pub fn from_pairs(n: usize, pairs: Vec<(usize, usize)>) -> NodePattern {
        NodePattern::rectangular(n, n, pairs)
    }

    /// The `rows × width` pattern of the `(row, col)` pairs, in any order and with repeats
    /// (pairs outside are dropped): the pattern of a constraint Jacobian `G`.
    pub fn rectangular(n: usize, width: usize, mut pairs: Vec<(usize, usize)>) -> NodePattern {
        pairs.retain(|&(r, c)| r < n && c < width);
        pairs.sort_unstable();
        pairs.dedup();
        let mut row_start = vec![0; n + 1];
        for &(r, _) in &pairs {
            row_start[r + 1] += 1;
        }
        for r in 0..n {
            row_start[r + 1] += row_start[r];
        }
        NodePattern {
            n,
            width,
            row_start,
            cols: pairs.into_iter().map(|(_, c)| c).collect(),
        }
    }

    /// Degrees of freedom.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Columns (rows but for a rectangular pattern).
    pub fn width(&self) -> usize {
        self.width
    }

    /// Stored entries.
    pub fn nnz(&self) -> usize {
        self.cols.len()
    }

    /// The stored columns of `row`.
    #[inline]
    pub fn row(&self, row: usize) -> &[usize] {
        match (self.row_start.get(row), self.row_start.get(row + 1)) {
            (Some(&a), Some(&b)) => &self.cols[a..b],
            _ => &[],
        }
    }

    /// Where `(row, col)` is stored, if it is.
    ///
    /// Inlined across crates: the sparse kernels of a model (its own crate) call it, through
    /// [`NodeSink::add`], for every block entry of every node evaluation, and a call cost
    /// more than the search of a short row.
    #[inline]
    pub fn position(&self, row: usize, col: usize) -> Option<usize> {
        let (Some(&a), Some(&b)) = (self.row_start.get(row), self.row_start.get(row + 1)) else {
            return None;
        };
        let k = self.cols.get(a..b)?.binary_search(&col).ok()?;
        Some(a + k)
    }

    /// Every stored `(row, col)`, row by row.
    pub fn entries(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        (0..self.n).flat_map(move |r| self.row(r).iter().map(move |&c| (r, c)))
    }
}

/// The values of the four node blocks on a [`NodePattern`] (zeros where a block has none).
#[derive(Clone, Debug, PartialEq)]
pub struct NodeBlocks {
    /// `A` on the pattern.
    pub a: Vec<f64>,
    /// `B` on the pattern.
    pub b: Vec<f64>,
    /// `C` on the pattern.
    pub c: Vec<f64>,
    /// `E` on the pattern.
    pub e: Vec<f64>,
}

impl NodeBlocks {
    /// Zero blocks on a pattern of `nnz` entries.
    pub fn zeros(nnz: usize) -> NodeBlocks {
        NodeBlocks {
            a: vec![0.0; nnz],
            b: vec![0.0; nnz],
            c: vec![0.0; nnz],
            e: vec![0.0; nnz],
        }
    }

    /// Sets every value to zero.
    pub fn clear(&mut self) {
        for v in [&mut self.a, &mut self.b, &mut self.c, &mut self.e] {
            v.iter_mut().for_each(|x| *x = 0.0);
        }
    }
}

enum Target<'a> {
    /// Gradient only.
    Gradient,
    /// Values on a known pattern.
    Values(&'a NodePattern, &'a mut NodeBlocks),
    /// Records the pattern.
    Record(&'a mut Vec<(usize, usize)>),
}

/// Receives what a [`SparseNode`] computes at one node: the gradient `(L_q + F, L_v)`,
/// accumulated into zeroed vectors, and, when asked for, the entries of `A, B, C, E`.
pub struct NodeSink<'a> {
    lq_f: &'a mut [f64],
    lv: &'a mut [f64],
    target: Target<'a>,
    outside: bool,
}

impl<'a> NodeSink<'a> {
    /// A sink for the gradient alone. `lq_f` and `lv` are zeroed here.
    pub fn gradient(lq_f: &'a mut [f64], lv: &'a mut [f64]) -> NodeSink<'a> {
        lq_f.iter_mut().for_each(|x| *x = 0.0);
        lv.iter_mut().for_each(|x| *x = 0.0);
        NodeSink {
            lq_f,
            lv,
            target: Target::Gradient,
            outside: false,
        }
    }

    /// A sink for the gradient and the blocks on `pattern`. Everything is zeroed here.
    pub fn values(
        lq_f: &'a mut [f64],
        lv: &'a mut [f64],
        pattern: &'a NodePattern,
        blocks: &'a mut NodeBlocks,
    ) -> NodeSink<'a> {
        let mut sink = NodeSink::gradient(lq_f, lv);
        blocks.clear();
        sink.target = Target::Values(pattern, blocks);
        sink
    }

    /// A sink that records which block entries the kernel adds (their union is the
    /// [`NodePattern`]).
    pub fn record(
        lq_f: &'a mut [f64],
        lv: &'a mut [f64],
        pairs: &'a mut Vec<(usize, usize)>,
    ) -> NodeSink<'a> {
        let mut sink = NodeSink::gradient(lq_f, lv);
        sink.target = Target::Record(pairs);
        sink
    }

    /// Whether the caller wants the block entries (otherwise [`NodeSink::add`] may be
    /// skipped).
    pub fn wants_blocks(&self) -> bool {
        !matches!(self.target, Target::Gradient)
    }

    /// Adds `x` to `(L_q + F)_i`.
    #[inline]
    pub fn add_lq_f(&mut self, i: usize, x: f64) {
        match self.lq_f.get_mut(i) {
            Some(slot) => *slot += x,
            None => self.outside = true,
        }
    }

    /// Adds `x` to `(L_v)_i`.
    #[inline]
    pub fn add_lv(&mut self, i: usize, x: f64) {
        match self.lv.get_mut(i) {
            Some(slot) => *slot += x,
            None => self.outside = true,
        }
    }

    /// Adds `x` to entry `(row, col)` of `block`. Every term adds every entry it may touch,
    /// zero or not, so that the entries added do not depend on the state.
    #[inline]
    pub fn add(&mut self, block: Block, row: usize, col: usize, x: f64) {
        match &mut self.target {
            Target::Gradient => {}
            Target::Record(pairs) => pairs.push((row, col)),
            Target::Values(pattern, blocks) => match pattern.position(row, col) {
                Some(k) => {
                    let v = match block {
                        Block::A => &mut blocks.a,
                        Block::B => &mut blocks.b,
                        Block::C => &mut blocks.c,
                        Block::E => &mut blocks.e,
                    };
                    v[k] += x;
                }
                None => self.outside = true,
            },
        }
    }

    /// Whether the kernel wrote outside `n` or outside the pattern (a defect of the kernel,
    /// which the integrator reports as [`Error::InvalidModel`](crate::Error::InvalidModel)).
    pub fn outside(&self) -> bool {
        self.outside
    }
}

/// Node kernels that add local terms into sparse blocks (DESIGN §9).
///
/// The contract, which the integrator relies on:
/// - [`SparseNode::eval`] adds, for every term of `L` and every force entry, its gradient
///   into the sink, and, if [`NodeSink::wants_blocks`], every block entry the term may touch;
/// - which entries it adds does not depend on `(t, q, v)`: the integrator records the pattern
///   once per run and evaluates on it afterwards;
/// - the result equals the dense kernels ([`ForcedLagrangian::node_jacobian_at`](crate::ForcedLagrangian::node_jacobian_at))
///   up to round-off.
pub trait SparseNode {
    /// Degrees of freedom.
    fn dof(&self) -> usize;

    /// Adds the node's gradient `(L_q + F, L_v)` at `(t, q, v)` and, when asked, its block
    /// entries into `sink`.
    fn eval(&self, t: f64, q: &[f64], v: &[f64], sink: &mut NodeSink<'_>);

    /// The Lagrangian `L(t, q, v)`, for the energy.
    fn lagrangian_value(&self, t: f64, q: &[f64], v: &[f64]) -> f64;

    /// The number of holonomic constraints these kernels evaluate (DESIGN §11); none by
    /// default. A constrained model runs on the sparse backend only if this equals its
    /// [`ForcedLagrangian::constraint_count`](crate::ForcedLagrangian::constraint_count).
    fn sparse_constraint_count(&self) -> usize {
        0
    }

    /// Adds the constraints `g(t, q)` and, when [`ConstraintSink::wants_derivatives`], every
    /// entry of `G = ∂g/∂q` and of each `∂²g_k/∂q²` that may be nonzero, into `sink`. The
    /// entries added must not depend on `(t, q)`, and the values must equal
    /// [`ForcedLagrangian::constraints`](crate::ForcedLagrangian::constraints).
    fn eval_constraints(&self, t: f64, q: &[f64], sink: &mut ConstraintSink<'_>) {
        let _ = (t, q, sink);
    }

    /// Whether [`Self::eval_parameter`] computes the parameter derivatives (the macro's
    /// per-term kernels do, for a model whose Lagrangian, read with its parameters as
    /// dual numbers, still splits into local terms); none by default.
    fn has_parameter_kernels(&self) -> bool {
        false
    }

    /// Adds `∂(L_q + F)/∂θ_k` into `fq` and `∂L_v/∂θ_k` into `lv` (`N` entries each) at
    /// `(t, q, v)` with the parameters `theta` (the values of
    /// [`ForcedLagrangian::parameter_values`](crate::ForcedLagrangian::parameter_values)),
    /// term by term: each term's mixed derivatives over its own slots, at a cost linear in
    /// the model's size, where the general kernels take hyper-dual numbers over all `N`
    /// coordinates (`N²`). Returns `false`, adding nothing, where
    /// [`Self::has_parameter_kernels`] is `false`.
    #[allow(clippy::too_many_arguments)]
    fn eval_parameter(
        &self,
        t: f64,
        q: &[f64],
        v: &[f64],
        theta: &[f64],
        k: usize,
        fq: &mut [f64],
        lv: &mut [f64],
    ) -> bool {
        let _ = (t, q, v, theta, k, fq, lv);
        false
    }
}

enum ConstraintTarget<'a> {
    /// Values of `g` alone.
    Values,
    /// `g`, the entries of `G` on its pattern and the curvature `Σ_k λ_k ∂²g_k` on the node
    /// pattern (with `lambda` empty, no curvature).
    Jacobian {
        g_pattern: &'a NodePattern,
        g_values: &'a mut [f64],
        node_pattern: &'a NodePattern,
        lambda: &'a [f64],
        curvature: &'a mut [f64],
    },
    /// `H = ∂(G v)/∂q` by its entries `(k, a, Σ_c ∂²g_k/∂q_a∂q_c v_c)`, unsummed.
    #[cfg_attr(not(feature = "sparse"), allow(dead_code))]
    Rate {
        v: &'a [f64],
        entries: &'a mut Vec<(usize, usize, f64)>,
    },
    /// Records which entries of `G` and of the curvature the kernel adds.
    Record {
        g_pairs: &'a mut Vec<(usize, usize)>,
        curvature_pairs: &'a mut Vec<(usize, usize)>,
    },
}

/// Receives what [`SparseNode::eval_constraints`] computes at one position: the values
/// `g_k(t, q)`, accumulated into a zeroed vector, and, when asked for, the entries of
/// `G = ∂g/∂q` and of the multipliers' curvature `Σ_k λ_k ∂²g_k/∂q²` (DESIGN §11).
pub struct ConstraintSink<'a> {
    g: &'a mut [f64],
    target: ConstraintTarget<'a>,
    outside: bool,
}

impl<'a> ConstraintSink<'a> {
    /// A sink for the values `g` alone (zeroed here).
    pub fn values(g: &'a mut [f64]) -> ConstraintSink<'a> {
        g.iter_mut().for_each(|x| *x = 0.0);
        ConstraintSink {
            g,
            target: ConstraintTarget::Values,
            outside: false,
        }
    }

    /// A sink for `g`, for `G` on `g_pattern` (an `m`-row pattern) and, weighted by
    /// `lambda` (`m` values, or none to skip it), for the curvature on `node_pattern`.
    /// Everything is zeroed here.
    pub fn jacobian(
        g: &'a mut [f64],
        (g_pattern, g_values): (&'a NodePattern, &'a mut [f64]),
        node_pattern: &'a NodePattern,
        lambda: &'a [f64],
        curvature: &'a mut [f64],
    ) -> ConstraintSink<'a> {
        g_values.iter_mut().for_each(|x| *x = 0.0);
        curvature.iter_mut().for_each(|x| *x = 0.0);
        let mut sink = ConstraintSink::values(g);
        sink.target = ConstraintTarget::Jacobian {
            g_pattern,
            g_values,
            node_pattern,
            lambda,
            curvature,
        };
        sink
    }

    /// A sink for `g` and for `H = ∂(G v)/∂q` at the velocity `v`, by its entries into
    /// `entries` (cleared here; entries of equal `(k, a)` add up), from the constraints'
    /// second derivatives.
    #[cfg_attr(not(feature = "sparse"), allow(dead_code))]
    pub(crate) fn rate(
        g: &'a mut [f64],
        v: &'a [f64],
        entries: &'a mut Vec<(usize, usize, f64)>,
    ) -> ConstraintSink<'a> {
        entries.clear();
        let mut sink = ConstraintSink::values(g);
        sink.target = ConstraintTarget::Rate { v, entries };
        sink
    }

    /// A sink that records the entries of `G` and of the curvature that the kernel adds.
    pub fn record(
        g: &'a mut [f64],
        g_pairs: &'a mut Vec<(usize, usize)>,
        curvature_pairs: &'a mut Vec<(usize, usize)>,
    ) -> ConstraintSink<'a> {
        let mut sink = ConstraintSink::values(g);
        sink.target = ConstraintTarget::Record {
            g_pairs,
            curvature_pairs,
        };
        sink
    }

    /// Whether the caller wants `G` and the curvature (otherwise
    /// [`ConstraintSink::add_gradient`] and [`ConstraintSink::add_curvature`] may be skipped).
    pub fn wants_derivatives(&self) -> bool {
        !matches!(self.target, ConstraintTarget::Values)
    }

    /// Adds `x` to `g_k`.
    #[inline]
    pub fn add_value(&mut self, k: usize, x: f64) {
        match self.g.get_mut(k) {
            Some(slot) => *slot += x,
            None => self.outside = true,
        }
    }

    /// Adds `x` to `G[k, a] = ∂g_k/∂q_a`. As with [`NodeSink::add`], every entry that may be
    /// nonzero is added, whatever the state.
    #[inline]
    pub fn add_gradient(&mut self, k: usize, a: usize, x: f64) {
        match &mut self.target {
            ConstraintTarget::Values | ConstraintTarget::Rate { .. } => {}
            ConstraintTarget::Record { g_pairs, .. } => g_pairs.push((k, a)),
            ConstraintTarget::Jacobian {
                g_pattern,
                g_values,
                ..
            } => match g_pattern.position(k, a) {
                Some(i) => g_values[i] += x,
                None => self.outside = true,
            },
        }
    }

    /// Adds `x = ∂²g_k/∂q_a∂q_c` to the curvature, entry `(a, c)`, weighted by `λ_k`.
    #[inline]
    pub fn add_curvature(&mut self, k: usize, a: usize, c: usize, x: f64) {
        match &mut self.target {
            ConstraintTarget::Values => {}
            ConstraintTarget::Rate { v, entries } => match v.get(c) {
                Some(vc) => entries.push((k, a, x * vc)),
                None => self.outside = true,
            },
            ConstraintTarget::Record {
                curvature_pairs, ..
            } => curvature_pairs.push((a, c)),
            ConstraintTarget::Jacobian {
                node_pattern,
                lambda,
                curvature,
                ..
            } => {
                if lambda.is_empty() {
                    return;
                }
                match (node_pattern.position(a, c), lambda.get(k)) {
                    (Some(i), Some(l)) => curvature[i] += l * x,
                    _ => self.outside = true,
                }
            }
        }
    }

    /// Whether the kernel wrote outside `m`, `n` or the recorded patterns.
    pub fn outside(&self) -> bool {
        self.outside
    }
}

/// Sparse constraint kernels for a model whose [`SparseNode`] kernels do not evaluate its
/// constraints: `g`, `G` and the curvature from the model's generic
/// [`ForcedLagrangian::constraints`](crate::ForcedLagrangian::constraints) with dual numbers,
/// the node kernels the model's own.
///
/// `G` costs `N` evaluations of `g` with a first-order dual number, one per coordinate; every
/// entry is computed, so an entry outside the recorded pattern is seen (and refused), never
/// dropped. The curvature costs one evaluation with a hyper-dual number per pair `(a, c)` of
/// coordinates that one constraint reads, as the pattern of `G` records them: it serves the
/// Newton iteration only, whose residual (`g` and `Gᵀλ`) is exact either way. The pattern is
/// recorded from the gradients at the state given and at a perturbed one, so that an entry
/// that happens to vanish there is still recorded.
#[cfg(feature = "sparse")]
pub(crate) struct DualConstraints<'a, M, const N: usize> {
    /// The model.
    pub(crate) model: &'a M,
    /// Its own node kernels.
    pub(crate) node: &'a dyn SparseNode,
}

#[cfg(feature = "sparse")]
impl<M: crate::ForcedLagrangian<N>, const N: usize> DualConstraints<'_, M, N> {
    /// The gradients `∂g_k/∂q_a` at `(t, q)`, by `a`: `grads[a * m + k]`.
    fn gradients(&self, t: f64, q: &[f64], grads: &mut [f64]) {
        use num_dual::Dual64;
        let m = self.model.constraint_count();
        let mut x: Vec<Dual64> = q.iter().map(|&v| Dual64::from(v)).collect();
        let mut g = vec![Dual64::from(0.0); m];
        for a in 0..N.min(x.len()) {
            x[a].eps = 1.0;
            if let Ok(arr) = <&[Dual64; N]>::try_from(&x[..]) {
                self.model.constraints(Dual64::from(t), arr, &mut g);
            }
            for (k, gk) in g.iter().enumerate() {
                grads[a * m + k] = gk.eps;
            }
            x[a].eps = 0.0;
        }
    }
}

#[cfg(feature = "sparse")]
impl<M: crate::ForcedLagrangian<N>, const N: usize> SparseNode for DualConstraints<'_, M, N> {
    fn dof(&self) -> usize {
        self.node.dof()
    }

    fn eval(&self, t: f64, q: &[f64], v: &[f64], sink: &mut NodeSink<'_>) {
        self.node.eval(t, q, v, sink)
    }

    fn lagrangian_value(&self, t: f64, q: &[f64], v: &[f64]) -> f64 {
        self.node.lagrangian_value(t, q, v)
    }

    fn has_parameter_kernels(&self) -> bool {
        self.node.has_parameter_kernels()
    }

    fn eval_parameter(
        &self,
        t: f64,
        q: &[f64],
        v: &[f64],
        theta: &[f64],
        k: usize,
        fq: &mut [f64],
        lv: &mut [f64],
    ) -> bool {
        self.node.eval_parameter(t, q, v, theta, k, fq, lv)
    }

    fn sparse_constraint_count(&self) -> usize {
        self.model.constraint_count()
    }

    fn eval_constraints(&self, t: f64, q: &[f64], sink: &mut ConstraintSink<'_>) {
        use num_dual::HyperDual64;
        let m = self.model.constraint_count();
        if q.len() != N {
            sink.outside = true;
            return;
        }
        let mut g = vec![0.0; m];
        if let Ok(arr) = <&[f64; N]>::try_from(q) {
            self.model.constraints(t, arr, &mut g);
        }
        for (k, x) in g.iter().enumerate() {
            sink.add_value(k, *x);
        }
        if !sink.wants_derivatives() {
            return;
        }
        let mut grads = vec![0.0; N * m];
        self.gradients(t, q, &mut grads);
        // The coordinates each constraint reads: the recorded pattern's rows, or, when
        // recording, the gradients' nonzeros here and at a perturbed state.
        let mut reads: Vec<Vec<usize>> = vec![Vec::new(); m];
        match &sink.target {
            ConstraintTarget::Jacobian { g_pattern, .. } => {
                for (k, r) in reads.iter_mut().enumerate() {
                    r.extend_from_slice(g_pattern.row(k));
                }
            }
            _ => {
                let mut probe = vec![0.0; N * m];
                let shifted: Vec<f64> = q
                    .iter()
                    .enumerate()
                    .map(|(a, x)| x + (1e-3 * (1.0 + x.abs())) * (0.7 + 0.37 * a as f64).sin())
                    .collect();
                self.gradients(t, &shifted, &mut probe);
                for (k, r) in reads.iter_mut().enumerate() {
                    r.extend(
                        (0..N).filter(|&a| grads[a * m + k] != 0.0 || probe[a * m + k] != 0.0),
                    );
                }
            }
        }
        for a in 0..N {
            for k in 0..m {
                let x = grads[a * m + k];
                if x != 0.0 || reads[k].binary_search(&a).is_ok() {
                    sink.add_gradient(k, a, x);
                }
            }
        }
        // The curvature, pair by pair over the coordinates one constraint reads (not asked
        // for without multipliers).
        if let ConstraintTarget::Jacobian { lambda, .. } = &sink.target
            && lambda.is_empty()
        {
            return;
        }
        let mut pairs: Vec<(usize, usize)> = reads
            .iter()
            .flat_map(|r| r.iter().flat_map(move |&a| r.iter().map(move |&c| (a, c))))
            .collect();
        pairs.sort_unstable();
        pairs.dedup();
        let mut x: Vec<HyperDual64> = q.iter().map(|&v| HyperDual64::from(v)).collect();
        let mut h = vec![HyperDual64::from(0.0); m];
        for (a, c) in pairs {
            x[a].eps1 = 1.0;
            x[c].eps2 = 1.0;
            if let Ok(arr) = <&[HyperDual64; N]>::try_from(&x[..]) {
                self.model.constraints(HyperDual64::from(t), arr, &mut h);
            }
            x[a].eps1 = 0.0;
            x[c].eps2 = 0.0;
            for (k, hk) in h.iter().enumerate() {
                if reads[k].binary_search(&a).is_ok() && reads[k].binary_search(&c).is_ok() {
                    sink.add_curvature(k, a, c, hk.eps1eps2);
                }
            }
        }
    }
}
