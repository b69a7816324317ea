use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - println!("{}", 1),
)]
struct Loud {}

fn main() {}
