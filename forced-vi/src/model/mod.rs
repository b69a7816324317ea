//! The model interface: what a forced Lagrangian system provides to the integrator.
//!
//! A model implements [`ForcedLagrangian`]: a Lagrangian `L(q, v)` and a non-conservative force
//! `F(q, v)`, both generic over the [`Scalar`] so that num-dual can differentiate them. The
//! integrator only ever calls the two *node kernels*, [`ForcedLagrangian::node_gradient`] and
//! [`ForcedLagrangian::node_jacobian`], which have general dual-number defaults in
//! [`general`]. The `#[forced_lagrangian]` macro overrides them with kernels specialised to
//! the model's structure (DESIGN §2, "Specialise").

use nalgebra::{SMatrix, SVector};

use crate::scalar::{Scalar, lift};

mod sparse_node;
#[cfg(test)]
mod tests;

#[cfg(feature = "sparse")]
pub(crate) use sparse_node::DualConstraints;
pub use sparse_node::{Block, ConstraintSink, NodeBlocks, NodePattern, NodeSink, SparseNode};

/// Which derivative blocks a model can have; the macro fills this in from the expressions.
///
/// The flags are promises: `false` means the quantity is identically zero (or constant), and
/// the runtime may skip work for it. The default, [`Structure::GENERAL`], promises nothing.
/// The integrator checks each promise at the initial state and beside it, and refuses a
/// broken one with [`crate::Error::InvalidModel`] (see the guide's `STRUCTURE`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Structure {
    /// The model has a non-conservative force.
    pub has_force: bool,
    /// The force depends on the velocities (so `∂F/∂v` is not zero).
    pub force_uses_velocity: bool,
    /// The mass matrix `E = ∂²L/∂v²` is constant and `C = ∂²L/∂v∂q` is zero.
    pub constant_mass: bool,
    /// The step equations are linear with constant coefficients: `L` is a polynomial of
    /// degree at most two and `F` one of degree at most one in `(q, v)`, neither depending
    /// on `t`, so the node blocks `A, B, C, E` are the same at every state. Fixed steps of
    /// one size then keep one factorisation for the whole run and accept the first Newton
    /// correction made with it as they would a fresh one's (see
    /// [`NewtonOptions::simplified`](crate::NewtonOptions::simplified)).
    pub linear: bool,
    /// The model depends on time explicitly: it overrides
    /// [`ForcedLagrangian::lagrangian_at`] or [`ForcedLagrangian::force_at`]. When `false`,
    /// the integrator calls the autonomous kernels and leaves out `∂L/∂t` (a model that
    /// does use `t` under a `false` flag is refused by [`crate::Integrator`]'s first step).
    pub uses_time: bool,
}

impl Structure {
    /// No structural knowledge: every block is computed.
    pub const GENERAL: Structure = Structure {
        has_force: true,
        force_uses_velocity: true,
        constant_mass: false,
        linear: false,
        uses_time: false,
    };

    /// [`Structure::GENERAL`] for a model that depends on time.
    pub const GENERAL_DRIVEN: Structure = Structure {
        uses_time: true,
        ..Structure::GENERAL
    };
}

/// The physical-limit gradient of the doubled Lagrangian at one node:
/// `∂Λ/∂q₋ = L_q + F` and `∂Λ/∂v₋ = L_v` (DESIGN §2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeGradient<const N: usize> {
    /// `L_q(q, v) + F(q, v)`.
    pub fq: SVector<f64, N>,
    /// `L_v(q, v)`, the momentum.
    pub lv: SVector<f64, N>,
}

/// The physical-limit gradient and mixed second derivative of Λ at one node.
///
/// `A = ∂(L_q + F)/∂q`, `B = ∂(L_q + F)/∂v`, `C = ∂L_v/∂q`, `E = ∂L_v/∂v` (the mass matrix).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeJacobian<const N: usize> {
    /// The gradient blocks at the same node.
    pub grad: NodeGradient<N>,
    /// `∂(L_q + F)/∂q`.
    pub a: SMatrix<f64, N, N>,
    /// `∂(L_q + F)/∂v`.
    pub b: SMatrix<f64, N, N>,
    /// `∂L_v/∂q`.
    pub c: SMatrix<f64, N, N>,
    /// `∂L_v/∂v`, the mass matrix.
    pub e: SMatrix<f64, N, N>,
}

/// A forced Lagrangian system with `N` degrees of freedom.
///
/// Implement [`lagrangian`](Self::lagrangian) and, for a forced system,
/// [`force`](Self::force); everything else has a default. Usually the
/// `#[forced_lagrangian]` macro writes this impl.
///
/// ```
/// use forced_vi::prelude::*;
///
/// /// A damped harmonic oscillator: L = ½v² − ½kq², F = −cv.
/// struct Damped { k: f64, c: f64 }
///
/// impl ForcedLagrangian<1> for Damped {
///     fn lagrangian<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> D {
///         v[0] * v[0] * 0.5 - q[0] * q[0] * (0.5 * self.k)
///     }
///     fn force<D: Scalar>(&self, _q: &[D; 1], v: &[D; 1]) -> [D; 1] {
///         [-v[0] * self.c]
///     }
/// }
///
/// let model = Damped { k: 1.0, c: 0.1 };
/// let j = model.node_jacobian(&[0.5].into(), &[0.0].into());
/// assert_eq!(j.e[(0, 0)], 1.0);   // mass
/// assert_eq!(j.a[(0, 0)], -1.0);  // −k
/// assert_eq!(j.b[(0, 0)], -0.1);  // −c
/// ```
pub trait ForcedLagrangian<const N: usize> {
    /// What the runtime may skip; see [`Structure`].
    const STRUCTURE: Structure = Structure::GENERAL;

    /// The names of the coordinates, for reports and error messages.
    fn coordinate_names(&self) -> [&'static str; N] {
        ["q"; N]
    }

    /// The Lagrangian `L(q, v)`.
    fn lagrangian<D: Scalar>(&self, q: &[D; N], v: &[D; N]) -> D;

    /// The non-conservative generalised force `F(q, v)`; zero unless overridden.
    fn force<D: Scalar>(&self, q: &[D; N], v: &[D; N]) -> [D; N] {
        let _ = (q, v);
        [D::from(0.0); N]
    }

    /// The Lagrangian at time `t`, `L(t, q, v)`. Autonomous models keep the default, which
    /// is [`Self::lagrangian`]. A driven model overrides it (and [`Self::force_at`]) and sets
    /// `STRUCTURE.uses_time`; its [`Self::lagrangian`] is then its value at `t = 0`.
    fn lagrangian_at<D: Scalar>(&self, t: D, q: &[D; N], v: &[D; N]) -> D {
        let _ = t;
        self.lagrangian(q, v)
    }

    /// The force at time `t`, `F(t, q, v)`; the default is [`Self::force`].
    fn force_at<D: Scalar>(&self, t: D, q: &[D; N], v: &[D; N]) -> [D; N] {
        let _ = t;
        self.force(q, v)
    }

    /// The names of the parameters `θ` that [`crate::output::Tangents`]
    /// differentiates, in order: the struct's fields for a `#[forced_lagrangian]` model.
    /// The default is none (no parameter columns); a hand-written model declares its
    /// parameters by overriding this, [`Self::parameter_values`],
    /// [`Self::lagrangian_with`] and [`Self::force_with`].
    fn parameter_names(&self) -> &'static [&'static str] {
        &[]
    }

    /// The values of the parameters, in the order of [`Self::parameter_names`].
    fn parameter_values(&self) -> Vec<f64> {
        Vec::new()
    }

    /// `L(t, q, v)` with the parameters set to `theta` (dual numbers, so that the runtime
    /// can differentiate in them). The default ignores `theta`.
    fn lagrangian_with<D: Scalar>(&self, t: D, q: &[D; N], v: &[D; N], theta: &[D]) -> D {
        let _ = theta;
        self.lagrangian_at(t, q, v)
    }

    /// `F(t, q, v)` with the parameters set to `theta`; the default ignores `theta`.
    fn force_with<D: Scalar>(&self, t: D, q: &[D; N], v: &[D; N], theta: &[D]) -> [D; N] {
        let _ = theta;
        self.force_at(t, q, v)
    }

    /// Whether the model may have holonomic constraints. `false` promises that
    /// [`ForcedLagrangian::constraint_count`] is 0, and the runtime then compiles none of a
    /// constrained step's code for the model (its constraint rows, projection and dual-number
    /// constraint kernels): a smaller, faster build. The default, `true`, promises nothing;
    /// the macro sets `false` for a model without `constraints(...)`. A model that breaks the
    /// promise is refused by [`crate::Integrator::new`] ([`crate::Error::InvalidModel`]).
    const CONSTRAINED: bool = true;

    /// `false` promises that [`ForcedLagrangian::constraints`] does not read `t` (a fixed
    /// constraint): the runtime then leaves out the rate `∂g/∂t` that a constraint reading
    /// the time adds to the velocity-level constraint `G v + ∂g/∂t = 0` and to the work of
    /// the constraint forces (DESIGN §11). The default, `true`, promises nothing (the rate is
    /// computed, and is zero for a fixed constraint); the macro sets `false` when no
    /// constraint names `t`. A model that breaks the promise at its initial positions is
    /// refused by the first step ([`crate::Error::InvalidModel`]).
    const CONSTRAINTS_READ_TIME: bool = true;

    /// The number `m` of holonomic constraints `g(t, q) = 0` (DESIGN §11); none by default.
    fn constraint_count(&self) -> usize {
        0
    }

    /// The constraints `g(t, q)`, `m` values written to `g`. Each must vanish on the
    /// motion; they may not read velocities (nonholonomic constraints are not supported).
    fn constraints<D: Scalar>(&self, t: D, q: &[D; N], g: &mut [D]) {
        let _ = (t, q, g);
    }

    /// `g(t, q)` with the parameters set to `theta` (dual numbers, so that sensitivities
    /// can differentiate the constraints in them, DESIGN §12). The default ignores `theta`:
    /// a hand-written model whose constraints read a parameter must write this too, as it
    /// writes [`ForcedLagrangian::lagrangian_with`]; the macro writes it.
    fn constraints_with<D: Scalar>(&self, t: D, q: &[D; N], theta: &[D], g: &mut [D]) {
        let _ = theta;
        self.constraints(t, q, g)
    }

    /// Stack bytes that one call of a node kernel may need. The integrator runs the
    /// kernels on a stack at least this deep (growing it on the heap when the caller's is
    /// too shallow), so a large model cannot overflow a 2 MiB thread stack. The default
    /// bounds the general dual-number kernels of [`general`]; the macro sets it from the
    /// dual numbers its own kernels use.
    const KERNEL_STACK_BYTES: usize = general::stack_bytes::<N>();

    /// Checks the model's parameters; the name of the first non-finite one is the error.
    fn check_parameters(&self) -> Result<(), &'static str> {
        Ok(())
    }

    /// Checks what the compiler could not see, such as array indices against a length
    /// that is a const parameter. The message says what is wrong; [`crate::Integrator::new`]
    /// returns it as [`crate::Error::InvalidModel`].
    fn check_model(&self) -> Result<(), String> {
        Ok(())
    }

    /// The node kernel for residuals: `(L_q + F, L_v)` at `(q, v)`.
    fn node_gradient(&self, q: &SVector<f64, N>, v: &SVector<f64, N>) -> NodeGradient<N>
    where
        Self: Sized,
    {
        general::node_gradient(self, q, v)
    }

    /// The node kernel at time `t`: the autonomous [`Self::node_gradient`] unless the model
    /// uses time.
    #[inline]
    fn node_gradient_at(&self, t: f64, q: &SVector<f64, N>, v: &SVector<f64, N>) -> NodeGradient<N>
    where
        Self: Sized,
    {
        if Self::STRUCTURE.uses_time {
            general::node_gradient_at(self, t, q, v)
        } else {
            self.node_gradient(q, v)
        }
    }

    /// The Jacobian node kernel at time `t` (see [`Self::node_gradient_at`]).
    #[inline]
    fn node_jacobian_at(&self, t: f64, q: &SVector<f64, N>, v: &SVector<f64, N>) -> NodeJacobian<N>
    where
        Self: Sized,
    {
        if Self::STRUCTURE.uses_time {
            general::node_jacobian_at(self, t, q, v)
        } else {
            self.node_jacobian(q, v)
        }
    }

    /// The mass matrix at time `t`.
    #[inline]
    fn mass_matrix_at(&self, t: f64, q: &SVector<f64, N>, v: &SVector<f64, N>) -> SMatrix<f64, N, N>
    where
        Self: Sized,
    {
        if Self::STRUCTURE.uses_time {
            general::node_jacobian_at(self, t, q, v).e
        } else {
            self.mass_matrix(q, v)
        }
    }

    /// `∂L/∂t` at `(t, q, v)`: zero for an autonomous model.
    fn lagrangian_dt(&self, t: f64, q: &SVector<f64, N>, v: &SVector<f64, N>) -> f64
    where
        Self: Sized,
    {
        if Self::STRUCTURE.uses_time {
            let (qa, va): ([f64; N], [f64; N]) = ((*q).into(), (*v).into());
            let l = self.lagrangian_at(num_dual::Dual64::new(t, 1.0), &lift(&qa), &lift(&va));
            l.eps
        } else {
            0.0
        }
    }

    /// The node kernel for Newton Jacobians: gradient plus the blocks `A, B, C, E`.
    fn node_jacobian(&self, q: &SVector<f64, N>, v: &SVector<f64, N>) -> NodeJacobian<N>
    where
        Self: Sized,
    {
        general::node_jacobian(self, q, v)
    }

    /// The mass matrix `E = ∂²L/∂v²` at `(q, v)`.
    fn mass_matrix(&self, q: &SVector<f64, N>, v: &SVector<f64, N>) -> SMatrix<f64, N, N>
    where
        Self: Sized,
    {
        self.node_jacobian(q, v).e
    }

    /// The energy `E = v · L_v − L` at `(q, v)`.
    fn energy(&self, q: &SVector<f64, N>, v: &SVector<f64, N>) -> f64
    where
        Self: Sized,
    {
        let lv = self.node_gradient(q, v).lv;
        v.dot(&lv) - self.lagrangian::<f64>(&(*q).into(), &(*v).into())
    }

    /// The model's sparse node kernels (DESIGN §9), if it has them. `#[forced_lagrangian]`
    /// returns them for a model it can split into local terms; the default, `None`, keeps the
    /// dense path.
    fn sparse_node(&self) -> Option<&dyn SparseNode> {
        None
    }
}

/// General node kernels built from num-dual's derivative drivers.
///
/// They need nothing but [`ForcedLagrangian::lagrangian`] and [`ForcedLagrangian::force`],
/// and are exact (no finite differences). Cost per node: for the residual, one first-order
/// pass of `L` over the `2N` directions of `(q, v)` for `N ≤ 8`, two (one in `q`, one in
/// `v`) past that; for the Jacobian, one second-order pass of `L` over `(q, v)` and one
/// first-order pass of `F` for `N ≤ 2`, and past that three second-order evaluations of `L`
/// (in `q`, in `v`, and a hyper-dual one in both) and two first-order Jacobians of `F`.
pub mod general {
    use super::*;
    use nalgebra::SVector;
    use num_dual::{
        Dual2SVec64, DualSVec64, HyperDualSVec64, gradient, hessian, jacobian, partial_hessian,
    };

    /// A bound on the stack that [`node_jacobian`] needs: a few arrays of `N` hyper-dual
    /// numbers over `N + N` directions (or of the fused kernels' dual numbers over the `2N`
    /// directions of `(q, v)`), and the node blocks.
    pub const fn stack_bytes<const N: usize>() -> usize {
        let dual = std::mem::size_of::<HyperDualSVec64<N, N>>();
        let dual2 = std::mem::size_of::<Dual2SVec64<N>>();
        let mut big = if dual > dual2 { dual } else { dual2 };
        let fused = if N <= fused::JACOBIAN_MAX_N {
            2 * std::mem::size_of::<Dual2SVec64<{ 2 * fused::JACOBIAN_MAX_N }>>()
        } else if N <= fused::GRADIENT_MAX_N {
            2 * std::mem::size_of::<DualSVec64<{ 2 * fused::GRADIENT_MAX_N }>>()
        } else {
            0
        };
        if fused > big {
            big = fused;
        }
        let arrays = N.saturating_mul(big).saturating_mul(8);
        let blocks = std::mem::size_of::<NodeJacobian<N>>().saturating_mul(16);
        arrays.saturating_add(blocks).saturating_add(64 * 1024)
    }

    fn arr<T: Copy + nalgebra::Scalar, const N: usize>(x: &SVector<T, N>) -> [T; N] {
        std::array::from_fn(|i| x[i])
    }

    /// `(L_q + F, L_v)` at `(q, v)`.
    pub fn node_gradient<M: ForcedLagrangian<N>, const N: usize>(
        m: &M,
        q: &SVector<f64, N>,
        v: &SVector<f64, N>,
    ) -> NodeGradient<N> {
        node_gradient_at(m, 0.0, q, v)
    }

    /// `(L_q + F, L_v)` at `(t, q, v)`, from [`ForcedLagrangian::lagrangian_at`] and
    /// [`ForcedLagrangian::force_at`].
    pub fn node_gradient_at<M: ForcedLagrangian<N>, const N: usize>(
        m: &M,
        t: f64,
        q: &SVector<f64, N>,
        v: &SVector<f64, N>,
    ) -> NodeGradient<N> {
        match N {
            1 => return fused::gradient::<M, N, 2>(m, t, q, v),
            2 => return fused::gradient::<M, N, 4>(m, t, q, v),
            3 => return fused::gradient::<M, N, 6>(m, t, q, v),
            4 => return fused::gradient::<M, N, 8>(m, t, q, v),
            5 => return fused::gradient::<M, N, 10>(m, t, q, v),
            6 => return fused::gradient::<M, N, 12>(m, t, q, v),
            7 => return fused::gradient::<M, N, 14>(m, t, q, v),
            8 => return fused::gradient::<M, N, 16>(m, t, q, v),
            _ => {}
        }
        split_gradient_at(m, t, q, v)
    }

    /// [`node_gradient_at`] by one first-order pass in `q` and one in `v`.
    pub(crate) fn split_gradient_at<M: ForcedLagrangian<N>, const N: usize>(
        m: &M,
        t: f64,
        q: &SVector<f64, N>,
        v: &SVector<f64, N>,
    ) -> NodeGradient<N> {
        let (qa, va) = (arr(q), arr(v));
        let (_, lq) = gradient(
            |x: SVector<DualSVec64<N>, N>| m.lagrangian_at(t.into(), &arr(&x), &lift(&va)),
            q,
        );
        let (_, lv) = gradient(
            |x: SVector<DualSVec64<N>, N>| m.lagrangian_at(t.into(), &lift(&qa), &arr(&x)),
            v,
        );
        let f = if M::STRUCTURE.has_force {
            SVector::from(m.force_at::<f64>(t, &qa, &va))
        } else {
            SVector::zeros()
        };
        NodeGradient { fq: lq + f, lv }
    }

    /// `g(t, q)` into `g` and its Jacobian `G = ∂g/∂q` (`m × N`) into `jac`, from
    /// [`ForcedLagrangian::constraints`] with one dual-number gradient per constraint.
    pub fn constraint_jacobian_at<M: ForcedLagrangian<N>, const N: usize>(
        m: &M,
        t: f64,
        q: &SVector<f64, N>,
        g: &mut [f64],
        jac: &mut nalgebra::DMatrix<f64>,
    ) {
        let count = m.constraint_count();
        for r in 0..count.min(g.len()).min(jac.nrows()) {
            let (value, grad) = gradient(
                |x: SVector<DualSVec64<N>, N>| {
                    let mut out = vec![DualSVec64::<N>::from(0.0); count];
                    m.constraints(t.into(), &arr(&x), &mut out);
                    out[r]
                },
                q,
            );
            g[r] = value;
            for c in 0..N {
                jac[(r, c)] = grad[c];
            }
        }
    }

    /// `∂g/∂t` at `(t, q)` into `rate` (`m` values): the explicit rate of constraints that
    /// read the time, zero for those that do not. A motion on `g(t, q) = 0` meets
    /// `G v + ∂g/∂t = 0` (DESIGN §11). One evaluation of [`ForcedLagrangian::constraints`] with
    /// a dual number in `t` (none for a model that promises fixed constraints,
    /// [`ForcedLagrangian::CONSTRAINTS_READ_TIME`]).
    pub fn constraint_rate_at<M: ForcedLagrangian<N>, const N: usize>(
        m: &M,
        t: f64,
        q: &[f64],
        rate: &mut [f64],
    ) {
        use num_dual::Dual64;
        rate.fill(0.0);
        if !M::CONSTRAINTS_READ_TIME {
            return;
        }
        let count = m.constraint_count();
        // Small models (the dense backend's) on the stack, without allocating.
        const SMALL: usize = 16;
        if N <= SMALL && count <= SMALL {
            let (mut x, mut g) = ([Dual64::from(0.0); SMALL], [Dual64::from(0.0); SMALL]);
            for (xa, &v) in x.iter_mut().zip(q) {
                *xa = Dual64::from(v);
            }
            if let Ok(arr) = <&[Dual64; N]>::try_from(&x[..N]) {
                m.constraints(Dual64::new(t, 1.0), arr, &mut g[..count]);
            }
            for (r, gk) in rate.iter_mut().zip(&g[..count]) {
                *r = gk.eps;
            }
            return;
        }
        let x: Vec<Dual64> = q.iter().map(|&v| Dual64::from(v)).collect();
        let mut g = vec![Dual64::from(0.0); count];
        if let Ok(arr) = <&[Dual64; N]>::try_from(&x[..]) {
            m.constraints(Dual64::new(t, 1.0), arr, &mut g);
        }
        for (r, gk) in rate.iter_mut().zip(&g) {
            *r = gk.eps;
        }
    }

    /// `Σ_r λ_r ∂²g_r/∂q²` at `(t, q)`, the constraints' curvature weighted by the
    /// multipliers.
    pub fn constraint_curvature_at<M: ForcedLagrangian<N>, const N: usize>(
        m: &M,
        t: f64,
        q: &SVector<f64, N>,
        lambda: &[f64],
    ) -> SMatrix<f64, N, N> {
        let count = m.constraint_count();
        let (_, _, h) = hessian(
            |x: SVector<Dual2SVec64<N>, N>| {
                let mut out = vec![Dual2SVec64::<N>::from(0.0); count];
                m.constraints(t.into(), &arr(&x), &mut out);
                (out.iter().zip(lambda))
                    .fold(Dual2SVec64::<N>::from(0.0), |acc, (g, &l)| acc + *g * l)
            },
            q,
        );
        h
    }

    /// A direction in `(t, q, θ)` for [`constraint_second_at`]: a rate in `t`, one in `q`
    /// (`None`: none) and a unit rate in one parameter (`None`: none).
    #[derive(Clone, Copy, Debug)]
    pub(crate) struct Direction<'a> {
        pub(crate) t: f64,
        pub(crate) q: Option<&'a [f64]>,
        pub(crate) theta: Option<usize>,
    }

    /// The constraints' first derivatives along `d1` and `d2` and their second derivative
    /// along both at `(t, q)` with the parameters `theta`, each `m` values (into `first1`,
    /// `first2`, `second`), from one evaluation of [`ForcedLagrangian::constraints_with`]
    /// with hyper-dual numbers. The sensitivities of a constrained step need them (DESIGN
    /// §12): `Σ_r w_r ∂²g_r/∂q∂θ`, the rate `∂(G v + ∂g/∂t)/∂q`, `∂g/∂θ`.
    pub(crate) fn constraint_second_at<M: ForcedLagrangian<N>, const N: usize>(
        m: &M,
        (t, q, theta): (f64, &[f64], &[f64]),
        (d1, d2): (Direction<'_>, Direction<'_>),
        (first1, first2, second): (&mut [f64], &mut [f64], &mut [f64]),
    ) {
        use num_dual::HyperDual64;
        let count = m.constraint_count();
        let along =
            |d: &Direction<'_>, a: usize| d.q.and_then(|x| x.get(a).copied()).unwrap_or(0.0);
        let at = |x: &[f64], a: usize| x.get(a).copied().unwrap_or(f64::NAN);
        let qh: Vec<HyperDual64> = (0..N)
            .map(|a| HyperDual64::new(at(q, a), along(&d1, a), along(&d2, a), 0.0))
            .collect();
        let unit = |d: &Direction<'_>, k: usize| if d.theta == Some(k) { 1.0 } else { 0.0 };
        let th: Vec<HyperDual64> = (theta.iter().enumerate())
            .map(|(k, &x)| HyperDual64::new(x, unit(&d1, k), unit(&d2, k), 0.0))
            .collect();
        let th_dual = HyperDual64::new(t, d1.t, d2.t, 0.0);
        let mut g = vec![HyperDual64::from(0.0); count];
        if let Ok(arr) = <&[HyperDual64; N]>::try_from(&qh[..]) {
            m.constraints_with(th_dual, arr, &th, &mut g);
        }
        for (r, gr) in g.iter().enumerate() {
            if let (Some(a), Some(b), Some(c)) =
                (first1.get_mut(r), first2.get_mut(r), second.get_mut(r))
            {
                (*a, *b, *c) = (gr.eps1, gr.eps2, gr.eps1eps2);
            }
        }
    }

    /// A bound on the stack that [`constraint_jacobian_at`] and [`constraint_curvature_at`]
    /// need: arrays of `N` second-order dual numbers in `N` directions.
    pub const fn constraint_stack_bytes<const N: usize>() -> usize {
        let dual = std::mem::size_of::<Dual2SVec64<N>>();
        N.saturating_mul(dual)
            .saturating_mul(8)
            .saturating_add(64 * 1024)
    }

    /// A bound on the stack that [`node_parameter_gradient_at`] needs.
    pub const fn parameter_stack_bytes<const N: usize>() -> usize {
        let dual = std::mem::size_of::<HyperDualSVec64<N, 1>>();
        N.saturating_mul(dual)
            .saturating_mul(8)
            .saturating_add(64 * 1024)
    }

    /// `∂(L_q + F)/∂θ_k` and `∂L_v/∂θ_k` at `(t, q, v)`, for the parameters `theta` (the
    /// values of [`ForcedLagrangian::parameter_values`]), from
    /// [`ForcedLagrangian::lagrangian_with`] and [`ForcedLagrangian::force_with`] with
    /// hyper-dual numbers over `(q, θ_k)` and `(v, θ_k)`.
    pub fn node_parameter_gradient_at<M: ForcedLagrangian<N>, const N: usize>(
        m: &M,
        (t, q, v): (f64, &SVector<f64, N>, &SVector<f64, N>),
        theta: &[f64],
        k: usize,
    ) -> NodeGradient<N> {
        let (qa, va) = (arr(q), arr(v));
        let th = SVector::<f64, 1>::from([theta.get(k).copied().unwrap_or(f64::NAN)]);
        fn with<D: Scalar>(theta: &[f64], k: usize, x: D) -> Vec<D> {
            (theta.iter().enumerate())
                .map(|(j, &y)| if j == k { x } else { D::from(y) })
                .collect()
        }
        let (_, _, _, lq_th) = partial_hessian(
            |(x, p): (
                SVector<HyperDualSVec64<N, 1>, N>,
                SVector<HyperDualSVec64<N, 1>, 1>,
            )| {
                m.lagrangian_with(t.into(), &arr(&x), &lift(&va), &with(theta, k, p[0]))
            },
            (q, &th),
        );
        let (_, _, _, lv_th) = partial_hessian(
            |(x, p): (
                SVector<HyperDualSVec64<N, 1>, N>,
                SVector<HyperDualSVec64<N, 1>, 1>,
            )| {
                m.lagrangian_with(t.into(), &lift(&qa), &arr(&x), &with(theta, k, p[0]))
            },
            (v, &th),
        );
        let mut fq = lq_th.column(0).into_owned();
        if M::STRUCTURE.has_force {
            let (_, f_th) = jacobian(
                |p: SVector<DualSVec64<1>, 1>| {
                    SVector::from(m.force_with(
                        t.into(),
                        &lift(&qa),
                        &lift(&va),
                        &with(theta, k, p[0]),
                    ))
                },
                &th,
            );
            fq += f_th.column(0);
        }
        NodeGradient {
            fq,
            lv: lv_th.column(0).into_owned(),
        }
    }

    /// `∂/∂θ_k [νf · (L_q + F) + νl · L_v]` at `(t, q, v)`, for the parameters `theta`:
    /// the parameter part of an adjoint, from one evaluation of
    /// [`ForcedLagrangian::lagrangian_with`] with hyper-dual numbers (`ε₁` along `(νf,
    /// νl)`, `ε₂` along `θ_k`) and one of [`ForcedLagrangian::force_with`] with a dual
    /// number along `θ_k`. The cost is that of a few evaluations of `L` and `F`, whatever
    /// `N`.
    pub fn parameter_contraction<M: ForcedLagrangian<N>, const N: usize>(
        m: &M,
        (t, q, v): (f64, &[f64], &[f64]),
        (nf, nl): (&[f64], &[f64]),
        theta: &[f64],
        k: usize,
    ) -> f64 {
        use num_dual::{Dual64, HyperDual64};
        let at = |x: &[f64], i: usize| x.get(i).copied().unwrap_or(f64::NAN);
        let qh: [HyperDual64; N] =
            std::array::from_fn(|a| HyperDual64::new(at(q, a), at(nf, a), 0.0, 0.0));
        let vh: [HyperDual64; N] =
            std::array::from_fn(|a| HyperDual64::new(at(v, a), at(nl, a), 0.0, 0.0));
        let th: Vec<HyperDual64> = (theta.iter().enumerate())
            .map(|(j, &x)| HyperDual64::new(x, 0.0, if j == k { 1.0 } else { 0.0 }, 0.0))
            .collect();
        let mut out = m
            .lagrangian_with(HyperDual64::from(t), &qh, &vh, &th)
            .eps1eps2;
        if M::STRUCTURE.has_force {
            let qd: [Dual64; N] = std::array::from_fn(|a| Dual64::from(at(q, a)));
            let vd: [Dual64; N] = std::array::from_fn(|a| Dual64::from(at(v, a)));
            let thd: Vec<Dual64> = (theta.iter().enumerate())
                .map(|(j, &x)| Dual64::new(x, if j == k { 1.0 } else { 0.0 }))
                .collect();
            let f = m.force_with(Dual64::from(t), &qd, &vd, &thd);
            out += (0..N).map(|a| at(nf, a) * f[a].eps).sum::<f64>();
        }
        out
    }

    /// A bound on the stack that [`parameter_contraction`] needs.
    pub const fn contraction_stack_bytes<const N: usize>() -> usize {
        N.saturating_mul(std::mem::size_of::<num_dual::HyperDual64>())
            .saturating_mul(8)
            .saturating_add(64 * 1024)
    }

    /// One pass over the `K = 2N` directions of `(q, v)` together: one evaluation of `L` (and
    /// of `F`) where the split kernels make two for the gradient and three for the Jacobian.
    /// Each elementary function of the model (a `sin`, an `exp`) is then called once per
    /// kernel instead of two or three times.
    ///
    /// The gradient's numbers have `1 + 2N` parts, against two passes of `1 + N`: the same
    /// arithmetic in one pass. The Hessian's have `1 + 2N + 4N²`, against `2(1 + N + N²) +
    /// (1 + N)²` for the three split passes, and a product of two costs about three times
    /// its square part: the fused pass does more arithmetic from `N = 3` on. Measured with
    /// callgrind on a hand-written driven chain (`cos` of `t`, of each `q` and of neighbour
    /// differences; 20,000 kernel calls), fused against split: the Jacobian 2.0M against
    /// 17.2M instructions for `N = 1`, 32M against 48M for `N = 2`, 172M against 125M for
    /// `N = 3`; the gradient 6.0M against 31M for `N = 2`, 14M against 54M for `N = 4`, 61M
    /// against 124M for `N = 8`. Whole runs of the Kapitza pendulum (`N = 1`, four `sin`
    /// or `cos` per evaluation of `L`), 10,000 lobatto3 steps: 72M instructions against
    /// 176M, with the same final state to the bit.
    mod fused {
        use super::*;
        use nalgebra::SMatrix;

        /// The largest `N` whose Jacobian kernel is fused.
        pub const JACOBIAN_MAX_N: usize = 2;
        /// The largest `N` whose gradient kernel is fused.
        pub const GRADIENT_MAX_N: usize = 8;

        /// `(q, v)` as one point of `R^K`.
        fn stack<const N: usize, const K: usize>(
            q: &SVector<f64, N>,
            v: &SVector<f64, N>,
        ) -> SVector<f64, K> {
            SVector::from_fn(|i, _| if i < N { q[i] } else { v[i - N] })
        }

        /// The `q` and `v` halves of a point of `R^K`.
        fn halves<T: Copy + nalgebra::Scalar, const N: usize, const K: usize>(
            x: &SVector<T, K>,
        ) -> ([T; N], [T; N]) {
            (
                std::array::from_fn(|a| x[a]),
                std::array::from_fn(|a| x[N + a]),
            )
        }

        /// [`super::node_gradient_at`] in one first-order pass.
        pub fn gradient<M: ForcedLagrangian<N>, const N: usize, const K: usize>(
            m: &M,
            t: f64,
            q: &SVector<f64, N>,
            v: &SVector<f64, N>,
        ) -> NodeGradient<N> {
            // Every arm of the callers' `match N` is compiled; only `K = 2N` is taken.
            if K != 2 * N {
                return split_gradient_at(m, t, q, v);
            }
            let (_, g) = num_dual::gradient(
                |x: SVector<DualSVec64<K>, K>| {
                    let (qd, vd) = halves::<_, N, K>(&x);
                    m.lagrangian_at(t.into(), &qd, &vd)
                },
                &stack(q, v),
            );
            let lq = SVector::from_fn(|a, _| g[a]);
            let lv = SVector::from_fn(|a, _| g[N + a]);
            let f = if M::STRUCTURE.has_force {
                SVector::from(m.force_at::<f64>(t, &arr(q), &arr(v)))
            } else {
                SVector::zeros()
            };
            NodeGradient { fq: lq + f, lv }
        }

        /// [`super::node_jacobian_at`] in one second-order pass of `L` and one first-order
        /// pass of `F`.
        pub fn jacobian<M: ForcedLagrangian<N>, const N: usize, const K: usize>(
            m: &M,
            t: f64,
            q: &SVector<f64, N>,
            v: &SVector<f64, N>,
        ) -> NodeJacobian<N> {
            if K != 2 * N {
                return split_jacobian_at(m, t, q, v);
            }
            let x = stack(q, v);
            let (_, g, h) = num_dual::hessian(
                |x: SVector<Dual2SVec64<K>, K>| {
                    let (qd, vd) = halves::<_, N, K>(&x);
                    m.lagrangian_at(t.into(), &qd, &vd)
                },
                &x,
            );
            let mut fq = SVector::<f64, N>::from_fn(|a, _| g[a]);
            let lv = SVector::from_fn(|a, _| g[N + a]);
            let mut a = SMatrix::<f64, N, N>::from_fn(|i, j| h[(i, j)]);
            let mut b = SMatrix::<f64, N, N>::from_fn(|i, j| h[(i, N + j)]);
            let c = SMatrix::<f64, N, N>::from_fn(|i, j| h[(N + i, j)]);
            let e = SMatrix::<f64, N, N>::from_fn(|i, j| h[(N + i, N + j)]);
            if M::STRUCTURE.has_force {
                let (f, jac) = num_dual::jacobian(
                    |x: SVector<DualSVec64<K>, K>| {
                        let (qd, vd) = halves::<_, N, K>(&x);
                        SVector::from(m.force_at(t.into(), &qd, &vd))
                    },
                    &x,
                );
                fq += f;
                a += SMatrix::<f64, N, N>::from_fn(|i, j| jac[(i, j)]);
                if M::STRUCTURE.force_uses_velocity {
                    b += SMatrix::<f64, N, N>::from_fn(|i, j| jac[(i, N + j)]);
                }
            }
            NodeJacobian {
                grad: NodeGradient { fq, lv },
                a,
                b,
                c,
                e,
            }
        }
    }

    /// The gradient and the blocks `A, B, C, E` at `(q, v)`.
    pub fn node_jacobian<M: ForcedLagrangian<N>, const N: usize>(
        m: &M,
        q: &SVector<f64, N>,
        v: &SVector<f64, N>,
    ) -> NodeJacobian<N> {
        node_jacobian_at(m, 0.0, q, v)
    }

    /// The gradient and the blocks `A, B, C, E` at `(t, q, v)`.
    pub fn node_jacobian_at<M: ForcedLagrangian<N>, const N: usize>(
        m: &M,
        t: f64,
        q: &SVector<f64, N>,
        v: &SVector<f64, N>,
    ) -> NodeJacobian<N> {
        match N {
            1 => return fused::jacobian::<M, N, 2>(m, t, q, v),
            2 => return fused::jacobian::<M, N, 4>(m, t, q, v),
            _ => {}
        }
        split_jacobian_at(m, t, q, v)
    }

    /// [`node_jacobian_at`] by second-order passes in `q`, in `v` and in both (hyper-dual),
    /// and first-order passes of `F` in `q` and in `v`.
    pub(crate) fn split_jacobian_at<M: ForcedLagrangian<N>, const N: usize>(
        m: &M,
        t: f64,
        q: &SVector<f64, N>,
        v: &SVector<f64, N>,
    ) -> NodeJacobian<N> {
        let (qa, va) = (arr(q), arr(v));
        let (_, _, lqq) = hessian(
            |x: SVector<Dual2SVec64<N>, N>| m.lagrangian_at(t.into(), &arr(&x), &lift(&va)),
            q,
        );
        let (_, _, lvv) = hessian(
            |x: SVector<Dual2SVec64<N>, N>| m.lagrangian_at(t.into(), &lift(&qa), &arr(&x)),
            v,
        );
        // One hyper-dual pass gives L_q, L_v and the mixed block L_qv.
        let (_, lq, lv, lqv) = partial_hessian(
            |(x, y): (
                SVector<HyperDualSVec64<N, N>, N>,
                SVector<HyperDualSVec64<N, N>, N>,
            )| m.lagrangian_at(t.into(), &arr(&x), &arr(&y)),
            (q, v),
        );
        let (mut fq, mut a, mut b) = (lq, lqq, lqv);
        if M::STRUCTURE.has_force {
            let (f, fq_jac) = jacobian(
                |x: SVector<DualSVec64<N>, N>| {
                    SVector::from(m.force_at(t.into(), &arr(&x), &lift(&va)))
                },
                q,
            );
            fq += f;
            a += fq_jac;
            if M::STRUCTURE.force_uses_velocity {
                let (_, fv_jac) = jacobian(
                    |y: SVector<DualSVec64<N>, N>| {
                        SVector::from(m.force_at(t.into(), &lift(&qa), &arr(&y)))
                    },
                    v,
                );
                b += fv_jac;
            }
        }
        NodeJacobian {
            grad: NodeGradient { fq, lv },
            a,
            b,
            c: lqv.transpose(),
            e: lvv,
        }
    }
}
