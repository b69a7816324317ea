//! Discretisations as data: every scheme is a coefficient set `(d, c, b)` (DESIGN §3).
//!
//! The path over one step is the polynomial through control points at the nodes `d`
//! (`d₀ = 0`, `d_{s−1} = 1`); the action is approximated by the quadrature `(c, b)` on
//! `[0, 1]`. All schemes share one residual and Jacobian assembly in [`crate::integrator`].

use std::fmt;
use std::str::FromStr;

use crate::error::SchemeError;

/// The name of a scheme, as used on the command line and in reports.
///
/// Ids: `midpoint`, `trapezoid`, `alpha(<value>)`, `lobatto<s>` for `s ≥ 2`.
///
/// ```
/// use forced_vi::SchemeId;
/// let id: SchemeId = "alpha(0.25)".parse().unwrap();
/// assert_eq!(id, SchemeId::Alpha(0.25));
/// assert_eq!("lobatto3".parse::<SchemeId>().unwrap().to_string(), "lobatto3");
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SchemeId {
    /// `L_d = h L((q₀ + q₁)/2, (q₁ − q₀)/h)`: order 2.
    Midpoint,
    /// Linear path, trapezoidal quadrature: order 2.
    Trapezoid,
    /// `L_d = h L((1 − α)q₀ + αq₁, (q₁ − q₀)/h)`: order 2 at `α = ½`, else 1.
    Alpha(f64),
    /// Galerkin with `s` Lobatto control points and Lobatto quadrature: order `2s − 2`.
    Lobatto(usize),
}

impl fmt::Display for SchemeId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SchemeId::Midpoint => write!(f, "midpoint"),
            SchemeId::Trapezoid => write!(f, "trapezoid"),
            SchemeId::Alpha(a) => write!(f, "alpha({a})"),
            SchemeId::Lobatto(s) => write!(f, "lobatto{s}"),
        }
    }
}

impl FromStr for SchemeId {
    type Err = SchemeError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let t = text.trim();
        let unknown = || SchemeError::Unknown(t.to_string());
        match t {
            "midpoint" => return Ok(SchemeId::Midpoint),
            "trapezoid" => return Ok(SchemeId::Trapezoid),
            _ => {}
        }
        if let Some(rest) = t.strip_prefix("lobatto") {
            // Plain decimal digits only: no sign, no leading zero, no whitespace.
            if rest.is_empty() || !rest.bytes().all(|b| b.is_ascii_digit()) || rest.starts_with('0')
            {
                return Err(unknown());
            }
            let s: usize = rest.parse().unwrap_or(usize::MAX);
            return check_stages(s).map(SchemeId::Lobatto);
        }
        if let Some(inner) = t.strip_prefix("alpha(").and_then(|r| r.strip_suffix(')')) {
            let a: f64 = inner.trim().parse().map_err(|_| unknown())?;
            return if a.is_finite() && (0.0..=1.0).contains(&a) {
                Ok(SchemeId::Alpha(a))
            } else {
                Err(SchemeError::AlphaOutOfRange(a))
            };
        }
        Err(unknown())
    }
}

/// The most control points a Lobatto scheme may have (order `2 · 32 − 2 = 62`).
///
/// Measured (`scheme::accuracy` tests against the 60-digit values of
/// `scripts/lobatto_limits.py`): the nodes and weights stay within 1.1e-16 and 1.7e-14
/// (relative) of exact up to s = 48, and within 7.6e-15 up to 32; a damped oscillator run
/// with s = 32 is accurate to round-off. The bound keeps the step system, `(s − 1)·n`
/// unknowns with an `O((s n)³)` factorisation, and the set-up cost of a scheme small; no
/// `f64` computation gains from more than about 10 stages.
pub const MAX_STAGES: usize = 32;

/// Largest Lebesgue constant `max_j Σ_m |ℓ_m(1 + d_j)|` for which the predictor
/// extrapolates the previous step's polynomial. It grows like 5.8^s (589 at s = 5, 6.9e5 at
/// s = 9, 4.4e32 at s = 44; `forced-vi/data/lobatto_predictor.csv`); it multiplies the round-off of the
/// previous step, so beyond this the predictor is a straight line along the velocity.
const MAX_PREDICTOR_LEBESGUE: f64 = 1e6;

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
#[derive(Clone, Debug)]
pub struct Scheme {
    id: SchemeId,
    d: Vec<f64>,
    c: Vec<f64>,
    b: Vec<f64>,
    /// `Φ_ij = ℓ_j(c_i)`, row-major `r × s`.
    phi: Vec<f64>,
    /// `Ψ_ij = ℓ_j'(c_i)`, row-major `r × s`.
    psi: Vec<f64>,
    /// The non-zero terms of the Jacobian chain rule, see [`JacobianTerm`].
    terms: Vec<JacobianTerm>,
    /// `ℓ_m(1 + d_j)`, row-major `s × s`: the previous step's polynomial extrapolated to
    /// this step's control points (the predictor for equal steps).
    extrapolation: Vec<f64>,
    /// `ℓ_m'(1)`: the polynomial's slope at the end of the step.
    end_slope: Vec<f64>,
    /// Whether the predictor may extrapolate (see [`MAX_PREDICTOR_LEBESGUE`]).
    extrapolates: bool,
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
            SchemeId::Lobatto(s) => {
                check_stages(s)?;
                let (x, w) = lobatto_nodes_weights(s);
                (x.clone(), x, w)
            }
        };
        Ok(Self::from_coefficients(id, d, c, b))
    }

    /// The `s`-stage Lobatto Galerkin scheme (order `2s − 2`).
    pub fn lobatto(s: usize) -> Result<Self, SchemeError> {
        Self::new(SchemeId::Lobatto(s))
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
        let extrapolation: Vec<f64> = (0..s * s)
            .map(|k| lagrange(&d, k % s, 1.0 + d[k / s]))
            .collect();
        let lebesgue = extrapolation
            .chunks(s)
            .map(|row| row.iter().map(|x| x.abs()).sum::<f64>())
            .fold(0.0, f64::max);
        let end_slope = (0..s).map(|m| lagrange_derivative(&d, m, 1.0)).collect();
        Scheme {
            id,
            d,
            c,
            b,
            phi,
            psi,
            terms,
            extrapolation,
            end_slope,
            extrapolates: lebesgue <= MAX_PREDICTOR_LEBESGUE,
        }
    }

    /// The scheme's id.
    pub fn id(&self) -> SchemeId {
        self.id
    }
    /// Number of control points `s` (including both ends of the step).
    pub fn stages(&self) -> usize {
        self.d.len()
    }
    /// Number of quadrature nodes `r`.
    pub fn quadrature_nodes(&self) -> usize {
        self.c.len()
    }
    /// Control-point positions `d` on `[0, 1]`.
    pub fn d(&self) -> &[f64] {
        &self.d
    }
    /// Quadrature nodes `c` on `[0, 1]`.
    pub fn c(&self) -> &[f64] {
        &self.c
    }
    /// Quadrature weights `b`.
    pub fn b(&self) -> &[f64] {
        &self.b
    }
    /// `Φ_ij = ℓ_j(c_i)`.
    #[inline]
    pub fn phi(&self, i: usize, j: usize) -> f64 {
        self.phi[i * self.d.len() + j]
    }
    /// `Ψ_ij = ℓ_j'(c_i)`.
    #[inline]
    pub fn psi(&self, i: usize, j: usize) -> f64 {
        self.psi[i * self.d.len() + j]
    }
    /// The non-zero terms of the Jacobian chain rule.
    pub fn jacobian_terms(&self) -> &[JacobianTerm] {
        &self.terms
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

    /// `ℓ_m(1 + d_j)`: extrapolation to the next step's control points.
    #[inline]
    pub(crate) fn extrapolation(&self, j: usize, m: usize) -> f64 {
        self.extrapolation[j * self.d.len() + m]
    }

    /// Whether the predictor extrapolates the previous step's polynomial (false for
    /// Lobatto schemes with more than 9 stages, whose extrapolation amplifies round-off).
    #[inline]
    pub(crate) fn extrapolates(&self) -> bool {
        self.extrapolates
    }

    /// `ℓ_m'(1)`.
    #[inline]
    pub(crate) fn end_slope(&self, m: usize) -> f64 {
        self.end_slope[m]
    }

    /// Evaluates the Lagrange basis on the control points at `tau` (in units of the step).
    pub(crate) fn basis_at(&self, tau: f64, j: usize) -> f64 {
        lagrange(&self.d, j, tau)
    }
}

/// `ℓ_j(x)` on the nodes `d`.
fn lagrange(d: &[f64], j: usize, x: f64) -> f64 {
    if x == d[j] {
        return 1.0;
    }
    d.iter()
        .enumerate()
        .filter(|&(m, _)| m != j)
        .map(|(_, &dm)| (x - dm) / (d[j] - dm))
        .product()
}

/// `ℓ_j'(x)` on the nodes `d`, by the product rule (valid at the nodes too).
fn lagrange_derivative(d: &[f64], j: usize, x: f64) -> f64 {
    let mut sum = 0.0;
    for k in 0..d.len() {
        if k == j {
            continue;
        }
        let mut term = 1.0 / (d[j] - d[k]);
        for m in 0..d.len() {
            if m != j && m != k {
                term *= (x - d[m]) / (d[j] - d[m]);
            }
        }
        sum += term;
    }
    sum
}

/// Legendre `P_n(x)` and `P_n'(x)` by the three-term recurrence.
fn legendre(n: usize, x: f64) -> (f64, f64) {
    let (mut p0, mut p1) = (1.0, x);
    if n == 0 {
        return (1.0, 0.0);
    }
    for k in 2..=n {
        let kf = k as f64;
        let p2 = ((2.0 * kf - 1.0) * x * p1 - (kf - 1.0) * p0) / kf;
        p0 = p1;
        p1 = p2;
    }
    // P_n' from P_n and P_{n−1}; x = ±1 handled separately.
    let nf = n as f64;
    let dp = if (1.0 - x * x).abs() < 1e-300 {
        x.powi(n as i32 + 1) * nf * (nf + 1.0) / 2.0
    } else {
        nf * (p0 - x * p1) / (1.0 - x * x)
    };
    (p1, dp)
}

/// Gauss–Lobatto nodes and weights with `s` points, mapped to `[0, 1]`.
///
/// The interior nodes are the roots of `P'_{s−1}`, found by Newton's method from the
/// Chebyshev–Lobatto points; the weights are `2 / (n(n+1) P_n(x)²)` on `[−1, 1]`.
/// Results are made exactly symmetric about ½.
///
/// For `s < 2` the two-point rule is returned.
pub fn lobatto_nodes_weights(s: usize) -> (Vec<f64>, Vec<f64>) {
    let s = s.max(2);
    let n = s - 1;
    let nf = n as f64;
    let mut x = vec![0.0; s];
    for (k, xk) in x.iter_mut().enumerate() {
        // Descending on [−1, 1]: x_0 = 1, x_n = −1.
        *xk = (std::f64::consts::PI * k as f64 / nf).cos();
    }
    for xk in x.iter_mut().take(n).skip(1) {
        for _ in 0..100 {
            let (p, dp) = legendre(n, *xk);
            // (1 − x²) P'' = 2x P' − n(n+1) P
            let d2p = (2.0 * *xk * dp - nf * (nf + 1.0) * p) / (1.0 - *xk * *xk);
            let step = dp / d2p;
            *xk -= step;
            if step.abs() <= 1e-16 {
                break;
            }
        }
    }
    let mut nodes = vec![0.0; s];
    let mut weights = vec![0.0; s];
    for k in 0..s {
        let xk = -x[k]; // ascending
        let (p, _) = legendre(n, xk);
        nodes[k] = 0.5 * (1.0 + xk);
        weights[k] = 1.0 / (nf * (nf + 1.0) * p * p);
    }
    nodes[0] = 0.0;
    nodes[n] = 1.0;
    for k in 0..s / 2 {
        let a = 0.5 * (nodes[k] + (1.0 - nodes[n - k]));
        nodes[k] = a;
        nodes[n - k] = 1.0 - a;
        let w = 0.5 * (weights[k] + weights[n - k]);
        weights[k] = w;
        weights[n - k] = w;
    }
    if s % 2 == 1 {
        nodes[n / 2] = 0.5;
    }
    (nodes, weights)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &[f64], b: &[f64], tol: f64) {
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() <= tol, "{a:?} vs {b:?}");
        }
    }

    #[test]
    fn lobatto_known_values() {
        let (x, w) = lobatto_nodes_weights(2);
        close(&x, &[0.0, 1.0], 0.0);
        close(&w, &[0.5, 0.5], 1e-16);
        let (x, w) = lobatto_nodes_weights(3);
        close(&x, &[0.0, 0.5, 1.0], 0.0);
        close(&w, &[1.0 / 6.0, 2.0 / 3.0, 1.0 / 6.0], 2e-16);
        let r5 = 1.0 / 5f64.sqrt();
        let (x, w) = lobatto_nodes_weights(4);
        close(&x, &[0.0, 0.5 * (1.0 - r5), 0.5 * (1.0 + r5), 1.0], 2e-16);
        close(&w, &[1.0 / 12.0, 5.0 / 12.0, 5.0 / 12.0, 1.0 / 12.0], 2e-16);
        let r37 = (3.0f64 / 7.0).sqrt();
        let (x, w) = lobatto_nodes_weights(5);
        close(
            &x,
            &[0.0, 0.5 * (1.0 - r37), 0.5, 0.5 * (1.0 + r37), 1.0],
            2e-16,
        );
        close(
            &w,
            &[
                1.0 / 20.0,
                49.0 / 180.0,
                16.0 / 45.0,
                49.0 / 180.0,
                1.0 / 20.0,
            ],
            2e-16,
        );
    }

    #[test]
    fn lobatto_quadrature_is_exact_to_degree_2s_minus_3() {
        for s in 2..=9 {
            let (x, w) = lobatto_nodes_weights(s);
            for deg in 0..=(2 * s - 3) {
                let q: f64 = x.iter().zip(&w).map(|(x, w)| w * x.powi(deg as i32)).sum();
                let exact = 1.0 / (deg as f64 + 1.0);
                assert!((q - exact).abs() < 4e-15, "s={s} deg={deg}: {q} vs {exact}");
            }
        }
    }

    #[test]
    fn basis_derivative_rows_sum_to_zero() {
        for s in 2..=6 {
            let sch = Scheme::lobatto(s).unwrap();
            for i in 0..sch.quadrature_nodes() {
                let sp: f64 = (0..s).map(|j| sch.psi(i, j)).sum();
                let sf: f64 = (0..s).map(|j| sch.phi(i, j)).sum();
                assert!(sp.abs() < 1e-12 && (sf - 1.0).abs() < 1e-14);
            }
        }
    }

    #[test]
    fn ids_round_trip() {
        for t in [
            "midpoint",
            "trapezoid",
            "alpha(0.3)",
            "lobatto2",
            "lobatto5",
            "lobatto7",
        ] {
            let id: SchemeId = t.parse().unwrap();
            assert_eq!(id.to_string(), t);
            Scheme::new(id).unwrap();
        }
        assert!("lobatto1".parse::<SchemeId>().is_err());
        for bad in [
            "lobatto+3",
            "lobatto007",
            "lobatto 3",
            "lobatto",
            "lobatto-2",
            "lobatto3.0",
        ] {
            assert_eq!(
                bad.parse::<SchemeId>(),
                Err(SchemeError::Unknown(bad.to_string())),
                "{bad}"
            );
        }
        for big in [
            "lobatto33",
            "lobatto18446744073709551615",
            "lobatto99999999999999999999999",
        ] {
            assert!(matches!(
                big.parse::<SchemeId>(),
                Err(SchemeError::TooManyStages {
                    max: MAX_STAGES,
                    ..
                })
            ));
        }
        assert!(Scheme::lobatto(usize::MAX).is_err());
        assert!(Scheme::lobatto(1 << 40).is_err());
        assert!(Scheme::lobatto(MAX_STAGES).is_ok());
        assert!("alpha(1.5)".parse::<SchemeId>().is_err());
        assert!("rk4".parse::<SchemeId>().is_err());
    }
}

#[cfg(test)]
mod accuracy {
    use super::*;

    /// Max error of the f64 nodes and weights against the 60-digit values of
    /// `scripts/lobatto_limits.py`, per stage count.
    pub(super) fn errors() -> Vec<(usize, f64, f64)> {
        let text = include_str!("../data/lobatto_exact.csv");
        let mut out: Vec<(usize, f64, f64)> = Vec::new();
        for line in text.lines().skip(1) {
            let f: Vec<&str> = line.split(',').collect();
            let (s, k): (usize, usize) = (f[0].parse().unwrap(), f[1].parse().unwrap());
            let (x, w): (f64, f64) = (f[2].parse().unwrap(), f[3].parse().unwrap());
            let (xs, ws) = lobatto_nodes_weights(s);
            let ex = (xs[k] - x).abs();
            let ew = (ws[k] - w).abs() / w;
            match out.last_mut() {
                Some(last) if last.0 == s => {
                    last.1 = last.1.max(ex);
                    last.2 = last.2.max(ew);
                }
                _ => out.push((s, ex, ew)),
            }
        }
        out
    }

    #[test]
    fn nodes_and_weights_are_accurate_up_to_the_cap() {
        for (s, ex, ew) in errors() {
            if s <= MAX_STAGES {
                assert!(
                    ex <= 2.3e-16 && ew <= 1e-14,
                    "s = {s}: nodes {ex:e}, weights {ew:e}"
                );
            }
        }
    }

    #[test]
    fn predictor_extrapolates_only_while_its_lebesgue_constant_is_small() {
        for s in 2..=MAX_STAGES {
            let sch = Scheme::lobatto(s).unwrap();
            assert_eq!(sch.extrapolates(), s <= 9, "s = {s}");
        }
    }

    #[test]
    #[ignore]
    fn print_node_errors() {
        for (s, ex, ew) in errors() {
            println!("{s} {ex:.2e} {ew:.2e}");
        }
    }
}
