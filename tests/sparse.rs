//! The sparse step (DESIGN §9) on the hand-written FPU chain and membrane of
//! `forced_vi_models::large`: agreement with the dense path, the kernels against the dense
//! node blocks, large n on a small stack, typed errors, no allocation per step, orders.
//! `cargo test --workspace --release --test models_suite sparse::`.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::{Mutex, MutexGuard};

use forced_vi::output;
use forced_vi::sparse::{NodeBlocks, NodePattern, NodeSink, SparseNode};
use forced_vi::{
    Error, ForcedLagrangian, InitialState, Integrator, LinearPath, NewtonOptions, Scalar, Scheme,
    Trajectory,
};
use forced_vi_models::large::{FpuChain, Lattice2d};
use nalgebra::SVector;

/// [`System`], counting each thread's allocations (the test harness's own thread allocates
/// while it reports other tests, so a process-wide count would not be this thread's).
struct PerThread;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

fn count() {
    // `try_with`: during thread teardown the counter may be gone.
    let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
}

// SAFETY: every call is forwarded unchanged to `System`.
unsafe impl GlobalAlloc for PerThread {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: the caller upholds `GlobalAlloc::alloc`'s contract.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: as above.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        // SAFETY: as above.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as above.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOC: PerThread = PerThread;

/// Allocations made by this thread so far.
fn allocations() -> u64 {
    ALLOCATIONS.with(|c| c.get())
}

/// The tests of this file run one at a time (they share two cores with other builds).
fn serial() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

fn schemes() -> Vec<Scheme> {
    let mut v: Vec<Scheme> = (2..=5).map(|s| Scheme::lobatto(s).unwrap()).collect();
    v.push(Scheme::midpoint());
    v
}

fn run<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    scheme: &Scheme,
    h: f64,
    path: LinearPath,
    t_final: f64,
    init: InitialState<N>,
) -> Trajectory<N> {
    // Newton to a tolerance well below the comparison's: each path stops at an iterate
    // within its tolerance (1e-12 by default) of the step's solution, and those stopping
    // points, not the linear algebra, would set the paths' difference.
    let integ = Integrator::new(model, scheme.clone(), h)
        .unwrap()
        .newton(NewtonOptions::default().tolerances(1e-14, 1e-16))
        .linear_path(path);
    assert_eq!(integ.path_for(&init).unwrap(), path);
    integ.solve(init, t_final, output::Records).unwrap()
}

/// Largest difference of `q` and `p` over the run, relative to their largest size.
fn max_rel_diff<const N: usize>(a: &Trajectory<N>, b: &Trajectory<N>) -> f64 {
    assert_eq!(a.records.len(), b.records.len());
    let (mut diff, mut size) = (0.0f64, 0.0f64);
    for (x, y) in a.records.iter().zip(&b.records) {
        diff = diff.max((x.q - y.q).amax()).max((x.p - y.p).amax());
        size = size.max(x.q.amax()).max(x.p.amax());
    }
    diff / size
}

fn agree<const N: usize>(steps: usize) {
    let model = FpuChain::<N>::default();
    let h = 0.05;
    for scheme in schemes() {
        let t = steps as f64 * h;
        let dense = run(
            &model,
            &scheme,
            h,
            LinearPath::Dense,
            t,
            FpuChain::<N>::initial(),
        );
        let sparse = run(
            &model,
            &scheme,
            h,
            LinearPath::Sparse,
            t,
            FpuChain::<N>::initial(),
        );
        let d = max_rel_diff(&dense, &sparse);
        assert!(d < 1e-12, "n = {N}, {:?}: {d:e}", scheme.id());
        let (ed, es) = (dense.last().unwrap(), sparse.last().unwrap());
        assert!((ed.energy_balance - es.energy_balance).abs() < 1e-12);
        assert!((ed.v - es.v).amax() < 1e-12 * ed.v.amax().max(1.0));
    }
}

#[test]
fn sparse_and_dense_paths_agree_at_n8() {
    let _g = serial();
    agree::<8>(400);
}

#[test]
fn sparse_and_dense_paths_agree_at_n32() {
    let _g = serial();
    agree::<32>(200);
}

/// A state away from equilibrium, with every coordinate moving.
fn state<const N: usize>() -> (SVector<f64, N>, SVector<f64, N>) {
    let q = SVector::from_fn(|i, _| 0.3 * (1.7 * i as f64).sin() + 0.2);
    let v = SVector::from_fn(|i, _| 0.5 * (0.9 * i as f64 + 0.3).cos());
    (q, v)
}

/// `SparseNode::eval`'s gradient and blocks equal the dense kernels' (general dual numbers
/// over the whole generic Lagrangian), entry by entry, on and off the pattern.
fn blocks_match<M: ForcedLagrangian<N> + SparseNode, const N: usize>(model: &M) {
    let (q, v) = state::<N>();
    let dense = model.node_jacobian(&q, &v);
    let (mut lq_f, mut lv) = (vec![0.0; N], vec![0.0; N]);
    let mut pairs = Vec::new();
    let mut sink = NodeSink::record(&mut lq_f, &mut lv, &mut pairs);
    model.eval(0.0, q.as_slice(), v.as_slice(), &mut sink);
    let pattern = NodePattern::from_pairs(N, pairs);
    let mut blocks = NodeBlocks::zeros(pattern.nnz());
    let mut sink = NodeSink::values(&mut lq_f, &mut lv, &pattern, &mut blocks);
    model.eval(0.0, q.as_slice(), v.as_slice(), &mut sink);
    assert!(!sink.outside());
    let scale = dense.a.amax().max(dense.e.amax());
    for i in 0..N {
        assert!(
            (lq_f[i] - dense.grad.fq[i]).abs() < 1e-13 * scale,
            "L_q + F [{i}]"
        );
        assert!(
            (lv[i] - dense.grad.lv[i]).abs() < 1e-13 * scale,
            "L_v [{i}]"
        );
        for j in 0..N {
            let k = pattern.position(i, j);
            let at = |b: &[f64]| k.map_or(0.0, |k| b[k]);
            for (name, s, d) in [
                ("A", at(&blocks.a), dense.a[(i, j)]),
                ("B", at(&blocks.b), dense.b[(i, j)]),
                ("C", at(&blocks.c), dense.c[(i, j)]),
                ("E", at(&blocks.e), dense.e[(i, j)]),
            ] {
                assert!(
                    (s - d).abs() <= 1e-13 * scale,
                    "{name}[{i}, {j}]: {s} vs {d}"
                );
            }
        }
    }
    let l = model.lagrangian::<f64>(&q.into(), &v.into());
    assert!(
        (model.lagrangian_value(0.0, q.as_slice(), v.as_slice()) - l).abs()
            < 1e-14 * l.abs().max(1.0)
    );
}

#[test]
fn sparse_kernels_equal_the_dense_node_blocks() {
    let _g = serial();
    blocks_match(&FpuChain::<8>::default());
    blocks_match(&Lattice2d::<3, 9>::default());
    // The chain's pattern is tridiagonal: 3 n − 2 entries.
    let model = FpuChain::<8>::default();
    let (mut a, mut b, mut pairs) = (vec![0.0; 8], vec![0.0; 8], Vec::new());
    model.eval(
        0.0,
        &[0.1; 8],
        &[0.0; 8],
        &mut NodeSink::record(&mut a, &mut b, &mut pairs),
    );
    assert_eq!(NodePattern::from_pairs(8, pairs).nnz(), 3 * 8 - 2);
}

#[test]
fn n4096_chain_steps_on_a_2mib_thread() {
    let _g = serial();
    let handle = std::thread::Builder::new()
        .stack_size(2 << 20)
        .spawn(|| {
            let model = FpuChain::<4096>::default();
            let integ = Integrator::new(&model, Scheme::lobatto(3).unwrap(), 0.05).unwrap();
            let init = FpuChain::<4096>::initial();
            assert_eq!(integ.path_for(&init).unwrap(), LinearPath::Sparse);
            let run = integ.solve(init, 0.15, output::Records).unwrap();
            let end = run.last().unwrap();
            assert_eq!(end.step, 3);
            assert!(end.q.iter().all(|x| x.is_finite()));
            assert!(
                end.energy_balance.abs() < 1e-6 * end.energy,
                "{}",
                end.energy_balance
            );
            // The dense path is refused, not attempted: its kernels would need gigabytes.
            let dense =
                integ
                    .clone()
                    .linear_path(LinearPath::Dense)
                    .solve(init, 0.15, output::Records);
            assert!(matches!(failed(dense).error, Error::ModelTooLarge { .. }));
        })
        .unwrap();
    handle.join().unwrap();
}

/// A chain whose kernel adds an entry outside the recorded pattern once `q[0]` has moved
/// (its pattern depends on the state, which the contract forbids), or writes past `n`.
struct Misbehaving {
    chain: FpuChain<8>,
    past_n: bool,
}

impl ForcedLagrangian<8> for Misbehaving {
    fn lagrangian<D: Scalar>(&self, q: &[D; 8], v: &[D; 8]) -> D {
        self.chain.lagrangian(q, v)
    }
    fn force<D: Scalar>(&self, q: &[D; 8], v: &[D; 8]) -> [D; 8] {
        self.chain.force(q, v)
    }
    fn sparse_node(&self) -> Option<&dyn SparseNode> {
        Some(self)
    }
}

impl SparseNode for Misbehaving {
    fn dof(&self) -> usize {
        8
    }
    fn eval(&self, t: f64, q: &[f64], v: &[f64], sink: &mut NodeSink<'_>) {
        self.chain.eval(t, q, v, sink);
        if self.past_n {
            sink.add_lq_f(8, 0.0);
        } else if q[0] < 0.29 {
            sink.add(forced_vi::sparse::Block::A, 0, 7, 0.0);
        }
    }
    fn lagrangian_value(&self, t: f64, q: &[f64], v: &[f64]) -> f64 {
        self.chain.lagrangian_value(t, q, v)
    }
}

/// A model with the default (dense) kernels only.
struct Plain;

impl ForcedLagrangian<2> for Plain {
    fn lagrangian<D: Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> D {
        (v[0] * v[0] + v[1] * v[1] - q[0] * q[0] - q[1] * q[1]) * 0.5
    }
}

/// The failure of a run that must fail (without printing its records otherwise).
#[track_caller]
fn failed<const N: usize>(
    run: Result<Trajectory<N>, forced_vi::RunFailure<N>>,
) -> forced_vi::RunFailure<N> {
    match run {
        Ok(t) => panic!("the run succeeded with {} records", t.records.len()),
        Err(f) => f,
    }
}

#[test]
fn typed_errors_of_the_sparse_path() {
    let _g = serial();
    let init = InitialState::from_velocity([0.3; 8], [-1.0; 8]);
    let lob = Scheme::lobatto(3).unwrap();
    // A pattern that changes with the state: an error at that step, earlier steps kept.
    let bad = Misbehaving {
        chain: FpuChain::default(),
        past_n: false,
    };
    let integ = Integrator::new(&bad, lob.clone(), 0.001)
        .unwrap()
        .linear_path(LinearPath::Sparse);
    let failure = failed(integ.solve(init, 1.0, output::Records));
    assert!(
        matches!(failure.error, Error::InvalidModel { .. }),
        "{}",
        failure.error
    );
    let kept = failure.trajectory.records.len();
    assert!(kept > 1 && kept < 1001, "{kept}");
    // A kernel that writes past n: refused before the first step.
    let bad = Misbehaving {
        chain: FpuChain::default(),
        past_n: true,
    };
    let integ = Integrator::new(&bad, lob.clone(), 0.01).unwrap();
    let failure = failed(
        integ
            .linear_path(LinearPath::Sparse)
            .solve(init, 1.0, output::Records),
    );
    assert!(
        matches!(failure.error, Error::InvalidModel { .. }),
        "{}",
        failure.error
    );
    // Adaptive steps run on the sparse backend too, the same stepper as the dense one: the
    // two agree to round-off (their linear algebra differs, not their steps).
    let chain = FpuChain::<32>::default();
    let adaptive = Integrator::new(&chain, lob.clone(), 0.01)
        .unwrap()
        .tolerances(1e-8, 1e-8)
        .unwrap();
    assert_eq!(
        adaptive.path_for(&FpuChain::<32>::initial()).unwrap(),
        LinearPath::Sparse
    );
    let sparse = adaptive
        .final_state(FpuChain::<32>::initial(), 1.0)
        .unwrap();
    let dense = adaptive.clone().linear_path(LinearPath::Dense);
    let dense = dense.final_state(FpuChain::<32>::initial(), 1.0).unwrap();
    assert_eq!(sparse.stats.steps, dense.stats.steps);
    assert!(sparse.stats.steps > 3, "{:?}", sparse.stats);
    assert!(
        (sparse.q - dense.q).amax() < 1e-12,
        "{}",
        (sparse.q - dense.q).amax()
    );
    // The sparse path on a model without sparse kernels.
    let plain = Plain;
    let integ = Integrator::new(&plain, lob, 0.01)
        .unwrap()
        .linear_path(LinearPath::Sparse);
    let init = InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]);
    let err = failed(integ.solve(init, 1.0, output::Records)).error;
    assert!(matches!(err, Error::NoSparseKernels { .. }), "{err}");
    assert_eq!(err.kind(), "no_sparse_kernels");
    // Small models keep the dense path under Auto.
    let small = FpuChain::<4>::default();
    let integ = Integrator::new(&small, Scheme::lobatto(3).unwrap(), 0.01).unwrap();
    assert_eq!(
        integ.path_for(&FpuChain::<4>::initial()).unwrap(),
        LinearPath::Dense
    );
}

/// Allocations made by 40 steps of `stepper`, after 5 steps of warm-up.
fn allocations_in_steps<const N: usize>(
    stepper: &mut impl Iterator<Item = Result<forced_vi::StepRecord<N>, Error>>,
) -> u64 {
    for rec in stepper.by_ref().take(5) {
        rec.unwrap();
    }
    let before = allocations();
    for rec in stepper.by_ref().take(40) {
        rec.unwrap();
    }
    allocations() - before
}

#[test]
fn a_sparse_step_allocates_nothing() {
    let _g = serial();
    for s in [2, 3, 5] {
        let model = FpuChain::<256>::default();
        let integ = Integrator::new(&model, Scheme::lobatto(s).unwrap(), 0.05)
            .unwrap()
            .linear_path(LinearPath::Sparse);
        let mut stepper = integ.stepper(FpuChain::<256>::initial(), 10.0).unwrap();
        assert_eq!(stepper.path(), LinearPath::Sparse);
        assert_eq!(allocations_in_steps(&mut stepper), 0, "chain, lobatto{s}");
        // Adaptive steps (the estimate's reference solve, rejections) allocate nothing either.
        let adaptive = integ.clone().tolerances(1e-6, 1e-6).unwrap();
        let mut stepper = adaptive.stepper(FpuChain::<256>::initial(), 10.0).unwrap();
        assert_eq!(
            allocations_in_steps(&mut stepper),
            0,
            "adaptive chain, lobatto{s}"
        );
        // The same stepper on the dense backend.
        let small = FpuChain::<8>::default();
        let dense = Integrator::new(&small, Scheme::lobatto(s).unwrap(), 0.05)
            .unwrap()
            .linear_path(LinearPath::Dense);
        let mut stepper = dense.stepper(FpuChain::<8>::initial(), 10.0).unwrap();
        assert_eq!(stepper.path(), LinearPath::Dense);
        assert_eq!(
            allocations_in_steps(&mut stepper),
            0,
            "dense chain, lobatto{s}"
        );
    }
    // The lattice too: a 2-D pattern, whose LU has fill.
    let model = Lattice2d::<16, 256>::default();
    let integ = Integrator::new(&model, Scheme::lobatto(3).unwrap(), 0.05).unwrap();
    let mut stepper = integ
        .stepper(Lattice2d::<16, 256>::initial(), 10.0)
        .unwrap();
    assert_eq!(stepper.path(), LinearPath::Sparse);
    assert_eq!(allocations_in_steps(&mut stepper), 0, "lattice");
    // The allocator counts: a run allocates (its buffers, once).
    let before = allocations();
    integ
        .solve(Lattice2d::<16, 256>::initial(), 0.1, output::Records)
        .unwrap();
    assert!(allocations() > before);
}

/// Least-squares slope of `log err` against `log h`.
fn slope(hs: &[f64], errs: &[f64]) -> f64 {
    let xs: Vec<f64> = hs.iter().map(|h| h.ln()).collect();
    let ys: Vec<f64> = errs.iter().map(|e| e.ln()).collect();
    let n = xs.len() as f64;
    let (mx, my) = (xs.iter().sum::<f64>() / n, ys.iter().sum::<f64>() / n);
    let sxy: f64 = xs.iter().zip(&ys).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = xs.iter().map(|x| (x - mx) * (x - mx)).sum();
    sxy / sxx
}

/// The n = 64 chain's state at T = 8 from `scripts/chain_reference.py` (scipy DOP853 at
/// rtol 3e-14, Radau agreeing to 1e-14): `(q0, v0, q_T, p_T)`.
fn chain_reference() -> ([f64; 64], [f64; 64], [f64; 64], [f64; 64]) {
    let text = include_str!("../data/reference/fpu_chain_64.csv");
    let (mut q0, mut v0, mut qt, mut pt) = ([0.0; 64], [0.0; 64], [0.0; 64], [0.0; 64]);
    let rows = text.lines().filter(|l| !l.starts_with('#')).skip(1);
    let mut count = 0;
    for line in rows {
        let c: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        let i = c[0] as usize;
        (q0[i], v0[i], qt[i], pt[i]) = (c[1], c[2], c[3], c[4]);
        count += 1;
    }
    assert_eq!(count, 64);
    (q0, v0, qt, pt)
}

/// Orders of lobatto2…5 on the n = 64 FPU-β chain through the sparse path, as fitted slopes
/// of the final error against an independent scipy solution (committed numbers).
#[test]
fn orders_on_the_n64_chain_against_scipy() {
    let _g = serial();
    let model = FpuChain::<64>::default();
    let (q0, v0, q_ref, p_ref) = chain_reference();
    // The reference was made with exactly these initial data (modes 8 and 20).
    let x = |i: usize| std::f64::consts::PI * (i + 1) as f64 / 65.0;
    for i in 0..64 {
        assert!((q0[i] - 0.3 * (8.0 * x(i)).sin()).abs() < 1e-15);
        assert!((v0[i] - 0.8 * (20.0 * x(i)).cos()).abs() < 1e-15);
    }
    let (t, init) = (8.0, InitialState::from_velocity(q0, v0));
    let (q_ref, p_ref) = (SVector::from(q_ref), SVector::from(p_ref));
    let err = |s: usize, steps: usize| {
        let traj = run(
            &model,
            &Scheme::lobatto(s).unwrap(),
            t / steps as f64,
            LinearPath::Sparse,
            t,
            init,
        );
        let last = *traj.last().unwrap();
        (last.q - q_ref).amax().max((last.p - p_ref).amax())
    };
    // lobatto5 stays above 1e-11 (at 64 steps it reaches 1.5e-12, within 15× of the floor
    // that the Newton tolerance and round-off put at about 1e-13, which bent the fit), and
    // starts past the pre-asymptotic range (16 → 20 → 24 steps: local orders 15.9, 9.1).
    let cases: [(usize, &[usize]); 4] = [
        (2, &[40, 80, 160, 320]),
        (3, &[32, 64, 128]),
        (4, &[20, 40, 80]),
        (5, &[28, 32, 40, 48]),
    ];
    for (s, steps) in cases {
        let hs: Vec<f64> = steps.iter().map(|&k| t / k as f64).collect();
        let errs: Vec<f64> = steps.iter().map(|&k| err(s, k)).collect();
        let order = 2.0 * s as f64 - 2.0;
        let fitted = slope(&hs, &errs);
        eprintln!("lobatto{s}: errors {errs:?}, slope {fitted:.2}");
        assert!(
            (fitted - order).abs() < 0.3,
            "lobatto{s}: slope {fitted} (errors {errs:?})"
        );
        assert!(
            errs.iter().all(|&e| e > 1e-12),
            "lobatto{s}: errors at the reference's accuracy {errs:?}"
        );
    }
}

/// The step-size band of a large sparse model (`forced_vi::control`): an accepted step that
/// the controller would resize by a factor between 0.9 and 1.2 keeps its size, so the sparse
/// LU made for it serves the next step too. On either backend, so that a run takes the same
/// steps on both.
#[test]
fn adaptive_steps_of_a_large_sparse_model_keep_their_size_within_the_band() {
    let chain = FpuChain::<32>::default();
    for path in [LinearPath::Sparse, LinearPath::Dense] {
        let integ = Integrator::adaptive(&chain, Scheme::lobatto(3).unwrap(), 1e-7, 1e-7)
            .unwrap()
            .linear_path(path);
        let run = integ
            .solve(FpuChain::<32>::initial(), 20.0, output::Records)
            .unwrap();
        let t: Vec<f64> = run.records.iter().map(|r| r.t).collect();
        let h: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(h.len() > 10, "{path:?}: {} steps", h.len());
        let (mut kept, mut grown, mut shrunk_in_band) = (0, 0, 0);
        // The last step is cut to the end of the run.
        for w in h[..h.len() - 1].windows(2) {
            let ratio = w[1] / w[0];
            // Growth comes from accepted steps only, so none is within the band.
            assert!(
                !(1.0 + 1e-9..=1.2).contains(&ratio),
                "{path:?}: a step grew by {ratio}"
            );
            if (ratio - 1.0).abs() <= 1e-9 {
                kept += 1;
            } else if ratio > 1.2 {
                grown += 1;
            } else if ratio >= 0.9 {
                shrunk_in_band += 1;
            }
        }
        // A step shrunk within the band follows a rejected attempt (its retry), never an
        // accepted step.
        assert!(
            shrunk_in_band <= run.stats.rejected_steps,
            "{path:?}: {shrunk_in_band} steps shrunk within the band, {} rejections",
            run.stats.rejected_steps
        );
        assert!(
            kept > 3 && grown > 0,
            "{path:?}: kept {kept}, grown {grown}"
        );
    }
}
