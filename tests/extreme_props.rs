//! Property tests of robustness (issue 5): over random parameters, initial data, step sizes,
//! schemes and subdivision levels of the paper's model (`CoupledVanDerPol`) and a stiff model
//! (`StiffVanDerPol`, μ up to 10⁷), a run never panics and ends either in a trajectory whose
//! every record is finite or in a typed error whose partial trajectory is all finite.
//!
//! `cargo test --workspace --release --test models_suite extreme_props::`: 2 × 10⁴ cases in release builds (fewer in
//! debug builds), with short final times (at most 200 steps).

use forced_vi::prelude::*;
use forced_vi::{RunFailure, SchemeId};
use forced_vi_models::models::{CoupledVanDerPol, StiffVanDerPol};
use proptest::prelude::*;
use proptest::test_runner::Config;

/// Cases per property: at least 10⁴ in total in release builds.
const CASES: u32 = if cfg!(debug_assertions) { 300 } else { 10_000 };

fn config() -> Config {
    Config {
        cases: CASES,
        failure_persistence: None,
        ..Config::default()
    }
}

/// A float from `normal` most of the time, and now and then NaN, ±∞ or a huge value.
fn with_specials(normal: impl Strategy<Value = f64>) -> impl Strategy<Value = f64> {
    prop_oneof![
        60 => normal,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
        1 => Just(1e300),
    ]
}

/// `10^x` for `x` uniform in `[lo, hi]`.
fn log_uniform(lo: f64, hi: f64) -> impl Strategy<Value = f64> {
    (lo..hi).prop_map(|x| 10f64.powf(x))
}

fn scheme_id() -> impl Strategy<Value = SchemeId> {
    prop_oneof![
        Just(SchemeId::Midpoint),
        Just(SchemeId::Trapezoid),
        (2usize..=5).prop_map(SchemeId::Lobatto),
    ]
}

/// Every record finite.
fn finite<const N: usize>(traj: &Trajectory<N>) -> Result<(), String> {
    for r in &traj.records {
        let ok =
            r.q.iter()
                .chain(r.p.iter())
                .chain(r.v.iter())
                .all(|x| x.is_finite())
                && r.energy.is_finite()
                && r.energy_balance.is_finite()
                && r.t.is_finite();
        if !ok {
            return Err(format!("non-finite record at step {}: {r:?}", r.step));
        }
    }
    Ok(())
}

/// Runs and checks the property; returns a description of a violation.
fn check<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    id: SchemeId,
    h: f64,
    steps: usize,
    levels: u32,
    init: InitialState<N>,
) -> Result<(), String> {
    let scheme = Scheme::new(id).map_err(|e| format!("scheme {id}: {e}"))?;
    let t_final = h * steps as f64;
    let result = match Integrator::new(model, scheme, h) {
        Ok(i) => i
            .max_subdivisions(levels)
            .solve(init, t_final, output::Records),
        Err(error) => Err(RunFailure::from(error)),
    };
    match result {
        Ok(traj) => {
            finite(&traj)?;
            if traj.records.len() != traj.stats.steps + 1 {
                return Err(format!(
                    "{} records for {} steps",
                    traj.records.len(),
                    traj.stats.steps
                ));
            }
            Ok(())
        }
        Err(f) => {
            // A typed error with a stable kind and a message, and a finite partial trajectory.
            let kind = f.error.kind();
            if kind.is_empty() || f.error.to_string().is_empty() {
                return Err(format!("error without a kind: {:?}", f.error));
            }
            finite(&f.trajectory).map_err(|e| format!("{kind}: {e}"))
        }
    }
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn extreme_props_coupled_van_der_pol(
        eps in with_specials(-2.0..5.0f64),
        rho in with_specials(-0.9..3.0f64),
        lambda in with_specials(-1.0..3.0f64),
        q in prop::array::uniform2(with_specials(-20.0..20.0f64)),
        v in prop::array::uniform2(with_specials(-50.0..50.0f64)),
        h in log_uniform(-4.0, 0.5),
        steps in 0usize..200,
        levels in 0u32..4,
        id in scheme_id(),
    ) {
        let model = CoupledVanDerPol { eps, rho, lambda };
        let init = InitialState::from_velocity(q, v);
        let r = check(&model, id, h, steps, levels, init);
        prop_assert!(r.is_ok(), "{:?}: {}", (eps, rho, lambda, q, v, h, steps, levels, id), r.unwrap_err());
    }

    #[test]
    fn extreme_props_stiff_van_der_pol(
        mu in prop_oneof![20 => log_uniform(-2.0, 7.0), 1 => Just(f64::NAN), 1 => Just(-1e3)],
        q in with_specials(-4.0..4.0f64),
        v in with_specials(-1e3..1e3f64),
        h in log_uniform(-5.0, 1.0),
        steps in 0usize..200,
        levels in 0u32..4,
        id in scheme_id(),
        momentum in any::<bool>(),
    ) {
        let model = StiffVanDerPol { mu };
        let init = if momentum {
            InitialState::from_momentum([q], [v])
        } else {
            InitialState::from_velocity([q], [v])
        };
        let r = check(&model, id, h, steps, levels, init);
        prop_assert!(r.is_ok(), "{:?}: {}", (mu, q, v, h, steps, levels, id, momentum), r.unwrap_err());
    }
}
