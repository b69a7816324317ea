//! Per-step cost of the paper's coupled van der Pol model, `#[forced_lagrangian]` kernels
//! against hand-written analytic ones (`forced_vi_scenes::handwritten`), through the same
//! stepper for every scheme at h = 0.01; plus the heap allocations per step, counted by a
//! counting global allocator in this bench binary. Run with
//! `cargo bench -p forced-vi-benches --bench step`.
//!
//! Each criterion iteration runs 100 steps from the paper's initial state (setup included), so
//! the time is per 100 steps (throughput in steps); the allocation count is printed per step.

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use forced_vi::prelude::*;
use forced_vi_scenes::handwritten::HandCoupledVanDerPol;
use forced_vi_scenes::models::CoupledVanDerPol;

#[path = "../src/alloc_count.rs"]
mod alloc_count;

#[global_allocator]
static ALLOC: alloc_count::Counting = alloc_count::Counting;

const SCHEMES: [&str; 5] = ["lobatto2", "lobatto3", "lobatto4", "lobatto5", "midpoint"];
const H: f64 = 0.01;
const STEPS: usize = 100;
const INIT: InitialState<2> = InitialState::Velocity {
    q: [-0.5, -0.25],
    v: [0.0, 4.0],
};

fn scheme(name: &str) -> Scheme {
    Scheme::new(name.parse().expect("scheme name")).expect("scheme")
}

/// Runs `STEPS` steps and returns the last position (kept alive with `black_box`).
fn run<M: ForcedLagrangian<2>>(integ: &Integrator<'_, M, 2>) -> f64 {
    let mut q = 0.0;
    integ
        .solve(INIT, STEPS as f64 * H, output::each_step(|r| q = r.q[0]))
        .expect("run");
    q
}

/// Heap allocations per step between the first and the last record.
fn allocs_per_step<M: ForcedLagrangian<2>>(integ: &Integrator<'_, M, 2>) -> f64 {
    let mut first = None;
    let mut last = 0;
    let stats = integ
        .solve(
            INIT,
            10.0,
            output::each_step(|_| {
                let c = alloc_count::allocations();
                first.get_or_insert(c);
                last = c;
            }),
        )
        .expect("run");
    (last - first.unwrap_or(last)) as f64 / stats.steps as f64
}

fn step(c: &mut Criterion) {
    let gen = CoupledVanDerPol::PAPER;
    let hand = HandCoupledVanDerPol::PAPER;
    let mut group = c.benchmark_group("step_100");
    group.throughput(Throughput::Elements(STEPS as u64));
    for name in SCHEMES {
        let ig = Integrator::new(&gen, scheme(name), H).expect("integrator");
        let ih = Integrator::new(&hand, scheme(name), H).expect("integrator");
        println!(
            "{name}: allocations per step: generated {}, hand-written {}",
            allocs_per_step(&ig),
            allocs_per_step(&ih)
        );
        group.bench_with_input(BenchmarkId::new("generated", name), &ig, |b, i| {
            b.iter(|| black_box(run(black_box(i))))
        });
        group.bench_with_input(BenchmarkId::new("handwritten", name), &ih, |b, i| {
            b.iter(|| black_box(run(black_box(i))))
        });
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1))
        .sample_size(30)
        // criterion's plots need a system font, which CI machines may lack.
        .without_plots();
    targets = step
}
criterion_main!(benches);
