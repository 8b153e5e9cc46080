//! How the tests build the crates they generate, shared by coolc's tests and the
//! docs' test (`tests/tests/docs.rs`, which includes this file): in one target
//! directory, with the workspace's lock and profile, so that the runtime and its
//! dependencies are built there once.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The repository's root (both test packages are one level below it).
fn repository() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
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
        .env_remove("RUSTFLAGS");
    command
}
