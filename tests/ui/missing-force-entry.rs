use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) - 0.5 * (x * x + y * y),
    force(x = -c * x_dot),
)]
struct Damped {
    c: f64,
}

fn main() {}
