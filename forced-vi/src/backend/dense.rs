//! The dense backend: `N × N` node blocks from the model's node kernels, the step Jacobian
//! of DESIGN §3 as a dense matrix, factored by LU with partial pivoting ([`crate::Newton`]).

use nalgebra::{DMatrix, DVector, SVector};

use super::{Layout, StepBackend, StepFailure};
use crate::error::Error;
use crate::initial::{mass_check, mass_factor, solve_velocity, MIN_MASS_RCOND};
use crate::model::ForcedLagrangian;
use crate::newton::{solve_small, DenseLu, Newton, NewtonOptions, NewtonReport};
use crate::scalar::all_finite;
use crate::scheme::Scheme;
use crate::step_equations::StepProblem;

/// The dense step equations, their Newton solver and the unknowns.
pub(crate) struct DenseBackend<'a, M, const N: usize> {
    prob: StepProblem<'a, M, N>,
    newton: Newton,
    z: DVector<f64>,
    /// The right-hand side of a tangent solve (made on the first one).
    rhs: DVector<f64>,
    /// The transposed step Jacobian and its factors, for adjoints (made on first use).
    adjoint: Option<(DMatrix<f64>, DenseLu)>,
}

impl<'a, M: ForcedLagrangian<N>, const N: usize> DenseBackend<'a, M, N> {
    /// Buffers for `model` and `scheme`.
    pub(crate) fn new(model: &'a M, scheme: &'a Scheme, newton: NewtonOptions) -> Self {
        let (s, r) = (scheme.stages(), scheme.quadrature_nodes());
        let dim = (s - 1) * N;
        let zero = SVector::<f64, N>::zeros();
        let grad = crate::model::NodeGradient { fq: zero, lv: zero };
        DenseBackend {
            prob: StepProblem {
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
                base: DMatrix::zeros(dim, dim),
                base_h: f64::NAN,
            },
            newton: Newton::new(dim, newton),
            z: DVector::zeros(dim),
            rhs: DVector::zeros(0),
            adjoint: None,
        }
    }
}

/// `x` as a vector of the model's size (a caller's slice always has `N` entries).
#[inline(always)]
fn vector<const N: usize>(x: &[f64]) -> SVector<f64, N> {
    SVector::from_column_slice(x)
}

impl<M: ForcedLagrangian<N>, const N: usize> StepBackend for DenseBackend<'_, M, N> {
    #[inline(always)]
    fn layout(&self) -> Layout {
        Layout::new(N, self.prob.scheme.stages() - 1, false)
    }

    #[inline(always)]
    fn scheme(&self) -> &Scheme {
        self.prob.scheme
    }

    #[inline(always)]
    fn z(&self) -> &[f64] {
        self.z.as_slice()
    }

    #[inline(always)]
    fn z_mut(&mut self) -> &mut [f64] {
        self.z.as_mut_slice()
    }

    #[inline]
    fn solve(
        &mut self,
        h: f64,
        t0: f64,
        (q0, p0): (&[f64], &[f64]),
        scale: f64,
    ) -> Result<NewtonReport, StepFailure> {
        let prob = &mut self.prob;
        prob.h = h;
        prob.t0 = t0;
        prob.q0.as_mut_slice().copy_from_slice(q0);
        prob.p0.as_mut_slice().copy_from_slice(p0);
        self.newton.invalidate();
        self.newton
            .solve(prob, &mut self.z, scale)
            .map_err(StepFailure::Newton)
    }

    #[inline(always)]
    fn last_iterations(&self) -> usize {
        self.newton.last_iterations()
    }

    #[inline(always)]
    fn node_fq(&self, i: usize) -> &[f64] {
        self.prob.grads[i].fq.as_slice()
    }

    #[inline(always)]
    fn node_x(&self, i: usize) -> &[f64] {
        self.prob.xs[i].as_slice()
    }

    #[inline(always)]
    fn node_v(&self, i: usize) -> &[f64] {
        self.prob.vs[i].as_slice()
    }

    fn gradient(
        &mut self,
        (t, q, v): (f64, &[f64], &[f64]),
        fq: &mut [f64],
        lv: &mut [f64],
    ) -> Result<(), Error> {
        let g = self
            .prob
            .model
            .node_gradient_at(t, &vector::<N>(q), &vector::<N>(v));
        if !(all_finite(&g.lv) && all_finite(&g.fq)) {
            return Err(Error::NonFiniteModel { step: 0, t });
        }
        fq.copy_from_slice(g.fq.as_slice());
        lv.copy_from_slice(g.lv.as_slice());
        Ok(())
    }

    fn velocity(
        &mut self,
        (t, q, p): (f64, &[f64], &[f64]),
        v: &mut [f64],
        step: usize,
    ) -> Result<(), Error> {
        let model = self.prob.model;
        let solved = solve_velocity(model, &vector(q), &vector(p), vector(v), step, t)?;
        v.copy_from_slice(solved.as_slice());
        Ok(())
    }

    fn mass_sign(&mut self, (t, q, v): (f64, &[f64], &[f64])) -> Result<f64, Error> {
        mass_check(self.prob.model, &vector(q), &vector(v), 0, t)
    }

    fn mass_at_end(
        &mut self,
        (t, q, v): (f64, &[f64], &[f64]),
        sign: f64,
    ) -> Result<(), StepFailure> {
        let e = self.prob.model.mass_matrix_at(t, &vector(q), &vector(v));
        match mass_factor(&e) {
            Some((rcond, s)) if rcond >= MIN_MASS_RCOND && s == sign => Ok(()),
            other => {
                // A change of sign means a singular mass was crossed: condition 0.
                let rcond = match other {
                    Some((rc, s)) if s == sign => rc,
                    _ => 0.0,
                };
                Err(StepFailure::SingularMass { rcond })
            }
        }
    }

    fn linearize(&mut self) -> Result<(), StepFailure> {
        self.newton
            .factor_at(&mut self.prob, &self.z)
            .map_err(StepFailure::Newton)
    }

    fn apply_node(&self, i: usize, (dx, dv): (&[f64], &[f64]), dfq: &mut [f64], dlv: &mut [f64]) {
        let Some(nj) = self.prob.jacs.get(i) else {
            dfq.fill(f64::NAN);
            dlv.fill(f64::NAN);
            return;
        };
        let (dx, dv) = (vector::<N>(dx), vector::<N>(dv));
        dfq.copy_from_slice((nj.a * dx + nj.b * dv).as_slice());
        dlv.copy_from_slice((nj.c * dx + nj.e * dv).as_slice());
    }

    fn solve_linearized(&mut self, b: &mut [f64]) {
        if self.rhs.len() != b.len() {
            self.rhs = DVector::zeros(b.len());
        }
        self.rhs.as_mut_slice().copy_from_slice(b);
        self.newton.solve_factored(&mut self.rhs);
        b.copy_from_slice(self.rhs.as_slice());
    }

    fn momentum_tangent(
        &mut self,
        (t, q, v): (f64, &[f64], &[f64]),
        (dq, dv): (&[f64], &[f64]),
        dp: &mut [f64],
    ) -> Result<(), Error> {
        let nj = self.prob.model.node_jacobian_at(t, &vector(q), &vector(v));
        let out = nj.c * vector::<N>(dq) + nj.e * vector::<N>(dv);
        if !all_finite(&out) {
            return Err(Error::NonFiniteModel { step: 0, t });
        }
        dp.copy_from_slice(out.as_slice());
        Ok(())
    }

    fn velocity_tangent(
        &mut self,
        (t, q, v): (f64, &[f64], &[f64]),
        (dq, dp): (&[f64], &[f64]),
        dv: &mut [f64],
    ) -> Result<(), Error> {
        let nj = self.prob.model.node_jacobian_at(t, &vector(q), &vector(v));
        let rhs = vector::<N>(dp) - nj.c * vector::<N>(dq);
        match solve_small(&nj.e, &rhs) {
            Some((x, rcond)) if rcond >= MIN_MASS_RCOND && all_finite(&x) => {
                dv.copy_from_slice(x.as_slice());
                Ok(())
            }
            other => Err(Error::SingularMassMatrix {
                step: 0,
                t,
                rcond: other.map_or(0.0, |(_, rc)| rc),
            }),
        }
    }

    fn step_data(&self) -> (f64, f64, &[f64], &[f64]) {
        let p = &self.prob;
        (p.h, p.t0, p.q0.as_slice(), p.p0.as_slice())
    }

    fn restore(&mut self, h: f64, t0: f64, (q0, p0): (&[f64], &[f64]), z: &[f64]) {
        let prob = &mut self.prob;
        prob.h = h;
        prob.t0 = t0;
        prob.q0.as_mut_slice().copy_from_slice(q0);
        prob.p0.as_mut_slice().copy_from_slice(p0);
        self.z.as_mut_slice().copy_from_slice(z);
        self.newton.invalidate();
    }

    fn linearize_transposed(&mut self) -> Result<(), StepFailure> {
        self.linearize()?;
        let jac = self.newton.jacobian();
        let dim = jac.nrows();
        let (jt, lu) = self
            .adjoint
            .get_or_insert_with(|| (DMatrix::zeros(dim, dim), DenseLu::new(dim)));
        jac.transpose_to(jt);
        lu.factor(jt).map_err(StepFailure::Newton)
    }

    fn solve_transposed(&mut self, b: &mut [f64]) {
        let Some((_, lu)) = self.adjoint.as_ref() else {
            b.fill(f64::NAN);
            return;
        };
        if self.rhs.len() != b.len() {
            self.rhs = DVector::zeros(b.len());
        }
        self.rhs.as_mut_slice().copy_from_slice(b);
        lu.solve_in_place(&mut self.rhs);
        b.copy_from_slice(self.rhs.as_slice());
    }

    fn apply_node_transposed(
        &self,
        i: usize,
        (mf, ml): (&[f64], &[f64]),
        ux: &mut [f64],
        uv: &mut [f64],
    ) {
        let Some(nj) = self.prob.jacs.get(i) else {
            ux.fill(f64::NAN);
            uv.fill(f64::NAN);
            return;
        };
        let (mf, ml) = (vector::<N>(mf), vector::<N>(ml));
        ux.copy_from_slice((nj.a.tr_mul(&mf) + nj.c.tr_mul(&ml)).as_slice());
        uv.copy_from_slice((nj.b.tr_mul(&mf) + nj.e.tr_mul(&ml)).as_slice());
    }

    fn momentum_cotangent(
        &mut self,
        (t, q, v): (f64, &[f64], &[f64]),
        y: &[f64],
        (cq, ev): (&mut [f64], &mut [f64]),
    ) -> Result<(), Error> {
        let nj = self.prob.model.node_jacobian_at(t, &vector(q), &vector(v));
        let y = vector::<N>(y);
        let (a, b) = (nj.c.tr_mul(&y), nj.e.tr_mul(&y));
        if !(all_finite(&a) && all_finite(&b)) {
            return Err(Error::NonFiniteModel { step: 0, t });
        }
        cq.copy_from_slice(a.as_slice());
        ev.copy_from_slice(b.as_slice());
        Ok(())
    }

    #[inline(always)]
    fn deep_stack(&self) -> bool {
        true
    }
}
