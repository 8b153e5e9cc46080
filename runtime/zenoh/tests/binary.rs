//! The `coolctl` binary this package installs, as built: it names itself and its
//! version, and its help lists every command. (Its behaviour against running nodes is
//! tested in `tests/zenoh/tests/coolctl.rs` and `security.rs`, on components coolc
//! generates, with that package's build of the same source. This test also makes
//! `cargo test --workspace` build this binary, which the example's `top` test runs.)

use std::process::Command;

fn run(args: &[&str]) -> (Option<i32>, String) {
    let output = Command::new(env!("CARGO_BIN_EXE_coolctl"))
        .args(args)
        .output()
        .expect("coolctl runs");
    (
        output.status.code(),
        String::from_utf8_lossy(&output.stdout).into_owned(),
    )
}

#[test]
fn the_binary_names_its_version_and_every_command() {
    let (code, version) = run(&["--version"]);
    assert_eq!(code, Some(0));
    assert_eq!(
        version.trim(),
        format!("coolctl {}", env!("CARGO_PKG_VERSION"))
    );
    let (code, help) = run(&["--help"]);
    assert_eq!(code, Some(0));
    for command in [
        "nodes",
        "list",
        "watch",
        "set",
        "get",
        "configure",
        "degrade",
        "top",
        "echo",
    ] {
        assert!(
            help.lines()
                .any(|line| line.trim_start().starts_with(command)),
            "`{command}` missing from:\n{help}"
        );
    }
}
