//! End to end: `forced-vi-report step-cost --quick` writes `step_cost.csv` with the
//! `diagnostics` and `path` columns and `ensemble_throughput.csv` for 1 and 2 threads.

use std::fs;
use std::process::Command;

#[test]
fn step_cost_quick_writes_both_csvs() {
    let dir = tempfile::tempdir().unwrap();
    let status = Command::new(env!("CARGO_BIN_EXE_forced-vi-report"))
        .args(["step-cost", "--quick", "--no-progress", "--out"])
        .arg(dir.path())
        .status()
        .unwrap();
    assert!(status.success());

    let sc = fs::read_to_string(dir.path().join("step_cost.csv")).unwrap();
    let mut lines = sc.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (diag, path, method, ns) = (
        col("diagnostics"),
        col("path"),
        col("method"),
        col("ns_per_step_generated"),
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    for r in &rows {
        assert!(r[diag] == "full" || r[diag] == "none", "{r:?}");
        assert!(r[path] == "dense" || r[path] == "sparse", "{r:?}");
    }
    // The paper model is timed with and without diagnostics for every scheme.
    for m in ["lobatto2", "lobatto3", "lobatto4", "lobatto5", "midpoint"] {
        for d in ["full", "none"] {
            let row = rows
                .iter()
                .find(|r| r[0] == "coupled_van_der_pol" && r[method] == m && r[diag] == d)
                .unwrap_or_else(|| panic!("no {m} {d} row"));
            let t: f64 = row[ns].parse().unwrap();
            assert!(t > 0.0 && t.is_finite(), "{row:?}");
        }
    }

    // The sparse path of fpu_chain up to n = 1024 (issue 12), for both schemes; the dense path
    // at small n; the membrane on both.
    for m in ["lobatto2", "lobatto3"] {
        for n in [32, 128, 512, 1024] {
            let row = rows
                .iter()
                .find(|r| {
                    r[0] == "fpu_chain"
                        && r[method] == m
                        && r[path] == "sparse"
                        && r[2] == n.to_string()
                })
                .unwrap_or_else(|| panic!("no fpu_chain {m} sparse n = {n} row"));
            let t: f64 = row[ns].parse().unwrap_or_else(|_| panic!("{row:?}"));
            assert!(t > 0.0 && t.is_finite(), "{row:?}");
        }
        for (scene, p) in [
            ("fpu_chain", "dense"),
            ("lattice_2d", "sparse"),
            ("lattice_2d", "dense"),
        ] {
            assert!(
                rows.iter()
                    .any(|r| r[0] == scene && r[method] == m && r[path] == p && !r[ns].is_empty()),
                "no measured {scene} {m} {p} row"
            );
        }
    }

    let et = fs::read_to_string(dir.path().join("ensemble_throughput.csv")).unwrap();
    let mut lines = et.lines();
    assert_eq!(
        lines.next(),
        Some("threads,members,member_steps_per_second")
    );
    let threads: Vec<(usize, usize, f64)> = lines
        .map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            (
                c[0].parse().unwrap(),
                c[1].parse().unwrap(),
                c[2].parse().unwrap(),
            )
        })
        .collect();
    assert_eq!(threads.iter().map(|t| t.0).collect::<Vec<_>>(), [1, 2]);
    for (_, members, rate) in threads {
        assert_eq!(members, 25);
        assert!(rate > 0.0 && rate.is_finite());
    }
}
