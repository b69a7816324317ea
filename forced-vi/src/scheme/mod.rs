//! Discretisations as data: every scheme is a coefficient set `(d, c, b)` (DESIGN §3).
//!
//! The path over one step is the polynomial through control points at the nodes `d`
//! (`d₀ = 0`, `d_{s−1} = 1`); the action is approximated by the quadrature `(c, b)` on
//! `[0, 1]`. All schemes share one residual and Jacobian assembly, in `step_equations` (DESIGN §3).
//!
//! | piece | module |
//! |---|---|
//! | [`Scheme`]: the coefficients, `Φ`, `Ψ` and the Jacobian terms; [`JacobianTerm`] | this one |
//! | [`SchemeId`], its names and their parsing | `id` |
//! | the Lagrange basis on the control points; Lobatto nodes and weights | `coefficients` |

#[cfg(test)]
mod accuracy;
mod coefficients;
mod id;
#[cfg(test)]
mod tests;

pub use coefficients::lobatto_nodes_weights;
use coefficients::{lagrange, lagrange_derivative};
pub use id::SchemeId;

use std::sync::{Arc, OnceLock};

use crate::error::SchemeError;

/// The most control points a Lobatto scheme may have (order `2 · 32 − 2 = 62`).
///
/// Measured (`scheme::accuracy` tests against the 60-digit values of
/// `scripts/lobatto_limits.py`): the nodes and weights stay within 1.1e-16 and 1.7e-14
/// (relative) of exact up to s = 48, and within 7.6e-15 up to 32; a damped oscillator run
/// with s = 32 is accurate to round-off. The bound keeps the step system, `(s − 1)·n`
/// unknowns with an `O((s n)³)` factorisation, and the set-up cost of a scheme small; no
/// `f64` computation gains from more than about 10 stages.
pub const MAX_STAGES: usize = 32;

/// Largest Lebesgue constant `max_j Σ_m |ℓ_m(1 + d_j)|` of the predictor's extrapolation of
/// the previous step's polynomial. Through all `s` control points it grows like 5.8^s (589 at
/// s = 5, 6.9e5 at s = 9, 4.4e32 at s = 44; `forced-vi/data/lobatto_predictor.csv`), and it
/// multiplies the round-off of the previous step. Above s = 9 the predictor therefore
/// extrapolates the polynomial through a spread subset of the control points, the largest
/// (both ends and evenly spaced indices between) whose constant is within this bound: nine
/// points, a degree-8 polynomial, at s = 10 … 32 (see [`Scheme::predictor_degree`]).
///
/// Before, the predictor was a straight line along the velocity there, `O(h²)` off: on Kepler
/// with drag (`h = 0.01`) every lobatto10 step then made a fresh Jacobian and LU where
/// lobatto9 kept the last step's, and took 1.96 µs per step against lobatto9's 1.27 µs.
const MAX_PREDICTOR_LEBESGUE: f64 = 1e6;

/// The fewest points a subset of the predictor may have (all the control points of a
/// smaller scheme): below a quadratic the straight line along the velocity serves as well.
const MIN_PREDICTOR_POINTS: usize = 3;

/// Lobatto schemes with up to this many points have their tables made once per process.
const CACHED_STAGES: usize = 12;

/// The tables of the Lobatto schemes with up to [`CACHED_STAGES`] points, made on first use
/// and shared by every [`Scheme`] of that many points, with their error estimate's tables.
/// Making them costs far more than a step of a small model (measured with callgrind: about
/// 33 000 instructions for lobatto5, 64 000 for the tables of its adaptive estimate,
/// 80 000 for lobatto7, against about 5 500 for a lobatto3 step of a two-coordinate model):
/// without the cache, a program that builds an integrator per short run (a shooting
/// method, a parameter scan) would pay them on every run. Above that many points (at most
/// 33, about 1.8 MB at 32) each scheme makes its own.
static LOBATTO_TABLES: [OnceLock<Arc<Tables>>; CACHED_STAGES + 1] =
    [const { OnceLock::new() }; CACHED_STAGES + 1];

/// The barycentric weights `w_m = 1 / ∏_{k ≠ m} (d_m − d_k)` of the points `d`.
fn barycentric_weights(d: &[f64]) -> Vec<f64> {
    (0..d.len())
        .map(|m| {
            let prod: f64 = (0..d.len())
                .filter(|&k| k != m)
                .map(|k| d[m] - d[k])
                .product();
            1.0 / prod
        })
        .collect()
}

/// The predictor's points (see [`MAX_PREDICTOR_LEBESGUE`]) and its extrapolation table
/// `ℓ_m(1 + d_j)`, row-major `s × s`: all the control points `d` where their extrapolation's
/// Lebesgue constant is within the bound, else the largest spread subset (both ends, and
/// the indices `round(i (s − 1) / (k − 1))` between) of the sizes from
/// [`MIN_PREDICTOR_POINTS`] up whose constants are; none if the smallest fails.
fn predictor_points(d: &[f64]) -> (Vec<usize>, Vec<f64>) {
    let s = d.len();
    // The table through `k` spread points, if its Lebesgue constant is within the bound.
    let through = |k: usize| {
        let points: Vec<usize> = if k == s {
            (0..s).collect()
        } else {
            let mut p: Vec<usize> = (0..k)
                .map(|i| ((i * (s - 1)) as f64 / (k - 1) as f64).round() as usize)
                .collect();
            p.dedup();
            p
        };
        let pd: Vec<f64> = points.iter().map(|&m| d[m]).collect();
        let mut table = vec![0.0; s * s];
        for (j, row) in table.chunks_mut(s).enumerate() {
            for (i, &m) in points.iter().enumerate() {
                row[m] = lagrange(&pd, i, 1.0 + d[j]);
            }
        }
        let lebesgue = table
            .chunks(s)
            .map(|row| row.iter().map(|x| x.abs()).sum::<f64>())
            .fold(0.0, f64::max);
        (lebesgue <= MAX_PREDICTOR_LEBESGUE).then_some((points, table))
    };
    // All the points where they pass; else subsets from the smallest up, until one fails
    // (the constant grows with the points: trying from the top cost 24 tables at s = 32).
    if let Some(all) = through(s) {
        return all;
    }
    let mut best = None;
    for k in MIN_PREDICTOR_POINTS..s {
        match through(k) {
            Some(found) => best = Some(found),
            None => break,
        }
    }
    best.unwrap_or_else(|| (Vec::new(), vec![0.0; s * s]))
}

fn check_stages(s: usize) -> Result<usize, SchemeError> {
    if s < 2 {
        Err(SchemeError::TooFewStages(s))
    } else if s > MAX_STAGES {
        Err(SchemeError::TooManyStages {
            requested: s,
            max: MAX_STAGES,
        })
    } else {
        Ok(s)
    }
}

/// A scheme's coefficients and the matrices derived from them.
///
/// Cloning is cheap: the tables are shared (a reference count), so a scheme can be cloned
/// into every run without copying them. The tables of a Lobatto scheme with up to 12 points
/// (and those of its adaptive error estimate) are made once per process, on first use, and
/// shared by every scheme of that size: building `Scheme::lobatto(s)` again, for a run or an
/// [`Integrator`](crate::Integrator) per parameter set, costs no more than a clone.
#[derive(Clone, Debug)]
pub struct Scheme {
    id: SchemeId,
    t: Arc<Tables>,
}

/// The tables of a [`Scheme`], made once and shared by its clones.
#[derive(Debug)]
struct Tables {
    d: Vec<f64>,
    c: Vec<f64>,
    b: Vec<f64>,
    /// `Φ_ij = ℓ_j(c_i)`, row-major `r × s`.
    phi: Vec<f64>,
    /// `Ψ_ij = ℓ_j'(c_i)`, row-major `r × s`.
    psi: Vec<f64>,
    /// The non-zero terms of the Jacobian chain rule, see [`JacobianTerm`].
    terms: Vec<JacobianTerm>,
    /// Those of `terms` with a non-zero coefficient on `A`, and those with one on `B`: all
    /// there is besides the `E` part for a constant mass matrix (where `C ≡ 0`).
    a_terms: Vec<JacobianTerm>,
    b_terms: Vec<JacobianTerm>,
    /// `terms` gathered by Jacobian block (see [`BlockSum`]).
    block_sums: Vec<BlockSum>,
    /// `b_i Φ_ij` and `b_i Ψ_ij`, row `j` (see [`Scheme::residual_weights`]).
    res_phi: Vec<f64>,
    res_psi: Vec<f64>,
    /// `ℓ_m(1 + d_j)`, row-major `s × s`: the previous step's polynomial extrapolated to
    /// this step's control points (the predictor for equal steps); `ℓ_m` the Lagrange basis
    /// of the predictor's points, zero at a control point not among them.
    extrapolation: Vec<f64>,
    /// The predictor's points: indices of the control points its polynomial goes through,
    /// all of them up to s = 9 (see [`MAX_PREDICTOR_LEBESGUE`]).
    pred_points: Vec<usize>,
    /// The barycentric weights of the predictor's points, as [`Tables::weights`] for all.
    pred_weights: Vec<f64>,
    /// `ℓ_m'(1)`: the polynomial's slope at the end of the step.
    end_slope: Vec<f64>,
    /// The barycentric weights `w_m = 1 / ∏_{k ≠ m} (d_m − d_k)`, so that
    /// `ℓ_m(τ) = w_m ∏_{k ≠ m} (τ − d_k)` (see [`Scheme::basis_at`]).
    weights: Vec<f64>,
    /// Whether the predictor may extrapolate (see [`MAX_PREDICTOR_LEBESGUE`]).
    extrapolates: bool,
    /// The error estimate's scheme and its tables, made on first use (adaptive runs), and
    /// those of the estimate over pairs of steps (see [`Scheme::pair_estimate_tables`]).
    estimate: OnceLock<EstimateTables>,
    pair_estimate: OnceLock<EstimateTables>,
}

/// What an adaptive run's error estimate needs from a scheme ([`crate::control`]), made once
/// per scheme and shared by its clones and runs.
#[derive(Debug)]
pub(crate) struct EstimateTables {
    /// [`Scheme::error_reference`].
    pub(crate) reference: Scheme,
    /// `ℓ_m(d'_j)`: the step polynomial at the reference's control points `j = 1 … r − 1`
    /// (row `j − 1`, column `m − 1`, `m = 1 … s − 1`).
    pub(crate) lift: Vec<f64>,
    /// The Lagrange basis of the step's quadrature nodes at the reference's (row `j`: its
    /// node `j`); empty unless the quadrature nodes are the control points (Lobatto).
    pub(crate) block_weights: Vec<f64>,
    /// The Lagrange basis of the step's control points at the reference's control points
    /// `0 … r − 2` (row `j`): a constrained step's multipliers there.
    pub(crate) lift_lambda: Vec<f64>,
    /// Two steps of one size under one reference step of twice it (see
    /// [`crate::control`], "Pairs"): the reference's control point `j = 1 … r − 1` at
    /// `2 d'_j` steps, in the second step where that is past one (`pair_second[j − 1]`), and
    /// the step polynomial there, `ℓ_m(2 d'_j)` or `ℓ_m(2 d'_j − 1)` (row `j − 1`, column
    /// `m − 1`).
    pub(crate) pair_lift: Vec<f64>,
    pub(crate) pair_second: Vec<bool>,
}

/// The terms of one block `∂G_j/∂x_m` of the step Jacobian, gathered by the node block
/// they weigh: `(i, w)` adds `w A_i` (times `h`), `w B_i`, `w C_i` or `w E_i` (over `h`).
/// The same coefficients as [`JacobianTerm`], without the zeros, so that a block is summed
/// in one place and written once.
#[derive(Clone, Debug, Default)]
pub(crate) struct BlockSum {
    /// Residual block row.
    pub(crate) j: usize,
    /// Unknown block column (`m ≥ 1`).
    pub(crate) m: usize,
    pub(crate) a: Vec<(usize, f64)>,
    pub(crate) b: Vec<(usize, f64)>,
    pub(crate) c: Vec<(usize, f64)>,
    pub(crate) e: Vec<(usize, f64)>,
}

/// One term of `∂G_j/∂x_m = Σ_i b_i [h Φ_ij Φ_im A_i + Φ_ij Ψ_im B_i + Ψ_ij Φ_im C_i
/// + Ψ_ij Ψ_im E_i / h]` for a residual row `j < s − 1` and an unknown `m ≥ 1`, with the
/// factors of `h` left out. Terms whose four coefficients vanish (most of them for Lobatto,
/// where `Φ = I`) are not stored.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JacobianTerm {
    /// Quadrature node.
    pub i: usize,
    /// Residual block row.
    pub j: usize,
    /// Unknown block column (`m ≥ 1`).
    pub m: usize,
    /// `b_i Φ_ij Φ_im` (times `h`) on `A`.
    pub a: f64,
    /// `b_i Φ_ij Ψ_im` on `B`.
    pub b: f64,
    /// `b_i Ψ_ij Φ_im` on `C`.
    pub c: f64,
    /// `b_i Ψ_ij Ψ_im` (over `h`) on `E`.
    pub e: f64,
}

impl Scheme {
    /// Builds the scheme named by `id`.
    pub fn new(id: SchemeId) -> Result<Self, SchemeError> {
        let (d, c, b) = match id {
            SchemeId::Midpoint => (vec![0.0, 1.0], vec![0.5], vec![1.0]),
            SchemeId::Trapezoid => (vec![0.0, 1.0], vec![0.0, 1.0], vec![0.5, 0.5]),
            SchemeId::Alpha(a) => {
                if !(a.is_finite() && (0.0..=1.0).contains(&a)) {
                    return Err(SchemeError::AlphaOutOfRange(a));
                }
                (vec![0.0, 1.0], vec![a], vec![1.0])
            }
            SchemeId::Lobatto(s) => return check_stages(s).map(Self::lobatto_tables),
        };
        Ok(Self::from_coefficients(id, d, c, b))
    }

    /// The `s`-point Lobatto scheme, `s ≥ 2` checked by the caller (the error reference may
    /// have `MAX_STAGES + 1` points). Up to [`CACHED_STAGES`] points its tables are made
    /// once per process and shared (see [`LOBATTO_TABLES`]).
    fn lobatto_tables(s: usize) -> Self {
        let make = || {
            let (x, w) = coefficients::nodes_weights(s);
            Self::from_coefficients(SchemeId::Lobatto(s), x.clone(), x, w)
        };
        match LOBATTO_TABLES.get(s) {
            Some(cell) => Scheme {
                id: SchemeId::Lobatto(s),
                t: Arc::clone(cell.get_or_init(|| make().t)),
            },
            None => make(),
        }
    }

    /// The `s`-stage Lobatto Galerkin scheme (order `2s − 2`).
    pub fn lobatto(s: usize) -> Result<Self, SchemeError> {
        Self::new(SchemeId::Lobatto(s))
    }

    /// The fewest coordinates from which [`crate::Integrator::auto`] takes the sparse
    /// column of [`Scheme::for_tolerance`] (`lobatto4`) for a model on the sparse backend;
    /// below them, the dense column.
    ///
    /// Measured on 2026-11-30 (adaptive runs, medians of 3; `rtol = atol = tol` from 1e-4
    /// to 1e-12; the time of each rule's choice over the cheapest of lobatto4..8):
    /// - the hand-written FPU chain to T = 20 (`forced_vi_models::large::FpuChain`), smooth:
    ///   at n = 8 lobatto4 took 1.2–4.7 times the cheapest and the dense column 1.0–1.1;
    ///   at n = 16, 1.0–2.4 against 1.2–1.5; at n = 32, 1.0–1.5 against 1.3–1.7; from
    ///   n = 128 and 256 lobatto4 was the cheapest (within 1.01), the dense column 1.1–3.4;
    /// - an FPU chain of 8 masses written with the macro (`tests/held_out_models_third.rs`):
    ///   lobatto4 1.2–14.7 times the cheapest (120 ms against 8 ms at 1e-12), the dense
    ///   column 1.0–1.15;
    /// - the over-damped chain of `tests/extreme.rs` (c = 10⁵, T = 200; one run each, tol
    ///   1e-3 to 1e-7, and 1e-10 at n = 8 and 12): the dense column took 0.07–0.63 times
    ///   lobatto4's time at n = 8, 12 and 16, and 0.30–0.47 at n = 32.
    ///
    /// From 32 coordinates the two rules trade: lobatto4 is the cheaper on the smooth
    /// chain, the dense column on the stiff one, and at n = 32 lobatto4 stays, as measured
    /// when the rule was made on the large scenes.
    pub const AUTO_SPARSE_MIN_DOF: usize = 32;

    /// The Lobatto scheme an adaptive run at tolerance `tol` should use, by backend.
    ///
    /// | `tol` | dense column (small models) | sparse column (large models) |
    /// |---|---|---|
    /// | above `10⁻⁷` | `lobatto6` (order 10) | `lobatto4` (order 6) |
    /// | `10⁻⁷` and below | `lobatto8` (order 14) | `lobatto4` |
    ///
    /// On the dense backend a stage costs little next to a step, so a high order wins at
    /// every tolerance the report sweeps, and the number of stages is even. No Lobatto
    /// scheme damps a stiff mode that a step does not resolve (on `x'' = −λx'` at
    /// `λh = 10⁶` one step returns the velocity as `+v₀` for s = 3, 5, 7 and as `−v₀` for
    /// s = 2, 4, 6, 8), and on the van der Pol oscillator at μ = 10⁶ the odd ones fail
    /// where the even ones do not (`examples/auto_order`, from the automatic first step,
    /// capped at 2·10⁶ steps; measured at the commit that last changed these figures):
    /// adaptive lobatto5 took 1.8·10⁴ steps at tol 1e-5 and 8.0·10⁵ at 1e-6, and lobatto5
    /// and lobatto7 reached the cap at 1e-7 and 1e-9, while lobatto6 took 1.2·10³ to
    /// 6.0·10³ steps from 1e-3 to 1e-7 and lobatto8 1.3·10⁵ at 1e-9 (lobatto6 reached the
    /// cap there), every run that finished within 1e-11 of the reference; on a slowly
    /// driven over-damped oscillator (λ = 10⁶, held out) lobatto6 took 521 and 1195 steps
    /// at 1e-3 and 1e-5, lobatto5 4638 and 17191. The parity is not the whole story: on the
    /// same van der Pol, lobatto9 and lobatto10 finish at tol 1e-3, but at 1e-6 and 1e-7
    /// they stop with a step too small or reach the cap of 2·10⁶ steps, three of the four
    /// runs at its first relaxation jump (measured when the rule was chosen). On the
    /// non-stiff models of that example this rule took 0.92–1.27 times the cheapest fixed
    /// choice (median 1.00 and 1.02, two runs, timed in rotated rounds; the same
    /// computation timed twice in those rounds differed by up to 1.25×). When the rule was
    /// chosen, the cheapest stage count per tolerance (lobatto5 above 10⁻⁶, lobatto7 at
    /// 10⁻⁹ and below, the rule before) took 0.99–1.06 and the rule 1.00–1.16, timed apart.
    ///
    /// The switch to lobatto8 was at 10⁻⁹ until a held-out model of two masses on a spring of
    /// 10⁴ (`examples/tolerance_sweep`, fourth set) showed lobatto7 and lobatto8 at half of
    /// lobatto6's time at tol 1e-4 and 1e-7: they resolve its fast, lightly damped mode in
    /// fewer steps. lobatto8's time over lobatto6's on the 37 models of that example (38 runs,
    /// medians of 5 alternating runs each): at tol 1e-5 median 1.11 (0.50–1.62), at 1e-6 1.07 (0.47–1.46),
    /// at 1e-7 0.99 (0.54–1.46), at 1e-8 0.96 (0.53–1.48); at 1e-4 on the report's models
    /// 1.3–1.6. On the stiff models it takes fewer steps at every tolerance (the van der Pol
    /// at μ = 10⁶: 3522 against 5966 at 1e-7; the over-damped oscillator 30285 against
    /// 93002). So the switch is at 10⁻⁷, where it costs nothing on the median. With it,
    /// `examples/auto_order` read 0.83–1.13 on its six non-stiff models (median 1.02), and
    /// `examples/tolerance_sweep` 0.86–1.80 over its 114 model-tolerance pairs (median
    /// 1.03, against 0.91–1.93 and 1.06 with the switch at 10⁻⁹ in the same session; the
    /// same computation timed twice there differed by up to 1.46×), with 6 of its 228 slopes
    /// outside 0.8–1.2 instead of 8.
    ///
    /// On the sparse backend the LU's fill grows with the stages: `lobatto4` at every
    /// tolerance. lobatto3 is cheaper on the report's large non-stiff scenes at tol 1e-4
    /// (lobatto4 takes 1.6 and 1.9 times its time on the FPU chain and the 2-D lattice at
    /// n = 1024 in the committed report), but on a stiff one it takes tens of times more
    /// steps: on an over-damped chain of 32 masses (`examples/auto_order`) lobatto3 took
    /// 3.1·10⁴ and 2.0·10⁵ steps at tol 1e-3 and 1e-5, 22–24 and 44–53 times lobatto4's
    /// time (809 and 2901 steps; two runs).
    ///
    /// That holds where the LU is most of a step. On the smaller models of the sparse
    /// backend the node evaluations are, and the dense column is the cheaper one, stiff or
    /// not: [`crate::Integrator::auto`] takes the sparse column only from
    /// [`Scheme::AUTO_SPARSE_MIN_DOF`] coordinates.
    ///
    /// The sparse column does not hold on every model at tight tolerances. On a damped
    /// sine-Gordon chain of 256 coordinates (the step-cost report's first-answer model;
    /// adaptive runs to T = 10, one timing each), lobatto5 and lobatto6 took 13.7 and
    /// 13.5 ms at tol 1e-9 against lobatto4's 22.0 ms, and 19.5 and 17.0 ms at 1e-11
    /// against 40.8 ms, to about the same error: their steps were 2.6–6.3 times fewer. On
    /// the FPU chain of 1024 masses (T = 400) and the 32 × 32 membrane (T = 10) lobatto4
    /// stayed the cheapest from 1e-5 to 1e-11, or within 1 % of it (lobatto5 and lobatto6
    /// took up to 1.45 and 1.63 times its time on the chain, 1.66 and 2.34 on the
    /// membrane); on the FPU chain lobatto6's steps were only 1.2–2.0 times fewer than
    /// lobatto4's. Both chains have the same pattern, so the rule cannot tell them apart
    /// before a run; where a model is known to behave like the first, choose the scheme.
    ///
    /// A tolerance that is not finite or not positive gets `lobatto6` (`lobatto4` on the
    /// sparse backend). [`crate::Integrator::auto`] applies it.
    pub fn for_tolerance(tol: f64, sparse: bool) -> Self {
        let s = match (sparse, tol) {
            (true, _) => 4,
            (false, t) if t.is_nan() || t > 1e-7 => 6,
            (false, _) => 8,
        };
        Self::new(SchemeId::Lobatto(s)).unwrap_or_else(|_| Self::midpoint())
    }

    /// The midpoint rule.
    pub fn midpoint() -> Self {
        Self::from_coefficients(SchemeId::Midpoint, vec![0.0, 1.0], vec![0.5], vec![1.0])
    }

    fn from_coefficients(id: SchemeId, d: Vec<f64>, c: Vec<f64>, b: Vec<f64>) -> Self {
        let s = d.len();
        let mut phi = vec![0.0; c.len() * s];
        let mut psi = vec![0.0; c.len() * s];
        for (i, &ci) in c.iter().enumerate() {
            for j in 0..s {
                phi[i * s + j] = lagrange(&d, j, ci);
                psi[i * s + j] = lagrange_derivative(&d, j, ci);
            }
        }
        let mut terms = Vec::new();
        for (i, &bi) in b.iter().enumerate() {
            for j in 0..s - 1 {
                for m in 1..s {
                    let (phj, psj) = (phi[i * s + j], psi[i * s + j]);
                    let (phm, psm) = (phi[i * s + m], psi[i * s + m]);
                    let t = JacobianTerm {
                        i,
                        j,
                        m,
                        a: bi * phj * phm,
                        b: bi * phj * psm,
                        c: bi * psj * phm,
                        e: bi * psj * psm,
                    };
                    if t.a != 0.0 || t.b != 0.0 || t.c != 0.0 || t.e != 0.0 {
                        terms.push(t);
                    }
                }
            }
        }
        // Block `(j, m)` at `(m − 1)(s − 1) + j`, its terms in the order of `terms`: one pass
        // over them (a pass per block made the tables `O(s⁵)`: 16.7 ms at s = 32).
        let mut block_sums: Vec<BlockSum> = (1..s)
            .flat_map(|m| (0..s - 1).map(move |j| (j, m)))
            .map(|(j, m)| BlockSum {
                j,
                m,
                ..BlockSum::default()
            })
            .collect();
        for t in &terms {
            let Some(sum) = block_sums.get_mut((t.m - 1) * (s - 1) + t.j) else {
                continue;
            };
            for (list, w) in [
                (&mut sum.a, t.a),
                (&mut sum.b, t.b),
                (&mut sum.c, t.c),
                (&mut sum.e, t.e),
            ] {
                if w != 0.0 {
                    list.push((t.i, w));
                }
            }
        }
        let (pred_points, extrapolation) = predictor_points(&d);
        let pred_d: Vec<f64> = pred_points.iter().map(|&m| d[m]).collect();
        let pred_weights = barycentric_weights(&pred_d);
        let end_slope = (0..s).map(|m| lagrange_derivative(&d, m, 1.0)).collect();
        let weights = barycentric_weights(&d);
        let r = c.len();
        let res_phi: Vec<f64> = (0..s * r)
            .map(|k| b[k % r] * phi[(k % r) * s + k / r])
            .collect();
        let res_psi: Vec<f64> = (0..s * r)
            .map(|k| b[k % r] * psi[(k % r) * s + k / r])
            .collect();
        Scheme {
            id,
            t: Arc::new(Tables {
                d,
                c,
                b,
                phi,
                psi,
                a_terms: terms.iter().copied().filter(|t| t.a != 0.0).collect(),
                b_terms: terms.iter().copied().filter(|t| t.b != 0.0).collect(),
                block_sums,
                res_phi,
                res_psi,
                terms,
                extrapolation,
                end_slope,
                weights,
                extrapolates: !pred_points.is_empty(),
                pred_points,
                pred_weights,
                estimate: OnceLock::new(),
                pair_estimate: OnceLock::new(),
            }),
        }
    }

    /// The scheme's id.
    pub fn id(&self) -> SchemeId {
        self.id
    }
    /// Number of control points `s` (including both ends of the step).
    pub fn stages(&self) -> usize {
        self.t.d.len()
    }
    /// Number of quadrature nodes `r`.
    pub fn quadrature_nodes(&self) -> usize {
        self.t.c.len()
    }
    /// Control-point positions `d` on `[0, 1]`.
    pub fn d(&self) -> &[f64] {
        &self.t.d
    }
    /// Quadrature nodes `c` on `[0, 1]`.
    pub fn c(&self) -> &[f64] {
        &self.t.c
    }
    /// Quadrature weights `b`.
    pub fn b(&self) -> &[f64] {
        &self.t.b
    }
    /// `Φ_ij = ℓ_j(c_i)`, for `i` below [`Self::quadrature_nodes`] and `j` below
    /// [`Self::stages`]; `None` outside.
    pub fn phi(&self, i: usize, j: usize) -> Option<f64> {
        let len = self.t.d.len();
        let k = i.checked_mul(len)?.checked_add(j).filter(|_| j < len)?;
        self.t.phi.get(k).copied()
    }
    /// `Ψ_ij = ℓ_j'(c_i)`, for `i` below [`Self::quadrature_nodes`] and `j` below
    /// [`Self::stages`]; `None` outside.
    pub fn psi(&self, i: usize, j: usize) -> Option<f64> {
        let len = self.t.d.len();
        let k = i.checked_mul(len)?.checked_add(j).filter(|_| j < len)?;
        self.t.psi.get(k).copied()
    }
    /// [`Self::phi`] at indices the caller keeps in range.
    #[inline]
    pub(crate) fn phi_at(&self, i: usize, j: usize) -> f64 {
        self.t.phi[i * self.t.d.len() + j]
    }
    /// [`Self::psi`] at indices the caller keeps in range.
    #[inline]
    pub(crate) fn psi_at(&self, i: usize, j: usize) -> f64 {
        self.t.psi[i * self.t.d.len() + j]
    }
    /// `(Φ_i·, Ψ_i·)`: row `i` of each, `s` entries.
    #[inline]
    pub(crate) fn basis_rows(&self, i: usize) -> (&[f64], &[f64]) {
        let s = self.t.d.len();
        (
            &self.t.phi[i * s..(i + 1) * s],
            &self.t.psi[i * s..(i + 1) * s],
        )
    }
    /// `(b_i Φ_ij, b_i Ψ_ij)` for `i = 0 … r − 1`: the weights of node `i`'s `L_q + F` (times
    /// `h`) and `L_v` in residual row `j`.
    #[inline]
    pub(crate) fn residual_weights(&self, j: usize) -> (&[f64], &[f64]) {
        let r = self.t.c.len();
        (
            &self.t.res_phi[j * r..(j + 1) * r],
            &self.t.res_psi[j * r..(j + 1) * r],
        )
    }
    /// The non-zero terms of the Jacobian chain rule.
    pub fn jacobian_terms(&self) -> &[JacobianTerm] {
        &self.t.terms
    }

    /// The terms gathered by Jacobian block, every block `(j, m)` once, column by column.
    pub(crate) fn block_sums(&self) -> &[BlockSum] {
        &self.t.block_sums
    }

    /// The terms with a non-zero coefficient on `A`, and those with one on `B`.
    pub(crate) fn force_jacobian_terms(&self) -> (&[JacobianTerm], &[JacobianTerm]) {
        (&self.t.a_terms, &self.t.b_terms)
    }

    /// The classical order of the scheme.
    pub fn order(&self) -> usize {
        match self.id {
            SchemeId::Midpoint | SchemeId::Trapezoid => 2,
            SchemeId::Alpha(0.5) => 2,
            SchemeId::Alpha(_) => 1,
            SchemeId::Lobatto(s) => 2 * s - 2,
        }
    }

    /// The scheme that estimates the local error of adaptive steps ([`crate::control`]):
    /// the Lobatto scheme with `p / 2 + 2` control points, of order at least `p + 2` for a
    /// scheme of order `p`. It may have one point more than [`MAX_STAGES`].
    pub(crate) fn error_reference(&self) -> Scheme {
        self.estimate_tables().reference.clone()
    }

    /// The error estimate's tables ([`EstimateTables`]), made on the first call.
    pub(crate) fn estimate_tables(&self) -> &EstimateTables {
        self.t
            .estimate
            .get_or_init(|| self.make_estimate_tables(self.order() / 2 + 2))
    }

    /// The scheme that estimates the local error of pairs of adaptive steps
    /// ([`crate::control`], "Pairs"): as [`Scheme::error_reference`], but lobatto5 for
    /// lobatto3, whose pair would share lobatto4's end weight.
    pub(crate) fn pair_error_reference(&self) -> Scheme {
        self.pair_estimate_tables().reference.clone()
    }

    /// The tables of [`Scheme::pair_error_reference`], made on the first call.
    pub(crate) fn pair_estimate_tables(&self) -> &EstimateTables {
        self.t.pair_estimate.get_or_init(|| {
            let extra = usize::from(self.id() == SchemeId::Lobatto(3));
            self.make_estimate_tables(self.order() / 2 + 2 + extra)
        })
    }

    /// The error estimate's tables against the Lobatto scheme of `points` control points.
    fn make_estimate_tables(&self, points: usize) -> EstimateTables {
        {
            let reference = Self::lobatto_tables(points);
            let (d, c) = (reference.d(), reference.c());
            let s1 = self.stages() - 1;
            let lift = d[1..]
                .iter()
                .flat_map(|&dj| (1..=s1).map(move |m| (dj, m)))
                .map(|(dj, m)| lagrange(&self.t.d, m, dj))
                .collect();
            let block_weights = if self.c() == self.d() {
                c.iter()
                    .flat_map(|&cj| (0..=s1).map(move |m| (cj, m)))
                    .map(|(cj, m)| lagrange(&self.t.d, m, cj))
                    .collect()
            } else {
                Vec::new()
            };
            let lift_lambda = d[..d.len() - 1]
                .iter()
                .flat_map(|&dj| (0..=s1).map(move |m| (dj, m)))
                .map(|(dj, m)| lagrange(&self.t.d, m, dj))
                .collect();
            let pair_at = |dj: f64| {
                let tau = 2.0 * dj;
                if tau > 1.0 { tau - 1.0 } else { tau }
            };
            let pair_lift = d[1..]
                .iter()
                .flat_map(|&dj| (1..=s1).map(move |m| (dj, m)))
                .map(|(dj, m)| lagrange(&self.t.d, m, pair_at(dj)))
                .collect();
            let pair_second = d[1..].iter().map(|&dj| 2.0 * dj > 1.0).collect();
            EstimateTables {
                reference,
                lift,
                block_weights,
                lift_lambda,
                pair_lift,
                pair_second,
            }
        }
    }
    /// `ℓ_m(1 + d_j)` for every `m`: extrapolation to the next step's control point `j`
    /// (empty for a `j` beyond the control points).
    #[inline]
    pub(crate) fn extrapolation_row(&self, j: usize) -> &[f64] {
        let len = self.t.d.len();
        self.t
            .extrapolation
            .get(j * len..(j + 1) * len)
            .unwrap_or(&[])
    }

    /// Whether the predictor extrapolates the previous step's polynomial (see
    /// [`MAX_PREDICTOR_LEBESGUE`]).
    #[inline]
    pub(crate) fn extrapolates(&self) -> bool {
        self.t.extrapolates
    }

    /// The degree of the polynomial the predictor extrapolates from the last step to the
    /// next: `s − 1` up to s = 9, and 8 above, where it goes through nine of the control
    /// points (the whole polynomial's extrapolation would multiply the last step's round-off
    /// by more than 10⁶).
    pub fn predictor_degree(&self) -> usize {
        self.t.pred_points.len().saturating_sub(1)
    }

    /// The predictor's Lagrange basis at `tau` (in units of the step), on the control
    /// points: `out[m] = ℓ_m(τ)` for the predictor's points, zero at the others. The basis of
    /// all the control points ([`Scheme::basis_at`]) where the predictor goes through them
    /// all.
    pub(crate) fn predictor_basis_at(&self, tau: f64, out: &mut [f64]) {
        let t = &*self.t;
        if t.pred_points.len() == t.d.len() {
            return self.basis_at(tau, out);
        }
        out.fill(0.0);
        let mut before = 1.0;
        for &m in &t.pred_points {
            if let Some(o) = out.get_mut(m) {
                *o = before;
            }
            before *= tau - t.d[m];
        }
        let mut after = 1.0;
        for (&m, &wk) in t.pred_points.iter().zip(&t.pred_weights).rev() {
            if let Some(o) = out.get_mut(m) {
                *o *= after * wk;
            }
            after *= tau - t.d[m];
        }
    }

    /// `ℓ_m'(1)`.
    #[inline]
    pub(crate) fn end_slope(&self, m: usize) -> f64 {
        self.t.end_slope[m]
    }

    /// The Lagrange basis on the control points at `tau` (in units of the step):
    /// `out[m] = ℓ_m(τ)` for `m = 0 … s − 1`. By the barycentric weights and the products of
    /// `τ − d_k` before and after `m`: `O(s)` products and no division, against `O(s²)`
    /// quotients for the basis one function at a time.
    pub(crate) fn basis_at(&self, tau: f64, out: &mut [f64]) {
        let (d, w) = (&self.t.d, &self.t.weights);
        // `out[m]` first holds the product over `k < m`, then takes the one over `k > m`.
        let mut before = 1.0;
        for (o, &dk) in out.iter_mut().zip(d) {
            *o = before;
            before *= tau - dk;
        }
        let mut after = 1.0;
        for ((o, &dk), &wk) in out.iter_mut().zip(d).zip(w).rev() {
            *o *= after * wk;
            after *= tau - dk;
        }
    }
}
