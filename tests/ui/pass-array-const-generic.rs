#![deny(warnings)]
//! A chain of `N` masses between walls, `N` a const parameter.
use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(q: [f64; N]),
    lagrangian = (0..N).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum()
        - (0..=N)
            .map(|i| {
                let left = if i == 0 { 0.0 } else { q[i - 1] };
                let right = if i == N { 0.0 } else { q[i] };
                0.5 * k * (right - left).powi(2)
            })
            .sum(),
    force(q[i] = -c * q_dot[i]),
)]
struct Chain<const N: usize> {
    k: f64,
    c: f64,
}

fn main() {
    let m = Chain::<100> { k: 1.0, c: 0.01 };
    let q = [0.0; 100];
    assert_eq!(m.lagrangian::<f64>(&q, &q), 0.0);
}
