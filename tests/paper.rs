//! The paper's tests (DESIGN §5): `cargo test --workspace --release paper_`.

use forced_vi::prelude::*;
use forced_vi::SchemeId;
use forced_vi_scenes::models::{CoupledVanDerPol, DampedOscillator};
use forced_vi_scenes::reference::{embedded, Reference, ReferencePoint};
use forced_vi_scenes::report::orders::{observed_order, slope};

fn reference(scene: &str) -> Reference {
    Reference::parse(embedded(scene).expect("embedded reference")).expect("valid reference")
}

/// Max-norm errors in q, p and energy at the final time against a reference row.
fn final_errors<M: ForcedLagrangian<2>>(
    model: &M,
    id: SchemeId,
    h: f64,
    init: &ReferencePoint,
    goal: &ReferencePoint,
) -> [f64; 3] {
    let q0 = [init.q[0], init.q[1]];
    let v0 = [init.v[0], init.v[1]];
    let run = Integrator::new(model, Scheme::new(id).unwrap(), h)
        .unwrap()
        .solve(InitialState::from_velocity(q0, v0), goal.t, output::Records)
        .unwrap();
    let end = run.last().unwrap();
    assert!((end.t - goal.t).abs() < 1e-12);
    let eq = (0..2)
        .map(|i| (end.q[i] - goal.q[i]).abs())
        .fold(0.0, f64::max);
    let ep = (0..2)
        .map(|i| (end.p[i] - goal.p[i]).abs())
        .fold(0.0, f64::max);
    [eq, ep, (end.energy - goal.energy).abs()]
}

/// Step sizes 1/n from 1 down to 5e-5.
fn grid() -> Vec<f64> {
    [
        1, 2, 4, 5, 8, 10, 12, 14, 16, 20, 25, 32, 40, 50, 64, 80, 100, 200, 400, 1000, 2000, 5000,
        10000, 20000,
    ]
    .iter()
    .map(|&n| 1.0 / n as f64)
    .collect()
}

fn lobatto_errors(s: usize, members: &[usize], steps: &[f64]) -> Vec<(f64, [f64; 3])> {
    let scene = if members.len() > 1 {
        "coupled_van_der_pol_ensemble"
    } else {
        "coupled_van_der_pol"
    };
    let r = reference(scene);
    steps
        .iter()
        .map(|&h| {
            let mut sum = [0.0; 3];
            for &m in members {
                let e = final_errors(
                    &CoupledVanDerPol::PAPER,
                    SchemeId::Lobatto(s),
                    h,
                    r.initial(m).unwrap(),
                    r.at(m, 1.0).unwrap(),
                );
                for k in 0..3 {
                    sum[k] += e[k] / members.len() as f64;
                }
            }
            (h, sum)
        })
        .collect()
}

fn check_orders(s: usize, errs: &[(f64, [f64; 3])], what: &str) {
    let expected = (2 * s - 2) as f64;
    for (k, name) in ["q", "p", "energy"].iter().enumerate() {
        let pts: Vec<(f64, f64)> = errs.iter().map(|(h, e)| (*h, e[k])).collect();
        let fit = observed_order(&pts, 1.0)
            .unwrap_or_else(|| panic!("{what} lobatto{s} {name}: too few points in range"));
        let (order, used) = (fit.order, fit.used.len());
        eprintln!("{what} lobatto{s} {name}: order {order:.3} over {used} points");
        assert!(
            (order - expected).abs() <= 0.3,
            "{what} lobatto{s} {name}: fitted order {order:.3}, expected {expected}"
        );
    }
}

#[test]
fn paper_coupled_van_der_pol_lobatto_orders() {
    for s in 2..=5 {
        let errs = lobatto_errors(s, &[0], &grid());
        check_orders(s, &errs, "single");
    }
}

#[test]
fn paper_coupled_van_der_pol_flat_tails() {
    let tail = [1e-3, 5e-4, 2e-4, 1e-4, 5e-5];
    for s in 3..=5 {
        let errs = lobatto_errors(s, &[0], &tail);
        for (h, e) in &errs {
            eprintln!(
                "lobatto{s} h={h:e}: err q {:.2e} p {:.2e} energy {:.2e}",
                e[0], e[1], e[2]
            );
            assert!(
                e.iter().all(|&x| x <= 1e-12),
                "lobatto{s} h={h}: {e:?} above 1e-12"
            );
        }
        // No round-off growth: slimplectic's error grows like h^-2 here; a slope more negative
        // than −0.5 (faster than the √steps random walk) would be a round-off problem.
        for k in 0..3 {
            // Below one ulp of an O(1) value (2.2e-16) errors are quantised noise.
            let pts: Vec<(f64, f64)> = errs
                .iter()
                .map(|(h, e)| (*h, e[k].max(f64::EPSILON)))
                .collect();
            let slope = slope(&pts).unwrap();
            assert!(
                slope > -0.5,
                "lobatto{s}: error grows as h shrinks (slope {slope:.2})"
            );
        }
    }
}

#[test]
fn paper_coupled_van_der_pol_ensemble_orders() {
    let r = reference("coupled_van_der_pol_ensemble");
    let members: Vec<usize> = (0..r.members()).collect();
    assert_eq!(members.len(), 25);
    for s in 2..=5 {
        // Only as far down as the error stays above the fitting floor, to save time.
        let smallest = [0.0, 0.0, 5e-4, 1e-3, 5e-3, 5e-3][s];
        let steps: Vec<f64> = grid().into_iter().filter(|&h| h >= smallest).collect();
        let errs = lobatto_errors(s, &members, &steps);
        for (h, e) in &errs {
            eprintln!(
                "lobatto{s} h={h:.5} mean err {:.3e} {:.3e} {:.3e}",
                e[0], e[1], e[2]
            );
        }
        check_orders(s, &errs, "ensemble mean");
    }
}

#[test]
fn paper_energy_balance_converges_at_scheme_order() {
    let model = CoupledVanDerPol::PAPER;
    for s in 2..=5 {
        let mut pts = Vec::new();
        for h in grid() {
            let run = Integrator::new(&model, Scheme::lobatto(s).unwrap(), h)
                .unwrap()
                .solve(
                    InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]),
                    1.0,
                    output::Records,
                )
                .unwrap();
            let worst = run
                .records
                .iter()
                .map(|r| r.energy_balance.abs())
                .fold(0.0, f64::max);
            pts.push((h, worst));
        }
        let order = observed_order(&pts, 1.0).unwrap().order;
        eprintln!("lobatto{s}: energy-balance order {order:.3}");
        assert!(
            (order - (2 * s - 2) as f64).abs() <= 0.3,
            "lobatto{s}: {order}"
        );
    }
}

#[test]
fn paper_damped_oscillator_midpoint_recurrence() {
    let model = DampedOscillator::DEFAULT;
    let h = 0.07;
    let run = Integrator::new(&model, Scheme::midpoint(), h)
        .unwrap()
        .solve(
            InitialState::from_velocity([1.0, 0.0], [0.0, 0.5]),
            200.0 * h,
            output::Records,
        )
        .unwrap();
    let mat = |a: [[f64; 2]; 2]| nalgebra::Matrix2::new(a[0][0], a[0][1], a[1][0], a[1][1]);
    let (m, k, d) = (
        mat(model.mass()),
        mat(model.stiffness()),
        mat(model.damping()),
    );
    let q: Vec<_> = run.records.iter().map(|r| r.q).collect();
    let mut worst: f64 = 0.0;
    for w in q.windows(3) {
        let t1 = m * (w[2] - 2.0 * w[1] + w[0]) / (h * h);
        let t2 = d * (w[2] - w[0]) / (2.0 * h);
        let t3 = k * (w[2] + 2.0 * w[1] + w[0]) / 4.0;
        // Relative to the size of the summands before they cancel: the floating-point
        // evaluation of the recurrence itself cannot be more exact than that.
        let mq = m.abs() * (w[2].abs() + 2.0 * w[1].abs() + w[0].abs()) / (h * h);
        let dq = d.abs() * (w[2].abs() + w[0].abs()) / (2.0 * h);
        let kq = k.abs() * (w[2].abs() + 2.0 * w[1].abs() + w[0].abs()) / 4.0;
        let scale = mq.amax().max(dq.amax()).max(kq.amax());
        worst = worst.max((t1 + t2 + t3).amax() / scale);
    }
    eprintln!("midpoint recurrence: worst relative defect {worst:.2e}");
    assert!(worst <= 1e-12, "relative defect {worst:e}");
}

/// A free particle of mass `m` under a nonlinear force, to read off the discrete forces.
struct Pushed {
    m: f64,
}

impl ForcedLagrangian<1> for Pushed {
    fn lagrangian<D: Scalar>(&self, _q: &[D; 1], v: &[D; 1]) -> D {
        v[0] * v[0] * (0.5 * self.m)
    }
    fn force<D: Scalar>(&self, q: &[D; 1], v: &[D; 1]) -> [D; 1] {
        [q[0].sin() * v[0] + q[0] * q[0] - 0.3]
    }
}

#[test]
fn paper_alpha_rule_forcing_contributions() {
    let model = Pushed { m: 1.7 };
    let h = 0.1;
    for alpha in [0.0, 0.25, 0.5, 0.8, 1.0] {
        let run = Integrator::new(&model, Scheme::new(SchemeId::Alpha(alpha)).unwrap(), h)
            .unwrap()
            .solve(
                InitialState::from_velocity([0.4], [1.1]),
                h,
                output::Records,
            )
            .unwrap();
        let (r0, r1) = (&run.records[0], &run.records[1]);
        let vbar = (r1.q[0] - r0.q[0]) / h;
        let qa = (1.0 - alpha) * r0.q[0] + alpha * r1.q[0];
        let f = model.force::<f64>(&[qa], &[vbar])[0];
        // D1 L_d + h(1−α)F = −p0 and D2 L_d + hαF = p1 (the paper's example).
        let left = -model.m * vbar + h * (1.0 - alpha) * f + r0.p[0];
        let right = model.m * vbar + h * alpha * f - r1.p[0];
        eprintln!("alpha {alpha}: defects {left:.1e} {right:.1e}");
        assert!(
            left.abs() <= 1e-14 && right.abs() <= 1e-14,
            "alpha {alpha}: {left:e} {right:e}"
        );
    }
}
