//! The larger run of the random-description property (`tests/all/valid_descriptions.rs`
//! runs a fixed sample in the test suite): draws `--count` descriptions with the same
//! generator (`tests/support/random.rs`), checks each one, emits every accepted one
//! as a crate of one workspace, `cargo check`s the workspace once, and prints how many
//! descriptions were checked, accepted, built and failed.
//!
//! ```text
//! cargo run -p coolc --example random_descriptions -- --count 200 [--first-seed 0] [--keep DIR]
//! ```
//!
//! Seeds are `first-seed .. first-seed + count`, so a run is reproducible and a
//! failing seed can be drawn again (`describe(seed)`). The crates build in
//! `target/gen-tests` (shared with the tests' generated crates). Exit status 1 when a
//! description is rejected or a crate fails to build or warns.

#[path = "../tests/support/random.rs"]
mod random;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

use coolc::ir::RuntimeDep;
use coolc::{RenderOptions, lower, merge};

/// The command line.
struct Args {
    count: u64,
    first_seed: u64,
    keep: Option<PathBuf>,
}

fn parse_args() -> Result<Args, String> {
    let mut args = Args {
        count: 100,
        first_seed: 0,
        keep: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        let mut value = |name: &str| it.next().ok_or(format!("{name} needs a value"));
        match arg.as_str() {
            "--count" => {
                args.count = value("--count")?
                    .parse()
                    .map_err(|e| format!("--count: {e}"))?;
            }
            "--first-seed" => {
                args.first_seed = value("--first-seed")?
                    .parse()
                    .map_err(|e| format!("--first-seed: {e}"))?;
            }
            "--keep" => args.keep = Some(PathBuf::from(value("--keep")?)),
            other => {
                return Err(format!(
                    "unknown argument `{other}` (use --count N, --first-seed S, --keep DIR)"
                ));
            }
        }
    }
    Ok(args)
}

/// Analyzes one in-memory description (`main.cool` importing `types.cool`).
fn analyze(files: &[(String, String)]) -> coolc::Analysis {
    coolc::analyze(&["main.cool"], &|path: &Path| {
        files
            .iter()
            .find(|(name, _)| Path::new(name) == path)
            .map(|(_, text)| text.clone())
            .ok_or_else(|| std::io::Error::from(std::io::ErrorKind::NotFound))
    })
}

fn main() -> ExitCode {
    let args = match parse_args() {
        Ok(args) => args,
        Err(message) => {
            eprintln!("random_descriptions: {message}");
            return ExitCode::from(2);
        }
    };
    let temp;
    let dir = match &args.keep {
        Some(dir) => {
            std::fs::create_dir_all(dir).expect("create the --keep directory");
            dir.clone()
        }
        None => {
            temp = tempfile::tempdir().expect("a temporary directory");
            temp.path().to_owned()
        }
    };
    let manifest_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let runtime = RuntimeDep::Path(
        manifest_dir
            .join("../runtime")
            .canonicalize()
            .expect("the runtime crate")
            .display()
            .to_string(),
    );
    let started = std::time::Instant::now();
    let mut rejected = Vec::new();
    let mut members = Vec::new();
    for seed in args.first_seed..args.first_seed + args.count {
        let files = random::describe(seed);
        let checked = match analyze(&files).checked() {
            Ok(checked) => checked,
            Err(analysis) => {
                eprintln!(
                    "seed {seed} rejected:\n{}",
                    analysis.render(RenderOptions::plain())
                );
                rejected.push(seed);
                continue;
            }
        };
        let name = format!("random{seed}");
        let options = lower::Options {
            package: name.clone(),
            runtime: runtime.clone(),
            sources: vec!["main.cool".to_owned()],
            inputs: coolc::fingerprint::inputs(checked.sources().files()),
        };
        let krate = lower::lower(&checked, &options);
        merge::write_crate(&dir.join(&name), &krate).expect("write the crate");
        members.push(name);
    }
    let checked_in = started.elapsed();
    let quoted: Vec<String> = members.iter().map(|m| format!("\"{m}\"")).collect();
    std::fs::write(
        dir.join("Cargo.toml"),
        format!(
            "[workspace]\nresolver = \"3\"\nmembers = [{}]\n",
            quoted.join(", ")
        ),
    )
    .expect("write the workspace manifest");
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let output = Command::new(cargo)
        .args([
            "check",
            "--workspace",
            "--all-targets",
            "--keep-going",
            "--message-format=short",
        ])
        .current_dir(&dir)
        .env("CARGO_TARGET_DIR", manifest_dir.join("../target/gen-tests"))
        .env_remove("RUSTFLAGS")
        .output()
        .expect("run cargo");
    let stderr = String::from_utf8_lossy(&output.stderr);
    // Short messages start with the file's path, inside its member's directory.
    let member_of = |line: &str| -> Option<String> {
        let first = line.split(['/', '\\']).next()?;
        members.iter().find(|m| *m == first).cloned()
    };
    let mut failed = BTreeSet::new();
    let mut warned = BTreeSet::new();
    for line in stderr.lines() {
        if line.contains(": error") {
            failed.extend(member_of(line));
        } else if line.contains(": warning") {
            warned.extend(member_of(line));
        }
    }
    if !output.status.success() && failed.is_empty() {
        // An error not tied to one member (a manifest, the runtime): all failed.
        failed.extend(members.iter().cloned());
    }
    for line in stderr
        .lines()
        .filter(|l| l.contains(": error") || l.contains(": warning"))
    {
        eprintln!("{line}");
    }
    let built = members.len() - failed.len();
    println!(
        "random descriptions: seeds {}..{}: {} checked, {} accepted, {} rejected; {} built, {} failed, {} with warnings (check+emit {:.1} s, cargo check {:.1} s)",
        args.first_seed,
        args.first_seed + args.count,
        args.count,
        members.len(),
        rejected.len(),
        built,
        failed.len(),
        warned.len(),
        checked_in.as_secs_f64(),
        (started.elapsed() - checked_in).as_secs_f64(),
    );
    if rejected.is_empty() && failed.is_empty() && warned.is_empty() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}
