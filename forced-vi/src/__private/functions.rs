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

/// `x.powf(n)` in model code, for a real exponent. num-dual's `powf` builds every term
/// from `x^(n − 3)`, which overflows for a small base (`1e-160.powf(0.5)` came out infinite)
/// and is infinite at a zero base, where `0 · ∞` makes even the value NaN (`x.powf(2.5)` at
/// `x = 0`, where the function and its first two derivatives vanish). Here each Taylor coefficient is its own power,
/// `n (n − 1) ⋯ (n − k + 1) x^(n − k) / k!`, applied to the nilpotent part of `x` (exact up to
/// the type's order of derivatives), so a term is infinite only where that derivative is.
#[inline]
pub fn powf<D: Scalar>(x: D, n: f64) -> D {
    let r = x.re();
    let f0 = r.powf(n);
    if D::NDERIV == 0 {
        return D::from(f0);
    }
    if D::NDERIV > 3 {
        return x.powf(n);
    }
    // The k-th Taylor coefficient: zero where the falling factorial is (an integer `n`
    // below `k`), whatever the power of a zero base.
    let coefficient = |k: i32| {
        let c =
            (0..k).fold(1.0, |c, j| c * (n - f64::from(j))) / f64::from((1..=k).product::<i32>());
        if c == 0.0 {
            0.0
        } else {
            c * r.powf(n - f64::from(k))
        }
    };
    let e = x - D::from(r);
    let mut y = D::from(f0) + e * coefficient(1);
    if D::NDERIV >= 2 {
        y += e * e * coefficient(2);
    }
    if D::NDERIV >= 3 {
        y += e * e * e * coefficient(3);
    }
    y
}

/// The real part of a scalar: a cast of a parameter to an integer in the code that
/// differentiates in the parameters (`lagrangian_with`, `force_with`), where the parameter
/// is a `__D` value. An integer of a parameter has no derivative (it is piecewise constant),
/// as in the `f64` code.
#[inline]
pub fn re<D: Scalar>(x: D) -> f64 {
    x.re()
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_dual::{Dual2_64, Dual64, DualNum, HyperDual64};

    #[test]
    fn powf_and_its_derivatives_are_finite_where_the_function_is_smooth() {
        for n in [0.0, 1.0, 1.5, 2.0, 2.5, 3.0, 3.7, -1.5] {
            for x in [0.0, 1e-300, 1e-160, 1e-10, 0.3, 2.0, 1e100] {
                if n < 0.0 && x == 0.0 {
                    continue;
                }
                let y = powf(HyperDual64::new(x, 1.0, 1.0, 0.0), n);
                let d1 = if n == 0.0 { 0.0 } else { n * x.powf(n - 1.0) };
                let d2 = if n == 0.0 || n == 1.0 {
                    0.0
                } else {
                    n * (n - 1.0) * x.powf(n - 2.0)
                };
                let close =
                    |a: f64, b: f64| a == b || (a - b).abs() <= 1e-14 * b.abs().max(a.abs());
                // A first-order type: right wherever the first derivative is finite.
                if d1.is_finite() {
                    let y1 = powf(Dual64::new(x, 1.0), n);
                    assert!(
                        close(y1.re, x.powf(n)) && close(y1.eps, d1),
                        "{x}^{n}: {y1}"
                    );
                }
                // A second-order one wherever the second is (`0^1.5` has an infinite one).
                if d1.is_finite() && d2.is_finite() {
                    assert!(close(y.re, x.powf(n)), "{x}^{n}: {}", y.re);
                    assert!(close(y.eps1, d1), "{x}^{n}: d1 {} {d1}", y.eps1);
                    assert!(close(y.eps1eps2, d2), "{x}^{n}: d2 {} {d2}", y.eps1eps2);
                }
            }
        }
        // num-dual's own form, for the record: NaN at a zero base, infinite at a small one.
        assert!(HyperDual64::new(0.0, 1.0, 1.0, 0.0).powf(2.5).re.is_nan());
        assert!(
            HyperDual64::new(1e-160, 1.0, 1.0, 0.0)
                .powf(0.5)
                .re
                .is_infinite()
        );
        assert_eq!(powf(2.0f64, 2.5), 2.0f64.powf(2.5));
        // A second-order type of one variable (`Dual2`) and a negative base with an integer
        // exponent.
        let y = powf(Dual2_64::new(-2.0, 1.0, 0.0), 3.0);
        assert!((y.re + 8.0).abs() < 1e-14 && (y.v1 - 12.0).abs() < 1e-13);
        assert!((y.v2 + 12.0).abs() < 1e-13, "{}", y.v2);
    }

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
