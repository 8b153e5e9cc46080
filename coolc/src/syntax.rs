//! Parsing: `.cool` text to [`ast::File`] with byte spans.
//!
//! **Invariant:** parsing never fails. [`parse`] returns the items it could build plus
//! every syntax error. The text is parsed one item at a time (`item_step`); when an
//! item does not parse, a component is retried member by member (`component_head`,
//! then `member_step`), an automaton state by state (`automaton_head`,
//! `automaton_step`) and a state section by section (`state_head`, `state_step`).
//! Whatever still fails is reported and skipped up to the next plausible start (an
//! item or member keyword at the start of a line, or past the next `;` or block), so
//! one typo does not hide the rest of the file.

use pest::Parser as _;
use pest::error::{ErrorVariant, InputLocation};
use pest::iterators::Pair;

use crate::ast::{self, FileId, Span};
use crate::diagnostics::{Code, Diagnostic};

pub use grammar::{CoolParser, Rule};

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
    "connect",
    "on",
    "recovery",
    "restart",
];

/// Keywords that start a state member, for recovery.
const STATE_MEMBER_KEYWORDS: &[&str] = &["entry", "exit", "periodic", "on", "after", "may", "when"];

/// Parses one file. Never fails: returns what it could build and every syntax error.
pub fn parse(file: FileId, text: &str) -> (ast::File, Vec<Diagnostic>) {
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

struct FileParser<'t> {
    file: FileId,
    text: &'t str,
    diagnostics: Vec<Diagnostic>,
    /// Notes of the component being parsed member by member.
    notes: Vec<ast::Note>,
    /// The diagnostics (by index) about `///` doc comments with nothing to document,
    /// and the spans of those comments.
    dangling: Vec<(usize, Span)>,
}

impl<'t> FileParser<'t> {
    fn items(&mut self) -> Vec<ast::Item> {
        let mut items = Vec::new();
        let mut offset = 0;
        while offset <= self.text.len() {
            let rest = &self.text[offset..];
            match parse_detailed(Rule::item_step, rest) {
                Ok(mut pairs) => {
                    let Some(pair) = pairs.next() else { break };
                    if pair.as_rule() == Rule::EOI {
                        break;
                    }
                    let end = offset + pair.as_span().end();
                    let mut builder = Builder {
                        base: offset,
                        file: self.file,
                        diagnostics: &mut self.diagnostics,
                        notes: &mut self.notes,
                    };
                    if let Some(item) = builder.item(pair) {
                        items.push(item);
                    }
                    offset = if end > offset {
                        end
                    } else {
                        next_char(self.text, offset)
                    };
                }
                Err(error) => {
                    if let Some((component, end)) = self.component_by_members(offset) {
                        items.push(ast::Item::Component(component));
                        offset = end;
                        continue;
                    }
                    let at = self.report(&error, offset);
                    let next = next_start(self.text, offset, at, ITEM_KEYWORDS, false);
                    offset = if next > offset {
                        next
                    } else {
                        next_char(self.text, offset)
                    };
                }
            }
        }
        items
    }

    /// Parses a component member by member, recovering at member boundaries. Returns
    /// `None` when not even the component's head parses.
    fn component_by_members(&mut self, start: usize) -> Option<(ast::Component, usize)> {
        let head = CoolParser::parse(Rule::component_head, &self.text[start..])
            .ok()?
            .next()?;
        let builder = Builder {
            base: start,
            file: self.file,
            diagnostics: &mut self.diagnostics,
            notes: &mut self.notes,
        };
        let mut doc = Vec::new();
        let mut kind = None;
        let mut name = None;
        for part in head.clone().into_inner() {
            match part.as_rule() {
                Rule::doc_line => doc.push(doc_text(part.as_str())),
                Rule::component_kind => {
                    kind = Some((component_kind(part.as_str()), builder.span(&part)))
                }
                Rule::ident => name = Some(builder.ident(&part)),
                _ => {}
            }
        }
        let (kind, kind_span) = kind?;
        let name = name?;
        let mut offset = start + head.as_span().end();
        let mut members = Vec::new();
        let end = loop {
            match parse_detailed(Rule::member_step, &self.text[offset..]) {
                Ok(mut pairs) => {
                    let pair = pairs.next()?;
                    let pair_end = offset + pair.as_span().end();
                    match pair.as_rule() {
                        Rule::member => {
                            let mut builder = Builder {
                                base: offset,
                                file: self.file,
                                diagnostics: &mut self.diagnostics,
                                notes: &mut self.notes,
                            };
                            if let Some(member) = builder.member(pair) {
                                members.push(member);
                            }
                            offset = if pair_end > offset {
                                pair_end
                            } else {
                                next_char(self.text, offset)
                            };
                        }
                        Rule::component_end => break pair_end,
                        _ => {
                            // End of input inside the component: the missing `}` was
                            // reported by the failed item parse; report it here.
                            let at = self.text.len();
                            self.diagnostics.push(
                                Diagnostic::error(
                                    Code::UnexpectedToken,
                                    self.file,
                                    Span::new(at, at),
                                    format!(
                                        "expected `}}` closing component `{}`, found end of file",
                                        name.name
                                    ),
                                )
                                .with_label("the file ends here")
                                .with_other(
                                    self.file,
                                    name.span,
                                    "component opened here",
                                ),
                            );
                            break at;
                        }
                    }
                }
                Err(error) => {
                    if let Some((automaton, end)) = self.automaton_by_states(offset) {
                        members.push(ast::Member::Automaton(automaton));
                        offset = end;
                        continue;
                    }
                    let at = self.report(&error, offset);
                    let next = next_start(self.text, offset, at, MEMBER_KEYWORDS, true);
                    if next >= self.text.len() {
                        break self.text.len();
                    }
                    offset = if next > offset {
                        next
                    } else {
                        next_char(self.text, offset)
                    };
                }
            }
        };
        let component = ast::Component {
            doc: ast::Doc(doc),
            kind,
            kind_span,
            name,
            members,
            notes: std::mem::take(&mut self.notes),
            span: Span::new(start + head.as_span().start(), end),
        };
        Some((component, end))
    }

    /// Parses an automaton state by state, recovering at `state` and `initial`.
    /// Returns `None` when not even its head parses.
    fn automaton_by_states(&mut self, start: usize) -> Option<(ast::Automaton, usize)> {
        let head = CoolParser::parse(Rule::automaton_head, &self.text[start..])
            .ok()?
            .next()?;
        let mut builder = Builder {
            base: start,
            file: self.file,
            diagnostics: &mut self.diagnostics,
            notes: &mut self.notes,
        };
        builder.note(&head);
        let keyword_pair = head
            .clone()
            .into_inner()
            .find(|p| p.as_rule() == Rule::automaton_kw)?;
        let keyword = if keyword_pair.as_str() == "supervisor" {
            ast::AutomatonKeyword::Supervisor
        } else {
            ast::AutomatonKeyword::Automaton
        };
        let keyword_span = builder.span(&keyword_pair);
        let mut automaton = ast::Automaton {
            keyword,
            keyword_span,
            initial: Vec::new(),
            states: Vec::new(),
            span: Span::default(),
        };
        let mut offset = start + head.as_span().end();
        let end = loop {
            match parse_detailed(Rule::automaton_step, &self.text[offset..]) {
                Ok(mut pairs) => {
                    let pair = pairs.next()?;
                    let pair_end = offset + pair.as_span().end();
                    let mut builder = Builder {
                        base: offset,
                        file: self.file,
                        diagnostics: &mut self.diagnostics,
                        notes: &mut self.notes,
                    };
                    match pair.as_rule() {
                        Rule::initial => {
                            builder.note(&pair);
                            if let Some(name) = children(pair).first() {
                                automaton.initial.push(builder.ident(name));
                            }
                        }
                        Rule::state => automaton.states.extend(builder.state(pair)),
                        Rule::automaton_end => break pair_end,
                        // The end of the input: the component reports the missing brace.
                        _ => break self.text.len(),
                    }
                    offset = if pair_end > offset {
                        pair_end
                    } else {
                        next_char(self.text, offset)
                    };
                }
                Err(error) => {
                    if let Some((state, end)) = self.state_by_members(offset) {
                        automaton.states.push(state);
                        offset = end;
                        continue;
                    }
                    let at = self.report(&error, offset);
                    let next = next_start(self.text, offset, at, &["state", "initial"], true);
                    if next >= self.text.len() {
                        break self.text.len();
                    }
                    offset = if next > offset {
                        next
                    } else {
                        next_char(self.text, offset)
                    };
                }
            }
        };
        automaton.span = Span::new(keyword_span.start, end);
        Some((automaton, end))
    }

    /// Parses a state member by member, recovering after the next `;`. Returns `None`
    /// when not even its head parses.
    fn state_by_members(&mut self, start: usize) -> Option<(ast::State, usize)> {
        let head = CoolParser::parse(Rule::state_head, &self.text[start..])
            .ok()?
            .next()?;
        let builder = Builder {
            base: start,
            file: self.file,
            diagnostics: &mut self.diagnostics,
            notes: &mut self.notes,
        };
        let doc = docs(&head);
        let name = builder.ident(children(head.clone()).first()?);
        let notes_before = self.notes.len();
        let head_start = start + head.as_span().start();
        let mut offset = start + head.as_span().end();
        let mut members = Vec::new();
        let mut member_docs = Vec::new();
        let end = loop {
            match parse_detailed(Rule::state_step, &self.text[offset..]) {
                Ok(mut pairs) => {
                    let pair = pairs.next()?;
                    let pair_end = offset + pair.as_span().end();
                    match pair.as_rule() {
                        Rule::state_end => break pair_end,
                        Rule::EOI => break self.text.len(),
                        _ => {
                            let mut builder = Builder {
                                base: offset,
                                file: self.file,
                                diagnostics: &mut self.diagnostics,
                                notes: &mut self.notes,
                            };
                            if let Some((member, doc)) = builder.state_member(pair) {
                                members.push(member);
                                member_docs.push(doc);
                            }
                        }
                    }
                    offset = if pair_end > offset {
                        pair_end
                    } else {
                        next_char(self.text, offset)
                    };
                }
                Err(error) => {
                    let at = self.report(&error, offset);
                    let next = next_start(self.text, offset, at, STATE_MEMBER_KEYWORDS, true);
                    if next >= self.text.len() {
                        break self.text.len();
                    }
                    offset = if next > offset {
                        next
                    } else {
                        next_char(self.text, offset)
                    };
                }
            }
        };
        in_context(
            &mut self.notes[notes_before..],
            &format!("state `{}`", name.name),
        );
        let state = ast::State {
            doc,
            name,
            members,
            member_docs,
            span: Span::new(head_start, end),
        };
        Some((state, end))
    }

    /// Records a pest error as a diagnostic; returns the absolute error offset.
    fn report(&mut self, error: &pest::error::Error<Rule>, base: usize) -> usize {
        let (diagnostic, dangling) = syntax_error(self.file, self.text, error, base);
        let at = diagnostic.primary_span().start;
        if dangling {
            self.dangling
                .push((self.diagnostics.len(), diagnostic.primary_span()));
        }
        self.diagnostics.push(diagnostic);
        at
    }
}

/// Turns a pest error into a readable diagnostic; `true` when it is about a `///`
/// doc comment with nothing to document (the diagnostic's span is that comment).
fn syntax_error(
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
fn dangling_doc(text: &str, at: usize) -> Option<Span> {
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
fn is_punctuation_token(token: &str) -> bool {
    !token.is_empty()
        && token.chars().all(|c| c.is_ascii_punctuation() && c != '_')
        && !matches!(token, "//" | "///" | "/*" | "*/")
}

/// Collapses long keyword lists into what they mean.
fn summarize(mut expected: Vec<String>) -> Vec<String> {
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

fn is_member_start(name: &str) -> bool {
    name == "a `///` doc comment"
        || name == "`observable`/`controllable`/`local`"
        || name == "`automaton`/`supervisor`"
        || MEMBER_KEYWORDS.iter().any(|kw| name == format!("`{kw}`"))
}

fn is_item_start(name: &str) -> bool {
    name == "a `///` doc comment"
        || name == "`atomic`/`compound`"
        || ITEM_KEYWORDS.iter().any(|kw| name == format!("`{kw}`"))
}

fn is_expr_start(name: &str) -> bool {
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

fn join_or(items: &[String]) -> String {
    match items {
        [] => String::new(),
        [one] => one.clone(),
        [init @ .., last] => format!("{} or {last}", init.join(", ")),
    }
}

/// Describes the text at an error position: `` `word` ``, `` `;` `` or end of file.
fn describe_found(rest: &str) -> (String, usize) {
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
fn rule_name(rule: Rule) -> Option<&'static str> {
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
        kw_connect => "`connect`",
        kw_via => "`via`",
        kw_error => "`error`",
        kw_recovery => "`recovery`",
        kw_deadline => "`deadline`",
        kw_restart => "`restart`",
        kw_limit => "`limit`",
        kw_in => "`in`",
        kw_backoff => "`backoff`",
        _ => return None,
    })
}

/// Where to resume after an error at `error_at` in text that started at `start`:
/// the next line whose first word is one of `keywords`, at brace depth 0 relative to
/// `start` (or, failing that, at column 0), after the error. In member mode, a `}`
/// at depth 0 (the component's end) and the end of a `;`- or `}`-terminated member
/// also stop the scan.
fn next_start(
    text: &str,
    start: usize,
    error_at: usize,
    keywords: &[&str],
    member_mode: bool,
) -> usize {
    let bytes = text.as_bytes();
    // Depth in any bracket, and in braces only: a `(` or `[` left open inside the bad
    // member must not hide the members and the closing brace after it.
    let mut depth: i64 = 0;
    let mut braces: i64 = 0;
    let mut index = start;
    let mut line_start = true;
    let mut fallback = None;
    let mut first_token: Option<usize> = None;
    while index < bytes.len() {
        let byte = bytes[index];
        match byte {
            b'\n' => {
                line_start = true;
                index += 1;
                continue;
            }
            b' ' | b'\t' | b'\r' => {
                index += 1;
                continue;
            }
            b'/' if bytes.get(index + 1) == Some(&b'/') && bytes.get(index + 2) != Some(&b'/') => {
                while index < bytes.len() && bytes[index] != b'\n' {
                    index += 1;
                }
                continue;
            }
            b'/' if bytes.get(index + 1) == Some(&b'*') => {
                index += 2;
                while index < bytes.len()
                    && !(bytes[index] == b'*' && bytes.get(index + 1) == Some(&b'/'))
                {
                    index += 1;
                }
                index = (index + 2).min(bytes.len());
                line_start = false;
                continue;
            }
            _ => {}
        }
        let at_line_start = std::mem::replace(&mut line_start, false);
        let is_first_token = first_token.is_none();
        first_token.get_or_insert(index);
        if index >= error_at && !is_first_token && at_line_start {
            let word_end = text[index..]
                .find(|c: char| !(c.is_alphanumeric() || c == '_'))
                .map_or(text.len(), |n| index + n);
            let word = &text[index..word_end];
            let is_doc = text[index..].starts_with("///");
            if keywords.contains(&word) || is_doc {
                if depth == 0 || (member_mode && braces == 0) {
                    return index;
                }
                if fallback.is_none() && (index == 0 || bytes[index - 1] == b'\n') && !member_mode {
                    fallback = Some(index);
                }
            }
        }
        match byte {
            b'"' => {
                index += 1;
                while index < bytes.len() && bytes[index] != b'"' && bytes[index] != b'\n' {
                    index += if bytes[index] == b'\\' { 2 } else { 1 };
                }
                index += 1;
                continue;
            }
            b'{' | b'[' | b'(' => {
                depth += 1;
                braces += i64::from(byte == b'{');
            }
            b'}' | b']' | b')' => {
                depth -= 1;
                if member_mode && byte == b'}' {
                    braces -= 1;
                    if braces < 0 {
                        // The component's closing brace: resume there.
                        return index;
                    }
                    if braces == 0 && index >= error_at {
                        return index + 1;
                    }
                }
            }
            b';' if member_mode && depth == 0 && index >= error_at => return index + 1,
            _ => {}
        }
        index += 1;
    }
    fallback.unwrap_or(text.len()).min(text.len())
}

/// The offset of the char after the one at `offset` (or one past the end).
fn next_char(text: &str, offset: usize) -> usize {
    text[offset.min(text.len())..]
        .chars()
        .next()
        .map_or(text.len() + 1, |c| offset + c.len_utf8())
}

/// The construct `pair` as a note's subject: its text after its doc comment, up to
/// its first `{` or `;`, on one line, in backticks.
fn subject(pair: &P<'_>) -> String {
    let start = pair
        .clone()
        .into_inner()
        .find(|p| p.as_rule() != Rule::doc_line)
        .map_or(0, |p| p.as_span().start() - pair.as_span().start());
    let text = &pair.as_str()[start..];
    let head = text.find(['{', ';']).map_or(text, |end| &text[..end]);
    let words: Vec<&str> = head.split_whitespace().collect();
    format!("`{}`", words.join(" "))
}

/// Prefixes the subjects of `notes` with `context` (the state or instance they are in).
fn in_context(notes: &mut [ast::Note], context: &str) {
    for note in notes {
        note.subject = format!("{context}: {}", note.subject);
    }
}

fn doc_text(line: &str) -> String {
    let body = line
        .strip_prefix("///")
        .unwrap_or(line)
        .trim_end_matches('\r');
    body.strip_prefix(' ').unwrap_or(body).to_owned()
}

fn component_kind(text: &str) -> ast::ComponentKind {
    if text == "compound" {
        ast::ComponentKind::Compound
    } else {
        ast::ComponentKind::Atomic
    }
}

/// Builds AST nodes from pairs of one parse that started at byte `base`.
struct Builder<'d> {
    base: usize,
    file: FileId,
    diagnostics: &'d mut Vec<Diagnostic>,
    /// Where doc comments on constructs without a Rust item of their own go, until
    /// the component that holds them takes them.
    notes: &'d mut Vec<ast::Note>,
}

type P<'i> = Pair<'i, Rule>;

/// True for the `kw_*` keyword rules.
fn is_keyword(rule: Rule) -> bool {
    matches!(
        rule,
        Rule::kw_import
            | Rule::kw_packet
            | Rule::kw_enum
            | Rule::kw_extern
            | Rule::kw_converter
            | Rule::kw_link
            | Rule::kw_crate
            | Rule::kw_system
            | Rule::kw_configuration
            | Rule::kw_input
            | Rule::kw_output
            | Rule::kw_pull
            | Rule::kw_tick
            | Rule::kw_fifo
            | Rule::kw_ufifo
            | Rule::kw_last
            | Rule::kw_poster
            | Rule::kw_data
            | Rule::kw_max
            | Rule::kw_timing
            | Rule::kw_period
            | Rule::kw_max_response
            | Rule::kw_priority
            | Rule::kw_quality
            | Rule::kw_exception
            | Rule::kw_retry
            | Rule::kw_every
            | Rule::kw_goto
            | Rule::kw_ignore
            | Rule::kw_degrade
            | Rule::kw_initial
            | Rule::kw_state
            | Rule::kw_entry
            | Rule::kw_exit
            | Rule::kw_periodic
            | Rule::kw_on
            | Rule::kw_after
            | Rule::kw_without
            | Rule::kw_may
            | Rule::kw_when
            | Rule::kw_instance
            | Rule::kw_substitutes
            | Rule::kw_redundant
            | Rule::kw_connect
            | Rule::kw_via
            | Rule::kw_error
            | Rule::kw_recovery
            | Rule::kw_deadline
            | Rule::kw_restart
            | Rule::kw_limit
            | Rule::kw_in
            | Rule::kw_backoff
    )
}

/// The children of a pair, keywords and doc lines removed.
fn children(pair: P<'_>) -> Vec<P<'_>> {
    pair.into_inner()
        .filter(|p| !is_keyword(p.as_rule()) && p.as_rule() != Rule::doc_line)
        .collect()
}

fn docs(pair: &P<'_>) -> ast::Doc {
    ast::Doc(
        pair.clone()
            .into_inner()
            .filter(|p| p.as_rule() == Rule::doc_line)
            .map(|p| doc_text(p.as_str()))
            .collect(),
    )
}

impl Builder<'_> {
    /// Keeps the doc comment of `pair`, a construct without a Rust item of its own, as
    /// a note of the enclosing component.
    fn note(&mut self, pair: &P<'_>) {
        let doc = docs(pair);
        if !doc.0.is_empty() {
            self.notes.push(ast::Note {
                subject: subject(pair),
                doc,
            });
        }
    }

    fn span(&self, pair: &P<'_>) -> Span {
        let span = pair.as_span();
        Span::new(self.base + span.start(), self.base + span.end())
    }

    fn ident(&self, pair: &P<'_>) -> ast::Ident {
        ast::Ident {
            name: pair.as_str().to_owned(),
            span: self.span(pair),
        }
    }

    fn error(&mut self, code: Code, span: Span, message: String) {
        self.diagnostics
            .push(Diagnostic::error(code, self.file, span, message));
    }

    fn item(&mut self, pair: P<'_>) -> Option<ast::Item> {
        let doc = docs(&pair);
        let inner = children(pair).into_iter().next()?;
        let span = self.span(&inner);
        let item = match inner.as_rule() {
            Rule::import => {
                let path = self.string(&children(inner).into_iter().next()?);
                ast::Item::Import(ast::Import { path, span })
            }
            Rule::packet => {
                let mut parts = children(inner).into_iter();
                let name = self.ident(&parts.next()?);
                let fields = parts.filter_map(|p| self.field(p)).collect();
                ast::Item::Packet(ast::Packet {
                    doc,
                    name,
                    fields,
                    span,
                })
            }
            Rule::enum_def => {
                let mut parts = children(inner).into_iter();
                let name = self.ident(&parts.next()?);
                let variants = parts
                    .filter_map(|p| {
                        let doc = docs(&p);
                        let name = self.ident(&children(p).into_iter().next()?);
                        Some(ast::Variant { doc, name })
                    })
                    .collect();
                ast::Item::Enum(ast::EnumDef {
                    doc,
                    name,
                    variants,
                    span,
                })
            }
            Rule::extern_packet => {
                let parts = children(inner);
                let name = self.ident(parts.first()?);
                let rust_path = self.string(parts.get(1)?);
                ast::Item::ExternPacket(ast::ExternPacket {
                    doc,
                    name,
                    rust_path,
                    span,
                })
            }
            Rule::converter => {
                let parts = children(inner);
                let name = self.ident(parts.first()?);
                let from = self.ty(parts.get(1)?.clone())?;
                let to = self.ty(parts.get(2)?.clone())?;
                ast::Item::Converter(ast::Converter {
                    doc,
                    name,
                    from,
                    to,
                    span,
                })
            }
            Rule::component => {
                let mut kind = ast::ComponentKind::Atomic;
                let mut kind_span = span;
                let mut name = None;
                let mut members = Vec::new();
                for part in children(inner) {
                    match part.as_rule() {
                        Rule::component_kind => {
                            kind = component_kind(part.as_str());
                            kind_span = self.span(&part);
                        }
                        Rule::ident => name = Some(self.ident(&part)),
                        Rule::member => members.extend(self.member(part)),
                        _ => {}
                    }
                }
                ast::Item::Component(ast::Component {
                    doc,
                    kind,
                    kind_span,
                    name: name?,
                    members,
                    notes: std::mem::take(self.notes),
                    span,
                })
            }
            _ => return None,
        };
        Some(item)
    }

    fn field(&mut self, pair: P<'_>) -> Option<ast::Field> {
        let span = self.span(&pair);
        let doc = docs(&pair);
        let parts = children(pair);
        let name = self.ident(parts.first()?);
        let ty = self.ty(parts.get(1)?.clone())?;
        let default = match parts.get(2) {
            Some(p) => Some(self.expr(p.clone())?),
            None => None,
        };
        Some(ast::Field {
            doc,
            name,
            ty,
            default,
            span,
        })
    }

    fn string(&mut self, pair: &P<'_>) -> ast::StrLit {
        let span = self.span(pair);
        let raw = pair.as_str();
        let body = &raw[1..raw.len().saturating_sub(1).max(1)];
        let value = self.unescape(body, span.start + 1);
        ast::StrLit { value, span }
    }

    fn unescape(&mut self, body: &str, start: usize) -> String {
        let mut out = String::with_capacity(body.len());
        let mut chars = body.char_indices().peekable();
        while let Some((index, ch)) = chars.next() {
            if ch != '\\' {
                out.push(ch);
                continue;
            }
            let Some((_, escaped)) = chars.next() else {
                break;
            };
            match escaped {
                'n' => out.push('\n'),
                'r' => out.push('\r'),
                't' => out.push('\t'),
                '0' => out.push('\0'),
                '\\' => out.push('\\'),
                '"' => out.push('"'),
                '\'' => out.push('\''),
                'u' => {
                    let rest = &body[index + 2..];
                    let parsed = rest
                        .strip_prefix('{')
                        .and_then(|r| r.find('}').map(|end| &r[..end]))
                        .and_then(|hex| u32::from_str_radix(hex, 16).ok().map(|v| (v, hex.len())))
                        .and_then(|(v, len)| char::from_u32(v).map(|c| (c, len)));
                    match parsed {
                        Some((c, len)) => {
                            out.push(c);
                            for _ in 0..len + 2 {
                                chars.next();
                            }
                        }
                        None => self.error(
                            Code::InvalidEscape,
                            Span::new(start + index, start + index + 2),
                            "invalid unicode escape: write `\\u{1F600}` with 1 to 6 hex digits"
                                .to_owned(),
                        ),
                    }
                }
                other => self.error(
                    Code::InvalidEscape,
                    Span::new(start + index, start + index + 1 + other.len_utf8()),
                    format!(
                        "unknown escape `\\{}` (known: \\n \\r \\t \\0 \\\\ \\\" \\u{{…}})",
                        other.escape_debug()
                    ),
                ),
            }
        }
        out
    }

    fn int_lit(&mut self, pair: &P<'_>) -> ast::IntLit {
        let span = self.span(pair);
        let text = pair.as_str().replace('_', "");
        let parsed = match text.strip_prefix("0x") {
            Some(hex) => u64::from_str_radix(hex, 16),
            None => text.parse::<u64>(),
        };
        let value = parsed.unwrap_or_else(|_| {
            self.error(
                Code::InvalidNumber,
                span,
                format!("integer `{}` does not fit in 64 bits", pair.as_str()),
            );
            0
        });
        ast::IntLit { value, span }
    }

    fn ty(&mut self, pair: P<'_>) -> Option<ast::Type> {
        let span = self.span(&pair);
        let mut parts = children(pair).into_iter();
        let base = parts.next()?;
        let base_span = self.span(&base);
        let kind = match base.as_rule() {
            Rule::prim => ast::TypeKind::Prim(prim(base.as_str())?),
            Rule::ident => ast::TypeKind::Named(self.ident(&base)),
            Rule::list_ty => {
                let inner = children(base);
                let element = self.ty(inner.first()?.clone())?;
                match inner.get(1) {
                    Some(size) => ast::TypeKind::Array(Box::new(element), self.int_lit(size)),
                    None => ast::TypeKind::List(Box::new(element)),
                }
            }
            _ => return None,
        };
        let mut ty = ast::Type {
            kind,
            span: base_span,
        };
        for mark in parts {
            let end = self.span(&mark).end;
            ty = ast::Type {
                kind: ast::TypeKind::Optional(Box::new(ty)),
                span: Span::new(span.start, end),
            };
        }
        Some(ty)
    }

    fn member(&mut self, pair: P<'_>) -> Option<ast::Member> {
        let doc = docs(&pair);
        let notes_before = self.notes.len();
        let has_item = |rule| {
            matches!(
                rule,
                Rule::configuration
                    | Rule::variable
                    | Rule::input
                    | Rule::output
                    | Rule::exception
                    | Rule::instance
            )
        };
        if pair
            .clone()
            .into_inner()
            .find(|p| p.as_rule() != Rule::doc_line)
            .is_some_and(|inner| !has_item(inner.as_rule()))
        {
            // Its doc comment has no Rust item to go to: a note.
            self.note(&pair);
        }
        let inner = children(pair).into_iter().next()?;
        let span = self.span(&inner);
        let member = match inner.as_rule() {
            Rule::link => {
                let part = children(inner).into_iter().next()?;
                let kind = match part.as_rule() {
                    Rule::link_crate => {
                        let parts = children(part);
                        let name = self.string(parts.first()?);
                        let spec_pair = parts.get(1)?.clone();
                        let spec = if spec_pair.as_rule() == Rule::string {
                            ast::CrateSpec::Version(self.string(&spec_pair))
                        } else {
                            let table_span = self.span(&spec_pair);
                            let mut entries = Vec::new();
                            for entry in children(spec_pair) {
                                let entry_span = self.span(&entry);
                                let parts = children(entry);
                                let key = self.ident(parts.first()?);
                                let value = self.expr(parts.get(1)?.clone())?;
                                entries.push(ast::TableEntry {
                                    key,
                                    value,
                                    span: entry_span,
                                });
                            }
                            ast::CrateSpec::Table(entries, table_span)
                        };
                        ast::LinkKind::Crate { name, spec }
                    }
                    _ => ast::LinkKind::System {
                        name: self.string(children(part).first()?),
                    },
                };
                ast::Member::Link(ast::Link { kind, span })
            }
            Rule::configuration => {
                let fields = children(inner)
                    .into_iter()
                    .filter_map(|p| self.field(p))
                    .collect();
                ast::Member::Configuration(ast::Configuration { doc, fields, span })
            }
            Rule::variable => {
                let parts = children(inner);
                let kind_pair = parts.first()?;
                let kind = match kind_pair.as_str() {
                    "observable" => ast::VarKind::Observable,
                    "controllable" => ast::VarKind::Controllable,
                    _ => ast::VarKind::Local,
                };
                let kind_span = self.span(kind_pair);
                let name = self.ident(parts.get(1)?);
                let mut ty = None;
                let mut value = None;
                for part in &parts[2..] {
                    if part.as_rule() == Rule::ty {
                        ty = Some(self.ty(part.clone())?);
                    } else {
                        value = Some(self.expr(part.clone())?);
                    }
                }
                ast::Member::Variable(ast::Variable {
                    doc,
                    kind,
                    kind_span,
                    name,
                    ty,
                    value,
                    span,
                })
            }
            Rule::input => {
                let pull = inner
                    .clone()
                    .into_inner()
                    .find(|p| p.as_rule() == Rule::kw_pull)
                    .map(|p| self.span(&p));
                let parts = children(inner);
                let name = self.ident(parts.first()?);
                let def_pair = parts.get(1)?.clone();
                let def = match def_pair.as_rule() {
                    Rule::port_ref => ast::InputDef::Export(self.port_ref(def_pair)?),
                    Rule::tick_kind => ast::InputDef::Tick,
                    Rule::fifo_kind => {
                        let parts = children(def_pair);
                        ast::InputDef::Fifo {
                            ty: self.ty(parts.first()?.clone())?,
                            size: self.int_lit(parts.get(1)?),
                            policy: parts.get(2).map(|p| self.ident(p)),
                        }
                    }
                    Rule::ufifo_kind => {
                        let parts = children(def_pair);
                        ast::InputDef::Ufifo {
                            ty: self.ty(parts.first()?.clone())?,
                            size: self.int_lit(parts.get(1)?),
                            max: parts.get(2).map(|p| self.int_lit(p)),
                        }
                    }
                    Rule::last_kind => {
                        ast::InputDef::Last(self.ty(children(def_pair).first()?.clone())?)
                    }
                    Rule::poster_kind => {
                        ast::InputDef::Poster(self.ty(children(def_pair).first()?.clone())?)
                    }
                    _ => return None,
                };
                ast::Member::Input(ast::Input {
                    doc,
                    name,
                    def,
                    pull,
                    span,
                })
            }
            Rule::output => {
                let pull = inner
                    .clone()
                    .into_inner()
                    .find(|p| p.as_rule() == Rule::kw_pull)
                    .map(|p| self.span(&p));
                let parts = children(inner);
                let name = self.ident(parts.first()?);
                let def_pair = parts.get(1)?.clone();
                let def = match def_pair.as_rule() {
                    Rule::port_ref => ast::OutputDef::Export(self.port_ref(def_pair)?),
                    Rule::tick_kind => ast::OutputDef::Tick,
                    Rule::data_kind => {
                        ast::OutputDef::Data(self.ty(children(def_pair).first()?.clone())?)
                    }
                    Rule::poster_kind => {
                        ast::OutputDef::Poster(self.ty(children(def_pair).first()?.clone())?)
                    }
                    _ => return None,
                };
                ast::Member::Output(ast::Output {
                    doc,
                    name,
                    def,
                    pull,
                    span,
                })
            }
            Rule::timing => ast::Member::Timing(self.timing(inner)?),
            Rule::exception => {
                let mut name = None;
                let mut description = None;
                let mut plan = Vec::new();
                for part in children(inner) {
                    match part.as_rule() {
                        Rule::ident => name = Some(self.ident(&part)),
                        Rule::string => description = Some(self.string(&part)),
                        _ => plan.extend(self.plan_step(part)),
                    }
                }
                let name = name?;
                in_context(
                    &mut self.notes[notes_before..],
                    &format!("exception `{}`", name.name),
                );
                ast::Member::Exception(ast::Exception {
                    doc,
                    name,
                    description,
                    plan,
                    span,
                })
            }
            Rule::automaton => {
                let mut keyword = ast::AutomatonKeyword::Automaton;
                let mut keyword_span = span;
                let mut initial = Vec::new();
                let mut states = Vec::new();
                for part in children(inner) {
                    match part.as_rule() {
                        Rule::automaton_kw => {
                            if part.as_str() == "supervisor" {
                                keyword = ast::AutomatonKeyword::Supervisor;
                            }
                            keyword_span = self.span(&part);
                        }
                        Rule::initial => {
                            self.note(&part);
                            initial.push(self.ident(children(part).first()?));
                        }
                        Rule::state => states.extend(self.state(part)),
                        _ => {}
                    }
                }
                ast::Member::Automaton(ast::Automaton {
                    keyword,
                    keyword_span,
                    initial,
                    states,
                    span,
                })
            }
            Rule::instance => {
                let parts = children(inner);
                let name = self.ident(parts.first()?);
                let component = self.ident(parts.get(1)?);
                let mut instance = ast::Instance {
                    doc,
                    name,
                    component,
                    substitutes: None,
                    node: None,
                    overrides: Vec::new(),
                    timing: None,
                    span,
                };
                for part in parts.into_iter().skip(2) {
                    match part.as_rule() {
                        Rule::substitutes_clause => {
                            instance.substitutes = Some(self.ident(children(part).first()?))
                        }
                        Rule::node_clause => {
                            instance.node = Some(self.string(children(part).first()?))
                        }
                        Rule::override_entry => {
                            self.note(&part);
                            let override_span = self.span(&part);
                            let parts = children(part);
                            let name = self.ident(parts.first()?);
                            let value = self.expr(parts.get(1)?.clone())?;
                            instance.overrides.push(ast::Override {
                                name,
                                value,
                                span: override_span,
                            });
                        }
                        Rule::timing => {
                            // A second timing block is merged: entries keep their order.
                            let timing = self.timing(part)?;
                            match &mut instance.timing {
                                Some(existing) => {
                                    existing.entries.extend(timing.entries);
                                    existing.span = existing.span.join(timing.span);
                                }
                                None => instance.timing = Some(timing),
                            }
                        }
                        _ => {}
                    }
                }
                in_context(
                    &mut self.notes[notes_before..],
                    &format!("instance `{}`", instance.name.name),
                );
                ast::Member::Instance(instance)
            }
            Rule::redundant => {
                let members = children(inner).iter().map(|p| self.ident(p)).collect();
                ast::Member::Redundant(ast::Redundant { members, span })
            }
            Rule::connect => {
                let parts = children(inner);
                let from = self.port_ref(parts.first()?.clone())?;
                let to = self.port_ref(parts.get(1)?.clone())?;
                let via = parts.get(2).map(|p| self.ident(p));
                ast::Member::Connect(ast::Connect {
                    from,
                    to,
                    via,
                    span,
                })
            }
            Rule::on_error => {
                let parts = children(inner);
                let instance = self.ident(parts.first()?);
                let policy = self.ident(parts.get(1)?);
                ast::Member::OnError(ast::OnError {
                    instance,
                    policy,
                    span,
                })
            }
            Rule::recovery => {
                let mut recovery = ast::Recovery {
                    retry_every: None,
                    deadline: None,
                    span,
                };
                for part in children(inner) {
                    self.note(&part);
                    let rule = part.as_rule();
                    let value = self.expr(children(part).first()?.clone())?;
                    if rule == Rule::recovery_retry {
                        recovery.retry_every = Some(value);
                    } else {
                        recovery.deadline = Some(value);
                    }
                }
                ast::Member::Recovery(recovery)
            }
            Rule::restart => {
                let mut restart = ast::Restart {
                    limit: None,
                    backoff: None,
                    span,
                };
                for part in children(inner) {
                    let rule = part.as_rule();
                    let values = children(part);
                    let pair = (
                        self.expr(values.first()?.clone())?,
                        self.expr(values.get(1)?.clone())?,
                    );
                    if rule == Rule::restart_limit {
                        restart.limit = Some(pair);
                    } else {
                        restart.backoff = Some(pair);
                    }
                }
                ast::Member::Restart(restart)
            }
            _ => return None,
        };
        Some(member)
    }

    fn port_ref(&mut self, pair: P<'_>) -> Option<ast::PortRef> {
        let span = self.span(&pair);
        let parts = children(pair);
        Some(match parts.as_slice() {
            [port] => ast::PortRef {
                instance: None,
                port: self.ident(port),
                span,
            },
            [instance, port] => ast::PortRef {
                instance: Some(self.ident(instance)),
                port: self.ident(port),
                span,
            },
            _ => return None,
        })
    }

    fn timing(&mut self, pair: P<'_>) -> Option<ast::Timing> {
        let span = self.span(&pair);
        let mut entries = Vec::new();
        for entry in children(pair) {
            self.note(&entry);
            let entry_span = self.span(&entry);
            let rule = entry.as_rule();
            let parts = children(entry);
            let timing_entry = match rule {
                Rule::period_entry => {
                    let interval = parts.first()?.clone();
                    let interval_span = self.span(&interval);
                    let bounds = children(interval);
                    let lo = self.expr(bounds.first()?.clone())?;
                    let hi = match bounds.get(1) {
                        Some(hi) => Some(self.expr(hi.clone())?),
                        None => None,
                    };
                    ast::TimingEntry::Period(ast::Interval {
                        lo,
                        hi,
                        span: interval_span,
                    })
                }
                Rule::max_response_entry => {
                    ast::TimingEntry::MaxResponse(self.expr(parts.first()?.clone())?)
                }
                Rule::priority_entry => {
                    ast::TimingEntry::Priority(self.expr(parts.first()?.clone())?)
                }
                Rule::quality_entry => ast::TimingEntry::Quality(
                    parts.iter().map(|p| self.ident(p)).collect(),
                    entry_span,
                ),
                _ => continue,
            };
            entries.push(timing_entry);
        }
        Some(ast::Timing { entries, span })
    }

    fn plan_step(&mut self, pair: P<'_>) -> Option<ast::PlanStep> {
        self.note(&pair);
        let span = self.span(&pair);
        let rule = pair.as_rule();
        let parts = children(pair);
        let kind = match rule {
            Rule::retry_step => ast::PlanKind::Retry {
                count: self.int_lit(parts.first()?),
                every: self.expr(parts.get(1)?.clone())?,
            },
            Rule::goto_step => ast::PlanKind::Goto(self.ident(parts.first()?)),
            Rule::ignore_step => ast::PlanKind::Ignore,
            Rule::degrade_step => ast::PlanKind::Degrade,
            _ => return None,
        };
        Some(ast::PlanStep { kind, span })
    }

    fn state(&mut self, pair: P<'_>) -> Option<ast::State> {
        let span = self.span(&pair);
        let doc = docs(&pair);
        let mut parts = children(pair).into_iter();
        let name = self.ident(&parts.next()?);
        let notes_before = self.notes.len();
        let (members, member_docs) = parts.filter_map(|part| self.state_member(part)).unzip();
        in_context(
            &mut self.notes[notes_before..],
            &format!("state `{}`", name.name),
        );
        Some(ast::State {
            doc,
            name,
            members,
            member_docs,
            span,
        })
    }

    /// One section or transition, with its doc comment. Sections and `may` document
    /// their trait methods; a transition's doc comment becomes a note.
    fn state_member(&mut self, part: P<'_>) -> Option<(ast::StateMember, ast::Doc)> {
        let doc = docs(&part);
        let has_method = matches!(
            part.as_rule(),
            Rule::entry_section | Rule::exit_section | Rule::periodic_section | Rule::may_rule
        );
        if !has_method {
            self.note(&part);
        }
        let member_span = self.span(&part);
        let rule = part.as_rule();
        let has_without = part
            .clone()
            .into_inner()
            .any(|p| p.as_rule() == Rule::kw_without);
        let values = children(part);
        let member = match rule {
            Rule::entry_section => ast::StateMember::Entry(member_span),
            Rule::exit_section => ast::StateMember::Exit(member_span),
            Rule::periodic_section => ast::StateMember::Periodic {
                period: match values.first() {
                    Some(p) => Some(self.expr(p.clone())?),
                    None => None,
                },
                span: member_span,
            },
            Rule::on_rule => ast::StateMember::On {
                port: self.ident(values.first()?),
                target: self.ident(values.get(1)?),
                span: member_span,
            },
            Rule::after_rule => {
                let delay = self.expr(values.first()?.clone())?;
                let (without, target) = if has_without {
                    (Some(self.ident(values.get(1)?)), self.ident(values.get(2)?))
                } else {
                    (None, self.ident(values.get(1)?))
                };
                ast::StateMember::After {
                    delay,
                    without,
                    target,
                    span: member_span,
                }
            }
            Rule::may_rule => ast::StateMember::May {
                targets: values.iter().map(|p| self.ident(p)).collect(),
                span: member_span,
            },
            Rule::when_rule => ast::StateMember::When {
                condition: self.expr(values.first()?.clone())?,
                target: self.ident(values.get(1)?),
                span: member_span,
            },
            _ => return None,
        };
        Some((member, doc))
    }

    fn expr(&mut self, pair: P<'_>) -> Option<ast::Expr> {
        let span = self.span(&pair);
        match pair.as_rule() {
            Rule::expr | Rule::and_expr => {
                let op = if pair.as_rule() == Rule::expr {
                    ast::BinaryOp::Or
                } else {
                    ast::BinaryOp::And
                };
                let mut parts = pair
                    .into_inner()
                    .filter(|p| !matches!(p.as_rule(), Rule::or_op | Rule::and_op));
                let mut left = self.expr(parts.next()?)?;
                for right in parts {
                    let right = self.expr(right)?;
                    let joined = left.span.join(right.span);
                    left = ast::Expr {
                        kind: ast::ExprKind::Binary(op, Box::new(left), Box::new(right)),
                        span: joined,
                    };
                }
                Some(left)
            }
            Rule::cmp_expr => {
                let parts: Vec<_> = pair.into_inner().collect();
                let left = self.expr(parts.first()?.clone())?;
                match (parts.get(1), parts.get(2)) {
                    (Some(op), Some(right)) => {
                        let op = match op.as_str() {
                            "==" => ast::BinaryOp::Eq,
                            "!=" => ast::BinaryOp::Ne,
                            "<=" => ast::BinaryOp::Le,
                            ">=" => ast::BinaryOp::Ge,
                            "<" => ast::BinaryOp::Lt,
                            _ => ast::BinaryOp::Gt,
                        };
                        let right = self.expr(right.clone())?;
                        Some(ast::Expr {
                            kind: ast::ExprKind::Binary(op, Box::new(left), Box::new(right)),
                            span,
                        })
                    }
                    _ => Some(left),
                }
            }
            Rule::unary => {
                let parts: Vec<_> = pair.into_inner().collect();
                let (operand, ops) = parts.split_last()?;
                let mut value = self.expr(operand.clone())?;
                for op in ops.iter().rev() {
                    let op_kind = if op.as_str() == "!" {
                        ast::UnaryOp::Not
                    } else {
                        ast::UnaryOp::Neg
                    };
                    let start = self.span(op).start;
                    let joined = Span::new(start, value.span.end);
                    value = ast::Expr {
                        kind: ast::ExprKind::Unary(op_kind, Box::new(value)),
                        span: joined,
                    };
                }
                Some(value)
            }
            Rule::integer => {
                let literal = self.int_lit(&pair);
                Some(ast::Expr {
                    kind: ast::ExprKind::Int(literal.value),
                    span,
                })
            }
            Rule::float => {
                let value = pair.as_str().replace('_', "").parse::<f64>().unwrap_or(0.0);
                Some(ast::Expr {
                    kind: ast::ExprKind::Float(value),
                    span,
                })
            }
            Rule::string => {
                let literal = self.string(&pair);
                Some(ast::Expr {
                    kind: ast::ExprKind::Str(literal.value),
                    span,
                })
            }
            Rule::bool_lit => Some(ast::Expr {
                kind: ast::ExprKind::Bool(pair.as_str() == "true"),
                span,
            }),
            Rule::none_lit => Some(ast::Expr {
                kind: ast::ExprKind::None,
                span,
            }),
            Rule::duration => {
                let text = pair.as_str();
                let unit = pair.into_inner().next()?.as_str();
                let number = text[..text.len() - unit.len()].replace('_', "");
                let factor: u128 = match unit {
                    "ns" => 1,
                    "us" => 1_000,
                    "ms" => 1_000_000,
                    "s" => 1_000_000_000,
                    _ => 60_000_000_000,
                };
                let nanos = if number.contains('.') {
                    let value = number.parse::<f64>().unwrap_or(0.0) * factor as f64;
                    (value.is_finite() && value < 1e30).then(|| value.round() as u128)
                } else {
                    number
                        .parse::<u128>()
                        .ok()
                        .and_then(|n| n.checked_mul(factor))
                };
                let nanos = nanos.unwrap_or_else(|| {
                    self.error(
                        Code::InvalidNumber,
                        span,
                        format!("duration `{text}` is too large"),
                    );
                    0
                });
                Some(ast::Expr {
                    kind: ast::ExprKind::Duration(nanos),
                    span,
                })
            }
            Rule::frequency => {
                let text = pair.as_str();
                let unit = pair.into_inner().next()?.as_str();
                let number = text[..text.len() - unit.len()].replace('_', "");
                let factor = match unit {
                    "Hz" => 1.0,
                    "kHz" => 1e3,
                    _ => 1e6,
                };
                let hertz = number.parse::<f64>().unwrap_or(0.0) * factor;
                Some(ast::Expr {
                    kind: ast::ExprKind::Frequency(hertz),
                    span,
                })
            }
            Rule::repeat_lit => {
                let parts = children(pair);
                let value = self.expr(parts.first()?.clone())?;
                let count = self.int_lit(parts.get(1)?);
                Some(ast::Expr {
                    kind: ast::ExprKind::Repeat(Box::new(value), count),
                    span,
                })
            }
            Rule::list_lit => {
                let mut items = Vec::new();
                for part in children(pair) {
                    items.push(self.expr(part)?);
                }
                Some(ast::Expr {
                    kind: ast::ExprKind::List(items),
                    span,
                })
            }
            Rule::enum_value => {
                let parts = children(pair);
                Some(ast::Expr {
                    kind: ast::ExprKind::EnumValue {
                        enum_name: self.ident(parts.first()?),
                        variant: self.ident(parts.get(1)?),
                    },
                    span,
                })
            }
            Rule::path => {
                let segments = children(pair).iter().map(|p| self.ident(p)).collect();
                Some(ast::Expr {
                    kind: ast::ExprKind::Path(segments),
                    span,
                })
            }
            _ => None,
        }
    }
}

fn prim(text: &str) -> Option<ast::Prim> {
    use ast::Prim::*;
    Some(match text {
        "bool" => Bool,
        "i8" => I8,
        "i16" => I16,
        "i32" => I32,
        "i64" => I64,
        "u8" => U8,
        "u16" => U16,
        "u32" => U32,
        "u64" => U64,
        "f32" => F32,
        "f64" => F64,
        "String" => String,
        "Time" => Time,
        "Duration" => Duration,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
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
