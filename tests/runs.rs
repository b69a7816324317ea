//! `Integrator::runs`: runs restarted on one stepper give what new steppers give, to the
//! bit, whatever came before them (other initial states and lengths, other outputs, failed
//! runs and refused initial data).

use forced_vi::prelude::*;
use forced_vi::{LinearPath, Runs};
use forced_vi_models::large::FpuChain;
use forced_vi_models::models::{CoupledVanDerPol, DampedOscillator, KeplerDrag};
use forced_vi_models::rigid_chain::RigidChain;

/// Runs `cases` (initial state, final time) one after another on one [`Runs`], each with
/// every output, and compares each result with a new stepper's.
fn compare<M: ForcedLagrangian<N>, const N: usize>(
    what: &str,
    integ: &Integrator<'_, M, N>,
    cases: &[(InitialState<N>, f64)],
) {
    let mut runs: Runs<'_, '_, M, N> = integ.runs();
    // Twice over, so that every output follows every other.
    for round in 0..2 {
        for (i, &(init, t)) in cases.iter().enumerate() {
            let at = format!("{what}, round {round}, case {i}");
            let times = [0.0, 0.3 * t, t];
            assert_eq!(
                runs.solve(init, t, output::Records),
                integ.solve(init, t, output::Records),
                "{at}: records"
            );
            assert_eq!(
                runs.solve(init, t, output::Final),
                integ.solve(init, t, output::Final),
                "{at}: final"
            );
            assert_eq!(
                runs.solve(init, t, output::Samples(&times)),
                integ.solve(init, t, output::Samples(&times)),
                "{at}: samples"
            );
            if M::CONSTRAINED {
                continue;
            }
            assert_eq!(
                runs.solve(init, t, output::Tangents),
                integ.solve(init, t, output::Tangents),
                "{at}: tangents"
            );
            let dloss = |e: &FinalState<N>| (e.q, e.p);
            assert_eq!(
                runs.solve(init, t, output::adjoint(dloss)),
                integ.solve(init, t, output::adjoint(dloss)),
                "{at}: adjoint"
            );
        }
    }
}

fn vdp(q: [f64; 2], v: [f64; 2]) -> InitialState<2> {
    InitialState::from_velocity(q, v)
}

#[test]
fn runs_restarted_give_new_steppers_results_on_small_models() {
    let m = CoupledVanDerPol::PAPER;
    let cases = [
        (vdp([-0.5, -0.25], [0.0, 4.0]), 1.0),
        (vdp([1.0, 0.3], [0.5, -1.0]), 0.7),
        (InitialState::from_momentum([0.2, -0.4], [1.0, 0.5]), 1.3),
    ];
    for s in [2, 3, 5, 7] {
        let sch = Scheme::lobatto(s).unwrap();
        compare(
            &format!("vdp fixed lobatto{s}"),
            &Integrator::new(&m, sch.clone(), 0.05).unwrap(),
            &cases,
        );
        compare(
            &format!("vdp adaptive lobatto{s}"),
            &Integrator::adaptive(&m, sch.clone(), 1e-8, 1e-8).unwrap(),
            &cases,
        );
        // Tolerances with a given first step, and subdivision.
        compare(
            &format!("vdp tolerances lobatto{s}"),
            &Integrator::new(&m, sch, 0.1)
                .unwrap()
                .max_subdivisions(3)
                .tolerances(1e-6, 1e-9)
                .unwrap(),
            &cases,
        );
    }
    compare(
        "vdp midpoint",
        &Integrator::new(&m, Scheme::midpoint(), 0.02).unwrap(),
        &cases,
    );
    compare(
        "vdp auto",
        &Integrator::auto(&m, 1e-10, 1e-10).unwrap(),
        &cases,
    );

    // A linear model, whose adaptive steps keep their factors.
    let d = DampedOscillator::DEFAULT;
    for integ in [
        Integrator::new(&d, Scheme::lobatto(4).unwrap(), 0.1).unwrap(),
        Integrator::adaptive(&d, Scheme::lobatto(3).unwrap(), 1e-9, 1e-9).unwrap(),
    ] {
        compare("damped", &integ, &cases);
    }
    let k = KeplerDrag::DEFAULT;
    let kcases = [
        (vdp([1.0, 0.0], [0.0, 1.2]), 5.0),
        (vdp([0.0, 1.5], [-0.7, 0.1]), 3.0),
    ];
    compare(
        "kepler lobatto6",
        &Integrator::new(&k, Scheme::lobatto(6).unwrap(), 0.1).unwrap(),
        &kcases,
    );
    compare(
        "kepler adaptive lobatto4",
        &Integrator::adaptive(&k, Scheme::lobatto(4).unwrap(), 1e-9, 1e-9).unwrap(),
        &kcases,
    );
}

#[test]
fn runs_restarted_give_new_steppers_results_on_a_constrained_and_a_sparse_model() {
    let chain = RigidChain::<8>::default();
    let mut angles = RigidChain::<8>::initial_angles();
    let first = chain.at_rest(&angles);
    angles.iter_mut().for_each(|a| *a *= 0.5);
    let cases = [(first, 0.5), (chain.at_rest(&angles), 0.3)];
    for s in [3, 5] {
        let sch = Scheme::lobatto(s).unwrap();
        compare(
            &format!("chain fixed lobatto{s}"),
            &Integrator::new(&chain, sch.clone(), 0.01).unwrap(),
            &cases,
        );
        compare(
            &format!("chain adaptive lobatto{s}"),
            &Integrator::adaptive(&chain, sch, 1e-8, 1e-8).unwrap(),
            &cases,
        );
    }
    // The sparse backend makes a new stepper for every run.
    let fpu = FpuChain::<8>::default();
    let init = FpuChain::<8>::initial();
    let integ = Integrator::new(&fpu, Scheme::lobatto(3).unwrap(), 0.1)
        .unwrap()
        .linear_path(LinearPath::Sparse);
    assert_eq!(integ.path_for(&init), Ok(LinearPath::Sparse));
    compare("fpu sparse", &integ, &[(init, 2.0), (init, 1.0)]);
    // The same model forced onto the dense backend restarts it; on `Auto`, where the backend
    // is chosen at the initial state, every run makes its own.
    let moved = InitialState::from_velocity([0.01; 8], [0.0; 8]);
    for path in [LinearPath::Dense, LinearPath::Auto] {
        let integ = Integrator::new(&fpu, Scheme::lobatto(3).unwrap(), 0.1)
            .unwrap()
            .linear_path(path);
        compare(
            &format!("fpu {path:?}"),
            &integ,
            &[(init, 1.0), (moved, 0.5)],
        );
    }
}

/// A run that fails, or whose initial data is refused, leaves the next run as a new
/// stepper's: the failures are the same typed errors with the same steps kept.
#[test]
fn runs_after_failures_give_new_steppers_results() {
    let m = CoupledVanDerPol::PAPER;
    let good = vdp([-0.5, -0.25], [0.0, 4.0]);
    let bad = vdp([f64::NAN, 0.0], [0.0, 1.0]);
    for integ in [
        Integrator::new(&m, Scheme::lobatto(3).unwrap(), 0.05)
            .unwrap()
            .max_steps(30),
        Integrator::adaptive(&m, Scheme::lobatto(5).unwrap(), 1e-10, 1e-10)
            .unwrap()
            .max_steps(6),
    ] {
        let mut runs = integ.runs();
        // Refused before any step (too many steps for the fixed run; the adaptive run
        // stops at its cap mid-run), refused initial data and final times, a run of length
        // zero, runs that end well.
        for (init, t) in [
            (good, 1.0),
            (bad, 1.0),
            (good, 1.0),
            (good, f64::NAN),
            (good, 0.2),
            (good, -1.0),
            (bad, 0.2),
            (good, 0.0),
            (good, 0.3),
        ] {
            let a = runs.solve(init, t, output::Records);
            let b = integ.solve(init, t, output::Records);
            // As text: an error that carries the NaN final time is not equal to itself.
            assert_eq!(format!("{a:?}"), format!("{b:?}"), "{init:?} to {t}");
        }
        assert!(runs.solve(bad, 1.0, output::Final).is_err());
        assert!(runs.solve(good, 0.2, output::Final).is_ok());
    }
}
