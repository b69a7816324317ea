//! With the `serde` feature, a trajectory and the other plain results survive a JSON round
//! trip bit for bit, and the errors serialise.

use forced_vi::prelude::*;
use forced_vi::{DenseState, Error, FinalState, LinearPath, RunFailure};

#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot)
        - 0.5 * (x * x + (1.0 + rho) * y * y)
        - lambda * (x - y) * (x - y),
    force(x = (eps - x * x) * x_dot, y = (eps - y * y) * y_dot),
)]
struct CoupledVanDerPol {
    eps: f64,
    rho: f64,
    lambda: f64,
}

const MODEL: CoupledVanDerPol = CoupledVanDerPol {
    eps: 0.5,
    rho: 0.02,
    lambda: 0.8,
};

fn round_trip<T>(value: &T) -> T
where
    T: serde::Serialize + serde::de::DeserializeOwned,
{
    let json = serde_json::to_string(value).expect("serialises");
    serde_json::from_str(&json).expect("deserialises")
}

#[test]
fn a_trajectory_round_trips_through_json() -> Result<(), Error> {
    let init = InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]);
    let integrator = Integrator::new(&MODEL, Scheme::lobatto(3)?, 0.01)?;
    let run = integrator
        .solve(init, 1.0, output::Records)
        .map_err(|f| f.error)?;
    assert_eq!(run.records.len(), 101);
    // Every f64 is written with enough digits to read back the same bits.
    let back = round_trip(&run);
    // (Compared record by record: a failure names the first record that differs.)
    assert_eq!(back.records.len(), run.records.len());
    for (b, r) in back.records.iter().zip(&run.records) {
        assert_eq!(b, r);
    }
    assert!(back == run);
    assert_eq!(back.records[57].q, run.records[57].q);
    assert_eq!(back.stats, run.stats);

    // The JSON is plain: a record is an object with the vectors as arrays.
    let value = serde_json::to_value(run.records[1]).expect("serialises");
    assert_eq!(value["step"], 1);
    assert_eq!(value["q"].as_array().map(Vec::len), Some(2));

    let end: FinalState<2> = integrator.final_state(init, 1.0).map_err(|f| f.error)?;
    assert_eq!(round_trip(&end), end);
    let mid: DenseState<2> = run.at(0.505).expect("inside the run");
    assert_eq!(round_trip(&mid), mid);
    assert_eq!(round_trip(&init), init);
    assert_eq!(round_trip(&LinearPath::Sparse), LinearPath::Sparse);
    assert_eq!(round_trip(&SchemeId::Alpha(0.25)), SchemeId::Alpha(0.25));
    Ok(())
}

#[test]
fn arrays_longer_than_32_round_trip() {
    // serde's own array impls stop at 32: these go through serde-big-array.
    let init = InitialState::from_momentum([0.5; 40], std::array::from_fn(|i| i as f64));
    assert_eq!(round_trip(&init), init);
    let tol = Tolerance::<40>::scalar(1e-6, 1e-9).expect("valid tolerances");
    assert_eq!(round_trip(&tol), tol);
}

#[test]
fn errors_and_failures_serialise() {
    let Err(err) = Integrator::new(&MODEL, Scheme::midpoint(), -0.1) else {
        panic!("a negative step is refused");
    };
    let value = serde_json::to_value(&err).expect("serialises");
    assert_eq!(
        value,
        serde_json::json!({ "InvalidStepSize": { "h": -0.1 } })
    );

    let integrator = Integrator::new(&MODEL, Scheme::midpoint(), 0.1)
        .expect("valid options")
        .max_steps(3);
    let failure: RunFailure<2> = integrator
        .solve(
            InitialState::from_velocity([0.0; 2], [0.0; 2]),
            1.0,
            output::Records,
        )
        .expect_err("more steps than the cap");
    let value = serde_json::to_value(&failure).expect("serialises");
    assert!(value["error"].get("TooManySteps").is_some(), "{value}");
}
