//! The documentation agrees with the compiler: every diagnostic code is documented,
//! every documented code exists, and every `cool` example in `docs/language.md`
//! parses as written (examples that are members of a component are parsed inside
//! one). The tutorial's build-script crate builds as written, and the example of
//! everything a section can use (`docs/generated-code.md`) compiles warning-free.

use std::collections::BTreeSet;
use std::path::Path;

use coolc::diagnostics::Code;

fn language_md() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/language.md");
    std::fs::read_to_string(path).expect("docs/language.md is readable")
}

/// The fenced blocks marked `cool`, with the line where each starts.
fn cool_blocks(text: &str) -> Vec<(usize, String)> {
    let mut blocks = Vec::new();
    let mut current: Option<(usize, String)> = None;
    for (index, line) in text.lines().enumerate() {
        match (&mut current, line.trim_start()) {
            (None, fence) if fence.starts_with("```cool") => {
                current = Some((index + 1, String::new()))
            }
            (Some(_), fence) if fence.starts_with("```") => blocks.extend(current.take()),
            (Some((_, body)), _) => {
                body.push_str(line);
                body.push('\n');
            }
            (None, _) => {}
        }
    }
    blocks
}

/// The codes named in the text, as `coolc::stage::rule`.
fn documented_codes(text: &str) -> BTreeSet<String> {
    text.split('`')
        .filter(|word| word.starts_with("coolc::") && word.matches("::").count() == 2)
        .map(str::to_owned)
        .collect()
}

#[test]
fn every_diagnostic_code_is_documented_and_every_documented_code_exists() {
    let text = language_md();
    let documented = documented_codes(&text);
    let real: BTreeSet<String> = Code::ALL.iter().map(|c| c.as_str().to_owned()).collect();
    let undocumented: Vec<_> = real.difference(&documented).collect();
    let unknown: Vec<_> = documented.difference(&real).collect();
    assert!(
        undocumented.is_empty(),
        "codes missing from docs/language.md: {undocumented:?}"
    );
    assert!(
        unknown.is_empty(),
        "docs/language.md names codes coolc does not have: {unknown:?}"
    );
}

#[test]
fn every_cool_example_in_the_language_reference_parses() {
    const ITEM_KEYWORDS: &[&str] = &[
        "import",
        "packet",
        "enum",
        "extern",
        "converter",
        "atomic",
        "compound",
        "///",
        "//",
    ];
    let text = language_md();
    let blocks = cool_blocks(&text);
    assert!(
        blocks.len() >= 10,
        "expected the reference to show its constructs, found {} blocks",
        blocks.len()
    );
    let mut checked = 0;
    for (line, body) in &blocks {
        // An outline such as `atomic MotionController { ... }` is prose, not code.
        if body.contains("{ ... }") {
            continue;
        }
        let first_word = body.split_whitespace().next().unwrap_or_default();
        let is_items = ITEM_KEYWORDS.iter().any(|kw| first_word.starts_with(kw))
            && !body.trim_start().starts_with("// ")
            || body.trim_start().starts_with("///");
        let source = if is_items {
            body.clone()
        } else if first_word == "state" || first_word == "initial" {
            format!("atomic DocExample {{ automaton {{ {body} }} }}")
        } else {
            format!("atomic DocExample {{ {body} }}")
        };
        let analysis = coolc::analyze_text("example.cool", &source);
        let syntax_errors: Vec<_> = analysis
            .diagnostics
            .iter()
            .filter(|d| d.code.as_str().starts_with("coolc::syntax::"))
            .collect();
        assert!(
            syntax_errors.is_empty(),
            "the example at docs/language.md:{line} does not parse:\n{}",
            analysis.render(coolc::RenderOptions::plain())
        );
        checked += 1;
    }
    assert!(checked >= 10, "only {checked} examples were checked");
}

fn doc(name: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../docs")
        .join(name);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The text of `text` from the heading starting with `heading` to the next heading of
/// the same level.
fn section<'a>(text: &'a str, heading: &str) -> &'a str {
    let start = text
        .find(&format!("\n{heading}"))
        .unwrap_or_else(|| panic!("no section {heading:?}"))
        + 1;
    let level = heading.split(' ').next().unwrap_or("##");
    let end = text[start + heading.len()..]
        .find(&format!("\n{level} "))
        .map_or(text.len(), |i| start + heading.len() + i + 1);
    &text[start..end]
}

/// The fenced blocks of `text` marked `lang`, in order.
fn blocks(text: &str, lang: &str) -> Vec<String> {
    let mut found = Vec::new();
    let mut current: Option<String> = None;
    for line in text.lines() {
        match &mut current {
            None if line.trim_start() == format!("```{lang}") => current = Some(String::new()),
            Some(_) if line.trim_start().starts_with("```") => found.extend(current.take()),
            Some(body) => {
                body.push_str(line);
                body.push('\n');
            }
            None => {}
        }
    }
    found
}

/// The repository root.
fn repository() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .canonicalize()
        .unwrap()
}

/// Runs `cargo <args>` in `dir` with the generated-crate target directory the coolc
/// tests share (the runtime and coolc are built there once); panics with cargo's
/// output when it fails.
fn cargo(dir: &Path, args: &[&str]) {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let output = std::process::Command::new(cargo)
        .args(args)
        .current_dir(dir)
        .env("CARGO_TARGET_DIR", repository().join("target/gen-tests"))
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
}

/// Lowers one description for a crate named `package` on the repository's runtime.
fn lower(name: &str, text: &str, package: &str) -> coolc::ir::Crate {
    let checked = coolc::analyze_text(name, text)
        .checked()
        .unwrap_or_else(|analysis| panic!("{}", analysis.render(coolc::RenderOptions::plain())));
    let options = coolc::lower::Options {
        package: package.to_owned(),
        runtime: coolc::ir::RuntimeDep::Path(repository().join("runtime").display().to_string()),
        sources: vec![name.to_owned()],
        inputs: coolc::fingerprint::inputs(checked.sources().files()),
    };
    coolc::lower::lower(&checked, &options)
}

#[test]
fn the_documented_header_is_the_starters() {
    let text = doc("generated-code.md");
    let starter = lower(
        "blinker.cool",
        &coolc::cli::starter_description("Blinker"),
        "blinker",
    );
    let header = starter.header();
    assert!(
        text.lines().any(|line| line == header),
        "docs/generated-code.md should show the header {header}"
    );
}

#[test]
fn the_tutorials_description_is_the_starter() {
    let tutorial = doc("tutorial.md");
    let described = &blocks(section(&tutorial, "## 2. "), "cool")[0];
    assert_eq!(*described, coolc::cli::starter_description("Blinker"));
}

#[test]
fn the_tutorials_build_script_crate_builds() {
    // Section 8 as written: its Cargo.toml (the clone's paths made real), build.rs and
    // src/lib.rs, with the starter blinker's description and code.
    let tutorial = doc("tutorial.md");
    let text = section(&tutorial, "## 8. ");
    let manifest = &blocks(text, "toml")[0];
    let rust = blocks(text, "rust");
    let file = |name: &str| {
        rust.iter()
            .find(|b| b.starts_with(&format!("// {name}\n")))
            .unwrap_or_else(|| panic!("no `// {name}` block in section 8"))
            .clone()
    };
    assert!(
        file("src/lib.rs").contains("pub mod generated {"),
        "the build-script form includes the generated code inside `mod generated`"
    );
    let dir = tempfile::tempdir().unwrap();
    let krate = dir.path().join("blinker-build");
    std::fs::create_dir_all(krate.join("src")).unwrap();
    std::fs::create_dir_all(krate.join("components")).unwrap();
    let root = format!("{}/", repository().display());
    assert!(manifest.contains("\"../coolbot/"), "{manifest}");
    std::fs::write(
        krate.join("Cargo.toml"),
        manifest.replace("\"../coolbot/", &format!("\"{root}")),
    )
    .unwrap();
    std::fs::write(krate.join("build.rs"), file("build.rs")).unwrap();
    std::fs::write(krate.join("src/lib.rs"), file("src/lib.rs")).unwrap();
    let description = coolc::cli::starter_description("Blinker");
    std::fs::write(krate.join("components/blinker.cool"), &description).unwrap();
    let lowered = lower("blinker.cool", &description, "blinker");
    std::fs::write(
        krate.join("src/blinker.rs"),
        coolc::emit::starter_component(&lowered.atomics[0]),
    )
    .unwrap();
    cargo(&krate, &["build", "--quiet"]);
}

#[test]
fn the_section_api_example_compiles_warning_free() {
    // docs/generated-code.md, "What a section can use": the description and the user
    // file, in the crate `coolc compile` writes.
    let text = doc("generated-code.md");
    let text = section(&text, "## What a section can use");
    let description = &blocks(text, "cool")[0];
    let code = &blocks(text, "rust")[0];
    let krate = lower("watcher.cool", description, "watcher");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("watcher");
    coolc::merge::write_crate(&out, &krate).unwrap();
    // Every stub of the generated file is filled in by the documented one.
    let stubs = std::fs::read_to_string(out.join("src/watcher.rs")).unwrap();
    for method in &krate.atomics[0].methods {
        let name = format!("fn {}(", method.name);
        assert!(stubs.contains(&name) && code.contains(&name), "{name}");
    }
    std::fs::write(out.join("src/watcher.rs"), code).unwrap();
    cargo(
        &out,
        &["clippy", "--quiet", "--all-targets", "--", "-D", "warnings"],
    );
}

#[test]
fn the_harness_example_runs() {
    // docs/generated-code.md, "Testing a component alone": the description, its code
    // and its test, in the crate `coolc compile` writes; the test passes.
    let text = doc("generated-code.md");
    let text = section(&text, "## Testing a component alone");
    let description = &blocks(text, "cool")[0];
    let code = blocks(text, "rust");
    let (user, test) = (&code[0], &code[1]);
    assert!(test.matches("#[test]").count() >= 2, "{test}");
    let krate = lower("tally.cool", description, "tally");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("tally");
    coolc::merge::write_crate(&out, &krate).unwrap();
    std::fs::write(out.join("src/tally.rs"), user).unwrap();
    std::fs::create_dir_all(out.join("tests")).unwrap();
    std::fs::write(out.join("tests/tally.rs"), test).unwrap();
    cargo(
        &out,
        &["clippy", "--quiet", "--all-targets", "--", "-D", "warnings"],
    );
    cargo(&out, &["test", "--quiet", "--test", "tally"]);
}

/// The tests the "Constructs at run time" table of `docs/language.md` cites, as
/// `(file, test)`: each cell names `path/file.rs::test`, and `::test` goes on with the
/// file named before it.
fn cited_tests(text: &str) -> Vec<(String, String)> {
    let table = text
        .split("## Constructs at run time")
        .nth(1)
        .expect("the table's section");
    let mut cited = Vec::new();
    for row in table
        .lines()
        .skip_while(|line| !line.starts_with('|'))
        .take_while(|line| line.starts_with('|'))
        .skip(2)
    {
        let cell = row.trim_end_matches('|').rsplit('|').next().unwrap_or("");
        let mut file = String::new();
        for (index, piece) in cell.split('`').enumerate() {
            if index % 2 == 0 {
                continue;
            }
            let Some((path, test)) = piece.rsplit_once("::") else {
                continue;
            };
            if !path.is_empty() {
                file = path.to_owned();
            }
            if !file.is_empty() && !test.is_empty() {
                cited.push((file.clone(), test.to_owned()));
            }
        }
    }
    cited
}

#[test]
fn every_test_the_constructs_table_cites_exists() {
    let cited = cited_tests(&language_md());
    assert!(cited.len() > 50, "the table cites tests: {cited:?}");
    let missing: Vec<String> = cited
        .iter()
        .filter(|(file, test)| {
            let source = std::fs::read_to_string(repository().join(file)).unwrap_or_default();
            !source.contains(&format!("fn {test}("))
        })
        .map(|(file, test)| format!("{file}::{test}"))
        .collect();
    assert!(
        missing.is_empty(),
        "docs/language.md cites tests that do not exist: {missing:#?}"
    );
}
