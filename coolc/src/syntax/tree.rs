//! AST building: pest pairs of a parsed item to `ast` nodes with byte spans, doc
//! comments and notes; literal values checked as they are read (escapes, integer
//! ranges).

use pest::iterators::Pair;

use super::Rule;
use crate::ast::{self, FileId, Span};
use crate::diagnostics::{Code, Diagnostic};

/// The construct `pair` as a note's subject: its text after its doc comment, up to
/// its first `{` or `;`, on one line, in backticks.
pub(super) fn subject(pair: &P<'_>) -> String {
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
pub(super) fn in_context(notes: &mut [ast::Note], context: &str) {
    for note in notes {
        note.subject = format!("{context}: {}", note.subject);
    }
}

pub(super) fn doc_text(line: &str) -> String {
    let body = line
        .strip_prefix("///")
        .unwrap_or(line)
        .trim_end_matches('\r');
    body.strip_prefix(' ').unwrap_or(body).to_owned()
}

pub(super) fn component_kind(text: &str) -> ast::ComponentKind {
    if text == "compound" {
        ast::ComponentKind::Compound
    } else {
        ast::ComponentKind::Atomic
    }
}

/// Builds AST nodes from pairs of one parse that started at byte `base`.
pub(super) struct Builder<'d> {
    pub(super) base: usize,
    pub(super) file: FileId,
    pub(super) diagnostics: &'d mut Vec<Diagnostic>,
    /// Where doc comments on constructs without a Rust item of their own go, until
    /// the component that holds them takes them.
    pub(super) notes: &'d mut Vec<ast::Note>,
}

pub(super) type P<'i> = Pair<'i, Rule>;

/// True for the `kw_*` keyword rules.
pub(super) fn is_keyword(rule: Rule) -> bool {
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
            | Rule::kw_thread
            | Rule::kw_connect
            | Rule::kw_via
            | Rule::kw_error
            | Rule::kw_recovery
            | Rule::kw_deadline
            | Rule::kw_restart
            | Rule::kw_limit
            | Rule::kw_in
            | Rule::kw_backoff
            | Rule::kw_adaptation
            | Rule::kw_ros
            | Rule::kw_as
    )
}

/// The children of a pair, keywords and doc lines removed.
pub(super) fn children(pair: P<'_>) -> Vec<P<'_>> {
    pair.into_inner()
        .filter(|p| !is_keyword(p.as_rule()) && p.as_rule() != Rule::doc_line)
        .collect()
}

pub(super) fn docs(pair: &P<'_>) -> ast::Doc {
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
    pub(super) fn note(&mut self, pair: &P<'_>) {
        let doc = docs(pair);
        if !doc.0.is_empty() {
            self.notes.push(ast::Note {
                subject: subject(pair),
                doc,
            });
        }
    }

    pub(super) fn span(&self, pair: &P<'_>) -> Span {
        let span = pair.as_span();
        Span::new(self.base + span.start(), self.base + span.end())
    }

    pub(super) fn ident(&self, pair: &P<'_>) -> ast::Ident {
        ast::Ident {
            name: pair.as_str().to_owned(),
            span: self.span(pair),
        }
    }

    pub(super) fn error(&mut self, code: Code, span: Span, message: String) {
        self.diagnostics
            .push(Diagnostic::error(code, self.file, span, message));
    }

    /// `substitutes a.b`: refused, since a substitute stands in its original's
    /// compound (where it is wired like the original and its supervisor commands it).
    fn substitute_elsewhere(
        &mut self,
        name: &ast::Ident,
        component: &ast::Ident,
        owner: &ast::Ident,
        last: &ast::Ident,
        path: &[ast::Ident],
    ) {
        let dotted: Vec<&str> = path.iter().map(|p| p.name.as_str()).collect();
        let dotted = dotted.join(".");
        let span = Span::new(owner.span.start, last.span.end);
        self.diagnostics.push(
            Diagnostic::error(
                Code::UnknownInstance,
                self.file,
                span,
                format!(
                    "`{dotted}` names an instance inside another component: a substitute is declared in the compound of the instance it substitutes"
                ),
            )
            .with_label("not an instance of this compound")
            .with_help(format!(
                "declare `instance {}: {} substitutes {};` in the component of `{}`",
                name.name,
                component.name,
                last.name,
                path.get(path.len().saturating_sub(2))
                    .map_or(owner.name.as_str(), |p| p.name.as_str())
            )),
        );
    }

    pub(super) fn item(&mut self, pair: P<'_>) -> Option<ast::Item> {
        let doc = docs(&pair);
        let inner = children(pair).into_iter().next()?;
        let span = self.span(&inner);
        let item = match inner.as_rule() {
            Rule::import => {
                let path = self.string(&children(inner).into_iter().next()?);
                ast::Item::Import(ast::Import { path, span })
            }
            Rule::ros_import => {
                let parts = children(inner);
                let ros_name = self.string(parts.first()?);
                let alias = parts.get(1).map(|p| self.ident(p));
                let name = alias
                    .clone()
                    .or_else(|| ast::RosImport::own_name(&ros_name));
                ast::Item::RosImport(ast::RosImport {
                    doc,
                    ros_name,
                    alias,
                    name,
                    span,
                })
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

    pub(super) fn field(&mut self, pair: P<'_>) -> Option<ast::Field> {
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

    pub(super) fn string(&mut self, pair: &P<'_>) -> ast::StrLit {
        let span = self.span(pair);
        let raw = pair.as_str();
        let body = &raw[1..raw.len().saturating_sub(1).max(1)];
        let value = self.unescape(body, span.start + 1);
        ast::StrLit { value, span }
    }

    pub(super) fn unescape(&mut self, body: &str, start: usize) -> String {
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

    pub(super) fn int_lit(&mut self, pair: &P<'_>) -> ast::IntLit {
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

    pub(super) fn ty(&mut self, pair: P<'_>) -> Option<ast::Type> {
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

    pub(super) fn member(&mut self, pair: P<'_>) -> Option<ast::Member> {
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
                let mut range = None;
                for part in &parts[2..] {
                    match part.as_rule() {
                        Rule::ty => ty = Some(self.ty(part.clone())?),
                        Rule::var_range => {
                            let range_span = self.span(part);
                            let bounds = children(part.clone());
                            let low = self.expr(bounds.first()?.clone())?;
                            let inclusive = bounds.get(1)?.as_str() == "..=";
                            let high = self.expr(bounds.get(2)?.clone())?;
                            range = Some(ast::VarRange {
                                low,
                                high,
                                inclusive,
                                span: range_span,
                            });
                        }
                        _ => value = Some(self.expr(part.clone())?),
                    }
                }
                ast::Member::Variable(ast::Variable {
                    doc,
                    kind,
                    kind_span,
                    name,
                    ty,
                    value,
                    range,
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
            Rule::adaptation => ast::Member::Adaptation(self.adaptation(inner)?),
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
                    adaptation: Vec::new(),
                    span,
                };
                for part in parts.into_iter().skip(2) {
                    match part.as_rule() {
                        Rule::substitutes_clause => {
                            let path: Vec<ast::Ident> =
                                children(part).iter().map(|p| self.ident(p)).collect();
                            match path.as_slice() {
                                [original] => instance.substitutes = Some(original.clone()),
                                [owner, .., last] => self.substitute_elsewhere(
                                    &instance.name,
                                    &instance.component,
                                    owner,
                                    last,
                                    &path,
                                ),
                                [] => {}
                            }
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
                        Rule::adaptation => {
                            // Every block is kept: the checker reports a second one.
                            instance.adaptation.push(self.adaptation(part)?);
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
            Rule::thread => {
                let mut names = children(inner).into_iter().map(|p| self.ident(&p));
                let name = names.next()?;
                ast::Member::Thread(ast::Thread {
                    name,
                    members: names.collect(),
                    span,
                })
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

    pub(super) fn port_ref(&mut self, pair: P<'_>) -> Option<ast::PortRef> {
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

    pub(super) fn timing(&mut self, pair: P<'_>) -> Option<ast::Timing> {
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

    pub(super) fn adaptation(&mut self, pair: P<'_>) -> Option<ast::Adaptation> {
        let span = self.span(&pair);
        let mut entries = Vec::new();
        for entry in children(pair) {
            if entry.as_rule() != Rule::adaptation_entry {
                continue;
            }
            self.note(&entry);
            let entry_span = self.span(&entry);
            let parts = children(entry);
            let key = self.ident(parts.first()?);
            let value = match parts.get(1) {
                Some(value) => Some(self.expr(value.clone())?),
                None => None,
            };
            entries.push(ast::AdaptEntry {
                key,
                value,
                span: entry_span,
            });
        }
        Some(ast::Adaptation { entries, span })
    }

    pub(super) fn plan_step(&mut self, pair: P<'_>) -> Option<ast::PlanStep> {
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

    pub(super) fn state(&mut self, pair: P<'_>) -> Option<ast::State> {
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
    pub(super) fn state_member(&mut self, part: P<'_>) -> Option<(ast::StateMember, ast::Doc)> {
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

    pub(super) fn expr(&mut self, pair: P<'_>) -> Option<ast::Expr> {
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
                // `1e999` parses as infinity, which no Rust literal writes.
                if !value.is_finite() {
                    self.error(
                        Code::InvalidNumber,
                        span,
                        format!("`{}` is beyond the largest `f64`", pair.as_str()),
                    );
                }
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
                // The runtime counts time in u64 nanoseconds: a longer duration would
                // be cut short without a word.
                let nanos = nanos.filter(|&n| n <= u128::from(u64::MAX));
                let nanos = nanos.unwrap_or_else(|| {
                    self.error(
                        Code::InvalidNumber,
                        span,
                        format!(
                            "duration `{text}` is too large (the longest is {}ns, about 584 years)",
                            u64::MAX
                        ),
                    );
                    // Not 0: that would also be reported as a zero duration.
                    u128::from(u64::MAX)
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

pub(super) fn prim(text: &str) -> Option<ast::Prim> {
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
