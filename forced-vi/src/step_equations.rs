//! The step equations of DESIGN §3: the residual `G_j` and its Jacobian `∂G_j/∂x_m`,
//! assembled from the node kernels for any scheme `(d, c, b)`, in the increments
//! `Z_j = x_j − q_k`. This is the only place where they are written.

use nalgebra::{DMatrix, DVector, SMatrix, SVector};

use crate::buffers::{zero_matrix, zeros};
use crate::error::NewtonFailure;
use crate::model::{ForcedLagrangian, NodeGradient, NodeJacobian};
use crate::newton::NonlinearSystem;
use crate::scalar::all_finite;
use crate::scheme::Scheme;

/// The nonlinear system of one step, in the increments `Z_j = x_j − q_k` (DESIGN §3).
pub(crate) struct StepProblem<'a, M, const N: usize> {
    pub(crate) model: &'a M,
    pub(crate) scheme: &'a Scheme,
    pub(crate) h: f64,
    /// The step's start time; node `i` is at `t0 + c_i h` (DESIGN §7).
    pub(crate) t0: f64,
    pub(crate) q0: SVector<f64, N>,
    pub(crate) p0: SVector<f64, N>,
    pub(crate) xs: Vec<SVector<f64, N>>,
    pub(crate) vs: Vec<SVector<f64, N>>,
    pub(crate) grads: Vec<NodeGradient<N>>,
    pub(crate) jacs: Vec<NodeJacobian<N>>,
    /// For a constant mass matrix, the `E` part of the Jacobian of a unit step, built on the
    /// first Jacobian (`base_built`); a step of size `h` takes it over `h`.
    pub(crate) base: DMatrix<f64>,
    pub(crate) base_built: bool,
    /// Holonomic constraints (DESIGN §11): their number `m`, and scratch for `g` and, per
    /// control point, `G = ∂g/∂q` (`m × N`). The unknowns `ŵ_j = h² λ_j`, `j = 0 … s − 2`,
    /// follow the increments in `z`; the rows `g(x_j)`, `j = 1 … s − 1`, follow the
    /// gradient rows.
    pub(crate) cons: usize,
    pub(crate) gval: Vec<f64>,
    pub(crate) gjac: Vec<DMatrix<f64>>,
    /// The factors on each constraint's rows and on its unknowns, set for each solve
    /// ([`StepProblem::scale_constraints`]): the Newton iteration's unknowns are
    /// `ŵ_j / col_scale`; and scratch for the multipliers `ŵ_j` of a control point.
    pub(crate) row_scale: Vec<f64>,
    pub(crate) col_scale: Vec<f64>,
    pub(crate) lam: Vec<f64>,
    /// The node blocks in `jacs` were given (interpolated from another scheme's, for the
    /// error estimate of [`crate::control`]): the Jacobian is assembled from them without
    /// evaluating the node kernels.
    pub(crate) blocks_given: bool,
    /// `h |A| |x|` at the last Jacobian ([`NonlinearSystem::residual_noise`]), and that `h`.
    pub(crate) noise: f64,
    pub(crate) noise_h: f64,
    /// The same per coordinate: `h max_i Σ_b |A_i|_ab |x_i|_b` over the nodes `i`.
    pub(crate) noise_rows: Vec<f64>,
    /// The residual's scale for this solve: the whole step's (the constraint rows'), and
    /// each coordinate's (its gradient rows'; [`crate::backend::coordinate_scales`]).
    pub(crate) scale: f64,
    pub(crate) coord_scale: Vec<f64>,
    /// The unknowns `xs` and `vs` were last computed from, while `nodes_valid` (cleared
    /// when `h`, `t0` or `q0` change): a Jacobian at the point of the last residual, as
    /// Newton asks for, takes the node values as they are.
    pub(crate) nodes_z: Vec<f64>,
    pub(crate) nodes_valid: bool,
}

impl<'a, M: ForcedLagrangian<N>, const N: usize> StepProblem<'a, M, N> {
    /// The buffers for `model` and `scheme`, no step set (`h` is NaN until a solve sets it).
    pub(crate) fn new(model: &'a M, scheme: &'a Scheme) -> Self {
        let (s, r) = (scheme.stages(), scheme.quadrature_nodes());
        let cons = model.constraint_count();
        let dim = (s - 1) * (N + cons);
        let zero = SVector::<f64, N>::zeros();
        let grad = NodeGradient { fq: zero, lv: zero };
        StepProblem {
            model,
            scheme,
            h: f64::NAN,
            t0: 0.0,
            q0: zero,
            p0: zero,
            xs: vec![zero; r],
            vs: vec![zero; r],
            grads: vec![grad; r],
            jacs: Vec::with_capacity(r),
            base: zero_matrix(dim, dim),
            base_built: false,
            cons,
            gval: zeros(cons),
            gjac: vec![zero_matrix(cons, N); s],
            row_scale: vec![1.0; cons],
            col_scale: vec![1.0; cons],
            lam: zeros(cons),
            blocks_given: false,
            noise: 0.0,
            noise_h: 0.0,
            noise_rows: zeros(N),
            scale: 0.0,
            coord_scale: zeros(N),
            nodes_z: Vec::with_capacity(dim),
            nodes_valid: false,
        }
    }
}

impl<M: ForcedLagrangian<N>, const N: usize> StepProblem<'_, M, N> {
    /// Back to the state the backend's constructor made, keeping the buffers (a new run on
    /// the same buffers). Every field is named, so that a field added later must be decided
    /// on here.
    pub(crate) fn restart(&mut self) {
        let StepProblem {
            model: _,
            scheme: _,
            h,
            t0,
            q0,
            p0,
            xs,
            vs,
            grads,
            jacs,
            base: _,
            base_built,
            cons: _,
            gval,
            gjac,
            row_scale,
            col_scale,
            lam,
            blocks_given,
            noise,
            noise_h,
            noise_rows,
            scale,
            coord_scale,
            nodes_z,
            nodes_valid,
        } = self;
        *h = f64::NAN;
        *t0 = 0.0;
        q0.fill(0.0);
        p0.fill(0.0);
        xs.iter_mut().chain(vs.iter_mut()).for_each(|x| x.fill(0.0));
        for g in grads.iter_mut() {
            g.fq.fill(0.0);
            g.lv.fill(0.0);
        }
        jacs.clear();
        *base_built = false;
        gval.fill(0.0);
        gjac.iter_mut().for_each(|g| g.fill(0.0));
        row_scale.fill(1.0);
        col_scale.fill(1.0);
        lam.fill(0.0);
        *blocks_given = false;
        *noise = 0.0;
        *noise_h = 0.0;
        noise_rows.fill(0.0);
        *scale = 0.0;
        coord_scale.fill(0.0);
        nodes_z.clear();
        *nodes_valid = false;
    }

    fn nodes(&mut self, z: &DVector<f64>) {
        if self.nodes_valid && self.nodes_z[..] == z.as_slice()[..] {
            return;
        }
        self.nodes_z.clear();
        self.nodes_z.extend_from_slice(z.as_slice());
        self.nodes_valid = true;
        let (zs, _) = z.as_slice().as_chunks::<N>();
        // The increments of control points 1 … s − 1 (control point 0 is `q_k` itself,
        // increment 0); the constraint unknowns after them are not positions.
        let s1 = self.scheme.stages() - 1;
        let zs = &zs[..s1.min(zs.len())];
        // The common sizes with their loops unrolled (the same sums, in the same order).
        let unrolled = match zs.len() {
            1 => self.nodes_unrolled::<1>(zs),
            2 => self.nodes_unrolled::<2>(zs),
            3 => self.nodes_unrolled::<3>(zs),
            4 => self.nodes_unrolled::<4>(zs),
            5 => self.nodes_unrolled::<5>(zs),
            6 => self.nodes_unrolled::<6>(zs),
            7 => self.nodes_unrolled::<7>(zs),
            _ => false,
        };
        if unrolled {
            return;
        }
        let inv_h = 1.0 / self.h;
        for (i, (xi, vi)) in self.xs.iter_mut().zip(self.vs.iter_mut()).enumerate() {
            let (phi, psi) = self.scheme.basis_rows(i);
            let (Some(phi), Some(psi)) = (phi.get(1..=zs.len()), psi.get(1..=zs.len())) else {
                continue;
            };
            let (mut x, mut v) = (self.q0, SVector::<f64, N>::zeros());
            // One pass over the control points, no test on the weights (a zero weight of
            // `Φ` adds zero).
            for ((zj, &ph), &ps) in zs.iter().zip(phi).zip(psi) {
                for a in 0..N {
                    x[a] += ph * zj[a];
                    v[a] += ps * zj[a];
                }
            }
            *xi = x;
            *vi = v * inv_h;
        }
    }

    /// [`Self::nodes`] for `S1` control points after the first, as fixed-size loops; false
    /// (nothing done) where the scheme's rows do not have that size.
    #[inline(always)]
    fn nodes_unrolled<const S1: usize>(&mut self, zs: &[[f64; N]]) -> bool {
        let Ok(zs) = <&[[f64; N]; S1]>::try_from(zs) else {
            return false;
        };
        let (sch, inv_h) = (self.scheme, 1.0 / self.h);
        for (i, (xi, vi)) in self.xs.iter_mut().zip(self.vs.iter_mut()).enumerate() {
            let (phi, psi) = sch.basis_rows(i);
            let rows = phi.get(1..=S1).zip(psi.get(1..=S1));
            let Some((Ok(phi), Ok(psi))) =
                rows.map(|(a, b)| (<&[f64; S1]>::try_from(a), b.try_into()))
            else {
                continue;
            };
            let psi: &[f64; S1] = psi;
            let (mut x, mut v) = (self.q0, SVector::<f64, N>::zeros());
            for j in 0..S1 {
                for a in 0..N {
                    x[a] += phi[j] * zs[j][a];
                    v[a] += psi[j] * zs[j][a];
                }
            }
            *xi = x;
            *vi = v * inv_h;
        }
        true
    }

    /// The gradient rows of the residual from the node gradients, for `R` quadrature nodes
    /// as fixed-size loops (the same sums, in the same order as the general loop of
    /// [`NonlinearSystem::residual`]); false (nothing done) for another node count.
    #[inline(always)]
    fn rows_unrolled<const R: usize>(&self, rs: &mut [[f64; N]]) -> bool {
        let (sch, h) = (self.scheme, self.h);
        let Some(Ok(grads)) = self.grads.get(..R).map(<&[NodeGradient<N>; R]>::try_from) else {
            return false;
        };
        if sch.quadrature_nodes() != R {
            return false;
        }
        for (j, rj) in rs.iter_mut().take(sch.stages() - 1).enumerate() {
            let mut gj = if j == 0 { self.p0 } else { SVector::zeros() };
            let (wf, wl) = sch.residual_weights(j);
            let (Ok(wf), Ok(wl)) = (<&[f64; R]>::try_from(wf), <&[f64; R]>::try_from(wl)) else {
                return false;
            };
            for i in 0..R {
                let (cf, l, g) = (wf[i] * h, wl[i], &grads[i]);
                for a in 0..N {
                    gj[a] += cf * g.fq[a] + l * g.lv[a];
                }
            }
            rj.copy_from_slice(gj.as_slice());
        }
        true
    }

    /// The gradient rows of the residual from the node gradients in `grads`, and the
    /// constraint rows.
    #[inline(always)]
    fn residual_rows(
        &mut self,
        z: &DVector<f64>,
        r: &mut DVector<f64>,
    ) -> Result<(), NewtonFailure> {
        let (sch, h) = (self.scheme, self.h);
        let (rs, _) = r.as_mut_slice().as_chunks_mut::<N>();
        let unrolled = match sch.quadrature_nodes() {
            2 => self.rows_unrolled::<2>(rs),
            3 => self.rows_unrolled::<3>(rs),
            4 => self.rows_unrolled::<4>(rs),
            5 => self.rows_unrolled::<5>(rs),
            6 => self.rows_unrolled::<6>(rs),
            7 => self.rows_unrolled::<7>(rs),
            8 => self.rows_unrolled::<8>(rs),
            _ => false,
        };
        for (j, rj) in rs.iter_mut().take(sch.stages() - 1).enumerate() {
            if unrolled {
                break;
            }
            let mut gj = if j == 0 { self.p0 } else { SVector::zeros() };
            let (wf, wl) = sch.residual_weights(j);
            for ((g, &f), &l) in self.grads.iter().zip(wf).zip(wl) {
                let cf = f * h;
                for a in 0..N {
                    gj[a] += cf * g.fq[a] + l * g.lv[a];
                }
            }
            rj.copy_from_slice(gj.as_slice());
        }
        // `M::CONSTRAINED` first, alone: a model that promises no constraints compiles none
        // of their code (see `ForcedLagrangian::CONSTRAINED`).
        if M::CONSTRAINED && self.cons > 0 {
            self.constraint_rows(z, r, None)?;
        }
        Ok(())
    }

    /// The node blocks at the node values into `jacs`, and with `grads` their gradient
    /// blocks into `grads` (the residual's terms at the same point).
    fn node_blocks(&mut self, grads: bool) -> Result<(), NewtonFailure> {
        let (sch, h) = (self.scheme, self.h);
        for i in 0..sch.quadrature_nodes() {
            let t = self.t0 + sch.c()[i] * h;
            let nj = self.model.node_jacobian_at(t, &self.xs[i], &self.vs[i]);
            if !(all_finite(&nj.a) && all_finite(&nj.b) && all_finite(&nj.c) && all_finite(&nj.e)) {
                return Err(NewtonFailure::NonFinite);
            }
            if grads {
                let g = nj.grad;
                if !(all_finite(&g.fq) && all_finite(&g.lv)) {
                    return Err(NewtonFailure::NonFinite);
                }
                if let Some(slot) = self.grads.get_mut(i) {
                    *slot = g;
                }
            }
            // Filled on the first Jacobian (capacity made once): a zero `N × N` block made
            // beforehand would sit on the caller's stack.
            match self.jacs.get_mut(i) {
                Some(slot) => *slot = nj,
                None => self.jacs.push(nj),
            }
        }
        Ok(())
    }

    /// The Jacobian from the node blocks in `jacs`, with the forces' round-off
    /// ([`NonlinearSystem::residual_noise`]) and the constraint rows.
    fn assemble(&mut self, z: &DVector<f64>, jac: &mut DMatrix<f64>) -> Result<(), NewtonFailure> {
        let (sch, h) = (self.scheme, self.h);
        // `h |A| |x|` ([`crate::newton::force_round_off`]) and the same per row, in one pass
        // over the blocks `A`. In place: an `N × N` temporary would sit on the stack. The
        // first node sets the rows (a fill with zeros before it, read back at another width,
        // stalled); a NaN counts as nothing, as in a fold with `f64::max` from zero.
        let mut x_max = 0.0f64;
        for x in self.xs.iter().chain([&self.q0]) {
            for v in x.iter() {
                let a = v.abs();
                x_max = if a > x_max { a } else { x_max };
            }
        }
        let mut a_max = 0.0f64;
        let mut first = true;
        for (i, nj) in self.jacs.iter().enumerate() {
            let x = self.xs.get(i);
            for a in 0..N {
                let mut row = 0.0;
                for b in 0..N {
                    let e = nj.a[(a, b)].abs();
                    a_max = if e > a_max { e } else { a_max };
                    if let Some(x) = x {
                        row += e * x[b].abs();
                    }
                }
                let (Some(m), Some(_)) = (self.noise_rows.get_mut(a), x) else {
                    continue;
                };
                let v = h * row;
                if first {
                    *m = if v > 0.0 { v } else { 0.0 };
                } else if v > *m {
                    *m = v;
                }
            }
            first &= x.is_none();
        }
        if first {
            self.noise_rows.fill(0.0);
        }
        self.noise = h * a_max * x_max;
        self.noise_h = h;
        let constant_mass = M::STRUCTURE.constant_mass;
        let rows = jac.nrows();
        if constant_mass {
            // E is the same at every node and every step: its part is built once, and
            // scaled by 1/h (adaptive steps change h on every step).
            if !self.base_built {
                // Each block once, its coefficients summed first: term by term, lobatto7's
                // 252 terms cost about 8.7k instructions, 7 % of a two-step run.
                let e = self.jacs[0].e;
                let bs = self.base.as_mut_slice();
                bs.fill(0.0);
                for p in sch.block_sums() {
                    let coef: f64 = p.e.iter().map(|&(_, w)| w).sum();
                    if coef != 0.0 {
                        add_block(bs, rows, p.j, p.m, coef, &e);
                    }
                }
                self.base_built = true;
            }
            let inv_h = 1.0 / h;
            let js = jac.as_mut_slice();
            for (x, y) in js.iter_mut().zip(self.base.as_slice()) {
                *x = y * inv_h;
            }
        } else {
            jac.fill(0.0);
        }
        let js = jac.as_mut_slice();
        if constant_mass {
            // `C ≡ 0` and `E` done, so only the terms on `A` and `B` (for Lobatto, where
            // `Φ = I`, `s − 1` of the first and `(s − 1)²` of the second), each list without
            // the others' zeros.
            let (a_terms, b_terms) = sch.force_jacobian_terms();
            for t in a_terms {
                add_block(js, rows, t.j, t.m, t.a * h, &self.jacs[t.i].a);
            }
            for t in b_terms {
                add_block(js, rows, t.j, t.m, t.b, &self.jacs[t.i].b);
            }
        } else if N <= SMALL_BLOCK {
            add_grouped(js, rows, sch, &self.jacs, h);
        } else {
            add_terms(js, rows, sch, &self.jacs, h);
        }
        if M::CONSTRAINED && self.cons > 0 {
            let mut scratch = DVector::zeros(0);
            self.constraint_rows(z, &mut scratch, Some(jac))?;
        }
        Ok(())
    }
}

impl<M: ForcedLagrangian<N>, const N: usize> NonlinearSystem for StepProblem<'_, M, N> {
    fn residual(&mut self, z: &DVector<f64>, r: &mut DVector<f64>) -> Result<(), NewtonFailure> {
        self.nodes(z);
        let (sch, h) = (self.scheme, self.h);
        for i in 0..sch.quadrature_nodes() {
            let t = self.t0 + sch.c()[i] * h;
            let g = self.model.node_gradient_at(t, &self.xs[i], &self.vs[i]);
            if !(all_finite(&g.fq) && all_finite(&g.lv)) {
                return Err(NewtonFailure::NonFinite);
            }
            self.grads[i] = g;
        }
        self.residual_rows(z, r)
    }

    /// Both at one `z` from one pass of the Jacobian kernel, whose gradient blocks are the
    /// residual's terms: a step's first iterate takes its residual and its factors at the
    /// same point (every fixed step of a small model, every adaptive step), and the
    /// gradient kernel is not run there.
    fn residual_and_jacobian(
        &mut self,
        z: &DVector<f64>,
        r: &mut DVector<f64>,
        jac: &mut DMatrix<f64>,
    ) -> Result<(), NewtonFailure> {
        if self.blocks_given {
            self.residual(z, r)?;
            return self.jacobian(z, jac);
        }
        self.nodes(z);
        self.node_blocks(true)?;
        self.residual_rows(z, r)?;
        self.assemble(z, jac)
    }

    fn jacobian(&mut self, z: &DVector<f64>, jac: &mut DMatrix<f64>) -> Result<(), NewtonFailure> {
        self.nodes(z);
        if !self.blocks_given {
            self.node_blocks(false)?;
        }
        self.assemble(z, jac)
    }

    fn residual_noise(&self) -> f64 {
        self.noise
    }

    /// A constrained model's rows share one floor (see the sparse step's `rows_apart`).
    fn rows_apart(&self) -> bool {
        self.cons == 0
    }

    /// The rows of one coordinate (at every control point) form a group.
    fn group_max(&self, out: &mut [f64]) {
        let nz = (self.scheme.stages() - 1) * N;
        let len = nz.min(out.len());
        // The largest of each coordinate gathered into an `[f64; N]`, then written to every
        // block: by blocks of `N` as arrays, whose copies are a few moves (strided iterators
        // cost several times the instructions, and a slice's `copy_from_slice` a call to
        // `memcpy`: 96 instructions a call on coupled van der Pol, lobatto3, against 45).
        let (blocks, tail) = out[..len].as_chunks_mut::<N>();
        // A NaN entry counts as nothing, as in a fold with `f64::max`.
        let clamp = |m: f64| if m > 0.0 { m } else { 0.0 };
        let Some((first, rest)) = blocks.split_first_mut() else {
            // Fewer rows than one block: each its own.
            tail.iter_mut().for_each(|m| *m = clamp(*m));
            return;
        };
        let mut most = first.map(clamp);
        for block in rest.iter() {
            for (m, x) in most.iter_mut().zip(block) {
                *m = if *x > *m { *x } else { *m };
            }
        }
        *first = most;
        rest.iter_mut().for_each(|block| *block = most);
    }

    /// Each coordinate's gradient rows get its own scale, the constraint rows the step's
    /// (a constrained model: every row the step's).
    fn row_scales(&self, scale: f64, out: &mut [f64]) {
        if self.cons > 0 {
            out.fill(scale);
            return;
        }
        let nz = (self.scheme.stages() - 1) * N;
        let (grad, cons) = out.split_at_mut(nz.min(out.len()));
        // By blocks of `N` (a cycling iterator cost several times the instructions).
        for block in grad.chunks_exact_mut(N) {
            block.copy_from_slice(&self.coord_scale[..N]);
        }
        cons.fill(self.scale);
    }

    /// Each coordinate's gradient rows get its own forces' round-off, the constraint rows
    /// the largest.
    fn add_row_noise(&self, out: &mut [f64]) {
        if self.cons > 0 {
            out.iter_mut().for_each(|x| *x += self.noise);
            return;
        }
        let nz = (self.scheme.stages() - 1) * N;
        let (grad, cons) = out.split_at_mut(nz.min(out.len()));
        for block in grad.chunks_exact_mut(N) {
            for (x, n) in block.iter_mut().zip(&self.noise_rows[..N]) {
                *x += n;
            }
        }
        cons.iter_mut().for_each(|x| *x += self.noise);
    }

    /// A linear model's step equations (`STRUCTURE.linear`), without constraints: the
    /// Jacobian depends on `h` alone.
    fn constant_jacobian(&self) -> bool {
        M::STRUCTURE.linear && self.cons == 0
    }
}

impl<M: ForcedLagrangian<N>, const N: usize> StepProblem<'_, M, N> {
    /// Sets the factors on each constraint's rows and unknowns for a solve with the
    /// momentum scale `scale` from the guess `z` (see [`crate::newton::constraint_scales`]),
    /// from the gradients at the step's start, `(t0, q0)`, already set, and the mass matrix
    /// of the last Jacobian (at `(t0, q0)` at rest before the first); puts `z`'s multipliers
    /// in the iteration's units ([`Self::unscale_multipliers`] takes them back).
    pub(crate) fn scale_constraints(&mut self, scale: f64, z: &mut [f64]) {
        let (s1, m) = (self.scheme.stages() - 1, self.cons);
        let nz = s1 * N;
        let largest = |x: &[f64]| x.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let x_size = largest(self.q0.as_slice()).max(largest(&z[..nz.min(z.len())]));
        let mass = match self.jacs.first() {
            Some(nj) => largest(nj.e.as_slice()),
            None => {
                let rest = SVector::<f64, N>::zeros();
                let nj = self.model.node_jacobian_at(self.t0, &self.q0, &rest);
                largest(nj.e.as_slice())
            }
        };
        let g0 = &mut self.gjac[0];
        crate::model::general::constraint_jacobian_at(
            self.model,
            self.t0,
            &self.q0,
            &mut self.gval,
            g0,
        );
        for k in 0..m {
            let g_norm = (0..N).fold(0.0f64, |a, c| a.max(g0[(k, c)].abs()));
            (self.row_scale[k], self.col_scale[k]) =
                crate::newton::constraint_scales(scale, g_norm, (x_size, mass));
            for j in 0..s1 {
                if let Some(w) = z.get_mut(nz + j * m + k) {
                    *w /= self.col_scale[k];
                }
            }
        }
    }

    /// Takes `z`'s multipliers from the iteration's units back to `ŵ_j` (see
    /// [`Self::scale_constraints`]).
    pub(crate) fn unscale_multipliers(&self, z: &mut [f64]) {
        let (s1, m) = (self.scheme.stages() - 1, self.cons);
        let nz = s1 * N;
        for (k, c) in self.col_scale.iter().enumerate() {
            for j in 0..s1 {
                if let Some(w) = z.get_mut(nz + j * m + k) {
                    *w *= c;
                }
            }
        }
    }
}

impl<M: ForcedLagrangian<N>, const N: usize> StepProblem<'_, M, N> {
    /// The constraint terms of the step equations (DESIGN §11, Lobatto schemes: control
    /// point `j` is quadrature node `j`): `−h b_j G(x_j)ᵀ λ_j` in the gradient rows and the
    /// rows `g(x_j)`; with `jac`, their derivatives instead (`−h b_j G(x_j)ᵀ` in the `λ_j`
    /// columns, `−h b_j Σ_r λ_{j,r} ∂²g_r` on the diagonal blocks, `G(x_j)` in the
    /// constraint rows). The rows are `g` itself, not `g/h`, times the factor of
    /// [`crate::newton::constraint_scales`]: their round-off (`ε |G| |q|` unscaled) then
    /// stays within the Newton's round-off floor at any step size and in any units.
    fn constraint_rows(
        &mut self,
        z: &DVector<f64>,
        r: &mut DVector<f64>,
        mut jac: Option<&mut DMatrix<f64>>,
    ) -> Result<(), NewtonFailure> {
        let (sch, h, m) = (self.scheme, self.h, self.cons);
        let s = sch.stages();
        let nz = (s - 1) * N;
        let zs = z.as_slice();
        for j in 0..s {
            let x = if j == 0 { self.q0 } else { self.xs[j] };
            let t = self.t0 + sch.c()[j] * h;
            crate::model::general::constraint_jacobian_at(
                self.model,
                t,
                &x,
                &mut self.gval,
                &mut self.gjac[j],
            );
            let gj = &self.gjac[j];
            if !(self.gval.iter().all(|v| v.is_finite()) && gj.iter().all(|v| v.is_finite())) {
                return Err(NewtonFailure::NonFinite);
            }
            // The unknowns are `ŵ_j = h² λ_j` (over `col_scale` in the iteration), so that
            // every block of the Jacobian is of order 1/h (a step of any size keeps it well
            // scaled): `h b_j λ_j = (b_j/h) ŵ_j`.
            let hb = sch.b()[j] / h;
            match jac.as_deref_mut() {
                None => {
                    let rs = r.as_mut_slice();
                    if j >= 1 {
                        for (k, (g, f)) in self.gval.iter().zip(&self.row_scale).enumerate() {
                            rs[nz + (j - 1) * m + k] = f * g;
                        }
                    }
                    if j + 1 < s {
                        let lam = &zs[nz + j * m..nz + (j + 1) * m];
                        let cs = &self.col_scale;
                        for a in 0..N {
                            let f: f64 = (0..m).map(|k| gj[(k, a)] * (cs[k] * lam[k])).sum();
                            rs[j * N + a] -= hb * f;
                        }
                    }
                }
                Some(jm) => {
                    if j + 1 < s {
                        for (k, c) in self.col_scale.iter().enumerate() {
                            for a in 0..N {
                                jm[(j * N + a, nz + j * m + k)] = -hb * c * gj[(k, a)];
                            }
                        }
                        if j >= 1 {
                            let u = &zs[nz + j * m..nz + (j + 1) * m];
                            for ((l, c), x) in self.lam.iter_mut().zip(&self.col_scale).zip(u) {
                                *l = c * x;
                            }
                            let curv = crate::model::general::constraint_curvature_at(
                                self.model, t, &x, &self.lam,
                            );
                            if !all_finite(&curv) {
                                return Err(NewtonFailure::NonFinite);
                            }
                            for c in 0..N {
                                for a in 0..N {
                                    jm[(j * N + a, (j - 1) * N + c)] -= hb * curv[(a, c)];
                                }
                            }
                        }
                    }
                    if j >= 1 {
                        for (k, f) in self.row_scale.iter().enumerate() {
                            for a in 0..N {
                                jm[(nz + (j - 1) * m + k, (j - 1) * N + a)] = f * gj[(k, a)];
                            }
                        }
                    }
                }
            }
        }
        Ok(())
    }
}

/// The general part of the step Jacobian (DESIGN §3), each block summed on the stack over
/// the terms that weigh it ([`Scheme::block_sums`]) and written once. The per-term update of
/// [`add_terms`] costs about 20 instructions per `N × N` block at `N = 2`: on the double
/// pendulum (lobatto6, callgrind) the assembly was half of the Jacobian, more than the
/// node Hessians. For `N ≤ SMALL_BLOCK`.
fn add_grouped<const N: usize>(
    js: &mut [f64],
    rows: usize,
    sch: &Scheme,
    jacs: &[NodeJacobian<N>],
    h: f64,
) {
    let inv_h = 1.0 / h;
    for p in sch.block_sums() {
        let mut acc = SMatrix::<f64, N, N>::zeros();
        for &(i, w) in &p.a {
            acc += jacs[i].a * (w * h);
        }
        for &(i, w) in &p.b {
            acc += jacs[i].b * w;
        }
        for &(i, w) in &p.c {
            acc += jacs[i].c * w;
        }
        for &(i, w) in &p.e {
            acc += jacs[i].e * (w * inv_h);
        }
        add_block(js, rows, p.j, p.m, 1.0, &acc);
    }
}

/// The same as [`add_grouped`], term by term, in place: for large `N`, whose blocks do not
/// belong on the stack.
fn add_terms<const N: usize>(
    js: &mut [f64],
    rows: usize,
    sch: &Scheme,
    jacs: &[NodeJacobian<N>],
    h: f64,
) {
    for t in sch.jacobian_terms() {
        let nj = &jacs[t.i];
        if t.a != 0.0 {
            add_block(js, rows, t.j, t.m, t.a * h, &nj.a);
        }
        if t.b != 0.0 {
            add_block(js, rows, t.j, t.m, t.b, &nj.b);
        }
        if t.c != 0.0 {
            add_block(js, rows, t.j, t.m, t.c, &nj.c);
        }
        add_block(js, rows, t.j, t.m, t.e / h, &nj.e);
    }
}

/// Up to this many coordinates, a Jacobian block is summed in an `N × N` matrix on the stack
/// (at most 512 bytes); above it, in place.
const SMALL_BLOCK: usize = 8;

/// Adds `coef · blk` to block `(j, m − 1)` of a column-major matrix with `rows` rows.
#[inline(always)]
fn add_block<const N: usize>(
    js: &mut [f64],
    rows: usize,
    j: usize,
    m: usize,
    coef: f64,
    blk: &SMatrix<f64, N, N>,
) {
    let origin = (m - 1) * N * rows + j * N;
    for c in 0..N {
        let col = &mut js[origin + c * rows..origin + c * rows + N];
        for (x, y) in col.iter_mut().zip(blk.column(c).iter()) {
            *x += coef * y;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::NodeGradient;
    use crate::scheme::SchemeId;

    /// Node blocks with every entry different, none zero.
    fn blocks<const N: usize>(nodes: usize) -> Vec<NodeJacobian<N>> {
        let entry = |i: usize, k: usize, r: usize, c: usize| {
            let x = (1 + i * 31 + k * 7 + r * 3 + c * 5) as f64;
            (x * 0.618).sin() + 0.1 * k as f64
        };
        (0..nodes)
            .map(|i| NodeJacobian {
                grad: NodeGradient {
                    fq: SVector::zeros(),
                    lv: SVector::zeros(),
                },
                a: SMatrix::from_fn(|r, c| entry(i, 0, r, c)),
                b: SMatrix::from_fn(|r, c| entry(i, 1, r, c)),
                c: SMatrix::from_fn(|r, c| entry(i, 2, r, c)),
                e: SMatrix::from_fn(|r, c| entry(i, 3, r, c)),
            })
            .collect()
    }

    fn compare<const N: usize>(sch: &Scheme) {
        let rows = (sch.stages() - 1) * N;
        let jacs = blocks::<N>(sch.quadrature_nodes());
        for h in [0.7, 1e-3] {
            let (mut grouped, mut terms) = (vec![0.0; rows * rows], vec![0.0; rows * rows]);
            add_grouped(&mut grouped, rows, sch, &jacs, h);
            add_terms(&mut terms, rows, sch, &jacs, h);
            assert_same_jacobian(
                &grouped,
                &terms,
                format!("{:?}, N = {N}, h = {h}", sch.id()),
            );
        }
    }

    /// `got` is the Jacobian `want` (not empty) to 64 ε of its largest entry.
    fn assert_same_jacobian(got: &[f64], want: &[f64], what: String) {
        let size = want.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let diff = got
            .iter()
            .zip(want)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
        assert!(size > 1.0, "{what}: empty Jacobian");
        assert!(
            diff <= 64.0 * f64::EPSILON * size,
            "{what}: {diff:e} of {size:e}"
        );
    }

    /// A driven model with a mass that depends on `q` (the general assembly), and one with a
    /// constant mass and a force in `q` and `v` (the constant-mass assembly).
    struct Driven;
    impl crate::model::ForcedLagrangian<2> for Driven {
        const STRUCTURE: crate::model::Structure = crate::model::Structure::GENERAL_DRIVEN;
        fn lagrangian<D: crate::scalar::Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> D {
            self.lagrangian_at(D::from(0.0), q, v)
        }
        fn lagrangian_at<D: crate::scalar::Scalar>(&self, t: D, q: &[D; 2], v: &[D; 2]) -> D {
            let mass = q[0].cos() * q[0].cos() * 0.5 + 1.0;
            mass * v[0] * v[0] * 0.5 + v[1] * v[1] * 0.5 + q[0].sin() * v[1] * t.cos()
                - (q[1] / 3.0).exp()
        }
        fn force<D: crate::scalar::Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> [D; 2] {
            self.force_at(D::from(0.0), q, v)
        }
        fn force_at<D: crate::scalar::Scalar>(&self, t: D, q: &[D; 2], v: &[D; 2]) -> [D; 2] {
            [
                -v[0] * 0.3 * (q[1] * q[1] + 1.0),
                (t * 2.0).sin() * q[0] - v[1] * v[0],
            ]
        }
    }
    struct Steady;
    impl crate::model::ForcedLagrangian<2> for Steady {
        const STRUCTURE: crate::model::Structure = crate::model::Structure {
            constant_mass: true,
            ..crate::model::Structure::GENERAL
        };
        fn lagrangian<D: crate::scalar::Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> D {
            (v[0] * v[0] + v[1] * v[1] * 2.0) * 0.5
                + D::from(1.0) / (q[0] * q[0] + q[1] * q[1]).sqrt()
        }
        fn force<D: crate::scalar::Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> [D; 2] {
            [-v[0] * 0.1 * q[1], -v[1] * v[1] * 0.05]
        }
    }

    /// Both at one guess, from one pass of the Jacobian kernel, against the residual and
    /// the Jacobian made apart, for each scheme and both assemblies.
    fn fused_matches<M: crate::model::ForcedLagrangian<2>>(model: &M) {
        let schemes = (2..=7)
            .map(|s| Scheme::lobatto(s).expect("scheme"))
            .chain([Scheme::new(SchemeId::Midpoint).expect("scheme")]);
        for sch in schemes {
            let fresh = || {
                let mut prob = StepProblem::new(model, &sch);
                (prob.h, prob.t0) = (0.3, 1.7);
                prob.q0 = SVector::from([0.8, 1.1]);
                prob.p0 = SVector::from([-0.4, 0.6]);
                prob
            };
            let n = (sch.stages() - 1) * 2;
            let z = DVector::from_fn(n, |i, _| 0.05 * (i as f64 + 1.0).sin());
            let (mut r1, mut j1) = (DVector::zeros(n), DMatrix::zeros(n, n));
            let mut apart = fresh();
            apart.residual(&z, &mut r1).expect("residual");
            apart.jacobian(&z, &mut j1).expect("jacobian");
            let (mut r2, mut j2) = (DVector::zeros(n), DMatrix::zeros(n, n));
            let mut fused = fresh();
            fused
                .residual_and_jacobian(&z, &mut r2, &mut j2)
                .expect("both");
            let size = |x: &[f64]| x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let diff = |x: &[f64], y: &[f64]| {
                x.iter()
                    .zip(y)
                    .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()))
            };
            let (rs, js) = (size(r1.as_slice()), size(j1.as_slice()));
            assert!(rs > 0.1 && js > 0.1, "{:?}: empty", sch.id());
            let (dr, dj) = (
                diff(r1.as_slice(), r2.as_slice()),
                diff(j1.as_slice(), j2.as_slice()),
            );
            assert!(
                dr <= 16.0 * f64::EPSILON * rs,
                "{:?}: residual {dr:e} of {rs:e}",
                sch.id()
            );
            assert_eq!(dj, 0.0, "{:?}: Jacobian {dj:e} of {js:e}", sch.id());
            assert_eq!(apart.noise, fused.noise, "{:?}: noise", sch.id());
        }
    }

    #[test]
    fn residual_and_jacobian_together_match_them_apart() {
        fused_matches(&Driven);
        fused_matches(&Steady);
    }

    /// The constant-mass assembly (`E` built once per stepper from the summed coefficients,
    /// then `A` and `B` term by term) against the general term-by-term assembly of the same
    /// node blocks, for each scheme and at two step sizes.
    #[test]
    fn constant_mass_assembly_matches_the_terms() {
        let schemes = (2..=8)
            .map(|s| Scheme::lobatto(s).expect("scheme"))
            .chain([Scheme::new(SchemeId::Midpoint).expect("scheme")]);
        for sch in schemes {
            let n = (sch.stages() - 1) * 2;
            let mut prob = StepProblem::new(&Steady, &sch);
            (prob.q0, prob.p0) = (SVector::from([0.8, 1.1]), SVector::from([-0.4, 0.6]));
            for h in [0.3, 1e-3] {
                prob.h = h;
                let z = DVector::from_fn(n, |i, _| h * (i as f64 + 1.0).sin());
                let mut jac = DMatrix::zeros(n, n);
                prob.jacobian(&z, &mut jac).expect("jacobian");
                let mut terms = vec![0.0; n * n];
                add_terms(&mut terms, n, &sch, &prob.jacs, h);
                assert_same_jacobian(jac.as_slice(), &terms, format!("{:?}, h = {h}", sch.id()));
            }
        }
    }

    /// The blocks summed on the stack give the term-by-term Jacobian, for schemes whose
    /// `Φ` is the identity (Lobatto) and those whose it is not.
    #[test]
    fn grouped_assembly_matches_the_terms() {
        let mut schemes: Vec<Scheme> = (2..=8)
            .map(|s| Scheme::lobatto(s).expect("scheme"))
            .collect();
        for id in [
            SchemeId::Midpoint,
            SchemeId::Trapezoid,
            SchemeId::Alpha(0.3),
        ] {
            schemes.push(Scheme::new(id).expect("scheme"));
        }
        for sch in &schemes {
            compare::<1>(sch);
            compare::<2>(sch);
            compare::<5>(sch);
        }
    }
}
