//! Lowering an atomic component, from its resolved model alone
//! ([`crate::checked::model`]): ports, variables, configuration, timing, exceptions,
//! pull answers and the user automaton (its states by `automaton`). Compounds share
//! the port, variable and timing lowering here (`compound.rs`).

use super::automaton::{self, Lowered, SectionOwner};
use super::{
    GEN_TYPES, Lowerer, SERDE_WITH, USER_TYPES, adaptation, duration_code, prim_of, prim_rust,
    rust_ty, serde_adapter, unique,
};
use crate::checked::model::{
    Component, Input, InputKind, Output, OutputKind, OverflowPolicy, PlanStep, Prim, Range,
    TimingEntry, Ty, TypeDef, VarKind, Variable,
};
use crate::ident;
use crate::ir::{self, Code};

/// `self.vars`: where an atomic component's glue holds its variables.
pub(super) fn glue_vars() -> Code {
    Code::atom("self").field("vars")
}

/// What the glue keeps and runs to report its variables to the runtime
/// (`coolbot::Automaton::changed_variables`), from each variable and, if its values
/// are compared in their Rust type ([`Lowerer::compares`]), the function converting
/// one to a `coolbot::Value` ([`Lowerer::converter`]): the fields of its copies of
/// them as last reported (`self.published`, `(name, type)`, `None` before the first
/// report), and one statement per observable or controllable variable, in index
/// order, comparing it with its copy, or leaving it to the runtime to read.
fn publication(vars: &[(ir::Var, Option<Code>)]) -> (Vec<(String, String)>, Vec<Code>) {
    let mut published = Vec::new();
    let mut reports = Vec::new();
    for (var, convert) in vars {
        let Some(index) = var.spec_index else {
            continue;
        };
        let changes = Code::atom("changes");
        let index = Code::atom(index.to_string());
        if let Some(convert) = convert {
            let name = &var.field.name;
            published.push((
                name.clone(),
                format!("::core::option::Option<{}>", var.field.ty),
            ));
            reports.push(changes.method(
                "compare",
                vec![
                    index,
                    Code::prefix(
                        "&mut ",
                        Code::atom("self").field("published").field(name.as_str()),
                    ),
                    glue_vars().field(name.as_str()).reference(),
                    convert.clone(),
                ],
            ));
        } else {
            reports.push(changes.method("read", vec![index]));
        }
    }
    (published, reports)
}

/// The Rust type (under the component modules' path to the types) and the `.cool`
/// name of a packet type.
fn packet_type(ty: &Ty) -> (String, String) {
    (rust_ty(ty, GEN_TYPES), ty.to_string())
}

impl<'a> Lowerer<'a> {
    /// An atomic component, from its resolved model alone.
    pub(super) fn atomic(&self, c: &'a Component, module: String) -> ir::Atomic {
        let config: Vec<ir::Field> = c
            .configuration
            .iter()
            .flatten()
            .map(|f| self.field(&f.doc, &f.name, &f.ty, f.default.as_ref(), GEN_TYPES))
            .collect();
        let mut spec_index = 0;
        let typed: Vec<(ir::Var, Option<Code>)> = c
            .variables
            .iter()
            .filter_map(|v| {
                let var = self.variable(v, &mut spec_index, &glue_vars())?;
                let ty = v.written.as_ref()?;
                let convert = self.compares(ty).then(|| self.converter(v, ty));
                Some((var, convert))
            })
            .collect();
        let (published, reports) = publication(&typed);
        let vars: Vec<ir::Var> = typed.into_iter().map(|(var, _)| var).collect();
        // An atomic's ports are all declared (exports are a compound's).
        let inputs: Vec<(&Input, ir::Port)> = c
            .inputs
            .iter()
            .filter_map(|input| Some((input, self.input(input)?)))
            .collect();
        let outputs: Vec<(&Output, ir::Port)> = c
            .outputs
            .iter()
            .filter_map(|output| Some((output, self.output(output)?)))
            .collect();
        let Lowered {
            states,
            initial,
            mut methods,
            section_arms,
            choose_arms,
            when: _,
        } = automaton::states(c.automaton.as_ref(), SectionOwner::Atomic);

        let mut exceptions = Vec::new();
        for e in &c.exceptions {
            let name = &e.name;
            let handler = unique(ident::method("on_", name, ""), &methods);
            let plan: Vec<Code> = e
                .plan
                .iter()
                .map(|step| match step {
                    PlanStep::Retry { count, every } => Code::structure(
                        "::coolbot::PlanStep::Retry",
                        vec![
                            (
                                "count",
                                Code::atom(u32::try_from(*count).unwrap_or(u32::MAX).to_string()),
                            ),
                            ("every", duration_code(every.nanos)),
                        ],
                    ),
                    PlanStep::Goto(target) => Code::call(
                        "::coolbot::PlanStep::Goto",
                        vec![Code::atom(target.index.to_string())],
                    ),
                    PlanStep::Ignore => Code::atom("::coolbot::PlanStep::Ignore"),
                    PlanStep::Degrade => Code::atom("::coolbot::PlanStep::Degrade"),
                })
                .collect();
            let description = e.description.as_deref().unwrap_or("");
            methods.push(ir::Method {
                name: handler.clone(),
                doc: vec![format!(
                    "Called when exception `{name}` is raised, before its continuity plan runs."
                )],
                signature: format!("fn {handler}(&mut self, cx: &mut Cx<'_>, message: &str)"),
                user_signature: format!("fn {handler}(&mut self, cx: &mut Cx<'_>, message: &str)"),
                stub_body: vec![
                    ir::StubLine::Comment(format!(
                        "// Exception `{name}` was raised; its continuity plan runs next."
                    )),
                    ir::StubLine::Statement("let _ = (cx, message);".to_owned()),
                ],
            });
            exceptions.push(ir::ExceptionIr {
                doc: e.doc.clone(),
                cool_name: name.clone(),
                variant: ident::camel(name),
                handler,
                spec: Code::structure(
                    "::coolbot::ExceptionSpec",
                    vec![
                        ("name", Code::string(name)),
                        ("description", Code::string(description)),
                        ("plan", Code::slice(plan)),
                    ],
                ),
            });
        }

        let mut answer_arms = Vec::new();
        for (index, (output, port)) in outputs.iter().enumerate() {
            let Some(declared) = output.port.as_ref().filter(|declared| declared.pull) else {
                continue;
            };
            let (ty, send) = match &declared.kind {
                OutputKind::Data(ty) => (ty, "send"),
                OutputKind::Poster(ty) => (ty, "post"),
                OutputKind::Tick => continue,
            };
            let method = unique(ident::method("answer_", &output.name, ""), &methods);
            let name = &output.name;
            let stub_body = if let Some(default) = self.stub_default(ty) {
                vec![
                    ir::StubLine::Comment(format!(
                        "// A consumer pulled from output `{name}`: compute the packet to answer with."
                    )),
                    ir::StubLine::Statement("let _ = cx;".to_owned()),
                    ir::StubLine::Value(Code::call("Ok", vec![default])),
                ]
            } else {
                vec![
                    ir::StubLine::Statement("let _ = cx;".to_owned()),
                    ir::StubLine::Value(Code::call(
                        "Err",
                        vec![Code::call(
                            "coolbot::Fault::message",
                            vec![Code::string(&format!(
                                "the pull answer `{method}` is not written yet"
                            ))],
                        )],
                    )),
                ]
            };
            methods.push(ir::Method {
                name: method.clone(),
                doc: vec![format!("Called when a consumer pulls from output `{name}`: the packet to send.")],
                signature: format!(
                    "fn {method}(&mut self, cx: &mut Cx<'_>) -> ::core::result::Result<{}, ::coolbot::Fault>",
                    rust_ty(ty, GEN_TYPES)
                ),
                user_signature: format!(
                    "fn {method}(&mut self, cx: &mut Cx<'_>) -> Result<{}, coolbot::Fault>",
                    rust_ty(ty, USER_TYPES)
                ),
                stub_body,
            });
            answer_arms.push(ir::AnswerArm {
                output: index,
                method,
                field: port.field.clone(),
                send: send.to_owned(),
            });
        }

        let mut atomic = ir::Atomic {
            spec: Code::atom(""),
            doc: c.doc.clone(),
            notes: ir::notes(
                c.notes
                    .iter()
                    .map(|n| (n.subject.as_str(), n.doc.as_slice())),
            ),
            type_name: c.name.clone(),
            user_struct: ident::camel(&c.name),
            module,
            config,
            vars,
            published,
            reports,
            inputs: inputs.into_iter().map(|(_, p)| p).collect(),
            outputs: outputs.into_iter().map(|(_, p)| p).collect(),
            states,
            initial,
            exceptions,
            timing: self.timing(c.timing.as_deref()),
            adaptation: adaptation::written_fields(&c.adaptation),
            methods,
            section_arms,
            choose_arms,
            answer_arms,
        };
        atomic.spec = spec(&atomic);
        atomic
    }

    /// Whether the glue compares values of `ty` in their Rust type to publish them
    /// (`coolbot::Changes::compare`): every type whose `PartialEq` coolc derives,
    /// which says two values are equal only when their `coolbot::Value`s are. Not a
    /// type that holds an extern packet, whose `PartialEq` is another crate's (if it
    /// has one): the runtime reads and compares its `Value`.
    fn compares(&self, ty: &Ty) -> bool {
        fn walk<'t>(lowerer: &Lowerer<'t>, ty: &Ty, visiting: &mut Vec<&'t str>) -> bool {
            // (A ROS 2 message holds only ROS 2 types.)
            match ty {
                Ty::Bool
                | Ty::Int(_)
                | Ty::Float(_)
                | Ty::Str
                | Ty::Time
                | Ty::Duration
                | Ty::Enum(_)
                | Ty::Ros { .. } => true,
                Ty::List(inner) | Ty::Array(inner, _) | Ty::Optional(inner) => {
                    walk(lowerer, inner, visiting)
                }
                Ty::Packet(name) => match lowerer.checked.type_def(name) {
                    Some(TypeDef::Packet(packet)) if visiting.contains(&packet.name.as_str()) => {
                        true
                    }
                    Some(TypeDef::Packet(packet)) => {
                        visiting.push(&packet.name);
                        let fields = &packet.fields;
                        let compares = fields.iter().all(|f| walk(lowerer, &f.ty, visiting));
                        visiting.pop();
                        compares
                    }
                    _ => false,
                },
                Ty::Extern(_) | Ty::Unknown => false,
            }
        }
        walk(self, ty, &mut Vec::new())
    }

    /// The function converting a reference to variable `v` of type `ty` to a
    /// `coolbot::Value`, as the glue's `get` converts it ([`Lowerer::variable`]):
    /// through its serde_with adapter, by `From` for a primitive with a default, else
    /// by serde.
    fn converter(&self, v: &Variable, ty: &Ty) -> Code {
        let has_default = v.value.is_some() || self.ty_defaultable(ty);
        let rust_ty = if has_default {
            rust_ty(ty, GEN_TYPES)
        } else {
            format!("::core::option::Option<{}>", rust_ty(ty, GEN_TYPES))
        };
        match (serde_adapter(ty), prim_of(ty)) {
            (Some(adapter), _) => {
                let adapter = if has_default {
                    adapter
                } else {
                    format!("::core::option::Option<{adapter}>")
                };
                Code::atom(format!("super::__cool_to_value_as::<{rust_ty}, {adapter}>"))
            }
            (None, Some(_)) if has_default => Code::atom("super::__cool_value_of"),
            _ => Code::atom("super::__cool_to_value"),
        }
    }

    /// A declared variable (`observable`/`controllable`/`local` with a type) as a
    /// `Vars` field; `receiver` is the Rust expression holding the `Vars` in the glue
    /// ([`glue_vars`]). Observable and controllable ones take the next `spec_index`.
    pub(super) fn variable(
        &self,
        v: &Variable,
        spec_index: &mut usize,
        receiver: &Code,
    ) -> Option<ir::Var> {
        let ty = v.written.as_ref()?;
        let default = if v.value.is_none() && !self.ty_defaultable(ty) {
            // No default and no `Default`: the variable has no value
            // until set.
            None
        } else {
            Some(self.field_default(ty, v.value.as_ref(), GEN_TYPES))
        };
        let (rust_ty, default_expr) = match default.clone() {
            Some(d) => (rust_ty(ty, GEN_TYPES), d),
            None => (
                format!("::core::option::Option<{}>", rust_ty(ty, GEN_TYPES)),
                Code::atom("::core::option::Option::None"),
            ),
        };
        let has_default = default.is_some();
        let kind = match v.kind {
            VarKind::Observable => "Observable",
            VarKind::Controllable => "Controllable",
            VarKind::Local => "Local",
        };
        let index = (v.kind != VarKind::Local).then(|| {
            *spec_index += 1;
            *spec_index - 1
        });
        let field = ident::snake(&v.name);
        // A type holding an array longer than 32 elements goes through its serde_with
        // adapter (wrapped in `Option` like the field when it has no default).
        let adapter = serde_adapter(ty).map(|adapter| {
            if has_default {
                adapter
            } else {
                format!("::core::option::Option<{adapter}>")
            }
        });
        let held = receiver.clone().field(field.as_str());
        let value = || Code::atom("value");
        let to_value_call = |value: Code| Code::call("super::__cool_to_value", vec![value]);
        let (to_value, from_value) = match (&adapter, prim_of(ty)) {
            (Some(adapter), _) => (
                to_value_call(
                    Code::call(
                        format!("{SERDE_WITH}ser::SerializeAsWrap::<{rust_ty}, {adapter}>::new"),
                        vec![held.reference()],
                    )
                    .reference(),
                ),
                Code::call(
                    format!(
                        "super::__cool_from_value::<{SERDE_WITH}de::DeserializeAsWrap<{rust_ty}, {adapter}>>"
                    ),
                    vec![value()],
                )
                .method(
                    "map",
                    vec![Code::atom(format!(
                        "{SERDE_WITH}de::DeserializeAsWrap::into_inner"
                    ))],
                ),
            ),
            (None, Some(p)) if has_default => (
                Code::call(
                    "::coolbot::Value::from",
                    vec![if p == Prim::String {
                        held.method("clone", Vec::new())
                    } else {
                        held
                    }],
                ),
                Code::call(format!("<{}>::try_from", prim_rust(p)), vec![value()]),
            ),
            _ => (
                to_value_call(held.reference()),
                Code::call("super::__cool_from_value", vec![value()]),
            ),
        };
        // Floats printed with `{:?}` keep their point (`1.0`, not `1`).
        let range_of = |kind: &str, low: String, high: String| {
            Code::core_some(Code::call(
                format!("::coolbot::VarRange::{kind}"),
                vec![Code::atom(low), Code::atom(high)],
            ))
        };
        let range = match v.range {
            None => Code::core_none(),
            Some(Range::Int(low, high)) => range_of("Int", low.to_string(), high.to_string()),
            Some(Range::Float(low, high)) => {
                range_of("Float", format!("{low:?}"), format!("{high:?}"))
            }
            Some(Range::F32(low, high)) => range_of("F32", format!("{low:?}"), format!("{high:?}")),
        };
        Some(ir::Var {
            to_value,
            from_value,
            range,
            field: ir::Field {
                doc: v.doc.clone(),
                name: ident::snake(&v.name),
                cool_name: v.name.clone(),
                ty: rust_ty,
                default: default_expr,
                serde_with: None,
            },
            kind: kind.to_owned(),
            spec_index: index,
            cool_ty: ty.to_string(),
        })
    }

    pub(super) fn timing(&self, timing: Option<&[TimingEntry]>) -> Code {
        let (mut period, mut max_period, mut max_response, mut priority) = (None, None, None, 0u8);
        let mut qualities = Vec::new();
        for entry in timing.unwrap_or_default() {
            match entry {
                TimingEntry::Period(lo, hi) => {
                    period = Some(lo.nanos);
                    max_period = hi.map(|hi| hi.nanos);
                }
                TimingEntry::MaxResponse(d) => max_response = Some(d.nanos),
                TimingEntry::Priority(p) => priority = *p,
                TimingEntry::Quality(names) => {
                    qualities = names.iter().map(|n| Code::string(n)).collect();
                }
            }
        }
        let opt = |ns: Option<u64>| Code::option(ns.map(duration_code));
        Code::structure(
            "::coolbot::TimingSpec",
            vec![
                ("period", opt(period)),
                ("max_period", opt(max_period)),
                ("max_response", opt(max_response)),
                ("priority", Code::atom(priority.to_string())),
                ("qualities", Code::slice(qualities)),
            ],
        )
    }

    /// A declared input as a port of the generated struct (`None` for an export
    /// whose port could not be followed, which a checked model does not have).
    pub(super) fn input(&self, input: &Input) -> Option<ir::Port> {
        use ir::Code;
        let declared = input.port.as_ref()?;
        let kind_path = |kind: &str| format!("::coolbot::InputKind::{kind}");
        let (handle, args, kind) = match &declared.kind {
            InputKind::Tick => ("TickIn", Vec::new(), Code::atom(kind_path("Tick"))),
            InputKind::Fifo { size, policy, .. } => {
                let policy = Code::atom(format!(
                    "::coolbot::OverflowPolicy::{}",
                    match policy.unwrap_or_default() {
                        OverflowPolicy::Reject => "Reject",
                        OverflowPolicy::DropOldest => "DropOldest",
                        OverflowPolicy::Block => "Block",
                    }
                ));
                let size = Code::atom(size.to_string());
                (
                    "FifoIn",
                    vec![size.clone(), policy.clone()],
                    Code::structure(
                        kind_path("Fifo"),
                        vec![("capacity", size), ("policy", policy)],
                    ),
                )
            }
            InputKind::Ufifo { size, max, .. } => {
                let size = Code::atom(size.to_string());
                let max = Code::option(max.map(|max| Code::atom(max.to_string())));
                (
                    "UfifoIn",
                    vec![size.clone(), max.clone()],
                    Code::structure(kind_path("Ufifo"), vec![("initial", size), ("max", max)]),
                )
            }
            InputKind::Last(_) => ("LastIn", Vec::new(), Code::atom(kind_path("Last"))),
            InputKind::Poster(_) => ("PosterIn", Vec::new(), Code::atom(kind_path("Poster"))),
        };
        Some(port(
            &input.doc,
            &input.name,
            (handle, declared.kind.port_kind().as_str()),
            declared.kind.packet(),
            args,
            kind,
            declared.pull,
        ))
    }

    /// A declared output as a port of the generated struct (as [`Self::input`]).
    pub(super) fn output(&self, output: &Output) -> Option<ir::Port> {
        let declared = output.port.as_ref()?;
        let (handle, kind) = match &declared.kind {
            OutputKind::Tick => ("TickOut", "Tick"),
            OutputKind::Data(_) => ("DataOut", "Data"),
            OutputKind::Poster(_) => ("PosterOut", "Poster"),
        };
        Some(port(
            &output.doc,
            &output.name,
            (handle, declared.kind.port_kind().as_str()),
            declared.kind.packet(),
            Vec::new(),
            Code::atom(format!("::coolbot::OutputKind::{kind}")),
            declared.pull,
        ))
    }
}

/// A port of the generated struct: its handle `::coolbot::port::<handle>` (generic
/// over the packet type, none for a tick), built by `new(args)`, and its kind's name.
fn port(
    doc: &[String],
    name: &str,
    (handle, kind_name): (&str, &'static str),
    packet: Option<&Ty>,
    args: Vec<Code>,
    kind: Code,
    pull: bool,
) -> ir::Port {
    let path = format!("::coolbot::port::{handle}");
    let (rust, cool) = packet.map_or_else(|| ("()".to_owned(), String::new()), packet_type);
    ir::Port {
        doc: doc.to_vec(),
        cool_name: name.to_owned(),
        field: ident::snake(name),
        handle: match packet {
            Some(_) => format!("{path}<{rust}>"),
            None => path.clone(),
        },
        rust_packet: rust,
        kind_name,
        ctor: Code::call(format!("{path}::new"), args),
        kind,
        packet: cool,
        pull,
    }
}

/// The `coolbot::Spec` of atomic component `c`: its states, ports, exposed
/// variables, exceptions and timing.
fn spec(c: &ir::Atomic) -> Code {
    let list = Code::slice;
    Code::structure(
        "::coolbot::Spec",
        vec![
            ("type_name", Code::string(&c.type_name)),
            ("doc", Code::atom(c.doc_literal())),
            (
                "states",
                list(c.states.iter().map(|st| st.spec.clone()).collect()),
            ),
            ("initial", Code::atom(c.initial.to_string())),
            (
                "inputs",
                list(
                    c.inputs
                        .iter()
                        .map(|p| p.spec(&p.cool_name, true))
                        .collect(),
                ),
            ),
            (
                "outputs",
                list(
                    c.outputs
                        .iter()
                        .map(|p| p.spec(&p.cool_name, false))
                        .collect(),
                ),
            ),
            (
                "variables",
                list(
                    c.vars
                        .iter()
                        .filter(|v| v.spec_index.is_some())
                        .map(ir::Var::spec)
                        .collect(),
                ),
            ),
            (
                "exceptions",
                list(c.exceptions.iter().map(|e| e.spec.clone()).collect()),
            ),
            ("timing", c.timing.clone()),
        ],
    )
}
