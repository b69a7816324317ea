use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(x, y, x),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) - 0.5 * (x * x + y * y),
)]
struct Twice {}

fn main() {}
