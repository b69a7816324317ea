//! Driven systems, `L(t, q, v)` and `F(t, q, v)` (DESIGN §7): fitted orders 2/4/6/8 in q, p
//! and the energy balance `E − E0 − W + ∫L_t` against independent references (mpmath Taylor
//! series at 25 digits, cross-checked with scipy DOP853 and Radau at 1e-13:
//! `scripts/driven_reference.py`).
//! `cargo test --release --test scenes_suite driven::`.

use forced_vi::prelude::*;
use forced_vi::Error;
use forced_vi_scenes::models::{DrivenDuffing, KapitzaPendulum};
use forced_vi_scenes::reference::Reference;
use forced_vi_scenes::report::orders::observed_order;
use rayon::prelude::*;

/// Final errors in q, p and the energy balance for `lobatto(s)` at each `h` (the step sizes in
/// parallel; each run streams its records and keeps the last).
fn errors<M: ForcedLagrangian<1> + Sync>(
    model: &M,
    text: &str,
    t_final: f64,
    s: usize,
    steps: &[f64],
) -> Vec<(f64, [f64; 3])> {
    let r = Reference::parse(text).unwrap();
    let start = r.initial(0).unwrap();
    let end = r.at(0, t_final).unwrap();
    steps
        .par_iter()
        .map(|&h| {
            let mut last = [f64::NAN; 3];
            Integrator::new(model, Scheme::lobatto(s).unwrap(), h)
                .unwrap()
                .solve(
                    InitialState::from_velocity([start.q[0]], [start.v[0]]),
                    t_final,
                    output::each_step(|r| last = [r.q[0], r.p[0], r.energy_balance]),
                )
                .unwrap_or_else(|f| panic!("lobatto{s} h={h}: {}", f.error));
            let eq = (last[0] - end.q[0]).abs();
            let ep = (last[1] - end.p[0]).abs();
            (h, [eq, ep, last[2].abs()])
        })
        .collect()
}

fn check(name: &str, s: usize, errs: &[(f64, [f64; 3])], energy_scale: f64) {
    let expected = (2 * s - 2) as f64;
    for (k, what) in ["q", "p", "energy balance"].iter().enumerate() {
        let pts: Vec<(f64, f64)> = errs.iter().map(|(h, e)| (*h, e[k])).collect();
        // q and p: the fit uses errors above 1e-10; below, the chaotic Duffing run amplifies
        // the round-off of its ~10⁵ steps.
        // The balance needs no reference: its floor is the round-off of the energy's terms
        // (the fit's own rule, scaled by the energy).
        let (pts, scale) = if k < 2 {
            (pts.into_iter().filter(|p| p.1 > 1e-10).collect(), 1.0)
        } else {
            (pts, energy_scale)
        };
        let fit = observed_order(&pts, scale)
            .unwrap_or_else(|| panic!("{name} lobatto{s} {what}: no fit in {errs:?}"));
        eprintln!("{name} lobatto{s} {what}: order {:.2}", fit.order);
        // The balance must converge at least at the scheme's order; on Kapitza's pendulum
        // lobatto5's balance falls faster (10.0 over its short window above round-off).
        let ok = if k < 2 {
            (fit.order - expected).abs() <= 0.3
        } else {
            fit.order >= expected - 0.3
        };
        assert!(
            ok,
            "{name} lobatto{s} {what}: order {} (expected {expected}) from {:?}",
            fit.order, fit.used
        );
    }
}

fn grid(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| hi * (lo / hi).powf(k as f64 / (n - 1) as f64))
        .collect()
}

const DUFFING: &str = include_str!("../data/reference/driven_duffing.csv");
const KAPITZA: &str = include_str!("../data/reference/kapitza_pendulum.csv");

#[test]
fn driven_duffing_orders() {
    let t_final = 2.0 * std::f64::consts::PI / 1.2 * 5.0;
    for (s, lo, hi) in [
        (2, 5e-5, 5e-2),
        (3, 1e-3, 2e-1),
        (4, 5e-3, 3e-1),
        (5, 1e-2, 4e-1),
    ] {
        let errs = errors(
            &DrivenDuffing::CHAOTIC,
            DUFFING,
            t_final,
            s,
            &grid(lo, hi, 16),
        );
        check("driven_duffing", s, &errs, 1.0);
    }
}

#[test]
fn driven_kapitza_pendulum_orders() {
    for (s, lo, hi) in [
        (2, 1e-4, 4e-3),
        (3, 1e-4, 1e-2),
        (4, 5e-4, 2e-2),
        (5, 1e-3, 2.5e-2),
    ] {
        let errs = errors(
            &KapitzaPendulum::UPRIGHT,
            KAPITZA,
            10.0,
            s,
            &grid(lo, hi, 16),
        );
        // The balance carries the drive's kinetic energy and its integral, of size
        // m (aΩ)² = 25, whose round-off does not cancel (measured floor ~2e-12).
        check("kapitza_pendulum", s, &errs, 25.0);
    }
}

/// The upright pendulum stays up: Kapitza's stabilisation, run adaptively.
#[test]
fn driven_kapitza_pendulum_stays_upright_adaptively() {
    let run = Integrator::new(&KapitzaPendulum::UPRIGHT, Scheme::lobatto(3).unwrap(), 1e-3)
        .unwrap()
        .tolerances(1e-8, 1e-8)
        .unwrap()
        .solve(
            InitialState::from_velocity([std::f64::consts::PI - 0.3], [0.0]),
            10.0,
            output::Records,
        )
        .unwrap();
    let end = run.last().unwrap();
    assert!(
        (end.q[0] - std::f64::consts::PI).abs() < 0.5,
        "{}",
        end.q[0]
    );
    assert!(end.energy_balance.abs() < 1e-5, "{}", end.energy_balance);
}

/// A model that uses time under `uses_time = false` is refused.
struct Mislabelled;

impl ForcedLagrangian<1> for Mislabelled {
    fn lagrangian<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> D {
        (v[0] * v[0] - q[0] * q[0]) * 0.5
    }
    fn force_at<D: Scalar>(&self, t: D, _q: &[D; 1], _v: &[D; 1]) -> [D; 1] {
        [t.sin()]
    }
}

#[test]
fn driven_time_flag_is_checked() {
    let f = Integrator::new(&Mislabelled, Scheme::lobatto(3).unwrap(), 0.1)
        .unwrap()
        .solve(
            InitialState::from_velocity([1.0], [0.0]),
            1.0,
            output::Records,
        )
        .unwrap_err();
    assert!(matches!(f.error, Error::InvalidModel { .. }), "{}", f.error);
}

mod macro_models {
    use forced_vi::prelude::*;

    /// The driven Duffing oscillator, written with the macro: `t` in the force.
    #[forced_lagrangian(
        coordinates(x),
        lagrangian = x_dot * x_dot / 2 - alpha * x * x / 2 - beta * x.powi(4) / 4,
        force(x = -delta * x_dot + gamma * (omega * t).cos()),
    )]
    pub struct MacroDuffing {
        pub delta: f64,
        pub alpha: f64,
        pub beta: f64,
        pub gamma: f64,
        pub omega: f64,
    }

    /// Kapitza's pendulum, written with the macro: `t` in the Lagrangian.
    #[forced_lagrangian(
        coordinates(th),
        lagrangian = {
            let ys = a * (big_omega * t).cos();
            let yd = -a * big_omega * (big_omega * t).sin();
            0.5 * m * (l * l * th_dot * th_dot + 2 * l * th.sin() * th_dot * yd + yd * yd)
                - m * g * (ys - l * th.cos())
        },
        force(th = -c * th_dot),
    )]
    pub struct MacroKapitza {
        pub m: f64,
        pub l: f64,
        pub g: f64,
        pub a: f64,
        pub big_omega: f64,
        pub c: f64,
    }

    /// An autonomous model: no `t`.
    #[forced_lagrangian(
        coordinates(x),
        lagrangian = x_dot * x_dot / 2 - x * x / 2,
        force(x = -c * x_dot),
    )]
    pub struct Damped {
        pub c: f64,
    }
}

/// Runs both models from the same state with lobatto2…4 and compares every step.
fn same_trajectory<A: ForcedLagrangian<1>, B: ForcedLagrangian<1>>(
    a: &A,
    b: &B,
    h: f64,
    t_final: f64,
    start: ([f64; 1], [f64; 1]),
) {
    for s in [2, 3, 4] {
        let ra = Integrator::new(a, Scheme::lobatto(s).unwrap(), h)
            .unwrap()
            .solve(
                InitialState::from_velocity(start.0, start.1),
                t_final,
                output::Records,
            )
            .unwrap();
        let rb = Integrator::new(b, Scheme::lobatto(s).unwrap(), h)
            .unwrap()
            .solve(
                InitialState::from_velocity(start.0, start.1),
                t_final,
                output::Records,
            )
            .unwrap();
        assert_eq!(ra.records.len(), rb.records.len());
        for (x, y) in ra.records.iter().zip(&rb.records) {
            assert_eq!(x.t, y.t);
            let d = (x.q[0] - y.q[0])
                .abs()
                .max((x.p[0] - y.p[0]).abs())
                .max((x.energy_balance - y.energy_balance).abs());
            assert!(d < 1e-12, "lobatto{s} at t = {}: {d:e}", x.t);
        }
    }
}

/// `t` in `#[forced_lagrangian]` expressions: the macro's driven Duffing oscillator and
/// Kapitza pendulum follow the hand-written models step by step, and say they use time.
#[test]
fn driven_macro_matches_hand_written() {
    use macro_models::{Damped, MacroDuffing, MacroKapitza};
    let d = DrivenDuffing::CHAOTIC;
    let md = MacroDuffing {
        delta: d.delta,
        alpha: d.alpha,
        beta: d.beta,
        gamma: d.gamma,
        omega: d.omega,
    };
    let k = KapitzaPendulum::UPRIGHT;
    let mk = MacroKapitza {
        m: k.m,
        l: k.l,
        g: k.g,
        a: k.a,
        big_omega: k.big_omega,
        c: k.c,
    };
    let (sd, sk) = (
        <MacroDuffing as ForcedLagrangian<1>>::STRUCTURE,
        <MacroKapitza as ForcedLagrangian<1>>::STRUCTURE,
    );
    assert!(sd.uses_time && sd.constant_mass && sd.force_uses_velocity);
    assert!(sk.uses_time && !sk.constant_mass);
    let autonomous = <Damped as ForcedLagrangian<1>>::STRUCTURE;
    assert!(!autonomous.uses_time && autonomous.constant_mass);
    same_trajectory(&md, &d, 0.05, 3.0, ([1.0], [0.0]));
    same_trajectory(&mk, &k, 0.002, 0.5, ([std::f64::consts::PI - 0.3], [0.0]));
    // The generated `doubled_lagrangian` carries the time.
    let (q, v, qq, vv) = ([0.3], [1.0], [0.1], [-0.7]);
    let a = mk.doubled_lagrangian::<f64>(0.7, &q, &v, &qq, &vv);
    let b = forced_vi::doubled::doubled_lagrangian_at(&k, 0.7, &q, &v, &qq, &vv);
    assert!((a - b).abs() < 1e-12 * a.abs().max(1.0), "{a} {b}");
    assert!((a + mk.doubled_lagrangian::<f64>(0.7, &qq, &vv, &q, &v)).abs() < 1e-12);
}
