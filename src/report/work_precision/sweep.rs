//! One case of the work-precision study: a method swept over its grid on one scene.

use forced_vi::Scheme;
use rayon::prelude::*;

use super::rows::{Failure, Mode, OrderRow, Paired, Row, Spread, Summary};
use crate::report::orders;
use crate::report::plan::{Plan, ORDER2_TOL_FLOOR, PAPER_SCENE, PREDICTED_RUN_FACTOR};
use crate::report::study::Study;
use crate::report::timing;
use crate::report::Method;
use crate::scenes::{Outcome, Scene, SceneError};

/// The rows and failures of one sweep.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Swept {
    /// Measured points, largest `h` or tolerance first.
    pub rows: Vec<Row>,
    /// Points without a result.
    pub failures: Vec<Failure>,
}

/// The sweeps of the selected scenes and methods, one at a time (they are timed).
pub struct Sweeps<'a> {
    /// The selected scenes.
    pub scenes: &'a [&'a dyn Scene],
    /// The grids.
    pub plan: &'a Plan,
}

impl Study for Sweeps<'_> {
    /// `(scene index, method, mode)`.
    type Case = (usize, Method, Mode);
    type Row = Swept;
    const PARALLEL: bool = false;

    fn label(&self, &(i, m, mode): &Self::Case) -> String {
        format!("{} {}", self.scenes[i].name(), mode.label(&m))
    }

    fn run(&self, &(i, m, mode): &Self::Case) -> Swept {
        sweep(self.scenes[i], &m, mode, self.plan)
    }

    fn panicked(&self, &(i, m, mode): &Self::Case) -> Swept {
        Swept {
            rows: Vec::new(),
            failures: vec![Failure {
                scene: self.scenes[i].name(),
                method: m,
                mode,
                h_or_tol: f64::NAN,
                message: "the sweep panicked".into(),
            }],
        }
    }
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

fn max_abs(a: &[f64]) -> f64 {
    a.iter().map(|x| x.abs()).fold(0.0, f64::max)
}

/// The size of the reference values of a scene: `[|q|∞, |p|∞, |E|]` over all members.
pub fn reference_scale(scene: &dyn Scene) -> [f64; 3] {
    let mut s = [0.0f64; 3];
    for m in 0..scene.members() {
        if let Some(r) = scene.reference(m) {
            s[0] = s[0].max(max_abs(&r.q));
            s[1] = s[1].max(max_abs(&r.p));
            s[2] = s[2].max(r.energy.abs());
        }
    }
    s
}

/// Runs one method at one `h` or tolerance on every member of a scene (members in parallel).
fn run_members(
    scene: &dyn Scene,
    (method, mode): (&Method, Mode),
    scheme: Option<&Scheme>,
    x: f64,
) -> Result<Vec<Outcome>, String> {
    let one = |member: usize| match (method, scheme) {
        (Method::Variational(_), Some(s)) if mode == Mode::Adaptive => {
            scene.run_adaptive(s, x, member)
        }
        (Method::Variational(_), Some(s)) => scene.run_variational(s, x, member),
        (Method::Baseline(b), _) => scene.run_baseline(*b, x, member),
        (Method::Variational(id), None) => Err(SceneError::Variational(
            forced_vi::SchemeError::Unknown(id.to_string()).into(),
        )),
    };
    let out = match (method, scheme) {
        _ if scene.members() == 1 => one(0).map(|o| vec![o]),
        // An ensemble of variational runs as the library runs one (`Integrator::ensemble`:
        // one stepper per worker, restarted member to member); a baseline builds its solver
        // for each member.
        (Method::Variational(_), Some(s)) => {
            scene.run_variational_members(s, x, mode == Mode::Adaptive)
        }
        _ => (0..scene.members()).into_par_iter().map(one).collect(),
    };
    out.map_err(|e| e.to_string())
}

/// Errors of every member against its reference, as min/mean/max over the members.
fn spreads(scene: &dyn Scene, outcomes: &[Outcome]) -> Result<[Spread; 3], String> {
    let mut member_errs: [Vec<f64>; 3] = Default::default();
    for (m, o) in outcomes.iter().enumerate() {
        let r = scene
            .reference(m)
            .ok_or_else(|| format!("no reference for member {m}"))?;
        let e = [
            max_abs_diff(&o.end.q, &r.q),
            max_abs_diff(&o.end.p, &r.p),
            (o.end.energy - r.energy).abs(),
        ];
        if !e.iter().all(|x| x.is_finite()) {
            return Err(format!("non-finite result for member {m}"));
        }
        for (k, ek) in e.into_iter().enumerate() {
            member_errs[k].push(ek);
        }
    }
    Ok(member_errs.map(|v| Spread {
        min: v.iter().copied().fold(f64::INFINITY, f64::min),
        mean: v.iter().sum::<f64>() / v.len() as f64,
        max: v.iter().copied().fold(0.0, f64::max),
    }))
}

/// Measures one point: errors, steps and the median wall time. Returns the row and the time of
/// the first repeat.
fn measure(
    scene: &dyn Scene,
    (method, mode): (&Method, Mode),
    scheme: Option<&Scheme>,
    x: f64,
    plan: &Plan,
) -> Result<(Row, f64), String> {
    let timing = timing::repeated(
        |first| plan.repeats(first),
        || run_members(scene, (method, mode), scheme, x),
    )?;
    let outcomes = timing.first;
    let row = Row {
        scene: scene.name(),
        method: *method,
        mode,
        h_or_tol: x,
        steps: outcomes.iter().map(|o| o.steps).sum(),
        member_steps_min: outcomes.iter().map(|o| o.steps).min().unwrap_or(0),
        newton_iters: outcomes.iter().map(|o| o.newton_iterations).sum(),
        seconds: timing.median,
        err: spreads(scene, &outcomes)?,
    };
    Ok((row, timing.first_seconds))
}

/// The cheapest variational run and the cheapest baseline run of `summary` whose error in q
/// on `scene` is at most `target`, timed again in rounds (`None` when either side never
/// reached it).
///
/// The sweeps time each run once, at its own moment; on a machine shared with other jobs
/// the speed drifts between those moments (measured: the same baseline run 1.8 times slower
/// in one report than in the next), and the ratio of two such times carries the drift.
/// So the [`PAIRED_CANDIDATES`] cheapest runs of each side by the sweeps' times are timed
/// again, in rounds that run them all right after each other, and each side's fastest by
/// those medians is kept: the sweeps' times only shortlist, and a run that was timed at a
/// quiet moment does not stand in for one that is faster.
pub fn paired(scene: &dyn Scene, summary: &Summary, target: f64, plan: &Plan) -> Option<Paired> {
    let cheapest = |variational: bool| {
        let mut rows: Vec<&Row> = summary
            .rows
            .iter()
            .filter(|r| r.scene == scene.name() && r.method.is_variational() == variational)
            .filter(|r| r.errors()[0] <= target)
            .collect();
        rows.sort_by(|a, b| a.seconds.total_cmp(&b.seconds));
        rows.truncate(PAIRED_CANDIDATES);
        rows
    };
    let (vis, bases) = (cheapest(true), cheapest(false));
    let (fastest_vi, fastest_base) = (vis.first()?, bases.first()?);
    let rounds = plan
        .repeats(fastest_vi.seconds.max(fastest_base.seconds))
        .max(plan.max_repeats.min(5));
    let candidates: Vec<&Row> = vis.iter().chain(&bases).copied().collect();
    let medians = time_again(scene, &candidates, rounds);
    fn best<'r>(medians: &[f64], rows: &[&'r Row]) -> Option<(&'r Row, f64)> {
        let i = (0..rows.len()).min_by(|&a, &b| medians[a].total_cmp(&medians[b]))?;
        Some((rows[i], medians[i]))
    }
    let (vi, base, seconds) = match medians {
        Ok(m) => {
            let (vi, tv) = best(&m[..vis.len()], &vis)?;
            let (base, tb) = best(&m[vis.len()..], &bases)?;
            (vi, base, Ok((tv, tb)))
        }
        Err(e) => (*fastest_vi, *fastest_base, Err(e)),
    };
    Some(Paired {
        scene: scene.name(),
        target,
        variational: (vi.method, vi.mode, vi.h_or_tol),
        baseline: (base.method, base.h_or_tol),
        seconds,
        rounds,
        candidates: (vis.len(), bases.len()),
    })
}

/// Times `rows` of `scene` again: [`timing::rotated`] rounds that run them all one after
/// the other, each round starting one further along; the median of each over the rounds.
pub fn time_again(scene: &dyn Scene, rows: &[&Row], rounds: usize) -> Result<Vec<f64>, String> {
    let candidates: Vec<(&Row, Option<Scheme>)> =
        rows.iter().map(|r| (*r, r.method.scheme())).collect();
    let mut samplers: Vec<Box<dyn FnMut() -> Result<f64, String> + '_>> = candidates
        .iter()
        .map(|(row, scheme)| {
            Box::new(move || {
                let (out, seconds) = timing::timed(|| {
                    run_members(
                        scene,
                        (&row.method, row.mode),
                        scheme.as_ref(),
                        row.h_or_tol,
                    )
                });
                out.map(|_| seconds)
            }) as Box<dyn FnMut() -> Result<f64, String> + '_>
        })
        .collect();
    let mut fs: Vec<&mut dyn FnMut() -> Result<f64, String>> =
        samplers.iter_mut().map(|f| &mut **f as _).collect();
    timing::rotated(rounds, &mut fs)
}

/// How many of the cheapest runs of each side [`paired`] times again.
pub const PAIRED_CANDIDATES: usize = 3;

/// The grid of `method` in `mode` on `scene`: step sizes, or tolerances (second-order
/// schemes stop at [`ORDER2_TOL_FLOOR`] in adaptive mode).
pub fn grid(plan: &Plan, scene: &dyn Scene, method: &Method, mode: Mode) -> Vec<f64> {
    match (method, mode) {
        (Method::Variational(_), Mode::Fixed) => {
            let order = method.scheme().map_or(0, |s| s.order());
            plan.step_sizes(scene.t_final(), order)
        }
        (Method::Variational(_), Mode::Adaptive) => {
            let order = method.scheme().map_or(0, |s| s.order());
            let floor = if order <= 2 { ORDER2_TOL_FLOOR } else { 0.0 };
            let tols = plan.adaptive_tolerances.iter().copied();
            tols.filter(|t| *t >= floor).collect()
        }
        (Method::Baseline(_), _) => plan.tolerances.clone(),
    }
}

/// The predicted time of a variational run at `x`, from the previous point `(x0, t0)` (step
/// size or tolerance, seconds): the work goes as `1/h` with fixed steps and as `tol^(−1/p)`
/// with adaptive steps of order `p`. `None` for the baselines, whose effective order varies.
pub fn predicted_seconds(method: &Method, mode: Mode, (x0, t0): (f64, f64), x: f64) -> Option<f64> {
    let order = method.scheme()?.order() as f64;
    let ratio = x0 / x;
    match mode {
        Mode::Fixed => Some(t0 * ratio),
        Mode::Adaptive => Some(t0 * ratio.powf(1.0 / order)),
    }
}

/// Sweeps one method over its grid on one scene, stopping early as [`Plan`] says.
fn sweep(scene: &dyn Scene, method: &Method, mode: Mode, plan: &Plan) -> Swept {
    let scheme = method.scheme();
    let scale = reference_scale(scene);
    let keep_tail = plan.full_paper_tail
        && method.is_variational()
        && mode == Mode::Fixed
        && scene.name() == PAPER_SCENE;
    let mut out = Swept::default();
    let mut floor_run = 0;
    let mut last: Option<(f64, f64)> = None;
    for x in grid(plan, scene, method, mode) {
        let too_long = last.and_then(|(x0, t0)| predicted_seconds(method, mode, (x0, t0), x));
        if !keep_tail && too_long.is_some_and(|t| t > PREDICTED_RUN_FACTOR * plan.max_run_seconds) {
            break;
        }
        match measure(scene, (method, mode), scheme.as_ref(), x, plan) {
            Ok((row, first)) => {
                last = Some((x, first));
                let e = row.errors();
                if orders::at_floor(e[0], scale[0]) && orders::at_floor(e[1], scale[1]) {
                    floor_run += 1;
                } else {
                    floor_run = 0;
                }
                out.rows.push(row);
                if !keep_tail && (floor_run >= plan.floor_points || first > plan.max_run_seconds) {
                    break;
                }
            }
            Err(message) => out.failures.push(Failure {
                scene: scene.name(),
                method: *method,
                mode,
                h_or_tol: x,
                message,
            }),
        }
    }
    out
}

/// Why an order in q is blank or off (empty when it is within 0.3 of `expected`): the fit
/// that does not settle the order, or the sweep's points and how many lie between the
/// round-off floor and the ceiling of the rule (`orders`).
fn order_note(
    pts: &[(f64, f64)],
    fit: Option<&orders::Fit>,
    expected: usize,
    scale: f64,
) -> String {
    let s = scale.max(1.0);
    let inside = pts
        .iter()
        .filter(|&&(_, e)| e.is_finite() && e >= orders::FLOOR * s && e <= orders::CEILING * s)
        .count();
    match fit {
        Some(f) if f.unsettled().is_some() => format!(
            "blank: no stretch of the sweep above round-off settles the order; the fit over \
             {} points (h = {:.3e}..{:.3e}) reads {:.2} with {}",
            f.used.len(),
            f.used[f.used.len() - 1].0,
            f.used[0].0,
            f.order,
            f.unsettled().map_or(String::new(), |u| u.to_string()),
        ),
        Some(f) if (f.order - expected as f64).abs() <= 0.3 => String::new(),
        Some(f) => format!(
            "off by {:.2} over {} points (h = {:.3e}..{:.3e})",
            f.order - expected as f64,
            f.used.len(),
            f.used[f.used.len() - 1].0,
            f.used[0].0
        ),
        None if pts.is_empty() => "no fixed-step run".into(),
        None => format!(
            "blank: {inside} of {} runs have errors between the round-off floor and the \
             pre-asymptotic ceiling, fewer of them where the error still falls; a fit needs {}",
            pts.len(),
            orders::MIN_POINTS
        ),
    }
}

/// Fits the observed orders of every variational method on every scene.
pub fn fit_orders(scenes: &[&dyn Scene], summary: &mut Summary) {
    for scene in scenes {
        let scale = reference_scale(*scene);
        for method in summary.methods.clone() {
            let Method::Variational(id) = method else {
                continue;
            };
            let Ok(scheme) = Scheme::new(id) else {
                continue;
            };
            let points = |k: usize| -> Vec<(f64, f64)> {
                summary
                    .rows
                    .iter()
                    .filter(|r| r.scene == scene.name() && r.method == method)
                    .filter(|r| r.mode == Mode::Fixed)
                    .map(|r| (r.h_or_tol, r.errors()[k]))
                    .collect()
            };
            let fits = [0, 1, 2].map(|k| orders::observed_order(&points(k), scale[k]));
            let expected = scheme.order();
            let note = order_note(&points(0), fits[0].as_ref(), expected, scale[0]);
            // Only settled fits are published (`orders`, rules 4 and 5).
            let observed = fits.map(|f| f.filter(|f| f.unsettled().is_none()));
            summary.orders.push(OrderRow {
                scene: scene.name(),
                method,
                stages: scheme.stages(),
                expected,
                observed,
                note,
            });
        }
    }
}
