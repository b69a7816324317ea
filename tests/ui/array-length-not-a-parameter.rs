use forced_vi::prelude::*;

const LEN: usize = 4;

#[forced_lagrangian(
    coordinates(q: [f64; LEN]),
    lagrangian = (0..LEN).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum(),
)]
struct Chain {}

fn main() {}
