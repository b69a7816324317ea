use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(q: [f64; 1000], p: [f64; 1000]),
    lagrangian = 0.5 * q_dot[0] * q_dot[0] + 0.5 * p_dot[0] * p_dot[0]
        - (0..1000).map(|i| q[i]).sum().powi(2),
)]
struct TooMany {}

fn main() {}
