#![deny(warnings)]
//! Arrays of literal length, mixed with a scalar; `q[i] = ...` and `q = [...]` forces.
use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(q: [f64; 4], s, p: [f64; 2]),
    lagrangian = (0..4).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum()
        + 0.5 * (s_dot * s_dot + p_dot[0] * p_dot[0] + p_dot[1] * p_dot[1])
        - {
            let mut v = 0.0;
            for i in 0..3 {
                let d = q[i + 1] - q[i];
                v += 0.5 * k * d * d;
            }
            v
        }
        - 0.5 * (s * s + p[0] * p[0] + p[1] * p[1]),
    force(q[i] = -c * q_dot[i], s = 0.0, p = [-c * p_dot[0], -c * p_dot[1]]),
)]
struct Chain {
    k: f64,
    c: f64,
}

fn main() {
    let m = Chain { k: 2.0, c: 0.1 };
    assert_eq!(m.coordinate_names()[5], "p[0]");
}
