#![deny(warnings)]
// The `if`s below have equal branches on purpose (the macro must read an `if` at the start of
// a Lagrangian); clippy sees them since these cases are root test targets.
#![allow(clippy::if_same_then_else)]
//! Integer literals are `f64` where a real number is meant; a parameter may be a base of
//! `powf`, and `max`/`min` work on coordinates. A Lagrangian may start with a block or an
//! `if`.
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

fn main() {
    let m = Ints { k: 2.0 };
    let j = m.node_jacobian(&[0.1, 0.2].into(), &[0.3, 0.4].into());
    assert!(j.a.iter().all(|x| x.is_finite()));
    let m = IfFirst {};
    assert!(m.node_gradient(&[0.1].into(), &[0.3].into()).fq[0].is_finite());
}
