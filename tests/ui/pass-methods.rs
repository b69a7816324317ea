#![deny(warnings)]
//! Method calls go through num-dual's `DualNum`; parameters and literals stay `f64`.
use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) * (2.0 + a.sin())
        - x.sin() * y.cos()
        - (0.1 * x).exp()
        + (2.0 + y * y).ln()
        - (1.0 + x * x).sqrt()
        - x.powi(4) / 4.0
        - (1.0 + y * y).powf(1.5)
        - (1.0 + x * x).powf(y / 10.0)
        - a / (1.0 + y * y)
        - x.tanh().mul_add(a, 1.0),
    force(x = -(a - x_dot.abs()) * x_dot, y = 2.0 - y),
)]
struct Everything {
    a: f64,
}

fn main() {
    let m = Everything { a: 0.5 };
    let j = m.node_jacobian(&[0.1, 0.2].into(), &[0.3, 0.4].into());
    assert!(j.a.iter().all(|x| x.is_finite()));
}
