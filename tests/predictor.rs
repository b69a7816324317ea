//! The predictor's correction by its own error at an unchanged step size, and at one near
//! the last (adaptive steps; see the runtime's `stepper::predict`): fewer Newton iterations,
//! the same solution.
//! `cargo test --workspace --release --test models_suite predictor_`.

use forced_vi::prelude::*;
use forced_vi::NewtonOptions;
use forced_vi_models::models::{CoupledVanDerPol, DoublePendulumFriction, KeplerDrag};

fn run<M: ForcedLagrangian<2>>(
    model: &M,
    s: usize,
    h: f64,
    t: f64,
    init: InitialState<2>,
    newton: NewtonOptions,
) -> FinalState<2> {
    Integrator::new(model, Scheme::lobatto(s).unwrap(), h)
        .unwrap()
        .newton(newton)
        .final_state(init, t)
        .unwrap()
}

#[test]
fn predictor_correction_saves_newton_iterations() {
    // lobatto3 at h = 0.01: the plain extrapolation is off by about 3e-6, and every step
    // took a second iteration (1.78 per step); corrected, about 2e-8, and one. With a fresh
    // Jacobian at every iteration (full Newton), so that the count is the predictor's and
    // not that of factors kept from the step before.
    let init = InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]);
    let end = run(
        &CoupledVanDerPol::PAPER,
        3,
        0.01,
        1.0,
        init,
        NewtonOptions::default().simplified(false),
    );
    let per_step = end.stats.newton_iterations as f64 / end.stats.steps as f64;
    eprintln!("lobatto3: {per_step:.2} Newton iterations per step");
    assert!(per_step <= 1.1, "{per_step}");
}

#[test]
fn predictor_correction_saves_newton_iterations_on_adaptive_steps() {
    // Adaptive lobatto3 at tol 1e-6 to T = 20. The counts include the one iteration of each
    // step's error estimate, so one iteration for the step itself is 2 per step. With the
    // correction at equal steps only (the steps change size at every step), the step took
    // a second iteration on most steps: 2.67 per step on the coupled van der Pol
    // oscillators and 2.96 on the double pendulum; corrected, 2.01 on both.
    let cvdp = Integrator::adaptive(
        &CoupledVanDerPol::PAPER,
        Scheme::lobatto(3).unwrap(),
        1e-6,
        1e-6,
    )
    .unwrap()
    .final_state(InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]), 20.0)
    .unwrap();
    let model = DoublePendulumFriction::DEFAULT;
    let dpend = Integrator::adaptive(&model, Scheme::lobatto(3).unwrap(), 1e-6, 1e-6)
        .unwrap()
        .final_state(InitialState::from_velocity([1.0, 0.5], [0.0, 0.0]), 20.0)
        .unwrap();
    for (end, name) in [(cvdp, "coupled van der Pol"), (dpend, "double pendulum")] {
        let st = end.stats;
        let per_step = st.newton_iterations as f64 / (st.steps + st.rejected_steps) as f64;
        eprintln!("{name}: {per_step:.2} Newton iterations per attempt");
        assert!(per_step <= 2.2, "{name}: {per_step}");
    }
}

#[test]
fn predictor_correction_keeps_the_solution() {
    // The same steps with Newton run far past its tolerance: the default run's stopping
    // points, from the corrected predictor or not, are within its tolerance.
    let cases: [(&dyn Fn(NewtonOptions) -> FinalState<2>, &str); 3] = [
        (
            &|o| {
                let init = InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]);
                run(&CoupledVanDerPol::PAPER, 3, 0.01, 3.0, init, o)
            },
            "coupled van der Pol, lobatto3",
        ),
        (
            &|o| {
                let init = InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]);
                run(&CoupledVanDerPol::PAPER, 5, 0.02, 3.0, init, o)
            },
            "coupled van der Pol, lobatto5",
        ),
        (
            &|o| {
                let init = InitialState::from_velocity([1.0, 0.0], [0.0, 1.2]);
                run(&KeplerDrag::DEFAULT, 4, 0.05, 20.0, init, o)
            },
            "Kepler, lobatto4",
        ),
    ];
    for (solve, name) in cases {
        let plain = solve(NewtonOptions::default());
        let tight = solve(NewtonOptions::default().tolerances(1e-15, 1e-17));
        let size = plain.q.amax().max(plain.p.amax());
        let diff = (plain.q - tight.q).amax().max((plain.p - tight.p).amax()) / size;
        eprintln!("{name}: {diff:.1e}");
        assert!(diff <= 1e-12, "{name}: {diff:e}");
    }
}

/// Fixed steps of 6 or more unknowns start from the factors of the step before (see the
/// runtime's dense backend): the error floor is that of full Newton (a fresh Jacobian at
/// every iteration). Accepting an iterate of those factors once the residual reached its
/// round-off floor left Kepler with drag, lobatto7 at 256 steps to T = 20, 7e-14 off the
/// reference (1e-15 with fresh factors): the residual's floor counts round-off that a step
/// cancels, a few hundred ulps of the momentum per step. (The two runs differ from each
/// other by more than either from the reference: the orbit amplifies round-off about 60
/// times over the run.)
#[test]
fn predictor_factors_across_steps_keep_the_round_off_floor() {
    // `data/reference/kepler_drag.csv` at T = 20.
    let reference = [-4.697_136_546_825_119_7e-1, -1.040_802_007_232_158_7];
    let init = InitialState::from_velocity([1.0, 0.0], [0.0, 1.2]);
    for (s, steps) in [(4, 1024.0), (5, 512.0), (6, 512.0), (7, 256.0), (7, 512.0)] {
        let h = 20.0 / steps;
        let err = |o: NewtonOptions| {
            let end = run(&KeplerDrag::DEFAULT, s, h, 20.0, init, o);
            let e = (end.q[0] - reference[0])
                .abs()
                .max((end.q[1] - reference[1]).abs());
            (
                e,
                end.stats.newton_iterations as f64 / end.stats.steps as f64,
            )
        };
        let (carried, per_step) = err(NewtonOptions::default());
        let (full, _) = err(NewtonOptions::default().simplified(false));
        eprintln!("lobatto{s}, {steps} steps: {per_step:.2} iterations per step, {carried:.1e} off, full Newton {full:.1e}");
        assert!(
            carried <= 4.0 * full + 4e-15,
            "lobatto{s}: {carried:e} against {full:e}"
        );
        // The carried factors are used: a second iteration on most steps.
        assert!(per_step >= 1.2, "lobatto{s}: {per_step}");
    }
}
