//! Error control (DESIGN §8): tolerances, the step-doubling error norm and the PI step-size
//! controller. The stepping itself lives in [`crate::stepper`].
//!
//! **The estimate.** A step of size `h` is taken twice: once whole (`y₁`) and once as two
//! halves (`y₂`). For a scheme of order `p` the local errors are `C h^{p+1}` and
//! `C h^{p+1} / 2^p`, so `e = (y₂ − y₁) / (2^p − 1)` estimates the local error of `y₂`,
//! the solution that is *propagated* (each half step is an ordinary variational step, so
//! the run stays variational and its energy ledger exact to the quadrature). The estimate
//! is asymptotically exact, of order `p + 1` in `h`, and works for every scheme; it costs
//! three steps per step (one of `h`, two of `h/2`).
//!
//! **The norm.** `‖e‖ = sqrt(mean((e_i / (atol_i + rtol_i max(|y₁ᵢ|, |y₂ᵢ|)))²))` over the
//! positions and momenta, multiplied by `T / h` (`T` the run's length): the control is per
//! unit step, so that the local errors add up to at most about `tol` over the run and the
//! global error is proportional to the tolerance (an error per step would make it fall like
//! `tol^{p/(p+1)}`).
//!
//! **The controller.** A PI controller (Gustafsson; Hairer & Wanner, IV.2) on `‖e‖ ∝ h^p`:
//! `h_new = h · clamp(0.9 ‖e‖^{−0.7/p} ‖e_prev‖^{0.4/p}, 0.2, 5)`, with no growth right
//! after a rejection.

use crate::error::Error;

/// Relative and absolute tolerances, per coordinate; the same pair applies to the
/// coordinate's position and its momentum.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tolerance<const N: usize> {
    /// Relative tolerances.
    pub rtol: [f64; N],
    /// Absolute tolerances.
    pub atol: [f64; N],
}

impl<const N: usize> Tolerance<N> {
    /// The same `rtol` and `atol` for every coordinate.
    pub fn scalar(rtol: f64, atol: f64) -> Result<Self, Error> {
        Self::per_component([rtol; N], [atol; N])
    }

    /// One pair per coordinate. Each must be finite and non-negative, and not both zero.
    pub fn per_component(rtol: [f64; N], atol: [f64; N]) -> Result<Self, Error> {
        for i in 0..N {
            let (r, a) = (rtol[i], atol[i]);
            let ok = r.is_finite() && a.is_finite() && r >= 0.0 && a >= 0.0 && r + a > 0.0;
            if !ok {
                return Err(Error::InvalidTolerance {
                    index: i,
                    rtol: r,
                    atol: a,
                });
            }
        }
        Ok(Tolerance { rtol, atol })
    }

    /// The weighted RMS norm of `(y₂ − y₁) / (2^order − 1)` over positions and momenta,
    /// each component scaled by `per_unit` (`T / h`: error per unit step) and floored at the
    /// round-off of the values it compares.
    pub(crate) fn error_norm(
        &self,
        order: usize,
        per_unit: f64,
        (q1, p1): (&[f64], &[f64]),
        (q2, p2): (&[f64], &[f64]),
    ) -> f64 {
        let scale = per_unit / (2f64.powi(order.min(60) as i32) - 1.0);
        let mut sum = 0.0;
        for i in 0..N {
            for (a, b) in [(q1[i], q2[i]), (p1[i], p2[i])] {
                let size = a.abs().max(b.abs());
                let sc = self.atol[i] + self.rtol[i] * size;
                // No estimate is below the round-off of the values it compares: a tolerance
                // finer than that cannot be met, and the step size runs into its floor.
                let e = ((b - a).abs() * scale).max(2.0 * f64::EPSILON * size) / sc;
                sum += e * e;
            }
        }
        (sum / (2 * N).max(1) as f64).sqrt()
    }
}

/// The PI step-size controller.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Controller {
    /// The exponent `p` of `‖e‖ ∝ h^p`.
    order: f64,
    err_prev: f64,
    rejected: bool,
}

impl Controller {
    const SAFETY: f64 = 0.9;
    const MIN_FACTOR: f64 = 0.2;
    const MAX_FACTOR: f64 = 5.0;

    pub(crate) fn new(order: usize) -> Self {
        Controller {
            order: order.max(1) as f64,
            err_prev: 1.0,
            rejected: false,
        }
    }

    /// The next step after accepting a step `h` with error `err ≤ 1`.
    pub(crate) fn accept(&mut self, h: f64, err: f64) -> f64 {
        let err = err.max(1e-10);
        let mut fac =
            Self::SAFETY * err.powf(-0.7 / self.order) * self.err_prev.powf(0.4 / self.order);
        if self.rejected {
            fac = fac.min(1.0);
        }
        self.err_prev = err;
        self.rejected = false;
        h * fac.clamp(Self::MIN_FACTOR, Self::MAX_FACTOR)
    }

    /// The retry after rejecting a step `h` with error `err > 1` (or a failed solve, with
    /// `err = ∞`).
    pub(crate) fn reject(&mut self, h: f64, err: f64) -> f64 {
        self.rejected = true;
        let fac = if err.is_finite() {
            Self::SAFETY * err.powf(-1.0 / self.order)
        } else {
            0.25
        };
        h * fac.clamp(Self::MIN_FACTOR, 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tolerances_are_validated() {
        assert!(Tolerance::<2>::scalar(1e-6, 1e-9).is_ok());
        assert!(Tolerance::<2>::scalar(0.0, 1e-9).is_ok());
        for (r, a) in [
            (-1e-6, 1e-9),
            (f64::NAN, 1e-9),
            (1e-6, f64::INFINITY),
            (0.0, 0.0),
        ] {
            assert!(Tolerance::<1>::scalar(r, a).is_err(), "{r} {a}");
        }
    }

    #[test]
    fn norm_is_the_weighted_rms_of_the_richardson_difference() {
        let tol = Tolerance::<1>::scalar(0.0, 1e-3).unwrap();
        let z = [0.0];
        let d = [3e-3];
        // Order 1: e = Δ / (2 − 1); one of two components is off by 3 tolerances.
        let n = tol.error_norm(1, 1.0, (&z, &z), (&d, &z));
        assert!((n - 3.0 / 2f64.sqrt()).abs() < 1e-12);
        // Order 2: divided by 3.
        let n = tol.error_norm(2, 1.0, (&z, &z), (&d, &z));
        assert!((n - 1.0 / 2f64.sqrt()).abs() < 1e-12);
        // Per unit step: ten steps per run make each count ten times.
        let n = tol.error_norm(2, 10.0, (&z, &z), (&d, &z));
        assert!((n - 10.0 / 2f64.sqrt()).abs() < 1e-11);
        // Round-off floor: identical values of size 1 at atol 1e-300 are not exact.
        let tiny = Tolerance::<1>::scalar(0.0, 1e-300).unwrap();
        let one = [1.0];
        assert!(tiny.error_norm(2, 1.0, (&one, &one), (&one, &one)) > 1e280);
    }

    #[test]
    fn controller_shrinks_on_rejection_and_grows_boundedly() {
        let mut c = Controller::new(4);
        assert!(c.reject(1.0, 100.0) < 1.0);
        // Right after a rejection the step does not grow.
        assert!(c.accept(1.0, 1e-6) <= 1.0);
        assert!(c.accept(1.0, 1e-12) <= 5.0);
        assert_eq!(c.reject(1.0, f64::INFINITY), 0.25);
    }
}
