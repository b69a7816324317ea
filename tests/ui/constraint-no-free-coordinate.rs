use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) - g * y,
    constraints(x * x + y * y - 1.0, x - y),
)]
struct Pinned {
    g: f64,
}

fn main() {}
