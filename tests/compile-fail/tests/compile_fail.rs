//! The type guarantees of generated code, pinned by cases that must not compile
//! (`tests/ui/*.rs`, each with the compiler's message in `*.stderr`): a `may` choice
//! of a state outside the `may` list is unrepresentable, a missing stub is a
//! compile error that names the stub, and setting an instance's observable variable
//! through its typed handle is a compile error that says why. The correct
//! implementation in `src/lib.rs` builds, and runs in its harness here.
//!
//! Each case is a binary of a scratch crate that depends on this package, built as
//! the tests build the crates coolc generates (`generated_crates`: their target
//! directory, lock and profile), so that the runtime and its dependencies are built
//! there once for all of them. A case's message is compared line by line where it
//! says what is wrong and where ([`significant`]); `COOLC_BLESS=1` writes the
//! messages of today's compiler into the `*.stderr` files.

use std::path::{Path, PathBuf};

#[path = "../../../coolc/tests/all/common/generated_crates.rs"]
#[allow(dead_code, reason = "shared with coolc's tests, which use all of it")]
mod generated_crates;

fn package() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).to_owned()
}

/// The label a line under a source excerpt puts on the code its `^` or `-` marks
/// (`^^^^ the variable this would set is observable`), if it is such a line.
fn label(line: &str) -> Option<String> {
    let (_, marked) = line.split_once('|')?;
    let marked = marked.trim_start();
    if !marked.starts_with(['^', '-']) {
        return None;
    }
    let text = marked.trim_start_matches(['^', '-', ' ', '|']).trim();
    (!text.is_empty()).then(|| format!("label: {text}"))
}

/// The lines of a compiler message that say what is wrong and where (the errors,
/// warnings, notes and help, the labels on the code, and the locations in the case),
/// without what differs between builds: the source excerpts, cargo's closing lines,
/// the case's directory, and the line numbers of locations in other files.
fn significant(message: &str, case: &str) -> Vec<String> {
    message
        .lines()
        .map(str::trim)
        .filter_map(|line| {
            let kept = !line.starts_with("error: could not compile")
                && [
                    "error", "warning", "note", "help", "= note", "= help", "-->",
                ]
                .iter()
                .any(|start| line.starts_with(start));
            if kept {
                Some(line.to_owned())
            } else {
                label(line)
            }
        })
        .map(|line| match line.strip_prefix("--> ") {
            Some(location) => {
                let file = location.split(':').next().unwrap_or(location);
                if file.ends_with(&format!("/{case}.rs")) || file == format!("tests/ui/{case}.rs") {
                    let at = location.strip_prefix(file).unwrap_or_default();
                    format!("--> {case}.rs{at}")
                } else {
                    let name = file.rsplit('/').next().unwrap_or(file);
                    format!("--> {name}")
                }
            }
            None => line,
        })
        .collect()
}

#[test]
fn misuse_of_generated_code_does_not_compile() {
    let ui = package().join("tests/ui");
    let mut cases: Vec<String> = std::fs::read_dir(&ui)
        .unwrap()
        .filter_map(|entry| {
            let path = entry.unwrap().path();
            (path.extension()? == "rs").then(|| path.file_stem()?.to_str().map(str::to_owned))?
        })
        .collect();
    cases.sort();
    assert!(cases.len() >= 3, "{cases:?}");
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path().join("compile-fail-cases");
    std::fs::create_dir_all(dir.join("src/bin")).unwrap();
    let runtime = package().join("../../runtime").canonicalize().unwrap();
    std::fs::write(
        dir.join("Cargo.toml"),
        format!(
            "[package]\nname = \"compile-fail-cases\"\nversion = \"0.0.0\"\nedition = \"2024\"\n\
             publish = false\n\n[dependencies]\n\
             coolbot = {{ path = \"{}\" }}\ncoolbot-compile-fail = {{ path = \"{}\" }}\n",
            runtime.display(),
            package().display(),
        ),
    )
    .unwrap();
    for case in &cases {
        std::fs::copy(
            ui.join(format!("{case}.rs")),
            dir.join(format!("src/bin/{case}.rs")),
        )
        .unwrap();
    }
    let mut wrong = Vec::new();
    for case in &cases {
        let output = generated_crates::gen_cargo(&dir)
            .args(["build", "--quiet", "--bin", case])
            .env("CARGO_TERM_COLOR", "never")
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        let pinned = ui.join(format!("{case}.stderr"));
        if std::env::var_os("COOLC_BLESS").is_some_and(|v| v == "1") {
            // The compiler's message as it is now, without cargo's closing lines.
            let message: Vec<&str> = stderr
                .lines()
                .take_while(|line| {
                    !line.starts_with("For more information")
                        && !line.starts_with("error: could not compile")
                })
                .collect();
            let message = message.join("\n").trim_end().to_owned() + "\n";
            let message = message
                .replace(&format!("{}/", package().display()), "")
                .replace("src/bin/", "tests/ui/");
            std::fs::write(&pinned, message).unwrap();
        }
        let expected = std::fs::read_to_string(&pinned).unwrap();
        let (got, wanted) = (significant(&stderr, case), significant(&expected, case));
        if output.status.success() || got != wanted {
            wrong.push(format!(
                "{case}: {}; expected\n  {}\ngot\n  {}\nthe compiler said:\n{stderr}",
                if output.status.success() {
                    "compiled"
                } else {
                    "another message"
                },
                wanted.join("\n  "),
                got.join("\n  ")
            ));
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n\n"));
}

#[test]
fn the_correct_implementation_builds_and_runs() {
    use coolbot_compile_fail::generated::gate::{Harness, UserState};
    let mut gate = Harness::running(coolbot_compile_fail::Gate::default()).unwrap();
    assert_eq!(gate.user_state(), Some(UserState::Closed));
    gate.tick_push().unwrap();
    gate.settle().unwrap();
    assert_eq!(gate.user_state(), Some(UserState::Open));
    gate.advance(std::time::Duration::from_millis(99)).unwrap();
    assert_eq!(gate.user_state(), Some(UserState::Open));
    // The first periodic section, then `open`'s choice: back to `closed`.
    gate.advance(std::time::Duration::from_millis(1)).unwrap();
    assert_eq!(gate.user_state(), Some(UserState::Closed));
    assert_eq!(gate.vars().openings, 1);
}
