#![deny(warnings)]
// The `if`s below have equal branches on purpose (the macro must read an `if` at the start of
// a Lagrangian); clippy sees them since these cases are root test targets.
#![allow(clippy::if_same_then_else)]
//! Integer literals are `f64` where a real number is meant; a parameter may be a base of
//! `powf`, and `max`/`min` work on coordinates. A Lagrangian may start with a block or an
//! `if`. Integer arithmetic that a real number reproduces is a real where one is meant
//! (`4 / 2`, `7 % 4`, `2.pow(3)`); `(3 / 2) as f64` asks for Rust's integer division; an
//! index may divide (`q[i / 2]`).
use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = { x_dot * x_dot / 2 } + if k > 1 { y_dot * y_dot / 2 } else { y_dot * y_dot / 2 }
        - 2 * x * y
        - k.powf(x)
        - x.max(y)
        - x.min(y).powi(2)
        - k.max(1) * x,
    force(x = -x_dot / 10, y = 0),
)]
struct Ints {
    k: f64,
}

#[forced_lagrangian(
    coordinates(x),
    lagrangian = if x > 0.0 { 0.5 * x_dot * x_dot } else { 0.5 * x_dot * x_dot } - 0.5 * x * x,
)]
struct IfFirst {}

#[forced_lagrangian(
    coordinates(q: [f64; 4]),
    lagrangian = (0..4).map(|i| q_dot[i] * q_dot[i] * (4 / 2 + ((i / 2) as f64)) / 2).sum()
        - (7 % 4) * q[0] * q[3 - 3 / 2]
        - 2.pow(3) * q[(1 + 5) % 4]
        - ((3 / 2) as f64) * (0..4).map(|i| q[i / 2] * q[i]).sum(),
)]
struct Exact {}

fn main() {
    let m = Ints { k: 2.0 };
    let j = m.node_jacobian(&[0.1, 0.2].into(), &[0.3, 0.4].into());
    assert!(j.a.iter().all(|x| x.is_finite()));
    let m = IfFirst {};
    assert!(m.node_gradient(&[0.1].into(), &[0.3].into()).fq[0].is_finite());
    // L = Σ (2 + ⌊i/2⌋) q̇ᵢ² / 2 − 3 q₀ q₂ − 8 q₂ − Σ q_{⌊i/2⌋} qᵢ.
    let (q, v) = ([0.1, 0.2, 0.3, 0.4], [0.5, 0.6, 0.7, 0.8]);
    let g = Exact {}.node_gradient(&q.into(), &v.into());
    let fv = [2.0 * v[0], 2.0 * v[1], 3.0 * v[2], 3.0 * v[3]];
    let fq = [
        -3.0 * q[2] - (2.0 * q[0] + q[1]),
        -(q[0] + q[2] + q[3]),
        -3.0 * q[0] - 8.0 - q[1],
        -q[1],
    ];
    for i in 0..4 {
        assert!(
            (g.lv[i] - fv[i]).abs() < 1e-14,
            "{i}: {} {}",
            g.lv[i],
            fv[i]
        );
        assert!(
            (g.fq[i] - fq[i]).abs() < 1e-14,
            "{i}: {} {}",
            g.fq[i],
            fq[i]
        );
    }
}
