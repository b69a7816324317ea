//! An array chosen by an `if` (or assigned another array) is not one known group of
//! coordinates: indexing it would read the wrong one. It is an error at the `if`.
use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(q: [f64; 2]),
    lagrangian = 0.5 * (q_dot[0] * q_dot[0] + q_dot[1] * q_dot[1])
        - { let a = if k > 0.0 { q } else { q_dot }; 0.5 * k * a[0] * a[0] },
)]
struct SameGroup {
    k: f64,
}

#[forced_lagrangian(
    coordinates(p: [f64; 2], r: [f64; 2]),
    lagrangian = 0.5 * (p_dot[0] * p_dot[0] + r_dot[0] * r_dot[0])
        - { let mut a = p; if k > 0.0 { a = r; } 0.5 * a[0] * a[0] },
)]
struct Assigned {
    k: f64,
}

fn main() {}
