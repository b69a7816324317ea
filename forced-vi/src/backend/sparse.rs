//! The sparse backend (DESIGN §9): node blocks on the model's recorded pattern, the step
//! Jacobian on the pattern they induce, factored by faer's sparse LU with the symbolic
//! analysis and the workspace made once per run.

use super::{Layout, StepBackend, StepFailure, TANGENT_BLOCK};
use crate::error::Error;
use crate::error::NewtonFailure;
use crate::model::{NodePattern, NodeSink};
use crate::newton::{NewtonOptions, NewtonReport};
use crate::scheme::Scheme;
use crate::sparse::constraints::Saddle;
use crate::sparse::equations::{NodeRef, SparseStep};
use crate::sparse::lu::SparseLu;
use crate::sparse::newton::SparseNewton;
use crate::sparse::velocity::VelocitySolver;

/// Two step sizes within this relative distance count as one for carrying the factors
/// across steps: the grid `t_k = k h` of a fixed-step run makes steps that differ from `h`
/// by a few ulps of `t_k`, up to `1e-8` relative for `t / h` up to about `1e7`.
const SAME_STEP: f64 = 1e-8;

/// The sparse step equations, their Newton solver, the velocity solver and the unknowns.
pub(crate) struct SparseBackend<'a> {
    prob: SparseStep<'a>,
    newton: SparseNewton,
    velocity: VelocitySolver,
    z: Vec<f64>,
    /// The transposed step Jacobian's solver and where `J`'s values go in it, for
    /// adjoints (made on first use).
    adjoint: Option<(SparseLu, Vec<usize>)>,
    /// The step Jacobian at the solution and its factors, for tangents (made on first
    /// use), apart from the Newton's, which carry over to the next step.
    tangent: Option<SparseNewton>,
    /// A constrained model: the saddle-point solve at a step's end, the impulse of the
    /// constraint forces over the last step and its end multipliers `h² λ_{s−1}` (as in
    /// the dense backend).
    saddle: Option<Saddle>,
    /// A constrained step's end projection linearised at its end, for its tangent (see
    /// [`StepBackend::sparse_constraint_terms`]), and whether it is factored.
    end_tangent: Option<Box<Saddle>>,
    end_factored: bool,
    impulse: Vec<f64>,
    mu: Vec<f64>,
    ptil: Vec<f64>,
    /// The next solve starts from the last one's factors ([`StepBackend::carry_factors`]).
    carry: bool,
    /// A constrained model: `∂g/∂t` at `(t, q)` (see [`ConstraintRate`]) and its buffer.
    rate: Option<ConstraintRate<'a>>,
    rate_at: Vec<f64>,
}

/// Writes `∂g/∂t` at `(t, q)` into its last argument: the explicit time rate of a model's
/// constraints, from its generic `constraints` with a dual number in `t` (the sparse
/// kernels give `g` and `G` only). A step's end meets `G v + ∂g/∂t = 0` (DESIGN §11).
pub(crate) type ConstraintRate<'a> = Box<dyn Fn(f64, &[f64], &mut [f64]) + 'a>;

/// A constrained model's steps on this backend solve to this fraction of Newton's `rtol`.
/// Its factors are kept across iterations and steps, so its iterates converge linearly and
/// stop just inside the test, where the dense backend's fresh factors land far below it;
/// and an error `rtol · |z|` in the multipliers `ŵ = h² λ` moves the momentum by
/// `rtol · |z| / h`, through the constraint impulse. Measured on a 4-link chain
/// (`RigidChain<8>`, T = 2): the adaptive runs at tol 1e-11 to 1e-13 took as many steps
/// as with the full `rtol` at looser tolerances and fewer at tight ones (lobatto5 at 1e-11
/// 127 instead of 198, lobatto7 at 1e-12 89 instead of 433, and at 1e-13 257 steps
/// instead of a singular Jacobian after 642; the dense backend 123, 47 and 53), with the
/// same Newton iterations per step at 1e-4 and 1e-8; the drift from the dense backend over
/// 2000 fixed steps of lobatto7 (h = 1e-3) fell from 7e-14 to 3e-14 in `p`. The absolute
/// `atol` is kept: a thousandth of it stalled RATTLE's first steps from rest.
const CONSTRAINED_RTOL: f64 = 1e-3;

impl<'a> SparseBackend<'a> {
    /// Buffers for `node` and `scheme` on the recorded node `pattern` (and, for a
    /// constrained model, the pattern of `G`); with `constant_mass` (the model's promise)
    /// the velocity solve factors `E` once.
    pub(crate) fn new(
        node: NodeRef<'a>,
        scheme: &'a Scheme,
        (pattern, g_pattern): (NodePattern, Option<NodePattern>),
        newton: NewtonOptions,
        constant_mass: bool,
        rate: Option<ConstraintRate<'a>>,
    ) -> Result<Self, Error> {
        let velocity = VelocitySolver::new(&pattern, constant_mass)?;
        let saddle = match &g_pattern {
            Some(g) => Some(Saddle::new(&pattern, g)?),
            None => None,
        };
        let newton = if saddle.is_some() {
            newton.tolerances(newton.rtol * CONSTRAINED_RTOL, newton.atol)
        } else {
            newton
        };
        let (n, m) = (pattern.n(), g_pattern.as_ref().map_or(0, |g| g.n()));
        let mut prob = SparseStep::new(node, scheme, pattern, g_pattern, constant_mass);
        let lu = SparseLu::new(
            prob.step_pattern.dim,
            std::mem::take(&mut prob.step_pattern.col_ptr),
            std::mem::take(&mut prob.step_pattern.row_idx),
        )
        .map_err(|_| Error::InvalidModel {
            message: "the sparse step pattern cannot be analysed".into(),
        })?;
        Ok(SparseBackend {
            z: vec![0.0; prob.step_pattern.dim],
            prob,
            newton: SparseNewton::new(lu, newton),
            velocity,
            adjoint: None,
            tangent: None,
            impulse: vec![0.0; if saddle.is_some() { n } else { 0 }],
            ptil: vec![0.0; if saddle.is_some() { n } else { 0 }],
            carry: false,
            mu: vec![0.0; m],
            saddle,
            end_tangent: None,
            end_factored: false,
            rate,
            rate_at: vec![0.0; m],
        })
    }

    /// The end of a constrained step (DESIGN §11), as the dense backend's `project`: the
    /// multipliers `μ = λ_{s−1}` and the velocity with `L_v(q_{k+1}, v) + h b_{s−1} Gᵀ μ = p̃`
    /// and `G v + ∂g/∂t = 0`, then the impulse of the constraint forces over the step.
    fn project(&mut self) -> Result<(), StepFailure> {
        let (Some(saddle), Some(cons)) = (self.saddle.as_mut(), self.prob.cons.as_ref()) else {
            return Ok(());
        };
        let prob = &self.prob;
        let (sch, h, n) = (prob.scheme, prob.h, prob.n);
        let (s, s1, m) = (sch.stages(), sch.stages() - 1, cons.m);
        let nz = n * s1;
        // p̃ = p_k + h Σ b_i (L_q + F)_i − Σ_{j < s−1} (b_j/h) G(x_j)ᵀ ŵ_j.
        self.ptil.copy_from_slice(&prob.p0);
        for (i, &bi) in sch.b().iter().enumerate() {
            for (p, f) in self.ptil.iter_mut().zip(&prob.fq[i * n..(i + 1) * n]) {
                *p += h * bi * f;
            }
        }
        self.impulse.fill(0.0);
        for j in 0..s1 {
            let hb = sch.b()[j] / h;
            for (e, (k, a)) in cons.pattern.entries().enumerate() {
                self.impulse[a] += hb * cons.jac_at(j)[e] * self.z[nz + k * s1 + j];
            }
        }
        for (p, i) in self.ptil.iter_mut().zip(&self.impulse) {
            *p -= i;
        }
        // The velocity guess: the step polynomial's end slope.
        for a in 0..n {
            saddle.v[a] = (1..=s1)
                .map(|mm| sch.end_slope(mm) / h * self.z[a * s1 + mm - 1])
                .sum();
        }
        let g1 = cons.jac_at(s - 1);
        let (t1, q1) = (prob.t0 + h, &prob.xs[(s - 1) * n..s * n]);
        match &self.rate {
            Some(rate) => rate(t1, q1, &mut self.rate_at),
            None => self.rate_at.fill(0.0),
        }
        saddle
            .end_of_step(
                prob.node.get(),
                &prob.pattern,
                (&cons.pattern, g1, &self.rate_at),
                (t1, q1, &self.ptil),
            )
            .map_err(StepFailure::Newton)?;
        for (e, (k, a)) in cons.pattern.entries().enumerate() {
            self.impulse[a] += g1[e] * saddle.mu[k];
        }
        // In the units of the step's unknowns: `ŵ = h² λ = h μ̂ / b_{s−1}`.
        for (w, x) in self.mu.iter_mut().zip(&saddle.mu) {
            *w = h * x / sch.b()[s - 1];
        }
        let _ = m;
        Ok(())
    }
}

impl StepBackend for SparseBackend<'_> {
    #[inline(always)]
    fn layout(&self) -> Layout {
        let m = self.prob.cons.as_ref().map_or(0, |c| c.m);
        Layout::new(self.prob.n, m, self.prob.scheme.stages() - 1, true)
    }

    #[inline(always)]
    fn scheme(&self) -> &Scheme {
        self.prob.scheme
    }

    #[inline(always)]
    fn z(&self) -> &[f64] {
        &self.z
    }

    #[inline(always)]
    fn z_mut(&mut self) -> &mut [f64] {
        &mut self.z
    }

    fn solve(
        &mut self,
        h: f64,
        t0: f64,
        (q0, p0): (&[f64], &[f64]),
        (scale, force): (f64, &[f64]),
    ) -> Result<NewtonReport, StepFailure> {
        let prob = &mut self.prob;
        prob.scale = scale;
        super::coordinate_scales(h, (p0, force), &mut prob.coord_scale);
        let same_h = (prob.h - h).abs() <= SAME_STEP * h.abs();
        prob.h = h;
        prob.t0 = t0;
        prob.q0.copy_from_slice(q0);
        prob.p0.copy_from_slice(p0);
        // Simplified Newton across steps: a step of the same size starts from the factors
        // of the last Jacobian (a sparse LU costs more than the rest of a step), which the
        // iteration refreshes when they contract slowly (see `crate::newton`). Not for
        // one-iteration solves (the error estimate's), unless they were told to carry the
        // factors ([`StepBackend::carry_factors`]).
        let carry = std::mem::take(&mut self.carry);
        let simplified_across = same_h && self.newton.options().max_iterations > 1;
        if !(carry || simplified_across) {
            self.newton.invalidate();
        }
        let solved = self.newton.solve(prob, &mut self.z, scale);
        let outside = prob.outside;
        match solved {
            Ok(report) => {
                self.project()?;
                Ok(report)
            }
            Err(_) if outside => Err(StepFailure::OutsidePattern),
            // The one Newton iteration of the error estimate (`crate::control`) ends its
            // step too, so that its momentum carries its constraint impulse.
            Err(f @ NewtonFailure::MaxIterations { .. })
                if self.saddle.is_some() && self.newton.options().max_iterations == 1 =>
            {
                self.project()?;
                Err(StepFailure::Newton(f))
            }
            Err(f) => Err(StepFailure::Newton(f)),
        }
    }

    #[inline(always)]
    fn last_iterations(&self) -> usize {
        self.newton.last_iterations()
    }

    fn carry_factors(&mut self, h: f64, negligible: f64) -> bool {
        // A constrained model's step Jacobian has constraint rows that do not scale with
        // `1 / h`: its factors are not carried.
        self.carry = self.saddle.is_none() && self.newton.iteration.carry_factors(h, negligible);
        self.carry
    }

    fn solve_within(&mut self, bound: f64) {
        if self.saddle.is_none() {
            self.newton.iteration.solve_within(bound);
        }
    }

    fn carried_error(&self) -> f64 {
        self.newton.iteration.carried_error()
    }

    fn reject_carry(&mut self) {
        self.newton.iteration.reject_carry()
    }

    fn next_correction(&mut self) -> (f64, f64, bool) {
        self.newton.next_correction::<SparseStep<'_>>()
    }

    fn factors_across_steps(&mut self, _on: bool) {}

    fn set_costly_factors(&mut self, costly: bool) {
        self.newton.iteration.set_costly_factors(costly)
    }

    #[inline(always)]
    fn node_fq(&self, i: usize) -> &[f64] {
        let n = self.prob.n;
        &self.prob.fq[i * n..(i + 1) * n]
    }

    #[inline(always)]
    fn node_x(&self, i: usize) -> &[f64] {
        let n = self.prob.n;
        &self.prob.xs[i * n..(i + 1) * n]
    }

    #[inline(always)]
    fn node_v(&self, i: usize) -> &[f64] {
        let n = self.prob.n;
        &self.prob.vs[i * n..(i + 1) * n]
    }

    fn gradient(
        &mut self,
        (t, q, v): (f64, &[f64], &[f64]),
        fq: &mut [f64],
        lv: &mut [f64],
    ) -> Result<(), Error> {
        let mut sink = NodeSink::gradient(fq, lv);
        self.prob.node.get().eval(t, q, v, &mut sink);
        if sink.outside() {
            return Err(Error::outside_pattern());
        }
        let finite = |x: &[f64]| x.iter().all(|c| c.is_finite());
        if !(finite(fq) && finite(lv)) {
            return Err(Error::NonFiniteModel { step: 0, t });
        }
        Ok(())
    }

    fn velocity(
        &mut self,
        (t, q, p): (f64, &[f64], &[f64]),
        v: &mut [f64],
        step: usize,
    ) -> Result<(), Error> {
        let (node, pattern) = (self.prob.node.get(), &self.prob.pattern);
        self.velocity.solve(node, pattern, (t, q, p), v, step)
    }

    fn mass_sign(&mut self, at: (f64, &[f64], &[f64])) -> Result<f64, Error> {
        let (node, pattern) = (self.prob.node.get(), &self.prob.pattern);
        self.velocity.check_mass(node, pattern, at)?;
        Ok(1.0)
    }

    /// The sparse LU gives no determinant's sign: a singular mass at the step's end shows
    /// in the velocity solve that follows ([`Error::SingularMassMatrix`]).
    fn mass_at_end(&mut self, _at: (f64, &[f64], &[f64]), _sign: f64) -> Result<(), StepFailure> {
        Ok(())
    }

    fn linearize(&mut self) -> Result<(), StepFailure> {
        self.linearize_with(true)
    }

    fn apply_node(&self, i: usize, (dx, dv): (&[f64], &[f64]), dfq: &mut [f64], dlv: &mut [f64]) {
        let Some(blk) = self.prob.blocks.get(i) else {
            dfq.fill(f64::NAN);
            dlv.fill(f64::NAN);
            return;
        };
        dfq.fill(0.0);
        dlv.fill(0.0);
        for (k, (r, c)) in self.prob.pattern.entries().enumerate() {
            dfq[r] += blk.a[k] * dx[c] + blk.b[k] * dv[c];
            dlv[r] += blk.c[k] * dx[c] + blk.e[k] * dv[c];
        }
    }

    fn solve_linearized(&mut self, b: &mut [f64]) {
        match self.tangent.as_mut() {
            Some(t) => t.solve_factored(b),
            None => b.fill(f64::NAN),
        }
    }

    fn tangent_blocks(&self) -> bool {
        true
    }

    fn apply_node_block(
        &self,
        i: usize,
        (dx, dv): (&[f64], &[f64]),
        dfq: &mut [f64],
        dlv: &mut [f64],
    ) {
        let Some(blk) = self.prob.blocks.get(i) else {
            dfq.fill(f64::NAN);
            dlv.fill(f64::NAN);
            return;
        };
        dfq.fill(0.0);
        dlv.fill(0.0);
        // Each direction's entries take the operations of `apply_node`, in its order.
        let (dx, _) = dx.as_chunks::<TANGENT_BLOCK>();
        let (dv, _) = dv.as_chunks::<TANGENT_BLOCK>();
        let (dfq, _) = dfq.as_chunks_mut::<TANGENT_BLOCK>();
        let (dlv, _) = dlv.as_chunks_mut::<TANGENT_BLOCK>();
        for (k, (r, c)) in self.prob.pattern.entries().enumerate() {
            let (a, b, cc, e) = (blk.a[k], blk.b[k], blk.c[k], blk.e[k]);
            let (x, v) = (&dx[c], &dv[c]);
            for ((f, &x), &v) in dfq[r].iter_mut().zip(x).zip(v) {
                *f += a * x + b * v;
            }
            for ((l, &x), &v) in dlv[r].iter_mut().zip(x).zip(v) {
                *l += cc * x + e * v;
            }
        }
    }

    fn solve_linearized_block(&mut self, b: &mut [f64]) {
        match self.tangent.as_mut() {
            Some(t) => t.solve_factored_block(b),
            None => b.fill(f64::NAN),
        }
    }

    fn momentum_tangent(
        &mut self,
        at: (f64, &[f64], &[f64]),
        d: (&[f64], &[f64]),
        dp: &mut [f64],
    ) -> Result<(), Error> {
        let (node, pattern) = (self.prob.node.get(), &self.prob.pattern);
        self.velocity.momentum_tangent(node, pattern, at, d, dp)
    }

    fn velocity_tangent(
        &mut self,
        at: (f64, &[f64], &[f64]),
        d: (&[f64], &[f64]),
        dv: &mut [f64],
    ) -> Result<(), Error> {
        let (node, pattern) = (self.prob.node.get(), &self.prob.pattern);
        self.velocity.velocity_tangent(node, pattern, at, d, dv)
    }

    fn constraint_impulse(&self) -> Option<&[f64]> {
        self.saddle.is_some().then_some(&self.impulse[..])
    }

    fn end_multipliers(&self) -> &[f64] {
        &self.mu
    }

    fn constraint_residuals(&mut self, at: (f64, &[f64], &[f64])) -> Result<[f64; 4], Error> {
        let prob = &mut self.prob;
        match prob.cons.as_mut() {
            Some(c) => {
                match &self.rate {
                    Some(rate) => rate(at.0, at.1, &mut self.rate_at),
                    None => self.rate_at.fill(0.0),
                }
                c.residuals(prob.node.get(), &prob.pattern, at, &self.rate_at)
            }
            None => Ok([0.0; 4]),
        }
    }

    fn step_data(&self) -> (f64, f64, &[f64], &[f64]) {
        let p = &self.prob;
        (p.h, p.t0, &p.q0, &p.p0)
    }

    fn force_round_off_rate(&self) -> f64 {
        self.prob.force_round_off_rate()
    }

    fn force_gain(&self, h: f64) -> f64 {
        self.prob.force_gain(h)
    }

    fn restore(&mut self, h: f64, t0: f64, (q0, p0): (&[f64], &[f64]), z: &[f64]) {
        let prob = &mut self.prob;
        prob.h = h;
        prob.t0 = t0;
        prob.q0.copy_from_slice(q0);
        prob.p0.copy_from_slice(p0);
        self.z.copy_from_slice(z);
        self.newton.invalidate();
    }

    fn linearize_transposed(&mut self) -> Result<(), StepFailure> {
        // The backward pass solves with the transpose alone: the Jacobian is assembled,
        // not factored.
        self.linearize_with(false)?;
        let Some(tangent) = self.tangent.as_ref() else {
            return Err(StepFailure::Newton(NewtonFailure::SingularJacobian));
        };
        if self.adjoint.is_none() {
            let t = tangent
                .lu()
                .transposed()
                .map_err(|_| StepFailure::Newton(NewtonFailure::SingularJacobian))?;
            self.adjoint = Some(t);
        }
        let Some((lu_t, map)) = self.adjoint.as_mut() else {
            return Err(StepFailure::Newton(NewtonFailure::SingularJacobian));
        };
        tangent.lu().fill_transposed(lu_t, map);
        lu_t.factor().map_err(StepFailure::Newton)
    }

    fn solve_transposed(&mut self, b: &mut [f64]) {
        match self.adjoint.as_mut() {
            Some((lu_t, _)) => lu_t.solve_in_place(b),
            None => b.fill(f64::NAN),
        }
    }

    fn apply_node_transposed(
        &self,
        i: usize,
        (mf, ml): (&[f64], &[f64]),
        ux: &mut [f64],
        uv: &mut [f64],
    ) {
        let Some(blk) = self.prob.blocks.get(i) else {
            ux.fill(f64::NAN);
            uv.fill(f64::NAN);
            return;
        };
        ux.fill(0.0);
        uv.fill(0.0);
        for (k, (r, c)) in self.prob.pattern.entries().enumerate() {
            ux[c] += blk.a[k] * mf[r] + blk.c[k] * ml[r];
            uv[c] += blk.b[k] * mf[r] + blk.e[k] * ml[r];
        }
    }

    fn momentum_cotangent(
        &mut self,
        at: (f64, &[f64], &[f64]),
        y: &[f64],
        out: (&mut [f64], &mut [f64]),
    ) -> Result<(), Error> {
        let (node, pattern) = (self.prob.node.get(), &self.prob.pattern);
        self.velocity.momentum_cotangent(node, pattern, at, y, out)
    }

    #[inline(always)]
    fn deep_stack(&self) -> bool {
        false
    }

    fn sparse_constraint_terms(
        &mut self,
    ) -> Result<Option<super::SparseConstraintTerms>, StepFailure> {
        let (Some(saddle), Some(mut cons)) = (self.saddle.as_ref(), self.prob.cons.take()) else {
            return Ok(None);
        };
        let terms = self.constraint_terms_on(&mut cons, &saddle.v.clone());
        self.prob.cons = Some(cons);
        terms.map(Some)
    }

    fn end_velocity(&self) -> Option<&[f64]> {
        self.saddle.as_ref().map(|s| &s.v[..])
    }

    fn restore_end(&mut self, mu: &[f64], v1: &[f64]) {
        if self.mu.len() == mu.len() {
            self.mu.copy_from_slice(mu);
        }
        if let Some(saddle) = self.saddle.as_mut().filter(|s| s.v.len() == v1.len()) {
            saddle.v.copy_from_slice(v1);
        }
    }

    fn solve_end_projection(&mut self, rhs: &mut [f64]) -> bool {
        match self.end_tangent.as_mut() {
            Some(saddle) if self.end_factored => {
                saddle.solve(rhs);
                true
            }
            _ => false,
        }
    }
}

impl SparseBackend<'_> {
    /// The step Jacobian at the solution into the tangent's buffers, factored (`factor`)
    /// or only assembled.
    fn linearize_with(&mut self, factor: bool) -> Result<(), StepFailure> {
        if self.tangent.is_none() {
            let lu = self
                .newton
                .lu()
                .with_same_pattern()
                .map_err(|_| StepFailure::Newton(NewtonFailure::SingularJacobian))?;
            self.tangent = Some(SparseNewton::new(lu, *self.newton.options()));
        }
        let Some(tangent) = self.tangent.as_mut() else {
            return Err(StepFailure::Newton(NewtonFailure::SingularJacobian));
        };
        let prob = &mut self.prob;
        let made = if factor {
            tangent.factor_at(prob, &self.z)
        } else {
            tangent.assemble_at(prob, &self.z)
        };
        made.map_err(|f| {
            if prob.outside {
                StepFailure::OutsidePattern
            } else {
                StepFailure::Newton(f)
            }
        })
    }

    /// [`StepBackend::sparse_constraint_terms`] with the step's constraints `cons` (taken
    /// out of the step for the call) and the projected end velocity `v1`: at the control
    /// points of the last linearisation, with the step's multipliers, and at the end, whose
    /// projection matrix is factored again at `(q₁, v₁)` (the step's own factors are those
    /// of its last iterate).
    fn constraint_terms_on(
        &mut self,
        cons: &mut crate::sparse::constraints::StepConstraints,
        v1: &[f64],
    ) -> Result<super::SparseConstraintTerms, StepFailure> {
        self.end_factored = false;
        let prob = &self.prob;
        let (sch, h, n, m) = (prob.scheme, prob.h, prob.n, cons.m);
        let (s, s1) = (sch.stages(), sch.stages() - 1);
        let nz = n * s1;
        let node = prob.node.get();
        let mut lambda = vec![0.0; m];
        let (mut g, mut k) = (Vec::with_capacity(s), Vec::with_capacity(s1));
        let mut kmu = Vec::new();
        let failed = |f: NewtonFailure| StepFailure::Newton(f);
        for j in 0..s {
            let t = prob.t0 + sch.c()[j] * h;
            let x = &prob.xs[j * n..(j + 1) * n];
            if j < s1 {
                for (kk, l) in lambda.iter_mut().enumerate() {
                    *l = self.z[nz + kk * s1 + j];
                }
            } else {
                // The impulse `μ̂ = (b_{s−1}/h) ŵ_{s−1}`.
                let wb = sch.b()[s1] / h;
                for (l, w) in lambda.iter_mut().zip(&self.mu) {
                    *l = wb * w;
                }
            }
            cons.eval(node, &prob.pattern, (j, t, x), &lambda)
                .map_err(failed)?;
            g.push(cons.jac_at(j).to_vec());
            if j < s1 {
                k.push(cons.curvature.clone());
            } else {
                kmu = cons.curvature.clone();
            }
        }
        // `C₁` and `E₁` at the projected end.
        let (t1, q1) = (prob.t0 + h, &prob.xs[s1 * n..s * n]);
        let (mut lq_f, mut lv) = (vec![0.0; n], vec![0.0; n]);
        let mut blocks = crate::model::NodeBlocks::zeros(prob.pattern.nnz());
        let mut sink = NodeSink::values(&mut lq_f, &mut lv, &prob.pattern, &mut blocks);
        node.eval(t1, q1, v1, &mut sink);
        let outside = sink.outside();
        let finite = |x: &[f64]| x.iter().all(|v| v.is_finite());
        if outside || !(finite(&blocks.c) && finite(&blocks.e)) {
            return Err(failed(NewtonFailure::NonFinite));
        }
        let c1k: Vec<f64> = blocks.c.iter().zip(&kmu).map(|(c, k)| c + k).collect();
        // `H = ∂(G v₁)/∂q` from the kernels' second derivatives, where `g` does not read `t`
        // (else the stepper takes it with dual numbers, `∂²g/∂t∂q` included).
        let rate = if self.rate.is_none() {
            let (mut gval, mut entries) = (vec![0.0; m], Vec::new());
            let mut sink = crate::model::ConstraintSink::rate(&mut gval, v1, &mut entries);
            node.eval_constraints(t1, q1, &mut sink);
            if sink.outside() {
                return Err(failed(NewtonFailure::NonFinite));
            }
            if !entries.iter().all(|e| e.2.is_finite()) {
                return Err(failed(NewtonFailure::NonFinite));
            }
            Some(entries)
        } else {
            None
        };
        let g_pattern = &cons.pattern;
        if self.end_tangent.is_none() {
            let saddle = Saddle::new(&prob.pattern, g_pattern)
                .map_err(|_| failed(NewtonFailure::SingularJacobian))?;
            self.end_tangent = Some(Box::new(saddle));
        }
        if let Some(saddle) = self.end_tangent.as_mut() {
            saddle
                .factor_with(&prob.pattern, &blocks.e, &g[s1])
                .map_err(failed)?;
            self.end_factored = true;
        }
        Ok(super::SparseConstraintTerms {
            g_entries: g_pattern.entries().collect(),
            g,
            node_entries: prob.pattern.entries().collect(),
            k,
            c1k,
            kmu,
            v1: v1.to_vec(),
            rate,
        })
    }
}
