//! Unit tests of the Newton solver and the dense LU.

use nalgebra::{DMatrix, DVector};

use super::*;

struct Cubic;
impl NonlinearSystem for Cubic {
    fn residual(&mut self, z: &DVector<f64>, r: &mut DVector<f64>) -> Result<(), NewtonFailure> {
        r[0] = z[0] * z[0] * z[0] - 2.0 * z[0] - 5.0 + z[1];
        r[1] = z[1] - 0.1 * z[0];
        Ok(())
    }
    fn jacobian(&mut self, z: &DVector<f64>, j: &mut DMatrix<f64>) -> Result<(), NewtonFailure> {
        j[(0, 0)] = 3.0 * z[0] * z[0] - 2.0;
        j[(0, 1)] = 1.0;
        j[(1, 0)] = -0.1;
        j[(1, 1)] = 1.0;
        Ok(())
    }
}

#[test]
fn converges_quadratically_and_checks_both_tests() {
    let mut n = Newton::new(2, NewtonOptions::default().simplified(false));
    let mut z = DVector::from_vec(vec![2.0, 0.0]);
    let rep = n.solve(&mut Cubic, &mut z, 1.0).unwrap();
    assert!(rep.iterations <= 6, "{rep:?}");
    // Simplified Newton converges too, linearly, refreshing its factors when slow.
    let mut n = Newton::new(2, NewtonOptions::default());
    let mut z2 = DVector::from_vec(vec![2.0, 0.0]);
    let rep = n.solve(&mut Cubic, &mut z2, 1.0).unwrap();
    assert!(rep.iterations <= 12, "{rep:?}");
    // Within the requested tolerance, rtol · |z| ≈ 2e-12.
    assert!((&z2 - &z).amax() < 5e-12, "{}", (&z2 - &z).amax());
    let mut r = DVector::zeros(2);
    Cubic.residual(&z, &mut r).unwrap();
    assert!(r.amax() < 1e-13);
}

#[test]
fn lu_solves_and_detects_singularity() {
    let a = DMatrix::from_row_slice(3, 3, &[0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 1.0]);
    let mut lu = DenseLu::new(3);
    lu.factor(&a).unwrap();
    let x = DVector::from_vec(vec![1.0, -2.0, 0.5]);
    let mut b = &a * &x;
    lu.solve_in_place(&mut b);
    assert!((b - x).amax() < 1e-14);
    let s = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 4.0]);
    assert_eq!(lu_err(&s), Some(NewtonFailure::SingularJacobian));
}

/// `R(z) = A z − b + c · z³` (componentwise cube), for linear (`c = 0`) and nonlinear
/// systems.
struct Poly {
    a: DMatrix<f64>,
    b: DVector<f64>,
    c: f64,
}
impl NonlinearSystem for Poly {
    fn residual(&mut self, z: &DVector<f64>, r: &mut DVector<f64>) -> Result<(), NewtonFailure> {
        r.copy_from(&(&self.a * z - &self.b + z.map(|x| self.c * x * x * x)));
        Ok(())
    }
    fn jacobian(&mut self, z: &DVector<f64>, j: &mut DMatrix<f64>) -> Result<(), NewtonFailure> {
        j.copy_from(&self.a);
        for i in 0..z.len() {
            j[(i, i)] += 3.0 * self.c * z[i] * z[i];
        }
        Ok(())
    }
}

#[test]
fn trust_newton_huge_guess_is_not_accepted_early() {
    // The reproducer: the floor used to come from |J|·|z| of the 1e30 guess.
    let a = DMatrix::from_row_slice(2, 2, &[1.0, 0.999, 0.999, 1.0]);
    let b = DVector::from_vec(vec![1.0, 2.0]);
    let exact = a.clone().lu().solve(&b).unwrap();
    let mut sys = Poly { a, b, c: 0.0 };
    for simplified in [true, false] {
        let mut n = Newton::new(2, NewtonOptions::default().simplified(simplified));
        let mut z = DVector::from_vec(vec![1e30, -1e30]);
        match n.solve(&mut sys, &mut z, 1.0) {
            Ok(rep) => {
                assert!((&z - &exact).amax() < 1e-9, "{rep:?} {z}");
                assert!(rep.residual <= rep.residual_bound, "{rep:?}");
            }
            Err(e) => panic!("a linear system converges: {e}"),
        }
    }
}

/// A linear system is solved by its first correction, whose residual lands at a few ε of
/// its terms: the solve ends there instead of taking a second correction to confirm it. A
/// nonlinear one does not stop at its first iterate.
#[test]
fn a_linear_system_ends_after_one_correction() {
    let a = DMatrix::from_row_slice(
        4,
        4,
        &[
            4.0, -1.0, 0.5, 0.0, 1.0, 5.0, -2.0, 0.3, 0.2, -0.7, 3.0, 1.0, -1.0, 0.0, 0.4, 6.0,
        ],
    );
    let b = DVector::from_vec(vec![1.0, -2.0, 3.5, 0.25]);
    let exact = a.clone().lu().solve(&b).unwrap();
    for (c, one) in [(0.0, true), (0.3, false)] {
        let mut sys = Poly {
            a: a.clone(),
            b: b.clone(),
            c,
        };
        for simplified in [true, false] {
            let mut n = Newton::new(4, NewtonOptions::default().simplified(simplified));
            let mut z = DVector::from_vec(vec![0.3, -0.1, 0.9, 0.0]);
            let rep = n.solve(&mut sys, &mut z, 1.0).unwrap();
            assert_eq!(rep.iterations == 1, one, "c = {c}: {rep:?}");
            if c == 0.0 {
                assert!(
                    (&z - &exact).amax() < 1e-15 * 8.0,
                    "{}",
                    (&z - &exact).amax()
                );
            }
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(400))]
    /// Whatever the guess, `solve` meets its stated bound or returns an error; for a
    /// linear system, the error in `z` is then within `|A⁻¹| · bound`.
    #[test]
    fn trust_newton_meets_its_stated_bound_or_fails(
        n in 1usize..6,
        entries in proptest::collection::vec(-1.0f64..1.0, 36),
        rhs in proptest::collection::vec(-1e3f64..1e3, 6),
        guess in proptest::collection::vec(-1.0f64..1.0, 6),
        guess_exp in -3i32..=30,
        cubic in proptest::prop_oneof![proptest::strategy::Just(0.0), -1.0f64..1.0],
        simplified in proptest::bool::ANY,
        scale_exp in -3i32..6,
    ) {
        let mut a = DMatrix::from_fn(n, n, |i, j| entries[i * 6 + j]);
        for i in 0..n {
            a[(i, i)] += 2.0 * a.row(i).abs().sum().max(0.5) * if i % 2 == 0 { 1.0 } else { -1.0 };
        }
        let b = DVector::from_fn(n, |i, _| rhs[i]);
        let mut z = DVector::from_fn(n, |i, _| guess[i] * 10f64.powi(guess_exp));
        let c = if cubic != 0.0 { cubic * a.abs().max() } else { 0.0 };
        let mut sys = Poly { a: a.clone(), b: b.clone(), c };
        let scale = 10f64.powi(scale_exp);
        let mut solver = Newton::new(n, NewtonOptions::default().simplified(simplified));
        if let Ok(rep) = solver.solve(&mut sys, &mut z, scale) {
            let mut r = DVector::zeros(n);
            sys.residual(&z, &mut r).unwrap();
            let rn = r.amax();
            proptest::prop_assert!(rn <= rep.residual_bound * (1.0 + 1e-12), "{rn} > {rep:?}");
            // The bound is the stated one, from the accepted iterate.
            let mut j = DMatrix::zeros(n, n);
            sys.jacobian(&z, &mut j).unwrap();
            let stated = (1e-9 * scale)
                .max(round_off_floor(scale, j.amax(), z.amax()));
            proptest::prop_assert!(rep.residual_bound <= 4.0 * stated, "{rep:?} vs {stated}");
            if c == 0.0 {
                let inv = a.clone().try_inverse().unwrap();
                let exact = &inv * &b;
                let bound = inv.abs().row_sum().max() * rep.residual_bound;
                proptest::prop_assert!(
                    (&z - &exact).amax() <= 1.01 * bound + 1e-13 * exact.amax(),
                    "error {} > {bound}", (&z - &exact).amax()
                );
            }
        }
    }
}

#[test]
fn options_are_validated() {
    let o = NewtonOptions::default();
    assert!(o.validate().is_ok());
    assert_eq!(o.tolerances(-1.0, 0.0).validate(), Err(("rtol", -1.0)));
    assert!(o.tolerances(1e-12, f64::NAN).validate().is_err());
    assert!(o.residual_tol(0.0).validate().is_err());
    assert!(o.max_iterations(0).validate().is_err());
    assert!(o.max_iterations(usize::MAX).validate().is_err());
}

fn lu_err(a: &DMatrix<f64>) -> Option<NewtonFailure> {
    DenseLu::new(a.nrows()).factor(a).err()
}

/// A step-like system `R(z) = K z / h + c · sin(z) − b`: the `1 / h` mass term of the step
/// equations and a nonlinearity; counts its Jacobians.
struct StepLike {
    k: DMatrix<f64>,
    h: f64,
    c: f64,
    b: DVector<f64>,
    jacobians: usize,
}
impl NonlinearSystem for StepLike {
    fn residual(&mut self, z: &DVector<f64>, r: &mut DVector<f64>) -> Result<(), NewtonFailure> {
        r.copy_from(&(&self.k * z / self.h + z.map(|x| self.c * x.sin()) - &self.b));
        Ok(())
    }
    fn jacobian(&mut self, z: &DVector<f64>, j: &mut DMatrix<f64>) -> Result<(), NewtonFailure> {
        self.jacobians += 1;
        j.copy_from(&(&self.k / self.h));
        for i in 0..z.len() {
            j[(i, i)] += self.c * z[i].cos();
        }
        Ok(())
    }
}

impl StepLike {
    /// The system of the carried-factor tests: `K` the 3×3 second difference, a fixed `b`.
    fn tridiagonal(h: f64, c: f64) -> Self {
        StepLike {
            k: DMatrix::from_row_slice(3, 3, &[2.0, -1.0, 0.0, -1.0, 2.0, -1.0, 0.0, -1.0, 2.0]),
            h,
            c,
            b: DVector::from_vec(vec![0.3, -0.2, 0.1]),
            jacobians: 0,
        }
    }
}

/// One Newton iteration, as the error estimate runs it, from `z0`: `(iterate, Jacobians)`.
fn one_iteration(n: &mut Newton, sys: &mut StepLike, z0: &DVector<f64>) -> DVector<f64> {
    let mut z = z0.clone();
    // One iteration is what is asked: it ends in `MaxIterations` unless already converged.
    let _ = n.solve(sys, &mut z, 1.0);
    z
}

#[test]
fn carried_factors_are_scaled_by_the_step_ratio_checked_and_refreshed_when_off() {
    let opts = NewtonOptions::default().max_iterations(1);
    let z0 = DVector::from_vec(vec![0.0, 0.0, 0.0]);
    let mut sys = StepLike::tridiagonal(0.1, 0.2);
    // The exact solution at h = 0.07, by full Newton.
    let exact = |sys: &mut StepLike| {
        let mut n = Newton::new(3, NewtonOptions::default().simplified(false));
        let mut z = z0.clone();
        n.solve(sys, &mut z, 1.0).expect("exact");
        z
    };
    let mut n = Newton::new(3, opts);
    // No factors yet: nothing to carry.
    assert!(!n.iteration.carry_factors(0.1, 0.0));
    one_iteration(&mut n, &mut sys, &z0);
    assert_eq!(sys.jacobians, 1);
    // A smaller step: the factors of h = 0.1 serve, scaled by 0.07 / 0.1 (unscaled, the
    // correction would be 43 % too large, and the residual check would refresh them); the
    // iterate is about as close to the solution as a fresh Newton iteration's.
    sys.h = 0.07;
    let star = exact(&mut sys);
    sys.jacobians = 0;
    assert!(n.iteration.carry_factors(0.07, 0.0));
    let carried = one_iteration(&mut n, &mut sys, &z0);
    assert_eq!(sys.jacobians, 0, "the carried factors were kept");
    // Its error is about what it reports (the contraction of its two corrections), and far
    // below the start's.
    let (ec, bound) = ((&carried - &star).amax(), n.iteration.carried_error());
    assert!(
        bound > 0.0 && ec <= 2.0 * bound,
        "error {ec:e}, bound {bound:e}"
    );
    assert!(ec <= 1e-4 * (&z0 - &star).amax(), "carried error {ec:e}");
    // A stiff nonlinearity (c = 500, so h·c = 35) makes the old factors useless: the
    // residual check catches it, the iteration is redone with fresh factors, and it equals
    // a fresh solve bit for bit.
    let mut stiff = StepLike::tridiagonal(0.07, 500.0);
    assert!(n.iteration.carry_factors(0.07, 0.0));
    let redone = one_iteration(&mut n, &mut stiff, &z0);
    assert_eq!(stiff.jacobians, 1, "refreshed");
    let fresh = one_iteration(&mut Newton::new(3, opts), &mut stiff, &z0);
    assert_eq!(redone, fresh);
    assert_eq!(n.iteration.carried_error(), 0.0);
    // After a failure, carrying pauses for 0, then 1, 3, 7, … solves: the stiff factors
    // fail on the other system (the second failure in a row), so the next solve makes
    // fresh ones, and the one after that carries again.
    assert!(n.iteration.carry_factors(0.07, 0.0));
    sys.jacobians = 0;
    let _ = one_iteration(&mut n, &mut sys, &z0);
    assert_eq!(sys.jacobians, 1, "refreshed");
    assert!(!n.iteration.carry_factors(0.07, 0.0));
    let _ = one_iteration(&mut n, &mut sys, &z0);
    assert_eq!(sys.jacobians, 2, "fresh");
    assert!(n.iteration.carry_factors(0.07, 0.0));
}

#[test]
fn a_negligible_second_correction_of_carried_factors_is_left_out() {
    let opts = NewtonOptions::default().max_iterations(1);
    let z0 = DVector::from_vec(vec![0.0, 0.0, 0.0]);
    let mut sys = StepLike::tridiagonal(0.1, 0.2);
    // Factors at h = 0.1, carried to h = 0.07 twice: with the second correction applied
    // (nothing is negligible), and left out (any size is).
    let mut run = |negligible: f64| {
        let mut n = Newton::new(3, opts);
        sys.h = 0.1;
        assert!(!n.iteration.carry_factors(0.1, negligible));
        one_iteration(&mut n, &mut sys, &z0);
        sys.h = 0.07;
        assert!(n.iteration.carry_factors(0.07, negligible));
        let z = one_iteration(&mut n, &mut sys, &z0);
        (z, n.iteration.carried_error())
    };
    let (polished, bound) = run(0.0);
    let (first, second) = run(f64::INFINITY);
    // Left out, the iterate is the first correction's, off from the polished one by about
    // the second correction, which is what it reports as its error; applied, the error
    // left is far smaller.
    let gap = (&polished - &first).amax();
    assert!(gap > 0.0, "the second correction was not left out");
    assert!(
        (gap - second).abs() <= 0.05 * second,
        "gap {gap:e}, reported {second:e}"
    );
    assert!(bound < 0.1 * second, "bound {bound:e}, second {second:e}");
}

#[test]
fn a_solve_within_a_bound_stops_early_and_meets_it() {
    // The solution to round-off, and the iterations it takes.
    let mut exact = DVector::from_vec(vec![2.0, 0.0]);
    let full = Newton::new(2, NewtonOptions::default())
        .solve(&mut Cubic, &mut exact, 1.0)
        .unwrap();
    for bound in [1e-3, 1e-6, 1e-9] {
        let mut n = Newton::new(2, NewtonOptions::default());
        n.iteration.solve_within(bound);
        let mut z = DVector::from_vec(vec![2.0, 0.0]);
        let rep = n.solve(&mut Cubic, &mut z, 1.0).unwrap();
        let err = (&z - &exact).amax();
        assert!(err <= bound, "bound {bound:e}: error {err:e}");
        // Newton's quadratic convergence leaves the tightest bound no iteration to save.
        assert!(
            rep.iterations < full.iterations || (bound < 1e-6 && rep.iterations == full.iterations),
            "bound {bound:e}: {} iterations, {} to round-off",
            rep.iterations,
            full.iterations
        );
        // For that solve only: the next one goes to round-off again.
        let mut z = DVector::from_vec(vec![2.0, 0.0]);
        let again = n.solve(&mut Cubic, &mut z, 1.0).unwrap();
        assert!((&z - &exact).amax() < 5e-12, "{again:?}");
    }
}

/// The row maxima of the Jacobian are those of a plain fold with `f64::max` from zero (a NaN
/// entry counts as nothing), whatever the buffer held before.
#[test]
fn row_maxima_match_a_plain_fold_at_every_order() {
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 8.0 - 4.0
    };
    for n in 1..=18usize {
        for trial in 0..4 {
            let mut a = DMatrix::from_fn(n, n, |_, _| next());
            if trial == 1 {
                a[(n / 2, n - 1)] = f64::NAN;
            }
            if trial == 2 {
                a[(n - 1, 0)] = -1e300;
            }
            let fold: Vec<f64> = (0..n)
                .map(|i| (0..n).fold(0.0f64, |m, j| m.max(a[(i, j)].abs())))
                .collect();
            let all = fold.iter().fold(0.0f64, |m, x| m.max(*x));
            let mut lin = DenseLinear {
                lu: DenseLu::new(n),
                jac: a.clone(),
                row_max: vec![7.0; n.saturating_sub(1)],
            };
            assert_eq!(lin.scan_rows(), all, "n = {n}");
            assert_eq!(lin.row_max, fold, "n = {n}");
            let mut out = vec![7.0; n];
            assert_eq!(scan_rows_general(n, a.as_slice(), &mut out), all, "n = {n}");
            assert_eq!(out, fold, "n = {n}");
        }
    }
}
