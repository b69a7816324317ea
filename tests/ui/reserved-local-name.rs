use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(x),
    lagrangian = { let __fvi_v = 0.5 * x_dot; __fvi_v * x_dot },
)]
struct Clash {}

fn main() {}
