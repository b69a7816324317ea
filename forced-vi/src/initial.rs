//! Initial data and the velocity solve `L_v(q, v) = p` (DESIGN §3, "Initial data"), with
//! the mass-matrix checks that both need.

use nalgebra::{DMatrix, DVector, SMatrix, SVector};

use crate::error::Error;
use crate::model::ForcedLagrangian;
use crate::scalar::all_finite;

/// Initial data: `(q₀, v₀)` as in the paper, or `(q₀, p₀)`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum InitialState<const N: usize> {
    /// Position and velocity; the momentum is `p₀ = L_v(q₀, v₀)`.
    Velocity {
        /// `q₀`.
        #[cfg_attr(feature = "serde", serde(with = "serde_big_array::BigArray"))]
        q: [f64; N],
        /// `v₀`.
        #[cfg_attr(feature = "serde", serde(with = "serde_big_array::BigArray"))]
        v: [f64; N],
    },
    /// Position and momentum; the velocity solves `L_v(q₀, v₀) = p₀`.
    Momentum {
        /// `q₀`.
        #[cfg_attr(feature = "serde", serde(with = "serde_big_array::BigArray"))]
        q: [f64; N],
        /// `p₀`.
        #[cfg_attr(feature = "serde", serde(with = "serde_big_array::BigArray"))]
        p: [f64; N],
    },
}

impl<const N: usize> InitialState<N> {
    /// `(q₀, v₀)`.
    pub fn from_velocity(q: [f64; N], v: [f64; N]) -> Self {
        InitialState::Velocity { q, v }
    }
    /// `(q₀, p₀)`.
    pub fn from_momentum(q: [f64; N], p: [f64; N]) -> Self {
        InitialState::Momentum { q, p }
    }

    /// `(q₀, v₀, true)` or `(q₀, p₀, false)`.
    pub(crate) fn parts(&self) -> (&[f64], &[f64], bool) {
        match self {
            InitialState::Velocity { q, v } => (q, v, true),
            InitialState::Momentum { q, p } => (q, p, false),
        }
    }

    /// `(q₀, Some(v₀))` or `(q₀, None)`.
    #[cfg_attr(not(feature = "sparse"), allow(dead_code))]
    pub(crate) fn as_slices(&self) -> (&[f64], Option<&[f64]>) {
        match self {
            InitialState::Velocity { q, v } => (q, Some(v)),
            InitialState::Momentum { q, .. } => (q, None),
        }
    }
}

/// Mass matrices whose equilibrated reciprocal condition is below this are singular.
pub(crate) const MIN_MASS_RCOND: f64 = 1e-13;

/// The reciprocal condition estimate and the sign of the determinant of a mass matrix,
/// from the LU pivots of its equilibrated form `D⁻¹ E D⁻¹`, `D = diag(√max_j |E_ij|)`.
///
/// Equilibration makes the test scale-invariant: `diag(1e-14, 1)` is as well conditioned
/// as the identity. `None` if a row is zero or a value is not finite.
pub(crate) fn mass_factor<const N: usize>(e: &SMatrix<f64, N, N>) -> Option<(f64, f64)> {
    let mut d = [0.0f64; N];
    for (i, di) in d.iter_mut().enumerate() {
        let m = e.row(i).amax();
        if !(m.is_finite() && m > 0.0) {
            return None;
        }
        *di = 1.0 / m.sqrt();
    }
    let mut a = SMatrix::<f64, N, N>::from_fn(|i, j| e[(i, j)] * d[i] * d[j]);
    let (mut lo, mut hi, mut sign) = (f64::INFINITY, 0.0f64, 1.0f64);
    for k in 0..N {
        let p = (k..N).max_by(|&i, &j| a[(i, k)].abs().total_cmp(&a[(j, k)].abs()))?;
        let piv = a[(p, k)];
        if piv == 0.0 || !piv.is_finite() {
            return None;
        }
        if p != k {
            a.swap_rows(k, p);
            sign = -sign;
        }
        sign *= piv.signum();
        lo = lo.min(piv.abs());
        hi = hi.max(piv.abs());
        for i in k + 1..N {
            let l = a[(i, k)] / piv;
            for j in k + 1..N {
                let u = a[(k, j)];
                a[(i, j)] -= l * u;
            }
        }
    }
    Some((if N == 0 { 1.0 } else { lo / hi }, sign))
}

/// Checks the mass matrix at `(q, v)`; returns the sign of its determinant.
pub(crate) fn mass_check<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    q: &SVector<f64, N>,
    v: &SVector<f64, N>,
    step: usize,
    t: f64,
) -> Result<f64, Error> {
    let e = model.mass_matrix_at(t, q, v);
    if !all_finite(&e) {
        return Err(Error::NonFiniteModel { step, t });
    }
    match mass_factor(&e) {
        Some((rcond, sign)) if rcond >= MIN_MASS_RCOND => Ok(sign),
        other => Err(Error::SingularMassMatrix {
            step,
            t,
            rcond: other.map_or(0.0, |(rc, _)| rc),
        }),
    }
}

/// Solves `L_v(q, v) = p` for `v` by a damped Newton method from `guess`.
///
/// One step is exact for a kinetic energy quadratic in `v` with a constant mass matrix.
/// Otherwise it iterates, halving steps that do not reduce the residual (or leave the
/// model's domain), until each row meets `|L_v(q, v) − p|_a ≤ 1e-13 (|p_a| + Σ_b |E_ab| |v_b|)`
/// or the round-off floor of those terms, and fails with [`Error::VelocitySolveFailed`]
/// after 60 iterations.
pub(crate) fn solve_velocity<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    q: &SVector<f64, N>,
    p: &SVector<f64, N>,
    guess: SVector<f64, N>,
    step: usize,
    t: f64,
) -> Result<SVector<f64, N>, Error> {
    let lv = |v: &SVector<f64, N>| model.node_gradient_at(t, q, v).lv;
    let mass = |v: &SVector<f64, N>| model.mass_matrix_at(t, q, v);
    let constant_mass = M::STRUCTURE.constant_mass;
    velocity_iteration::<N>((&lv, &mass, constant_mass), p, guess, (step, t))
}

/// The model's `v ↦ L_v(t, q, v)` at fixed `(t, q)`.
type MomentumMap<'a, const N: usize> = dyn Fn(&SVector<f64, N>) -> SVector<f64, N> + 'a;
/// The model's `v ↦ E(t, q, v)` at fixed `(t, q)`.
type MassMap<'a, const N: usize> = dyn Fn(&SVector<f64, N>) -> SMatrix<f64, N, N> + 'a;

/// [`solve_velocity`]'s iteration on the model's `(L_v, E, constant mass)` at fixed
/// `(t, q)`. Generic over the number of coordinates only: one copy serves every model of
/// `N` coordinates.
fn velocity_iteration<const N: usize>(
    (lv, mass, constant_mass): (&MomentumMap<'_, N>, &MassMap<'_, N>, bool),
    p: &SVector<f64, N>,
    guess: SVector<f64, N>,
    (step, t): (usize, f64),
) -> Result<SVector<f64, N>, Error> {
    let singular = |rcond| Error::SingularMassMatrix { step, t, rcond };
    let residual_at = |v: &SVector<f64, N>| -> Option<SVector<f64, N>> {
        let r = lv(v) - p;
        all_finite(&r).then_some(r)
    };
    let mut v = guess;
    if constant_mass {
        let e = mass(&v);
        let r = residual_at(&v).ok_or(Error::NonFiniteModel { step, t })?;
        let (dv, _) = crate::newton::solve_small(&e, &(-r)).ok_or(singular(0.0))?;
        v += dv;
        return if all_finite(&v) {
            Ok(v)
        } else {
            Err(Error::NonFiniteModel { step, t })
        };
    }
    let mut r = residual_at(&v).ok_or(Error::NonFiniteModel { step, t })?;
    for _ in 0..60 {
        let e = mass(&v);
        if !all_finite(&e) {
            return Err(Error::NonFiniteModel { step, t });
        }
        // Each row against its own terms, `|p_a| + Σ_b |E_ab| |v_b|`: against the largest
        // row's, a light coordinate beside a heavy one was accepted far from its solution
        // (a 1 kg pendulum on a 1e9 kg cart, fixed lobatto5 at h = 0.125: its angular
        // velocity 4.9e-5 off, the guess taken as it was).
        let size = SVector::<f64, N>::from_fn(|a, _| {
            p[a].abs() + (0..N).map(|b| e[(a, b)].abs() * v[b].abs()).sum::<f64>()
        });
        let weighed = |r: &SVector<f64, N>, k: f64| {
            (0..N).fold(0.0f64, |m, a| {
                let x = r[a].abs() / (k * size[a] + 4.0 * f64::MIN_POSITIVE);
                if x > m || x.is_nan() { x } else { m }
            })
        };
        if weighed(&r, 1e-13) <= 1.0 {
            return Ok(v);
        }
        let (dv, _) = crate::newton::solve_small(&e, &(-r)).ok_or(singular(0.0))?;
        let mut lambda = 1.0;
        loop {
            let trial = v + dv * lambda;
            if let Some(rt) = residual_at(&trial).filter(|_| all_finite(&trial))
                && weighed(&rt, 1e-13) < weighed(&r, 1e-13) * (1.0 - 1e-4 * lambda)
            {
                v = trial;
                r = rt;
                break;
            }
            lambda *= 0.5;
            if lambda < 1e-10 {
                // No step reduces the residual: at the round-off floor, or stuck.
                return if weighed(&r, 64.0 * f64::EPSILON) <= 1.0 {
                    Ok(v)
                } else {
                    Err(Error::VelocitySolveFailed {
                        step,
                        t,
                        residual: r.amax(),
                    })
                };
            }
        }
    }
    Err(Error::VelocitySolveFailed {
        step,
        t,
        residual: r.amax(),
    })
}

/// The tolerance of the initial-data check of a constrained model (`g(0, q_0) = 0`,
/// `G(q_0) v_0 + ∂g/∂t = 0`), relative to the size of the data.
pub const CONSTRAINT_TOL: f64 = 1e-10;

/// `g(0, q_0)`, the velocity-level residual `G(q_0) v_0 + ∂g/∂t` and `G` of a constrained
/// model (DESIGN §11).
fn constraint_residuals<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    q: &SVector<f64, N>,
    v: &SVector<f64, N>,
) -> (DVector<f64>, DVector<f64>, DMatrix<f64>) {
    let m = model.constraint_count();
    let mut g = DVector::zeros(m);
    let mut jac = DMatrix::zeros(m, N);
    crate::model::general::constraint_jacobian_at(model, 0.0, q, g.as_mut_slice(), &mut jac);
    let mut rate = DVector::zeros(m);
    crate::model::general::constraint_rate_at(model, 0.0, q.as_slice(), rate.as_mut_slice());
    let gv = &jac * DVector::from_column_slice(v.as_slice()) + rate;
    (g, gv, jac)
}

/// `|g(t, q)|`, `|G(q) v + ∂g/∂t|`, the size of that sum's terms, `|G| |v| + |∂g/∂t|`, and
/// `|G|` (max-norms), of a constrained model, from the general dual-number kernels (the
/// dense backend's).
pub(crate) fn constraint_residuals_at<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    t: f64,
    q: &[f64],
    v: &[f64],
) -> [f64; 4] {
    let m = model.constraint_count();
    if m == 0 {
        return [0.0; 4];
    }
    let mut g = DVector::zeros(m);
    let mut jac = DMatrix::zeros(m, N);
    let q = SVector::<f64, N>::from_column_slice(q);
    crate::model::general::constraint_jacobian_at(model, t, &q, g.as_mut_slice(), &mut jac);
    let mut rate = DVector::zeros(m);
    crate::model::general::constraint_rate_at(model, t, q.as_slice(), rate.as_mut_slice());
    let v = DVector::from_column_slice(v);
    let gv = &jac * &v + &rate;
    [
        g.amax(),
        gv.amax(),
        jac.amax() * v.amax() + rate.amax(),
        jac.amax(),
    ]
}

/// The distance of `q` from the constraints, `|g| / |G|`, in the units of `q`: `|g|` alone
/// is in the constraints' own units (a pendulum's `(x² + y² − l²) / 2` at 0.5 % off its
/// circle reads 5e-11 at `l = 1e-4`, and its round-off 1e-4 at `l = 1e6`). `|g|` itself
/// where the gradients vanish.
fn distance(g: f64, gradient: f64) -> f64 {
    if gradient > 0.0 { g / gradient } else { g }
}

/// Checks that initial data lie on the constraints, from `[|g|, |G v + ∂g/∂t|, |G| |v| +
/// |∂g/∂t|, |G|]` at `(0, q_0, v_0)`, each over `|G|`, in the units of `q` and `v` (see
/// [`distance`]): `|g| / |G| ≤ 10⁻¹⁰ (1 + |q_0|)` and `|G v + ∂g/∂t| / |G| ≤ 10⁻¹⁰ max(1,
/// (|G| |v| + |∂g/∂t|) / |G|)` (max-norms), else [`Error::InconsistentInitialState`], whose
/// residual and tolerance are those distances.
pub(crate) fn check_constraints(q: &[f64], [g, gv, size, gs]: [f64; 4]) -> Result<(), Error> {
    let amax = |x: &[f64]| x.iter().fold(0.0f64, |m, y| m.max(y.abs()));
    let tol_q = CONSTRAINT_TOL * (1.0 + amax(q));
    let tol_v = CONSTRAINT_TOL * distance(size, gs).max(1.0);
    let (g, gv) = (distance(g, gs), distance(gv, gs));
    for (what, r, tol) in [("position", g, tol_q), ("velocity", gv, tol_v)] {
        if r.is_nan() || r > tol {
            return Err(Error::InconsistentInitialState {
                what,
                residual: r,
                tol,
            });
        }
    }
    Ok(())
}

impl<const N: usize> InitialState<N> {
    /// The initial state `(q, v)` of a constrained model made consistent (DESIGN §11):
    /// `q` moved onto `g(q) = 0` by Gauss–Newton steps of least change
    /// (`q ← q − Gᵀ(GGᵀ)⁻¹ g`), then `v` projected onto `G v + ∂g/∂t = 0` the same way (at
    /// `t = 0`; `∂g/∂t = 0` for constraints that do not read the time). A typed error
    /// if a component of `q` or `v` is not finite ([`Error::NonFiniteInitialData`]), the
    /// constraints are singular at `q` or the projection does not converge.
    ///
    /// A model whose sparse kernels evaluate its constraints
    /// ([`SparseNode::sparse_constraint_count`](crate::model::SparseNode::sparse_constraint_count)) is
    /// projected on sparse storage, with the saddle-point matrix `[[I, Gᵀ], [G, 0]]`.
    pub fn projected<M: ForcedLagrangian<N>>(
        model: &M,
        q: [f64; N],
        v: [f64; N],
    ) -> Result<Self, Error> {
        if N == 0 {
            return Err(Error::InvalidModel {
                message: "the model has no coordinates (N = 0)".into(),
            });
        }
        // The user's data, named as such (not as a value the model returned).
        for (what, x) in [("q", &q[..]), ("v", &v[..])] {
            if let Some(index) = x.iter().position(|c| !c.is_finite()) {
                return Err(Error::NonFiniteInitialData { what, index });
            }
        }
        #[cfg(feature = "sparse")]
        if let Some(node) = model.sparse_node() {
            let m = model.constraint_count();
            let (mut q, mut v) = (q, v);
            let qv = (&mut q[..], &mut v[..]);
            let rate = |q: &[f64], out: &mut [f64]| {
                crate::model::general::constraint_rate_at(model, 0.0, q, out)
            };
            if m > 0 && node.sparse_constraint_count() == m {
                crate::sparse::constraints::project_initial(node, qv, CONSTRAINT_TOL, &rate)?;
                return Ok(InitialState::from_velocity(q, v));
            }
            // A large model: its constraints' kernels from dual numbers, on sparse storage.
            if m > 0 && N >= crate::LinearPath::SPARSE_MIN_DOF {
                let node = crate::model::DualConstraints { model, node };
                crate::sparse::constraints::project_initial(&node, qv, CONSTRAINT_TOL, &rate)?;
                return Ok(InitialState::from_velocity(q, v));
            }
        }
        let stack = crate::model::general::constraint_stack_bytes::<N>();
        if stack > crate::MAX_KERNEL_STACK {
            return Err(Error::ModelTooLarge {
                dof: N,
                max_dof: crate::LinearPath::DENSE_MAX_DOF,
                stack_bytes: stack,
                max: crate::MAX_KERNEL_STACK,
            });
        }
        crate::stack::with_stack(stack, || projected_dense(model, q, v))
    }
}

/// [`InitialState::projected`] with the general dual-number kernels.
fn projected_dense<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    q: [f64; N],
    v: [f64; N],
) -> Result<InitialState<N>, Error> {
    let (mut q, mut v) = (SVector::from(q), SVector::from(v));
    let singular = Error::UnsupportedConstraints {
        message: "the constraints are singular (G Gᵀ not invertible) at the initial state",
    };
    // Gauss–Newton to round-off (quadratic: a few steps), accepted within the check's
    // tolerance if round-off stops it earlier.
    let (mut done, mut last) = (false, f64::INFINITY);
    for _ in 0..50 {
        let (g, _, jac) = constraint_residuals(model, &q, &v);
        if !(g.iter().all(|x| x.is_finite()) && jac.iter().all(|x| x.is_finite())) {
            return Err(Error::NonFiniteModel { step: 0, t: 0.0 });
        }
        let size = 1.0 + q.amax();
        done = distance(g.amax(), jac.amax()) <= 0.01 * CONSTRAINT_TOL * size;
        // Quadratic convergence until round-off stops it (a step that no longer halves `g`).
        if g.amax() == 0.0 || (done && g.amax() > 0.5 * last) {
            break;
        }
        last = g.amax();
        let y = (&jac * jac.transpose())
            .lu()
            .solve(&g)
            .ok_or(singular.clone())?;
        let dq = jac.transpose() * y;
        q -= SVector::<f64, N>::from_column_slice(dq.as_slice());
    }
    if !done {
        let (g, _, jac) = constraint_residuals(model, &q, &v);
        return Err(Error::InconsistentInitialState {
            what: "position",
            residual: distance(g.amax(), jac.amax()),
            tol: CONSTRAINT_TOL * (1.0 + q.amax()),
        });
    }
    let (_, gv, jac) = constraint_residuals(model, &q, &v);
    let y = (&jac * jac.transpose()).lu().solve(&gv).ok_or(singular)?;
    v -= SVector::<f64, N>::from_column_slice((jac.transpose() * y).as_slice());
    Ok(InitialState::from_velocity(q.into(), v.into()))
}
