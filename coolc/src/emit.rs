//! Emission: the IR printed through the askama templates in `templates/`, formatted.
//!
//! **Invariant:** emission cannot fail on user input. Every file but `build.rs` comes
//! out of its template already in `rustfmt`'s layout (see `layout`), so no formatter
//! runs for it. In a compound module, a top-level item whose layout `layout` is not
//! certain of (a rule function, the builder) is formatted alone, the rest of the file
//! kept. `build.rs`, and any file whose layout `layout` is not certain of outside such
//! items, are formatted with `rustfmt` when it is installed (one run over all of
//! them), else generated ones are printed with `prettyplease` (a compound module's
//! uncertain items alone) and user ones keep the templates' layout. The files are
//! rendered on every core. Each file is parsed at most once: by `rustfmt` or by `syn` for
//! `prettyplease`, and by `syn` in debug builds where no formatter parses it. A file
//! that does not parse is a template bug and panics with the offending text (the test
//! suite also compiles every generated crate). Output depends only on the IR.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use askama::Template;

use crate::layout::{ITEM_BEGIN, ITEM_END, ITEM_END_FORMAT, Layout};
use crate::par::par_map;
use crate::{ir, manifest};

/// Who owns an emitted file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FileKind {
    /// Rewritten by every compile.
    Generated,
    /// Written once, then only merged into (see `merge`).
    User,
    /// `Cargo.toml`: written whole once, then only coolc's own entries are updated
    /// (see `manifest`).
    Manifest,
    /// `src/main.rs`: written only by the compile that creates the crate (no
    /// `Cargo.toml` yet), never again.
    Starter,
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
pub(crate) struct StubSet {
    /// Path of the user file relative to the crate root.
    pub(crate) path: PathBuf,
    /// Last path segment of the trait the `impl` block implements.
    pub(crate) trait_name: String,
    /// `(method name, stub text)` in order; the text is indented for an impl block.
    pub(crate) stubs: Vec<(String, String)>,
}

/// How emission lays out the Rust files it writes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Formatting {
    /// Formatted for people: `rustfmt` when it is installed (the files are `cargo fmt`
    /// clean), else `prettyplease` for generated files. What `coolc compile` writes.
    #[default]
    Formatted,
    /// The templates' own layout: the same tokens, so the same Rust (it compiles and
    /// is warning-free exactly when the formatted files are), only not laid out for
    /// reading. Checked with `syn` in debug builds only. For output nobody reads, such
    /// as the [`crate::builder::Builder`]'s file in `OUT_DIR`; several times faster,
    /// since formatting is most of emission's cost.
    Unformatted,
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
    /// The module names, in rustfmt's order (`reorder_modules`).
    modules: Vec<String>,
}

/// The manifest as the first compile writes it: the template, its entries filled in
/// by `manifest::update`.
pub(crate) fn cargo_toml(krate: &ir::Crate) -> String {
    let template = render(&CargoToml { krate });
    match manifest::update(&template, krate, true) {
        Ok(updated) => updated.text,
        Err(error) => panic!("coolc bug: the manifest template does not update: {error}"),
    }
}

/// `modules` sorted as rustfmt orders `mod` declarations, and whether that order is
/// certain (raw identifiers are left to rustfmt).
fn rustfmt_module_order(mut modules: Vec<String>) -> (Vec<String>, bool) {
    modules.sort();
    let certain = !modules.iter().any(|m| m.starts_with("r#"));
    (modules, certain)
}

impl<'a> GeneratedMod<'a> {
    fn new(krate: &'a ir::Crate) -> (GeneratedMod<'a>, bool) {
        let (modules, certain) = rustfmt_module_order(krate.module_names());
        (GeneratedMod { krate, modules }, certain)
    }
}

#[derive(Template)]
#[template(path = "types.rs", escape = "none")]
struct TypesRs<'a> {
    krate: &'a ir::Crate,
    types: &'a ir::Types,
    l: Layout,
}

#[derive(Template)]
#[template(path = "atomic.rs", escape = "none")]
struct AtomicRs<'a> {
    krate: &'a ir::Crate,
    c: &'a ir::Atomic,
    l: Layout,
}

/// The typed test harness, appended to the atomic component's module.
#[derive(Template)]
#[template(path = "harness.rs", escape = "none")]
struct HarnessRs<'a> {
    c: &'a ir::Atomic,
    h: crate::lower::harness::Harness,
    l: Layout,
}

#[derive(Template)]
#[template(path = "compound.rs", escape = "none")]
struct CompoundRs<'a> {
    krate: &'a ir::Crate,
    c: &'a ir::Compound,
    l: Layout,
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
    l: Layout,
}

#[derive(Template)]
#[template(path = "user_compound.rs", escape = "none")]
struct UserCompound<'a> {
    c: &'a ir::Compound,
    l: Layout,
}

#[derive(Template)]
#[template(path = "user_converters.rs", escape = "none")]
struct UserConverters<'a> {
    methods: &'a [ir::Method],
    l: Layout,
}

#[derive(Template)]
#[template(path = "user_stub.rs", escape = "none")]
struct UserStub<'a> {
    method: &'a ir::Method,
}

/// A template's text, ending with one newline (askama drops the template file's
/// last one).
fn render(template: &impl Template) -> String {
    match template.render() {
        Ok(mut text) => {
            if !text.ends_with('\n') {
                text.push('\n');
            }
            text
        }
        Err(error) => panic!("coolc bug: a template failed to render: {error}"),
    }
}

/// Checks that generated Rust parses; a failure is a template bug.
fn check_parses(code: &str) -> syn::File {
    match syn::parse_file(code) {
        Ok(file) => file,
        Err(error) => panic!("coolc bug: emitted Rust does not parse ({error}):\n{code}"),
    }
}

/// [`check_parses`] in debug builds (and so in the test suite, which also compiles
/// every generated crate); nothing in release builds, where the parse would cost as
/// much as the rest of emission and only ever finds template bugs.
fn debug_check_parses(code: &str) {
    if cfg!(debug_assertions) {
        check_parses(code);
    }
}

/// Formats generated Rust without `rustfmt`: `prettyplease`, keeping the leading `//`
/// header lines (which `syn` drops). Its parse doubles as the template check.
fn pretty(code: &str) -> String {
    let file = check_parses(code);
    let mut out = String::with_capacity(code.len() + code.len() / 4);
    for line in code
        .lines()
        .take_while(|l| l.starts_with("//") && !l.starts_with("//!") && !l.starts_with("///"))
    {
        out.push_str(line);
        out.push('\n');
    }
    out.push_str(&prettyplease::unparse(&file));
    out
}

/// `text` with each of its items to format (see `Layout::begin_item`) printed by
/// `prettyplease` on its own, its markers removed, the rest kept as it is.
fn pretty_items(text: &str) -> String {
    let lines: Vec<&str> = text.split('\n').collect();
    let items: Vec<String> = items_to_format(text)
        .into_iter()
        .map(|range| prettyplease::unparse(&check_parses(&lines[range].join("\n"))))
        .collect();
    let printed = items.join(&format!("\n{ITEM_BOUNDARY}\n"));
    match with_formatted_items(text, &printed) {
        Some(text) => text,
        None => panic!("coolc bug: the items of a file do not match their printing"),
    }
}

fn rustfmt_program() -> std::ffi::OsString {
    std::env::var_os("RUSTFMT").unwrap_or_else(|| "rustfmt".into())
}

/// The version line of `rustfmt` (or of the program `RUSTFMT` names), `None` when it
/// does not run: probed once per process with `--version`, so that without it no
/// scratch tree is written and no process is spawned per file.
fn rustfmt_version() -> Option<&'static str> {
    static VERSION: std::sync::OnceLock<Option<String>> = std::sync::OnceLock::new();
    VERSION
        .get_or_init(|| {
            let output = Command::new(rustfmt_program())
                .arg("--version")
                .stdin(Stdio::null())
                .stderr(Stdio::null())
                .output()
                .ok()?;
            output
                .status
                .success()
                .then(|| String::from_utf8_lossy(&output.stdout).trim().to_owned())
        })
        .as_deref()
}

/// Whether `rustfmt` runs (see [`rustfmt_version`]).
fn rustfmt_installed() -> bool {
    rustfmt_version().is_some()
}

/// Runs `rustfmt --edition 2024` over `code`; `None` when it is not installed (see
/// [`rustfmt_installed`]) or fails.
fn rustfmt_stdin(code: &str) -> Option<String> {
    use std::io::Write;
    if !rustfmt_installed() {
        return None;
    }
    let mut child = Command::new(rustfmt_program())
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

/// Whether `text` declares out-of-line modules (`mod x;`), which `rustfmt` would go
/// and format too when given the file by path.
fn declares_modules(text: &str) -> bool {
    text.lines().any(|line| {
        let line = line.trim_start();
        (line.starts_with("mod ") || line.starts_with("pub mod ")) && line.ends_with(';')
    })
}

/// From how many files [`rustfmt_files`] splits the work over several processes.
const PATHS_PER_RUSTFMT: usize = 32;

/// Formats Rust files with `rustfmt`: the files that declare no modules with one run
/// (one per core for many files) over a scratch copy (given by path: no module of theirs is followed), the others
/// (`src/lib.rs`, a `mod.rs`) one by one from stdin. `None`, without writing
/// anything, when `rustfmt` is not installed; `None` when it fails (the caller falls
/// back to per-file formatting).
fn rustfmt_files(files: &[(&Path, &str)]) -> Option<Vec<String>> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    if !rustfmt_installed() || files.is_empty() {
        return None;
    }
    static SCRATCH: AtomicUsize = AtomicUsize::new(0);
    let dir = std::env::temp_dir().join(format!(
        "coolc-fmt-{}-{}",
        std::process::id(),
        SCRATCH.fetch_add(1, Ordering::Relaxed)
    ));
    let result = (|| {
        let mut paths = Vec::new();
        for (index, (path, text)) in files.iter().enumerate() {
            if declares_modules(text) {
                continue;
            }
            // Flat names: the scratch copy needs no directories.
            let name = format!("{index}-{}", path.file_name()?.to_string_lossy());
            let path = dir.join(name);
            paths.push((index, path));
        }
        if !paths.is_empty() {
            std::fs::create_dir_all(&dir).ok()?;
            for (index, path) in &paths {
                std::fs::write(path, files[*index].1).ok()?;
            }
            // Many files: one rustfmt per core, started together (each start costs
            // tens of milliseconds, so a few files go to one process).
            let processes = if paths.len() >= PATHS_PER_RUSTFMT {
                std::thread::available_parallelism()
                    .map_or(1, std::num::NonZero::get)
                    .min(paths.len() / (PATHS_PER_RUSTFMT / 2))
                    .max(1)
            } else {
                1
            };
            let chunk = paths.len().div_ceil(processes);
            let children: Vec<std::process::Child> = paths
                .chunks(chunk)
                .map(|part| {
                    Command::new(rustfmt_program())
                        .args(["--edition", "2024", "--quiet"])
                        .args(part.iter().map(|(_, path)| path))
                        .current_dir(&dir)
                        .stdout(Stdio::null())
                        .stderr(Stdio::null())
                        .spawn()
                })
                .collect::<Result<_, _>>()
                .ok()?;
            let mut ok = true;
            for mut child in children {
                ok &= child.wait().is_ok_and(|status| status.success());
            }
            if !ok {
                return None;
            }
        }
        let mut by_path = paths.into_iter().peekable();
        let mut out = Vec::with_capacity(files.len());
        for (index, (_, text)) in files.iter().enumerate() {
            match by_path.peek() {
                Some((at, path)) if *at == index => {
                    out.push(std::fs::read_to_string(path).ok()?);
                    by_path.next();
                }
                _ => out.push(rustfmt_stdin(text)?),
            }
        }
        Some(out)
    })();
    let _ = std::fs::remove_dir_all(&dir);
    result
}

/// Who formats generated code in this process, for caches of formatted files:
/// `rustfmt` and its version, or the built-in printer.
pub(crate) fn formatter_id() -> String {
    match rustfmt_version() {
        Some(version) => version.to_owned(),
        None => format!("prettyplease (coolc {})", env!("CARGO_PKG_VERSION")),
    }
}

/// A rendered template and whether it is already in `rustfmt`'s layout. A file in
/// that layout but for some of its items keeps their markers (see
/// `Layout::begin_item`) and is not: [`format_files`] formats those items alone.
fn render_laid_out<T: Template>(template: &T, layout: &Layout) -> (String, bool) {
    let text = render(template);
    if layout.ok() && text.contains(ITEM_END_FORMAT) {
        return (text, false);
    }
    (strip_items(&text), layout.ok())
}

/// Whether a marker line of an item (see `Layout::begin_item`).
fn is_item_marker(line: &str) -> bool {
    line == ITEM_BEGIN || line == ITEM_END || line == ITEM_END_FORMAT
}

/// `text` without the item marker lines.
fn strip_items(text: &str) -> String {
    if !text.contains(ITEM_BEGIN) {
        return text.to_owned();
    }
    let mut out = String::with_capacity(text.len());
    for line in text.split_inclusive('\n') {
        if !is_item_marker(line.trim_end_matches('\n')) {
            out.push_str(line);
        }
    }
    out
}

/// The items of `text` to format (see `Layout::begin_item`), each a range of
/// lines (marker lines excluded).
fn items_to_format(text: &str) -> Vec<std::ops::Range<usize>> {
    let mut items = Vec::new();
    let mut start = None;
    for (index, line) in text.split('\n').enumerate() {
        if line == ITEM_BEGIN {
            start = Some(index + 1);
        } else if line == ITEM_END_FORMAT {
            if let Some(start) = start.take() {
                items.push(start..index);
            }
        } else if line == ITEM_END {
            start = None;
        }
    }
    items
}

/// The comment line between two items given to `rustfmt` in one file.
const ITEM_BOUNDARY: &str = "// coolc: next item";

/// The items of `text` to format, as one Rust file for `rustfmt` (top-level items
/// are formatted each on its own, so each comes out as it would in `text`).
fn items_file(text: &str) -> String {
    let lines: Vec<&str> = text.split('\n').collect();
    let items: Vec<String> = items_to_format(text)
        .into_iter()
        .map(|range| lines[range].join("\n"))
        .collect();
    let mut out = items.join(&format!("\n\n{ITEM_BOUNDARY}\n\n"));
    out.push('\n');
    out
}

/// `text` with its items to format replaced by `formatted` (`rustfmt`'s output of
/// [`items_file`]), its markers removed; `None` when the items do not match.
fn with_formatted_items(text: &str, formatted: &str) -> Option<String> {
    let parts: Vec<&str> = formatted
        .split(&format!("\n{ITEM_BOUNDARY}\n"))
        .map(|part| part.trim_matches('\n'))
        .collect();
    let items = items_to_format(text);
    if parts.len() != items.len() {
        return None;
    }
    let lines: Vec<&str> = text.split('\n').collect();
    let mut out = String::with_capacity(text.len() + formatted.len());
    let mut next = 0;
    for (range, part) in items.iter().zip(parts) {
        for line in &lines[next..range.start] {
            if !is_item_marker(line) {
                out.push_str(line);
                out.push('\n');
            }
        }
        out.push_str(part);
        out.push('\n');
        next = range.end;
    }
    for (index, line) in lines[next..].iter().enumerate() {
        if !is_item_marker(line) {
            out.push_str(line);
            if next + index + 1 < lines.len() {
                out.push('\n');
            }
        }
    }
    Some(out)
}

/// Which files of a crate to render: all, those whose templates need a formatter,
/// or those whose templates are written in rustfmt's layout (see `layout`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Part {
    /// Every file.
    All,
    /// The files a formatter lays out: `build.rs`.
    NeedsFormatter,
    /// The others (some of which may still turn out to need the formatter).
    LaidOut,
}

impl Part {
    /// Whether a file whose template is (`laid_out`) or is not in rustfmt's layout
    /// belongs to this part.
    fn wants(self, laid_out: bool) -> bool {
        match self {
            Part::All => true,
            Part::NeedsFormatter => !laid_out,
            Part::LaidOut => laid_out,
        }
    }
}

/// The generated module texts as rendered: `(module name, text, already in rustfmt's
/// layout)`, `types` first.
fn render_modules(krate: &ir::Crate) -> Vec<(String, String, bool)> {
    render_modules_part(krate, Part::All)
}

/// [`render_modules`] of one [`Part`] (all of them are in rustfmt's layout but
/// where [`Layout`] says otherwise).
fn render_modules_part(krate: &ir::Crate, part: Part) -> Vec<(String, String, bool)> {
    if !part.wants(true) {
        return Vec::new();
    }
    let mut jobs = vec![Job::Types];
    jobs.extend(krate.atomics.iter().map(Job::Atomic));
    jobs.extend(krate.compounds.iter().map(Job::Compound));
    par_map(&jobs, |job| {
        let (module, (text, laid_out)) = match *job {
            Job::Types => (&krate.types.module, render_types(krate)),
            Job::Atomic(c) => (&c.module, render_atomic(krate, c)),
            Job::Compound(c) => (&c.module, render_compound(krate, c)),
            _ => unreachable!("only modules are listed"),
        };
        (module.clone(), text, laid_out)
    })
}

/// The types module and whether it is in rustfmt's layout.
fn render_types(krate: &ir::Crate) -> (String, bool) {
    let template = TypesRs {
        krate,
        types: &krate.types,
        l: Layout::default(),
    };
    render_laid_out(&template, &template.l)
}

/// An atomic component's module, its typed harness appended, and whether it is in
/// rustfmt's layout.
fn render_atomic(krate: &ir::Crate, c: &ir::Atomic) -> (String, bool) {
    let template = AtomicRs {
        krate,
        c,
        l: Layout::default(),
    };
    let (mut text, laid_out) = render_laid_out(&template, &template.l);
    let harness = HarnessRs {
        c,
        h: crate::lower::harness::harness(c),
        l: Layout::default(),
    };
    let (harness_text, harness_laid_out) = render_laid_out(&harness, &harness.l);
    text.push('\n');
    text.push_str(&harness_text);
    (text, laid_out && harness_laid_out)
}

/// A compound component's module and whether it is in rustfmt's layout.
fn render_compound(krate: &ir::Crate, c: &ir::Compound) -> (String, bool) {
    let template = CompoundRs {
        krate,
        c,
        l: Layout::default(),
    };
    render_laid_out(&template, &template.l)
}

/// Every generated module in one file, for `include!` from `OUT_DIR` (the
/// [`crate::builder::Builder`] output): `pub mod x { ... }` per module plus the
/// support functions, formatted with `prettyplease` (no process is needed).
pub fn single_file(krate: &ir::Crate) -> String {
    single_file_with(krate, Formatting::Formatted)
}

/// [`single_file`], formatted with `prettyplease` (one module per thread) or not at
/// all ([`Formatting::Unformatted`]).
pub fn single_file_with(krate: &ir::Crate, formatting: Formatting) -> String {
    single_file_parts(krate, formatting).concat()
}

/// [`single_file_with`] written to `out` part by part, without the whole file in one
/// more string (what the `Builder` of a build script writes; the file of 11,000
/// components is about 300 MiB).
pub fn write_single_file_with(
    krate: &ir::Crate,
    formatting: Formatting,
    out: &mut impl std::io::Write,
) -> std::io::Result<()> {
    for part in single_file_parts(krate, formatting) {
        out.write_all(part.as_bytes())?;
    }
    out.flush()
}

/// The single file in parts, in order: its header line first.
fn single_file_parts(krate: &ir::Crate, formatting: Formatting) -> Vec<String> {
    let modules = render_modules(krate);
    let mut parts: Vec<String> = par_map(&modules, |(module, text, _)| {
        // The module's text without its header line and item markers.
        let body = match text.split_once('\n') {
            Some((first, rest)) if first.starts_with("// @generated") => rest,
            _ => text.as_str(),
        };
        let body = if body.contains(ITEM_BEGIN) {
            std::borrow::Cow::Owned(strip_items(body))
        } else {
            std::borrow::Cow::Borrowed(body)
        };
        let mut part = String::with_capacity(body.len() + module.len() + 16);
        part.push_str("pub mod ");
        part.push_str(module);
        part.push_str(" {\n");
        part.push_str(&body);
        if !body.ends_with('\n') {
            part.push('\n');
        }
        part.push_str("}\n");
        part
    });
    // The support functions, taken from the generated `mod.rs`.
    let mod_rs = render(&GeneratedMod::new(krate).0);
    if let Some(start) = mod_rs.find("/// Converts a variable") {
        parts.push(mod_rs[start..].to_owned());
    }
    let mut parts = match formatting {
        Formatting::Formatted => par_map(&parts, |part| prettyplease::unparse(&check_parses(part))),
        Formatting::Unformatted => {
            if cfg!(debug_assertions) {
                par_map(&parts, |part| debug_check_parses(part));
            }
            parts
        }
    };
    let mut header = krate.header();
    header.push('\n');
    parts.insert(0, header);
    parts
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
            stub_body: c.stub_body.clone(),
        })
        .collect()
}

/// User module names declared in `src/lib.rs`, in order.
pub(crate) fn user_modules(krate: &ir::Crate) -> Vec<String> {
    let mut modules = Vec::new();
    if !krate.types.converters.is_empty() {
        modules.push("converters".to_owned());
    }
    modules.extend(krate.atomics.iter().map(|a| a.module.clone()));
    modules.extend(krate.compounds.iter().map(|c| c.module.clone()));
    modules
}

/// The text of method `name` in a formatted user file: from its `    fn name(` line to
/// the closing `    }` line, both included.
fn extract_stub(text: &str, name: &str) -> Option<String> {
    let start = text.find(&format!("\n    fn {name}("))? + 1;
    let end = start + text[start..].find("\n    }\n")? + "\n    }\n".len();
    Some(text[start..end].to_owned())
}

/// The stubs of every user file, for merging, taken from the emitted user files
/// `files` (so they are formatted like a fresh file).
pub(crate) fn stub_sets(krate: &ir::Crate, files: &[EmittedFile]) -> Vec<StubSet> {
    let by_path: std::collections::HashMap<&Path, &str> = files
        .iter()
        .map(|f| (f.path.as_path(), f.contents.as_str()))
        .collect();
    let set = |path: PathBuf, trait_name: &str, methods: &[ir::Method]| {
        let text = by_path.get(path.as_path()).copied();
        StubSet {
            trait_name: trait_name.to_owned(),
            stubs: methods
                .iter()
                .map(|m| {
                    let stub = text
                        .and_then(|t| extract_stub(t, &m.name))
                        .unwrap_or_else(|| render(&UserStub { method: m }));
                    (m.name.clone(), stub)
                })
                .collect(),
            path,
        }
    };
    let mut sets: Vec<StubSet> = krate
        .atomics
        .iter()
        .map(|c| set(user_path(&c.module), "Behavior", &c.methods))
        .collect();
    for c in &krate.compounds {
        sets.push(set(user_path(&c.module), "Supervisor", &c.methods));
        sets.push(set(user_path(&c.module), "Parts", &c.parts));
    }
    if !krate.types.converters.is_empty() {
        sets.push(set(
            PathBuf::from("src/converters.rs"),
            "Converters",
            &converter_methods(krate),
        ));
    }
    sets
}

fn user_path(module: &str) -> PathBuf {
    PathBuf::from(format!("src/{}.rs", module.trim_start_matches("r#")))
}

/// Every file of the crate directory for `krate`, formatted (one `rustfmt` run for
/// the whole crate when it is installed, `prettyplease` for generated files
/// otherwise).
pub fn emit_crate(krate: &ir::Crate) -> Vec<EmittedFile> {
    emit_crate_with(krate, Formatting::Formatted)
}

/// [`emit_crate`], formatted or not (see [`Formatting`]).
pub(crate) fn emit_crate_with(krate: &ir::Crate, formatting: Formatting) -> Vec<EmittedFile> {
    let (mut files, laid_out) = render_crate(krate);
    match formatting {
        Formatting::Formatted => {
            let needs: Vec<bool> = laid_out.iter().map(|l| !l).collect();
            format_files(&mut files, &needs);
        }
        Formatting::Unformatted => {
            for file in &mut files {
                file.contents = strip_items(&file.contents);
            }
            if cfg!(debug_assertions) {
                par_map(&files, |f| {
                    if is_rust(&f.path) {
                        debug_check_parses(&f.contents);
                    }
                });
            }
        }
    }
    files
}

fn is_rust(path: &Path) -> bool {
    path.extension().is_some_and(|e| e == "rs")
}

/// Every file of the crate for `krate` as its template renders it, and for each
/// whether it is already in `rustfmt`'s layout (so needs no formatter; non-Rust files
/// count as laid out).
pub fn render_crate(krate: &ir::Crate) -> (Vec<EmittedFile>, Vec<bool>) {
    render_crate_part(krate, Part::All)
}

/// [`render_crate`] of one [`Part`] (the files in the same order).
pub(crate) fn render_crate_part(krate: &ir::Crate, part: Part) -> (Vec<EmittedFile>, Vec<bool>) {
    // Only `build.rs` is written for the formatter.
    let mut jobs = Vec::new();
    if part.wants(true) {
        jobs.push(Job::Manifest);
    }
    if !krate.system_libs.is_empty() && part.wants(false) {
        jobs.push(Job::BuildRs);
    }
    if part.wants(true) {
        jobs.push(Job::GeneratedMod);
        jobs.push(Job::Types);
        jobs.extend(krate.atomics.iter().map(Job::Atomic));
        jobs.extend(krate.compounds.iter().map(Job::Compound));
        jobs.push(Job::UserLib);
        jobs.extend(krate.atomics.iter().map(Job::UserAtomic));
        jobs.extend(krate.compounds.iter().map(Job::UserCompound));
        if !krate.types.converters.is_empty() {
            jobs.push(Job::Converters);
        }
        jobs.push(Job::Main);
        if !krate.starter.tests.is_empty() {
            jobs.push(Job::Tests);
        }
    }
    // The files are independent: rendered on every core.
    par_map(&jobs, |job| job.render(krate)).into_iter().unzip()
}

/// One file of a crate to render.
#[derive(Clone, Copy, Debug)]
enum Job<'a> {
    Manifest,
    BuildRs,
    GeneratedMod,
    Types,
    Atomic(&'a ir::Atomic),
    Compound(&'a ir::Compound),
    UserLib,
    UserAtomic(&'a ir::Atomic),
    UserCompound(&'a ir::Compound),
    Converters,
    Main,
    Tests,
}

impl Job<'_> {
    /// The file and whether it is in rustfmt's layout.
    fn render(self, krate: &ir::Crate) -> (EmittedFile, bool) {
        let file = |path: PathBuf, (contents, laid_out): (String, bool), kind| {
            (
                EmittedFile {
                    path,
                    contents,
                    kind,
                },
                laid_out,
            )
        };
        let generated = |module: &str| {
            PathBuf::from(format!(
                "src/generated/{}.rs",
                module.trim_start_matches("r#")
            ))
        };
        match self {
            Job::Manifest => file(
                "Cargo.toml".into(),
                (cargo_toml(krate), true),
                FileKind::Manifest,
            ),
            Job::BuildRs => file(
                "build.rs".into(),
                (render(&BuildRs { krate }), false),
                FileKind::Generated,
            ),
            Job::GeneratedMod => {
                let (template, certain) = GeneratedMod::new(krate);
                file(
                    "src/generated/mod.rs".into(),
                    (render(&template), certain),
                    FileKind::Generated,
                )
            }
            Job::Types => file(
                generated(&krate.types.module),
                render_types(krate),
                FileKind::Generated,
            ),
            Job::Atomic(c) => file(
                generated(&c.module),
                render_atomic(krate, c),
                FileKind::Generated,
            ),
            Job::Compound(c) => file(
                generated(&c.module),
                render_compound(krate, c),
                FileKind::Generated,
            ),
            Job::UserLib => {
                let (modules, certain) = rustfmt_module_order(user_modules(krate));
                file(
                    "src/lib.rs".into(),
                    (render(&UserLib { modules: &modules }), certain),
                    FileKind::User,
                )
            }
            Job::UserAtomic(c) => {
                let template = UserComponent {
                    c,
                    l: Layout::default(),
                };
                file(
                    user_path(&c.module),
                    render_laid_out(&template, &template.l),
                    FileKind::User,
                )
            }
            Job::UserCompound(c) => {
                let template = UserCompound {
                    c,
                    l: Layout::default(),
                };
                file(
                    user_path(&c.module),
                    render_laid_out(&template, &template.l),
                    FileKind::User,
                )
            }
            Job::Converters => {
                let methods = converter_methods(krate);
                let template = UserConverters {
                    methods: &methods,
                    l: Layout::default(),
                };
                file(
                    "src/converters.rs".into(),
                    render_laid_out(&template, &template.l),
                    FileKind::User,
                )
            }
            Job::Main => file(
                "src/main.rs".into(),
                render_starter_main(krate),
                FileKind::Starter,
            ),
            Job::Tests => file(
                "tests/components.rs".into(),
                render_starter_tests(krate),
                FileKind::Starter,
            ),
        }
    }
}

/// Formats the Rust files of `files` marked in `needs` (see the module doc); the
/// others are checked to parse in debug builds.
pub(crate) fn format_files(files: &mut [EmittedFile], needs: &[bool]) {
    let selected: Vec<usize> = (0..files.len())
        .filter(|&i| needs[i] && is_rust(&files[i].path))
        .collect();
    if cfg!(debug_assertions) {
        par_map(files, |f| {
            if is_rust(&f.path) {
                debug_check_parses(&strip_items(&f.contents));
            }
        });
    }
    // A file with items to format gives rustfmt those items only.
    let inputs: Vec<String> = selected
        .iter()
        .map(|&i| {
            let text = &files[i].contents;
            if text.contains(ITEM_END_FORMAT) {
                items_file(text)
            } else {
                text.clone()
            }
        })
        .collect();
    let rust: Vec<(&Path, &str)> = selected
        .iter()
        .zip(&inputs)
        .map(|(&i, input)| (files[i].path.as_path(), input.as_str()))
        .collect();
    // rustfmt fails on Rust that does not parse, and then the fallback below parses
    // every file: a template bug is caught on both paths.
    let formatted: Vec<Option<String>> = match rustfmt_files(&rust) {
        Some(formatted) => selected
            .iter()
            .zip(formatted)
            .map(|(&i, new)| {
                let text = &files[i].contents;
                if !text.contains(ITEM_END_FORMAT) {
                    return Some(new);
                }
                with_formatted_items(text, &new).or_else(|| rustfmt_stdin(&strip_items(text)))
            })
            .collect(),
        // The files are independent: print them on every core.
        None => par_map(&selected, |&i| {
            let file = &files[i];
            // Without rustfmt, user files keep the templates' own layout
            // (`prettyplease` would drop their comments); a file with items to
            // format gets those printed, each on its own, and keeps the rest.
            (file.kind == FileKind::Generated).then(|| {
                if file.contents.contains(ITEM_END_FORMAT) {
                    pretty_items(&file.contents)
                } else {
                    pretty(&strip_items(&file.contents))
                }
            })
        }),
    };
    for (i, new) in selected.into_iter().zip(formatted) {
        match new {
            Some(new) => files[i].contents = new,
            None => files[i].contents = strip_items(&files[i].contents),
        }
    }
}

/// Formats one hand-laid-out user file (comments matter) with `rustfmt` when it is
/// installed (which fails on Rust that does not parse); checked in debug builds
/// otherwise.
fn format_user(code: &str) -> String {
    rustfmt_stdin(code).unwrap_or_else(|| {
        debug_check_parses(code);
        code.to_owned()
    })
}

#[derive(Template)]
#[template(path = "starter_component.rs", escape = "none")]
struct StarterComponent<'a> {
    c: &'a ir::Atomic,
}

#[derive(Template)]
#[template(path = "starter_main.rs", escape = "none")]
struct StarterMain<'a> {
    starter: &'a ir::Starter,
    l: Layout,
}

/// The filled-in user file of the `coolc new` starter component.
pub fn starter_component(c: &ir::Atomic) -> String {
    format_user(&render(&StarterComponent { c }))
}

#[derive(Template)]
#[template(path = "starter_test.rs", escape = "none")]
struct StarterTest<'a> {
    c: &'a ir::Atomic,
    lib: &'a str,
}

/// The test `coolc new` writes for its starter component (in the crate's `tests/`):
/// it drives the component in its generated harness.
pub(crate) fn starter_test(krate: &ir::Crate, c: &ir::Atomic) -> String {
    format_user(&render(&StarterTest {
        c,
        lib: &krate.lib_name,
    }))
}

#[derive(Template)]
#[template(path = "starter_tests.rs", escape = "none")]
struct StarterTests<'a> {
    tests: &'a [ir::StarterTest],
    l: Layout,
}

/// The `tests/components.rs` written into a crate being created (when it has an
/// atomic component), and whether it is in rustfmt's layout: one test per atomic
/// component, which runs it in its generated harness for a second of virtual time
/// from its stubs.
fn render_starter_tests(krate: &ir::Crate) -> (String, bool) {
    let template = StarterTests {
        tests: &krate.starter.tests,
        l: Layout::default(),
    };
    render_laid_out(&template, &template.l)
}

/// The `src/main.rs` of a new crate, and whether it is in rustfmt's layout: runs
/// every component no compound instantiates, for two seconds.
fn render_starter_main(krate: &ir::Crate) -> (String, bool) {
    let template = StarterMain {
        starter: &krate.starter,
        l: Layout::default(),
    };
    render_laid_out(&template, &template.l)
}

/// `render_starter_main`, formatted like a user file.
pub fn starter_main(krate: &ir::Crate) -> String {
    match render_starter_main(krate) {
        (text, true) => text,
        (text, false) => format_user(&text),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Without rustfmt, a file's items to format are printed by `prettyplease`, each
    /// on its own; the rest of the file keeps its layout.
    #[test]
    fn without_rustfmt_marked_items_alone_are_printed() {
        let text = format!(
            "//! Module.\n\nfn   kept( ) {{}}\n\n{ITEM_BEGIN}\n/// Doc.\nfn   messy( ) -> u8 {{ 1 }}\n{ITEM_END_FORMAT}\n"
        );
        assert_eq!(
            pretty_items(&text),
            "//! Module.\n\nfn   kept( ) {}\n\n/// Doc.\nfn messy() -> u8 {\n    1\n}\n"
        );
    }

    /// A file whose second item is marked for the formatter: only that item goes to
    /// it, and its formatted text replaces it, markers gone.
    #[test]
    fn marked_items_alone_are_formatted() {
        let text = format!(
            "//! Module.\n\n{ITEM_BEGIN}\nfn kept() {{}}\n{ITEM_END}\n\n{ITEM_BEGIN}\n/// Doc.\nfn   messy( ) {{ 1 }}\n{ITEM_END_FORMAT}\n\nfn tail() {{}}\n"
        );
        let items = items_file(&text);
        assert_eq!(items, "/// Doc.\nfn   messy( ) { 1 }\n");
        let formatted = "/// Doc.\nfn messy() {\n    1\n}\n";
        assert_eq!(
            with_formatted_items(&text, formatted).as_deref(),
            Some(
                "//! Module.\n\nfn kept() {}\n\n/// Doc.\nfn messy() {\n    1\n}\n\nfn tail() {}\n"
            )
        );
        // Output that does not split into as many items is refused.
        let two = format!("{formatted}\n{ITEM_BOUNDARY}\n\nfn other() {{}}\n");
        assert_eq!(with_formatted_items(&text, &two), None);
        assert_eq!(
            strip_items(&text),
            "//! Module.\n\nfn kept() {}\n\n/// Doc.\nfn   messy( ) { 1 }\n\nfn tail() {}\n"
        );
    }
}
