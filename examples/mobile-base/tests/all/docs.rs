//! The commands the docs give for the example robot (`cargo run ... -p mobile-base
//! ... -- ARGS` in README.md, examples/README.md and docs/) are ones its command line
//! takes: each one's arguments, with `--help` after them, parse. Clap reads every
//! option and value it meets before `--help`, so an unknown option or a value its
//! parser refuses (`--duration 10m`) fails here; what it checks only once the whole
//! line is read (an option that requires or excludes another) is not.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The files of the docs that give commands.
fn documents() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let mut files = vec![root.join("README.md"), root.join("examples/README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .expect("docs/")
        .map(|entry| entry.expect("an entry").path())
        .filter(|path| path.extension().is_some_and(|e| e == "md"))
        .collect();
    docs.sort();
    files.extend(docs);
    files
}

/// Each command line of `text` (a line that starts with `cargo run`, or `$ cargo
/// run`, with its `\` continuations) that runs the example: its features and the
/// arguments after `--`.
fn commands(text: &str) -> Vec<(String, Vec<String>)> {
    let mut found = Vec::new();
    let mut lines = text.lines();
    while let Some(line) = lines.next() {
        let line = line.trim_start().trim_start_matches("$ ");
        if !line.starts_with("cargo run") || !line.contains("-p mobile-base") {
            continue;
        }
        let mut command = line.to_owned();
        while command.trim_end().ends_with('\\') {
            command = command.trim_end().trim_end_matches('\\').to_owned();
            command.push(' ');
            command.push_str(lines.next().unwrap_or_default().trim());
        }
        let command = command.split(" #").next().unwrap_or_default();
        let Some((cargo, args)) = command.split_once(" -- ") else {
            continue;
        };
        let args: Vec<String> = args
            .split_whitespace()
            .filter(|arg| *arg != "&")
            .map(str::to_owned)
            .collect();
        found.push((cargo.to_owned(), args));
    }
    found
}

#[test]
fn every_command_the_docs_give_for_the_example_parses() {
    let mut checked = 0;
    for file in documents() {
        let text = std::fs::read_to_string(&file).expect("a document");
        for (cargo, args) in commands(&text) {
            // Only the ROS 2 options exist in one build and not the other.
            if cargo.contains("--features ros2") && !cfg!(feature = "ros2") {
                continue;
            }
            let output = Command::new(env!("CARGO_BIN_EXE_mobile-base"))
                .args(&args)
                .arg("--help")
                .output()
                .expect("the example runs");
            assert!(
                output.status.success(),
                "{}: `{cargo} -- {}` is refused: {}",
                file.display(),
                args.join(" "),
                String::from_utf8_lossy(&output.stderr)
            );
            checked += 1;
        }
    }
    // README.md alone gives the main job and five network runs.
    assert!(checked >= 6, "only {checked} commands found");
}

#[test]
fn a_command_is_read_with_its_continuations_and_without_its_comment() {
    let text = "run:\n$ cargo run -p mobile-base --features network -- \\\n    --node robot &\n\
                cargo run --release -p mobile-base -- --duration 10s   # wander\n\
                cargo run -p coolc -- check\n";
    assert_eq!(
        commands(text),
        vec![
            (
                "cargo run -p mobile-base --features network".to_owned(),
                vec!["--node".to_owned(), "robot".to_owned()]
            ),
            (
                "cargo run --release -p mobile-base".to_owned(),
                vec!["--duration".to_owned(), "10s".to_owned()]
            ),
        ]
    );
}
