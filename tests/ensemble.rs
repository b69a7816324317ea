//! Ensembles through the library API (`forced_vi::ensemble`):
//! `cargo test --workspace --release ensemble_`.

use std::time::Instant;

use forced_vi::prelude::*;
use forced_vi::Error;
use forced_vi_scenes::models::CoupledVanDerPol;
use forced_vi_scenes::scenes::{self, Scene};

/// The paper's 25-member ensemble (scene `coupled_van_der_pol_ensemble`) as initial states.
fn paper_members() -> (Vec<InitialState<2>>, f64) {
    let all = scenes::all().expect("scenes build");
    let scene: &dyn Scene = all
        .iter()
        .find(|s| s.name() == "coupled_van_der_pol_ensemble")
        .expect("the ensemble scene exists")
        .as_ref();
    let members = (0..scene.members())
        .map(|m| {
            let (q, v) = scene.initial(m).expect("member exists");
            InitialState::from_velocity([q[0], q[1]], [v[0], v[1]])
        })
        .collect();
    (members, scene.t_final())
}

#[test]
fn ensemble_paper_members_match_member_by_member_runs() {
    let (members, t_final) = paper_members();
    assert_eq!(members.len(), 25);
    let integrator =
        Integrator::new(&CoupledVanDerPol::PAPER, Scheme::lobatto(3).unwrap(), 0.01).unwrap();
    let runs = integrator.ensemble(&members, t_final, output::Records);
    let ends = integrator.ensemble(&members, t_final, output::Final);
    assert_eq!(runs.len(), 25);
    assert_eq!(ends.len(), 25);
    for (m, init) in members.iter().enumerate() {
        let alone = integrator.solve(*init, t_final, output::Records).unwrap();
        // Bit for bit: every member runs the same sequential code.
        assert_eq!(runs[m].as_ref().unwrap(), &alone, "member {m}");
        let (end, last) = (ends[m].as_ref().unwrap(), alone.last().unwrap());
        // The final state leaves out the per-step diagnostics; the state is the same.
        assert_eq!(
            (end.t, end.q, end.p),
            (last.t, last.q, last.p),
            "member {m}"
        );
        assert!((end.v - last.v).amax() <= 1e-12 && (end.energy - last.energy).abs() <= 1e-12);
        assert_eq!(end.stats, alone.stats, "member {m}");
        assert_eq!(end.stats.steps, 100);
    }
}

/// The report's ensemble path (`Scene::run_variational_members`, through
/// `Integrator::ensemble`) gives each member's outcome of a run of its own, to the bit: fixed
/// steps and adaptive ones, a paired scheme (lobatto3) and one that is not (lobatto5).
#[test]
fn ensemble_scene_path_matches_member_by_member_runs() {
    let all = scenes::all().expect("scenes build");
    let scene: &dyn Scene = all
        .iter()
        .find(|s| s.name() == "coupled_van_der_pol_ensemble")
        .expect("the ensemble scene exists")
        .as_ref();
    for (s, x, adaptive) in [
        (3, 0.05, false),
        (5, 0.25, false),
        (3, 1e-6, true),
        (5, 1e-8, true),
    ] {
        let scheme = Scheme::lobatto(s).unwrap();
        let together = scene.run_variational_members(&scheme, x, adaptive).unwrap();
        assert_eq!(together.len(), scene.members());
        for (m, t) in together.iter().enumerate() {
            let alone = match adaptive {
                true => scene.run_adaptive(&scheme, x, m),
                false => scene.run_variational(&scheme, x, m),
            }
            .unwrap();
            let what = format!("lobatto{s} at {x:e}, adaptive {adaptive}, member {m}");
            assert_eq!(t.end.q, alone.end.q, "{what}");
            assert_eq!(t.end.p, alone.end.p, "{what}");
            assert_eq!(t.end.energy.to_bits(), alone.end.energy.to_bits(), "{what}");
            assert_eq!(
                (t.steps, t.newton_iterations),
                (alone.steps, alone.newton_iterations),
                "{what}"
            );
        }
    }
}

#[test]
fn ensemble_bad_member_gives_its_typed_error_and_the_others_run() {
    let (mut members, t_final) = paper_members();
    members[7] = InitialState::from_velocity([f64::NAN, 0.0], [0.0, 4.0]);
    let integrator =
        Integrator::new(&CoupledVanDerPol::PAPER, Scheme::lobatto(3).unwrap(), 0.01).unwrap();
    let runs = integrator.ensemble(&members, t_final, output::Records);
    let ends = integrator.ensemble(&members, t_final, output::Final);
    for m in 0..members.len() {
        if m == 7 {
            let failure = runs[m].as_ref().unwrap_err();
            assert!(
                matches!(failure.error, Error::NonFiniteInitialData { .. }),
                "{failure}"
            );
            assert!(failure.trajectory.records.is_empty());
            let failure = ends[m].as_ref().unwrap_err();
            assert!(
                matches!(failure.error, Error::NonFiniteInitialData { .. }),
                "{failure}"
            );
        } else {
            let alone = integrator
                .solve(members[m], t_final, output::Records)
                .unwrap();
            assert_eq!(runs[m].as_ref().unwrap(), &alone, "member {m}");
            assert_eq!(ends[m].as_ref().unwrap().q, alone.last().unwrap().q);
        }
    }
}

/// Parameter sets: one model per member through `ensemble::map`.
#[test]
fn ensemble_over_parameter_sets_matches_separate_runs() {
    let models: Vec<CoupledVanDerPol> = [0.1, 0.5, 1.0]
        .iter()
        .map(|&eps| CoupledVanDerPol {
            eps,
            ..CoupledVanDerPol::PAPER
        })
        .collect();
    let init = InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]);
    let run = |m: &CoupledVanDerPol| {
        Integrator::new(m, Scheme::lobatto(3).unwrap(), 0.01)
            .unwrap()
            .solve(init, 1.0, output::Records)
            .map_err(|f| f.error)
    };
    let together = forced_vi::ensemble::map(&models, run);
    for (m, model) in models.iter().enumerate() {
        assert_eq!(together[m], run(model), "member {m}");
    }
}

/// Prints the parallel speed-up of the 25-member ensemble (final state only) on 1 and 2
/// rayon threads. No timed assertion: the machine is shared.
#[test]
fn ensemble_speed_up_on_two_threads_is_reported() {
    let (members, _) = paper_members();
    let t_final = 50.0;
    let integrator =
        Integrator::new(&CoupledVanDerPol::PAPER, Scheme::lobatto(3).unwrap(), 0.01).unwrap();
    let mut best = [f64::INFINITY; 2];
    for (slot, threads) in [1, 2].into_iter().enumerate() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        for _ in 0..3 {
            let start = Instant::now();
            let ends = pool.install(|| integrator.ensemble(&members, t_final, output::Final));
            best[slot] = best[slot].min(start.elapsed().as_secs_f64());
            assert!(ends.iter().all(Result::is_ok));
        }
    }
    let member_steps = members.len() as f64 * (t_final / 0.01).round();
    eprintln!(
        "ensemble (25 members, lobatto3, h = 0.01, t = {t_final}, final state only): \
         1 thread {:.1} ms ({:.3e} member-steps/s), 2 threads {:.1} ms ({:.3e} member-steps/s), \
         speed-up {:.2}x",
        best[0] * 1e3,
        member_steps / best[0],
        best[1] * 1e3,
        member_steps / best[1],
        best[0] / best[1]
    );
}
