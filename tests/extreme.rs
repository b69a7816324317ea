//! Bad input and extreme cases: `cargo test --workspace --release extreme_`.
//!
//! Every case must end in a typed error that names what is wrong, with the steps computed
//! before it returned, or in a finite trajectory. Never a panic, never a NaN reported as a
//! result.

// `RunFailure` keeps what a run computed before failing, by value.
#![allow(clippy::result_large_err)]

use forced_vi::prelude::*;
use forced_vi::{Error, NewtonFailure, NewtonOptions, RunFailure};
use forced_vi_models::models::CoupledVanDerPol;

fn cvdp_run(h: f64, t_final: f64, init: InitialState<2>) -> Result<Trajectory<2>, RunFailure<2>> {
    let model = CoupledVanDerPol::PAPER;
    match Integrator::new(&model, Scheme::lobatto(3).unwrap(), h) {
        Ok(i) => i.solve(init, t_final, output::Records),
        Err(error) => Err(RunFailure::from(error)),
    }
}

fn paper_init() -> InitialState<2> {
    InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0])
}

#[test]
fn extreme_bad_step_size() {
    for h in [0.0, -0.1, f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let err = Integrator::new(&CoupledVanDerPol::PAPER, Scheme::midpoint(), h).unwrap_err();
        assert!(matches!(err, Error::InvalidStepSize { .. }), "{h}: {err}");
        assert!(err.to_string().contains("step size"));
    }
}

#[test]
fn extreme_bad_final_time() {
    for t in [-1.0, f64::NAN, f64::INFINITY] {
        let f = cvdp_run(0.1, t, paper_init()).unwrap_err();
        assert!(
            matches!(f.error, Error::InvalidFinalTime { .. }),
            "{t}: {}",
            f.error
        );
    }
    // Zero is a valid final time: just the initial record.
    let run = cvdp_run(0.1, 0.0, paper_init()).unwrap();
    assert_eq!(run.records.len(), 1);
}

#[test]
fn extreme_non_finite_initial_data() {
    let cases = [
        (
            InitialState::from_velocity([f64::NAN, 0.0], [0.0, 0.0]),
            "q",
            0,
        ),
        (
            InitialState::from_velocity([0.0, 0.0], [0.0, f64::INFINITY]),
            "v",
            1,
        ),
        (
            InitialState::from_momentum([0.0, 0.0], [f64::NEG_INFINITY, 0.0]),
            "p",
            0,
        ),
    ];
    for (init, what, index) in cases {
        let f = cvdp_run(0.1, 1.0, init).unwrap_err();
        assert_eq!(f.error, Error::NonFiniteInitialData { what, index });
        assert!(f.error.to_string().contains(&format!("{what}[{index}]")));
    }
}

#[test]
fn extreme_non_finite_parameter() {
    let model = CoupledVanDerPol {
        eps: 0.5,
        rho: f64::NAN,
        lambda: 0.8,
    };
    let err = Integrator::new(&model, Scheme::midpoint(), 0.1).unwrap_err();
    assert_eq!(err, Error::NonFiniteParameter { name: "rho" });
    let model = CoupledVanDerPol {
        eps: f64::INFINITY,
        rho: 0.0,
        lambda: 0.8,
    };
    let err = Integrator::new(&model, Scheme::midpoint(), 0.1).unwrap_err();
    assert_eq!(err, Error::NonFiniteParameter { name: "eps" });
}

#[test]
fn extreme_singular_mass_from_parameters() {
    // M = [[1, 1], [1, 1]] makes L degenerate in v.
    let model = TwoMasses {
        m: [[1.0, 1.0], [1.0, 1.0]],
    };
    let f = Integrator::new(&model, Scheme::lobatto(2).unwrap(), 0.1)
        .unwrap()
        .solve(
            InitialState::from_velocity([1.0, 0.0], [0.0, 0.5]),
            1.0,
            output::Records,
        )
        .unwrap_err();
    assert!(
        matches!(f.error, Error::SingularMassMatrix { step: 0, .. }),
        "{}",
        f.error
    );
}

/// `L = ½vᵀMv − ½|q|²`.
struct TwoMasses {
    m: [[f64; 2]; 2],
}

impl ForcedLagrangian<2> for TwoMasses {
    fn lagrangian<D: Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> D {
        let mut l = (q[0] * q[0] + q[1] * q[1]) * -0.5;
        for i in 0..2 {
            for j in 0..2 {
                l += v[i] * v[j] * (0.5 * self.m[i][j]);
            }
        }
        l
    }
}

/// `L = ½(a − q²)v² − ½q²`: the mass vanishes at `|q| = √a`.
struct VanishingMass {
    a: f64,
}

impl ForcedLagrangian<1> for VanishingMass {
    fn lagrangian<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> D {
        (-q[0] * q[0] + self.a) * v[0] * v[0] * 0.5 - q[0] * q[0] * 0.5
    }
}

#[test]
fn extreme_mass_becomes_singular_mid_run() {
    let model = VanishingMass { a: 0.25 };
    let f = Integrator::new(&model, Scheme::lobatto(3).unwrap(), 0.01)
        .unwrap()
        .solve(
            InitialState::from_velocity([0.0], [1.0]),
            5.0,
            output::Records,
        )
        .unwrap_err();
    eprintln!("{}", f.error);
    assert!(
        matches!(
            f.error,
            Error::SingularMassMatrix { .. } | Error::NewtonFailed { .. }
        ),
        "{}",
        f.error
    );
    let kept = &f.trajectory.records;
    assert!(kept.len() > 5, "the steps before the failure are kept");
    assert!(kept
        .iter()
        .all(|r| r.q[0].abs() < 0.5 && r.energy.is_finite()));
}

/// A force that is NaN for `q > 1`. Also used by `trust_runtime` (one model type, one
/// instantiation of the runtime in the test binary).
pub(crate) struct SqrtDrag;

impl ForcedLagrangian<1> for SqrtDrag {
    fn lagrangian<D: Scalar>(&self, _q: &[D; 1], v: &[D; 1]) -> D {
        v[0] * v[0] * 0.5
    }
    fn force<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> [D; 1] {
        [-v[0] * (-q[0] + 1.0).sqrt() * 0.1]
    }
}

#[test]
fn extreme_force_returns_nan_mid_run() {
    let f = Integrator::new(&SqrtDrag, Scheme::lobatto(2).unwrap(), 0.01)
        .unwrap()
        .max_subdivisions(3)
        .solve(
            InitialState::from_velocity([0.0], [2.0]),
            2.0,
            output::Records,
        )
        .unwrap_err();
    match f.error {
        Error::NonFiniteModel { step, t } => {
            assert!(step > 10 && t > 0.1, "step {step}, t {t}");
            assert_eq!(f.trajectory.records.len(), step);
        }
        ref e => panic!("expected NonFiniteModel, got {e}"),
    }
    assert!(f
        .trajectory
        .records
        .iter()
        .all(|r| r.q[0].is_finite() && r.q[0] <= 1.0));
}

#[test]
fn extreme_newton_does_not_converge() {
    // Two Newton iterations cannot meet a 1e-15 tolerance from a poor first-step guess.
    let opts = NewtonOptions::default().max_iterations(1);
    let f = Integrator::new(&CoupledVanDerPol::PAPER, Scheme::lobatto(4).unwrap(), 0.5)
        .unwrap()
        .newton(opts)
        .solve(paper_init(), 2.0, output::Records)
        .unwrap_err();
    match f.error {
        Error::NewtonFailed {
            step,
            t,
            residual,
            failure,
        } => {
            assert_eq!(step, 1);
            assert_eq!(t, 0.0);
            assert!(residual.is_finite());
            assert!(matches!(failure, NewtonFailure::MaxIterations { .. }));
        }
        ref e => panic!("expected NewtonFailed, got {e}"),
    }
    assert_eq!(f.trajectory.records.len(), 1, "the initial record is kept");
    let msg = f.error.to_string();
    assert!(msg.contains("step 1") && msg.contains("t = 0"), "{msg}");
}

#[test]
fn extreme_huge_step_is_finite_or_typed() {
    for s in 2..=5 {
        for h in [1.0, 2.0, 5.0] {
            match cvdp_run(h, 20.0, paper_init()) {
                Ok(run) => assert!(run
                    .records
                    .iter()
                    .all(|r| r.q.iter().all(|x| x.is_finite()))),
                Err(f) => {
                    assert!(f.trajectory.records.iter().all(|r| r.energy.is_finite()));
                    eprintln!("lobatto{s} h={h}: {}", f.error);
                }
            }
        }
    }
}

#[test]
fn extreme_very_stiff_steps_converge_at_round_off() {
    // μ = 1e6 with h = 100 and 1000: the step's residual sits at round-off of terms that
    // cancel; Newton must accept it instead of reporting a failure.
    let model = forced_vi_models::models::StiffVanDerPol::VERY_STIFF;
    for (h, levels) in [(100.0, 0), (1000.0, 6)] {
        let run = Integrator::new(&model, Scheme::midpoint(), h)
            .unwrap()
            .max_subdivisions(levels)
            .solve(
                InitialState::from_velocity([2.0], [0.0]),
                3.0 * h,
                output::Records,
            )
            .unwrap_or_else(|f| panic!("h = {h}: {}", f.error));
        let end = run.last().unwrap();
        // On the slow manifold q drifts down from 2 by a tiny amount over t ≤ 3000 (τ ≤ 3e-3).
        assert!(
            end.q[0] < 2.0 && end.q[0] > 1.99,
            "h = {h}: q = {}",
            end.q[0]
        );
    }
}

/// Two damped springs about equilibria far from the origin (`c = 1e6`): the forces, of
/// size 1e-3, are differences of positions of size 1e6, each rounded at about 1e-10.
#[forced_lagrangian(
    coordinates(x, y),
    lagrangian = (x_dot * x_dot + y_dot * y_dot) / 2
        - k * ((x - c) * (x - c) + (y - c) * (y - c) + (y - x) * (y - x)) / 2,
    force(x = -d * x_dot, y = -d * y_dot),
)]
pub struct FarSprings {
    pub k: f64,
    pub c: f64,
    pub d: f64,
}

#[test]
fn extreme_far_positions_converge_at_round_off() {
    // Newton's round-off floor must count the forces' round-off at positions of size |q|,
    // which the increments do not show: with it counted only from the increments and the
    // forces, these steps (like the 1024-site FPU chain's first step at h = T/64 on the
    // sparse backend) were refused as diverging, with the residual at 1e-10.
    let (c, u0) = (1e6, [1e-3, -2e-3]);
    let far = FarSprings { k: 1.0, c, d: 0.1 };
    let near = FarSprings { c: 0.0, ..far };
    for s in 2..=5 {
        for h in [0.5, 0.2, 0.1] {
            let end = |m: &FarSprings| {
                let q = [m.c + u0[0], m.c + u0[1]];
                Integrator::new(m, Scheme::lobatto(s).unwrap(), h)
                    .unwrap()
                    .final_state(InitialState::from_velocity(q, [0.0; 2]), 5.0)
                    .unwrap_or_else(|f| panic!("lobatto{s}, h = {h}, c = {}: {}", m.c, f.error))
            };
            let (a, b) = (end(&far), end(&near));
            // The same motion, up to the round-off of positions of size 1e6 (2e-10 each).
            for i in 0..2 {
                let du = (a.q[i] - c) - b.q[i];
                assert!(
                    du.abs() < 1e-8,
                    "lobatto{s}, h = {h}: displacement {i} off by {du:e}"
                );
            }
        }
    }
    // The sparse backend: the FPU chain at n = 1024, four steps of T/64.
    let chain = forced_vi_models::large::FpuChain::<1024>::default();
    let integ = Integrator::new(&chain, Scheme::lobatto(3).unwrap(), 100.0 / 64.0).unwrap();
    assert_eq!(
        integ
            .path_for(&forced_vi_models::large::FpuChain::<1024>::initial())
            .unwrap(),
        forced_vi::LinearPath::Sparse
    );
    let end = integ
        .final_state(
            forced_vi_models::large::FpuChain::<1024>::initial(),
            4.0 * 100.0 / 64.0,
        )
        .unwrap_or_else(|f| panic!("fpu_chain 1024: {}", f.error));
    assert_eq!(end.stats.steps, 4);
}

/// Hairer's scaled van der Pol at μ = 10⁶ (`ε = 10⁻¹²`, τ ∈ [0, 2], run as the unscaled
/// model over t ∈ [0, 2·10⁶]): adaptive lobatto6 goes through the initial layer and both
/// relaxation jumps and ends `Ok` within the tolerance of `x(2)` from scipy's Radau on the
/// scaled form (`data/reference/van_der_pol_scaled_1e6.csv`, good to about 1e-13). Its
/// steps at the jumps (about 10⁻⁷) stay far above the floor `16ε t` that stops lobatto4
/// there; the stability report has every scheme and tolerance.
#[test]
fn extreme_scaled_van_der_pol_mu_1e6_adaptive_lobatto6_ends_within_tolerance() {
    let x_ref = 1.705_546_217_535_202_5;
    let model = forced_vi_models::models::StiffVanDerPol::VERY_STIFF;
    for tol in [1e-3, 1e-6] {
        let end = Integrator::adaptive(&model, Scheme::lobatto(6).unwrap(), tol, tol)
            .unwrap()
            .final_state(InitialState::from_velocity([2.0], [0.0]), 2.0e6)
            .unwrap_or_else(|f| panic!("tol {tol}: {}", f.error));
        let err = (end.q[0] - x_ref).abs();
        assert!(err <= tol, "tol {tol}: x(2) off by {err:e}");
        // The run resolves the jumps rather than stepping over them: hundreds of steps.
        assert!(
            end.stats.steps > 100,
            "tol {tol}: {} steps",
            end.stats.steps
        );
    }
}

/// An adaptive step's Newton solve may stop short of round-off (`crate::control`, "Newton's
/// stop"), and its error in the increments reaches the momenta multiplied by `h |A| + |B|`:
/// on this oscillator `|B|` is up to 3·10⁶. Bounding the increments alone, lobatto8 at tol
/// 3e-1 and lobatto5 at tol 1, with the whole run as the first step, read that error as
/// their estimate at every step size and ended in `StepSizeTooSmall` after one and two
/// steps. Every Lobatto scheme from 5 to 8 at loose tolerances, from either first step, must
/// end `Ok` within the tolerance.
#[test]
fn extreme_scaled_van_der_pol_mu_1e6_loose_tolerances_are_not_held_by_newtons_stop() {
    let x_ref = 1.705_546_217_535_202_5;
    let model = forced_vi_models::models::StiffVanDerPol::VERY_STIFF;
    let t_final = 2.0e6;
    for s in 5..=8 {
        for tol in [1.0, 0.3, 0.1] {
            for whole_first_step in [false, true] {
                let integ = if whole_first_step {
                    Integrator::new(&model, Scheme::lobatto(s).unwrap(), t_final)
                        .and_then(|i| i.tolerances(tol, tol))
                } else {
                    Integrator::adaptive(&model, Scheme::lobatto(s).unwrap(), tol, tol)
                };
                let end = integ
                    .unwrap()
                    .max_steps(200_000)
                    .final_state(InitialState::from_velocity([2.0], [0.0]), t_final)
                    .unwrap_or_else(|f| {
                        panic!(
                            "lobatto{s} tol {tol} first step T {whole_first_step}: {}",
                            f.error
                        )
                    });
                let err = (end.q[0] - x_ref).abs();
                assert!(err <= tol, "lobatto{s} tol {tol}: x(2) off by {err:e}");
            }
        }
    }
}

/// `Integrator::auto` on the same oscillator at a loose and a tight tolerance: its even stage
/// counts (lobatto6, lobatto8) finish within the tolerance, where the odd ones it took before
/// stopped at 1e-5 with a step too small (lobatto5) and needed more than 2·10⁶ steps at 1e-9
/// (lobatto7). The cap turns such a regression into a failure, not a long wait.
#[test]
fn extreme_scaled_van_der_pol_mu_1e6_auto_ends_within_tolerance() {
    let x_ref = 1.705_546_217_535_202_5;
    let model = forced_vi_models::models::StiffVanDerPol::VERY_STIFF;
    for tol in [1e-5, 1e-9] {
        let end = Integrator::auto(&model, tol, tol)
            .unwrap()
            .max_steps(500_000)
            .final_state(InitialState::from_velocity([2.0], [0.0]), 2.0e6)
            .unwrap_or_else(|f| panic!("tol {tol}: {}", f.error));
        let err = (end.q[0] - x_ref).abs();
        assert!(err <= tol, "tol {tol}: x(2) off by {err:e}");
    }
}

/// No Lobatto scheme damps a stiff mode that its step does not resolve: on `x'' = −λx'` at
/// `λh = 10⁶`, one step returns the velocity as `+v₀` for an odd number of stages and as
/// `−v₀` for an even one (to `O(1/(λh))`), where the flow takes it to `e^{−λh} v₀ ≈ 0`. The
/// documented reason (`Scheme::for_tolerance`) why `auto` takes even stage counts.
#[test]
fn extreme_lobatto_steps_carry_an_unresolved_stiff_mode_with_the_sign_of_their_parity() {
    // ω tiny, ζ huge: x'' = −ω²x − 2ζω x' ≈ −λ x' with λ = 2ζω = 10⁶.
    let model = forced_vi_models::models::OverdampedOscillator {
        omega: 1e-6,
        zeta: 5e11,
    };
    for s in 2..=8 {
        let end = Integrator::new(&model, Scheme::lobatto(s).unwrap(), 1.0)
            .unwrap()
            .final_state(InitialState::from_velocity([0.0], [1.0]), 1.0)
            .unwrap_or_else(|f| panic!("lobatto{s}: {}", f.error));
        let sign = if s % 2 == 1 { 1.0 } else { -1.0 };
        // Measured: `|v − sign| = 2 s (s − 1) / (λh)`, from 4e-6 (s = 2) to 1.1e-4 (s = 8).
        assert!(
            (end.v[0] - sign).abs() <= 2.0 * (s * s) as f64 / 1e6,
            "lobatto{s}: v = {} after one step",
            end.v[0]
        );
    }
}

/// `Integrator::auto` on a large stiff model (the sparse backend): an over-damped chain of 32
/// masses whose velocities relax at a rate of about 10⁵. lobatto4, which it takes, needs 809
/// steps at tol 1e-3; lobatto3, which it took before, 3.1·10⁴ (24 times the time).
#[test]
fn extreme_overdamped_chain_auto_takes_few_steps_on_the_sparse_backend() {
    const N: usize = 32;
    let model = forced_vi_models::models::SpringChain::<N> {
        m: 1.0,
        k: 1e4,
        beta: 1.0,
        c: 1e5,
    };
    let q0: [f64; N] = std::array::from_fn(|i| {
        let bump = if i == N / 2 { 0.05 } else { 0.0 };
        0.1 * (std::f64::consts::PI * (i + 1) as f64 / (N + 1) as f64).sin() + bump
    });
    let init = InitialState::from_velocity(q0, [0.0; N]);
    let auto = Integrator::auto(&model, 1e-3, 1e-3).unwrap();
    assert_eq!(auto.path_for(&init).unwrap(), forced_vi::LinearPath::Sparse);
    let end = auto
        .max_steps(5000)
        .final_state(init, 200.0)
        .unwrap_or_else(|f| panic!("{}", f.error));
    // Against a lobatto5 run at tol 1e-8 (the shape decays smoothly: q is about 0.087).
    let reference = Integrator::adaptive(&model, Scheme::lobatto(5).unwrap(), 1e-8, 1e-8)
        .unwrap()
        .final_state(init, 200.0)
        .unwrap();
    let err = (0..N)
        .map(|i| (end.q[i] - reference.q[i]).abs())
        .fold(0.0, f64::max);
    assert!(err <= 1e-3, "off by {err:e}");
}

/// `Integrator::auto` on a smaller model of the sparse backend (12 masses, the same
/// over-damped chain): there the node evaluations, not the LU, are most of a step, and it
/// takes the dense column's order (lobatto6 at tol 1e-3, order 10), still on the sparse
/// backend. Measured (`Scheme::AUTO_SPARSE_MIN_DOF`): 162 steps in 5.3 ms, where lobatto4,
/// which it took before, needed 852 steps and 11.7 ms.
#[test]
fn extreme_small_sparse_chain_auto_takes_the_dense_order() {
    const N: usize = 12;
    let model = forced_vi_models::models::SpringChain::<N> {
        m: 1.0,
        k: 1e4,
        beta: 1.0,
        c: 1e5,
    };
    let q0: [f64; N] = std::array::from_fn(|i| {
        let bump = if i == N / 2 { 0.05 } else { 0.0 };
        0.1 * (std::f64::consts::PI * (i + 1) as f64 / (N + 1) as f64).sin() + bump
    });
    let init = InitialState::from_velocity(q0, [0.0; N]);
    let auto = Integrator::auto(&model, 1e-3, 1e-3).unwrap();
    assert_eq!(auto.path_for(&init).unwrap(), forced_vi::LinearPath::Sparse);
    assert_eq!(auto.scheme().order(), 10);
    let end = auto
        .max_steps(2000)
        .final_state(init, 200.0)
        .unwrap_or_else(|f| panic!("{}", f.error));
    let reference = Integrator::adaptive(&model, Scheme::lobatto(5).unwrap(), 1e-8, 1e-8)
        .unwrap()
        .final_state(init, 200.0)
        .unwrap();
    let err = (0..N)
        .map(|i| (end.q[i] - reference.q[i]).abs())
        .fold(0.0, f64::max);
    assert!(err <= 1e-3, "off by {err:e}");
    assert!(end.stats.steps < 400, "{} steps", end.stats.steps);
}
