//! Lowering of compound components: the supervisor (states, sections, own variables),
//! the instances and everything the runtime's `coolbot::CompoundBuilder` is told
//! (connections, exports, mapped variables, policies, substitutes, redundant groups,
//! recovery) and the `when` rules, compiled to typed Rust over `coolbot::View`.
//!
//! Like the rest of lowering, this never fails: the checker has accepted the
//! description, and anything it would have rejected lowers to something harmless
//! (an unknown type reads as a missing value, which makes a comparison `false`).

use std::collections::BTreeSet;

use super::{
    GEN_TYPES, Lowerer, SectionOwner, StateSections, choose_stub, doc, duration_ns, duration_rust,
    may_targets, section_stubs, unique_among,
};
use crate::ast::{self, BinaryOp, ExprKind, FileId, Prim, TypeKind, UnaryOp};
use crate::check::model::{DEFAULT_STATES, RESULTS, Ty};
use crate::check::{RTy, Typed};
use crate::ident;
use crate::ir;

/// The supervisor state of a compound that declares none.
const IMPLICIT_STATE: &str = "supervising";

/// The `coolbot::TaskResult` pattern a `result` symbol (`check::model::RESULTS`)
/// stands for.
fn result_pattern(symbol: &str) -> Option<&'static str> {
    match symbol {
        "none" => Some("::coolbot::TaskResult::None"),
        "success" => Some("::coolbot::TaskResult::Success(_)"),
        "fail" => Some("::coolbot::TaskResult::Fail(_)"),
        _ => None,
    }
}

/// Where a typed node is missing (never in a checked model): an unknown type, which
/// reads as a missing value.
static UNKNOWN: Typed = Typed {
    ty: RTy::Unknown,
    operands: Vec::new(),
};

/// Operand `index` of a typed node.
fn part(typed: &Typed, index: usize) -> &Typed {
    typed.operands.get(index).unwrap_or(&UNKNOWN)
}

/// The Rust path of enum `name` as a compound module sees it.
fn enum_path(name: &str) -> String {
    format!("{GEN_TYPES}{}", ident::camel(name))
}

/// The checker's type of an operand as the generated Rust can read it: a packet, a
/// list or anything else that is not a rule value becomes [`RTy::Unknown`] (so
/// comparisons with it are `false`), also under `?`; `T??` reads as `T?`.
fn readable(ty: &RTy) -> RTy {
    match ty {
        RTy::Optional(inner) => match readable(inner) {
            RTy::Unknown => RTy::Unknown,
            RTy::Optional(inner) => RTy::Optional(inner),
            inner => RTy::Optional(Box::new(inner)),
        },
        RTy::Other(_) | RTy::Symbol(_) | RTy::Unknown => RTy::Unknown,
        other => other.clone(),
    }
}

/// Whether a type is unreadable: comparisons with it are `false`.
fn unreadable(ty: &RTy) -> bool {
    matches!(ty, RTy::Unknown | RTy::Other(_) | RTy::Symbol(_))
}

/// A rule operand: Rust text and its type.
#[derive(Clone, Debug)]
struct Operand {
    code: String,
    ty: RTy,
    /// `code` is an `Option` of the value (a read from the view that may be
    /// missing); `false` when `code` is the value itself.
    maybe: bool,
    /// An `f32` (or `f32?`) widened to `f64`: a float literal it is compared with is
    /// rounded to `f32` first.
    narrow: bool,
}

/// A compound's scope for rules and exports.
struct Scope<'a, 'b> {
    lowerer: &'b Lowerer<'a>,
    component: &'a ast::Component,
    /// The rule's supervisor state (own `user_state` is known statically).
    state: String,
    reads: Vec<String>,
    uses_view: bool,
    uses_vars: bool,
}

impl<'a> Lowerer<'a> {
    /// The instance `name` of `component`.
    fn instance_of(component: &'a ast::Component, name: &str) -> Option<&'a ast::Instance> {
        component.members.iter().find_map(|m| match m {
            ast::Member::Instance(i) if i.name.name == name => Some(i),
            _ => None,
        })
    }

    fn component_of(&self, instance: &ast::Instance) -> Option<&'a ast::Component> {
        self.checked
            .component(&instance.component.name)
            .map(|(_, component)| component)
    }

    /// The input or output (`input`) port `port` of `component`, followed through
    /// the exports of nested compounds to the atomic port that implements it.
    fn leaf_port(
        &self,
        component: &'a ast::Component,
        port: &str,
        input: bool,
        depth: usize,
    ) -> Option<LeafPort<'a>> {
        if depth > 64 {
            return None;
        }
        for member in &component.members {
            match member {
                ast::Member::Input(i) if input && i.name.name == port => {
                    return match &i.def {
                        ast::InputDef::Export(target) => {
                            self.exported_port(component, target, true, depth)
                        }
                        _ => Some(LeafPort::Input(i)),
                    };
                }
                ast::Member::Output(o) if !input && o.name.name == port => {
                    return match &o.def {
                        ast::OutputDef::Export(target) => {
                            self.exported_port(component, target, false, depth)
                        }
                        _ => Some(LeafPort::Output(o)),
                    };
                }
                _ => {}
            }
        }
        None
    }

    /// The atomic port an export of `component` names.
    fn exported_port(
        &self,
        component: &'a ast::Component,
        target: &ast::PortRef,
        input: bool,
        depth: usize,
    ) -> Option<LeafPort<'a>> {
        let instance = Self::instance_of(component, &target.instance.as_ref()?.name)?;
        let inner = self.component_of(instance)?;
        self.leaf_port(inner, &target.port.name, input, depth + 1)
    }

    /// The packet type of the port an export names: `Some(None)` for a tick port,
    /// `None` when it does not resolve.
    fn export_type(
        &self,
        component: &'a ast::Component,
        target: &ast::PortRef,
        input: bool,
    ) -> Option<Option<&'a ast::Type>> {
        Some(match self.exported_port(component, target, input, 0)? {
            LeafPort::Input(i) => match &i.def {
                ast::InputDef::Fifo { ty, .. }
                | ast::InputDef::Ufifo { ty, .. }
                | ast::InputDef::Last(ty)
                | ast::InputDef::Poster(ty) => Some(ty),
                ast::InputDef::Tick | ast::InputDef::Export(_) => None,
            },
            LeafPort::Output(o) => match &o.def {
                ast::OutputDef::Data(ty) | ast::OutputDef::Poster(ty) => Some(ty),
                ast::OutputDef::Tick | ast::OutputDef::Export(_) => None,
            },
        })
    }

    /// The spec entry (`coolbot::InputSpec`/`OutputSpec`) of an exported port: the
    /// atomic port's, under the compound's name for it.
    fn export_spec(
        &self,
        component: &'a ast::Component,
        name: &str,
        target: &ast::PortRef,
        input: bool,
    ) -> Option<String> {
        let port = match self.exported_port(component, target, input, 0)? {
            LeafPort::Input(i) => self.input(i),
            LeafPort::Output(o) => self.output(o),
        }?;
        let kind = if input { "InputSpec" } else { "OutputSpec" };
        Some(format!(
            "::coolbot::{kind} {{ name: {}, kind: {}, packet: {}, pull: {} }}",
            ident::string_literal(name),
            port.kind,
            ident::string_literal(&port.packet),
            port.pull
        ))
    }

    /// The declared type of variable `name` of `component` (through mapped variables
    /// of nested compounds), and whether it is observable (or controllable).
    fn variable_type(
        &self,
        component: &'a ast::Component,
        name: &str,
        depth: usize,
    ) -> Option<(&'a ast::Type, ast::VarKind)> {
        if depth > 64 {
            return None;
        }
        let variable = component.members.iter().find_map(|m| match m {
            ast::Member::Variable(v) if v.name.name == name => Some(v),
            _ => None,
        })?;
        match (&variable.ty, &variable.value) {
            (Some(ty), _) => Some((ty, variable.kind)),
            (None, Some(value)) => {
                let ExprKind::Path(segments) = &value.kind else {
                    return None;
                };
                let [instance, inner_var] = segments.as_slice() else {
                    return None;
                };
                let instance = Self::instance_of(component, &instance.name)?;
                let inner = self.component_of(instance)?;
                self.variable_type(inner, &inner_var.name, depth + 1)
                    .map(|(ty, _)| (ty, variable.kind))
            }
            (None, None) => None,
        }
    }

    /// The user states and quality levels of `component` (a compound's supervisor
    /// states are its user states).
    fn states_and_qualities(component: &ast::Component) -> (Vec<String>, Vec<String>) {
        let mut states = Vec::new();
        let mut qualities = Vec::new();
        for member in &component.members {
            match member {
                ast::Member::Automaton(a) if states.is_empty() => {
                    states = a.states.iter().map(|s| s.name.name.clone()).collect();
                }
                ast::Member::Timing(t) => {
                    for entry in &t.entries {
                        if let ast::TimingEntry::Quality(names, _) = entry {
                            qualities = names.iter().map(|n| n.name.clone()).collect();
                        }
                    }
                }
                _ => {}
            }
        }
        (states, qualities)
    }

    /// Whether compound `c` connects through a converter, itself or in a compound it
    /// nests at any depth: its builder then takes the converters as a type argument
    /// and passes them on to the nested builders.
    fn uses_converters(&self, c: &'a ast::Component, visiting: &mut BTreeSet<&'a str>) -> bool {
        let own = c
            .members
            .iter()
            .any(|m| matches!(m, ast::Member::Connect(k) if k.via.is_some()));
        own || self.nests_converters(c, visiting)
    }

    /// Whether an instance of compound `c` is a compound that uses converters.
    fn nests_converters(&self, c: &'a ast::Component, visiting: &mut BTreeSet<&'a str>) -> bool {
        if !visiting.insert(&c.name.name) {
            // A compound nesting itself was rejected by the checker.
            return false;
        }
        let nested = c.members.iter().any(|m| match m {
            ast::Member::Instance(i) => self.component_of(i).is_some_and(|t| {
                t.kind == ast::ComponentKind::Compound && self.uses_converters(t, visiting)
            }),
            _ => false,
        });
        visiting.remove(c.name.name.as_str());
        nested
    }

    /// Lowers compound `c` into the IR of its generated module.
    pub(super) fn compound(&self, c: &'a ast::Component, module: String) -> ir::Compound {
        let mut instances = Vec::new();
        let mut connections = Vec::new();
        let mut steps = Vec::new();
        let mut vars = Vec::new();
        let mut automaton = None;
        let mut timing = None;
        let mut recovery = None;
        let mut uses_converters = false;
        let mut input_specs = Vec::new();
        let mut output_specs = Vec::new();
        // `Parts` method names: `supervisor`, then one per instance.
        let mut part_names: Vec<String> = vec!["supervisor".to_owned()];
        let mut spec_index = 0;
        let mapped_controllables = Self::mapped_controllables(c);
        for member in &c.members {
            match member {
                ast::Member::Instance(i) => {
                    let method = unique_among(
                        ident::snake(&i.name.name),
                        part_names.iter().map(String::as_str),
                    );
                    part_names.push(method.clone());
                    instances.push(self.instance(i, method, &mapped_controllables));
                }
                ast::Member::Connect(connect) => {
                    let end = |p: &ast::PortRef| match &p.instance {
                        Some(i) => format!("{}.{}", i.name, p.port.name),
                        None => p.port.name.clone(),
                    };
                    let via = connect.via.as_ref().map(|v| ident::snake(&v.name));
                    uses_converters |= via.is_some();
                    connections.push(ir::Connection {
                        from: end(&connect.from),
                        to: end(&connect.to),
                        via,
                        converter: connect.via.as_ref().map(|v| v.name.clone()),
                    });
                }
                ast::Member::Input(input) => {
                    if let ast::InputDef::Export(target) = &input.def {
                        let address = port_address(target);
                        let name = ident::string_literal(&input.name.name);
                        let target_lit = ident::string_literal(&address);
                        let step = match self.export_type(c, target, true) {
                            Some(None) => format!(".export_tick_input({name}, {target_lit})"),
                            Some(Some(ty)) => format!(
                                ".export_input::<{}>({name}, {target_lit})",
                                self.rust_type(ty, GEN_TYPES)
                            ),
                            None => format!(".export_input::<()>({name}, {target_lit})"),
                        };
                        steps.push(step);
                        input_specs.extend(self.export_spec(c, &input.name.name, target, true));
                    }
                }
                ast::Member::Output(output) => {
                    if let ast::OutputDef::Export(target) = &output.def {
                        output_specs.extend(self.export_spec(c, &output.name.name, target, false));
                        let name = ident::string_literal(&output.name.name);
                        let target_lit = ident::string_literal(&port_address(target));
                        steps.push(match self.export_type(c, target, false) {
                            Some(None) => format!(".export_tick_output({name}, {target_lit})"),
                            Some(Some(ty)) => format!(
                                ".export_output::<{}>({name}, {target_lit})",
                                self.rust_type(ty, GEN_TYPES)
                            ),
                            None => format!(".export_output::<()>({name}, {target_lit})"),
                        });
                    }
                }
                ast::Member::Variable(v) => match (&v.ty, &v.value) {
                    (None, Some(value)) => {
                        if let ExprKind::Path(segments) = &value.kind {
                            let target: Vec<&str> =
                                segments.iter().map(|s| s.name.as_str()).collect();
                            let call = match v.kind {
                                ast::VarKind::Controllable => "map_controllable",
                                _ => "map_observable",
                            };
                            steps.push(format!(
                                ".{call}({}, {})",
                                ident::string_literal(&v.name.name),
                                ident::string_literal(&target.join("."))
                            ));
                        }
                    }
                    (Some(_), _) => {
                        if let Some(var) = self.variable(v, &mut spec_index, "vars") {
                            vars.push(var);
                        }
                    }
                    (None, None) => {}
                },
                ast::Member::OnError(on) => {
                    let policy = match on.policy.name.as_str() {
                        "restart" => "Restart",
                        "substitute" => "Substitute",
                        "ignore" => "Ignore",
                        _ => "Propagate",
                    };
                    steps.push(format!(
                        ".on_error({}, ::coolbot::Policy::{policy})",
                        ident::string_literal(&on.instance.name)
                    ));
                }
                ast::Member::Redundant(r) => {
                    let members: Vec<String> = r
                        .members
                        .iter()
                        .map(|m| ident::string_literal(&m.name))
                        .collect();
                    steps.push(format!(".redundant(&[{}])", members.join(", ")));
                }
                ast::Member::Recovery(r) => {
                    recovery.get_or_insert(r);
                }
                ast::Member::Restart(r) => {
                    if let Some((count, window)) = &r.limit {
                        // Checked: an integer in `1..=u32::MAX` and non-zero durations.
                        let count = match count.kind {
                            ExprKind::Int(n) => u32::try_from(n).unwrap_or(u32::MAX),
                            _ => u32::MAX,
                        };
                        steps.push(format!(
                            ".restart_budget({count}, {})",
                            duration_rust(duration_ns(window).unwrap_or(10_000_000_000))
                        ));
                    }
                    if let Some((first, last)) = &r.backoff {
                        steps.push(format!(
                            ".restart_backoff({}, {})",
                            duration_rust(duration_ns(first).unwrap_or(10_000_000)),
                            duration_rust(duration_ns(last).unwrap_or(1_000_000_000))
                        ));
                    }
                }
                ast::Member::Automaton(a) => {
                    automaton.get_or_insert(a);
                }
                ast::Member::Timing(t) => {
                    timing.get_or_insert(t);
                }
                _ => {}
            }
        }
        // Substitutes after every instance (a substitute may be declared before the
        // instance it stands for).
        for i in &instances {
            if let Some(primary) = &i.substitutes {
                steps.push(format!(
                    ".substitute({}, {})",
                    ident::string_literal(&i.name),
                    ident::string_literal(primary)
                ));
            }
        }
        if let Some(r) = recovery {
            let ns =
                |e: Option<&ast::Expr>, default: u64| e.and_then(duration_ns).unwrap_or(default);
            steps.push(format!(
                ".recovery({}, {})",
                duration_rust(ns(r.retry_every.as_ref(), 500_000_000)),
                duration_rust(ns(r.deadline.as_ref(), 5_000_000_000))
            ));
        }

        let supervisor = self.supervisor(c, automaton);
        let mut rules = Vec::new();
        for (state, condition, target) in &supervisor.when {
            let file = self
                .checked
                .component(&c.name.name)
                .map_or(FileId(0), |(file, _)| file);
            let typed = self.checked.rule(file, condition).unwrap_or(&UNKNOWN);
            let mut scope = Scope {
                lowerer: self,
                component: c,
                state: state.clone(),
                reads: Vec::new(),
                uses_view: false,
                uses_vars: false,
            };
            let expr = scope.boolean(condition, typed);
            let function = format!("__cool_rule_{}", rules.len());
            let reads: Vec<String> = scope
                .reads
                .iter()
                .map(|r| ident::string_literal(r))
                .collect();
            let call = match (scope.uses_view, scope.uses_vars) {
                (_, true) => format!(
                    "{{ let vars = ::std::sync::Arc::clone(&vars); move |view: &::coolbot::View| {function}(view, &__cool_lock(&vars)) }}"
                ),
                (_, false) => function.clone(),
            };
            rules.push(ir::Rule {
                state: ident::string_literal(state),
                target: ident::string_literal(target),
                reads: format!("&[{}]", reads.join(", ")),
                view_param: if scope.uses_view { "view" } else { "_" }.to_owned(),
                vars_param: if scope.uses_vars {
                    Some("vars".to_owned())
                } else {
                    None
                },
                function,
                expr,
                call,
                doc: format!(
                    "`when {}` in state `{state}` -> `{target}`",
                    show(condition)
                ),
            });
        }

        let handles = self.handles(c, &instances);
        let name = ident::camel_raw(&c.name.name);
        let parts = instances
            .iter()
            .map(|i| self.part_stub(i))
            .collect::<Vec<_>>();
        let mut all_parts = vec![ir::Method {
            name: "supervisor".to_owned(),
            doc: Vec::new(),
            signature: String::new(),
            user_signature: "fn supervisor(&mut self) -> impl Supervisor".to_owned(),
            stub_body: vec![
                "// The supervisor: its sections are the `impl Supervisor` above.".to_owned(),
                format!("{name}Supervisor::default()"),
            ],
        }];
        all_parts.extend(parts);
        ir::Compound {
            doc: doc(&c.doc),
            notes: ir::notes(&c.notes),
            type_name: c.name.name.clone(),
            module,
            user_struct: format!("{name}Parts"),
            supervisor_struct: format!("{name}Supervisor"),
            parts: all_parts,
            uses_converters: uses_converters || self.nests_converters(c, &mut BTreeSet::new()),
            instances,
            connections,
            steps,
            mapped: self.mapped_fields(c),
            input_specs,
            output_specs,
            vars,
            states: supervisor.states,
            initial: supervisor.initial,
            methods: supervisor.methods,
            section_arms: supervisor.section_arms,
            choose_arms: supervisor.choose_arms,
            timing: self.timing(timing),
            rules,
            handles,
        }
    }

    /// The typed handles of `c`'s instances for the supervisor's `Cx`: one per
    /// instance whose component is known, in declaration order.
    fn handles(&self, c: &'a ast::Component, instances: &[ir::Instance]) -> Vec<ir::Handle> {
        // Names the handles' methods and types must not take: `Instances` has no
        // other method; the types live beside the module's own.
        let mut methods: Vec<String> = Vec::new();
        let mut types: Vec<String> = Vec::new();
        let mut handles = Vec::new();
        for lowered in instances {
            let Some(instance) = Self::instance_of(c, &lowered.name) else {
                continue;
            };
            let (Some(component), Some(module)) =
                (self.component_of(instance), lowered.module.as_ref())
            else {
                continue;
            };
            let method = unique_among(
                ident::snake(&lowered.name),
                methods.iter().map(String::as_str),
            );
            methods.push(method.clone());
            let type_name = unique_among(
                format!("{}Instance", ident::camel_raw(&lowered.name)),
                types.iter().map(String::as_str),
            );
            types.push(type_name.clone());
            let mut setters = Vec::new();
            let mut config = None;
            for member in &component.members {
                match member {
                    ast::Member::Variable(v) if v.kind == ast::VarKind::Controllable => {
                        let Some((ty, _)) = self.variable_type(component, &v.name.name, 0) else {
                            continue;
                        };
                        let rust_ty = self.rust_type(ty, GEN_TYPES);
                        // A type holding an array longer than 32 elements goes through
                        // its serde_with adapter, as the instance's own variable does.
                        let to_value = match (super::serde_adapter(ty), &ty.kind) {
                            (Some(adapter), _) => format!(
                                "super::__cool_to_value(&{}ser::SerializeAsWrap::<{rust_ty}, {adapter}>::new(&value))",
                                super::SERDE_WITH
                            ),
                            (None, TypeKind::Prim(_)) => "::coolbot::Value::from(value)".to_owned(),
                            (None, _) => "super::__cool_to_value(&value)".to_owned(),
                        };
                        setters.push(ir::Setter {
                            method: ident::method("set_", &v.name.name, ""),
                            variable: v.name.name.clone(),
                            ty: rust_ty,
                            to_value,
                        });
                    }
                    ast::Member::Configuration(block)
                        if !lowered.compound && !block.fields.is_empty() =>
                    {
                        config = Some(format!("super::{module}::Config"));
                    }
                    _ => {}
                }
            }
            let (_, mut levels) = Self::states_and_qualities(component);
            if let Some(own) = instance.timing.as_ref().and_then(|timing| {
                timing.entries.iter().find_map(|entry| match entry {
                    ast::TimingEntry::Quality(levels, _) => Some(levels),
                    _ => None,
                })
            }) {
                levels = own.iter().map(|level| level.name.clone()).collect();
            }
            let quality = (levels.len() >= 2).then(|| {
                let name = unique_among(
                    format!("{}Quality", ident::camel_raw(&lowered.name)),
                    types.iter().map(String::as_str),
                );
                types.push(name.clone());
                let variants = levels
                    .iter()
                    .map(|level| (ident::camel(level), level.clone()))
                    .collect();
                (name, variants)
            });
            handles.push(ir::Handle {
                instance: lowered.name.clone(),
                method,
                type_name,
                component: lowered.component.clone(),
                setters,
                config,
                quality,
            });
        }
        handles
    }

    /// The mapped controllable variables of compound `c`: `(name, instance,
    /// variable)`, in declaration order.
    fn mapped_controllables(c: &'a ast::Component) -> Vec<(&'a str, &'a str, &'a str)> {
        c.members
            .iter()
            .filter_map(|m| match m {
                ast::Member::Variable(v)
                    if v.ty.is_none() && v.kind == ast::VarKind::Controllable =>
                {
                    match &v.value.as_ref()?.kind {
                        ExprKind::Path(segments) => match segments.as_slice() {
                            [instance, variable] => Some((
                                v.name.name.as_str(),
                                instance.name.as_str(),
                                variable.name.as_str(),
                            )),
                            _ => None,
                        },
                        _ => None,
                    }
                }
                _ => None,
            })
            .collect()
    }

    /// The `Mapped` fields of compound `c`: one per mapped controllable variable,
    /// typed like the instance variable it names.
    fn mapped_fields(&self, c: &'a ast::Component) -> Vec<ir::MappedField> {
        Self::mapped_controllables(c)
            .into_iter()
            .map(|(name, instance, variable)| {
                let ty = Self::instance_of(c, instance)
                    .and_then(|i| self.component_of(i))
                    .and_then(|t| self.variable_type(t, variable, 0))
                    .map(|(ty, _)| {
                        let rust = self.rust_type(ty, GEN_TYPES);
                        if self.defaultable(ty, &mut BTreeSet::new()) {
                            rust
                        } else {
                            // Its `Vars` field has no default: an `Option` itself.
                            format!("::core::option::Option<{rust}>")
                        }
                    })
                    .unwrap_or_else(|| "()".to_owned());
                ir::MappedField {
                    name: ident::snake(name),
                    cool_name: name.to_owned(),
                    target: format!("{instance}.{variable}"),
                    ty,
                }
            })
            .collect()
    }

    /// One instance: how the builder makes its component. `mapped` are the mapped
    /// controllable variables of the enclosing compound (their initial values,
    /// given to `builder_with`, go to the instance).
    fn instance(
        &self,
        i: &'a ast::Instance,
        method: String,
        mapped: &[(&str, &str, &str)],
    ) -> ir::Instance {
        let target = self.component_of(i);
        let module = target.and_then(|t| self.modules.get(t.name.name.as_str()).cloned());
        let compound = target.is_some_and(|t| t.kind == ast::ComponentKind::Compound);
        let name = ident::string_literal(&i.name.name);
        let config_overrides = self.overrides(i, true);
        let var_overrides = self.overrides(i, false);
        // The enclosing compound's mapped controllables that name this instance:
        // `(instance variable, field of the enclosing `Mapped`)`.
        let from_mapped: Vec<(String, String)> = mapped
            .iter()
            .filter(|(_, instance, _)| *instance == i.name.name)
            .map(|(name, _, variable)| (ident::snake(variable), ident::snake(name)))
            .collect();
        // A nested compound's own mapped controllables, overridden here or fed from
        // the enclosing `Mapped`.
        let inner_mapped: Vec<(&str, &str, &str)> = match target {
            Some(t) if compound => Self::mapped_controllables(t),
            _ => Vec::new(),
        };
        let is_inner_mapped = |field: &str| {
            inner_mapped
                .iter()
                .any(|(n, _, _)| ident::snake(n) == field)
        };
        let mut mapped_overrides: Vec<(String, String)> = Vec::new();
        if let Some(t) = target.filter(|_| compound) {
            for o in &i.overrides {
                let field = ident::snake(&o.name.name);
                if !is_inner_mapped(&field) {
                    continue;
                }
                if let Some((ty, _)) = self.variable_type(t, &o.name.name, 0) {
                    let value = self.value(&o.value, Some(ty), GEN_TYPES);
                    let value = if self.defaultable(ty, &mut BTreeSet::new()) {
                        value
                    } else {
                        format!("::core::option::Option::Some({value})")
                    };
                    mapped_overrides.push((field, value));
                }
            }
        }
        let component = module.as_ref().map(|module| {
            let (config_fields, var_fields) = target.map(field_counts).unwrap_or_default();
            let vars_from_mapped: Vec<(String, String)> = from_mapped
                .iter()
                .filter(|(field, _)| !is_inner_mapped(field))
                .cloned()
                .collect();
            let mapped_from_mapped: Vec<(String, String)> = from_mapped
                .iter()
                .filter(|(field, _)| is_inner_mapped(field))
                .cloned()
                .collect();
            let config = fields(
                module,
                "Config",
                &config_overrides,
                &[],
                config_fields,
                false,
            );
            let vars = fields(
                module,
                "Vars",
                &var_overrides,
                &vars_from_mapped,
                var_fields,
                false,
            );
            let nested = fields(
                module,
                "Mapped",
                &mapped_overrides,
                &mapped_from_mapped,
                inner_mapped.len(),
                true,
            );
            let plain = config_overrides.is_empty()
                && var_overrides.is_empty()
                && from_mapped.is_empty()
                && mapped_overrides.is_empty();
            // A nested compound that uses converters gets the enclosing compound's.
            let converters = match target {
                Some(t) if compound && self.uses_converters(t, &mut BTreeSet::new()) => "::<C>",
                _ => "",
            };
            match (compound, plain) {
                (true, true) => format!(
                    "super::{module}::component{converters}({name}, parts.{method}())?"
                ),
                (true, false) => format!(
                    "super::{module}::component_with{converters}({name}, parts.{method}(), {vars}, {nested})?"
                ),
                (false, true) => format!("super::{module}::component({name}, parts.{method}())"),
                (false, false) => format!(
                    "super::{module}::component_with({name}, parts.{method}(), {config}, {vars})"
                ),
            }
        });
        let var_overrides: Vec<(String, String)> =
            var_overrides.into_iter().chain(mapped_overrides).collect();
        let applied: BTreeSet<&str> = config_overrides
            .iter()
            .chain(&var_overrides)
            .map(|(field, _)| field.as_str())
            .collect();
        let unapplied: Vec<String> = i
            .overrides
            .iter()
            .filter(|o| !applied.contains(ident::snake(&o.name.name).as_str()))
            .map(|o| o.name.name.clone())
            .collect();
        let timing = match (&module, &i.timing) {
            (Some(module), Some(t)) => {
                Some(self.timing_override(t, &format!("super::{module}::SPEC.timing")))
            }
            _ => None,
        };
        let component = match (component, &timing) {
            (Some(build), Some(timing)) => Some(format!("{build}.with_timing({timing})")),
            (build, _) => build,
        };
        ir::Instance {
            name: i.name.name.clone(),
            method,
            component: i.component.name.clone(),
            module,
            compound,
            substitutes: i.substitutes.as_ref().map(|s| s.name.clone()),
            node: i.node.as_ref().map(|n| n.value.clone()),
            build: component,
            timing,
            unapplied,
            config_overrides,
            var_overrides,
        }
    }

    /// An instance's `timing { ... }`: the entries it names replace those of the
    /// component's block (`base`), the others are kept.
    fn timing_override(&self, timing: &ast::Timing, base: &str) -> String {
        let mut fields = Vec::new();
        let option = |ns: Option<u64>| match ns {
            Some(ns) => format!("::core::option::Option::Some({})", duration_rust(ns)),
            None => "::core::option::Option::None".to_owned(),
        };
        for entry in &timing.entries {
            match entry {
                ast::TimingEntry::Period(interval) => {
                    fields.push(("period", option(duration_ns(&interval.lo))));
                    fields.push((
                        "max_period",
                        option(interval.hi.as_ref().and_then(duration_ns)),
                    ));
                }
                ast::TimingEntry::MaxResponse(e) => {
                    fields.push(("max_response", option(duration_ns(e))));
                }
                ast::TimingEntry::Priority(e) => {
                    let priority = super::int_value(e)
                        .unwrap_or(0)
                        .clamp(i32::MIN.into(), i32::MAX.into());
                    fields.push(("priority", priority.to_string()));
                }
                ast::TimingEntry::Quality(names, _) => {
                    let names: Vec<String> = names
                        .iter()
                        .map(|n| ident::string_literal(&n.name))
                        .collect();
                    fields.push(("qualities", format!("&[{}]", names.join(", "))));
                }
            }
        }
        // A later entry of the same kind wins, as in a component's block.
        let mut text = String::from("::coolbot::TimingSpec { ");
        let mut named = Vec::new();
        for (index, (field, value)) in fields.iter().enumerate() {
            if fields[index + 1..].iter().any(|(f, _)| f == field) {
                continue;
            }
            named.push(*field);
            text.push_str(&format!("{field}: {value}, "));
        }
        if named.len() < 5 {
            text.push_str(&format!("..{base}"));
        }
        text.push_str(" }");
        text
    }

    /// The `Parts` method of an instance, with its user stub.
    fn part_stub(&self, i: &ir::Instance) -> ir::Method {
        let module = i.module.clone().unwrap_or_else(|| "types".to_owned());
        let (returns, body) = if i.compound {
            (
                format!("impl crate::generated::{module}::Parts"),
                format!(
                    "crate::{module}::{}Parts::default()",
                    ident::camel_raw(&i.component)
                ),
            )
        } else {
            (
                format!("impl crate::generated::{module}::Behavior"),
                format!("crate::{module}::{}::default()", ident::camel(&i.component)),
            )
        };
        ir::Method {
            name: i.method.clone(),
            doc: Vec::new(),
            signature: String::new(),
            user_signature: format!("fn {}(&mut self) -> {returns}", i.method),
            stub_body: vec![
                format!(
                    "// Instance `{}`: the {} it runs.",
                    i.name,
                    if i.compound { "parts" } else { "behavior" }
                ),
                body,
            ],
        }
    }
}

/// An atomic port an export leads to.
enum LeafPort<'a> {
    Input(&'a ast::Input),
    Output(&'a ast::Output),
}

/// The lowered supervisor automaton.
struct Supervisor {
    states: Vec<ir::State>,
    initial: usize,
    methods: Vec<ir::Method>,
    section_arms: Vec<(String, String)>,
    choose_arms: Vec<ir::ChooseArm>,
    /// `(state, condition, target)` of every `when`, in order.
    when: Vec<(String, ast::Expr, String)>,
}

impl Lowerer<'_> {
    fn supervisor(&self, c: &ast::Component, automaton: Option<&ast::Automaton>) -> Supervisor {
        let states_ast: Vec<&ast::State> = automaton
            .map(|a| a.states.iter().collect())
            .unwrap_or_default();
        let state_index = |name: &str| {
            states_ast
                .iter()
                .position(|s| s.name.name == name)
                .unwrap_or(0)
        };
        let input_index = |name: &str| {
            c.members
                .iter()
                .filter(|m| matches!(m, ast::Member::Input(_)))
                .position(|m| matches!(m, ast::Member::Input(i) if i.name.name == name))
                .unwrap_or(0)
        };
        let initial = automaton
            .and_then(|a| a.initial.first())
            .map(|i| state_index(&i.name))
            .unwrap_or(0);
        let mut states = Vec::new();
        let mut methods = Vec::new();
        let mut section_arms = Vec::new();
        let mut choose_arms = Vec::new();
        let mut when = Vec::new();
        for (index, state) in states_ast.iter().enumerate() {
            let name = &state.name.name;
            let (mut entry, mut exit, mut periodic) = (false, false, None);
            let (mut on, mut after, mut may) = (Vec::new(), Vec::new(), Vec::new());
            for member in &state.members {
                match member {
                    ast::StateMember::Entry(_) => entry = true,
                    ast::StateMember::Exit(_) => exit = true,
                    ast::StateMember::Periodic { period, .. } => {
                        periodic = Some(format!(
                            "Some(::coolbot::PeriodicSpec {{ period: {} }})",
                            super::option_duration(period.as_ref())
                        ));
                    }
                    ast::StateMember::On { port, target, .. } => on.push(format!(
                        "::coolbot::OnSpec {{ port: {}, target: {} }}",
                        input_index(&port.name),
                        state_index(&target.name)
                    )),
                    ast::StateMember::After {
                        delay,
                        without,
                        target,
                        ..
                    } => after.push(format!(
                        "::coolbot::AfterSpec {{ delay: {}, without: {}, target: {} }}",
                        duration_rust(duration_ns(delay).unwrap_or_default()),
                        match without {
                            Some(port) => format!("Some({})", input_index(&port.name)),
                            None => "None".to_owned(),
                        },
                        state_index(&target.name)
                    )),
                    ast::StateMember::When {
                        condition, target, ..
                    } => when.push((name.clone(), condition.clone(), target.name.clone())),
                    ast::StateMember::May { targets, .. } => {
                        may_targets(targets, &state_index, &mut may);
                    }
                }
            }
            section_stubs(
                &StateSections {
                    index,
                    name,
                    entry,
                    periodic: periodic.is_some(),
                    exit,
                    docs: super::SectionDocs::of(state),
                },
                SectionOwner::Supervisor,
                &mut methods,
                &mut section_arms,
            );
            let may_enum = (!may.is_empty()).then(|| format!("{}May", ident::camel_raw(name)));
            if let Some(may_enum) = &may_enum {
                choose_stub(
                    index,
                    name,
                    may_enum,
                    &may,
                    &super::SectionDocs::of(state).may,
                    &mut methods,
                    &mut choose_arms,
                );
            }
            let spec = format!(
                "::coolbot::StateSpec {{ name: {}, entry: {entry}, exit: {exit}, periodic: {}, on: &[{}], after: &[{}], may: &[{}] }}",
                ident::string_literal(name),
                periodic.unwrap_or_else(|| "None".to_owned()),
                on.join(", "),
                after.join(", "),
                may.iter()
                    .map(|(_, i, _)| i.to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
            states.push(ir::State {
                doc: doc(&state.doc),
                cool_name: name.clone(),
                variant: ident::camel(name),
                may_enum,
                may,
                spec,
            });
        }
        if states.is_empty() {
            // No `supervisor { ... }`: one state without sections, so the compound
            // has a user automaton like every component.
            states.push(ir::State {
                doc: vec!["The only state of a compound without a `supervisor` block.".to_owned()],
                cool_name: IMPLICIT_STATE.to_owned(),
                variant: ident::camel(IMPLICIT_STATE),
                may_enum: None,
                may: Vec::new(),
                spec: format!(
                    "::coolbot::StateSpec {{ name: {}, entry: false, exit: false, periodic: None, on: &[], after: &[], may: &[] }}",
                    ident::string_literal(IMPLICIT_STATE)
                ),
            });
        }
        Supervisor {
            states,
            initial,
            methods,
            section_arms,
            choose_arms,
            when,
        }
    }
}

/// A struct expression `super::<module>::<kind> { ... }` setting `overrides`
/// (`(field, value)`) and fields fed from the enclosing compound's `Mapped`
/// (`(field, Mapped field)`), the others from `Default` (no struct update when every
/// one of the `all` fields is named: clippy's `needless_update`). `optional`: the
/// fields are `Option`s (a `Mapped`), so a given value wins over the written one
/// with `or`, not `unwrap_or`.
fn fields(
    module: &str,
    kind: &str,
    overrides: &[(String, String)],
    from_mapped: &[(String, String)],
    all: usize,
    optional: bool,
) -> String {
    let path = format!("super::{module}::{kind}");
    let mut named: Vec<&str> = Vec::new();
    for (field, _) in overrides.iter().chain(from_mapped) {
        if !named.contains(&field.as_str()) {
            named.push(field);
        }
    }
    if named.is_empty() {
        return format!("{path}::default()");
    }
    let mut entries = Vec::new();
    for field in &named {
        let written = overrides.iter().find(|(f, _)| f == field).map(|(_, v)| {
            if optional {
                format!("::core::option::Option::Some({v})")
            } else {
                v.clone()
            }
        });
        let given: Vec<String> = from_mapped
            .iter()
            .filter(|(f, _)| f == field)
            .map(|(_, m)| format!("mapped.{m}"))
            .collect();
        let value = match (given.split_first(), written.as_ref()) {
            (None, Some(written)) => written.clone(),
            (None, None) => format!("{path}::default().{field}"),
            (Some((first, rest)), written) => {
                let mut chain = first.clone();
                for other in rest {
                    chain.push_str(&format!(".or({other})"));
                }
                match (optional, written) {
                    (true, Some(written)) => format!("{chain}.or({written})"),
                    (true, None) => chain,
                    (false, Some(written)) => format!("{chain}.unwrap_or({written})"),
                    (false, None) => {
                        format!("{chain}.unwrap_or_else(|| {path}::default().{field})")
                    }
                }
            }
        };
        entries.push(format!("{field}: {value}"));
    }
    if named.len() < all {
        entries.push(format!("..{path}::default()"));
    }
    format!("{path} {{ {} }}", entries.join(", "))
}

/// How many fields an atomic component's `Config` and `Vars` have.
fn field_counts(component: &ast::Component) -> (usize, usize) {
    let mut config = 0;
    let mut vars = 0;
    for member in &component.members {
        match member {
            ast::Member::Configuration(c) => config += c.fields.len(),
            ast::Member::Variable(v) if v.ty.is_some() => vars += 1,
            _ => {}
        }
    }
    (config, vars)
}

fn port_address(target: &ast::PortRef) -> String {
    match &target.instance {
        Some(i) => format!("{}.{}", i.name, target.port.name),
        None => target.port.name.clone(),
    }
}

/// A rule condition as written (for the generated documentation).
fn show(expr: &ast::Expr) -> String {
    match &expr.kind {
        ExprKind::Int(n) => n.to_string(),
        ExprKind::Float(x) => format!("{x:?}"),
        ExprKind::Str(s) => format!("{s:?}"),
        ExprKind::Bool(b) => b.to_string(),
        ExprKind::Duration(ns) => match *ns {
            ns if ns > 0 && ns % 60_000_000_000 == 0 => format!("{}min", ns / 60_000_000_000),
            ns if ns > 0 && ns % 1_000_000_000 == 0 => format!("{}s", ns / 1_000_000_000),
            ns if ns > 0 && ns % 1_000_000 == 0 => format!("{}ms", ns / 1_000_000),
            ns if ns > 0 && ns % 1_000 == 0 => format!("{}us", ns / 1_000),
            ns => format!("{ns}ns"),
        },
        ExprKind::Frequency(hz) => format!("{hz}Hz"),
        ExprKind::Path(parts) => parts
            .iter()
            .map(|p| p.name.as_str())
            .collect::<Vec<_>>()
            .join("."),
        ExprKind::EnumValue { enum_name, variant } => {
            format!("{}::{}", enum_name.name, variant.name)
        }
        ExprKind::List(items) => format!(
            "[{}]",
            items.iter().map(show).collect::<Vec<_>>().join(", ")
        ),
        ExprKind::Repeat(item, n) => format!("[{}; {}]", show(item), n.value),
        ExprKind::None => "none".to_owned(),
        ExprKind::Unary(UnaryOp::Not, inner) => format!("!{}", show_operand(inner)),
        ExprKind::Unary(UnaryOp::Neg, inner) => format!("-{}", show_operand(inner)),
        ExprKind::Binary(op @ (BinaryOp::And | BinaryOp::Or), l, r) => {
            let side = |e: &ast::Expr| {
                if needs_parens(*op, e) {
                    format!("({})", show(e))
                } else {
                    show(e)
                }
            };
            format!("{} {} {}", side(l), op.as_str(), side(r))
        }
        ExprKind::Binary(op, l, r) => {
            format!("{} {} {}", show_operand(l), op.as_str(), show_operand(r))
        }
    }
}

fn show_operand(expr: &ast::Expr) -> String {
    match &expr.kind {
        ExprKind::Binary(..) => format!("({})", show(expr)),
        _ => show(expr),
    }
}

/// Whether `operand` of logical operator `op` needs parentheses: an `||` inside an
/// `&&` (comparisons and `&&` bind tighter than `||`, comparisons tighter than
/// `&&`).
fn needs_parens(op: BinaryOp, operand: &ast::Expr) -> bool {
    op == BinaryOp::And && matches!(operand.kind, ExprKind::Binary(BinaryOp::Or, ..))
}

impl Scope<'_, '_> {
    fn read(&mut self, name: String) {
        if !self.reads.contains(&name) {
            self.reads.push(name);
        }
    }

    /// A boolean Rust expression for `expr`, typed `typed` by the checker (a missing
    /// or unreadable value makes the comparison that reads it `false`).
    fn boolean(&mut self, expr: &ast::Expr, typed: &Typed) -> String {
        match &expr.kind {
            ExprKind::Binary(op @ (BinaryOp::And | BinaryOp::Or), l, r) => {
                let l = self.logic_operand(*op, l, part(typed, 0));
                let r = self.logic_operand(*op, r, part(typed, 1));
                format!("{l} {} {r}", op.as_str())
            }
            ExprKind::Binary(op, l, r) => {
                self.comparison(*op, (l, part(typed, 0)), (r, part(typed, 1)))
            }
            ExprKind::Unary(UnaryOp::Not, inner) => {
                let text = self.boolean(inner, part(typed, 0));
                match &inner.kind {
                    ExprKind::Binary(..) => format!("!({text})"),
                    _ => format!("!{text}"),
                }
            }
            _ => {
                let operand = self.operand(expr, typed);
                match (operand.ty, operand.maybe) {
                    (RTy::Bool, false) => operand.code,
                    (RTy::Bool, true) => format!("{}.unwrap_or(false)", operand.code),
                    _ => "false".to_owned(),
                }
            }
        }
    }

    /// An operand of `&&` or `||` (`op`): parenthesized only where Rust's precedence
    /// would read it otherwise (an `||` inside an `&&`).
    fn logic_operand(&mut self, op: BinaryOp, expr: &ast::Expr, typed: &Typed) -> String {
        let text = self.boolean(expr, typed);
        if needs_parens(op, expr) {
            format!("({text})")
        } else {
            text
        }
    }

    /// An operand of a comparison (or a bare boolean).
    fn operand(&mut self, expr: &ast::Expr, typed: &Typed) -> Operand {
        let known = |code: String, ty: RTy| Operand {
            code,
            ty,
            maybe: false,
            narrow: false,
        };
        match &expr.kind {
            ExprKind::Int(n) => known(n.to_string(), RTy::Int),
            ExprKind::Float(x) => known(format!("{x:?}"), RTy::Float),
            ExprKind::Str(s) => known(ident::string_literal(s), RTy::Str),
            ExprKind::Bool(b) => known(b.to_string(), RTy::Bool),
            ExprKind::Duration(_) => known(
                duration_rust(duration_ns(expr).unwrap_or_default()),
                RTy::Duration,
            ),
            ExprKind::None => known(String::new(), RTy::NoneLit),
            ExprKind::EnumValue { enum_name, variant } => known(
                format!(
                    "{}::{}",
                    enum_path(&enum_name.name),
                    ident::camel(&variant.name)
                ),
                RTy::Enum(enum_name.name.clone()),
            ),
            ExprKind::Unary(UnaryOp::Neg, inner) => match self.operand(inner, part(typed, 0)) {
                Operand {
                    code,
                    ty: ty @ (RTy::Int | RTy::Float),
                    maybe: false,
                    narrow,
                } => Operand {
                    narrow,
                    ..known(format!("-{code}"), ty)
                },
                Operand {
                    code,
                    ty: ty @ (RTy::Int | RTy::Float),
                    maybe: true,
                    narrow,
                } => Operand {
                    code: format!("{code}.map(|value| -value)"),
                    ty,
                    maybe: true,
                    narrow,
                },
                _ => known(String::new(), RTy::Unknown),
            },
            ExprKind::Unary(UnaryOp::Not, _) | ExprKind::Binary(..) => {
                known(format!("({})", self.boolean(expr, typed)), RTy::Bool)
            }
            ExprKind::Path(segments) => match segments.as_slice() {
                [name] => self.own(&name.name, &typed.ty),
                [instance, variable] => {
                    self.variable_operand(&instance.name, &variable.name, None, &typed.ty)
                }
                _ => known(String::new(), RTy::Unknown),
            },
            ExprKind::Frequency(_) | ExprKind::List(_) | ExprKind::Repeat(..) => {
                known(String::new(), RTy::Unknown)
            }
        }
    }

    /// A bare name of type `ty`: an own variable, a mapped one, an own default
    /// variable, or a symbol (`ty` is then what the checker resolved it to).
    fn own(&mut self, name: &str, ty: &RTy) -> Operand {
        let unreadable = Operand {
            code: String::new(),
            ty: RTy::Unknown,
            maybe: false,
            narrow: false,
        };
        let component = self.component;
        let variable = component.members.iter().find_map(|m| match m {
            ast::Member::Variable(v) if v.name.name == name => Some(v),
            _ => None,
        });
        if let Some(v) = variable {
            return match (&v.ty, &v.value) {
                (Some(declared), _) => {
                    if v.kind != ast::VarKind::Local {
                        self.read(name.to_owned());
                    }
                    self.uses_vars = true;
                    let field = format!("vars.{}", ident::snake(name));
                    let has_default = v.value.is_some()
                        || self.lowerer.defaultable(declared, &mut BTreeSet::new());
                    let f64_field = is_f64(declared);
                    let ty = readable(ty);
                    if !has_default {
                        // Held as `Option<T>` until set: read it as a missing value.
                        return own_value(&format!("{field}.as_ref()"), &ty, true, f64_field);
                    }
                    own_value(&field, &ty, false, f64_field)
                }
                (None, Some(value)) => match &value.kind {
                    ExprKind::Path(segments) => match segments.as_slice() {
                        // Read with `view.mapped(name)`, from the instance standing
                        // for `instance` now.
                        [instance, variable] => {
                            self.variable_operand(&instance.name, &variable.name, Some(name), ty)
                        }
                        _ => unreadable,
                    },
                    _ => unreadable,
                },
                (None, None) => unreadable,
            };
        }
        match name {
            // Rules are evaluated while the compound runs.
            "state" => Operand {
                code: "::coolbot::State::Running".to_owned(),
                ty: RTy::State,
                maybe: false,
                narrow: false,
            },
            // A rule is evaluated in its own supervisor state.
            "user_state" => Operand {
                code: ident::string_literal(&self.state),
                ty: readable(ty),
                maybe: false,
                narrow: false,
            },
            // The compound's own default observables, copied into the view at each
            // supervision turn.
            "result" | "error" | "cpu_time" | "elapsed_time" | "quality" => {
                self.read(name.to_owned());
                self.uses_view = true;
                let (code, ty, maybe) = match name {
                    "result" => (
                        "::core::option::Option::Some(view.own_result())".to_owned(),
                        RTy::Result,
                        true,
                    ),
                    "error" => (
                        "view.own_error().unwrap_or(\"\")".to_owned(),
                        RTy::Str,
                        false,
                    ),
                    "quality" => ("view.own_quality()".to_owned(), readable(ty), false),
                    _ => (format!("view.own_{name}()"), RTy::Duration, false),
                };
                Operand {
                    code,
                    ty,
                    maybe,
                    narrow: false,
                }
            }
            _ => symbol(name, ty),
        }
    }

    /// `instance.variable` of type `ty`, read from the view; through mapped variable
    /// `mapped` when given and `variable` is one of the instance's own (a default
    /// variable, `state`..., is read on `instance` itself).
    fn variable_operand(
        &mut self,
        instance: &str,
        variable: &str,
        mapped: Option<&str>,
        ty: &RTy,
    ) -> Operand {
        let unreadable = Operand {
            code: String::new(),
            ty: RTy::Unknown,
            maybe: false,
            narrow: false,
        };
        let Some(interface) = Lowerer::instance_of(self.component, instance)
            .and_then(|i| self.lowerer.checked.interface(&i.component.name))
        else {
            return unreadable;
        };
        let lit = ident::string_literal(instance);
        let maybe = |code: String, ty: RTy| Operand {
            code,
            ty,
            maybe: true,
            narrow: false,
        };
        let ty = readable(ty);
        if let Some(declared) = interface.variables.get(variable) {
            let raw = match mapped {
                Some(name) => {
                    self.read(name.to_owned());
                    format!("view.mapped({})", ident::string_literal(name))
                }
                None => {
                    self.read(format!("{instance}.{variable}"));
                    format!("view.var({lit}, {})", ident::string_literal(variable))
                }
            };
            self.uses_view = true;
            let f64_field = holds_f64(&declared.ty);
            return match view_value(&raw, &ty) {
                Some(code) => Operand {
                    narrow: !f64_field && is_float(&ty),
                    ..maybe(code, ty)
                },
                None => unreadable,
            };
        }
        let code = match variable {
            "state" => format!("view.state({lit})"),
            "user_state" => format!("view.user_state({lit})"),
            "result" => format!("view.result({lit})"),
            // No error reads as the empty one: `error != "x"` holds then.
            "error" => {
                self.read(format!("{instance}.error"));
                self.uses_view = true;
                return Operand {
                    code: format!("view.error({lit}).unwrap_or(\"\")"),
                    ty: RTy::Str,
                    maybe: false,
                    narrow: false,
                };
            }
            "cpu_time" | "elapsed_time" | "quality" => {
                format!("view.monitor({lit}).map(|monitor| monitor.{variable})")
            }
            _ => return unreadable,
        };
        // (`cpu_time` and `elapsed_time` have no change event of their own: the
        // runtime counts them as changed every supervisor period.)
        self.read(format!("{instance}.{variable}"));
        self.uses_view = true;
        maybe(code, ty)
    }

    /// `left op right`, each with its typed node.
    fn comparison(
        &mut self,
        op: BinaryOp,
        (left, left_typed): (&ast::Expr, &Typed),
        (right, right_typed): (&ast::Expr, &Typed),
    ) -> String {
        let mut l = self.operand(left, left_typed);
        let mut r = self.operand(right, right_typed);
        if unreadable(&l.ty) || unreadable(&r.ty) {
            return "false".to_owned();
        }
        // An `f32` compared with a float literal: the literal rounded to `f32`, as the
        // variable holds it.
        if l.narrow
            && let Some(literal) = f32_literal(right)
        {
            r.code = literal;
        }
        if r.narrow
            && let Some(literal) = f32_literal(left)
        {
            l.code = literal;
        }
        // `user_state == on`: a missing user state (the automaton has not started)
        // differs from every state, for `!=` too.
        if matches!(l.ty, RTy::UserState(..)) && l.maybe != r.maybe {
            let (maybe, plain) = if l.maybe { (&l, &r) } else { (&r, &l) };
            return format!(
                "{} {} ::core::option::Option::Some({})",
                maybe.code,
                op.as_str(),
                plain.code
            );
        }
        // `x != v` is `!(x == v)`, also when a side is missing.
        if op == BinaryOp::Ne && (l.maybe || r.maybe) {
            return format!("!({})", self.compare(BinaryOp::Eq, l, r));
        }
        self.compare(op, l, r)
    }

    /// `l op r`, both operands resolved (`!=` over a missing value is handled by
    /// the caller).
    fn compare(&mut self, op: BinaryOp, mut l: Operand, mut r: Operand) -> String {
        let rust_op = op.as_str();
        // `x == none`, `x != none`.
        if r.ty == RTy::NoneLit {
            std::mem::swap(&mut l, &mut r);
        }
        if l.ty == RTy::NoneLit {
            let test = match op {
                BinaryOp::Ne => "is_some",
                _ => "is_none",
            };
            return match (&r.ty, r.maybe) {
                (RTy::Optional(_), false) => format!("{}.{test}()", r.code),
                (RTy::Optional(_), true) => {
                    format!("{}.is_some_and(|value| value.{test}())", r.code)
                }
                (RTy::Result, _) => {
                    let pattern = "::coolbot::TaskResult::None";
                    let negate = if op == BinaryOp::Ne { "!" } else { "" };
                    format!(
                        "{}.is_some_and(|result| {negate}::core::matches!(result, {pattern}))",
                        r.code
                    )
                }
                _ => "false".to_owned(),
            };
        }
        // `result == fail`: a pattern match.
        if l.ty == RTy::Result && r.ty == RTy::Result {
            return self.result_comparison(op, &l, &r);
        }
        let l_opt = matches!(l.ty, RTy::Optional(_));
        let r_opt = matches!(r.ty, RTy::Optional(_));
        // An ordering with an optional side: `none` satisfies none of them.
        if (l_opt || r_opt) && op != BinaryOp::Eq && op != BinaryOp::Ne {
            return ordering(rust_op, &l, &r);
        }
        // One optional side and one plain side: the plain side is wrapped in `Some`.
        let bind = |operand: &Operand, name: &str, wrap: bool| -> (String, String) {
            let owned_text = operand.ty == RTy::Optional(Box::new(RTy::Str));
            let value = if operand.maybe && owned_text {
                format!("{name}.as_deref()")
            } else if operand.maybe {
                name.to_owned()
            } else {
                operand.code.clone()
            };
            let value = if wrap {
                format!("::core::option::Option::Some({value})")
            } else {
                value
            };
            (operand.code.clone(), value)
        };
        let (l_source, l_value) = bind(&l, "left", r_opt && !l_opt);
        let (r_source, r_value) = bind(&r, "right", l_opt && !r_opt);
        let test = format!("{l_value} {rust_op} {r_value}");
        match (l.maybe, r.maybe) {
            (false, false) => test,
            (true, false) => format!("{l_source}.is_some_and(|left| {test})"),
            (false, true) => format!("{r_source}.is_some_and(|right| {test})"),
            (true, true) => {
                format!("{l_source}.zip({r_source}).is_some_and(|(left, right)| {test})")
            }
        }
    }

    /// A comparison of two results: by kind (`none`, `success`, `fail`).
    fn result_comparison(&mut self, op: BinaryOp, l: &Operand, r: &Operand) -> String {
        let negate = if op == BinaryOp::Ne { "!" } else { "" };
        // A symbol side is a pattern.
        let pattern = |operand: &Operand| -> Option<String> {
            (!operand.maybe).then(|| operand.code.clone())
        };
        match (pattern(l), pattern(r)) {
            (Some(p), None) | (None, Some(p)) => {
                let source = if l.maybe { &l.code } else { &r.code };
                format!("{source}.is_some_and(|result| {negate}::core::matches!(result, {p}))")
            }
            (None, None) => format!(
                "{}.zip({}).is_some_and(|(left, right)| ::core::mem::discriminant(left) {} ::core::mem::discriminant(right))",
                l.code,
                r.code,
                op.as_str()
            ),
            (Some(a), Some(b)) => (if (a == b) == (op != BinaryOp::Ne) {
                "true"
            } else {
                "false"
            })
            .to_owned(),
        }
    }
}

/// `l op r` for an ordering `op` with an optional side: every `Option` layer (a
/// missing read, an optional value) is opened with `is_some_and`, so a missing value
/// or `none` makes it `false`.
fn ordering(rust_op: &str, l: &Operand, r: &Operand) -> String {
    let layers = |operand: &Operand| {
        usize::from(matches!(operand.ty, RTy::Optional(_))) + usize::from(operand.maybe)
    };
    let value = |operand: &Operand, name: &str| {
        if layers(operand) == 0 {
            operand.code.clone()
        } else {
            name.to_owned()
        }
    };
    let open = |operand: &Operand, name: &str, inner: String| -> String {
        match layers(operand) {
            0 => inner,
            1 => format!("{}.is_some_and(|{name}| {inner})", operand.code),
            _ => format!(
                "{}.is_some_and(|{name}| {name}.is_some_and(|{name}| {inner}))",
                operand.code
            ),
        }
    };
    let test = format!("{} {rust_op} {}", value(l, "left"), value(r, "right"));
    open(l, "left", open(r, "right", test))
}

/// A float literal (`0.1`, `-0.1`) as an `f64` holding its `f32` rounding, or `None`
/// for anything else (and for a literal beyond `f32`'s range, which no `f32` equals).
fn f32_literal(expr: &ast::Expr) -> Option<String> {
    let (negative, value) = match &expr.kind {
        ExprKind::Float(x) => (false, *x),
        ExprKind::Unary(UnaryOp::Neg, inner) => match &inner.kind {
            ExprKind::Float(x) => (true, *x),
            _ => return None,
        },
        _ => return None,
    };
    // Rounding to `f32` is the point: the variable holds that rounding.
    let narrow = value as f32;
    if !narrow.is_finite() {
        return None;
    }
    let sign = if negative { "-" } else { "" };
    Some(format!("f64::from({sign}{narrow:?}_f32)"))
}

/// A symbol of the type the checker resolved it to (the other side's, without `?`).
fn symbol(name: &str, resolved: &RTy) -> Operand {
    let plain = |code: String, ty: RTy| Operand {
        code,
        ty,
        maybe: false,
        narrow: false,
    };
    match crate::check::strip(resolved) {
        // The checker's names; `coolbot::State` variants are their camel case.
        RTy::State if DEFAULT_STATES.contains(&name) => plain(
            format!("::coolbot::State::{}", ident::camel(name)),
            RTy::State,
        ),
        ty @ RTy::UserState(_, states) if states.iter().any(|s| s == name) => {
            plain(ident::string_literal(name), ty.clone())
        }
        RTy::Result => match result_pattern(name).filter(|_| RESULTS.contains(&name)) {
            Some(pattern) => plain(pattern.to_owned(), RTy::Result),
            None => plain(String::new(), RTy::Unknown),
        },
        ty @ RTy::Quality(_, levels) => match levels.iter().position(|l| l == name) {
            Some(index) => plain(format!("{index}_usize"), ty.clone()),
            None => plain(String::new(), RTy::Unknown),
        },
        _ => plain(String::new(), RTy::Unknown),
    }
}

/// An own variable's field read as a rule operand (`maybe` when it is held as an
/// `Option` reference until set).
fn own_value(field: &str, ty: &RTy, maybe: bool, f64_field: bool) -> Operand {
    let unreadable = Operand {
        code: String::new(),
        ty: RTy::Unknown,
        maybe: false,
        narrow: false,
    };
    if maybe {
        // `Option<&T>`: only the types whose value can be copied out of a reference.
        let code = match ty {
            RTy::Bool | RTy::Duration | RTy::Time | RTy::Enum(_) => format!("{field}.copied()"),
            _ => return unreadable,
        };
        return Operand {
            code,
            ty: ty.clone(),
            maybe: true,
            narrow: false,
        };
    }
    let code = match ty {
        RTy::Int => format!("i128::from({field})"),
        RTy::Float if f64_field => field.to_owned(),
        RTy::Float => format!("f64::from({field})"),
        RTy::Str => format!("{field}.as_str()"),
        RTy::Bool | RTy::Duration | RTy::Time | RTy::Enum(_) => field.to_owned(),
        RTy::Optional(inner) => match inner.as_ref() {
            RTy::Int => format!("{field}.map(i128::from)"),
            RTy::Float if f64_field => field.to_owned(),
            RTy::Float => format!("{field}.map(f64::from)"),
            RTy::Str => format!("{field}.as_deref()"),
            RTy::Bool | RTy::Duration | RTy::Time | RTy::Enum(_) => field.to_owned(),
            _ => return unreadable,
        },
        _ => return unreadable,
    };
    let narrow = !f64_field && is_float(ty);
    Operand {
        code,
        ty: ty.clone(),
        maybe: false,
        narrow,
    }
}

/// Whether `ty` is a float or an optional float.
fn is_float(ty: &RTy) -> bool {
    match ty {
        RTy::Float => true,
        RTy::Optional(inner) => **inner == RTy::Float,
        _ => false,
    }
}

/// Reads an instance variable's `Option<&coolbot::Value>` (`raw`) as an `Option` of
/// the operand's Rust value.
fn view_value(raw: &str, ty: &RTy) -> Option<String> {
    let decode = |rust: &str| format!("{raw}.and_then(|value| <{rust}>::try_from(value).ok())");
    let serde = |rust: &str| {
        format!("{raw}.and_then(|value| super::__cool_from_value::<{rust}>(value).ok())")
    };
    Some(match ty {
        RTy::Bool => decode("bool"),
        RTy::Int => format!(
            "{raw}.and_then(|value| <i64>::try_from(value).map(i128::from).or_else(|_| <u64>::try_from(value).map(i128::from)).ok())"
        ),
        RTy::Float => decode("f64"),
        RTy::Str => format!(
            "{raw}.and_then(|value| match value {{ ::coolbot::Value::Str(text) => ::core::option::Option::Some(text.as_str()), _ => ::core::option::Option::None }})"
        ),
        RTy::Duration => decode("::std::time::Duration"),
        RTy::Time => decode("::coolbot::Time"),
        RTy::Enum(name) => serde(&enum_path(name)),
        RTy::Optional(inner) => match inner.as_ref() {
            RTy::Bool => serde("::core::option::Option<bool>"),
            RTy::Int => format!(
                "{}.map(|value| value.map(i128::from))",
                serde("::core::option::Option<i64>")
            ),
            RTy::Float => serde("::core::option::Option<f64>"),
            RTy::Duration => serde("::core::option::Option<::std::time::Duration>"),
            RTy::Time => serde("::core::option::Option<::coolbot::Time>"),
            RTy::Enum(name) => serde(&format!("::core::option::Option<{}>", enum_path(name))),
            // Owned: compared through `as_deref` (see `Scope::comparison`).
            RTy::Str => serde("::core::option::Option<::std::string::String>"),
            _ => return None,
        },
        _ => return None,
    })
}

/// Whether a variable of type `ty` holds an `f64` or `f64?` (read as is; `f32`
/// widens).
fn holds_f64(ty: &Ty) -> bool {
    match ty {
        Ty::Float(prim) => *prim == Prim::F64,
        Ty::Optional(inner) => holds_f64(inner),
        _ => false,
    }
}

/// Whether `ty` is `f64` or `f64?` (read as is; `f32` widens).
fn is_f64(ty: &ast::Type) -> bool {
    match &ty.kind {
        TypeKind::Prim(p) => *p == Prim::F64,
        TypeKind::Optional(inner) => is_f64(inner),
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use crate::ir;
    use crate::lower::{Options, lower};

    const TEXT: &str = "
        enum Mode { Normal, Backup }
        atomic Leaf {
            observable level: u32 = 0;
            controllable gain: f64 = 1.0;
            output out: data<u32>;
            input input: fifo<u32>(4);
            timing { period 10ms; }
            automaton { initial on; state on { periodic; } }
        }
        compound Box {
            instance a: Leaf { timing { priority 3; } }
            instance b: Leaf substitutes a;
            input input = a.input;
            output out = a.out;
            observable level = a.level;
            controllable gain = a.gain;
            observable mode: Mode = Mode::Normal;
            local faults: u32 = 0;
            on error a: substitute;
            supervisor {
                initial on;
                state on {
                    entry;
                    when (a.state == running_error || faults > 2) && mode == Mode::Normal -> off;
                    when level > 3 && !(a.user_state == on) -> off;
                }
                state off { exit; }
            }
        }
        compound Outer { instance inner: Box { gain = 2.0; } }
    ";

    fn compounds() -> Vec<ir::Compound> {
        compounds_of(TEXT)
    }

    fn compounds_of(text: &str) -> Vec<ir::Compound> {
        let checked = crate::analyze_text("t.cool", text)
            .checked()
            .unwrap_or_else(|analysis| {
                panic!("{}", analysis.render(crate::RenderOptions::plain()))
            });
        lower(&checked, &Options::default()).compounds
    }

    /// The condition and reads of each rule of the first compound of `text`.
    fn rules_of(text: &str) -> Vec<(String, String)> {
        compounds_of(text)[0]
            .rules
            .iter()
            .map(|r| (r.expr.clone(), r.reads.clone()))
            .collect()
    }

    const MONITORED: &str = "
        atomic Meter {
            observable ratio: f32 = 0.0;
            observable maybe: u8? = none;
            timing { period 10ms; quality fine, coarse; }
            automaton { initial on; state on { periodic; } }
        }
        compound Watch {
            instance m: Meter { timing { quality best, good, poor; } }
            instance n: Meter;
            local opt: u8? = none;
            local x: f32 = 0.1;
            supervisor {
                initial on;
                state on {
                    when m.quality == poor -> off;
                    when n.quality == coarse && m.cpu_time > 1s -> off;
                    when opt < 4 || 4 > opt || m.maybe >= 2 -> off;
                    when x == 0.1 || m.ratio <= -0.5 -> off;
                    when m.error != \"boom\" && m.user_state != on -> off;
                    when m.state != running -> off;
                }
                state off { entry; }
            }
        }";

    #[test]
    fn quality_reads_its_own_key_and_the_instance_levels() {
        let rules = rules_of(MONITORED);
        // The runtime announces a quality change under `m.quality`; the levels are
        // the instance's override (`poor` is its third), else the component's.
        assert_eq!(rules[0].1, r#"&["m.quality"]"#);
        assert!(rules[0].0.contains("== 2_usize"), "{}", rules[0].0);
        assert!(rules[1].0.contains("== 1_usize"), "{}", rules[1].0);
        // `cpu_time` has no change event: read under its own key, which the runtime
        // counts as changed every supervisor period.
        assert_eq!(rules[1].1, r#"&["n.quality", "m.cpu_time"]"#);
    }

    const CONTROLLED: &str = "
        atomic Drive {
            configuration { accel: f64 = 1.0; }
            controllable speed: f64 = 1.0;
            controllable label: String = \"d\";
            observable travelled: f64 = 0.0;
            timing { period 5ms; quality full, eco; }
            automaton { initial on; state on { periodic; } }
        }
        compound Base {
            instance motion: Drive;
            instance spare: Drive { timing { quality only; } }
            timing { quality best, good; }
            supervisor {
                initial on;
                state on {
                    entry;
                    may -> off;
                    when result == fail || error != \"\" -> off;
                    when quality == good && cpu_time > 1s -> off;
                    when motion.speed < 0.5 -> off;
                }
                state off { entry; }
            }
        }";

    #[test]
    fn rules_read_the_compounds_own_defaults_and_instance_controllables() {
        let rules = rules_of(CONTROLLED);
        assert_eq!(rules[0].1, r#"&["result", "error"]"#);
        assert!(
            rules[0].0.contains("Some(view.own_result())"),
            "{}",
            rules[0].0
        );
        assert!(rules[0].0.contains("view.own_error()"), "{}", rules[0].0);
        assert_eq!(rules[1].1, r#"&["quality", "cpu_time"]"#);
        assert!(
            rules[1].0.contains("view.own_quality() == 1_usize"),
            "{}",
            rules[1].0
        );
        assert!(rules[1].0.contains("view.own_cpu_time()"), "{}", rules[1].0);
        assert_eq!(rules[2].1, r#"&["motion.speed"]"#);
        assert!(
            rules[2].0.contains(r#"view.var("motion", "speed")"#),
            "{}",
            rules[2].0
        );
    }

    #[test]
    fn a_supervisor_may_becomes_its_target_enum_and_a_choose_stub() {
        let compound = &compounds_of(CONTROLLED)[0];
        let on = &compound.states[0];
        assert_eq!(on.may_enum.as_deref(), Some("OnMay"));
        assert!(on.spec.contains("may: &[1]"), "{}", on.spec);
        assert!(compound.methods.iter().any(|m| m.name == "on_choose"));
        assert_eq!(compound.choose_arms.len(), 1);
        assert_eq!(compound.choose_arms[0].targets, [("Off".to_owned(), 1)]);
    }

    #[test]
    fn every_instance_gets_a_typed_handle() {
        let handles = &compounds_of(CONTROLLED)[0].handles;
        assert_eq!(handles.len(), 2);
        let motion = &handles[0];
        assert_eq!(
            (motion.method.as_str(), motion.type_name.as_str()),
            ("motion", "MotionInstance")
        );
        let setters: Vec<(&str, &str, &str)> = motion
            .setters
            .iter()
            .map(|s| (s.method.as_str(), s.ty.as_str(), s.to_value.as_str()))
            .collect();
        assert_eq!(
            setters,
            [
                ("set_speed", "f64", "::coolbot::Value::from(value)"),
                (
                    "set_label",
                    "::std::string::String",
                    "::coolbot::Value::from(value)"
                ),
            ]
        );
        assert_eq!(motion.config.as_deref(), Some("super::drive::Config"));
        let (quality, levels) = motion.quality.clone().unwrap();
        assert_eq!(quality, "MotionQuality");
        assert_eq!(
            levels,
            [
                ("Full".to_owned(), "full".to_owned()),
                ("Eco".to_owned(), "eco".to_owned())
            ]
        );
        // One level (its override): nothing to set.
        assert_eq!(handles[1].quality, None);
    }

    #[test]
    fn orderings_over_optionals_never_hold_for_none() {
        let expr = &rules_of(MONITORED)[2].0;
        assert!(
            expr.contains("vars.opt.map(i128::from).is_some_and(|left| left < 4)"),
            "{expr}"
        );
        assert!(
            expr.contains("vars.opt.map(i128::from).is_some_and(|right| 4 > right)"),
            "{expr}"
        );
        assert!(
            expr.contains(".is_some_and(|left| left.is_some_and(|left| left >= 2))"),
            "{expr}"
        );
        assert!(!expr.contains("Some(4)"), "{expr}");
    }

    #[test]
    fn f32_sides_compare_with_the_literal_rounded_to_f32() {
        let expr = &rules_of(MONITORED)[3].0;
        assert!(
            expr.contains("f64::from(vars.x) == f64::from(0.1_f32)"),
            "{expr}"
        );
        assert!(expr.contains("left <= f64::from(-0.5_f32)"), "{expr}");
    }

    #[test]
    fn not_equal_is_the_negation_of_equal_when_a_value_is_missing() {
        let rules = rules_of(MONITORED);
        let expr = &rules[4].0;
        assert!(
            expr.contains(r#"view.error("m").unwrap_or("") != "boom""#),
            "{expr}"
        );
        assert!(
            expr.contains(r#"view.user_state("m") != ::core::option::Option::Some("on")"#),
            "{expr}"
        );
        assert!(
            rules[5].0.starts_with("!(view.state(\"m\")"),
            "{}",
            rules[5].0
        );
    }

    #[test]
    fn rules_compile_with_their_reads() {
        let c = &compounds()[0];
        let reads: Vec<&str> = c.rules.iter().map(|r| r.reads.as_str()).collect();
        // A local variable is not in the supervisor's spec: not a read.
        assert_eq!(
            reads,
            [r#"&["a.state", "mode"]"#, r#"&["level", "a.user_state"]"#]
        );
        assert!(c.rules[0].expr.starts_with("(view"), "{}", c.rules[0].expr);
        assert!(
            c.rules[0].expr.contains("|| i128::from(vars.faults) > 2)"),
            "{}",
            c.rules[0].expr
        );
        assert_eq!(c.rules[0].vars_param.as_deref(), Some("vars"));
        // A mapped variable reads the instance standing in for `a` now.
        assert!(c.rules[1].expr.contains(r#"view.mapped("level")"#));
        assert!(!c.rules[1].expr.contains(r#"view.var("a", "level")"#));
        assert!(c.rules[1].expr.contains("!(view"));
        assert_eq!(c.rules[1].vars_param, None);
        assert_eq!(c.rules[1].call, "__cool_rule_1");
    }

    #[test]
    fn builder_steps_follow_the_description() {
        let c = &compounds()[0];
        assert_eq!(
            c.steps,
            [
                r#".export_input::<u32>("input", "a.input")"#,
                r#".export_output::<u32>("out", "a.out")"#,
                r#".map_observable("level", "a.level")"#,
                r#".map_controllable("gain", "a.gain")"#,
                r#".on_error("a", ::coolbot::Policy::Substitute)"#,
                r#".substitute("b", "a")"#,
            ]
        );
        assert_eq!(
            c.input_specs,
            [
                "::coolbot::InputSpec { name: \"input\", kind: ::coolbot::InputKind::Fifo { capacity: 4, policy: ::coolbot::OverflowPolicy::Reject }, packet: \"u32\", pull: false }"
            ]
        );
        assert_eq!(c.output_specs.len(), 1);
        let a = &c.instances[0];
        let build = a.build.as_deref().unwrap();
        assert!(
            build.ends_with(
                ".with_timing(::coolbot::TimingSpec { priority: 3, ..super::leaf::SPEC.timing })"
            ),
            "{build}"
        );
        // Only `mode` is in the supervisor's spec; `faults` is local.
        let exposed: Vec<&str> = c
            .vars
            .iter()
            .filter(|v| v.spec_index.is_some())
            .map(|v| v.field.name.as_str())
            .collect();
        assert_eq!(exposed, ["mode"]);
        let parts: Vec<&str> = c.parts.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(parts, ["supervisor", "a", "b"]);
        let sections: Vec<&str> = c.methods.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(sections, ["on_entry", "off_exit"]);
    }

    #[test]
    fn an_instance_named_supervisor_gets_another_method() {
        let analysis = crate::analyze_text(
            "t.cool",
            "atomic Leaf { automaton { initial on; state on { entry; } } }\ncompound Top { instance supervisor: Leaf; }",
        );
        let checked = analysis.checked().expect("no error");
        let krate = lower(&checked, &Options::default());
        let parts: Vec<&str> = krate.compounds[0]
            .parts
            .iter()
            .map(|m| m.name.as_str())
            .collect();
        assert_eq!(parts, ["supervisor", "supervisor_2"]);
    }

    #[test]
    fn nested_compounds_and_implicit_supervisors() {
        let outer = &compounds()[1];
        // An override of the nested compound's mapped controllable `gain`.
        assert_eq!(
            outer.instances[0].build.as_deref(),
            Some(
                r#"super::r#box::component_with("inner", parts.inner(), super::r#box::Vars::default(), super::r#box::Mapped { gain: ::core::option::Option::Some(2.0) })?"#
            )
        );
        assert!(outer.instances[0].unapplied.is_empty());
        // Box's own `Mapped` feeds its instance `a`.
        let inner = &compounds()[0];
        assert_eq!(inner.mapped.len(), 1);
        assert_eq!(inner.mapped[0].ty, "f64");
        assert!(
            inner.instances[0]
                .build
                .as_deref()
                .unwrap()
                .contains("gain: mapped.gain.unwrap_or_else(|| super::leaf::Vars::default().gain)"),
            "{:?}",
            inner.instances[0].build
        );
        assert!(outer.instances[0].compound);
        assert!(
            outer.parts[1]
                .user_signature
                .ends_with("impl crate::generated::r#box::Parts")
        );
        // No supervisor block: one state without sections.
        assert_eq!(outer.states.len(), 1);
        assert_eq!(outer.states[0].cool_name, "supervising");
        assert!(outer.methods.is_empty());
    }
}
