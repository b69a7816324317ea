//! The accuracy of the Lobatto nodes and weights against 60-digit values, up to the cap.

use super::*;

/// Max error of the f64 nodes and weights against the 60-digit values of
/// `scripts/lobatto_limits.py`, per stage count.
pub(super) fn errors() -> Vec<(usize, f64, f64)> {
    let text = include_str!("../../data/lobatto_exact.csv");
    let mut out: Vec<(usize, f64, f64)> = Vec::new();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let (s, k): (usize, usize) = (f[0].parse().unwrap(), f[1].parse().unwrap());
        let (x, w): (f64, f64) = (f[2].parse().unwrap(), f[3].parse().unwrap());
        let (xs, ws) = coefficients::nodes_weights(s);
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
fn predictor_extrapolates_within_its_lebesgue_bound_at_every_stage_count() {
    for s in 2..=MAX_STAGES {
        let sch = Scheme::lobatto(s).unwrap();
        assert!(sch.extrapolates(), "s = {s}");
        // All the control points up to s = 9 (constant 6.9e5), then a subset: nine points.
        let degree = if s <= 9 { s - 1 } else { 8 };
        assert_eq!(sch.predictor_degree(), degree, "s = {s}");
        let lebesgue = (0..s)
            .map(|j| {
                sch.extrapolation_row(j)
                    .iter()
                    .map(|x| x.abs())
                    .sum::<f64>()
            })
            .fold(0.0, f64::max);
        assert!(lebesgue <= MAX_PREDICTOR_LEBESGUE, "s = {s}: {lebesgue:e}");
        // The table's rows and the basis at 1 + d_j agree; each row sums to 1 and
        // extrapolates the monomial of the predictor's degree exactly.
        let mut basis = vec![0.0; s];
        for j in 0..s {
            let tau = 1.0 + sch.d()[j];
            sch.predictor_basis_at(tau, &mut basis);
            let row = sch.extrapolation_row(j);
            for (a, b) in basis.iter().zip(row) {
                assert!((a - b).abs() <= 1e-9 * (1.0 + b.abs()), "s = {s}, j = {j}");
            }
            let sum: f64 = row.iter().sum();
            assert!((sum - 1.0).abs() <= 1e-8, "s = {s}: {sum}");
            let mono: f64 = row
                .iter()
                .zip(sch.d())
                .map(|(l, x)| l * x.powi(degree as i32))
                .sum();
            let want = tau.powi(degree as i32);
            assert!((mono - want).abs() <= 1e-7 * want, "s = {s}: {mono} {want}");
        }
    }
}

#[test]
#[ignore]
fn print_node_errors() {
    for (s, ex, ew) in errors() {
        println!("{s} {ex:.2e} {ew:.2e}");
    }
}
