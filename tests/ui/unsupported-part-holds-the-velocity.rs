use forced_vi::prelude::*;

// The only kinetic term sits inside a part the macro does not support: it reports that
// part, and does not go on to call the Lagrangian velocity-free.
#[forced_lagrangian(
    coordinates(q: [f64; 3]),
    lagrangian = (0..3).map(|i| 0.5 * q_dot[i] * q_dot[i] - q[i] * q[i]).sum::<f64>(),
)]
struct Turbofish {}

fn main() {}
