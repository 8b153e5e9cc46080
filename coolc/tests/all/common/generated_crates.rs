//! How the tests build the crates they generate, shared by coolc's tests, the docs'
//! test (`tests/tests/docs.rs`) and the compile-fail cases
//! (`tests/compile-fail/tests/compile_fail.rs`), which include this file: in one target
//! directory, with the workspace's lock and profile, so that the runtime and its
//! dependencies are built there once.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The repository's root: the nearest directory above the test's package that holds
/// the workspace's `Cargo.lock`.
fn repository() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .skip(1)
        .find(|dir| dir.join("Cargo.lock").is_file())
        .expect("the workspace's Cargo.lock above the package")
        .to_owned()
}

/// How every generated crate of the tests is built, in the target directory they
/// share (`target/gen-tests`): with the workspace's `Cargo.lock` (`locked_as_workspace`)
/// and without debug information for dependencies (a `cargo` argument, before the
/// command), as the workspace builds. The same everywhere, or the shared directory
/// holds two builds of every dependency.
const GEN_PROFILE: [&str; 2] = ["--config", "profile.dev.package.\"*\".debug=false"];

/// The shared target directory of the generated crates.
pub fn gen_target() -> PathBuf {
    repository().join("target/gen-tests")
}

/// Gives the crate or workspace at `dir` the workspace's `Cargo.lock` (unless it has
/// one): its dependencies resolve to the versions the workspace builds and tests,
/// offline, rather than to whatever the registry offers today.
fn locked_as_workspace(dir: &Path) {
    let lock = dir.join("Cargo.lock");
    if !lock.exists() {
        let workspace = repository().join("Cargo.lock");
        std::fs::copy(workspace, lock).unwrap();
    }
}

/// A `cargo` command for the generated crate or workspace at `dir`, built as every
/// generated crate of the tests is: in [`gen_target`], with the workspace's lock
/// ([`locked_as_workspace`]) and [`GEN_PROFILE`], and without the flags the test
/// itself was built with (`RUSTFLAGS`: they would make another build of every
/// dependency there); the command's arguments follow.
pub fn gen_cargo(dir: &Path) -> Command {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    locked_as_workspace(dir);
    let mut command = Command::new(cargo);
    command
        .args(GEN_PROFILE)
        .current_dir(dir)
        .env("CARGO_TARGET_DIR", gen_target())
        .env_remove("RUSTFLAGS")
        .env_remove("RUSTC_WORKSPACE_WRAPPER")
        .env_remove("CLIPPY_ARGS");
    command
}

/// [`gen_cargo`], with the crate's own targets compiled by clippy's driver and every
/// warning an error: the lints of `cargo clippy --all-targets -- -D warnings` in the
/// build that `cargo build` or `cargo test` makes anyway. `cargo clippy` only checks,
/// and a check of each dependency is another build of it beside the one the tests
/// run; through the driver (what `cargo clippy` itself sets, `RUSTC_WORKSPACE_WRAPPER`
/// and its `-D warnings` in `CLIPPY_ARGS`) the dependencies, compiled by plain `rustc`,
/// are built once. Every command that compiles one crate uses this or [`gen_cargo`],
/// not both: the driver is part of the crate's fingerprint, and a switch recompiles
/// the crate.
pub fn gen_cargo_linted(dir: &Path) -> Command {
    let mut command = gen_cargo(dir);
    command.env("RUSTC_WORKSPACE_WRAPPER", clippy_driver()).env(
        "CLIPPY_ARGS",
        "-D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__",
    );
    command
}

/// The arguments of a linted build ([`gen_cargo_linted`]) that covers what
/// `cargo clippy --all-targets` would in a generated crate: its library, binaries and
/// integration tests. A generated crate holds no unit tests, so its unit-test
/// harnesses would compile and link the same code again.
pub fn lint_args(dir: &Path) -> &'static [&'static str] {
    if dir.join("tests").is_dir() {
        &["test", "--quiet", "--no-run", "--test", "*"]
    } else {
        &["build", "--quiet"]
    }
}

/// Runs `command` ([`gen_cargo`] or [`gen_cargo_linted`] for the crate at `dir`) with
/// `args` and the variables `env` (set for cargo and so for the tests it runs);
/// panics with cargo's output when it fails; returns its stdout.
pub fn run_cargo(
    mut command: Command,
    dir: &Path,
    args: &[&str],
    env: &[(&str, &OsStr)],
) -> String {
    let output = command
        .args(args)
        .envs(env.iter().copied())
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "cargo {args:?} failed in {}:\n{}\n{}",
        dir.display(),
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// Builds the crate at `dir` with its library, binaries and integration tests linted
/// by clippy under `-D warnings` ([`gen_cargo_linted`], [`lint_args`]); later commands
/// that compile it go through [`gen_cargo_linted`] too.
pub fn lint(dir: &Path) {
    run_cargo(gen_cargo_linted(dir), dir, lint_args(dir), &[]);
}

/// Clippy's driver of the toolchain whose `cargo` runs the tests (beside it).
fn clippy_driver() -> PathBuf {
    let cargo = std::env::var_os("CARGO").map_or_else(|| PathBuf::from("cargo"), PathBuf::from);
    let driver = cargo.with_file_name("clippy-driver");
    if cargo
        .parent()
        .is_some_and(|dir| !dir.as_os_str().is_empty())
    {
        assert!(
            driver.exists(),
            "no {}: the tests lint generated crates with clippy (`rustup component add clippy`)",
            driver.display()
        );
    }
    driver
}
