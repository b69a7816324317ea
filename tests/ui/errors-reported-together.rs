use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(x, y, y),
    lagrangian = 0.5 * x_dot * x_dot - kk * x * x,
    force(x = -c * x_dot, w = 1.0),
)]
struct Many {
    c: i32,
}

// The stub impl keeps code that uses the model free of follow-on errors.
fn energy(m: &Many) -> f64 {
    m.energy(&[0.0, 0.0].into(), &[1.0, 0.0].into())
}

fn main() {
    let _ = energy;
}
