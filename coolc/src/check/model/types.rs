//! The vocabulary of the model: resolved types, port kinds with their settings,
//! ranges, adaptation tuning, the default automaton's names, and the type of a typed
//! rule expression.

use std::fmt;

use crate::ast::{self, Span};

/// A resolved type.
#[derive(Clone, Debug, PartialEq)]
pub enum Ty {
    /// `bool`
    Bool,
    /// An integer primitive.
    Int(ast::Prim),
    /// `f32` or `f64`.
    Float(ast::Prim),
    /// `String`
    Str,
    /// `Time`
    Time,
    /// `Duration`
    Duration,
    /// A packet, by name.
    Packet(String),
    /// An enum, by name.
    Enum(String),
    /// An extern packet, by name.
    Extern(String),
    /// A ROS 2 message type (`import ros`), by the name the descriptions use and the
    /// type's full name (`sensor_msgs/msg/LaserScan`, as written in the import).
    Ros {
        /// The name in the descriptions (the import's alias, else the type's name).
        name: String,
        /// The type's full name.
        ros: String,
    },
    /// `[T]`
    List(Box<Ty>),
    /// `[T; N]`
    Array(Box<Ty>, u64),
    /// `T?`
    Optional(Box<Ty>),
    /// A name that did not resolve (already reported): matches everything.
    Unknown,
}

impl Ty {
    /// Equality where an unknown type matches anything.
    pub fn same(&self, other: &Ty) -> bool {
        match (self, other) {
            (Ty::Unknown, _) | (_, Ty::Unknown) => true,
            (Ty::List(a), Ty::List(b)) | (Ty::Optional(a), Ty::Optional(b)) => a.same(b),
            (Ty::Array(a, n), Ty::Array(b, m)) => n == m && a.same(b),
            // Two names of one ROS type are the same type.
            (Ty::Ros { ros: a, .. }, Ty::Ros { ros: b, .. }) => a == b,
            _ => self == other,
        }
    }

    /// Where the default value of the generated Rust type comes from: the one list
    /// of the types that have one whatever they hold, which the checker
    /// (`has_default`) and `lower` (`default_of`) both follow.
    pub fn default_from(&self) -> DefaultFrom<'_> {
        match self {
            Ty::Bool
            | Ty::Int(_)
            | Ty::Float(_)
            | Ty::Str
            | Ty::Time
            | Ty::Duration
            | Ty::List(_)
            | Ty::Optional(_)
            // A ROS message type always has one (`lower::ros`).
            | Ty::Ros { .. } => DefaultFrom::Always,
            Ty::Array(inner, length) => DefaultFrom::Elements(inner, *length),
            Ty::Enum(name) | Ty::Packet(name) => DefaultFrom::Definition(name),
            // coolc cannot see another crate's type.
            Ty::Extern(_) => DefaultFrom::Never,
            Ty::Unknown => DefaultFrom::Unknown,
        }
    }
}

/// Where a type's default value comes from ([`Ty::default_from`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DefaultFrom<'t> {
    /// The type implements `Default` whatever it holds.
    Always,
    /// An array `[T; N]`: from its element type's.
    Elements(&'t Ty, u64),
    /// An enum (its first variant) or a packet (its fields'), by name.
    Definition(&'t str),
    /// An extern packet: none coolc can build.
    Never,
    /// A name that did not resolve (already reported).
    Unknown,
}

impl fmt::Display for Ty {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Ty::Bool => f.write_str("bool"),
            Ty::Int(prim) | Ty::Float(prim) => f.write_str(prim_name(*prim)),
            Ty::Str => f.write_str("String"),
            Ty::Time => f.write_str("Time"),
            Ty::Duration => f.write_str("Duration"),
            Ty::Packet(name) | Ty::Enum(name) | Ty::Extern(name) | Ty::Ros { name, .. } => {
                f.write_str(name)
            }
            Ty::List(inner) => write!(f, "[{inner}]"),
            Ty::Array(inner, n) => write!(f, "[{inner}; {n}]"),
            Ty::Optional(inner) => write!(f, "{inner}?"),
            Ty::Unknown => f.write_str("{unknown}"),
        }
    }
}

/// The name of a primitive type as written.
pub fn prim_name(prim: ast::Prim) -> &'static str {
    use ast::Prim::*;
    match prim {
        Bool => "bool",
        I8 => "i8",
        I16 => "i16",
        I32 => "i32",
        I64 => "i64",
        U8 => "u8",
        U16 => "u16",
        U32 => "u32",
        U64 => "u64",
        F32 => "f32",
        F64 => "f64",
        String => "String",
        Time => "Time",
        Duration => "Duration",
    }
}

/// The kinds of port (paper Figure 3): the tag of an [`InputKind`] or [`OutputKind`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum PortKind {
    /// `tick` (input or output)
    Tick,
    /// `fifo<T>(n)` input
    Fifo,
    /// `ufifo<T>(n)` input
    Ufifo,
    /// `last<T>` input
    Last,
    /// `poster<T>` (input or output)
    Poster,
    /// `data<T>` output
    Data,
}

impl PortKind {
    /// The kind as written.
    pub fn as_str(self) -> &'static str {
        match self {
            PortKind::Tick => "tick",
            PortKind::Fifo => "fifo",
            PortKind::Ufifo => "ufifo",
            PortKind::Last => "last",
            PortKind::Poster => "poster",
            PortKind::Data => "data",
        }
    }
}

/// What an input port is: its kind with its packet type and settings, evaluated.
#[derive(Clone, Debug, PartialEq)]
pub enum InputKind {
    /// `tick`
    Tick,
    /// `fifo<T>(size[, policy])`
    Fifo {
        /// Packet type.
        ty: Ty,
        /// Queue length.
        size: u64,
        /// Overflow policy, when written ([`OverflowPolicy::default`] applies
        /// otherwise).
        policy: Option<OverflowPolicy>,
    },
    /// `ufifo<T>(size[, max m])`
    Ufifo {
        /// Packet type.
        ty: Ty,
        /// Initial length and growth step.
        size: u64,
        /// Growth cap, when written.
        max: Option<u64>,
    },
    /// `last<T>`
    Last(Ty),
    /// `poster<T>`
    Poster(Ty),
}

impl InputKind {
    /// The input as written (`None` for an export, which has no kind of its own).
    pub(crate) fn of(def: &ast::InputDef, ty: impl Fn(&ast::Type) -> Ty) -> Option<InputKind> {
        Some(match def {
            ast::InputDef::Tick => InputKind::Tick,
            ast::InputDef::Fifo {
                ty: packet,
                size,
                policy,
            } => InputKind::Fifo {
                ty: ty(packet),
                size: size.value,
                policy: policy.as_ref().and_then(|p| OverflowPolicy::named(&p.name)),
            },
            ast::InputDef::Ufifo {
                ty: packet,
                size,
                max,
            } => InputKind::Ufifo {
                ty: ty(packet),
                size: size.value,
                max: max.as_ref().map(|m| m.value),
            },
            ast::InputDef::Last(packet) => InputKind::Last(ty(packet)),
            ast::InputDef::Poster(packet) => InputKind::Poster(ty(packet)),
            ast::InputDef::Export(_) => return None,
        })
    }

    /// The port kind (and so the connection kind an input forms, paper Figure 3).
    pub fn port_kind(&self) -> PortKind {
        match self {
            InputKind::Tick => PortKind::Tick,
            InputKind::Fifo { .. } => PortKind::Fifo,
            InputKind::Ufifo { .. } => PortKind::Ufifo,
            InputKind::Last(_) => PortKind::Last,
            InputKind::Poster(_) => PortKind::Poster,
        }
    }

    /// The packet type (`None` for a tick).
    pub fn packet(&self) -> Option<&Ty> {
        match self {
            InputKind::Tick => None,
            InputKind::Fifo { ty, .. } | InputKind::Ufifo { ty, .. } => Some(ty),
            InputKind::Last(ty) | InputKind::Poster(ty) => Some(ty),
        }
    }
}

/// What an output port is: its kind with its packet type.
#[derive(Clone, Debug, PartialEq)]
pub enum OutputKind {
    /// `tick`
    Tick,
    /// `data<T>`
    Data(Ty),
    /// `poster<T>`
    Poster(Ty),
}

impl OutputKind {
    /// The output as written (`None` for an export).
    pub(crate) fn of(def: &ast::OutputDef, ty: impl Fn(&ast::Type) -> Ty) -> Option<OutputKind> {
        Some(match def {
            ast::OutputDef::Tick => OutputKind::Tick,
            ast::OutputDef::Data(packet) => OutputKind::Data(ty(packet)),
            ast::OutputDef::Poster(packet) => OutputKind::Poster(ty(packet)),
            ast::OutputDef::Export(_) => return None,
        })
    }

    /// The port kind.
    pub fn port_kind(&self) -> PortKind {
        match self {
            OutputKind::Tick => PortKind::Tick,
            OutputKind::Data(_) => PortKind::Data,
            OutputKind::Poster(_) => PortKind::Poster,
        }
    }

    /// The packet type (`None` for a tick).
    pub fn packet(&self) -> Option<&Ty> {
        match self {
            OutputKind::Tick => None,
            OutputKind::Data(ty) | OutputKind::Poster(ty) => Some(ty),
        }
    }
}

/// What a full `fifo` input does with a new packet (`fifo<T>(n, policy)`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum OverflowPolicy {
    /// `reject` (the default): the new packet is refused and counted.
    #[default]
    Reject,
    /// `drop_oldest`: the oldest queued packet makes room.
    DropOldest,
    /// `block`: the producer waits for room, up to a timeout.
    Block,
}

impl OverflowPolicy {
    /// Every policy with its name in the language.
    pub const ALL: [(&'static str, OverflowPolicy); 3] = [
        ("reject", OverflowPolicy::Reject),
        ("drop_oldest", OverflowPolicy::DropOldest),
        ("block", OverflowPolicy::Block),
    ];

    /// The policy named `name`.
    pub fn named(name: &str) -> Option<OverflowPolicy> {
        Self::ALL
            .iter()
            .find(|(known, _)| *known == name)
            .map(|(_, policy)| *policy)
    }

    /// Its name in the language.
    pub fn name(self) -> &'static str {
        Self::ALL
            .iter()
            .find(|(_, known)| *known == self)
            .map_or("", |(name, _)| name)
    }
}

/// A declared port: its kind and whether it is `pull`.
#[derive(Clone, Debug, PartialEq)]
pub struct Declared<K> {
    /// The kind, with its packet type.
    pub kind: K,
    /// `pull` was written.
    pub pull: bool,
}

/// An input's or an output's kind.
#[derive(Clone, Debug, PartialEq)]
pub enum Declaration {
    /// An input port.
    Input(InputKind),
    /// An output port.
    Output(OutputKind),
}

/// A port as seen from outside: for an export, the port it reaches (through every
/// level of exports), at the export's span.
#[derive(Clone, Debug, PartialEq)]
pub struct Port {
    /// Its kind, with its packet type and settings.
    pub declared: Declaration,
    /// `pull` was written.
    pub pull: bool,
    /// Where it is declared (in the component's file).
    pub span: Span,
}

impl Port {
    /// Its kind.
    pub fn kind(&self) -> PortKind {
        match &self.declared {
            Declaration::Input(kind) => kind.port_kind(),
            Declaration::Output(kind) => kind.port_kind(),
        }
    }

    /// Its packet type (`None` for ticks).
    pub fn ty(&self) -> Option<&Ty> {
        match &self.declared {
            Declaration::Input(kind) => kind.packet(),
            Declaration::Output(kind) => kind.packet(),
        }
    }

    /// A `fifo` input whose overflow policy is `block`.
    pub fn block(&self) -> bool {
        matches!(
            self.declared,
            Declaration::Input(InputKind::Fifo {
                policy: Some(OverflowPolicy::Block),
                ..
            })
        )
    }

    /// The input it is, with `pull` (`None` for an output).
    pub fn input(&self) -> Option<Declared<InputKind>> {
        match &self.declared {
            Declaration::Input(kind) => Some(Declared {
                kind: kind.clone(),
                pull: self.pull,
            }),
            Declaration::Output(_) => None,
        }
    }

    /// The output it is, with `pull` (`None` for an input).
    pub fn output(&self) -> Option<Declared<OutputKind>> {
        match &self.declared {
            Declaration::Output(kind) => Some(Declared {
                kind: kind.clone(),
                pull: self.pull,
            }),
            Declaration::Input(_) => None,
        }
    }
}

/// A constant number as written: an integer or a float, its sign applied.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Number {
    /// An integer.
    Int(i128),
    /// A number with a point.
    Float(f64),
}

impl Number {
    /// The number `expr` writes, if it writes one.
    pub fn of(expr: &ast::Expr) -> Option<Number> {
        match &expr.kind {
            ast::ExprKind::Int(value) => Some(Number::Int((*value).into())),
            ast::ExprKind::Float(value) => Some(Number::Float(*value)),
            ast::ExprKind::Unary(ast::UnaryOp::Neg, inner) => match Number::of(inner)? {
                Number::Int(value) => Some(Number::Int(-value)),
                Number::Float(value) => Some(Number::Float(-value)),
            },
            _ => None,
        }
    }

    #[allow(clippy::cast_precision_loss)]
    fn float(self) -> f64 {
        match self {
            Number::Int(value) => value as f64,
            Number::Float(value) => value,
        }
    }
}

/// The values a controllable variable may be set to, both ends included, in the
/// variable's own kind of number (an `f32` variable's ends rounded to `f32`, as its
/// values are stored).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Range {
    /// An integer variable's range.
    Int(i128, i128),
    /// An `f64` variable's range.
    Float(f64, f64),
    /// An `f32` variable's range.
    F32(f32, f32),
}

impl Range {
    /// The range `range` says for a variable of type `ty`: `None` unless its ends are
    /// numbers of the type (finite, within `f32` for an `f32`).
    #[allow(clippy::cast_possible_truncation)]
    pub fn of(range: &ast::VarRange, ty: &Ty) -> Option<Range> {
        let (low, high) = (Number::of(&range.low)?, Number::of(&range.high)?);
        match (ty, low, high) {
            (Ty::Int(_), Number::Int(low), Number::Int(high)) => Some(Range::Int(low, high)),
            (Ty::Float(ast::Prim::F32), low, high) => {
                let (low, high) = (low.float() as f32, high.float() as f32);
                (low.is_finite() && high.is_finite()).then_some(Range::F32(low, high))
            }
            (Ty::Float(_), low, high) => {
                let (low, high) = (low.float(), high.float());
                (low.is_finite() && high.is_finite()).then_some(Range::Float(low, high))
            }
            _ => None,
        }
    }

    /// Whether the range holds no value (its low end above its high end).
    pub fn is_empty(&self) -> bool {
        match *self {
            Range::Int(low, high) => low > high,
            Range::Float(low, high) => low > high,
            Range::F32(low, high) => low > high,
        }
    }

    /// Whether `number` lies in the range, judged as the variable stores it.
    #[allow(clippy::cast_possible_truncation)]
    pub fn contains(&self, number: Number) -> bool {
        match (*self, number) {
            (Range::Int(low, high), Number::Int(value)) => (low..=high).contains(&value),
            // A float for an integer: a type error, reported as one.
            (Range::Int(..), Number::Float(_)) => true,
            (Range::Float(low, high), number) => (low..=high).contains(&number.float()),
            (Range::F32(low, high), number) => (low..=high).contains(&(number.float() as f32)),
        }
    }
}

impl fmt::Display for Range {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Range::Int(low, high) => write!(f, "{low}..={high}"),
            Range::Float(low, high) => write!(f, "{low:?}..={high:?}"),
            Range::F32(low, high) => write!(f, "{low:?}..={high:?}"),
        }
    }
}

/// What an `adaptation { ... }` block says (`check::adaptation` checks it; a key not
/// written is `None`, and the runtime's default applies).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Tuning {
    /// `off;`: adaptation turned off.
    pub off: bool,
    /// `window N;`: the sliding window of periods the detector counts violations in.
    pub window: Option<u32>,
    /// `violations N;`: bad periods within the window that make a time violation.
    pub violations: Option<u32>,
    /// `hold N;`: periods ignored after every change of level (the hold-down).
    pub hold: Option<u32>,
    /// `settle N;`: consecutive spare periods before a promotion.
    pub settle: Option<u32>,
    /// `homogeneity N;` (compounds): the width of the homogeneity interval.
    pub homogeneity: Option<u32>,
    /// `selector name;` (compounds): which instance degrades or is promoted first.
    pub selector: Option<SelectorKind>,
}

/// The selectors the language names (`coolbot::adapt::Selector` implementations).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SelectorKind {
    /// `protect_priority`: `coolbot::adapt::ProtectPriority` (the default).
    ProtectPriority,
    /// `fastest_correction`: `coolbot::adapt::FastestCorrection`.
    FastestCorrection,
}

impl SelectorKind {
    /// Every selector with its name in the language.
    pub const ALL: [(&'static str, SelectorKind); 2] = [
        ("protect_priority", SelectorKind::ProtectPriority),
        ("fastest_correction", SelectorKind::FastestCorrection),
    ];
}

impl Tuning {
    /// The tuning one block says, reading only well-formed entries (the checker
    /// reports the others, and a checked model has none).
    pub fn of(block: &ast::Adaptation) -> Tuning {
        let mut tuning = Tuning::default();
        for entry in &block.entries {
            let count = match entry.value.as_ref().map(|value| &value.kind) {
                Some(ast::ExprKind::Int(n)) => u32::try_from(*n).ok(),
                _ => None,
            };
            match entry.key.name.as_str() {
                "off" => tuning.off = true,
                "window" => tuning.window = tuning.window.or(count),
                "violations" => tuning.violations = tuning.violations.or(count),
                "hold" => tuning.hold = tuning.hold.or(count),
                "settle" => tuning.settle = tuning.settle.or(count),
                "homogeneity" => tuning.homogeneity = tuning.homogeneity.or(count),
                "selector" => {
                    if let Some(ast::ExprKind::Path(path)) =
                        entry.value.as_ref().map(|value| &value.kind)
                        && let [name] = path.as_slice()
                    {
                        tuning.selector = SelectorKind::ALL
                            .iter()
                            .find(|(known, _)| *known == name.name)
                            .map(|(_, kind)| *kind);
                    }
                }
                _ => {}
            }
        }
        tuning
    }

    /// This tuning with an instance's block `over` laid on it: the keys `over` writes
    /// replace these, and `over` alone says whether adaptation is off.
    pub fn overlaid(&self, over: &Tuning) -> Tuning {
        Tuning {
            off: over.off,
            window: over.window.or(self.window),
            violations: over.violations.or(self.violations),
            hold: over.hold.or(self.hold),
            settle: over.settle.or(self.settle),
            homogeneity: over.homogeneity.or(self.homogeneity),
            selector: over.selector.or(self.selector),
        }
    }
}

/// The names of the default automaton's states (paper Figure 2).
pub const DEFAULT_STATES: &[&str] = &[
    "starting",
    "ready",
    "running",
    "suspended",
    "dead",
    "starting_error",
    "running_error",
    "end",
];

/// The values of the default variable `result`.
pub const RESULTS: &[&str] = &["none", "success", "fail"];

/// The default observable variables of every component.
pub const DEFAULT_OBSERVABLES: &[&str] = &[
    "state",
    "user_state",
    "result",
    "error",
    "cpu_time",
    "elapsed_time",
    "quality",
];

/// The default controllable variables of every component.
pub const DEFAULT_CONTROLLABLES: &[&str] = &[
    "new_state",
    "configuration",
    "period",
    "max_response",
    "priority",
];

/// The type of a rule expression: the one rule typer's output, read by `lower`
/// (which compiles each node to Rust by its type) as well as by the checks here.
#[derive(Clone, Debug, PartialEq)]
pub enum RTy {
    /// `bool`
    Bool,
    /// Any integer (rules widen every integer to one type).
    Int,
    /// `f32` or `f64`.
    Float,
    /// `String`
    Str,
    /// `Duration`
    Duration,
    /// `Time`
    Time,
    /// An enum, by its `.cool` name.
    Enum(String),
    /// `T?`
    Optional(Box<RTy>),
    /// A default automaton state.
    State,
    /// A user state of the named component, with its states.
    UserState(String, Vec<String>),
    /// `none`, `success` or `fail`.
    Result,
    /// A quality level of the named component.
    Quality(String, Vec<String>),
    /// The `none` literal.
    NoneLit,
    /// A bare name that is not a variable.
    Symbol(ast::Ident),
    /// Anything else (a packet, a list, a frequency), described: a rule cannot read
    /// it, it only compares with `none` when optional.
    Other(String),
    /// Already reported.
    Unknown,
}

impl RTy {
    /// The type as a noun without its article ("float", "optional float"); `None` for
    /// the kinds that are not named with an article (`none`, a symbol, a description).
    fn noun(&self) -> Option<String> {
        Some(match self {
            RTy::Bool => "bool".to_owned(),
            RTy::Int => "integer".to_owned(),
            RTy::Float => "float".to_owned(),
            RTy::Str => "string".to_owned(),
            RTy::Duration => "duration".to_owned(),
            RTy::Time => "time".to_owned(),
            RTy::Enum(name) => format!("`{name}` value"),
            RTy::Optional(inner) => match inner.noun() {
                Some(noun) => format!("optional {noun}"),
                None => format!("optional {inner}"),
            },
            RTy::State => "default automaton state".to_owned(),
            RTy::UserState(component, _) => format!("user state of `{component}`"),
            RTy::Result => "result".to_owned(),
            RTy::Quality(component, _) => format!("quality level of `{component}`"),
            RTy::Unknown => "unknown type".to_owned(),
            RTy::NoneLit | RTy::Symbol(_) | RTy::Other(_) => return None,
        })
    }
}

/// Every type reads the same way in messages: "a float", "a string", "an optional
/// integer", "a `Mode` value".
impl fmt::Display for RTy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(noun) = self.noun() {
            // ("a user state": the vowel of "user" is not sounded as one.)
            let vowel = noun.starts_with(['a', 'e', 'i', 'o', 'u']) && !noun.starts_with("user");
            return write!(f, "{} {noun}", if vowel { "an" } else { "a" });
        }
        match self {
            RTy::NoneLit => f.write_str("`none`"),
            RTy::Symbol(name) => write!(f, "`{}`", name.name),
            RTy::Other(description) => f.write_str(description),
            _ => Ok(()),
        }
    }
}

/// A rule expression as the checker typed it: the expression itself, node by node,
/// each node with its type and its operands (those of a unary or binary operator,
/// the items of a list; none otherwise). A bare name compared with a state, result or
/// quality level carries the type it resolved to (`State`, `UserState`, `Result`,
/// `Quality`), never `Symbol`.
#[derive(Clone, Debug, PartialEq)]
pub struct Typed {
    /// The node's type.
    pub ty: RTy,
    /// What the node is.
    pub node: Node,
    /// Its operands, in order.
    pub operands: Vec<Typed>,
}

/// What a node of a rule expression is, without its operands.
#[derive(Clone, Debug, PartialEq)]
pub enum Node {
    /// An integer literal (a sign is a [`Node::Unary`]).
    Int(u64),
    /// A floating-point literal.
    Float(f64),
    /// A string literal, unescaped.
    Str(String),
    /// `true` / `false`.
    Bool(bool),
    /// A duration literal, in nanoseconds.
    Duration(u128),
    /// A frequency literal, in hertz.
    Frequency(f64),
    /// `a`, `a.b`: a variable, an instance's variable or a symbol.
    Path(Vec<String>),
    /// `Enum::Variant`
    EnumValue {
        /// The enum type.
        enum_name: String,
        /// The variant.
        variant: String,
    },
    /// `[a, b, c]` (the items are the operands).
    List,
    /// `[value; n]` (the value is the operand).
    Repeat(u64),
    /// `none`
    None,
    /// `!e`, `-e`
    Unary(ast::UnaryOp),
    /// `a op b`
    Binary(ast::BinaryOp),
}

impl Node {
    /// The node `kind` is.
    pub fn of(kind: &ast::ExprKind) -> Node {
        use ast::ExprKind as E;
        match kind {
            E::Int(value) => Node::Int(*value),
            E::Float(value) => Node::Float(*value),
            E::Str(text) => Node::Str(text.clone()),
            E::Bool(value) => Node::Bool(*value),
            E::Duration(nanos) => Node::Duration(*nanos),
            E::Frequency(hertz) => Node::Frequency(*hertz),
            E::Path(parts) => Node::Path(parts.iter().map(|part| part.name.clone()).collect()),
            E::EnumValue { enum_name, variant } => Node::EnumValue {
                enum_name: enum_name.name.clone(),
                variant: variant.name.clone(),
            },
            E::List(_) => Node::List,
            E::Repeat(_, count) => Node::Repeat(count.value),
            E::None => Node::None,
            E::Unary(op, _) => Node::Unary(*op),
            E::Binary(op, ..) => Node::Binary(*op),
        }
    }
}

impl Typed {
    /// `expr` with every node of type [`RTy::Unknown`]: what a rule the checker did
    /// not type stays (only in a model of input with errors).
    pub fn untyped(expr: &ast::Expr) -> Typed {
        use ast::ExprKind as E;
        let operands: Vec<&ast::Expr> = match &expr.kind {
            E::List(items) => items.iter().collect(),
            E::Repeat(item, _) | E::Unary(_, item) => vec![&**item],
            E::Binary(_, left, right) => vec![&**left, &**right],
            _ => Vec::new(),
        };
        Typed {
            ty: RTy::Unknown,
            node: Node::of(&expr.kind),
            operands: operands.into_iter().map(Typed::untyped).collect(),
        }
    }
}

/// The type inside every `?` layer.
pub fn strip(ty: &RTy) -> &RTy {
    match ty {
        RTy::Optional(inner) => strip(inner),
        other => other,
    }
}
