//! Trust: the dense backend never aborts on a large model. Every run method on the dense
//! path, at `N = 256` and at the largest `N` the dense path accepts
//! ([`LinearPath::DENSE_MAX_DOF`]), on the main thread and on a thread with the default
//! 2 MiB stack; one coordinate more is the typed [`Error::ModelTooLarge`] on the dense path
//! and the sparse backend under `Auto`. The node kernels return `N × N` blocks by value (32
//! MiB at `N = 1024`), so the stepper runs a step on a stack sized for it. The same methods on
//! the sparse backend at `N = 1024`, whose code shares the stepper with the dense one (a dense
//! call inlined into that shared code once put 8 MiB blocks on its frame).
//!
//! The sensitivity outputs too, on a constrained 64-coordinate chain (both backends) and at
//! the largest `N`.
//!
//! A test binary of its own, without libtest's harness, so that the main thread is one of
//! the threads tested (libtest runs tests on threads of its own):
//! `cargo test --release -p forced-vi-models --test trust_dense_stack`.

use forced_vi::prelude::*;
use forced_vi::{Error, LinearPath};
use forced_vi_models::models::SpringChain;
use forced_vi_models::rigid_chain::RigidChain;

const H: f64 = 0.02;
/// Two steps: the second `next()` of the reproducer is a step of a running stepper.
const T: f64 = 2.0 * H;

fn initial<const N: usize>() -> InitialState<N> {
    let q = std::array::from_fn(|i| 0.1 * ((i + 1) as f64 * 0.7).sin());
    InitialState::from_velocity(q, [0.0; N])
}

fn dense<const N: usize>(model: &SpringChain<N>) -> Integrator<'_, SpringChain<N>, N> {
    on_path(model, LinearPath::Dense)
}

fn on_path<const N: usize>(
    model: &SpringChain<N>,
    path: LinearPath,
) -> Integrator<'_, SpringChain<N>, N> {
    // lobatto2 at the largest N: its LU (N × N) keeps the test to seconds.
    let s = if N > 256 { 2 } else { 3 };
    Integrator::new(model, Scheme::lobatto(s).unwrap(), H)
        .unwrap()
        .linear_path(path)
}

/// The final positions of every run method, which must agree.
fn every_method<const N: usize>(path: LinearPath) -> Vec<(&'static str, f64)> {
    let model = SpringChain::<N>::DEFAULT;
    let integ = on_path(&model, path);
    assert_eq!(integ.path_for(&initial()).unwrap(), path);
    let mut out = Vec::new();
    let run = integ.solve(initial(), T, output::Records).unwrap();
    out.push(("run", run.last().unwrap().q[N / 2]));
    let fin = integ.final_state(initial(), T).unwrap();
    out.push(("final_state", fin.q[N / 2]));
    let mut last = 0.0;
    integ
        .solve(initial(), T, output::each_step(|r| last = r.q[N / 2]))
        .unwrap();
    out.push(("for_each_step", last));
    let mut stepper = integ.stepper(initial(), T).unwrap();
    assert_eq!(stepper.path(), path);
    let end = stepper.by_ref().last().unwrap().unwrap();
    out.push(("stepper", end.q[N / 2]));
    let samples = integ.solve(initial(), T, output::Samples(&[T])).unwrap();
    out.push(("sample", samples[0].q[N / 2]));
    let adaptive = integ.clone().tolerances(1e-6, 1e-6).unwrap();
    let ada = adaptive.final_state(initial(), T).unwrap();
    let runs = integ.ensemble(&[initial(), initial()], T, output::Records);
    for r in runs {
        out.push(("run_ensemble", r.unwrap().last().unwrap().q[N / 2]));
    }
    for r in integ.ensemble(&[initial()], T, output::Final) {
        out.push(("run_ensemble_final", r.unwrap().q[N / 2]));
    }
    let reference = out[0].1;
    for (name, q) in &out {
        assert!(
            (q - reference).abs() <= 1e-12 * reference.abs().max(1e-3),
            "N = {N}, {name}: {q} against run's {reference}"
        );
    }
    assert!(
        (ada.q[N / 2] - reference).abs() < 1e-5,
        "adaptive {}",
        ada.q[N / 2]
    );
    out
}

/// One coordinate more than the dense path takes: typed errors, never an abort.
fn too_large_for_dense() {
    const N: usize = LinearPath::DENSE_MAX_DOF + 1;
    let model = SpringChain::<N>::DEFAULT;
    let integ = dense(&model);
    let err = integ.final_state(initial(), T).unwrap_err().error;
    assert!(matches!(err, Error::ModelTooLarge { dof: N, .. }), "{err}");
    let err = integ.stepper(initial(), T).err().unwrap();
    assert!(matches!(err, Error::ModelTooLarge { .. }), "{err}");
    let err = integ
        .solve(initial(), T, output::Records)
        .unwrap_err()
        .error;
    assert_eq!(err.kind(), "model_too_large");
    // Under Auto the model's sparse kernels take it.
    let auto = integ.linear_path(LinearPath::Auto);
    assert_eq!(auto.path_for(&initial()).unwrap(), LinearPath::Sparse);
    assert!(auto.final_state(initial(), T).is_ok());
}

/// The sensitivity outputs on large dense models: the tangent (`output::Tangents`) and the
/// loss gradient (`output::adjoint`) evaluate the node blocks before the first step, after
/// the last, and through the backward pass, outside the steps themselves; each runs on the
/// step's stack too (a 64-coordinate rigid chain, whose general kernels take the blocks
/// with second-order dual numbers in 128 directions, aborted on the main thread's 8 MiB).
/// The constrained chain on the dense backend and on the sparse one (which shares the
/// stepper), and the unconstrained spring chain at the largest `N` the dense path takes,
/// whose gradient is a backward pass.
fn sensitivities_of_large_dense_models() {
    const N: usize = 64;
    let chain = RigidChain::<N>::default();
    let init = chain.initial();
    let h = 1e-3;
    let integ = Integrator::new(&chain, Scheme::lobatto(3).unwrap(), h).unwrap();
    let loss = |end: &forced_vi::FinalState<N>| (end.q, end.v);
    for path in [LinearPath::Dense, LinearPath::Sparse] {
        let integ = integ.clone().linear_path(path);
        let sens = integ.solve(init, 2.0 * h, output::Tangents).unwrap();
        assert!(sens.wrt_initial.iter().all(|x| x.is_finite()), "{path:?}");
        let grad = integ.solve(init, 2.0 * h, output::adjoint(loss)).unwrap();
        assert!(grad.wrt_initial.iter().all(|x| x.is_finite()), "{path:?}");
    }
    const M: usize = LinearPath::DENSE_MAX_DOF;
    let springs = SpringChain::<M>::DEFAULT;
    let integ = dense(&springs);
    let loss = |end: &forced_vi::FinalState<M>| (end.q, end.v);
    let grad = integ.solve(initial(), T, output::adjoint(loss)).unwrap();
    assert!(grad.wrt_initial.iter().all(|x| x.is_finite()));
}

/// Runs `f` on the main thread and, at the same time (the test takes half the wall time on
/// two cores), on a thread with a 2 MiB stack.
fn on_both_threads(name: &str, f: fn()) {
    let small = std::thread::Builder::new()
        .name(name.into())
        .stack_size(2 << 20)
        .spawn(f)
        .unwrap();
    f();
    println!("test {name} (main thread) ... ok");
    small
        .join()
        .unwrap_or_else(|_| panic!("{name} failed on a 2 MiB thread"));
    println!("test {name} (2 MiB thread) ... ok");
}

fn main() {
    on_both_threads("trust_dense_every_method_at_256", || {
        every_method::<256>(LinearPath::Dense);
    });
    on_both_threads("trust_dense_every_method_at_the_largest_n", || {
        every_method::<{ LinearPath::DENSE_MAX_DOF }>(LinearPath::Dense);
    });
    on_both_threads("trust_sparse_every_method_at_1024", || {
        every_method::<1024>(LinearPath::Sparse);
    });
    on_both_threads("trust_dense_model_too_large", too_large_for_dense);
    on_both_threads(
        "trust_dense_sensitivities_of_large_models",
        sensitivities_of_large_dense_models,
    );
}
