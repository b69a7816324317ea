//! Shared tallies of the stability section: outcome counts, the wrong-answer test and the
//! cheapest run reaching a target.

use super::rows::{BaselineRow, Outcome, Row};
use crate::baselines::Baseline;

/// Outcome counts of one scene (or of all).
pub struct Counts {
    pub scene: String,
    pub runs: usize,
    pub ok: usize,
    pub recovered: usize,
    pub wrong: usize,
    /// `(kind, count)` of the failures, in order of appearance.
    pub failed: Vec<(String, usize)>,
}

impl Counts {
    pub fn of(scene: &str, rows: &[&Row], scale: f64) -> Counts {
        let mut failed: Vec<(String, usize)> = Vec::new();
        for r in rows {
            if let Outcome::Failed(k) = &r.outcome {
                match failed.iter_mut().find(|(n, _)| n == k) {
                    Some(e) => e.1 += 1,
                    None => failed.push((k.clone(), 1)),
                }
            }
        }
        let count = |o: Outcome| rows.iter().filter(|r| r.outcome == o).count();
        Counts {
            scene: format!("`{scene}`"),
            runs: rows.len(),
            ok: count(Outcome::Ok),
            recovered: count(Outcome::Recovered),
            wrong: rows.iter().filter(|r| is_wrong(r, scale)).count(),
            failed,
        }
    }

    pub fn failed_total(&self) -> usize {
        self.failed.iter().map(|k| k.1).sum()
    }
}

/// A finished run whose final error exceeds half the solution's size.
pub fn is_wrong(r: &Row, scale: f64) -> bool {
    !matches!(r.outcome, Outcome::Failed(_)) && r.err_final > 0.5 * scale
}

/// The cheapest (by wall time) variational row of `scene` reaching `target`.
pub fn best_variational<'a>(rows: &'a [Row], scene: &str, target: f64) -> Option<&'a Row> {
    rows.iter()
        .filter(|r| r.scene == scene && !matches!(r.outcome, Outcome::Failed(_)))
        .filter(|r| r.err_final <= target)
        .min_by(|a, b| a.seconds.total_cmp(&b.seconds))
}

pub fn best_baseline<'a>(
    rows: &'a [BaselineRow],
    scene: &str,
    solver: Baseline,
    target: f64,
) -> Option<&'a BaselineRow> {
    rows.iter()
        .filter(|r| r.scene == scene && r.solver == solver && r.failure.is_none())
        // A run identical to the reference is the reference itself: leave it out.
        .filter(|r| r.err_final > 0.0 && r.err_final <= target)
        .min_by(|a, b| a.seconds.total_cmp(&b.seconds))
}

/// The failures of a scene by kind (`all`: their total).
pub fn failed_by_kind(c: &Counts) -> String {
    match (c.failed.as_slice(), c.scene == "all") {
        (_, true) => c.failed_total().to_string(),
        ([], false) => "0".to_string(),
        (kinds, false) => {
            let kinds: Vec<String> = kinds.iter().map(|(k, n)| format!("{k}: {n}")).collect();
            kinds.join(", ")
        }
    }
}
