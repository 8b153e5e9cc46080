//! Recovery: parsing one item, member, state or state member at a time when the
//! whole does not parse, reporting what fails and resuming at the next plausible start
//! (`next_start`), so that one error does not hide the rest of the file.

use pest::Parser as _;

use super::errors::syntax_error;
use super::tree::{Builder, children, component_kind, doc_text, docs, in_context};
use super::{
    CoolParser, ITEM_KEYWORDS, MEMBER_KEYWORDS, Rule, STATE_MEMBER_KEYWORDS, parse_detailed,
};
use crate::ast::{self, FileId, Span};
use crate::diagnostics::{Code, Diagnostic};

pub(super) struct FileParser<'t> {
    pub(super) file: FileId,
    pub(super) text: &'t str,
    pub(super) diagnostics: Vec<Diagnostic>,
    /// Notes of the component being parsed member by member.
    pub(super) notes: Vec<ast::Note>,
    /// The diagnostics (by index) about `///` doc comments with nothing to document,
    /// and the spans of those comments.
    pub(super) dangling: Vec<(usize, Span)>,
}

impl<'t> FileParser<'t> {
    pub(super) fn items(&mut self) -> Vec<ast::Item> {
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
    pub(super) fn component_by_members(&mut self, start: usize) -> Option<(ast::Component, usize)> {
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
    pub(super) fn automaton_by_states(&mut self, start: usize) -> Option<(ast::Automaton, usize)> {
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
    pub(super) fn state_by_members(&mut self, start: usize) -> Option<(ast::State, usize)> {
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
    pub(super) fn report(&mut self, error: &pest::error::Error<Rule>, base: usize) -> usize {
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

/// Where to resume after an error at `error_at` in text that started at `start`:
/// the next line whose first word is one of `keywords`, at brace depth 0 relative to
/// `start` (or, failing that, at column 0), after the error. In member mode, a `}`
/// at depth 0 (the component's end) and the end of a `;`- or `}`-terminated member
/// also stop the scan.
pub(super) fn next_start(
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
pub(super) fn next_char(text: &str, offset: usize) -> usize {
    text[offset.min(text.len())..]
        .chars()
        .next()
        .map_or(text.len() + 1, |c| offset + c.len_utf8())
}
