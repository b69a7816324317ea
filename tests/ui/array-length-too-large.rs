use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(q: [f64; 18446744073709551615], p: [f64; 2]),
    lagrangian = 0.5 * q_dot[0] * q_dot[0] + 0.5 * p_dot[0] * p_dot[0],
)]
struct Huge {}

fn main() {}
