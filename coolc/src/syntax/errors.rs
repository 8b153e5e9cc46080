//! Error shaping: a pest error turned into one readable diagnostic (what was
//! expected, summarized and named as the reference names it; what was found; a
//! dangling `///` doc comment told apart).

use pest::error::{ErrorVariant, InputLocation};

use super::{ITEM_KEYWORDS, MEMBER_KEYWORDS, Rule};
use crate::ast::{FileId, Span};
use crate::diagnostics::{Code, Diagnostic};

/// Turns a pest error into a readable diagnostic; `true` when it is about a `///`
/// doc comment with nothing to document (the diagnostic's span is that comment).
pub(super) fn syntax_error(
    file: FileId,
    text: &str,
    error: &pest::error::Error<Rule>,
    base: usize,
) -> (Diagnostic, bool) {
    let mut position = match error.location {
        InputLocation::Pos(pos) => pos,
        InputLocation::Span((start, _)) => start,
    };
    let mut expected: Vec<String> = Vec::new();
    let attempts = error.parse_attempts();
    let further = attempts
        .as_ref()
        .filter(|attempts| attempts.max_position > position);
    if let Some(attempts) = further {
        // A literal token was expected further on than any rule: point there.
        position = attempts.max_position;
        let tokens: Vec<String> = attempts
            .expected_tokens()
            .iter()
            .map(ToString::to_string)
            .collect();
        let punctuation: Vec<&String> = tokens.iter().filter(|t| is_punctuation_token(t)).collect();
        if punctuation.is_empty() {
            let words = tokens
                .iter()
                .filter(|t| !t.is_empty() && t.chars().all(|c| c.is_alphanumeric() || c == '_'));
            expected.extend(words.map(|t| format!("`{t}`")));
        } else {
            expected.extend(punctuation.into_iter().map(|t| format!("`{t}`")));
        }
    } else {
        if let ErrorVariant::ParsingError { positives, .. } = &error.variant {
            for rule in positives {
                if let Some(name) = rule_name(*rule) {
                    expected.push(name.to_owned());
                }
            }
        }
        if let Some(attempts) = attempts.filter(|attempts| attempts.max_position == position) {
            for token in attempts.expected_tokens() {
                let token = token.to_string();
                if is_punctuation_token(&token) {
                    expected.push(format!("`{token}`"));
                }
            }
        }
    }
    expected.sort();
    expected.dedup();
    let expected = summarize(expected);
    let at = (base + position).min(text.len());
    if let Some(doc) = dangling_doc(text, at) {
        let diagnostic = Diagnostic::error(
            Code::UnexpectedToken,
            file,
            doc,
            "a `///` doc comment must come right before the item, member, field, variant, state, section, transition or entry it documents",
        )
        .with_label("documents nothing here")
        .with_help("write `//` for a plain comment");
        return (diagnostic, true);
    }
    let (found, len) = describe_found(&text[at..]);
    let message = if expected.is_empty() {
        format!("unexpected {found}")
    } else {
        format!("expected {}, found {found}", join_or(&expected))
    };
    let diagnostic = Diagnostic::error(
        Code::UnexpectedToken,
        file,
        Span::new(at, at + len),
        message,
    )
    .with_label("unexpected here");
    (diagnostic, false)
}

/// The span of the `///` doc comment that a syntax error at `at` is about: the doc
/// line at `at`, or the one right before it (only blank space between) when a
/// closing brace or the end of the file follows it.
pub(super) fn dangling_doc(text: &str, at: usize) -> Option<Span> {
    // The error may point into the `///` (after the `//` a plain comment would take).
    for start in (at.saturating_sub(3)..=at).rev() {
        if !text.is_char_boundary(start) {
            continue;
        }
        let rest = text.get(start..).unwrap_or_default();
        let line_start = text[..start].rfind('\n').map_or(0, |n| n + 1);
        let line_end = rest.find('\n').map_or(text.len(), |n| start + n);
        let in_comment = text[line_start..start].contains("//");
        if rest.starts_with("///") && !rest.starts_with("////") && !in_comment {
            return Some(Span::new(start, line_end));
        }
    }
    let rest = &text[at..];
    if !(rest.is_empty() || rest.starts_with('}')) {
        return None;
    }
    let before = text[..at].trim_end();
    let line_start = before.rfind('\n').map_or(0, |n| n + 1);
    let line = &before[line_start..];
    let indent = line.len() - line.trim_start().len();
    let doc = line.trim_start();
    (doc.starts_with("///") && !doc.starts_with("////"))
        .then(|| Span::new(line_start + indent, before.len()))
}

/// True for a punctuation token worth naming (not a comment opener).
pub(super) fn is_punctuation_token(token: &str) -> bool {
    !token.is_empty()
        && token.chars().all(|c| c.is_ascii_punctuation() && c != '_')
        && !matches!(token, "//" | "///" | "/*" | "*/")
}

/// Collapses long keyword lists into what they mean.
pub(super) fn summarize(mut expected: Vec<String>) -> Vec<String> {
    if expected.iter().any(|e| e == "a type") {
        expected.retain(|e| e != "`[`");
    }
    let starts_expression = |e: &String| ["`(`", "`[`", "`!`", "`-`", "`\"`"].contains(&e.as_str());
    if expected.iter().any(|e| e == "`(`") && expected.iter().any(|e| e == "`!`" || e == "`-`") {
        expected.retain(|e| !starts_expression(e));
        expected.insert(0, "an expression".to_owned());
    }
    let has = |name: &str| expected.iter().any(|e| e == name);
    if has("`input`") && has("`connect`") && has("`timing`") {
        let mut rest: Vec<String> = expected
            .into_iter()
            .filter(|e| !is_member_start(e))
            .collect();
        rest.insert(0, "a component member".to_owned());
        return rest;
    }
    if has("`import`") && has("`packet`") && has("`atomic`/`compound`") {
        let mut rest: Vec<String> = expected.into_iter().filter(|e| !is_item_start(e)).collect();
        rest.insert(0, "an item (`import`, `packet`, `enum`, `extern packet`, `converter`, `atomic`, `compound`)".to_owned());
        return rest;
    }
    if has("`entry`") && has("`on`") && has("`may`") {
        let mut rest: Vec<String> = expected
            .into_iter()
            .filter(|e| {
                ![
                    "`entry`",
                    "`exit`",
                    "`periodic`",
                    "`on`",
                    "`after`",
                    "`may`",
                    "`when`",
                ]
                .contains(&e.as_str())
            })
            .collect();
        rest.insert(
            0,
            "a section or transition (`entry`, `exit`, `periodic`, `on`, `after`, `may`, `when`)"
                .to_owned(),
        );
        return rest;
    }
    if has("an integer") && has("a string") && has("a name") {
        let mut rest: Vec<String> = expected.into_iter().filter(|e| !is_expr_start(e)).collect();
        rest.insert(0, "an expression".to_owned());
        return rest;
    }
    expected
}

pub(super) fn is_member_start(name: &str) -> bool {
    name == "a `///` doc comment"
        || name == "`observable`/`controllable`/`local`"
        || name == "`automaton`/`supervisor`"
        || MEMBER_KEYWORDS.iter().any(|kw| name == format!("`{kw}`"))
}

pub(super) fn is_item_start(name: &str) -> bool {
    name == "a `///` doc comment"
        || name == "`atomic`/`compound`"
        || ITEM_KEYWORDS.iter().any(|kw| name == format!("`{kw}`"))
}

pub(super) fn is_expr_start(name: &str) -> bool {
    [
        "an integer",
        "a string",
        "a name",
        "a float",
        "a duration",
        "a frequency",
        "`true`/`false`",
        "`none`",
        "`!` or `-`",
        "`(`",
        "`[`",
        "a list",
        "`Enum::Variant`",
    ]
    .contains(&name)
}

pub(super) fn join_or(items: &[String]) -> String {
    match items {
        [] => String::new(),
        [one] => one.clone(),
        [init @ .., last] => format!("{} or {last}", init.join(", ")),
    }
}

/// Describes the text at an error position: `` `word` ``, `` `;` `` or end of file.
pub(super) fn describe_found(rest: &str) -> (String, usize) {
    let Some(first) = rest.chars().next() else {
        return ("end of file".to_owned(), 0);
    };
    if first.is_alphanumeric() || first == '_' {
        let len = rest
            .find(|c: char| !(c.is_alphanumeric() || c == '_'))
            .unwrap_or(rest.len());
        return (format!("`{}`", &rest[..len]), len);
    }
    if first == '"' {
        return ("a string".to_owned(), first.len_utf8());
    }
    (format!("`{}`", first.escape_debug()), first.len_utf8())
}

/// A readable name for a rule in "expected ..." messages; `None` for rules that never
/// help a reader.
pub(super) fn rule_name(rule: Rule) -> Option<&'static str> {
    use Rule::*;
    Some(match rule {
        doc_line => "a `///` doc comment",
        ident | path | port_ref => "a name",
        string => "a string",
        integer => "an integer",
        float => "a float",
        duration => "a duration",
        frequency => "a frequency",
        bool_lit => "`true`/`false`",
        none_lit => "`none`",
        ty | prim | list_ty => "a type",
        optional_mark => "`?`",
        component_kind => "`atomic`/`compound`",
        var_kind => "`observable`/`controllable`/`local`",
        automaton_kw => "`automaton`/`supervisor`",
        unary_op => "`!` or `-`",
        cmp_op => "a comparison",
        or_op => "`||`",
        and_op => "`&&`",
        repeat_lit | list_lit => "a list",
        enum_value => "`Enum::Variant`",
        component_end | automaton_end | state_end => "`}`",
        duration_unit => "a duration unit",
        frequency_unit => "a frequency unit",
        kw_import => "`import`",
        kw_packet => "`packet`",
        kw_enum => "`enum`",
        kw_extern => "`extern`",
        kw_converter => "`converter`",
        kw_link => "`link`",
        kw_crate => "`crate`",
        kw_system => "`system`",
        kw_configuration => "`configuration`",
        kw_input => "`input`",
        kw_output => "`output`",
        kw_pull => "`pull`",
        kw_tick => "`tick`",
        kw_fifo => "`fifo`",
        kw_ufifo => "`ufifo`",
        kw_last => "`last`",
        kw_poster => "`poster`",
        kw_data => "`data`",
        kw_max => "`max`",
        kw_timing => "`timing`",
        kw_period => "`period`",
        kw_max_response => "`max_response`",
        kw_priority => "`priority`",
        kw_quality => "`quality`",
        kw_exception => "`exception`",
        kw_retry => "`retry`",
        kw_every => "`every`",
        kw_goto => "`goto`",
        kw_ignore => "`ignore`",
        kw_degrade => "`degrade`",
        kw_initial => "`initial`",
        kw_state => "`state`",
        kw_entry => "`entry`",
        kw_exit => "`exit`",
        kw_periodic => "`periodic`",
        kw_on => "`on`",
        kw_after => "`after`",
        kw_without => "`without`",
        kw_may => "`may`",
        kw_when => "`when`",
        kw_instance => "`instance`",
        kw_substitutes => "`substitutes`",
        kw_redundant => "`redundant`",
        kw_thread => "`thread`",
        kw_connect => "`connect`",
        kw_via => "`via`",
        kw_error => "`error`",
        kw_recovery => "`recovery`",
        kw_deadline => "`deadline`",
        kw_restart => "`restart`",
        kw_limit => "`limit`",
        kw_in => "`in`",
        range_op => "`..=`",
        var_range => "`in low..=high`",
        kw_backoff => "`backoff`",
        kw_adaptation => "`adaptation`",
        kw_ros => "`ros`",
        kw_as => "`as`",
        _ => return None,
    })
}
