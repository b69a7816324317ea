use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(q: [f64; 3]),
    lagrangian = (0..3).map(|i| 0.5 * q_dot[i] * q_dot[i] - 0.5 * q[i] * q[i]).sum(),
    force(q = [-c * q_dot[0], -c * q_dot[1]]),
)]
struct Chain {
    c: f64,
}

fn main() {}
