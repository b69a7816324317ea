use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(q: [f64; 3]),
    lagrangian = {
        let mut s = 0.0;
        for j in 0..4 {
            s += 0.5 * q_dot[j] * q_dot[j];
        }
        s
    },
)]
struct Chain {}

fn main() {}
