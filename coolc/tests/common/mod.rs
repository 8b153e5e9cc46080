//! Helpers shared by the tests that write, build and run generated crates.
#![allow(dead_code, reason = "each test binary uses a different subset")]

use std::path::{Path, PathBuf};
use std::process::Command;

use coolc::ir::RuntimeDep;
use coolc::{lower, merge};

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
    let analysis = coolc::analyze(&[root], &|p: &Path| std::fs::read_to_string(p));
    assert!(
        !analysis.has_errors(),
        "{}",
        analysis.render(coolc::RenderOptions::plain())
    );
    let options = lower::Options {
        package: package.to_owned(),
        runtime: runtime(),
        sources: vec![root.file_name().unwrap().to_string_lossy().into_owned()],
        inputs: coolc::fingerprint::inputs(analysis.sources.files()),
    };
    merge::write_crate(out, &lower::lower(&analysis.files, &options)).unwrap()
}

/// Runs `cargo <args>` in `dir` with the shared generated-crate target directory;
/// panics with cargo's output when it fails; returns its stdout.
pub fn cargo(dir: &Path, args: &[&str]) -> String {
    let target = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/gen-tests");
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let output = Command::new(cargo)
        .args(args)
        .current_dir(dir)
        .env("CARGO_TARGET_DIR", target)
        .env_remove("RUSTFLAGS")
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
