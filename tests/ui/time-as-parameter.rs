use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * k * x * x,
    force(x = (omega * t).cos()),
)]
struct TimeParameter {
    k: f64,
    omega: f64,
    t: f64,
}

fn main() {}
