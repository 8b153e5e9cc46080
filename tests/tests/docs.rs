//! The documentation agrees with the compiler: every diagnostic code is documented,
//! every documented code exists, and every `cool` example in `docs/language.md`
//! parses as written (examples that are members of a component are parsed inside
//! one).

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
