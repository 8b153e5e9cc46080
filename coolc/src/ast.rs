//! The abstract syntax tree of `.cool` descriptions.
//!
//! The parser (`syntax`) builds these types from pest pairs; everything after it
//! (`resolve`, `check`, `lower`) reads them. The tree is deliberately permissive: it
//! can hold things the language forbids (an `instance` inside an `atomic`, two
//! `timing` blocks, a `when` rule in an atomic automaton) so that the checker, not the
//! parser, rejects them with a precise diagnostic.
//!
//! **Invariant:** every node that a diagnostic may point at carries a [`Span`] of byte
//! offsets into the text of the file it came from ([`File::id`]).

use std::fmt;

/// Identifies one source file inside a [`crate::source::SourceMap`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct FileId(pub u32);

/// A half-open byte range `start..end` in one source file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Span {
    /// First byte of the node.
    pub start: usize,
    /// One past the last byte of the node.
    pub end: usize,
}

impl Span {
    /// A span from `start` to `end`.
    pub fn new(start: usize, end: usize) -> Self {
        Span { start, end }
    }

    /// The smallest span covering both `self` and `other`.
    pub(crate) fn join(self, other: Span) -> Span {
        Span::new(self.start.min(other.start), self.end.max(other.end))
    }

    /// Length in bytes.
    pub(crate) fn len(self) -> usize {
        self.end - self.start
    }
}

impl From<Span> for miette::SourceSpan {
    fn from(span: Span) -> Self {
        (span.start, span.len()).into()
    }
}

/// A name as written, with where it was written.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub(crate) struct Ident {
    /// The identifier text.
    pub(crate) name: String,
    /// Where it appears.
    pub(crate) span: Span,
}

impl fmt::Display for Ident {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name)
    }
}

/// `///` doc comment lines attached to the next item or member, without the `///`
/// and with one leading space removed. Empty when there is none.
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub(crate) struct Doc(pub Vec<String>);

impl Doc {}

/// A string literal, unescaped, with its span (quotes included).
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct StrLit {
    /// The unescaped contents.
    pub(crate) value: String,
    /// Where it appears, quotes included.
    pub(crate) span: Span,
}

/// A non-negative integer literal used where only a count or size makes sense.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct IntLit {
    /// The value as written.
    pub(crate) value: u64,
    /// Where it appears.
    pub(crate) span: Span,
}

/// One parsed source file.
#[derive(Clone, Debug, PartialEq)]
pub struct File {
    /// The file within the source map.
    pub id: FileId,
    /// The items in source order.
    pub(crate) items: Vec<Item>,
}

/// A top-level item.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Item {
    /// `import "other.cool";`
    Import(Import),
    /// `import ros "pkg/msg/Type" [as Name];`
    RosImport(RosImport),
    /// `packet Name { field: Type, ... }`
    Packet(Packet),
    /// `enum Name { A, B }`
    Enum(EnumDef),
    /// `extern packet Name = "rust::Path";`
    ExternPacket(ExternPacket),
    /// `converter Name: From -> To;`
    Converter(Converter),
    /// `atomic Name { ... }` or `compound Name { ... }`
    Component(Component),
}

/// `import "path.cool";`: the path is relative to the importing file.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Import {
    /// The path as written.
    pub(crate) path: StrLit,
    /// The whole item.
    pub(crate) span: Span,
}

/// `import ros "sensor_msgs/msg/LaserScan" [as Scan];`: a ROS 2 message type used as
/// a packet type, under its own name or the one after `as`.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct RosImport {
    /// Doc comment.
    pub(crate) doc: Doc,
    /// The type's full name as written (`sensor_msgs/msg/LaserScan`).
    pub(crate) ros_name: StrLit,
    /// The name after `as`, if written.
    pub(crate) alias: Option<Ident>,
    /// The name the descriptions use: the alias, else the type's own name
    /// ([`RosImport::own_name`]); `None` when neither is written as a name.
    pub(crate) name: Option<Ident>,
    /// The whole item.
    pub(crate) span: Span,
}

impl RosImport {
    /// The type's own name in `ros_name`, the text after the last `/`, as a name the
    /// descriptions can use (with the span of that text inside the string); `None`
    /// when it is not an identifier.
    pub(crate) fn own_name(ros_name: &StrLit) -> Option<Ident> {
        let text = &ros_name.value;
        let last = text.rsplit('/').next().unwrap_or(text);
        let mut chars = last.chars();
        let identifier = chars
            .next()
            .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
            && chars.all(|c| c.is_ascii_alphanumeric() || c == '_');
        if !identifier || matches!(last, "true" | "false" | "none") {
            return None;
        }
        // The span covers the quotes; with an escape inside, offsets in the value are
        // not offsets in the text, and the name's span is the whole string.
        let raw_len = ros_name.span.len().saturating_sub(2);
        let span = if raw_len == text.len() {
            let end = ros_name.span.end - 1;
            Span::new(end - last.len(), end)
        } else {
            ros_name.span
        };
        Some(Ident {
            name: last.to_owned(),
            span,
        })
    }
}

/// `packet Name { field: Type = default, ... }`
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Packet {
    /// Doc comment.
    pub(crate) doc: Doc,
    /// The packet type name.
    pub(crate) name: Ident,
    /// Fields in declaration order.
    pub(crate) fields: Vec<Field>,
    /// The whole item.
    pub(crate) span: Span,
}

/// `name: Type` or `name: Type = default`, in packets and `configuration` blocks.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Field {
    /// Doc comment.
    pub(crate) doc: Doc,
    /// Field name.
    pub(crate) name: Ident,
    /// Declared type.
    pub(crate) ty: Type,
    /// Default value, if written.
    pub(crate) default: Option<Expr>,
    /// The whole field.
    pub(crate) span: Span,
}

/// `enum Name { A, B, C }`
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct EnumDef {
    /// Doc comment.
    pub(crate) doc: Doc,
    /// The enum type name.
    pub(crate) name: Ident,
    /// Variants in declaration order.
    pub(crate) variants: Vec<Variant>,
    /// The whole item.
    pub(crate) span: Span,
}

/// One enum variant.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Variant {
    /// Doc comment.
    pub(crate) doc: Doc,
    /// Variant name.
    pub(crate) name: Ident,
}

/// `extern packet Name = "crate::Type";`
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct ExternPacket {
    /// Doc comment.
    pub(crate) doc: Doc,
    /// The name used in descriptions.
    pub(crate) name: Ident,
    /// The Rust type path it stands for.
    pub(crate) rust_path: StrLit,
    /// The whole item.
    pub(crate) span: Span,
}

/// `converter Name: From -> To;`
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Converter {
    /// Doc comment.
    pub(crate) doc: Doc,
    /// Converter name.
    pub(crate) name: Ident,
    /// Packet type it reads.
    pub(crate) from: Type,
    /// Packet type it produces.
    pub(crate) to: Type,
    /// The whole item.
    pub(crate) span: Span,
}

/// A type as written.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Type {
    /// What kind of type.
    pub(crate) kind: TypeKind,
    /// Where it appears.
    pub(crate) span: Span,
}

/// The shapes a type can take.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum TypeKind {
    /// A primitive type.
    Prim(Prim),
    /// A packet, enum or extern packet, by name.
    Named(Ident),
    /// `[T]`
    List(Box<Type>),
    /// `[T; N]`
    Array(Box<Type>, IntLit),
    /// `T?`
    Optional(Box<Type>),
}

/// The primitive types of the language.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) enum Prim {
    /// `bool`
    Bool,
    /// `i8`
    I8,
    /// `i16`
    I16,
    /// `i32`
    I32,
    /// `i64`
    I64,
    /// `u8`
    U8,
    /// `u16`
    U16,
    /// `u32`
    U32,
    /// `u64`
    U64,
    /// `f32`
    F32,
    /// `f64`
    F64,
    /// `String`
    String,
    /// `Time`: a point in time.
    Time,
    /// `Duration`: a span of time.
    Duration,
}

/// `atomic Name { ... }` or `compound Name { ... }`.
///
/// Both kinds share one member list; the checker reports members that the kind does
/// not allow (an `instance` in an atomic, an `automaton` in a compound).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Component {
    /// Doc comment.
    pub(crate) doc: Doc,
    /// Atomic or compound.
    pub(crate) kind: ComponentKind,
    /// Span of the `atomic`/`compound` keyword.
    pub(crate) kind_span: Span,
    /// Component type name.
    pub(crate) name: Ident,
    /// Members in source order.
    pub(crate) members: Vec<Member>,
    /// Doc comments on constructs inside the component that have no generated Rust
    /// item of their own (timing entries, transitions, connections, ...), in source
    /// order.
    pub(crate) notes: Vec<Note>,
    /// The whole item.
    pub(crate) span: Span,
}

/// A doc comment on a construct without a generated Rust item of its own: lowering
/// prints it in the rustdoc of the component's `SPEC`, after the construct's text.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Note {
    /// The construct as written, up to its first `{` or `;`, in backticks, with its
    /// context: `` `period 100ms` ``, ``state `moving`: `on halt -> stopped` ``.
    pub(crate) subject: String,
    /// The doc comment.
    pub(crate) doc: Doc,
}

/// The two kinds of component.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) enum ComponentKind {
    /// Embodied as one thread.
    Atomic,
    /// A composition of instances under a supervisor.
    Compound,
}

/// One member of a component body.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Member {
    /// `link crate "name" = "version";` / `link crate "name" = { ... };` / `link system "m";`
    Link(Link),
    /// `configuration { field: Type = default; ... }`
    Configuration(Configuration),
    /// `observable`/`controllable`/`local` variables, own or mapped.
    Variable(Variable),
    /// `input name: kind<T>(...) [pull];` or, in a compound, `input name = inst.port;`
    Input(Input),
    /// `output name: kind<T> [pull];` or, in a compound, `output name = inst.port;`
    Output(Output),
    /// `timing { ... }`
    Timing(Timing),
    /// `exception name ["description"] [{ plan }];`
    Exception(Exception),
    /// `automaton { ... }` (atomic) or `supervisor { ... }` (compound).
    Automaton(Automaton),
    /// `instance name: Component [substitutes other] [on "node"] [{ overrides }];`
    Instance(Instance),
    /// `redundant a, b, ...;`
    Redundant(Redundant),
    /// `thread name { a, b, ... }`
    Thread(Thread),
    /// `connect a.out -> b.in [via Converter];`
    Connect(Connect),
    /// `on error instance: policy;`
    OnError(OnError),
    /// `recovery { retry every D; deadline D; }`
    Recovery(Recovery),
    /// `restart { limit N in D; backoff D..D; }`
    Restart(Restart),
    /// `adaptation { off; }` or `adaptation { key value; ... }`
    Adaptation(Adaptation),
}

/// A `link` member: a dependency of the generated crate.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Link {
    /// Crate or system library.
    pub(crate) kind: LinkKind,
    /// The whole member.
    pub(crate) span: Span,
}

/// What a `link` names.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum LinkKind {
    /// `link crate "name" = spec;`: a Cargo dependency.
    Crate {
        /// Crate name.
        name: StrLit,
        /// Version requirement or inline table.
        spec: CrateSpec,
    },
    /// `link system "m";`: a native library, linked from a build script.
    System {
        /// Library name as given to the linker.
        name: StrLit,
    },
}

/// The right-hand side of `link crate "name" = ...`.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum CrateSpec {
    /// `"4"`: a version requirement.
    Version(StrLit),
    /// `{ version = "0.33", features = ["x"] }`: TOML-like key/value pairs.
    Table(Vec<TableEntry>, Span),
}

/// `key = value` inside an inline crate table.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct TableEntry {
    /// The key.
    pub(crate) key: Ident,
    /// The value: a string, bool, integer or list of strings.
    pub(crate) value: Expr,
    /// The whole entry.
    pub(crate) span: Span,
}

/// `configuration { field: Type = default; ... }`
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Configuration {
    /// Doc comment.
    pub(crate) doc: Doc,
    /// Configuration fields.
    pub(crate) fields: Vec<Field>,
    /// The whole member.
    pub(crate) span: Span,
}

/// How a variable is exposed (paper 3.1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) enum VarKind {
    /// Published on the monitoring port `m`.
    Observable,
    /// Set through the control port `c`.
    Controllable,
    /// Internal.
    Local,
}

/// `observable name: Type [= default];`, or in a compound `observable name = inst.var;`.
///
/// An own variable has `ty`; a mapped one has no `ty` and a path `value`. The checker
/// decides which it is and rejects other combinations.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Variable {
    /// Doc comment.
    pub(crate) doc: Doc,
    /// Observable, controllable or local.
    pub(crate) kind: VarKind,
    /// Span of the kind keyword.
    pub(crate) kind_span: Span,
    /// Variable name.
    pub(crate) name: Ident,
    /// Declared type, if any.
    pub(crate) ty: Option<Type>,
    /// Default value or mapping path, if any.
    pub(crate) value: Option<Expr>,
    /// `in low..=high`, if any.
    pub(crate) range: Option<VarRange>,
    /// The whole member.
    pub(crate) span: Span,
}

/// `in low..=high` on a variable: the values it may be set to.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct VarRange {
    /// The lowest value.
    pub(crate) low: Expr,
    /// The highest value.
    pub(crate) high: Expr,
    /// `..=` (true) or `..` (false; refused by the checker).
    pub(crate) inclusive: bool,
    /// From `in` to the end of `high`.
    pub(crate) span: Span,
}

/// An input port declaration.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Input {
    /// Doc comment.
    pub(crate) doc: Doc,
    /// Port name.
    pub(crate) name: Ident,
    /// The port's kind, or the exported port it maps to.
    pub(crate) def: InputDef,
    /// Span of `pull`, when the input uses the pull model.
    pub(crate) pull: Option<Span>,
    /// The whole member.
    pub(crate) span: Span,
}

/// What an input port is.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum InputDef {
    /// `tick`
    Tick,
    /// `fifo<T>(n)` or `fifo<T>(n, policy)`
    Fifo {
        /// Packet type.
        ty: Type,
        /// Queue length.
        size: IntLit,
        /// Overflow policy name (`reject`, `drop_oldest`, `block`), if written.
        policy: Option<Ident>,
    },
    /// `ufifo<T>(n)` or `ufifo<T>(n, max m)`
    Ufifo {
        /// Initial queue length (and growth step).
        size: IntLit,
        /// Packet type.
        ty: Type,
        /// Optional cap on growth.
        max: Option<IntLit>,
    },
    /// `last<T>`
    Last(Type),
    /// `poster<T>`
    Poster(Type),
    /// `= instance.port` in a compound: an exported input.
    Export(PortRef),
}

/// An output port declaration.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Output {
    /// Doc comment.
    pub(crate) doc: Doc,
    /// Port name.
    pub(crate) name: Ident,
    /// The port's kind, or the exported port it maps to.
    pub(crate) def: OutputDef,
    /// Span of `pull`, when the output answers pull requests (a user stub computes
    /// each answer).
    pub(crate) pull: Option<Span>,
    /// The whole member.
    pub(crate) span: Span,
}

/// What an output port is.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum OutputDef {
    /// `tick`
    Tick,
    /// `data<T>`: connects to `last`, `fifo` and `ufifo` inputs.
    Data(Type),
    /// `poster<T>`
    Poster(Type),
    /// `= instance.port` in a compound: an exported output.
    Export(PortRef),
}

/// `instance.port`, or a bare `port` meaning the compound's own port.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct PortRef {
    /// The instance, when written.
    pub(crate) instance: Option<Ident>,
    /// The port.
    pub(crate) port: Ident,
    /// The whole reference.
    pub(crate) span: Span,
}

/// `timing { period ...; max_response ...; priority ...; quality ...; }`
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Timing {
    /// Entries in source order.
    pub(crate) entries: Vec<TimingEntry>,
    /// The whole block.
    pub(crate) span: Span,
}

/// One entry of a `timing` block.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum TimingEntry {
    /// `period 10ms;` or `period 10ms..40ms;` (frequencies allowed).
    Period(Interval),
    /// `max_response 20ms;`
    MaxResponse(Expr),
    /// `priority 5;`
    Priority(Expr),
    /// `quality full, reduced, minimal;` best first.
    Quality(Vec<Ident>, Span),
}

/// `lo` or `lo..hi`.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Interval {
    /// Nominal (lower) bound.
    pub(crate) lo: Expr,
    /// Upper bound, if an interval was written.
    pub(crate) hi: Option<Expr>,
    /// The whole interval.
    pub(crate) span: Span,
}

/// `exception name ["description"] [{ plan }];`
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Exception {
    /// Doc comment.
    pub(crate) doc: Doc,
    /// Exception name.
    pub(crate) name: Ident,
    /// Human description, if written.
    pub(crate) description: Option<StrLit>,
    /// Continuity plan steps, tried in order; empty when there is no plan.
    pub(crate) plan: Vec<PlanStep>,
    /// The whole member.
    pub(crate) span: Span,
}

/// One step of a continuity plan (paper 3.5).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct PlanStep {
    /// What the step does.
    pub(crate) kind: PlanKind,
    /// The whole step.
    pub(crate) span: Span,
}

/// The continuity plan actions.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum PlanKind {
    /// `retry N every D;`: run the failing section again.
    Retry {
        /// How many times.
        count: IntLit,
        /// Delay between attempts.
        every: Expr,
    },
    /// `goto STATE;`: move the user automaton.
    Goto(Ident),
    /// `ignore;`: log and go on.
    Ignore,
    /// `degrade;`: ask adaptation for a lower quality level.
    Degrade,
}

/// The user automaton: `automaton { ... }` in an atomic, `supervisor { ... }` in a
/// compound.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Automaton {
    /// `automaton` or `supervisor`.
    pub(crate) keyword: AutomatonKeyword,
    /// Span of the keyword.
    pub(crate) keyword_span: Span,
    /// Every `initial NAME;` written (the checker wants exactly one).
    pub(crate) initial: Vec<Ident>,
    /// States in source order.
    pub(crate) states: Vec<State>,
    /// The whole block.
    pub(crate) span: Span,
}

/// Which keyword opened an automaton block.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) enum AutomatonKeyword {
    /// `automaton`
    Automaton,
    /// `supervisor`
    Supervisor,
}

/// `state name { ... }`
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct State {
    /// Doc comment.
    pub(crate) doc: Doc,
    /// State name.
    pub(crate) name: Ident,
    /// Sections and transitions in source order.
    pub(crate) members: Vec<StateMember>,
    /// The doc comment of each member (`members[i]`'s is `member_docs[i]`), empty
    /// when none was written.
    pub(crate) member_docs: Vec<Doc>,
    /// The whole state.
    pub(crate) span: Span,
}

/// Sections and transitions inside a state.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum StateMember {
    /// `entry;`
    Entry(Span),
    /// `exit;`
    Exit(Span),
    /// `periodic;` or `periodic 20ms;`
    Periodic {
        /// A state-specific period, if written.
        period: Option<Expr>,
        /// The whole member.
        span: Span,
    },
    /// `on port -> target;`
    On {
        /// The input port whose packet fires the transition.
        port: Ident,
        /// Target state.
        target: Ident,
        /// The whole member.
        span: Span,
    },
    /// `after D -> target;` or `after D without port -> target;`
    After {
        /// The delay.
        delay: Expr,
        /// The watched input port, for a watchdog.
        without: Option<Ident>,
        /// Target state.
        target: Ident,
        /// The whole member.
        span: Span,
    },
    /// `may -> a, b;`: targets the section code itself may choose.
    May {
        /// The allowed targets.
        targets: Vec<Ident>,
        /// The whole member.
        span: Span,
    },
    /// `when condition -> target;`: a supervisor rule.
    When {
        /// A boolean expression over variables.
        condition: Expr,
        /// Target state.
        target: Ident,
        /// The whole member.
        span: Span,
    },
}

/// `instance name: Component [substitutes other] [on "node"] [{ overrides }];`
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Instance {
    /// Doc comment.
    pub(crate) doc: Doc,
    /// Instance name.
    pub(crate) name: Ident,
    /// The component type instantiated.
    pub(crate) component: Ident,
    /// The instance this one substitutes, if any.
    pub(crate) substitutes: Option<Ident>,
    /// The node it runs on, for remote instantiation.
    pub(crate) node: Option<StrLit>,
    /// `name = value;` overrides of configuration fields or controllable variables.
    pub(crate) overrides: Vec<Override>,
    /// A `timing { ... }` override.
    pub(crate) timing: Option<Timing>,
    /// `adaptation { ... }` overrides, in source order (more than one is an error).
    pub(crate) adaptation: Vec<Adaptation>,
    /// The whole member.
    pub(crate) span: Span,
}

/// `name = value;` inside an instance body.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Override {
    /// Configuration field or controllable variable.
    pub(crate) name: Ident,
    /// New value.
    pub(crate) value: Expr,
    /// The whole override.
    pub(crate) span: Span,
}

/// `redundant a, b;`
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Redundant {
    /// The redundant instances.
    pub(crate) members: Vec<Ident>,
    /// The whole member.
    pub(crate) span: Span,
}

/// `thread name { a, b, ... }`: an execution group.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Thread {
    /// The group's name.
    pub(crate) name: Ident,
    /// The instances on the group's thread, as written.
    pub(crate) members: Vec<Ident>,
    /// The whole member.
    pub(crate) span: Span,
}

/// `connect from -> to [via Converter];`
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Connect {
    /// The output end.
    pub(crate) from: PortRef,
    /// The input end.
    pub(crate) to: PortRef,
    /// The converter, if any.
    pub(crate) via: Option<Ident>,
    /// The whole member.
    pub(crate) span: Span,
}

/// `on error instance: policy;`
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct OnError {
    /// The instance.
    pub(crate) instance: Ident,
    /// `propagate`, `restart`, `substitute` or `ignore` (checked later).
    pub(crate) policy: Ident,
    /// The whole member.
    pub(crate) span: Span,
}

/// `recovery { retry every D; deadline D; }`
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Recovery {
    /// How often instances in the recovery queue are restarted.
    pub(crate) retry_every: Option<Expr>,
    /// How long an instance may stay in the queue.
    pub(crate) deadline: Option<Expr>,
    /// The whole member.
    pub(crate) span: Span,
}

/// `restart { limit N in D; backoff D..D; }`: the budget and backoff of the compound's
/// `restart` policy.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Restart {
    /// `limit N in D`: at most `N` restarts of one instance within any `D`.
    pub(crate) limit: Option<(Expr, Expr)>,
    /// `backoff D..D`: the first wait before a repeated restart, and the longest.
    pub(crate) backoff: Option<(Expr, Expr)>,
    /// The whole member.
    pub(crate) span: Span,
}

/// `adaptation { off; }` or `adaptation { window 4; hold 5; ... }`.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Adaptation {
    /// Entries in source order.
    pub(crate) entries: Vec<AdaptEntry>,
    /// The whole block.
    pub(crate) span: Span,
}

/// One `key [value];` entry of an `adaptation` block (the checker knows the keys).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct AdaptEntry {
    /// `off`, `window`, `violations`, `hold`, `settle`, `homogeneity`, `selector`, ...
    pub(crate) key: Ident,
    /// The value, absent for `off`.
    pub(crate) value: Option<Expr>,
    /// The whole entry.
    pub(crate) span: Span,
}

/// An expression: default values, rule conditions, timing values, overrides.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Expr {
    /// What kind of expression.
    pub(crate) kind: ExprKind,
    /// Where it appears.
    pub(crate) span: Span,
}

/// The expression forms.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum ExprKind {
    /// An integer literal (sign is a [`UnaryOp::Neg`]).
    Int(u64),
    /// A floating-point literal.
    Float(f64),
    /// A string literal, unescaped.
    Str(String),
    /// `true` / `false`.
    Bool(bool),
    /// A duration literal, in nanoseconds (`250ns 500us 10ms 2s 1min`).
    Duration(u128),
    /// A frequency literal, in hertz (`10Hz 1kHz`).
    Frequency(f64),
    /// `a`, `a.b`: a variable, instance variable, state or result name, resolved by
    /// context.
    Path(Vec<Ident>),
    /// `Enum::Variant`
    EnumValue {
        /// The enum type.
        enum_name: Ident,
        /// The variant.
        variant: Ident,
    },
    /// `[a, b, c]`
    List(Vec<Expr>),
    /// `[value; n]`
    Repeat(Box<Expr>, IntLit),
    /// `none`: the empty optional value.
    None,
    /// `!e`, `-e`
    Unary(UnaryOp, Box<Expr>),
    /// `a op b`
    Binary(BinaryOp, Box<Expr>, Box<Expr>),
}

/// Prefix operators.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) enum UnaryOp {
    /// `!`
    Not,
    /// `-`
    Neg,
}

/// Infix operators, loosest first: `||`, `&&`, comparisons.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) enum BinaryOp {
    /// `||`
    Or,
    /// `&&`
    And,
    /// `==`
    Eq,
    /// `!=`
    Ne,
    /// `<`
    Lt,
    /// `<=`
    Le,
    /// `>`
    Gt,
    /// `>=`
    Ge,
}

impl BinaryOp {
    /// The operator as written in `.cool` (and in Rust).
    pub(crate) fn as_str(self) -> &'static str {
        match self {
            BinaryOp::Or => "||",
            BinaryOp::And => "&&",
            BinaryOp::Eq => "==",
            BinaryOp::Ne => "!=",
            BinaryOp::Lt => "<",
            BinaryOp::Le => "<=",
            BinaryOp::Gt => ">",
            BinaryOp::Ge => ">=",
        }
    }
}
