//! Names: Rust keywords (an error), naming conventions (a warning) and duplicates
//! within one scope (an error with a label on both definitions).

use std::collections::BTreeMap;

use super::Checker;
use crate::ast;
use crate::diagnostics::{Code, Diagnostic};

/// Rust's strict and reserved keywords (2024 edition), which generated code cannot use
/// as plain identifiers.
const RUST_KEYWORDS: &[&str] = &[
    "as", "async", "await", "break", "const", "continue", "crate", "dyn", "else", "enum", "extern",
    "false", "fn", "for", "if", "impl", "in", "let", "loop", "match", "mod", "move", "mut", "pub",
    "ref", "return", "self", "Self", "static", "struct", "super", "trait", "true", "type",
    "unsafe", "use", "where", "while", "abstract", "become", "box", "do", "final", "gen", "macro",
    "override", "priv", "try", "typeof", "unsized", "virtual", "yield",
];

/// A type-like name (packet, enum, variant, converter, component): no keyword,
/// UpperCamelCase.
pub(super) fn type_name(checker: &mut Checker<'_, '_>, name: &ast::Ident) {
    if keyword(checker, name) {
        return;
    }
    if !is_upper_camel(&name.name) {
        checker.push(
            Diagnostic::warning(
                Code::Naming,
                checker.file,
                name.span,
                format!("`{}` should be UpperCamelCase", name.name),
            )
            .with_label("type names are UpperCamelCase")
            .with_help(format!("write `{}`", to_upper_camel(&name.name))),
        );
    }
}

/// Any other name (field, port, variable, state, exception, instance): no keyword,
/// snake_case.
pub(super) fn value_name(checker: &mut Checker<'_, '_>, name: &ast::Ident) {
    let rust = crate::ident::snake_raw(&name.name);
    if rust.starts_with(|c: char| c.is_ascii_digit()) {
        let diagnostic = checker
            .error(
                Code::NoRustName,
                name.span,
                format!(
                    "`{}` has no Rust name: without its leading `_` it is `{rust}`",
                    name.name
                ),
            )
            .with_label("a digit after the leading `_`")
            .with_help("the generated code drops a leading `_`: start the name with a letter");
        checker.push(diagnostic);
        return;
    }
    if keyword(checker, name) {
        return;
    }
    if !is_snake(&name.name) {
        checker.push(
            Diagnostic::warning(
                Code::Naming,
                checker.file,
                name.span,
                format!("`{}` should be snake_case", name.name),
            )
            .with_label("names other than types are snake_case")
            .with_help(format!("write `{}`", to_snake(&name.name))),
        );
    }
}

/// Warns about a Rust keyword used as a name: the generated code escapes it
/// (`r#type`, or `self_` for the keywords that cannot be raw), which the developer
/// then has to write in their own code. Returns true when it was one.
fn keyword(checker: &mut Checker<'_, '_>, name: &ast::Ident) -> bool {
    if !RUST_KEYWORDS.contains(&name.name.as_str()) {
        return false;
    }
    let escaped = if NOT_RAW.contains(&name.name.as_str()) {
        format!("{}_", name.name)
    } else {
        format!("r#{}", name.name)
    };
    checker.push(
        Diagnostic::warning(
            Code::RustKeyword,
            checker.file,
            name.span,
            format!(
                "`{}` is a Rust keyword: the generated code calls it `{escaped}`",
                name.name
            ),
        )
        .with_label("reserved in Rust")
        .with_help("rename it to keep escaped identifiers out of the code you write"),
    );
    true
}

/// Keywords that cannot be raw identifiers; the generated code appends `_`.
const NOT_RAW: &[&str] = &["self", "Self", "super", "crate"];

/// Reports every name declared twice among `names` (one scope).
pub(super) fn duplicates<'n>(
    checker: &mut Checker<'_, '_>,
    names: impl IntoIterator<Item = &'n ast::Ident>,
    what: &str,
) {
    let mut seen: BTreeMap<&str, &ast::Ident> = BTreeMap::new();
    for name in names {
        match seen.get(name.name.as_str()) {
            Some(first) => {
                let diagnostic = checker
                    .error(
                        Code::Duplicate,
                        name.span,
                        format!("{what} `{}` is declared more than once", name.name),
                    )
                    .with_label("declared again here")
                    .with_secondary(first.span, "first declared here")
                    .with_help("rename or remove one of them");
                checker.push(diagnostic);
            }
            None => {
                seen.insert(&name.name, name);
            }
        }
    }
}

/// How a name is written in the generated code.
pub(super) type Form = fn(&str) -> String;

/// The Rust form of a name in the generated code: a field, method or module.
pub(super) fn snake(name: &str) -> String {
    crate::ident::snake(name)
}

/// The Rust form of a name in the generated code: a type or variant.
pub(super) fn camel(name: &str) -> String {
    crate::ident::camel(name)
}

/// Reports two names of one scope that differ as written but become one Rust
/// identifier in the generated code (`_a` and `a`, `fooBar` and `foo_bar`, `A_B` and
/// `AB`): `forms` are the Rust forms the names take there. Names equal as written
/// are [`duplicates`]' to report.
pub(super) fn rust_clashes<'n>(
    checker: &mut Checker<'_, '_>,
    names: impl IntoIterator<Item = &'n ast::Ident>,
    what: &str,
    forms: &[Form],
) {
    let file = checker.file;
    clashes(
        checker,
        names.into_iter().map(|name| (file, name)),
        what,
        forms,
    );
}

/// [`rust_clashes`] over names that may come from several files.
pub(super) fn clashes<'n>(
    checker: &mut Checker<'_, '_>,
    names: impl IntoIterator<Item = (ast::FileId, &'n ast::Ident)>,
    what: &str,
    forms: &[Form],
) {
    let mut seen: BTreeMap<(usize, String), (ast::FileId, &ast::Ident)> = BTreeMap::new();
    for (file, name) in names {
        for (index, form) in forms.iter().enumerate() {
            let rust = form(&name.name);
            match seen.get(&(index, rust.clone())) {
                Some((first_file, first)) if first.name != name.name => {
                    let diagnostic = Diagnostic::error(
                        Code::NameClash,
                        file,
                        name.span,
                        format!(
                            "{what} `{}` and {what} `{}` are both `{rust}` in the generated code",
                            first.name, name.name
                        ),
                    )
                    .with_label(format!("`{rust}` in Rust"))
                    .with_other(*first_file, first.span, format!("also `{rust}` in Rust"))
                    .with_help("rename one of them: names that differ only in case, `_` or a Rust keyword's escape are one name in Rust");
                    checker.push(diagnostic);
                    break;
                }
                Some(_) => {}
                None => {
                    seen.insert((index, rust), (file, name));
                }
            }
        }
    }
}

fn is_upper_camel(name: &str) -> bool {
    name.chars().next().is_some_and(|c| c.is_ascii_uppercase()) && !name.contains('_')
}

fn is_snake(name: &str) -> bool {
    let trimmed = name.trim_start_matches('_');
    !trimmed.is_empty()
        && trimmed
            .chars()
            .next()
            .is_some_and(|c| c.is_ascii_lowercase())
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
}

fn to_upper_camel(name: &str) -> String {
    name.split('_')
        .filter(|part| !part.is_empty())
        .map(|part| {
            let mut chars = part.chars();
            chars
                .next()
                .map(|c| c.to_ascii_uppercase().to_string() + chars.as_str())
                .unwrap_or_default()
        })
        .collect()
}

fn to_snake(name: &str) -> String {
    let mut out = String::new();
    for (index, c) in name.chars().enumerate() {
        if c.is_ascii_uppercase() {
            if index > 0 && !out.ends_with('_') {
                out.push('_');
            }
            out.push(c.to_ascii_lowercase());
        } else {
            out.push(c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn casing_predicates_and_fixes() {
        assert!(is_upper_camel("MotionController"));
        assert!(!is_upper_camel("motion_controller"));
        assert!(is_snake("max_speed2"));
        assert!(!is_snake("maxSpeed"));
        assert_eq!(to_snake("maxSpeed"), "max_speed");
        assert_eq!(to_upper_camel("range_scan"), "RangeScan");
    }
}
