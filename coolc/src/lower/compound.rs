//! Lowering of compound components, from their resolved model alone
//! ([`crate::checked::model`]): its own variables, the supervisor (its states are
//! lowered by `automaton`, as an atomic's are), the instances and everything the
//! runtime's `coolbot::CompoundBuilder` is told
//! (connections, exports, mapped variables, policies, substitutes, redundant groups,
//! recovery). The `when` rules are compiled to typed Rust over `coolbot::View` by the
//! submodule `rules`.
//!
//! Like the rest of lowering, this never fails: the checker has accepted the
//! description, and anything it would have rejected lowers to something harmless
//! (an unknown type reads as a missing value, which makes a comparison `false`).

mod rules;

use std::collections::BTreeSet;

use super::automaton::{self, Lowered, SectionOwner};
use super::{GEN_TYPES, Lowerer, adaptation, duration_code, rust_ty, unique_among};
use crate::checked::model::{
    Component, ComponentKind, ErrorPolicy, Instance, PortRef, TimingEntry, Tuning, Ty, VarKind,
};
use crate::ident;
use crate::ir::{self, Code};

/// The supervisor state of a compound that declares none.
const IMPLICIT_STATE: &str = "supervising";

/// A compound's mapped controllable variable: `(name, instance, variable)`.
type MappedControllable<'m> = (&'m str, &'m str, &'m str);

impl<'a> Lowerer<'a> {
    /// The type of variable `name` of component `component` (through mapped
    /// variables of nested compounds).
    fn variable_type(&self, component: &str, name: &str) -> Option<Ty> {
        self.checked
            .component(component)?
            .variables
            .iter()
            .find(|v| v.name == name)?
            .ty
            .clone()
    }

    /// Whether compound `c` connects through a converter, itself or in a compound it
    /// nests at any depth: its builder then takes the converters as a type argument
    /// and passes them on to the nested builders.
    fn uses_converters(&self, c: &'a Component, visiting: &mut BTreeSet<&'a str>) -> bool {
        let own = c.connections.iter().any(|k| k.via.is_some());
        own || self.nests_converters(c, visiting)
    }

    /// Whether an instance of compound `c` is a compound that uses converters.
    fn nests_converters(&self, c: &'a Component, visiting: &mut BTreeSet<&'a str>) -> bool {
        if !visiting.insert(&c.name) {
            // A compound nesting itself was rejected by the checker.
            return false;
        }
        let nested = c.instances.iter().any(|i| {
            self.checked.component(&i.component).is_some_and(|t| {
                t.kind == ComponentKind::Compound && self.uses_converters(t, visiting)
            })
        });
        visiting.remove(c.name.as_str());
        nested
    }

    /// Lowers compound `c` into the IR of its generated module.
    pub(super) fn compound(&self, c: &'a Component, module: String) -> ir::Compound {
        // Builder steps with where their member is written: they follow source
        // order across member kinds.
        let mut ordered: Vec<(usize, Code)> = Vec::new();
        let mut input_specs = Vec::new();
        let mut output_specs = Vec::new();
        let mut exported_ports = Vec::new();
        let mapped_controllables = Self::mapped_controllables(c);

        // `Parts` method names: `supervisor`, then one per instance.
        let mut part_names: Vec<String> = vec!["supervisor".to_owned()];
        let mut instances = Vec::new();
        for i in &c.instances {
            let method = unique_among(ident::snake(&i.name), part_names.iter().map(String::as_str));
            part_names.push(method.clone());
            instances.push(self.instance(i, method, &mapped_controllables));
        }
        let connections: Vec<ir::Connection> = c
            .connections
            .iter()
            .map(|connect| ir::Connection {
                from: port_address(&connect.from),
                to: port_address(&connect.to),
                via: connect.via.as_ref().map(|v| ident::snake(v)),
                converter: connect.via.clone(),
            })
            .collect();
        let uses_converters = c.connections.iter().any(|k| k.via.is_some());
        for input in &c.inputs {
            let Some(target) = &input.export else {
                continue;
            };
            let packet = input.port.as_ref().map(|p| p.kind.packet());
            let step = export_step(&input.name, target, packet, true);
            exported_ports.push((input.name.clone(), packet_rust(packet)));
            ordered.push((input.span.start, step));
            input_specs.extend(self.input(input).map(|port| port.spec(&input.name, true)));
        }
        for output in &c.outputs {
            let Some(target) = &output.export else {
                continue;
            };
            output_specs.extend(
                self.output(output)
                    .map(|port| port.spec(&output.name, false)),
            );
            let packet = output.port.as_ref().map(|p| p.kind.packet());
            exported_ports.push((output.name.clone(), packet_rust(packet)));
            let step = export_step(&output.name, target, packet, false);
            ordered.push((output.span.start, step));
        }
        let mut vars = Vec::new();
        let mut spec_index = 0;
        for v in &c.variables {
            match (&v.written, &v.mapping) {
                (Some(_), _) => {
                    if let Some(var) = self.variable(v, &mut spec_index, &Code::atom("vars")) {
                        vars.push(var);
                    }
                }
                (None, Some(path)) => {
                    let call = match v.kind {
                        VarKind::Controllable => "map_controllable",
                        _ => "map_observable",
                    };
                    ordered.push((
                        v.span.start,
                        Code::call(
                            call,
                            vec![Code::string(&v.name), Code::string(&path.join("."))],
                        ),
                    ));
                }
                (None, None) => {}
            }
        }
        for on in &c.policies {
            let policy = match on.policy {
                ErrorPolicy::Propagate => "::coolbot::Policy::Propagate",
                ErrorPolicy::Restart => "::coolbot::Policy::Restart",
                ErrorPolicy::Substitute => "::coolbot::Policy::Substitute",
                ErrorPolicy::Ignore => "::coolbot::Policy::Ignore",
            };
            ordered.push((
                on.span.start,
                Code::call(
                    "on_error",
                    vec![Code::string(&on.instance), Code::atom(policy)],
                ),
            ));
        }
        for r in &c.redundant {
            ordered.push((
                r.span.start,
                Code::call("redundant", vec![names(&r.members)]),
            ));
        }
        for t in &c.threads {
            ordered.push((
                t.span.start,
                Code::call("thread", vec![Code::string(&t.name), names(&t.members)]),
            ));
        }
        if let Some(r) = &c.restart {
            if let Some((count, window)) = &r.limit {
                ordered.push((
                    r.span.start,
                    Code::call(
                        "restart_budget",
                        vec![Code::atom(count.to_string()), duration_code(window.nanos)],
                    ),
                ));
            }
            if let Some((first, last)) = &r.backoff {
                ordered.push((
                    r.span.start,
                    Code::call(
                        "restart_backoff",
                        vec![duration_code(first.nanos), duration_code(last.nanos)],
                    ),
                ));
            }
        }
        // Stable: the two steps of one `restart` block keep their order.
        ordered.sort_by_key(|(start, _)| *start);
        let mut steps: Vec<Code> = ordered.into_iter().map(|(_, step)| step).collect();
        steps.extend(compound_adaptation(c));
        // Substitutes after every instance (a substitute may be declared before the
        // instance it stands for).
        for i in &instances {
            if let Some(primary) = &i.substitutes {
                steps.push(Code::call(
                    "substitute",
                    vec![Code::string(&i.name), Code::string(primary)],
                ));
            }
        }
        if let Some(r) = &c.recovery {
            steps.push(Code::call(
                "recovery",
                vec![
                    duration_code(r.retry_every_nanos()),
                    duration_code(r.deadline_nanos()),
                ],
            ));
        }

        let supervisor = self.supervisor(c);
        let rules = rules::compile(self, c, &supervisor.when);

        let handles = self.handles(c, &instances);
        let name = ident::camel_raw(&c.name);
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
                ir::StubLine::Comment(
                    "// The supervisor: its sections are the `impl Supervisor` above.".to_owned(),
                ),
                ir::StubLine::Value(Code::call(format!("{name}Supervisor::default"), Vec::new())),
            ],
        }];
        all_parts.extend(parts);
        let mut compound = ir::Compound {
            spec: Code::atom(""),
            doc: c.doc.clone(),
            notes: ir::notes(
                c.notes
                    .iter()
                    .map(|n| (n.subject.as_str(), n.doc.as_slice())),
            ),
            type_name: c.name.clone(),
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
            exported_ports,
            vars,
            states: supervisor.states,
            initial: supervisor.initial,
            methods: supervisor.methods,
            section_arms: supervisor.section_arms,
            choose_arms: supervisor.choose_arms,
            timing: self.timing(c.timing.as_deref()),
            rules,
            handles,
        };
        compound.spec = spec(&compound);
        compound
    }

    /// The typed handles of `c`'s instances for the supervisor's `Cx`: one per
    /// instance whose component is known, in declaration order.
    fn handles(&self, c: &'a Component, instances: &[ir::Instance]) -> Vec<ir::Handle> {
        // Names the handles' methods and types must not take: `Instances` has no
        // other method; the types live beside the module's own.
        let mut methods: Vec<String> = Vec::new();
        let mut types: Vec<String> = Vec::new();
        let mut handles = Vec::new();
        for (instance, lowered) in c.instances.iter().zip(instances) {
            let (Some(component), Some(module)) = (
                self.checked.component(&instance.component),
                lowered.module.as_ref(),
            ) else {
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
            for v in component
                .variables
                .iter()
                .filter(|v| v.kind == VarKind::Controllable)
            {
                let Some(ty) = self.variable_type(&component.name, &v.name) else {
                    continue;
                };
                let rust_ty = rust_ty(&ty, GEN_TYPES);
                // A type holding an array longer than 32 elements goes through its
                // serde_with adapter, as the instance's own variable does.
                let value = Code::atom("value");
                let to_value = match (super::serde_adapter(&ty), &ty) {
                    (Some(adapter), _) => Code::call(
                        "super::__cool_to_value",
                        vec![
                            Code::call(
                                format!(
                                    "{}ser::SerializeAsWrap::<{rust_ty}, {adapter}>::new",
                                    super::SERDE_WITH
                                ),
                                vec![value.reference()],
                            )
                            .reference(),
                        ],
                    ),
                    (
                        None,
                        Ty::Bool | Ty::Int(_) | Ty::Float(_) | Ty::Str | Ty::Time | Ty::Duration,
                    ) => Code::call("::coolbot::Value::from", vec![value]),
                    (None, _) => Code::call("super::__cool_to_value", vec![value.reference()]),
                };
                setters.push(ir::Setter {
                    method: ident::method("set_", &v.name, ""),
                    variable: v.name.clone(),
                    ty: rust_ty,
                    to_value,
                });
            }
            // The handle's other methods keep their names: an observable `period`
            // gets no `set_period` of its own.
            let taken: Vec<&str> = setters
                .iter()
                .map(|s| s.method.as_str())
                .chain(["set_period", "set_quality"])
                .collect();
            let observables = component
                .variables
                .iter()
                .filter(|v| v.kind == VarKind::Observable)
                .map(|v| (ident::method("set_", &v.name, ""), v.name.clone()))
                .filter(|(method, _)| !taken.contains(&method.as_str()))
                .collect();
            let config = (!lowered.compound
                && component
                    .configuration
                    .as_ref()
                    .is_some_and(|fields| !fields.is_empty()))
            .then(|| format!("super::{module}::Config"));
            let mut levels = quality_levels(component.timing.as_deref()).unwrap_or_default();
            if let Some(own) = instance.timing.as_deref().and_then(first_quality_levels) {
                levels = own;
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
                observables,
                config,
                quality,
            });
        }
        handles
    }

    /// The mapped controllable variables of compound `c`, in declaration order.
    fn mapped_controllables(c: &'a Component) -> Vec<MappedControllable<'a>> {
        c.variables
            .iter()
            .filter(|v| v.written.is_none() && v.kind == VarKind::Controllable)
            .filter_map(|v| match v.mapping.as_deref()? {
                [instance, variable] => {
                    Some((v.name.as_str(), instance.as_str(), variable.as_str()))
                }
                _ => None,
            })
            .collect()
    }

    /// The `Mapped` fields of compound `c`: one per mapped controllable variable,
    /// typed like the instance variable it names.
    fn mapped_fields(&self, c: &'a Component) -> Vec<ir::MappedField> {
        Self::mapped_controllables(c)
            .into_iter()
            .map(|(name, instance, variable)| {
                let ty = c
                    .instances
                    .iter()
                    .find(|i| i.name == instance)
                    .and_then(|i| self.variable_type(&i.component, variable))
                    .map(|ty| {
                        let rust = rust_ty(&ty, GEN_TYPES);
                        if self.ty_defaultable(&ty) {
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
        i: &'a Instance,
        method: String,
        mapped: &[MappedControllable<'_>],
    ) -> ir::Instance {
        let target = self.checked.component(&i.component);
        let module = target.and_then(|t| self.modules.get(t.name.as_str()).cloned());
        let compound = target.is_some_and(|t| t.kind == ComponentKind::Compound);
        let config_overrides = self.overrides(i, true);
        let var_overrides = self.overrides(i, false);
        // The enclosing compound's mapped controllables that name this instance:
        // `(instance variable, field of the enclosing `Mapped`)`.
        let from_mapped: Vec<(String, String)> = mapped
            .iter()
            .filter(|(_, instance, _)| *instance == i.name)
            .map(|(name, _, variable)| (ident::snake(variable), ident::snake(name)))
            .collect();
        // A nested compound's own mapped controllables, overridden here or fed from
        // the enclosing `Mapped`.
        let inner_mapped: Vec<MappedControllable<'_>> = match target {
            Some(t) if compound => Self::mapped_controllables(t),
            _ => Vec::new(),
        };
        let is_inner_mapped = |field: &str| {
            inner_mapped
                .iter()
                .any(|(n, _, _)| ident::snake(n) == field)
        };
        let mut mapped_overrides: Vec<(String, Code)> = Vec::new();
        if let Some(t) = target.filter(|_| compound) {
            for o in &i.overrides {
                let field = ident::snake(&o.name);
                if !is_inner_mapped(&field) {
                    continue;
                }
                if let Some(ty) = self.variable_type(&t.name, &o.name) {
                    let value = self.value(&o.value, Some(&ty), GEN_TYPES);
                    let value = if self.ty_defaultable(&ty) {
                        value
                    } else {
                        Code::core_some(value)
                    };
                    mapped_overrides.push((field, value));
                }
            }
        }
        let build = module.as_ref().map(|module| {
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
            let function = if plain { "component" } else { "component_with" };
            let mut args = vec![
                Code::string(&i.name),
                Code::atom("parts").method(method.as_str(), Vec::new()),
            ];
            match (compound, plain) {
                (_, true) => {}
                (true, false) => args.extend([vars, nested]),
                (false, false) => args.extend([config, vars]),
            }
            let build = Code::call(format!("super::{module}::{function}{converters}"), args);
            if compound { build.try_op() } else { build }
        });
        let applied: BTreeSet<&str> = config_overrides
            .iter()
            .chain(&var_overrides)
            .chain(&mapped_overrides)
            .map(|(field, _)| field.as_str())
            .collect();
        let unapplied: Vec<String> = i
            .overrides
            .iter()
            .filter(|o| !applied.contains(ident::snake(&o.name).as_str()))
            .map(|o| o.name.clone())
            .collect();
        let build = match (build, &module, &i.timing) {
            (Some(build), Some(module), Some(timing)) => {
                let base = Code::atom(format!("super::{module}::SPEC")).field("timing");
                Some(build.method("with_timing", vec![timing_override(timing, base)]))
            }
            (build, _, _) => build,
        };
        // Checked: only an instance of an atomic component has an `adaptation` block.
        let build = match (build, &i.tuning) {
            (Some(build), Some(tuning)) => {
                Some(build.method("with_adaptation", vec![adaptation::config_always(tuning)]))
            }
            (build, _) => build,
        };
        ir::Instance {
            name: i.name.clone(),
            method,
            component: i.component.clone(),
            module,
            compound,
            substitutes: i.substitutes.as_ref().map(|s| s.name.clone()),
            node: i.node.clone(),
            build,
            unapplied,
        }
    }

    /// The `Parts` method of an instance, with its user stub.
    fn part_stub(&self, i: &ir::Instance) -> ir::Method {
        let module = i.module.clone().unwrap_or_else(|| "types".to_owned());
        let (returns, body) = if i.compound {
            (
                format!("impl crate::generated::{module}::Parts"),
                format!(
                    "crate::{module}::{}Parts::default",
                    ident::camel_raw(&i.component)
                ),
            )
        } else {
            (
                format!("impl crate::generated::{module}::Behavior"),
                format!("crate::{module}::{}::default", ident::camel(&i.component)),
            )
        };
        ir::Method {
            name: i.method.clone(),
            doc: Vec::new(),
            signature: String::new(),
            user_signature: format!("fn {}(&mut self) -> {returns}", i.method),
            stub_body: vec![
                ir::StubLine::Comment(format!(
                    "// Instance `{}`: the {} it runs.",
                    i.name,
                    if i.compound { "parts" } else { "behavior" }
                )),
                ir::StubLine::Value(Code::call(body, Vec::new())),
            ],
        }
    }
}

impl<'a> Lowerer<'a> {
    /// The supervisor of compound `c`: its states, or one implicit state without
    /// sections when it declares none.
    fn supervisor(&self, c: &'a Component) -> Lowered<'a> {
        let mut lowered = automaton::states(c.automaton.as_ref(), SectionOwner::Supervisor);
        let states = &mut lowered.states;
        if states.is_empty() {
            // No `supervisor { ... }`: one state without sections, so the compound
            // has a user automaton like every component.
            states.push(ir::State {
                doc: vec!["The only state of a compound without a `supervisor` block.".to_owned()],
                cool_name: IMPLICIT_STATE.to_owned(),
                variant: ident::camel(IMPLICIT_STATE),
                may_enum: None,
                may: Vec::new(),
                spec: Code::structure(
                    "::coolbot::StateSpec",
                    vec![
                        ("name", Code::string(IMPLICIT_STATE)),
                        ("entry", Code::atom("false")),
                        ("exit", Code::atom("false")),
                        ("periodic", Code::atom("None")),
                        ("on", Code::slice(Vec::new())),
                        ("after", Code::slice(Vec::new())),
                        ("may", Code::slice(Vec::new())),
                    ],
                ),
            });
        }
        lowered
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
    overrides: &[(String, Code)],
    from_mapped: &[(String, String)],
    all: usize,
    optional: bool,
) -> Code {
    let path = format!("super::{module}::{kind}");
    let default_path = format!("{path}::default");
    let default = || Code::call(default_path.as_str(), Vec::new());
    let mut named: Vec<&str> = Vec::new();
    for field in overrides
        .iter()
        .map(|(f, _)| f)
        .chain(from_mapped.iter().map(|(f, _)| f))
    {
        if !named.contains(&field.as_str()) {
            named.push(field);
        }
    }
    if named.is_empty() {
        return default();
    }
    let mut entries = Vec::new();
    for field in &named {
        let written = overrides.iter().find(|(f, _)| f == field).map(|(_, v)| {
            if optional {
                Code::core_some(v.clone())
            } else {
                v.clone()
            }
        });
        let mut given = from_mapped
            .iter()
            .filter(|(f, _)| f == field)
            .map(|(_, m)| Code::atom("mapped").field(m.as_str()));
        let value = match (given.next(), written) {
            (None, Some(written)) => written,
            (None, None) => default().field(*field),
            (Some(first), written) => {
                let chain = given.fold(first, |chain, other| chain.method("or", vec![other]));
                match (optional, written) {
                    (true, Some(written)) => chain.method("or", vec![written]),
                    (true, None) => chain,
                    (false, Some(written)) => chain.method("unwrap_or", vec![written]),
                    (false, None) => chain.method(
                        "unwrap_or_else",
                        vec![Code::closure("", default().field(*field))],
                    ),
                }
            }
        };
        entries.push(((*field).to_owned(), value));
    }
    if named.len() < all {
        Code::StructRest(path, entries, Box::new(default()))
    } else {
        Code::Struct(path, entries)
    }
}

/// The builder steps of a compound's own `adaptation { ... }`.
fn compound_adaptation(c: &Component) -> Vec<Code> {
    let tuning = &c.adaptation;
    let config = adaptation::config(&Tuning {
        selector: None,
        ..tuning.clone()
    });
    config
        .map(|config| Code::call("adaptation", vec![config]))
        .into_iter()
        .chain(
            adaptation::selector(tuning)
                .map(|selector| Code::call("adaptation_selector", vec![selector])),
        )
        .collect()
}

/// An instance's `timing { ... }`: the entries it names replace those of the
/// component's block (`base`), the others are kept.
fn timing_override(timing: &[TimingEntry], base: Code) -> Code {
    let mut fields = Vec::new();
    let option = |ns: Option<u64>| match ns {
        Some(ns) => Code::core_some(duration_code(ns)),
        None => Code::core_none(),
    };
    for entry in timing {
        match entry {
            TimingEntry::Period(lo, hi) => {
                fields.push(("period", option(Some(lo.nanos))));
                fields.push(("max_period", option(hi.map(|hi| hi.nanos))));
            }
            TimingEntry::MaxResponse(d) => {
                fields.push(("max_response", option(Some(d.nanos))));
            }
            TimingEntry::Priority(priority) => {
                fields.push(("priority", Code::atom(priority.to_string())));
            }
            TimingEntry::Quality(names) => {
                fields.push(("qualities", self::names(names)));
            }
        }
    }
    // A later entry of the same kind wins, as in a component's block.
    let mut named: Vec<(String, Code)> = Vec::new();
    for (index, (field, value)) in fields.iter().enumerate() {
        if fields[index + 1..].iter().any(|(f, _)| f == field) {
            continue;
        }
        named.push(((*field).to_owned(), value.clone()));
    }
    let path = "::coolbot::TimingSpec".to_owned();
    if named.len() < 5 {
        Code::StructRest(path, named, Box::new(base))
    } else {
        Code::Struct(path, named)
    }
}

/// The builder step exporting input (`input`) or output `name` as `target`,
/// whose port carries `packet` (`Some(None)`: a tick port; `None`: unknown).
fn export_step(name: &str, target: &PortRef, packet: Option<Option<&Ty>>, input: bool) -> Code {
    let (tick, typed) = if input {
        ("export_tick_input", "export_input")
    } else {
        ("export_tick_output", "export_output")
    };
    let method = match packet {
        Some(None) => tick.to_owned(),
        _ => format!("{typed}::<{}>", packet_rust(packet)),
    };
    Code::call(
        method,
        vec![Code::string(name), Code::string(&port_address(target))],
    )
}

/// The Rust type of the packets of an exported port (`()` for a tick port or an
/// unknown one).
fn packet_rust(packet: Option<Option<&Ty>>) -> String {
    match packet {
        Some(Some(ty)) => rust_ty(ty, GEN_TYPES),
        _ => "()".to_owned(),
    }
}

/// The slice `&["a", "b"]` of names.
fn names(names: &[String]) -> Code {
    Code::slice(names.iter().map(|name| Code::string(name)).collect())
}

/// How many fields an atomic component's `Config` and `Vars` have.
fn field_counts(component: &Component) -> (usize, usize) {
    let config = component.configuration.as_ref().map_or(0, Vec::len);
    let vars = component
        .variables
        .iter()
        .filter(|v| v.written.is_some())
        .count();
    (config, vars)
}

/// The quality levels of the last `quality` entry of a `timing` block.
fn quality_levels(timing: Option<&[TimingEntry]>) -> Option<Vec<String>> {
    timing?.iter().rev().find_map(|entry| match entry {
        TimingEntry::Quality(levels) => Some(levels.clone()),
        _ => None,
    })
}

/// The quality levels of the first `quality` entry of an instance's `timing` block.
fn first_quality_levels(timing: &[TimingEntry]) -> Option<Vec<String>> {
    timing.iter().find_map(|entry| match entry {
        TimingEntry::Quality(levels) => Some(levels.clone()),
        _ => None,
    })
}

/// `instance.port`, or `port`.
fn port_address(port: &PortRef) -> String {
    match &port.instance {
        Some(instance) => format!("{}.{}", instance.name, port.port),
        None => port.port.clone(),
    }
}

/// The `coolbot::Spec` of compound `c`: the supervisor's states, the ports it exports,
/// its own exposed variables and its timing (`coolbot::CompoundBuilder::build`
/// completes it).
fn spec(c: &ir::Compound) -> Code {
    Code::structure(
        "::coolbot::Spec",
        vec![
            ("type_name", Code::atom(format!("\"{}\"", c.type_name))),
            ("doc", Code::atom(c.doc_literal())),
            (
                "states",
                Code::slice(c.states.iter().map(|st| st.spec.clone()).collect()),
            ),
            ("initial", Code::atom(c.initial.to_string())),
            ("inputs", Code::slice(c.input_specs.clone())),
            ("outputs", Code::slice(c.output_specs.clone())),
            (
                "variables",
                Code::slice(
                    c.vars
                        .iter()
                        .filter(|v| v.spec_index.is_some())
                        .map(ir::Var::spec)
                        .collect(),
                ),
            ),
            ("exceptions", Code::atom("&[]")),
            ("timing", c.timing.clone()),
        ],
    )
}

#[cfg(test)]
mod tests {
    use crate::ir::{self, Code};
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

    /// Each code's one-line text.
    fn texts(codes: &[Code]) -> Vec<String> {
        codes.iter().map(Code::to_string).collect()
    }

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
            .map(|r| (r.expr.to_string(), r.reads.to_string()))
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
                    when m.period > 20ms || n.max_response == 0ms || m.priority < -2 -> off;
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

    #[test]
    fn timing_variables_read_the_monitor_under_their_own_keys() {
        let rules = rules_of(MONITORED);
        let (expr, reads) = &rules[6];
        assert_eq!(reads, r#"&["m.period", "n.max_response", "m.priority"]"#);
        assert!(
            expr.contains("monitor.period.unwrap_or_default()")
                && expr.contains("monitor.max_response.unwrap_or_default()")
                && expr.contains("i128::from(monitor.priority)"),
            "{expr}"
        );
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
        assert!(on.spec.to_string().contains("may: &[1]"), "{}", on.spec);
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
        let setters: Vec<(&str, &str, String)> = motion
            .setters
            .iter()
            .map(|s| (s.method.as_str(), s.ty.as_str(), s.to_value.to_string()))
            .collect();
        assert_eq!(
            setters,
            [
                (
                    "set_speed",
                    "f64",
                    "::coolbot::Value::from(value)".to_owned()
                ),
                (
                    "set_label",
                    "::std::string::String",
                    "::coolbot::Value::from(value)".to_owned()
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
        let reads: Vec<String> = c.rules.iter().map(|r| r.reads.to_string()).collect();
        // A local variable is not in the supervisor's spec: not a read.
        assert_eq!(
            reads,
            [r#"&["a.state", "mode"]"#, r#"&["level", "a.user_state"]"#]
        );
        let exprs: Vec<String> = c.rules.iter().map(|r| r.expr.to_string()).collect();
        // The condition is a tree: `(a || b) && c`, its operator at the root.
        assert!(
            matches!(&c.rules[0].expr, Code::Binary(left, "&&", _)
                if matches!(left.as_ref(), Code::Paren(_))),
            "{:?}",
            c.rules[0].expr
        );
        assert!(exprs[0].starts_with("(view"), "{}", exprs[0]);
        assert!(
            exprs[0].contains("|| i128::from(vars.faults) > 2)"),
            "{}",
            exprs[0]
        );
        assert_eq!(c.rules[0].vars_param.as_deref(), Some("vars"));
        assert_eq!(
            c.rules[0].call.to_string(),
            "{ let vars = ::std::sync::Arc::clone(&vars); move |view: &::coolbot::View| __cool_rule_0(view, &__cool_lock(&vars)) }"
        );
        // A mapped variable reads the instance standing in for `a` now.
        assert!(exprs[1].contains(r#"view.mapped("level")"#));
        assert!(!exprs[1].contains(r#"view.var("a", "level")"#));
        assert!(exprs[1].contains("!(view"));
        assert_eq!(c.rules[1].vars_param, None);
        assert_eq!(c.rules[1].call.to_string(), "__cool_rule_1");
    }

    #[test]
    fn an_execution_group_is_a_thread_step_in_its_place() {
        let c = &compounds_of(
            "
            atomic Leaf { input feed: last<u32>; output out: data<u32>; }
            compound Loop {
                instance a: Leaf;
                instance b: Leaf;
                instance c: Leaf;
                on error a: restart;
                thread control { b, a }
                connect a.out -> b.feed;
                thread other { c }
            }
            ",
        )[0];
        assert_eq!(
            texts(&c.steps),
            [
                r#"on_error("a", ::coolbot::Policy::Restart)"#,
                r#"thread("control", &["b", "a"])"#,
                r#"thread("other", &["c"])"#,
            ]
        );
    }

    #[test]
    fn builder_steps_follow_the_description() {
        let c = &compounds()[0];
        assert_eq!(
            texts(&c.steps),
            [
                r#"export_input::<u32>("input", "a.input")"#,
                r#"export_output::<u32>("out", "a.out")"#,
                r#"map_observable("level", "a.level")"#,
                r#"map_controllable("gain", "a.gain")"#,
                r#"on_error("a", ::coolbot::Policy::Substitute)"#,
                r#"substitute("b", "a")"#,
            ]
        );
        assert_eq!(
            texts(&c.input_specs),
            [
                "::coolbot::InputSpec { name: \"input\", kind: ::coolbot::InputKind::Fifo { capacity: 4, policy: ::coolbot::OverflowPolicy::Reject }, packet: \"u32\", pull: false }"
            ]
        );
        assert_eq!(c.output_specs.len(), 1);
        let a = &c.instances[0];
        let build = a.build.as_ref().unwrap().to_string();
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
        let build = outer.instances[0].build.as_ref().unwrap();
        assert_eq!(
            build.to_string(),
            r#"super::r#box::component_with("inner", parts.inner(), super::r#box::Vars::default(), super::r#box::Mapped { gain: ::core::option::Option::Some(2.0) })?"#
        );
        // A tree: the nested compound's builder call, then `?`.
        assert!(
            matches!(build, Code::Try(call) if matches!(call.as_ref(), Code::Call(callee, args)
                if callee == "super::r#box::component_with" && args.len() == 4)),
            "{build:?}"
        );
        assert!(outer.instances[0].unapplied.is_empty());
        // Box's own `Mapped` feeds its instance `a`.
        let inner = &compounds()[0];
        assert_eq!(inner.mapped.len(), 1);
        assert_eq!(inner.mapped[0].ty, "f64");
        assert!(
            inner.instances[0]
                .build
                .as_ref()
                .unwrap()
                .to_string()
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
