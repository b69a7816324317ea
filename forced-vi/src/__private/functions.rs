//! Elementary functions whose num-dual form breaks down where the function itself is fine.

use crate::scalar::Scalar;

/// `x.tanh()` in model code. num-dual's `tanh` is `sinh / cosh`: from `|x| ≈ 355` its
/// derivative terms divide an overflowed `cosh²` (NaN, where tanh is ±1 and its derivatives
/// vanish), and from `|x| ≈ 710` its value is NaN too. A regularised Coulomb friction
/// `−μ tanh(v / ε)` with `ε = 10⁻³` reaches that at `|v| = 0.36`. Here every term stays
/// bounded: `tanh x = −m / (2 + m)` with `m = expm1(−2|x|) ∈ (−1, 0]` (and the sign of
/// `x`), to within a few ulps of `f64::tanh` in value (`expm1` keeps small `x` accurate).
#[inline]
pub fn tanh<D: Scalar>(x: D) -> D {
    if x.re() >= 0.0 {
        let m = (x * -2.0).exp_m1();
        -m / (m + 2.0)
    } else {
        let m = (x * 2.0).exp_m1();
        m / (m + 2.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_dual::{Dual2_64, DualNum};

    #[test]
    fn tanh_and_its_derivatives_are_finite_and_right_at_any_argument() {
        for x in [
            -1e300, -800.0, -400.0, -20.0, -1.0, -1e-9, 0.0, 1e-300, 1e-9, 0.3, 1.0, 5.0, 20.0,
            360.0, 800.0, 1e300,
        ] {
            let y = tanh(Dual2_64::new(x, 1.0, 0.0));
            let t = x.tanh();
            let (d1, d2) = (1.0 - t * t, -2.0 * t * (1.0 - t * t));
            assert!(
                (y.re - t).abs() <= 4.0 * f64::EPSILON * t.abs(),
                "{x}: {} {t}",
                y.re
            );
            assert!(
                (y.v1 - d1).abs() <= 1e-15 * (1.0 + d1.abs()),
                "{x}: {} {d1}",
                y.v1
            );
            assert!(
                (y.v2 - d2).abs() <= 1e-15 * (1.0 + d2.abs()),
                "{x}: {} {d2}",
                y.v2
            );
            // num-dual's own form, for the record: NaN from |x| ≈ 355.
            if x.abs() > 400.0 {
                assert!(Dual2_64::new(x, 1.0, 0.0).tanh().v1.is_nan());
            }
        }
        assert!((tanh(2.5f64) - 2.5f64.tanh()).abs() <= 2.0 * f64::EPSILON);
    }
}
