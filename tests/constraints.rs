//! Holonomic constraints (DESIGN §11, issue 25): the constrained Lobatto schemes (RATTLE at
//! s = 2) against minimal coordinates, the constraints kept at every step, Noether's
//! momentum of a symmetric constrained model, and the typed errors.
//! `cargo test --workspace --release --test constraints`.

use forced_vi::{Error, ForcedLagrangian, InitialState, Integrator, LinearPath, Scalar, Scheme};

const M: f64 = 1.0;
const G: f64 = 9.81;
const L: f64 = 1.5;
const C: f64 = 0.3;

/// A pendulum in Cartesian coordinates with linear air drag: `L = ½m|v|² − m g y`,
/// `F = −c v`, `g(q) = (x² + y² − l²)/2`.
struct CartesianPendulum;

impl ForcedLagrangian<2> for CartesianPendulum {
    fn lagrangian<D: Scalar>(&self, q: &[D; 2], v: &[D; 2]) -> D {
        (v[0] * v[0] + v[1] * v[1]) * (0.5 * M) - q[1] * (M * G)
    }
    fn force<D: Scalar>(&self, _q: &[D; 2], v: &[D; 2]) -> [D; 2] {
        [v[0] * -C, v[1] * -C]
    }
    fn constraint_count(&self) -> usize {
        1
    }
    fn constraints<D: Scalar>(&self, _t: D, q: &[D; 2], g: &mut [D]) {
        g[0] = (q[0] * q[0] + q[1] * q[1] - L * L) * 0.5;
    }
}

/// The same pendulum in its angle from the downward vertical: `L = ½ m l² θ̇² + m g l cos θ`,
/// `F = −c l² θ̇`.
struct AnglePendulum;

impl ForcedLagrangian<1> for AnglePendulum {
    fn lagrangian<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> D {
        v[0] * v[0] * (0.5 * M * L * L) + q[0].cos() * (M * G * L)
    }
    fn force<D: Scalar>(&self, _q: &[D; 1], v: &[D; 1]) -> [D; 1] {
        [v[0] * (-C * L * L)]
    }
}

const THETA0: f64 = 1.2;
const OMEGA0: f64 = 0.4;
const T: f64 = 2.0;

fn cartesian_start() -> InitialState<2> {
    let (s, c) = THETA0.sin_cos();
    InitialState::from_velocity([L * s, -L * c], [L * c * OMEGA0, L * s * OMEGA0])
}

/// The Cartesian state `(x, y, p_x, p_y)` at `T` from the angle form, lobatto5 at h = 1e-3
/// (its error is below 1e-14 here).
fn reference() -> [f64; 4] {
    let end = Integrator::new(&AnglePendulum, Scheme::lobatto(5).expect("scheme"), 1e-3)
        .expect("integrator")
        .final_state(InitialState::from_velocity([THETA0], [OMEGA0]), T)
        .expect("reference run");
    let (th, w) = (end.q[0], end.v[0]);
    let (s, c) = th.sin_cos();
    [L * s, -L * c, M * L * c * w, M * L * s * w]
}

/// Least-squares slope of log err against log h.
fn slope(pts: &[(f64, f64)]) -> f64 {
    let n = pts.len() as f64;
    let (sx, sy) = pts
        .iter()
        .fold((0.0, 0.0), |(a, b), (h, e)| (a + h.ln(), b + e.ln()));
    let (mx, my) = (sx / n, sy / n);
    let (num, den) = pts.iter().fold((0.0, 0.0), |(a, b), (h, e)| {
        (a + (h.ln() - mx) * (e.ln() - my), b + (h.ln() - mx).powi(2))
    });
    num / den
}

#[test]
fn constraint_cartesian_pendulum_converges_to_the_angle_form() {
    let r = reference();
    for s in 2..=5 {
        let order = (2 * s - 2) as f64;
        let mut pts_q = Vec::new();
        let mut pts_p = Vec::new();
        // Larger steps for the higher orders, which reach round-off sooner.
        let h0 = [0.1, 0.1, 0.2, 0.4][s - 2];
        for k in 0..4 {
            let h = h0 / 2f64.powi(k);
            let end = Integrator::new(&CartesianPendulum, Scheme::lobatto(s).expect("s"), h)
                .expect("integrator")
                .final_state(cartesian_start(), T)
                .expect("constrained run");
            let eq = (end.q[0] - r[0]).abs().max((end.q[1] - r[1]).abs());
            let ep = (end.p[0] - r[2]).abs().max((end.p[1] - r[3]).abs());
            // Points above the round-off floor only.
            if eq > 1e-12 {
                pts_q.push((h, eq));
            }
            if ep > 1e-12 {
                pts_p.push((h, ep));
            }
        }
        let (oq, op) = (slope(&pts_q), slope(&pts_p));
        eprintln!(
            "lobatto{s}: order {oq:.2} in q, {op:.2} in p ({} / {} points)",
            pts_q.len(),
            pts_p.len()
        );
        assert!(
            pts_q.len() >= 2 && pts_p.len() >= 2,
            "lobatto{s}: too few points"
        );
        assert!((oq - order).abs() < 0.3, "lobatto{s}: order {oq:.2} in q");
        assert!((op - order).abs() < 0.3, "lobatto{s}: order {op:.2} in p");
    }
}

#[test]
fn constraint_residuals_stay_at_round_off() {
    for s in [2, 3, 5] {
        let integ = Integrator::new(&CartesianPendulum, Scheme::lobatto(s).expect("s"), 0.01)
            .expect("integrator");
        let mut worst = (0.0f64, 0.0f64);
        let mut reported = 0.0f64;
        let mut tension = f64::INFINITY;
        integ
            .for_each_step(cartesian_start(), 50.0, |r| {
                let g = 0.5 * (r.q[0] * r.q[0] + r.q[1] * r.q[1] - L * L);
                let gv = r.q[0] * r.v[0] + r.q[1] * r.v[1];
                worst = (worst.0.max(g.abs()), worst.1.max(gv.abs()));
                reported = reported.max(r.constraint_residual);
                if r.step > 0 {
                    // The rod pulls towards the pivot: the force points along −q.
                    tension = tension
                        .min(-(r.constraint_force[0] * r.q[0] + r.constraint_force[1] * r.q[1]));
                }
            })
            .expect("run");
        assert!(reported <= worst.0.max(worst.1) * 1.01 + 1e-300 && reported > 0.0);
        assert!(tension > 0.0, "the rod pushes: {tension}");
        eprintln!(
            "lobatto{s}: |g| ≤ {:.1e}, |G v| ≤ {:.1e} over 5000 steps",
            worst.0, worst.1
        );
        assert!(worst.0 < 1e-12 * L * L, "lobatto{s}: |g| = {:.1e}", worst.0);
        assert!(
            worst.1 < 1e-12 * L * L,
            "lobatto{s}: |G v| = {:.1e}",
            worst.1
        );
    }
}

/// A spherical pendulum, unforced: `L = ½m|v|² − m g z`, `g(q) = (|q|² − l²)/2`; the
/// rotations about the vertical are a symmetry, so `L_z = m (x ẏ − y ẋ)` is conserved.
struct SphericalPendulum {
    drag: f64,
}

impl ForcedLagrangian<3> for SphericalPendulum {
    fn lagrangian<D: Scalar>(&self, q: &[D; 3], v: &[D; 3]) -> D {
        (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) * (0.5 * M) - q[2] * (M * G)
    }
    fn force<D: Scalar>(&self, _q: &[D; 3], v: &[D; 3]) -> [D; 3] {
        [v[0] * -self.drag, v[1] * -self.drag, v[2] * -self.drag]
    }
    fn constraint_count(&self) -> usize {
        1
    }
    fn constraints<D: Scalar>(&self, _t: D, q: &[D; 3], g: &mut [D]) {
        g[0] = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] - L * L) * 0.5;
    }
}

#[test]
fn constraint_spherical_pendulum_keeps_its_vertical_momentum() {
    // Off the constraints at first: `projected` makes the data consistent.
    let init = InitialState::projected(
        &SphericalPendulum { drag: 0.0 },
        [1.0, 0.2, -1.0],
        [0.1, 1.5, 0.3],
    )
    .expect("projection");
    let lz =
        |q: &nalgebra::SVector<f64, 3>, p: &nalgebra::SVector<f64, 3>| q[0] * p[1] - q[1] * p[0];
    for (drag, bound) in [(0.0, 1e-12), (0.2, f64::INFINITY)] {
        let model = SphericalPendulum { drag };
        let run = Integrator::new(&model, Scheme::lobatto(3).expect("s"), 0.01)
            .expect("integrator")
            .run(init, 20.0)
            .expect("run");
        let first = lz(&run.records[0].q, &run.records[0].p);
        let drift = run
            .records
            .iter()
            .map(|r| (lz(&r.q, &r.p) - first).abs())
            .fold(0.0f64, f64::max);
        let last = run.records.last().expect("records");
        eprintln!(
            "drag {drag}: L_z drift {drift:.1e} (L_z = {first:.3}), energy balance {:.1e}",
            last.energy_balance
        );
        if drag == 0.0 {
            assert!(
                drift < bound * first.abs().max(1.0),
                "L_z drifts by {drift:.1e}"
            );
        } else {
            // With drag L_z decays: the check can fail.
            assert!(lz(&last.q, &last.p).abs() < 0.1 * first.abs());
        }
        // The constraint forces do no work: the ledger balances.
        assert!(
            last.energy_balance.abs() < 1e-4,
            "balance {:.1e}",
            last.energy_balance
        );
    }
}

#[test]
fn constraint_errors_are_typed() {
    let model = CartesianPendulum;
    let integ = Integrator::new(&model, Scheme::lobatto(3).expect("s"), 0.01).expect("integrator");
    // Off the circle, and a velocity across it.
    let off = integ.final_state(InitialState::from_velocity([L, 0.1], [0.0, 0.0]), 1.0);
    assert!(matches!(
        off.map_err(|f| f.error),
        Err(Error::InconsistentInitialState {
            what: "position",
            ..
        })
    ));
    let across = integ.final_state(InitialState::from_velocity([L, 0.0], [1.0, 0.0]), 1.0);
    assert!(matches!(
        across.map_err(|f| f.error),
        Err(Error::InconsistentInitialState {
            what: "velocity",
            ..
        })
    ));
    // A scheme without multipliers at its control points, the sparse backend, tolerances.
    let mid = Integrator::new(&model, Scheme::midpoint(), 0.01).expect("integrator");
    assert!(matches!(
        mid.final_state(cartesian_start(), 1.0).map_err(|f| f.error),
        Err(Error::UnsupportedConstraints { .. })
    ));
    let sparse = Integrator::new(&model, Scheme::lobatto(3).expect("s"), 0.01)
        .expect("integrator")
        .linear_path(LinearPath::Sparse);
    assert!(matches!(
        sparse
            .final_state(cartesian_start(), 1.0)
            .map_err(|f| f.error),
        Err(Error::UnsupportedConstraints { .. })
    ));
    // Derivatives do not carry the multipliers yet: refused, not wrong.
    assert!(matches!(
        integ
            .sensitivities(cartesian_start(), 1.0)
            .map_err(|f| f.error),
        Err(Error::UnsupportedConstraints { .. })
    ));
    assert!(matches!(
        integ
            .adjoint_gradient(cartesian_start(), 1.0, |e| (e.q, e.v))
            .map_err(|f| f.error),
        Err(Error::UnsupportedConstraints { .. })
    ));
}

/// The Cartesian pendulum written with the attribute.
#[forced_vi::forced_lagrangian(
    coordinates(x, y),
    lagrangian = 0.5 * m * (x_dot * x_dot + y_dot * y_dot) - m * g * y,
    force(x = -c * x_dot, y = -c * y_dot),
    constraints(0.5 * (x * x + y * y - l * l)),
)]
struct MacroPendulum {
    m: f64,
    g: f64,
    l: f64,
    c: f64,
}

#[test]
fn constraint_macro_model_equals_the_hand_written_one() {
    let model = MacroPendulum {
        m: M,
        g: G,
        l: L,
        c: C,
    };
    assert_eq!(model.constraint_count(), 1);
    let run = |end: forced_vi::FinalState<2>| (end.q, end.p);
    let a = run(
        Integrator::new(&model, Scheme::lobatto(3).expect("s"), 0.01)
            .expect("integrator")
            .final_state(cartesian_start(), T)
            .expect("macro model"),
    );
    let b = run(
        Integrator::new(&CartesianPendulum, Scheme::lobatto(3).expect("s"), 0.01)
            .expect("integrator")
            .final_state(cartesian_start(), T)
            .expect("hand-written model"),
    );
    assert!((a.0 - b.0).amax() < 1e-13 && (a.1 - b.1).amax() < 1e-13);
}

/// A double pendulum in Cartesian coordinates (two rods, two constraints) with the joint
/// friction of `DoublePendulumFriction`: torques `−c θ̇₁`, `−c θ̇₂` on the absolute angles,
/// as Cartesian forces `F = −c Σ_i θ̇_i ∇θ_i`.
#[forced_vi::forced_lagrangian(
    coordinates(x1, y1, x2, y2),
    lagrangian = 0.5 * m1 * (x1_dot * x1_dot + y1_dot * y1_dot)
        + 0.5 * m2 * (x2_dot * x2_dot + y2_dot * y2_dot)
        - m1 * g * y1
        - m2 * g * y2,
    force(
        x1 = {
            let r1 = x1 * x1 + y1 * y1;
            let dx = x2 - x1;
            let dy = y2 - y1;
            let r2 = dx * dx + dy * dy;
            let w1 = (x1 * y1_dot - y1 * x1_dot) / r1;
            let w2 = (dx * (y2_dot - y1_dot) - dy * (x2_dot - x1_dot)) / r2;
            -c * w1 * (-y1) / r1 - c * w2 * dy / r2
        },
        y1 = {
            let r1 = x1 * x1 + y1 * y1;
            let dx = x2 - x1;
            let dy = y2 - y1;
            let r2 = dx * dx + dy * dy;
            let w1 = (x1 * y1_dot - y1 * x1_dot) / r1;
            let w2 = (dx * (y2_dot - y1_dot) - dy * (x2_dot - x1_dot)) / r2;
            -c * w1 * x1 / r1 + c * w2 * dx / r2
        },
        x2 = {
            let dx = x2 - x1;
            let dy = y2 - y1;
            let r2 = dx * dx + dy * dy;
            let w2 = (dx * (y2_dot - y1_dot) - dy * (x2_dot - x1_dot)) / r2;
            c * w2 * dy / r2
        },
        y2 = {
            let dx = x2 - x1;
            let dy = y2 - y1;
            let r2 = dx * dx + dy * dy;
            let w2 = (dx * (y2_dot - y1_dot) - dy * (x2_dot - x1_dot)) / r2;
            -c * w2 * dx / r2
        },
    ),
    constraints(
        0.5 * (x1 * x1 + y1 * y1 - l1 * l1),
        0.5 * ((x2 - x1) * (x2 - x1) + (y2 - y1) * (y2 - y1) - l2 * l2),
    ),
)]
struct CartesianDoublePendulum {
    m1: f64,
    m2: f64,
    l1: f64,
    l2: f64,
    g: f64,
    c: f64,
}

#[test]
fn constraint_double_pendulum_with_joint_friction_matches_the_angle_form() {
    use forced_vi_models::models::DoublePendulumFriction;
    let d = DoublePendulumFriction::DEFAULT;
    let model = CartesianDoublePendulum {
        m1: d.m1,
        m2: d.m2,
        l1: d.l1,
        l2: d.l2,
        g: d.g,
        c: d.c,
    };
    let (th, w) = ([1.0, 0.5], [0.0, 0.3]);
    let cart = |th: [f64; 2], w: [f64; 2]| {
        let (s1, c1) = th[0].sin_cos();
        let (s2, c2) = th[1].sin_cos();
        let q = [
            d.l1 * s1,
            -d.l1 * c1,
            d.l1 * s1 + d.l2 * s2,
            -d.l1 * c1 - d.l2 * c2,
        ];
        let v = [
            d.l1 * c1 * w[0],
            d.l1 * s1 * w[0],
            d.l1 * c1 * w[0] + d.l2 * c2 * w[1],
            d.l1 * s1 * w[0] + d.l2 * s2 * w[1],
        ];
        (q, v)
    };
    let (q0, v0) = cart(th, w);
    let t_final = 3.0;
    let angle = Integrator::new(&d, Scheme::lobatto(5).expect("s"), 1e-3)
        .expect("integrator")
        .final_state(InitialState::from_velocity(th, w), t_final)
        .expect("angle form");
    let (q_ref, v_ref) = cart([angle.q[0], angle.q[1]], [angle.v[0], angle.v[1]]);
    let mut last = f64::INFINITY;
    for (s, h) in [(3, 0.01), (4, 0.01), (5, 0.02)] {
        let end = Integrator::new(&model, Scheme::lobatto(s).expect("s"), h)
            .expect("integrator")
            .final_state(InitialState::from_velocity(q0, v0), t_final)
            .expect("Cartesian form");
        let eq = (0..4)
            .map(|a| (end.q[a] - q_ref[a]).abs())
            .fold(0.0, f64::max);
        let ev = (0..4)
            .map(|a| (end.v[a] - v_ref[a]).abs())
            .fold(0.0, f64::max);
        eprintln!("lobatto{s} h = {h}: |q − q_ref| = {eq:.1e}, |v − v_ref| = {ev:.1e}");
        assert!(eq < 1e-6 && ev < 1e-5, "lobatto{s}: {eq:.1e} {ev:.1e}");
        last = eq;
    }
    assert!(last < 1e-9, "{last:.1e}");
}

#[test]
fn constraint_adaptive_steps_follow_the_tolerance() {
    let r = reference();
    for s in 2..=5 {
        let mut pts = Vec::new();
        let tols: &[f64] = if s == 2 {
            &[1e-3, 1e-4, 1e-5, 1e-6]
        } else {
            &[1e-4, 1e-6, 1e-8, 1e-10]
        };
        for &tol in tols {
            let end =
                Integrator::adaptive(&CartesianPendulum, Scheme::lobatto(s).expect("s"), tol, tol)
                    .expect("integrator")
                    .final_state(cartesian_start(), T)
                    .expect("adaptive constrained run");
            let err = (0..2)
                .map(|a| (end.q[a] - r[a]).abs().max((end.p[a] - r[2 + a]).abs()))
                .fold(0.0, f64::max);
            eprintln!(
                "lobatto{s} tol {tol:.0e}: {} steps, err {err:.2e} ({:.2} tol)",
                end.stats.steps,
                err / tol
            );
            assert!(err <= 10.0 * tol, "lobatto{s} tol {tol:.0e}: {err:.2e}");
            pts.push((tol, err));
        }
        let k = slope(&pts);
        eprintln!("lobatto{s}: slope {k:.2}");
        assert!((0.7..=1.3).contains(&k), "lobatto{s}: slope {k:.2}");
    }
}

#[test]
fn constraint_dense_output_and_ensembles_work() {
    let model = CartesianPendulum;
    // Dense output between the steps (the cubic Hermite interpolant of the records, error
    // O(h⁴)) against the angle form: with steps of at most 0.02 and then 0.01 the worst
    // error, off the circle and off the angle form's positions, falls 10-fold (measured:
    // 1.4e-7 to 1.4e-8; 16-fold if every step were exactly halved, which the controller
    // does not do).
    // Many times, spread across the steps, so that each run's worst point is near a
    // step's middle.
    let times: Vec<f64> = (0..397).map(|k| k as f64 * 0.005_03 + 0.001).collect();
    let angle = Integrator::new(&AnglePendulum, Scheme::lobatto(5).expect("s"), 1e-3)
        .expect("integrator")
        .sample(InitialState::from_velocity([THETA0], [OMEGA0]), &times)
        .expect("reference samples");
    let worst = |max_step: f64| {
        let samples = Integrator::adaptive(&model, Scheme::lobatto(4).expect("s"), 1e-10, 1e-10)
            .expect("integrator")
            .max_step(max_step)
            .expect("bound")
            .sample(cartesian_start(), &times)
            .expect("samples");
        let mut worst = 0.0f64;
        for (s, a) in samples.iter().zip(&angle) {
            let g = 0.5 * (s.q[0] * s.q[0] + s.q[1] * s.q[1] - L * L);
            let (sn, cs) = a.q[0].sin_cos();
            let e = (s.q[0] - L * sn).abs().max((s.q[1] + L * cs).abs());
            worst = worst.max(g.abs()).max(e);
        }
        worst
    };
    let (coarse, fine) = (worst(0.02), worst(0.01));
    eprintln!("dense output: {coarse:.1e} at steps ≤ 0.02, {fine:.1e} at ≤ 0.01");
    assert!(
        coarse / fine > 10.0 && fine < 2e-8,
        "{coarse:.1e} {fine:.1e}"
    );
    // An ensemble of consistent starts: every member keeps its constraint.
    let members: Vec<InitialState<2>> = (0..6)
        .map(|k| {
            let th = 0.2 + 0.3 * k as f64;
            let (s, c) = th.sin_cos();
            InitialState::from_velocity([L * s, -L * c], [0.0, 0.0])
        })
        .collect();
    let ends = Integrator::new(&model, Scheme::lobatto(3).expect("s"), 0.01)
        .expect("integrator")
        .run_ensemble_final(&members, 2.0);
    for end in &ends {
        let end = end.as_ref().expect("member");
        let g = 0.5 * (end.q[0] * end.q[0] + end.q[1] * end.q[1] - L * L);
        assert!(g.abs() < 1e-13, "{g:.1e}");
    }
}
