//! Random and mutated inputs never panic `analyze`: parsing, resolution and every
//! check must turn any text into diagnostics.

use std::path::{Path, PathBuf};

use proptest::prelude::*;

/// The ok fixtures, concatenated into one self-contained text per file (imports are
/// answered from the same set).
fn fixtures() -> Vec<(String, String)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data");
    let mut out = Vec::new();
    for sub in ["ok", "err", "warn"] {
        let mut entries: Vec<PathBuf> = std::fs::read_dir(dir.join(sub))
            .expect("fixture dir")
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|e| e == "cool"))
            .collect();
        entries.sort();
        for path in entries {
            let name = format!(
                "{sub}/{}",
                path.file_name().unwrap_or_default().to_string_lossy()
            );
            out.push((
                name,
                std::fs::read_to_string(&path).expect("readable fixture"),
            ));
        }
    }
    out
}

/// Analyzes `text` as `main.cool`; other names are served from the ok fixtures so
/// imports keep working.
fn analyze(text: &str) {
    let fixtures = fixtures_cached();
    let loader = |path: &Path| -> std::io::Result<String> {
        if path == Path::new("main.cool") {
            return Ok(text.to_owned());
        }
        let name = path
            .file_name()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned();
        fixtures
            .iter()
            .find(|(fixture, _)| fixture.ends_with(&format!("/{name}")))
            .map(|(_, text)| text.clone())
            .ok_or_else(|| std::io::Error::from(std::io::ErrorKind::NotFound))
    };
    let analysis = coolc::analyze(&["main.cool"], &loader);
    // Rendering must not panic either, in both formats.
    let _ = analysis.render(coolc::RenderOptions::plain());
    let _ = analysis.render(coolc::RenderOptions::json());
}

fn fixtures_cached() -> &'static [(String, String)] {
    static FIXTURES: std::sync::OnceLock<Vec<(String, String)>> = std::sync::OnceLock::new();
    FIXTURES.get_or_init(fixtures)
}

const TOKENS: &[&str] = &[
    "{",
    "}",
    ";",
    "(",
    ")",
    "[",
    "]",
    "<",
    ">",
    "->",
    "..",
    "::",
    ".",
    ",",
    "=",
    "==",
    "||",
    "&&",
    "!",
    "-",
    "?",
    "\"",
    "///",
    "/*",
    "*/",
    "//",
    "atomic",
    "compound",
    "state",
    "initial",
    "input",
    "output",
    "connect",
    "instance",
    "when",
    "on",
    "after",
    "may",
    "fifo<f64>(0)",
    "10ms",
    "1kHz",
    "0x",
    "1e999",
    "99999999999999999999999",
    "\\u{",
    "é",
    "\u{FEFF}",
    "\n",
];

#[derive(Debug, Clone)]
enum Mutation {
    Delete(usize, usize),
    Duplicate(usize, usize, usize),
    Swap(usize, usize, usize),
    Insert(usize, usize),
}

fn apply(text: &str, mutation: &Mutation) -> String {
    let bytes = text.as_bytes();
    let len = bytes.len().max(1);
    let range = |a: usize, b: usize| {
        let start = a % len;
        let end = (start + b % 40).min(bytes.len());
        (start.min(bytes.len()), end)
    };
    let out: Vec<u8> = match *mutation {
        Mutation::Delete(a, b) => {
            let (s, e) = range(a, b);
            [&bytes[..s], &bytes[e..]].concat()
        }
        Mutation::Duplicate(a, b, at) => {
            let (s, e) = range(a, b);
            let at = at % (bytes.len() + 1);
            [&bytes[..at], &bytes[s..e], &bytes[at..]].concat()
        }
        Mutation::Swap(a, b, c) => {
            let (s1, e1) = range(a, b);
            let (s2, e2) = range(c, b);
            if e1 <= s2 {
                [
                    &bytes[..s1],
                    &bytes[s2..e2],
                    &bytes[e1..s2],
                    &bytes[s1..e1],
                    &bytes[e2..],
                ]
                .concat()
            } else {
                bytes.to_vec()
            }
        }
        Mutation::Insert(at, token) => {
            let at = at % (bytes.len() + 1);
            [
                &bytes[..at],
                TOKENS[token % TOKENS.len()].as_bytes(),
                &bytes[at..],
            ]
            .concat()
        }
    };
    // Mutations work on bytes; the analyzer takes UTF-8 text, as the loader does.
    String::from_utf8_lossy(&out).into_owned()
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Mutation::Delete(a, b)),
        (any::<usize>(), any::<usize>(), any::<usize>())
            .prop_map(|(a, b, c)| Mutation::Duplicate(a, b, c)),
        (any::<usize>(), any::<usize>(), any::<usize>())
            .prop_map(|(a, b, c)| Mutation::Swap(a, b, c)),
        (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Mutation::Insert(a, b)),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn random_text_never_panics(text in "\\PC{0,200}") {
        analyze(&text);
    }

    #[test]
    fn random_token_soup_never_panics(tokens in proptest::collection::vec(0..TOKENS.len(), 0..60)) {
        let text: Vec<&str> = tokens.iter().map(|&i| TOKENS[i]).collect();
        analyze(&text.join(" "));
    }

    #[test]
    fn mutated_fixtures_never_panic(
        index in any::<usize>(),
        mutations in proptest::collection::vec(mutation(), 1..6),
    ) {
        let fixtures = fixtures_cached();
        let (_, original) = &fixtures[index % fixtures.len()];
        let mut text = original.clone();
        for mutation in &mutations {
            text = apply(&text, mutation);
        }
        analyze(&text);
    }
}

#[test]
fn the_mutation_harness_reaches_every_fixture() {
    // Guards the proptests above against an empty fixture set.
    assert!(
        fixtures_cached().len() >= 30,
        "found {} fixtures",
        fixtures_cached().len()
    );
}

#[test]
fn deep_nesting_is_an_error_not_a_crash() {
    for text in [
        format!(
            "atomic A {{ timing {{ period {}1ms; }} }}",
            "(".repeat(20_000)
        ),
        format!("packet P {{ x: {}f64 }}", "[".repeat(20_000)),
        format!("{} packet P {{ x: f64 }}", "/*".repeat(20_000)),
        format!(
            "compound C {{ supervisor {{ state s {{ when {}a -> s; }} }} }}",
            "!".repeat(20_000)
        ),
    ] {
        let analysis = coolc::analyze_text("deep.cool", &text);
        assert!(analysis.has_errors(), "deep nesting was accepted");
    }
}

#[test]
fn nesting_below_the_limit_parses() {
    let depth = coolc::syntax::MAX_DEPTH - 4;
    let text = format!(
        "compound C {{ local x: bool = true; supervisor {{ initial s; state s {{ when {}x{} -> s; }} }} }}",
        "(".repeat(depth),
        ")".repeat(depth)
    );
    let analysis = coolc::analyze_text("deep.cool", &text);
    assert!(
        !analysis.has_errors(),
        "{}",
        analysis.render(coolc::RenderOptions::plain())
    );
}
