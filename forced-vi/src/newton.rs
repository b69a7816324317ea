//! A damped Newton solver for square nonlinear systems, on nalgebra.
//!
//! It knows nothing about time, steps or schemes: a problem is anything that implements
//! [`NonlinearSystem`]. All buffers are made once in [`Newton::new`] and reused, so a solve
//! does not allocate.

use nalgebra::{DMatrix, DVector, SMatrix, SVector};

use crate::error::NewtonFailure;

/// A square nonlinear system `R(z) = 0`.
pub trait NonlinearSystem {
    /// The residual at `z`. An `Err` means the residual could not be evaluated (for example,
    /// the model returned a non-finite value).
    fn residual(&mut self, z: &DVector<f64>, r: &mut DVector<f64>) -> Result<(), NewtonFailure>;

    /// The Jacobian `∂R/∂z` at `z`.
    fn jacobian(&mut self, z: &DVector<f64>, j: &mut DMatrix<f64>) -> Result<(), NewtonFailure>;
}

/// Options of the Newton solver. `Default` gives the values listed per field.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub struct NewtonOptions {
    /// Cap on iterations per solve (default 12).
    pub max_iterations: usize,
    /// Relative tolerance on the estimated error of `z` (default 1e-12).
    pub rtol: f64,
    /// Absolute tolerance on the estimated error of `z` (default 1e-15).
    pub atol: f64,
    /// Tolerance on the residual, relative to the caller's residual scale (default 1e-9).
    pub residual_tol: f64,
    /// Halvings allowed in the line search before declaring stagnation (default 10).
    pub max_backtracks: usize,
    /// Reuse the Jacobian's LU factors across the iterations of one solve (simplified
    /// Newton) (default true). The factors are kept only while the contraction rate stays
    /// below 1e-2, so the accepted iterate is as exact as full Newton's; the round-off-level
    /// error floors depend on that.
    pub simplified: bool,
}

impl Default for NewtonOptions {
    fn default() -> Self {
        NewtonOptions {
            max_iterations: 12,
            rtol: 1e-12,
            atol: 1e-15,
            residual_tol: 1e-9,
            max_backtracks: 10,
            simplified: true,
        }
    }
}

impl NewtonOptions {
    /// Sets the iteration cap.
    #[must_use]
    pub fn max_iterations(mut self, n: usize) -> Self {
        self.max_iterations = n;
        self
    }
    /// Sets the relative and absolute tolerances on the solution.
    #[must_use]
    pub fn tolerances(mut self, rtol: f64, atol: f64) -> Self {
        self.rtol = rtol;
        self.atol = atol;
        self
    }
    /// Sets the residual tolerance (relative to the momentum scale).
    #[must_use]
    pub fn residual_tol(mut self, tol: f64) -> Self {
        self.residual_tol = tol;
        self
    }
    /// Turns simplified Newton (reused LU factors) on or off.
    #[must_use]
    pub fn simplified(mut self, on: bool) -> Self {
        self.simplified = on;
        self
    }
}

impl NewtonOptions {
    /// Checks the options: tolerances finite and non-negative (the residual tolerance
    /// positive), at least one and at most 10 000 iterations, at most 64 halvings. The `Err`
    /// names the offending field and its value.
    pub fn validate(&self) -> Result<(), (&'static str, f64)> {
        let nonneg = |x: f64| x.is_finite() && x >= 0.0;
        if !nonneg(self.rtol) {
            return Err(("rtol", self.rtol));
        }
        if !nonneg(self.atol) {
            return Err(("atol", self.atol));
        }
        if !(self.residual_tol.is_finite() && self.residual_tol > 0.0) {
            return Err(("residual_tol", self.residual_tol));
        }
        if !(1..=10_000).contains(&self.max_iterations) {
            return Err(("max_iterations", self.max_iterations as f64));
        }
        if self.max_backtracks > 64 {
            return Err(("max_backtracks", self.max_backtracks as f64));
        }
        Ok(())
    }
}

/// Simplified Newton refreshes its Jacobian when the contraction rate exceeds this.
const THETA_REFRESH: f64 = 1e-2;

/// What a successful solve reports.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NewtonReport {
    /// Linear solves performed.
    pub iterations: usize,
    /// Max-norm of the residual at the solution.
    pub residual: f64,
    /// Line-search halvings taken in total.
    pub backtracks: usize,
    /// The bound that `residual` met: `max(residual_tol · scale, 64 ε (scale + |J| · |z|))`
    /// at the accepted iterate (see [`Newton::solve`]).
    pub residual_bound: f64,
}

/// LU with partial pivoting, in place in a buffer made once.
///
/// nalgebra's `LU` allocates a permutation for each factorisation of a dynamically sized
/// matrix; the stepper factors a small matrix every iteration, so it keeps its own buffers.
#[derive(Clone, Debug)]
pub struct DenseLu {
    lu: DMatrix<f64>,
    piv: Vec<usize>,
    row_scale: Vec<f64>,
}

impl DenseLu {
    /// Buffers for `n × n` systems.
    pub fn new(n: usize) -> Self {
        DenseLu {
            lu: DMatrix::zeros(n, n),
            piv: vec![0; n],
            row_scale: vec![0.0; n],
        }
    }

    /// Factors `a`. Fails if a pivot is zero or negligible against the scale of its own
    /// row (a scale-invariant test: rows of very different sizes are not singular).
    pub fn factor(&mut self, a: &DMatrix<f64>) -> Result<(), NewtonFailure> {
        let n = a.nrows();
        self.lu.as_mut_slice().copy_from_slice(a.as_slice());
        let m = self.lu.as_mut_slice(); // column-major: m[i + j * n] is row i, column j
        if m.iter().any(|x| !x.is_finite()) {
            return Err(NewtonFailure::NonFinite);
        }
        for (i, r) in self.row_scale.iter_mut().enumerate() {
            *r = (0..n).fold(0.0f64, |s, j| s.max(m[i + j * n].abs()));
        }
        for k in 0..n {
            let col = &m[k * n..(k + 1) * n];
            let (mut p, mut best) = (k, col[k].abs());
            for (i, x) in col.iter().enumerate().skip(k + 1) {
                if x.abs() > best {
                    best = x.abs();
                    p = i;
                }
            }
            if best <= self.row_scale[p] * f64::EPSILON * 1e-3 || best == 0.0 {
                return Err(NewtonFailure::SingularJacobian);
            }
            self.piv[k] = p;
            if p != k {
                for j in 0..n {
                    m.swap(k + j * n, p + j * n);
                }
                self.row_scale.swap(k, p);
            }
            let inv = 1.0 / m[k + k * n];
            for x in &mut m[k * n + k + 1..(k + 1) * n] {
                *x *= inv;
            }
            for j in k + 1..n {
                let u = m[k + j * n];
                if u != 0.0 {
                    let (left, right) = m.split_at_mut(j * n);
                    let lcol = &left[k * n + k + 1..(k + 1) * n];
                    for (x, l) in right[k + 1..n].iter_mut().zip(lcol) {
                        *x -= l * u;
                    }
                }
            }
        }
        Ok(())
    }

    /// Solves `A x = b` in place with the last factors.
    pub fn solve_in_place(&self, b: &mut DVector<f64>) {
        let n = self.piv.len();
        let m = self.lu.as_slice();
        let x = b.as_mut_slice();
        for (k, &p) in self.piv.iter().enumerate() {
            x.swap(k, p);
        }
        for j in 0..n {
            let xj = x[j];
            if xj != 0.0 {
                for (xi, l) in x[j + 1..n].iter_mut().zip(&m[j * n + j + 1..(j + 1) * n]) {
                    *xi -= l * xj;
                }
            }
        }
        for j in (0..n).rev() {
            x[j] /= m[j + j * n];
            let xj = x[j];
            if xj != 0.0 {
                for (xi, u) in x[..j].iter_mut().zip(&m[j * n..j * n + j]) {
                    *xi -= u * xj;
                }
            }
        }
    }
}

/// Solves `a x = b` for a small static matrix by LU with partial pivoting, on the stack.
///
/// Returns `x` and a reciprocal condition estimate (smallest over largest pivot), or `None`
/// if a pivot is exactly zero or a value is not finite. nalgebra's own LU needs typenum
/// bounds that a generic `const N` cannot meet.
pub fn solve_small<const N: usize>(
    a: &SMatrix<f64, N, N>,
    b: &SVector<f64, N>,
) -> Option<(SVector<f64, N>, f64)> {
    let (mut a, mut x) = (*a, *b);
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for k in 0..N {
        let p = (k..N).max_by(|&i, &j| a[(i, k)].abs().total_cmp(&a[(j, k)].abs()))?;
        let piv = a[(p, k)];
        if piv == 0.0 || !piv.is_finite() {
            return None;
        }
        lo = lo.min(piv.abs());
        hi = hi.max(piv.abs());
        a.swap_rows(k, p);
        x.swap_rows(k, p);
        for i in k + 1..N {
            let l = a[(i, k)] / piv;
            for j in k..N {
                let u = a[(k, j)];
                a[(i, j)] -= l * u;
            }
            let xk = x[k];
            x[i] -= l * xk;
        }
    }
    for i in (0..N).rev() {
        let mut s = x[i];
        for j in i + 1..N {
            s -= a[(i, j)] * x[j];
        }
        x[i] = s / a[(i, i)];
    }
    Some((x, if N == 0 { 1.0 } else { lo / hi }))
}

/// The Newton solver with its reusable buffers.
#[derive(Clone, Debug)]
pub struct Newton {
    opts: NewtonOptions,
    lu: DenseLu,
    jac: DMatrix<f64>,
    r: DVector<f64>,
    r_trial: DVector<f64>,
    dz: DVector<f64>,
    z_trial: DVector<f64>,
    have_factors: bool,
    last_iterations: usize,
}

/// The round-off level of a residual whose terms, of size `scale` and `|J| · |z|`, cancel.
#[inline]
pub fn round_off_floor(scale: f64, jac_scale: f64, z_norm: f64) -> f64 {
    64.0 * f64::EPSILON * (scale + jac_scale * z_norm)
}

/// Max-norm that propagates NaN (unlike `f64::max`).
fn max_norm(x: &DVector<f64>) -> f64 {
    let mut m = 0.0f64;
    for &v in x.as_slice() {
        let a = v.abs();
        m = if a > m || a.is_nan() { a } else { m };
    }
    m
}

impl Newton {
    /// A solver for systems of `n` unknowns.
    pub fn new(n: usize, opts: NewtonOptions) -> Self {
        Newton {
            opts,
            lu: DenseLu::new(n),
            jac: DMatrix::zeros(n, n),
            r: DVector::zeros(n),
            r_trial: DVector::zeros(n),
            dz: DVector::zeros(n),
            z_trial: DVector::zeros(n),
            have_factors: false,
            last_iterations: 0,
        }
    }

    /// The options in use.
    pub fn options(&self) -> &NewtonOptions {
        &self.opts
    }

    /// The residual at the last accepted iterate (valid after a successful solve).
    pub fn residual(&self) -> &DVector<f64> {
        &self.r
    }

    /// Linear solves done by the last call to [`Newton::solve`], converged or not.
    pub fn last_iterations(&self) -> usize {
        self.last_iterations
    }

    /// Forgets reusable Jacobian factors (call when the problem changes).
    pub fn invalidate(&mut self) {
        self.have_factors = false;
    }

    /// Solves `R(z) = 0` from the initial guess in `z`, overwriting it.
    ///
    /// `residual_scale` sets the units of the residual test. Convergence needs both a small
    /// estimated error in `z`, from the contraction rate `θ = |Δz_k| / |Δz_{k−1}|` as in
    /// Hairer's codes, and a small residual. A step that does not reduce the residual is
    /// halved (line search); repeated growth is divergence.
    ///
    /// An `Ok` iterate `z` (max-norms throughout) satisfies the stated bound
    ///
    /// `|R(z)| ≤ max(residual_tol · scale, 64 ε (scale + |J| · |z|))`
    ///
    /// where `|J|` is the largest entry of the last Jacobian. The second term is the
    /// round-off floor of a residual whose terms, of size `scale` and `|J|·|z|` at the
    /// solution, cancel. It is computed from the accepted iterate itself, never from the
    /// initial guess, so a huge guess cannot widen it. Unless the residual is at that floor,
    /// the estimated error of `z` is also below `rtol · |z| + atol`.
    pub fn solve<S: NonlinearSystem>(
        &mut self,
        sys: &mut S,
        z: &mut DVector<f64>,
        residual_scale: f64,
    ) -> Result<NewtonReport, NewtonFailure> {
        let o = self.opts;
        let scale = residual_scale.max(f64::MIN_POSITIVE);
        let res_tol = o.residual_tol * scale;
        let mut jac_scale = 0.0f64;
        sys.residual(z, &mut self.r)?;
        let mut rnorm = max_norm(&self.r);
        if !rnorm.is_finite() {
            return Err(NewtonFailure::NonFinite);
        }
        let mut prev_step = f64::INFINITY;
        let mut backtracks = 0;
        let mut growth = 0;
        self.last_iterations = 0;
        for it in 1..=o.max_iterations {
            self.last_iterations = it;
            if !(o.simplified && self.have_factors) {
                sys.jacobian(z, &mut self.jac)?;
                self.lu.factor(&self.jac)?;
                self.have_factors = true;
                jac_scale = self
                    .jac
                    .as_slice()
                    .iter()
                    .fold(0.0f64, |m, x| m.max(x.abs()));
            }
            // Below this level residuals at the current iterate are round-off.
            let res_floor = round_off_floor(scale, jac_scale, max_norm(z));
            self.dz.as_mut_slice().copy_from_slice(self.r.as_slice());
            self.lu.solve_in_place(&mut self.dz);
            self.dz.neg_mut();
            let full = max_norm(&self.dz);
            if !full.is_finite() {
                return Err(NewtonFailure::NonFinite);
            }
            // Line search on the residual norm.
            let mut lambda = 1.0;
            let mut halvings = 0;
            let trial_norm = loop {
                for ((t, x), d) in self
                    .z_trial
                    .as_mut_slice()
                    .iter_mut()
                    .zip(z.as_slice())
                    .zip(self.dz.as_slice())
                {
                    *t = x + lambda * d;
                }
                let ok = sys.residual(&self.z_trial, &mut self.r_trial).is_ok();
                let tn = if ok {
                    max_norm(&self.r_trial)
                } else {
                    f64::NAN
                };
                if tn.is_finite() && (tn <= rnorm * (1.0 - 1e-4 * lambda) || tn <= res_floor) {
                    break tn;
                }
                // A full step that grows the residual right next to the solution is still
                // accepted once: Newton's local convergence, not the norm, is then in charge.
                if tn.is_finite() && halvings == 0 && full <= o.rtol * max_norm(z) + o.atol {
                    break tn;
                }
                halvings += 1;
                if halvings > o.max_backtracks {
                    if o.simplified && self.have_factors {
                        // Stale factors: retry this iteration with a fresh Jacobian.
                        self.have_factors = false;
                        break f64::NAN;
                    }
                    return Err(NewtonFailure::Stagnated { residual: rnorm });
                }
                lambda *= 0.5;
            };
            if trial_norm.is_nan() {
                continue;
            }
            backtracks += halvings;
            std::mem::swap(z, &mut self.z_trial);
            std::mem::swap(&mut self.r, &mut self.r_trial);
            let step = lambda * full;
            let theta = step / prev_step;
            if trial_norm > rnorm && it > 1 {
                growth += 1;
                if growth >= 3 {
                    return Err(NewtonFailure::Diverged {
                        residual: trial_norm,
                    });
                }
            }
            rnorm = trial_norm;
            prev_step = step;
            let err_estimate = if it == 1 || !theta.is_finite() {
                step
            } else if theta < 1.0 {
                step * theta / (1.0 - theta)
            } else {
                f64::INFINITY
            };
            let tol = o.rtol * max_norm(z) + o.atol;
            // A residual at the round-off floor cannot be reduced further: the iterate is as
            // exact as the problem's conditioning allows, even if the increments are noise.
            let at_floor = it > 1 && rnorm <= round_off_floor(scale, jac_scale, max_norm(z));
            if (err_estimate <= tol && rnorm <= res_tol && halvings == 0) || at_floor {
                return Ok(NewtonReport {
                    iterations: it,
                    residual: rnorm,
                    backtracks,
                    residual_bound: res_tol.max(round_off_floor(scale, jac_scale, max_norm(z))),
                });
            }
            if o.simplified && (it == 1 || theta > THETA_REFRESH) {
                // Stale factors contract slowly; a fresh Jacobian restores quadratic
                // convergence, so the accepted iterate is as exact as full Newton's.
                // After the first iteration θ is unknown; a small first correction means a
                // good initial guess, so the factors taken there stay accurate.
                if it > 1 || step > 1e-3 * max_norm(z) {
                    self.have_factors = false;
                }
            }
        }
        Err(NewtonFailure::MaxIterations { residual: rnorm })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Cubic;
    impl NonlinearSystem for Cubic {
        fn residual(
            &mut self,
            z: &DVector<f64>,
            r: &mut DVector<f64>,
        ) -> Result<(), NewtonFailure> {
            r[0] = z[0] * z[0] * z[0] - 2.0 * z[0] - 5.0 + z[1];
            r[1] = z[1] - 0.1 * z[0];
            Ok(())
        }
        fn jacobian(
            &mut self,
            z: &DVector<f64>,
            j: &mut DMatrix<f64>,
        ) -> Result<(), NewtonFailure> {
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
        fn residual(
            &mut self,
            z: &DVector<f64>,
            r: &mut DVector<f64>,
        ) -> Result<(), NewtonFailure> {
            r.copy_from(&(&self.a * z - &self.b + z.map(|x| self.c * x * x * x)));
            Ok(())
        }
        fn jacobian(
            &mut self,
            z: &DVector<f64>,
            j: &mut DMatrix<f64>,
        ) -> Result<(), NewtonFailure> {
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
}
