//! The dense backend: `N × N` node blocks from the model's node kernels, the step Jacobian
//! of DESIGN §3 as a dense matrix, factored by LU with partial pivoting ([`crate::Newton`]).

use nalgebra::{DMatrix, DVector, SVector};

use super::{Layout, StepBackend, StepFailure};
use crate::error::Error;
use crate::initial::{mass_check, mass_factor, solve_velocity, MIN_MASS_RCOND};
use crate::model::ForcedLagrangian;
use crate::newton::{Newton, NewtonOptions, NewtonReport};
use crate::scalar::all_finite;
use crate::scheme::Scheme;
use crate::step_equations::StepProblem;

/// The dense step equations, their Newton solver and the unknowns.
pub(crate) struct DenseBackend<'a, M, const N: usize> {
    prob: StepProblem<'a, M, N>,
    newton: Newton,
    z: DVector<f64>,
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

    #[inline(always)]
    fn deep_stack(&self) -> bool {
        true
    }
}
