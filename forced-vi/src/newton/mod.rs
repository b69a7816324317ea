//! A damped Newton solver for square nonlinear systems, on nalgebra.
//!
//! It knows nothing about time, steps or schemes: a problem is anything that implements
//! [`NonlinearSystem`]. All buffers are made once in [`Newton::new`] and reused, so a solve
//! does not allocate.
//!
//! | piece | module |
//! |---|---|
//! | [`NonlinearSystem`], [`Newton`] on a dense Jacobian, [`NewtonReport`] | this one |
//! | the iteration, generic over its linear algebra (shared with the sparse Newton) | `iteration` |
//! | [`NewtonOptions`] and their checks | `options` |
//! | dense LU: [`DenseLu`] for the step Jacobian, [`solve_small`] for `N × N` blocks | `lu` |

mod iteration;
mod lu;
mod options;
#[cfg(test)]
mod tests;

use crate::buffers::{zero_matrix, zero_vector, zeros};
use nalgebra::{DMatrix, DVector};

use crate::error::NewtonFailure;

pub use iteration::round_off_floor;
pub(crate) use iteration::{Iteration, LinearSolver};
pub use lu::{DenseLu, solve_small};
pub use options::NewtonOptions;

/// A square nonlinear system `R(z) = 0`.
pub trait NonlinearSystem {
    /// The residual at `z`. An `Err` means the residual could not be evaluated (for example,
    /// the model returned a non-finite value).
    fn residual(&mut self, z: &DVector<f64>, r: &mut DVector<f64>) -> Result<(), NewtonFailure>;

    /// The Jacobian `∂R/∂z` at `z`.
    fn jacobian(&mut self, z: &DVector<f64>, j: &mut DMatrix<f64>) -> Result<(), NewtonFailure>;

    /// [`NonlinearSystem::residual`] then [`NonlinearSystem::jacobian`] at the same `z`
    /// (the default): a system whose Jacobian's evaluation gives the residual's terms too
    /// makes both in one pass. The iteration asks for it where a solve makes fresh factors
    /// at its guess.
    fn residual_and_jacobian(
        &mut self,
        z: &DVector<f64>,
        r: &mut DVector<f64>,
        j: &mut DMatrix<f64>,
    ) -> Result<(), NewtonFailure> {
        self.residual(z, r)?;
        self.jacobian(z, j)
    }

    /// The round-off of the residual that does not shrink with `z`, as of the last
    /// [`NonlinearSystem::jacobian`]: it widens the round-off floor of [`Newton::solve`]
    /// (default 0). For a step's equations it is `h |A| |x|`, the forces' round-off at
    /// positions of size `|x|` (`A = ∂(L_q + F)/∂q`), which the increments `z` do not
    /// show: a chain displaced by 1 with forces of 1e-5 computes them from differences
    /// of positions, each rounded at 1e-16.
    fn residual_noise(&self) -> f64 {
        0.0
    }

    /// The scale `ρ_a` of each residual row `a`, for a solve with `residual_scale` `scale`
    /// (default: `scale` for every row). Row `a` meets the residual test at
    /// `|R_a| ≤ residual_tol ρ_a`, and its round-off floor counts `ρ_a` among its terms
    /// (see [`Newton::solve`]). A system whose rows are in different units, or of very
    /// different sizes (a step's momenta of a light and a heavy coordinate), gives each its
    /// own.
    fn row_scales(&self, scale: f64, out: &mut [f64]) {
        out.fill(scale);
    }

    /// Adds each residual row's round-off that does not shrink with `z` to `out` (default:
    /// [`NonlinearSystem::residual_noise`] to every row).
    fn add_row_noise(&self, out: &mut [f64]) {
        let noise = self.residual_noise();
        out.iter_mut().for_each(|x| *x += noise);
    }

    /// Whether each row's round-off floor counts its own terms: its scale
    /// ([`NonlinearSystem::row_scales`]), its noise ([`NonlinearSystem::add_row_noise`])
    /// and the largest Jacobian entry of its group ([`NonlinearSystem::group_max`]) times
    /// the largest unknown. Without it (the default), every row's floor counts the largest
    /// of each: `64 ε (scale + ν + |J| |z|)` of [`Newton::solve`].
    fn rows_apart(&self) -> bool {
        false
    }

    /// With [`NonlinearSystem::rows_apart`]: replaces each row's value in `out` (its largest
    /// Jacobian entry) by the largest over the rows whose round-off it shares (default: all
    /// of them).
    fn group_max(&self, out: &mut [f64]) {
        let m = out.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        out.fill(m);
    }

    /// The Jacobian is the same at every `z` and in every solve of this system's size (a
    /// linear model's step equations at one step size): factors made for an earlier solve
    /// are then exact, and their first correction is accepted as a fresh one's would be.
    fn constant_jacobian(&self) -> bool {
        false
    }
}

/// `h |A| |x|`, the [`NonlinearSystem::residual_noise`] of a step's equations: the forces'
/// round-off at positions of size `|x|`, from the entries of `A = ∂(L_q + F)/∂q` at the
/// step's nodes and the positions there.
pub(crate) fn force_round_off<'a>(
    h: f64,
    a: impl IntoIterator<Item = &'a [f64]>,
    x: impl IntoIterator<Item = &'a [f64]>,
) -> f64 {
    // Plain loops over the parts: a small model's step takes this once per Jacobian, and a
    // chain of flattening iterators cost it several times the comparisons. A plain
    // comparison, not `f64::max`, whose NaN rule costs more instructions (a NaN is
    // skipped either way).
    fn max_abs<'a>(parts: impl IntoIterator<Item = &'a [f64]>) -> f64 {
        let mut m = 0.0f64;
        for part in parts {
            for v in part {
                let a = v.abs();
                m = if a > m { a } else { m };
            }
        }
        m
    }
    h * max_abs(a) * max_abs(x)
}

/// The rows' factor over the one that puts their round-off at `ε scale` (see
/// [`constraint_scales`]).
const ROW_MARGIN: f64 = 4.0;

/// The factors on constraint `k`'s rows `g_k(x_j)` and on its unknowns `ŵ_j = h² λ_j` in
/// the step equations (DESIGN §11), for a solve with the momentum scale `scale` of the
/// Newton's tests, `|G_k|` the max-norm of the constraint's gradient at the step's start,
/// `X` the size of the positions the step covers and `m` that of the mass matrix:
/// - rows times `scale / (|G_k| X)` ([`ROW_MARGIN`] times that). A row `g_k` carries the
///   round-off `ε |G_k| X` of its terms, in the constraint's own units, which the Newton's
///   floor (in momenta) does not count; scaled, it carries a few `ε scale`, within that
///   floor, and its residual test bounds the distance from the constraint, `|g_k| / |G_k|`,
///   relative to `X`. (Rows held to their round-off, 64 times the factor, left iterations
///   that could not end.)
/// - unknowns over `m / |G_k|`: the iteration solves for `|G_k| ŵ_j / m`, the displacement
///   the constraint's impulse over the step makes, in the units of the increments beside
///   it, so that its error test (relative to the largest unknown) resolves the multipliers
///   as it does the increments. `ŵ` itself scales as `1 / |G_k|`: with the rows alone
///   scaled, a pendulum's constraint multiplied by 1e12 had multipliers below the test's
///   absolute tolerance and ended 3e-8 off the run in metres (fixed steps, h = 0.01).
///
/// So a model written in micrometres, or with its constraint multiplied by a constant, is
/// solved as the same model in metres, to 1e-10 (before, such runs ended in
/// [`NewtonFailure::MaxIterations`] with their residuals at round-off). Either factor is 1
/// where it is not a positive finite number (a gradient that vanishes there).
///
/// The dense backend only, which makes fresh factors at every step of a constrained model.
/// The factors follow the momentum scale from step to step, and the sparse backend keeps
/// its Newton factors across steps of one size: with these factors there, a 256-link chain
/// (lobatto2, h = 1.25e-4) ended 2.7e-17 off its constraints against 4.5e-18, and factors
/// kept while within a factor 4 of the new ones made an 8-link chain's Newton fail. The
/// sparse backend keeps its rows and unknowns unscaled.
pub(crate) fn constraint_scales(scale: f64, g_norm: f64, (x_size, mass): (f64, f64)) -> (f64, f64) {
    let factor = |f: f64| if f.is_finite() && f > 0.0 { f } else { 1.0 };
    (
        factor(ROW_MARGIN * scale / (g_norm * x_size)),
        factor(mass / g_norm),
    )
}

/// `|A| |x|` from a [`force_round_off`] `noise` taken with the step `h`: the forces'
/// round-off at the nodes, over ε, per unit step (0 before the first Jacobian).
pub(crate) fn force_round_off_rate(noise: f64, h: f64) -> f64 {
    if h > 0.0 { noise / h } else { 0.0 }
}

/// What a successful solve reports.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
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

/// The Newton solver with its reusable buffers.
#[derive(Clone, Debug)]
pub struct Newton {
    /// The iteration; the error estimate's backend reaches its carried factors
    /// (`Iteration::carry_factors`) here.
    pub(crate) iteration: Iteration<DVector<f64>>,
    linear: DenseLinear,
}

/// The dense Jacobian and its LU factors.
#[derive(Clone, Debug)]
struct DenseLinear {
    lu: DenseLu,
    jac: DMatrix<f64>,
    /// `max_b |J_ab|` for each row `a` of `jac`, made with it by one scan.
    row_max: Vec<f64>,
}

impl DenseLinear {
    /// Each row's largest absolute entry of `jac` into `row_max`; returns the largest of all
    /// (a NaN entry counts as nothing, as in a fold with `f64::max`).
    fn scan_rows(&mut self) -> f64 {
        let rows = self.jac.nrows();
        if self.row_max.len() != rows {
            self.row_max.resize(rows, 0.0);
        }
        let (m, out) = (self.jac.as_slice(), &mut self.row_max[..]);
        // Not by columns as arrays of a size known at compile time, as the LU: that took 77
        // instructions instead of 209 for a 4 × 4 Jacobian, but lobatto3 on coupled van der
        // Pol (h = 0.01) took 337 instead of 308 ns per step (medians, interleaved runs).
        scan_rows_general(rows, m, out)
    }
}

/// [`DenseLinear::scan_rows`], by slices of the column-major storage (nalgebra's column
/// iterator cost four times as many instructions). The first column sets the maxima: a
/// fill with zeros before it, read back at another width, stalled (in sampled profiles of
/// lobatto3 on coupled van der Pol, the scan fell from 5 % of the step's time to 2 %). A
/// NaN entry counts as nothing.
fn scan_rows_general(rows: usize, m: &[f64], out: &mut [f64]) -> f64 {
    let mut cols = m.chunks_exact(rows.max(1));
    if let Some(first) = cols.next() {
        for (o, &x) in out.iter_mut().zip(first) {
            let a = x.abs();
            *o = if a > 0.0 { a } else { 0.0 };
        }
    }
    for col in cols {
        for (o, &x) in out.iter_mut().zip(col) {
            let a = x.abs();
            *o = if a > *o { a } else { *o };
        }
    }
    out.iter().fold(0.0f64, |m, &x| if x > m { x } else { m })
}

impl<S: NonlinearSystem + ?Sized> LinearSolver<S> for DenseLinear {
    type Vector = DVector<f64>;

    #[inline(always)]
    fn residual(sys: &mut S, z: &DVector<f64>, r: &mut DVector<f64>) -> Result<(), NewtonFailure> {
        sys.residual(z, r)
    }

    #[inline]
    fn refresh(&mut self, sys: &mut S, z: &DVector<f64>) -> Result<f64, NewtonFailure> {
        sys.jacobian(z, &mut self.jac)?;
        self.lu.factor(&self.jac)?;
        Ok(self.scan_rows())
    }

    #[inline]
    fn refresh_with_residual(
        &mut self,
        sys: &mut S,
        z: &DVector<f64>,
        r: &mut DVector<f64>,
    ) -> Result<f64, NewtonFailure> {
        sys.residual_and_jacobian(z, r, &mut self.jac)?;
        // A residual that is not finite is reported as such, before the factorisation of
        // its Jacobian could call it singular.
        if !r.iter().all(|x| x.is_finite()) {
            return Err(NewtonFailure::NonFinite);
        }
        self.lu.factor(&self.jac)?;
        Ok(self.scan_rows())
    }

    #[inline(always)]
    fn solve_in_place(&mut self, b: &mut DVector<f64>) {
        self.lu.solve_in_place(b);
    }

    fn constant_jacobian(sys: &S) -> bool {
        sys.constant_jacobian()
    }

    #[inline(always)]
    fn row_scales(sys: &S, scale: f64, out: &mut [f64]) {
        sys.row_scales(scale, out)
    }

    #[inline(always)]
    fn add_row_noise(sys: &S, out: &mut [f64]) {
        sys.add_row_noise(out)
    }

    #[inline(always)]
    fn rows_apart(sys: &S) -> bool {
        sys.rows_apart()
    }

    #[inline(always)]
    fn group_max(sys: &S, out: &mut [f64]) {
        sys.group_max(out)
    }

    #[inline]
    fn row_max(&self, out: &mut [f64]) {
        // Made by the refresh that made the factors (`scan_rows`).
        if out.len() == self.row_max.len() {
            out.copy_from_slice(&self.row_max);
        } else {
            out.fill(0.0);
            for (o, &x) in out.iter_mut().zip(&self.row_max) {
                *o = x;
            }
        }
    }
}

impl Newton {
    /// A solver for systems of `n` unknowns.
    pub fn new(n: usize, opts: NewtonOptions) -> Self {
        Newton {
            iteration: Iteration::new(opts, zero_vector(n)),
            linear: DenseLinear {
                lu: DenseLu::new(n),
                jac: zero_matrix(n, n),
                row_max: zeros(n),
            },
        }
    }

    /// The options in use.
    pub fn options(&self) -> &NewtonOptions {
        &self.iteration.opts
    }

    /// The residual at the last accepted iterate (valid after a successful solve).
    pub fn residual(&self) -> &DVector<f64> {
        &self.iteration.r
    }

    /// Linear solves done by the last call to [`Newton::solve`], converged or not.
    pub fn last_iterations(&self) -> usize {
        self.iteration.last_iterations
    }

    /// The size of the correction that would follow the last solve's iterate (see the
    /// iteration's `next_correction`).
    pub(crate) fn next_correction(&mut self) -> (f64, f64, bool) {
        self.iteration
            .next_correction::<dyn NonlinearSystem, _>(&mut self.linear)
    }

    /// Forgets reusable Jacobian factors (call when the problem changes).
    pub fn invalidate(&mut self) {
        self.iteration.have_factors = false;
        self.iteration.jrow_valid = false;
    }

    /// Evaluates and factors the Jacobian of `sys` at `z` (for the tangent of a solution,
    /// DESIGN §12); a following [`Newton::solve`] makes its own factors.
    pub(crate) fn factor_at<S: NonlinearSystem>(
        &mut self,
        sys: &mut S,
        z: &DVector<f64>,
    ) -> Result<(), NewtonFailure> {
        self.iteration.have_factors = false;
        self.iteration.jrow_valid = false;
        let sys: &mut dyn NonlinearSystem = sys;
        LinearSolver::<dyn NonlinearSystem>::refresh(&mut self.linear, sys, z).map(|_| ())
    }

    /// The Jacobian of the last [`Newton::factor_at`] or refresh.
    pub(crate) fn jacobian(&self) -> &DMatrix<f64> {
        &self.linear.jac
    }

    /// Solves `J x = b` in place with the factors of [`Newton::factor_at`].
    pub(crate) fn solve_factored(&self, b: &mut DVector<f64>) {
        self.linear.lu.solve_in_place(b);
    }

    /// Solves `R(z) = 0` from the initial guess in `z`, overwriting it.
    ///
    /// `residual_scale` sets the units of the residual test. Convergence needs both a small
    /// estimated error in `z`, from the contraction rate `θ = |Δz_k| / |Δz_{k−1}|` as in
    /// Hairer's codes, and a small residual; or a residual at its round-off floor (below),
    /// which no further correction reduces. After the first correction, whose contraction
    /// is not known yet, only a sixteenth of that floor counts: a linear system lands there
    /// in one correction and is not solved twice. A step that does not reduce the residual
    /// is halved (line search); repeated growth is divergence.
    ///
    /// An `Ok` iterate `z` (max-norms throughout) satisfies the stated bound
    ///
    /// `|R(z)| ≤ max(residual_tol · scale, 64 ε (scale + ν + |J| · |z|))`
    ///
    /// where `|J|` is the largest entry of the last Jacobian and `ν` the system's
    /// [`NonlinearSystem::residual_noise`]. The second term is the round-off floor of a
    /// residual whose terms, of size `scale`, `ν` and `|J|·|z|` at the solution, cancel. It is computed from the accepted iterate itself, never from the
    /// initial guess, so a huge guess cannot widen it. Unless the residual is at that floor,
    /// the estimated error of `z` is also below `rtol · |z| + atol`.
    pub fn solve<S: NonlinearSystem>(
        &mut self,
        sys: &mut S,
        z: &mut DVector<f64>,
        residual_scale: f64,
    ) -> Result<NewtonReport, NewtonFailure> {
        self.solve_dyn(sys, z, residual_scale)
    }

    /// [`Newton::solve`] behind a trait object: the iteration is compiled once, not once
    /// per model (a residual or a Jacobian costs far more than the indirect call).
    fn solve_dyn(
        &mut self,
        sys: &mut dyn NonlinearSystem,
        z: &mut DVector<f64>,
        residual_scale: f64,
    ) -> Result<NewtonReport, NewtonFailure> {
        self.iteration
            .solve(&mut self.linear, sys, z, residual_scale)
    }
}
