//! Issue 10, the macro's classes: `STRUCTURE` claims and specialised kernels that must agree
//! with the general dual-number path (classes 5 and 6), out-of-range indices that must be
//! typed errors or NaN, never a panic (class 7), accepted syntax (class 10) and the kernel
//! stack bound.
// The models are written as a user would (`s = s * x_dot`), and the claims under test are
// constants.
#![allow(clippy::assign_op_pattern, clippy::assertions_on_constants)]

use forced_vi::model::general;
use forced_vi::prelude::*;
use forced_vi::{Error, NodeJacobian};
use nalgebra::SVector;

fn close(a: f64, b: f64) -> bool {
    a == b || (a - b).abs() <= 1e-10 * (1.0 + a.abs().max(b.abs()))
}

/// Every block of the generated kernels equals the general path at `(q, v)`.
fn assert_matches_general<M: ForcedLagrangian<N>, const N: usize>(m: &M, q: [f64; N], v: [f64; N]) {
    let (q, v) = (SVector::from(q), SVector::from(v));
    let s: NodeJacobian<N> = m.node_jacobian(&q, &v);
    let g: NodeJacobian<N> = general::node_jacobian(m, &q, &v);
    let blocks = [
        ("fq", s.grad.fq.as_slice(), g.grad.fq.as_slice()),
        ("lv", s.grad.lv.as_slice(), g.grad.lv.as_slice()),
        ("a", s.a.as_slice(), g.a.as_slice()),
        ("b", s.b.as_slice(), g.b.as_slice()),
        ("c", s.c.as_slice(), g.c.as_slice()),
        ("e", s.e.as_slice(), g.e.as_slice()),
    ];
    for (name, x, y) in blocks {
        for (k, (a, b)) in x.iter().zip(y).enumerate() {
            assert!(close(*a, *b), "{name}[{k}]: kernel {a:e}, general {b:e}");
        }
    }
    let gr = m.node_gradient(&q, &v);
    let gg = general::node_gradient(m, &q, &v);
    for k in 0..N {
        assert!(close(gr.fq[k], gg.fq[k]) && close(gr.lv[k], gg.lv[k]));
    }
    let mass = m.mass_matrix(&q, &v);
    for (a, b) in mass.iter().zip(g.e.iter()) {
        assert!(close(*a, *b), "mass matrix: {a:e} vs {b:e}");
    }
}

// Class 5: an `if` without `else` and a loop make the mass depend on the velocity.

#[forced_lagrangian(
    coordinates(x),
    lagrangian = -0.5 * x * x + {
        let mut m = 1.0;
        if x_dot > 0.0 {
            m = 3.0;
        }
        0.5 * m * x_dot * x_dot
    },
)]
struct IfMass {}

#[forced_lagrangian(
    coordinates(x),
    lagrangian = -0.5 * x * x + {
        let mut s = 1.0;
        for _k in 0..4 {
            s = s * x_dot;
        }
        0.25 * s
    },
)]
struct LoopMass {}

#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = {
        let mut s = 0.0;
        for _k in 0..3 {
            s += 0.5 * x_dot * x_dot;
        }
        s
    } + 0.5 * y_dot * y_dot - {
        let mut w = 1.0;
        let mut t = 0.0;
        for _k in 0..2 {
            t = w;
            w = y;
        }
        t * x * x
    },
    force(x = { let mut f = 0.0; if y > 0.5 { f = -x_dot; } f }, y = 0.0),
)]
struct LoopCarried {}

#[test]
fn trust_if_without_else_claims_nothing() {
    assert!(!IfMass::STRUCTURE.constant_mass);
    let m = IfMass {};
    assert_matches_general(&m, [0.5], [1.0]);
    assert_matches_general(&m, [0.5], [-1.0]);
    let e_pos = m.mass_matrix(&[0.5].into(), &[1.0].into())[(0, 0)];
    let e_neg = m.mass_matrix(&[0.5].into(), &[-1.0].into())[(0, 0)];
    assert_eq!((e_pos, e_neg), (3.0, 1.0));
}

#[test]
fn trust_loop_degree_is_a_fixpoint() {
    assert!(!LoopMass::STRUCTURE.constant_mass);
    let m = LoopMass {};
    for v in [0.3, 1.0, 2.0] {
        assert_matches_general(&m, [0.5], [v]);
    }
    // An accumulator of quadratic terms keeps a constant mass.
    assert!(LoopCarried::STRUCTURE.constant_mass);
    // A value carried from one iteration to the next (`t = w; w = y`) and a force chosen
    // by a condition on `y` still get every dependence.
    assert!(LoopCarried::STRUCTURE.force_uses_velocity);
    let m = LoopCarried {};
    assert_matches_general(&m, [0.4, 0.7], [0.3, -0.2]);
    assert_matches_general(&m, [0.4, 0.2], [0.3, -0.2]);
}

// Class 6: compile-time derivatives never drop an overflowing coefficient.

#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 1e308 * x * x,
    force(x = -1e308 * x * x * x_dot),
)]
struct Huge {}

#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) - 0.9e308 * x * x - 0.9e308 * x * x + 1e-200 * 1e-200 * 1e250 * y * y,
)]
struct HugeSum {}

#[test]
fn trust_overflowing_coefficients_take_the_dual_path() {
    let m = Huge {};
    let j = m.node_jacobian(&[1e-10].into(), &[0.3].into());
    assert!(
        j.grad.fq[0] != 0.0,
        "L_q + F must not vanish: {:e}",
        j.grad.fq[0]
    );
    assert_matches_general(&m, [1e-10], [0.3]);
    assert_matches_general(&m, [1e-160], [1e-3]);
    let m = HugeSum {};
    assert_matches_general(&m, [1e-10, 0.5], [0.3, 0.1]);
}

// Class 7: indices.

#[forced_lagrangian(
    coordinates(q: [f64; N]),
    lagrangian = (0..N).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum() + q_dot[2],
)]
struct VelocityPastEnd<const N: usize> {}

#[forced_lagrangian(
    coordinates(q: [f64; N]),
    lagrangian = (0..N).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum(),
    force(q[i] = -k * (q[i] - q[i + 1])),
)]
struct ForcePastEnd<const N: usize> {
    k: f64,
}

#[forced_lagrangian(
    coordinates(q: [f64; N]),
    lagrangian = (0..N).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum()
        - (0..N).map(|i| if i + 1 < N { 0.5 * (q[i + 1] - q[i]).powi(2) } else { 0.0 }).sum(),
    force(q[i] = if i == 0 { -c * q_dot[i] } else { -c * (q_dot[i] - q_dot[i - 1]) }),
)]
struct Guarded<const N: usize> {
    c: f64,
}

#[forced_lagrangian(
    coordinates(q: [f64; N]),
    lagrangian = (0..N).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum()
        + if q[0] > 0.0 { q[N] } else { 0.0 },
)]
struct DataDependentIndex<const N: usize> {}

#[test]
fn trust_const_generic_index_out_of_range_is_a_typed_error() {
    let h = 0.1;
    let m = VelocityPastEnd::<2> {};
    match Integrator::new(&m, Scheme::midpoint(), h) {
        Err(Error::InvalidModel { message }) => assert!(message.contains("q_dot[2]"), "{message}"),
        Err(e) => panic!("wrong error {e}"),
        Ok(_) => panic!("q_dot[2] at N = 2 accepted"),
    }
    assert!(VelocityPastEnd::<3> {}.check_model().is_ok());
    for n_ok in [
        ForcePastEnd::<2> { k: 1.0 }.check_model(),
        ForcePastEnd::<2> { k: 1.0 }.check_model(),
    ] {
        assert!(n_ok.is_err_and(|m| m.contains("q[i + 1]")));
    }
    match Integrator::new(&ForcePastEnd::<4> { k: 1.0 }, Scheme::midpoint(), h) {
        Err(Error::InvalidModel { .. }) => {}
        other => panic!("expected InvalidModel, got {:?}", other.err()),
    }
}

#[test]
fn trust_guarded_indices_are_accepted_and_exact() {
    let m = Guarded::<3> { c: 0.2 };
    assert!(m.check_model().is_ok());
    assert!(Integrator::new(&m, Scheme::midpoint(), 0.1).is_ok());
    assert_matches_general(&m, [0.1, -0.2, 0.3], [0.5, 0.1, -0.4]);
    let m = Guarded::<1> { c: 0.2 };
    assert!(m.check_model().is_ok());
    assert_matches_general(&m, [0.1], [0.5]);
}

#[test]
fn trust_data_dependent_index_is_nan_not_a_panic() {
    let m = DataDependentIndex::<2> {};
    // Not reached at the check's point, so the model is accepted ...
    assert!(m.check_model().is_ok());
    // ... and where it is reached, the model's value is NaN (so the energy is not finite
    // and the run reports it) instead of a panic; the kernels run too.
    assert!(m.lagrangian::<f64>(&[0.5, 0.0], &[0.1, 0.2]).is_nan());
    let _ = m.node_gradient(&[0.5, 0.0].into(), &[0.1, 0.2].into());
    let _ = m.node_jacobian(&[0.5, 0.0].into(), &[0.1, 0.2].into());
    let _ = m.mass_matrix(&[0.5, 0.0].into(), &[0.1, 0.2].into());
    assert_matches_general(&m, [-0.5, 0.0], [0.1, 0.2]);
}

// Class 10: accepted syntax.

#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = { x_dot * x_dot / 2 } + y_dot * y_dot / 2 - 2 * x * y - k.powf(x) - x.max(y) - x.min(y) * 3 / 2,
    force(x = -x_dot / 10, y = 1),
)]
struct Ints {
    k: f64,
}

#[forced_lagrangian(
    coordinates(x),
    lagrangian = if k > 0.0 { 0.5 * x_dot * x_dot } else { x_dot * x_dot } - 0.5 * x * x,
)]
struct IfFirst {
    k: f64,
}

#[test]
fn trust_integer_literals_and_methods() {
    let m = Ints { k: 2.0 };
    for (q, v) in [([0.5, 0.2], [0.3, 0.1]), ([-0.5, 0.7], [0.3, -1.0])] {
        assert_matches_general(&m, q, v);
    }
    // ½ẋ² − 2xy − kˣ − max(x, y) − min(x, y)·3/2 at x = 0.5 > y = 0.2: L_x = −2y − kˣ ln k − 1.
    let g = m.node_gradient(&[0.5, 0.2].into(), &[0.3, 0.1].into());
    let want = -2.0 * 0.2 - 2f64.powf(0.5) * 2f64.ln() - 1.0 - 0.03;
    assert!(close(g.fq[0], want), "{} vs {want}", g.fq[0]);
    let m = IfFirst { k: 1.0 };
    assert_matches_general(&m, [0.5], [0.3]);
}

// The kernel stack bound covers the kernels: they run on a thread whose stack is exactly
// `KERNEL_STACK_BYTES` (a debug build, without inlining, needs the most).

#[forced_lagrangian(
    coordinates(q: [f64; N]),
    lagrangian = (0..N).map(|i| 0.5 * (1.0 + q[i] * q[i]) * q_dot[i] * q_dot[i]).sum()
        - (0..N).map(|i| q[i].cos()).sum(),
    force(q[i] = -c * q_dot[i] * q[i]),
)]
struct Dense<const N: usize> {
    c: f64,
}

#[test]
fn trust_kernels_fit_their_stack_bound() {
    const N: usize = 24;
    let bytes = <Dense<N> as ForcedLagrangian<N>>::KERNEL_STACK_BYTES;
    let run = std::thread::Builder::new()
        .stack_size(bytes)
        .spawn(|| {
            let m = Dense::<N> { c: 0.1 };
            let q = SVector::<f64, N>::from_fn(|i, _| 0.1 * i as f64);
            let v = SVector::<f64, N>::from_fn(|i, _| 0.05 * i as f64);
            let j = m.node_jacobian(&q, &v);
            let g = m.node_gradient(&q, &v);
            let e = m.mass_matrix(&q, &v);
            j.a[(0, 0)] + g.fq[0] + e[(0, 0)]
        })
        .map(|h| h.join());
    assert!(matches!(run, Ok(Ok(x)) if x.is_finite()));
}

// Integer ranges through casts and divisions (a run-time panic class): an index whose values
// the analysis cannot bound stays checked (NaN, never a panic), and is no compile error.

#[forced_lagrangian(
    coordinates(q: [f64; 130]),
    lagrangian = (0..130).map(|i| 0.5 * q_dot[i] * q_dot[i] - 0.5 * k * q[i] * q[i]).sum()
        - (0..130).map(|i| 0.01 * q[(i as i8) as usize]).sum(),
)]
struct NarrowingCastIndex {
    k: f64,
}

#[forced_lagrangian(
    coordinates(q: [f64; 4]),
    lagrangian = (0..4).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum()
        - (0..4).map(|i| 0.5 * q[(i - 1) / 2] * q[i]).sum(),
)]
struct WrappedDivisionIndex {}

#[forced_lagrangian(
    coordinates(q: [f64; 256]),
    lagrangian = (0..256).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum()
        - (0..300).map(|i| 0.5 * k * q[(i as u8) as usize] * q[(i as u8) as usize]).sum(),
)]
struct WrappingCastInRange {
    k: f64,
}

#[forced_lagrangian(
    coordinates(q: [f64; 5]),
    lagrangian = (0..5).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum()
        - (0..5).map(|i| (0..i).map(|j| q[i - 1] * q[j]).sum()).sum(),
)]
struct EmptyInnerRange {}

#[test]
fn trust_unprovable_indices_are_checked_not_panics_nor_errors() {
    let r = std::panic::catch_unwind(|| {
        NarrowingCastIndex { k: 1.0 }.lagrangian::<f64>(&[0.1; 130], &[0.0; 130])
    });
    assert!(
        r.is_ok_and(|x| x.is_nan()),
        "i as i8 wraps: a checked index"
    );
    let r = std::panic::catch_unwind(|| {
        WrappedDivisionIndex {}.lagrangian::<f64>(&[0.1; 4], &[0.0; 4])
    });
    assert!(
        r.is_ok_and(|x| x.is_nan()),
        "(0 - 1) / 2 wraps: a checked index"
    );
    let q: [f64; 256] = std::array::from_fn(|k| 0.01 * k as f64);
    let plain = -(0..300)
        .map(|i| 0.5 * 2.0 * q[(i as u8) as usize] * q[(i as u8) as usize])
        .sum::<f64>();
    let l = WrappingCastInRange { k: 2.0 }.lagrangian::<f64>(&q, &[0.0; 256]);
    assert!(close(l, plain), "{l} vs {plain}");
    let q = [0.1, 0.2, 0.3, 0.4, 0.5];
    let plain = -(0..5)
        .map(|i| (0..i).map(|j| q[i - 1] * q[j]).sum::<f64>())
        .sum::<f64>();
    assert!(close(
        EmptyInnerRange {}.lagrangian::<f64>(&q, &[0.0; 5]),
        plain
    ));
    assert_matches_general(&EmptyInnerRange {}, q, [0.1; 5]);
}

// A helper function that takes a whole coordinate array depends on it.

fn trust_coupling<D: Scalar>(q: &[D; 2]) -> D {
    q[0] * q[1] * 0.6 * q[0]
}

#[forced_lagrangian(
    coordinates(q: [f64; 2]),
    lagrangian = 0.5 * (q_dot[0] * q_dot[0] + q_dot[1] * q_dot[1])
        - 0.5 * k * (q[0] * q[0] + q[1] * q[1]) - trust_coupling(q),
)]
struct ArrayArgument {
    k: f64,
}

#[test]
fn trust_array_argument_makes_the_call_dual() {
    assert!(!ArrayArgument::STRUCTURE.linear);
    assert_matches_general(&ArrayArgument { k: 1.0 }, [0.3, -0.7], [0.2, 0.5]);
}

// Integers computed from a coordinate or velocity (through integer methods, an index, a
// range's end) make the mass piecewise: no constant-mass claim.

#[forced_lagrangian(
    coordinates(x),
    lagrangian = {
        let j = if x_dot > 0.0 { 1 } else { 3 };
        let m = j.max(1);
        0.5 * (m as f64) * x_dot * x_dot
    } - 0.5 * k * x * x,
)]
struct IntMethodMass {
    k: f64,
}

#[forced_lagrangian(
    coordinates(q: [f64; 2]),
    lagrangian = 0.5 * (q_dot[0] * q_dot[0] + q_dot[1] * q_dot[1])
        + { let j = if q[0] > 0.0 { 0 } else { 1 }; q_dot[j] * q_dot[j] }
        - 0.5 * k * (q[0] * q[0] + q[1] * q[1]),
)]
struct IndexChosenMass {
    k: f64,
}

#[forced_lagrangian(
    coordinates(x),
    lagrangian = {
        let n = if x > 0.0 { 1 } else { 3 };
        (0..n).map(|_j| 0.5 * x_dot * x_dot).sum()
    } - 0.5 * x * x,
)]
struct RangeEndMass {}

#[forced_lagrangian(
    coordinates(x),
    lagrangian = {
        let n: i32 = if x > 0.0 { 1 } else { 3 };
        if n.abs() == 1 { 0.5 * x_dot * x_dot } else { 1.5 * x_dot * x_dot }
    } - 0.5 * x * x,
)]
struct AbsConditionMass {}

#[forced_lagrangian(
    coordinates(q: [f64; N]),
    lagrangian = (0..N).map(|i| {
            let j = if q[i] > 0.0 { 10 } else { 11 };
            let m = j.max(1);
            0.05 * (m as f64) * q_dot[i] * q_dot[i]
        }).sum()
        - (0..N).map(|i| 0.5 * k * q[i] * q[i]).sum(),
)]
struct PiecewiseChain<const N: usize> {
    k: f64,
}

#[test]
fn trust_integers_from_coordinates_are_not_constant() {
    assert!(!IntMethodMass::STRUCTURE.constant_mass);
    assert!(!IndexChosenMass::STRUCTURE.constant_mass);
    assert!(!RangeEndMass::STRUCTURE.constant_mass);
    assert!(!AbsConditionMass::STRUCTURE.constant_mass);
    assert!(!PiecewiseChain::<4>::STRUCTURE.constant_mass);
    for s in [1.0, -1.0] {
        assert_matches_general(&IntMethodMass { k: 1.0 }, [0.3 * s], [0.5 * s]);
        assert_matches_general(&IndexChosenMass { k: 1.0 }, [0.3 * s, 0.2], [0.5, 0.1]);
        assert_matches_general(&RangeEndMass {}, [0.3 * s], [0.5]);
        assert_matches_general(&AbsConditionMass {}, [0.3 * s], [0.5]);
        assert_matches_general(
            &PiecewiseChain::<4> { k: 1.0 },
            [0.3 * s, -0.2, 0.1, 0.4],
            [0.5; 4],
        );
    }
}

// Integer constants are folded at the model's own integer type (`i32` by default), and an
// index is a `usize` as in plain Rust.

#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 1e-10 * x * x * (65536 * 65536) as f64,
)]
struct I32Product {}

#[forced_lagrangian(
    coordinates(q: [f64; 3]),
    lagrangian = (0..3).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum()
        - (0..2).map(|i| 0.5 * q[((i * 1000000 * 10000) % 3).min(2)].powi(2)).sum(),
)]
struct UsizeIndexArithmetic {}

#[test]
fn trust_integer_types_match_the_models_code() {
    assert_matches_general(&I32Product {}, [0.5], [0.1]);
    let (q, v): ([f64; 3], [f64; 3]) = ([0.1, 0.2, 0.3], [0.0; 3]);
    let plain = -(0..2usize)
        .map(|i| 0.5 * q[((i * 1000000 * 10000) % 3).min(2)].powi(2_i32))
        .sum::<f64>();
    let l = UsizeIndexArithmetic {}.lagrangian::<f64>(&q, &v);
    assert!(close(l, plain), "{l} vs {plain}");
}

// A power of a difference is not expanded into monomials that cancel.

#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.25 * (x - c).powi(4),
)]
struct OffsetQuartic {
    c: f64,
}

#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) - 0.25 * (y - x).powi(4)
        - 0.1 * x * (x - y).powi(2),
)]
struct QuarticBond {}

#[test]
fn trust_powers_of_differences_keep_their_accuracy() {
    for x in [1000.001, 1000.01, 1000.1] {
        assert_matches_general(&OffsetQuartic { c: 1000.0 }, [x], [0.0]);
    }
    assert_matches_general(&QuarticBond {}, [100.0, 100.01], [0.0, 0.0]);
}

/// A parameter cast to an integer (`x.powi(k as i32)`) and to `f64`.
#[forced_lagrangian(coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * x.powi(k as i32) - 0.5 * c * (k as f64) * x * x)]
struct ParameterCasts {
    k: f64,
    c: f64,
}

/// A cast of a parameter compiles in the code that differentiates in the parameters, where
/// the parameter is a `__D` value: `k as f64` keeps its derivative, and `k as i32` takes the
/// real part (no derivative, as in the `f64` code). Before, the model did not compile: rustc
/// refused `__D as i32` (E0605) at the whole attribute. The sensitivities match central
/// differences of the flow.
#[test]
fn trust_parameter_casts_compile_and_differentiate() {
    let init = InitialState::from_velocity([0.5], [0.0]);
    let end = |k: f64, c: f64| {
        Integrator::new(&ParameterCasts { k, c }, Scheme::lobatto(3).unwrap(), 0.01)
            .unwrap()
            .final_state(init, 1.0)
            .unwrap()
            .q[0]
    };
    let model = ParameterCasts { k: 2.5, c: 0.3 };
    let s = Integrator::new(&model, Scheme::lobatto(3).unwrap(), 0.01)
        .unwrap()
        .solve(init, 1.0, output::Tangents)
        .unwrap();
    let d = 1e-6;
    let fd_k = (end(2.5 + d, 0.3) - end(2.5 - d, 0.3)) / (2.0 * d);
    let fd_c = (end(2.5, 0.3 + d) - end(2.5, 0.3 - d)) / (2.0 * d);
    for (what, got, fd) in [
        ("k", s.wrt_parameters[(0, 0)], fd_k),
        ("c", s.wrt_parameters[(0, 1)], fd_c),
    ] {
        assert!(
            (got - fd).abs() <= 1e-8 * fd.abs().max(1.0),
            "d q / d {what}: {got} against {fd}"
        );
    }
    // The integer power: `k = 2.5` reads `x²`, as the model's `f64` code does.
    let l = model.lagrangian::<f64>(&[0.5], &[0.1]);
    assert_eq!(l, 0.5 * 0.1 * 0.1 - 0.5 * 0.25 - 0.5 * 0.3 * 2.5 * 0.25);
}

/// Methods of `f64` on a parameter that the `__D` type lacks.
#[forced_lagrangian(coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * k.floor() * x * x
        - 0.1 * k.to_radians() * x * x * (if k.is_sign_negative() { 1.0 } else { 2.0 }))]
struct ParameterMethods {
    k: f64,
}

/// `floor`, `is_sign_negative` (piecewise constant: the real part) and `to_radians` (a
/// scale) on a parameter compile in the code that differentiates in the parameters; before,
/// rustc refused them there ("no method named `floor` found for type parameter `__D`"). The
/// sensitivity matches central differences of the flow.
#[test]
fn trust_parameter_methods_compile_and_differentiate() {
    let init = InitialState::from_velocity([0.5], [0.0]);
    let end = |k: f64| {
        Integrator::new(&ParameterMethods { k }, Scheme::lobatto(3).unwrap(), 0.01)
            .unwrap()
            .final_state(init, 1.0)
            .unwrap()
            .q[0]
    };
    let s = Integrator::new(
        &ParameterMethods { k: 2.5 },
        Scheme::lobatto(3).unwrap(),
        0.01,
    )
    .unwrap()
    .solve(init, 1.0, output::Tangents)
    .unwrap();
    let d = 1e-6;
    let fd = (end(2.5 + d) - end(2.5 - d)) / (2.0 * d);
    let got = s.wrt_parameters[(0, 0)];
    assert!(
        (got - fd).abs() <= 1e-8 * fd.abs().max(1.0),
        "{got} against {fd}"
    );
}
