//! Component members: placement (what an atomic or a compound may hold), blocks that
//! may appear once, per-scope duplicates, variables, ports and exceptions.

use super::model::DEFAULT_CONTROLLABLES;
use super::model::{DEFAULT_OBSERVABLES, Number, Range, Ty};
use super::{Checker, adaptation, automaton, compound, names, response, values};
use crate::ast::{self, ComponentKind, Span};
use crate::diagnostics::{Code, Diagnostic};

/// A configuration field without a written default takes its type's: the
/// configuration is built from its defaults when the component starts, so a field
/// whose type has none (an extern packet, an enum without variants, a packet holding
/// one) is refused here rather than failing the crate's build.
pub(super) fn configuration_defaults(
    checker: &mut Checker<'_, '_>,
    files: &[ast::File],
    types: &[super::model::TypeDef],
) {
    let type_def = |name: &str| types.iter().find(|def| def.name() == name);
    for file in files {
        checker.file = file.id;
        for item in &file.items {
            let ast::Item::Component(component) = item else {
                continue;
            };
            for member in &component.members {
                let ast::Member::Configuration(configuration) = member else {
                    continue;
                };
                for field in configuration.fields.iter().filter(|f| f.default.is_none()) {
                    let ty = checker.model.ty(&field.ty);
                    if ty == Ty::Unknown || super::model::has_default(&ty, &type_def) {
                        continue;
                    }
                    let diagnostic = checker
                        .error(
                            Code::NoDefault,
                            field.ty.span,
                            format!(
                                "configuration field `{}` needs a default, and type `{ty}` has none coolc can build",
                                field.name.name
                            ),
                        )
                        .with_label("no default value")
                        .with_help(no_default_help(&field.name.name, &ty, &type_def));
                    checker.push(diagnostic);
                }
            }
        }
    }
}

/// How to give configuration field `name` of type `ty` (which has no default) a
/// value to start from, and why the type has none: make the field optional, or the
/// field of a packet it holds that lacks one; an extern packet has none coolc can
/// build, even when its Rust type implements `Default`.
fn no_default_help<'t>(
    name: &str,
    ty: &Ty,
    type_def: &dyn Fn(&str) -> Option<&'t super::model::TypeDef>,
) -> String {
    use super::model::TypeDef;
    let mut help = format!("make the field optional, `{name}: {ty}?`, which starts as `none`");
    // Down to what has no default: through arrays, and through the first field of a
    // packet that has no default, the innermost such field kept.
    let mut holder: Option<(&str, &str, &Ty)> = None;
    let mut current = ty;
    let mut visited: Vec<&str> = Vec::new();
    let cause = loop {
        let name = match current {
            Ty::Array(inner, _) => {
                current = inner;
                continue;
            }
            Ty::Extern(name) | Ty::Enum(name) | Ty::Packet(name) => name,
            _ => break None,
        };
        match type_def(name) {
            Some(TypeDef::Packet(packet)) if !visited.contains(&packet.name.as_str()) => {
                visited.push(&packet.name);
                // Not a field holding a packet walked through already: that is a
                // packet holding itself, an error of its own.
                let lacking = packet.fields.iter().find(|field| {
                    field.default.is_none()
                        && !held_packet(&field.ty).is_some_and(|held| visited.contains(&held))
                        && !super::model::has_default(&field.ty, type_def)
                });
                let Some(field) = lacking else {
                    break None;
                };
                holder = Some((&packet.name, &field.name, &field.ty));
                current = &field.ty;
            }
            Some(definition @ (TypeDef::Extern(_) | TypeDef::Enum(_))) => break Some(definition),
            _ => break None,
        }
    };
    if let Some((packet, field, field_ty)) = holder {
        help.push_str(&format!(
            ", or make field `{field}` of packet `{packet}` optional (`{field}: {field_ty}?`)"
        ));
    }
    match cause {
        Some(TypeDef::Extern(def)) => help.push_str(&format!(
            ": extern packet `{}` has no default coolc can build, even when `{}` implements `Default` (coolc cannot see another crate's types)",
            def.name, def.rust_path
        )),
        Some(TypeDef::Enum(def)) => {
            help.push_str(&format!(": enum `{}` has no variant to start from", def.name));
        }
        _ => {}
    }
    help
}

/// The packet a value of `ty` holds by value, through arrays.
fn held_packet(ty: &Ty) -> Option<&str> {
    match ty {
        Ty::Array(inner, _) => held_packet(inner),
        Ty::Packet(name) => Some(name),
        _ => None,
    }
}

/// The longest module name of a component (its `snake_case` name), in bytes: the
/// module is written as `src/<module>.rs` and `src/generated/<module>.rs`, a file
/// name holds at most 255 bytes on common file systems, and room is left for the
/// `.rs` and the `_component` suffix a module name taken by coolc gets.
pub(crate) const MAX_MODULE_NAME: usize = 200;

/// A component's name makes its module's file name: at most [`MAX_MODULE_NAME`]
/// bytes in `snake_case`.
fn module_name_length(checker: &mut Checker<'_, '_>, component: &ast::Component) {
    let module = crate::ident::snake_raw(&component.name.name);
    if module.len() <= MAX_MODULE_NAME {
        return;
    }
    let diagnostic = checker
        .error(
            Code::NameTooLong,
            component.name.span,
            format!(
                "the name of component `{}...` is too long: its module `{}...` has {} bytes, at most {MAX_MODULE_NAME}",
                component.name.name.chars().take(24).collect::<String>(),
                module.chars().take(24).collect::<String>(),
                module.len()
            ),
        )
        .with_label("too long for a file name")
        .with_help(format!(
            "the module is written as `src/<module>.rs`, and a file name holds at most 255 bytes: shorten the name to at most {MAX_MODULE_NAME} bytes in snake_case"
        ));
    checker.push(diagnostic);
}

/// Every check of one component.
pub(super) fn component(checker: &mut Checker<'_, '_>, component: &ast::Component) {
    names::type_name(checker, &component.name);
    module_name_length(checker, component);
    if component.kind == ComponentKind::Atomic {
        generated_names(checker, component);
    }
    placement(checker, component);
    repeated_blocks(checker, component);
    scopes(checker, component);
    for member in &component.members {
        match member {
            ast::Member::Link(link) => self::link(checker, link),
            ast::Member::Configuration(configuration) => {
                for field in &configuration.fields {
                    values::field(checker, field);
                }
                values::configuration_size(checker, configuration);
            }
            ast::Member::Variable(variable) => self::variable(checker, component, variable),
            ast::Member::Input(input) => self::input(checker, input),
            ast::Member::Output(output) => self::output(checker, output),
            ast::Member::Timing(timing) => {
                values::timing(checker, timing);
                if component.kind == ComponentKind::Compound {
                    compound::compound_timing(checker, timing, &component.name.name);
                }
            }
            ast::Member::Exception(exception) => {
                self::exception(checker, exception);
                degrade_without_quality(checker, component, exception);
            }
            ast::Member::Recovery(recovery) => {
                if let Some(every) = &recovery.retry_every {
                    values::duration(checker, every, "`retry every`");
                }
                if let Some(deadline) = &recovery.deadline {
                    values::duration(checker, deadline, "`deadline`");
                }
            }
            ast::Member::Restart(restart) => self::restart(checker, restart),
            ast::Member::Adaptation(block) => {
                let compound = component.kind == ComponentKind::Compound;
                let resolved = checker.model.resolved(&component.name.name);
                let target = adaptation::Target {
                    compound,
                    adapts: compound || adaptation::adapts(resolved.timing.iter().flatten()),
                    window: None,
                };
                adaptation::block(checker, block, target);
            }
            ast::Member::Automaton(_)
            | ast::Member::Instance(_)
            | ast::Member::Redundant(_)
            | ast::Member::Thread(_)
            | ast::Member::Connect(_)
            | ast::Member::OnError(_) => {}
        }
    }
    values::variables_size(checker, component);
    automaton::automata(checker, component);
    if component.kind == ComponentKind::Atomic {
        response::unmeasured_responses(checker, component);
    }
    if component.kind == ComponentKind::Compound {
        compound::compound(checker, component);
    }
}

/// Members that the component's kind does not allow.
fn placement(checker: &mut Checker<'_, '_>, component: &ast::Component) {
    let atomic = component.kind == ComponentKind::Atomic;
    for member in &component.members {
        let problem: Option<(Span, &str, &str)> = match member {
            ast::Member::Instance(m) if atomic => Some((
                m.span,
                "an `instance`",
                "instances live in compounds: declare `compound` instead of `atomic`",
            )),
            ast::Member::Redundant(m) if atomic => Some((
                m.span,
                "`redundant`",
                "redundancy groups instances of a compound",
            )),
            ast::Member::Thread(m) if atomic => Some((
                m.span,
                "`thread`",
                "an execution group puts instances of a compound on one thread",
            )),
            ast::Member::Connect(m) if atomic => Some((
                m.span,
                "`connect`",
                "connections join instances of a compound",
            )),
            ast::Member::OnError(m) if atomic => Some((
                m.span,
                "`on error`",
                "error policies apply to instances of a compound; use `exception` plans here",
            )),
            ast::Member::Recovery(m) if atomic => Some((
                m.span,
                "`recovery`",
                "the recovery queue belongs to a compound",
            )),
            ast::Member::Restart(m) if atomic => Some((
                m.span,
                "`restart { }`",
                "the restart budget belongs to a compound's `restart` policy",
            )),
            ast::Member::Input(ast::Input {
                def: ast::InputDef::Export(_),
                span,
                ..
            }) if atomic => Some((
                *span,
                "an exported input",
                "an atomic declares its own ports: `input name: fifo<T>(16);`",
            )),
            ast::Member::Output(ast::Output {
                def: ast::OutputDef::Export(_),
                span,
                ..
            }) if atomic => Some((
                *span,
                "an exported output",
                "an atomic declares its own ports: `output name: data<T>;`",
            )),
            ast::Member::Input(input)
                if !atomic && !matches!(input.def, ast::InputDef::Export(_)) =>
            {
                Some((
                    input.span,
                    "an input of its own",
                    "a compound exports its instances' ports: `input name = instance.port;`",
                ))
            }
            ast::Member::Output(output)
                if !atomic && !matches!(output.def, ast::OutputDef::Export(_)) =>
            {
                Some((
                    output.span,
                    "an output of its own",
                    "a compound exports its instances' ports: `output name = instance.port;`",
                ))
            }
            ast::Member::Automaton(a)
                if atomic && a.keyword == ast::AutomatonKeyword::Supervisor =>
            {
                Some((
                    a.keyword_span,
                    "a `supervisor`",
                    "an atomic component's user automaton is written `automaton { ... }`",
                ))
            }
            ast::Member::Automaton(a)
                if !atomic && a.keyword == ast::AutomatonKeyword::Automaton =>
            {
                Some((
                    a.keyword_span,
                    "an `automaton`",
                    "a compound's user automaton is its supervisor: write `supervisor { ... }`",
                ))
            }
            ast::Member::Exception(m) if !atomic => Some((
                m.span,
                "an `exception`",
                "exceptions are raised by atomic components; use `on error` here",
            )),
            ast::Member::Link(m) if !atomic => Some((
                m.span,
                "a `link`",
                "links belong to the atomic components that use the dependency",
            )),
            ast::Member::Configuration(m) if !atomic => Some((
                m.span,
                "a `configuration`",
                "a compound's instances take configuration overrides \
                 (`instance n: T { field = value; }`); map their controllable variables \
                 to set them from outside",
            )),
            _ => None,
        };
        if let Some((span, what, help)) = problem {
            let kind = if atomic { "an atomic" } else { "a compound" };
            let diagnostic = checker
                .error(
                    Code::MisplacedMember,
                    span,
                    format!("{what} is not allowed in {kind} component"),
                )
                .with_label("not allowed here")
                .with_secondary(
                    component.kind_span,
                    format!("`{}` is declared here", component.name.name),
                )
                .with_help(help);
            checker.push(diagnostic);
        }
    }
}

/// `restart { limit N in D; backoff D..D; }`: a positive count that fits the runtime's
/// `u32`, non-zero durations, a backoff whose first wait is not longer than its last.
fn restart(checker: &mut Checker<'_, '_>, restart: &ast::Restart) {
    if let Some((count, window)) = &restart.limit {
        if let ast::ExprKind::Int(0) = count.kind {
            let diagnostic = checker
                .error(
                    Code::ZeroSize,
                    count.span,
                    "a restart limit must not be zero",
                )
                .with_label("zero here")
                .with_help("to never restart, use `on error x: propagate;`");
            checker.push(diagnostic);
        } else {
            values::value(checker, count, &Ty::Int(ast::Prim::U32));
        }
        values::duration(checker, window, "the restart window");
    }
    if let Some((first, last)) = &restart.backoff {
        values::duration(checker, first, "`backoff`");
        values::duration(checker, last, "`backoff`");
        if let (ast::ExprKind::Duration(lo), ast::ExprKind::Duration(hi)) =
            (&first.kind, &last.kind)
            && lo > hi
        {
            let diagnostic = checker
                .error(
                    Code::ReversedInterval,
                    first.span.join(last.span),
                    "the backoff's first wait is longer than its last",
                )
                .with_label("reversed interval")
                .with_help("write the first wait first: `backoff 10ms..1s;`");
            checker.push(diagnostic);
        }
    }
}

/// `configuration`, `timing`, `automaton`/`supervisor`, `recovery` and `restart`
/// appear at most once.
fn repeated_blocks(checker: &mut Checker<'_, '_>, component: &ast::Component) {
    let mut seen: Vec<(&str, Span)> = Vec::new();
    for member in &component.members {
        let (name, span) = match member {
            ast::Member::Configuration(m) => ("configuration", m.span),
            ast::Member::Timing(m) => ("timing", m.span),
            ast::Member::Automaton(m) => ("automaton", m.keyword_span),
            ast::Member::Recovery(m) => ("recovery", m.span),
            ast::Member::Restart(m) => ("restart", m.span),
            ast::Member::Adaptation(m) => ("adaptation", m.span),
            _ => continue,
        };
        if let Some((_, first)) = seen.iter().find(|(seen_name, _)| *seen_name == name) {
            let diagnostic = checker
                .error(
                    Code::RepeatedBlock,
                    span,
                    format!("a component has at most one `{name}` block"),
                )
                .with_label("second block")
                .with_secondary(*first, "first block")
                .with_help("merge the two blocks");
            checker.push(diagnostic);
        } else {
            seen.push((name, span));
        }
    }
}

/// Duplicates per scope: ports (inputs and outputs share one), variables (which also
/// may not reuse a default variable's name), configuration fields, exceptions,
/// instances.
fn scopes(checker: &mut Checker<'_, '_>, component: &ast::Component) {
    let mut ports = Vec::new();
    let mut variables = Vec::new();
    let mut fields = Vec::new();
    let mut exceptions = Vec::new();
    let mut instances = Vec::new();
    for member in &component.members {
        match member {
            ast::Member::Input(m) => ports.push(&m.name),
            ast::Member::Output(m) => ports.push(&m.name),
            ast::Member::Variable(m) => variables.push(&m.name),
            ast::Member::Configuration(m) => fields.extend(m.fields.iter().map(|f| &f.name)),
            ast::Member::Exception(m) => exceptions.push(&m.name),
            ast::Member::Instance(m) => instances.push(&m.name),
            _ => {}
        }
    }
    names::duplicates(checker, ports.iter().copied(), "port");
    names::duplicates(checker, variables.iter().copied(), "variable");
    names::duplicates(checker, fields.iter().copied(), "configuration field");
    names::duplicates(checker, exceptions.iter().copied(), "exception");
    names::duplicates(checker, instances.iter().copied(), "instance");
    let snake: &[names::Form] = &[names::snake];
    let both: &[names::Form] = &[names::snake, names::camel];
    names::rust_clashes(checker, ports, "port", snake);
    names::rust_clashes(checker, variables.iter().copied(), "variable", snake);
    names::rust_clashes(checker, fields, "configuration field", snake);
    names::rust_clashes(checker, exceptions, "exception", both);
    names::rust_clashes(checker, instances, "instance", both);
    for name in variables {
        // Compared as Rust names: `Period` becomes `period` (its field, its setter).
        let rust = crate::ident::snake_raw(&name.name);
        if DEFAULT_OBSERVABLES.contains(&rust.as_str())
            || DEFAULT_CONTROLLABLES.contains(&rust.as_str())
        {
            let diagnostic = checker
                .error(Code::Duplicate, name.span, format!("`{}` is a default variable of every component", name.name))
                .with_label("clashes with the default variable")
                .with_help("choose another name; the default variables are state, user_state, result, error, cpu_time, elapsed_time, quality, new_state, configuration, period, max_response and priority");
            checker.push(diagnostic);
        }
    }
}

/// An atomic component's code (its user file) imports its generated module whole and
/// defines a struct named like the component: a component named like a type of that
/// module it uses (`Behavior`, `Cx`, a state's `<State>May`) would hide it.
fn generated_names(checker: &mut Checker<'_, '_>, component: &ast::Component) {
    let rust = crate::ident::camel_raw(&component.name.name);
    let clash = |diagnostic: Diagnostic| {
        diagnostic
            .with_label("the struct of the component's code")
            .with_help("rename the component")
    };
    if let Some(what) = match rust.as_str() {
        "Behavior" => Some("the trait its code implements"),
        "Cx" => Some("the context its sections take"),
        _ => None,
    } {
        let diagnostic = checker.error(
            Code::NameClash,
            component.name.span,
            format!(
                "the code of atomic component `{}` defines a struct `{rust}`, which hides `{rust}`, {what}",
                component.name.name
            ),
        );
        checker.push(clash(diagnostic));
        return;
    }
    for member in &component.members {
        let ast::Member::Automaton(automaton) = member else {
            continue;
        };
        for state in &automaton.states {
            let may = state.members.iter().find_map(|m| match m {
                ast::StateMember::May { span, .. } => Some(*span),
                _ => None,
            });
            let Some(may) = may else { continue };
            let enum_name = format!("{}May", crate::ident::camel_raw(&state.name.name));
            if enum_name == rust {
                let diagnostic = checker
                    .error(
                        Code::NameClash,
                        component.name.span,
                        format!(
                            "the code of atomic component `{}` defines a struct `{enum_name}`, which hides `{enum_name}`, the targets state `{}` may choose",
                            component.name.name, state.name.name
                        ),
                    )
                    .with_secondary(may, format!("makes the enum `{enum_name}`"));
                checker.push(clash(diagnostic));
                return;
            }
        }
    }
}

fn link(checker: &mut Checker<'_, '_>, link: &ast::Link) {
    let name = match &link.kind {
        ast::LinkKind::Crate { name, .. } | ast::LinkKind::System { name } => name,
    };
    if name.value.trim().is_empty() {
        let diagnostic = checker
            .error(Code::BadLink, name.span, "a link needs a name")
            .with_label("empty name");
        checker.push(diagnostic);
    } else {
        match &link.kind {
            ast::LinkKind::System { name } => system_library_name(checker, name),
            ast::LinkKind::Crate { name, .. } => crate_name(checker, name),
        }
    }
    if let ast::LinkKind::Crate {
        spec: ast::CrateSpec::Table(entries, span),
        ..
    } = &link.kind
    {
        crate_table(checker, entries, *span);
    }
}

/// A `link system` name goes to the linker through the generated build script
/// (`cargo:rustc-link-lib=NAME`): a plain library name only, so that nothing else
/// reaches the script or the linker.
fn system_library_name(checker: &mut Checker<'_, '_>, name: &ast::StrLit) {
    let plain = !name.value.starts_with('-')
        && name
            .value
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | '+'));
    if !plain {
        let diagnostic = checker
            .error(
                Code::BadLink,
                name.span,
                format!("`{}` is not a library name", name.value.escape_debug()),
            )
            .with_label("not a plain library name")
            .with_help("a system library is named with ASCII letters, digits, `_`, `-`, `.` and `+`, not starting with `-` (`m`, `ssl`, `stdc++`)");
        checker.push(diagnostic);
    }
}

/// A `link crate` name becomes a key of the generated `Cargo.toml` and the name the
/// component's code uses: a crate name (ASCII letters, digits, `_` and `-`, starting
/// with a letter or `_`), and not `coolbot`, the runtime dependency coolc writes.
fn crate_name(checker: &mut Checker<'_, '_>, name: &ast::StrLit) {
    let valid = name
        .value
        .chars()
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && name
            .value
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-'));
    if !valid {
        let diagnostic = checker
            .error(
                Code::BadLink,
                name.span,
                format!("`{}` is not a crate name", name.value.escape_debug()),
            )
            .with_label("not a crate name")
            .with_help("a crate is named with ASCII letters, digits, `_` and `-`, starting with a letter or `_`");
        checker.push(diagnostic);
    } else if name.value == "coolbot" {
        let diagnostic = checker
            .error(
                Code::BadLink,
                name.span,
                "`coolbot` is the runtime crate, which coolc writes into the generated `Cargo.toml`",
            )
            .with_label("coolc's own dependency")
            .with_help("remove this link: the generated crate depends on the coolbot coolc was built with");
        checker.push(diagnostic);
    }
}

/// Two `link crate` of one crate (in any components) must say the same: the generated
/// `Cargo.toml` holds one dependency per crate.
pub(super) fn crate_versions(checker: &mut Checker<'_, '_>, files: &[ast::File]) {
    let mut seen: std::collections::BTreeMap<
        &str,
        (ast::FileId, &ast::StrLit, &ast::CrateSpec, &str),
    > = std::collections::BTreeMap::new();
    for file in files {
        for item in &file.items {
            let ast::Item::Component(component) = item else {
                continue;
            };
            for member in &component.members {
                let ast::Member::Link(ast::Link {
                    kind: ast::LinkKind::Crate { name, spec },
                    ..
                }) = member
                else {
                    continue;
                };
                let Some((first_file, first_name, first_spec, first_component)) =
                    seen.get(name.value.as_str()).copied()
                else {
                    seen.insert(&name.value, (file.id, name, spec, &component.name.name));
                    continue;
                };
                if same_spec(first_spec, spec) {
                    continue;
                }
                checker.file = file.id;
                let diagnostic = checker
                    .error(
                        Code::BadLink,
                        spec_span(spec),
                        format!(
                            "`{}` links crate `{}` differently from `{first_component}`",
                            component.name.name, name.value
                        ),
                    )
                    .with_label(format!("`{}` asks for `{}`", component.name.name, spec_text(spec)))
                    .with_other(
                        first_file,
                        spec_span(first_spec),
                        format!("`{first_component}` asks for `{}`", spec_text(first_spec)),
                    )
                    .with_help(format!(
                        "the generated crate has one `{}` dependency: link it with the same version or table everywhere",
                        first_name.value
                    ));
                checker.push(diagnostic);
            }
        }
    }
}

fn spec_span(spec: &ast::CrateSpec) -> Span {
    match spec {
        ast::CrateSpec::Version(version) => version.span,
        ast::CrateSpec::Table(_, span) => *span,
    }
}

/// The spec as written, without spans, for comparing and quoting.
fn spec_text(spec: &ast::CrateSpec) -> String {
    match spec {
        ast::CrateSpec::Version(version) => format!("{:?}", version.value),
        ast::CrateSpec::Table(entries, _) => {
            let entries: Vec<String> = entries
                .iter()
                .map(|e| format!("{} = {}", e.key.name, expr_text(&e.value)))
                .collect();
            format!("{{ {} }}", entries.join(", "))
        }
    }
}

fn expr_text(expr: &ast::Expr) -> String {
    match &expr.kind {
        ast::ExprKind::Str(s) => format!("{s:?}"),
        ast::ExprKind::Bool(b) => b.to_string(),
        ast::ExprKind::Int(i) => i.to_string(),
        ast::ExprKind::Float(f) => f.to_string(),
        ast::ExprKind::List(items) => {
            let items: Vec<String> = items.iter().map(expr_text).collect();
            format!("[{}]", items.join(", "))
        }
        other => format!("{other:?}"),
    }
}

fn same_spec(a: &ast::CrateSpec, b: &ast::CrateSpec) -> bool {
    spec_text(a) == spec_text(b)
}

/// The keys an inline crate table may use, with the kind of value each takes.
const CRATE_KEYS: &[(&str, &str)] = &[
    ("version", "string"),
    ("path", "string"),
    ("git", "string"),
    ("branch", "string"),
    ("tag", "string"),
    ("rev", "string"),
    ("package", "string"),
    ("registry", "string"),
    ("features", "list"),
    ("default_features", "bool"),
    ("optional", "bool"),
];

/// `{ version = "0.33", features = ["x"] }`: known keys, each once, with values of
/// the right kind, and a source (`version`, `path` or `git`).
fn crate_table(checker: &mut Checker<'_, '_>, entries: &[ast::TableEntry], span: Span) {
    names::duplicates(checker, entries.iter().map(|e| &e.key), "crate table key");
    for entry in entries {
        let Some((_, kind)) = CRATE_KEYS.iter().find(|(key, _)| *key == entry.key.name) else {
            checker.unknown(
                Code::BadLink,
                &entry.key,
                "crate table key",
                "",
                CRATE_KEYS.iter().map(|(key, _)| *key),
            );
            continue;
        };
        let fits = match *kind {
            "string" => matches!(entry.value.kind, ast::ExprKind::Str(_)),
            "bool" => matches!(entry.value.kind, ast::ExprKind::Bool(_)),
            _ => match &entry.value.kind {
                ast::ExprKind::List(items) => items
                    .iter()
                    .all(|item| matches!(item.kind, ast::ExprKind::Str(_))),
                _ => false,
            },
        };
        if !fits {
            let expected = match *kind {
                "string" => "a string",
                "bool" => "`true` or `false`",
                _ => "a list of strings",
            };
            let diagnostic = checker
                .error(
                    Code::BadLink,
                    entry.value.span,
                    format!("`{}` takes {expected}", entry.key.name),
                )
                .with_label(format!("expected {expected}"));
            checker.push(diagnostic);
        }
    }
    if !entries
        .iter()
        .any(|e| matches!(e.key.name.as_str(), "version" | "path" | "git"))
    {
        let diagnostic = checker
            .error(
                Code::BadLink,
                span,
                "a crate table needs `version`, `path` or `git`",
            )
            .with_label("no source for the crate")
            .with_help("add `version = \"1\"`");
        checker.push(diagnostic);
    }
}

/// Own variables have a type (and maybe a default of that type); mapped ones (in a
/// compound) name an instance's variable of the same kind and have no type.
fn variable(checker: &mut Checker<'_, '_>, component: &ast::Component, variable: &ast::Variable) {
    names::value_name(checker, &variable.name);
    match (&variable.ty, &variable.value) {
        (Some(ty), Some(value)) => {
            values::ty(checker, ty);
            if matches!(&value.kind, ast::ExprKind::Path(segments) if segments.len() == 2) {
                let diagnostic = checker
                    .error(Code::BadVariable, variable.span, format!("variable `{}` has a type and a mapping", variable.name.name))
                    .with_label("typed and mapped")
                    .with_help("a mapped variable takes its type from the instance's variable: remove the `: Type`");
                checker.push(diagnostic);
                return;
            }
            let expected = checker.model.ty(ty);
            values::value(checker, value, &expected);
        }
        (Some(ty), None) => values::ty(checker, ty),
        (None, None) => {
            let diagnostic = checker
                .error(
                    Code::BadVariable,
                    variable.span,
                    format!("variable `{}` has no type", variable.name.name),
                )
                .with_label("missing `: Type`")
                .with_help(format!(
                    "write `{}: f64;` (any type), or in a compound map it: `= instance.variable`",
                    variable.name.name
                ));
            checker.push(diagnostic);
        }
        (None, Some(value)) => compound::mapped_variable(checker, component, variable, value),
    }
    if let Some(range) = &variable.range {
        self::range(checker, variable, range);
    }
}

/// `in low..=high`: on an own controllable variable of a number type, with bounds of
/// its type in order, and its default inside.
fn range(checker: &mut Checker<'_, '_>, variable: &ast::Variable, range: &ast::VarRange) {
    let refuse =
        |checker: &mut Checker<'_, '_>, span: Span, message: String, label: &str, help: &str| {
            let diagnostic = checker
                .error(Code::BadRange, span, message)
                .with_label(label)
                .with_help(help);
            checker.push(diagnostic);
        };
    let name = &variable.name.name;
    if variable.kind != ast::VarKind::Controllable {
        let kind = match variable.kind {
            ast::VarKind::Observable => "observable",
            _ => "local",
        };
        return refuse(
            checker,
            range.span,
            format!("`{name}` is {kind}: only a controllable variable has a range"),
            "a range on a variable nobody sets from outside",
            "a range bounds what the control port may set: remove it, or make the variable `controllable`",
        );
    }
    let Some(ty) = &variable.ty else {
        return refuse(
            checker,
            range.span,
            format!("`{name}` is mapped: it takes the range of the instance's variable"),
            "a range on a mapped variable",
            "declare the range on the instance's own variable",
        );
    };
    let expected = checker.model.ty(ty);
    if !matches!(expected, Ty::Int(_) | Ty::Float(_)) {
        return refuse(
            checker,
            range.span,
            format!("`{name}` is a `{expected}`: only a number has a range"),
            "a range on a variable that is not a number",
            "ranges bound integer and float variables",
        );
    }
    if !range.inclusive {
        return refuse(
            checker,
            range.span,
            "a range includes both ends: write `low..=high`".to_owned(),
            "`..`",
            "write `in low..=high`",
        );
    }
    let before = checker.diagnostics.len();
    values::value(checker, &range.low, &expected);
    values::value(checker, &range.high, &expected);
    let reported = checker.diagnostics.len() > before;
    let Some(bounds) = Range::of(range, &expected) else {
        // Ends that are not numbers of the type: reported just above, or beyond what
        // the type holds.
        if !reported && Number::of(&range.low).is_some() && Number::of(&range.high).is_some() {
            refuse(
                checker,
                range.span,
                format!("the range of `{name}` has an end beyond what a `{expected}` holds"),
                "not a finite value of the type",
                "write ends the variable's type can hold",
            );
        }
        return;
    };
    if bounds.is_empty() {
        return refuse(
            checker,
            range.span,
            format!("the range of `{name}` is empty: its low end is above its high end"),
            "empty range",
            "write the lower bound first",
        );
    }
    if let Some(default) = variable.value.as_ref()
        && let Some(value) = Number::of(default)
        && !bounds.contains(value)
    {
        let diagnostic = checker
            .error(
                Code::BadRange,
                default.span,
                format!("the default of `{name}` lies outside its range {bounds}"),
            )
            .with_label("outside the range")
            .with_secondary(range.span, "the range")
            .with_help("give a default inside the range");
        checker.push(diagnostic);
    }
}

fn input(checker: &mut Checker<'_, '_>, input: &ast::Input) {
    names::value_name(checker, &input.name);
    match &input.def {
        ast::InputDef::Tick => {
            // No tick output answers pulls (`output`), so a tick input that pulls
            // could never be connected.
            if let Some(pull) = input.pull {
                let diagnostic = checker
                    .error(
                        Code::ConnectKind,
                        pull,
                        "a `tick` input cannot pull: no tick output answers pull requests",
                    )
                    .with_label("`pull` on a tick input")
                    .with_help(
                        "remove `pull`, or make the input `last<T> pull` or `fifo<T>(n) pull`",
                    );
                checker.push(diagnostic);
            }
        }
        ast::InputDef::Export(_) => {}
        ast::InputDef::Fifo { ty, size, policy } => {
            values::ty(checker, ty);
            values::positive(checker, size, "a fifo size");
            queue_size(checker, size, ty, "a fifo size");
            if let Some(policy) = policy
                && !FIFO_POLICIES.contains(&policy.name.as_str())
            {
                checker.unknown(
                    Code::UnknownPolicy,
                    policy,
                    "fifo policy",
                    "",
                    FIFO_POLICIES.iter().copied(),
                );
            }
        }
        ast::InputDef::Ufifo { ty, size, max } => {
            values::ty(checker, ty);
            values::positive(checker, size, "a ufifo size");
            queue_size(checker, size, ty, "a ufifo size");
            if let Some(max) = max
                && max.value < size.value
            {
                let diagnostic = checker
                    .error(
                        Code::UfifoCap,
                        max.span,
                        format!(
                            "the cap {} is below the initial size {}",
                            max.value, size.value
                        ),
                    )
                    .with_label("cap below initial size")
                    .with_secondary(size.span, "initial size")
                    .with_help(format!("write a cap of at least {}", size.value));
                checker.push(diagnostic);
            }
        }
        ast::InputDef::Last(ty) | ast::InputDef::Poster(ty) => values::ty(checker, ty),
    }
}

/// A queue's size is allocated when the component starts: at most
/// [`super::MAX_QUEUE_SIZE`] packets, and at most [`values::MAX_QUEUE_BYTES`] of
/// packets of type `ty` (each held inline in the queue).
fn queue_size(checker: &mut Checker<'_, '_>, size: &ast::IntLit, ty: &ast::Type, what: &str) {
    if size.value > super::MAX_QUEUE_SIZE {
        let diagnostic = checker
            .error(
                Code::SizeLimit,
                size.span,
                format!("{what} is at most {}", super::MAX_QUEUE_SIZE),
            )
            .with_label("too large: the queue is allocated when the component starts")
            .with_help("a ufifo grows from a small size: `ufifo<T>(64, max 10000000)`");
        checker.push(diagnostic);
        return;
    }
    let each = values::packet_size_of(checker, ty);
    let bytes = u128::from(size.value).saturating_mul(each);
    if bytes > u128::from(values::MAX_QUEUE_BYTES) {
        let diagnostic = checker
            .error(
                Code::SizeLimit,
                size.span,
                format!(
                    "{what} of {} packets of about {each} bytes takes about {bytes} bytes, more than {} ({} MiB)",
                    size.value,
                    values::MAX_QUEUE_BYTES,
                    values::MAX_QUEUE_BYTES >> 20
                ),
            )
            .with_label("too large: the queue is allocated when the component starts")
            .with_help(
                "a smaller queue, or a ufifo that grows from a small size: `ufifo<T>(64, max 10000000)`",
            );
        checker.push(diagnostic);
    }
}

/// The overflow policies of a full `fifo` input.
pub(super) const FIFO_POLICIES: &[&str] = &["reject", "drop_oldest", "block"];

fn output(checker: &mut Checker<'_, '_>, output: &ast::Output) {
    names::value_name(checker, &output.name);
    match &output.def {
        ast::OutputDef::Tick | ast::OutputDef::Export(_) => {
            if let (Some(pull), ast::OutputDef::Tick) = (output.pull, &output.def) {
                let diagnostic = checker
                    .error(
                        Code::ConnectKind,
                        pull,
                        "a `tick` output carries no data and cannot answer pull requests",
                    )
                    .with_label("`pull` on a tick output")
                    .with_help("remove `pull`, or make the output `data<T> pull`");
                checker.push(diagnostic);
            }
        }
        ast::OutputDef::Data(ty) | ast::OutputDef::Poster(ty) => values::ty(checker, ty),
    }
}

fn exception(checker: &mut Checker<'_, '_>, exception: &ast::Exception) {
    names::value_name(checker, &exception.name);
    for step in &exception.plan {
        if let ast::PlanKind::Retry { count, every } = &step.kind {
            values::positive(checker, count, "a retry count");
            if count.value > u64::from(u32::MAX) {
                let diagnostic = checker
                    .error(
                        Code::SizeLimit,
                        count.span,
                        format!("a retry count is at most {}", u32::MAX),
                    )
                    .with_label("too many: the runtime counts retries in 32 bits")
                    .with_help(format!("write a count from 1 to {}", u32::MAX));
                checker.push(diagnostic);
            }
            values::duration(checker, every, "`retry ... every`");
        }
    }
}

/// A `degrade` step lowers the quality level by one; with fewer than two levels it
/// never applies and is skipped (the plan goes on to its next step, or, after the
/// last, the component goes to running error). An instance's `timing` override may
/// declare levels of its own: the help says so.
fn degrade_without_quality(
    checker: &mut Checker<'_, '_>,
    component: &ast::Component,
    exception: &ast::Exception,
) {
    let Some(position) = exception
        .plan
        .iter()
        .position(|step| matches!(step.kind, ast::PlanKind::Degrade))
    else {
        return;
    };
    let step = &exception.plan[position];
    let levels = component
        .members
        .iter()
        .filter_map(|member| match member {
            ast::Member::Timing(timing) => Some(timing),
            _ => None,
        })
        .flat_map(|timing| &timing.entries)
        .filter_map(|entry| match entry {
            ast::TimingEntry::Quality(levels, _) => Some(levels.len()),
            _ => None,
        })
        .max()
        .unwrap_or(0);
    if levels >= 2 {
        return;
    }
    let then = if position + 1 < exception.plan.len() {
        "skipped: the plan goes on to its next step"
    } else {
        "skipped: the plan ends and the component goes to running error"
    };
    let diagnostic = Diagnostic::warning(
        Code::DegradeWithoutQuality,
        checker.file,
        step.span,
        format!(
            "`degrade` has no lower quality to go to: `{}` declares {} quality level{}",
            component.name.name,
            if levels == 0 { "no".to_owned() } else { levels.to_string() },
            if levels == 1 { "" } else { "s" }
        ),
    )
    .with_label(then)
    .with_help(format!(
        "declare two or more levels, best first, in the timing block (`timing {{ quality full, reduced; }}`); an instance's `timing` override that declares them also makes the step apply for that instance of `{}`",
        component.name.name
    ));
    checker.push(diagnostic);
}
