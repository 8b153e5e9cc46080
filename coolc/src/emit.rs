//! Emission: the IR printed through the askama templates in `templates/`, formatted.
//!
//! **Invariant:** emission cannot fail on user input. Every generated Rust file is
//! parsed with `syn` and printed with `prettyplease` (then `rustfmt` when it is
//! installed, so the files are `cargo fmt` clean); a file that does not parse is a
//! template bug and panics with the offending text. Output depends only on the IR.

use std::path::PathBuf;
use std::process::{Command, Stdio};

use askama::Template;

use crate::ir;

/// Who owns an emitted file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FileKind {
    /// Rewritten by every compile.
    Generated,
    /// Written once, then only merged into (see `merge`).
    User,
}

/// One file of the emitted crate.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EmittedFile {
    /// Path relative to the crate root.
    pub path: PathBuf,
    /// Full contents.
    pub contents: String,
    /// Who owns it.
    pub kind: FileKind,
}

/// A user file's stubs, for merging into an existing file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StubSet {
    /// Path of the user file relative to the crate root.
    pub path: PathBuf,
    /// Last path segment of the trait the `impl` block implements.
    pub trait_name: String,
    /// `(method name, stub text)` in order; the text is indented for an impl block.
    pub stubs: Vec<(String, String)>,
}

#[derive(Template)]
#[template(path = "cargo.toml", escape = "none")]
struct CargoToml<'a> {
    krate: &'a ir::Crate,
}

#[derive(Template)]
#[template(path = "build.rs", escape = "none")]
struct BuildRs<'a> {
    krate: &'a ir::Crate,
}

#[derive(Template)]
#[template(path = "generated_mod.rs", escape = "none")]
struct GeneratedMod<'a> {
    krate: &'a ir::Crate,
}

#[derive(Template)]
#[template(path = "types.rs", escape = "none")]
struct TypesRs<'a> {
    krate: &'a ir::Crate,
    types: &'a ir::Types,
}

#[derive(Template)]
#[template(path = "atomic.rs", escape = "none")]
struct AtomicRs<'a> {
    krate: &'a ir::Crate,
    c: &'a ir::Atomic,
}

#[derive(Template)]
#[template(path = "compound.rs", escape = "none")]
struct CompoundRs<'a> {
    krate: &'a ir::Crate,
    c: &'a ir::Compound,
}

#[derive(Template)]
#[template(path = "user_lib.rs", escape = "none")]
struct UserLib<'a> {
    modules: &'a [String],
}

#[derive(Template)]
#[template(path = "user_component.rs", escape = "none")]
struct UserComponent<'a> {
    c: &'a ir::Atomic,
}

#[derive(Template)]
#[template(path = "user_compound.rs", escape = "none")]
struct UserCompound<'a> {
    c: &'a ir::Compound,
}

#[derive(Template)]
#[template(path = "user_converters.rs", escape = "none")]
struct UserConverters<'a> {
    methods: &'a [ir::Method],
}

#[derive(Template)]
#[template(path = "user_stub.rs", escape = "none")]
struct UserStub<'a> {
    method: &'a ir::Method,
}

fn render(template: &impl Template) -> String {
    match template.render() {
        Ok(text) => text,
        Err(error) => panic!("coolc bug: a template failed to render: {error}"),
    }
}

/// Formats generated Rust: parse with `syn` (a failure is a template bug), then
/// `rustfmt` when it is installed (keeping the templates' blank lines), else
/// `prettyplease`. Leading `//` comment lines are kept as the header.
pub fn format_generated(code: &str) -> String {
    let file = match syn::parse_file(code) {
        Ok(file) => file,
        Err(error) => panic!("coolc bug: generated code does not parse ({error}):\n{code}"),
    };
    if let Some(formatted) = rustfmt(code) {
        return formatted;
    }
    let header: String = code
        .lines()
        .take_while(|l| l.starts_with("//") && !l.starts_with("//!") && !l.starts_with("///"))
        .map(|l| format!("{l}\n"))
        .collect();
    format!("{header}{}", prettyplease::unparse(&file))
}

/// Formats hand-laid-out Rust (user files: comments matter) with `rustfmt` when it is
/// available; checks that it parses either way.
fn format_user(code: &str) -> String {
    if let Err(error) = syn::parse_file(code) {
        panic!("coolc bug: a user stub file does not parse ({error}):\n{code}");
    }
    rustfmt(code).unwrap_or_else(|| code.to_owned())
}

/// Runs `rustfmt --edition 2024` over `code`; `None` when it is not installed or fails.
fn rustfmt(code: &str) -> Option<String> {
    use std::io::Write;
    let program = std::env::var_os("RUSTFMT").unwrap_or_else(|| "rustfmt".into());
    let mut child = Command::new(program)
        .args(["--edition", "2024", "--emit", "stdout", "--quiet"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .ok()?;
    let mut stdin = child.stdin.take()?;
    let input = code.to_owned();
    let writer = std::thread::spawn(move || stdin.write_all(input.as_bytes()));
    let output = child.wait_with_output().ok()?;
    writer.join().ok()?.ok()?;
    if output.status.success() {
        String::from_utf8(output.stdout).ok()
    } else {
        None
    }
}

/// Formats one stub method as it sits in an impl block (indented by four spaces).
fn format_stub(stub: &str) -> String {
    let wrapped = format!("impl T for U {{\n{stub}\n}}\n");
    match rustfmt(&wrapped) {
        Some(formatted) => {
            let lines: Vec<&str> = formatted.lines().collect();
            let inner = &lines[1.min(lines.len())..lines.len().saturating_sub(1)];
            inner.iter().map(|l| format!("{l}\n")).collect()
        }
        None => stub.to_owned(),
    }
}

/// The generated module texts: `(module name, formatted contents)`, `types` first.
pub fn generated_modules(krate: &ir::Crate) -> Vec<(String, String)> {
    let mut modules = vec![(
        krate.types.module.clone(),
        format_generated(&render(&TypesRs {
            krate,
            types: &krate.types,
        })),
    )];
    for c in &krate.atomics {
        modules.push((
            c.module.clone(),
            format_generated(&render(&AtomicRs { krate, c })),
        ));
    }
    for c in &krate.compounds {
        modules.push((
            c.module.clone(),
            format_generated(&render(&CompoundRs { krate, c })),
        ));
    }
    modules
}

/// The contents of `generated/mod.rs`.
pub fn generated_mod_rs(krate: &ir::Crate) -> String {
    format_generated(&render(&GeneratedMod { krate }))
}

/// Every generated module in one file, for `include!` from `OUT_DIR` (the
/// [`crate::builder::Builder`] output): `pub mod x { ... }` per module plus the
/// support functions.
pub fn single_file(krate: &ir::Crate) -> String {
    let mut out = format!(
        "// @generated by coolc from {}. Do not edit: coolc overwrites this file.\n",
        krate.sources_text()
    );
    for (module, text) in generated_modules(krate) {
        let body: String = text
            .lines()
            .filter(|l| !l.starts_with("// @generated"))
            .map(|l| format!("{l}\n"))
            .collect();
        out.push_str(&format!("pub mod {module} {{\n{body}}}\n"));
    }
    // The support functions, taken from the generated `mod.rs`.
    let mod_rs = render(&GeneratedMod { krate });
    if let Some(start) = mod_rs.find("/// Converts a variable") {
        out.push_str(&mod_rs[start..]);
    }
    format_generated(&out)
}

/// The converter stubs as user-file methods.
fn converter_methods(krate: &ir::Crate) -> Vec<ir::Method> {
    krate
        .types
        .converters
        .iter()
        .map(|c| ir::Method {
            name: c.method.clone(),
            doc: c.doc.clone(),
            signature: String::new(),
            user_signature: format!("fn {}(from: &{}) -> {}", c.method, c.user_from, c.user_to),
            stub_body: c.stub_body.lines().map(str::to_owned).collect(),
        })
        .collect()
}

/// User module names declared in `src/lib.rs`, in order.
pub fn user_modules(krate: &ir::Crate) -> Vec<String> {
    let mut modules = Vec::new();
    if !krate.types.converters.is_empty() {
        modules.push("converters".to_owned());
    }
    modules.extend(krate.atomics.iter().map(|a| a.module.clone()));
    modules.extend(krate.compounds.iter().map(|c| c.module.clone()));
    modules
}

/// The stubs of every user file, for merging.
pub fn stub_sets(krate: &ir::Crate) -> Vec<StubSet> {
    let stub = |m: &ir::Method| {
        (
            m.name.clone(),
            format_stub(&render(&UserStub { method: m })),
        )
    };
    let mut sets: Vec<StubSet> = krate
        .atomics
        .iter()
        .map(|c| StubSet {
            path: PathBuf::from(format!("src/{}.rs", c.module.trim_start_matches("r#"))),
            trait_name: "Behavior".to_owned(),
            stubs: c.methods.iter().map(stub).collect(),
        })
        .collect();
    sets.extend(krate.compounds.iter().map(|c| StubSet {
        path: PathBuf::from(format!("src/{}.rs", c.module.trim_start_matches("r#"))),
        trait_name: "Parts".to_owned(),
        stubs: c.parts.iter().map(stub).collect(),
    }));
    if !krate.types.converters.is_empty() {
        sets.push(StubSet {
            path: PathBuf::from("src/converters.rs"),
            trait_name: "Converters".to_owned(),
            stubs: converter_methods(krate).iter().map(stub).collect(),
        });
    }
    sets
}

/// Every file of the crate directory for `krate`.
pub fn emit_crate(krate: &ir::Crate) -> Vec<EmittedFile> {
    let generated = |path: String, contents: String| EmittedFile {
        path: PathBuf::from(path),
        contents,
        kind: FileKind::Generated,
    };
    let user = |path: String, contents: String| EmittedFile {
        path: PathBuf::from(path),
        contents,
        kind: FileKind::User,
    };
    let mut files = vec![generated(
        "Cargo.toml".to_owned(),
        render(&CargoToml { krate }) + "\n",
    )];
    if !krate.system_libs.is_empty() {
        files.push(generated(
            "build.rs".to_owned(),
            format_generated(&render(&BuildRs { krate })),
        ));
    }
    files.push(generated(
        "src/generated/mod.rs".to_owned(),
        generated_mod_rs(krate),
    ));
    for (module, text) in generated_modules(krate) {
        files.push(generated(
            format!("src/generated/{}.rs", module.trim_start_matches("r#")),
            text,
        ));
    }
    let modules = user_modules(krate);
    files.push(user(
        "src/lib.rs".to_owned(),
        format_user(&render(&UserLib { modules: &modules })),
    ));
    for c in &krate.atomics {
        files.push(user(
            format!("src/{}.rs", c.module.trim_start_matches("r#")),
            format_user(&render(&UserComponent { c })),
        ));
    }
    for c in &krate.compounds {
        files.push(user(
            format!("src/{}.rs", c.module.trim_start_matches("r#")),
            format_user(&render(&UserCompound { c })),
        ));
    }
    if !krate.types.converters.is_empty() {
        let methods = converter_methods(krate);
        files.push(user(
            "src/converters.rs".to_owned(),
            format_user(&render(&UserConverters { methods: &methods })),
        ));
    }
    files
}

#[derive(Template)]
#[template(path = "starter_component.rs", escape = "none")]
struct StarterComponent<'a> {
    c: &'a ir::Atomic,
}

#[derive(Template)]
#[template(path = "starter_main.rs", escape = "none")]
struct StarterMain<'a> {
    krate: &'a ir::Crate,
    c: &'a ir::Atomic,
}

/// The filled-in user file of the `coolc new` starter component.
pub fn starter_component(c: &ir::Atomic) -> String {
    format_user(&render(&StarterComponent { c }))
}

/// The `src/main.rs` of a `coolc new` crate: runs the starter component.
pub fn starter_main(krate: &ir::Crate, c: &ir::Atomic) -> String {
    format_user(&render(&StarterMain { krate, c }))
}
