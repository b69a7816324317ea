//! End to end: `forced-vi-report stability --quick` writes `stability.csv` with the promised
//! columns, every outcome is `ok`, `recovered` or `failed:<kind>`, no case panicked, and no
//! `ok` or `recovered` row carries a non-finite error.

use std::fs;
use std::process::Command;

#[test]
fn extreme_stability_quick_report() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path();
    let status = Command::new(env!("CARGO_BIN_EXE_forced-vi-report"))
        .args(["stability", "--quick", "--no-progress", "--out"])
        .arg(out)
        .status()
        .unwrap();
    assert!(status.success());

    let csv = fs::read_to_string(out.join("stability.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some(
            "scene,method,h,outcome,steps_done,max_newton_iters,err_final,\
             max_energy_balance_err,mode,tol"
        )
    );
    let rows: Vec<&str> = lines.collect();
    assert!(rows.len() >= 20, "{} rows", rows.len());
    let mut scenes = std::collections::BTreeSet::new();
    let mut adaptive = 0;
    for row in &rows {
        let cols: Vec<&str> = row.split(',').collect();
        assert_eq!(cols.len(), 10, "{row}");
        match cols[8] {
            "fixed" => assert_eq!(cols[9], "", "{row}"),
            "adaptive" => {
                adaptive += 1;
                let tol: f64 = cols[9].parse().unwrap_or_else(|_| panic!("{row}"));
                assert!(tol > 0.0 && tol < 1.0, "{row}");
                // Every finished adaptive run is within 100·tol of the reference.
                if matches!(cols[3], "ok" | "recovered") {
                    let err: f64 = cols[6].parse().unwrap();
                    assert!(err <= 100.0 * tol, "{row}");
                }
            }
            m => panic!("mode `{m}`: {row}"),
        }
        scenes.insert(cols[0]);
        let h: f64 = cols[2].parse().unwrap();
        assert!(h.is_finite() && h > 0.0, "{row}");
        let outcome = cols[3];
        let _steps: usize = cols[4].parse().unwrap();
        let _iters: usize = cols[5].parse().unwrap();
        let err: f64 = cols[6].parse().unwrap();
        let balance: f64 = cols[7].parse().unwrap();
        match outcome {
            "ok" | "recovered" => {
                assert!(err.is_finite() && err >= 0.0, "{row}");
                assert!(balance.is_finite(), "{row}");
            }
            o => {
                let kind = o.strip_prefix("failed:").unwrap_or_else(|| panic!("{row}"));
                assert!(!kind.is_empty(), "{row}");
                assert_ne!(kind, "panic", "{row}");
                assert_ne!(kind, "non_finite_result", "{row}");
            }
        }
    }
    assert!(scenes.len() >= 5, "{scenes:?}");
    assert!(adaptive >= 5, "{adaptive} adaptive rows");

    let readme = fs::read_to_string(out.join("README.md")).unwrap();
    assert!(readme.contains("## Stability on stiff and extreme cases"));
    let section = fs::read_to_string(out.join("sections").join("stability.md")).unwrap();
    assert!(section.contains("### Adaptive runs"));

    // The remarks are this run's: the chain's remark (its sentence and its table) names
    // every outcome its fixed-step rows had, with the largest hω of the grid as the run
    // computed it.
    let remarks = section
        .split("### Remarks")
        .nth(1)
        .expect("a Remarks subsection");
    let chain = remarks
        .split("\n- **")
        .find(|l| l.contains("`stiff_spring_chain`"))
        .expect("a remark on the chain");
    for row in &rows {
        let cols: Vec<&str> = row.split(',').collect();
        if cols[0] == "stiff_spring_chain" && cols[8] == "fixed" {
            assert!(chain.contains(&format!("`{}`", cols[1])), "{row}: {chain}");
            assert!(chain.contains(&format!("`{}`", cols[3])), "{row}: {chain}");
        }
    }
}
