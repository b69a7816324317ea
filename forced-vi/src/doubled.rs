//! Galley's doubled Lagrangian, exposed for inspection and as an independent check of the
//! node kernels (DESIGN §2).
//!
//! `Λ(q, v, Q, V) = L(Q, V) − L(q, v) + ½ (F(q, v) + F(Q, V)) · (Q − q)`.
//!
//! In the ± variables `q₊ = (q + Q)/2`, `q₋ = Q − q`, the physical limit is `q₋ = v₋ = 0`.
//! There the gradient in the minus directions is `(L_q + F, L_v)` and the mixed
//! minus × plus second derivative is `[[A, B], [C, E]]`.

use nalgebra::{SMatrix, SVector};
use num_dual::{HyperDualSVec64, partial_hessian};

use crate::model::{ForcedLagrangian, NodeGradient, NodeJacobian};
use crate::scalar::{Scalar, lift};

/// The doubled Lagrangian `Λ(q, v, Q, V)` of an autonomous model (at `t = 0` for a driven
/// one; see [`doubled_lagrangian_at`]).
pub fn doubled_lagrangian<M, D, const N: usize>(
    model: &M,
    q: &[D; N],
    v: &[D; N],
    qq: &[D; N],
    vv: &[D; N],
) -> D
where
    M: ForcedLagrangian<N>,
    D: Scalar,
{
    doubled_lagrangian_at(model, D::from(0.0), q, v, qq, vv)
}

/// The doubled Lagrangian with time carried along (DESIGN §7):
/// `Λ(t, q, v, Q, V) = L(t, Q, V) − L(t, q, v) + ½(F(t, q, v) + F(t, Q, V))·(Q − q)`.
pub fn doubled_lagrangian_at<M, D, const N: usize>(
    model: &M,
    t: D,
    q: &[D; N],
    v: &[D; N],
    qq: &[D; N],
    vv: &[D; N],
) -> D
where
    M: ForcedLagrangian<N>,
    D: Scalar,
{
    let mut lambda = model.lagrangian_at(t, qq, vv) - model.lagrangian_at(t, q, v);
    if M::STRUCTURE.has_force {
        let f = model.force_at(t, q, v);
        let ff = model.force_at(t, qq, vv);
        for i in 0..N {
            lambda += (f[i] + ff[i]) * (qq[i] - q[i]) * 0.5;
        }
    }
    lambda
}

/// Λ in the ± variables: `Λ(q₊ − q₋/2, v₊ − v₋/2, q₊ + q₋/2, v₊ + v₋/2)`.
pub fn doubled_lagrangian_pm<M, D, const N: usize>(
    model: &M,
    q_plus: &[D; N],
    v_plus: &[D; N],
    q_minus: &[D; N],
    v_minus: &[D; N],
) -> D
where
    M: ForcedLagrangian<N>,
    D: Scalar,
{
    let lo = |x: &[D; N], dx: &[D; N]| std::array::from_fn(|i| x[i] - dx[i] * 0.5);
    let hi = |x: &[D; N], dx: &[D; N]| std::array::from_fn(|i| x[i] + dx[i] * 0.5);
    doubled_lagrangian(
        model,
        &lo(q_plus, q_minus),
        &lo(v_plus, v_minus),
        &hi(q_plus, q_minus),
        &hi(v_plus, v_minus),
    )
}

/// The physical-limit gradient and mixed Hessian blocks of Λ, taken literally: four
/// hyper-dual partial Hessians of Λ in (minus, plus) directions at `q₋ = v₋ = 0`.
///
/// This is the definition, not the fast path; the node kernels must agree with it.
pub fn physical_limit_blocks<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    q: &SVector<f64, N>,
    v: &SVector<f64, N>,
) -> NodeJacobian<N> {
    type H<const N: usize> = HyperDualSVec64<N, N>;
    let zero = SVector::<f64, N>::zeros();
    let arr = |x: &SVector<H<N>, N>| -> [H<N>; N] { std::array::from_fn(|i| x[i]) };
    let (qa, va, za) = (
        lift::<H<N>, N>(&(*q).into()),
        lift::<H<N>, N>(&(*v).into()),
        lift::<H<N>, N>(&[0.0; N]),
    );
    // (q₋, q₊) → ∂Λ/∂q₋ and A
    let (_, fq, _, a) = partial_hessian(
        |(m, p): (SVector<H<N>, N>, SVector<H<N>, N>)| {
            doubled_lagrangian_pm(model, &arr(&p), &va, &arr(&m), &za)
        },
        (&zero, q),
    );
    // (q₋, v₊) → B
    let (_, _, _, b) = partial_hessian(
        |(m, p): (SVector<H<N>, N>, SVector<H<N>, N>)| {
            doubled_lagrangian_pm(model, &qa, &arr(&p), &arr(&m), &za)
        },
        (&zero, v),
    );
    // (v₋, q₊) → ∂Λ/∂v₋ and C
    let (_, lv, _, c) = partial_hessian(
        |(m, p): (SVector<H<N>, N>, SVector<H<N>, N>)| {
            doubled_lagrangian_pm(model, &arr(&p), &va, &za, &arr(&m))
        },
        (&zero, q),
    );
    // (v₋, v₊) → E
    let (_, _, _, e): (f64, _, _, SMatrix<f64, N, N>) = partial_hessian(
        |(m, p): (SVector<H<N>, N>, SVector<H<N>, N>)| {
            doubled_lagrangian_pm(model, &qa, &arr(&p), &za, &arr(&m))
        },
        (&zero, v),
    );
    NodeJacobian {
        grad: NodeGradient { fq, lv },
        a,
        b,
        c,
        e,
    }
}
