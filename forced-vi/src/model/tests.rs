//! The fused node kernels (one pass over `(q, v)`) against the split ones (a pass per block),
//! on models with every kind of term: time, transcendental functions, products of `q` and
//! `v`, and forces in `t`, `q` and `v`.

use nalgebra::SVector;
use proptest::prelude::*;

use super::general::{node_gradient_at, node_jacobian_at, split_gradient_at, split_jacobian_at};
use super::*;

/// `L = ½ Σ m_a(q) v_a² + Σ_a sin(q_a) v_{a+1} cos(t) − Σ_a exp(q_a / 3) + q_0 q_{N−1} t`,
/// `F_a = −c v_a (1 + q_a²) + sin(2t) q_{a+1}`, with `m_a(q) = 1 + ½ cos(q_a)²`.
struct Mixed<const N: usize>;

impl<const N: usize> ForcedLagrangian<N> for Mixed<N> {
    const STRUCTURE: Structure = Structure::GENERAL_DRIVEN;

    fn lagrangian<D: Scalar>(&self, q: &[D; N], v: &[D; N]) -> D {
        self.lagrangian_at(D::from(0.0), q, v)
    }
    fn lagrangian_at<D: Scalar>(&self, t: D, q: &[D; N], v: &[D; N]) -> D {
        let mut l = q[0] * q[N - 1] * t;
        for a in 0..N {
            let c = q[a].cos();
            let mass = c * c * 0.5 + 1.0;
            l += mass * v[a] * v[a] * 0.5 + q[a].sin() * v[(a + 1) % N] * t.cos()
                - (q[a] / 3.0).exp();
        }
        l
    }
    fn force<D: Scalar>(&self, q: &[D; N], v: &[D; N]) -> [D; N] {
        self.force_at(D::from(0.0), q, v)
    }
    fn force_at<D: Scalar>(&self, t: D, q: &[D; N], v: &[D; N]) -> [D; N] {
        std::array::from_fn(|a| {
            -v[a] * 0.3 * (q[a] * q[a] + 1.0) + (t * 2.0).sin() * q[(a + 1) % N]
        })
    }
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-13 * (1.0 + a.abs().max(b.abs()))
}

fn same<const N: usize>(t: f64, x: &[f64]) -> Result<(), TestCaseError> {
    let q = SVector::<f64, N>::from_fn(|a, _| x[a]);
    let v = SVector::<f64, N>::from_fn(|a, _| x[9 + a]);
    let m = Mixed::<N>;
    let (g, gs) = (
        node_gradient_at(&m, t, &q, &v),
        split_gradient_at(&m, t, &q, &v),
    );
    let (j, js) = (
        node_jacobian_at(&m, t, &q, &v),
        split_jacobian_at(&m, t, &q, &v),
    );
    let pairs = [
        (g.fq.as_slice(), gs.fq.as_slice()),
        (g.lv.as_slice(), gs.lv.as_slice()),
        (j.grad.fq.as_slice(), js.grad.fq.as_slice()),
        (j.grad.lv.as_slice(), js.grad.lv.as_slice()),
        (j.a.as_slice(), js.a.as_slice()),
        (j.b.as_slice(), js.b.as_slice()),
        (j.c.as_slice(), js.c.as_slice()),
        (j.e.as_slice(), js.e.as_slice()),
    ];
    for (k, (f, s)) in pairs.iter().enumerate() {
        for (x, y) in f.iter().zip(s.iter()) {
            prop_assert!(close(*x, *y), "block {k}: fused {x} split {y}");
        }
    }
    // The gradient of the Jacobian kernel is the residual kernel's.
    for (x, y) in j.grad.fq.iter().zip(g.fq.iter()) {
        prop_assert!(close(*x, *y));
    }
    Ok(())
}

proptest! {
    #[test]
    fn fused_kernels_agree_with_split_ones(
        t in -3.0f64..3.0,
        x in proptest::collection::vec(-2.0f64..2.0, 18),
    ) {
        // Every fused size (Jacobian to 2, gradient to 8) and the first split one.
        same::<1>(t, &x)?;
        same::<2>(t, &x)?;
        same::<3>(t, &x)?;
        same::<5>(t, &x)?;
        same::<8>(t, &x)?;
        same::<9>(t, &x)?;
    }
}
