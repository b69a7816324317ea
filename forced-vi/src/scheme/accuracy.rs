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
