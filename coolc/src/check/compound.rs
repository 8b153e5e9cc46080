//! Compounds: instances and their overrides, substitutes and redundancy (equal
//! interfaces), connections (kinds, directions, cardinalities, packet types and
//! converters per the port typology table), exported ports, mapped variables, error
//! policies, unconnected transition inputs, and compounds that contain themselves.

use std::collections::{BTreeMap, BTreeSet};

use super::model::{
    Component, InputKind, Model, OutputKind, OverflowPolicy, Port, PortKind, StateMember, Ty,
    Variable,
};
use super::{Checker, adaptation, names, response, values};
use crate::ast::{self, ComponentKind, Span};
use crate::diagnostics::{Code, Diagnostic};
use crate::resolve::DefKind;

/// Every compound-specific check of `component`.
pub(super) fn compound(checker: &mut Checker<'_, '_>, component: &ast::Component) {
    let instances = instances(checker, component);
    for member in &component.members {
        match member {
            ast::Member::Instance(instance) => {
                self::instance(checker, component, instance, &instances)
            }
            ast::Member::Redundant(redundant) => {
                self::redundant(checker, component, &instances, redundant)
            }
            ast::Member::Connect(connect) => self::connect(checker, component, &instances, connect),
            ast::Member::Input(ast::Input {
                def: ast::InputDef::Export(target),
                ..
            }) => {
                endpoint(
                    checker,
                    &instances,
                    target,
                    Direction::Input,
                    "exported input",
                );
            }
            ast::Member::Output(ast::Output {
                def: ast::OutputDef::Export(target),
                ..
            }) => {
                endpoint(
                    checker,
                    &instances,
                    target,
                    Direction::Output,
                    "exported output",
                );
            }
            ast::Member::OnError(on_error) => {
                self::on_error(checker, component, &instances, on_error)
            }
            _ => {}
        }
    }
    arrangement(checker, component, &instances);
    super::thread::threads(checker, component);
    cardinality(checker, component, &instances);
    unwired_substitutes(checker, component, &instances);
    duplicate_policies(checker, component);
    unconnected_transition_inputs(checker, component, &instances);
    unused_blocks(checker, component);
}

/// A `restart { }` block with no `restart` policy, or a `recovery { }` block with
/// nothing that uses the recovery queue (no `substitute` policy, no redundant group)
/// or its deadline (no `restart` policy: an instance stuck past its `max_response`
/// for the deadline is propagated), changes nothing at run time: a warning says so.
fn unused_blocks(checker: &mut Checker<'_, '_>, component: &ast::Component) {
    let policy = |name: &str| {
        component
            .members
            .iter()
            .any(|member| matches!(member, ast::Member::OnError(on) if on.policy.name == name))
    };
    let grouped = component
        .members
        .iter()
        .any(|member| matches!(member, ast::Member::Redundant(_)));
    for member in &component.members {
        let (block, span, help) = match member {
            ast::Member::Restart(restart) if !policy("restart") => (
                "restart",
                restart.span,
                "it sets the budget of the `restart` policy: add `on error x: restart;` or remove the block",
            ),
            ast::Member::Recovery(recovery)
                if !policy("substitute") && !policy("restart") && !grouped =>
            {
                (
                    "recovery",
                    recovery.span,
                    "the recovery queue holds instances whose policy is `substitute` and failed redundant members, and its deadline bounds how long a `restart` waits for a stuck instance: add one or remove the block",
                )
            }
            _ => continue,
        };
        let diagnostic = Diagnostic::warning(
            Code::UnusedBlock,
            checker.file,
            span,
            format!(
                "`{block} {{ }}` applies to no instance of `{}`",
                component.name.name
            ),
        )
        .with_label("changes nothing at run time")
        .with_help(help);
        checker.push(diagnostic);
    }
}

/// The instances of a compound by name, with the interface of their component
/// (`None` when the component is unknown, already reported).
type Instances<'c> = BTreeMap<&'c str, (&'c ast::Instance, Option<std::rc::Rc<Component>>)>;

fn instances<'c>(checker: &mut Checker<'_, '_>, component: &'c ast::Component) -> Instances<'c> {
    let mut out = BTreeMap::new();
    for member in &component.members {
        let ast::Member::Instance(instance) = member else {
            continue;
        };
        let symbols = checker.model.symbols;
        let def = symbols.resolve(
            checker.file,
            &instance.component,
            &[DefKind::Component],
            Code::UnknownComponent,
            "component",
            checker.diagnostics,
        );
        let interface = def.map(|_| checker.model.resolved(&instance.component.name));
        out.entry(instance.name.name.as_str())
            .or_insert((instance, interface));
    }
    out
}

fn instance(
    checker: &mut Checker<'_, '_>,
    component: &ast::Component,
    instance: &ast::Instance,
    instances: &Instances<'_>,
) {
    names::value_name(checker, &instance.name);
    if let Some(node) = &instance.node
        && node.value.trim().is_empty()
    {
        let diagnostic = checker
            .error(Code::TypeMismatch, node.span, "a node name cannot be empty")
            .with_label("empty");
        checker.push(diagnostic);
    }
    if let Some(original) = &instance.substitutes {
        substitute(checker, instance, original, instances);
        unused_substitute(checker, component, instance, original, instances);
    }
    response::instance_override(checker, instance);
    let interface = instances
        .get(instance.name.name.as_str())
        .and_then(|(_, interface)| interface.clone());
    names::duplicates(
        checker,
        instance.overrides.iter().map(|o| &o.name),
        "override",
    );
    for override_ in &instance.overrides {
        let Some(interface) = &interface else {
            continue;
        };
        let fields = interface.fields_by_name();
        let controllable = interface
            .variable(&override_.name.name)
            .filter(|var| var.kind == ast::VarKind::Controllable);
        let controllable_ty = controllable.map(Variable::resolved_ty);
        let expected = fields
            .get(override_.name.name.as_str())
            .copied()
            .or(controllable_ty.as_ref());
        // A controllable's override meets its range, as a set would; a mapped
        // controllable's range is that of the variable it maps.
        if let Some(var) = controllable
            && let Some((range, reached)) = effective_range(checker, &instance.component.name, var)
            && !range.is_empty()
            && let Some(value) = super::model::Number::of(&override_.value)
            && !range.contains(value)
        {
            let help = match reached {
                Some(path) => format!(
                    "give a value inside the range of `{path}`, which `{}` maps",
                    override_.name.name
                ),
                None => "give a value inside the range its component declares".to_owned(),
            };
            let diagnostic = checker
                .error(
                    Code::BadRange,
                    override_.value.span,
                    format!(
                        "`{}` of `{}` takes values in {range}",
                        override_.name.name, instance.component.name
                    ),
                )
                .with_label("outside the variable's range")
                .with_help(help);
            checker.push(diagnostic);
        }
        match expected {
            Some(expected) => {
                // A name that is both a field and a controllable: the override sets
                // both, so its value is of both types.
                if let (Some(field), Some(var_ty)) = (
                    fields.get(override_.name.name.as_str()),
                    controllable_ty.as_ref(),
                ) && !field.same(var_ty)
                {
                    let note = format!(
                        "`{name}` of `{component}` is both a configuration field of type `{field}` and a controllable variable of type `{var_ty}`: an override sets both, so its value must be of both types; rename one of them in `{component}`",
                        name = override_.name.name,
                        component = instance.component.name,
                    );
                    values::value_of_each(checker, &override_.value, &[*field, var_ty], &note);
                } else {
                    values::value(checker, &override_.value, expected);
                }
            }
            None => {
                let candidates: Vec<&str> = fields
                    .keys()
                    .copied()
                    .chain(
                        interface
                            .variables_by_name()
                            .into_iter()
                            .filter(|(_, var)| var.kind == ast::VarKind::Controllable)
                            .map(|(name, _)| name),
                    )
                    .collect();
                checker.unknown(
                    Code::UnknownOverride,
                    &override_.name,
                    "configuration field or controllable variable",
                    &format!(" in `{}`", instance.component.name),
                    candidates,
                );
            }
        }
    }
    if let Some(timing) = &instance.timing {
        values::timing(checker, timing);
        let nested = checker
            .model
            .known(&instance.component.name)
            .is_some_and(|def| def.kind == ComponentKind::Compound);
        if nested {
            compound_timing(checker, timing, &instance.component.name);
        }
    }
    instance_adaptation(checker, component, instance);
}

/// The range a set of controllable `var` of component `component` meets: its own, or,
/// for a mapped controllable, that of the variable it maps (through nested compounds),
/// with the path of the instance variable it reaches (`m.speed`).
fn effective_range(
    checker: &Checker<'_, '_>,
    component: &str,
    var: &Variable,
) -> Option<(super::model::Range, Option<String>)> {
    if let Some(range) = var.range {
        return Some((range, None));
    }
    let mut owner = checker.model.resolved(component);
    let mut mapping = var.mapping.clone()?;
    // Containment cycles are errors of their own: the walk is bounded.
    for _ in 0..64 {
        let [instance, name] = mapping.as_slice() else {
            return None;
        };
        let inner = owner.instances.iter().find(|i| &i.name == instance)?;
        let inner = checker.model.resolved(&inner.component);
        let target = inner
            .variable(name)
            .filter(|v| v.kind == ast::VarKind::Controllable)?;
        if let Some(range) = target.range {
            return Some((range, Some(var.mapping.as_ref()?.join("."))));
        }
        mapping = target.mapping.clone()?;
        owner = inner.clone();
    }
    None
}

/// An instance's `adaptation { ... }`: once, on an instance of an atomic component,
/// checked against the timing that applies to the instance.
fn instance_adaptation(
    checker: &mut Checker<'_, '_>,
    compound: &ast::Component,
    instance: &ast::Instance,
) {
    let [block, rest @ ..] = instance.adaptation.as_slice() else {
        return;
    };
    for repeated in rest {
        let diagnostic = checker
            .error(
                Code::RepeatedBlock,
                repeated.span,
                "an instance has at most one `adaptation` block",
            )
            .with_label("second block")
            .with_secondary(block.span, "first block")
            .with_help("merge the two blocks");
        checker.push(diagnostic);
    }
    let Some(def) = checker.model.known(&instance.component.name) else {
        return;
    };
    if def.kind == ComponentKind::Compound {
        let diagnostic = checker
            .error(
                Code::MisplacedMember,
                block.span,
                format!(
                    "an instance of compound `{}` cannot tune its adaptation",
                    instance.component.name
                ),
            )
            .with_label("on an instance of a compound")
            .with_help(format!(
                "write the `adaptation` block in compound `{}` itself",
                instance.component.name
            ));
        checker.push(diagnostic);
        return;
    }
    // Its component's timing, then the instance's override of it.
    let enclosing = checker.model.resolved(&compound.name.name);
    let overrides = enclosing
        .instances
        .iter()
        .find(|resolved| resolved.name == instance.name.name)
        .and_then(|resolved| resolved.timing.as_deref())
        .unwrap_or_default();
    let adapts = adaptation::adapts(def.timing.iter().flatten().chain(overrides));
    let window = def.adaptation.window.map(u64::from);
    adaptation::block(
        checker,
        block,
        adaptation::Target {
            compound: false,
            adapts,
            window,
        },
    );
}

/// A compound's own `timing` (or a nested compound instance's `timing` override)
/// takes one period for its supervisor's periodic sections, `max_response`,
/// `priority`, and quality levels (its own `quality`, set through its control port,
/// which its rules read and its sections act on by commanding instances); a period
/// interval would be a degraded period of the supervisor itself, which no adaptation
/// uses: a compound's period degrades through its instances. It is an error rather
/// than accepted and ignored.
pub(super) fn compound_timing(checker: &mut Checker<'_, '_>, timing: &ast::Timing, compound: &str) {
    for entry in &timing.entries {
        let ast::TimingEntry::Period(ast::Interval {
            hi: Some(_), span, ..
        }) = entry
        else {
            continue;
        };
        let diagnostic = checker
            .error(
                Code::MisplacedMember,
                *span,
                format!("the timing of compound `{compound}` cannot have a period interval"),
            )
            .with_label("not allowed in a compound")
            .with_help(
                "a compound's period degrades through its instances: give the interval to the atomic components inside, and one period to the supervisor",
            );
        checker.push(diagnostic);
    }
}

/// `substitutes other`: another instance of this compound with the same interface.
fn substitute(
    checker: &mut Checker<'_, '_>,
    instance: &ast::Instance,
    original: &ast::Ident,
    instances: &Instances<'_>,
) {
    if original.name == instance.name.name {
        let diagnostic = checker
            .error(
                Code::UnknownInstance,
                original.span,
                format!("instance `{}` cannot substitute itself", original.name),
            )
            .with_label("itself");
        checker.push(diagnostic);
        return;
    }
    let Some((original_instance, original_interface)) = instances.get(original.name.as_str())
    else {
        checker.unknown(
            Code::UnknownInstance,
            original,
            "instance",
            "",
            instances.keys().copied(),
        );
        return;
    };
    let this = instances
        .get(instance.name.name.as_str())
        .and_then(|(_, interface)| interface.clone());
    if let (Some(this), Some(other)) = (this, original_interface) {
        let differences = interface_differences(&this, other);
        if !differences.is_empty() {
            let diagnostic = checker
                .error(
                    Code::InterfaceMismatch,
                    instance.component.span,
                    format!(
                        "`{}` ({}) cannot substitute `{}` ({}): their interfaces differ",
                        instance.name.name,
                        instance.component.name,
                        original.name,
                        original_instance.component.name
                    ),
                )
                .with_label("different interface")
                .with_secondary(
                    original_instance.component.span,
                    "the substituted instance's component",
                )
                .with_help(differences.join("; "));
            checker.push(diagnostic);
        }
    }
}

/// What differs between two interfaces: ports (direction, kind, packet type) and
/// observable variables.
fn interface_differences(a: &Component, b: &Component) -> Vec<String> {
    let mut out = Vec::new();
    for (direction, ours, theirs) in [
        ("input", a.input_ports(), b.input_ports()),
        ("output", a.output_ports(), b.output_ports()),
    ] {
        let names: BTreeSet<&str> = ours.keys().chain(theirs.keys()).copied().collect();
        for name in names {
            match (ours.get(name), theirs.get(name)) {
                (Some(p), Some(q)) if !same_port(p, q) => {
                    out.push(format!(
                        "{direction} `{name}` is `{}` here but `{}` there",
                        describe_port(p),
                        describe_port(q)
                    ));
                }
                (Some(_), None) => out.push(format!("extra {direction} `{name}`")),
                (None, Some(_)) => out.push(format!("missing {direction} `{name}`")),
                _ => {}
            }
        }
    }
    // Observable and controllable variables (mapped ones and `Set` commands follow
    // whoever stands for the instance).
    let exposed = |i: &Component| -> BTreeMap<String, (ast::VarKind, Ty)> {
        i.variables_by_name()
            .into_iter()
            .filter(|(_, v)| v.kind != ast::VarKind::Local)
            .map(|(n, v)| (n.to_owned(), (v.kind, v.resolved_ty())))
            .collect()
    };
    let (ours, theirs) = (exposed(a), exposed(b));
    let names: BTreeSet<&String> = ours.keys().chain(theirs.keys()).collect();
    for name in names {
        match (ours.get(name), theirs.get(name)) {
            (Some((k, p)), Some((l, q))) if k != l || !p.same(q) => out.push(format!(
                "variable `{name}` is {} `{p}` here but {} `{q}` there",
                kind_word(*k),
                kind_word(*l)
            )),
            (Some((k, _)), None) => out.push(format!("extra {} `{name}`", kind_word(*k))),
            (None, Some((l, _))) => out.push(format!("missing {} `{name}`", kind_word(*l))),
            _ => {}
        }
    }
    out
}

fn same_port(a: &Port, b: &Port) -> bool {
    a.kind() == b.kind()
        && a.pull == b.pull
        && match (a.ty(), b.ty()) {
            (Some(x), Some(y)) => x.same(y),
            (None, None) => true,
            _ => false,
        }
}

fn describe_port(port: &Port) -> String {
    let pull = if port.pull { " pull" } else { "" };
    match port.ty() {
        Some(ty) => format!("{}<{ty}>{pull}", port.kind().as_str()),
        None => format!("{}{pull}", port.kind().as_str()),
    }
}

/// `redundant a, b;`: distinct instances of this compound with equal interfaces.
fn redundant(
    checker: &mut Checker<'_, '_>,
    compound: &ast::Component,
    instances: &Instances<'_>,
    redundant: &ast::Redundant,
) {
    names::duplicates(checker, redundant.members.iter(), "redundant member");
    lossy_members(checker, compound, instances, redundant);
    let mut first: Option<(&ast::Ident, std::rc::Rc<Component>)> = None;
    for member in &redundant.members {
        let Some((instance, interface)) = instances.get(member.name.as_str()) else {
            checker.unknown(
                Code::UnknownInstance,
                member,
                "instance",
                "",
                instances.keys().copied(),
            );
            continue;
        };
        let Some(interface) = interface else { continue };
        match &first {
            None => first = Some((member, interface.clone())),
            Some((first_member, first_interface)) => {
                let differences = interface_differences(interface, first_interface);
                if !differences.is_empty() {
                    let diagnostic = checker
                        .error(
                            Code::InterfaceMismatch,
                            member.span,
                            format!(
                                "redundant instances need equal interfaces, but `{}` ({}) differs from `{}`",
                                member.name, instance.component.name, first_member.name
                            ),
                        )
                        .with_label("different interface")
                        .with_secondary(first_member.span, "compared with this instance")
                        .with_help(differences.join("; "));
                    checker.push(diagnostic);
                }
            }
        }
    }
}

/// Redundant members whose data output is read (the group's merged stream) and that
/// may drop different packets at an input they are fed through: a failover to a
/// member that dropped packets may then skip or double packets of the stream without
/// a count (`docs/runtime.md`, "Redundancy": partial). A `fifo` that rejects or drops
/// the oldest, or a capped `ufifo`, may drop wherever it is fed; a `block` fifo fed by
/// a connection drops after its timeout, while one behind an exported input is safe
/// (the compound leaves out, counts and resynchronizes a member whose queue stays
/// full); an uncapped `ufifo` never drops. Every member's type is read (their
/// interfaces are equal but their policies need not be).
fn lossy_members(
    checker: &mut Checker<'_, '_>,
    compound: &ast::Component,
    instances: &Instances<'_>,
    redundant: &ast::Redundant,
) {
    let members: BTreeSet<&str> = redundant.members.iter().map(|m| m.name.as_str()).collect();
    let of_members = |end: &&ast::PortRef| {
        end.instance
            .as_ref()
            .is_some_and(|instance| members.contains(instance.name.as_str()))
    };
    // The members' inputs (by port: a connection to one feeds them all), each with
    // whether a connection feeds it (else only an export).
    let mut fed: BTreeMap<&str, bool> = BTreeMap::new();
    for member in &compound.members {
        match member {
            ast::Member::Connect(connect) if of_members(&&connect.to) => {
                fed.insert(connect.to.port.name.as_str(), true);
            }
            ast::Member::Input(ast::Input {
                def: ast::InputDef::Export(target),
                ..
            }) if of_members(&target) => {
                fed.entry(target.port.name.as_str()).or_insert(false);
            }
            _ => {}
        }
    }
    let read: BTreeSet<&str> = compound
        .members
        .iter()
        .filter_map(|member| match member {
            ast::Member::Connect(connect) => Some(&connect.from),
            ast::Member::Output(ast::Output {
                def: ast::OutputDef::Export(target),
                ..
            }) => Some(target),
            _ => None,
        })
        .filter(of_members)
        .map(|end| end.port.name.as_str())
        .collect();
    let mut lossy: BTreeSet<String> = BTreeSet::new();
    let mut streams = false;
    for member in &redundant.members {
        // Its type's own declared ports.
        let Some((instance, Some(component))) = instances.get(member.name.as_str()) else {
            continue;
        };
        let type_name = &instance.component.name;
        streams |= component.outputs.iter().any(|output| {
            output.export.is_none()
                && read.contains(output.name.as_str())
                && matches!(
                    output.port.as_ref().map(|port| &port.kind),
                    Some(OutputKind::Data(_))
                )
        });
        for input in component
            .inputs
            .iter()
            .filter(|input| input.export.is_none())
        {
            let Some(&by_connection) = fed.get(input.name.as_str()) else {
                continue;
            };
            let why = match input.port.as_ref().map(|port| &port.kind) {
                Some(InputKind::Fifo { policy, .. }) => match policy.unwrap_or_default() {
                    OverflowPolicy::Block if by_connection => Some(
                        "`fifo`, `block`: fed by a connection, it drops after its timeout"
                            .to_owned(),
                    ),
                    OverflowPolicy::Block => None,
                    policy => Some(format!("`fifo`, `{}`", policy.name())),
                },
                Some(InputKind::Ufifo { max: Some(_), .. }) => {
                    Some("`ufifo` with a cap".to_owned())
                }
                _ => None,
            };
            if let Some(why) = why {
                lossy.insert(format!("`{type_name}.{}` ({why})", input.name));
            }
        }
    }
    if !streams || lossy.is_empty() {
        return;
    }
    let diagnostic = Diagnostic::warning(
        Code::RedundantLossyInput,
        checker.file,
        redundant.span,
        format!(
            "redundant members may drop different packets, and so send different streams: {}",
            lossy.into_iter().collect::<Vec<_>>().join(", ")
        ),
    )
    .with_label("a failover may skip or double packets of the stream, uncounted")
    .with_help(
        "where the merged stream must be exact, feed the members through an exported `block` \
         fifo (the compound leaves out, counts and resynchronizes a member whose queue stays \
         full) or give them uncapped `ufifo` inputs",
    );
    checker.push(diagnostic);
}

/// Substitutions and redundant groups the runtime can arrange: each instance takes
/// part in at most one of them, once (one substitute per instance, a substitute
/// substitutes one instance and has none of its own, no instance both in a
/// substitution and in a redundant group or in two groups).
fn arrangement(
    checker: &mut Checker<'_, '_>,
    component: &ast::Component,
    instances: &Instances<'_>,
) {
    // Where each instance was first placed, and as what.
    let mut placed: BTreeMap<String, (Span, String)> = BTreeMap::new();
    let mut place = |checker: &mut Checker<'_, '_>, ident: &ast::Ident, role: String| {
        if !instances.contains_key(ident.name.as_str()) {
            return;
        }
        let Some((earlier, was)) = placed.get(ident.name.as_str()) else {
            placed.insert(ident.name.clone(), (ident.span, role));
            return;
        };
        let diagnostic = checker
            .error(
                Code::Arrangement,
                ident.span,
                format!("`{}` cannot be {role}: it is already {was}", ident.name),
            )
            .with_label(role.clone())
            .with_secondary(*earlier, format!("{was} here"))
            .with_help(
                "an instance takes part in one substitution (as the substitute or the substituted \
                 instance) or one redundant group: the runtime could not tell who stands for it",
            );
        checker.push(diagnostic);
    };
    for member in &component.members {
        if let ast::Member::Instance(instance) = member
            && let Some(original) = &instance.substitutes
            && original.name != instance.name.name
        {
            place(
                checker,
                &instance.name,
                format!("the substitute of `{}`", original.name),
            );
            place(
                checker,
                original,
                format!("substituted by `{}`", instance.name.name),
            );
        }
    }
    for member in &component.members {
        if let ast::Member::Redundant(redundant) = member {
            let mut seen = BTreeSet::new();
            for ident in &redundant.members {
                // A name twice in one group is `duplicate`.
                if seen.insert(ident.name.as_str()) {
                    place(checker, ident, "in a redundant group".to_owned());
                }
            }
        }
    }
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Direction {
    Input,
    Output,
}

/// Resolves `instance.port` to a port of the given direction, reporting what is wrong.
fn endpoint(
    checker: &mut Checker<'_, '_>,
    instances: &Instances<'_>,
    target: &ast::PortRef,
    direction: Direction,
    what: &str,
) -> Option<Port> {
    let Some(instance_name) = &target.instance else {
        let diagnostic = checker
            .error(
                Code::UnknownInstance,
                target.span,
                format!("the {what} must name an instance's port"),
            )
            .with_label("no instance")
            .with_help(format!("write `instance.{}`", target.port.name));
        checker.push(diagnostic);
        return None;
    };
    let Some((instance, interface)) = instances.get(instance_name.name.as_str()) else {
        checker.unknown(
            Code::UnknownInstance,
            instance_name,
            "instance",
            "",
            instances.keys().copied(),
        );
        return None;
    };
    let interface = interface.as_ref()?;
    let name = target.port.name.as_str();
    let (wanted, other, wanted_name, other_name) = match direction {
        Direction::Input => (
            interface.input(name),
            interface.output(name),
            "input",
            "output",
        ),
        Direction::Output => (
            interface.output(name),
            interface.input(name),
            "output",
            "input",
        ),
    };
    if wanted.is_some() {
        return wanted;
    }
    if other.is_some() {
        let help = match direction {
            Direction::Input => {
                "a connection goes from an output to an input: `connect a.out -> b.in;`"
            }
            Direction::Output => {
                "a connection goes from an output to an input: `connect a.out -> b.in;`"
            }
        };
        let diagnostic = checker
            .error(
                Code::ConnectDirection,
                target.span,
                format!(
                    "`{}` is an {other_name} of `{}`, but the {what} needs an {wanted_name}",
                    target.port.name, instance.component.name
                ),
            )
            .with_label(format!("an {other_name}"))
            .with_help(help);
        checker.push(diagnostic);
        return None;
    }
    checker.unknown(
        Code::UnknownPort,
        &target.port,
        &format!("{wanted_name} port"),
        &format!(
            " in `{}` (component `{}`)",
            instance_name.name, instance.component.name
        ),
        match direction {
            Direction::Input => interface.input_ports(),
            Direction::Output => interface.output_ports(),
        }
        .into_keys(),
    );
    None
}

/// `connect a.out -> b.in [via C];` against the typology table.
fn connect(
    checker: &mut Checker<'_, '_>,
    component: &ast::Component,
    instances: &Instances<'_>,
    connect: &ast::Connect,
) {
    let from = endpoint(
        checker,
        instances,
        &connect.from,
        Direction::Output,
        "connection's source",
    );
    let to = endpoint(
        checker,
        instances,
        &connect.to,
        Direction::Input,
        "connection's destination",
    );
    let converter = connect.via.as_ref().and_then(|via| {
        let symbols = checker.model.symbols;
        symbols.resolve(
            checker.file,
            via,
            &[DefKind::Converter],
            Code::UnknownConverter,
            "converter",
            checker.diagnostics,
        )?;
        checker.model.converter(&via.name)
    });
    let (Some(from), Some(to)) = (from, to) else {
        return;
    };
    let allowed = matches!(
        (from.kind(), to.kind()),
        (PortKind::Tick, PortKind::Tick)
            | (PortKind::Poster, PortKind::Poster)
            | (
                PortKind::Data,
                PortKind::Last | PortKind::Fifo | PortKind::Ufifo
            )
    );
    if !allowed {
        let help = match from.kind() {
            PortKind::Tick => "a `tick` output connects to `tick` inputs",
            PortKind::Poster => "a `poster` output connects to `poster` inputs",
            _ => "a `data` output connects to `last`, `fifo` and `ufifo` inputs",
        };
        // Both ends in full, packet types included: a wrong kind often comes with a
        // wrong port (`data<Detection>` into `poster<JointPosition>`).
        let typed = |kind: PortKind, ty: Option<&Ty>| match ty {
            Some(ty) => format!("{}<{ty}>", kind.as_str()),
            None => kind.as_str().to_owned(),
        };
        let mut help = help.to_owned();
        if let (Some(out_ty), Some(in_ty), None) = (from.ty(), to.ty(), &connect.via)
            && !out_ty.same(in_ty)
        {
            help.push_str(&format!(
                "; the packet types differ too (`{out_ty}` and `{in_ty}`): is this the port you meant?"
            ));
        }
        let diagnostic = checker
            .error(
                Code::ConnectKind,
                connect.span,
                format!(
                    "cannot connect `{}`, a `{}` output, to `{}`, a `{}` input",
                    path(&connect.from),
                    typed(from.kind(), from.ty()),
                    path(&connect.to),
                    typed(to.kind(), to.ty()),
                ),
            )
            .with_label("incompatible port kinds")
            .with_help(help);
        checker.push(diagnostic);
        return;
    }
    if to.pull && !from.pull {
        let diagnostic = checker
            .error(
                Code::ConnectKind,
                connect.to.span,
                "a `pull` input needs a producer that answers pull requests",
            )
            .with_label("pull input")
            .with_secondary(
                connect.from.span,
                "this output does not answer pull requests",
            )
            .with_help("add `pull` to the output's declaration");
        checker.push(diagnostic);
    }
    let (Some(out_ty), Some(in_ty)) = (from.ty(), to.ty()) else {
        if let Some(via) = &connect.via {
            let diagnostic = checker
                .error(
                    Code::ConverterMismatch,
                    via.span,
                    "a tick connection carries no data to convert",
                )
                .with_label("converter on a tick connection")
                .with_help("remove `via ...`");
            checker.push(diagnostic);
        }
        return;
    };
    match (&connect.via, converter) {
        (Some(via), Some((converter_file, converter))) => {
            let converter_from = checker.model.ty(&converter.from);
            let converter_to = checker.model.ty(&converter.to);
            let mut problems = Vec::new();
            if !converter_from.same(out_ty) {
                problems.push(format!(
                    "it reads `{converter_from}` but the output carries `{out_ty}`"
                ));
            }
            if !converter_to.same(in_ty) {
                problems.push(format!(
                    "it produces `{converter_to}` but the input takes `{in_ty}`"
                ));
            }
            if !problems.is_empty() {
                let diagnostic = checker
                    .error(
                        Code::ConverterMismatch,
                        via.span,
                        format!(
                            "converter `{}` does not fit this connection: {}",
                            via.name,
                            problems.join(" and ")
                        ),
                    )
                    .with_label("mismatched converter")
                    .with_other(converter_file, converter.span, "converter declared here");
                checker.push(diagnostic);
            }
        }
        (Some(_), None) => {}
        (None, _) => {
            if !out_ty.same(in_ty) {
                let diagnostic = checker
                    .error(
                        Code::PacketMismatch,
                        connect.span,
                        format!("`{}` carries `{out_ty}` but `{}` takes `{in_ty}`", path(&connect.from), path(&connect.to)),
                    )
                    .with_label("packet types differ")
                    .with_help(format!(
                        "declare `converter {}To{}: {out_ty} -> {in_ty};` and add `via {}To{}` to this connection",
                        type_word(out_ty),
                        type_word(in_ty),
                        type_word(out_ty),
                        type_word(in_ty)
                    ));
                checker.push(diagnostic);
            }
        }
    }
    let _ = component;
}

fn type_word(ty: &Ty) -> String {
    let text = ty.to_string();
    let word: String = text.chars().filter(|c| c.is_alphanumeric()).collect();
    let mut chars = word.chars();
    chars
        .next()
        .map(|c| c.to_ascii_uppercase().to_string() + chars.as_str())
        .unwrap_or_default()
}

fn path(port: &ast::PortRef) -> String {
    match &port.instance {
        Some(instance) => format!("{}.{}", instance.name, port.port.name),
        None => port.port.name.clone(),
    }
}

/// One producer of an input (by instance or redundant group, and port): the output
/// or exported input that feeds it, the instance its connection names, and where.
type Producer = (String, String, Span);

/// `last` and `poster` inputs take one producer (a connection or an export from the
/// compound's interface); `fifo`, `ufifo` and `tick` inputs take any number, and an
/// output feeds any number of inputs (a `data` output any number of queues, each
/// with its own).
fn cardinality(
    checker: &mut Checker<'_, '_>,
    component: &ast::Component,
    instances: &Instances<'_>,
) {
    // A redundant group's members are fed together (every connection to a member
    // reaches all of them): they share their inputs' producers.
    let mut groups: BTreeMap<&str, String> = BTreeMap::new();
    for member in &component.members {
        if let ast::Member::Redundant(redundant) = member {
            let names: Vec<&str> = redundant.members.iter().map(|m| m.name.as_str()).collect();
            for name in &names {
                groups.entry(name).or_insert_with(|| names.join(", "));
            }
        }
    }
    let mut producers: BTreeMap<(String, String), Vec<Producer>> = BTreeMap::new();
    let mut seen_connections: BTreeMap<(String, String), Span> = BTreeMap::new();
    // (group, input port, producer) -> the converter of its first connection, where.
    let mut converted: BTreeMap<(String, String, String), (Option<String>, Span)> = BTreeMap::new();
    for member in &component.members {
        let (target, producer, span) = match member {
            ast::Member::Connect(connect) => {
                let key = (path(&connect.from), path(&connect.to));
                if let Some(first) = seen_connections.get(&key) {
                    let diagnostic = checker
                        .error(
                            Code::Duplicate,
                            connect.span,
                            format!("`{}` is connected to `{}` twice", key.0, key.1),
                        )
                        .with_label("second connection")
                        .with_secondary(*first, "first connection");
                    checker.push(diagnostic);
                    continue;
                }
                seen_connections.insert(key.clone(), connect.span);
                // A redundant group's output is one merged stream, whichever member
                // the connection names; a converter makes another producer.
                let from = match connect
                    .from
                    .instance
                    .as_ref()
                    .and_then(|i| groups.get(i.name.as_str()))
                {
                    Some(group) => format!("{group}.{}", connect.from.port.name),
                    None => key.0,
                };
                let via = connect.via.as_ref().map(|via| via.name.as_str());
                if let Some(instance) = &connect.to.instance
                    && let Some(group) = groups.get(instance.name.as_str())
                {
                    let port = (group.clone(), connect.to.port.name.clone(), from.clone());
                    let conversion = |via: Option<&str>| match via {
                        Some(via) => format!("`{via}`"),
                        None => "no converter".to_owned(),
                    };
                    match converted.get(&port) {
                        Some((other, first)) if other.as_deref() != via => {
                            let diagnostic = checker
                                .error(
                                    Code::ConnectCardinality,
                                    connect.span,
                                    format!(
                                        "`{from}` reaches input `{}` of the redundant group `{group}` twice, through {} and through {}",
                                        connect.to.port.name,
                                        conversion(other.as_deref()),
                                        conversion(via)
                                    ),
                                )
                                .with_label("second connection")
                                .with_secondary(*first, "first connection")
                                .with_help(
                                    "every member gets one connection from an output: connect it once, or feed the group from two outputs",
                                );
                            checker.push(diagnostic);
                            continue;
                        }
                        Some((_, first)) => {
                            // Accepted (the runtime connects the output to each member
                            // once), but it says something the author may not mean.
                            let diagnostic = Diagnostic::warning(
                                Code::GroupConnectedTwice,
                                checker.file,
                                connect.span,
                                format!(
                                    "`{from}` is connected to the redundant group `{group}` already: one connection to a member feeds every member",
                                ),
                            )
                            .with_label("feeds the group a second time")
                            .with_secondary(*first, "this connection feeds every member")
                            .with_help("remove one of the two connections");
                            checker.push(diagnostic);
                        }
                        None => {
                            converted.insert(port, (via.map(str::to_owned), connect.span));
                        }
                    }
                }
                let producer = match via {
                    Some(via) => format!("{from} via {via}"),
                    None => from,
                };
                (&connect.to, producer, connect.span)
            }
            ast::Member::Input(ast::Input {
                name,
                def: ast::InputDef::Export(target),
                span,
                ..
            }) => (target, name.name.clone(), *span),
            _ => continue,
        };
        let Some(instance) = &target.instance else {
            continue;
        };
        let group = groups.get(instance.name.as_str());
        let ends = producers
            .entry((
                group.cloned().unwrap_or_else(|| instance.name.clone()),
                target.port.name.clone(),
            ))
            .or_default();
        // One output connected to several members of a group is one producer: the
        // runtime makes its connection to each member once.
        if !ends.iter().any(|(other, _, _)| *other == producer) {
            ends.push((producer, instance.name.clone(), span));
        }
    }
    for ((owner, port_name), ends) in producers {
        if ends.len() < 2 {
            continue;
        }
        let (_, instance, first) = &ends[0];
        let Some((_, Some(interface))) = instances.get(instance.as_str()) else {
            continue;
        };
        let Some(port) = interface.input(&port_name) else {
            continue;
        };
        if matches!(port.kind(), PortKind::Last | PortKind::Poster) {
            let grouped = owner != *instance;
            for (_, instance, extra) in &ends[1..] {
                let kind = port.kind().as_str();
                // What merges several producers depends on the kind: `data` packets
                // queue in a fifo; a poster is one producer's shared value, read on
                // demand, so each producer needs an input of its own.
                let merge = if port.kind() == PortKind::Poster {
                    "a `poster` input reads one producer's poster: declare one `poster` \
                     input per producer, or merge their values in a component of its own"
                } else {
                    "use a `fifo` or `ufifo` input to merge several producers"
                };
                let (message, help) = if grouped {
                    (
                        format!(
                            "`{instance}.{port_name}` is a `{kind}` input of the redundant \
                             group `{owner}` and takes exactly one producer"
                        ),
                        format!(
                            "every member of a redundant group gets what each connection to \
                             one of them brings, so connect the group's input once. To take \
                             several producers: {merge}"
                        ),
                    )
                } else {
                    (
                        format!(
                            "`{instance}.{port_name}` is a `{kind}` input and takes exactly \
                             one producer"
                        ),
                        merge.to_owned(),
                    )
                };
                let diagnostic = checker
                    .error(Code::ConnectCardinality, *extra, message)
                    .with_label("second producer")
                    .with_secondary(*first, "first producer")
                    .with_help(help);
                checker.push(diagnostic);
            }
        }
    }
}

/// A substitute takes over its original's connections and exports when it stands
/// for it, so it is not wired itself (its own connection and the original's would
/// then meet at its ports).
fn unwired_substitutes(
    checker: &mut Checker<'_, '_>,
    component: &ast::Component,
    instances: &Instances<'_>,
) {
    let mut ends: Vec<&ast::PortRef> = Vec::new();
    for member in &component.members {
        match member {
            ast::Member::Connect(connect) => ends.extend([&connect.from, &connect.to]),
            ast::Member::Input(ast::Input {
                def: ast::InputDef::Export(target),
                ..
            })
            | ast::Member::Output(ast::Output {
                def: ast::OutputDef::Export(target),
                ..
            }) => ends.push(target),
            _ => {}
        }
    }
    for end in ends {
        let Some(instance) = &end.instance else {
            continue;
        };
        let Some((declared, _)) = instances.get(instance.name.as_str()) else {
            continue;
        };
        let Some(original) = &declared.substitutes else {
            continue;
        };
        if original.name == instance.name {
            continue;
        }
        let diagnostic = checker
            .error(
                Code::Arrangement,
                end.span,
                format!(
                    "`{}` substitutes `{}` and is not wired itself",
                    instance.name, original.name
                ),
            )
            .with_label("a substitute's port")
            .with_secondary(declared.name.span, "declared a substitute here")
            .with_help(format!(
                "wire `{}.{}`: its substitute takes that connection over while it stands for it",
                original.name, end.port.name
            ));
        checker.push(diagnostic);
    }
}

/// One `on error` per instance.
fn duplicate_policies(checker: &mut Checker<'_, '_>, component: &ast::Component) {
    let targets = component.members.iter().filter_map(|member| match member {
        ast::Member::OnError(on_error) => Some(&on_error.instance),
        _ => None,
    });
    names::duplicates(checker, targets, "`on error` for instance");
}

/// The error policies a compound may apply to an instance.
const POLICIES: &[&str] = &["propagate", "restart", "substitute", "ignore"];

/// A substitute takes over only when its original's policy is `substitute`; with any
/// other policy it is built and waits in `ready` for nothing: a warning at its
/// `substitutes`.
fn unused_substitute(
    checker: &mut Checker<'_, '_>,
    component: &ast::Component,
    instance: &ast::Instance,
    original: &ast::Ident,
    instances: &Instances<'_>,
) {
    // An arrangement the runtime cannot follow is an error of its own: a substitute
    // of a substitute, of a redundant member, or a second substitute.
    let Some((original_instance, _)) = instances.get(original.name.as_str()) else {
        return;
    };
    let grouped = component.members.iter().any(|member| {
        matches!(member, ast::Member::Redundant(group)
            if group.members.iter().any(|m| m.name == original.name))
    });
    let first = component.members.iter().find_map(|member| match member {
        ast::Member::Instance(other)
            if other
                .substitutes
                .as_ref()
                .is_some_and(|o| o.name == original.name) =>
        {
            Some(other.name.name.as_str())
        }
        _ => None,
    });
    if original.name == instance.name.name
        || original_instance.substitutes.is_some()
        || grouped
        || first != Some(instance.name.name.as_str())
    {
        return;
    }
    let policy = component.members.iter().find_map(|member| match member {
        ast::Member::OnError(on) if on.instance.name == original.name => Some(on),
        _ => None,
    });
    if policy.is_some_and(|on| on.policy.name == "substitute") {
        return;
    }
    let why = policy.map_or_else(
        || {
            format!(
                "`{}` has no `on error` line, so its policy is `propagate`",
                original.name
            )
        },
        |on| format!("the policy of `{}` is `{}`", original.name, on.policy.name),
    );
    let mut diagnostic = Diagnostic::warning(
        Code::UnusedSubstitute,
        checker.file,
        original.span,
        format!(
            "`{}` never stands in for `{}`: {why}",
            instance.name.name, original.name
        ),
    )
    .with_label("never takes over")
    .with_help(format!(
        "write `on error {}: substitute;` for `{}` to take over when `{}` fails, or remove `substitutes {}` (a substitute is built and waits in `ready`)",
        original.name, instance.name.name, original.name, original.name
    ));
    if let Some(on) = policy {
        diagnostic = diagnostic.with_secondary(on.span, "the policy of the original");
    }
    checker.push(diagnostic);
}

/// `on error instance: policy;`: a known instance and policy; `substitute` needs an
/// instance declared `substitutes` it.
fn on_error(
    checker: &mut Checker<'_, '_>,
    component: &ast::Component,
    instances: &Instances<'_>,
    on_error: &ast::OnError,
) {
    if !instances.contains_key(on_error.instance.name.as_str()) {
        checker.unknown(
            Code::UnknownInstance,
            &on_error.instance,
            "instance",
            "",
            instances.keys().copied(),
        );
    }
    let policy = on_error.policy.name.as_str();
    if !POLICIES.contains(&policy) {
        checker.unknown(
            Code::BadPolicy,
            &on_error.policy,
            "error policy",
            "",
            POLICIES.iter().copied(),
        );
        return;
    }
    if policy == "substitute" {
        let has_substitute = instances.values().any(|(instance, _)| {
            instance
                .substitutes
                .as_ref()
                .is_some_and(|original| original.name == on_error.instance.name)
        });
        if !has_substitute {
            let diagnostic = checker
                .error(
                    Code::BadPolicy,
                    on_error.policy.span,
                    format!(
                        "`substitute` needs an instance that substitutes `{}`",
                        on_error.instance.name
                    ),
                )
                .with_label("no substitute declared")
                .with_help(format!(
                    "declare one: `instance spare: {} substitutes {};`",
                    instances
                        .get(on_error.instance.name.as_str())
                        .map(|(i, _)| i.component.name.as_str())
                        .unwrap_or("Component"),
                    on_error.instance.name
                ));
            checker.push(diagnostic);
        }
    }
    unconsulted_policy(checker, component, instances, on_error);
}

/// The runtime consults no policy for a substitute (one that fails while standing in
/// leaves nothing to stand for the original: the compound fails) nor for a member of
/// a redundant group (it goes to the recovery queue while the others keep the group
/// running). A policy written for one would be accepted and ignored: it is an error.
fn unconsulted_policy(
    checker: &mut Checker<'_, '_>,
    component: &ast::Component,
    instances: &Instances<'_>,
    on_error: &ast::OnError,
) {
    let name = on_error.instance.name.as_str();
    let substitutes = instances
        .get(name)
        .and_then(|(instance, _)| instance.substitutes.as_ref());
    let grouped = component.members.iter().any(|member| {
        matches!(member, ast::Member::Redundant(group)
            if group.members.iter().any(|m| m.name == name))
    });
    let (why, help) = if let Some(original) = substitutes {
        (
            format!("`{name}` substitutes `{}`", original.name),
            format!(
                "a substitute that fails while it stands in leaves nothing to stand for `{}`: the compound goes to running_error; remove this line",
                original.name
            ),
        )
    } else if grouped {
        (
            format!("`{name}` is a member of a redundant group"),
            "a failed member goes to the recovery queue while the other members keep the group running (`recovery { }` sets its retries); remove this line".to_owned(),
        )
    } else {
        return;
    };
    let diagnostic = checker
        .error(
            Code::BadPolicy,
            on_error.span,
            format!("no policy applies to `{name}`: {why}"),
        )
        .with_label("never consulted")
        .with_help(help);
    checker.push(diagnostic);
}

/// A mapped variable `observable x = instance.variable;`: the instance exists and has
/// a variable of the same kind (observable for observable, controllable for
/// controllable); `local` cannot be mapped.
pub(super) fn mapped_variable(
    checker: &mut Checker<'_, '_>,
    component: &ast::Component,
    variable: &ast::Variable,
    value: &ast::Expr,
) {
    let segments = match &value.kind {
        ast::ExprKind::Path(segments) if segments.len() == 2 => segments,
        _ => {
            let diagnostic = checker
                .error(Code::BadVariable, variable.span, format!("variable `{}` has a value but no type", variable.name.name))
                .with_label("missing `: Type`")
                .with_help("write `name: Type = value;`, or map an instance's variable with `= instance.variable`");
            checker.push(diagnostic);
            return;
        }
    };
    if component.kind == ComponentKind::Atomic {
        let diagnostic = checker
            .error(
                Code::MisplacedMember,
                variable.span,
                "only a compound can map an instance's variable",
            )
            .with_label("mapped variable in an atomic")
            .with_help("give the variable a type: `name: Type = default;`");
        checker.push(diagnostic);
        return;
    }
    if variable.kind == ast::VarKind::Local {
        let diagnostic = checker
            .error(
                Code::BadVariable,
                variable.kind_span,
                "a `local` variable cannot be mapped",
            )
            .with_label("local")
            .with_help("map it as `observable` or `controllable`, or give it a type");
        checker.push(diagnostic);
        return;
    }
    let (instance_name, variable_name) = (&segments[0], &segments[1]);
    let Some(instance) = Model::instance(component, &instance_name.name) else {
        let names: Vec<&str> = component
            .members
            .iter()
            .filter_map(|m| match m {
                ast::Member::Instance(i) => Some(i.name.name.as_str()),
                _ => None,
            })
            .collect();
        checker.unknown(Code::UnknownInstance, instance_name, "instance", "", names);
        return;
    };
    if checker.model.component(&instance.component.name).is_none() {
        return;
    }
    let interface = checker.model.resolved(&instance.component.name);
    match interface.variable(&variable_name.name) {
        Some(var) if var.kind == variable.kind => {}
        Some(var) => {
            let diagnostic = checker
                .error(
                    Code::BadVariable,
                    variable_name.span,
                    format!(
                        "`{}` is {} in `{}`, but this mapping is {}",
                        variable_name.name,
                        kind_word(var.kind),
                        instance.component.name,
                        kind_word(variable.kind)
                    ),
                )
                .with_label("kind differs")
                .with_help("map an observable variable as `observable` and a controllable one as `controllable`");
            checker.push(diagnostic);
        }
        None => {
            let candidates: Vec<&str> = interface
                .variables_by_name()
                .into_iter()
                .filter(|(_, var)| var.kind == variable.kind)
                .map(|(name, _)| name)
                .collect();
            checker.unknown(
                Code::UnknownVariable,
                variable_name,
                &format!("{} variable", kind_word(variable.kind)),
                &format!(
                    " in `{}` (component `{}`)",
                    instance_name.name, instance.component.name
                ),
                candidates,
            );
        }
    }
}

fn kind_word(kind: ast::VarKind) -> &'static str {
    match kind {
        ast::VarKind::Observable => "observable",
        ast::VarKind::Controllable => "controllable",
        ast::VarKind::Local => "local",
    }
}

/// Warns about an instance input that a transition of its component waits on (`on`
/// or `after ... without`) but that nothing feeds: that transition can never fire.
/// Substitute instances are skipped: they take over the original's connections.
fn unconnected_transition_inputs(
    checker: &mut Checker<'_, '_>,
    component: &ast::Component,
    instances: &Instances<'_>,
) {
    let mut fed: BTreeSet<(String, String)> = BTreeSet::new();
    for member in &component.members {
        let target = match member {
            ast::Member::Connect(connect) => &connect.to,
            ast::Member::Input(ast::Input {
                def: ast::InputDef::Export(target),
                ..
            }) => target,
            _ => continue,
        };
        if let Some(instance) = &target.instance {
            fed.insert((instance.name.clone(), target.port.name.clone()));
        }
    }
    // What feeds one member of a redundant group feeds whichever member stands for
    // the group.
    for member in &component.members {
        if let ast::Member::Redundant(redundant) = member {
            let ports: Vec<String> = fed
                .iter()
                .filter(|(i, _)| redundant.members.iter().any(|m| m.name == *i))
                .map(|(_, port)| port.clone())
                .collect();
            for m in &redundant.members {
                for port in &ports {
                    fed.insert((m.name.clone(), port.clone()));
                }
            }
        }
    }
    for (name, (instance, _)) in instances {
        if instance.substitutes.is_some() {
            continue;
        }
        let Some(inner) = checker.model.known(&instance.component.name) else {
            continue;
        };
        // The ports its automaton waits on: `on port`, `after d without port`.
        let waited = inner
            .automaton
            .iter()
            .flat_map(|automaton| &automaton.states)
            .flat_map(|state| &state.members)
            .filter_map(|member| match member {
                StateMember::On { port, .. }
                | StateMember::After {
                    without: Some(port),
                    ..
                } => Some(port),
                _ => None,
            });
        let mut warned = BTreeSet::new();
        for port in waited {
            if fed.contains(&(name.to_string(), port.name.clone()))
                || !warned.insert(port.name.clone())
            {
                continue;
            }
            let diagnostic = Diagnostic::warning(
                Code::UnconnectedPort,
                checker.file,
                instance.name.span,
                format!(
                    "input `{}` of `{name}` is never fed, but its automaton waits on it",
                    port.name
                ),
            )
            .with_label(format!("`{name}.{}` has no producer", port.name))
            .with_help(format!(
                "connect an output to it (`connect x.out -> {name}.{};`) or export it",
                port.name
            ));
            checker.push(diagnostic);
        }
    }
}

/// Reports every compound that contains itself, directly or through other compounds,
/// once per cycle, with the chain.
pub(super) fn self_containing(checker: &mut Checker<'_, '_>, files: &[ast::File]) {
    let model = checker.model;
    let mut reported: BTreeSet<Vec<String>> = BTreeSet::new();
    for file in files {
        for item in &file.items {
            let ast::Item::Component(component) = item else {
                continue;
            };
            if component.kind != ComponentKind::Compound {
                continue;
            }
            let mut chain = vec![component.name.name.clone()];
            let mut first_member: Option<Span> = None;
            if let Some(cycle) = find_cycle(
                model,
                &component.name.name,
                &mut chain,
                &mut first_member,
                &mut BTreeSet::new(),
            ) {
                let mut key = cycle.clone();
                key.sort();
                if !reported.insert(key) {
                    continue;
                }
                let span = first_member.unwrap_or(component.name.span);
                let diagnostic = Diagnostic::error(
                    Code::SelfContaining,
                    file.id,
                    span,
                    format!("compound `{}` contains itself: {}", component.name.name, cycle.join(" -> ")),
                )
                .with_label("this instance leads back to the compound")
                .with_secondary(component.name.span, "the compound")
                .with_help("a compound cannot be an instance of itself, directly or through other compounds");
                checker.push(diagnostic);
            }
        }
    }
}

/// Depth-first search for a path from `chain[0]` back to itself.
fn find_cycle(
    model: &Model<'_>,
    current: &str,
    chain: &mut Vec<String>,
    first_member: &mut Option<Span>,
    visited: &mut BTreeSet<String>,
) -> Option<Vec<String>> {
    if !visited.insert(current.to_owned()) {
        return None;
    }
    let (_, component) = model.component(current)?;
    for member in &component.members {
        let ast::Member::Instance(instance) = member else {
            continue;
        };
        let next = &instance.component.name;
        if chain.len() == 1 {
            *first_member = Some(instance.component.span);
        }
        if *next == chain[0] {
            let mut cycle = chain.clone();
            cycle.push(next.clone());
            return Some(cycle);
        }
        chain.push(next.clone());
        if let Some(cycle) = find_cycle(model, next, chain, first_member, visited) {
            return Some(cycle);
        }
        chain.pop();
    }
    None
}
