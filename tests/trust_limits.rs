//! Trust at the limits of the inputs (a held-out probe of 2026-11-29): models too large for a
//! thread's stack, no coordinates at all, tolerances built without their checks, adaptive
//! steps that must grow on a linear model, and derivatives that leave `f64`'s range. Each
//! ends in a correct `Ok` or a typed error, never an abort, a panic or a frozen step.
//! `cargo test --release --test models_suite trust_limits::`.

use forced_vi::prelude::*;
use forced_vi::{Error, Tolerance};
use forced_vi_models::large::FpuChain;
use forced_vi_models::models::{DrivenDuffing, SpringChain};
use nalgebra::SVector;

/// Runs `f` on a thread with a stack of `bytes`, as a pool's worker or a user's thread has.
fn on_stack(bytes: usize, f: impl FnOnce() + Send + 'static) {
    std::thread::Builder::new()
        .stack_size(bytes)
        .spawn(f)
        .expect("a thread")
        .join()
        .expect("no panic");
}

/// A model of 8192 coordinates (sparse backend) on a thread of 2 MiB: its runs, outputs and
/// failures once held copies of `[f64; N]` values on the caller's stack (12.6 to 27 MB per
/// frame at 131072 coordinates) and aborted the process on a stack overflow.
#[test]
fn trust_large_models_run_on_a_small_stack() {
    const N: usize = 8192;
    on_stack(2 << 20, || {
        let m = SpringChain::<N>::FPU;
        let mut q = Box::new([0.0; N]);
        for (i, x) in q.iter_mut().enumerate() {
            *x = 0.1 * (std::f64::consts::PI * (i + 1) as f64 / (N as f64 + 1.0)).sin();
        }
        let init = InitialState::from_velocity(*q, [0.0; N]);
        let integ = Integrator::new(&m, Scheme::lobatto(2).unwrap(), 0.05).unwrap();
        let end = integ.final_state(init, 0.2).unwrap();
        let run = integ.solve(init, 0.2, output::Records).unwrap();
        assert_eq!(run.records.len(), 5);
        assert_eq!(run.records[4].q, end.q);
        let samples = integ
            .solve(init, 0.2, output::Samples(&[0.1, 0.2]))
            .unwrap();
        assert_eq!(samples[1].q, end.q);
        let mut seen = 0;
        integ
            .solve(init, 0.2, output::each_step(|_| seen += 1))
            .unwrap();
        assert_eq!(seen, 5);
        let members = integ.ensemble(&[init, init], 0.2, output::Final);
        for member in members {
            assert_eq!(member.unwrap().q, end.q);
        }
        let adaptive = integ.clone().tolerances(1e-6, 1e-6).unwrap();
        let a = adaptive.final_state(init, 0.2).unwrap();
        let gap = (0..N)
            .map(|i| (a.q[i] - end.q[i]).abs())
            .fold(0.0, f64::max);
        assert!(gap < 1e-4, "{gap}");
        let records = integ.stepper(init, 0.2).unwrap().count();
        assert_eq!(records, 5);
        // Bad data: the typed error, not an overflow.
        let bad = InitialState::from_velocity([f64::NAN; N], [0.0; N]);
        let err = integ.solve(bad, 0.2, output::Records).unwrap_err().error;
        assert!(matches!(err, Error::NonFiniteInitialData { .. }), "{err}");
        // The forward sensitivities' tangent over 8192 coordinates and 4 parameters,
        // 16388 columns of 16384 numbers (2.1 GB, kept twice): refused before the first step.
        // (Without the per-term parameter kernels, their dual numbers would have needed
        // 8.6 GB of stack, whose mapping failed with a panic.)
        let err = integ.solve(init, 0.2, output::Tangents).unwrap_err().error;
        let Error::TangentTooLarge {
            dof,
            columns,
            bytes,
            max,
        } = err
        else {
            panic!("{err}");
        };
        assert_eq!(
            (dof, columns, bytes),
            (N, 2 * N + 4, 2 * N * (2 * N + 4) * 8)
        );
        assert_eq!(max, forced_vi::MAX_TANGENT_BYTES);
    });
}

/// A model without parameters past the tangent's bound: its forward sensitivities were not
/// bounded at all, and at 16384 coordinates asked for 8.6 GB twice over (three times while
/// the result was copied out), where a failed allocation aborts the process. Refused with
/// the typed error, on a thread of 2 MiB; at the largest size under the bound, the
/// sensitivities run.
#[test]
fn trust_large_models_refuse_forward_sensitivities_past_the_tangent_bound() {
    on_stack(2 << 20, || {
        const N: usize = 16384;
        let m = FpuChain::<N>::default();
        let integ = Integrator::new(&m, Scheme::lobatto(2).unwrap(), 0.05).unwrap();
        let err = (integ.solve(large_initial::<N>(), 0.1, output::Tangents))
            .unwrap_err()
            .error;
        assert!(
            matches!(err, Error::TangentTooLarge { dof: N, .. }),
            "{err}"
        );
    });
    on_stack(2 << 20, || {
        const N: usize = 64;
        let m = FpuChain::<N>::default();
        let integ = Integrator::new(&m, Scheme::lobatto(2).unwrap(), 0.05).unwrap();
        let sens = integ.solve(large_initial::<N>(), 0.1, output::Tangents);
        let sens = sens.unwrap();
        assert_eq!(sens.wrt_initial.shape(), (2 * N, 2 * N));
        assert_eq!(sens.wrt_parameters.shape(), (2 * N, 0));
    });
}

/// The adjoint of that model (8192 coordinates, 4 parameters) on a thread of 2 MiB: it takes
/// the parameters' terms by scalar contractions, so it is not refused as the forward
/// sensitivities are. Its gradient in the parameters against central differences of the
/// loss `½ |q_T|²`.
#[test]
fn trust_large_models_take_the_adjoint_in_their_parameters() {
    const N: usize = 8192;
    on_stack(2 << 20, || {
        let m = SpringChain::<N>::FPU;
        let init = large_initial::<N>();
        let integ = Integrator::new(&m, Scheme::lobatto(2).unwrap(), 0.05).unwrap();
        let theta = m.parameter_values();
        let grad = adjoint_in_parameters(&integ, init);
        for (k, g) in grad.iter().enumerate() {
            let d = 1e-5 * theta[k].abs().max(1.0);
            let fd = (loss_at(&theta, k, d, init) - loss_at(&theta, k, -d, init)) / (2.0 * d);
            assert!(
                (g - fd).abs() <= 1e-6 * fd.abs().max(1e-3),
                "parameter {k}: adjoint {g:e}, central differences {fd:e}"
            );
        }
    });
}

/// The initial state of the large-model tests: a small sine bump, at rest.
#[inline(never)]
fn large_initial<const N: usize>() -> InitialState<N> {
    let mut q = Box::new([0.0; N]);
    for (i, x) in q.iter_mut().enumerate() {
        *x = 0.1 * (std::f64::consts::PI * (i + 1) as f64 / (N as f64 + 1.0)).sin();
    }
    InitialState::from_velocity(*q, [0.0; N])
}

/// `∂ℓ/∂θ` of `ℓ = ½ |q_T|²` (T = 0.2) by the adjoint, in a frame of its own (its results
/// hold `[f64; N]` values, which the caller's 2 MiB thread has no room for all at once).
#[inline(never)]
fn adjoint_in_parameters<const N: usize>(
    integ: &Integrator<'_, SpringChain<N>, N>,
    init: InitialState<N>,
) -> Vec<f64> {
    let grad = integ
        .solve(init, 0.2, output::adjoint(|e| (e.q, SVector::zeros())))
        .unwrap();
    grad.wrt_parameters.iter().copied().collect()
}

/// `ℓ = ½ |q_T|²` with parameter `k` of `theta` moved by `d` (lobatto2, h = 0.05, T = 0.2).
#[inline(never)]
fn loss_at<const N: usize>(theta: &[f64], k: usize, d: f64, init: InitialState<N>) -> f64 {
    let mut th = theta.to_vec();
    th[k] += d;
    let model = SpringChain::<N> {
        m: th[0],
        k: th[1],
        beta: th[2],
        c: th[3],
    };
    let end = Integrator::new(&model, Scheme::lobatto(2).unwrap(), 0.05)
        .unwrap()
        .final_state(init, 0.2)
        .unwrap();
    0.5 * end.q.iter().map(|x| x * x).sum::<f64>()
}

/// A model with no coordinates: a typed error, where a run panicked in nalgebra.
#[test]
fn trust_a_model_without_coordinates_is_refused() {
    struct Empty;
    impl ForcedLagrangian<0> for Empty {
        fn lagrangian<D: Scalar>(&self, _q: &[D; 0], _v: &[D; 0]) -> D {
            D::from(0.0)
        }
    }
    let err = Integrator::new(&Empty, Scheme::lobatto(3).unwrap(), 0.1).unwrap_err();
    assert!(matches!(err, Error::InvalidModel { .. }), "{err}");
    let err = InitialState::projected(&Empty, [], []).unwrap_err();
    assert!(matches!(err, Error::InvalidModel { .. }), "{err}");
}

/// Tolerances made from the public fields skip `Tolerance::per_component`'s checks: each run
/// checks them before its first step (a negative `rtol` had run to an `Ok` 1.2e-2 off, an
/// infinite one to `Ok(−14)` against −1.68).
#[test]
fn trust_tolerances_built_from_their_fields_are_checked() {
    #[forced_lagrangian(coordinates(x), lagrangian = 0.5 * x_dot * x_dot - 0.5 * x * x)]
    struct Unit {}
    let init = InitialState::from_velocity([1.0], [0.0]);
    for (rtol, atol) in [
        (-1.0, 1.0),
        (0.0, 0.0),
        (f64::NAN, 1e-6),
        (f64::INFINITY, 1e-6),
        (1e-6, -1e-9),
    ] {
        let tol = Tolerance {
            rtol: [rtol],
            atol: [atol],
        };
        let integ = Integrator::new(&Unit {}, Scheme::lobatto(3).unwrap(), 0.1)
            .unwrap()
            .tolerance(tol);
        let failure = integ.final_state(init, 1.0).unwrap_err();
        assert!(
            matches!(failure.error, Error::InvalidTolerance { index: 0, .. }),
            "{}",
            failure.error
        );
        assert_eq!(failure.stats.steps, 0);
    }
}

/// A linear model (`STRUCTURE.linear`) keeps its adaptive step in a band of sizes; a reading
/// below the estimate's resolution lets the step grow by 1.1, which the band cancelled:
/// started at 1e-6 (a coordinate of 1e6 beside one of 1e-6), the step stayed there for 10⁷
/// steps and 10 s.
#[test]
fn trust_adaptive_steps_grow_on_linear_models() {
    #[forced_lagrangian(
        coordinates(x, y),
        lagrangian = 0.5 * (x_dot * x_dot + y_dot * y_dot) - 0.5 * (x * x + y * y)
    )]
    struct Pair {}
    let init = InitialState::from_velocity([1e6, 1e-6], [0.0, 0.0]);
    for tol in [1e-8, 1e-10] {
        let end = Integrator::adaptive(&Pair {}, Scheme::lobatto(4).unwrap(), tol, tol)
            .unwrap()
            .final_state(init, 10.0)
            .unwrap();
        // Measured: 184 and 245 steps.
        assert!(end.stats.steps < 1000, "{}", end.stats.steps);
        let err = (end.q[0] - 1e6 * 10f64.cos()).abs();
        assert!(err <= 10.0 * tol * 1e6, "{err}");
    }
}

/// Derivatives that leave `f64`'s range (the chaotic Duffing oscillator stretches
/// perturbations by e^{0.11 t}) end the run at the step where they do, as an overflow of
/// the tangent or the adjoint: the tangent ran on to the end and was reported as a singular
/// mass matrix at step 0, the adjoint as a non-finite model value at step 0.
#[test]
fn trust_derivatives_that_overflow_are_reported_where_they_do() {
    let m = DrivenDuffing::CHAOTIC;
    let integ = Integrator::new(&m, Scheme::lobatto(2).unwrap(), 0.1).unwrap();
    let init = InitialState::from_velocity([1.0], [0.0]);
    let failure = integ.solve(init, 8000.0, output::Tangents).unwrap_err();
    match failure.error {
        Error::Overflow { step, t, quantity } => {
            assert_eq!(quantity, "tangent");
            assert!(step > 1000 && step < 80000, "{step}");
            assert!((t - 0.1 * (step - 1) as f64).abs() < 1e-6, "{t} {step}");
            // The steps before it are kept.
            assert_eq!(failure.stats.steps, step - 1);
        }
        other => panic!("{other}"),
    }
    // A loss gradient at the top of the range overflows the backward pass at once.
    let dloss = |_: &FinalState<1>| (SVector::from([1e308]), SVector::zeros());
    let failure = integ.solve(init, 1.0, output::adjoint(dloss)).unwrap_err();
    match failure.error {
        Error::Overflow { step, quantity, .. } => {
            assert_eq!(quantity, "adjoint");
            assert!((1..=10).contains(&step), "{step}");
        }
        other => panic!("{other}"),
    }
}

/// An index of a constraint that is out of range at every evaluation (`q[N]` in a model of
/// `N` coordinates): refused by `Integrator::new` with the index named, as one in the
/// Lagrangian is, where every run ended in `NonFiniteModel` at step 0.
#[test]
fn trust_a_constraint_index_out_of_range_is_named() {
    #[forced_lagrangian(
        coordinates(q: [f64; N]),
        lagrangian = (0..N).map(|i| 0.5 * q_dot[i] * q_dot[i]).sum(),
        constraints(q[0] - q[N] + q[1]),
    )]
    struct PastTheEnd<const N: usize> {}
    let err = Integrator::new(&PastTheEnd::<3> {}, Scheme::lobatto(3).unwrap(), 0.1).unwrap_err();
    match err {
        Error::InvalidModel { message } => assert!(message.contains("out of range"), "{message}"),
        other => panic!("{other}"),
    }
}
