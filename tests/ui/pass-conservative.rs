#![deny(warnings)]
//! No force: a conservative model.
use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(theta),
    lagrangian = 0.5 * len * len * theta_dot * theta_dot + g * len * theta.cos(),
)]
struct Pendulum {
    g: f64,
    len: f64,
}

fn main() {
    let p = Pendulum { g: 9.81, len: 1.0 };
    const { assert!(!<Pendulum as ForcedLagrangian<1>>::STRUCTURE.has_force) };
    assert_eq!(p.force::<f64>(&[0.3], &[0.1]), [0.0]);
}
