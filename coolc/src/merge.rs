//! Writing an emitted crate to disk without destroying user code.
//!
//! Generated files are rewritten (only when their contents changed, so cargo does not
//! rebuild needlessly). User files are written when missing; an existing one is only
//! ever added to: stubs for methods that are new in the description are inserted just
//! before the closing brace of the file's `impl ... Behavior for ...` (or
//! `Converters`) block, and `src/lib.rs` gets `pub mod` lines for new user modules.
//! Every other byte of a user file is preserved. Methods the user has whose stub no
//! longer exists are reported, never deleted.
//!
//! The last generated stubs are kept in `.coolc/stubs/` inside the crate, so the
//! user can diff what coolc would write today against their code.

use std::fs;
use std::io;
use std::path::{Path, PathBuf};

use syn::spanned::Spanned;

use crate::emit::{self, EmittedFile, FileKind, StubSet};
use crate::ir;

/// What writing a crate did, for the CLI to report.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Report {
    /// Files written or rewritten (generated, and user files created).
    pub written: Vec<PathBuf>,
    /// Stubs added to existing user files: `(file, method names)`.
    pub added: Vec<(PathBuf, Vec<String>)>,
    /// Warnings: methods left in user files whose description member is gone, user
    /// files that could not be merged.
    pub warnings: Vec<String>,
}

/// The outcome of merging stubs into one user file's text.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Merged {
    /// The new text (equal to the input when nothing was added).
    pub text: String,
    /// Methods whose stubs were added.
    pub added: Vec<String>,
    /// Methods the user has that no stub asks for any more.
    pub stale: Vec<String>,
}

/// Why a user file could not be merged.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum MergeError {
    /// The user file is not valid Rust.
    #[error("it does not parse as Rust ({0})")]
    Parse(String),
    /// No `impl ... <trait> for ...` block was found.
    #[error("it has no `impl {0} for ...` block")]
    NoImpl(String),
}

/// Methods of the generated traits that have default bodies (never stale).
const PROVIDED: &[&str] = &["start", "stop"];

/// Adds the stubs of `set` missing from `text`.
pub fn merge_stubs(text: &str, set: &StubSet) -> Result<Merged, MergeError> {
    let file = syn::parse_file(text).map_err(|e| MergeError::Parse(e.to_string()))?;
    let block = file
        .items
        .iter()
        .find_map(|item| match item {
            syn::Item::Impl(block) => {
                let (_, path, _) = block.trait_.as_ref()?;
                let last = path.segments.last()?;
                (last.ident == set.trait_name).then_some(block)
            }
            _ => None,
        })
        .ok_or_else(|| MergeError::NoImpl(set.trait_name.clone()))?;
    let present: Vec<String> = block
        .items
        .iter()
        .filter_map(|item| match item {
            syn::ImplItem::Fn(f) => Some(f.sig.ident.to_string()),
            _ => None,
        })
        .collect();
    let wanted: Vec<&str> = set.stubs.iter().map(|(name, _)| name.as_str()).collect();
    let stale: Vec<String> = present
        .iter()
        .filter(|name| {
            let bare = name.trim_start_matches("r#");
            !wanted.iter().any(|w| w.trim_start_matches("r#") == bare) && !PROVIDED.contains(&bare)
        })
        .cloned()
        .collect();
    let missing: Vec<&(String, String)> = set
        .stubs
        .iter()
        .filter(|(name, _)| {
            let bare = name.trim_start_matches("r#");
            !present.iter().any(|p| p.trim_start_matches("r#") == bare)
        })
        .collect();
    if missing.is_empty() {
        return Ok(Merged {
            text: text.to_owned(),
            added: Vec::new(),
            stale,
        });
    }
    let close = block.brace_token.span.close().span().start();
    let brace = byte_offset(text, close.line, close.column);
    // Insert at the start of the brace's line when only indentation precedes it, so
    // the brace keeps its own line; otherwise just before the brace.
    let line_start = text[..brace].rfind('\n').map_or(0, |i| i + 1);
    let (at, lead) = if text[line_start..brace].trim().is_empty() {
        (line_start, "")
    } else {
        (brace, "\n")
    };
    let mut insertion = String::from(lead);
    for (_, stub) in &missing {
        insertion.push('\n');
        insertion.push_str(stub.trim_end());
        insertion.push('\n');
    }
    let mut merged = String::with_capacity(text.len() + insertion.len());
    merged.push_str(&text[..at]);
    merged.push_str(&insertion);
    merged.push_str(&text[at..]);
    Ok(Merged {
        text: merged,
        added: missing.iter().map(|(name, _)| name.clone()).collect(),
        stale,
    })
}

/// The byte offset of a 1-based line and 0-based character column.
fn byte_offset(text: &str, line: usize, column: usize) -> usize {
    let mut offset = 0;
    for (index, l) in text.split_inclusive('\n').enumerate() {
        if index + 1 == line {
            return offset + l.char_indices().nth(column).map_or(l.len(), |(i, _)| i);
        }
        offset += l.len();
    }
    text.len()
}

/// Adds `pub mod m;` lines for `modules` not declared in `lib_rs`.
pub fn merge_modules(
    lib_rs: &str,
    modules: &[String],
) -> Result<(String, Vec<String>), MergeError> {
    let file = syn::parse_file(lib_rs).map_err(|e| MergeError::Parse(e.to_string()))?;
    let declared: Vec<String> = file
        .items
        .iter()
        .filter_map(|item| match item {
            syn::Item::Mod(m) => Some(m.ident.to_string()),
            _ => None,
        })
        .collect();
    let missing: Vec<String> = modules
        .iter()
        .filter(|m| !declared.contains(m))
        .cloned()
        .collect();
    let mut text = lib_rs.to_owned();
    if !missing.is_empty() && !text.ends_with('\n') {
        text.push('\n');
    }
    for module in &missing {
        text.push_str(&format!("pub mod {module};\n"));
    }
    Ok((text, missing))
}

fn write_if_changed(path: &Path, contents: &str) -> io::Result<bool> {
    if fs::read_to_string(path).is_ok_and(|old| old == contents) {
        return Ok(false);
    }
    if let Some(parent) = path.parent() {
        fs::create_dir_all(parent)?;
    }
    fs::write(path, contents)?;
    Ok(true)
}

/// Writes the crate for `krate` into `dir`, merging into existing user files.
pub fn write_crate(dir: &Path, krate: &ir::Crate) -> io::Result<Report> {
    let files = emit::emit_crate(krate);
    write_files(
        dir,
        &files,
        &emit::stub_sets(krate),
        &emit::user_modules(krate),
    )
}

/// Writes emitted `files` into `dir` (see the module doc).
pub fn write_files(
    dir: &Path,
    files: &[EmittedFile],
    stub_sets: &[StubSet],
    user_modules: &[String],
) -> io::Result<Report> {
    let mut report = Report::default();
    for file in files {
        let path = dir.join(&file.path);
        match file.kind {
            FileKind::Generated => {
                if write_if_changed(&path, &file.contents)? {
                    report.written.push(file.path.clone());
                }
            }
            FileKind::User if !path.exists() => {
                write_if_changed(&path, &file.contents)?;
                report.written.push(file.path.clone());
            }
            FileKind::User => {
                let text = fs::read_to_string(&path)?;
                if file.path == Path::new("src/lib.rs") {
                    match merge_modules(&text, user_modules) {
                        Ok((merged, added)) if !added.is_empty() => {
                            fs::write(&path, merged)?;
                            report.added.push((file.path.clone(), added));
                        }
                        Ok(_) => {}
                        Err(error) => report.warnings.push(format!(
                            "{} was not updated: {error}; declare these modules yourself: {}",
                            file.path.display(),
                            user_modules.join(", ")
                        )),
                    }
                    continue;
                }
                let Some(set) = stub_sets.iter().find(|s| s.path == file.path) else {
                    continue;
                };
                match merge_stubs(&text, set) {
                    Ok(merged) => {
                        if !merged.added.is_empty() {
                            fs::write(&path, &merged.text)?;
                            report.added.push((file.path.clone(), merged.added));
                        }
                        if !merged.stale.is_empty() {
                            report.warnings.push(format!(
                                "{} has methods the description no longer asks for (kept, remove them when done): {}",
                                file.path.display(),
                                merged.stale.join(", ")
                            ));
                        }
                    }
                    Err(error) => report.warnings.push(format!(
                        "{} was not updated: {error}; its stubs are in .coolc/stubs/{}",
                        file.path.display(),
                        file.path.display()
                    )),
                }
            }
        }
    }
    // Keep the latest stubs for reference (what coolc would write today).
    for file in files.iter().filter(|f| f.kind == FileKind::User) {
        write_if_changed(&dir.join(".coolc/stubs").join(&file.path), &file.contents)?;
    }
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(stubs: &[&str]) -> StubSet {
        StubSet {
            path: PathBuf::from("src/x.rs"),
            trait_name: "Behavior".to_owned(),
            stubs: stubs
                .iter()
                .map(|n| (n.to_string(), format!("    fn {n}(&mut self) {{}}\n")))
                .collect(),
        }
    }

    const USER: &str = "use crate::generated::x::*;\n\npub struct X {}\n\nimpl Behavior for X {\n    fn a_entry(&mut self) {\n        // mine\n    }\n}\n";

    #[test]
    fn adds_only_missing_stubs_before_the_closing_brace() {
        let merged = merge_stubs(USER, &set(&["a_entry", "b_entry"])).unwrap();
        assert_eq!(merged.added, ["b_entry"]);
        assert!(merged.stale.is_empty());
        assert_eq!(
            merged.text,
            "use crate::generated::x::*;\n\npub struct X {}\n\nimpl Behavior for X {\n    fn a_entry(&mut self) {\n        // mine\n    }\n\n    fn b_entry(&mut self) {}\n}\n"
        );
        assert!(merged.text.starts_with(&USER[..USER.len() - 2]));
    }

    #[test]
    fn reports_stale_methods_and_keeps_them() {
        let merged = merge_stubs(USER, &set(&[])).unwrap();
        assert_eq!(merged.stale, ["a_entry"]);
        assert_eq!(merged.text, USER);
    }

    #[test]
    fn empty_impl_on_one_line() {
        let merged = merge_stubs("struct X;\nimpl m::Behavior for X {}\n", &set(&["a"])).unwrap();
        assert_eq!(
            merged.text,
            "struct X;\nimpl m::Behavior for X {\n\n    fn a(&mut self) {}\n}\n"
        );
    }

    #[test]
    fn unparsable_or_missing_impl_is_an_error() {
        assert!(matches!(
            merge_stubs("fn (", &set(&["a"])),
            Err(MergeError::Parse(_))
        ));
        assert_eq!(
            merge_stubs("struct X;", &set(&["a"])),
            Err(MergeError::NoImpl("Behavior".to_owned()))
        );
    }

    #[test]
    fn modules_are_appended() {
        let (text, added) = merge_modules(
            "pub mod generated;\npub mod a;",
            &["a".to_owned(), "b".to_owned()],
        )
        .unwrap();
        assert_eq!(added, ["b"]);
        assert_eq!(text, "pub mod generated;\npub mod a;\npub mod b;\n");
    }
}
