//! Tolerance proportionality on models the controller was not tuned on:
//! `cargo run --release --example tolerance_sweep`.
//!
//! Forty-two small forced models, none of them a report scene, each run adaptively with
//! lobatto3–7 and with `Integrator::auto` at `rtol = atol = tol` for tol = 1e-3 … 1e-12:
//! nine the controller was measured on when it was last changed, three that amplify errors
//! over the run (the eccentric Kepler orbit over two lengths), added after that change, and
//! a held-out set of ten added on 2026-11-29 with no change to the controller (a Rayleigh
//! oscillator, two coupled oscillators of frequencies 1 and 12, a bead on a rotating hoop, a
//! spherical pendulum, an over-damped oscillator, an oscillator of amplitude 1000, a Morse
//! oscillator, a linear oscillator driven near resonance, a Kepler orbit of eccentricity
//! about 0.8, a double well), and a second held-out set of five of kinds the others lack,
//! added later that day, again with no change to the controller (a pendulum whose gravity
//! oscillates, two unequal masses joined by a damper, a charge in a magnetic field driven by
//! an electric one with quadratic drag, a relativistic oscillator, a softened Kepler
//! potential), and a third held-out set of five, added on 2026-11-30, again with no change
//! to the controller (a heavy symmetric top in Euler angles, an FPU chain of eight masses
//! written with the macro, the Caldirola–Kanai oscillator, smoothed dry friction, a
//! pendulum on a pushed cart), and a fourth held-out set of five, added later that day, again
//! with no change to the controller (a particle bouncing off a Lennard-Jones wall, two masses
//! on a spring of 10⁴, a slow oscillator over T = 10⁴, a purely quartic well, a
//! Lennard-Jones pair in the plane), and the fifth set of `tests/held_out.rs`. The final
//! error in `q` (max-norm) is taken against fixed-step lobatto7 at `h = 2e-3`, checked
//! against lobatto6 at `h = 1e-3`. A sweep's slope is the
//! least-squares slope of log(error) against log(tol) over its runs of at least 4 steps
//! whose error is above `1e-13 · max(1, |q_ref|)`, as in the report. The last lines count
//! the slopes outside 0.8–1.2 (issue 23's target), for each held-out set and for all, and
//! give the largest final error over its tolerance.
//!
//! Measured on 2026-11-29: 168 sweeps, 5 slopes outside 0.8–1.2, the largest final error
//! 7.83 times the tolerance. In the held-out set, 3 of its 60 slopes are outside, all on
//! the over-damped oscillator (lobatto6 0.57, lobatto7 0.32, `auto` 0.70), and its largest
//! final error is 1.87 times the tolerance (the double well, lobatto5 at 1e-3). There those
//! runs take 6 to 23 steps and end 1e-9 to 1e-3 times the tolerance off: each step's
//! estimate matches its local error (traced for lobatto7 at 1e-3: 1.1e-4 of the tolerance
//! against 1.2e-4), but the flow damps the errors (its modes decay as e^(−0.38 t) and
//! e^(−2.6 t)), so the final error is what the last few steps leave, and their sizes move in
//! jumps as the tolerance changes. In the second held-out set, 1 of its 30 slopes is outside
//! (the relativistic oscillator's lobatto7, 0.78: its runs at the looser tolerances take 15
//! to 20 steps and end far below the tolerance), and its largest final error is 1.98 times
//! the tolerance (the softened Kepler potential, lobatto7 at 1e-4). `tests/held_out.rs`
//! checks this set on every test run, against 30-digit references of its equations of motion
//! (`scripts/held_out_reference.py`) and in positions and momenta: there every run ends
//! within 10 times the tolerance and every slope lies in 0.84–1.18.
//!
//! The third held-out set, measured on 2026-11-30 when it was added: 30 sweeps, 3 slopes
//! outside 0.8–1.2 (the FPU chain's lobatto6 at 1.20, the dry friction's `auto` at 0.76,
//! whose runs end 6e-5 to 1e-2 times the tolerance off, and the cart's lobatto3 at 1.22,
//! whose errors fall from 0.3 to 0.007 times the tolerance as it tightens), and a largest
//! final error of 0.70 times the tolerance (the cart, lobatto5 at 1e-12). No run failed.
//! On the FPU chain it showed that `auto` took lobatto4 on every model of the sparse
//! backend: 5072 steps over the sweep, 1.2–14.7 times the cheapest scheme's time; with
//! `Scheme::AUTO_SPARSE_MIN_DOF` it takes the dense column's order there (450 steps).
//!
//! `tests/held_out.rs` checks the third set too, in positions and momenta against references
//! from its equations of motion (`scripts/held_out_reference_third.py`): every run within 0.78
//! times the tolerance, and 29 of its 30 slopes in 0.83–1.17; the cart's lobatto3 reads
//! 1.2005 there (its error changes sign as the tolerance tightens).
//!
//! The fourth held-out set, measured when it was added: 30 sweeps, none of its slopes
//! outside 0.8–1.2, and a largest final error of 4.67 times the tolerance (the
//! Lennard-Jones pair, lobatto4; its orbit amplifies errors as the Kepler ones do). On the
//! two masses on a stiff spring, lobatto3–5, lobatto7 and `auto` (lobatto8) end their runs at
//! 1e-12 in `ToleranceBelowRoundOff`, where lobatto6 ends `Ok` 0.02 times the tolerance
//! off: each step's momentum comparison leaves out the spring's rounding,
//! `4 ε h |A| |x|` with `|A| = 2·10⁴`, about 0.02–0.04 of the tolerance per step at 1e-12,
//! and the run adds those up plainly (see `forced_vi::control`, "What the estimates leave
//! out"); the larger steps of the higher orders leave out more per step.
//! `tests/held_out.rs` checks the fourth set too, in positions and momenta against
//! references from its equations of motion (`scripts/held_out_reference_fourth.py`); there
//! the Lennard-Jones pair's momentum ends up to 13.72 times the tolerance off (its flow
//! amplifies a perturbation of the initial state 112-fold), the wall's 10.35 times (61-fold).
//!
//! The fifth held-out set, of `tests/held_out.rs` (a swinging Atwood machine, a triple
//! pendulum, a charge in a Penning trap, a particle pulled over a washboard to x = 300, an
//! oscillator about x = 10⁴), measured when it was added (2026-11-30, no change to the
//! controller): 30 sweeps, largest final error 0.44 times the tolerance, 3 slopes outside
//! 0.8–1.2: the washboard's lobatto3 (1.28; its errors are at most 0.01 of the tolerance of
//! `max(1, |q|) = 300`) and the far oscillator's lobatto4 and lobatto7 (0.71, 0.65). The
//! latter read errors at that oscillator's round-off: its force is evaluated at a position
//! rounded to `10⁴ ε`, and `tests/held_out.rs`, which leaves out the tolerances below that
//! floor, reads 0.797 and 1.03 there. On it, lobatto3–5 end at 1e-11 or 1e-12 in
//! `ToleranceBelowRoundOff`. Over all 258 sweeps, the same day: 9 slopes outside 0.8–1.2,
//! mean |slope − 1| 0.066, largest final error 7.78 times the tolerance.
//!
//! Last, `auto` is timed against each scheme on every model at tol 1e-4, 1e-7 and 1e-10
//! (medians of 5 rotated rounds, each timed run right after an untimed one of itself), and
//! its time is divided by the cheapest scheme's whose final error is within 10·tol.
//! Measured on 2026-11-30 over the 114 pairs, with `auto` switching to lobatto8 at 10⁻⁹:
//! 0.91 to 1.93, median 1.06, above 1.5 in 5; `auto` against the same scheme run beside it,
//! the same computation, read 0.84 to 1.58, the timing's noise. Beyond that noise: the two
//! masses on a stiff spring, where lobatto7 and lobatto8 take about half of lobatto6's time
//! at 1e-4 and 1e-7 (1.93 and 1.92; they resolve its fast mode in fewer steps), the quartic
//! well at 1e-7 (1.64) and the dry friction at 1e-4 (1.52). With the switch moved to 10⁻⁷
//! (`Scheme::for_tolerance`), in the same session: 0.86 to 1.80, median 1.03, above 1.5 in
//! 3 (the noise 0.76 to 1.46), the stiff pair at 1e-4 (1.80, lobatto7 the cheapest) the one
//! beyond the noise; and 6 of the 228 slopes outside 0.8–1.2 instead of 8 (the over-damped
//! oscillator's `auto` and the dry friction's are now inside). The first 99 pairs, measured
//! before the fourth set was added: 0.85 to 1.45, median 1.04. With the fifth set, 129
//! pairs, later the same day: 0.80 to 2.33, median 1.05, above 1.5 in 3 (the noise 0.68 to
//! 1.69): the stiff pair at 1e-4 (2.33, lobatto7 the cheapest) the one beyond the noise; on
//! the fifth set's 15 pairs, 0.80 to 1.41.
//!
//! With the error estimated over pairs of steps by default on the dense path (2026-12-02,
//! `forced_vi::control`, "Pairs"; lobatto3 takes them here, the higher orders and `auto`'s
//! choices do not): lobatto3's 43 sweeps had no slope outside 0.8–1.2 and a largest final
//! error of 3.01 times the tolerance (the slow oscillator over T = 10⁴). Before lobatto4
//! was left out of pairs, the same sweep read its Lennard-Jones pair (fourth set) at up to
//! 20.99 times the tolerance, against 4.67 with one estimate per step.
use forced_vi::prelude::*;

/// A pendulum with linear drag.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot + x.cos(),
    force(x = -0.3 * x_dot)
)]
struct Pendulum {}

/// A driven, damped hardening Duffing oscillator (not chaotic at this forcing).
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x - 0.25 * x * x * x * x,
    force(x = -0.2 * x_dot + 0.5 * (1.2 * t).cos())
)]
struct Duffing {}

/// A van der Pol oscillator, μ = 3.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x,
    force(x = 3.0 * (1.0 - x * x) * x_dot)
)]
struct VanDerPol {}

/// Hénon–Heiles with weak drag.
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) - 0.5 * (x * x + y * y) - x * x * y
        + y * y * y / 3.0,
    force(x = -0.05 * x_dot, y = -0.05 * y_dot)
)]
struct HenonHeiles {}

/// An elastic pendulum in polar coordinates with drag.
#[forced_lagrangian(
    coordinates(r, th),
    lagrangian = 0.5 * (r_dot * r_dot + r * r * th_dot * th_dot) + 9.81 * r * th.cos()
        - 20.0 * (r - 1.0) * (r - 1.0),
    force(r = -0.1 * r_dot, th = -0.1 * th_dot)
)]
struct Elastic {}

/// A charge in a uniform magnetic field and a harmonic trap, with drag (a gyroscopic term).
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) + (x * y_dot - y * x_dot)
        - 0.25 * (x * x + y * y),
    force(x = -0.1 * x_dot, y = -0.1 * y_dot)
)]
struct Magnetic {}

/// A periodic Toda lattice of three particles with drag.
#[forced_lagrangian(
    coordinates(a, b, c),
    lagrangian = 0.5 * (a_dot * a_dot + b_dot * b_dot + c_dot * c_dot)
        - (a - b).exp()
        - (b - c).exp()
        - (c - a).exp(),
    force(a = -0.05 * a_dot, b = -0.05 * b_dot, c = -0.05 * c_dot)
)]
struct Toda {}

/// A pendulum driven by a periodic torque.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot + 4.0 * x.cos(),
    force(x = -0.1 * x_dot + 1.5 * (0.7 * t).sin())
)]
struct DrivenPendulum {}

/// Two coupled nonlinear springs with quadratic drag.
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot)
        - 0.5 * (x * x + 4.0 * y * y)
        - 0.3 * x * x * y * y,
    force(
        x = -0.2 * x_dot * (x_dot * x_dot + y_dot * y_dot).sqrt(),
        y = -0.2 * y_dot * (x_dot * x_dot + y_dot * y_dot + 1e-3).sqrt()
    )
)]
struct QuadraticDrag {}

/// A Kepler orbit of eccentricity 0.56 with weak drag: a perturbation of its period grows
/// linearly, so the orbit amplifies errors over the run (three orbits, and nine).
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) + 1.0 / (x * x + y * y).sqrt(),
    force(x = -0.001 * x_dot, y = -0.001 * y_dot)
)]
struct EccentricKepler {}

/// A pendulum started near its separatrix (3 rad), light drag: its period depends steeply
/// on its energy.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot + x.cos(),
    force(x = -0.01 * x_dot)
)]
struct NearSeparatrix {}

/// An undriven hardening Duffing oscillator with weak drag, amplitude 1.5: its frequency
/// depends on its amplitude.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x - 0.5 * x * x * x * x,
    force(x = -0.01 * x_dot)
)]
struct HardeningDuffing {}

/// A Rayleigh oscillator, self-excited through its velocity (held-out set of 2026-11-29).
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x,
    force(x = (1.0 - x_dot * x_dot / 3.0) * x_dot)
)]
struct Rayleigh {}

/// Two oscillators of frequencies 1 and 12, weakly coupled, light drag.
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) - 0.5 * x * x - 72.0 * y * y - 0.3 * x * y,
    force(x = -0.02 * x_dot, y = -0.02 * y_dot)
)]
struct TwoScale {}

/// A bead on a rotating hoop, with drag.
#[forced_lagrangian(
    coordinates(th),
    lagrangian = 0.5 * th_dot * th_dot + 2.0 * th.sin() * th.sin() + 2.0 * th.cos(),
    force(th = -0.1 * th_dot)
)]
struct Hoop {}

/// A spherical pendulum with light drag: a mass matrix that depends on the position.
#[forced_lagrangian(
    coordinates(th, ph),
    lagrangian = 0.5 * (th_dot * th_dot + th.sin() * th.sin() * ph_dot * ph_dot) + 3.0 * th.cos(),
    force(th = -0.05 * th_dot, ph = -0.05 * ph_dot)
)]
struct Spherical {}

/// A heavily damped (over-damped) nonlinear oscillator, not stiff: c = 3.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x - 0.1 * x * x * x * x,
    force(x = -3.0 * x_dot)
)]
struct Overdamped {}

/// An oscillator of amplitude 1000 with a weak cubic term: relative tolerances at work.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x - 1e-7 * x * x * x * x,
    force(x = -0.05 * x_dot)
)]
struct BigScale {}

/// A Morse oscillator with drag.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - (1.0 - (-x).exp()) * (1.0 - (-x).exp()),
    force(x = -0.05 * x_dot)
)]
struct Morse {}

/// A linear oscillator driven near resonance, from rest.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x,
    force(x = -0.05 * x_dot + (0.95 * t).cos())
)]
struct Resonance {}

/// A Kepler orbit of eccentricity about 0.8 with weak drag.
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) + 1.0 / (x * x + y * y).sqrt(),
    force(x = -0.002 * x_dot, y = -0.002 * y_dot)
)]
struct Kepler08 {}

/// A double well with drag, started over the barrier.
#[forced_lagrangian(
    coordinates(x),
    lagrangian = 0.5 * x_dot * x_dot + 0.5 * x * x - 0.25 * x * x * x * x,
    force(x = -0.1 * x_dot)
)]
struct DoubleWell {}

// The second held-out set (shared with `tests/held_out.rs`).
#[path = "../tests/held_out_models.rs"]
mod held_out_models;
use held_out_models::{Lorentz, Parametric, Relativistic, SoftKepler, TwoMass};
// The third held-out set.
#[path = "../tests/held_out_models_third.rs"]
mod held_out_models_third;
use held_out_models_third::{CaldirolaKanai, CartPendulum, DryFriction, FpuChain, HeavyTop};
// The fourth held-out set (shared with `tests/held_out.rs`).
#[path = "../tests/held_out_models_fourth.rs"]
mod held_out_models_fourth;
use held_out_models_fourth::{LjDimer, LjWall, Quartic, Slow, StiffPair};
// The fifth held-out set (shared with `tests/held_out.rs`).
#[path = "../tests/held_out_models_fifth.rs"]
mod held_out_models_fifth;
use held_out_models_fifth::{
    FarOscillator, PenningTrap, SwingingAtwood, TriplePendulum, Washboard,
};

/// One sweep's summary.
struct Sweep {
    slope: Option<f64>,
    worst: f64,
    /// Accepted and rejected steps over the sweep's runs.
    steps: usize,
    rejected: usize,
    /// For `auto` (`None` for the schemes), at each tolerance of [`AUTO_TOLS`]: its time over
    /// the cheapest scheme's whose final error is within 10·tol, and over the time of the
    /// scheme it chose, run apart in the same rounds (the same computation: the timing's
    /// noise).
    auto_cost: Option<Vec<(f64, f64)>>,
}

/// The tolerances at which `auto` is timed against every scheme.
const AUTO_TOLS: [f64; 3] = [1e-4, 1e-7, 1e-10];

/// `auto`'s time over the cheapest scheme's and over its own scheme's, the stages it chose
/// and the cheapest scheme's.
type AutoCost = ((f64, f64), usize, usize);

/// Rounds of the timing of `auto` against the schemes; each round runs lobatto3–8 and `auto`
/// one after the other, starting one further along than the round before, each timed run
/// right after an untimed run of itself.
const ROUNDS: usize = 5;

/// `auto`'s time over the cheapest of lobatto3–8 whose final error in `q` (relative to
/// `scale`) is within 10·tol, at `tol`, and over its own scheme's: medians over [`ROUNDS`]
/// rotated rounds. Also returns the stages it chose and the cheapest scheme's.
fn auto_cost<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    (init, t_final): (InitialState<N>, f64),
    (q_ref, scale): (&[f64], f64),
    tol: f64,
) -> Result<AutoCost, Box<dyn std::error::Error>> {
    let mut runs = Vec::new();
    for s in 3..=8 {
        runs.push(Integrator::adaptive(model, Scheme::lobatto(s)?, tol, tol)?);
    }
    runs.push(Integrator::auto(model, tol, tol)?);
    let mut times = vec![Vec::new(); runs.len()];
    let mut within = vec![false; runs.len()];
    for round in 0..ROUNDS {
        for k in 0..runs.len() {
            let i = (k + round) % runs.len();
            // Each timed run follows a run of itself (the runs before it would leave the
            // caches warm for some and not for others).
            let _ = runs[i].final_state(init, t_final);
            let start = std::time::Instant::now();
            let end = runs[i].final_state(init, t_final);
            times[i].push(start.elapsed().as_secs_f64());
            if let Ok(end) = end {
                within[i] = max_diff::<N>(end.q.as_slice(), q_ref) <= 10.0 * tol * scale;
            }
        }
    }
    let median = |t: &mut Vec<f64>| {
        t.sort_by(f64::total_cmp);
        t[t.len() / 2]
    };
    let medians: Vec<f64> = times.iter_mut().map(median).collect();
    let best = (0..runs.len() - 1)
        .filter(|&i| within[i])
        .min_by(|&a, &b| medians[a].total_cmp(&medians[b]))
        .ok_or("no scheme within 10 tol")?;
    let auto = runs.len() - 1;
    let chose = runs[auto].scheme().stages();
    let own = medians[auto] / medians[chose.clamp(3, 8) - 3];
    Ok(((medians[auto] / medians[best], own), chose, best + 3))
}

/// Prints a set's sweeps, its slopes outside 0.8–1.2 and its largest final error.
fn summarise(label: &str, set: &[Sweep]) {
    let slopes: Vec<f64> = set.iter().filter_map(|s| s.slope).collect();
    let out: Vec<String> = slopes
        .iter()
        .filter(|k| !(0.8..=1.2).contains(*k))
        .map(|k| format!("{k:.2}"))
        .collect();
    let worst = set.iter().map(|s| s.worst).fold(0.0, f64::max);
    println!(
        "{label}: {} sweeps, {} slopes outside 0.8–1.2 ({}); largest final error {worst:.2} tol",
        slopes.len(),
        out.len(),
        out.join(", ")
    );
}

/// The least-squares slope of `ln y` against `ln x`.
fn slope(pts: &[(f64, f64)]) -> Option<f64> {
    if pts.len() < 2 {
        return None;
    }
    let n = pts.len() as f64;
    let mx = pts.iter().map(|p| p.0.ln()).sum::<f64>() / n;
    let my = pts.iter().map(|p| p.1.ln()).sum::<f64>() / n;
    let sxy: f64 = pts.iter().map(|p| (p.0.ln() - mx) * (p.1.ln() - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0.ln() - mx).powi(2)).sum();
    Some(sxy / sxx)
}

fn max_diff<const N: usize>(a: &[f64], b: &[f64]) -> f64 {
    (0..N).map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max)
}

fn sweep_model<M: ForcedLagrangian<N>, const N: usize>(
    name: &str,
    model: &M,
    init: InitialState<N>,
    t_final: f64,
    out: &mut Vec<Sweep>,
) -> Result<(), Box<dyn std::error::Error>> {
    let reference = Integrator::new(model, Scheme::lobatto(7)?, 2e-3)?
        .final_state(init, t_final)
        .map_err(|f| f.error)?;
    let check = Integrator::new(model, Scheme::lobatto(6)?, 1e-3)?
        .final_state(init, t_final)
        .map_err(|f| f.error)?;
    let scale = reference.q.iter().fold(1.0f64, |m, x| m.max(x.abs()));
    let agree = max_diff::<N>(reference.q.as_slice(), check.q.as_slice());
    println!("{name}: T = {t_final}, reference checked to {agree:.1e}");
    for s in (3..=8).map(|s| if s == 8 { None } else { Some(s) }) {
        let (mut pts, mut worst, mut steps, mut rejected) = (Vec::new(), 0.0f64, 0, 0);
        let mut line = String::new();
        for k in 3..=12 {
            let tol = 10f64.powi(-k);
            let integ = match s {
                Some(s) => Integrator::adaptive(model, Scheme::lobatto(s)?, tol, tol)?,
                None => Integrator::auto(model, tol, tol)?,
            };
            match integ.final_state(init, t_final) {
                Ok(end) => {
                    let err = max_diff::<N>(end.q.as_slice(), reference.q.as_slice());
                    worst = worst.max(err / tol / scale);
                    steps += end.stats.steps;
                    rejected += end.stats.rejected_steps;
                    if end.stats.steps >= 4 && err > 1e-13 * scale {
                        pts.push((tol, err));
                    }
                    line += &format!(" {:.0e}", err / tol);
                }
                Err(f) => line += &format!(" [{}]", f.error),
            }
        }
        let k = slope(&pts);
        let label = s.map_or("auto".to_string(), |s| format!("lobatto{s}"));
        println!(
            "  {label:9} slope {} over {} runs, worst err/tol {worst:.2}, {steps} steps, {rejected} rejected; err/tol:{line}",
            k.map_or("–".into(), |k| format!("{k:.2}")),
            pts.len(),
        );
        let auto_cost = match s {
            Some(_) => None,
            None => {
                let mut ratios = Vec::new();
                let mut line = String::new();
                for tol in AUTO_TOLS {
                    let (r, chose, best) =
                        auto_cost(model, (init, t_final), (reference.q.as_slice(), scale), tol)?;
                    line += &format!(
                        " {tol:.0e}: lobatto{chose} {:.2} (lobatto{best}; own {:.2})",
                        r.0, r.1
                    );
                    ratios.push(r);
                }
                println!("  auto's time over the cheapest scheme's:{line}");
                Some(ratios)
            }
        };
        out.push(Sweep {
            slope: k,
            worst,
            steps,
            rejected,
            auto_cost,
        });
    }
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut all = Vec::new();
    sweep_model(
        "pendulum",
        &Pendulum {},
        InitialState::from_velocity([2.0], [0.0]),
        10.0,
        &mut all,
    )?;
    sweep_model(
        "duffing",
        &Duffing {},
        InitialState::from_velocity([1.0], [0.0]),
        10.0,
        &mut all,
    )?;
    sweep_model(
        "van_der_pol",
        &VanDerPol {},
        InitialState::from_velocity([2.0], [0.0]),
        10.0,
        &mut all,
    )?;
    let hh = InitialState::from_velocity([0.3, 0.1], [0.0, 0.35]);
    sweep_model("henon_heiles", &HenonHeiles {}, hh, 10.0, &mut all)?;
    sweep_model(
        "elastic",
        &Elastic {},
        InitialState::from_velocity([1.2, 0.8], [0.0, 0.0]),
        10.0,
        &mut all,
    )?;
    sweep_model(
        "magnetic",
        &Magnetic {},
        InitialState::from_velocity([1.0, 0.0], [0.0, 0.5]),
        10.0,
        &mut all,
    )?;
    let toda = InitialState::from_velocity([0.0, 0.5, -0.3], [0.8, -0.2, 0.1]);
    sweep_model("toda", &Toda {}, toda, 10.0, &mut all)?;
    sweep_model(
        "driven_pendulum",
        &DrivenPendulum {},
        InitialState::from_velocity([0.5], [0.0]),
        15.0,
        &mut all,
    )?;
    let drag = InitialState::from_velocity([1.0, 0.5], [0.3, 0.0]);
    sweep_model("quadratic_drag", &QuadraticDrag {}, drag, 10.0, &mut all)?;
    // Models that amplify errors (added after the controller's last change).
    let ecc = InitialState::from_velocity([1.0, 0.0], [0.0, 1.25]);
    sweep_model("eccentric_kepler", &EccentricKepler {}, ecc, 40.0, &mut all)?;
    sweep_model(
        "eccentric_kepler_long",
        &EccentricKepler {},
        ecc,
        120.0,
        &mut all,
    )?;
    let sep = InitialState::from_velocity([3.0], [0.0]);
    sweep_model("near_separatrix", &NearSeparatrix {}, sep, 40.0, &mut all)?;
    let hard = InitialState::from_velocity([1.5], [0.0]);
    sweep_model(
        "hardening_duffing",
        &HardeningDuffing {},
        hard,
        60.0,
        &mut all,
    )?;
    let before = all.len();
    // A held-out set of ten models, added on 2026-11-29 with no change to the controller.
    let held: [(&str, f64); 10] = [
        ("rayleigh", 20.0),
        ("two_scale", 10.0),
        ("hoop", 15.0),
        ("spherical", 10.0),
        ("overdamped", 10.0),
        ("big_scale", 10.0),
        ("morse", 20.0),
        ("resonance", 30.0),
        ("kepler_e08", 20.0),
        ("double_well", 20.0),
    ];
    let one = |x: f64, v: f64| InitialState::from_velocity([x], [v]);
    let two = |x: [f64; 2], v: [f64; 2]| InitialState::from_velocity(x, v);
    sweep_model(held[0].0, &Rayleigh {}, one(0.1, 0.0), held[0].1, &mut all)?;
    let ts = two([1.0, 0.1], [0.0, 0.0]);
    sweep_model(held[1].0, &TwoScale {}, ts, held[1].1, &mut all)?;
    sweep_model(held[2].0, &Hoop {}, one(0.5, 1.0), held[2].1, &mut all)?;
    let sp = two([1.0, 0.0], [0.0, 1.5]);
    sweep_model(held[3].0, &Spherical {}, sp, held[3].1, &mut all)?;
    sweep_model(
        held[4].0,
        &Overdamped {},
        one(2.0, 0.0),
        held[4].1,
        &mut all,
    )?;
    sweep_model(
        held[5].0,
        &BigScale {},
        one(1000.0, 0.0),
        held[5].1,
        &mut all,
    )?;
    sweep_model(held[6].0, &Morse {}, one(-0.5, 0.0), held[6].1, &mut all)?;
    sweep_model(held[7].0, &Resonance {}, one(0.0, 0.0), held[7].1, &mut all)?;
    let k8 = two([1.0, 0.0], [0.0, 1.34]);
    sweep_model(held[8].0, &Kepler08 {}, k8, held[8].1, &mut all)?;
    sweep_model(
        held[9].0,
        &DoubleWell {},
        one(0.1, 1.2),
        held[9].1,
        &mut all,
    )?;
    let second = all.len();
    // A second held-out set of five, of kinds the others lack, added later on 2026-11-29,
    // again with no change to the controller.
    let p = one(0.6, 0.0);
    sweep_model("parametric", &Parametric {}, p, 15.0, &mut all)?;
    let tm = two([1.0, -0.5], [0.0, 0.0]);
    sweep_model("two_mass", &TwoMass {}, tm, 15.0, &mut all)?;
    let lz = two([0.0, 0.0], [1.0, 0.0]);
    sweep_model("lorentz", &Lorentz {}, lz, 15.0, &mut all)?;
    let rel = one(0.5, 0.5);
    sweep_model("relativistic", &Relativistic {}, rel, 15.0, &mut all)?;
    let sk = two([1.0, 0.0], [0.0, 0.8]);
    sweep_model("soft_kepler", &SoftKepler {}, sk, 15.0, &mut all)?;
    let third = all.len();
    // A third held-out set of five, of kinds the others lack, added on 2026-11-30 with no
    // change to the controller.
    let top = InitialState::from_velocity([0.6, 0.0, 0.0], [0.0, 0.5, 5.0]);
    sweep_model("heavy_top", &HeavyTop {}, top, 15.0, &mut all)?;
    let mut c0 = [0.0; 8];
    c0[0] = 0.8;
    c0[3] = -0.4;
    let chain = InitialState::from_velocity(c0, [0.0; 8]);
    sweep_model("fpu_chain", &FpuChain {}, chain, 20.0, &mut all)?;
    sweep_model(
        "caldirola_kanai",
        &CaldirolaKanai {},
        one(1.0, 0.0),
        20.0,
        &mut all,
    )?;
    sweep_model(
        "dry_friction",
        &DryFriction {},
        one(2.0, 0.0),
        15.0,
        &mut all,
    )?;
    let cart = two([0.0, 1.0], [0.0, 0.0]);
    sweep_model("cart_pendulum", &CartPendulum {}, cart, 15.0, &mut all)?;
    let fourth = all.len();
    // A fourth held-out set of five, added later on 2026-11-30 with no change to the
    // controller.
    sweep_model("lj_wall", &LjWall {}, one(1.5, 0.0), 30.0, &mut all)?;
    let pair = two([1.0, 1.01], [0.0, 0.0]);
    sweep_model("stiff_pair", &StiffPair {}, pair, 10.0, &mut all)?;
    sweep_model("slow", &Slow {}, one(1.0, 0.0), 1.0e4, &mut all)?;
    sweep_model("quartic", &Quartic {}, one(1.0, 0.0), 30.0, &mut all)?;
    let dimer = two([1.3, 0.0], [0.0, 0.5]);
    sweep_model("lj_dimer", &LjDimer {}, dimer, 30.0, &mut all)?;
    let fifth = all.len();
    // The fifth held-out set of `tests/held_out.rs`, added later on 2026-11-30 with no change
    // to the controller.
    let atwood = two([1.0, 1.0], [0.0, 0.0]);
    sweep_model(
        "swinging_atwood",
        &SwingingAtwood {},
        atwood,
        10.0,
        &mut all,
    )?;
    let triple = InitialState::from_velocity([0.3, -0.2, 0.4], [0.0; 3]);
    sweep_model(
        "triple_pendulum",
        &TriplePendulum {},
        triple,
        10.0,
        &mut all,
    )?;
    let trap = InitialState::from_velocity([1.0, 0.0, 0.5], [0.0, 0.3, 0.0]);
    sweep_model("penning_trap", &PenningTrap {}, trap, 15.0, &mut all)?;
    sweep_model("washboard", &Washboard {}, one(0.0, 20.0), 15.0, &mut all)?;
    let far = one(1.0e4 + 1.0, 0.0);
    sweep_model("far_oscillator", &FarOscillator {}, far, 15.0, &mut all)?;
    summarise("held-out set of 2026-11-29", &all[before..second]);
    summarise("second held-out set of 2026-11-29", &all[second..third]);
    summarise("third held-out set of 2026-11-30", &all[third..fourth]);
    summarise("fourth held-out set of 2026-11-30", &all[fourth..fifth]);
    summarise("fifth held-out set of 2026-11-30", &all[fifth..]);
    let slopes: Vec<f64> = all.iter().filter_map(|s| s.slope).collect();
    let outside = slopes.iter().filter(|k| !(0.8..=1.2).contains(*k)).count();
    let mean = slopes.iter().map(|k| (k - 1.0).abs()).sum::<f64>() / slopes.len().max(1) as f64;
    let worst = all.iter().map(|s| s.worst).fold(0.0, f64::max);
    let steps: usize = all.iter().map(|s| s.steps).sum();
    let rejected: usize = all.iter().map(|s| s.rejected).sum();
    println!(
        "{} sweeps: {outside} slopes outside 0.8–1.2, mean |slope − 1| {mean:.3}; largest final error {worst:.2} tol (relative to max(1, |q_ref|)); {steps} steps and {rejected} rejected in all",
        slopes.len()
    );
    let pairs: Vec<(f64, f64)> = all
        .iter()
        .filter_map(|s| s.auto_cost.as_ref())
        .flatten()
        .copied()
        .collect();
    let sorted = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v
    };
    let costs = sorted(pairs.iter().map(|p| p.0).collect());
    let noise = sorted(pairs.iter().map(|p| p.1).collect());
    if let (Some(first), Some(last)) = (costs.first(), costs.last()) {
        let over = costs.iter().filter(|&&r| r > 1.5).count();
        println!(
            "auto against the cheapest scheme within 10 tol, {} model-tolerance pairs: time ratio {first:.2} to {last:.2}, median {:.2}, above 1.5 in {over}; against its own scheme timed beside it (the noise) {:.2} to {:.2}",
            costs.len(),
            costs[costs.len() / 2],
            noise[0],
            noise[noise.len() - 1]
        );
    }
    Ok(())
}
