//! The final state alone (`Integrator::final_state`): the same answer as a full run, without
//! the per-step diagnostics. `cargo test --workspace --release --test models_suite final_state::`.

use forced_vi::prelude::*;
use forced_vi::Error;
use forced_vi_models::models::{CoupledVanDerPol, DoublePendulumFriction};

#[test]
fn final_state_matches_the_full_run() {
    let init = InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]);
    for s in 2..=5 {
        let integ =
            Integrator::new(&CoupledVanDerPol::PAPER, Scheme::lobatto(s).unwrap(), 0.01).unwrap();
        let full = integ.solve(init, 3.0, output::Records).unwrap();
        let end = integ.final_state(init, 3.0).unwrap();
        let last = full.last().unwrap();
        assert_eq!(end.t, 3.0);
        assert_eq!(end.stats.steps, last.step);
        for i in 0..2 {
            assert!((end.q[i] - last.q[i]).abs() <= 1e-13, "lobatto{s}");
            assert!((end.p[i] - last.p[i]).abs() <= 1e-13, "lobatto{s}");
            assert!((end.v[i] - last.v[i]).abs() <= 1e-12, "lobatto{s}");
        }
        assert!((end.energy - last.energy).abs() <= 1e-12);
    }
    // Adaptive, and with a state-dependent mass matrix.
    let model = DoublePendulumFriction::DEFAULT;
    let integ = Integrator::new(&model, Scheme::lobatto(3).unwrap(), 0.1)
        .unwrap()
        .tolerances(1e-9, 1e-9)
        .unwrap();
    let init = InitialState::from_velocity([1.0, 0.5], [0.0, 0.0]);
    let full = integ.solve(init, 5.0, output::Records).unwrap();
    let end = integ.final_state(init, 5.0).unwrap();
    let last = full.last().unwrap();
    assert!((end.q - last.q).amax() <= 1e-12 && (end.v - last.v).amax() <= 1e-10);
}

#[test]
fn final_state_keeps_typed_errors_and_stats() {
    let integ = Integrator::new(&CoupledVanDerPol::PAPER, Scheme::lobatto(3).unwrap(), 0.01)
        .unwrap()
        .max_steps(10);
    let init = InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]);
    let f = integ.final_state(init, 1.0).unwrap_err();
    assert!(matches!(f.error, Error::TooManySteps { .. }), "{}", f.error);
    let f = integ
        .clone()
        .max_steps(1000)
        .tolerances(1e-12, 1e-12)
        .unwrap()
        .max_steps(5)
        .final_state(init, 1.0)
        .unwrap_err();
    assert!(
        matches!(f.error, Error::MaxStepsReached { .. }),
        "{}",
        f.error
    );
    assert_eq!(f.stats.steps, 5);
}
