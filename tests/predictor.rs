//! The predictor's correction by its own error at an unchanged step size (see the runtime's
//! `stepper::predict`): fewer Newton iterations, the same solution.
//! `cargo test --workspace --release --test models_suite predictor_`.

use forced_vi::prelude::*;
use forced_vi::NewtonOptions;
use forced_vi_models::models::{CoupledVanDerPol, KeplerDrag};

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
    // took a second iteration (1.78 per step); corrected, about 2e-8, and one.
    let init = InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]);
    let end = run(
        &CoupledVanDerPol::PAPER,
        3,
        0.01,
        1.0,
        init,
        NewtonOptions::default(),
    );
    let per_step = end.stats.newton_iterations as f64 / end.stats.steps as f64;
    eprintln!("lobatto3: {per_step:.2} Newton iterations per step");
    assert!(per_step <= 1.1, "{per_step}");
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
