use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(x),
    lagrangian = -0.5 * k * x * x,
)]
struct Potential {
    k: f64,
}

fn main() {}
