//! End to end: `forced-vi-report --quick` writes a complete report, with the promised CSV
//! columns and the paper's orders on `coupled_van_der_pol`.

use std::fs;
use std::path::Path;
use std::process::Command;

fn report_bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_forced-vi-report"))
}

fn read(path: &Path) -> String {
    fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn quick_report_writes_csvs_plots_and_the_paper_orders() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path();
    let status = report_bin()
        .args(["--quick", "--no-progress", "--out"])
        .arg(out)
        .status()
        .unwrap();
    assert!(status.success());

    let wp = read(&out.join("work_precision.csv"));
    let mut lines = wp.lines();
    assert_eq!(
        lines.next(),
        Some("scene,method,h_or_tol,steps,newton_iters,seconds,err_q,err_p,err_energy,mode")
    );
    let rows: Vec<&str> = lines.collect();
    assert!(rows.len() > 100, "{} rows", rows.len());
    for row in &rows {
        let cols: Vec<&str> = row.split(',').collect();
        assert_eq!(cols.len(), 10, "{row}");
        for x in &cols[2..9] {
            let v: f64 = x.parse().unwrap_or_else(|_| panic!("{row}"));
            assert!(v.is_finite() && v >= 0.0, "{row}");
        }
        assert!(cols[9] == "fixed" || cols[9] == "adaptive", "{row}");
        if cols[9] == "adaptive" {
            assert!(
                cols[1].starts_with("lobatto") || cols[1] == "midpoint",
                "{row}"
            );
        }
    }
    // `--quick` runs every variational scheme adaptively too, on every scene.
    for method in ["lobatto2", "lobatto3", "lobatto5", "midpoint"] {
        let adaptive = rows
            .iter()
            .filter(|r| r.split(',').nth(1) == Some(method) && r.ends_with(",adaptive"))
            .count();
        assert!(adaptive >= 5, "{adaptive} adaptive rows of {method}");
    }
    for scene in [
        "coupled_van_der_pol",
        "coupled_van_der_pol_ensemble",
        "damped_oscillator",
        "double_pendulum_friction",
        "kepler_drag",
    ] {
        for method in [
            "lobatto2", "lobatto5", "midpoint", "dop853", "tsit45", "bdf",
        ] {
            let prefix = format!("{scene},{method},");
            assert!(
                rows.iter().any(|r| r.starts_with(&prefix)),
                "no rows for {scene} {method}"
            );
        }
    }

    let orders = read(&out.join("orders.csv"));
    let mut lines = orders.lines();
    assert_eq!(
        lines.next(),
        Some("scene,method,stages,expected_order,observed_order,note")
    );
    // Every published order is within 0.3 of the scheme's, or its row says why it is blank.
    for line in orders.lines().skip(1) {
        let cols: Vec<&str> = line.splitn(6, ',').collect();
        let expected: f64 = cols[3].parse().unwrap();
        match cols[4].parse::<f64>() {
            Ok(observed) => assert!((observed - expected).abs() <= 0.3, "{line}"),
            Err(_) => assert!(
                cols[5].starts_with("\"blank")
                    || cols[5].starts_with("blank")
                    || cols[5].starts_with("no "),
                "{line}"
            ),
        }
    }
    let mut checked = 0;
    for line in lines.filter(|l| l.starts_with("coupled_van_der_pol,")) {
        let cols: Vec<&str> = line.split(',').collect();
        let stages: f64 = cols[2].parse().unwrap();
        let expected: f64 = cols[3].parse().unwrap();
        let observed: f64 = cols[4]
            .parse()
            .unwrap_or_else(|_| panic!("no order: {line}"));
        assert_eq!(expected, 2.0 * stages - 2.0, "{line}");
        assert!((observed - expected).abs() <= 0.3, "{line}");
        checked += 1;
    }
    assert_eq!(checked, 5, "lobatto2..5 and midpoint");

    let readme = read(&out.join("README.md"));
    assert!(readme.starts_with("# forced-vi report"));
    assert!(readme.contains("## Work-precision report"));
    let section = read(&out.join("sections/work_precision.md"));
    assert!(section.contains("tolerance proportionality"));
    assert!(section.contains("`lobatto3 (adaptive)`"));
    // heyoka, the external baseline: its own columns and series, labelled external, and no
    // series on the ensemble, where it ran member 0 alone.
    let external = "heyoka (external, measured at commit time, JIT excluded)";
    assert!(section.contains(&format!("| {external} |")));
    assert!(section.contains("**Bold**: the cheapest of the methods timed by this run."));
    // The best variational run against the best baseline, timed again in alternation: a row
    // per scene and target where both reached it, each with a ratio.
    let paired = section
        .split("### The best variational run against the best baseline, timed in alternation")
        .nth(1)
        .expect("the paired timing section");
    let rows: Vec<&str> = paired
        .lines()
        .take_while(|l| !l.starts_with("###"))
        .filter(|l| l.starts_with("| `"))
        .collect();
    assert!(rows.len() >= 8, "{rows:?}");
    for row in &rows {
        let ratio: f64 = row
            .trim_end_matches(" |")
            .rsplit("| ")
            .next()
            .unwrap()
            .parse()
            .unwrap();
        assert!(ratio.is_finite() && ratio > 0.0, "{row}");
    }
    assert!(read(&out.join("work_precision_kepler_drag.svg")).contains(external));
    let ensemble = read(&out.join("work_precision_coupled_van_der_pol_ensemble.svg"));
    assert!(!ensemble.contains("heyoka"));
    for svg in [
        "error_vs_h_coupled_van_der_pol.svg",
        "work_precision_kepler_drag.svg",
        "energy_balance.svg",
    ] {
        let text = read(&out.join(svg));
        assert!(text.starts_with("<svg"), "{svg}");
        assert!(readme.contains(svg), "README embeds {svg}");
    }
}

#[test]
fn unknown_scene_or_method_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    for args in [["--scene", "nope"], ["--method", "rk4"]] {
        let output = report_bin()
            .args(["--quick", "--no-progress", "--out"])
            .arg(dir.path())
            .args(args)
            .output()
            .unwrap();
        assert!(!output.status.success());
        let err = String::from_utf8_lossy(&output.stderr);
        assert!(err.contains(args[1]), "{err}");
    }
    assert!(!dir.path().join("work_precision.csv").exists());
}
