//! Lowering: a checked model to the IR the templates print.
//!
//! Lowering takes a [`Checked`] model, which exists only when the checker found no
//! error, and looks every name up in it (types, components, interfaces, typed rules).
//! Everything is lowered from the resolved model alone (`crate::checked::model`):
//! types and converters here, atomic components in `atomic`, compounds in `compound`.
//! Values come evaluated in the model; only `when` conditions are compiled here from
//! their written form and typed tree (`compound/rules.rs`).
//! It never fails: a lookup that finds nothing (impossible in a checked model) lowers
//! to something harmless (index 0, the type `()`), never a panic.

use std::collections::{BTreeMap, BTreeSet};

use crate::checked::Checked;
use crate::checked::model::{
    ComponentKind, CrateSpec, DefaultFrom, Duration, Instance, Link, Packet, Prim, TableValue, Ty,
    TypeDef, Value, VarKind,
};
use crate::ident;
use crate::ir::{self, RuntimeDep};
use crate::par::par_map;

mod adaptation;
mod atomic;
mod automaton;
mod compound;
pub(crate) mod harness;
mod ros;
mod starter;

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
const DEFAULT: &str = "::core::default::Default::default";

/// [`DEFAULT`] called.
fn default_code() -> ir::Code {
    ir::Code::call(DEFAULT, Vec::new())
}

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
    // Module names in source order; names coolc uses itself are taken, and so are the
    // names of the crate's root files (`src/lib.rs`, `src/main.rs`) and `mod` (the
    // name of a directory module's file).
    let mut taken: BTreeSet<String> = [
        "types",
        "support",
        "converters",
        "generated",
        "lib",
        "main",
        "mod",
    ]
    .map(str::to_owned)
    .into_iter()
    .collect();
    for c in checked.components() {
        let mut module = ident::snake_raw(&c.name);
        while !taken.insert(module.clone()) {
            module.push_str("_component");
        }
        lowerer.modules.insert(&c.name, ident::escape(&module));
    }
    lowerer.lower_crate(options)
}

/// A Cargo package name made from `name` (lowercase, `-` separated).
pub(crate) fn package_name(name: &str) -> String {
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

/// `::std::time::Duration::from_nanos(ns)`.
fn duration_code(ns: u64) -> ir::Code {
    ir::Code::call(
        "::std::time::Duration::from_nanos",
        vec![ir::Code::atom(ns.to_string())],
    )
}

/// `::core::array::from_fn(|_| item)`.
fn array_from_fn(item: ir::Code) -> ir::Code {
    ir::Code::call("::core::array::from_fn", vec![ir::Code::closure("_", item)])
}

fn option_duration(duration: Option<&Duration>) -> ir::Code {
    ir::Code::option(duration.map(|duration| duration_code(duration.nanos)))
}

/// The path of the serde_with crate as generated code sees it (re-exported by the
/// runtime).
const SERDE_WITH: &str = "::coolbot::serde_with::";

/// The serde_with adapter type of `ty` when it holds an array longer than 32
/// elements, directly or in lists, optionals and arrays (serde's own impls stop at 32):
/// `[Same; 72]`, `Option<[[Same; 40]; 2]>`.
fn serde_adapter(ty: &Ty) -> Option<String> {
    adapter(ty, false)
}

/// The serde_with adapter of a packet or configuration field of type `ty`: as
/// [`serde_adapter`], and a list of `u8` (`[u8]`, an image's pixels) serialized as
/// one slice of bytes (`Bytes`) rather than byte by byte. Every encoding the runtime
/// uses writes both alike (postcard and CDR a length and the bytes, JSON an array of
/// numbers), so only the speed changes: a 4 MiB image is one copy, not four million
/// calls.
fn field_adapter(ty: &Ty) -> Option<String> {
    adapter(ty, true)
}

/// `ty`'s adapter when it needs one: arrays longer than 32 elements, and with `bytes`
/// lists of `u8`.
fn adapter(ty: &Ty, bytes: bool) -> Option<String> {
    let is_bytes = |inner: &Ty| bytes && *inner == Ty::Int(Prim::U8);
    fn needs(ty: &Ty, is_bytes: &dyn Fn(&Ty) -> bool) -> bool {
        match ty {
            Ty::List(inner) => is_bytes(inner) || needs(inner, is_bytes),
            Ty::Optional(inner) => needs(inner, is_bytes),
            Ty::Array(inner, n) => *n > 32 || needs(inner, is_bytes),
            _ => false,
        }
    }
    fn walk(ty: &Ty, is_bytes: &dyn Fn(&Ty) -> bool) -> String {
        match ty {
            Ty::List(inner) if is_bytes(inner) => format!("{SERDE_WITH}Bytes"),
            Ty::List(inner) => format!("::std::vec::Vec<{}>", walk(inner, is_bytes)),
            Ty::Array(inner, n) => format!("[{}; {n}]", walk(inner, is_bytes)),
            Ty::Optional(inner) => format!("::core::option::Option<{}>", walk(inner, is_bytes)),
            _ => format!("{SERDE_WITH}Same"),
        }
    }
    needs(ty, &is_bytes).then(|| walk(ty, &is_bytes))
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
        Ty::Packet(name) | Ty::Enum(name) | Ty::Extern(name) | Ty::Ros { name, .. } => {
            format!("{prefix}{}", ident::camel(name))
        }
        Ty::List(inner) => format!("::std::vec::Vec<{}>", rust_ty(inner, prefix)),
        Ty::Array(inner, n) => format!("[{}; {n}]", rust_ty(inner, prefix)),
        Ty::Optional(inner) => format!("::core::option::Option<{}>", rust_ty(inner, prefix)),
        Ty::Unknown => "()".to_owned(),
    }
}

/// The primitive a resolved type is, if it is one.
fn prim_of(ty: &Ty) -> Option<Prim> {
    match ty {
        Ty::Bool => Some(Prim::Bool),
        Ty::Int(p) | Ty::Float(p) => Some(*p),
        Ty::Str => Some(Prim::String),
        Ty::Time => Some(Prim::Time),
        Ty::Duration => Some(Prim::Duration),
        _ => None,
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
    /// Whether the emitted resolved type has a default value.
    fn ty_defaultable(&self, ty: &Ty) -> bool {
        self.default_of(ty).is_some()
    }

    /// The Rust expression of the default value of the emitted type, or `None` when
    /// it has none (an extern packet, an empty enum, a packet holding one of those).
    /// Arrays longer than 32 elements, or of elements without `Default`, are built
    /// with `core::array::from_fn`: the standard library implements `Default` for
    /// arrays only up to 32 elements.
    fn default_of(&self, ty: &Ty) -> Option<ir::Code> {
        match ty.default_from() {
            DefaultFrom::Always => Some(default_code()),
            DefaultFrom::Elements(inner, n) => {
                let item = self.default_of(inner)?;
                Some(if n <= 32 && item == default_code() {
                    default_code()
                } else {
                    array_from_fn(item)
                })
            }
            DefaultFrom::Definition(name) => match self.checked.type_def(name) {
                Some(TypeDef::Enum(e)) if !e.variants.is_empty() => Some(default_code()),
                Some(TypeDef::Packet(p)) if self.packet_defaultable(p) => Some(default_code()),
                _ => None,
            },
            DefaultFrom::Never | DefaultFrom::Unknown => None,
        }
    }

    /// The default value of `ty` as a user stub writes it (`Default::default()` when
    /// the type implements `Default`).
    fn stub_default(&self, ty: &Ty) -> Option<ir::Code> {
        let default = self.default_of(ty)?;
        Some(default.replace_call(DEFAULT, "Default::default"))
    }

    /// The one rule of `check::model::has_default`, which the checker asks too.
    fn packet_defaultable(&self, packet: &Packet) -> bool {
        crate::checked::model::has_default(&Ty::Packet(packet.name.clone()), &|name| {
            self.checked.type_def(name)
        })
    }

    /// The Rust expression of a field default: the written value, or the type's
    /// default.
    fn field_default(&self, field_ty: &Ty, value: Option<&Value>, prefix: &str) -> ir::Code {
        match value {
            Some(value) => self.value(value, Some(field_ty), prefix),
            None => self.default_of(field_ty).unwrap_or_else(default_code),
        }
    }

    /// A Rust expression for a constant `.cool` value of type `ty`.
    fn value(&self, value: &Value, ty: Option<&Ty>, prefix: &str) -> ir::Code {
        use ir::Code;
        if let Some(Ty::Optional(inner)) = ty {
            return match value {
                Value::None => Code::core_none(),
                _ => Code::core_some(self.value(value, Some(inner), prefix)),
            };
        }
        match value {
            Value::Int(n) => match ty {
                Some(Ty::Float(_)) => Code::atom(format!("{n}.0")),
                Some(Ty::Duration) => duration_code(u64::try_from(*n).unwrap_or_default()),
                _ => Code::atom(n.to_string()),
            },
            Value::Float(x) => Code::atom(format!("{x:?}")),
            Value::Str(s) => Code::call("::std::string::String::from", vec![Code::string(s)]),
            Value::Bool(b) => Code::atom(b.to_string()),
            Value::Duration(duration) => duration_code(duration.nanos),
            Value::Enum { ty, variant } => Code::atom(format!(
                "{prefix}{}::{}",
                ident::camel(ty),
                ident::camel(variant)
            )),
            Value::List(items) => {
                let inner = match ty {
                    Some(Ty::List(inner) | Ty::Array(inner, _)) => Some(&**inner),
                    _ => None,
                };
                let items: Vec<Code> = items.iter().map(|v| self.value(v, inner, prefix)).collect();
                match ty {
                    Some(Ty::Array(..)) => Code::List("[".to_owned(), items),
                    _ => Code::List("::std::vec![".to_owned(), items),
                }
            }
            Value::Repeat(item, n) => {
                let inner = match ty {
                    Some(Ty::List(inner) | Ty::Array(inner, _)) => Some(&**inner),
                    _ => None,
                };
                let copy = inner.is_some_and(|t| self.is_copy(t));
                let item = self.value(item, inner, prefix);
                match ty {
                    Some(Ty::List(_)) => Code::Other(format!("::std::vec![{item}; {n}]")),
                    // `[value; n]` needs a `Copy` value.
                    _ if copy => Code::Repeat(Box::new(item), *n),
                    _ => array_from_fn(item),
                }
            }
            Value::None => Code::core_none(),
            // Not a constant: the checker rejects it.
            Value::Invalid => default_code(),
        }
    }

    /// Whether values of the emitted type are `Copy` (so `[value; n]` compiles).
    fn is_copy(&self, ty: &Ty) -> bool {
        match ty {
            Ty::Bool | Ty::Int(_) | Ty::Float(_) | Ty::Time | Ty::Duration | Ty::Enum(_) => true,
            Ty::Optional(inner) | Ty::Array(inner, _) => self.is_copy(inner),
            Ty::Str
            | Ty::List(_)
            | Ty::Packet(_)
            | Ty::Extern(_)
            | Ty::Ros { .. }
            | Ty::Unknown => false,
        }
    }

    /// A packet or configuration field of resolved type `ty`.
    fn field(
        &self,
        doc: &[String],
        name: &str,
        ty: &Ty,
        default: Option<&Value>,
        prefix: &str,
    ) -> ir::Field {
        ir::Field {
            doc: doc.to_vec(),
            name: ident::snake(name),
            cool_name: name.to_owned(),
            ty: rust_ty(ty, prefix),
            default: self.field_default(ty, default, prefix),
            serde_with: field_adapter(ty).map(|adapter| format!("{SERDE_WITH}As::<{adapter}>")),
        }
    }

    fn lower_crate(&self, options: &Options) -> ir::Crate {
        let mut types = ir::Types {
            module: "types".to_owned(),
            ..Default::default()
        };
        let mut atomics = Vec::new();
        let mut compounds = Vec::new();
        let mut dependencies: Vec<ir::Dependency> = Vec::new();
        let mut system_libs: Vec<String> = Vec::new();
        for def in self.checked.types() {
            match def {
                TypeDef::Packet(p) => types.packets.push(ir::Packet {
                    doc: p.doc.clone(),
                    name: ident::camel(&p.name),
                    fields: p
                        .fields
                        .iter()
                        .map(|f| self.field(&f.doc, &f.name, &f.ty, f.default.as_ref(), ""))
                        .collect(),
                    has_default: self.packet_defaultable(p),
                }),
                TypeDef::Enum(e) => types.enums.push(ir::Enum {
                    doc: e.doc.clone(),
                    name: ident::camel(&e.name),
                    variants: e
                        .variants
                        .iter()
                        .map(|(doc, name)| ir::EnumVariant {
                            doc: doc.clone(),
                            name: ident::camel(name),
                            cool_name: name.clone(),
                        })
                        .collect(),
                }),
                TypeDef::Extern(e) => types.externs.push(ir::Extern {
                    doc: e.doc.clone(),
                    name: ident::camel(&e.name),
                    path: e.rust_path.clone(),
                }),
                TypeDef::Ros(r) => {
                    let mut doc = r.doc.clone();
                    if !doc.is_empty() {
                        doc.push(String::new());
                    }
                    doc.push(format!("The ROS 2 message type `{}`.", r.ros));
                    types.externs.push(ir::Extern {
                        doc,
                        name: ident::camel(&r.name),
                        path: format!(
                            "ros::{}::{}",
                            ident::escape(r.ros.package()),
                            ident::escape(r.ros.name())
                        ),
                    });
                }
            }
        }
        types.ros = ros::packages(self.checked);
        for c in self.checked.converters() {
            let method = ident::snake(&c.name);
            let stub_body = if let Some(default) = self.stub_default(&c.to) {
                vec![
                    ir::StubLine::Comment(format!(
                        "// Converter `{}`: build the output packet from `from`.",
                        c.name
                    )),
                    ir::StubLine::Statement("let _ = from;".to_owned()),
                    ir::StubLine::Value(default),
                ]
            } else {
                vec![
                    ir::StubLine::Statement("let _ = from;".to_owned()),
                    ir::StubLine::Value(ir::Code::call(
                        "panic!",
                        vec![ir::Code::string(&format!(
                            "converter `{}` is not written yet: fill in `{}` in src/converters.rs",
                            c.name, method
                        ))],
                    )),
                ]
            };
            types.converters.push(ir::Converter {
                doc: c.doc.clone(),
                cool_name: c.name.clone(),
                method,
                from: rust_ty(&c.from, ""),
                to: rust_ty(&c.to, ""),
                user_from: rust_ty(&c.from, USER_TYPES),
                user_to: rust_ty(&c.to, USER_TYPES),
                stub_body,
            });
        }
        for c in self.checked.components() {
            for link in &c.links {
                match link {
                    Link::Crate { name, spec } => {
                        // The checks refused `coolbot` (coolc's to write) and two
                        // different specs of one crate.
                        let key = toml_key(name);
                        if !dependencies.iter().any(|d| d.key == key) {
                            dependencies.push(ir::Dependency {
                                key,
                                value: crate_spec(spec),
                            });
                        }
                    }
                    Link::System(name) => {
                        if !system_libs.contains(name) {
                            system_libs.push(name.clone());
                        }
                    }
                }
            }
        }
        // The components are lowered each on its own: on every core.
        enum Lowered {
            Atomic(ir::Atomic),
            Compound(ir::Compound),
        }
        let components: Vec<_> = self.checked.components().collect();
        let lowered = par_map(&components, |c| {
            let module = self.modules[c.name.as_str()].clone();
            match c.kind {
                ComponentKind::Atomic => Lowered::Atomic(self.atomic(c, module)),
                ComponentKind::Compound => Lowered::Compound(self.compound(c, module)),
            }
        });
        for component in lowered {
            match component {
                Lowered::Atomic(atomic) => atomics.push(atomic),
                Lowered::Compound(compound) => compounds.push(compound),
            }
        }
        let package = package_name(&options.package);
        let mut krate = ir::Crate {
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
            starter: ir::Starter::default(),
        };
        krate.starter = starter::starter(&krate);
        krate
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
    /// variables (`!config`), as `(field, value)`: a name that is both sets both.
    /// A compound's own controllable variables count; its mapped ones do not (they
    /// have no `Vars` field).
    fn overrides(&self, instance: &Instance, config: bool) -> Vec<(String, ir::Code)> {
        let Some(component) = self.checked.component(&instance.component) else {
            return Vec::new();
        };
        let mut overrides = Vec::new();
        for o in &instance.overrides {
            if config {
                for f in component
                    .configuration
                    .iter()
                    .flatten()
                    .filter(|f| f.name == o.name)
                {
                    overrides.push((
                        ident::snake(&f.name),
                        self.value(&o.value, Some(&f.ty), GEN_TYPES),
                    ));
                }
            } else {
                for v in component
                    .variables
                    .iter()
                    .filter(|v| v.kind == VarKind::Controllable && v.name == o.name)
                {
                    if let Some(ty) = &v.written {
                        overrides.push((
                            ident::snake(&v.name),
                            self.value(&o.value, Some(ty), GEN_TYPES),
                        ));
                    }
                }
            }
        }
        overrides
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

fn toml_value(value: &TableValue) -> String {
    match value {
        TableValue::Str(s) => ir::toml_string(s),
        TableValue::Bool(b) => b.to_string(),
        TableValue::Int(n) => n.to_string(),
        TableValue::Float(x) => format!("{x:?}"),
        TableValue::List(items) => {
            format!(
                "[{}]",
                items.iter().map(toml_value).collect::<Vec<_>>().join(", ")
            )
        }
    }
}

fn crate_spec(spec: &CrateSpec) -> String {
    match spec {
        CrateSpec::Version(v) => ir::toml_string(v),
        CrateSpec::Table(entries) => {
            let entries: Vec<String> = entries
                .iter()
                .map(|(key, value)| {
                    // `.cool` names cannot hold `-`: Cargo's `default-features` is
                    // written `default_features`, which edition 2024 rejects as is.
                    let key = match key.as_str() {
                        "default_features" => "default-features",
                        other => other,
                    };
                    format!("{} = {}", toml_key(key), toml_value(value))
                })
                .collect();
            format!("{{ {} }}", entries.join(", "))
        }
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
    fn components_named_like_the_crates_own_files_get_other_modules() {
        let krate = lower_text(
            "atomic Main { } atomic Lib { } atomic Mod { } atomic Types { } atomic Motor { }",
        );
        assert_eq!(
            krate.module_names(),
            [
                "types",
                "main_component",
                "lib_component",
                "mod_component",
                "types_component",
                "motor"
            ]
        );
    }

    #[test]
    fn link_crate_tables_become_cargo_tables() {
        let krate = lower_text(
            "atomic A { link crate \"serde_json\" = { version = \"1\", default_features = false, features = [\"std\"] }; link system \"m\"; }",
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
    fn the_glue_compares_variables_whose_equality_coolc_derives() {
        let krate = lower_text(
            "extern packet Image = \"image::RgbImage\";\n\
             packet Pose { x: f64 = 0.0, tags: [String] = [] }\n\
             packet Framed { image: Image?, n: u32 = 0 }\n\
             atomic A {\n\
                 observable pose: Pose; observable poses: [Pose];\n\
                 local hidden: u32 = 0; controllable gain: f32 = 1.0;\n\
                 observable image: Image?; observable framed: Framed;\n\
             }",
        );
        let a = &krate.atomics[0];
        let published: Vec<&str> = a.published.iter().map(|(name, _)| name.as_str()).collect();
        assert_eq!(published, ["pose", "poses", "gain"]);
        assert_eq!(a.published[2].1, "::core::option::Option<f32>");
        let reports: Vec<String> = a.reports.iter().map(ToString::to_string).collect();
        assert_eq!(reports.len(), 5, "{reports:?}");
        assert_eq!(
            reports[2],
            "changes.compare(2, &mut self.published.gain, &self.vars.gain, super::__cool_value_of)"
        );
        // An extern packet's `PartialEq` is another crate's: the runtime reads it.
        assert_eq!(reports[3..], ["changes.read(3)", "changes.read(4)"]);
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
            "packet P { a: f64 = 1.5, b: Duration = 10ms, c: [bool; 2] = [true; 2], d: u8? = 3, e: [u8] = [1, 2], f: f32 = -2, g: i8 = -3 }",
        );
        let defaults: Vec<String> = krate.types.packets[0]
            .fields
            .iter()
            .map(|f| f.default.to_string())
            .collect();
        assert_eq!(
            defaults,
            [
                "1.5",
                "::std::time::Duration::from_nanos(10000000)",
                "[true; 2]",
                "::core::option::Option::Some(3)",
                "::std::vec![1, 2]",
                "-2.0",
                "-3"
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
