//! Resolves the model from the syntax trees: [`Model`] looks names up in them and
//! builds each component once, when it is first asked for (exports are followed and
//! mapped variables typed through the components they reach, each built once too).
//! Inside its own containment cycle a component is empty; `compound::self_containing`
//! reports the cycle. This is the only place where names are looked up and settings
//! evaluated. It never fails: on input with errors what cannot be resolved is left
//! `None`, and a value that cannot be evaluated is left out (a delay is zero).

use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet};
use std::rc::Rc;

use super::component::{
    Automaton, Component, Connection, Converter, CrateSpec, Duration, Enum, ErrorPolicy, Exception,
    Extern, Field, Input, Instance, InstanceRef, Link, Note, Output, Override, Packet, PlanStep,
    Policy, PortRef, Recovery, Redundant, Ref, Restart, RosImport, State, StateMember, TableValue,
    Thread, TimingEntry, TypeDef, Value, Variable,
};
use super::types::{Declared, InputKind, OutputKind, PortKind, Range, Tuning, Ty, Typed};
use crate::ast::{self, FileId, Span};
use crate::resolve::{DefKind, Symbols};

/// The syntax trees with their lookups, and every component resolved so far.
pub(crate) struct Model<'a> {
    /// All files.
    pub files: &'a [ast::File],
    /// The top-level symbols.
    pub symbols: &'a Symbols,
    components: RefCell<BTreeMap<String, Rc<Component>>>,
    in_progress: RefCell<BTreeSet<String>>,
}

impl<'a> Model<'a> {
    /// A model over `files`.
    pub fn new(files: &'a [ast::File], symbols: &'a Symbols) -> Self {
        Model {
            files,
            symbols,
            components: RefCell::default(),
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

    /// Component `name`, resolved (empty when unknown, or when asked for again while
    /// it is being resolved, i.e. inside a containment cycle).
    pub fn resolved(&self, name: &str) -> Rc<Component> {
        if let Some(found) = self.components.borrow().get(name) {
            return found.clone();
        }
        let Some((file, component)) = self.component(name) else {
            return Rc::new(Component::empty(name));
        };
        if !self.in_progress.borrow_mut().insert(name.to_owned()) {
            return Rc::new(Component::empty(name));
        }
        let resolved = Rc::new(self.build(file, component));
        self.in_progress.borrow_mut().remove(name);
        self.components
            .borrow_mut()
            .insert(name.to_owned(), resolved.clone());
        resolved
    }

    /// Component `name`, resolved, when a component of that name is declared.
    pub fn known(&self, name: &str) -> Option<Rc<Component>> {
        self.component(name).map(|_| self.resolved(name))
    }

    /// Every component, resolved, in source order (files in `FileId` order), each
    /// once (the one the symbol table names), with what needs the whole model: each
    /// connection's kind, each instance's tuning over its component's, each `when`
    /// condition's typed tree (from `rules`, by file and span).
    pub fn finish(self, rules: &BTreeMap<(FileId, Span), Typed>) -> Vec<Component> {
        let mut names = Vec::new();
        for file in self.files {
            for item in &file.items {
                if let ast::Item::Component(component) = item
                    && self
                        .component(&component.name.name)
                        .is_some_and(|(at, _)| at == file.id)
                {
                    names.push(component.name.name.clone());
                }
            }
        }
        // What each component's connections and instances reach.
        let reached: Vec<Reached> = names
            .iter()
            .map(|name| {
                let component = self.resolved(name);
                let kinds = component
                    .connections
                    .iter()
                    .map(|connection| self.connection_kind(&component, &connection.to))
                    .collect();
                let tunings = component
                    .instances
                    .iter()
                    .map(|instance| {
                        let own = instance.tuning.as_ref()?;
                        Some(self.resolved(&instance.component).adaptation.overlaid(own))
                    })
                    .collect();
                Reached { kinds, tunings }
            })
            .collect();
        let mut memo = self.components.into_inner();
        names
            .iter()
            .zip(reached)
            .filter_map(|(name, Reached { kinds, tunings })| {
                let mut component =
                    Rc::try_unwrap(memo.remove(name)?).unwrap_or_else(|shared| (*shared).clone());
                for (connection, kind) in component.connections.iter_mut().zip(kinds) {
                    connection.kind = kind;
                }
                for (instance, tuning) in component.instances.iter_mut().zip(tunings) {
                    instance.tuning = tuning;
                }
                let file = component.file;
                for state in component.automaton.iter_mut().flat_map(|a| &mut a.states) {
                    for member in &mut state.members {
                        if let StateMember::When {
                            condition, span, ..
                        } = member
                            && let Some(typed) = rules.get(&(file, *span))
                        {
                            *condition = typed.clone();
                        }
                    }
                }
                Some(component)
            })
            .collect()
    }

    /// The kind of the input a connection's `to` end reaches: an instance's input,
    /// or for a bare port the compound's own.
    fn connection_kind(&self, component: &Component, to: &PortRef) -> Option<PortKind> {
        let owner = match &to.instance {
            Some(instance) => {
                let instance = component
                    .instances
                    .iter()
                    .find(|found| found.name == instance.name)?;
                self.resolved(&instance.component)
            }
            None => self.resolved(&component.name),
        };
        Some(owner.input(&to.port)?.kind())
    }

    /// Every packet, enum, extern packet and ROS import, then every converter, in source
    /// order (files in `FileId` order), each once (the one the symbol table names).
    pub fn types(&self) -> (Vec<TypeDef>, Vec<Converter>) {
        let model = self;
        let named_here = |file: FileId, name: &str| {
            self.symbols
                .defs
                .get(name)
                .is_some_and(|def| def.file == file)
        };
        let mut types = Vec::new();
        let mut converters = Vec::new();
        for file in self.files {
            for item in &file.items {
                match item {
                    ast::Item::Packet(packet) if named_here(file.id, &packet.name.name) => {
                        types.push(TypeDef::Packet(Packet {
                            doc: packet.doc.0.clone(),
                            name: packet.name.name.clone(),
                            fields: packet
                                .fields
                                .iter()
                                .map(|field| Field {
                                    doc: field.doc.0.clone(),
                                    name: field.name.name.clone(),
                                    ty: model.ty(&field.ty),
                                    default: field.default.as_ref().map(Value::of),
                                })
                                .collect(),
                        }));
                    }
                    ast::Item::Enum(def) if named_here(file.id, &def.name.name) => {
                        types.push(TypeDef::Enum(Enum {
                            doc: def.doc.0.clone(),
                            name: def.name.name.clone(),
                            variants: def
                                .variants
                                .iter()
                                .map(|v| (v.doc.0.clone(), v.name.name.clone()))
                                .collect(),
                        }));
                    }
                    ast::Item::ExternPacket(def) if named_here(file.id, &def.name.name) => {
                        types.push(TypeDef::Extern(Extern {
                            doc: def.doc.0.clone(),
                            name: def.name.name.clone(),
                            rust_path: def.rust_path.value.clone(),
                        }));
                    }
                    ast::Item::RosImport(import) => {
                        let (Some(name), Ok(ros)) = (
                            &import.name,
                            crate::ros::TypeName::parse(&import.ros_name.value),
                        ) else {
                            continue;
                        };
                        if named_here(file.id, &name.name) {
                            types.push(TypeDef::Ros(RosImport {
                                doc: import.doc.0.clone(),
                                name: name.name.clone(),
                                ros,
                            }));
                        }
                    }
                    ast::Item::Converter(def) if named_here(file.id, &def.name.name) => {
                        converters.push(Converter {
                            doc: def.doc.0.clone(),
                            name: def.name.name.clone(),
                            from: model.ty(&def.from),
                            to: model.ty(&def.to),
                        });
                    }
                    _ => {}
                }
            }
        }
        (types, converters)
    }

    /// Builds one component: its members in one walk.
    fn build(&self, file: FileId, component: &ast::Component) -> Component {
        let mut out = Component {
            file,
            kind: component.kind,
            doc: component.doc.0.clone(),
            notes: component
                .notes
                .iter()
                .map(|note| Note {
                    subject: note.subject.clone(),
                    doc: note.doc.0.clone(),
                })
                .collect(),
            ..Component::empty(&component.name.name)
        };
        let policies: BTreeMap<&str, ErrorPolicy> = component
            .members
            .iter()
            .filter_map(|member| match member {
                ast::Member::OnError(on) => Some((
                    on.instance.name.as_str(),
                    ErrorPolicy::named(&on.policy.name)?,
                )),
                _ => None,
            })
            .collect();
        // Names transitions and plans resolve to indices against: the states of the
        // (first) automaton and every input, in order.
        let states: Vec<&str> = component
            .members
            .iter()
            .find_map(|member| match member {
                ast::Member::Automaton(automaton) => Some(
                    automaton
                        .states
                        .iter()
                        .map(|state| state.name.name.as_str())
                        .collect(),
                ),
                _ => None,
            })
            .unwrap_or_default();
        let ports: Vec<&str> = inputs(component)
            .map(|input| input.name.name.as_str())
            .collect();
        for member in &component.members {
            match member {
                ast::Member::Input(input) => out.inputs.push(Input {
                    doc: input.doc.0.clone(),
                    name: input.name.name.clone(),
                    export: match &input.def {
                        ast::InputDef::Export(target) => Some(self.port_ref(component, target)),
                        _ => None,
                    },
                    port: match &input.def {
                        ast::InputDef::Export(target) => self
                            .exported(component, target)
                            .and_then(|inner| inner.input(&target.port.name))
                            .and_then(|port| port.input()),
                        def => InputKind::of(def, |ty| self.ty(ty)).map(|kind| Declared {
                            kind,
                            pull: input.pull.is_some(),
                        }),
                    },
                    span: input.span,
                }),
                ast::Member::Output(output) => out.outputs.push(Output {
                    doc: output.doc.0.clone(),
                    name: output.name.name.clone(),
                    export: match &output.def {
                        ast::OutputDef::Export(target) => Some(self.port_ref(component, target)),
                        _ => None,
                    },
                    port: match &output.def {
                        ast::OutputDef::Export(target) => self
                            .exported(component, target)
                            .and_then(|inner| inner.output(&target.port.name))
                            .and_then(|port| port.output()),
                        def => OutputKind::of(def, |ty| self.ty(ty)).map(|kind| Declared {
                            kind,
                            pull: output.pull.is_some(),
                        }),
                    },
                    span: output.span,
                }),
                ast::Member::Variable(variable) => out.variables.push(Variable {
                    doc: variable.doc.0.clone(),
                    name: variable.name.name.clone(),
                    kind: variable.kind,
                    written: variable.ty.as_ref().map(|ty| self.ty(ty)),
                    value: variable
                        .value
                        .as_ref()
                        .filter(|_| variable.ty.is_some())
                        .map(Value::of),
                    mapping: match (&variable.ty, variable.value.as_ref().map(|v| &v.kind)) {
                        (None, Some(ast::ExprKind::Path(segments))) => {
                            Some(segments.iter().map(|s| s.name.clone()).collect())
                        }
                        _ => None,
                    },
                    ty: match (&variable.ty, &variable.value) {
                        (Some(ty), _) => Some(self.ty(ty)),
                        (None, Some(value)) => self.mapped_variable(component, value),
                        (None, None) => None,
                    }
                    .filter(|ty| *ty != Ty::Unknown),
                    range: variable
                        .range
                        .as_ref()
                        .zip(variable.ty.as_ref())
                        .filter(|_| variable.kind == ast::VarKind::Controllable)
                        .and_then(|(range, ty)| Range::of(range, &self.ty(ty))),
                    span: variable.span,
                }),
                // Every block's fields (a second block is an error).
                ast::Member::Configuration(configuration) => {
                    out.configuration.get_or_insert_with(Vec::new).extend(
                        configuration.fields.iter().map(|field| Field {
                            doc: field.doc.0.clone(),
                            name: field.name.name.clone(),
                            ty: self.ty(&field.ty),
                            default: field.default.as_ref().map(Value::of),
                        }),
                    );
                }
                // The first block that says something (a second one is an error).
                ast::Member::Adaptation(block) if out.adaptation == Tuning::default() => {
                    out.adaptation = Tuning::of(block);
                }
                ast::Member::Timing(timing) if out.timing.is_none() => {
                    out.timing = Some(timing.entries.iter().filter_map(timing_entry).collect());
                }
                ast::Member::Automaton(automaton) if out.automaton.is_none() => {
                    out.automaton = Some(self.automaton(automaton, &states, &ports));
                }
                ast::Member::Link(link) => out.links.push(match &link.kind {
                    ast::LinkKind::Crate { name, spec } => Link::Crate {
                        name: name.value.clone(),
                        spec: match spec {
                            ast::CrateSpec::Version(version) => {
                                CrateSpec::Version(version.value.clone())
                            }
                            ast::CrateSpec::Table(entries, _) => CrateSpec::Table(
                                entries
                                    .iter()
                                    .map(|e| (e.key.name.clone(), TableValue::of(&e.value)))
                                    .collect(),
                            ),
                        },
                    },
                    ast::LinkKind::System { name } => Link::System(name.value.clone()),
                }),
                ast::Member::Exception(exception) => out.exceptions.push(Exception {
                    doc: exception.doc.0.clone(),
                    name: exception.name.name.clone(),
                    description: exception.description.as_ref().map(|d| d.value.clone()),
                    plan: exception
                        .plan
                        .iter()
                        .map(|step| match &step.kind {
                            ast::PlanKind::Retry { count, every } => PlanStep::Retry {
                                count: count.value,
                                every: delay(every),
                            },
                            ast::PlanKind::Goto(target) => {
                                PlanStep::Goto(state_ref(&states, &target.name))
                            }
                            ast::PlanKind::Ignore => PlanStep::Ignore,
                            ast::PlanKind::Degrade => PlanStep::Degrade,
                        })
                        .collect(),
                }),
                ast::Member::Instance(instance) => out.instances.push(Instance {
                    name: instance.name.name.clone(),
                    component: instance.component.name.clone(),
                    compound: self.is_compound(&instance.component.name),
                    node: instance.node.as_ref().map(|node| node.value.clone()),
                    substitutes: instance
                        .substitutes
                        .as_ref()
                        .map(|primary| self.instance_ref(component, &primary.name)),
                    on_error: policies.get(instance.name.name.as_str()).copied(),
                    overrides: instance
                        .overrides
                        .iter()
                        .map(|o| Override {
                            name: o.name.name.clone(),
                            value: Value::of(&o.value),
                        })
                        .collect(),
                    timing: instance
                        .timing
                        .as_ref()
                        .map(|timing| timing.entries.iter().filter_map(timing_entry).collect()),
                    // Its own block, laid on its component's tuning by `finish`.
                    tuning: instance.adaptation.first().map(Tuning::of),
                    span: instance.span,
                }),
                ast::Member::OnError(on) => {
                    if let Some(policy) = ErrorPolicy::named(&on.policy.name) {
                        out.policies.push(Policy {
                            instance: on.instance.name.clone(),
                            policy,
                            span: on.span,
                        });
                    }
                }
                ast::Member::Redundant(redundant) => out.redundant.push(Redundant {
                    members: redundant
                        .members
                        .iter()
                        .map(|member| member.name.clone())
                        .collect(),
                    span: redundant.span,
                }),
                ast::Member::Thread(thread) => out.threads.push(Thread {
                    name: thread.name.name.clone(),
                    members: thread
                        .members
                        .iter()
                        .map(|member| member.name.clone())
                        .collect(),
                    span: thread.span,
                }),
                ast::Member::Connect(connect) => out.connections.push(Connection {
                    from: self.port_ref(component, &connect.from),
                    to: self.port_ref(component, &connect.to),
                    via: connect.via.as_ref().map(|via| via.name.clone()),
                    // Set by `finish`, once every component is resolved.
                    kind: None,
                }),
                ast::Member::Recovery(recovery) if out.recovery.is_none() => {
                    out.recovery = Some(Recovery {
                        retry_every: recovery.retry_every.as_ref().and_then(Duration::of),
                        deadline: recovery.deadline.as_ref().and_then(Duration::of),
                        span: recovery.span,
                    });
                }
                ast::Member::Restart(restart) if out.restart.is_none() => {
                    out.restart = Some(Restart {
                        limit: restart.limit.as_ref().and_then(|(count, window)| {
                            let count = match count.kind {
                                ast::ExprKind::Int(n) => u32::try_from(n).ok()?,
                                _ => return None,
                            };
                            Some((count, Duration::of(window)?))
                        }),
                        backoff: restart.backoff.as_ref().and_then(|(first, last)| {
                            Some((Duration::of(first)?, Duration::of(last)?))
                        }),
                        span: restart.span,
                    });
                }
                _ => {}
            }
        }
        out
    }

    fn is_compound(&self, name: &str) -> bool {
        self.component(name)
            .is_some_and(|(_, c)| c.kind == ast::ComponentKind::Compound)
    }

    /// The component of the instance `name` declared in `component`.
    fn instance_component(
        &self,
        component: &ast::Component,
        name: &str,
    ) -> Option<&'a ast::Component> {
        let instance = Model::instance(component, name)?;
        self.component(&instance.component.name).map(|(_, c)| c)
    }

    fn instance_ref(&self, component: &ast::Component, name: &str) -> InstanceRef {
        InstanceRef {
            name: name.to_owned(),
            compound: self
                .instance_component(component, name)
                .is_some_and(|c| c.kind == ast::ComponentKind::Compound),
        }
    }

    fn port_ref(&self, component: &ast::Component, port: &ast::PortRef) -> PortRef {
        PortRef {
            instance: port
                .instance
                .as_ref()
                .map(|instance| self.instance_ref(component, &instance.name)),
            port: port.port.name.clone(),
        }
    }

    /// The component whose port an export names, through the instance's component.
    fn exported(&self, component: &ast::Component, target: &ast::PortRef) -> Option<Rc<Component>> {
        let instance = Self::instance(component, &target.instance.as_ref()?.name)?;
        Some(self.resolved(&instance.component.name))
    }

    /// The type of the instance variable a mapped variable names.
    fn mapped_variable(&self, component: &ast::Component, value: &ast::Expr) -> Option<Ty> {
        let ast::ExprKind::Path(segments) = &value.kind else {
            return None;
        };
        let [instance, variable] = segments.as_slice() else {
            return None;
        };
        let instance = Self::instance(component, &instance.name)?;
        let inner = self.resolved(&instance.component.name);
        inner.variable(&variable.name)?.ty.clone()
    }

    fn automaton(&self, automaton: &ast::Automaton, states: &[&str], ports: &[&str]) -> Automaton {
        Automaton {
            initial: automaton
                .initial
                .first()
                .map(|i| state_ref(states, &i.name)),
            states: automaton
                .states
                .iter()
                .map(|state| State {
                    doc: state.doc.0.clone(),
                    name: state.name.name.clone(),
                    member_docs: state.member_docs.iter().map(|d| d.0.clone()).collect(),
                    members: state
                        .members
                        .iter()
                        .map(|member| self.state_member(member, states, ports))
                        .collect(),
                })
                .collect(),
        }
    }

    fn state_member(
        &self,
        member: &ast::StateMember,
        states: &[&str],
        ports: &[&str],
    ) -> StateMember {
        let state = |name: &ast::Ident| state_ref(states, &name.name);
        let port = |name: &ast::Ident| state_ref(ports, &name.name);
        match member {
            ast::StateMember::Entry(_) => StateMember::Entry,
            ast::StateMember::Exit(_) => StateMember::Exit,
            ast::StateMember::Periodic { period, .. } => {
                StateMember::Periodic(period.as_ref().and_then(Duration::of))
            }
            ast::StateMember::On {
                port: on, target, ..
            } => StateMember::On {
                port: port(on),
                target: state(target),
            },
            ast::StateMember::After {
                delay,
                without,
                target,
                ..
            } => StateMember::After {
                delay: self::delay(delay),
                without: without.as_ref().map(port),
                target: state(target),
            },
            ast::StateMember::May { targets, .. } => {
                StateMember::May(targets.iter().map(state).collect())
            }
            ast::StateMember::When {
                condition, target, ..
            } => StateMember::When {
                // Typed by `finish`, once every rule is.
                condition: Typed::untyped(condition),
                span: condition.span,
                target: state(target),
            },
        }
    }
}

/// What a component's connections and instances reach in the others: each
/// connection's kind, each instance's tuning.
struct Reached {
    kinds: Vec<Option<PortKind>>,
    tunings: Vec<Option<Tuning>>,
}

/// `name` resolved to its index in `names` (0 when absent: input with errors).
fn state_ref(names: &[&str], name: &str) -> Ref {
    Ref {
        name: name.to_owned(),
        index: names.iter().position(|n| *n == name).unwrap_or(0),
    }
}

/// A delay: zero when it is not a duration (input with errors).
fn delay(expr: &ast::Expr) -> Duration {
    Duration::of(expr).unwrap_or(Duration::ZERO)
}

/// A `timing` entry evaluated (`None` when its value cannot be: input with errors).
fn timing_entry(entry: &ast::TimingEntry) -> Option<TimingEntry> {
    Some(match entry {
        ast::TimingEntry::Period(interval) => TimingEntry::Period(
            Duration::of(&interval.lo)?,
            interval.hi.as_ref().and_then(Duration::of),
        ),
        ast::TimingEntry::MaxResponse(value) => TimingEntry::MaxResponse(Duration::of(value)?),
        ast::TimingEntry::Priority(value) => TimingEntry::Priority(match value.kind {
            ast::ExprKind::Int(n) => u8::try_from(n).ok()?,
            _ => return None,
        }),
        ast::TimingEntry::Quality(levels, _) => {
            TimingEntry::Quality(levels.iter().map(|l| l.name.clone()).collect())
        }
    })
}

fn inputs(component: &ast::Component) -> impl Iterator<Item = &ast::Input> {
    component.members.iter().filter_map(|m| match m {
        ast::Member::Input(input) => Some(input),
        _ => None,
    })
}

#[cfg(test)]
mod tests {
    use crate::check::model::{PortKind, Ty};
    use crate::checked::model::{InputKind, OutputKind, OverflowPolicy, StateMember};

    const TEXT: &str = "packet Twist { v: f32 }\n\
        packet Wheels { left: f32 }\n\
        converter TwistToWheels: Twist -> Wheels;\n\
        atomic Drive {\n\
            input wheels: fifo<Wheels>(4, drop_oldest) pull;\n\
            output odometry: data<Twist> pull;\n\
            observable speed: f32 = 0.0;\n\
            automaton { initial idle; state idle { entry; on wheels -> run; } state run { entry; } }\n\
        }\n\
        compound Inner { instance d: Drive; input wheels = d.wheels; output odometry = d.odometry; observable speed = d.speed; }\n\
        compound Outer {\n\
            instance inner: Inner;\n\
            instance spare: Drive substitutes other;\n\
            instance other: Drive;\n\
            input wheels = inner.wheels;\n\
            observable speed = inner.speed;\n\
            connect inner.odometry -> other.wheels via TwistToWheels;\n\
            supervisor { initial s; state s { when other.speed > 1.0 -> s; } }\n\
        }";

    #[test]
    fn names_are_resolved_once_in_the_model() {
        let checked = crate::analyze_text("t.cool", TEXT)
            .checked()
            .unwrap_or_else(|a| panic!("{}", a.render(crate::RenderOptions::plain())));
        let outer = checked.component("Outer").expect("Outer");
        // An export two levels deep carries the atomic port it reaches.
        let wheels = &outer.inputs[0];
        assert_eq!(
            wheels.export.as_ref().map(|p| p.port.as_str()),
            Some("wheels")
        );
        assert!(
            wheels
                .export
                .as_ref()
                .and_then(|p| p.instance.as_ref())
                .is_some_and(|i| i.compound)
        );
        let declared = wheels
            .port
            .as_ref()
            .expect("resolved through Inner to Drive");
        assert!(declared.pull);
        assert_eq!(
            declared.kind,
            InputKind::Fifo {
                ty: Ty::Packet("Wheels".to_owned()),
                size: 4,
                policy: Some(OverflowPolicy::DropOldest)
            }
        );
        // A mapping through a mapping has the type of the variable at the end.
        assert_eq!(outer.variables[0].written, None);
        assert_eq!(
            outer.variables[0].ty,
            Some(Ty::Float(crate::ast::Prim::F32))
        );
        // A connection knows the kind of the input it feeds and its converter.
        let connection = &outer.connections[0];
        assert_eq!(connection.kind, Some(PortKind::Fifo));
        assert_eq!(connection.via.as_deref(), Some("TwistToWheels"));
        assert!(
            connection
                .from
                .instance
                .as_ref()
                .is_some_and(|i| i.compound)
        );
        assert!(connection.to.instance.as_ref().is_some_and(|i| !i.compound));
        // Instances know their component's kind, substitutes their primary.
        let spare = &outer.instances[1];
        assert!(outer.instances[0].compound && !spare.compound);
        assert_eq!(
            spare.substitutes.as_ref().map(|p| p.name.as_str()),
            Some("other")
        );
        // `when` rules carry their typed tree.
        let state = &outer.automaton.as_ref().expect("supervisor").states[0];
        assert!(matches!(
            &state.members[0],
            StateMember::When { condition: typed, target, .. }
                if typed.ty == crate::checked::model::RTy::Bool && target.name == "s"
        ));
        let inner = checked.component("Inner").expect("Inner");
        assert_eq!(
            inner.outputs[0].port.as_ref().map(|p| &p.kind),
            Some(&OutputKind::Data(Ty::Packet("Twist".to_owned())))
        );
        // Transitions refer to states and ports by the indices the model resolved.
        let drive = checked.component("Drive").expect("Drive");
        let automaton = drive.automaton.as_ref().expect("automaton");
        assert_eq!(automaton.initial.as_ref().map(|r| r.index), Some(0));
        assert!(matches!(
            &automaton.states[0].members[1],
            StateMember::On { port, target } if port.index == 0 && target.index == 1
        ));
        // Components come in source order, each once.
        let names: Vec<&str> = checked.components().map(|c| c.name.as_str()).collect();
        assert_eq!(names, ["Drive", "Inner", "Outer"]);
    }

    #[test]
    fn settings_are_evaluated_once_in_the_model() {
        use crate::checked::model::{
            CrateSpec, Duration, ErrorPolicy, Link, PlanStep, TableValue, TimingEntry, Value,
            Written,
        };
        let checked = crate::analyze_text(
            "t.cool",
            "atomic W {\n\
                 link crate \"x\" = { version = \"1\", features = [\"a\"], default_features = false };\n\
                 input q: fifo<u8>(2, block);\n\
                 input r: fifo<u8>(2);\n\
                 configuration { gain: f64 = -2; offsets: [f32; 2] = [-0.5; 2]; }\n\
                 timing { period 100Hz..20ms; priority 7; }\n\
                 adaptation { window 8; }\n\
                 exception slip { retry 2 every 250us; }\n\
                 automaton { initial s; state s { periodic 2kHz; after 1s -> s; } }\n\
             }\n\
             compound C {\n\
                 instance w: W { gain = 1.5; }\n\
                 on error w: ignore;\n\
                 restart { limit 4 in 1min; backoff 20ms..3s; }\n\
                 recovery { deadline 2s; }\n\
             }",
        )
        .checked()
        .unwrap_or_else(|a| panic!("{}", a.render(crate::RenderOptions::plain())));
        let ns = |nanos: u64| Duration {
            nanos,
            written: Written::Nanos(nanos.into()),
        };
        let w = checked.component("W").expect("W");
        let fifo = |i: usize| match &w.inputs[i].port.as_ref().expect("declared").kind {
            InputKind::Fifo { policy, .. } => *policy,
            other => panic!("{other:?}"),
        };
        assert_eq!(fifo(0), Some(OverflowPolicy::Block));
        assert_eq!(fifo(1), None);
        assert_eq!(fifo(1).unwrap_or_default(), OverflowPolicy::Reject);
        assert_eq!(
            w.timing.as_deref(),
            Some(
                &[
                    TimingEntry::Period(
                        Duration {
                            nanos: 10_000_000,
                            written: Written::Hertz(100.0)
                        },
                        Some(ns(20_000_000))
                    ),
                    TimingEntry::Priority(7)
                ][..]
            )
        );
        assert_eq!(
            w.exceptions[0].plan,
            [PlanStep::Retry {
                count: 2,
                every: ns(250_000)
            }]
        );
        let members = &w.automaton.as_ref().expect("automaton").states[0].members;
        assert!(matches!(
            members[0],
            StateMember::Periodic(Some(Duration { nanos: 500_000, .. }))
        ));
        assert!(matches!(
            members[1],
            StateMember::After { delay, .. } if delay == ns(1_000_000_000)
        ));
        assert_eq!(
            w.links,
            [Link::Crate {
                name: "x".to_owned(),
                spec: CrateSpec::Table(vec![
                    ("version".to_owned(), TableValue::Str("1".to_owned())),
                    (
                        "features".to_owned(),
                        TableValue::List(vec![TableValue::Str("a".to_owned())])
                    ),
                    ("default_features".to_owned(), TableValue::Bool(false)),
                ])
            }]
        );
        let defaults: Vec<_> = w
            .configuration
            .iter()
            .flatten()
            .map(|f| f.default.clone())
            .collect();
        assert_eq!(
            defaults,
            [
                Some(Value::Int(-2)),
                Some(Value::Repeat(Box::new(Value::Float(-0.5)), 2))
            ]
        );
        assert_eq!(w.adaptation.window, Some(8));
        let c = checked.component("C").expect("C");
        assert_eq!(c.adaptation, crate::check::model::Tuning::default());
        assert_eq!(c.instances[0].overrides[0].value, Value::Float(1.5));
        assert_eq!(c.instances[0].on_error, Some(ErrorPolicy::Ignore));
        assert_eq!(c.policies[0].policy, ErrorPolicy::Ignore);
        let restart = c.restart.as_ref().expect("restart");
        assert_eq!(restart.limit, Some((4, ns(60_000_000_000))));
        assert_eq!(restart.backoff, Some((ns(20_000_000), ns(3_000_000_000))));
        let recovery = c.recovery.as_ref().expect("recovery");
        assert_eq!(recovery.retry_every, None);
        assert_eq!(recovery.retry_every_nanos(), 500_000_000);
        assert_eq!(recovery.deadline_nanos(), 2_000_000_000);
    }
}
