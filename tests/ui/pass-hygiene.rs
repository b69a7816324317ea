#![deny(warnings)]
//! Generated code uses absolute paths only: names in the user's scope cannot capture it.
#![allow(non_camel_case_types, dead_code)]

mod nalgebra {}
mod num_dual {}
mod core {}
struct SVector;
struct Scalar;
struct f32;
type Result = ();
fn from() {}

#[forced_vi::forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * k * x * x + (x * x).sin(),
    force(x = -c * x_dot),
)]
struct Oscillator {
    k: f64,
    c: f64,
}

mod inner {
    #![no_implicit_prelude]

    #[::forced_vi::forced_lagrangian(
        coordinates(q: [f64; 2]),
        lagrangian = 0.5 * (q_dot[0] * q_dot[0] + q_dot[1] * q_dot[1]) - w * q[0] * q[1],
        force(q[i] = -w * q_dot[i]),
    )]
    pub struct Pair {
        pub w: f64,
    }
}

fn main() {
    use forced_vi::ForcedLagrangian;
    let m = Oscillator { k: 1.0, c: 0.1 };
    let _: () = Result::default();
    assert_eq!(
        m.node_jacobian(&[0.0].into(), &[0.0].into()).b[(0, 0)],
        -0.1
    );
    let p = inner::Pair { w: 2.0 };
    assert_eq!(
        p.mass_matrix(&[0.0; 2].into(), &[0.0; 2].into())[(1, 1)],
        1.0
    );
}
