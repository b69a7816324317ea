//! The root crate's unit tests, in an integration test so that `cargo test` does not build
//! the report library a second time with `cfg(test)` (it is the slowest crate of the build).
//! `cargo test --workspace --release --test scenes_suite units::`.

mod baselines {
    use forced_vi::ForcedLagrangian;
    use forced_vi::Scalar;
    use forced_vi_scenes::baselines::*;
    use nalgebra::{SMatrix, SVector};

    /// `L = ½vᵀMv − ½qᵀKq`, `F = −Dv` with fixed full matrices.
    struct Linear;
    const M: [[f64; 2]; 2] = [[2.0, 0.5], [0.5, 1.0]];
    const K: [[f64; 2]; 2] = [[3.0, -1.0], [-1.0, 2.0]];
    const D: [[f64; 2]; 2] = [[0.1, 0.02], [0.03, 0.05]];

    impl ForcedLagrangian<2> for Linear {
        fn lagrangian<S: Scalar>(&self, q: &[S; 2], v: &[S; 2]) -> S {
            let mut l = S::from(0.0);
            for i in 0..2 {
                for j in 0..2 {
                    l += (v[i] * v[j] * M[i][j] - q[i] * q[j] * K[i][j]) * 0.5;
                }
            }
            l
        }
        fn force<S: Scalar>(&self, _q: &[S; 2], v: &[S; 2]) -> [S; 2] {
            std::array::from_fn(|i| -(v[0] * D[i][0] + v[1] * D[i][1]))
        }
    }

    #[test]
    fn names_round_trip() {
        for b in Baseline::ALL {
            assert_eq!(b.name().parse::<Baseline>().unwrap(), b);
        }
        assert!("rk4".parse::<Baseline>().is_err());
    }

    #[test]
    fn first_order_form_solves_m_a_plus_d_v_plus_k_q() {
        let sys = OdeSystem::new(&Linear, &[0.0; 2], &[0.0; 2]).with_work();
        let y = [0.3, -0.2, 0.5, 0.1, 0.0];
        let mut dy = [0.0; 5];
        sys.rhs(0.0, &y, &mut dy);
        let mat = |a: [[f64; 2]; 2]| SMatrix::<f64, 2, 2>::from_fn(|i, j| a[i][j]);
        let (q, v) = (SVector::from([y[0], y[1]]), SVector::from([y[2], y[3]]));
        let residual = mat(M) * SVector::from([dy[2], dy[3]]) + mat(K) * q + mat(D) * v;
        assert!(residual.amax() < 1e-14, "{residual}");
        assert_eq!(&dy[..2], &y[2..4]);
        assert!(
            (dy[4] + v.dot(&(mat(D) * v))).abs() < 1e-15,
            "work rate is F·v"
        );
    }

    #[test]
    fn jacobian_times_matches_the_linear_system() {
        let sys = OdeSystem::new(&Linear, &[0.0; 2], &[0.0; 2]);
        let y = [0.3, -0.2, 0.5, 0.1];
        let w = [0.0, 0.0, 1.0, 0.0];
        let mut out = [0.0; 4];
        sys.jacobian_times(0.0, &y, &w, &mut out);
        // ∂(q')/∂v₁ = e₁; ∂(v')/∂v₁ = −M⁻¹ D e₁.
        let mat = |a: [[f64; 2]; 2]| SMatrix::<f64, 2, 2>::from_fn(|i, j| a[i][j]);
        let expect = -(mat(M).try_inverse().unwrap() * mat(D))
            .column(0)
            .into_owned();
        assert_eq!(&out[..2], &[1.0, 0.0]);
        assert!((out[2] - expect[0]).abs() < 1e-7 && (out[3] - expect[1]).abs() < 1e-7);
    }

    #[test]
    fn bad_tolerance_is_an_error() {
        let sys = OdeSystem::new(&Linear, &[0.0; 2], &[0.0; 2]);
        let y0 = sys.initial_state(&[1.0, 0.0], &[0.0, 0.0]);
        for tol in [0.0, -1.0, f64::NAN] {
            let r = solve(&sys, Baseline::Dop853, tol, &y0, 1.0, |_, _| {});
            assert!(matches!(r, Err(BaselineError::InvalidTolerance(_))));
        }
    }
}

mod report {
    use forced_vi::SchemeId;
    use forced_vi_scenes::baselines::Baseline;
    use forced_vi_scenes::report::*;

    #[test]
    fn methods_parse() {
        assert_eq!(
            "lobatto3".parse::<Method>().unwrap(),
            Method::Variational(SchemeId::Lobatto(3))
        );
        assert_eq!(
            "bdf".parse::<Method>().unwrap(),
            Method::Baseline(Baseline::Bdf)
        );
        assert!("rk4".parse::<Method>().is_err());
        let names: Vec<String> = Method::defaults().iter().map(Method::name).collect();
        assert_eq!(
            names,
            [
                "lobatto2", "lobatto3", "lobatto4", "lobatto5", "midpoint", "dop853", "tsit45",
                "bdf", "esdirk34"
            ]
        );
    }
}

mod report_readme {
    use forced_vi_scenes::report::readme::*;
    use std::fs;

    #[test]
    fn sections_are_ordered_and_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path();
        write_section(out, "step_cost", "## Step cost\nc").unwrap();
        write_section(out, "zzz_extra", "## Extra\nz").unwrap();
        write_section(out, "work_precision", "## Work\nold").unwrap();
        write_section(out, "work_precision", "## Work\nnew").unwrap();
        let readme = fs::read_to_string(out.join("README.md")).unwrap();
        assert!(readme.starts_with("# forced-vi report"));
        let (w, c, z) = (
            readme.find("## Work").unwrap(),
            readme.find("## Step cost").unwrap(),
            readme.find("## Extra").unwrap(),
        );
        assert!(w < c && c < z);
        assert!(readme.contains("new") && !readme.contains("old"));
        assert!(write_section(out, "../evil", "x").is_err());
    }
}

mod report_plan {
    use forced_vi_scenes::report::plan::*;

    #[test]
    fn step_sizes_cover_the_range_and_land_on_t() {
        let p = Plan::full();
        let hs = p.step_sizes(1.0, 4);
        assert_eq!(hs[0], 1.0);
        assert!((hs.last().unwrap() - 5e-5).abs() < 1e-18);
        assert!(hs.windows(2).all(|w| w[1] < w[0]));
        for h in p.step_sizes(20.0, 4) {
            let n = 20.0 / h;
            assert!((n - n.round()).abs() < 1e-9 && h <= 1.0);
        }
    }

    #[test]
    fn repeats_adapt_to_run_time() {
        let p = Plan::full();
        assert_eq!(p.repeats(10.0), 1);
        assert_eq!(p.repeats(1e-6), p.max_repeats);
        assert!(Plan::quick().tolerances.last().unwrap() >= &1e-13);
    }

    #[test]
    fn sweeps_predict_the_cost_of_the_next_point() {
        use forced_vi_scenes::report::work_precision::sweep::predicted_seconds;
        use forced_vi_scenes::report::work_precision::Mode;
        use forced_vi_scenes::report::Method;
        let m = |s: &str| s.parse::<Method>().unwrap();
        let close = |a: Option<f64>, b: f64| a.is_some_and(|a| (a - b).abs() <= 1e-12 * b);
        // Fixed steps: work as 1/h, whatever the order.
        let fixed = predicted_seconds(&m("lobatto5"), Mode::Fixed, (1e-2, 0.5), 1e-3);
        assert!(close(fixed, 5.0));
        // Adaptive: work as tol^(-1/p); midpoint has p = 2, lobatto3 p = 4.
        let mid = predicted_seconds(&m("midpoint"), Mode::Adaptive, (1e-4, 0.14), 1e-7);
        assert!(close(mid, 0.14 * 1e3f64.sqrt()));
        let l3 = predicted_seconds(&m("lobatto3"), Mode::Adaptive, (1e-4, 0.1), 1e-8);
        assert!(close(l3, 1.0));
        // The quick plan's cap (4 × 0.25 s) stops the midpoint sweep, not lobatto3's.
        let cap = PREDICTED_RUN_FACTOR * Plan::quick().max_run_seconds;
        assert!(mid.unwrap() > cap && l3.unwrap() <= cap);
        // The baselines' effective order varies: no prediction.
        assert!(predicted_seconds(&m("bdf"), Mode::Adaptive, (1e-4, 0.1), 1e-8).is_none());
    }
}

mod report_style {
    use forced_vi::SchemeId;
    use forced_vi_scenes::baselines::Baseline;
    use forced_vi_scenes::report::style::*;
    use forced_vi_scenes::report::Method;

    #[test]
    fn looks_and_labels() {
        let l2 = Method::Variational(SchemeId::Lobatto(2));
        let bdf = Method::Baseline(Baseline::Bdf);
        assert_eq!(Look::of(&l2, &[]).color, PALETTE[0]);
        assert!(Look::of(&bdf, &[]).dashed && !Look::of(&l2, &[]).dashed);
        assert!(Look::adaptive(&l2, &[]).dashed);
        assert_eq!(Look::adaptive(&l2, &[]).color, PALETTE[0]);
        let external = Look::external();
        assert!(external.dashed && !PALETTE.contains(&external.color));
        assert_eq!(external.shape, Some(Shape::HollowSquare));
        assert_eq!(sci(&1e-3), "1e-3");
        assert_eq!(sci(&1.0), "1");
        assert_eq!(log_range([1.0, 4.0, -1.0].into_iter()), Some((0.5, 8.0)));
    }
}

mod report_study {
    use forced_vi_scenes::report::study::*;

    struct Squares;

    impl Study for Squares {
        type Case = i32;
        type Row = Option<i32>;
        const PARALLEL: bool = true;
        fn label(&self, case: &i32) -> String {
            case.to_string()
        }
        fn run(&self, case: &i32) -> Option<i32> {
            assert!(*case != 3, "three");
            Some(case * case)
        }
        fn panicked(&self, _: &i32) -> Option<i32> {
            None
        }
    }

    #[test]
    fn rows_keep_the_case_order_and_panics_become_rows() {
        let hook = std::panic::take_hook();
        std::panic::set_hook(Box::new(|_| {}));
        let rows = run_cases(&Squares, &[1, 2, 3, 4], false);
        std::panic::set_hook(hook);
        assert_eq!(rows, [Some(1), Some(4), None, Some(16)]);
        assert!(check_scenes(&["x".into()], &["a", "b"]).is_err());
        assert!(selected(&[], "a") && !selected(&["b".into()], "a"));
    }
}

mod report_table {
    use forced_vi_scenes::report::table::*;
    use serde::{Deserialize, Serialize};
    use std::fs;

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct R {
        name: String,
        #[serde(with = "sci")]
        x: f64,
        #[serde(with = "sci::opt")]
        y: Option<f64>,
        n: usize,
    }

    #[test]
    fn csv_header_from_fields_and_floats_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.csv");
        let rows = [
            R {
                name: "a".into(),
                x: 1.5e-3,
                y: None,
                n: 3,
            },
            R {
                name: "b".into(),
                x: 0.1,
                y: Some(2.0),
                n: 0,
            },
        ];
        write_csv(&path, &rows).unwrap();
        let text = fs::read_to_string(&path).unwrap();
        assert_eq!(text, "name,x,y,n\na,1.5e-3,,3\nb,1e-1,2e0,0\n");
        let back: Vec<R> = csv::Reader::from_path(&path)
            .unwrap()
            .deserialize()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(back, rows);
        write_csv::<R>(&path, &[]).unwrap();
        assert_eq!(fs::read_to_string(&path).unwrap(), "name,x,y,n\n");
    }

    #[test]
    fn markdown_from_columns() {
        let rows = [(1, "x"), (2, "")];
        let cols = [
            col("n", |r: &(i32, &str)| r.0.to_string()),
            col("s", |r: &(i32, &str)| r.1.to_string()),
        ];
        assert_eq!(
            markdown(&rows, &cols),
            "| n | s |\n|---|---|\n| 1 | x |\n| 2 | |\n"
        );
    }
}

mod report_orders {
    use forced_vi_scenes::report::orders::*;

    #[test]
    fn recovers_a_clean_power_law() {
        let pts: Vec<_> = (0..10)
            .map(|k| {
                let h = 0.5f64.powi(k);
                (h, 1e-2 * h.powi(4))
            })
            .collect();
        let fit = observed_order(&pts, 1.0).unwrap();
        assert!((fit.order - 4.0).abs() < 1e-9);
    }

    #[test]
    fn ignores_the_round_off_tail_and_large_steps() {
        let mut pts = Vec::new();
        for k in 0..30 {
            let h = 0.7f64.powi(k);
            // order 6 with a pre-asymptotic bump at large h and a floor at 1e-14
            let e = 1e-1 * h.powi(6) * (1.0 + h) + 1e-14 * (1.0 + (k % 3) as f64);
            pts.push((h, e));
        }
        let fit = observed_order(&pts, 2.0).unwrap();
        assert!((fit.order - 6.0).abs() < 0.3, "{}", fit.order);
        assert!(fit.used.iter().all(|&(_, e)| e >= FLOOR * 2.0));
        assert!(fit.used.len() >= 5);
    }

    /// A round-off floor raised above `FLOOR` (a chaotic scene amplifies round-off) scatters;
    /// the fit stops where the curve stops falling (the committed driven_duffing lobatto5
    /// sweep, which fitted 2.07 before this rule).
    #[test]
    fn drops_a_scattered_floor_above_the_floor_constant() {
        let pts = [
            (0.5454, 4.33e-5),
            (0.4091, 1.89e-7),
            (0.3080, 4.60e-8),
            (0.2296, 4.52e-9),
            (0.1722, 4.56e-10),
            (0.1296, 4.71e-11),
            (0.0970, 4.44e-12),
            (0.0727, 4.57e-13),
            (0.0545, 2.25e-14),
            (0.0409, 1.04e-14),
            (0.0307, 8.03e-14),
            (0.0230, 1.29e-13),
            (0.0172, 1.78e-15),
            (0.0129, 4.14e-14),
            (0.0097, 7.92e-14),
        ];
        let fit = observed_order(&pts, 1.0).unwrap();
        assert!((fit.order - 8.0).abs() < 0.3, "{}", fit.order);
        assert!(fit.used.iter().all(|&(h, _)| h > 0.07));
    }

    /// The point just above a scattered tail carries the tail's noise: the quick report's
    /// driven_duffing lobatto5 sweep, with its point at h = 0.061 as measured before and
    /// after a change of the Jacobian's round-off (1.3e-13 and 2.4e-13); with it in the fit
    /// the order read 7.91 and 7.19.
    #[test]
    fn drops_the_points_within_the_noise_of_a_scattered_tail() {
        for near in [1.3078e-13, 2.4480e-13] {
            let pts = [
                (0.9696, 1.0602e-2),
                (0.6088, 3.0255e-4),
                (0.3850, 9.8262e-8),
                (0.2447, 7.4838e-9),
                (0.1540, 1.8639e-10),
                (0.09696, 4.6475e-12),
                (0.06117, near),
                (0.03861, 4.5630e-14),
                (0.02435, 4.4076e-14),
            ];
            let fit = observed_order(&pts, 1.0).unwrap();
            assert!((fit.order - 8.0).abs() < 0.1, "{near:e}: {}", fit.order);
            assert!(fit.used.iter().all(|&(h, _)| h > 0.07), "{near:e}");
        }
    }

    /// A pre-asymptotic wiggle that falls into the dropped tail (a point above its
    /// larger-`h` neighbour, as on the double pendulum's lobatto7 sweep) does not raise the
    /// noise that the points above the tail must clear: the median does not see it, where
    /// the tail's largest error dropped every point below 10 times the wiggle.
    #[test]
    fn a_wiggle_in_the_tail_does_not_raise_the_noise() {
        let mut pts: Vec<(f64, f64)> = (0..40)
            .map(|k| {
                let h = 0.85f64.powi(k);
                (h, 1e-2 * h.powi(8) + 1e-14 * (1.0 + (k % 3) as f64))
            })
            .collect();
        // A bump of 20 at the point whose clean error is just below 3e-13.
        let k = pts
            .iter()
            .position(|&(_, e)| e < 3e-13)
            .expect("the sweep reaches 3e-13");
        pts[k].1 *= 20.0;
        let wiggle = pts[k].1;
        let fit = observed_order(&pts, 1.0).unwrap();
        assert!((fit.order - 8.0).abs() < 0.3, "{}", fit.order);
        assert!(
            fit.used.iter().any(|&(_, e)| e < 10.0 * wiggle),
            "{wiggle:e}: {:?}",
            fit.used
        );
    }

    /// A clean power law settles its order, over three points as over many.
    #[test]
    fn a_clean_power_law_settles_its_order() {
        for (n, ratio) in [(3, 0.5f64), (12, 0.8)] {
            let pts: Vec<_> = (0..n)
                .map(|k| {
                    let h = ratio.powi(k);
                    (h, 1e-4 * h.powi(6) * (1.0 + 1e-3 * h))
                })
                .collect();
            let fit = observed_order(&pts, 1.0).unwrap();
            assert_eq!(fit.unsettled(), None, "{n}: {fit:?}");
            assert!(fit.half_width() < 0.01, "{}", fit.half_width());
        }
    }

    /// Three points of a wiggling curve that line up over too short a fall: the committed
    /// full report's driven_duffing lobatto6 sweep (order 10), which read 11.76 there,
    /// with the segments beyond them at 9.1..21.4.
    #[test]
    fn a_straight_but_short_fit_does_not_settle() {
        let pts = [
            (0.27271, 2.2759e-11),
            (0.25921, 1.3323e-11),
            (0.24467, 7.5222e-12),
            (0.22965, 3.5684e-12),
            (0.21636, 1.7725e-12),
        ];
        let fit = observed_order(&pts[2..], 1.0).unwrap();
        assert!(fit.half_width() < 0.3, "{}", fit.half_width());
        assert!(
            matches!(fit.unsettled(), Some(Unsettled::Short { .. })),
            "{fit:?}"
        );
        // With the two points above them (segments 9.1 and 10.5), the wiggle shows in the
        // residuals.
        let fit = observed_order(&pts, 1.0).unwrap();
        assert!(fit.unsettled().is_some(), "{fit:?}");
    }

    /// A pre-asymptotic triple that reaches the floor with a jump: the committed coupled van
    /// der Pol lobatto7 sweep (order 12), whose first three points above round-off fitted 9.02.
    #[test]
    fn a_bent_triple_does_not_settle() {
        let pts = [
            (1.0, 1.0e-4),
            (0.5, 1.4e-8),
            (1.0 / 3.0, 3.3e-10),
            (0.25, 2.6e-11),
            (0.2, 1.8e-13),
            (1.0 / 6.0, 1.1e-13),
            (1.0 / 7.0, 2.1e-14),
        ];
        let fit = observed_order(&pts, 1.8385).unwrap();
        assert!((fit.order - 9.0).abs() < 0.1, "{fit:?}");
        assert!(
            matches!(fit.unsettled(), Some(Unsettled::Wide { .. })),
            "{fit:?}"
        );
    }

    #[test]
    fn too_few_points_give_none() {
        assert!(observed_order(&[(1.0, 1e-4), (0.5, 1e-5)], 1.0).is_none());
        assert!(observed_order(&[(1.0, 1e-15), (0.5, 1e-16), (0.1, 1e-16)], 1.0).is_none());
    }
}

mod report_timing {
    use forced_vi_scenes::report::timing::*;

    #[test]
    fn median_of_odd_and_even() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(&mut []).is_nan());
    }

    #[test]
    fn repeats_follow_the_first_time_and_stop_on_errors() {
        let mut calls = 0;
        let t = repeated(
            |_| 4,
            || -> Result<usize, ()> {
                calls += 1;
                Ok(calls)
            },
        )
        .unwrap();
        assert_eq!((t.first, calls), (1, 4));
        let mut calls = 0;
        let e = repeated(
            |_| 4,
            || {
                calls += 1;
                if calls == 2 {
                    Err("second")
                } else {
                    Ok(())
                }
            },
        );
        assert_eq!(e, Err("second"));
        let mut order = Vec::new();
        let (a, b) = {
            let order = std::cell::RefCell::new(&mut order);
            interleaved(
                3,
                || -> Result<f64, ()> {
                    order.borrow_mut().push('a');
                    Ok(1.0)
                },
                || {
                    order.borrow_mut().push('b');
                    Ok(2.0)
                },
            )
            .unwrap()
        };
        assert_eq!((a, b), (1.0, 2.0));
        assert_eq!(order, ['a', 'b', 'b', 'a', 'a', 'b']);
        // Several, each round starting one further along; medians per function.
        let order = std::cell::RefCell::new(Vec::new());
        let mut samples = [
            vec![3.0, 1.0, 2.0, 9.0],
            vec![5.0; 4],
            vec![0.5, 7.0, 0.25, 1.0],
        ];
        let (s0, rest) = samples.split_at_mut(1);
        let (s1, s2) = rest.split_at_mut(1);
        let mut f0 = || -> Result<f64, ()> {
            order.borrow_mut().push(0);
            Ok(s0[0].pop().unwrap())
        };
        let mut f1 = || -> Result<f64, ()> {
            order.borrow_mut().push(1);
            Ok(s1[0].pop().unwrap())
        };
        let mut f2 = || -> Result<f64, ()> {
            order.borrow_mut().push(2);
            Ok(s2[0].pop().unwrap())
        };
        let medians = rotated(4, &mut [&mut f0, &mut f1, &mut f2]).unwrap();
        assert_eq!(medians, vec![2.5, 5.0, 0.75]);
        assert_eq!(order.into_inner(), [0, 1, 2, 1, 2, 0, 2, 0, 1, 0, 1, 2]);
        let mut fails = || -> Result<f64, &str> { Err("no") };
        assert_eq!(rotated(2, &mut [&mut fails]), Err("no"));
    }
}

mod handwritten {
    use forced_vi::prelude::*;
    use forced_vi_scenes::handwritten::*;
    use forced_vi_scenes::models::CoupledVanDerPol;
    use nalgebra::{SMatrix, SVector};

    fn close<const R: usize, const C: usize>(
        a: &SMatrix<f64, R, C>,
        b: &SMatrix<f64, R, C>,
        what: &str,
    ) {
        for (x, y) in a.iter().zip(b.iter()) {
            assert!(
                (x - y).abs() <= 1e-14 * x.abs().max(y.abs()).max(1.0),
                "{what}: {a} vs {b}"
            );
        }
    }

    #[test]
    fn kernels_match_generated() {
        let gen = CoupledVanDerPol::PAPER;
        let hand = HandCoupledVanDerPol::PAPER;
        assert_eq!(
            <CoupledVanDerPol as ForcedLagrangian<2>>::STRUCTURE,
            <HandCoupledVanDerPol as ForcedLagrangian<2>>::STRUCTURE
        );
        assert_eq!(gen.coordinate_names(), hand.coordinate_names());
        let mut s = 0.123_f64;
        let mut next = || {
            // A small deterministic generator over [−3, 3].
            s = (s * 9301.0 + 49297.0) % 233280.0;
            s / 233280.0 * 6.0 - 3.0
        };
        for _ in 0..500 {
            let q = SVector::<f64, 2>::new(next(), next());
            let v = SVector::<f64, 2>::new(next(), next());
            let (g, h) = (gen.node_jacobian(&q, &v), hand.node_jacobian(&q, &v));
            close(&g.grad.fq, &h.grad.fq, "fq");
            close(&g.grad.lv, &h.grad.lv, "lv");
            close(&g.a, &h.a, "A");
            close(&g.b, &h.b, "B");
            close(&g.c, &h.c, "C");
            close(&g.e, &h.e, "E");
            let (g, h) = (gen.node_gradient(&q, &v), hand.node_gradient(&q, &v));
            close(&g.fq, &h.fq, "gradient fq");
            close(&g.lv, &h.lv, "gradient lv");
            close(&gen.mass_matrix(&q, &v), &hand.mass_matrix(&q, &v), "mass");
            let (qa, va): ([f64; 2], [f64; 2]) = (q.into(), v.into());
            let (lg, lh) = (gen.lagrangian(&qa, &va), hand.lagrangian(&qa, &va));
            assert!((lg - lh).abs() <= 1e-14 * lg.abs().max(1.0));
            let (fg, fh) = (gen.force(&qa, &va), hand.force(&qa, &va));
            close(&SVector::from(fg), &SVector::from(fh), "force");
        }
    }

    #[test]
    fn trajectories_match_generated() {
        let init = InitialState::from_velocity([-0.5, -0.25], [0.0, 4.0]);
        for id in ["lobatto2", "lobatto3", "lobatto4", "lobatto5", "midpoint"] {
            let scheme = Scheme::new(id.parse().unwrap()).unwrap();
            let a = Integrator::new(&CoupledVanDerPol::PAPER, scheme.clone(), 0.01)
                .unwrap()
                .solve(init, 1.0, output::Records)
                .unwrap();
            let b = Integrator::new(&HandCoupledVanDerPol::PAPER, scheme, 0.01)
                .unwrap()
                .solve(init, 1.0, output::Records)
                .unwrap();
            let (ea, eb) = (a.last().unwrap(), b.last().unwrap());
            assert!((ea.q - eb.q).amax() < 1e-12, "{id}");
            assert!((ea.p - eb.p).amax() < 1e-12, "{id}");
        }
    }
}

mod scenes {
    use forced_vi::Scheme;
    use forced_vi_scenes::baselines::Baseline;
    use forced_vi_scenes::scenes::*;

    fn scene(name: &str) -> Box<dyn Scene> {
        all()
            .unwrap()
            .into_iter()
            .find(|s| s.name() == name)
            .unwrap()
    }

    /// The initial data and final times the report promises (and `scripts/reference.py` uses).
    #[test]
    fn scenes_start_and_end_where_documented() {
        let cases: [(&str, [f64; 2], [f64; 2], f64); 4] = [
            ("coupled_van_der_pol", [-0.5, -0.25], [0.0, 4.0], 1.0),
            ("damped_oscillator", [1.0, 0.0], [0.0, 0.5], 10.0),
            ("double_pendulum_friction", [1.0, 0.5], [0.0, 0.0], 5.0),
            ("kepler_drag", [1.0, 0.0], [0.0, 1.2], 20.0),
        ];
        for (name, q0, v0, t) in cases {
            let s = scene(name);
            assert_eq!(s.members(), 1, "{name}");
            assert_eq!(s.initial(0).unwrap(), (q0.to_vec(), v0.to_vec()), "{name}");
            assert_eq!(s.t_final(), t, "{name}");
        }
        let ens = scene("coupled_van_der_pol_ensemble");
        assert_eq!(ens.members(), 25);
        assert_eq!(ens.t_final(), 1.0);
        for m in 0..25 {
            let (q, v) = ens.initial(m).unwrap();
            assert!(q.iter().all(|x| (-4.0..=4.0).contains(x)));
            assert_eq!(v, vec![0.0, 4.0]);
        }
    }

    /// The report trusts a baseline only because it converges to the references: at a tight
    /// tolerance it agrees with every scene's reference, and tightening the tolerance from
    /// 1e-6 to 1e-10 shrinks its error.
    #[test]
    fn baselines_match_the_references() {
        for s in all().unwrap() {
            for b in Baseline::ALL {
                let bound = match b {
                    Baseline::Dop853 | Baseline::Tsit45 => 1e-7,
                    Baseline::Bdf => 1e-5,
                    Baseline::Esdirk34 => 1e-4,
                };
                let driven = ["driven_duffing", "kapitza_pendulum"].contains(&s.name());
                if driven && !matches!(b, Baseline::Tsit45 | Baseline::Dop853) {
                    // On the driven scenes only the explicit baselines are held to this (DOP853
                    // in autonomous form, see `baselines::solve`): the
                    // implicit ones may fail (ESDIRK34 stops with 50 nonlinear failures on
                    // driven Duffing at tol 1e-6); the report records what they do.
                    continue;
                }
                for m in 0..s.members().min(3) {
                    let r = s.reference(m).unwrap();
                    let err = |tol: f64| {
                        let o = s.run_baseline(b, tol, m).unwrap();
                        let dq = o.end.q.iter().zip(&r.q).map(|(a, b)| (a - b).abs());
                        let dp = o.end.p.iter().zip(&r.p).map(|(a, b)| (a - b).abs());
                        dq.chain(dp).fold(0.0, f64::max)
                    };
                    let (loose, tight) = (err(1e-6), err(1e-10));
                    let name = s.name();
                    assert!(
                        tight <= bound,
                        "{name}/{m} {b}: error {tight:e} at tol 1e-10"
                    );
                    assert!(
                        tight < loose / 10.0,
                        "{name}/{m} {b}: {loose:e} -> {tight:e}"
                    );
                }
            }
        }
    }

    /// The variational schemes converge to the same references (the report's orders rely on
    /// it); the paper tests check this in detail for the paper's scenes.
    #[test]
    fn lobatto_matches_the_references() {
        let scheme = Scheme::lobatto(4).unwrap();
        for s in all().unwrap() {
            // Kapitza's drive has period 0.126: it needs steps below the T/400 = 0.025 of
            // the others.
            let h = if s.name() == "kapitza_pendulum" {
                1e-3
            } else {
                s.t_final() / 400.0
            };
            let o = s.run_variational(&scheme, h, 0).unwrap();
            let r = s.reference(0).unwrap();
            let e = o.end.q.iter().zip(&r.q).map(|(a, b)| (a - b).abs());
            let e = e.fold(0.0, f64::max);
            assert!(e < 1e-8, "{}: {e:e}", s.name());
        }
    }

    #[test]
    fn scene_names_are_unique() {
        let scenes = all().unwrap();
        let mut names: Vec<_> = scenes.iter().map(|s| s.name()).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), scenes.len());
    }

    #[test]
    fn sampler_spreads_points() {
        let mut s = Sampler::new(10.0, 5);
        let kept: Vec<f64> = (0..=100)
            .map(|k| k as f64 * 0.1)
            .filter(|&t| s.take(t))
            .collect();
        assert!((5..=6).contains(&kept.len()), "{kept:?}");
        assert_eq!(kept[0], 0.0);
    }
}

mod report_step_cost {
    use forced_vi_scenes::report::step_cost::*;
    use forced_vi_scenes::report::step_cost::{compile, scaling};

    #[test]
    fn exponent_fit() {
        let rows: Vec<Row> = [32usize, 128, 512]
            .iter()
            .map(|&n| Row {
                scene: "fpu_chain".into(),
                method: "lobatto3".into(),
                n,
                diagnostics: "full",
                path: "sparse",
                generated: Some((n as f64).powi(2)),
                handwritten: None,
                iters: None,
                allocs: None,
                note: String::new(),
            })
            .collect();
        let fits = scaling::exponents(&rows);
        assert_eq!(fits.len(), 1);
        assert!((fits[0].exponent - 2.0).abs() < 1e-9);
        assert_eq!(fits[0].sizes, [32, 128, 512]);
        assert_eq!(
            (fits[0].scene.as_str(), fits[0].path),
            ("fpu_chain", "sparse")
        );
    }

    #[test]
    fn compile_crate_source_has_every_model() {
        let src = compile::crate_source(10);
        for i in 0..10 {
            assert!(src.contains(&format!("pub fn run{i}()")));
            assert!(src.contains(&format!("pub struct M{i}")));
        }
        assert!(compile::crate_source(1).contains("M0 { eps: 0.5, rho: 0.5, lambda: 0.5 }"));
    }

    mod first_answer {
        use forced_vi_scenes::report::step_cost::first_run::*;

        #[test]
        fn the_committed_heyoka_runs_and_reference_are_read() {
            let (runs, note) = heyoka_runs(HEYOKA_CSV).expect("runs");
            assert!(note.contains("heyoka_first_run.py"), "{note}");
            for tol in [1e-6, 1e-9] {
                let modes: Vec<&str> = (runs.iter())
                    .filter(|(t, _)| *t == tol)
                    .map(|(_, r)| r.mode.as_str())
                    .collect();
                assert_eq!(modes, ["default", "compact"], "tol {tol:e}");
            }
            for (tol, r) in &runs {
                assert!(r.jit > 0.0 && r.run > 0.0, "{tol:e} {r:?}");
                assert!(r.error > 0.0 && r.error < *tol, "{tol:e} {r:?}");
            }
            let q = reference(REFERENCE_CSV).expect("reference");
            assert_eq!(q.len(), N);
            assert!(q.iter().all(|x| x.is_finite()) && q.iter().any(|x| x.abs() > 1e-3));
        }

        #[test]
        fn the_table_adds_build_and_run_and_says_why_a_run_is_missing() {
            let heyoka = vec![HeyokaRun {
                mode: "compact".into(),
                jit: 0.2,
                run: 0.001,
                error: 1e-8,
            }];
            let forced = ForcedRun {
                tol: 1e-7,
                scheme: "lobatto4".into(),
                steps: 45,
                process: 0.02,
                inner: 0.015,
                error: 3e-9,
            };
            let rows = vec![
                FirstRow {
                    tol: 1e-6,
                    heyoka: heyoka.clone(),
                    forced: Some(forced),
                },
                FirstRow {
                    tol: 1e-9,
                    heyoka,
                    forced: None,
                },
            ];
            let f = FirstRun {
                build: 5.0,
                rows,
                note: "n".into(),
            };
            let mut md = String::new();
            markdown(&mut md, &Ok(f));
            assert!(md.contains("200.0 ms + 1.0 ms = **201.0 ms**"), "{md}");
            assert!(md.contains("5.0 s + 20.0 ms = **5.0 s**"), "{md}");
            assert!(md.contains("no tolerance of the ladder reached it"), "{md}");
            let mut md = String::new();
            markdown(&mut md, &Err("why".into()));
            assert!(md.contains("Not measured: why."), "{md}");
        }
    }
}

mod report_equal_error {
    use forced_vi::SchemeId;
    use forced_vi_scenes::report::work_precision::equal_error::*;
    use forced_vi_scenes::report::work_precision::{Mode, Row, Spread, Summary};
    use forced_vi_scenes::report::Method;

    fn row(mode: Mode, h_or_tol: f64, steps: usize, seconds: f64, err: f64) -> Row {
        let e = Spread {
            min: err,
            mean: err,
            max: err,
        };
        Row {
            scene: "s",
            method: Method::Variational(SchemeId::Lobatto(4)),
            mode,
            h_or_tol,
            steps,
            member_steps_min: steps,
            newton_iters: steps,
            seconds,
            err: [e; 3],
        }
    }

    /// On power laws the interpolation is exact: an adaptive run at the error of 30 uniform
    /// steps, taking 30 steps in twice their time, is a time ratio of 2 from steps 1 and
    /// per-step cost 2; runs too short, within the floor or outside the curve are left out.
    #[test]
    fn adaptive_runs_are_read_against_the_fixed_curve_at_their_error() {
        let err = |n: f64| n.powi(-6);
        let mut rows: Vec<Row> = [10usize, 20, 40, 80]
            .iter()
            .map(|&n| {
                row(
                    Mode::Fixed,
                    1.0 / n as f64,
                    n,
                    n as f64 * 1e-6,
                    err(n as f64),
                )
            })
            .collect();
        rows.push(row(Mode::Adaptive, 1e-8, 30, 60e-6, err(30.0)));
        rows.push(row(Mode::Adaptive, 1e-6, 3, 6e-6, err(12.0)));
        rows.push(row(Mode::Adaptive, 1e-4, 5, 1e-5, err(5.0)));
        rows.push(row(Mode::Adaptive, 1e-12, 90, 1e-4, 1e-16));
        let summary = Summary {
            methods: vec![Method::Variational(SchemeId::Lobatto(4))],
            rows,
            ..Summary::default()
        };
        let lines = lines(&summary, "s", |e| e < 1e-13);
        assert_eq!(lines.len(), 1);
        let p = &lines[0].pairs;
        assert_eq!(p.len(), 1, "{p:?}");
        assert_eq!(p[0].tol, 1e-8);
        assert!((p[0].time - 2.0).abs() < 1e-9, "{p:?}");
        assert!((p[0].steps - 1.0).abs() < 1e-9, "{p:?}");
        assert!((p[0].per_step() - 2.0).abs() < 1e-9, "{p:?}");
        // Between two fixed runs, not at one: 25 steps.
        let fixed: Vec<&Row> = summary
            .rows
            .iter()
            .filter(|r| r.mode == Mode::Fixed)
            .collect();
        let n = fixed_at(&fixed, err(25.0), |r| r.steps as f64).unwrap();
        assert!((n - 25.0).abs() < 1e-9, "{n}");
        assert_eq!(fixed_at(&fixed, err(5.0), |r| r.seconds), None);
        // The runs timed again: between 20 and 40 steps, halfway in log scale at about 28.3.
        let (f0, f1, x) = bracket(&fixed, err(800f64.sqrt())).unwrap();
        assert_eq!((f0.steps, f1.steps), (40, 20));
        assert!((x - 0.5).abs() < 1e-9, "{x}");
        // An adaptive run of 2 against fixed runs of 1 and 4 there: the curve gives 2, ratio 1.
        assert!((ratio_from(&[2.0, 1.0, 4.0], x).unwrap() - 1.0).abs() < 1e-9);
        assert_eq!(ratio_from(&[2.0, 0.0, 4.0], x), None);
    }
}

mod report_stiff_cost {
    use forced_vi_scenes::baselines::Baseline;
    use forced_vi_scenes::report::stability::*;

    fn adaptive(method: &str, tol: f64, err: f64, seconds: f64) -> Row {
        Row {
            scene: "stiff_van_der_pol",
            method: method.into(),
            h: 2000.0,
            tol: Some(tol),
            outcome: Outcome::Ok,
            steps_done: 100,
            max_newton_iters: 3,
            err_final: err,
            max_energy_balance_err: 0.0,
            subdivided_steps: 0,
            rejected_steps: 0,
            seconds,
        }
    }

    /// The table reads the runs timed again, not the sweeps' times: the sweeps rank
    /// lobatto3 first, the medians of the rounds lobatto4.
    #[test]
    fn the_stiff_table_reads_the_candidates_timed_again() {
        let bdf = BaselineRow {
            scene: "stiff_van_der_pol",
            solver: Baseline::Bdf,
            tol: 1e-6,
            err_final: 1e-8,
            steps: 400,
            seconds: 5e-4,
            failure: None,
        };
        let s = Summary {
            adaptive: vec![
                adaptive("lobatto3", 1e-2, 1e-9, 1e-3),
                adaptive("lobatto4", 1e-1, 1e-8, 4e-3),
            ],
            baselines: vec![bdf],
            stiff_times: StiffTimes {
                rounds: 7,
                adaptive: vec![(0, 2e-3), (1, 4e-4)],
                baselines: vec![(0, 2e-4)],
                failure: None,
            },
            ..Summary::default()
        };
        let md = stiff_cost(&s);
        let row = md.lines().find(|l| l.starts_with("| 1e-3")).unwrap();
        assert!(row.contains("`lobatto4` tol 1e-1"), "{row}");
        assert!(row.contains("400.0 µs") && row.contains("| 2.0 |"), "{row}");
        assert!(md.contains("timed again"), "{md}");
        // Without the second timing, the sweeps' times decide.
        let s = Summary {
            stiff_times: StiffTimes::default(),
            ..s
        };
        let md = stiff_cost(&s);
        let row = md.lines().find(|l| l.starts_with("| 1e-3")).unwrap();
        assert!(row.contains("`lobatto3` tol 1e-2"), "{row}");
    }
}

mod report_external {
    use forced_vi_scenes::report::work_precision::external::*;
    use forced_vi_scenes::report::work_precision::Summary;
    use forced_vi_scenes::scenes::all;

    const HEADER: &str = "scene,member,tol,order,steps,error,err_p,err_energy,run_seconds,\
                          jit_seconds,overhead_seconds,repeats,heyoka_version";

    /// The committed heyoka file parses, says where it was measured, covers the non-stiff,
    /// unconstrained scenes (member 0) and converges to their references: a check of the
    /// script's hand-written equations through the data it committed.
    #[test]
    fn committed_heyoka_file_fits_the_scenes() {
        let ext = External::heyoka().unwrap();
        assert!(ext.provenance.contains("commit time"), "{}", ext.provenance);
        assert!(!ext.versions().is_empty());
        let scenes = all().unwrap();
        for s in &scenes {
            let rows: Vec<&ExternalRow> = ext.rows.iter().filter(|r| r.scene == s.name()).collect();
            if s.name() == "cartesian_pendulum" {
                assert!(rows.is_empty(), "a constrained scene");
                continue;
            }
            assert!(rows.len() >= 10, "{}: {} rows", s.name(), rows.len());
            assert!(rows.iter().all(|r| r.member == 0 && r.repeats >= 1));
            let tightest = rows.iter().min_by(|a, b| a.tol.total_cmp(&b.tol)).unwrap();
            assert!(tightest.error < 1e-9, "{}: {:e}", s.name(), tightest.error);
        }
        assert!(ext
            .rows
            .iter()
            .all(|r| scenes.iter().any(|s| s.name() == r.scene)));
    }

    #[test]
    fn bad_rows_are_errors_and_the_cheapest_run_meets_the_target() {
        let row = |tol: &str, err: &str, secs: &str| {
            format!("kepler_drag,0,{tol},9,59,{err},1e-9,1e-9,{secs},2e-2,1e-6,5,7.0.0\n")
        };
        let text = format!(
            "# note\n{HEADER}\n{}{}{}",
            row("1e-4", "1e-5", "1e-5"),
            row("1e-8", "1e-9", "2e-5"),
            row("1e-10", "1e-11", "3e-5")
        );
        let ext = External::parse(&text).unwrap();
        assert_eq!(ext.provenance, "note");
        let summary = Summary {
            external: ext.of_scenes(&["kepler_drag"]),
            ..Summary::default()
        };
        let rows = summary.external.rows_of("kepler_drag");
        assert_eq!(
            rows.iter().map(|r| r.tol).collect::<Vec<_>>(),
            [1e-4, 1e-8, 1e-10]
        );
        let at = |target| {
            summary
                .external
                .cheapest("kepler_drag", target)
                .map(|r| r.tol)
        };
        assert_eq!(at(1e-6), Some(1e-8));
        assert_eq!(at(1e-3), Some(1e-4));
        assert_eq!(at(1e-12), None);
        assert!(summary.external.rows_of("damped_oscillator").is_empty());

        let negative = format!("{HEADER}\n{}", row("1e-4", "-1e-5", "1e-5"));
        assert!(External::parse(&negative).is_err());
        let nan = format!("{HEADER}\n{}", row("1e-4", "1e-5", "NaN"));
        assert!(External::parse(&nan).is_err());
        assert!(External::parse("scene,tol\nkepler_drag,1e-4\n").is_err());
    }
}
