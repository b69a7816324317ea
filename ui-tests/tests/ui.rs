//! Compile-time checks of `#[forced_lagrangian]`: every `tests/ui/<mistake>.rs` (at the
//! workspace root) must fail to compile with the committed `.stderr`. Bless new output with
//! `TRYBUILD=overwrite`. The `tests/ui/pass-*.rs` cases, which must compile under
//! `#![deny(warnings)]`, are test targets of `models/` (see its `Cargo.toml`): with
//! failing cases only, trybuild checks instead of building, so its dependencies are not
//! compiled a second time with code generation.
//!
//! The runner has a package of its own (`ui-tests/`): trybuild checks the cases against the
//! dependencies of the package that runs it, and here that is `forced-vi` without default
//! features (no faer, no rayon), not the report's (diffsol, plotters, ...).

/// The rustc flags trybuild 1.0.122 passes when it checks the cases (`rustflags.rs` and
/// `cargo.rs` there). It checks the dependencies first with the flags minus
/// `--diagnostic-width=140`, then the cases with them, and since the flags are part of every
/// unit's fingerprint, cargo checks every dependency twice (nalgebra, num-dual, the macro
/// crate...): 52 s for this test instead of 18 s, measured on a fresh target directory.
/// `CARGO_ENCODED_RUSTFLAGS` takes precedence over the `--config` flags trybuild sets (and it
/// does not clear it), so both of its cargo runs use this one set and share the dependencies.
/// The same flags, so the same diagnostics: if a later trybuild changed them, the `.stderr`
/// comparison below would show it.
const TRYBUILD_RUSTFLAGS: [&str; 6] = [
    "--cfg",
    "trybuild",
    "--verbose",
    "-A",
    "dead_code",
    "--diagnostic-width=140",
];

#[test]
fn ui() {
    // A user's own flags (coverage, say) go to trybuild untouched.
    if std::env::var_os("RUSTFLAGS").is_none()
        && std::env::var_os("CARGO_ENCODED_RUSTFLAGS").is_none()
    {
        std::env::set_var("CARGO_ENCODED_RUSTFLAGS", TRYBUILD_RUSTFLAGS.join("\x1f"));
    }
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
