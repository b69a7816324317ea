use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(q: [f64; 3]),
    lagrangian = (0..3).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum(),
    force(q[i] = -k * (q[i] - q[i + 1])),
)]
struct Chain {
    k: f64,
}

fn main() {}
