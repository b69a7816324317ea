use forced_vi::prelude::*;

#[forced_lagrangian(
    coordinates(t, h),
    lagrangian = 0.5 * (t_dot * t_dot + h_dot * h_dot) - 0.5 * (t * t + h * h),
)]
struct TimeCoordinate {}

fn main() {}
