//! Node-kernel cost, general num-dual path against the kernels `#[forced_lagrangian]` writes,
//! in ns per node evaluation. Run with `cargo bench -p forced-vi-benches --bench node_eval`.
//!
//! - `CoupledVanDerPol` (the paper's model): all polynomial, so the specialised kernels are
//!   plain `f64` code with a constant mass matrix;
//! - `DampedOscillator`: linear, constant A, B and E;
//! - `KeplerDrag`: a non-polynomial potential (second-order duals over `q` only);
//! - `DoublePendulumFriction`: a position-dependent mass matrix (one mixed dual term);
//! - `SpringChain<8>`: a const-generic array model with loops.

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use forced_vi::model::general;
use forced_vi::ForcedLagrangian;
use forced_vi_scenes::models::{
    CoupledVanDerPol, DampedOscillator, DoublePendulumFriction, KeplerDrag, SpringChain,
};
use nalgebra::SVector;

fn bench_model<M: ForcedLagrangian<N>, const N: usize>(
    c: &mut Criterion,
    name: &str,
    model: &M,
    q: SVector<f64, N>,
    v: SVector<f64, N>,
) {
    let mut group = c.benchmark_group(name);
    group.bench_function("node_gradient/general", |b| {
        b.iter(|| general::node_gradient(black_box(model), black_box(&q), black_box(&v)))
    });
    group.bench_function("node_gradient/specialised", |b| {
        b.iter(|| black_box(model).node_gradient(black_box(&q), black_box(&v)))
    });
    group.bench_function("node_jacobian/general", |b| {
        b.iter(|| general::node_jacobian(black_box(model), black_box(&q), black_box(&v)))
    });
    group.bench_function("node_jacobian/specialised", |b| {
        b.iter(|| black_box(model).node_jacobian(black_box(&q), black_box(&v)))
    });
    group.finish();
}

fn node_eval(c: &mut Criterion) {
    bench_model(
        c,
        "CoupledVanDerPol",
        &CoupledVanDerPol::PAPER,
        SVector::from([-0.5, -0.25]),
        SVector::from([0.0, 4.0]),
    );
    bench_model(
        c,
        "DampedOscillator",
        &DampedOscillator::DEFAULT,
        SVector::from([0.3, -0.2]),
        SVector::from([0.1, 0.5]),
    );
    bench_model(
        c,
        "KeplerDrag",
        &KeplerDrag::DEFAULT,
        SVector::from([1.0, 0.2]),
        SVector::from([0.1, 1.0]),
    );
    bench_model(
        c,
        "DoublePendulumFriction",
        &DoublePendulumFriction::DEFAULT,
        SVector::from([0.7, -0.4]),
        SVector::from([0.3, 1.2]),
    );
    bench_model(
        c,
        "SpringChain8",
        &SpringChain::<8>::DEFAULT,
        SVector::from_fn(|i, _| 0.1 * i as f64),
        SVector::from_fn(|i, _| 0.05 * i as f64),
    );
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1))
        .sample_size(30);
    targets = node_eval
}
criterion_main!(benches);
