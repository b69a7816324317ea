use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(q: [f64; 2]),
    lagrangian = 0.5 * (q_dot[0] * q_dot[0] + q_dot[1] * q_dot[1]) - (q[2] - q[0]).powi(2),
)]
struct Pair {}

fn main() {}
