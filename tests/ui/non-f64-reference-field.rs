use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x,
)]
struct Borrowed<'a> {
    k: &'a f64,
}

fn main() {}
