//! The options of the Newton solver and their checks.

/// Options of the Newton solver. `Default` gives the values listed per field.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[non_exhaustive]
pub struct NewtonOptions {
    /// Cap on iterations per solve (default 12).
    pub max_iterations: usize,
    /// Relative tolerance on the estimated error of `z` (default 1e-12). The sparse
    /// backend solves a constrained model's steps to a thousandth of it: its iterates stop
    /// just inside the test, and an error in the multipliers moves the momentum by that
    /// error over the step size.
    pub rtol: f64,
    /// Absolute tolerance on the estimated error of `z` (default 0). An absolute bound
    /// depends on the units of the coordinates: at 1e-15 it decided the solves of any
    /// model whose increments were below about 1e-3, which then stopped after one
    /// iteration (a chain written with lengths of 1e-8 took 1000 iterations over 1000
    /// steps against 1952, and ended 5e-11 off the same chain in units of 1, where 0
    /// leaves 3e-16). An iterate whose increments are at their round-off is accepted by
    /// the residual's round-off test instead.
    pub atol: f64,
    /// Tolerance on the residual, relative to the caller's residual scale (default 1e-9).
    pub residual_tol: f64,
    /// Halvings allowed in the line search before declaring stagnation (default 10).
    pub max_backtracks: usize,
    /// Reuse the Jacobian's LU factors across the iterations of one solve (simplified
    /// Newton) (default true), and, for fixed steps of at least 6 unknowns, across steps.
    /// The factors are kept only while the contraction rate stays below 1e-2, and those of
    /// an earlier step (or fresh ones kept past a far first correction) until the iterate's
    /// estimated error is below round-off, so the accepted iterate is as exact as full
    /// Newton's; the round-off-level error floors
    /// depend on that. A model whose `STRUCTURE.linear` is true has the same Jacobian at
    /// every step of one size: its fixed steps keep one factorisation at any number of
    /// unknowns, and the first correction made with it is accepted as a fresh one's.
    pub simplified: bool,
}

impl Default for NewtonOptions {
    fn default() -> Self {
        NewtonOptions {
            max_iterations: 12,
            rtol: 1e-12,
            atol: 0.0,
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
