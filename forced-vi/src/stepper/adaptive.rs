//! Adaptive steps (DESIGN §8): a step, its error estimate by one Newton iteration of the
//! reference scheme, the controller's decision, and the automatic first step. The estimate
//! and the controller are derived in [`crate::control`]. The same on every backend.

use super::checks::step_count;
use super::{Stepped, Stepper};
use crate::backend::{Layout, StepBackend, StepFailure, StepView};

/// The views of a step and of its reference.
type StepViews<'a> = (StepView<'a>, StepView<'a>);
use crate::control::{Controller, Tolerance};
use crate::error::{Error, NewtonFailure};
use crate::model::ForcedLagrangian;

/// The accumulated round-off, in units of the tolerance, past which a run stops (see
/// [`crate::control`]).
const ROUND_OFF_MAX: f64 = 3.0;

/// The steps of a window over which an adaptive run measures its pace (see
/// [`crate::control`], "The pace of a run").
pub(crate) const PACE_WINDOW: usize = 1 << 16;

/// The windows in a row, each with a largest step below the one before and too small for the
/// rest of the run to fit under the step cap, after which an adaptive run stops.
pub(crate) const PACE_WINDOWS: u32 = 32;
// `Error::PaceTooSlow` and `crate::control` name them.
const _: () = assert!(PACE_WINDOW == 65536 && PACE_WINDOWS == 32);

/// An adaptive run's pace (see [`Stepper::check_pace`]).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Pace {
    /// The largest step accepted in the current window, and in the one before.
    h_max: f64,
    h_before: f64,
    /// The slow windows in a row (see [`PACE_WINDOWS`]).
    slow_windows: u32,
    /// Set after too many: `(that window's largest step, steps needed, steps left)`.
    stalled: Option<(f64, f64, usize)>,
}

/// The first step of a pair, kept while the second is solved (see [`crate::control`],
/// "Pairs"): what the estimate over both reads of it, and the state at its end.
#[derive(Debug)]
pub(super) struct PairFirst {
    /// Its increments, in the backend's layout, and those at its end, per coordinate.
    z: Vec<f64>,
    end: Vec<f64>,
    /// Its momentum update, and the pair's.
    dp: Vec<f64>,
    dp_pair: Vec<f64>,
    /// `Σ_i |h b_i (L_q + F)_i|` over its nodes, per coordinate.
    size: Vec<f64>,
    /// Its force round-off rate and time rate (see `local_error`).
    rate: f64,
    time_rate: f64,
    /// The state at its end (at the second step's end once the pair is accepted, until
    /// that step is handed out).
    state: super::state::State,
}

/// An accepted pair's second step, handed out at the next call: its end time, its Newton
/// iterations and residual.
#[derive(Clone, Copy, Debug)]
pub(super) struct Pending {
    t: f64,
    iters: usize,
    residual: f64,
}

/// What one attempt of an adaptive step gives: the step's residual, its error estimate per
/// unit step over the tolerance, and for a pair (see [`crate::control`], "Pairs") the
/// second step's Newton iterations and residual.
type Attempted = (f64, f64, Option<(usize, f64)>);

impl PairFirst {
    fn new(n: usize, unknowns: usize) -> Self {
        PairFirst {
            z: vec![0.0; unknowns],
            end: vec![0.0; n],
            dp: vec![0.0; n],
            dp_pair: vec![0.0; n],
            size: vec![0.0; n],
            rate: 0.0,
            time_rate: 0.0,
            state: super::state::State::empty(),
        }
    }
}

/// What `local_error` reads of a pair's first step: its end increments (the first `N`
/// entries of `z` at the last control point), its momentum terms' sizes, its rates.
#[derive(Clone, Copy)]
struct FirstOfPair<'a> {
    end: &'a [f64],
    size: &'a [f64],
    rate: f64,
    time_rate: f64,
}

/// The part of the tolerance below which the estimate leaves out the second correction of
/// carried factors (see [`crate::control`]).
const NEGLIGIBLE: f64 = 0.01;

/// The share of a step's tolerance, as an error in every unknown, at which its Newton
/// iteration may stop (see [`crate::control`], "Newton's stop").
const NEWTON_SHARE: f64 = 0.01;

/// The round-off bound of a run, in units of the tolerance, from which a step in a band
/// (see [`crate::control`], "The band") keeps its size even after a reading below the
/// estimate's resolution (see `Stepper::step_adaptive`).
const BAND_ROUND_OFF: f64 = 0.5;

impl<M: ForcedLagrangian<N>, const N: usize> Stepper<'_, M, N> {
    /// One adaptive step from `t`: accepted when the estimated error per unit step is at
    /// most one, retried with a smaller step otherwise (see [`crate::control`]).
    pub(super) fn step_adaptive(&mut self, tol: &Tolerance<N>) -> Result<Stepped, Error> {
        // The second step of a pair accepted at the last call.
        if let Some(second) = self.pending.take() {
            if let Some(first) = self.pair.as_mut() {
                std::mem::swap(&mut self.state, &mut first.state);
            }
            self.t = second.t;
            self.check_pace(self.state.h_prev);
            return self.finish_step(second.iters, second.residual, 1);
        }
        let t0 = self.t;
        let rejected_before = self.stats.rejected_steps;
        self.saved.copy_from(&self.state);
        let span = self.t_final;
        // Never below the smallest step a run takes (a step that shrank to 0 would be
        // retried without end).
        let h_min = self.smallest_step(t0);
        let mut iters = 0;
        let mut last_failure = None;
        loop {
            let remaining = self.t_final - t0;
            let mut h = self.h_next.min(remaining).min(self.options.max_step);
            // A step over the next output time ends on it: the output is then a step's end,
            // to the tolerance (see `crate::control`, "Output times"). Like the last step,
            // it may be shorter than `min_step`, which bounds the steps the controller
            // chooses (an output closer than that to a step's start was interpolated: 1.6e6
            // times the tolerance off with lobatto5, outputs 0.004 apart, `min_step` 0.01).
            // Closer than the smallest step a run takes, the output is the step's start.
            let planned = h;
            let mut landing = None;
            // Not on an output time within the smallest step of the run's end: the sliver
            // left after it could not be taken (`StepSizeTooSmall` after every sample of a
            // grid that ends at `T − 2e-14`); the output is the end state there.
            let landable = |ts: f64| ts - t0 >= h_min && ts - t0 < h && self.t_final - ts >= h_min;
            if let Some(ts) = self.stop.filter(|&ts| landable(ts)) {
                landing = Some(ts);
                h = ts - t0;
            }
            // No sliver of a step at the end: the step goes to the end where that is at
            // most a step the controller predicts to pass (see `Controller::stretch`), and
            // no output time comes before it.
            let reach =
                || (self.state.h_prev * self.controller.stretch()).min(self.options.max_step);
            let near = remaining <= Controller::MAX_FACTOR * self.state.h_prev
                && self.stop.is_none_or(|ts| ts >= self.t_final);
            let last = landing.is_none()
                && (h >= remaining * (1.0 - 1e-10) || (near && remaining <= reach()));
            if last {
                h = remaining;
            }
            let chosen = !last && landing.is_none();
            if h < h_min || !h.is_finite() || (chosen && h < self.options.min_step) {
                return Err(match last_failure {
                    Some(f) => self.failure_error(f, t0),
                    None => Error::StepSizeTooSmall { t: t0, h },
                });
            }
            // The step spans what the clock advances by: the clock's next value `t0 + h` is
            // rounded, and a step of the unrounded `h` would leave the state that much off
            // the time it is reported at, every step (measured: a unit oscillator over
            // T = 1000 with `max_step` 1e-3, lobatto3 at tol 1e-10, was 2.8e-8 off, the
            // same with fixed steps of 1e-3 5.3e-13; see `crate::control`, "The clock").
            // The difference of two values of the clock within a factor of two of each
            // other is exact (Sterbenz), so once `h ≤ t0` the two agree to the bit.
            if !last && landing.is_none() {
                h = (t0 + h) - t0;
            }
            if self.stats.steps >= self.options.max_steps {
                return Err(Error::MaxStepsReached {
                    t: t0,
                    steps: self.options.max_steps,
                });
            }
            if let Some((h, needed, left)) = self.pace.stalled {
                return Err(Error::PaceTooSlow {
                    t: t0,
                    h,
                    needed,
                    left,
                });
            }
            // Per unit step: the local errors of a run add up to about `tol`.
            let per_unit = span / h;
            // Solved to a small share of the step's tolerance and of the last step's
            // estimate, not to round-off: the estimate measures the step as solved (see
            // `crate::control`, "Newton's stop").
            // An error `δ` in the increments moves the momentum update by up to
            // `(h |A| + |B|) δ`: the bound holds for the larger of the two (a strongly damped
            // model, `|B|` of 10⁶, would otherwise read Newton's error in its momenta at
            // every step size alike, and shrink its steps to the floor).
            let saved = (&self.saved.q.sum[..], &self.saved.p.sum[..]);
            let share = NEWTON_SHARE * self.err_last.min(1.0);
            let gain = self.backend.force_gain(h).max(1.0);
            let within = tol.uniform_error(per_unit, share, saved) / gain;
            self.backend.solve_within(within);
            // Two steps under one estimate (see `crate::control`, "Pairs"), away from the
            // run's end, its output times and the steps after a rejection.
            let t_mid = t0 + h;
            let paired = !self.pair_lift.0.is_empty()
                && chosen
                && self.err_last > 0.0
                && self.stats.rejected_steps == rejected_before
                && self.tangent.is_none()
                && self.tape.is_none()
                && remaining >= 3.0 * h
                && self.stop.is_none_or(|ts| ts - t0 >= 3.0 * h)
                && self.stats.steps + 2 <= self.options.max_steps
                && (t_mid + h) - t_mid == h
                && h * self.backend.force_gain(h) <= Controller::RESOLVED_RATES;
            let solved = if paired {
                self.attempt_pair(h, span / (2.0 * h), within, tol, &mut iters)
            } else {
                self.attempt(h, &mut iters).and_then(|res| {
                    let err = self.estimate(h, per_unit, tol, &mut iters, false)?;
                    Ok((res, err, None))
                })
            };
            // The run's round-off with this step, and the differences its estimates left
            // out as round-off (see `crate::control`): past the tolerance, the step is not
            // taken.
            let (round_off, unresolved) = match &solved {
                Ok((_, err, second)) if *err <= 1.0 => {
                    let st = &self.state;
                    let mut r = self.round_off_sq + tol.round_off_sq((&st.q.sum, &st.p.sum));
                    if let (Some(_), Some(first)) = (second, self.pair.as_ref()) {
                        let st = &first.state;
                        r += tol.round_off_sq((&st.q.sum, &st.p.sum));
                    }
                    (r, self.unresolved + self.unresolved_step)
                }
                _ => (0.0, 0.0),
            };
            let ratio = round_off.sqrt().max(unresolved);
            if ratio > ROUND_OFF_MAX {
                self.state.copy_from(&self.saved);
                return Err(Error::ToleranceBelowRoundOff {
                    t: t0,
                    steps: self.stats.steps,
                    ratio,
                });
            }
            // The tangent (of a sensitivity run) goes through accepted steps only.
            let solved = match solved {
                Ok((res, err, second)) if err <= 1.0 => self.carry().map(|()| (res, err, second)),
                other => other,
            };
            match solved {
                Ok((res, err, second)) => {
                    if err <= 1.0 {
                        self.round_off_sq = round_off;
                        self.unresolved = unresolved;
                        // A pair's estimate is shared by its two steps.
                        self.estimate = match second {
                            Some(_) => err / (span / h),
                            None => err / per_unit,
                        };
                        self.err_last = err;
                        let chosen = self.controller;
                        // The error's trend is followed only where the step resolves the
                        // model's fastest rates (see `crate::control`, "The controller").
                        let asymptotic =
                            h * self.backend.force_gain(h) <= Controller::RESOLVED_RATES;
                        self.h_next = self.controller.accept(h, err, self.resolution, asymptotic);
                        if landing.is_some() && h < planned {
                            // Cut short for an output time: the step the controller planned
                            // stays on offer, and its history stays that of the steps it
                            // chose (the short step's small error would hold the next
                            // step back).
                            self.h_next = self.h_next.max(planned);
                            self.controller = chosen;
                        }
                        // Not after a reading below the estimate's resolution, while the
                        // run's round-off bound is small: the controller lets such a step
                        // grow by at least 1.1 (see `Controller::accept`), which the band
                        // cancelled step after step (a linear model with coordinates of 1e6
                        // and 1e-6 kept its first step of 1e-6 for 10⁷ steps at tol 1e-8 to
                        // 1e-10; now 184 to 245 steps; a free particle over T = 1e10, 343198
                        // steps, now 133). Past half the bound the step is held, as before:
                        // there its readings are noise, and growing on them ended two
                        // constrained pendulums (lobatto3 at 1e-12) at the bound, which the
                        // held steps end within the tolerance. A resolved reading is held
                        // only from the band's share of the steady error on (see
                        // `crate::control`, "The band, for linear models").
                        let steady = self.controller.steady();
                        let kept = self.band.is_some_and(|b| {
                            let resolved = err >= self.resolution && err >= b.settled * steady;
                            (resolved || ratio >= BAND_ROUND_OFF)
                                && (b.lo * h..=b.hi * h).contains(&self.h_next)
                        });
                        if kept {
                            self.h_next = h;
                        }
                        self.t = match (last, landing) {
                            (true, _) => self.t_final,
                            (false, Some(ts)) => ts,
                            (false, None) => t0 + h,
                        };
                        // A pair: its first step is handed out now, its second at the next
                        // call.
                        if let (Some((iters_b, res_b)), Some(first)) = (second, self.pair.as_mut())
                        {
                            std::mem::swap(&mut self.state, &mut first.state);
                            self.pending = Some(Pending {
                                t: t_mid + h,
                                iters: iters_b,
                                residual: res_b,
                            });
                        }
                        self.check_pace(h);
                        return self.finish_step(iters, res, 1);
                    }
                    self.h_next = self.controller.reject(h, err);
                }
                Err(f) if f.is_fatal() => {
                    self.state.copy_from(&self.saved);
                    return Err(self.failure_error(f, t0));
                }
                Err(f) => {
                    last_failure = Some(f);
                    self.h_next = self.controller.reject(h, f64::INFINITY);
                }
            }
            self.stats.rejected_steps += 1;
            self.state.copy_from(&self.saved);
        }
    }

    /// The smallest step a run takes from `t0`: never below the round-off of the clock (a
    /// step that shrank to 0 would be retried without end).
    pub(crate) fn smallest_step(&self, t0: f64) -> f64 {
        (16.0 * f64::EPSILON * t0.abs().max(self.t_final.abs()))
            .max(super::StepOptions::SMALLEST_STEP)
    }

    /// Keeps the largest step of the current window of [`PACE_WINDOW`] steps, with `h` the
    /// step just accepted; at the window's end, counts the windows in a row whose largest
    /// step is smaller than the one before and too small for the rest of the run to fit
    /// under the step cap, and after [`PACE_WINDOWS`] of them marks the run as stalled (see
    /// [`crate::control`], "The pace of a run"): the next step then ends the run.
    fn check_pace(&mut self, h: f64) {
        let pace = &mut self.pace;
        pace.h_max = pace.h_max.max(h);
        let steps = self.stats.steps + 1;
        if steps.is_multiple_of(PACE_WINDOW) {
            let left = self.options.max_steps.saturating_sub(steps);
            let needed = (self.t_final - self.t) / pace.h_max;
            let slow = needed > left as f64 && pace.h_max < pace.h_before;
            pace.slow_windows = if slow { pace.slow_windows + 1 } else { 0 };
            if pace.slow_windows >= PACE_WINDOWS {
                pace.stalled = Some((pace.h_max, needed, left));
            }
            pace.h_before = pace.h_max;
            pace.h_max = 0.0;
        }
    }

    /// The weighted norm, per unit step, of the estimated local error of the step of size
    /// `h` just taken from the saved state: the step polynomial, lifted to the reference
    /// scheme's control points, improved by one Newton iteration of the reference's step
    /// equations; the difference of the two ends in `(q, p)`.
    /// Two steps of size `h` from the saved state, and the estimate of their local error
    /// over both (see [`crate::control`], "Pairs"): the first's residual, the estimate per
    /// unit step of the pair (`per_unit`: the run's length over `2h`), and the second's
    /// Newton iterations and residual. The state is the second's end, and the pair's first
    /// keeps the state at the first's.
    fn attempt_pair(
        &mut self,
        h: f64,
        per_unit: f64,
        within: f64,
        tol: &Tolerance<N>,
        iters: &mut usize,
    ) -> Result<Attempted, StepFailure> {
        let res = self.attempt(h, iters)?;
        let (n, unknowns) = (N, self.backend.z().len());
        let first = self
            .pair
            .get_or_insert_with(|| Box::new(PairFirst::new(n, unknowns)));
        let (s1, lay) = (self.scheme.stages() - 1, self.backend.layout());
        first.z.copy_from_slice(self.backend.z());
        for (a, e) in first.end.iter_mut().enumerate() {
            *e = first.z[lay.at(s1, a)];
        }
        first.dp.copy_from_slice(&self.dp);
        first.size.fill(0.0);
        for (i, &bi) in self.scheme.b().iter().enumerate() {
            for (size, f) in first.size.iter_mut().zip(self.backend.node_fq(i)) {
                *size += (h * bi * f).abs();
            }
        }
        first.rate = self.backend.force_round_off_rate();
        first.time_rate = if M::STRUCTURE.uses_time {
            time_rate(self.scheme.c(), &self.backend, h)
        } else {
            0.0
        };
        first.state.copy_from(&self.state);
        self.backend.solve_within(within);
        let mut iters_b = 0;
        let res_b = self.attempt(h, &mut iters_b);
        *iters += iters_b;
        let res_b = res_b?;
        *iters -= iters_b;
        let err = self.estimate(h, per_unit, tol, iters, true)?;
        Ok((res, err, Some((iters_b, res_b))))
    }

    fn estimate(
        &mut self,
        h: f64,
        per_unit: f64,
        tol: &Tolerance<N>,
        iters: &mut usize,
        paired: bool,
    ) -> Result<f64, StepFailure> {
        self.unresolved_step = 0.0;
        self.resolution = 0.0;
        let Some(reference) = self.reference.as_mut() else {
            return Ok(0.0);
        };
        let cons = self.model.constraint_count();
        // The reference's step: the pair's span, or the step.
        let first = self.pair.as_deref_mut().filter(|_| paired);
        let span = if first.is_some() { 2.0 * h } else { h };
        let st = &self.saved;
        let pmax = st.p.sum.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let scale = pmax.max(span * st.scale_f).max(f64::MIN_POSITIVE);
        // A second correction of carried factors that would change the estimate by at most
        // a hundredth of the tolerance is left out (see `crate::control`).
        let now = (&self.state.q.sum[..], &self.state.p.sum[..]);
        let negligible = tol.uniform_error(per_unit, NEGLIGIBLE, now);
        // Twice at most: with the factors of the last estimate, where they still serve,
        // and with fresh ones if the error they leave is not well below the tolerance.
        for fresh in [false, true] {
            let lifts = (self.lift, self.lift_lambda);
            let mu = if cons > 0 {
                self.backend.end_multipliers()
            } else {
                &[]
            };
            let (lay_r, r1) = (reference.layout(), reference.scheme().stages() - 1);
            let to = (lay_r, r1, reference.z_mut());
            match first.as_deref() {
                Some(f) => lift_pair::<N>(&f.z, self.backend.view(), to, self.pair_lift),
                None => lift_step::<N>(self.backend.view(), mu, to, lifts, cons),
            }
            // Fresh factors take the step's node blocks (see `crate::control`); a pair's
            // reference evaluates its own.
            let carried = !fresh && reference.carry_factors(span, negligible);
            if !carried && !self.block_weights.is_empty() && first.is_none() {
                reference.seed_node_blocks(&self.backend, self.block_weights);
            }
            let now = (&self.state.q.sum[..], &self.state.p.sum[..]);
            let start = (st.t_state, &st.q.sum[..], &st.p.sum[..]);
            let solve = (span, (scale, &st.force[..]), per_unit);
            match solve_reference(reference, start, solve, (tol, now), &mut self.err, iters)? {
                Some(true) => break,
                Some(false) => {}
                // No reference to check the step against: it is retried smaller, as a step
                // that failed its estimate.
                None => return Ok(f64::INFINITY),
            }
        }
        let now = (&self.state.q.sum[..], &self.state.p.sum[..]);
        let of_first = first.map(|f| {
            for ((d, a), b) in f.dp_pair.iter_mut().zip(&f.dp).zip(&self.dp) {
                *d = a + b;
            }
            let of = FirstOfPair {
                end: &f.end,
                size: &f.size,
                rate: f.rate,
                time_rate: f.time_rate,
            };
            (&f.dp_pair[..], of)
        });
        let dp = of_first.map_or(&self.dp[..], |(dp, _)| dp);
        let lhs = (dp, (h, span, st.t_state), per_unit, M::STRUCTURE.uses_time);
        let views = (self.backend.view(), reference.view());
        let (backend, reference) = (&self.backend, &*reference);
        let steps = (
            views,
            (backend as &dyn StepBackend, reference as &dyn StepBackend),
        );
        let of_first = of_first.map(|(_, of)| of);
        let (err, unresolved, resolution) =
            local_error(steps, lhs, of_first, (tol, now), &mut self.err);
        self.unresolved_step = unresolved;
        self.resolution = resolution;
        Ok(err)
    }

    /// The first step of an adaptive run, from the initial data (Hairer, Nørsett & Wanner,
    /// *Solving ODEs I*, II.4), in positions and velocities: with `y = (q, v)` and
    /// `f = (v, a)` (`a` the acceleration) in the weighted norm, `h₀ = 0.01 ‖y‖ / ‖f‖`, an
    /// Euler step of `h₀` to estimate `‖f'‖`, and
    /// `h = min(100 h₀, (0.01 / max(‖f‖, ‖f'‖))^{1/(p+1)})`, within the step bounds; where
    /// `‖y‖` or `‖f‖` is below 1e-5, `h₀ = 1e-6 T` (`T` the run's length).
    ///
    /// In velocities, not momenta: a momentum carries the unit of mass, which the one
    /// absolute tolerance does not (it weighs a position and its momentum alike), so a model
    /// whose masses are large numbers read a large `‖ṗ‖ / atol` and took a tiny `h₀`. An
    /// oscillator with `m = k = 1e15` released from rest, and the Earth around the Sun in SI
    /// units, ended in `StepSizeTooSmall` at `t = 0` (first steps of 5e-16 and 4e-14); the
    /// velocities and accelerations do not depend on the unit of mass. And relative to `T`,
    /// not 1e-6 itself: a run in nanoseconds (`T = 2e10`) from rest at the origin was
    /// refused with a first step of 1e-6, below the clock's resolution `16 ε T`.
    pub(super) fn choose_first_step(&mut self) -> Result<(), Error> {
        let Some(tol) = self.tolerance else {
            return Ok(());
        };
        let span = self.t_final;
        // A run of length zero takes no step, as with fixed steps: only the initial record.
        if span == 0.0 {
            self.n_steps = 0;
            return Ok(());
        }
        let bounds = (self.options.min_step, self.options.max_step);
        let order = self.scheme.order() as f64;
        let tol = (&tol.rtol[..], &tol.atol[..]);
        let h = first_step(&mut self.backend, &self.state, tol, span, bounds, order)?;
        self.h = h;
        self.h_next = h;
        self.state.h_prev = h;
        self.n_steps = step_count(span, h, usize::MAX)?;
        Ok(())
    }
}

/// [`Stepper::choose_first_step`]'s step from the initial state `st`, for a run over
/// `span` with step bounds `(min_step, max_step)` and a scheme of order `p`.
fn first_step(
    backend: &mut dyn StepBackend,
    st: &super::state::State,
    (rtol, atol): (&[f64], &[f64]),
    span: f64,
    (min_step, max_step): (f64, f64),
    p: f64,
) -> Result<f64, Error> {
    let n = st.v.len();
    let (q0, p0, v0) = (&st.q.sum[..], &st.p.sum[..], &st.v[..]);
    let w = |i: usize, y: f64| atol[i] + rtol[i] * y.abs();
    // A zero over a zero weight (a pure relative tolerance on a value at zero) weighs
    // nothing; a value other than zero over one is infinite, and the step starts small.
    let ratio = |x: f64, w: f64| if x == 0.0 { 0.0 } else { x / w };
    let rms = |a: &dyn Fn(usize) -> f64, b: &dyn Fn(usize) -> f64| {
        let sum: f64 = (0..n)
            .map(|i| ratio(a(i), w(i, q0[i])).powi(2) + ratio(b(i), w(i, v0[i])).powi(2))
            .sum();
        (sum / (2 * n).max(1) as f64).sqrt()
    };
    let cap = span.min(max_step);
    // Where the heuristic has nothing to go on (at rest at the origin, or no force).
    let fallback = 1e-6 * span;
    let (mut fq0, mut lv) = (vec![0.0; n], vec![0.0; n]);
    backend.gradient((0.0, q0, v0), &mut fq0, &mut lv)?;
    // The acceleration `E⁻¹ (L_q + F)`, from the velocity of a small change of momentum
    // along `L_q + F` (exact for a Lagrangian quadratic in `v`): a model whose velocity
    // solve fails there starts from the fallback, and the controller goes on from it.
    let mut a0 = vec![0.0; n];
    if acceleration(backend, (0.0, q0, p0, v0), &fq0, fallback, &mut a0).is_err() {
        return bounded(fallback, (cap, min_step), span);
    }
    let d0 = rms(&|i| q0[i], &|i| v0[i]);
    let d1 = rms(&|i| v0[i], &|i| a0[i]);
    let h0 = if d0 < 1e-5 || d1 < 1e-5 || !d1.is_finite() {
        fallback
    } else {
        0.01 * d0 / d1
    }
    .min(cap);
    // One explicit Euler step of h₀: the derivative's rate of change.
    let q1: Vec<f64> = (0..n).map(|i| q0[i] + h0 * v0[i]).collect();
    let p1: Vec<f64> = (0..n).map(|i| p0[i] + h0 * fq0[i]).collect();
    let mut v1: Vec<f64> = (0..n).map(|i| v0[i] + h0 * a0[i]).collect();
    let (mut fq1, mut a1) = (vec![0.0; n], vec![0.0; n]);
    let probe = backend
        .velocity((h0, &q1, &p1), &mut v1, 0)
        .and_then(|()| backend.gradient((h0, &q1, &v1), &mut fq1, &mut lv))
        .and_then(|()| acceleration(backend, (h0, &q1, &p1, &v1), &fq1, fallback, &mut a1));
    let h = match probe {
        Ok(()) => {
            let d2 = rms(&|i| v1[i] - v0[i], &|i| a1[i] - a0[i]) / h0;
            let dmax = d1.max(d2);
            let h1 = if dmax <= 1e-15 || !dmax.is_finite() {
                (h0 * 1e-3).max(fallback)
            } else {
                (0.01 / dmax).powf(1.0 / (p + 1.0))
            };
            (100.0 * h0).min(h1)
        }
        // The probe left the model's domain: start from h₀ and let the controller go on.
        Err(_) => h0,
    };
    bounded(h, (cap, min_step), span)
}

/// `h` within `[min_step, cap]`; a step that is not finite or below the clock's resolution
/// over `span` is a typed error.
fn bounded(h: f64, (cap, min_step): (f64, f64), span: f64) -> Result<f64, Error> {
    let h = h.min(cap).max(min_step);
    if !(h.is_finite() && h > 16.0 * f64::EPSILON * span) {
        return Err(Error::StepSizeTooSmall { t: 0.0, h });
    }
    Ok(h)
}

/// The acceleration `E⁻¹ f` at `(t, q)` with momentum `p` and velocity `v` there, `f` the
/// rate of the momentum (`L_q + F`), into `a`: the change of velocity that a change
/// `δ f` of the momentum makes, over `δ`, with `δ = fallback` (a time, small next to the
/// run's length).
fn acceleration(
    backend: &mut dyn StepBackend,
    (t, q, p, v): (f64, &[f64], &[f64], &[f64]),
    f: &[f64],
    delta: f64,
    a: &mut [f64],
) -> Result<(), Error> {
    let moved: Vec<f64> = p.iter().zip(f).map(|(p, f)| p + delta * f).collect();
    a.copy_from_slice(v);
    backend.velocity((t, q, &moved), a, 0)?;
    for (x, v) in a.iter_mut().zip(v) {
        *x = (*x - v) / delta;
    }
    Ok(())
}

/// Lifts the step polynomial of the step in `from` to the control points of the reference
/// scheme, into `(lay_r, r1, zr)` (its layout, its stages less one, its unknowns): the
/// increments by `lift` (row `j − 1`: `ℓ_m(d'_j)`) and, for a constrained model, the
/// multipliers by `lift_lambda`, with `mu` those at the step's end.
#[inline(always)]
fn lift_step<const N: usize>(
    from: StepView<'_>,
    mu: &[f64],
    (lay_r, r1, zr): (Layout, usize, &mut [f64]),
    (lift, lift_lambda): (&[f64], &[f64]),
    cons: usize,
) {
    let (s1, lay, z) = (from.scheme.stages() - 1, from.layout, from.z);
    // By strides: `(m, a)` of the step at `a·ca + (m − 1)·cm`, `(j, a)` of the reference at
    // `a·ra + (j − 1)·rm` (indexing each through `Layout::at` cost three times the sums).
    let ((ca, cm), (ra, rm)) = (lay.strides(), lay_r.strides());
    for (j, row) in lift.chunks_exact(s1).take(r1).enumerate() {
        for a in 0..N {
            let stages = z[a * ca..].iter().step_by(cm);
            zr[a * ra + j * rm] = row.iter().zip(stages).map(|(w, x)| w * x).sum();
        }
    }
    // A constrained model: the multipliers, interpolated in time from the step's
    // (`λ_0 … λ_{s−2}` in `z`, `λ_{s−1}` at its end) to the reference's control points.
    if cons > 0 {
        let s = s1 + 1;
        for j in 0..r1 {
            let row = &lift_lambda[j * s..(j + 1) * s];
            for k in 0..cons {
                let at = |m: usize| {
                    if m + 1 < s {
                        z[lay.multiplier(m, k)]
                    } else {
                        mu.get(k).copied().unwrap_or(0.0)
                    }
                };
                zr[lay_r.multiplier(j, k)] = (0..s).map(|m| row[m] * at(m)).sum();
            }
        }
    }
}

/// Lifts a pair of steps of one size, the first's increments `first_z` and the second in
/// `second` (increments from the first's end), to the control points of a reference step
/// over both, into `(lay_r, r1, zr)`: each point on the polynomial of the step it falls in
/// (`pair`: [`crate::scheme`]'s `pair_lift` and `pair_second`), the second's added to the
/// first's end.
#[inline(always)]
fn lift_pair<const N: usize>(
    first_z: &[f64],
    second: StepView<'_>,
    (lay_r, r1, zr): (Layout, usize, &mut [f64]),
    (lift, in_second): (&[f64], &[bool]),
) {
    let (s1, lay, z) = (second.scheme.stages() - 1, second.layout, second.z);
    let ((ca, cm), (ra, rm)) = (lay.strides(), lay_r.strides());
    for (j, (row, &later)) in lift.chunks_exact(s1).zip(in_second).take(r1).enumerate() {
        for a in 0..N {
            let (from, base) = match later {
                true => (z, first_z[lay.at(s1, a)]),
                false => (first_z, 0.0),
            };
            let stages = from[a * ca..].iter().step_by(cm);
            zr[a * ra + j * rm] = base + row.iter().zip(stages).map(|(w, x)| w * x).sum::<f64>();
        }
    }
}

/// The reference's solve (one iteration, more where it does not land) from `start = (t0,
/// q0, p0)`, `solve = (h, scale, per_unit)`; counts its iterations in `iters`. Returns
/// `Some(false)` if the factors it carried left an error above a tenth of the tolerance at
/// the step's end `now` (they are then refused, and the estimate must be made again), and
/// `None` if its iterations did not land; `err` is scratch.
fn solve_reference<const N: usize>(
    reference: &mut dyn StepBackend,
    (t0, q0, p0): (f64, &[f64], &[f64]),
    (h, scale, per_unit): (f64, (f64, &[f64]), f64),
    (tol, now): (&Tolerance<N>, (&[f64], &[f64])),
    err: &mut (Vec<f64>, Vec<f64>),
    iters: &mut usize,
) -> Result<Option<bool>, StepFailure> {
    let mut before = f64::INFINITY;
    for _ in 0..=REFERENCE_ROUNDS {
        match reference.solve(h, t0, (q0, p0), scale) {
            Ok(rep) => *iters += rep.iterations,
            // One iteration is what the estimate asks for (its options cap it there).
            Err(StepFailure::Newton(NewtonFailure::MaxIterations { .. })) => {
                *iters += reference.last_iterations()
            }
            Err(f) => {
                *iters += reference.last_iterations();
                return Err(f);
            }
        }
        // The carried factors' error, as an error in every position and momentum: at most
        // a tenth of the tolerance, or the estimate is made again with fresh factors.
        let left = reference.carried_error();
        if left > 0.0 {
            err.0.fill(left);
            err.1.fill(left);
            if tol.error_norm(per_unit, (&err.0, &err.1), now) > 0.1 {
                reference.reject_carry();
                return Ok(Some(false));
            }
            return Ok(Some(true));
        }
        // With fresh factors, one iteration from the lifted step is the reference to second
        // order where the step equations are smooth: the correction that would follow is
        // then far smaller than the one made, or the residual is at its round-off. Where
        // neither holds and the correction matters to the tolerance (a force that jumps
        // between the nodes of the step and of the reference; see `crate::control`,
        // "Forces that jump"), the reference iterates on while its corrections shrink; one
        // that does not settle leaves the step unchecked, and the step is retried smaller.
        let (next, made, at_floor) = reference.next_correction();
        err.0.fill(next);
        err.1.fill(next);
        if at_floor
            || next <= CONTRACTION * made
            || tol.error_norm(per_unit, (&err.0, &err.1), now) <= 0.1
        {
            return Ok(Some(true));
        }
        if next >= CONTRACTION * before {
            break;
        }
        before = next;
    }
    Ok(None)
}

/// The further iterations the reference may take when its first one does not land (see
/// [`solve_reference`]), and the contraction below which a correction counts as landed.
const REFERENCE_ROUNDS: usize = 3;
const CONTRACTION: f64 = 0.25;

/// The largest rate of change in time of `L_q + F` between neighbouring quadrature nodes
/// (`c`, on `[0, 1]`) of the step of size `h` in `backend`: a stand-in for `|∂ₜ(L_q + F)|`
/// that also holds the change the motion makes over the step (which the position and
/// velocity terms count as well), so it errs on the large side.
fn time_rate(c: &[f64], backend: &dyn StepBackend, h: f64) -> f64 {
    let mut rate = 0.0f64;
    for i in 1..c.len() {
        let dt = (c[i] - c[i - 1]).abs() * h;
        if dt > 0.0 {
            let (a, b) = (backend.node_fq(i - 1), backend.node_fq(i));
            for (x, y) in a.iter().zip(b) {
                rate = rate.max((y - x).abs() / dt);
            }
        }
    }
    rate
}

/// The weighted norm, per unit step, of the difference between the step in `backend` and
/// the reference's in `reference`, at their ends in `(q, p)`; `dp` is the step's momentum
/// update and `err` is scratch for the difference. Also returns what the comparison left
/// out as round-off, in the tolerance's norm (not per unit step; see [`crate::control`]),
/// and the estimate's resolution: the norm per unit step of its noise bounds, the
/// reading of a step whose every difference were at its bound. `timed`: the model depends
/// on time.
#[inline(always)]
fn local_error<const N: usize>(
    ((view, view_r), (backend, reference)): (StepViews<'_>, (&dyn StepBackend, &dyn StepBackend)),
    (dp, (h, span, t0), per_unit, timed): (&[f64], (f64, f64, f64), f64, bool),
    first: Option<FirstOfPair<'_>>,
    (tol, now): (&Tolerance<N>, (&[f64], &[f64])),
    err: &mut (Vec<f64>, Vec<f64>),
) -> (f64, f64, f64) {
    let (s1, lay, z) = (view.scheme.stages() - 1, view.layout, view.z);
    let (r1, lay_r, zr) = (view_r.scheme.stages() - 1, view_r.layout, view_r.z);
    // The differences in the first `N` entries of each buffer, what is cut from them in the
    // next `N`.
    let ((eq, cq), (ep, cp)) = (err.0.split_at_mut(N), err.1.split_at_mut(N));
    // Each difference less the round-off of the sums it compares (4ε of their terms'
    // sizes): noise that smaller steps do not reduce must not count as error per unit
    // step, or the step size would shrink without end.
    let noise = 4.0 * f64::EPSILON;
    // A constrained step's end multiplier balances the momentum `p₀ + …` and its end
    // position meets `g(q₀ + z) = 0`: both are resolved to the round-off of `p₀` and `q₀`,
    // which are among the terms compared; and of all their components, since the
    // constraint gradients spread the multipliers' round-off over every coordinate.
    let impulse = reference.constraint_impulse();
    let (_, _, q0, p0) = backend.step_data();
    let largest = |x: &[f64]| x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let (q0_size, p0_size) = match impulse {
        Some(_) => (largest(q0), largest(p0)),
        None => (0.0, 0.0),
    };
    // The momenta: `dp` less the reference's `h Σ_i b_i (L_q + F)_i`, less its constraint
    // impulse, and the sizes of the terms (in `eq` until the positions are compared), node
    // by node. Each force also carries the rounding of the position, velocity and time it
    // is evaluated at, `(|A| |x| + |B| |v| + |∂ₜ(L_q + F)| |t|) ε`, which its size alone
    // leaves out: where the forces are steep, that is what the two sums differ by once the
    // step is small (see `crate::control`, "Steep forces").
    let (b, rs) = (view.scheme.b(), view_r.scheme);
    ep.copy_from_slice(&dp[..N]);
    let mut rate = backend.force_round_off_rate();
    if let Some(f) = first {
        rate = rate.max(f.rate);
    }
    if timed {
        let t_size = t0.abs().max((t0 + span).abs());
        let mut r = time_rate(view.scheme.c(), backend, h).max(time_rate(rs.c(), reference, span));
        if let Some(f) = first {
            r = r.max(f.time_rate);
        }
        rate += t_size * r;
    }
    eq.fill(p0_size + span * rate);
    if let Some(f) = first {
        for (e, s) in eq.iter_mut().zip(f.size) {
            *e += s;
        }
    }
    for (i, &bi) in b.iter().enumerate() {
        for (size, f) in eq.iter_mut().zip(backend.node_fq(i)) {
            *size += (h * bi * f).abs();
        }
    }
    for (i, &bi) in rs.b().iter().enumerate() {
        let fq = reference.node_fq(i);
        for ((d, size), f) in ep.iter_mut().zip(eq.iter_mut()).zip(fq) {
            let t = span * bi * f;
            *d -= t;
            *size += t.abs();
        }
    }
    if let Some(imp) = impulse {
        for ((d, size), i) in ep.iter_mut().zip(eq.iter_mut()).zip(imp) {
            *d += i;
            *size += i.abs();
        }
    }
    // The noise bounds first (their norm per unit step is the estimate's resolution), then
    // what each difference loses to them.
    for ((d, c), size) in ep.iter_mut().zip(cp.iter_mut()).zip(eq.iter()) {
        *c = noise * size;
        *d = d.abs();
    }
    for (a, (e, c)) in eq.iter_mut().zip(cq.iter_mut()).enumerate() {
        let (x, y) = (z[lay.at(s1, a)], zr[lay_r.at(r1, a)]);
        let xa = first.map_or(0.0, |f| f.end[a]);
        *c = noise * (xa.abs() + x.abs() + y.abs() + q0_size);
        *e = (xa + x - y).abs();
    }
    let (cq, cp) = (&mut cq[..N], &mut cp[..N]);
    let resolution = tol.error_norm(per_unit, (cq, cp), now);
    for (e, c) in eq
        .iter_mut()
        .chain(ep.iter_mut())
        .zip(cq.iter_mut().chain(cp.iter_mut()))
    {
        *c = e.min(*c);
        *e -= *c;
    }
    let (err, unresolved) = tol.error_and_cut_norms(per_unit, (eq, ep), (cq, cp), now);
    (err, unresolved, resolution)
}
