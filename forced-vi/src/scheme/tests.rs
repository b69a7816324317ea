//! Unit tests of the schemes: Lobatto values, quadrature exactness, the basis, the ids.

use super::*;

fn close(a: &[f64], b: &[f64], tol: f64) {
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(b) {
        assert!((x - y).abs() <= tol, "{a:?} vs {b:?}");
    }
}

#[test]
fn lobatto_known_values() {
    let (x, w) = lobatto_nodes_weights(2).unwrap();
    close(&x, &[0.0, 1.0], 0.0);
    close(&w, &[0.5, 0.5], 1e-16);
    let (x, w) = lobatto_nodes_weights(3).unwrap();
    close(&x, &[0.0, 0.5, 1.0], 0.0);
    close(&w, &[1.0 / 6.0, 2.0 / 3.0, 1.0 / 6.0], 2e-16);
    let r5 = 1.0 / 5f64.sqrt();
    let (x, w) = lobatto_nodes_weights(4).unwrap();
    close(&x, &[0.0, 0.5 * (1.0 - r5), 0.5 * (1.0 + r5), 1.0], 2e-16);
    close(&w, &[1.0 / 12.0, 5.0 / 12.0, 5.0 / 12.0, 1.0 / 12.0], 2e-16);
    let r37 = (3.0f64 / 7.0).sqrt();
    let (x, w) = lobatto_nodes_weights(5).unwrap();
    close(
        &x,
        &[0.0, 0.5 * (1.0 - r37), 0.5, 0.5 * (1.0 + r37), 1.0],
        2e-16,
    );
    close(
        &w,
        &[
            1.0 / 20.0,
            49.0 / 180.0,
            16.0 / 45.0,
            49.0 / 180.0,
            1.0 / 20.0,
        ],
        2e-16,
    );
}

#[test]
fn lobatto_quadrature_is_exact_to_degree_2s_minus_3() {
    for s in 2..=9 {
        let (x, w) = lobatto_nodes_weights(s).unwrap();
        for deg in 0..=(2 * s - 3) {
            let q: f64 = x.iter().zip(&w).map(|(x, w)| w * x.powi(deg as i32)).sum();
            let exact = 1.0 / (deg as f64 + 1.0);
            assert!((q - exact).abs() < 4e-15, "s={s} deg={deg}: {q} vs {exact}");
        }
    }
}

#[test]
fn basis_derivative_rows_sum_to_zero() {
    for s in 2..=6 {
        let sch = Scheme::lobatto(s).unwrap();
        for i in 0..sch.quadrature_nodes() {
            let sp: f64 = (0..s).map(|j| sch.psi_at(i, j)).sum();
            let sf: f64 = (0..s).map(|j| sch.phi_at(i, j)).sum();
            assert!(sp.abs() < 1e-12 && (sf - 1.0).abs() < 1e-14);
        }
    }
}

#[test]
fn ids_round_trip() {
    for t in [
        "midpoint",
        "trapezoid",
        "alpha(0.3)",
        "lobatto2",
        "lobatto5",
        "lobatto7",
    ] {
        let id: SchemeId = t.parse().unwrap();
        assert_eq!(id.to_string(), t);
        Scheme::new(id).unwrap();
    }
    assert!("lobatto1".parse::<SchemeId>().is_err());
    for bad in [
        "lobatto+3",
        "lobatto007",
        "lobatto 3",
        "lobatto",
        "lobatto-2",
        "lobatto3.0",
    ] {
        assert_eq!(
            bad.parse::<SchemeId>(),
            Err(SchemeError::Unknown(bad.to_string())),
            "{bad}"
        );
    }
    for big in [
        "lobatto33",
        "lobatto18446744073709551615",
        "lobatto99999999999999999999999",
    ] {
        assert!(matches!(
            big.parse::<SchemeId>(),
            Err(SchemeError::TooManyStages {
                max: MAX_STAGES,
                ..
            })
        ));
    }
    assert!(Scheme::lobatto(usize::MAX).is_err());
    assert!(Scheme::lobatto(1 << 40).is_err());
    assert!(Scheme::lobatto(MAX_STAGES).is_ok());
    assert!("alpha(1.5)".parse::<SchemeId>().is_err());
    assert!("rk4".parse::<SchemeId>().is_err());
}

#[test]
fn the_order_follows_the_tolerance_and_the_backend() {
    let stages = |tol, sparse| match Scheme::for_tolerance(tol, sparse).id() {
        SchemeId::Lobatto(s) => s,
        other => panic!("{other:?}"),
    };
    assert_eq!(stages(1e-3, false), 6);
    assert_eq!(stages(1e-6, false), 6);
    assert_eq!(stages(2e-7, false), 6);
    assert_eq!(stages(1e-7, false), 8);
    assert_eq!(stages(1e-9, false), 8);
    assert_eq!(stages(1e-12, false), 8);
    assert_eq!(stages(f64::NAN, false), 6);
    assert_eq!(stages(1e-4, true), 4);
    assert_eq!(stages(1e-2, true), 4);
    assert_eq!(stages(1e-8, true), 4);
}

#[test]
fn basis_at_agrees_with_the_lagrange_products() {
    for s in 2..=10 {
        let sch = Scheme::lobatto(s).unwrap();
        let d = sch.d().to_vec();
        let mut out = vec![f64::NAN; s];
        for &tau in &[1.0, 1.01, 1.3, 1.75, 2.0, 2.9, 0.25] {
            sch.basis_at(tau, &mut out);
            let want: Vec<f64> = (0..s).map(|m| lagrange(&d, m, tau)).collect();
            let size = want.iter().map(|x| x.abs()).fold(1.0, f64::max);
            close(&out, &want, 64.0 * f64::EPSILON * size);
            // A partition of unity, at the nodes too.
            let sum: f64 = out.iter().sum();
            assert!(
                (sum - 1.0).abs() <= 64.0 * f64::EPSILON * size,
                "s = {s}, τ = {tau}"
            );
        }
        for (j, &dj) in d.iter().enumerate() {
            sch.basis_at(dj, &mut out);
            for (m, &l) in out.iter().enumerate() {
                assert_eq!(l == 0.0, m != j, "s = {s}, node {j}: ℓ_{m} = {l}");
                if m == j {
                    assert!((l - 1.0).abs() <= 8.0 * f64::EPSILON);
                }
            }
        }
    }
}

#[test]
fn lobatto_tables_are_made_once_up_to_the_cached_stages() {
    for s in 2..=MAX_STAGES {
        let (a, b) = (Scheme::lobatto(s).unwrap(), Scheme::lobatto(s).unwrap());
        // Shared below the bound, made per scheme above it; the same values either way.
        assert_eq!(Arc::ptr_eq(&a.t, &b.t), s <= CACHED_STAGES, "s = {s}");
        assert_eq!((a.d(), a.b()), (b.d(), b.b()));
        let (x, w) = lobatto_nodes_weights(s).unwrap();
        assert_eq!((a.d(), a.b()), (&x[..], &w[..]), "s = {s}");
        // The error reference: lobatto(s + 1), from the cache where it is there too.
        let r = a.error_reference();
        assert_eq!(r.id(), SchemeId::Lobatto(s + 1));
        assert_eq!(r.d(), &lobatto_nodes_weights(s + 1).unwrap().0[..]);
        if s < CACHED_STAGES {
            assert!(Arc::ptr_eq(&r.t, &Scheme::lobatto(s + 1).unwrap().t));
        }
    }
}

/// The public node function refuses counts outside the supported range instead of doing
/// `s²` work (or allocating) for any count it is given.
#[test]
fn lobatto_nodes_weights_refuses_counts_out_of_range() {
    assert!(matches!(
        lobatto_nodes_weights(0),
        Err(SchemeError::TooFewStages(0))
    ));
    assert!(matches!(
        lobatto_nodes_weights(1),
        Err(SchemeError::TooFewStages(1))
    ));
    assert!(lobatto_nodes_weights(MAX_STAGES + 1).is_ok());
    for s in [MAX_STAGES + 2, 1 << 20, usize::MAX] {
        assert!(
            matches!(
                lobatto_nodes_weights(s),
                Err(SchemeError::TooManyStages { .. })
            ),
            "{s}"
        );
    }
}

/// The public basis accessors answer `None` outside the tables instead of reading a
/// neighbouring entry (`phi(0, 3)` of a 3-point scheme was `Φ_10`).
#[test]
fn basis_accessors_are_checked() {
    let sch = Scheme::lobatto(3).unwrap();
    let (r, s) = (sch.quadrature_nodes(), sch.stages());
    assert_eq!(sch.phi(0, 0), Some(sch.phi_at(0, 0)));
    assert_eq!(sch.psi(r - 1, s - 1), Some(sch.psi_at(r - 1, s - 1)));
    for (i, j) in [(0, s), (r, 0), (usize::MAX, 0), (0, usize::MAX)] {
        assert_eq!(sch.phi(i, j), None, "({i}, {j})");
        assert_eq!(sch.psi(i, j), None, "({i}, {j})");
    }
}
