//! Name mangling: every Rust identifier coolc emits is computed here.
//!
//! `.cool` names are converted to the Rust casing their role needs (`snake_case` for
//! modules, fields and methods; `UpperCamelCase` for types and variants). A result
//! that is a Rust keyword is escaped as a raw identifier (`r#type`); the few keywords
//! that cannot be raw (`self`, `Self`, `super`, `crate`, `_`) get a trailing `_`
//! instead. Names coolc invents for itself start with `__cool_` (or its
//! camel form `__Cool`), which user names cannot produce after conversion because
//! conversion never yields a leading `__`.

/// Keywords of Rust 2024 (strict and reserved) that need escaping as identifiers.
const KEYWORDS: &[&str] = &[
    "as", "async", "await", "break", "const", "continue", "crate", "dyn", "else", "enum", "extern",
    "false", "fn", "for", "gen", "if", "impl", "in", "let", "loop", "match", "mod", "move", "mut",
    "pub", "ref", "return", "self", "Self", "static", "struct", "super", "trait", "true", "type",
    "unsafe", "use", "where", "while", "abstract", "become", "box", "do", "final", "macro",
    "override", "priv", "try", "typeof", "unsized", "virtual", "yield",
];

/// Keywords that cannot be written as raw identifiers.
const NOT_RAW: &[&str] = &["self", "Self", "super", "crate", "_"];

/// Whether `name` is a Rust 2024 keyword (strict or reserved).
pub fn is_keyword(name: &str) -> bool {
    KEYWORDS.contains(&name)
}

/// Escapes `name` if it is a Rust keyword; returns it unchanged otherwise.
pub fn escape(name: &str) -> String {
    if NOT_RAW.contains(&name) {
        format!("{name}_")
    } else if KEYWORDS.contains(&name) {
        format!("r#{name}")
    } else {
        name.to_owned()
    }
}

/// Splits a name into lowercase words at `_` and at case boundaries.
fn words(name: &str) -> Vec<String> {
    let mut words = Vec::new();
    let mut current = String::new();
    let chars: Vec<char> = name.chars().collect();
    for (index, &c) in chars.iter().enumerate() {
        if c == '_' {
            if !current.is_empty() {
                words.push(std::mem::take(&mut current));
            }
            continue;
        }
        if c.is_uppercase() && !current.is_empty() {
            let previous = chars[index - 1];
            let next_is_lower = chars.get(index + 1).is_some_and(|n| n.is_lowercase());
            // "fooBar" -> foo|bar, "HTTPServer" -> http|server, "V2X" stays together.
            if previous.is_lowercase() || (previous.is_uppercase() && next_is_lower) {
                words.push(std::mem::take(&mut current));
            }
        }
        current.extend(c.to_lowercase());
    }
    if !current.is_empty() {
        words.push(current);
    }
    words
}

/// `snake_case` form of a name, unescaped. A name that is already snake case is
/// returned as is (digits and single underscores kept).
pub fn snake_raw(name: &str) -> String {
    if name
        .chars()
        .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
    {
        return name.trim_start_matches('_').to_owned().or_if_empty("x");
    }
    words(name).join("_").or_if_empty("x")
}

/// `UpperCamelCase` form of a name, unescaped.
pub fn camel_raw(name: &str) -> String {
    if name.starts_with(|c: char| c.is_ascii_uppercase()) && !name.contains('_') {
        return name.to_owned();
    }
    let mut out = String::new();
    for word in words(name) {
        let mut chars = word.chars();
        if let Some(first) = chars.next() {
            out.extend(first.to_uppercase());
            out.push_str(chars.as_str());
        }
    }
    if out.starts_with(|c: char| c.is_ascii_digit()) {
        out.insert(0, 'N');
    }
    out.or_if_empty("X")
}

/// `snake_case` Rust identifier (module, field, method), keyword-escaped.
pub fn snake(name: &str) -> String {
    escape(&snake_raw(name))
}

/// `UpperCamelCase` Rust identifier (type, variant), keyword-escaped.
pub fn camel(name: &str) -> String {
    escape(&camel_raw(name))
}

/// A method name made of a member name and a suffix or prefix (`moving_entry`,
/// `on_link_lost`); never a keyword, so never escaped.
pub fn method(prefix: &str, name: &str, suffix: &str) -> String {
    let mut out = String::new();
    out.push_str(prefix);
    out.push_str(&snake_raw(name));
    out.push_str(suffix);
    escape(&out)
}

/// A Rust string literal for `text` (quotes included, escapes applied).
pub fn string_literal(text: &str) -> String {
    format!("{text:?}")
}

trait OrIfEmpty {
    fn or_if_empty(self, fallback: &str) -> String;
}

impl OrIfEmpty for String {
    fn or_if_empty(self, fallback: &str) -> String {
        if self.is_empty() {
            fallback.to_owned()
        } else {
            self
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snake_case_conversions() {
        assert_eq!(snake("MotionController"), "motion_controller");
        assert_eq!(snake("RangeServer"), "range_server");
        assert_eq!(snake("HTTPServer"), "http_server");
        assert_eq!(snake("link_lost"), "link_lost");
        assert_eq!(snake("map2d"), "map2d");
        assert_eq!(snake("Pose2D"), "pose2d");
    }

    #[test]
    fn camel_case_conversions() {
        assert_eq!(camel("moving"), "Moving");
        assert_eq!(camel("link_lost"), "LinkLost");
        assert_eq!(camel("Pose2D"), "Pose2D");
        assert_eq!(camel("self"), "Self_");
    }

    #[test]
    fn keywords_are_escaped() {
        assert_eq!(snake("type"), "r#type");
        assert_eq!(snake("loop"), "r#loop");
        assert_eq!(snake("self"), "self_");
        assert_eq!(camel("Self"), "Self_");
        assert_eq!(method("", "loop", "_entry"), "loop_entry");
    }
}
