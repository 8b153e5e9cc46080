//! The resolved components, types and converters: the one model the checks consult
//! and `lower` and `diagram` read instead of the syntax tree.
//!
//! Every name a component refers to is resolved here, once, by `build`: an instance
//! knows whether its component is a compound, an exported port carries the port it
//! reaches (through any depth of exports), a connection carries the kind of the input
//! it feeds, a mapped variable carries the type of what it maps, and a `when`
//! condition is the tree the one rule typer typed. Every setting is evaluated
//! once, here: durations and periods are [`Duration`]s, priorities and counts
//! integers, fifo and error policies enums, constant values (defaults, initial values,
//! overrides) [`Value`]s. Names stay as strings.
//!
//! Members of one kind keep their source order; members of different kinds are
//! held apart (a checked component has at most one `timing`, `configuration`,
//! automaton, `recovery` and `restart` block).

use std::collections::BTreeMap;

use super::types::{
    Declaration, Declared, DefaultFrom, InputKind, OutputKind, Port, PortKind, Range, Tuning, Ty,
    Typed,
};
use crate::ast::{self, FileId, Span};
use crate::ros::{Message, TypeHash, TypeName};

pub(crate) use crate::ast::{BinaryOp, ComponentKind, Prim, UnaryOp, VarKind};

/// A component, resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct Component {
    /// Its name.
    pub name: String,
    /// The file that defines it.
    pub file: FileId,
    /// Atomic or compound.
    pub kind: ComponentKind,
    /// Its doc comment.
    pub doc: Vec<String>,
    /// The doc comments written after it on its members' subjects
    /// (`docs/language.md`, "Lexical rules").
    pub notes: Vec<Note>,
    /// `link` members, in source order.
    pub links: Vec<Link>,
    /// Input ports, in source order.
    pub inputs: Vec<Input>,
    /// Output ports, in source order.
    pub outputs: Vec<Output>,
    /// Own and mapped variables, in source order.
    pub variables: Vec<Variable>,
    /// The `configuration { ... }` block's fields, when there is one.
    pub configuration: Option<Vec<Field>>,
    /// The `timing { ... }` block's entries, when there is one.
    pub timing: Option<Vec<TimingEntry>>,
    /// The user automaton (atomic) or supervisor (compound), when written.
    pub automaton: Option<Automaton>,
    /// Exceptions, in source order.
    pub exceptions: Vec<Exception>,
    /// Instances (compounds), in source order.
    pub instances: Vec<Instance>,
    /// `redundant a, b;` groups.
    pub redundant: Vec<Redundant>,
    /// `thread name { a, b }` execution groups, in source order.
    pub threads: Vec<Thread>,
    /// `on error instance: policy;` members, in source order.
    pub policies: Vec<Policy>,
    /// `connect` members, in source order.
    pub connections: Vec<Connection>,
    /// The `recovery { ... }` block.
    pub recovery: Option<Recovery>,
    /// The `restart { ... }` block.
    pub restart: Option<Restart>,
    /// Its own `adaptation { ... }` tuning (the default when it has none).
    pub adaptation: Tuning,
}

impl Component {
    /// A component with no member: what an unknown name resolves to, what a
    /// component resolves to inside its own containment cycle (which the checker
    /// reports), and what building a component starts from.
    pub(crate) fn empty(name: &str) -> Component {
        Component {
            name: name.to_owned(),
            file: FileId(0),
            kind: ComponentKind::Atomic,
            doc: Vec::new(),
            notes: Vec::new(),
            links: Vec::new(),
            inputs: Vec::new(),
            outputs: Vec::new(),
            variables: Vec::new(),
            configuration: None,
            timing: None,
            automaton: None,
            exceptions: Vec::new(),
            instances: Vec::new(),
            redundant: Vec::new(),
            threads: Vec::new(),
            policies: Vec::new(),
            connections: Vec::new(),
            recovery: None,
            restart: None,
            adaptation: Tuning::default(),
        }
    }

    /// The input `name` as others see it: the first one declared with that name
    /// whose kind is known (an export's is the port it reaches).
    pub(crate) fn input(&self, name: &str) -> Option<Port> {
        self.inputs
            .iter()
            .filter(|input| input.name == name)
            .find_map(Input::seen)
    }

    /// The output `name` as others see it (as for [`Component::input`]).
    pub(crate) fn output(&self, name: &str) -> Option<Port> {
        self.outputs
            .iter()
            .filter(|output| output.name == name)
            .find_map(Output::seen)
    }

    /// Every input others see, by name.
    pub(crate) fn input_ports(&self) -> BTreeMap<&str, Port> {
        let mut ports = BTreeMap::new();
        for input in &self.inputs {
            if let Some(port) = input.seen() {
                ports.entry(input.name.as_str()).or_insert(port);
            }
        }
        ports
    }

    /// Every output others see, by name.
    pub(crate) fn output_ports(&self) -> BTreeMap<&str, Port> {
        let mut ports = BTreeMap::new();
        for output in &self.outputs {
            if let Some(port) = output.seen() {
                ports.entry(output.name.as_str()).or_insert(port);
            }
        }
        ports
    }

    /// The variable `name` (the first declared with that name).
    pub(crate) fn variable(&self, name: &str) -> Option<&Variable> {
        self.variables.iter().find(|variable| variable.name == name)
    }

    /// Every variable by name (the first declared with each name).
    pub(crate) fn variables_by_name(&self) -> BTreeMap<&str, &Variable> {
        let mut variables = BTreeMap::new();
        for variable in &self.variables {
            variables.entry(variable.name.as_str()).or_insert(variable);
        }
        variables
    }

    /// Every configuration field by name (the first declared with each name).
    pub(crate) fn fields_by_name(&self) -> BTreeMap<&str, &Ty> {
        let mut fields = BTreeMap::new();
        for field in self.configuration.iter().flatten() {
            fields.entry(field.name.as_str()).or_insert(&field.ty);
        }
        fields
    }

    /// The user automaton's states, each once, in source order.
    pub(crate) fn user_states(&self) -> Vec<String> {
        let mut states: Vec<String> = Vec::new();
        for state in self.automaton.iter().flat_map(|a| &a.states) {
            if !states.contains(&state.name) {
                states.push(state.name.clone());
            }
        }
        states
    }

    /// The quality levels of its `timing` block, best first.
    pub(crate) fn quality(&self) -> Vec<String> {
        self.timing
            .iter()
            .flatten()
            .filter_map(|entry| match entry {
                TimingEntry::Quality(levels) => Some(levels.iter().cloned()),
                _ => None,
            })
            .flatten()
            .collect()
    }
}

/// An input port.
#[derive(Clone, Debug, PartialEq)]
pub struct Input {
    /// Its doc comment.
    pub doc: Vec<String>,
    /// Its name.
    pub name: String,
    /// `= instance.port`: the instance port it exports (compounds).
    pub export: Option<PortRef>,
    /// The declared port: its own declaration, or for an export the declaration it
    /// reaches through every level of exports (`None` only if that cannot be
    /// followed, which a checked model does not have).
    pub port: Option<Declared<InputKind>>,
    /// Where it is written (a compound's builder steps follow source order).
    pub span: Span,
}

impl Input {
    /// The port as others see it (`None` when its kind is not known).
    fn seen(&self) -> Option<Port> {
        let declared = self.port.as_ref()?;
        Some(Port {
            declared: Declaration::Input(declared.kind.clone()),
            pull: declared.pull,
            span: self.span,
        })
    }
}

/// An output port.
#[derive(Clone, Debug, PartialEq)]
pub struct Output {
    /// Its doc comment.
    pub doc: Vec<String>,
    /// Its name.
    pub name: String,
    /// `= instance.port`: the instance port it exports (compounds).
    pub export: Option<PortRef>,
    /// The declared port (through exports, as for [`Input::port`]).
    pub port: Option<Declared<OutputKind>>,
    /// Where it is written.
    pub span: Span,
}

impl Output {
    /// The port as others see it (`None` when its kind is not known).
    fn seen(&self) -> Option<Port> {
        let declared = self.port.as_ref()?;
        Some(Port {
            declared: Declaration::Output(declared.kind.clone()),
            pull: declared.pull,
            span: self.span,
        })
    }
}

/// `instance.port` or a compound's own `port`, resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct PortRef {
    /// The instance, `None` for the compound's own port.
    pub instance: Option<InstanceRef>,
    /// The port name.
    pub port: String,
}

/// A reference to an instance of the same compound.
#[derive(Clone, Debug, PartialEq)]
pub struct InstanceRef {
    /// The instance's name.
    pub name: String,
    /// Its component is a compound.
    pub compound: bool,
}

/// A variable.
#[derive(Clone, Debug, PartialEq)]
pub struct Variable {
    /// Its doc comment.
    pub doc: Vec<String>,
    /// Its name.
    pub name: String,
    /// Observable, controllable or local.
    pub kind: VarKind,
    /// The type as written (`None` for a mapped variable).
    pub written: Option<Ty>,
    /// The initial value, when written (`None` for a mapped variable).
    pub value: Option<Value>,
    /// A mapped variable's path (`["motion", "odometry"]`).
    pub mapping: Option<Vec<String>>,
    /// The type: as written, or that of the instance variable a mapping names
    /// (through mappings of nested compounds); `None` for a mapping of a default
    /// variable (`motion.state`).
    pub ty: Option<Ty>,
    /// `in low..=high`, its ends evaluated (an own controllable number only).
    pub range: Option<Range>,
    /// Where it is written (members of different kinds interleave by it).
    pub span: Span,
}

impl Variable {
    /// Its type, [`Ty::Unknown`] when it has none that resolved.
    pub(crate) fn resolved_ty(&self) -> Ty {
        self.ty.clone().unwrap_or(Ty::Unknown)
    }
}

/// A configuration field.
#[derive(Clone, Debug, PartialEq)]
pub struct Field {
    /// Its doc comment.
    pub doc: Vec<String>,
    /// Its name.
    pub name: String,
    /// Its type.
    pub ty: Ty,
    /// Its default, when written.
    pub default: Option<Value>,
}

/// One entry of a `timing` block.
#[derive(Clone, Debug, PartialEq)]
pub enum TimingEntry {
    /// `period lo;` or `period lo..hi;`
    Period(Duration, Option<Duration>),
    /// `max_response D;`
    MaxResponse(Duration),
    /// `priority N;`
    Priority(u8),
    /// `quality a, b, c;` best first.
    Quality(Vec<String>),
}

/// A state or an input port of the same component, by name and resolved to its
/// index (in the automaton's states, or in [`Component::inputs`]); prints as its
/// name.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Ref {
    /// The name as written.
    pub name: String,
    /// Its index (0 if it did not resolve, which a checked model does not have).
    pub index: usize,
}

impl std::fmt::Display for Ref {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name)
    }
}

/// A user automaton or supervisor.
#[derive(Clone, Debug, PartialEq)]
pub struct Automaton {
    /// The initial state.
    pub initial: Option<Ref>,
    /// The states, in source order.
    pub states: Vec<State>,
}

/// A state.
#[derive(Clone, Debug, PartialEq)]
pub struct State {
    /// Its doc comment.
    pub doc: Vec<String>,
    /// Its name.
    pub name: String,
    /// Sections and transitions, in source order.
    pub members: Vec<StateMember>,
    /// The doc comment of each member (`members[i]`'s is `member_docs[i]`; empty
    /// when none was written).
    pub member_docs: Vec<Vec<String>>,
}

/// A doc comment written after a component on one of its members' subjects.
#[derive(Clone, Debug, PartialEq)]
pub struct Note {
    /// What it is about.
    pub subject: String,
    /// The doc comment.
    pub doc: Vec<String>,
}

/// A `link` member: a dependency of the generated crate.
#[derive(Clone, Debug, PartialEq)]
pub enum Link {
    /// `link crate "name" = spec;`
    Crate {
        /// The crate's name.
        name: String,
        /// Its version or table.
        spec: CrateSpec,
    },
    /// `link system "name";`
    System(String),
}

/// The right-hand side of `link crate "name" = ...`.
#[derive(Clone, Debug, PartialEq)]
pub enum CrateSpec {
    /// `"4"`: a version requirement.
    Version(String),
    /// `{ version = "0.33", features = ["x"] }`: the keys as written, in order.
    Table(Vec<(String, TableValue)>),
}

/// A value in a crate table.
#[derive(Clone, Debug, PartialEq)]
pub enum TableValue {
    /// A string (a dotted name is its text).
    Str(String),
    /// `true` or `false`.
    Bool(bool),
    /// An integer.
    Int(u64),
    /// A number with a point.
    Float(f64),
    /// `[a, b]`
    List(Vec<TableValue>),
}

impl TableValue {
    /// The value `expr` says (an empty string for what a table cannot hold, which
    /// the checker reports).
    pub fn of(expr: &ast::Expr) -> TableValue {
        match &expr.kind {
            ast::ExprKind::Str(text) => TableValue::Str(text.clone()),
            ast::ExprKind::Bool(value) => TableValue::Bool(*value),
            ast::ExprKind::Int(value) => TableValue::Int(*value),
            ast::ExprKind::Float(value) => TableValue::Float(*value),
            ast::ExprKind::List(items) => {
                TableValue::List(items.iter().map(TableValue::of).collect())
            }
            ast::ExprKind::Path(parts) => TableValue::Str(
                parts
                    .iter()
                    .map(|part| part.name.as_str())
                    .collect::<Vec<_>>()
                    .join("."),
            ),
            _ => TableValue::Str(String::new()),
        }
    }
}

/// `exception name ["description"] [{ plan }];`
#[derive(Clone, Debug, PartialEq)]
pub struct Exception {
    /// Its doc comment.
    pub doc: Vec<String>,
    /// Its name.
    pub name: String,
    /// Its description, when written.
    pub description: Option<String>,
    /// Its continuity plan, in order.
    pub plan: Vec<PlanStep>,
}

/// One step of a continuity plan.
#[derive(Clone, Debug, PartialEq)]
pub enum PlanStep {
    /// `retry N every D;`
    Retry {
        /// How many times.
        count: u64,
        /// The delay between attempts.
        every: Duration,
    },
    /// `goto state;`
    Goto(Ref),
    /// `ignore;`
    Ignore,
    /// `degrade;`
    Degrade,
}

/// A section or transition of a state.
#[derive(Clone, Debug, PartialEq)]
pub enum StateMember {
    /// `entry;`
    Entry,
    /// `exit;`
    Exit,
    /// `periodic;` or `periodic D;`
    Periodic(Option<Duration>),
    /// `on port -> target;`
    On {
        /// The input port.
        port: Ref,
        /// The target state.
        target: Ref,
    },
    /// `after D [without port] -> target;`
    After {
        /// The delay.
        delay: Duration,
        /// The watched port.
        without: Option<Ref>,
        /// The target state.
        target: Ref,
    },
    /// `may -> a, b;`
    May(Vec<Ref>),
    /// `when condition -> target;`
    When {
        /// The condition, typed by the rule typer (every node of an untyped rule,
        /// which a checked model does not have, is [`RTy::Unknown`](super::RTy)).
        condition: Typed,
        /// Where the condition is written.
        span: Span,
        /// The target state.
        target: Ref,
    },
}

/// An instance of a component inside a compound.
#[derive(Clone, Debug, PartialEq)]
pub struct Instance {
    /// Its name.
    pub name: String,
    /// Its component's name ([`crate::Checked::component`] finds it).
    pub component: String,
    /// Its component is a compound.
    pub compound: bool,
    /// `on "node"`.
    pub node: Option<String>,
    /// `substitutes primary`.
    pub substitutes: Option<InstanceRef>,
    /// The policy of `on error instance: policy;`.
    pub on_error: Option<ErrorPolicy>,
    /// `{ name = value; ... }` overrides, in order.
    pub overrides: Vec<Override>,
    /// Its own `timing { ... }` entries, when written.
    pub timing: Option<Vec<TimingEntry>>,
    /// Its adaptation tuning when it has an `adaptation` block: its component's with
    /// the instance's laid on it.
    pub tuning: Option<Tuning>,
    /// Where it is written.
    pub span: Span,
}

/// `name = value;` in an instance's block.
#[derive(Clone, Debug, PartialEq)]
pub struct Override {
    /// The configuration field or controllable variable.
    pub name: String,
    /// The value.
    pub value: Value,
}

/// `redundant a, b;`
#[derive(Clone, Debug, PartialEq)]
pub struct Redundant {
    /// The instances, by name.
    pub members: Vec<String>,
    /// Where it is written.
    pub span: Span,
}

/// `thread name { a, b }`: instances on one thread, an execution group.
#[derive(Clone, Debug, PartialEq)]
pub struct Thread {
    /// The group's name.
    pub name: String,
    /// The instances, by name, in the order written.
    pub members: Vec<String>,
    /// Where it is written.
    pub span: Span,
}

/// `on error instance: policy;`
#[derive(Clone, Debug, PartialEq)]
pub struct Policy {
    /// The instance.
    pub instance: String,
    /// The policy.
    pub policy: ErrorPolicy,
    /// Where it is written.
    pub span: Span,
}

/// `connect from -> to [via Converter];`
#[derive(Clone, Debug, PartialEq)]
pub struct Connection {
    /// The output end.
    pub from: PortRef,
    /// The input end.
    pub to: PortRef,
    /// The converter, by name.
    pub via: Option<String>,
    /// The kind of the input `to` reaches (the connection's kind).
    pub kind: Option<PortKind>,
}

/// `recovery { retry every D; deadline D; }`
#[derive(Clone, Debug, PartialEq)]
pub struct Recovery {
    /// `retry every D`, when written.
    pub retry_every: Option<Duration>,
    /// `deadline D`, when written.
    pub deadline: Option<Duration>,
    /// Where it is written.
    pub span: Span,
}

impl Recovery {
    /// Nanoseconds between restarts of the queued instances when `retry every` is not
    /// written.
    pub const RETRY_EVERY_NANOS: u64 = 500_000_000;
    /// Nanoseconds an instance may stay queued when `deadline` is not written.
    pub const DEADLINE_NANOS: u64 = 5_000_000_000;

    /// Nanoseconds between restarts of the queued instances: as written, or the
    /// default.
    pub fn retry_every_nanos(&self) -> u64 {
        self.retry_every
            .map_or(Self::RETRY_EVERY_NANOS, |every| every.nanos)
    }

    /// Nanoseconds an instance may stay queued: as written, or the default.
    pub fn deadline_nanos(&self) -> u64 {
        self.deadline
            .map_or(Self::DEADLINE_NANOS, |deadline| deadline.nanos)
    }
}

/// `restart { limit N in D; backoff D..D; }`
#[derive(Clone, Debug, PartialEq)]
pub struct Restart {
    /// `limit N in D`: at most `N` restarts of one instance within any `D`.
    pub limit: Option<(u32, Duration)>,
    /// `backoff D..D`: the first wait and the longest.
    pub backoff: Option<(Duration, Duration)>,
    /// Where it is written.
    pub span: Span,
}

/// A length of time, evaluated once: a duration (`500ms`) or, where a period is
/// meant, a frequency (`100Hz`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Duration {
    /// Nanoseconds: a frequency's period rounded to the nearest; at most `u64::MAX`.
    pub nanos: u64,
    /// How it is written, to print it back.
    pub written: Written,
}

/// How a [`Duration`] is written.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Written {
    /// A duration literal, in nanoseconds.
    Nanos(u128),
    /// A frequency literal, in hertz.
    Hertz(f64),
}

/// A duration in the largest unit that divides it (`2s`, `500ms`, `1min`).
pub fn duration_text(nanos: u128) -> String {
    const UNITS: [(u128, &str); 5] = [
        (60_000_000_000, "min"),
        (1_000_000_000, "s"),
        (1_000_000, "ms"),
        (1_000, "us"),
        (1, "ns"),
    ];
    for (size, unit) in UNITS {
        if nanos != 0 && nanos.is_multiple_of(size) {
            return format!("{}{unit}", nanos / size);
        }
    }
    "0s".to_owned()
}

impl Duration {
    /// Zero, written `0s`: what an unevaluable delay becomes in a model built from
    /// input with errors.
    pub const ZERO: Duration = Duration {
        nanos: 0,
        written: Written::Nanos(0),
    };

    /// The duration a duration or frequency literal says (`None` for any other
    /// expression, or a frequency that is not positive: errors the checker reports).
    pub fn of(expr: &ast::Expr) -> Option<Duration> {
        match expr.kind {
            ast::ExprKind::Duration(nanos) => Some(Duration {
                nanos: u64::try_from(nanos).unwrap_or(u64::MAX),
                written: Written::Nanos(nanos),
            }),
            ast::ExprKind::Frequency(hertz) if hertz > 0.0 => Some(Duration {
                nanos: (1e9 / hertz).round() as u64,
                written: Written::Hertz(hertz),
            }),
            _ => None,
        }
    }
}

/// A constant value: a default, an initial value or an override. Its type is that of
/// the field or variable it fills (an integer filling a float stays an `Int`).
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// `true` or `false`.
    Bool(bool),
    /// An integer, its sign applied.
    Int(i128),
    /// A number with a point, its sign applied.
    Float(f64),
    /// A string.
    Str(String),
    /// A duration.
    Duration(Duration),
    /// `Enum::Variant`
    Enum {
        /// The enum's name.
        ty: String,
        /// The variant's name.
        variant: String,
    },
    /// `[a, b]`: the items of a list or an array.
    List(Vec<Value>),
    /// `[value; n]`
    Repeat(Box<Value>, u64),
    /// `none`
    None,
    /// Not a constant (a path, an operator): what the checker rejects, found only in
    /// a model built from input with errors.
    Invalid,
}

impl Value {
    /// The value `expr` says.
    pub fn of(expr: &ast::Expr) -> Value {
        match &expr.kind {
            ast::ExprKind::Bool(value) => Value::Bool(*value),
            ast::ExprKind::Int(value) => Value::Int((*value).into()),
            ast::ExprKind::Float(value) => Value::Float(*value),
            ast::ExprKind::Str(text) => Value::Str(text.clone()),
            ast::ExprKind::Duration(_) | ast::ExprKind::Frequency(_) => {
                Duration::of(expr).map_or(Value::Invalid, Value::Duration)
            }
            ast::ExprKind::EnumValue { enum_name, variant } => Value::Enum {
                ty: enum_name.name.clone(),
                variant: variant.name.clone(),
            },
            ast::ExprKind::List(items) => Value::List(items.iter().map(Value::of).collect()),
            ast::ExprKind::Repeat(item, count) => {
                Value::Repeat(Box::new(Value::of(item)), count.value)
            }
            ast::ExprKind::None => Value::None,
            ast::ExprKind::Unary(UnaryOp::Neg, inner) => match Value::of(inner) {
                Value::Int(value) => Value::Int(-value),
                Value::Float(value) => Value::Float(-value),
                _ => Value::Invalid,
            },
            ast::ExprKind::Unary(UnaryOp::Not, _)
            | ast::ExprKind::Binary(..)
            | ast::ExprKind::Path(_) => Value::Invalid,
        }
    }
}

/// What a compound does when an instance fails (`on error instance: policy;`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorPolicy {
    /// `propagate`: the compound fails too.
    Propagate,
    /// `restart`: the instance is restarted, within the compound's budget.
    Restart,
    /// `substitute`: its substitute takes its place; it waits in the recovery queue.
    Substitute,
    /// `ignore`: nothing happens; the instance stays in `running_error`.
    Ignore,
}

impl ErrorPolicy {
    /// Every policy with its name in the language.
    pub const ALL: [(&'static str, ErrorPolicy); 4] = [
        ("propagate", ErrorPolicy::Propagate),
        ("restart", ErrorPolicy::Restart),
        ("substitute", ErrorPolicy::Substitute),
        ("ignore", ErrorPolicy::Ignore),
    ];

    /// The policy named `name`.
    pub fn named(name: &str) -> Option<ErrorPolicy> {
        named(&Self::ALL, name)
    }

    /// Its name in the language.
    pub fn name(self) -> &'static str {
        name_of(&Self::ALL, self)
    }
}

fn named<T: Copy>(all: &[(&'static str, T)], name: &str) -> Option<T> {
    all.iter()
        .find(|(known, _)| *known == name)
        .map(|(_, value)| *value)
}

fn name_of<T: Copy + PartialEq>(all: &[(&'static str, T)], value: T) -> &'static str {
    all.iter()
        .find(|(_, known)| *known == value)
        .map_or("", |(name, _)| name)
}

/// A type definition, resolved.
#[derive(Clone, Debug, PartialEq)]
pub enum TypeDef {
    /// `packet Name { fields }`
    Packet(Packet),
    /// `enum Name { variants }`
    Enum(Enum),
    /// `extern packet Name = "path";`
    Extern(Extern),
    /// `import ros "pkg/msg/Type" [as Name];`
    Ros(RosImport),
}

/// Whether the generated code has a default value of `ty` (its Rust type implements
/// `Default`, or coolc builds one): not an extern packet (coolc cannot see another
/// crate's type), an enum without variants, nor a packet with a field of such a type
/// and no written default. `type_def` looks a packet or enum up by name.
pub fn has_default<'t>(ty: &Ty, type_def: &dyn Fn(&str) -> Option<&'t TypeDef>) -> bool {
    fn walk<'t>(
        ty: &Ty,
        type_def: &dyn Fn(&str) -> Option<&'t TypeDef>,
        visiting: &mut Vec<String>,
    ) -> bool {
        match ty.default_from() {
            DefaultFrom::Always => true,
            DefaultFrom::Elements(inner, _) => walk(inner, type_def, visiting),
            DefaultFrom::Definition(name) => match type_def(name) {
                Some(TypeDef::Enum(e)) => !e.variants.is_empty(),
                Some(TypeDef::Packet(p)) => {
                    // A packet that holds itself by value is an error of its own
                    // (`recursive_packet`): no follow-on error.
                    if visiting.contains(&p.name) {
                        return true;
                    }
                    visiting.push(p.name.clone());
                    let result = p
                        .fields
                        .iter()
                        .all(|f| f.default.is_some() || walk(&f.ty, type_def, visiting));
                    visiting.pop();
                    result
                }
                Some(TypeDef::Ros(_)) => true,
                Some(TypeDef::Extern(_)) => false,
                // An unknown name is an error of its own: no follow-on error.
                None => true,
            },
            DefaultFrom::Never => false,
            DefaultFrom::Unknown => true,
        }
    }
    walk(ty, type_def, &mut Vec::new())
}

impl TypeDef {
    /// Its name.
    pub fn name(&self) -> &str {
        match self {
            TypeDef::Packet(packet) => &packet.name,
            TypeDef::Enum(def) => &def.name,
            TypeDef::Extern(def) => &def.name,
            TypeDef::Ros(def) => &def.name,
        }
    }
}

/// `import ros "pkg/msg/Type" [as Name];`: a name for a ROS 2 message type.
#[derive(Clone, Debug, PartialEq)]
pub struct RosImport {
    /// Its doc comment.
    pub doc: Vec<String>,
    /// The name the descriptions use.
    pub name: String,
    /// The type.
    pub ros: TypeName,
}

/// A ROS 2 message type of the crate: one imported, or one that an imported type
/// references (directly or not).
#[derive(Clone, Debug, PartialEq)]
pub struct RosMessage {
    /// Its `.msg` file, read.
    pub message: Message,
    /// Its RIHS01 type hash.
    pub hash: TypeHash,
    /// Its full message definition as a rosbag2 bag holds it: its `.msg` text, then
    /// each type it references (`crate::ros::definition`).
    pub definition: String,
}

/// `packet Name { fields }`
#[derive(Clone, Debug, PartialEq)]
pub struct Packet {
    /// Its doc comment.
    pub doc: Vec<String>,
    /// Its name.
    pub name: String,
    /// Its fields, in order.
    pub fields: Vec<Field>,
}

/// `enum Name { variants }`
#[derive(Clone, Debug, PartialEq)]
pub struct Enum {
    /// Its doc comment.
    pub doc: Vec<String>,
    /// Its name.
    pub name: String,
    /// Its variants, in order: `(doc comment, name)`.
    pub variants: Vec<(Vec<String>, String)>,
}

/// `extern packet Name = "path";`
#[derive(Clone, Debug, PartialEq)]
pub struct Extern {
    /// Its doc comment.
    pub doc: Vec<String>,
    /// Its name.
    pub name: String,
    /// The Rust path of the type.
    pub rust_path: String,
}

/// `converter Name: From -> To;`
#[derive(Clone, Debug, PartialEq)]
pub struct Converter {
    /// Its doc comment.
    pub doc: Vec<String>,
    /// Its name.
    pub name: String,
    /// The packet type it takes.
    pub from: Ty,
    /// The packet type it makes.
    pub to: Ty,
}
