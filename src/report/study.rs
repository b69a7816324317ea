//! A study: planned cases, run one by one or in parallel into typed rows.
//!
//! Every command of the report is a study: it plans a list of cases, says how one case runs
//! into a row ([`Study::run`]) and what row stands for a case that panicked
//! ([`Study::panicked`]), and then writes the rows as CSV, a Markdown section and figures. The
//! loop is [`run_cases`]: a progress bar, a catch for panics, and rayon when the study allows
//! it ([`Study::PARALLEL`]). Studies that time their runs one at a time set it to `false`.

use std::panic::{catch_unwind, AssertUnwindSafe};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use rayon::prelude::*;

use super::ReportError;

/// One command's cases and how to run them.
pub trait Study: Sync {
    /// One planned case.
    type Case: Sync;
    /// What one case produces.
    type Row: Send;
    /// Run cases in parallel (rayon); `false` runs them in order, one at a time.
    const PARALLEL: bool;
    /// A short label of the case for the progress bar.
    fn label(&self, case: &Self::Case) -> String;
    /// Runs one case.
    fn run(&self, case: &Self::Case) -> Self::Row;
    /// The row of a case whose run panicked.
    fn panicked(&self, case: &Self::Case) -> Self::Row;
}

/// A progress bar on stderr, or a hidden one.
pub fn progress_bar(total: usize, show: bool) -> ProgressBar {
    let target = if show {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    };
    let pb = ProgressBar::with_draw_target(Some(total as u64), target);
    if let Ok(style) =
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} runs  {msg}")
    {
        pb.set_style(style.progress_chars("=> "));
    }
    pb
}

/// Runs every case of `study`, in the order of `cases`, and returns their rows in that order.
pub fn run_cases<S: Study>(study: &S, cases: &[S::Case], progress: bool) -> Vec<S::Row> {
    let pb = progress_bar(cases.len(), progress);
    let one = |case: &S::Case| {
        pb.set_message(study.label(case));
        let row = catch_unwind(AssertUnwindSafe(|| study.run(case)))
            .unwrap_or_else(|_| study.panicked(case));
        pb.inc(1);
        row
    };
    let rows = if S::PARALLEL {
        cases.par_iter().map(one).collect()
    } else {
        cases.iter().map(one).collect()
    };
    pb.finish_and_clear();
    rows
}

/// Checks that every requested scene name is known.
pub fn check_scenes(requested: &[String], known: &[&str]) -> Result<(), ReportError> {
    match requested.iter().find(|r| !known.contains(&r.as_str())) {
        Some(name) => Err(ReportError::UnknownScene {
            name: name.clone(),
            known: known.join(", "),
        }),
        None => Ok(()),
    }
}

/// Whether `name` is selected by `--scene` (empty: all are).
pub fn selected(requested: &[String], name: &str) -> bool {
    requested.is_empty() || requested.iter().any(|r| r == name)
}
