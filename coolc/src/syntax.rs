//! Parsing: `.cool` text to [`ast::File`] with byte spans.
//!
//! **Invariant:** parsing never fails. `parse` returns the items it could build plus
//! every syntax error. The text is parsed one item at a time (`item_step`); when an
//! item does not parse, a component is retried member by member (`component_head`,
//! then `member_step`), an automaton state by state (`automaton_head`,
//! `automaton_step`) and a state section by section (`state_head`, `state_step`).
//! Whatever still fails is reported and skipped up to the next plausible start (an
//! item or member keyword at the start of a line, or past the next `;` or block), so
//! one typo does not hide the rest of the file.
//!
//! The submodules: `recovery` (the item-, member- and state-wise retries and where to
//! resume), `errors` (pest errors shaped into diagnostics) and `tree` (pairs to AST
//! nodes).

use pest::Parser as _;

use crate::ast::{self, FileId, Span};
use crate::diagnostics::{Code, Diagnostic};

mod errors;
mod recovery;
mod tree;

pub use grammar::{CoolParser, Rule};
use recovery::FileParser;

/// The parser derived from `grammar/cool.pest`; `Rule` has one variant per rule.
#[allow(missing_docs)]
mod grammar {
    /// The parser derived from `grammar/cool.pest`.
    #[derive(pest_derive::Parser)]
    #[grammar = "../../grammar/cool.pest"]
    pub struct CoolParser;
}

/// Keywords that start an item, for recovery.
const ITEM_KEYWORDS: &[&str] = &[
    "import",
    "packet",
    "enum",
    "extern",
    "converter",
    "atomic",
    "compound",
];

/// Keywords that start a component member, for recovery.
const MEMBER_KEYWORDS: &[&str] = &[
    "link",
    "configuration",
    "observable",
    "controllable",
    "local",
    "input",
    "output",
    "timing",
    "exception",
    "automaton",
    "supervisor",
    "instance",
    "redundant",
    "thread",
    "connect",
    "on",
    "recovery",
    "restart",
    "adaptation",
];

/// Keywords that start a state member, for recovery.
const STATE_MEMBER_KEYWORDS: &[&str] = &["entry", "exit", "periodic", "on", "after", "may", "when"];

/// Parses one file. Never fails: returns what it could build and every syntax error.
pub(crate) fn parse(file: FileId, text: &str) -> (ast::File, Vec<Diagnostic>) {
    let deepest = match nesting(file, text) {
        Ok(deepest) => deepest,
        Err(diagnostic) => {
            return (
                ast::File {
                    id: file,
                    items: Vec::new(),
                },
                vec![*diagnostic],
            );
        }
    };
    if deepest <= SHALLOW {
        return parse_items(file, text);
    }
    // The generated parser recurses once per nesting level with large frames (in
    // debug builds especially); a dedicated thread with a roomy stack keeps
    // `MAX_DEPTH` levels far from the caller's stack limit.
    std::thread::scope(|scope| {
        let worker = std::thread::Builder::new()
            .name("coolc-parse".to_owned())
            .stack_size(PARSER_STACK)
            .spawn_scoped(scope, || parse_items(file, text));
        match worker {
            Ok(handle) => handle
                .join()
                .unwrap_or_else(|panic| std::panic::resume_unwind(panic)),
            Err(_) => parse_items(file, text),
        }
    })
}

/// Stack size of the parsing thread.
const PARSER_STACK: usize = 64 << 20;

/// Up to this nesting level a file is parsed on the caller's thread (a few hundred
/// KiB of stack even in debug builds); deeper files get the parsing thread.
const SHALLOW: usize = 12;

/// Parses the items of a file. A `///` doc comment with nothing to document after
/// it is reported once; the file is then parsed again with that comment blanked out
/// (same length, so spans hold), so that it costs nothing else: no member lost, no
/// error caused by the loss.
fn parse_items(file: FileId, text: &str) -> (ast::File, Vec<Diagnostic>) {
    let mut text = std::borrow::Cow::Borrowed(text);
    let mut doc_errors: Vec<Diagnostic> = Vec::new();
    loop {
        let mut parser = FileParser {
            file,
            text: &text,
            diagnostics: Vec::new(),
            notes: Vec::new(),
            dangling: Vec::new(),
        };
        let items = parser.items();
        if parser.dangling.is_empty() {
            let mut diagnostics = parser.diagnostics;
            if !doc_errors.is_empty() {
                diagnostics.extend(doc_errors);
                diagnostics.sort_by_key(|d| d.primary_span().start);
            }
            return (ast::File { id: file, items }, diagnostics);
        }
        let mut blanked = text.clone().into_owned().into_bytes();
        for (index, span) in parser.dangling.iter().rev() {
            blanked[span.start..span.end].fill(b' ');
            doc_errors.push(parser.diagnostics.swap_remove(*index));
        }
        // Only whole lines of UTF-8 text were replaced by spaces.
        text = std::borrow::Cow::Owned(String::from_utf8(blanked).unwrap_or_default());
    }
}

/// Parses with `rule`; on failure, parses again with pest's error detail (expected
/// tokens) switched on, which slows parsing, so it stays off until the first error.
/// The switch is process-wide and only ever turned on, so every error is reported
/// from a detailed parse, whatever other threads do.
fn parse_detailed(
    rule: Rule,
    input: &str,
) -> Result<pest::iterators::Pairs<'_, Rule>, Box<pest::error::Error<Rule>>> {
    CoolParser::parse(rule, input).or_else(|_| {
        pest::set_error_detail(true);
        CoolParser::parse(rule, input).map_err(Box::new)
    })
}

/// How deep brackets, block comments and runs of prefix operators may nest. Real
/// descriptions stay far below; the limit keeps the recursive parser and the checks
/// within the stack on any input.
pub const MAX_DEPTH: usize = 64;

/// The deepest nesting level of brackets, block comments and prefix operator runs, or
/// a diagnostic for nesting beyond [`MAX_DEPTH`] (the file is then not parsed).
fn nesting(file: FileId, text: &str) -> Result<usize, Box<Diagnostic>> {
    let mut max_level = 0;
    let bytes = text.as_bytes();
    let mut depth = 0usize;
    let mut comment_depth = 0usize;
    let mut prefix_run = 0usize;
    let mut index = 0;
    while index < bytes.len() {
        let byte = bytes[index];
        let next = bytes.get(index + 1).copied();
        let mut deepest = None;
        if comment_depth > 0 {
            if byte == b'/' && next == Some(b'*') {
                comment_depth += 1;
                deepest = Some((comment_depth, "block comments"));
                index += 1;
            } else if byte == b'*' && next == Some(b'/') {
                comment_depth -= 1;
                index += 1;
            }
        } else {
            match byte {
                b'/' if next == Some(b'/') => {
                    while index < bytes.len() && bytes[index] != b'\n' {
                        index += 1;
                    }
                    continue;
                }
                b'/' if next == Some(b'*') => {
                    comment_depth = 1;
                    index += 1;
                }
                b'"' => {
                    index += 1;
                    while index < bytes.len() && bytes[index] != b'"' && bytes[index] != b'\n' {
                        index += if bytes[index] == b'\\' { 2 } else { 1 };
                    }
                }
                b'(' | b'[' | b'{' => {
                    depth += 1;
                    deepest = Some((depth, "brackets"));
                }
                b')' | b']' | b'}' => depth = depth.saturating_sub(1),
                _ => {}
            }
            if matches!(byte, b'!' | b'-') && next != Some(b'>') && next != Some(b'=') {
                prefix_run += 1;
                deepest = deepest.or(Some((prefix_run, "prefix operators")));
            } else if !byte.is_ascii_whitespace() {
                prefix_run = 0;
            }
        }
        if let Some((level, _)) = deepest {
            max_level = max_level.max(level);
        }
        if let Some((level, what)) = deepest
            && level > MAX_DEPTH
        {
            let start = index.min(text.len());
            let end = text[start..]
                .chars()
                .next()
                .map_or(start, |c| start + c.len_utf8());
            return Err(Box::new(
                Diagnostic::error(
                    Code::TooDeep,
                    file,
                    Span::new(start, end),
                    format!("{what} nest deeper than {MAX_DEPTH} levels"),
                )
                .with_label("too deep")
                .with_help("simplify this part of the file; nothing after it was parsed"),
            ));
        }
        index += 1;
    }
    Ok(max_level)
}

/// Parses `input` with `rule` in full (for grammar tests): true when the whole input
/// matches.
pub fn matches_rule(rule: Rule, input: &str) -> bool {
    match CoolParser::parse(rule, input) {
        Ok(mut pairs) => pairs
            .next()
            .is_some_and(|pair| pair.as_span().end() == input.len()),
        Err(_) => false,
    }
}

#[cfg(test)]
mod tests {
    use super::errors::rule_name;
    use super::tree::is_keyword;
    use super::*;

    fn parse_ok(text: &str) -> ast::File {
        let (file, diagnostics) = parse(FileId(0), text);
        assert!(diagnostics.is_empty(), "{diagnostics:#?}");
        file
    }

    #[test]
    fn builds_items_with_docs_and_spans() {
        let text = "/// A pose.\npacket Pose { x: f64, y: f64 = 1.5 }\nenum Mode { A, B }";
        let file = parse_ok(text);
        assert_eq!(file.items.len(), 2);
        let ast::Item::Packet(packet) = &file.items[0] else {
            panic!("not a packet")
        };
        assert_eq!(packet.doc.0, vec!["A pose.".to_owned()]);
        assert_eq!(&text[packet.name.span.start..packet.name.span.end], "Pose");
        assert_eq!(
            packet.fields[1].default.as_ref().map(|d| &d.kind),
            Some(&ast::ExprKind::Float(1.5))
        );
    }

    #[test]
    fn durations_and_frequencies_are_normalised() {
        let file =
            parse_ok("atomic A { timing { period 1min..2s; max_response 250us; priority 10Hz; } }");
        let ast::Item::Component(component) = &file.items[0] else {
            panic!("not a component")
        };
        let ast::Member::Timing(timing) = &component.members[0] else {
            panic!("not timing")
        };
        let ast::TimingEntry::Period(interval) = &timing.entries[0] else {
            panic!("not period")
        };
        assert_eq!(interval.lo.kind, ast::ExprKind::Duration(60_000_000_000));
        assert_eq!(
            interval.hi.as_ref().map(|e| &e.kind),
            Some(&ast::ExprKind::Duration(2_000_000_000))
        );
        assert_eq!(
            timing.entries[2],
            ast::TimingEntry::Priority(ast::Expr {
                kind: ast::ExprKind::Frequency(10.0),
                span: Span::new(66, 70)
            })
        );
    }

    #[test]
    fn precedence_or_below_and_below_comparison() {
        let file =
            parse_ok("compound C { supervisor { state s { when !a == b && c || d -> s; } } }");
        let ast::Item::Component(component) = &file.items[0] else {
            panic!("not a component")
        };
        let ast::Member::Automaton(automaton) = &component.members[0] else {
            panic!("not automaton")
        };
        let ast::StateMember::When { condition, .. } = &automaton.states[0].members[0] else {
            panic!("not when")
        };
        let ast::ExprKind::Binary(ast::BinaryOp::Or, left, _) = &condition.kind else {
            panic!("{condition:?}")
        };
        let ast::ExprKind::Binary(ast::BinaryOp::And, left, _) = &left.kind else {
            panic!("{left:?}")
        };
        assert!(matches!(
            left.kind,
            ast::ExprKind::Binary(ast::BinaryOp::Eq, _, _)
        ));
    }

    #[test]
    fn recovers_at_items_and_members() {
        let text = "packet A { x: }\npacket B { y: f64 }\natomic C {\n input a: tick\n input b: tick;\n output c: data<B>;\n}\nenum E { X }";
        let (file, diagnostics) = parse(FileId(0), text);
        assert_eq!(diagnostics.len(), 2, "{diagnostics:#?}");
        assert_eq!(file.items.len(), 3, "{:#?}", file.items);
        let ast::Item::Component(component) = &file.items[1] else {
            panic!("not a component")
        };
        assert_eq!(component.members.len(), 2);
    }

    #[test]
    fn keyword_rules_are_exactly_the_kw_rules() {
        for rule in Rule::all_rules() {
            assert_eq!(
                is_keyword(*rule),
                format!("{rule:?}").starts_with("kw_"),
                "{rule:?}"
            );
            if is_keyword(*rule) {
                assert!(rule_name(*rule).is_some(), "{rule:?} has no readable name");
            }
        }
    }

    #[test]
    fn unknown_escape_is_reported() {
        let (_, diagnostics) = parse(FileId(0), r#"import "a\qb";"#);
        assert_eq!(diagnostics.len(), 1);
        assert_eq!(diagnostics[0].code, Code::InvalidEscape);
    }
}
