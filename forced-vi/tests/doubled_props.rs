//! Property tests of the doubled Lagrangian and the general node kernels.

use forced_vi::doubled::{doubled_lagrangian, doubled_lagrangian_at, physical_limit_blocks};
use forced_vi::model::general;
use forced_vi::prelude::*;
use forced_vi::{NodeJacobian, Structure};
use nalgebra::{SMatrix, SVector};
use proptest::prelude::*;

/// A model with every block non-zero: q-dependent mass, velocity-dependent force.
struct Rich {
    a: f64,
    b: f64,
}

impl ForcedLagrangian<2> for Rich {
    fn lagrangian<D: Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> D {
        let m11 = q[1].cos() * 0.3 + 2.0;
        let m12 = q[0].sin() * 0.2;
        (v[0] * v[0] * m11 + v[0] * v[1] * m12 * 2.0 + v[1] * v[1]) * 0.5
            - (q[0] * q[0] * self.a).exp() * 0.1
            - q[0] * q[1] * q[1] * self.b
            + v[0] * q[1] * 0.05
    }
    fn force<D: Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> [D; 2] {
        [
            -v[0] * (q[1] * q[1] + 1.0) * 0.2 + q[0].sin() * 0.1,
            -(v[1] * v[1] * v[1]) * 0.05 - v[0] * q[0] * 0.1,
        ]
    }
}

fn fd_blocks(m: &Rich, q: &SVector<f64, 2>, v: &SVector<f64, 2>) -> NodeJacobian<2> {
    let grad = |q: &SVector<f64, 2>, v: &SVector<f64, 2>| general::node_gradient(m, q, v);
    let h = 1e-6;
    let mut a = SMatrix::<f64, 2, 2>::zeros();
    let (mut b, mut c, mut e) = (a, a, a);
    for k in 0..2 {
        let mut dq = SVector::<f64, 2>::zeros();
        dq[k] = h;
        let (gp, gm) = (grad(&(q + dq), v), grad(&(q - dq), v));
        a.set_column(k, &((gp.fq - gm.fq) / (2.0 * h)));
        c.set_column(k, &((gp.lv - gm.lv) / (2.0 * h)));
        let (gp, gm) = (grad(q, &(v + dq)), grad(q, &(v - dq)));
        b.set_column(k, &((gp.fq - gm.fq) / (2.0 * h)));
        e.set_column(k, &((gp.lv - gm.lv) / (2.0 * h)));
    }
    NodeJacobian {
        grad: grad(q, v),
        a,
        b,
        c,
        e,
    }
}

fn close(x: &SMatrix<f64, 2, 2>, y: &SMatrix<f64, 2, 2>, tol: f64) -> bool {
    (x - y).amax() <= tol * (1.0 + y.amax())
}

/// A driven model: `L(t, q, v)` and `F(t, q, v)` both depend on time.
struct Driven;

impl ForcedLagrangian<2> for Driven {
    const STRUCTURE: Structure = Structure::GENERAL_DRIVEN;
    fn lagrangian<D: Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> D {
        self.lagrangian_at(D::from(0.0), q, v)
    }
    fn lagrangian_at<D: Scalar>(&self, t: D, q: &[D; 2], v: &[D; 2]) -> D {
        (v[0] * v[0] + v[1] * v[1]) * 0.5 + v[0] * q[1] * t.sin() - (q[0] * q[0]) * (t.cos() + 2.0)
    }
    fn force_at<D: Scalar>(&self, t: D, q: &[D; 2], v: &[D; 2]) -> [D; 2] {
        [-v[0] * 0.1 + (t * 3.0).cos(), -v[1] * q[0] * t]
    }
}

fn vec2() -> impl Strategy<Value = SVector<f64, 2>> {
    (-2.0..2.0f64, -2.0..2.0f64).prop_map(|(a, b)| SVector::from([a, b]))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn doubled_lagrangian_is_odd(q in vec2(), v in vec2(), qq in vec2(), vv in vec2(),
                                 a in 0.1..1.0f64, b in -1.0..1.0f64) {
        let m = Rich { a, b };
        let (q, v, qq, vv) = (q.into(), v.into(), qq.into(), vv.into());
        let l1: f64 = doubled_lagrangian(&m, &q, &v, &qq, &vv);
        let l2: f64 = doubled_lagrangian(&m, &qq, &vv, &q, &v);
        prop_assert!((l1 + l2).abs() <= 1e-12 * (1.0 + l1.abs()));
    }

    #[test]
    fn doubled_lagrangian_with_time_is_odd(q in vec2(), v in vec2(), qq in vec2(),
                                           vv in vec2(), t in -10.0..10.0f64) {
        let (q, v, qq, vv) = (q.into(), v.into(), qq.into(), vv.into());
        let l1: f64 = doubled_lagrangian_at(&Driven, t, &q, &v, &qq, &vv);
        let l2: f64 = doubled_lagrangian_at(&Driven, t, &qq, &vv, &q, &v);
        prop_assert!((l1 + l2).abs() <= 1e-12 * (1.0 + l1.abs()));
    }

    #[test]
    fn dual_blocks_match_finite_differences(q in vec2(), v in vec2(),
                                            a in 0.1..1.0f64, b in -1.0..1.0f64) {
        let m = Rich { a, b };
        let exact = general::node_jacobian(&m, &q, &v);
        let fd = fd_blocks(&m, &q, &v);
        for (x, y, name) in [(exact.a, fd.a, "A"), (exact.b, fd.b, "B"),
                             (exact.c, fd.c, "C"), (exact.e, fd.e, "E")] {
            prop_assert!(close(&x, &y, 1e-7), "{name}: {x} vs {y}");
        }
    }

    #[test]
    fn kernels_match_the_doubled_lagrangian(q in vec2(), v in vec2(),
                                            a in 0.1..1.0f64, b in -1.0..1.0f64) {
        let m = Rich { a, b };
        let lit = physical_limit_blocks(&m, &q, &v);
        let ker = general::node_jacobian(&m, &q, &v);
        let g = general::node_gradient(&m, &q, &v);
        for (x, y) in [(lit.a, ker.a), (lit.b, ker.b), (lit.c, ker.c), (lit.e, ker.e)] {
            prop_assert!(close(&x, &y, 1e-13), "{x} vs {y}");
        }
        prop_assert!((lit.grad.fq - g.fq).amax() <= 1e-13 * (1.0 + g.fq.amax()));
        prop_assert!((lit.grad.lv - g.lv).amax() <= 1e-13 * (1.0 + g.lv.amax()));
        prop_assert!((ker.grad.fq - g.fq).amax() <= 1e-13 * (1.0 + g.fq.amax()));
    }
}
