//! The generated crate for the examples (MotionController, RangeServer, MobileBase)
//! with filled-in stubs builds clippy-clean under `-D warnings`, is rustfmt-clean,
//! and runs on the runtime: components start, move through their user automata,
//! exchange packets over the connections `MobileBase` declares (one through a
//! converter), and publish variables on their monitoring ports.

mod common;

use common::{cargo, compile, copy_descriptions, data};

#[test]
fn generated_crate_builds_and_runs() {
    let dir = tempfile::tempdir().unwrap();
    let descriptions = dir.path().join("cool");
    let krate = dir.path().join("fleet");
    std::fs::create_dir_all(&descriptions).unwrap();
    copy_descriptions(&descriptions);
    compile(&descriptions.join("mobile_base.cool"), &krate, "fleet");

    // The untouched stubs (SimRangeServer, Gyro) must build as generated.
    for name in [
        "range_server.rs",
        "planner.rs",
        "converters.rs",
        "motion_controller.rs",
        "follower.rs",
    ] {
        std::fs::copy(data("filled").join(name), krate.join("src").join(name)).unwrap();
    }
    std::fs::create_dir_all(krate.join("tests")).unwrap();
    std::fs::copy(data("filled/run.rs"), krate.join("tests/run.rs")).unwrap();

    cargo(&krate, &["fmt", "--check"]);
    cargo(
        &krate,
        &["clippy", "--quiet", "--all-targets", "--", "-D", "warnings"],
    );
    let output = cargo(&krate, &["test", "--test", "run"]);
    assert!(
        output.contains("test mobile_base_instances_run_and_talk ... ok"),
        "{output}"
    );
}
