//! Random valid descriptions: a generator of descriptions that use the language
//! broadly (packets with arrays of any length, lists, optionals and nested packets,
//! enums, converters, atomics with every kind of member, compounds with converters and
//! nesting, an imported file) must pass `coolc check` without an error, and the crates
//! emitted for a fixed sample of them must build without a warning (all in one
//! workspace so the sample costs one build) and run.
//!
//! The generator (`tests/support/random.rs`, shared with the larger run of
//! `examples/random_descriptions.rs`) draws from a seed (proptest picks the seeds; a
//! failure prints the seed, and `describe(seed)` reproduces the description).

use crate::common;
#[path = "../support/random.rs"]
mod random;

use std::path::Path;
use std::process::Command;

use proptest::prelude::*;
use random::describe;

/// Analyzes the description of `seed` from memory.
fn analyze(files: &[(String, String)]) -> coolc::Analysis {
    coolc::analyze(&["main.cool"], &|path: &Path| {
        files
            .iter()
            .find(|(name, _)| Path::new(name) == path)
            .map(|(_, text)| text.clone())
            .ok_or_else(|| std::io::Error::from(std::io::ErrorKind::NotFound))
    })
}

fn assert_accepted(seed: u64, files: &[(String, String)]) {
    let analysis = analyze(files);
    assert!(
        !analysis.has_errors(),
        "seed {seed}:\n{}\n{}\n{}",
        files[0].1,
        files[1].1,
        analysis.render(coolc::RenderOptions::plain())
    );
}

proptest! {
    // A fixed seed: the same 64 descriptions every run (tests are deterministic).
    #![proptest_config(ProptestConfig {
        cases: 64,
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x0C00_1B07),
        ..ProptestConfig::default()
    })]

    #[test]
    fn random_valid_descriptions_pass_the_checker(seed in any::<u64>()) {
        assert_accepted(seed, &describe(seed));
    }
}

/// Seeds whose descriptions come within a few words of the 32 KiB a packet or a
/// component's variables take inline: one whose packets are padded up to their
/// alignment (9), and one whose last variable became a list that still takes its three
/// words (2787).
#[test]
fn descriptions_at_the_inline_bound_pass_the_checker() {
    for seed in [9, 2787] {
        assert_accepted(seed, &describe(seed));
    }
}

/// The seeds whose crates are built.
const SAMPLE: &[u64] = &[1, 2, 3, 5];

#[test]
fn a_sample_of_random_descriptions_builds_without_warnings() {
    let dir = tempfile::tempdir().unwrap();
    let mut members = Vec::new();
    // The sample covers what the generator is for.
    let texts: String = SAMPLE
        .iter()
        .flat_map(|seed| describe(*seed))
        .map(|(_, text)| text)
        .collect();
    for construct in [
        " via K",
        "; 72]",
        "; 33]",
        "instance n0: C",
        "?",
        "ufifo<",
        "poster<",
        // Every third atomic has no automaton.
        "atomic A2 ",
    ] {
        assert!(texts.contains(construct), "the sample lacks `{construct}`");
    }
    for seed in SAMPLE {
        let files = describe(*seed);
        assert_accepted(*seed, &files);
        let cool = dir.path().join(format!("cool{seed}"));
        std::fs::create_dir_all(&cool).unwrap();
        for (name, text) in &files {
            std::fs::write(cool.join(name), text).unwrap();
        }
        let name = format!("random{seed}");
        common::compile(&cool.join("main.cool"), &dir.path().join(&name), &name);
        members.push(format!("\"{name}\""));
    }
    std::fs::write(
        dir.path().join("Cargo.toml"),
        format!(
            "[workspace]\nresolver = \"3\"\nmembers = [{}]\n",
            members.join(", ")
        ),
    )
    .unwrap();
    let target = common::gen_target();
    let output = common::gen_cargo(dir.path())
        .args([
            "build",
            "--workspace",
            "--all-targets",
            "--message-format=short",
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    let warnings: Vec<&str> = stderr.lines().filter(|l| l.contains("warning")).collect();
    assert!(warnings.is_empty(), "{stderr}");
    // And each runs: its starter `main` adds every component no compound holds to a
    // system (which checks its shape), runs them for a moment with the untouched stubs
    // and stops them; a refusal or an unclean stop fails the process.
    for seed in SAMPLE {
        let binary = target.join("debug").join(format!("random{seed}"));
        let run = Command::new(&binary).arg("0.3").output().unwrap();
        let stdout = String::from_utf8_lossy(&run.stdout);
        assert!(
            run.status.success(),
            "seed {seed}: {}\n{stdout}\n{}",
            run.status,
            String::from_utf8_lossy(&run.stderr)
        );
        // The monitor of each root, printed as its `Display`: a first line
        // `name: state ...`, then indented lines; then the shutdown's report.
        let states: Vec<&str> = stdout
            .lines()
            .filter(|line| {
                !line.starts_with(' ')
                    && !line.starts_with("Report {")
                    && !line.starts_with("shutdown ")
            })
            .filter_map(|line| line.split_once(": "))
            .map(|(_, rest)| rest.split([' ', ',']).next().unwrap_or(rest))
            .collect();
        assert!(
            !states.is_empty(),
            "seed {seed}: no monitor printed\n{stdout}"
        );
        assert!(
            states.iter().all(|state| *state == "running"),
            "seed {seed}: every root runs: {states:?}\n{stdout}"
        );
    }
}
