//! Mutation test: descriptions derived from the fixtures by deleting lines either
//! fail the checker or lower and emit without panicking (emission parses every Rust
//! file it writes, so a template that breaks on an unusual shape panics here).

use std::path::{Path, PathBuf};

use proptest::prelude::*;

fn fixtures() -> Vec<PathBuf> {
    let mut paths = Vec::new();
    for dir in ["tests/data", "../tests/data/ok"] {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join(dir);
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "cool") {
                paths.push(path);
            }
        }
    }
    paths.sort();
    paths
}

/// Analyzes `root` with `mutated` standing in for its text (imports read from disk).
fn analyze_mutated(root: &Path, mutated: &str) -> coolc::Analysis {
    let text = mutated.to_owned();
    coolc::analyze(&[root], &|p: &Path| {
        if p == root {
            Ok(text.clone())
        } else {
            std::fs::read_to_string(p)
        }
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    #[test]
    fn deleting_lines_never_panics_emission(
        pick in any::<prop::sample::Index>(),
        deletions in prop::collection::vec(any::<prop::sample::Index>(), 1..4),
    ) {
        let fixtures = fixtures();
        let root = pick.get(&fixtures);
        let text = std::fs::read_to_string(root).unwrap();
        let mut lines: Vec<&str> = text.lines().collect();
        for deletion in &deletions {
            if lines.is_empty() {
                break;
            }
            let index = deletion.index(lines.len());
            lines.remove(index);
        }
        let analysis = analyze_mutated(root, &lines.join("\n"));
        if let Ok(checked) = analysis.checked() {
            let krate = coolc::lower::lower(&checked, &coolc::lower::Options::default());
            let files = coolc::emit::emit_crate(&krate);
            prop_assert!(files.iter().any(|f| f.path == Path::new("src/generated/mod.rs")));
        }
    }
}
