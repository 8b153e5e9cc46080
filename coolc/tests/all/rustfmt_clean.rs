//! Every Rust file `coolc` emits is `rustfmt`-clean: `rustfmt` (edition 2024, default
//! configuration) leaves it byte for byte unchanged. This covers the files whose
//! templates are written in rustfmt's layout and skip the formatter (`coolc/src/
//! layout.rs`), which must come out exactly as rustfmt would write them, and the
//! others, which are formatted at emission.
//!
//! `rustfmt` is the reference, not `prettyplease`: "clean" means that `cargo fmt` in
//! a generated crate changes nothing, and the two printers lay out code differently
//! (prettyplease's output is not rustfmt-clean). CI installs rustfmt with the
//! toolchain; without it this test fails and says so.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use coolc::emit::{self, FileKind};
use coolc::ir::RuntimeDep;
use coolc::lower;

fn rustfmt(code: &str) -> String {
    let mut child = Command::new("rustfmt")
        .args(["--edition", "2024", "--emit", "stdout", "--quiet"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("rustfmt is the reference of this test: install it (rustup component add rustfmt)");
    let mut stdin = child.stdin.take().unwrap();
    let input = code.to_owned();
    let writer = std::thread::spawn(move || stdin.write_all(input.as_bytes()));
    let output = child.wait_with_output().unwrap();
    writer.join().unwrap().unwrap();
    assert!(
        output.status.success(),
        "rustfmt failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout).unwrap()
}

fn lower_files(files: &[(PathBuf, String)], package: &str) -> coolc::ir::Crate {
    let roots: Vec<&Path> = files.iter().map(|(p, _)| p.as_path()).collect();
    let load = |path: &Path| {
        files
            .iter()
            .find(|(p, _)| p == path)
            .map(|(_, text)| text.clone())
            .map_or_else(|| std::fs::read_to_string(path), Ok)
    };
    let checked = coolc::analyze(&roots, &load)
        .checked()
        .unwrap_or_else(|analysis| panic!("{}", analysis.render(coolc::RenderOptions::plain())));
    let options = lower::Options {
        package: package.to_owned(),
        runtime: RuntimeDep::Version("0.1".to_owned()),
        sources: roots
            .iter()
            .map(|r| r.file_name().unwrap().to_string_lossy().into_owned())
            .collect(),
        inputs: coolc::fingerprint::inputs(checked.sources().files()),
    };
    lower::lower(&checked, &options)
}

fn on_disk(path: PathBuf) -> (PathBuf, String) {
    let text = std::fs::read_to_string(&path).unwrap();
    (path, text)
}

/// Asserts every Rust file of the crate is rustfmt-clean; returns how many atomic
/// modules and user files took the fast path (no formatter).
fn assert_clean(name: &str, krate: &coolc::ir::Crate) -> (usize, usize) {
    let (atomics, users, _) = assert_clean_listed(name, krate);
    (atomics, users)
}

/// [`assert_clean`], with the paths of every file that took the fast path.
fn assert_clean_listed(name: &str, krate: &coolc::ir::Crate) -> (usize, usize, Vec<PathBuf>) {
    let (_, laid_out) = emit::render_crate(krate);
    let files = emit::emit_crate(krate);
    let mut fast = (0, 0, Vec::new());
    for (file, laid_out) in files.iter().zip(laid_out) {
        if file.path.extension().is_none_or(|e| e != "rs") {
            continue;
        }
        let formatted = rustfmt(&file.contents);
        if formatted != file.contents {
            let line = formatted
                .split('\n')
                .zip(file.contents.split('\n'))
                .position(|(a, b)| a != b)
                .unwrap_or_else(|| formatted.lines().count().min(file.contents.lines().count()));
            let around = |text: &str| -> Vec<String> {
                text.split('\n')
                    .skip(line)
                    .take(8)
                    .map(str::to_owned)
                    .collect()
            };
            panic!(
                "{name}: {} is not rustfmt-clean (fast path: {laid_out}); first difference at line {}:\n--- emitted\n{:?}\n--- rustfmt\n{:?}",
                file.path.display(),
                line + 1,
                around(&file.contents),
                around(&formatted),
            );
        }
        let atomic = krate.atomics.iter().any(|a| {
            file.path
                == Path::new(&format!(
                    "src/generated/{}.rs",
                    a.module.trim_start_matches("r#")
                ))
        });
        if laid_out && atomic {
            fast.0 += 1;
        }
        if laid_out && file.kind == FileKind::User {
            fast.1 += 1;
        }
        if laid_out {
            fast.2.push(file.path.clone());
        }
    }
    fast
}

#[test]
fn fixtures_emit_rustfmt_clean_files() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/ok");
    let mut paths: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "cool"))
        .collect();
    paths.sort();
    assert!(!paths.is_empty());
    let mut fast = 0;
    for path in paths {
        let name = path.display().to_string();
        let krate = lower_files(&[on_disk(path)], "fixture");
        fast += assert_clean(&name, &krate).0;
    }
    assert!(fast > 0, "no fixture's atomic module took the fast path");
}

#[test]
fn examples_emit_rustfmt_clean_files_without_a_formatter() {
    for root in [
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/components/mobile_base.cool"),
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/mobile_base.cool"),
    ] {
        let name = root.display().to_string();
        let example = root.starts_with(Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples"));
        let krate = lower_files(&[on_disk(root)], "mobile-base");
        let (atomics, users, laid_out) = assert_clean_listed(&name, &krate);
        // The realistic descriptions take the fast path throughout: every atomic
        // module, every user file (atomic and compound, `src/lib.rs`), and for the
        // example every Rust file of the crate.
        assert_eq!(atomics, krate.atomics.len(), "{name}: atomic modules");
        let user_files = emit::emit_crate(&krate)
            .iter()
            .filter(|f| f.kind == FileKind::User)
            .count();
        assert_eq!(users, user_files, "{name}: user files");
        if example {
            let (files, _) = emit::render_crate(&krate);
            for file in files
                .iter()
                .filter(|f| f.path.extension().is_some_and(|e| e == "rs"))
            {
                assert!(
                    laid_out.contains(&file.path),
                    "{name}: {} goes to the formatter",
                    file.path.display()
                );
            }
        }
    }
}

#[test]
fn starter_emits_rustfmt_clean_files() {
    let text = coolc::cli::starter_description("Starter");
    let krate = lower_files(&[(PathBuf::from("starter.cool"), text)], "starter");
    assert_eq!(assert_clean("starter", &krate).0, 1);
}

/// Names at the edges of rustfmt's width rules: each description either takes the
/// fast path and is exact, or is formatted; both must be clean.
#[test]
fn long_and_short_names_stay_rustfmt_clean() {
    let mut taken = 0;
    for n in [1, 8, 17, 25, 33, 41, 49, 57, 70] {
        let name = "x".repeat(n);
        let camel = format!("C{}", "y".repeat(n));
        let text = format!(
            r#"
packet P{camel} {{ a: f64, b: [bool; 4] = [false; 4] }}
enum M{camel} {{ A, B }}

/// A component with names {n} long.
atomic {camel} {{
    configuration {{
        {name}: String = "{name}";
        r{name}: u32 = 3;
    }}
    observable o{name}: P{camel};
    observable b{name}: f32 = 1.5;
    controllable c{name}: f64 = 0.5;
    observable s{name}: String = "s";
    local m{name}: M{camel} = M{camel}::B;
    local l{name}: u64 = 0;
    input i{name}: fifo<P{camel}>(16);
    input t{name}: tick;
    input u{name}: last<P{camel}>;
    output d{name}: data<P{camel}> pull;
    output p{name}: poster<P{camel}>;
    output k{name}: tick;
    timing {{ period 10ms..40ms; max_response 20ms; priority 3; quality full, reduced; }}
    exception e{name} "lost {name}" {{ retry 3 every 100ms; }}
    exception g{name} {{ goto s{name}; }}
    exception h{name};
    automaton {{
        initial s{name};
        state s{name} {{
            entry; periodic; exit;
            on i{name} -> v{name};
            on t{name} -> s{name};
            after 500ms without i{name} -> s{name};
            may -> v{name}, s{name};
        }}
        state v{name} {{ entry; periodic 20ms; after 2s -> s{name}; }}
    }}
}}
"#
        );
        let krate = lower_files(&[(PathBuf::from(format!("names_{n}.cool")), text)], "names");
        let fast = assert_clean(&format!("names {n}"), &krate).0;
        eprintln!("names {n} long: {fast} fast atomic module(s)");
        taken += fast;
    }
    assert!(taken > 0, "no description took the fast path");
}

/// A compound's tables of pairs at the edges of rustfmt's rules: on the line of their
/// name, alone on the next line, and one pair per line.
#[test]
fn compound_tables_stay_rustfmt_clean() {
    for n in [1, 13, 14, 15, 16, 30] {
        let a = format!("a{}", "x".repeat(n - 1));
        let b = format!("b{}", "x".repeat(n - 1));
        let text = format!(
            r#"
atomic Worker {{
    automaton {{ initial working; state working {{ entry; }} }}
}}

/// Two workers, their names {n} long.
compound Cell {{
    instance {a}: Worker;
    instance {b}: Worker;
}}
"#
        );
        let krate = lower_files(&[(PathBuf::from(format!("pairs_{n}.cool")), text)], "pairs");
        assert_clean(&format!("names {n}"), &krate);
        // The file is in rustfmt's layout but for, at most, items formatted alone
        // (the builder's long `instance` calls): the tables need no formatter.
        let (rendered, laid_out) = emit::render_crate(&krate);
        let cell = rendered
            .iter()
            .position(|f| f.path == Path::new("src/generated/cell.rs"))
            .unwrap();
        assert!(
            laid_out[cell] || rendered[cell].contents.contains("coolc-item-format"),
            "names {n}: the compound module is left to the formatter"
        );
    }
}
