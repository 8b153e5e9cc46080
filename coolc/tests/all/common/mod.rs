//! Helpers shared by the tests that write, build and run generated crates.
#![allow(dead_code, reason = "not every test uses every helper")]

use std::ffi::OsStr;
use std::path::{Path, PathBuf};

use coolc::ir::RuntimeDep;

#[path = "generated_crates.rs"]
mod generated_crates;
use coolc::{lower, merge};
use generated_crates::run_cargo;
pub use generated_crates::{gen_cargo, gen_cargo_linted, gen_target, lint};

/// `coolc/tests/data/<name>`.
pub fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

/// The repository's runtime crate, by path.
pub fn runtime() -> RuntimeDep {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../runtime");
    RuntimeDep::Path(path.canonicalize().unwrap().display().to_string())
}

/// Copies the example descriptions into `dir`, without their `link crate` lines
/// (`serialport` needs libudev and `nalgebra` takes minutes to build; neither is
/// used by the test code).
pub fn copy_descriptions(dir: &Path) {
    for name in [
        "types.cool",
        "motion_controller.cool",
        "range_server.cool",
        "mobile_base.cool",
    ] {
        let text = std::fs::read_to_string(data(name)).unwrap();
        let text: String = text
            .lines()
            .filter(|l| !l.trim_start().starts_with("link crate"))
            .map(|l| format!("{l}\n"))
            .collect();
        std::fs::write(dir.join(name), text).unwrap();
    }
}

/// Analyzes `root`, lowers it and writes (or merges into) the crate `out`.
pub fn compile(root: &Path, out: &Path, package: &str) -> merge::Report {
    compile_with(root, out, package, &coolc::ros::Search::new())
}

/// [`compile`], with `import ros` types looked up through `ros`.
pub fn compile_with(
    root: &Path,
    out: &Path,
    package: &str,
    ros: &coolc::ros::Search,
) -> merge::Report {
    let read = |p: &Path| std::fs::read_to_string(p);
    let checked = coolc::analyze_with(&[root], &read, &|_| Vec::new(), ros)
        .checked()
        .unwrap_or_else(|analysis| panic!("{}", analysis.render(coolc::RenderOptions::plain())));
    let options = lower::Options {
        package: package.to_owned(),
        runtime: runtime(),
        sources: vec![root.file_name().unwrap().to_string_lossy().into_owned()],
        inputs: coolc::fingerprint::inputs(checked.sources().files()),
    };
    merge::write_crate(out, &lower::lower(&checked, &options)).unwrap()
}

/// Runs `cargo <args>` in `dir` with the shared generated-crate target directory;
/// panics with cargo's output when it fails; returns its stdout.
pub fn cargo(dir: &Path, args: &[&str]) -> String {
    cargo_with_env(dir, args, &[])
}

/// [`cargo`], with the variables `env` set for it (and so for the tests it runs).
pub fn cargo_with_env(dir: &Path, args: &[&str], env: &[(&str, &OsStr)]) -> String {
    run_cargo(gen_cargo(dir), dir, args, env)
}

/// [`cargo`], with the crate's own targets linted by clippy under `-D warnings` in
/// the same build ([`gen_cargo_linted`]; every command that compiles that crate goes
/// through this one).
pub fn cargo_linted(dir: &Path, args: &[&str]) -> String {
    cargo_linted_with_env(dir, args, &[])
}

/// [`cargo_linted`], with the variables `env` set for it.
pub fn cargo_linted_with_env(dir: &Path, args: &[&str], env: &[(&str, &OsStr)]) -> String {
    run_cargo(gen_cargo_linted(dir), dir, args, env)
}

/// Copies the filled-in user files `user_files` of `coolc/tests/data/<data_dir>` into
/// the crate `krate`'s `src/` and its `run.rs` into `tests/`; checks that the crate is
/// rustfmt-clean and clippy-clean under `-D warnings`; runs `tests/run.rs` and asserts
/// that each of `tests` passed.
pub fn fill_check_and_run(krate: &Path, data_dir: &str, user_files: &[&str], tests: &[&str]) {
    fill_check_and_run_with_env(krate, data_dir, user_files, tests, &[]);
}

/// [`fill_check_and_run`], with the variables `env` set for the tests.
pub fn fill_check_and_run_with_env(
    krate: &Path,
    data_dir: &str,
    user_files: &[&str],
    tests: &[&str],
    env: &[(&str, &OsStr)],
) {
    for name in user_files {
        std::fs::copy(data(data_dir).join(name), krate.join("src").join(name)).unwrap();
    }
    std::fs::create_dir_all(krate.join("tests")).unwrap();
    std::fs::copy(data(data_dir).join("run.rs"), krate.join("tests/run.rs")).unwrap();
    cargo(krate, &["fmt", "--check"]);
    // Every target built and linted (what `cargo clippy --all-targets` covers in a
    // generated crate: it has no benches), then the run tests.
    lint(krate);
    let output = cargo_linted_with_env(krate, &["test", "--test", "run"], env);
    for test in tests {
        assert!(output.contains(&format!("test {test} ... ok")), "{output}");
    }
}
