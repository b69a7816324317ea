//! `#[forced_lagrangian]`'s per-term kernels (issue 12, DESIGN §9): for models whose
//! Lagrangian splits into local terms, `SparseNode::eval` against the runtime's general dense
//! kernels (whole-model dual numbers, independent of the per-term code) at random states:
//! gradient and blocks agree to round-off, and every dense nonzero lies in the recorded
//! pattern; so do the parameters' per-term kernels (`SparseNode::eval_parameter`) with the
//! general kernels' hyper-dual numbers over all `N`. A model with a whole-array term gets no
//! `SparseNode`.

use forced_vi::model::general;
use forced_vi::prelude::*;
use forced_vi::sparse::{NodeBlocks, NodePattern, NodeSink};
use forced_vi::LinearPath;
use forced_vi_models::models::SpringChain;
use nalgebra::{SMatrix, SVector};
use proptest::prelude::*;

/// Nearest and next-nearest neighbour springs, with a sum scaled by a parameter.
#[forced_lagrangian(
    coordinates(q: [f64; N]),
    lagrangian = (0..N).map(|i| 0.5 * m * q_dot[i] * q_dot[i]).sum()
        - (1..N).map(|i| 0.5 * k * (q[i] - q[i - 1]).powi(2)).sum()
        - 0.5 * k2 * (2..N).map(|i| (q[i] - q[i - 2]).powi(2)).sum() / 2.0,
    force(q[i] = -c * q_dot[i]),
)]
struct TwoNeighbour<const N: usize> {
    m: f64,
    k: f64,
    k2: f64,
    c: f64,
}

/// A periodic ring written with `for` accumulations, a position-dependent mass and a
/// nonlinear force that reads a neighbour's velocity (literal length, dense kernels of its
/// own).
#[forced_lagrangian(
    coordinates(q: [f64; 12]),
    lagrangian = {
        let mut s = 0.0;
        for i in 0..12 {
            let w = 1.0 + 0.1 * q[i] * q[i];
            s += 0.5 * w * q_dot[i] * q_dot[i];
        }
        for i in 0..12 {
            s -= k * (q[(i + 1) % 12] - q[i]).cosh();
        }
        s
    },
    force(q[i] = -c * (1.0 + q[i] * q[i]) * q_dot[i].powi(3) + a * q_dot[(i + 1) % 12].sin()),
)]
struct Ring {
    k: f64,
    c: f64,
    a: f64,
}

/// Scalar and array coordinates, fixed indices, an array-literal force.
#[forced_lagrangian(
    coordinates(x, q: [f64; 3]),
    lagrangian = 0.5 * x_dot * x_dot * (2.0 + x.sin())
        + (0..3).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum()
        - (0..3).map(|i| 0.5 * k * (q[i] - x).powi(2)).sum()
        - x * q[0] * q_dot[2],
    force(x = -c * x_dot, q = [0.0, -c * q_dot[1] * q[2], q[0] * q_dot[2]]),
)]
struct Mixed {
    k: f64,
    c: f64,
}

/// A driven chain: `t` in a term of `L` and in the force.
#[forced_lagrangian(
    coordinates(q: [f64; N]),
    lagrangian = (0..N).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum()
        - (0..N).map(|i| 0.5 * k * (1.0 + 0.3 * (w * t).sin()) * q[i] * q[i]).sum()
        - (1..N).map(|i| 0.5 * (q[i] - q[i - 1]).powi(2)).sum(),
    force(q[i] = -c * q_dot[i] + a * (w * t + i as f64).cos() * q[i]),
)]
struct Driven<const N: usize> {
    k: f64,
    w: f64,
    c: f64,
    a: f64,
}

/// A 4 × 4 membrane (nested index sums, 2-D indices), literal length.
#[forced_lagrangian(
    coordinates(q: [f64; 16]),
    lagrangian = (0..16).map(|k| 0.5 * q_dot[k] * q_dot[k]).sum()
        - 0.5 * k * (0..4).map(|i| (0..3).map(|j| (q[i * 4 + j + 1] - q[i * 4 + j]).powi(2)).sum()).sum()
        - 0.5 * k * (0..3).map(|i| (0..4).map(|j| (q[(i + 1) * 4 + j] - q[i * 4 + j]).powi(2)).sum()).sum()
        - 0.25 * b * (0..16).map(|k| q[k].powi(4)).sum(),
    force(q[i] = -c * q_dot[i]),
)]
struct Lattice {
    k: f64,
    b: f64,
    c: f64,
}

/// A `W × W` membrane with const-generic sizes, each mass tied to its right and lower
/// neighbours (and the rows wrap, with an index past the end at the last mass).
#[forced_lagrangian(
    coordinates(q: [f64; N]),
    lagrangian = (0..N).map(|k| 0.5 * q_dot[k] * q_dot[k]).sum()
        - (0..W).map(|i| (0..W).map(|j| {
            let right = if j + 1 < W { q[i * W + j + 1] } else { 0.0 };
            let down = if i + 1 < W { q[(i + 1) * W + j] } else { 0.0 };
            0.5 * k * ((right - q[i * W + j]).powi(2) + (down - q[i * W + j]).powi(2))
        }).sum()).sum(),
    force(q[i] = -c * q_dot[i] * (1.0 + q[i] * q[i])),
)]
struct Membrane<const W: usize, const N: usize> {
    k: f64,
    c: f64,
}

/// A whole-array term (a sum used nonlinearly): no split, no `SparseNode`.
#[forced_lagrangian(
    coordinates(q: [f64; N]),
    lagrangian = (0..N).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum()
        - 0.5 * k * (0..N).map(|i| q[i]).sum().powi(2),
)]
struct Global<const N: usize> {
    k: f64,
}

fn close(a: f64, b: f64, scale: f64) -> bool {
    (a - b).abs() <= 1e-12 * scale.max(1.0)
}

fn max_abs<const N: usize>(m: &SMatrix<f64, N, N>) -> f64 {
    m.iter().fold(0.0, |a, x| a.max(x.abs()))
}

/// The sparse kernels at `(t, q, v)` against `dense` (the general kernels' result).
fn compare<M: ForcedLagrangian<N>, const N: usize>(
    m: &M,
    t: f64,
    q: &[f64; N],
    v: &[f64; N],
) -> Result<(), TestCaseError> {
    let node = m
        .sparse_node()
        .ok_or_else(|| TestCaseError::fail("no SparseNode"))?;
    prop_assert_eq!(node.dof(), N);
    let (qs, vs) = (SVector::from(*q), SVector::from(*v));
    let dense = general::node_jacobian_at(m, t, &qs, &vs);
    let (mut lq, mut lv) = (vec![0.0; N], vec![0.0; N]);
    let mut pairs = Vec::new();
    let mut sink = NodeSink::record(&mut lq, &mut lv, &mut pairs);
    node.eval(t, q, v, &mut sink);
    prop_assert!(!sink.outside());
    let pattern = NodePattern::from_pairs(N, pairs);
    let mut blocks = NodeBlocks::zeros(pattern.nnz());
    let mut sink = NodeSink::values(&mut lq, &mut lv, &pattern, &mut blocks);
    node.eval(t, q, v, &mut sink);
    prop_assert!(!sink.outside());
    let gscale = dense.grad.fq.amax().max(dense.grad.lv.amax());
    for i in 0..N {
        prop_assert!(
            close(lq[i], dense.grad.fq[i], gscale),
            "L_q+F[{}]: {} vs {}",
            i,
            lq[i],
            dense.grad.fq[i]
        );
        prop_assert!(
            close(lv[i], dense.grad.lv[i], gscale),
            "L_v[{}]: {} vs {}",
            i,
            lv[i],
            dense.grad.lv[i]
        );
    }
    for (name, d, s) in [
        ("A", &dense.a, &blocks.a),
        ("B", &dense.b, &blocks.b),
        ("C", &dense.c, &blocks.c),
        ("E", &dense.e, &blocks.e),
    ] {
        let scale = max_abs(d);
        for r in 0..N {
            for c in 0..N {
                let got = pattern.position(r, c).map_or(0.0, |k| s[k]);
                prop_assert!(
                    d[(r, c)] == 0.0 || pattern.position(r, c).is_some(),
                    "{}({}, {}) = {} is outside the pattern",
                    name,
                    r,
                    c,
                    d[(r, c)]
                );
                prop_assert!(
                    close(got, d[(r, c)], scale),
                    "{}({}, {}): {} vs {}",
                    name,
                    r,
                    c,
                    got,
                    d[(r, c)]
                );
            }
        }
    }
    // The gradient-only sink gives the same gradient.
    let (mut gq, mut gv) = (vec![1.0; N], vec![1.0; N]);
    let mut sink = NodeSink::gradient(&mut gq, &mut gv);
    node.eval(t, q, v, &mut sink);
    prop_assert!(!sink.outside());
    prop_assert_eq!(&gq, &lq);
    prop_assert_eq!(&gv, &lv);
    // The model's own dense kernels agree too (for a large or const-generic length they go
    // through the per-term code; for a small literal one they are symbolic or whole-model).
    let own = m.node_jacobian_at(t, &qs, &vs);
    for (d, o) in [
        (&dense.a, &own.a),
        (&dense.b, &own.b),
        (&dense.c, &own.c),
        (&dense.e, &own.e),
    ] {
        let scale = max_abs(d);
        prop_assert!(d.iter().zip(o.iter()).all(|(x, y)| close(*x, *y, scale)));
    }
    let value = node.lagrangian_value(t, q, v);
    let want = m.lagrangian_at::<f64>(t, q, v);
    prop_assert!(close(value, want, want.abs()));
    // The parameters' per-term kernels (every model here has parameters, and splits with
    // them as duals too) against the general kernels' hyper-dual numbers over all `N`.
    let theta = m.parameter_values();
    prop_assert!(!theta.is_empty());
    prop_assert!(node.has_parameter_kernels(), "no parameter kernels");
    for k in 0..theta.len() {
        let want = general::node_parameter_gradient_at(m, (t, &qs, &vs), &theta, k);
        let (mut fq, mut lv) = (vec![0.0; N], vec![0.0; N]);
        prop_assert!(node.eval_parameter(t, q, v, &theta, k, &mut fq, &mut lv));
        let scale = want.fq.amax().max(want.lv.amax());
        for i in 0..N {
            prop_assert!(
                close(fq[i], want.fq[i], scale),
                "d(L_q+F)[{}]/dtheta_{}: {} vs {}",
                i,
                k,
                fq[i],
                want.fq[i]
            );
            prop_assert!(
                close(lv[i], want.lv[i], scale),
                "dL_v[{}]/dtheta_{}: {} vs {}",
                i,
                k,
                lv[i],
                want.lv[i]
            );
        }
    }
    Ok(())
}

fn state<const N: usize>() -> impl Strategy<Value = ([f64; N], [f64; N], f64)> {
    (
        proptest::array::uniform::<_, N>(-1.5..1.5f64),
        proptest::array::uniform::<_, N>(-1.5..1.5f64),
        0.0..10.0f64,
    )
}

/// Runs on a thread with room for the general kernels' whole-model dual numbers.
fn on_big_stack(f: impl FnOnce() + Send + 'static) {
    let run = std::thread::Builder::new()
        .stack_size(256 << 20)
        .spawn(f)
        .map(|h| h.join());
    assert!(
        matches!(run, Ok(Ok(()))),
        "the comparison failed or panicked"
    );
}

fn config() -> ProptestConfig {
    ProptestConfig {
        cases: 24,
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

fn run<const N: usize>(f: impl Fn(&[f64; N], &[f64; N], f64) -> Result<(), TestCaseError>) {
    let mut runner = proptest::test_runner::TestRunner::new(config());
    let result = runner.run(&state::<N>(), |(q, v, t)| f(&q, &v, t));
    if let Err(e) = result {
        panic!("{e}");
    }
}

#[test]
fn spring_chain_8_matches_dense() {
    on_big_stack(|| run::<8>(|q, v, _| compare(&SpringChain::<8>::DEFAULT, 0.0, q, v)));
}

#[test]
fn spring_chain_32_matches_dense() {
    on_big_stack(|| run::<32>(|q, v, _| compare(&SpringChain::<32>::STIFF, 0.0, q, v)));
}

#[test]
fn two_neighbour_chain_matches_dense() {
    let m = TwoNeighbour::<10> {
        m: 1.5,
        k: 2.0,
        k2: 0.7,
        c: 0.1,
    };
    on_big_stack(move || run::<10>(|q, v, _| compare(&m, 0.0, q, v)));
}

#[test]
fn ring_with_nonlinear_force_matches_dense() {
    let m = Ring {
        k: 1.3,
        c: 0.2,
        a: 0.4,
    };
    on_big_stack(move || run::<12>(|q, v, _| compare(&m, 0.0, q, v)));
}

#[test]
fn mixed_coordinates_match_dense() {
    let m = Mixed { k: 3.0, c: 0.3 };
    on_big_stack(move || run::<4>(|q, v, _| compare(&m, 0.0, q, v)));
}

#[test]
fn driven_chain_matches_dense() {
    let m = Driven::<6> {
        k: 1.0,
        w: 2.0,
        c: 0.1,
        a: 0.5,
    };
    on_big_stack(move || run::<6>(|q, v, t| compare(&m, t, q, v)));
}

#[test]
fn lattice_with_nested_sums_matches_dense() {
    let m = Lattice {
        k: 1.2,
        b: 0.3,
        c: 0.05,
    };
    on_big_stack(move || run::<16>(|q, v, _| compare(&m, 0.0, q, v)));
}

#[test]
fn const_generic_membrane_matches_dense() {
    let m = Membrane::<3, 9> { k: 0.8, c: 0.1 };
    on_big_stack(move || run::<9>(|q, v, _| compare(&m, 0.0, q, v)));
}

#[test]
fn whole_array_term_keeps_the_dense_path() {
    let m = Global::<5> { k: 1.0 };
    assert!(m.sparse_node().is_none());
    // Its dense kernels still work.
    let j = m.node_jacobian(&SVector::from([0.1; 5]), &SVector::from([0.2; 5]));
    assert_eq!(j.a[(0, 1)], -1.0);
}

#[test]
fn chain_pattern_is_tridiagonal() {
    const N: usize = 16;
    let m = SpringChain::<N>::DEFAULT;
    let node = m.sparse_node().expect("the chain splits");
    let (mut lq, mut lv) = (vec![0.0; N], vec![0.0; N]);
    let mut pairs = Vec::new();
    let mut sink = NodeSink::record(&mut lq, &mut lv, &mut pairs);
    node.eval(0.0, &[0.1; N], &[0.2; N], &mut sink);
    assert!(!sink.outside());
    let pattern = NodePattern::from_pairs(N, pairs);
    assert_eq!(pattern.nnz(), 3 * N - 2);
    assert!(pattern.entries().all(|(r, c)| r.abs_diff(c) <= 1));
}

/// Damped oscillators of stiffness `1 + i`, with a loop variable and a force index named
/// like a field (`i`).
#[forced_lagrangian(
    coordinates(q: [f64; 8]),
    lagrangian = (0..8).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum()
        - (0..8).map(|i| 0.5 * (1.0 + i as f64) * q[i] * q[i]).sum(),
    force(q[i] = -0.1 * q_dot[i]),
)]
struct FieldNamedLikeLoop {
    i: f64,
}

/// A scalar coordinate `x` beside an array whose loop variable is also `x`, with a damping
/// force whose index is named like the field `c`.
#[forced_lagrangian(
    coordinates(x, q: [f64; 6]),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x
        + (0..6).map(|x| 0.5 * q_dot[x] * q_dot[x] - 0.5 * (1.0 + x as f64) * q[x] * q[x]).sum(),
    force(x = -c * x_dot, q[c] = -0.1 * q_dot[c]),
)]
struct CoordinateNamedLikeLoop {
    c: f64,
}

/// `CoordinateNamedLikeLoop` with its names apart (split into per-term kernels).
#[forced_lagrangian(
    coordinates(x, q: [f64; 6]),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x
        + (0..6).map(|j| 0.5 * q_dot[j] * q_dot[j] - 0.5 * (1.0 + j as f64) * q[j] * q[j]).sum(),
    force(x = -c * x_dot, q[j] = -0.1 * q_dot[j]),
)]
struct NamesApart {
    c: f64,
}

/// A loop variable named like a field or a coordinate: the dense code reads the variable,
/// and the per-term kernels read the field (bound over their argument) or the coordinate (a
/// bare scalar name); such a model ran `Ok` with every oscillator at stiffness `1 + i` for
/// the field `i = 100` (all ended at cos √101). Now a term's kernel leaves a parameter of the
/// loop variable's name unbound, and a loop variable named like a coordinate keeps the
/// dense kernels; the results are those of the model with its names apart.
#[test]
fn loop_variables_named_like_fields_or_coordinates_keep_their_meaning() {
    let m = FieldNamedLikeLoop { i: 100.0 };
    assert!(m.sparse_node().is_some());
    let init = InitialState::from_velocity([1.0; 8], [0.0; 8]);
    for path in [LinearPath::Sparse, LinearPath::Dense] {
        let end = Integrator::new(&m, Scheme::lobatto(4).unwrap(), 0.01)
            .unwrap()
            .linear_path(path)
            .final_state(init, 1.0)
            .unwrap();
        for (j, q) in end.q.iter().enumerate() {
            let w = (1.0 + j as f64 - 0.0025).sqrt();
            let exact = (-0.05f64).exp() * (w.cos() + 0.05 / w * w.sin());
            assert!(
                (q - exact).abs() < 1e-9,
                "{path:?} q[{j}] = {q}, exact {exact}"
            );
        }
    }
    let (clash, apart) = (CoordinateNamedLikeLoop { c: 0.3 }, NamesApart { c: 0.3 });
    assert!(clash.sparse_node().is_none());
    assert!(apart.sparse_node().is_some());
    let init = InitialState::from_velocity([0.5, 1.0, -1.0, 0.5, 0.2, -0.3, 0.8], [0.0; 7]);
    let a = Integrator::new(&clash, Scheme::lobatto(4).unwrap(), 0.01)
        .unwrap()
        .final_state(init, 1.0)
        .unwrap();
    let b = Integrator::new(&apart, Scheme::lobatto(4).unwrap(), 0.01)
        .unwrap()
        .final_state(init, 1.0)
        .unwrap();
    for k in 0..7 {
        assert!(
            (a.q[k] - b.q[k]).abs() < 1e-12,
            "{k}: {} {}",
            a.q[k],
            b.q[k]
        );
    }
    // The scalar coordinate, damped by the field `c`: x = ½ e^{−0.15 t}(cos ωt + …).
    let w = (1.0f64 - 0.15 * 0.15).sqrt();
    let x = 0.5 * (-0.15f64).exp() * (w.cos() + 0.15 / w * w.sin());
    assert!((a.q[0] - x).abs() < 1e-9, "{} {x}", a.q[0]);
}
