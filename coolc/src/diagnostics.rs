//! Diagnostics: what `syntax`, `resolve` and `check` report, as data.
//!
//! A [`Diagnostic`] is plain data (a stable [`Code`], a severity, a message, the file
//! it belongs to, labelled spans, an optional help and related diagnostics that may
//! point into other files). Rendering happens in one place, [`render`], which turns
//! each diagnostic into a `miette::Diagnostic` carrying its own source text, so a
//! related diagnostic in another file shows that file.
//!
//! Codes are namespaced by stage: `coolc::syntax::*`, `coolc::resolve::*`,
//! `coolc::check::*`. They are stable: tests, editors and CI scripts match on them.

use std::fmt;
use std::sync::Arc;

use miette::{GraphicalReportHandler, GraphicalTheme, LabeledSpan, NamedSource, SourceSpan};
use serde::Serialize;

use crate::ast::{FileId, Span};
use crate::source::SourceMap;

/// How serious a diagnostic is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Severity {
    /// The description cannot be compiled.
    Error,
    /// The description compiles, but something looks wrong.
    Warning,
    /// Context for another diagnostic (e.g. an earlier definition in another file).
    Note,
}

macro_rules! codes {
    ($($(#[doc = $doc:literal])* $variant:ident => $code:literal,)*) => {
        /// Every diagnostic code `coolc` can report. The string form is stable.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
        pub enum Code {
            $($(#[doc = $doc])* $variant,)*
        }

        impl Code {
            /// All codes, in declaration order.
            pub const ALL: &'static [Code] = &[$(Code::$variant,)*];

            /// The stable namespaced code, e.g. `coolc::check::unknown_port`.
            pub fn as_str(self) -> &'static str {
                match self {
                    $(Code::$variant => $code,)*
                }
            }
        }
    };
}

codes! {
    /// The parser met a token it did not expect.
    UnexpectedToken => "coolc::syntax::unexpected_token",
    /// A string literal holds an unknown escape sequence.
    InvalidEscape => "coolc::syntax::invalid_escape",
    /// A number literal does not fit its type.
    InvalidNumber => "coolc::syntax::invalid_number",
    /// Brackets, comments or prefix operators nest deeper than the parser allows.
    TooDeep => "coolc::syntax::too_deep",
    /// An imported file could not be read.
    ImportNotFound => "coolc::resolve::import_not_found",
    /// An import path is absolute, or names a file that is not a `.cool` file.
    BadImport => "coolc::resolve::bad_import",
    /// Files import each other in a cycle.
    ImportCycle => "coolc::resolve::import_cycle",
    /// A name is declared twice in one scope.
    Duplicate => "coolc::resolve::duplicate",
    /// A type name does not exist.
    UnknownType => "coolc::resolve::unknown_type",
    /// A component name does not exist.
    UnknownComponent => "coolc::resolve::unknown_component",
    /// A converter name does not exist.
    UnknownConverter => "coolc::resolve::unknown_converter",
    /// A port name does not exist.
    UnknownPort => "coolc::check::unknown_port",
    /// A state name does not exist.
    UnknownState => "coolc::check::unknown_state",
    /// A variable name does not exist.
    UnknownVariable => "coolc::check::unknown_variable",
    /// An instance name does not exist.
    UnknownInstance => "coolc::check::unknown_instance",
    /// An enum variant does not exist.
    UnknownVariant => "coolc::check::unknown_variant",
    /// A configuration field overridden by an instance does not exist.
    UnknownOverride => "coolc::check::unknown_override",
    /// A name is a Rust keyword.
    RustKeyword => "coolc::check::rust_keyword",
    /// A member is not allowed in this kind of component or block.
    MisplacedMember => "coolc::check::misplaced_member",
    /// A `link` is malformed (empty name, unknown or ill-typed crate table key).
    BadLink => "coolc::check::bad_link",
    /// A block that may appear once appears twice.
    RepeatedBlock => "coolc::check::repeated_block",
    /// An `adaptation` block names a key the language does not know.
    UnknownAdaptationKey => "coolc::check::unknown_adaptation_key",
    /// An `adaptation` block writes the same key twice.
    RepeatedAdaptationKey => "coolc::check::repeated_adaptation_key",
    /// An `adaptation` block says `off` and tunes adaptation too.
    AdaptationOffTuned => "coolc::check::adaptation_off_tuned",
    /// An `adaptation` count is beyond what the runtime accepts (`violations` above
    /// `window`, or above the runtime's maximum).
    AdaptationRange => "coolc::check::adaptation_range",
    /// An `adaptation` block's `selector` is not one the language knows.
    UnknownSelector => "coolc::check::unknown_selector",
    /// An atomic component's `adaptation` block tunes a component whose timing never
    /// adapts (no period interval, nor `max_response` with quality levels).
    TuningWithoutAdaptation => "coolc::check::tuning_without_adaptation",
    /// An automaton has no `initial`, or several.
    InitialState => "coolc::check::initial_state",
    /// A state cannot be reached from the initial state.
    UnreachableState => "coolc::check::unreachable_state",
    /// A `periodic` section has no period.
    PeriodicWithoutPeriod => "coolc::check::periodic_without_period",
    /// An interval's upper bound is below its lower bound.
    ReversedInterval => "coolc::check::reversed_interval",
    /// A size, count or period is zero.
    ZeroSize => "coolc::check::zero_size",
    /// A value does not have the type its place requires.
    TypeMismatch => "coolc::check::type_mismatch",
    /// A `fifo` overflow policy is not known.
    UnknownPolicy => "coolc::check::unknown_policy",
    /// A `ufifo` cap is below its initial size.
    UfifoCap => "coolc::check::ufifo_cap",
    /// A fifo or ufifo size above 1048576 packets: the runtime allocates it when the
    /// component starts.
    SizeLimit => "coolc::check::size_limit",
    /// A component's name is too long for its module's file name.
    NameTooLong => "coolc::check::name_too_long",
    /// A configuration field has no default and its type has none coolc can build.
    NoDefault => "coolc::check::no_default",
    /// A variable declaration mixes own and mapped forms wrongly.
    BadVariable => "coolc::check::bad_variable",
    /// A variable's range where none may be (not an own controllable number), not
    /// inclusive, empty, or with the default outside it.
    BadRange => "coolc::check::bad_range",
    /// A connection joins port kinds the typology table does not allow.
    ConnectKind => "coolc::check::connect_kind",
    /// A connection goes the wrong way (into an output or out of an input).
    ConnectDirection => "coolc::check::connect_direction",
    /// An input has more producers than its kind allows.
    ConnectCardinality => "coolc::check::connect_cardinality",
    /// The two ends of a connection carry different packet types and no converter.
    PacketMismatch => "coolc::check::packet_mismatch",
    /// A converter's types do not match the ends of its connection.
    ConverterMismatch => "coolc::check::converter_mismatch",
    /// A rule expression is ill-typed.
    RuleType => "coolc::check::rule_type",
    /// A rule reads what is not published where rules are evaluated: an instance's
    /// `local` variable or a default controllable variable.
    UnreadableInRule => "coolc::check::unreadable_in_rule",
    /// A substitute or redundant instance has a different interface.
    InterfaceMismatch => "coolc::check::interface_mismatch",
    /// An instance takes part in more than one substitution or redundant group.
    Arrangement => "coolc::check::arrangement",
    /// An execution group's member that is not an instance of its compound.
    ThreadUnknownMember => "coolc::check::thread_unknown_member",
    /// An execution group's member that is an instance of a compound.
    ThreadNotAtomic => "coolc::check::thread_not_atomic",
    /// An execution group's member that runs on another node (`on "node"`).
    ThreadRemoteMember => "coolc::check::thread_remote_member",
    /// An instance named twice in one execution group, or in two.
    ThreadTwice => "coolc::check::thread_twice",
    /// An execution group with no member.
    ThreadEmpty => "coolc::check::thread_empty",
    /// Two execution groups of one compound with one name.
    ThreadDuplicateName => "coolc::check::thread_duplicate_name",
    /// An execution group whose members' periods are not harmonic.
    ThreadPeriods => "coolc::check::thread_periods",
    /// A member of an execution group pulls from another member.
    ThreadPull => "coolc::check::thread_pull",
    /// A member's `block` fifo is fed by another member of its execution group.
    ThreadBlock => "coolc::check::thread_block",
    /// A cycle of connections among an execution group's members with no `last` or
    /// `poster` input on it.
    ThreadCycle => "coolc::check::thread_cycle",
    /// A compound contains itself.
    SelfContaining => "coolc::check::self_containing",
    /// A packet contains itself by value (an infinitely large type).
    RecursivePacket => "coolc::check::recursive_packet",
    /// An `on error` policy is unknown or unusable.
    BadPolicy => "coolc::check::bad_policy",
    /// A port of an instance is not connected or exported (warning).
    UnconnectedPort => "coolc::check::unconnected_port",
    /// A name does not follow the naming convention (warning).
    Naming => "coolc::check::naming",
    /// A `degrade` plan step in a component with fewer than two quality levels: it
    /// can never lower the quality, so the plan always fails (warning).
    DegradeWithoutQuality => "coolc::check::degrade_without_quality",
    /// A `restart { }` or `recovery { }` block that applies to no instance (warning).
    UnusedBlock => "coolc::check::unused_block",
    /// A substitute whose original's error policy is not `substitute`: it never
    /// takes over.
    UnusedSubstitute => "coolc::check::unused_substitute",
    /// Redundant members with a data output and an input that may drop packets by its
    /// overflow policy: a failover may then skip or double packets of the merged
    /// stream without a count (partial in the runtime; warning).
    RedundantLossyInput => "coolc::check::redundant_lossy_input",
    /// One output connected to two members of a redundant group the same way: one
    /// connection to a member already feeds every member (warning).
    GroupConnectedTwice => "coolc::check::group_connected_twice",
    /// An aperiodic atomic component with a `max_response` has an input no `on`
    /// transition handles: response times are measured at `on` transitions only
    /// (partial in the runtime; warning).
    UnmeasuredResponse => "coolc::check::unmeasured_response",
    /// Two names that differ as written but are one Rust identifier in the generated
    /// code, or an atomic component named like a type its own code imports.
    NameClash => "coolc::check::name_clash",
    /// A name whose generated Rust form is not an identifier: `_1` (the leading `_`
    /// is dropped, leaving a digit first).
    NoRustName => "coolc::check::no_rust_name",
}

impl fmt::Display for Code {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A labelled span inside the diagnostic's file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Label {
    /// What the label points at.
    pub span: Span,
    /// Text shown beside the span (may be empty).
    pub message: String,
}

/// One diagnostic: data only, rendered by [`render`].
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct Diagnostic {
    /// Stable code.
    pub code: Code,
    /// Error or warning.
    pub severity: Severity,
    /// One-line message.
    pub message: String,
    /// The file the labels point into.
    pub file: FileId,
    /// Labels, the primary (offending) one first.
    pub labels: Vec<Label>,
    /// Actionable help, if any.
    pub help: Option<String>,
    /// Related diagnostics, possibly in other files (an earlier definition, an import).
    pub related: Vec<Diagnostic>,
}

impl Diagnostic {
    /// An error with a primary label.
    pub(crate) fn error(code: Code, file: FileId, span: Span, message: impl Into<String>) -> Self {
        Diagnostic {
            code,
            severity: Severity::Error,
            message: message.into(),
            file,
            labels: vec![Label {
                span,
                message: String::new(),
            }],
            help: None,
            related: Vec::new(),
        }
    }

    /// A warning with a primary label.
    pub(crate) fn warning(
        code: Code,
        file: FileId,
        span: Span,
        message: impl Into<String>,
    ) -> Self {
        Diagnostic {
            severity: Severity::Warning,
            ..Diagnostic::error(code, file, span, message)
        }
    }

    /// Sets the text of the primary label.
    pub(crate) fn with_label(mut self, message: impl Into<String>) -> Self {
        if let Some(label) = self.labels.first_mut() {
            label.message = message.into();
        }
        self
    }

    /// Adds a secondary label in the same file.
    pub(crate) fn with_secondary(mut self, span: Span, message: impl Into<String>) -> Self {
        self.labels.push(Label {
            span,
            message: message.into(),
        });
        self
    }

    /// Points at something elsewhere: a secondary label when it is in the same file,
    /// a related note otherwise.
    pub(crate) fn with_other(self, file: FileId, span: Span, message: impl Into<String>) -> Self {
        if file == self.file {
            self.with_secondary(span, message)
        } else {
            let message = message.into();
            let note = Diagnostic {
                severity: Severity::Note,
                ..Diagnostic::error(self.code, file, span, message.clone())
            }
            .with_label(message);
            self.with_related(note)
        }
    }

    /// Sets the help text.
    pub(crate) fn with_help(mut self, help: impl Into<String>) -> Self {
        self.help = Some(help.into());
        self
    }

    /// Adds a related diagnostic.
    pub(crate) fn with_related(mut self, related: Diagnostic) -> Self {
        self.related.push(related);
        self
    }

    /// The primary span (the first label), or an empty span at 0.
    pub fn primary_span(&self) -> Span {
        self.labels
            .first()
            .map(|label| label.span)
            .unwrap_or_default()
    }
}

/// A diagnostic is a `miette::Diagnostic` on its own too (without source text: use
/// [`render`] to show the code it points at).
impl miette::Diagnostic for Diagnostic {
    fn code<'a>(&'a self) -> Option<Box<dyn fmt::Display + 'a>> {
        Some(Box::new(self.code.as_str()))
    }

    fn severity(&self) -> Option<miette::Severity> {
        Some(miette_severity(self.severity))
    }

    fn help<'a>(&'a self) -> Option<Box<dyn fmt::Display + 'a>> {
        self.help
            .as_ref()
            .map(|help| Box::new(help) as Box<dyn fmt::Display>)
    }

    fn labels(&self) -> Option<Box<dyn Iterator<Item = LabeledSpan> + '_>> {
        Some(Box::new(self.labels.iter().enumerate().map(
            |(index, label)| {
                let text = (!label.message.is_empty()).then(|| label.message.clone());
                let span: SourceSpan = label.span.into();
                if index == 0 {
                    LabeledSpan::new_primary_with_span(text, span)
                } else {
                    LabeledSpan::new_with_span(text, span)
                }
            },
        )))
    }

    fn related<'a>(&'a self) -> Option<Box<dyn Iterator<Item = &'a dyn miette::Diagnostic> + 'a>> {
        if self.related.is_empty() {
            None
        } else {
            Some(Box::new(
                self.related
                    .iter()
                    .map(|related| related as &dyn miette::Diagnostic),
            ))
        }
    }
}

fn miette_severity(severity: Severity) -> miette::Severity {
    match severity {
        Severity::Error => miette::Severity::Error,
        Severity::Warning => miette::Severity::Warning,
        Severity::Note => miette::Severity::Advice,
    }
}

/// How to render diagnostics.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RenderOptions {
    /// Graphical (miette) or JSON lines.
    pub format: RenderFormat,
    /// Use ANSI colours (graphical only).
    pub colour: bool,
    /// Wrap width in columns (graphical only).
    pub width: usize,
}

impl RenderOptions {
    /// No colour, 80 columns: stable output for tests and pipes.
    pub fn plain() -> Self {
        RenderOptions {
            format: RenderFormat::Graphical,
            colour: false,
            width: 80,
        }
    }

    /// One JSON object per line.
    pub fn json() -> Self {
        RenderOptions {
            format: RenderFormat::Json,
            colour: false,
            width: 80,
        }
    }
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions::plain()
    }
}

/// The output format of [`render`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RenderFormat {
    /// miette's graphical report, one after another.
    Graphical,
    /// One JSON object per diagnostic per line (`--message-format json`).
    Json,
}

/// Renders diagnostics in the given order.
pub fn render(sources: &SourceMap, diagnostics: &[Diagnostic], options: RenderOptions) -> String {
    match options.format {
        RenderFormat::Graphical => render_graphical(sources, diagnostics, options),
        RenderFormat::Json => {
            let mut out = String::new();
            for diagnostic in diagnostics {
                let json = to_json(sources, diagnostic);
                out.push_str(&serde_json::to_string(&json).unwrap_or_default());
                out.push('\n');
            }
            out
        }
    }
}

fn render_graphical(
    sources: &SourceMap,
    diagnostics: &[Diagnostic],
    options: RenderOptions,
) -> String {
    let theme = if options.colour {
        GraphicalTheme::unicode()
    } else {
        GraphicalTheme::unicode_nocolor()
    };
    let handler = GraphicalReportHandler::new_themed(theme)
        .with_width(options.width)
        .with_links(false);
    let mut out = String::new();
    for diagnostic in diagnostics {
        let report = Rendered::new(sources, diagnostic);
        if handler.render_report(&mut out, &report).is_err() {
            out.push_str(&format!("{}: {}\n", diagnostic.code, diagnostic.message));
        }
        out.push('\n');
    }
    out
}

/// A diagnostic joined with its source, in the shape miette renders.
#[derive(Debug)]
struct Rendered {
    code: Code,
    severity: Severity,
    message: String,
    help: Option<String>,
    labels: Vec<LabeledSpan>,
    source: NamedSource<Arc<str>>,
    related: Vec<Rendered>,
}

impl Rendered {
    fn new(sources: &SourceMap, diagnostic: &Diagnostic) -> Self {
        let text = sources.text(diagnostic.file);
        let clamp = |span: Span| -> SourceSpan {
            let start = span.start.min(text.len());
            let end = span.end.clamp(start, text.len());
            (start, end - start).into()
        };
        let labels = diagnostic
            .labels
            .iter()
            .enumerate()
            .map(|(index, label)| {
                let text = (!label.message.is_empty()).then(|| label.message.clone());
                if index == 0 {
                    LabeledSpan::new_primary_with_span(text, clamp(label.span))
                } else {
                    LabeledSpan::new_with_span(text, clamp(label.span))
                }
            })
            .collect();
        Rendered {
            code: diagnostic.code,
            severity: diagnostic.severity,
            message: diagnostic.message.clone(),
            help: diagnostic.help.clone(),
            labels,
            source: NamedSource::new(
                sources.display_path(diagnostic.file),
                sources.shared_text(diagnostic.file),
            ),
            related: diagnostic
                .related
                .iter()
                .map(|related| Rendered::new(sources, related))
                .collect(),
        }
    }
}

impl fmt::Display for Rendered {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Rendered {}

impl miette::Diagnostic for Rendered {
    fn code<'a>(&'a self) -> Option<Box<dyn fmt::Display + 'a>> {
        Some(Box::new(self.code.as_str()))
    }

    fn severity(&self) -> Option<miette::Severity> {
        Some(miette_severity(self.severity))
    }

    fn help<'a>(&'a self) -> Option<Box<dyn fmt::Display + 'a>> {
        self.help
            .as_ref()
            .map(|help| Box::new(help) as Box<dyn fmt::Display>)
    }

    fn source_code(&self) -> Option<&dyn miette::SourceCode> {
        Some(&self.source)
    }

    fn labels(&self) -> Option<Box<dyn Iterator<Item = LabeledSpan> + '_>> {
        Some(Box::new(self.labels.iter().cloned()))
    }

    fn related<'a>(&'a self) -> Option<Box<dyn Iterator<Item = &'a dyn miette::Diagnostic> + 'a>> {
        if self.related.is_empty() {
            None
        } else {
            Some(Box::new(
                self.related
                    .iter()
                    .map(|related| related as &dyn miette::Diagnostic),
            ))
        }
    }
}

/// The JSON form of a diagnostic (`--message-format json`).
#[derive(Debug, Serialize)]
struct JsonDiagnostic {
    code: &'static str,
    severity: Severity,
    message: String,
    file: String,
    line: usize,
    column: usize,
    span: JsonSpan,
    labels: Vec<JsonLabel>,
    help: Option<String>,
    related: Vec<JsonDiagnostic>,
}

#[derive(Debug, Serialize)]
struct JsonSpan {
    start: usize,
    end: usize,
}

#[derive(Debug, Serialize)]
struct JsonLabel {
    message: String,
    line: usize,
    column: usize,
    span: JsonSpan,
}

fn to_json(sources: &SourceMap, diagnostic: &Diagnostic) -> JsonDiagnostic {
    let primary = diagnostic.primary_span();
    let (line, column) = sources.line_col(diagnostic.file, primary.start);
    JsonDiagnostic {
        code: diagnostic.code.as_str(),
        severity: diagnostic.severity,
        message: diagnostic.message.clone(),
        file: sources.display_path(diagnostic.file),
        line,
        column,
        span: JsonSpan {
            start: primary.start,
            end: primary.end,
        },
        labels: diagnostic
            .labels
            .iter()
            .map(|label| {
                let (line, column) = sources.line_col(diagnostic.file, label.span.start);
                JsonLabel {
                    message: label.message.clone(),
                    line,
                    column,
                    span: JsonSpan {
                        start: label.span.start,
                        end: label.span.end,
                    },
                }
            })
            .collect(),
        help: diagnostic.help.clone(),
        related: diagnostic
            .related
            .iter()
            .map(|related| to_json(sources, related))
            .collect(),
    }
}

/// The closest candidate to `name` (edit distance at most a third of its length, at
/// least 1), for "did you mean" help. Ties go to the first candidate.
pub(crate) fn closest<'a>(
    name: &str,
    candidates: impl IntoIterator<Item = &'a str>,
) -> Option<&'a str> {
    let limit = (name.chars().count() / 3).max(1);
    let mut best: Option<(usize, &str)> = None;
    for candidate in candidates {
        if candidate == name {
            continue;
        }
        let distance = edit_distance(&name.to_lowercase(), &candidate.to_lowercase());
        if distance <= limit && best.is_none_or(|(d, _)| distance < d) {
            best = Some((distance, candidate));
        }
    }
    best.map(|(_, candidate)| candidate)
}

/// Levenshtein distance over chars.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut previous: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut current = vec![i + 1; b.len() + 1];
        for (j, cb) in b.iter().enumerate() {
            let cost = usize::from(ca != *cb);
            current[j + 1] = (previous[j] + cost)
                .min(previous[j + 1] + 1)
                .min(current[j] + 1);
        }
        previous = current;
    }
    previous[b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_finds_near_names_only() {
        assert_eq!(closest("comand", ["command", "halt"]), Some("command"));
        assert_eq!(closest("xyz", ["command", "halt"]), None);
        assert_eq!(edit_distance("kitten", "sitting"), 3);
    }

    #[test]
    fn codes_are_namespaced_and_unique() {
        let mut seen = std::collections::BTreeSet::new();
        for code in Code::ALL {
            assert!(code.as_str().starts_with("coolc::"), "{code}");
            assert!(seen.insert(code.as_str()), "duplicate {code}");
        }
    }
}
