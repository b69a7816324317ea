use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(r#x),
    lagrangian = 0.5 * x_dot * x_dot,
)]
struct Free {}

fn main() {}
