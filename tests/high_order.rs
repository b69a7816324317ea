//! Orders 10 to 18 (`lobatto6` to `lobatto10`) against a closed-form solution.
//!
//! The report's scenes cross from their pre-asymptotic range to round-off within a few
//! step sizes at these orders (`report/orders.csv` leaves most of them blank). A long run of
//! a lightly damped oscillator spreads that crossing over a decade of `h`: its global error
//! grows with the run's length while the round-off floor grows only with the step count.
//! The damped frequency is exactly 1, so the exact solution at `T = 200` is evaluated at an
//! exact argument (with `ω = 1`, `ω_d = 0.99998…`, the errors of `lobatto9` flattened at
//! 4e-14, the rounding of `ω_d T`; here they flatten at 3e-14, the run's own round-off).

use forced_vi::prelude::*;
use forced_vi_scenes::report::orders::{observed_order, slope};

/// `ẍ + 2γẋ + (1 + γ²) x = 0`: `L = v²/2 − (1 + γ²) q²/2`, `F = −2γ v`.
struct LightlyDamped;

const GAMMA: f64 = 0.005;
const T: f64 = 200.0;

impl ForcedLagrangian<1> for LightlyDamped {
    fn lagrangian<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> D {
        (v[0] * v[0] - q[0] * q[0] * (1.0 + GAMMA * GAMMA)) * 0.5
    }
    fn force<D: Scalar>(&self, _q: &[D; 1], v: &[D; 1]) -> [D; 1] {
        [v[0] * (-2.0 * GAMMA)]
    }
}

/// `(h, |q(T) − x(T)|)` for `T / h` from 25 to 400 by factors of about 1.1; `x(0) = 1`,
/// `ẋ(0) = 0`, so `x(t) = e^{−γt} (cos t + γ sin t)`.
fn errors(s: usize) -> Vec<(f64, f64)> {
    let exact = (-GAMMA * T).exp() * (T.cos() + GAMMA * T.sin());
    let mut counts: Vec<usize> = (0..40)
        .map(|k| (25.0 * 1.1f64.powi(k)).round() as usize)
        .filter(|&n| n <= 400)
        .collect();
    counts.dedup();
    counts
        .into_iter()
        .map(|n| {
            let h = T / n as f64;
            let end = Integrator::new(&LightlyDamped, Scheme::lobatto(s).unwrap(), h)
                .unwrap()
                .final_state(InitialState::from_velocity([1.0], [0.0]), T)
                .unwrap_or_else(|f| panic!("lobatto{s} h = {h}: {}", f.error));
            (h, (end.q[0] - exact).abs())
        })
        .collect()
}

/// `lobatto6..8`: the report's fit (`orders`) settles the order within 0.3. `lobatto9` and
/// `10`: their slope where the error lies between 1e-12 and 1e-6, printed (the asymptotic
/// range of orders 16 and 18 is below round-off here; measured 15.7 and 17.55, approached
/// from below as `h` shrinks, over grids of factors 1.03 to 1.15).
#[test]
fn high_order_lobatto6_to_8_converge_at_their_orders_on_a_closed_form_oscillator() {
    for s in 6..=10 {
        let pts = errors(s);
        let expected = (2 * s - 2) as f64;
        let band: Vec<(f64, f64)> = pts
            .iter()
            .copied()
            .filter(|&(_, e)| (1e-12..1e-6).contains(&e))
            .collect();
        eprintln!(
            "lobatto{s}: slope {:.3} over the {} errors in 1e-12..1e-6",
            slope(&band).unwrap_or(f64::NAN),
            band.len()
        );
        if s > 8 {
            continue;
        }
        let fit =
            observed_order(&pts, 1.0).unwrap_or_else(|| panic!("lobatto{s}: no fit in {pts:?}"));
        eprintln!(
            "lobatto{s}: order {:.3} ± {:.3} over {} points",
            fit.order,
            fit.half_width(),
            fit.used.len()
        );
        assert_eq!(fit.unsettled(), None, "lobatto{s}: {fit:?}");
        assert!(
            (fit.order - expected).abs() <= 0.3,
            "lobatto{s}: order {} (expected {expected}) from {:?}",
            fit.order,
            fit.used
        );
    }
}

/// Above nine stages the predictor extrapolates the polynomial through nine of the last
/// step's control points (`Scheme::predictor_degree`), not a straight line along the
/// velocity: on the coupled van der Pol oscillators at h = 0.1 the guess is then close
/// enough for the last step's factors, about one Newton iteration per step (measured 1.12 to
/// 1.16 for lobatto10 to 20; 2.33 to 2.51 with the straight line), and the end state is the
/// same to round-off.
#[test]
fn high_order_predictor_keeps_newton_short_above_nine_stages() {
    use forced_vi_scenes::models::CoupledVanDerPol;
    let model = CoupledVanDerPol::PAPER;
    let init = InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]);
    let reference = Integrator::new(&model, Scheme::lobatto(14).expect("scheme"), 0.01)
        .expect("integrator")
        .final_state(init, 10.0)
        .expect("reference run")
        .q;
    for s in [10, 12, 16, 20] {
        let scheme = Scheme::lobatto(s).expect("scheme");
        assert_eq!(scheme.predictor_degree(), 8, "lobatto{s}");
        let end = Integrator::new(&model, scheme, 0.1)
            .expect("integrator")
            .final_state(init, 10.0)
            .expect("run");
        let per_step = end.stats.newton_iterations as f64 / end.stats.steps as f64;
        let err = (end.q - reference).abs().max();
        eprintln!("lobatto{s}: {per_step:.2} Newton iterations per step, error {err:.1e}");
        assert!(
            per_step <= 1.3,
            "lobatto{s}: {per_step} iterations per step"
        );
        assert!(err <= 1e-12, "lobatto{s}: error {err:e}");
    }
}
