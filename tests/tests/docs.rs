//! The documentation agrees with the compiler and the runtime: every diagnostic code is
//! documented, every documented code exists, and every `cool` example in
//! `docs/language.md` parses as written (examples that are members of a component are
//! parsed inside one). Every `rust` block of the docs is compiled: the examples that
//! are whole files in the crates `coolc compile` writes for their descriptions (and
//! their tests run) and the tutorial's steps in the crate it builds, here; the API
//! fragments of the runtime and network docs in functions of the workspace member
//! `coolbot-docs-fragments` (`tests/docs-fragments`), whose table `FRAGMENTS` this
//! file shares, and which `every_api_fragment_of_the_docs_compiles` checks. A `rust`
//! block no test compiles fails `every_rust_block_of_the_docs_is_compiled`.

use std::collections::BTreeSet;
use std::path::Path;

use coolc::diagnostics::Code;

/// The table of the API fragments and how a block is found, shared with the build
/// script of `coolbot-docs-fragments`, which compiles them.
#[path = "../../coolc/tests/all/common/generated_crates.rs"]
mod generated_crates;
#[path = "../docs-fragments/places.rs"]
mod places;

use places::{FRAGMENTS, Place, doc, fences, place, repository};

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
    fences(text)
        .into_iter()
        .filter(|fence| fence.info == lang)
        .map(|fence| fence.body)
        .collect()
}

const GENERATED: &str = "docs/generated-code.md";
const TUTORIAL: &str = "docs/tutorial.md";

const WATCHER: Place = place(GENERATED, "## What a section can use", 0);
const TALLY: Place = place(
    GENERATED,
    "## Testing a component alone: the generated harness",
    0,
);
const TALLY_TEST: Place = place(
    GENERATED,
    "## Testing a component alone: the generated harness",
    1,
);
const BASE_SUPERVISOR: Place = place(GENERATED, "## A compound component's generated module", 0);
const BASE_MAIN: Place = place(GENERATED, "## A compound component's generated module", 1);
const BASE_TEST: Place = place(
    GENERATED,
    "## Testing a supervisor alone: the compound's harness",
    0,
);
const BUILDER_SCRIPT: Place = place(GENERATED, "## From a build script: `coolc::Builder`", 0);
const BUILDER_LIB: Place = place(GENERATED, "## From a build script: `coolc::Builder`", 1);
const TUTORIAL_STUBS: Place = place(TUTORIAL, "## 3. Fill in the stubs", 0);
const TUTORIAL_NEW_STUB: Place = place(TUTORIAL, "## 6. Regenerate: your code stays", 0);
const TUTORIAL_RESTS: Place = place(TUTORIAL, "## 7. Fill in the new stub and run again", 0);
const TUTORIAL_BUILD_SCRIPT: Place = place(TUTORIAL, "## 8. From a build script instead", 0);
const TUTORIAL_BUILD_LIB: Place = place(TUTORIAL, "## 8. From a build script instead", 1);
const TUTORIAL_FAILS: Place = place(TUTORIAL, "## 9. Compose: a compound component", 0);
const TUTORIAL_COVERS: Place = place(TUTORIAL, "## 9. Compose: a compound component", 1);
const TUTORIAL_MAIN: Place = place(TUTORIAL, "## 9. Compose: a compound component", 2);

/// Every `rust` block a test of this file compiles.
fn compiled() -> BTreeSet<Place> {
    let whole = [
        WATCHER,
        TALLY,
        TALLY_TEST,
        BASE_SUPERVISOR,
        BASE_MAIN,
        BASE_TEST,
        BUILDER_SCRIPT,
        BUILDER_LIB,
        TUTORIAL_STUBS,
        TUTORIAL_NEW_STUB,
        TUTORIAL_RESTS,
        TUTORIAL_BUILD_SCRIPT,
        TUTORIAL_BUILD_LIB,
        TUTORIAL_FAILS,
        TUTORIAL_COVERS,
        TUTORIAL_MAIN,
    ];
    whole
        .into_iter()
        .chain(FRAGMENTS.iter().map(|(place, _)| *place))
        .chain(ELSEWHERE.iter().map(|(place, _)| *place))
        .chain(std::iter::once(ROS_LIBRARY))
        .collect()
}

/// `rust` blocks that a test of another crate builds and runs, with that test's file:
/// the test reads its blocks from the docs by their heading
/// (`the_docs_name_where_their_blocks_are_built_elsewhere`).
const ELSEWHERE: &[(Place, &str)] = &[
    (
        place("docs/ros2.md", "## A description with ROS 2 types", 0),
        "coolc/tests/all/ros_crate.rs",
    ),
    (
        place("docs/ros2.md", "## A description with ROS 2 types", 1),
        "coolc/tests/all/ros_crate.rs",
    ),
    (
        place("docs/ros2.md", "## A description with ROS 2 types", 2),
        "coolc/tests/all/ros_crate.rs",
    ),
    (
        place("docs/ros2.md", "## A description with ROS 2 types", 3),
        "coolc/tests/all/ros_crate.rs",
    ),
];

/// The example of `coolc::ros`, which is the module's doc example (a doctest of
/// `coolc`): `the_ros_library_block_is_the_doctest_of_coolc_ros` keeps them the same.
const ROS_LIBRARY: Place = place("docs/ros2.md", "## The library: `coolc::ros`", 0);

#[test]
fn the_docs_name_where_their_blocks_are_built_elsewhere() {
    for (place, file) in ELSEWHERE {
        let test = doc(file);
        let heading = place.heading.trim_start_matches('#').trim_start();
        assert!(
            test.contains(place.doc) && test.contains(&format!("\"{}\"", place.heading)),
            "{file} does not read the blocks of {} under {heading:?}",
            place.doc
        );
        assert!(!place.text().trim().is_empty());
    }
}

#[test]
fn the_ros_library_block_is_the_doctest_of_coolc_ros() {
    let module = doc("coolc/src/ros/mod.rs");
    let doctest: String = module
        .lines()
        .filter_map(|line| line.strip_prefix("//!"))
        .map(|line| line.strip_prefix(' ').unwrap_or(line))
        .skip_while(|line| !line.starts_with("```"))
        .skip(1)
        .take_while(|line| !line.starts_with("```"))
        .map(|line| format!("{line}\n"))
        .collect();
    assert!(
        !doctest.is_empty(),
        "coolc/src/ros/mod.rs has a doc example"
    );
    assert_eq!(
        ROS_LIBRARY.text(),
        doctest,
        "docs/ros2.md's `coolc::ros` example differs from the doctest of coolc/src/ros/mod.rs"
    );
}

/// The Markdown files of the repository that show code.
const MARKDOWN: &[&str] = &[
    "README.md",
    "ARCHITECTURE.md",
    "examples/README.md",
    "docs/distribution.md",
    "docs/foxglove.md",
    "docs/generated-code.md",
    "docs/language.md",
    "docs/performance.md",
    "docs/ros2.md",
    "docs/runtime.md",
    "docs/tools.md",
    "docs/tutorial.md",
];

#[test]
fn every_rust_block_of_the_docs_is_compiled() {
    let mut found = BTreeSet::new();
    let mut unmarked = Vec::new();
    for &file in MARKDOWN {
        let text = doc(file);
        let mut under: std::collections::BTreeMap<String, usize> = Default::default();
        for fence in fences(&text) {
            let looks_like_rust = ["fn ", "let ", "use ", "impl "]
                .iter()
                .any(|word| fence.body.contains(word))
                && fence.body.contains(';');
            if fence.info.is_empty() && looks_like_rust {
                unmarked.push(format!("{file}:{}", fence.line));
            }
            if fence.info != "rust" {
                continue;
            }
            let index = under.entry(fence.heading.clone()).or_default();
            found.insert((file.to_owned(), fence.heading.clone(), *index, fence.line));
            *index += 1;
        }
    }
    let compiled = compiled();
    let missing: Vec<String> = found
        .iter()
        .filter(|(file, heading, index, _)| {
            !compiled
                .iter()
                .any(|p| p.doc == file && p.heading == heading && p.index == *index)
        })
        .map(|(file, heading, _, line)| format!("{file}:{line} (under {heading:?})"))
        .collect();
    assert!(
        missing.is_empty(),
        "rust blocks no test compiles (compile each here, or mark a block that is not \
         code `text`): {missing:#?}"
    );
    let stale: Vec<&Place> = compiled
        .iter()
        .filter(|p| {
            !found.iter().any(|(file, heading, index, _)| {
                p.doc == file && p.heading == heading && p.index == *index
            })
        })
        .collect();
    assert!(stale.is_empty(), "no such rust blocks: {stale:#?}");
    assert!(
        unmarked.is_empty(),
        "blocks without a language that look like Rust: {unmarked:?}"
    );
}

/// Runs `cargo <args>` in `dir` as coolc's tests build the crates they generate
/// ([`generated_crates::gen_cargo`]); panics with cargo's output when it fails.
fn cargo(dir: &Path, args: &[&str]) {
    generated_crates::run_cargo(generated_crates::gen_cargo(dir), dir, args, &[]);
}

/// [`cargo`], with the crate's own targets linted by clippy under `-D warnings` in
/// the same build ([`generated_crates::gen_cargo_linted`]: every command that
/// compiles that crate goes through this one).
fn cargo_linted(dir: &Path, args: &[&str]) {
    generated_crates::run_cargo(generated_crates::gen_cargo_linted(dir), dir, args, &[]);
}

/// Lowers the descriptions `files` (`(name, text)`; the first is the root, the others
/// what it imports) for a crate named `package` on the repository's runtime.
fn lower_files(files: &[(&str, &str)], package: &str) -> coolc::ir::Crate {
    let texts: std::collections::HashMap<std::path::PathBuf, String> = files
        .iter()
        .map(|(name, text)| (Path::new(name).to_owned(), (*text).to_owned()))
        .collect();
    let root = files[0].0;
    let checked = coolc::analyze(&[root], &|path: &Path| {
        texts
            .get(path)
            .cloned()
            .ok_or_else(|| std::io::Error::from(std::io::ErrorKind::NotFound))
    })
    .checked()
    .unwrap_or_else(|analysis| panic!("{}", analysis.render(coolc::RenderOptions::plain())));
    let options = coolc::lower::Options {
        package: package.to_owned(),
        runtime: coolc::ir::RuntimeDep::Path(repository().join("runtime").display().to_string()),
        sources: vec![root.to_owned()],
        inputs: coolc::fingerprint::inputs(checked.sources().files()),
    };
    coolc::lower::lower(&checked, &options)
}

/// Lowers one description for a crate named `package` on the repository's runtime.
fn lower(name: &str, text: &str, package: &str) -> coolc::ir::Crate {
    lower_files(&[(name, text)], package)
}

/// The method `fn name(` of `code` (an `impl` block's, indented four spaces), from
/// its line to its closing brace.
fn method<'a>(code: &'a str, name: &str) -> &'a str {
    let start = code
        .find(&format!("    fn {name}("))
        .unwrap_or_else(|| panic!("no method {name} in:\n{code}"));
    let end = code[start..]
        .find("\n    }\n")
        .map(|i| start + i + "\n    }\n".len())
        .unwrap_or_else(|| panic!("method {name} does not end"));
    &code[start..end]
}

#[test]
fn the_documented_header_is_the_starters() {
    let text = doc(GENERATED);
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
    let tutorial = doc(TUTORIAL);
    let described = &blocks(section(&tutorial, "## 2. "), "cool")[0];
    assert_eq!(*described, coolc::cli::starter_description("Blinker"));
}

#[test]
fn the_tutorials_build_script_crate_builds() {
    // Section 8 as written: its Cargo.toml (the clone's paths made real), build.rs and
    // src/lib.rs, with the starter blinker's description and code.
    let tutorial = doc(TUTORIAL);
    let manifest = &blocks(section(&tutorial, "## 8. "), "toml")[0];
    let (script, lib) = (TUTORIAL_BUILD_SCRIPT.text(), TUTORIAL_BUILD_LIB.text());
    assert!(script.starts_with("// build.rs\n"), "{script}");
    assert!(lib.starts_with("// src/lib.rs\n"), "{lib}");
    assert!(
        lib.contains("pub mod generated {"),
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
    std::fs::write(krate.join("build.rs"), script).unwrap();
    std::fs::write(krate.join("src/lib.rs"), lib).unwrap();
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

/// Inserts `insertion` into `text` after the first line equal to `after` (trimmed).
fn insert_after(text: &str, after: &str, insertion: &str) -> String {
    let at = text
        .find(&format!("{after}\n"))
        .unwrap_or_else(|| panic!("no line {after:?} in:\n{text}"))
        + after.len()
        + 1;
    format!("{}{insertion}{}", &text[..at], &text[at..])
}

#[test]
fn the_tutorials_crate_builds_at_its_last_step() {
    // The blinker of sections 2, 5 and 9 and the pair of section 9, with the code of
    // sections 3, 6, 7 and 9: section 7's `Blinker` with section 9's
    // `counting_periodic` and section 3's `done_entry` (as it says), and, as the
    // crate was at section 6, section 3's code with the stub section 6 shows.
    let tutorial = doc(TUTORIAL);
    let fifth = blocks(section(&tutorial, "## 5. "), "cool");
    let ninth = blocks(section(&tutorial, "## 9. "), "cool");
    let starter = coolc::cli::starter_description("Blinker");
    let counting = "        state counting {\n            entry;\n            periodic;\n            may -> done;\n        }\n";
    assert!(starter.contains(counting), "{starter}");
    let blinker = insert_after(
        &starter,
        "    observable count: u64 = 0;",
        &format!("\n{}", fifth[0]),
    )
    .replace(counting, &fifth[1]);
    let blinker = insert_after(&blinker, "        limit: u64 = 10;", &ninth[0]);
    let pair = &ninth[1];

    // What the tutorial says coolc writes.
    let first = lower("blinker.cool", &starter, "blinker");
    let written = coolc::emit::starter_component(&first.atomics[0]);
    let stubs = TUTORIAL_STUBS.text();
    assert!(
        written.contains(&stubs),
        "section 3 shows the code `coolc new` writes:\n{written}"
    );
    let krate = lower_files(
        &[("pair.cool", pair), ("blinker.cool", &blinker)],
        "blinker",
    );
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("blinker");
    coolc::merge::write_crate(&out, &krate).unwrap();
    let src = out.join("src");
    let stubbed = std::fs::read_to_string(src.join("blinker.rs")).unwrap();
    let new_stub = TUTORIAL_NEW_STUB.text();
    assert!(
        stubbed.contains(&new_stub),
        "section 6 shows the stub coolc adds:\n{stubbed}"
    );

    let header = "use crate::generated::blinker::*;\n\n";
    let rests = TUTORIAL_RESTS.text();
    let as_before = "    // counting_periodic and done_entry as before\n";
    assert!(rests.contains(as_before), "{rests}");
    let last = format!(
        "{}\n{}",
        TUTORIAL_FAILS.text(),
        method(&stubs, "done_entry")
    );
    std::fs::write(
        src.join("blinker.rs"),
        format!("{header}{}", rests.replace(as_before, &last)),
    )
    .unwrap();
    let at_six = stubs.replacen(
        "impl Behavior for Blinker {\n",
        &format!("impl Behavior for Blinker {{\n{new_stub}\n"),
        1,
    );
    std::fs::write(
        src.join("at_section_6.rs"),
        format!(
            "//! The blinker as section 6 left it.\n\n{header}\
             /// The starter's `Blinker`.\n#[derive(Debug, Default)]\npub struct Blinker {{}}\n\n{at_six}"
        ),
    )
    .unwrap();
    let user_pair = std::fs::read_to_string(src.join("pair.rs")).unwrap();
    let covers = TUTORIAL_COVERS.text();
    std::fs::write(
        src.join("pair.rs"),
        user_pair.replace(method(&user_pair, "covering_entry"), &covers),
    )
    .unwrap();
    std::fs::write(src.join("main.rs"), TUTORIAL_MAIN.text()).unwrap();
    let lib = std::fs::read_to_string(src.join("lib.rs")).unwrap();
    std::fs::write(src.join("lib.rs"), lib + "pub mod at_section_6;\n").unwrap();
    generated_crates::lint(&out);
}

#[test]
fn the_section_api_example_compiles_warning_free() {
    // docs/generated-code.md, "What a section can use": the description and the user
    // file, in the crate `coolc compile` writes.
    let text = doc(GENERATED);
    let text = section(&text, "## What a section can use");
    let description = &blocks(text, "cool")[0];
    let code = WATCHER.text();
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
    generated_crates::lint(&out);
}

#[test]
fn the_harness_example_runs() {
    // docs/generated-code.md, "Testing a component alone": the description, its code
    // and its test, in the crate `coolc compile` writes; the test passes.
    let text = doc(GENERATED);
    let text = section(&text, "## Testing a component alone");
    let description = &blocks(text, "cool")[0];
    let (user, test) = (TALLY.text(), TALLY_TEST.text());
    assert!(test.matches("#[test]").count() >= 2, "{test}");
    let krate = lower("tally.cool", description, "tally");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("tally");
    coolc::merge::write_crate(&out, &krate).unwrap();
    std::fs::write(out.join("src/tally.rs"), user).unwrap();
    std::fs::create_dir_all(out.join("tests")).unwrap();
    std::fs::write(out.join("tests/tally.rs"), test).unwrap();
    generated_crates::lint(&out);
    cargo_linted(&out, &["test", "--quiet", "--test", "tally"]);
}

/// The description of the compound example of `docs/generated-code.md`.
fn base_description() -> String {
    let text = doc(GENERATED);
    blocks(
        section(&text, "## A compound component's generated module"),
        "cool",
    )[0]
    .clone()
}

#[test]
fn the_compound_example_and_its_supervisor_tests_run() {
    // docs/generated-code.md, "A compound component's generated module" and "Testing
    // a supervisor alone": the description, the supervisor's code, a main and the
    // harness tests, in the crate `my-base` that `coolc compile` writes (the motion
    // controller keeps its stubs); the tests pass.
    let krate = lower("base.cool", &base_description(), "my-base");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("my-base");
    coolc::merge::write_crate(&out, &krate).unwrap();
    std::fs::write(out.join("src/mobile_base.rs"), BASE_SUPERVISOR.text()).unwrap();
    std::fs::write(out.join("src/main.rs"), BASE_MAIN.text()).unwrap();
    std::fs::create_dir_all(out.join("tests")).unwrap();
    let test = BASE_TEST.text();
    assert!(test.matches("#[test]").count() >= 3, "{test}");
    std::fs::write(out.join("tests/base.rs"), test).unwrap();
    generated_crates::lint(&out);
    cargo_linted(&out, &["test", "--quiet", "--test", "base"]);
}

#[test]
fn the_compound_example_builds_from_a_build_script() {
    // docs/generated-code.md, "From a build script": the example crate `my-base` with
    // the documented build.rs and src/lib.rs, its description in `components/`, the
    // supervisor's code and the motion controller's stubs.
    let description = base_description();
    let (script, lib) = (BUILDER_SCRIPT.text(), BUILDER_LIB.text());
    assert!(script.contains("\"components/base.cool\""), "{script}");
    let lowered = lower("base.cool", &description, "my-base");
    let dir = tempfile::tempdir().unwrap();
    let krate = dir.path().join("my-base-build");
    std::fs::create_dir_all(krate.join("src")).unwrap();
    std::fs::create_dir_all(krate.join("components")).unwrap();
    let root = repository();
    std::fs::write(
        krate.join("Cargo.toml"),
        format!(
            "[package]\nname = \"my-base\"\nversion = \"0.1.0\"\nedition = \"2024\"\n\n\
             [dependencies]\ncoolbot = {{ path = \"{runtime}\" }}\n\
             serde = {{ version = \"1\", features = [\"derive\"] }}\n\n\
             [build-dependencies]\ncoolc = {{ path = \"{coolc}\" }}\n",
            runtime = root.join("runtime").display(),
            coolc = root.join("coolc").display(),
        ),
    )
    .unwrap();
    std::fs::write(krate.join("components/base.cool"), &description).unwrap();
    std::fs::write(krate.join("build.rs"), script).unwrap();
    std::fs::write(krate.join("src/lib.rs"), lib).unwrap();
    std::fs::write(krate.join("src/mobile_base.rs"), BASE_SUPERVISOR.text()).unwrap();
    // The motion controller's stubs, as `coolc compile` writes them.
    let scratch = dir.path().join("scratch");
    coolc::merge::write_crate(&scratch, &lowered).unwrap();
    std::fs::copy(
        scratch.join("src/motion_controller.rs"),
        krate.join("src/motion_controller.rs"),
    )
    .unwrap();
    cargo(&krate, &["build", "--quiet"]);
}

#[test]
fn every_api_fragment_of_the_docs_compiles() {
    // `coolbot-docs-fragments` compiles them (a workspace member this test links, so
    // it built before): its build script wrote one function per entry of `FRAGMENTS`,
    // each from its doc as the doc reads now.
    let compiled = coolbot_docs_fragments::COMPILED;
    assert_eq!(
        compiled.len(),
        FRAGMENTS.len(),
        "coolbot-docs-fragments compiled {compiled:#?}"
    );
    for (fragment, (place, _)) in compiled.iter().zip(FRAGMENTS) {
        assert_eq!(
            (fragment.doc, fragment.heading, fragment.index),
            (place.doc, place.heading, place.index),
        );
        assert_eq!(
            fragment.text,
            place.text(),
            "coolbot-docs-fragments compiled an older text of {place:?}"
        );
    }
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
