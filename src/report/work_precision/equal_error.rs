//! Adaptive runs against fixed steps of the same scheme at equal error (issue 23's cost
//! target: an adaptive run within 1.3 times the best fixed step reaching its error).
//!
//! Each adaptive run is set beside the fixed-step curve of its scheme on its scene, read at
//! the adaptive run's own error by log-log interpolation between the two fixed runs around it
//! ([`fixed_at`]). So the comparison does not depend on how finely either grid is spaced:
//! reading the cheapest run of each grid that reaches a target instead favours whichever grid
//! happens to land just below it (the adaptive grid is a decade per point, the fixed one a
//! third of one).
//!
//! The time ratio splits into two factors that say where the cost goes:
//! - **steps**: the adaptive run's accepted steps over the fixed curve's steps at the same
//!   error: how well the controller places its steps (below 1: fewer than uniform steps);
//! - **per step**: the time ratio over the steps ratio: what an adaptive step costs (its
//!   solve, its error estimate, its rejected attempts) over a fixed one.
//!
//! The sweeps time the fixed and the adaptive runs of a line at different moments, and this
//! machine's speed drifts by 2× or more between moments, which moves a whole line. So each
//! line's middle adaptive run and the two fixed runs around its error are also timed again
//! together ([`middle_runs`], [`Timed`]), and that ratio is the one read against the target.

pub use super::rows::Timed;
use super::rows::{Mode, Row, Summary};
use crate::report::timing::median;
use crate::report::Method;

/// The fewest steps of an adaptive run that is compared: in a run of 1 to 3 steps the error
/// is set by the run's length, not by the tolerance (as in the proportionality slope).
pub const MIN_RUN_STEPS: usize = 4;

/// The two runs of a fixed-step curve around the error `err` (the first such pair, by
/// error) and the position of `err` between them in log scale (0 at the first, 1 at the
/// second); `None` outside the curve.
pub fn bracket<'r>(fixed: &[&'r Row], err: f64) -> Option<(&'r Row, &'r Row, f64)> {
    let mut pts: Vec<&Row> = fixed.to_vec();
    pts.sort_by(|a, b| a.errors()[0].total_cmp(&b.errors()[0]));
    pts.windows(2).find_map(|w| {
        let (e0, e1) = (w[0].errors()[0], w[1].errors()[0]);
        (e0 <= err && err <= e1 && e0 > 0.0).then(|| {
            let x = if e1 > e0 {
                (err / e0).ln() / (e1 / e0).ln()
            } else {
                0.0
            };
            (w[0], w[1], x)
        })
    })
}

/// Log-scale interpolation: `v0` at 0, `v1` at 1.
fn log_between(v0: f64, v1: f64, x: f64) -> f64 {
    (v0.ln() + x * (v1.ln() - v0.ln())).exp()
}

/// `value` of a fixed-step curve at the error `err`: log-log interpolation between the two
/// runs around it ([`bracket`]); `None` outside the curve or where a value is not positive.
pub fn fixed_at(fixed: &[&Row], err: f64, value: impl Fn(&Row) -> f64) -> Option<f64> {
    let (r0, r1, x) = bracket(fixed, err)?;
    let (v0, v1) = (value(r0), value(r1));
    (v0 > 0.0 && v1 > 0.0).then(|| log_between(v0, v1, x))
}

/// The runs that [`Timed`] times for a line: its middle adaptive run (by tolerance), the two
/// fixed runs around that run's error, and where the error lies between them.
pub fn middle_runs<'r>(
    summary: &'r Summary,
    line: &Line,
    at_floor: impl Fn(f64) -> bool,
) -> Option<(&'r Row, &'r Row, &'r Row, f64)> {
    let tol = line.pairs.get(line.pairs.len() / 2)?.tol;
    let adaptive = summary
        .rows_in(line.scene, &line.method, Mode::Adaptive)
        .into_iter()
        .find(|r| r.h_or_tol == tol)?;
    let fixed: Vec<&Row> = summary
        .rows_in(line.scene, &line.method, Mode::Fixed)
        .into_iter()
        .filter(|r| !at_floor(r.errors()[0]))
        .collect();
    let (f0, f1, x) = bracket(&fixed, adaptive.errors()[0])?;
    Some((adaptive, f0, f1, x))
}

/// The time ratio of [`middle_runs`] from their times `[adaptive, f0, f1]`.
pub fn ratio_from(times: &[f64], x: f64) -> Option<f64> {
    match times {
        [a, f0, f1] if *f0 > 0.0 && *f1 > 0.0 => Some(a / log_between(*f0, *f1, x)),
        _ => None,
    }
}

/// One adaptive run beside the fixed curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pair {
    /// Its tolerance.
    pub tol: f64,
    /// Its time over the fixed curve's time at its error.
    pub time: f64,
    /// Its accepted steps over the fixed curve's steps at its error.
    pub steps: f64,
}

impl Pair {
    /// What an adaptive step costs over a fixed one.
    pub fn per_step(&self) -> f64 {
        self.time / self.steps
    }
}

/// A scene and scheme: its adaptive runs beside its fixed curve.
#[derive(Clone, Debug, PartialEq)]
pub struct Line {
    /// The scene.
    pub scene: &'static str,
    /// The scheme.
    pub method: Method,
    /// The adaptive runs compared, loosest tolerance first.
    pub pairs: Vec<Pair>,
}

impl Line {
    /// The median of `f` over the pairs.
    pub fn median(&self, f: impl Fn(&Pair) -> f64) -> f64 {
        let mut v: Vec<f64> = self.pairs.iter().map(f).collect();
        median(&mut v)
    }

    /// The smallest and largest time ratio.
    pub fn time_range(&self) -> (f64, f64) {
        self.pairs
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), p| {
                (lo.min(p.time), hi.max(p.time))
            })
    }
}

/// The lines of one scene: every variational scheme with both fixed and adaptive runs. Runs
/// (fixed or adaptive) whose error is within the round-off floor (`at_floor`) are left out,
/// adaptive runs of fewer than [`MIN_RUN_STEPS`] steps (any member's) too, and adaptive runs
/// outside the fixed curve.
pub fn lines(summary: &Summary, scene: &'static str, at_floor: impl Fn(f64) -> bool) -> Vec<Line> {
    let mut out = Vec::new();
    for m in summary.methods.iter().filter(|m| m.is_variational()) {
        let fixed: Vec<&Row> = summary
            .rows_in(scene, m, Mode::Fixed)
            .into_iter()
            .filter(|r| !at_floor(r.errors()[0]))
            .collect();
        let mut pairs = Vec::new();
        // Loosest tolerance first.
        for r in summary.rows_in(scene, m, Mode::Adaptive).into_iter().rev() {
            let err = r.errors()[0];
            if at_floor(err) || r.member_steps_min < MIN_RUN_STEPS || r.seconds <= 0.0 {
                continue;
            }
            let time = fixed_at(&fixed, err, |f| f.seconds);
            let steps = fixed_at(&fixed, err, |f| f.steps as f64);
            if let (Some(t), Some(n)) = (time, steps) {
                pairs.push(Pair {
                    tol: r.h_or_tol,
                    time: r.seconds / t,
                    steps: r.steps as f64 / n,
                });
            }
        }
        if !pairs.is_empty() {
            out.push(Line {
                scene,
                method: *m,
                pairs,
            });
        }
    }
    out
}
