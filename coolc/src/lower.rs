//! Lowering: checked ASTs to the IR the templates print.
//!
//! Lowering takes a [`Checked`] model, which exists only when the checker found no
//! error, and looks every name up in it (types, components, interfaces, typed rules).
//! It never fails: a lookup that finds nothing (impossible in a checked model) lowers
//! to something harmless (index 0, the type `()`), never a panic.

use std::collections::{BTreeMap, BTreeSet};

use crate::ast::{self, ExprKind, Prim, TypeKind};
use crate::check::model::Ty;
use crate::checked::{Checked, TypeDef};
use crate::ident;
use crate::ir::{self, RuntimeDep};

mod adaptation;
mod compound;
pub mod harness;

/// What the caller decides about the emitted crate.
#[derive(Clone, Debug)]
pub struct Options {
    /// Cargo package name.
    pub package: String,
    /// Where the runtime crate comes from.
    pub runtime: RuntimeDep,
    /// Source file names shown in the generated-file header.
    pub sources: Vec<String>,
    /// The fingerprint of the inputs shown in the generated-file header:
    /// [`crate::fingerprint::inputs`] of the analysis's sources.
    pub inputs: String,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            package: "cool-components".to_owned(),
            runtime: RuntimeDep::Version("0.1".to_owned()),
            sources: Vec::new(),
            inputs: crate::fingerprint::inputs(&[]),
        }
    }
}

/// Path of the types module as seen from a component module.
const GEN_TYPES: &str = "super::types::";
/// Path of the types module as seen from user files.
const USER_TYPES: &str = "crate::generated::types::";
/// The default value of a type that implements `Default`.
const DEFAULT: &str = "::core::default::Default::default()";

struct Lowerer<'a> {
    /// The checked model: every name lowering meets is looked up in it.
    checked: &'a Checked,
    /// Generated module name of every component.
    modules: BTreeMap<&'a str, String>,
}

/// Lowers checked descriptions (imports included) to the IR of one crate.
pub fn lower(checked: &Checked, options: &Options) -> ir::Crate {
    let mut lowerer = Lowerer {
        checked,
        modules: BTreeMap::new(),
    };
    // Module names in source order; names coolc uses itself are taken.
    let mut taken: BTreeSet<String> = ["types", "support", "converters", "generated"]
        .map(str::to_owned)
        .into_iter()
        .collect();
    for (_, c) in checked.ast_components() {
        let mut module = ident::snake_raw(&c.name.name);
        while !taken.insert(module.clone()) {
            module.push_str("_component");
        }
        lowerer.modules.insert(&c.name.name, ident::escape(&module));
    }
    lowerer.lower_crate(checked.files(), options)
}

/// A Cargo package name made from `name` (lowercase, `-` separated).
pub fn package_name(name: &str) -> String {
    let snake = ident::snake_raw(name);
    let cleaned: String = snake
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
        .collect();
    let trimmed = cleaned.trim_matches('-');
    if trimmed.is_empty() {
        "cool-components".to_owned()
    } else {
        trimmed.to_owned()
    }
}

fn doc(doc: &ast::Doc) -> ir::Doc {
    doc.0.clone()
}

/// Nanoseconds of a duration or frequency expression.
fn duration_ns(expr: &ast::Expr) -> Option<u64> {
    match &expr.kind {
        ExprKind::Duration(ns) => Some(u64::try_from(*ns).unwrap_or(u64::MAX)),
        ExprKind::Frequency(hz) if *hz > 0.0 => Some((1e9 / hz).round() as u64),
        _ => None,
    }
}

fn duration_rust(ns: u64) -> String {
    format!("::std::time::Duration::from_nanos({ns})")
}

fn option_duration(expr: Option<&ast::Expr>) -> String {
    match expr.and_then(duration_ns) {
        Some(ns) => format!("Some({})", duration_rust(ns)),
        None => "None".to_owned(),
    }
}

/// The path of the serde_with crate as generated code sees it (re-exported by the
/// runtime).
const SERDE_WITH: &str = "::coolbot::serde_with::";

/// The serde_with adapter type of `ty` when it holds an array longer than 32
/// elements, directly or in lists, optionals and arrays (a packet field of such a
/// type is the packet's business): `[Same; 72]`, `Option<[[Same; 40]; 2]>`.
fn serde_adapter(ty: &Ty) -> Option<String> {
    fn adapter(ty: &Ty) -> String {
        match ty {
            Ty::List(inner) => format!("::std::vec::Vec<{}>", adapter(inner)),
            Ty::Array(inner, n) => format!("[{}; {n}]", adapter(inner)),
            Ty::Optional(inner) => format!("::core::option::Option<{}>", adapter(inner)),
            _ => format!("{SERDE_WITH}Same"),
        }
    }
    fn needs(ty: &Ty) -> bool {
        match ty {
            Ty::List(inner) | Ty::Optional(inner) => needs(inner),
            Ty::Array(inner, n) => *n > 32 || needs(inner),
            _ => false,
        }
    }
    needs(ty).then(|| adapter(ty))
}

/// The Rust type of a resolved type; named types under `prefix` (an unresolved one,
/// impossible in a checked model, is `()`).
fn rust_ty(ty: &Ty, prefix: &str) -> String {
    match ty {
        Ty::Bool => "bool".to_owned(),
        Ty::Int(p) | Ty::Float(p) => prim_rust(*p).to_owned(),
        Ty::Str => prim_rust(Prim::String).to_owned(),
        Ty::Time => prim_rust(Prim::Time).to_owned(),
        Ty::Duration => prim_rust(Prim::Duration).to_owned(),
        Ty::Packet(name) | Ty::Enum(name) | Ty::Extern(name) => {
            format!("{prefix}{}", ident::camel(name))
        }
        Ty::List(inner) => format!("::std::vec::Vec<{}>", rust_ty(inner, prefix)),
        Ty::Array(inner, n) => format!("[{}; {n}]", rust_ty(inner, prefix)),
        Ty::Optional(inner) => format!("::core::option::Option<{}>", rust_ty(inner, prefix)),
        Ty::Unknown => "()".to_owned(),
    }
}

fn cool_type(ty: &ast::Type) -> String {
    match &ty.kind {
        TypeKind::Prim(p) => prim_cool(*p).to_owned(),
        TypeKind::Named(name) => name.name.clone(),
        TypeKind::List(inner) => format!("[{}]", cool_type(inner)),
        TypeKind::Array(inner, n) => format!("[{}; {}]", cool_type(inner), n.value),
        TypeKind::Optional(inner) => format!("{}?", cool_type(inner)),
    }
}

fn prim_cool(p: Prim) -> &'static str {
    match p {
        Prim::Bool => "bool",
        Prim::I8 => "i8",
        Prim::I16 => "i16",
        Prim::I32 => "i32",
        Prim::I64 => "i64",
        Prim::U8 => "u8",
        Prim::U16 => "u16",
        Prim::U32 => "u32",
        Prim::U64 => "u64",
        Prim::F32 => "f32",
        Prim::F64 => "f64",
        Prim::String => "String",
        Prim::Time => "Time",
        Prim::Duration => "Duration",
    }
}

fn prim_rust(p: Prim) -> &'static str {
    match p {
        Prim::String => "::std::string::String",
        Prim::Time => "::coolbot::Time",
        Prim::Duration => "::std::time::Duration",
        other => prim_cool(other),
    }
}

impl<'a> Lowerer<'a> {
    /// The resolved type of a written type, from the checked model.
    fn ty(&self, ty: &ast::Type) -> Ty {
        self.checked.ty(ty)
    }

    fn rust_type(&self, ty: &ast::Type, prefix: &str) -> String {
        rust_ty(&self.ty(ty), prefix)
    }

    /// Whether the emitted type has a default value ([`Self::default_of`]).
    fn defaultable(&self, ty: &ast::Type, visiting: &mut BTreeSet<String>) -> bool {
        self.default_of(&self.ty(ty), visiting).is_some()
    }

    /// Whether the emitted resolved type has a default value.
    fn ty_defaultable(&self, ty: &Ty) -> bool {
        self.default_of(ty, &mut BTreeSet::new()).is_some()
    }

    /// The Rust expression of the default value of the emitted type, or `None` when
    /// it has none (an extern packet, an empty enum, a packet holding one of those).
    /// Arrays longer than 32 elements, or of elements without `Default`, are built
    /// with `core::array::from_fn`: the standard library implements `Default` for
    /// arrays only up to 32 elements.
    fn default_of(&self, ty: &Ty, visiting: &mut BTreeSet<String>) -> Option<String> {
        match ty {
            Ty::Bool
            | Ty::Int(_)
            | Ty::Float(_)
            | Ty::Str
            | Ty::Time
            | Ty::Duration
            | Ty::List(_)
            | Ty::Optional(_) => Some(DEFAULT.to_owned()),
            Ty::Array(inner, n) => {
                let item = self.default_of(inner, visiting)?;
                Some(if *n <= 32 && item == DEFAULT {
                    DEFAULT.to_owned()
                } else {
                    format!("::core::array::from_fn(|_| {item})")
                })
            }
            Ty::Enum(name) | Ty::Packet(name) => match self.checked.type_def(name) {
                Some(TypeDef::Enum(e)) if !e.variants.is_empty() => Some(DEFAULT.to_owned()),
                Some(TypeDef::Packet(p)) if self.packet_defaultable(p, visiting) => {
                    Some(DEFAULT.to_owned())
                }
                _ => None,
            },
            Ty::Extern(_) | Ty::Unknown => None,
        }
    }

    /// The default value of `ty` as a user stub writes it (`Default::default()` when
    /// the type implements `Default`).
    fn stub_default(&self, ty: &ast::Type) -> Option<String> {
        let default = self.default_of(&self.ty(ty), &mut BTreeSet::new())?;
        Some(default.replace(DEFAULT, "Default::default()"))
    }

    fn packet_defaultable(&self, packet: &ast::Packet, visiting: &mut BTreeSet<String>) -> bool {
        if !visiting.insert(packet.name.name.clone()) {
            return false;
        }
        let result = packet
            .fields
            .iter()
            .all(|f| f.default.is_some() || self.defaultable(&f.ty, visiting));
        visiting.remove(&packet.name.name);
        result
    }

    /// The Rust expression of a field default: the written value, or the type's
    /// default.
    fn field_default(
        &self,
        field_ty: &ast::Type,
        value: Option<&ast::Expr>,
        prefix: &str,
    ) -> String {
        let field_ty = self.ty(field_ty);
        match value {
            Some(expr) => self.value(expr, Some(&field_ty), prefix),
            None => self
                .default_of(&field_ty, &mut BTreeSet::new())
                .unwrap_or_else(|| DEFAULT.to_owned()),
        }
    }

    /// A Rust expression for a constant `.cool` value of type `ty`.
    fn value(&self, expr: &ast::Expr, ty: Option<&Ty>, prefix: &str) -> String {
        if let Some(Ty::Optional(inner)) = ty {
            return match &expr.kind {
                ExprKind::None => "::core::option::Option::None".to_owned(),
                _ => format!(
                    "::core::option::Option::Some({})",
                    self.value(expr, Some(inner), prefix)
                ),
            };
        }
        match &expr.kind {
            ExprKind::Int(n) => match ty {
                Some(Ty::Float(_)) => format!("{n}.0"),
                Some(Ty::Duration) => duration_rust(*n),
                _ => n.to_string(),
            },
            ExprKind::Float(x) => format!("{x:?}"),
            ExprKind::Str(s) => {
                format!("::std::string::String::from({})", ident::string_literal(s))
            }
            ExprKind::Bool(b) => b.to_string(),
            ExprKind::Duration(_) | ExprKind::Frequency(_) => {
                duration_rust(duration_ns(expr).unwrap_or_default())
            }
            ExprKind::EnumValue { enum_name, variant } => {
                format!(
                    "{prefix}{}::{}",
                    ident::camel(&enum_name.name),
                    ident::camel(&variant.name)
                )
            }
            ExprKind::List(items) => {
                let inner = match ty {
                    Some(Ty::List(inner) | Ty::Array(inner, _)) => Some(&**inner),
                    _ => None,
                };
                let items: Vec<String> =
                    items.iter().map(|e| self.value(e, inner, prefix)).collect();
                match ty {
                    Some(Ty::Array(..)) => format!("[{}]", items.join(", ")),
                    _ => format!("::std::vec![{}]", items.join(", ")),
                }
            }
            ExprKind::Repeat(item, n) => {
                let inner = match ty {
                    Some(Ty::List(inner) | Ty::Array(inner, _)) => Some(&**inner),
                    _ => None,
                };
                let copy = inner.is_some_and(|t| self.is_copy(t));
                let item = self.value(item, inner, prefix);
                match ty {
                    Some(Ty::List(_)) => format!("::std::vec![{item}; {}]", n.value),
                    // `[value; n]` needs a `Copy` value.
                    _ if copy => format!("[{item}; {}]", n.value),
                    _ => format!("::core::array::from_fn(|_| {item})"),
                }
            }
            ExprKind::None => "::core::option::Option::None".to_owned(),
            ExprKind::Unary(ast::UnaryOp::Neg, inner) => {
                format!("-{}", self.value(inner, ty, prefix))
            }
            ExprKind::Unary(ast::UnaryOp::Not, inner) => {
                format!("!{}", self.value(inner, ty, prefix))
            }
            // Paths and comparisons are not constant values; the checker rejects them
            // as defaults.
            ExprKind::Path(_) | ExprKind::Binary(..) => {
                "::core::default::Default::default()".to_owned()
            }
        }
    }

    /// Whether values of the emitted type are `Copy` (so `[value; n]` compiles).
    fn is_copy(&self, ty: &Ty) -> bool {
        match ty {
            Ty::Bool | Ty::Int(_) | Ty::Float(_) | Ty::Time | Ty::Duration | Ty::Enum(_) => true,
            Ty::Optional(inner) | Ty::Array(inner, _) => self.is_copy(inner),
            Ty::Str | Ty::List(_) | Ty::Packet(_) | Ty::Extern(_) | Ty::Unknown => false,
        }
    }

    fn field(&self, field: &ast::Field, prefix: &str) -> ir::Field {
        ir::Field {
            doc: doc(&field.doc),
            name: ident::snake(&field.name.name),
            cool_name: field.name.name.clone(),
            ty: self.rust_type(&field.ty, prefix),
            default: self.field_default(&field.ty, field.default.as_ref(), prefix),
            serde_with: serde_adapter(&self.ty(&field.ty))
                .map(|adapter| format!("{SERDE_WITH}As::<{adapter}>")),
        }
    }

    fn lower_crate(&self, files: &[ast::File], options: &Options) -> ir::Crate {
        let mut types = ir::Types {
            module: "types".to_owned(),
            ..Default::default()
        };
        let mut atomics = Vec::new();
        let mut compounds = Vec::new();
        let mut dependencies: Vec<ir::Dependency> = Vec::new();
        let mut system_libs: Vec<String> = Vec::new();
        let mut seen_types = BTreeSet::new();
        let mut seen_components = BTreeSet::new();
        for item in files.iter().flat_map(|f| &f.items) {
            match item {
                ast::Item::Packet(p) if seen_types.insert(p.name.name.clone()) => {
                    types.packets.push(ir::Packet {
                        doc: doc(&p.doc),
                        name: ident::camel(&p.name.name),
                        fields: p.fields.iter().map(|f| self.field(f, "")).collect(),
                        has_default: self.packet_defaultable(p, &mut BTreeSet::new()),
                    });
                }
                ast::Item::Enum(e) if seen_types.insert(e.name.name.clone()) => {
                    types.enums.push(ir::Enum {
                        doc: doc(&e.doc),
                        name: ident::camel(&e.name.name),
                        variants: e
                            .variants
                            .iter()
                            .map(|v| ir::EnumVariant {
                                doc: doc(&v.doc),
                                name: ident::camel(&v.name.name),
                                cool_name: v.name.name.clone(),
                            })
                            .collect(),
                    });
                }
                ast::Item::ExternPacket(e) if seen_types.insert(e.name.name.clone()) => {
                    types.externs.push(ir::Extern {
                        doc: doc(&e.doc),
                        name: ident::camel(&e.name.name),
                        path: e.rust_path.value.clone(),
                    });
                }
                ast::Item::Converter(c) => {
                    if types.converters.iter().any(|x| x.cool_name == c.name.name) {
                        continue;
                    }
                    let method = ident::snake(&c.name.name);
                    let stub_body = if let Some(default) = self.stub_default(&c.to) {
                        format!(
                            "// Converter `{}`: build the output packet from `from`.\n\
                             let _ = from;\n\
                             {default}",
                            c.name.name
                        )
                    } else {
                        format!(
                            "let _ = from;\n\
                             panic!({})",
                            ident::string_literal(&format!(
                                "converter `{}` is not written yet: fill in `{}` in src/converters.rs",
                                c.name.name, method
                            ))
                        )
                    };
                    types.converters.push(ir::Converter {
                        doc: doc(&c.doc),
                        cool_name: c.name.name.clone(),
                        method,
                        from: self.rust_type(&c.from, ""),
                        to: self.rust_type(&c.to, ""),
                        user_from: self.rust_type(&c.from, USER_TYPES),
                        user_to: self.rust_type(&c.to, USER_TYPES),
                        stub_body,
                    });
                }
                ast::Item::Component(c) if seen_components.insert(c.name.name.clone()) => {
                    for member in &c.members {
                        if let ast::Member::Link(link) = member {
                            match &link.kind {
                                ast::LinkKind::Crate { name, spec } => {
                                    // The runtime dependency is coolc's to write.
                                    let key = toml_key(&name.value);
                                    if key != "coolbot"
                                        && !dependencies.iter().any(|d| d.key == key)
                                    {
                                        dependencies.push(ir::Dependency {
                                            key,
                                            value: crate_spec(spec),
                                        });
                                    }
                                }
                                ast::LinkKind::System { name } => {
                                    if !system_libs.contains(&name.value) {
                                        system_libs.push(name.value.clone());
                                    }
                                }
                            }
                        }
                    }
                    let module = self.modules[c.name.name.as_str()].clone();
                    match c.kind {
                        ast::ComponentKind::Atomic => atomics.push(self.atomic(c, module)),
                        ast::ComponentKind::Compound => compounds.push(self.compound(c, module)),
                    }
                }
                _ => {}
            }
        }
        let package = package_name(&options.package);
        ir::Crate {
            lib_name: package.replace('-', "_"),
            package,
            runtime: options.runtime.clone(),
            dependencies,
            system_libs,
            sources: options.sources.clone(),
            inputs: options.inputs.clone(),
            types,
            atomics,
            compounds,
        }
    }

    fn atomic(&self, c: &'a ast::Component, module: String) -> ir::Atomic {
        let mut config = Vec::new();
        let mut vars = Vec::new();
        let mut inputs: Vec<(&ast::Input, ir::Port)> = Vec::new();
        let mut outputs: Vec<(&ast::Output, ir::Port)> = Vec::new();
        let mut timing = None;
        let mut exceptions_ast = Vec::new();
        let mut automaton = None;
        let mut spec_index = 0;
        for member in &c.members {
            match member {
                ast::Member::Configuration(cfg) => {
                    config.extend(cfg.fields.iter().map(|f| self.field(f, GEN_TYPES)));
                }
                ast::Member::Variable(v) => {
                    if let Some(var) = self.variable(v, &mut spec_index, "self.vars") {
                        vars.push(var);
                    }
                }
                ast::Member::Input(input) => {
                    if let Some(port) = self.input(input) {
                        inputs.push((input, port));
                    }
                }
                ast::Member::Output(output) => {
                    if let Some(port) = self.output(output) {
                        outputs.push((output, port));
                    }
                }
                ast::Member::Timing(t) => {
                    timing.get_or_insert(t);
                }
                ast::Member::Exception(e) => exceptions_ast.push(e),
                ast::Member::Automaton(a) => {
                    automaton.get_or_insert(a);
                }
                _ => {}
            }
        }
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
            inputs
                .iter()
                .position(|(i, _)| i.name.name == name)
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
                            option_duration(period.as_ref())
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
                    ast::StateMember::May { targets, .. } => {
                        may_targets(targets, &state_index, &mut may);
                    }
                    ast::StateMember::When { .. } => {}
                }
            }
            let variant = ident::camel(name);
            let may_enum = (!may.is_empty()).then(|| format!("{}May", ident::camel_raw(name)));
            section_stubs(
                &StateSections {
                    index,
                    name,
                    entry,
                    periodic: periodic.is_some(),
                    exit,
                    docs: SectionDocs::of(state),
                },
                SectionOwner::Atomic,
                &mut methods,
                &mut section_arms,
            );
            if let Some(may_enum) = &may_enum {
                choose_stub(
                    index,
                    name,
                    may_enum,
                    &may,
                    &SectionDocs::of(state).may,
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
                variant,
                may_enum,
                may,
                spec,
            });
        }

        let mut exceptions = Vec::new();
        for e in exceptions_ast {
            let name = &e.name.name;
            let handler = unique(ident::method("on_", name, ""), &methods);
            let plan: Vec<String> = e
                .plan
                .iter()
                .map(|step| match &step.kind {
                    ast::PlanKind::Retry { count, every } => format!(
                        "::coolbot::PlanStep::Retry {{ count: {}, every: {} }}",
                        u32::try_from(count.value).unwrap_or(u32::MAX),
                        duration_rust(duration_ns(every).unwrap_or_default())
                    ),
                    ast::PlanKind::Goto(target) => {
                        format!("::coolbot::PlanStep::Goto({})", state_index(&target.name))
                    }
                    ast::PlanKind::Ignore => "::coolbot::PlanStep::Ignore".to_owned(),
                    ast::PlanKind::Degrade => "::coolbot::PlanStep::Degrade".to_owned(),
                })
                .collect();
            let description = e
                .description
                .as_ref()
                .map(|d| d.value.as_str())
                .unwrap_or("");
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
                doc: doc(&e.doc),
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
            if output.pull.is_none() {
                continue;
            }
            let (ty, send) = match &output.def {
                ast::OutputDef::Data(ty) => (ty, "send"),
                ast::OutputDef::Poster(ty) => (ty, "post"),
                ast::OutputDef::Tick | ast::OutputDef::Export(_) => continue,
            };
            let method = unique(ident::method("answer_", &output.name.name, ""), &methods);
            let name = &output.name.name;
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
                    self.rust_type(ty, GEN_TYPES)
                ),
                user_signature: format!(
                    "fn {method}(&mut self, cx: &mut Cx<'_>) -> Result<{}, coolbot::Fault>",
                    self.rust_type(ty, USER_TYPES)
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
            doc: doc(&c.doc),
            notes: ir::notes(&c.notes),
            type_name: c.name.name.clone(),
            user_struct: ident::camel(&c.name.name),
            module,
            config,
            vars,
            inputs: inputs.into_iter().map(|(_, p)| p).collect(),
            outputs: outputs.into_iter().map(|(_, p)| p).collect(),
            states,
            initial,
            exceptions,
            timing: self.timing(timing),
            adaptation: self
                .checked
                .interface(&c.name.name)
                .and_then(|interface| adaptation::written_fields(&interface.adaptation)),
            methods,
            section_arms,
            choose_arms,
            answer_arms,
        }
    }

    /// A declared variable (`observable`/`controllable`/`local` with a type) as a
    /// `Vars` field; `receiver` is the Rust expression holding the `Vars` in the glue
    /// (`self.vars`). Observable and controllable ones take the next `spec_index`.
    fn variable(
        &self,
        v: &ast::Variable,
        spec_index: &mut usize,
        receiver: &str,
    ) -> Option<ir::Var> {
        let ty = v.ty.as_ref()?;
        let default = if v.value.is_none() && !self.defaultable(ty, &mut BTreeSet::new()) {
            // No default and no `Default`: the variable has no value
            // until set.
            None
        } else {
            Some(self.field_default(ty, v.value.as_ref(), GEN_TYPES))
        };
        let (rust_ty, default_expr) = match default.clone() {
            Some(d) => (self.rust_type(ty, GEN_TYPES), d),
            None => (
                format!("::core::option::Option<{}>", self.rust_type(ty, GEN_TYPES)),
                "::core::option::Option::None".to_owned(),
            ),
        };
        let has_default = default.is_some();
        let kind = match v.kind {
            ast::VarKind::Observable => "Observable",
            ast::VarKind::Controllable => "Controllable",
            ast::VarKind::Local => "Local",
        };
        let index = (v.kind != ast::VarKind::Local).then(|| {
            *spec_index += 1;
            *spec_index - 1
        });
        let field = ident::snake(&v.name.name);
        // A type holding an array longer than 32 elements goes through its serde_with
        // adapter (wrapped in `Option` like the field when it has no default).
        let adapter = serde_adapter(&self.ty(ty)).map(|adapter| {
            if has_default {
                adapter
            } else {
                format!("::core::option::Option<{adapter}>")
            }
        });
        let (to_value, from_value) = match (&adapter, &ty.kind) {
            (Some(adapter), _) => (
                format!(
                    "super::__cool_to_value(&{SERDE_WITH}ser::SerializeAsWrap::<{rust_ty}, {adapter}>::new(&{receiver}.{field}))"
                ),
                format!(
                    "super::__cool_from_value::<{SERDE_WITH}de::DeserializeAsWrap<{rust_ty}, {adapter}>>(value).map({SERDE_WITH}de::DeserializeAsWrap::into_inner)"
                ),
            ),
            (None, TypeKind::Prim(p)) if has_default => (
                if *p == Prim::String {
                    format!("::coolbot::Value::from({receiver}.{field}.clone())")
                } else {
                    format!("::coolbot::Value::from({receiver}.{field})")
                },
                format!(
                    "<{}>::try_from(value).map_err(|error| error.to_string())",
                    prim_rust(*p)
                ),
            ),
            _ => (
                format!("super::__cool_to_value(&{receiver}.{field})"),
                "super::__cool_from_value(value)".to_owned(),
            ),
        };
        Some(ir::Var {
            to_value,
            from_value,
            field: ir::Field {
                doc: doc(&v.doc),
                name: ident::snake(&v.name.name),
                cool_name: v.name.name.clone(),
                ty: rust_ty,
                default: default_expr,
                serde_with: None,
            },
            kind: kind.to_owned(),
            spec_index: index,
            cool_ty: cool_type(ty),
        })
    }

    fn timing(&self, timing: Option<&ast::Timing>) -> String {
        let (mut period, mut max_period, mut max_response, mut priority) = (None, None, None, 0i64);
        let mut qualities = Vec::new();
        for entry in timing.map(|t| t.entries.as_slice()).unwrap_or_default() {
            match entry {
                ast::TimingEntry::Period(interval) => {
                    period = duration_ns(&interval.lo);
                    max_period = interval.hi.as_ref().and_then(duration_ns);
                }
                ast::TimingEntry::MaxResponse(e) => max_response = duration_ns(e),
                ast::TimingEntry::Priority(e) => priority = int_value(e).unwrap_or(0),
                ast::TimingEntry::Quality(names, _) => {
                    qualities = names
                        .iter()
                        .map(|n| ident::string_literal(&n.name))
                        .collect();
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
            priority.clamp(i32::MIN.into(), i32::MAX.into()),
            qualities.join(", ")
        )
    }

    fn packet_type(&self, ty: &ast::Type) -> (String, String) {
        (self.rust_type(ty, GEN_TYPES), cool_type(ty))
    }

    fn input(&self, input: &ast::Input) -> Option<ir::Port> {
        let field = ident::snake(&input.name.name);
        let (handle, ctor, kind, packet) = match &input.def {
            ast::InputDef::Tick => (
                "::coolbot::port::TickIn".to_owned(),
                "::coolbot::port::TickIn::new()".to_owned(),
                "::coolbot::InputKind::Tick".to_owned(),
                String::new(),
            ),
            ast::InputDef::Fifo { ty, size, policy } => {
                let (rust, cool) = self.packet_type(ty);
                let policy = match policy.as_ref().map(|p| p.name.as_str()) {
                    Some("drop_oldest") => "DropOldest",
                    Some("block") => "Block",
                    _ => "Reject",
                };
                (
                    format!("::coolbot::port::FifoIn<{rust}>"),
                    format!(
                        "::coolbot::port::FifoIn::new({}, ::coolbot::OverflowPolicy::{policy})",
                        size.value
                    ),
                    format!(
                        "::coolbot::InputKind::Fifo {{ capacity: {}, policy: ::coolbot::OverflowPolicy::{policy} }}",
                        size.value
                    ),
                    cool,
                )
            }
            ast::InputDef::Ufifo { size, ty, max } => {
                let (rust, cool) = self.packet_type(ty);
                let max = match max {
                    Some(m) => format!("Some({})", m.value),
                    None => "None".to_owned(),
                };
                (
                    format!("::coolbot::port::UfifoIn<{rust}>"),
                    format!("::coolbot::port::UfifoIn::new({}, {max})", size.value),
                    format!(
                        "::coolbot::InputKind::Ufifo {{ initial: {}, max: {max} }}",
                        size.value
                    ),
                    cool,
                )
            }
            ast::InputDef::Last(ty) => {
                let (rust, cool) = self.packet_type(ty);
                (
                    format!("::coolbot::port::LastIn<{rust}>"),
                    "::coolbot::port::LastIn::new()".to_owned(),
                    "::coolbot::InputKind::Last".to_owned(),
                    cool,
                )
            }
            ast::InputDef::Poster(ty) => {
                let (rust, cool) = self.packet_type(ty);
                (
                    format!("::coolbot::port::PosterIn<{rust}>"),
                    "::coolbot::port::PosterIn::new()".to_owned(),
                    "::coolbot::InputKind::Poster".to_owned(),
                    cool,
                )
            }
            ast::InputDef::Export(_) => return None,
        };
        Some(ir::Port {
            doc: doc(&input.doc),
            cool_name: input.name.name.clone(),
            field,
            handle,
            ctor,
            kind,
            packet,
            pull: input.pull.is_some(),
        })
    }

    fn output(&self, output: &ast::Output) -> Option<ir::Port> {
        let field = ident::snake(&output.name.name);
        let (handle, ctor, kind, packet) = match &output.def {
            ast::OutputDef::Tick => (
                "::coolbot::port::TickOut".to_owned(),
                "::coolbot::port::TickOut::new()".to_owned(),
                "::coolbot::OutputKind::Tick".to_owned(),
                String::new(),
            ),
            ast::OutputDef::Data(ty) => {
                let (rust, cool) = self.packet_type(ty);
                (
                    format!("::coolbot::port::DataOut<{rust}>"),
                    "::coolbot::port::DataOut::new()".to_owned(),
                    "::coolbot::OutputKind::Data".to_owned(),
                    cool,
                )
            }
            ast::OutputDef::Poster(ty) => {
                let (rust, cool) = self.packet_type(ty);
                (
                    format!("::coolbot::port::PosterOut<{rust}>"),
                    "::coolbot::port::PosterOut::new()".to_owned(),
                    "::coolbot::OutputKind::Poster".to_owned(),
                    cool,
                )
            }
            ast::OutputDef::Export(_) => return None,
        };
        Some(ir::Port {
            doc: doc(&output.doc),
            cool_name: output.name.name.clone(),
            field,
            handle,
            ctor,
            kind,
            packet,
            pull: output.pull.is_some(),
        })
    }
}

/// `name`, or `name_2`, `name_3`... when a method of that name exists (a state `on`
/// with an exit section and an exception `exit` would both want `on_exit`).
fn unique(name: String, methods: &[ir::Method]) -> String {
    unique_among(name, methods.iter().map(|m| m.name.as_str()))
}

/// `name`, or `name_2`, `name_3`... when `taken` holds it.
fn unique_among<'t>(name: String, taken: impl Iterator<Item = &'t str> + Clone) -> String {
    let taken = |candidate: &str| taken.clone().any(|t| t == candidate);
    if !taken(&name) {
        return name;
    }
    (2..)
        .map(|n| format!("{name}_{n}"))
        .find(|c| !taken(c))
        .unwrap_or(name)
}

impl Lowerer<'_> {
    /// An instance's overrides of configuration fields (`config`) or controllable
    /// variables (`!config`), as `(field, Rust value)`: a name that is both sets both.
    /// A compound's own controllable variables count; its mapped ones do not (they
    /// have no `Vars` field).
    fn overrides(&self, instance: &ast::Instance, config: bool) -> Vec<(String, String)> {
        let Some((_, component)) = self.checked.ast_component(&instance.component.name) else {
            return Vec::new();
        };
        let mut overrides = Vec::new();
        for o in &instance.overrides {
            for member in &component.members {
                match member {
                    ast::Member::Configuration(cfg) if config => {
                        for f in cfg.fields.iter().filter(|f| f.name.name == o.name.name) {
                            overrides.push((
                                ident::snake(&f.name.name),
                                self.value(&o.value, Some(&self.ty(&f.ty)), GEN_TYPES),
                            ));
                        }
                    }
                    ast::Member::Variable(v)
                        if !config
                            && v.kind == ast::VarKind::Controllable
                            && v.name.name == o.name.name =>
                    {
                        if let Some(ty) = &v.ty {
                            overrides.push((
                                ident::snake(&v.name.name),
                                self.value(&o.value, Some(&self.ty(ty)), GEN_TYPES),
                            ));
                        }
                    }
                    _ => {}
                }
            }
        }
        overrides
    }
}

fn int_value(expr: &ast::Expr) -> Option<i64> {
    match &expr.kind {
        ExprKind::Int(n) => i64::try_from(*n).ok(),
        ExprKind::Unary(ast::UnaryOp::Neg, inner) => int_value(inner).map(|n| -n),
        _ => None,
    }
}

/// A TOML key: bare when possible, quoted otherwise.
fn toml_key(name: &str) -> String {
    if !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    {
        name.to_owned()
    } else {
        ir::toml_string(name)
    }
}

fn toml_value(expr: &ast::Expr) -> String {
    match &expr.kind {
        ExprKind::Str(s) => ir::toml_string(s),
        ExprKind::Bool(b) => b.to_string(),
        ExprKind::Int(n) => n.to_string(),
        ExprKind::Float(x) => format!("{x:?}"),
        ExprKind::List(items) => {
            format!(
                "[{}]",
                items.iter().map(toml_value).collect::<Vec<_>>().join(", ")
            )
        }
        ExprKind::Path(parts) => ir::toml_string(
            &parts
                .iter()
                .map(|p| p.name.as_str())
                .collect::<Vec<_>>()
                .join("."),
        ),
        _ => "\"\"".to_owned(),
    }
}

fn crate_spec(spec: &ast::CrateSpec) -> String {
    match spec {
        ast::CrateSpec::Version(v) => ir::toml_string(&v.value),
        ast::CrateSpec::Table(entries, _) => {
            let entries: Vec<String> = entries
                .iter()
                .map(|e| {
                    // `.cool` names cannot hold `-`: Cargo's `default-features` is
                    // written `default_features`, which edition 2024 rejects as is.
                    let key = match e.key.name.as_str() {
                        "default_features" => "default-features",
                        other => other,
                    };
                    format!("{} = {}", toml_key(key), toml_value(&e.value))
                })
                .collect();
            format!("{{ {} }}", entries.join(", "))
        }
    }
}

/// Adds `may` targets `targets` (by name; `state_index` gives their index) to `may`
/// as `(variant, index, name)`, each once.
pub(crate) fn may_targets(
    targets: &[ast::Ident],
    state_index: &dyn Fn(&str) -> usize,
    may: &mut Vec<(String, usize, String)>,
) {
    for target in targets {
        if !may.iter().any(|(_, _, n)| *n == target.name) {
            may.push((
                ident::camel(&target.name),
                state_index(&target.name),
                target.name.clone(),
            ));
        }
    }
}

/// The `<state>_choose` stub of state `name` (index `index`) whose `may` targets are
/// `may`, returning `Option<may_enum>`, and its glue arm.
pub(crate) fn choose_stub(
    index: usize,
    name: &str,
    may_enum: &str,
    may: &[(String, usize, String)],
    written: &[String],
    methods: &mut Vec<ir::Method>,
    choose_arms: &mut Vec<ir::ChooseArm>,
) {
    let method = ident::method("", name, "_choose");
    let targets: Vec<String> = may.iter().map(|(_, _, n)| format!("`{n}`")).collect();
    methods.push(ir::Method {
        name: method.clone(),
        doc: with_written(
            format!(
                "Called after each section of state `{name}`: return a target ({}) to move there, or `None` to stay.",
                targets.join(", ")
            ),
            written,
        ),
        signature: format!(
            "fn {method}(&mut self, cx: &mut Cx<'_>) -> ::core::option::Option<{may_enum}>"
        ),
        user_signature: format!("fn {method}(&mut self, cx: &mut Cx<'_>) -> Option<{may_enum}>"),
        stub_body: vec![
            format!("// State `{name}`: return Some({may_enum}::...) to leave it."),
            "let _ = cx;".to_owned(),
            "None".to_owned(),
        ],
    });
    choose_arms.push(ir::ChooseArm {
        state: index,
        method,
        may_enum: may_enum.to_owned(),
        targets: may.iter().map(|(v, i, _)| (v.clone(), *i)).collect(),
    });
}

/// Whose user automaton a state belongs to: the wording of its stubs and the receiver
/// the glue calls them on.
#[derive(Clone, Copy)]
pub(crate) enum SectionOwner {
    /// An atomic component's `Behavior` (`behavior.<state>_<section>`).
    Atomic,
    /// A compound's `Supervisor` (`supervisor.<state>_<section>`).
    Supervisor,
}

/// The sections one state declares.
pub(crate) struct StateSections<'a> {
    /// The state's index in `SPEC.states`.
    pub(crate) index: usize,
    /// The state's name.
    pub(crate) name: &'a str,
    pub(crate) entry: bool,
    pub(crate) periodic: bool,
    pub(crate) exit: bool,
    /// The doc comments written on the state's sections and `may` rules.
    pub(crate) docs: SectionDocs,
}

/// The doc comments on a state's sections and `may` rules: they document the trait
/// methods generated for them.
#[derive(Default)]
pub(crate) struct SectionDocs {
    pub(crate) entry: Vec<String>,
    pub(crate) periodic: Vec<String>,
    pub(crate) exit: Vec<String>,
    pub(crate) may: Vec<String>,
}

impl SectionDocs {
    /// The doc comments of `state`'s sections and `may` rules.
    pub(crate) fn of(state: &ast::State) -> SectionDocs {
        let mut docs = SectionDocs::default();
        for (member, doc) in state.members.iter().zip(&state.member_docs) {
            let lines = match member {
                ast::StateMember::Entry(_) => &mut docs.entry,
                ast::StateMember::Periodic { .. } => &mut docs.periodic,
                ast::StateMember::Exit(_) => &mut docs.exit,
                ast::StateMember::May { .. } => &mut docs.may,
                _ => continue,
            };
            lines.extend(doc.0.iter().cloned());
        }
        docs
    }
}

/// `first`, then (after an empty line) the written doc comment `written`, if any.
fn with_written(first: String, written: &[String]) -> Vec<String> {
    let mut lines = vec![first];
    if !written.is_empty() {
        lines.push(String::new());
        lines.extend(written.iter().cloned());
    }
    lines
}

/// One required stub and one glue arm per declared section of a state, in the order
/// entry, periodic, exit.
pub(crate) fn section_stubs(
    state: &StateSections<'_>,
    owner: SectionOwner,
    methods: &mut Vec<ir::Method>,
    section_arms: &mut Vec<(String, String)>,
) {
    let (subject, of_state, comment_state, receiver) = match owner {
        SectionOwner::Atomic => ("automaton", "state", "State", "behavior"),
        SectionOwner::Supervisor => (
            "supervisor",
            "supervisor state",
            "Supervisor state",
            "supervisor",
        ),
    };
    let name = state.name;
    let kinds = [
        (
            state.entry,
            "entry",
            "Entry",
            format!("runs once each time the {subject} enters the state"),
            &state.docs.entry,
        ),
        (
            state.periodic,
            "periodic",
            "Periodic",
            "runs once per period while in the state".to_owned(),
            &state.docs.periodic,
        ),
        (
            state.exit,
            "exit",
            "Exit",
            format!("runs once each time the {subject} leaves the state"),
            &state.docs.exit,
        ),
    ];
    for (present, suffix, section, when, written) in kinds {
        if !present {
            continue;
        }
        let method = ident::method("", name, &format!("_{suffix}"));
        methods.push(ir::Method {
            name: method.clone(),
            doc: with_written(
                format!("The {suffix} section of {of_state} `{name}`: {when}."),
                written,
            ),
            signature: format!(
                "fn {method}(&mut self, cx: &mut Cx<'_>) -> ::coolbot::SectionResult"
            ),
            user_signature: format!(
                "fn {method}(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult"
            ),
            stub_body: vec![
                format!("// {comment_state} `{name}`, {suffix} section: {when}."),
                "let _ = cx;".to_owned(),
                "Ok(())".to_owned(),
            ],
        });
        section_arms.push((
            format!("({}, ::coolbot::Section::{section})", state.index),
            format!("{receiver}.{method}(&mut cx)"),
        ));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lower_text(text: &str) -> ir::Crate {
        let checked = crate::analyze_text("t.cool", text)
            .checked()
            .unwrap_or_else(|analysis| {
                panic!("{}", analysis.render(crate::RenderOptions::plain()))
            });
        lower(&checked, &Options::default())
    }

    #[test]
    fn link_crate_tables_become_cargo_tables() {
        let krate = lower_text(
            "atomic A { link crate \"serde_json\" = { version = \"1\", default_features = false, features = [\"std\"] }; link crate \"coolbot\" = \"9\"; link system \"m\"; }",
        );
        assert_eq!(
            krate.dependencies,
            [ir::Dependency {
                key: "serde_json".to_owned(),
                value: "{ version = \"1\", default-features = false, features = [\"std\"] }"
                    .to_owned(),
            }]
        );
        assert_eq!(krate.system_libs, ["m"]);
        assert_eq!(ir::toml_string("a\"b\\c"), "\"a\\\"b\\\\c\"");
    }

    #[test]
    fn colliding_method_names_get_a_suffix() {
        let krate = lower_text(
            "atomic A { exception exit; automaton { initial on; state on { entry; exit; } } }",
        );
        let names: Vec<&str> = krate.atomics[0]
            .methods
            .iter()
            .map(|m| m.name.as_str())
            .collect();
        assert_eq!(names, ["on_entry", "on_exit", "on_exit_2"]);
    }

    /// Lowers text whose only errors are Rust keywords used as names (the checker
    /// rejects them; lowering escapes them anyway, as defence in depth).
    fn lower_keywords(text: &str) -> ir::Crate {
        let analysis = crate::analyze_text("t.cool", text);
        let codes: Vec<&str> = analysis
            .diagnostics
            .iter()
            .map(|d| d.code.as_str())
            .collect();
        assert!(
            codes.iter().all(|c| *c == "coolc::check::rust_keyword"),
            "{codes:?}"
        );
        lower(&analysis.assume_checked(), &Options::default())
    }

    #[test]
    fn keywords_and_casing_become_rust_names() {
        let krate = lower_keywords(
            "packet P { type: u8 }\natomic Loop { observable match: u8 = 1; automaton { initial move; state move { entry; } } }",
        );
        let packet = &krate.types.packets[0];
        assert_eq!(packet.fields[0].name, "r#type");
        assert!(!packet.fields[0].renamed());
        let atomic = &krate.atomics[0];
        assert_eq!(atomic.module, "r#loop");
        assert_eq!(atomic.states[0].variant, "Move");
        assert_eq!(atomic.methods[0].name, "move_entry");
    }

    #[test]
    fn defaults_follow_the_declared_type() {
        let krate = lower_text(
            "packet P { a: f64 = 1.5, b: Duration = 10ms, c: [bool; 2] = [true; 2], d: u8? = 3, e: [u8] = [1, 2] }",
        );
        let defaults: Vec<&str> = krate.types.packets[0]
            .fields
            .iter()
            .map(|f| f.default.as_str())
            .collect();
        assert_eq!(
            defaults,
            [
                "1.5",
                "::std::time::Duration::from_nanos(10000000)",
                "[true; 2]",
                "::core::option::Option::Some(3)",
                "::std::vec![1, 2]"
            ]
        );
    }

    #[test]
    fn rust_keywords_as_names_emit_valid_rust() {
        // The checker rejects Rust keywords as names (`coolc::check::rust_keyword`);
        // lowering escapes them anyway, as defence in depth. Every emitted Rust file is
        // parsed by `syn` while emitting: a keyword that is not escaped would panic here.
        let analysis = crate::analyze_text(
            "k.cool",
            "packet Self { type: u8, loop: bool = true }\n\
             enum Kind { Self, Fn }\n\
             atomic Loop {\n\
                 configuration { use: u8 = 1; }\n\
                 observable match: Self;\n\
                 controllable move: u8 = 2;\n\
                 input in: fifo<Self>(2);\n\
                 output ref: data<Kind> pull;\n\
                 exception break;\n\
                 automaton { initial self; state self { entry; may -> super; } state super { periodic 10ms; } }\n\
             }\n",
        );
        let codes: Vec<&str> = analysis
            .diagnostics
            .iter()
            .map(|d| d.code.as_str())
            .collect();
        assert!(
            codes.iter().all(|c| *c == "coolc::check::rust_keyword"),
            "{codes:?}"
        );
        let krate = lower(&analysis.assume_checked(), &Options::default());
        let files = crate::emit::emit_crate(&krate);
        let module = files
            .iter()
            .find(|f| f.path == std::path::Path::new("src/generated/loop.rs"))
            .expect("module file named after the component");
        assert!(
            module
                .contents
                .contains("pub r#match: super::types::Self_,"),
            "{}",
            module.contents
        );
        assert!(module.contents.contains("fn self_entry"));
        assert!(module.contents.contains("fn on_break"));
    }
}
