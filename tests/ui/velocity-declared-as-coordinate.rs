use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(x, x_dot),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x,
)]
struct Oscillator {}

fn main() {}
