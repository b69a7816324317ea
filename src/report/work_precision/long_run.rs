//! The energy-balance long run: every method on one scene to `t = 1000` at about equal cost.
//!
//! The budget is the wall time of `lobatto3` with `h = 0.02` ([`LONG_RUN_REFERENCE_H`]). Each
//! variational scheme gets the step size whose cost meets the budget (predicted from a pilot
//! run over a tenth of the time, then corrected once); each baseline gets, from a ladder of
//! tolerances `10^(−2 − k/2)`, the one whose measured time is nearest to it. Each variational
//! scheme also runs adaptively (issue 11), with the tolerance chosen the same way from
//! `10^(−3 − k/2)`: the energy ledger `E − E0 − W` with variable steps beside the fixed-step
//! one.

use forced_vi::{Scheme, SchemeId};

use super::rows::{BalanceCurve, Mode};
use crate::baselines::Baseline;
use crate::report::plan::Plan;
use crate::report::study::Study;
use crate::report::timing::{median, timed};
use crate::report::Method;
use crate::scenes::{BalanceSeries, Scene, SceneError};

/// The step size of the reference run that sets the long run's cost budget.
pub const LONG_RUN_REFERENCE_H: f64 = 0.02;

/// The long run of one scene: one case per method, one at a time (they are timed).
pub struct LongRunStudy<'a> {
    /// The scene.
    pub scene: &'a dyn Scene,
    /// Final time.
    pub t_final: f64,
    /// Samples per curve.
    pub samples: usize,
    /// The cost budget, seconds.
    pub budget: f64,
}

impl<'a> LongRunStudy<'a> {
    /// Measures the budget: the median of three reference runs (`None` if lobatto3 is
    /// unavailable).
    pub fn new(scene: &'a dyn Scene, plan: &Plan) -> Option<Self> {
        let reference = Scheme::new(SchemeId::Lobatto(3)).ok()?;
        let mut study = LongRunStudy {
            scene,
            t_final: plan.long_run_t,
            samples: plan.long_run_samples,
            budget: 0.0,
        };
        let mut times: Vec<f64> = (0..3)
            .map(|_| {
                study
                    .timed_vi(&reference, LONG_RUN_REFERENCE_H, study.t_final)
                    .1
            })
            .collect();
        study.budget = median(&mut times);
        Some(study)
    }

    fn timed_vi(
        &self,
        scheme: &Scheme,
        h: f64,
        t: f64,
    ) -> (Result<BalanceSeries, SceneError>, f64) {
        timed(|| self.scene.balance_variational(scheme, h, t, self.samples))
    }

    /// Whole step counts, so that every run ends exactly at `t_final`.
    fn step_for(&self, steps: f64) -> f64 {
        self.t_final / steps.round().clamp(self.t_final / 0.25, 1e8)
    }

    fn variational(&self, method: Method, id: SchemeId) -> Option<BalanceCurve> {
        let scheme = Scheme::new(id).ok()?;
        // Pilot over a tenth of the run, then one correction of the step count.
        let (pilot, secs) = self.timed_vi(&scheme, 0.1, self.t_final / 10.0);
        let pilot = pilot.ok()?;
        let mut steps = self.budget / (secs / pilot.steps.max(1) as f64);
        let mut h = self.step_for(steps);
        let (mut result, mut seconds) = self.timed_vi(&scheme, h, self.t_final);
        if result.is_ok() && (seconds / self.budget).ln().abs() > 1.25f64.ln() {
            steps *= self.budget / seconds;
            h = self.step_for(steps);
            (result, seconds) = self.timed_vi(&scheme, h, self.t_final);
        }
        let series = result.ok()?;
        Some(BalanceCurve {
            method,
            mode: Mode::Fixed,
            h_or_tol: h,
            seconds,
            series,
        })
    }

    fn baseline(&self, method: Method, b: Baseline) -> Option<BalanceCurve> {
        self.nearest_budget(method, Mode::Fixed, -2.0, |tol| {
            self.scene
                .balance_baseline(b, tol, self.t_final, self.samples)
        })
    }

    fn adaptive(&self, method: Method, id: SchemeId) -> Option<BalanceCurve> {
        let scheme = Scheme::new(id).ok()?;
        self.nearest_budget(method, Mode::Adaptive, -3.0, |tol| {
            self.scene
                .balance_adaptive(&scheme, tol, self.t_final, self.samples)
        })
    }

    /// Walks the tolerances `10^(first − k/2)` down to 1e-13 and keeps the run whose time is
    /// nearest the budget; stops once a run costs more than 1.5 budgets.
    fn nearest_budget(
        &self,
        method: Method,
        mode: Mode,
        first: f64,
        run: impl Fn(f64) -> Result<BalanceSeries, SceneError>,
    ) -> Option<BalanceCurve> {
        let mut best: Option<BalanceCurve> = None;
        let gap = |seconds: f64| (seconds / self.budget).ln().abs();
        let mut tol = 10f64.powf(first);
        while tol >= 1e-13 {
            let (result, seconds) = timed(|| run(tol));
            tol /= 10f64.sqrt();
            // A loose tolerance may fail where a tighter one succeeds.
            let Ok(series) = result else { continue };
            if best.as_ref().is_none_or(|c| gap(seconds) < gap(c.seconds)) {
                best = Some(BalanceCurve {
                    method,
                    mode,
                    h_or_tol: tol * 10f64.sqrt(),
                    seconds,
                    series,
                });
            }
            if seconds > 1.5 * self.budget {
                break;
            }
        }
        best
    }
}

impl Study for LongRunStudy<'_> {
    type Case = (Method, Mode);
    type Row = Option<BalanceCurve>;
    const PARALLEL: bool = false;

    fn label(&self, (method, mode): &(Method, Mode)) -> String {
        format!("{} long run: {}", self.scene.name(), mode.label(method))
    }

    fn run(&self, &(method, mode): &(Method, Mode)) -> Option<BalanceCurve> {
        match (method, mode) {
            (Method::Variational(id), Mode::Fixed) => self.variational(method, id),
            (Method::Variational(id), Mode::Adaptive) => self.adaptive(method, id),
            (Method::Baseline(b), Mode::Fixed) => self.baseline(method, b),
            (Method::Baseline(_), Mode::Adaptive) => None,
        }
    }

    fn panicked(&self, _: &(Method, Mode)) -> Option<BalanceCurve> {
        None
    }
}
