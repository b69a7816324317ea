//! The kernels that `#[forced_lagrangian]` writes, checked three ways on every model: against
//! the general num-dual path (`forced_vi::model::general`), against the literal definition
//! (`forced_vi::doubled::physical_limit_blocks`, hyper-dual partial Hessians of Λ), and
//! against central finite differences. Each specialisation has a model here that uses it.

use forced_vi::model::general;
use forced_vi::prelude::*;
use forced_vi::{doubled, NodeJacobian, Structure};
use forced_vi_models::models::{
    CoupledVanDerPol, DampedOscillator, DoublePendulumFriction, KeplerDrag, OverdampedOscillator,
    SpringChain, StiffVanDerPol,
};
use nalgebra::{SMatrix, SVector};

/// A small deterministic generator for test points.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }
    fn vec<const N: usize>(&mut self, scale: f64, shift: f64) -> SVector<f64, N> {
        SVector::from_fn(|_, _| shift + scale * self.next())
    }
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
}

fn assert_blocks_close<const N: usize>(
    what: &str,
    x: &NodeJacobian<N>,
    y: &NodeJacobian<N>,
    tol: f64,
) {
    let pairs: [(&str, &[f64], &[f64]); 6] = [
        ("fq", x.grad.fq.as_slice(), y.grad.fq.as_slice()),
        ("lv", x.grad.lv.as_slice(), y.grad.lv.as_slice()),
        ("a", x.a.as_slice(), y.a.as_slice()),
        ("b", x.b.as_slice(), y.b.as_slice()),
        ("c", x.c.as_slice(), y.c.as_slice()),
        ("e", x.e.as_slice(), y.e.as_slice()),
    ];
    for (name, u, w) in pairs {
        for (k, (p, r)) in u.iter().zip(w).enumerate() {
            assert!(
                close(*p, *r, tol),
                "{what}: block {name}[{k}] = {p:e}, expected {r:e}"
            );
        }
    }
}

/// Central differences of the gradient blocks give A, B (from `L_q + F`) and C, E (from
/// `L_v`); central differences of `L` give the gradient itself.
fn finite_differences<M: ForcedLagrangian<N>, const N: usize>(
    m: &M,
    q: &SVector<f64, N>,
    v: &SVector<f64, N>,
) -> NodeJacobian<N> {
    let lag =
        |q: &SVector<f64, N>, v: &SVector<f64, N>| m.lagrangian::<f64>(&(*q).into(), &(*v).into());
    let step = |x: f64| 1e-6 * (1.0 + x.abs());
    let mut fd = general::node_jacobian(m, q, v);
    let f = SVector::from(m.force::<f64>(&(*q).into(), &(*v).into()));
    for i in 0..N {
        let h = step(q[i]);
        let (mut qp, mut qm) = (*q, *q);
        qp[i] += h;
        qm[i] -= h;
        fd.grad.fq[i] = (lag(&qp, v) - lag(&qm, v)) / (2.0 * h) + f[i];
        let (gp, gm) = (m.node_gradient(&qp, v), m.node_gradient(&qm, v));
        fd.a.set_column(i, &((gp.fq - gm.fq) / (2.0 * h)));
        fd.c.set_column(i, &((gp.lv - gm.lv) / (2.0 * h)));
        let h = step(v[i]);
        let (mut vp, mut vm) = (*v, *v);
        vp[i] += h;
        vm[i] -= h;
        fd.grad.lv[i] = (lag(q, &vp) - lag(q, &vm)) / (2.0 * h);
        let (gp, gm) = (m.node_gradient(q, &vp), m.node_gradient(q, &vm));
        fd.b.set_column(i, &((gp.fq - gm.fq) / (2.0 * h)));
        fd.e.set_column(i, &((gp.lv - gm.lv) / (2.0 * h)));
    }
    fd
}

/// Checks a model at `points` random nodes; returns the specialised blocks at the last one.
fn check_model<M: ForcedLagrangian<N>, const N: usize>(
    name: &str,
    m: &M,
    scale: f64,
    shift: f64,
) -> Vec<NodeJacobian<N>> {
    let mut rng = Lcg(0x5eed ^ N as u64);
    let mut out = Vec::new();
    for _ in 0..12 {
        let q = rng.vec::<N>(scale, shift);
        let v = rng.vec::<N>(scale, 0.0);
        let spec = m.node_jacobian(&q, &v);
        let gen = general::node_jacobian(m, &q, &v);
        let def = doubled::physical_limit_blocks(m, &q, &v);
        let fd = finite_differences(m, &q, &v);
        assert_blocks_close(&format!("{name} vs general"), &spec, &gen, 1e-12);
        assert_blocks_close(
            &format!("{name} vs physical_limit_blocks"),
            &spec,
            &def,
            1e-12,
        );
        assert_blocks_close(&format!("{name} vs finite differences"), &spec, &fd, 1e-6);
        let grad = m.node_gradient(&q, &v);
        for i in 0..N {
            assert!(
                close(grad.fq[i], spec.grad.fq[i], 1e-13),
                "{name}: node_gradient fq"
            );
            assert!(
                close(grad.lv[i], spec.grad.lv[i], 1e-13),
                "{name}: node_gradient lv"
            );
        }
        let e = m.mass_matrix(&q, &v);
        for (x, y) in e.iter().zip(spec.e.iter()) {
            assert!(close(*x, *y, 1e-13), "{name}: mass_matrix");
        }
        if M::STRUCTURE.linear {
            // A linear claim: the general (dual-number) blocks are the same at every node.
            if let Some(first) = out.first() {
                let first: &NodeJacobian<N> = first;
                let blocks = |j: &NodeJacobian<N>| [j.a, j.b, j.c, j.e];
                for (x, y) in blocks(first).iter().zip(blocks(&gen).iter()) {
                    for (p, r) in x.iter().zip(y.iter()) {
                        assert!(close(*p, *r, 1e-12), "{name}: linear, but {p:e} != {r:e}");
                    }
                }
            }
        }
        if M::STRUCTURE.constant_mass {
            assert!(spec.c.iter().all(|&x| x == 0.0), "{name}: C must be zero");
            if let Some(first) = out.first() {
                let first: &NodeJacobian<N> = first;
                assert_eq!(first.e, spec.e, "{name}: E must be constant");
            }
        }
        if !M::STRUCTURE.has_force || !M::STRUCTURE.force_uses_velocity {
            // B is then L_qv alone, which general computes without the force.
            let lqv = general::node_jacobian(m, &q, &v).c.transpose();
            assert_eq!(
                spec.b.map(|x| x == 0.0),
                lqv.map(|x| x == 0.0),
                "{name}: B pattern"
            );
        }
        out.push(spec);
    }
    out
}

#[test]
fn coupled_van_der_pol() {
    let m = CoupledVanDerPol::PAPER;
    assert_eq!(
        <CoupledVanDerPol as ForcedLagrangian<2>>::STRUCTURE,
        Structure {
            has_force: true,
            force_uses_velocity: true,
            constant_mass: true,
            linear: false,
            uses_time: false,
        }
    );
    let blocks = check_model("CoupledVanDerPol", &m, 3.0, 0.0);
    for j in &blocks {
        // F_x does not use y or y_dot: structural zeros.
        assert_eq!(j.b[(0, 1)], 0.0);
        assert_eq!(j.b[(1, 0)], 0.0);
        assert_eq!(j.e, SMatrix::<f64, 2, 2>::identity());
    }
    assert_eq!(m.coordinate_names(), ["x", "y"]);
}

#[test]
fn damped_oscillator() {
    let m = DampedOscillator::DEFAULT;
    const { assert!(<DampedOscillator as ForcedLagrangian<2>>::STRUCTURE.constant_mass) };
    const { assert!(<DampedOscillator as ForcedLagrangian<2>>::STRUCTURE.linear) };
    let blocks = check_model("DampedOscillator", &m, 2.0, 0.0);
    for j in &blocks {
        for r in 0..2 {
            for c in 0..2 {
                assert_eq!(j.e[(r, c)], m.mass()[r][c]);
                assert_eq!(j.a[(r, c)], -m.stiffness()[r][c]);
                assert_eq!(j.b[(r, c)], -m.damping()[r][c]);
            }
        }
    }
}

#[test]
fn double_pendulum_has_a_varying_mass_matrix() {
    let m = DoublePendulumFriction::DEFAULT;
    let s = <DoublePendulumFriction as ForcedLagrangian<2>>::STRUCTURE;
    assert!(!s.constant_mass && s.has_force && s.force_uses_velocity);
    let blocks = check_model("DoublePendulumFriction", &m, 2.0, 0.0);
    assert!(blocks.iter().any(|j| j.c.iter().any(|&x| x != 0.0)));
}

#[test]
fn kepler_drag_non_polynomial_potential() {
    let m = KeplerDrag::DEFAULT;
    const { assert!(<KeplerDrag as ForcedLagrangian<2>>::STRUCTURE.constant_mass) };
    check_model("KeplerDrag", &m, 0.5, 1.5);
}

#[test]
fn one_dimensional_models() {
    check_model("StiffVanDerPol", &StiffVanDerPol::DEFAULT, 2.0, 0.0);
    check_model(
        "OverdampedOscillator",
        &OverdampedOscillator::DEFAULT,
        2.0,
        0.0,
    );
}

#[test]
fn spring_chain_const_generic() {
    let m = SpringChain::<5>::DEFAULT;
    let s = <SpringChain<5> as ForcedLagrangian<5>>::STRUCTURE;
    assert!(s.constant_mass && s.has_force && s.force_uses_velocity);
    check_model("SpringChain<5>", &m, 1.0, 0.0);
    check_model("SpringChain<1>", &SpringChain::<1>::STIFF, 1.0, 0.0);
    assert_eq!(m.coordinate_names(), ["q"; 5]);
}

/// Conservative: no force at all, so no force code and `has_force = false`.
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) - k * (x.powi(4) + y.powi(4)) - (x * y).sin(),
)]
struct Conservative {
    k: f64,
}

#[test]
fn conservative_model_has_no_force() {
    let s = <Conservative as ForcedLagrangian<2>>::STRUCTURE;
    assert!(!s.has_force && s.constant_mass);
    check_model("Conservative", &Conservative { k: 0.3 }, 1.5, 0.0);
}

/// A force that uses no velocity: no ∂F/∂v block.
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) - 0.5 * (x * x + y * y),
    force(x = -a * y.sin(), y = a * x.exp()),
)]
struct PositionForce {
    a: f64,
}

#[test]
fn force_without_velocity() {
    let s = <PositionForce as ForcedLagrangian<2>>::STRUCTURE;
    assert!(s.has_force && !s.force_uses_velocity && s.constant_mass);
    let blocks = check_model("PositionForce", &PositionForce { a: 0.7 }, 1.0, 0.0);
    for j in &blocks {
        assert!(j.b.iter().all(|&x| x == 0.0));
        // F_x uses only y: A[0][0] is the spring alone.
        assert_eq!(j.a[(0, 0)], -1.0);
    }
}

/// A kinetic term with a position-dependent coefficient, `let` bindings and a `for` loop, a
/// velocity-only non-polynomial term, and a constant force entry.
#[forced_lagrangian(
    coordinates(r, phi, z),
    lagrangian = 0.5 * (r_dot * r_dot + r * r * phi_dot * phi_dot)
        + {
            let mut s = 0.0;
            for k in 1..3 {
                s += (k as f64) * z_dot * z_dot / 4.0;
            }
            s
        }
        + (1.0 + z_dot * z_dot).sqrt()
        - 0.5 * w * (r - 1.0) * (r - 1.0)
        - if z > 0.0 { z * z } else { 0.5 * z * z },
    force(r = 0.0, phi = -w * phi_dot * r, z = 0.25),
)]
struct Mixed {
    w: f64,
}

#[test]
fn mixed_terms_loops_and_constant_force() {
    let s = <Mixed as ForcedLagrangian<3>>::STRUCTURE;
    assert!(!s.constant_mass && s.has_force && s.force_uses_velocity);
    check_model("Mixed", &Mixed { w: 2.0 }, 0.8, 1.2);
}

/// Array coordinates of literal length beside a scalar, with `q[i] = ...` and `q = [...]`
/// force forms, iterator sums and literal indices.
#[forced_lagrangian(
    coordinates(q: [f64; 3], s, p: [f64; 2]),
    lagrangian = (0..3).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum()
        + 0.5 * s_dot * s_dot
        + 0.5 * (p_dot[0] * p_dot[0] + p_dot[1] * p_dot[1])
        - (0..2).map(|i| (q[i + 1] - q[i]).powi(2)).sum()
        - 0.5 * k * q[0] * q[0]
        - (s - q[2]).cosh()
        - p[0] * p[1] * s,
    force(q[i] = -c * q_dot[i], s = -c * s_dot * s_dot, p = [-p[1], p[0]]),
)]
struct ArrayModel {
    k: f64,
    c: f64,
}

#[test]
fn array_forms_with_literal_lengths() {
    let m = ArrayModel { k: 2.0, c: 0.1 };
    let s = <ArrayModel as ForcedLagrangian<6>>::STRUCTURE;
    assert!(s.constant_mass && s.force_uses_velocity);
    check_model("ArrayModel", &m, 1.0, 0.0);
    assert_eq!(
        m.coordinate_names(),
        ["q[0]", "q[1]", "q[2]", "s", "p[0]", "p[1]"]
    );
}

#[test]
fn doubled_lagrangian_is_odd_and_matches_the_runtime() {
    let m = CoupledVanDerPol::PAPER;
    let (q, v, qq, vv) = ([0.3, -0.2], [1.0, 0.5], [0.1, 0.4], [-0.7, 0.2]);
    let a = m.doubled_lagrangian::<f64>(0.0, &q, &v, &qq, &vv);
    let b = m.doubled_lagrangian::<f64>(0.0, &qq, &vv, &q, &v);
    assert!((a + b).abs() < 1e-14);
    assert_eq!(a, doubled::doubled_lagrangian(&m, &q, &v, &qq, &vv));
}

#[test]
fn check_parameters_names_the_first_bad_field() {
    let mut m = CoupledVanDerPol::PAPER;
    assert_eq!(m.check_parameters(), Ok(()));
    m.rho = f64::NAN;
    m.lambda = f64::INFINITY;
    assert_eq!(m.check_parameters(), Err("rho"));
}

/// A driven model with `t` everywhere it can be: in polynomial and non-polynomial terms of
/// `L` (with and without velocities, so the mass matrix varies in time), and in force rows
/// that are polynomial in `(q, v)` or not.
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = (1.0 + 0.3 * (w * t).sin()) * x_dot * x_dot / 2 + y_dot * y_dot / 2
        - k * x * x / 2 - k * y * y / 2 + x * y * t
        + a * x.sin() * y_dot * (w * t).cos() - (y / 3.0).exp(),
    force(x = -c * x_dot + a * (w * t).cos(), y = -c * y_dot * (1.0 + x * x) + t * x),
)]
struct DrivenPair {
    k: f64,
    c: f64,
    a: f64,
    w: f64,
}

/// A driven model whose force has a row without `t` (polynomial: written out at compile
/// time) beside one with it, and `t` only in the potential.
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = x_dot * x_dot / 2 + y_dot * y_dot / 2 + x * y_dot - k * (x * x + y * y) / 2
        + a * x * y * (w * t).sin(),
    force(x = -c * x_dot + x * y, y = a * (w * t).cos()),
)]
struct DrivenRows {
    k: f64,
    c: f64,
    a: f64,
    w: f64,
}

/// A const-generic driven chain (its kernels go over whole arrays).
#[forced_lagrangian(
    coordinates(q: [f64; N]),
    lagrangian = (0..N).map(|i| q_dot[i] * q_dot[i] / 2 - k * q[i] * q[i] / 2
        + a * q[i] * (w * t).sin()).sum(),
    force(q[i] = -c * q_dot[i] + a * (w * t + q[i]).cos()),
)]
struct DrivenChain<const N: usize> {
    k: f64,
    c: f64,
    a: f64,
    w: f64,
}

/// The driven kernels at random times and states against the general path there.
fn check_driven<M: ForcedLagrangian<N>, const N: usize>(what: &str, m: &M) {
    assert!(M::STRUCTURE.uses_time, "{what}");
    let mut rng = Lcg(7);
    for _ in 0..200 {
        let t = 5.0 * rng.next();
        let (q, v) = (rng.vec::<N>(1.5, 0.0), rng.vec::<N>(2.0, 0.0));
        let (k, g) = (
            m.node_jacobian_at(t, &q, &v),
            general::node_jacobian_at(m, t, &q, &v),
        );
        assert_blocks_close(&format!("{what} at t = {t}"), &k, &g, 1e-12);
        let (kg, gg) = (
            m.node_gradient_at(t, &q, &v),
            general::node_gradient_at(m, t, &q, &v),
        );
        for (x, y) in kg
            .fq
            .iter()
            .chain(kg.lv.iter())
            .zip(gg.fq.iter().chain(gg.lv.iter()))
        {
            assert!(
                close(*x, *y, 1e-12),
                "{what}: gradient at t = {t}: {x:e} {y:e}"
            );
        }
        let e = m.mass_matrix_at(t, &q, &v);
        for (x, y) in e.iter().zip(g.e.iter()) {
            assert!(
                close(*x, *y, 1e-12),
                "{what}: mass matrix at t = {t}: {x:e} {y:e}"
            );
        }
        // The autonomous kernels are those at t = 0.
        let (k0, g0) = (
            m.node_jacobian(&q, &v),
            general::node_jacobian_at(m, 0.0, &q, &v),
        );
        assert_blocks_close(&format!("{what} at t = 0"), &k0, &g0, 1e-12);
    }
}

#[test]
fn driven_kernels_match_the_general_path_at_the_time() {
    check_driven(
        "DrivenPair",
        &DrivenPair {
            k: 2.0,
            c: 0.3,
            a: 0.7,
            w: 1.3,
        },
    );
    let s = <DrivenPair as ForcedLagrangian<2>>::STRUCTURE;
    assert!(!s.constant_mass && s.force_uses_velocity);
    check_driven(
        "DrivenRows",
        &DrivenRows {
            k: 1.5,
            c: 0.4,
            a: 0.9,
            w: 0.7,
        },
    );
    // `x * y_dot` makes `C = ∂²L/∂v∂q` nonzero: no constant-mass claim.
    let s = <DrivenRows as ForcedLagrangian<2>>::STRUCTURE;
    assert!(!s.constant_mass && s.force_uses_velocity && s.uses_time);
    let chain = DrivenChain::<3> {
        k: 1.0,
        c: 0.2,
        a: 0.5,
        w: 2.0,
    };
    check_driven("DrivenChain<3>", &chain);
    check_driven(
        "DrivenChain<9>",
        &DrivenChain::<9> {
            k: 1.0,
            c: 0.2,
            a: 0.5,
            w: 2.0,
        },
    );
}

/// An unsigned integer expression that wraps in the model's own code: `1usize - 3` is
/// 2⁶⁴ − 2 there, and the symbolic kernels, which evaluated integers as `i64`, took −2 (a
/// relative error of 1 in `L_q`, `STRUCTURE.linear` claimed for the wrong model, and a run
/// that ended `Ok` on the −2 model with an energy of 1.6e20). Such an expression is left to
/// the general kernels, which evaluate the model's code.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x - (1usize - 3) as f64 * 1e-20 * x * x,
    force(x = -(c - (2usize - 1) as f64) * x_dot),
)]
struct WrappingInteger {
    c: f64,
}

#[test]
fn wrapping_unsigned_integers_are_the_model_codes() {
    let m = WrappingInteger { c: 1.1 };
    // The model's own value: the wrapped coefficient, 1.8e19 × 1e-20.
    let l = m.lagrangian::<f64>(&[1.0], &[0.0]);
    let wrapped = -0.5 - (1usize.wrapping_sub(3)) as f64 * 1e-20;
    assert!((l - wrapped).abs() < 1e-12, "{l} {wrapped}");
    let (q, v) = (SVector::from([0.7]), SVector::from([-0.3]));
    let spec = m.node_jacobian(&q, &v);
    let gen = general::node_jacobian(&m, &q, &v);
    assert_blocks_close("WrappingInteger vs general", &spec, &gen, 1e-12);
    let grad = m.node_gradient(&q, &v);
    assert!(
        close(grad.fq[0], gen.grad.fq[0], 1e-13),
        "{} {}",
        grad.fq[0],
        gen.grad.fq[0]
    );
}
