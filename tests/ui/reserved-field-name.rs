use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(q: [f64; 2]),
    lagrangian = 0.5 * (q_dot[0] * q_dot[0] + q_dot[1] * q_dot[1]) - __fvi_q * q[0] * q[1],
)]
struct Clash {
    __fvi_q: f64,
}

fn main() {}
