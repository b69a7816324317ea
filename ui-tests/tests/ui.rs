//! Compile-time checks of `#[forced_lagrangian]`: every `tests/ui/<mistake>.rs` (at the
//! workspace root) must fail to compile with the committed `.stderr`. Bless new output with
//! `TRYBUILD=overwrite`. The `tests/ui/pass-*.rs` cases, which must compile under
//! `#![deny(warnings)]`, are test targets of the root package (see its `Cargo.toml`): with
//! failing cases only, trybuild checks instead of building, so its dependencies are not
//! compiled a second time with code generation.
//!
//! The runner has a package of its own (`ui-tests/`): trybuild checks the cases against the
//! dependencies of the package that runs it, and here that is `forced-vi` without default
//! features (no faer, no rayon), not the report's (diffsol, plotters, ...).

#[test]
fn ui() {
    let dir = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/ui"));
    let t = trybuild::TestCases::new();
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .expect("tests/ui exists")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "rs"))
        .collect();
    files.sort();
    for path in files {
        let pass = path
            .file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.starts_with("pass-"));
        if !pass {
            t.compile_fail(&path);
        }
    }
}
