//! Lowering an atomic component, from its resolved model alone
//! ([`crate::checked::model`]): ports, variables, configuration, timing, exceptions,
//! pull answers and the user automaton (its states by `automaton`). Compounds share
//! the port, variable and timing lowering here (`compound.rs`).

use super::automaton::{self, Lowered, SectionOwner};
use super::{
    GEN_TYPES, Lowerer, SERDE_WITH, USER_TYPES, adaptation, duration_rust, prim_of, prim_rust,
    rust_ty, serde_adapter, unique,
};
use crate::checked::model::{
    Component, Input, InputKind, Output, OutputKind, OverflowPolicy, PlanStep, Prim, Range,
    TimingEntry, Ty, VarKind, Variable,
};
use crate::ident;
use crate::ir;

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
        let vars: Vec<ir::Var> = c
            .variables
            .iter()
            .filter_map(|v| self.variable(v, &mut spec_index, "self.vars"))
            .collect();
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
            let plan: Vec<String> = e
                .plan
                .iter()
                .map(|step| match step {
                    PlanStep::Retry { count, every } => format!(
                        "::coolbot::PlanStep::Retry {{ count: {}, every: {} }}",
                        u32::try_from(*count).unwrap_or(u32::MAX),
                        duration_rust(every.nanos)
                    ),
                    PlanStep::Goto(target) => {
                        format!("::coolbot::PlanStep::Goto({})", target.index)
                    }
                    PlanStep::Ignore => "::coolbot::PlanStep::Ignore".to_owned(),
                    PlanStep::Degrade => "::coolbot::PlanStep::Degrade".to_owned(),
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
                    format!("// Exception `{name}` was raised; its continuity plan runs next."),
                    "let _ = (cx, message);".to_owned(),
                ],
            });
            exceptions.push(ir::ExceptionIr {
                doc: e.doc.clone(),
                cool_name: name.clone(),
                variant: ident::camel(name),
                handler,
                spec: format!(
                    "::coolbot::ExceptionSpec {{ name: {}, description: {}, plan: &[{}] }}",
                    ident::string_literal(name),
                    ident::string_literal(description),
                    plan.join(", ")
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
                    format!(
                        "// A consumer pulled from output `{name}`: compute the packet to answer with."
                    ),
                    "let _ = cx;".to_owned(),
                    format!("Ok({default})"),
                ]
            } else {
                vec![
                    "let _ = cx;".to_owned(),
                    format!(
                        "Err(coolbot::Fault::message({}))",
                        ident::string_literal(&format!(
                            "the pull answer `{method}` is not written yet"
                        ))
                    ),
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

        ir::Atomic {
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
        }
    }

    /// A declared variable (`observable`/`controllable`/`local` with a type) as a
    /// `Vars` field; `receiver` is the Rust expression holding the `Vars` in the glue
    /// (`self.vars`). Observable and controllable ones take the next `spec_index`.
    pub(super) fn variable(
        &self,
        v: &Variable,
        spec_index: &mut usize,
        receiver: &str,
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
                "::core::option::Option::None".to_owned(),
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
        let (to_value, from_value) = match (&adapter, prim_of(ty)) {
            (Some(adapter), _) => (
                format!(
                    "super::__cool_to_value(&{SERDE_WITH}ser::SerializeAsWrap::<{rust_ty}, {adapter}>::new(&{receiver}.{field}))"
                ),
                format!(
                    "super::__cool_from_value::<{SERDE_WITH}de::DeserializeAsWrap<{rust_ty}, {adapter}>>(value).map({SERDE_WITH}de::DeserializeAsWrap::into_inner)"
                ),
            ),
            (None, Some(p)) if has_default => (
                if p == Prim::String {
                    format!("::coolbot::Value::from({receiver}.{field}.clone())")
                } else {
                    format!("::coolbot::Value::from({receiver}.{field})")
                },
                format!("<{}>::try_from(value)", prim_rust(p)),
            ),
            _ => (
                format!("super::__cool_to_value(&{receiver}.{field})"),
                "super::__cool_from_value(value)".to_owned(),
            ),
        };
        // Floats printed with `{:?}` keep their point (`1.0`, not `1`).
        let range = match v.range {
            None => "::core::option::Option::None".to_owned(),
            Some(Range::Int(low, high)) => {
                format!("::core::option::Option::Some(::coolbot::VarRange::Int({low}, {high}))")
            }
            Some(Range::Float(low, high)) => format!(
                "::core::option::Option::Some(::coolbot::VarRange::Float({low:?}, {high:?}))"
            ),
            Some(Range::F32(low, high)) => {
                format!("::core::option::Option::Some(::coolbot::VarRange::F32({low:?}, {high:?}))")
            }
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

    pub(super) fn timing(&self, timing: Option<&[TimingEntry]>) -> String {
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
                    qualities = names.iter().map(|n| ident::string_literal(n)).collect();
                }
            }
        }
        let opt = |ns: Option<u64>| match ns {
            Some(ns) => format!("Some({})", duration_rust(ns)),
            None => "None".to_owned(),
        };
        format!(
            "::coolbot::TimingSpec {{ period: {}, max_period: {}, max_response: {}, priority: {}, qualities: &[{}] }}",
            opt(period),
            opt(max_period),
            opt(max_response),
            priority,
            qualities.join(", ")
        )
    }

    /// A declared input as a port of the generated struct (`None` for an export
    /// whose port could not be followed, which a checked model does not have).
    pub(super) fn input(&self, input: &Input) -> Option<ir::Port> {
        let declared = input.port.as_ref()?;
        let field = ident::snake(&input.name);
        let (handle, ctor, kind, packet) = match &declared.kind {
            InputKind::Tick => (
                "::coolbot::port::TickIn".to_owned(),
                "::coolbot::port::TickIn::new()".to_owned(),
                "::coolbot::InputKind::Tick".to_owned(),
                String::new(),
            ),
            InputKind::Fifo { ty, size, policy } => {
                let (rust, cool) = packet_type(ty);
                let policy = match policy.unwrap_or_default() {
                    OverflowPolicy::Reject => "Reject",
                    OverflowPolicy::DropOldest => "DropOldest",
                    OverflowPolicy::Block => "Block",
                };
                (
                    format!("::coolbot::port::FifoIn<{rust}>"),
                    format!(
                        "::coolbot::port::FifoIn::new({size}, ::coolbot::OverflowPolicy::{policy})"
                    ),
                    format!(
                        "::coolbot::InputKind::Fifo {{ capacity: {size}, policy: ::coolbot::OverflowPolicy::{policy} }}"
                    ),
                    cool,
                )
            }
            InputKind::Ufifo { size, ty, max } => {
                let (rust, cool) = packet_type(ty);
                let max = match max {
                    Some(m) => format!("Some({m})"),
                    None => "None".to_owned(),
                };
                (
                    format!("::coolbot::port::UfifoIn<{rust}>"),
                    format!("::coolbot::port::UfifoIn::new({size}, {max})"),
                    format!("::coolbot::InputKind::Ufifo {{ initial: {size}, max: {max} }}"),
                    cool,
                )
            }
            InputKind::Last(ty) => {
                let (rust, cool) = packet_type(ty);
                (
                    format!("::coolbot::port::LastIn<{rust}>"),
                    "::coolbot::port::LastIn::new()".to_owned(),
                    "::coolbot::InputKind::Last".to_owned(),
                    cool,
                )
            }
            InputKind::Poster(ty) => {
                let (rust, cool) = packet_type(ty);
                (
                    format!("::coolbot::port::PosterIn<{rust}>"),
                    "::coolbot::port::PosterIn::new()".to_owned(),
                    "::coolbot::InputKind::Poster".to_owned(),
                    cool,
                )
            }
        };
        Some(ir::Port {
            doc: input.doc.clone(),
            cool_name: input.name.clone(),
            field,
            handle,
            ctor,
            kind,
            packet,
            pull: declared.pull,
        })
    }

    /// A declared output as a port of the generated struct (as [`Self::input`]).
    pub(super) fn output(&self, output: &Output) -> Option<ir::Port> {
        let declared = output.port.as_ref()?;
        let field = ident::snake(&output.name);
        let (handle, ctor, kind, packet) = match &declared.kind {
            OutputKind::Tick => (
                "::coolbot::port::TickOut".to_owned(),
                "::coolbot::port::TickOut::new()".to_owned(),
                "::coolbot::OutputKind::Tick".to_owned(),
                String::new(),
            ),
            OutputKind::Data(ty) => {
                let (rust, cool) = packet_type(ty);
                (
                    format!("::coolbot::port::DataOut<{rust}>"),
                    "::coolbot::port::DataOut::new()".to_owned(),
                    "::coolbot::OutputKind::Data".to_owned(),
                    cool,
                )
            }
            OutputKind::Poster(ty) => {
                let (rust, cool) = packet_type(ty);
                (
                    format!("::coolbot::port::PosterOut<{rust}>"),
                    "::coolbot::port::PosterOut::new()".to_owned(),
                    "::coolbot::OutputKind::Poster".to_owned(),
                    cool,
                )
            }
        };
        Some(ir::Port {
            doc: output.doc.clone(),
            cool_name: output.name.clone(),
            field,
            handle,
            ctor,
            kind,
            packet,
            pull: declared.pull,
        })
    }
}
