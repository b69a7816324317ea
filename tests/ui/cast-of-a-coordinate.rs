//! A coordinate, a velocity or the time is a dual number in the kernels: a cast of one is
//! an error at the cast, not rustc's "non-primitive cast" over the whole attribute naming
//! the kernels' type.
use forced_vi::prelude::*;

#[forced_lagrangian(coordinates(x), lagrangian = 0.5 * x_dot * x_dot - x.sin().powi(2) - x as f64)]
struct CastCoordinate {}

#[forced_lagrangian(coordinates(x), lagrangian = 0.5 * x_dot * x_dot - (x_dot as usize) as f64 * x)]
struct CastVelocity {}

fn main() {}
