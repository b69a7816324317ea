//! Arithmetic between integers stays integer arithmetic, as in Rust (it indexes arrays), but
//! an integer literal next to a real is a real: `3 / 2` used as a real number would silently
//! be 1, so a truncating division or an overflow used as a real is an error at its tokens.
use forced_vi::prelude::*;

#[forced_lagrangian(coordinates(x), lagrangian = x_dot * x_dot * (3 / 2) - x)]
struct Truncates {}

#[forced_lagrangian(coordinates(x), lagrangian = { let half = 1 / 2; half * x_dot * x_dot })]
struct ThroughALocal {}

#[forced_lagrangian(coordinates(q: [f64; 4]), lagrangian = (0..4).map(|i| q_dot[i] * q_dot[i] * (1 + i / 2)).sum())]
struct IndexQuotient {}

#[forced_lagrangian(coordinates(x), lagrangian = x_dot * x_dot - 2147483647 * 2147483647 * 4 * x)]
struct Overflows {}

#[forced_lagrangian(coordinates(x), lagrangian = x_dot * x_dot, force(x = -x_dot * (1 / 0)))]
struct ByZero {}

fn main() {}
