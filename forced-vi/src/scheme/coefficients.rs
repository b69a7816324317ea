//! The coefficients behind a scheme: the Lagrange basis on the control points, and
//! Gauss–Lobatto nodes and weights to full `f64` precision for any supported number of
//! points.

use crate::error::SchemeError;

/// `ℓ_j(x)` on the nodes `d`.
pub(super) fn lagrange(d: &[f64], j: usize, x: f64) -> f64 {
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
pub(super) fn lagrange_derivative(d: &[f64], j: usize, x: f64) -> f64 {
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
/// `s` runs from 2 to `MAX_STAGES + 1` (the points of the error reference of
/// `lobatto(MAX_STAGES)`); other counts are a [`SchemeError`] (the work grows like `s²`, and
/// a count from user input should not decide it unchecked).
pub fn lobatto_nodes_weights(s: usize) -> Result<(Vec<f64>, Vec<f64>), SchemeError> {
    if s < 2 {
        return Err(SchemeError::TooFewStages(s));
    }
    if s > super::MAX_STAGES + 1 {
        return Err(SchemeError::TooManyStages {
            requested: s,
            max: super::MAX_STAGES + 1,
        });
    }
    Ok(nodes_weights(s))
}

/// [`lobatto_nodes_weights`] for an `s` the caller has checked (`s ≥ 2`).
pub(super) fn nodes_weights(s: usize) -> (Vec<f64>, Vec<f64>) {
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
