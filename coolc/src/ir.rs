//! The intermediate representation the templates print.
//!
//! `lower` builds it from the checked model. **Invariant:** every expression is a
//! `Code` tree (a `SPEC` entry, a default, a port constructor, a compound's builder
//! steps and instance builds, a rule's condition and test); every string here is
//! final Rust with no expression structure (an identifier, a type path, a literal, a
//! signature, a short stub statement) or final TOML. Nothing reads Rust back from
//! text, and the templates only loop over these structures and print them. Orders
//! are source orders.

use std::fmt;

/// A Rust expression as a tree: `lower` builds these trees, `layout` lays out the
/// shapes it has rules for (atoms, struct literals, calls, lists) and the Rust
/// formatter the others; no Rust is read back from text. Printed with `{}`, a tree
/// is its one-line form.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) enum Code {
    /// Text with no bracket rustfmt would break at: a path, a literal, `-1`,
    /// `[false; 8]`.
    Atom(String),
    /// `path { name: value, ... }`.
    Struct(String, Vec<(String, Code)>),
    /// `callee(args)`, a function, a tuple variant or a macro (`callee` ends in
    /// `!`).
    Call(String, Vec<Code>),
    /// `&[items]`, `[items]` or `::std::vec![items]`: the opening text, the items.
    List(String, Vec<Code>),
    /// `[item; count]`, kept on one line.
    Repeat(Box<Code>, u64),
    /// `path { name: value, ..., ..rest }`: the fields it names, the rest from
    /// `rest`.
    StructRest(String, Vec<(String, Code)>, Box<Code>),
    /// `receiver.method(args)`.
    Method(Box<Code>, String, Vec<Code>),
    /// `receiver.field`.
    Field(Box<Code>, String),
    /// `operand?`.
    Try(Box<Code>),
    /// A prefix operator and its operand: `!x`, `-x`, `&x`.
    Unary(&'static str, Box<Code>),
    /// `left op right`.
    Binary(Box<Code>, &'static str, Box<Code>),
    /// `(inner)`.
    Paren(Box<Code>),
    /// `|params| body`, or `move |params| body` when it moves (`params` is the
    /// pattern list as written: `left`, `(left, right)`, `view: &T`).
    Closure(bool, String, Box<Code>),
    /// `{ let name = value; ... tail }`.
    Block(Vec<(String, Code)>, Box<Code>),
    /// `match scrutinee { pattern => value, ... }`.
    Match(Box<Code>, Vec<(String, Code)>),
    /// A shape no rule covers (`vec![item; n]`): printed as it is, and the file it
    /// is in is left to the formatter.
    Other(String),
}

impl Code {
    /// [`Code::Atom`].
    pub(crate) fn atom(text: impl Into<String>) -> Code {
        Code::Atom(text.into())
    }

    /// A string literal for `text`.
    pub(crate) fn string(text: &str) -> Code {
        Code::Atom(crate::ident::string_literal(text))
    }

    /// [`Code::Call`].
    pub(crate) fn call(callee: impl Into<String>, args: Vec<Code>) -> Code {
        Code::Call(callee.into(), args)
    }

    /// [`Code::Struct`].
    pub(crate) fn structure(path: impl Into<String>, fields: Vec<(&str, Code)>) -> Code {
        Code::Struct(
            path.into(),
            fields
                .into_iter()
                .map(|(name, value)| (name.to_owned(), value))
                .collect(),
        )
    }

    /// A slice literal `&[items]`.
    pub(crate) fn slice(items: Vec<Code>) -> Code {
        Code::List("&[".to_owned(), items)
    }

    /// `Some(code)`.
    pub(crate) fn some(code: Code) -> Code {
        Code::call("Some", vec![code])
    }

    /// `Some(code)`, or `None`.
    pub(crate) fn option(code: Option<Code>) -> Code {
        code.map_or_else(|| Code::atom("None"), Code::some)
    }

    /// `::core::option::Option::Some(code)`, by its full path.
    pub(crate) fn core_some(code: Code) -> Code {
        Code::call("::core::option::Option::Some", vec![code])
    }

    /// `::core::option::Option::None`, by its full path.
    pub(crate) fn core_none() -> Code {
        Code::atom("::core::option::Option::None")
    }

    /// `self.method(args)`.
    pub(crate) fn method(self, method: impl Into<String>, args: Vec<Code>) -> Code {
        Code::Method(Box::new(self), method.into(), args)
    }

    /// `self.field`.
    pub(crate) fn field(self, field: impl Into<String>) -> Code {
        Code::Field(Box::new(self), field.into())
    }

    /// `self?`.
    pub(crate) fn try_op(self) -> Code {
        Code::Try(Box::new(self))
    }

    /// `op self` for a prefix operator `op`.
    pub(crate) fn prefix(op: &'static str, operand: Code) -> Code {
        Code::Unary(op, Box::new(operand))
    }

    /// `&self`.
    pub(crate) fn reference(self) -> Code {
        Code::prefix("&", self)
    }

    /// `left op right`.
    pub(crate) fn binary(left: Code, op: &'static str, right: Code) -> Code {
        Code::Binary(Box::new(left), op, Box::new(right))
    }

    /// `(self)`.
    pub(crate) fn paren(self) -> Code {
        Code::Paren(Box::new(self))
    }

    /// `|params| body`.
    pub(crate) fn closure(params: impl Into<String>, body: Code) -> Code {
        Code::Closure(false, params.into(), Box::new(body))
    }

    /// `move |params| body`.
    pub(crate) fn move_closure(params: impl Into<String>, body: Code) -> Code {
        Code::Closure(true, params.into(), Box::new(body))
    }

    /// This code with every call `from()` (no argument) made a call of `to`.
    pub(crate) fn replace_call(&self, from: &str, to: &str) -> Code {
        match self {
            Code::Call(callee, args) if callee == from && args.is_empty() => {
                Code::call(to, Vec::new())
            }
            _ => self.map_operands(&|operand| operand.replace_call(from, to)),
        }
    }

    /// This code with every part equal to `from` replaced by `to`.
    pub(crate) fn replace(&self, from: &Code, to: &Code) -> Code {
        if self == from {
            to.clone()
        } else {
            self.map_operands(&|operand| operand.replace(from, to))
        }
    }

    /// Whether `part` is this code or a part of it.
    pub(crate) fn contains(&self, part: &Code) -> bool {
        self == part
            || self
                .operands()
                .into_iter()
                .any(|operand| operand.contains(part))
    }

    /// The codes this one is made of, in order.
    fn operands(&self) -> Vec<&Code> {
        match self {
            Code::Atom(_) | Code::Other(_) => Vec::new(),
            Code::Struct(_, fields) => fields.iter().map(|(_, value)| value).collect(),
            Code::StructRest(_, fields, rest) => fields
                .iter()
                .map(|(_, value)| value)
                .chain([rest.as_ref()])
                .collect(),
            Code::Call(_, items) | Code::List(_, items) => items.iter().collect(),
            Code::Method(receiver, _, args) => {
                [receiver.as_ref()].into_iter().chain(args).collect()
            }
            Code::Repeat(operand, _)
            | Code::Field(operand, _)
            | Code::Try(operand)
            | Code::Unary(_, operand)
            | Code::Paren(operand)
            | Code::Closure(_, _, operand) => vec![operand.as_ref()],
            Code::Binary(left, _, right) => vec![left.as_ref(), right.as_ref()],
            Code::Block(lets, tail) => lets
                .iter()
                .map(|(_, value)| value)
                .chain([tail.as_ref()])
                .collect(),
            Code::Match(scrutinee, arms) => [scrutinee.as_ref()]
                .into_iter()
                .chain(arms.iter().map(|(_, value)| value))
                .collect(),
        }
    }

    /// This code with `f` applied to each of its operands ([`Code::operands`]).
    fn map_operands(&self, f: &dyn Fn(&Code) -> Code) -> Code {
        let all = |items: &[Code]| -> Vec<Code> { items.iter().map(f).collect() };
        let fields = |fields: &[(String, Code)]| -> Vec<(String, Code)> {
            fields
                .iter()
                .map(|(name, value)| (name.clone(), f(value)))
                .collect()
        };
        let boxed = |code: &Code| Box::new(f(code));
        match self {
            Code::Atom(_) | Code::Other(_) => self.clone(),
            Code::Struct(path, named) => Code::Struct(path.clone(), fields(named)),
            Code::StructRest(path, named, rest) => {
                Code::StructRest(path.clone(), fields(named), boxed(rest))
            }
            Code::Call(callee, args) => Code::Call(callee.clone(), all(args)),
            Code::List(open, items) => Code::List(open.clone(), all(items)),
            Code::Repeat(item, count) => Code::Repeat(boxed(item), *count),
            Code::Method(receiver, method, args) => {
                Code::Method(boxed(receiver), method.clone(), all(args))
            }
            Code::Field(receiver, field) => Code::Field(boxed(receiver), field.clone()),
            Code::Try(operand) => Code::Try(boxed(operand)),
            Code::Unary(op, operand) => Code::Unary(op, boxed(operand)),
            Code::Binary(left, op, right) => Code::Binary(boxed(left), op, boxed(right)),
            Code::Paren(inner) => Code::Paren(boxed(inner)),
            Code::Closure(moves, params, body) => {
                Code::Closure(*moves, params.clone(), boxed(body))
            }
            Code::Block(lets, tail) => Code::Block(fields(lets), boxed(tail)),
            Code::Match(scrutinee, arms) => Code::Match(boxed(scrutinee), fields(arms)),
        }
    }
}

impl fmt::Display for Code {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fn list(f: &mut fmt::Formatter<'_>, items: &[Code]) -> fmt::Result {
            for (i, item) in items.iter().enumerate() {
                if i > 0 {
                    f.write_str(", ")?;
                }
                write!(f, "{item}")?;
            }
            Ok(())
        }
        fn fields(f: &mut fmt::Formatter<'_>, fields: &[(String, Code)]) -> fmt::Result {
            for (i, (name, value)) in fields.iter().enumerate() {
                if i > 0 {
                    f.write_str(", ")?;
                }
                write!(f, "{name}: {value}")?;
            }
            Ok(())
        }
        match self {
            Code::Atom(text) | Code::Other(text) => f.write_str(text),
            Code::Struct(path, named) if named.is_empty() => write!(f, "{path} {{}}"),
            Code::Struct(path, named) => {
                write!(f, "{path} {{ ")?;
                fields(f, named)?;
                f.write_str(" }")
            }
            Code::StructRest(path, named, rest) => {
                write!(f, "{path} {{ ")?;
                fields(f, named)?;
                if !named.is_empty() {
                    f.write_str(", ")?;
                }
                write!(f, "..{rest} }}")
            }
            Code::Call(callee, args) => {
                write!(f, "{callee}(")?;
                list(f, args)?;
                f.write_str(")")
            }
            Code::List(open, items) => {
                f.write_str(open)?;
                list(f, items)?;
                f.write_str("]")
            }
            Code::Repeat(item, count) => write!(f, "[{item}; {count}]"),
            Code::Method(receiver, method, args) => {
                write!(f, "{receiver}.{method}(")?;
                list(f, args)?;
                f.write_str(")")
            }
            Code::Field(receiver, field) => write!(f, "{receiver}.{field}"),
            Code::Try(operand) => write!(f, "{operand}?"),
            Code::Unary(op, operand) => write!(f, "{op}{operand}"),
            Code::Binary(left, op, right) => write!(f, "{left} {op} {right}"),
            Code::Paren(inner) => write!(f, "({inner})"),
            Code::Closure(moves, params, body) => {
                if *moves {
                    f.write_str("move ")?;
                }
                write!(f, "|{params}| {body}")
            }
            Code::Block(lets, tail) => {
                f.write_str("{ ")?;
                for (name, value) in lets {
                    write!(f, "let {name} = {value}; ")?;
                }
                write!(f, "{tail} }}")
            }
            Code::Match(scrutinee, arms) => {
                write!(f, "match {scrutinee} {{ ")?;
                for (i, (pattern, value)) in arms.iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "{pattern} => {value}")?;
                }
                f.write_str(" }")
            }
        }
    }
}

/// One line of a user stub's body.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) enum StubLine {
    /// A `//` comment.
    Comment(String),
    /// A statement, `;` included (a short one, kept on its line).
    Statement(String),
    /// `let name = value;` (a short one, kept on its line).
    Let(String, Code),
    /// The body's value.
    Value(Code),
}

impl fmt::Display for StubLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StubLine::Comment(text) | StubLine::Statement(text) => f.write_str(text),
            StubLine::Let(name, value) => write!(f, "let {name} = {value};"),
            StubLine::Value(code) => write!(f, "{code}"),
        }
    }
}

/// Where the generated crate finds the runtime crate `coolbot`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RuntimeDep {
    /// `coolbot = { path = "..." }`
    Path(String),
    /// `coolbot = "..."`
    Version(String),
}

impl RuntimeDep {
    /// The right-hand side of the `coolbot = ...` line in `Cargo.toml`.
    pub(crate) fn toml(&self) -> String {
        match self {
            RuntimeDep::Path(path) => format!("{{ path = {} }}", toml_string(path)),
            RuntimeDep::Version(version) => toml_string(version),
        }
    }
}

/// A TOML basic string literal.
pub(crate) fn toml_string(text: &str) -> String {
    let mut out = String::from("\"");
    for c in text.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\t' => out.push_str("\\t"),
            c if c.is_control() => out.push_str(&format!("\\u{:04X}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// Everything emitted for one set of descriptions.
#[derive(Clone, Debug, PartialEq)]
pub struct Crate {
    /// Cargo package name.
    pub(crate) package: String,
    /// The library target name (`package` with `-` replaced).
    pub(crate) lib_name: String,
    /// The runtime dependency.
    pub(crate) runtime: RuntimeDep,
    /// `link crate` dependencies, deduplicated by name, first wins.
    pub(crate) dependencies: Vec<Dependency>,
    /// `link system` libraries, deduplicated.
    pub(crate) system_libs: Vec<String>,
    /// Source file names, for the generated-file header.
    pub(crate) sources: Vec<String>,
    /// The fingerprint of the compile's inputs (`crate::fingerprint::inputs`), for
    /// the generated-file header.
    pub(crate) inputs: String,
    /// Packets, enums, extern packets and converters.
    pub(crate) types: Types,
    /// Atomic components, in source order.
    pub atomics: Vec<Atomic>,
    /// Compound components, in source order.
    pub(crate) compounds: Vec<Compound>,
    /// What the compile that creates the crate writes into its starter files.
    pub(crate) starter: Starter,
}

/// The code of the starter files (`src/main.rs`, `tests/components.rs`).
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Starter {
    /// One expression per component no compound instantiates: its
    /// `coolbot::Component` (a compound's ends in `?`), atomic ones first.
    pub(crate) roots: Vec<Code>,
    /// One registration call per component type, with the network layer's
    /// `registry`.
    pub(crate) registrations: Vec<Code>,
    /// One test per atomic component.
    pub(crate) tests: Vec<StarterTest>,
}

/// The starter test of one atomic component: it runs in its generated harness for
/// a second of virtual time from its stubs.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct StarterTest {
    /// The test function's name.
    pub(crate) name: String,
    /// The user's behaviour, by default.
    pub(crate) behavior: Code,
    /// The running harness of `behavior`.
    pub(crate) harness: Code,
    /// The assertion that the component is in no error.
    pub(crate) check: Code,
}

impl Crate {
    /// The source file names for the generated-file header: all of them up to
    /// [`Crate::HEADER_SOURCES`], else the first ones and how many more (every
    /// generated file carries the header: naming 1,000 files in each of 2,000 files
    /// would be most of the output).
    pub(crate) fn sources_text(&self) -> String {
        match self.sources.len() {
            0 => "the .cool descriptions".to_owned(),
            n if n <= Self::HEADER_SOURCES => self.sources.join(", "),
            n => format!(
                "{} and {} more",
                self.sources[..Self::HEADER_SOURCES - 1].join(", "),
                n - (Self::HEADER_SOURCES - 1)
            ),
        }
    }

    /// The first line of every generated Rust file: coolc's version, the sources and
    /// the fingerprint of the inputs.
    pub fn header(&self) -> String {
        format!(
            "// @generated by coolc {} from {}; inputs {}. Do not edit: coolc overwrites this file.",
            env!("CARGO_PKG_VERSION"),
            self.sources_text(),
            self.inputs
        )
    }

    /// How many source names the generated-file header lists at most.
    pub(crate) const HEADER_SOURCES: usize = 4;

    /// Whether a `link crate` names `name`.
    pub fn links_crate(&self, name: &str) -> bool {
        self.dependencies.iter().any(|d| d.key == name)
    }

    /// The generated modules, in emission order (`types` first).
    pub fn module_names(&self) -> Vec<String> {
        let mut names = vec![self.types.module.clone()];
        names.extend(self.atomics.iter().map(|a| a.module.clone()));
        names.extend(self.compounds.iter().map(|c| c.module.clone()));
        names
    }
}

/// One Cargo dependency from `link crate`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Dependency {
    /// Crate name (a TOML key, quoted when needed).
    pub(crate) key: String,
    /// The TOML value: a version string or an inline table.
    pub(crate) value: String,
}

/// Doc comment lines (without `///`).
pub(crate) type Doc = Vec<String>;

/// The shared types module.
#[derive(Clone, Debug, PartialEq, Default)]
pub(crate) struct Types {
    /// Module name (`types`).
    pub(crate) module: String,
    /// Data packets.
    pub(crate) packets: Vec<Packet>,
    /// Enums.
    pub(crate) enums: Vec<Enum>,
    /// Extern packets and ROS imports (type aliases), in source order.
    pub(crate) externs: Vec<Extern>,
    /// Converters, as methods of the `Converters` trait.
    pub(crate) converters: Vec<Converter>,
    /// The ROS 2 message types (module `ros`), one module per package, by package.
    pub(crate) ros: Vec<RosPackage>,
}

/// The module of one ROS 2 package in the types module's `ros` module.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct RosPackage {
    /// The package's name.
    pub(crate) package: String,
    /// Module name (the package's name, keyword-escaped).
    pub(crate) module: String,
    /// Its message types, by name.
    pub(crate) messages: Vec<RosMessage>,
}

/// One ROS 2 message type: a packet struct, its constants and its names.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct RosMessage {
    /// The struct (it always has a `Default`).
    pub(crate) packet: Packet,
    /// Its constants, as associated consts.
    pub(crate) constants: Vec<RosConstant>,
    /// `coolbot::ros::RosType::NAME`, a Rust string literal.
    pub(crate) name: String,
    /// `coolbot::ros::RosType::DDS_NAME`, a Rust string literal.
    pub(crate) dds_name: String,
    /// `coolbot::ros::RosType::TYPE_HASH`, a Rust string literal.
    pub(crate) hash: String,
    /// `coolbot::ros::RosType::MESSAGE_DEFINITION`, a Rust string literal.
    pub(crate) definition: String,
}

/// A constant of a ROS 2 message type.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct RosConstant {
    /// Doc lines.
    pub(crate) doc: Doc,
    /// Rust name.
    pub(crate) name: String,
    /// Rust type.
    pub(crate) ty: String,
    /// Rust expression of its value.
    pub(crate) value: String,
}

/// A packet struct.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Packet {
    /// Doc lines.
    pub(crate) doc: Doc,
    /// Rust type name.
    pub(crate) name: String,
    /// Fields in declaration order.
    pub(crate) fields: Vec<Field>,
    /// Whether a `Default` impl is emitted (every field has a default or a defaultable
    /// type).
    pub(crate) has_default: bool,
}

/// A struct field (packets, `Config`, `Vars`).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Field {
    /// Doc lines.
    pub(crate) doc: Doc,
    /// Rust field name.
    pub(crate) name: String,
    /// The name as written in `.cool` (for serde renames and messages).
    pub(crate) cool_name: String,
    /// Rust type.
    pub(crate) ty: String,
    /// Rust expression of its default value.
    pub(crate) default: Code,
    /// The `#[serde(with = "...")]` adapter of a type holding an array longer than 32
    /// elements (serde's own impls stop at 32), or `None`.
    pub(crate) serde_with: Option<String>,
}

/// Whether `#[derive(Default)]` gives the same values as the written defaults (a
/// hand-written impl would then trip clippy's `derivable_impls`).
pub(crate) fn derive_default(fields: &[Field]) -> bool {
    fields.iter().all(|f| default_equivalent(&f.default))
}

/// Whether a default expression equals its type's `Default::default()`.
fn default_equivalent(code: &Code) -> bool {
    match code {
        // `Default` for arrays stops at 32 elements.
        Code::Repeat(item, count) => *count <= 32 && default_equivalent(item),
        Code::Atom(text) => matches!(
            text.as_str(),
            "0" | "0.0" | "false" | "::core::option::Option::None"
        ),
        Code::Call(callee, args) => match (callee.as_str(), args.as_slice()) {
            ("::core::default::Default::default", []) => true,
            ("::std::string::String::from", [Code::Atom(text)]) => text == "\"\"",
            _ => false,
        },
        Code::List(open, items) => open == "::std::vec![" && items.is_empty(),
        _ => false,
    }
}

impl Field {
    /// Whether the Rust name differs from the `.cool` name (serde needs a rename).
    pub(crate) fn renamed(&self) -> bool {
        self.name.trim_start_matches("r#") != self.cool_name
    }
}

impl Packet {
    /// Whether the packet derives `Default` (rather than a written impl).
    pub(crate) fn derives_default(&self) -> bool {
        self.has_default && derive_default(&self.fields)
    }

    /// Whether a hand-written `Default` impl is emitted.
    pub(crate) fn writes_default(&self) -> bool {
        self.has_default && !derive_default(&self.fields)
    }
}

/// An enum.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Enum {
    /// Doc lines.
    pub(crate) doc: Doc,
    /// Rust type name.
    pub(crate) name: String,
    /// Variants: doc, Rust name, `.cool` name.
    pub(crate) variants: Vec<EnumVariant>,
}

/// One enum variant.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct EnumVariant {
    /// Doc lines.
    pub(crate) doc: Doc,
    /// Rust variant name.
    pub(crate) name: String,
    /// The name as written.
    pub(crate) cool_name: String,
}

/// `extern packet Name = "path";`
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Extern {
    /// Doc lines.
    pub(crate) doc: Doc,
    /// Rust type name.
    pub(crate) name: String,
    /// The Rust type path.
    pub(crate) path: String,
}

/// A converter method.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Converter {
    /// Doc lines.
    pub(crate) doc: Doc,
    /// The converter name as written.
    pub(crate) cool_name: String,
    /// Method name.
    pub(crate) method: String,
    /// Input type, as seen from the generated types module.
    pub(crate) from: String,
    /// Output type, as seen from the generated types module.
    pub(crate) to: String,
    /// Input type, as seen from user code.
    pub(crate) user_from: String,
    /// Output type, as seen from user code.
    pub(crate) user_to: String,
    /// The stub body of the user implementation, one line each.
    pub(crate) stub_body: Vec<StubLine>,
}

impl Converter {
    /// Its method's signature in the `Converters` trait.
    pub(crate) fn signature(&self) -> String {
        format!("fn {}(from: &{}) -> {}", self.method, self.from, self.to)
    }
}

impl RosConstant {
    /// Its declaration up to the `=` before its value.
    pub(crate) fn lhs(&self) -> String {
        format!("pub const {}: {} =", self.name, self.ty)
    }
}

/// An atomic component's generated module.
#[derive(Clone, Debug, PartialEq)]
pub struct Atomic {
    /// Its `coolbot::Spec` literal.
    pub(crate) spec: Code,
    /// Doc lines.
    pub(crate) doc: Doc,
    /// The component type name as written.
    pub(crate) type_name: String,
    /// Module name.
    pub module: String,
    /// Name of the user struct in the user file.
    pub(crate) user_struct: String,
    /// `Config` fields.
    pub(crate) config: Vec<Field>,
    /// `Vars` fields with their exposure.
    pub(crate) vars: Vec<Var>,
    /// The glue's copies of its variables as last reported to the runtime (the
    /// observable and controllable ones it compares in their Rust type): `(field,
    /// type)`, each an `Option` of the variable's type.
    pub(crate) published: Vec<(String, String)>,
    /// The statements of the glue's `changed_variables`, one per observable or
    /// controllable variable, in index order.
    pub(crate) reports: Vec<Code>,
    /// Input ports in declaration order.
    pub(crate) inputs: Vec<Port>,
    /// Output ports in declaration order.
    pub(crate) outputs: Vec<Port>,
    /// User automaton states (index = state id).
    pub(crate) states: Vec<State>,
    /// Index of the initial state.
    pub(crate) initial: usize,
    /// Declared exceptions (index = exception id).
    pub(crate) exceptions: Vec<ExceptionIr>,
    /// Rust expression of the `coolbot::TimingSpec`.
    pub(crate) timing: Code,
    /// The fields of its `adaptation { ... }` (`coolbot::AdaptConfig` fields, as
    /// `(name, value)`), if it has a block that says anything.
    pub(crate) adaptation: Option<Vec<(String, Code)>>,
    /// Behavior trait methods (the stubs), in a stable order.
    pub methods: Vec<Method>,
    /// `section` dispatch arms: `(pattern, call)`.
    pub(crate) section_arms: Vec<(String, Code)>,
    /// `choose` dispatch arms: `(state index, state name, may enum)`.
    pub(crate) choose_arms: Vec<ChooseArm>,
    /// `answer` dispatch arms: `(output index, method, send call)`.
    pub(crate) answer_arms: Vec<AnswerArm>,
    /// Doc lines added to `SPEC`'s rustdoc: the doc comments of constructs without a
    /// Rust item of their own ([`notes`]).
    pub(crate) notes: Doc,
}

/// The doc lines that document a component's constructs without a Rust item of their
/// own, for `SPEC`'s rustdoc: per note an empty line, then its subject followed by
/// its first doc line, then its other doc lines.
pub(crate) fn notes<'n>(notes: impl IntoIterator<Item = (&'n str, &'n [String])>) -> Doc {
    let mut lines = Vec::new();
    for (subject, doc) in notes {
        lines.push(String::new());
        let mut doc = doc.iter();
        match doc.next().map(|line| line.trim_end()) {
            Some(first) if !first.is_empty() => lines.push(format!("{subject}: {first}")),
            _ => lines.push(format!("{subject}:")),
        }
        lines.extend(doc.cloned());
    }
    lines
}

/// The doc lines as one Rust string literal.
pub(crate) fn doc_literal(doc: &Doc) -> String {
    crate::ident::string_literal(&doc.join("\n"))
}

impl Atomic {
    /// Whether `Config` derives `Default`.
    pub(crate) fn config_derives_default(&self) -> bool {
        derive_default(&self.config)
    }

    /// Whether `Vars` derives `Default`.
    pub(crate) fn vars_derive_default(&self) -> bool {
        let fields: Vec<Field> = self.vars.iter().map(|v| v.field.clone()).collect();
        derive_default(&fields)
    }

    /// The doc comment as a Rust string literal.
    pub(crate) fn doc_literal(&self) -> String {
        doc_literal(&self.doc)
    }

    /// Whether any variable is controllable.
    pub(crate) fn has_controllable(&self) -> bool {
        self.vars.iter().any(Var::controllable)
    }

    /// Whether any variable is observable or controllable.
    pub(crate) fn has_exposed(&self) -> bool {
        self.vars.iter().any(|v| v.spec_index.is_some())
    }
}

/// One `Vars` field.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Var {
    /// The field.
    pub(crate) field: Field,
    /// `Observable`, `Controllable` or `Local`.
    pub(crate) kind: String,
    /// Index into `SPEC.variables` (observable and controllable only).
    pub(crate) spec_index: Option<usize>,
    /// The variable's type as written in `.cool`.
    pub(crate) cool_ty: String,
    /// Rust expression turning the field (`self.vars.<field>` in an atomic
    /// component's glue, `vars.<field>` in a compound's) into a `coolbot::Value`.
    pub(crate) to_value: Code,
    /// Rust expression turning `value: &coolbot::Value` into a `Result` of the field
    /// type whose error converts into `coolbot::ValueRefused`.
    pub(crate) from_value: Code,
    /// The `Option<coolbot::VarRange>` expression of its `in low..=high`.
    pub(crate) range: Code,
}

impl Var {
    /// The doc comment as a Rust string literal.
    pub(crate) fn doc_literal(&self) -> String {
        doc_literal(&self.field.doc)
    }

    /// Whether it can be set through the control port.
    pub(crate) fn controllable(&self) -> bool {
        self.kind == "Controllable"
    }

    /// Its `coolbot::VarSpec` (observable and controllable variables only).
    pub(crate) fn spec(&self) -> Code {
        Code::structure(
            "::coolbot::VarSpec",
            vec![
                ("name", Code::string(&self.field.cool_name)),
                (
                    "kind",
                    Code::atom(format!("::coolbot::VarKind::{}", self.kind)),
                ),
                ("ty", Code::string(&self.cool_ty)),
                ("doc", Code::atom(self.doc_literal())),
                ("range", self.range.clone()),
            ],
        )
    }
}

/// A port.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Port {
    /// Doc lines.
    pub(crate) doc: Doc,
    /// Port name as written.
    pub(crate) cool_name: String,
    /// Rust field name.
    pub(crate) field: String,
    /// Rust handle type.
    pub(crate) handle: String,
    /// The Rust type of its packets (`()` for a tick port).
    pub(crate) rust_packet: String,
    /// Its kind as written (`tick`, `fifo`, `ufifo`, `last`, `poster`, `data`).
    pub(crate) kind_name: &'static str,
    /// Rust expression building the handle.
    pub(crate) ctor: Code,
    /// Rust expression of its `InputKind`/`OutputKind`.
    pub(crate) kind: Code,
    /// Packet type as written (empty for ticks).
    pub(crate) packet: String,
    /// Pull model.
    pub(crate) pull: bool,
}

impl Port {
    /// Its `coolbot::InputSpec` (`input`) or `coolbot::OutputSpec`, under `name` (a
    /// compound's exported port is named by its export, not by the port it reaches).
    pub(crate) fn spec(&self, name: &str, input: bool) -> Code {
        let path = if input {
            "::coolbot::InputSpec"
        } else {
            "::coolbot::OutputSpec"
        };
        Code::structure(
            path,
            vec![
                ("name", Code::string(name)),
                ("kind", self.kind.clone()),
                ("packet", Code::string(&self.packet)),
                ("pull", Code::atom(if self.pull { "true" } else { "false" })),
            ],
        )
    }
}

/// A state of the user automaton.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct State {
    /// Doc lines.
    pub(crate) doc: Doc,
    /// Name as written.
    pub(crate) cool_name: String,
    /// `UserState` variant.
    pub(crate) variant: String,
    /// The `<State>May` enum, when the state has `may`.
    pub(crate) may_enum: Option<String>,
    /// `may` targets: (variant in the may enum, target state index, target name).
    pub(crate) may: Vec<(String, usize, String)>,
    /// Rust expression of its `coolbot::StateSpec`.
    pub(crate) spec: Code,
}

/// A declared exception.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct ExceptionIr {
    /// Doc lines.
    pub(crate) doc: Doc,
    /// Name as written.
    pub(crate) cool_name: String,
    /// `Exception` variant.
    pub(crate) variant: String,
    /// Handler method name.
    pub(crate) handler: String,
    /// Rust expression of its `coolbot::ExceptionSpec`.
    pub(crate) spec: Code,
}

/// One required method of `Behavior`, with its user stub.
#[derive(Clone, Debug, PartialEq)]
pub struct Method {
    /// Method name.
    pub name: String,
    /// Doc lines for the trait declaration.
    pub(crate) doc: Doc,
    /// The signature in the generated module (`fn ...(...) -> ...`).
    pub(crate) signature: String,
    /// The signature in the user file.
    pub(crate) user_signature: String,
    /// The stub body, one line each.
    pub(crate) stub_body: Vec<StubLine>,
}

/// One `choose` dispatch arm.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct ChooseArm {
    /// State index.
    pub(crate) state: usize,
    /// The choose method.
    pub(crate) method: String,
    /// The may enum.
    pub(crate) may_enum: String,
    /// (variant, target index).
    pub(crate) targets: Vec<(String, usize)>,
}

/// One `answer` dispatch arm.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct AnswerArm {
    /// Output index.
    pub(crate) output: usize,
    /// The answer method.
    pub(crate) method: String,
    /// The output field.
    pub(crate) field: String,
    /// `send` or `post`.
    pub(crate) send: String,
}

/// A compound component's generated module.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Compound {
    /// Its supervisor's `coolbot::Spec` literal.
    pub(crate) spec: Code,
    /// Doc lines.
    pub(crate) doc: Doc,
    /// Doc lines added to `SPEC`'s rustdoc ([`notes`]).
    pub(crate) notes: Doc,
    /// The component type name as written.
    pub(crate) type_name: String,
    /// Module name.
    pub(crate) module: String,
    /// Instances, in declaration order.
    pub(crate) instances: Vec<Instance>,
    /// Connections.
    pub(crate) connections: Vec<Connection>,
    /// Whether any connection goes through a converter (the builder is then generic
    /// over the converters).
    pub(crate) uses_converters: bool,
    /// Name of the user struct implementing `Parts` in the user file.
    pub(crate) user_struct: String,
    /// Name of the user struct implementing `Supervisor` in the user file.
    pub(crate) supervisor_struct: String,
    /// The `Parts` methods (`supervisor` first, then one per instance) with their
    /// user stubs.
    pub(crate) parts: Vec<Method>,
    /// The builder's method calls after the instances and connections, in order
    /// (exports, mapped variables, policies, redundant groups, substitutes,
    /// recovery): each a [`Code::Call`] of the method, printed after a `.`.
    pub(crate) steps: Vec<Code>,
    /// The `Mapped` fields: one per mapped controllable variable.
    pub(crate) mapped: Vec<MappedField>,
    /// `coolbot::InputSpec` expressions of the exported inputs, in order (what the
    /// builder gives the compound; listed in `SPEC` so that a supervisor's `on` and
    /// `without` validate).
    pub(crate) input_specs: Vec<Code>,
    /// `coolbot::OutputSpec` expressions of the exported outputs, in order.
    pub(crate) output_specs: Vec<Code>,
    /// Every exported port, inputs then outputs: its name and the Rust type of its
    /// packets (`()` for a tick port), for the network layer's registration.
    pub(crate) exported_ports: Vec<(String, String)>,
    /// The compound's own variables (`Vars`), read through the guard `vars`.
    pub(crate) vars: Vec<Var>,
    /// Supervisor states (index = state id).
    pub(crate) states: Vec<State>,
    /// Index of the initial supervisor state.
    pub(crate) initial: usize,
    /// The `Supervisor` trait methods (one per section), with their user stubs.
    pub(crate) methods: Vec<Method>,
    /// `section` dispatch arms: `(pattern, call)`.
    pub(crate) section_arms: Vec<(String, Code)>,
    /// Rust expression of the supervisor's `coolbot::TimingSpec`.
    pub(crate) timing: Code,
    /// The `when` rules, in declaration order.
    pub(crate) rules: Vec<Rule>,
    /// `choose` dispatch arms: one per supervisor state with `may`.
    pub(crate) choose_arms: Vec<ChooseArm>,
    /// The typed handles a supervisor section commands the instances with, one per
    /// instance whose component is known, in declaration order.
    pub(crate) handles: Vec<Handle>,
}

/// The typed handle of one instance in a compound's `Cx`: its methods command the
/// instance through `coolbot::Commander`.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Handle {
    /// The instance's name as written (what the commander is given).
    pub(crate) instance: String,
    /// The method of `Instances` returning it.
    pub(crate) method: String,
    /// The handle struct's name (`MotionInstance`).
    pub(crate) type_name: String,
    /// The component type name as written.
    pub(crate) component: String,
    /// One setter per controllable variable (own or mapped), in declaration order.
    pub(crate) setters: Vec<Setter>,
    /// `(method, variable)` for each observable variable whose `set_<variable>` names
    /// no other method: a call does not compile, with the reason
    /// (`coolbot::ObservableOnly`).
    pub(crate) observables: Vec<(String, String)>,
    /// The configuration type (`super::<module>::Config`) when the instance is an
    /// atomic component with a `configuration` block.
    pub(crate) config: Option<String>,
    /// The quality enum's name and its variants `(variant, level name)`, best first,
    /// when the instance has two or more quality levels.
    pub(crate) quality: Option<(String, Vec<(String, String)>)>,
}

/// `set_<variable>` on an instance handle.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Setter {
    /// Method name.
    pub(crate) method: String,
    /// The variable's name as written.
    pub(crate) variable: String,
    /// The value's Rust type.
    pub(crate) ty: String,
    /// The `coolbot::Value` expression of `value`.
    pub(crate) to_value: Code,
}

impl Instance {
    /// The unapplied overrides as one line of text (`a`, `b`).
    pub(crate) fn unapplied_text(&self) -> String {
        let names: Vec<String> = self.unapplied.iter().map(|n| format!("`{n}`")).collect();
        names.join(", ")
    }
}

/// One call of the chain that builds a compound (`CompoundBuilder`), in order.
#[derive(Clone, Copy, Debug)]
pub(crate) enum BuilderStep<'a> {
    /// `.instance(build)` or `.instance_on(node, build)`.
    Instance(&'a Instance, &'a Code),
    /// `.connect(..)` or `.connect_via(..)`.
    Connect(&'a Connection),
    /// Another step (policies, exports, substitutes, recovery...).
    Step(&'a Code),
    /// `.rule(..)`.
    Rule(&'a Rule),
}

impl Handle {
    /// The signature of the refusing setter `method` of an observable variable.
    pub(crate) fn refusal_signature(method: &str) -> String {
        format!(
            "pub fn {method}<T: ::coolbot::ObservableOnly>(&mut self, value: T) -> ::core::result::Result<(), ::coolbot::CommandError>"
        )
    }

    /// The signature of `configure`, taking a `config`.
    pub(crate) fn configure_signature(config: &str) -> String {
        format!(
            "pub fn configure(&mut self, configuration: {config}) -> ::core::result::Result<(), ::coolbot::CommandError>"
        )
    }

    /// The signature of `set_quality`, taking a `quality` and returning `ret`.
    pub(crate) fn quality_signature(quality: &str, ret: &str) -> String {
        format!("pub fn set_quality(&mut self, level: {quality}) -> {ret}")
    }

    /// The signature of its accessor, returning `{type_name}<'_>`.
    pub(crate) fn accessor_signature(&self) -> String {
        format!(
            "pub fn {}(&mut self) -> {}<'_>",
            self.method, self.type_name
        )
    }

    /// The signature of its stand-in's accessor, returning its stand-in's handle.
    pub(crate) fn stand_in_accessor_signature(&self) -> String {
        format!(
            "pub fn {}(&mut self) -> {}<'_>",
            self.method,
            self.stand_in_type()
        )
    }

    /// The type of its stand-in's handle (what the harness's `StandIns` gives for it).
    pub(crate) fn stand_in_type(&self) -> String {
        format!("{}StandIn", self.type_name)
    }
}

impl Setter {
    /// Its signature, returning `ret`.
    pub(crate) fn signature(&self, ret: &str) -> String {
        format!(
            "pub fn {}(&mut self, value: {}) -> {ret}",
            self.method, self.ty
        )
    }

    /// The arguments after the instance's name: the variable's name and value.
    pub(crate) fn args(&self) -> Vec<Code> {
        vec![
            Code::atom(format!("\"{}\"", self.variable)),
            self.to_value.clone(),
        ]
    }
}

impl Rule {
    /// Its function's signature.
    pub(crate) fn signature(&self) -> String {
        let vars = self
            .vars_param
            .as_ref()
            .map_or(String::new(), |vars| format!(", {vars}: &Vars"));
        format!(
            "fn {}({}: &::coolbot::View{vars}) -> bool",
            self.function, self.view_param
        )
    }
}

impl Compound {
    /// The doc comment as a Rust string literal.
    pub(crate) fn doc_literal(&self) -> String {
        doc_literal(&self.doc)
    }

    /// The signature of the harness's constructor `name` (`new`, `running`).
    pub(crate) fn harness_signature(&self, name: &str) -> String {
        format!(
            "pub fn {name}{}(parts: impl Parts) -> HarnessResult<Self>",
            self.generics()
        )
    }

    /// `(instance, component type)` of every instance.
    pub(crate) fn instance_pairs(&self) -> Vec<(&str, &str)> {
        self.instances
            .iter()
            .map(|i| (i.name.as_str(), i.component.as_str()))
            .collect()
    }

    /// `(instance, the instance it substitutes)`.
    pub(crate) fn substitute_pairs(&self) -> Vec<(&str, &str)> {
        self.instances
            .iter()
            .filter_map(|i| Some((i.name.as_str(), i.substitutes.as_deref()?)))
            .collect()
    }

    /// `(from, to)` of every connection.
    pub(crate) fn connection_pairs(&self) -> Vec<(&str, &str)> {
        self.connections
            .iter()
            .map(|k| (k.from.as_str(), k.to.as_str()))
            .collect()
    }

    /// The calls of the chain that builds the compound, in order.
    pub(crate) fn builder_steps(&self) -> Vec<BuilderStep<'_>> {
        let mut steps: Vec<BuilderStep<'_>> = self
            .instances
            .iter()
            .filter_map(|i| Some(BuilderStep::Instance(i, i.build.as_ref()?)))
            .collect();
        steps.extend(self.connections.iter().map(BuilderStep::Connect));
        steps.extend(self.steps.iter().map(BuilderStep::Step));
        steps.extend(self.rules.iter().map(BuilderStep::Rule));
        steps
    }

    /// Whether `Vars` derives `Default`.
    pub(crate) fn vars_derive_default(&self) -> bool {
        let fields: Vec<Field> = self.vars.iter().map(|v| v.field.clone()).collect();
        derive_default(&fields)
    }

    /// Whether the builder's chain carries comments (overrides of an instance's
    /// mapped variables that are not applied).
    pub(crate) fn builder_notes(&self) -> bool {
        self.instances
            .iter()
            .any(|i| i.build.is_some() && !i.unapplied.is_empty())
    }

    /// Whether any own variable is controllable.
    pub(crate) fn has_controllable(&self) -> bool {
        self.vars.iter().any(Var::controllable)
    }

    /// Whether any own variable is observable or controllable.
    pub(crate) fn has_exposed(&self) -> bool {
        self.vars.iter().any(|v| v.spec_index.is_some())
    }

    /// Whether any rule reads the own variables (the builder then shares them).
    pub(crate) fn rules_use_vars(&self) -> bool {
        self.rules.iter().any(|r| r.vars_param.is_some())
    }

    /// Whether the generated code locks the shared variables (`__cool_lock` is
    /// emitted only then).
    pub(crate) fn locks(&self) -> bool {
        !self.section_arms.is_empty()
            || !self.choose_arms.is_empty()
            || self.has_exposed()
            || self.has_controllable()
            || self.rules_use_vars()
    }

    /// The builder's generic parameters (`<C: ...>` when converters are used).
    pub(crate) fn generics(&self) -> &'static str {
        if self.uses_converters {
            "<C: super::types::Converters + 'static>"
        } else {
            ""
        }
    }

    /// The turbofish passing the converters on (`::<C>`), or nothing.
    pub(crate) fn turbofish(&self) -> &'static str {
        if self.uses_converters { "::<C>" } else { "" }
    }
}

/// A mapped controllable variable's initial value, a field of `Mapped`.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct MappedField {
    /// Rust field name.
    pub(crate) name: String,
    /// The variable's name as written.
    pub(crate) cool_name: String,
    /// The instance variable it maps (`instance.variable`).
    pub(crate) target: String,
    /// The instance variable's Rust type (the field is an `Option` of it).
    pub(crate) ty: String,
}

/// One instance of a compound.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Instance {
    /// Instance name as written.
    pub(crate) name: String,
    /// Its method on the `Parts` trait.
    pub(crate) method: String,
    /// Component type name.
    pub(crate) component: String,
    /// The generated module of the component.
    pub(crate) module: Option<String>,
    /// Whether the component is a compound.
    pub(crate) compound: bool,
    /// The instance it substitutes, if any.
    pub(crate) substitutes: Option<String>,
    /// The node of `on "node"` (instances run locally for now).
    pub(crate) node: Option<String>,
    /// Rust expression building its `coolbot::Component` (`?` applies to nested
    /// compounds); `None` when the component is unknown.
    pub(crate) build: Option<Code>,
    /// Overrides the generated code cannot apply (a nested compound's mapped
    /// controllable variables), by name.
    pub(crate) unapplied: Vec<String>,
}

/// One `connect` of a compound.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Connection {
    /// `instance.port` of the output end, relative to the compound.
    pub(crate) from: String,
    /// `instance.port` of the input end.
    pub(crate) to: String,
    /// Converter method on `Converters`, if any.
    pub(crate) via: Option<String>,
    /// The converter's name as written, if any.
    pub(crate) converter: Option<String>,
}

/// One `when condition -> target;` of a supervisor state.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Rule {
    /// The supervisor state, as a Rust string literal.
    pub(crate) state: String,
    /// The target state, as a Rust string literal.
    pub(crate) target: String,
    /// The `reads` slice expression (`&["ranges.state", "faults"]`).
    pub(crate) reads: Code,
    /// The rule function's name.
    pub(crate) function: String,
    /// Its `&coolbot::View` parameter name (`view`, or `_` when unused).
    pub(crate) view_param: String,
    /// Its `&Vars` parameter name, when the rule reads own variables.
    pub(crate) vars_param: Option<String>,
    /// The condition as a Rust `bool` expression.
    pub(crate) expr: Code,
    /// The test passed to `CompoundBuilder::rule`.
    pub(crate) call: Code,
    /// A line documenting the rule.
    pub(crate) doc: String,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expression_trees_print_as_rust() {
        let x = || Code::atom("x");
        let cases = [
            (
                Code::StructRest(
                    "S".to_owned(),
                    vec![("a".to_owned(), Code::atom("1"))],
                    Box::new(Code::call("S::default", Vec::new())),
                ),
                "S { a: 1, ..S::default() }",
            ),
            (
                Code::StructRest("S".to_owned(), Vec::new(), Box::new(x())),
                "S { ..x }",
            ),
            (
                x().field("f")
                    .method("g", vec![Code::atom("1"), Code::atom("2")]),
                "x.f.g(1, 2)",
            ),
            (Code::call("f", Vec::new()).try_op(), "f()?"),
            (
                Code::binary(
                    Code::prefix("!", x()),
                    "&&",
                    Code::binary(Code::prefix("-", x()), "<", x().reference()).paren(),
                ),
                "!x && (-x < &x)",
            ),
            (
                x().method(
                    "zip",
                    vec![
                        Code::closure("(l, r)", Code::atom("l")),
                        Code::closure("", x()),
                    ],
                ),
                "x.zip(|(l, r)| l, || x)",
            ),
            (
                Code::Block(
                    vec![("y".to_owned(), x())],
                    Box::new(Code::move_closure("v: &V", Code::atom("y"))),
                ),
                "{ let y = x; move |v: &V| y }",
            ),
            (
                Code::Match(
                    Box::new(x()),
                    vec![
                        ("A(t)".to_owned(), Code::core_some(Code::atom("t"))),
                        ("_".to_owned(), Code::core_none()),
                    ],
                ),
                "match x { A(t) => ::core::option::Option::Some(t), _ => ::core::option::Option::None }",
            ),
        ];
        for (code, text) in cases {
            assert_eq!(code.to_string(), text);
        }
    }

    #[test]
    fn replace_swaps_a_part_wherever_it_is() {
        let held = Code::atom("self").field("vars").field("x");
        let code = Code::call(
            "to",
            vec![Code::call("wrap", vec![held.clone().reference()]).reference()],
        );
        assert!(code.contains(&held));
        assert!(!code.contains(&Code::atom("self").field("vars").field("y")));
        let replaced = code.replace(&held, &Code::atom("value"));
        assert_eq!(replaced.to_string(), "to(&wrap(&value))");
        assert!(!replaced.contains(&held));
    }

    #[test]
    fn replace_call_reaches_into_closures() {
        let default = "::core::default::Default::default";
        let code = Code::call(
            "::core::array::from_fn",
            vec![Code::closure("_", Code::call(default, Vec::new()))],
        );
        assert_eq!(
            code.replace_call(default, "Default::default").to_string(),
            "::core::array::from_fn(|_| Default::default())"
        );
    }
}
