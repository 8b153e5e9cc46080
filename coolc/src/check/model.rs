//! What each component offers to the others, computed from the AST.
//!
//! An [`Interface`] lists a component's ports (with kinds and packet types), its
//! variables, configuration fields, user states and quality levels. A compound's
//! exported ports and mapped variables are looked up through its instances, so the
//! interface of a compound is what its users see. Containment cycles are cut (the
//! inner interface is empty); `compound::self_containing` reports them.

use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::rc::Rc;

use crate::ast::{self, FileId, Span};
use crate::resolve::{DefKind, Symbols};

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
    fn of(def: &ast::InputDef, ty: impl Fn(&ast::Type) -> Ty) -> Option<InputKind> {
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
    fn of(def: &ast::OutputDef, ty: impl Fn(&ast::Type) -> Ty) -> Option<OutputKind> {
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

/// A variable as seen from outside.
#[derive(Clone, Debug, PartialEq)]
pub struct Var {
    /// Observable, controllable or local.
    pub kind: ast::VarKind,
    /// Its type.
    pub ty: Ty,
    /// Its range (`in low..=high`), when it is an own controllable number with one
    /// the checker accepts.
    pub range: Option<Range>,
    /// Where it is declared.
    pub span: Span,
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

/// What a component offers.
#[derive(Clone, Debug, Default)]
pub struct Interface {
    /// Input ports by name.
    pub inputs: BTreeMap<String, Port>,
    /// Output ports by name.
    pub outputs: BTreeMap<String, Port>,
    /// Own and mapped variables by name.
    pub variables: BTreeMap<String, Var>,
    /// Configuration fields by name.
    pub config: BTreeMap<String, Ty>,
    /// User automaton states, in source order.
    pub states: Vec<String>,
    /// Quality levels, best first.
    pub quality: Vec<String>,
    /// The component's own `adaptation { ... }` tuning (default when it has none).
    pub adaptation: Tuning,
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

/// The AST plus lookups and memoised interfaces.
pub struct Model<'a> {
    /// All files.
    pub files: &'a [ast::File],
    /// The top-level symbols.
    pub symbols: &'a Symbols,
    interfaces: RefCell<BTreeMap<String, Rc<Interface>>>,
    in_progress: RefCell<BTreeSet<String>>,
}

impl<'a> Model<'a> {
    /// A model over `files`.
    pub fn new(files: &'a [ast::File], symbols: &'a Symbols) -> Self {
        Model {
            files,
            symbols,
            interfaces: RefCell::default(),
            in_progress: RefCell::default(),
        }
    }

    /// The component named `name`, with its file.
    pub fn component(&self, name: &str) -> Option<(FileId, &'a ast::Component)> {
        let def = self.symbols.defs.get(name)?;
        match self.files.get(def.file.0 as usize)?.items.get(def.item)? {
            ast::Item::Component(component) => Some((def.file, component)),
            _ => None,
        }
    }

    /// The enum named `name`.
    pub fn enum_def(&self, name: &str) -> Option<&'a ast::EnumDef> {
        let def = self.symbols.defs.get(name)?;
        match self.files.get(def.file.0 as usize)?.items.get(def.item)? {
            ast::Item::Enum(def) => Some(def),
            _ => None,
        }
    }

    /// The `import ros` that defines `name`.
    pub fn ros_import(&self, name: &str) -> Option<&'a ast::RosImport> {
        let def = self.symbols.defs.get(name)?;
        match self.files.get(def.file.0 as usize)?.items.get(def.item)? {
            ast::Item::RosImport(import) => Some(import),
            _ => None,
        }
    }

    /// The converter named `name`.
    pub fn converter(&self, name: &str) -> Option<(FileId, &'a ast::Converter)> {
        let def = self.symbols.defs.get(name)?;
        match self.files.get(def.file.0 as usize)?.items.get(def.item)? {
            ast::Item::Converter(converter) => Some((def.file, converter)),
            _ => None,
        }
    }

    /// Resolves a written type (unknown names give [`Ty::Unknown`]).
    pub fn ty(&self, ty: &ast::Type) -> Ty {
        match &ty.kind {
            ast::TypeKind::Prim(prim) => match prim {
                ast::Prim::Bool => Ty::Bool,
                ast::Prim::F32 | ast::Prim::F64 => Ty::Float(*prim),
                ast::Prim::String => Ty::Str,
                ast::Prim::Time => Ty::Time,
                ast::Prim::Duration => Ty::Duration,
                other => Ty::Int(*other),
            },
            ast::TypeKind::Named(name) => {
                match self.symbols.defs.get(&name.name).map(|def| def.kind) {
                    Some(DefKind::Packet) => Ty::Packet(name.name.clone()),
                    Some(DefKind::Enum) => Ty::Enum(name.name.clone()),
                    Some(DefKind::ExternPacket) => Ty::Extern(name.name.clone()),
                    Some(DefKind::RosMessage) => match self.ros_import(&name.name) {
                        Some(import) => Ty::Ros {
                            name: name.name.clone(),
                            ros: import.ros_name.value.clone(),
                        },
                        None => Ty::Unknown,
                    },
                    _ => Ty::Unknown,
                }
            }
            ast::TypeKind::List(inner) => Ty::List(Box::new(self.ty(inner))),
            ast::TypeKind::Array(inner, size) => Ty::Array(Box::new(self.ty(inner)), size.value),
            ast::TypeKind::Optional(inner) => Ty::Optional(Box::new(self.ty(inner))),
        }
    }

    /// The interface of component `name` (empty when unknown or when asked again
    /// while being computed, i.e. inside a containment cycle).
    pub fn interface(&self, name: &str) -> Rc<Interface> {
        if let Some(found) = self.interfaces.borrow().get(name) {
            return found.clone();
        }
        let Some((_, component)) = self.component(name) else {
            return Rc::new(Interface::default());
        };
        if !self.in_progress.borrow_mut().insert(name.to_owned()) {
            return Rc::new(Interface::default());
        }
        let interface = Rc::new(self.compute(component));
        self.in_progress.borrow_mut().remove(name);
        self.interfaces
            .borrow_mut()
            .insert(name.to_owned(), interface.clone());
        interface
    }

    /// The component type of instance `instance` inside `component`.
    pub fn instance<'c>(
        component: &'c ast::Component,
        instance: &str,
    ) -> Option<&'c ast::Instance> {
        component.members.iter().find_map(|member| match member {
            ast::Member::Instance(found) if found.name.name == instance => Some(found),
            _ => None,
        })
    }

    fn compute(&self, component: &ast::Component) -> Interface {
        let mut interface = Interface::default();
        for member in &component.members {
            match member {
                ast::Member::Input(input) => {
                    let port = match &input.def {
                        ast::InputDef::Export(target) => self.exported(component, target, true),
                        def => InputKind::of(def, |ty| self.ty(ty)).map(|kind| Port {
                            declared: Declaration::Input(kind),
                            pull: input.pull.is_some(),
                            span: input.span,
                        }),
                    };
                    if let Some(mut port) = port {
                        port.span = input.span;
                        interface
                            .inputs
                            .entry(input.name.name.clone())
                            .or_insert(port);
                    }
                }
                ast::Member::Output(output) => {
                    let port = match &output.def {
                        ast::OutputDef::Export(target) => self.exported(component, target, false),
                        def => OutputKind::of(def, |ty| self.ty(ty)).map(|kind| Port {
                            declared: Declaration::Output(kind),
                            pull: output.pull.is_some(),
                            span: output.span,
                        }),
                    };
                    if let Some(mut port) = port {
                        port.span = output.span;
                        interface
                            .outputs
                            .entry(output.name.name.clone())
                            .or_insert(port);
                    }
                }
                ast::Member::Variable(variable) => {
                    let ty = match (&variable.ty, &variable.value) {
                        (Some(ty), _) => self.ty(ty),
                        (None, Some(value)) => self
                            .mapped_variable(component, value)
                            .unwrap_or(Ty::Unknown),
                        (None, None) => Ty::Unknown,
                    };
                    interface
                        .variables
                        .entry(variable.name.name.clone())
                        .or_insert(Var {
                            kind: variable.kind,
                            range: variable
                                .range
                                .as_ref()
                                .filter(|_| {
                                    variable.kind == ast::VarKind::Controllable
                                        && variable.ty.is_some()
                                })
                                .and_then(|range| Range::of(range, &ty)),
                            ty,
                            span: variable.span,
                        });
                }
                ast::Member::Configuration(configuration) => {
                    for field in &configuration.fields {
                        interface
                            .config
                            .entry(field.name.name.clone())
                            .or_insert_with(|| self.ty(&field.ty));
                    }
                }
                ast::Member::Automaton(automaton) => {
                    for state in &automaton.states {
                        if !interface.states.contains(&state.name.name) {
                            interface.states.push(state.name.name.clone());
                        }
                    }
                }
                // The first block (a second one is an error).
                ast::Member::Adaptation(block) if interface.adaptation == Tuning::default() => {
                    interface.adaptation = Tuning::of(block);
                }
                ast::Member::Timing(timing) => {
                    for entry in &timing.entries {
                        if let ast::TimingEntry::Quality(levels, _) = entry {
                            interface
                                .quality
                                .extend(levels.iter().map(|level| level.name.clone()));
                        }
                    }
                }
                _ => {}
            }
        }
        interface
    }

    /// The port an export names, through the instance's component.
    pub fn exported(
        &self,
        component: &ast::Component,
        target: &ast::PortRef,
        input: bool,
    ) -> Option<Port> {
        let instance = Self::instance(component, &target.instance.as_ref()?.name)?;
        let inner = self.interface(&instance.component.name);
        let ports = if input { &inner.inputs } else { &inner.outputs };
        ports.get(&target.port.name).cloned()
    }

    /// The type of the instance variable a mapped variable names.
    pub fn mapped_variable(&self, component: &ast::Component, value: &ast::Expr) -> Option<Ty> {
        let ast::ExprKind::Path(segments) = &value.kind else {
            return None;
        };
        let [instance, variable] = segments.as_slice() else {
            return None;
        };
        let instance = Self::instance(component, &instance.name)?;
        let inner = self.interface(&instance.component.name);
        inner
            .variables
            .get(&variable.name)
            .map(|var| var.ty.clone())
    }
}
