//! Sensitivities of the discrete flow (DESIGN §12, issue 24): the tangent carried through
//! the factored step Jacobian against central differences of the runs themselves, the
//! symplecticity of the unforced map in `(q, p)`, the two backends against each other, and
//! adaptive runs against fixed ones.
//! `cargo test --workspace --release --test models_suite sensitivity::`.

use forced_vi::output;
use forced_vi::{
    ForcedLagrangian, InitialState, Integrator, LinearPath, NewtonOptions, Scalar, Scheme,
    Sensitivities,
};
use forced_vi_models::large::{FpuChain, Lattice2d};
use forced_vi_models::models::{
    CoupledVanDerPol, DampedOscillator, DoublePendulumFriction, DrivenDuffing, KapitzaPendulum,
    KeplerDrag, SpringChain,
};
use nalgebra::{DMatrix, SVector};

/// `∂(q_T, v_T)/∂(q_0, v_0)` by central differences of fixed-step final states, step `delta`
/// relative to each entry's size.
fn central_differences<M: ForcedLagrangian<N>, const N: usize>(
    integ: &Integrator<'_, M, N>,
    (q0, v0): ([f64; N], [f64; N]),
    t_final: f64,
    delta: f64,
) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(2 * N, 2 * N);
    for c in 0..2 * N {
        let run = |sign: f64| {
            let (mut q, mut v) = (q0, v0);
            let x = if c < N { &mut q[c] } else { &mut v[c - N] };
            let d = delta * x.abs().max(1.0);
            *x += sign * d;
            let end = integ
                .final_state(InitialState::from_velocity(q, v), t_final)
                .expect("a perturbed run");
            (end.q, end.v, d)
        };
        let ((qp, vp, d), (qm, vm, _)) = (run(1.0), run(-1.0));
        for a in 0..N {
            out[(a, c)] = (qp[a] - qm[a]) / (2.0 * d);
            out[(N + a, c)] = (vp[a] - vm[a]) / (2.0 * d);
        }
    }
    out
}

/// `max |A − B| / max |B|`.
fn relative(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).amax() / b.amax()
}

fn check_against_differences<M: ForcedLagrangian<N>, const N: usize>(
    name: &str,
    model: &M,
    scheme: Scheme,
    h: f64,
    (q0, v0): ([f64; N], [f64; N]),
    t_final: f64,
) -> f64 {
    let integ = Integrator::new(model, scheme, h).expect("integrator");
    let s: Sensitivities<N> = integ
        .solve(
            InitialState::from_velocity(q0, v0),
            t_final,
            output::Tangents,
        )
        .expect("sensitivity run");
    let end = integ
        .final_state(InitialState::from_velocity(q0, v0), t_final)
        .expect("run");
    assert_eq!(s.q, end.q, "{name}: the same final state");
    assert_eq!(s.stats.steps, end.stats.steps);
    assert_eq!(s.wrt_initial.shape(), (2 * N, 2 * N));
    let fd = central_differences(&integ, (q0, v0), t_final, 1e-5);
    let rel = relative(&s.wrt_initial, &fd);
    eprintln!(
        "{name}: |S − FD| / |FD| = {rel:.2e}, |S| = {:.2e}",
        fd.amax()
    );
    assert!(rel < 1e-6, "{name}: {rel:.2e}");
    rel
}

#[test]
fn sensitivity_matches_central_differences_on_the_report_models() {
    let l3 = || Scheme::lobatto(3).expect("scheme");
    check_against_differences(
        "coupled_van_der_pol",
        &CoupledVanDerPol::PAPER,
        l3(),
        0.01,
        ([-0.5, -0.25], [0.0, 4.0]),
        1.0,
    );
    check_against_differences(
        "damped_oscillator",
        &DampedOscillator::DEFAULT,
        l3(),
        0.05,
        ([1.0, -0.5], [0.0, 0.3]),
        10.0,
    );
    check_against_differences(
        "double_pendulum_friction",
        &DoublePendulumFriction::DEFAULT,
        l3(),
        0.01,
        ([1.0, 0.5], [0.0, 0.0]),
        5.0,
    );
    check_against_differences(
        "kepler_drag",
        &KeplerDrag::DEFAULT,
        Scheme::lobatto(4).expect("scheme"),
        0.05,
        ([1.0, 0.0], [0.0, 1.1]),
        20.0,
    );
    check_against_differences(
        "driven_duffing",
        &DrivenDuffing::CHAOTIC,
        l3(),
        0.02,
        ([1.0], [0.0]),
        10.0,
    );
    check_against_differences(
        "kapitza_pendulum",
        &KapitzaPendulum::UPRIGHT,
        l3(),
        1e-3,
        ([3.0], [0.0]),
        2.0,
    );
}

#[test]
fn sensitivity_every_scheme_matches_central_differences() {
    for scheme in [
        Scheme::midpoint(),
        Scheme::lobatto(2).expect("scheme"),
        Scheme::lobatto(4).expect("scheme"),
        Scheme::lobatto(5).expect("scheme"),
        Scheme::new(forced_vi::SchemeId::Alpha(0.3)).expect("scheme"),
    ] {
        let name = format!("coupled_van_der_pol {}", scheme.id());
        check_against_differences(
            &name,
            &CoupledVanDerPol::PAPER,
            scheme,
            0.02,
            ([-0.5, -0.25], [0.0, 4.0]),
            1.0,
        );
    }
}

/// A double pendulum without friction: `F = 0`, a configuration-dependent mass matrix.
struct DoublePendulum;

impl ForcedLagrangian<2> for DoublePendulum {
    fn lagrangian<D: Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> D {
        let (a, b) = (q[0], q[1]);
        let (va, vb) = (v[0], v[1]);
        va * va + vb * vb * 0.5 + va * vb * (a - b).cos() + a.cos() * 2.0 * 9.81 + b.cos() * 9.81
    }
}

/// The `(q, p)` tangent from the `(q, v)` one: `dp = C dq + E dv` at both ends.
fn qp_tangent<M: ForcedLagrangian<N>, const N: usize>(
    model: &M,
    s: &Sensitivities<N>,
    (q0, v0): ([f64; N], [f64; N]),
) -> DMatrix<f64> {
    let to_p = |q: &SVector<f64, N>, v: &SVector<f64, N>| {
        let j = model.node_jacobian(q, v);
        let mut m = DMatrix::<f64>::identity(2 * N, 2 * N);
        for r in 0..N {
            for c in 0..N {
                m[(N + r, c)] = j.c[(r, c)];
                m[(N + r, N + c)] = j.e[(r, c)];
            }
        }
        m
    };
    let start = to_p(&SVector::from(q0), &SVector::from(v0));
    let end = to_p(&s.q, &s.v);
    end * &s.wrt_initial * start.try_inverse().expect("regular mass")
}

#[test]
fn sensitivity_unforced_map_is_symplectic() {
    let init = ([1.0, 0.5], [0.0, 0.0]);
    for scheme in [
        Scheme::midpoint(),
        Scheme::lobatto(3).expect("scheme"),
        Scheme::lobatto(5).expect("scheme"),
    ] {
        let mut j = DMatrix::<f64>::zeros(4, 4);
        for a in 0..2 {
            j[(a, 2 + a)] = 1.0;
            j[(2 + a, a)] = -1.0;
        }
        // Over 100 steps within 1e-12; over 500, where |M| grows to about 5, within
        // 1e-12 |M|² (the round-off of the products, which grows with the steps).
        for (t_final, bound) in [(1.0, 1.0), (5.0, f64::NAN)] {
            let s = Integrator::new(&DoublePendulum, scheme.clone(), 0.01)
                .expect("integrator")
                .solve(
                    InitialState::from_velocity(init.0, init.1),
                    t_final,
                    output::Tangents,
                )
                .expect("run");
            let m = qp_tangent(&DoublePendulum, &s, init);
            let defect = (m.transpose() * &j * &m - &j).amax();
            let bound = 1e-12
                * if bound.is_nan() {
                    m.amax().powi(2)
                } else {
                    bound
                };
            eprintln!(
                "{} T = {t_final}: |MᵀJM − J| = {defect:.2e} (|M| = {:.1e})",
                scheme.id(),
                m.amax()
            );
            assert!(defect < bound, "{defect:.2e}");
        }
    }
    // With friction the map contracts volume: det M < 1 (a check that the test can fail).
    let friction = DoublePendulumFriction::DEFAULT;
    let s = Integrator::new(&friction, Scheme::lobatto(3).expect("scheme"), 0.01)
        .expect("integrator")
        .solve(
            InitialState::from_velocity(init.0, init.1),
            5.0,
            output::Tangents,
        )
        .expect("run");
    let det = qp_tangent(&friction, &s, init).determinant();
    assert!(det < 0.9, "det = {det}");
}

#[test]
fn sensitivity_sparse_backend_matches_dense() {
    const N: usize = 12;
    let model = FpuChain::<N>::default();
    let init = FpuChain::<N>::initial();
    for scheme in [Scheme::lobatto(3), Scheme::lobatto(4)] {
        let scheme = scheme.expect("scheme");
        let run = |path| {
            Integrator::new(&model, scheme.clone(), 0.05)
                .expect("integrator")
                .linear_path(path)
                .solve(init, 3.0, output::Tangents)
                .expect("run")
        };
        let (dense, sparse) = (run(LinearPath::Dense), run(LinearPath::Sparse));
        let rel = relative(&sparse.wrt_initial, &dense.wrt_initial);
        eprintln!("fpu_chain {N} {}: sparse vs dense {rel:.2e}", scheme.id());
        assert!(rel < 1e-10, "{rel:.2e}");
    }
    // And against differences on the sparse backend itself.
    let integ = Integrator::new(&model, Scheme::lobatto(3).expect("scheme"), 0.05)
        .expect("integrator")
        .linear_path(LinearPath::Sparse);
    let s = integ.solve(init, 3.0, output::Tangents).expect("run");
    let (q0, v0) = match init {
        InitialState::Velocity { q, v } => (q, v),
        InitialState::Momentum { .. } => unreachable!(),
    };
    let fd = central_differences(&integ, (q0, v0), 3.0, 1e-5);
    let rel = relative(&s.wrt_initial, &fd);
    assert!(rel < 1e-6, "{rel:.2e}");
    // The macro's chain with its 4 parameters: 30 columns, which the sparse backend carries
    // 8 at a time (the last block part empty), against the dense backend's one by one.
    const M: usize = 13;
    let chain = SpringChain::<M>::FPU;
    let init = FpuChain::<M>::initial();
    let run = |path| {
        Integrator::new(&chain, Scheme::lobatto(3).expect("scheme"), 0.05)
            .expect("integrator")
            .linear_path(path)
            .solve(init, 1.0, output::Tangents)
            .expect("run")
    };
    let (dense, sparse) = (run(LinearPath::Dense), run(LinearPath::Sparse));
    assert_eq!(sparse.wrt_parameters.ncols(), 4);
    let rel = relative(&sparse.wrt_initial, &dense.wrt_initial);
    let rel_p = relative(&sparse.wrt_parameters, &dense.wrt_parameters);
    eprintln!("spring_chain {M}: sparse vs dense {rel:.2e}, parameters {rel_p:.2e}");
    assert!(rel < 1e-10 && rel_p < 1e-10, "{rel:.2e} {rel_p:.2e}");
    // An 8 × 8 membrane, whose LU has supernodes of 8 columns and more (solved through faer's
    // dense kernels, a column of the block at a time).
    let membrane = Lattice2d::<8, 64>::default();
    let init = Lattice2d::<8, 64>::initial();
    let run = |path| {
        Integrator::new(&membrane, Scheme::lobatto(3).expect("scheme"), 0.05)
            .expect("integrator")
            .linear_path(path)
            .solve(init, 0.15, output::Tangents)
            .expect("run")
    };
    let (dense, sparse) = (run(LinearPath::Dense), run(LinearPath::Sparse));
    let rel = relative(&sparse.wrt_initial, &dense.wrt_initial);
    eprintln!("lattice_2d 64: sparse vs dense {rel:.2e}");
    assert!(rel < 1e-10, "{rel:.2e}");
}

#[test]
fn sensitivity_adaptive_runs_hold_their_steps() {
    // Adaptive at a tight tolerance and fixed at a small step approximate the same flow
    // derivative.
    let model = CoupledVanDerPol::PAPER;
    let init = InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]);
    let scheme = Scheme::lobatto(4).expect("scheme");
    let adaptive = Integrator::adaptive(&model, scheme.clone(), 1e-11, 1e-11)
        .expect("integrator")
        .solve(init, 1.0, output::Tangents)
        .expect("adaptive run");
    let fixed = Integrator::new(&model, scheme, 1e-3)
        .expect("integrator")
        .solve(init, 1.0, output::Tangents)
        .expect("fixed run");
    let rel = relative(&adaptive.wrt_initial, &fixed.wrt_initial);
    eprintln!(
        "adaptive ({} steps) vs fixed: {rel:.2e}",
        adaptive.stats.steps
    );
    assert!(adaptive.stats.steps < fixed.stats.steps / 4);
    assert!(rel < 1e-8, "{rel:.2e}");
}

#[test]
fn sensitivity_subdivided_steps_are_carried() {
    // A step too large for Newton is subdivided; the tangent goes through the substeps.
    let model = KeplerDrag::DEFAULT;
    let (q0, v0) = ([1.0, 0.0], [0.0, 1.1]);
    let integ = Integrator::new(&model, Scheme::lobatto(3).expect("scheme"), 1.0)
        .expect("integrator")
        .newton(NewtonOptions::default().max_iterations(2))
        .max_subdivisions(6);
    let s = integ
        .solve(InitialState::from_velocity(q0, v0), 8.0, output::Tangents)
        .expect("run");
    let fd = central_differences(&integ, (q0, v0), 8.0, 1e-5);
    let rel = relative(&s.wrt_initial, &fd);
    eprintln!(
        "subdivided: {} of {} steps, {rel:.2e}",
        s.stats.subdivided_steps, s.stats.steps
    );
    assert!(s.stats.subdivided_steps > 0);
    assert!(rel < 1e-6, "{rel:.2e}");
}

/// `∂(q_T, v_T)/∂θ` by central differences over models rebuilt from perturbed parameters.
fn parameter_differences<M: ForcedLagrangian<N>, const N: usize>(
    make: impl Fn(&[f64]) -> M,
    theta: &[f64],
    (scheme, h): (Scheme, f64),
    init: InitialState<N>,
    t_final: f64,
) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(2 * N, theta.len());
    for k in 0..theta.len() {
        let d = 1e-5 * theta[k].abs().max(1.0);
        let run = |sign: f64| {
            let mut th = theta.to_vec();
            th[k] += sign * d;
            let model = make(&th);
            Integrator::new(&model, scheme.clone(), h)
                .expect("integrator")
                .final_state(init, t_final)
                .expect("a perturbed run")
        };
        let (p, m) = (run(1.0), run(-1.0));
        for a in 0..N {
            out[(a, k)] = (p.q[a] - m.q[a]) / (2.0 * d);
            out[(N + a, k)] = (p.v[a] - m.v[a]) / (2.0 * d);
        }
    }
    out
}

fn check_parameters<M: ForcedLagrangian<N>, const N: usize>(
    name: &str,
    make: impl Fn(&[f64]) -> M,
    names: &[&str],
    (scheme, h): (Scheme, f64),
    init: InitialState<N>,
    t_final: f64,
) {
    let model = make(&[]);
    let theta = model.parameter_values();
    assert_eq!(
        model.parameter_names(),
        names,
        "{name}: the fields, in order"
    );
    let model = make(&theta);
    let s = Integrator::new(&model, scheme.clone(), h)
        .expect("integrator")
        .solve(init, t_final, output::Tangents)
        .expect("run");
    assert_eq!(s.wrt_parameters.shape(), (2 * N, names.len()));
    let fd = parameter_differences(&make, &theta, (scheme, h), init, t_final);
    let rel = relative(&s.wrt_parameters, &fd);
    eprintln!(
        "{name} parameters: |S − FD| / |FD| = {rel:.2e}, |S| = {:.2e}",
        fd.amax()
    );
    assert!(rel < 1e-6, "{name}: {rel:.2e}");
}

#[test]
fn sensitivity_parameters_match_central_differences() {
    let l3 = || (Scheme::lobatto(3).expect("scheme"), 0.01);
    // `make(&[])` gives the default model; `make(θ)` the model with parameters θ.
    let pick = |th: &[f64], d: &[f64]| -> Vec<f64> {
        if th.is_empty() {
            d.to_vec()
        } else {
            th.to_vec()
        }
    };
    check_parameters(
        "coupled_van_der_pol",
        |th: &[f64]| {
            let p = pick(th, &[0.5, 0.02, 0.8]);
            CoupledVanDerPol {
                eps: p[0],
                rho: p[1],
                lambda: p[2],
            }
        },
        &["eps", "rho", "lambda"],
        l3(),
        InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]),
        1.0,
    );
    check_parameters(
        "double_pendulum_friction",
        |th: &[f64]| {
            let d = DoublePendulumFriction::DEFAULT;
            let p = pick(th, &[d.m1, d.m2, d.l1, d.l2, d.g, d.c]);
            DoublePendulumFriction {
                m1: p[0],
                m2: p[1],
                l1: p[2],
                l2: p[3],
                g: p[4],
                c: p[5],
            }
        },
        &["m1", "m2", "l1", "l2", "g", "c"],
        l3(),
        InitialState::from_velocity([1.0, 0.5], [0.0, 0.0]),
        3.0,
    );
    check_parameters(
        "kepler_drag",
        |th: &[f64]| {
            let p = pick(th, &[1.0, 0.01]);
            KeplerDrag {
                mu: p[0],
                gamma: p[1],
            }
        },
        &["mu", "gamma"],
        (Scheme::lobatto(4).expect("scheme"), 0.05),
        InitialState::from_velocity([1.0, 0.0], [0.0, 1.1]),
        10.0,
    );
    // Mass parameters: p_0 = L_v(q_0, v_0) moves with them.
    check_parameters(
        "damped_oscillator",
        |th: &[f64]| {
            let d = DampedOscillator::DEFAULT;
            let base = d.parameter_values();
            let p = pick(th, &base);
            let mut m = d;
            m.m11 = p[0];
            m.m12 = p[1];
            m.m22 = p[2];
            m.k11 = p[3];
            m.k12 = p[4];
            m.k22 = p[5];
            m.d11 = p[6];
            m.d12 = p[7];
            m.d21 = p[8];
            m.d22 = p[9];
            m
        },
        &[
            "m11", "m12", "m22", "k11", "k12", "k22", "d11", "d12", "d21", "d22",
        ],
        (Scheme::lobatto(3).expect("scheme"), 0.05),
        InitialState::from_velocity([1.0, -0.5], [0.0, 0.3]),
        5.0,
    );
    // A const-generic chain, whose parameters' node terms come from its per-term kernels
    // (`SparseNode::eval_parameter`), the mass `m` among them.
    check_parameters(
        "spring_chain 8",
        |th: &[f64]| {
            let d = SpringChain::<8>::FPU;
            let p = pick(th, &[d.m, d.k, d.beta, d.c]);
            SpringChain::<8> {
                m: p[0],
                k: p[1],
                beta: p[2],
                c: p[3],
            }
        },
        &["m", "k", "beta", "c"],
        (Scheme::lobatto(4).expect("scheme"), 0.05),
        FpuChain::<8>::initial(),
        3.0,
    );
}

#[test]
fn sensitivity_hand_written_models_declare_no_parameters() {
    let s = Integrator::new(
        &DrivenDuffing::CHAOTIC,
        Scheme::lobatto(3).expect("scheme"),
        0.02,
    )
    .expect("integrator")
    .solve(
        InitialState::from_velocity([1.0], [0.0]),
        1.0,
        output::Tangents,
    )
    .expect("run");
    assert_eq!(s.wrt_parameters.shape(), (2, 0));
    assert!(DrivenDuffing::CHAOTIC.parameter_names().is_empty());
}

/// The adjoint gradient of `ℓ = ½|q_T|² + w · v_T` against `Sᵀ g` of the forward
/// sensitivities; returns the larger relative difference (initial data, parameters).
fn adjoint_against_forward<M: ForcedLagrangian<N>, const N: usize>(
    integ: &Integrator<'_, M, N>,
    init: InitialState<N>,
    t_final: f64,
) -> f64 {
    let w = SVector::<f64, N>::from_fn(|a, _| 0.3 - 0.1 * a as f64);
    let fwd = integ
        .solve(init, t_final, output::Tangents)
        .expect("forward");
    let adj = integ
        .solve(init, t_final, output::adjoint(|end| (end.q, w)))
        .expect("adjoint");
    assert_eq!(adj.q, fwd.q);
    let mut g = nalgebra::DVector::zeros(2 * N);
    for a in 0..N {
        g[a] = fwd.q[a];
        g[N + a] = w[a];
    }
    let expect_init = fwd.wrt_initial.transpose() * &g;
    let expect_par = fwd.wrt_parameters.transpose() * &g;
    let rel = |a: &nalgebra::DVector<f64>, b: &nalgebra::DVector<f64>| {
        if b.is_empty() {
            0.0
        } else {
            (a - b).amax() / b.amax().max(f64::MIN_POSITIVE)
        }
    };
    assert_eq!(adj.wrt_parameters.len(), expect_par.len());
    rel(&adj.wrt_initial, &expect_init).max(rel(&adj.wrt_parameters, &expect_par))
}

#[test]
fn sensitivity_adjoint_equals_forward() {
    let cases: Vec<(&str, f64)> = vec![
        (
            "coupled_van_der_pol lobatto3",
            adjoint_against_forward(
                &Integrator::new(
                    &CoupledVanDerPol::PAPER,
                    Scheme::lobatto(3).expect("s"),
                    0.01,
                )
                .expect("integrator"),
                InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]),
                1.0,
            ),
        ),
        (
            "coupled_van_der_pol midpoint",
            adjoint_against_forward(
                &Integrator::new(&CoupledVanDerPol::PAPER, Scheme::midpoint(), 0.01)
                    .expect("integrator"),
                InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]),
                1.0,
            ),
        ),
        (
            "double_pendulum_friction lobatto5",
            adjoint_against_forward(
                &Integrator::new(
                    &DoublePendulumFriction::DEFAULT,
                    Scheme::lobatto(5).expect("s"),
                    0.02,
                )
                .expect("integrator"),
                InitialState::from_velocity([1.0, 0.5], [0.0, 0.0]),
                3.0,
            ),
        ),
        (
            "kepler_drag adaptive lobatto4",
            adjoint_against_forward(
                &Integrator::adaptive(
                    &KeplerDrag::DEFAULT,
                    Scheme::lobatto(4).expect("s"),
                    1e-8,
                    1e-8,
                )
                .expect("integrator"),
                InitialState::from_velocity([1.0, 0.0], [0.0, 1.1]),
                10.0,
            ),
        ),
        (
            "driven_duffing lobatto3",
            adjoint_against_forward(
                &Integrator::new(
                    &DrivenDuffing::CHAOTIC,
                    Scheme::lobatto(3).expect("s"),
                    0.02,
                )
                .expect("integrator"),
                InitialState::from_velocity([1.0], [0.0]),
                10.0,
            ),
        ),
        (
            "damped_oscillator lobatto2",
            adjoint_against_forward(
                &Integrator::new(
                    &DampedOscillator::DEFAULT,
                    Scheme::lobatto(2).expect("s"),
                    0.05,
                )
                .expect("integrator"),
                InitialState::from_velocity([1.0, -0.5], [0.0, 0.3]),
                5.0,
            ),
        ),
        (
            "fpu_chain 12 sparse lobatto3",
            adjoint_against_forward(
                &Integrator::new(
                    &FpuChain::<12>::default(),
                    Scheme::lobatto(3).expect("s"),
                    0.05,
                )
                .expect("integrator")
                .linear_path(LinearPath::Sparse),
                FpuChain::<12>::initial(),
                3.0,
            ),
        ),
    ];
    for (name, rel) in cases {
        eprintln!("{name}: adjoint vs forward {rel:.2e}");
        assert!(rel < 1e-10, "{name}: {rel:.2e}");
    }
}

/// `x'' + c x' + x = 0`, hand-written: its flow's Jacobian is known in closed form.
struct LinearDamped {
    c: f64,
}

impl ForcedLagrangian<1> for LinearDamped {
    fn lagrangian<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> D {
        (v[0] * v[0] - q[0] * q[0]) * 0.5
    }
    fn force<D: Scalar>(&self, _q: &[D; 1], v: &[D; 1]) -> [D; 1] {
        [-v[0] * self.c]
    }
}

/// `∂(x, v)(t)/∂(x_0, v_0)` of `x'' + c x' + x = 0` (`c < 2`).
fn linear_damped_jacobian(c: f64, t: f64) -> DMatrix<f64> {
    let (sg, w) = (c / 2.0, (1.0 - c * c / 4.0).sqrt());
    let (e, co, si) = ((-sg * t).exp(), (w * t).cos(), (w * t).sin());
    DMatrix::from_row_slice(
        2,
        2,
        &[
            e * (co + sg / w * si),
            e * si / w,
            -e * si / w,
            e * (co - sg / w * si),
        ],
    )
}

/// Many small steps: the tangent against the flow's Jacobian in closed form, and against
/// the adjoint of the same run. The tangent took the velocity directions of the nodes as
/// `(1/h) Σ_m Ψ_im dx_m` over the control points' directions, whose common part `dq`
/// cancels only to round-off (`Σ_m Ψ_im = 0`): an error `ε |dq| / h` per step. Before, 4·10⁵
/// lobatto3 steps ended about 1e-8 off both (measured on the coupled oscillators: 1.0e-8
/// from the adjoint at 3.6·10⁵ steps, 3.1e-7 at 3.6·10⁶); now both are within the
/// round-off of the run (here 5.5e-11 and 2.6e-11 for lobatto3).
#[test]
fn sensitivity_many_small_steps_keep_the_tangent_exact() {
    let (c, t_final, h) = (0.3, 4.0, 1e-5);
    let model = LinearDamped { c };
    let exact = linear_damped_jacobian(c, t_final);
    let init = InitialState::from_velocity([1.0], [-0.2]);
    for s in [3, 4] {
        let integ = Integrator::new(&model, Scheme::lobatto(s).unwrap(), h).unwrap();
        let fwd = integ.solve(init, t_final, output::Tangents).unwrap();
        let err = relative(&fwd.wrt_initial, &exact);
        assert!(
            err <= 1e-9,
            "lobatto{s}: tangent {err:e} off the exact Jacobian"
        );
        let adj = adjoint_against_forward(&integ, init, t_final);
        assert!(adj <= 1e-9, "lobatto{s}: adjoint {adj:e} off the tangent");
    }
}
