//! The `coolc` command line: `check`, `compile`, `new` and `diagram`.
//!
//! Exit codes: 0 when there is no error, 1 when the descriptions have errors
//! (diagnostics) or, for `compile --check`, when files would change, 2 for usage and
//! I/O errors. Diagnostics go to stderr rendered for a
//! person (colour only when stderr is a terminal and `NO_COLOR` is unset), or to
//! stdout as JSON lines with `--message-format json`.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand, ValueEnum};

use crate::ir::RuntimeDep;
use crate::{
    Checked, RenderFormat, RenderOptions, diagram, emit, fingerprint, ident, lower, manifest, merge,
};

/// Exit code: no error.
pub(crate) const EXIT_OK: u8 = 0;
/// Exit code: the descriptions have errors.
pub(crate) const EXIT_DIAGNOSTICS: u8 = 1;
/// Exit code: bad usage or an I/O error.
pub(crate) const EXIT_USAGE: u8 = 2;

/// Compile CoolBOT `.cool` component descriptions into Rust crates.
#[derive(Debug, Parser)]
#[command(name = "coolc", version, about, propagate_version = true)]
pub struct Cli {
    /// How diagnostics are printed: `human` (stderr) or `json` (one object per line
    /// on stdout; `compile --check` lists the files that would change the same way).
    #[arg(long, value_enum, default_value_t = MessageFormat::Human, global = true)]
    pub(crate) message_format: MessageFormat,

    /// A directory of ROS 2 interface packages (`DIR/<package>/msg/<Type>.msg`) where
    /// `import ros` types are looked up, before `AMENT_PREFIX_PATH` and the types
    /// coolc ships; repeat it for several, searched in order.
    #[arg(long = "ros-path", value_name = "DIR", global = true)]
    pub(crate) ros_paths: Vec<PathBuf>,

    /// The command.
    #[command(subcommand)]
    pub(crate) command: Commands,
}

/// Diagnostic output formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(crate) enum MessageFormat {
    /// Rendered for a person, on stderr.
    Human,
    /// JSON lines on stdout, for editors and CI.
    Json,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub(crate) enum Commands {
    /// Check descriptions and report every error, without writing anything.
    Check {
        /// The `.cool` files (their imports are followed).
        #[arg(required = true)]
        files: Vec<PathBuf>,
    },
    /// Compile descriptions into a crate directory (generated code and user stubs).
    Compile {
        /// The `.cool` files (their imports are followed).
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// The crate directory to write (created when missing; user code in it is kept).
        #[arg(short, long)]
        out: PathBuf,
        /// The Cargo package name (default: the name in the crate's `Cargo.toml`, else
        /// the output directory's name).
        #[arg(long)]
        name: Option<String>,
        /// Where the runtime is found (default for an existing crate: its `Cargo.toml`'s
        /// `coolbot` entry, kept as it is).
        #[command(flatten)]
        runtime: RuntimeArgs,
        /// Write nothing: list the files a compile would change and exit with 1 when
        /// there are any, 0 when the crate is up to date (for CI).
        #[arg(long)]
        check: bool,
    },
    /// Draw components as diagrams (Graphviz DOT or mermaid): interfaces, the
    /// structure of compounds, automata and supervisors.
    Diagram {
        /// The `.cool` files (their imports are followed).
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// The component to draw (any loaded file; default: every component of the
        /// files given).
        #[arg(long)]
        component: Option<String>,
        /// Which view.
        #[arg(long, value_enum, default_value_t = ViewArg::All)]
        view: ViewArg,
        /// The output format (`markdown`: a heading and a mermaid block per diagram).
        #[arg(long, value_enum, default_value_t = DiagramFormat::Dot)]
        format: DiagramFormat,
        /// Draw automata inside the default automaton's `running` state.
        #[arg(long)]
        default_automaton: bool,
        /// Write to this file instead of stdout.
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
    /// Create a new component crate with a starter description that builds and runs.
    New {
        /// The crate directory and package name (e.g. `blinker`): the last path
        /// component must be a valid package name, as for `cargo new`.
        name: String,
        /// Where the runtime is found.
        #[command(flatten)]
        runtime: RuntimeArgs,
    },
}

/// The views of `coolc diagram`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(crate) enum ViewArg {
    /// Ports by kind and direction, the default ports `c` and `m`, variables.
    Interface,
    /// A compound's instances, connections, exports, policies and groups.
    Structure,
    /// The user automaton or the supervisor.
    Automaton,
    /// Every view that applies.
    All,
}

/// The formats of `coolc diagram`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(crate) enum DiagramFormat {
    /// Graphviz DOT (`dot -Tsvg`).
    Dot,
    /// One mermaid flowchart.
    Mermaid,
    /// Markdown with one mermaid block per diagram.
    Markdown,
}

/// How the generated `Cargo.toml` names the runtime crate `coolbot`.
#[derive(Debug, Args)]
#[group(multiple = false)]
pub(crate) struct RuntimeArgs {
    /// Depend on the runtime by path (default: this coolc's own `runtime/` directory
    /// when it exists).
    #[arg(long)]
    pub(crate) runtime_path: Option<PathBuf>,
    /// Depend on the runtime by version from crates.io.
    #[arg(long)]
    pub(crate) runtime_version: Option<String>,
}

impl RuntimeArgs {
    /// Whether an option was given.
    fn given(&self) -> bool {
        self.runtime_path.is_some() || self.runtime_version.is_some()
    }

    /// The runtime dependency of a crate written to `out`.
    fn dep(&self, out: &Path) -> RuntimeDep {
        if let Some(version) = &self.runtime_version {
            return RuntimeDep::Version(version.clone());
        }
        let path = match &self.runtime_path {
            Some(path) => std::path::absolute(path).unwrap_or_else(|_| path.clone()),
            None => match repository_runtime() {
                Some(path) => path,
                None => return RuntimeDep::Version("0.1".to_owned()),
            },
        };
        RuntimeDep::Path(runtime_path_from(&path, out).display().to_string())
    }
}

/// The `runtime/` directory of the repository this coolc was built from, if it still
/// exists.
pub(crate) fn repository_runtime() -> Option<PathBuf> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../runtime");
    let path = path.canonicalize().ok()?;
    path.join("Cargo.toml").exists().then_some(path)
}

/// How the manifest in `out` names `runtime`: relative when `out` lies inside the
/// directory holding the runtime (a crate inside the repository stays relocatable),
/// absolute otherwise.
pub(crate) fn runtime_path_from(runtime: &Path, out: &Path) -> PathBuf {
    let out = std::path::absolute(out).unwrap_or_else(|_| out.to_path_buf());
    let out = normalize(&out);
    let runtime = normalize(runtime);
    let Some(root) = runtime.parent() else {
        return runtime;
    };
    let Ok(below) = out.strip_prefix(root) else {
        return runtime;
    };
    let mut relative = PathBuf::new();
    for _ in below.components() {
        relative.push("..");
    }
    relative.push(runtime.file_name().unwrap_or_default());
    relative
}

/// Removes `.` and resolves `..` lexically.
fn normalize(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for component in path.components() {
        match component {
            std::path::Component::CurDir => {}
            std::path::Component::ParentDir => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out
}

/// Runs the CLI on parsed arguments.
pub fn run(cli: Cli) -> ExitCode {
    let result = match &cli.command {
        Commands::Check { files } => check(&cli, files).map(|checked| {
            // Silence would leave a person wondering whether anything was checked.
            if cli.message_format == MessageFormat::Human {
                let warnings = checked.warnings().len();
                eprintln!(
                    "coolc: {} description file(s) checked: no error{}",
                    checked.sources().files().len(),
                    if warnings == 0 {
                        String::new()
                    } else {
                        format!(", {warnings} warning(s)")
                    }
                );
            }
        }),
        Commands::Compile {
            files,
            out,
            name,
            runtime,
            check,
        } => package_for(name.as_deref(), out).and_then(|package| {
            let options = merge::WriteOptions {
                check: *check,
                keep_runtime: !runtime.given(),
            };
            compile(&cli, files, out, &package, runtime.dep(out), options).map(|_| ())
        }),
        Commands::New { name, runtime } => new(&cli, Path::new(name), runtime.dep(Path::new(name))),
        Commands::Diagram {
            files,
            component,
            view,
            format,
            default_automaton,
            output,
        } => {
            let options = diagram::Options {
                component: component.clone(),
                views: match view {
                    ViewArg::Interface => vec![diagram::View::Interface],
                    ViewArg::Structure => vec![diagram::View::Structure],
                    ViewArg::Automaton => vec![diagram::View::Automaton],
                    ViewArg::All => Vec::new(),
                },
                default_automaton: *default_automaton,
            };
            let format = match format {
                DiagramFormat::Dot => diagram::Format::Dot,
                DiagramFormat::Mermaid => diagram::Format::Mermaid,
                DiagramFormat::Markdown => diagram::Format::Markdown,
            };
            draw(&cli, files, &options, format, output.as_deref())
        }
    };
    match result {
        Ok(()) => ExitCode::from(EXIT_OK),
        Err(Failure::Diagnostics | Failure::Stale) => ExitCode::from(EXIT_DIAGNOSTICS),
        Err(Failure::Usage(message)) => {
            eprintln!("error: {message}");
            ExitCode::from(EXIT_USAGE)
        }
    }
}

enum Failure {
    /// Already rendered.
    Diagnostics,
    /// `compile --check`: files would change (already listed).
    Stale,
    /// A usage or I/O error message.
    Usage(String),
}

/// The package name of `coolc compile`'s crate: the one given (checked as `coolc new`
/// checks it), else the existing manifest's (the name given once is kept), else one
/// made from the directory's name; when that is no valid package name (`-o gen`: a
/// keyword), `cool-` goes before it, and the compile says so.
fn package_for(given: Option<&str>, out: &Path) -> Result<String, Failure> {
    if let Some(name) = given {
        // The name as the crate gets it (lowercase, `-` separated) is what cargo and
        // Rust see: `Type` is `type`, a keyword.
        return match name_error(name) {
            Some(why) => Err(Failure::Usage(format!(
                "invalid package name `{name}` (--name): {why}; pass a name such as `blinker` or `my-robot`"
            ))),
            None => Ok(name.to_owned()),
        };
    }
    if let Some(name) = std::fs::read_to_string(out.join("Cargo.toml"))
        .ok()
        .and_then(|text| manifest::package_name(&text))
    {
        return Ok(name);
    }
    let dir = dir_name(out);
    let name = lower::package_name(&dir);
    let Some(why) = package_name_error(&name) else {
        return Ok(name);
    };
    let chosen = format!("cool-{name}");
    let as_package = if name == dir {
        String::new()
    } else {
        format!(", as a package name `{name}`")
    };
    eprintln!(
        "coolc: `{dir}`{as_package} cannot name the package ({why}): it is named `{chosen}`; pass --name to choose another"
    );
    Ok(chosen)
}

fn dir_name(path: &Path) -> String {
    std::path::absolute(path)
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "cool-components".to_owned())
}

fn render_options(cli: &Cli) -> RenderOptions {
    match cli.message_format {
        MessageFormat::Json => RenderOptions::json(),
        MessageFormat::Human => RenderOptions {
            format: RenderFormat::Graphical,
            colour: std::io::stderr().is_terminal() && std::env::var_os("NO_COLOR").is_none(),
            width: 100,
        },
    }
}

/// Analyzes `files`, prints the diagnostics, fails when there are errors.
fn check(cli: &Cli, files: &[PathBuf]) -> Result<Checked, Failure> {
    for file in files {
        if let Err(error) = std::fs::metadata(file) {
            return Err(Failure::Usage(format!(
                "cannot read {}: {error}",
                file.display()
            )));
        }
    }
    for dir in &cli.ros_paths {
        if !dir.is_dir() {
            return Err(Failure::Usage(format!(
                "--ros-path {}: not a directory",
                dir.display()
            )));
        }
    }
    let analysis = crate::analyze_files(
        files,
        &crate::ros::Search::from_env(cli.ros_paths.iter().cloned()),
    );
    if !analysis.diagnostics.is_empty() {
        let rendered = analysis.render(render_options(cli));
        match cli.message_format {
            MessageFormat::Json => print!("{rendered}"),
            MessageFormat::Human => eprint!("{rendered}"),
        }
    }
    analysis.checked().map_err(|analysis| {
        if cli.message_format == MessageFormat::Human {
            eprintln!("coolc: {} error(s)", analysis.error_count());
        }
        Failure::Diagnostics
    })
}

fn compile(
    cli: &Cli,
    files: &[PathBuf],
    out: &Path,
    package: &str,
    runtime: RuntimeDep,
    write: merge::WriteOptions,
) -> Result<crate::ir::Crate, Failure> {
    let mut timings = crate::Timings::from_env();
    let checked = check(cli, files)?;
    timings.span("check");
    let options = lower::Options {
        package: package.to_owned(),
        runtime,
        sources: files
            .iter()
            .map(|f| {
                f.file_name().map_or_else(
                    || f.display().to_string(),
                    |n| n.to_string_lossy().into_owned(),
                )
            })
            .collect(),
        inputs: fingerprint::inputs(checked.sources().files()),
    };
    let krate = lower::lower(&checked, &options);
    timings.span("lower");
    if !write.check {
        left_out(out, files, &checked, &krate)?;
    }
    let report = merge::write_crate_with(out, &krate, write)
        .map_err(|e| Failure::Usage(format!("cannot write {}: {e}", out.display())))?;
    if write.check {
        return check_report(out, &report, cli.message_format).map(|()| krate);
    }
    for (file, methods) in &report.added {
        eprintln!("coolc: added to {}: {}", file.display(), methods.join(", "));
    }
    for file in &report.removed {
        eprintln!("coolc: removed {} (no longer generated)", file.display());
    }
    for warning in &report.warnings {
        eprintln!("warning: {warning}");
    }
    eprintln!(
        "coolc: wrote {} ({} file(s) changed)",
        out.display(),
        report.written.len()
    );
    Ok(krate)
}

/// Refuses a compile that would remove a component's generated module, whose user
/// file stays, while a description in the crate's directory is not among the
/// compile's: most likely the one that describes it, left out of the command line
/// (the crate's components are compiled together). Deleting a description removes
/// its components; a compile of every description keeps them.
fn left_out(
    out: &Path,
    files: &[PathBuf],
    checked: &Checked,
    krate: &crate::ir::Crate,
) -> Result<(), Failure> {
    let orphaned = merge::orphaned_user_files(out, krate);
    if orphaned.is_empty() {
        return Ok(());
    }
    let compiled: Vec<PathBuf> = checked
        .sources()
        .files()
        .iter()
        .filter_map(|file| std::fs::canonicalize(&file.path).ok())
        .collect();
    let mut undescribed = Vec::new();
    descriptions_under(out, 0, &mut undescribed);
    undescribed
        .retain(|path| std::fs::canonicalize(path).is_ok_and(|path| !compiled.contains(&path)));
    if undescribed.is_empty() {
        return Ok(());
    }
    undescribed.sort();
    let shown = |path: &Path| path.strip_prefix(".").unwrap_or(path).display().to_string();
    let removed: Vec<String> = orphaned
        .iter()
        .map(|user| {
            let name = user.file_name().unwrap_or_default();
            format!(
                "{} (which {} uses)",
                shown(&out.join("src/generated").join(name)),
                shown(&out.join(user))
            )
        })
        .collect();
    let command: Vec<String> = files
        .iter()
        .chain(&undescribed)
        .map(|path| shown(path))
        .collect();
    Err(Failure::Usage(format!(
        "this compile would remove {}, and {} in the crate is not among its descriptions: \
         compile every description of the crate together (coolc compile {} -o {}); a \
         component meant to go: delete its description, or its user file and its `pub mod` \
         line in src/lib.rs. Nothing was written.",
        removed.join(", "),
        undescribed
            .iter()
            .map(|path| shown(path))
            .collect::<Vec<_>>()
            .join(", "),
        command.join(" "),
        out.display()
    )))
}

/// The `.cool` files of the crate at `dir`: under it, not in `target/`, a hidden
/// directory, another crate (a directory with a `Cargo.toml`) or a linked directory,
/// at most a few levels down.
fn descriptions_under(dir: &Path, depth: usize, found: &mut Vec<PathBuf>) {
    const DEPTH: usize = 4;
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let name = entry.file_name();
        let name = name.to_string_lossy();
        let Ok(kind) = entry.file_type() else {
            continue;
        };
        if kind.is_dir() {
            if depth < DEPTH
                && !name.starts_with('.')
                && name != "target"
                && !path.join("Cargo.toml").exists()
            {
                descriptions_under(&path, depth + 1, found);
            }
        } else if kind.is_file() && path.extension().is_some_and(|e| e == "cool") {
            found.push(path);
        }
    }
}

/// A file `compile --check` found out of date, as one JSON line
/// (`--message-format json`).
#[derive(Debug, serde::Serialize)]
struct StaleFile<'a> {
    /// Always `"stale_file"`: what the line is.
    reason: &'static str,
    /// The file, under the output directory.
    path: String,
    /// `"write"` (created or rewritten), `"add_stubs"` (stubs added to a user
    /// file) or `"remove"` (generated before, no longer).
    change: &'static str,
    /// The methods whose stubs would be added (`add_stubs` only).
    #[serde(skip_serializing_if = "<[String]>::is_empty")]
    methods: &'a [String],
}

/// `compile --check`: lists on stdout every file the compile would write, add stubs
/// to or remove (one path per line, or one JSON object per line in `json` format);
/// fails when there is one.
fn check_report(out: &Path, report: &merge::Report, format: MessageFormat) -> Result<(), Failure> {
    for warning in &report.warnings {
        eprintln!("warning: {warning}");
    }
    // Per file, one change: a removal or stub insertion says more than a write.
    let mut changed: std::collections::BTreeMap<&Path, (&'static str, &[String])> =
        std::collections::BTreeMap::new();
    for file in &report.written {
        changed.insert(file, ("write", &[]));
    }
    for (file, methods) in &report.added {
        changed.insert(file, ("add_stubs", methods));
    }
    for file in &report.removed {
        changed.insert(file, ("remove", &[]));
    }
    if changed.is_empty() {
        eprintln!("coolc: {} is up to date", out.display());
        return Ok(());
    }
    for (file, (change, methods)) in &changed {
        let path = out.join(file).display().to_string();
        match format {
            MessageFormat::Human => println!("{path}"),
            MessageFormat::Json => {
                let line = StaleFile {
                    reason: "stale_file",
                    path,
                    change,
                    methods,
                };
                println!("{}", serde_json::to_string(&line).unwrap_or_default());
            }
        }
    }
    eprintln!(
        "coolc: {} file(s) in {} would change: run `coolc compile` without --check",
        changed.len(),
        out.display()
    );
    Err(Failure::Stale)
}

/// `coolc diagram`: checks, then draws.
fn draw(
    cli: &Cli,
    files: &[PathBuf],
    options: &diagram::Options,
    format: diagram::Format,
    output: Option<&Path>,
) -> Result<(), Failure> {
    let checked = check(cli, files)?;
    let diagrams = diagram::diagrams(&checked, files.len(), options)
        .map_err(|e| Failure::Usage(e.to_string()))?;
    let text = diagram::render(&diagrams, format).map_err(|e| Failure::Usage(e.to_string()))?;
    match output {
        Some(path) => std::fs::write(path, text)
            .map_err(|e| Failure::Usage(format!("cannot write {}: {e}", path.display()))),
        None => {
            print!("{text}");
            Ok(())
        }
    }
}

fn new(cli: &Cli, dir: &Path, runtime: RuntimeDep) -> Result<(), Failure> {
    let name = if dir.as_os_str().is_empty() {
        String::new()
    } else {
        dir_name(dir)
    };
    if let Some(why) = name_error(&name) {
        return Err(Failure::Usage(format!(
            "invalid package name `{name}`: {why}; pass a name such as `blinker` or `my-robot`"
        )));
    }
    if dir.exists() {
        return Err(Failure::Usage(format!("{} already exists", dir.display())));
    }
    let type_name = ident::camel_raw(&name.replace('-', "_"));
    let description = starter_description(&type_name);
    let components = dir.join("components");
    let io = |e: std::io::Error| Failure::Usage(format!("cannot write {}: {e}", dir.display()));
    std::fs::create_dir_all(&components).map_err(io)?;
    let cool = components.join(format!("{}.cool", ident::snake_raw(&type_name)));
    std::fs::write(&cool, description).map_err(io)?;
    let krate = compile(
        cli,
        &[cool],
        dir,
        &name,
        runtime,
        merge::WriteOptions::default(),
    )?;
    let Some(atomic) = krate.atomics.first() else {
        return Err(Failure::Usage(
            "the starter description has no component".to_owned(),
        ));
    };
    let module = atomic.module.trim_start_matches("r#");
    std::fs::write(
        dir.join(format!("src/{module}.rs")),
        emit::starter_component(atomic),
    )
    .map_err(io)?;
    std::fs::create_dir_all(dir.join("tests")).map_err(io)?;
    std::fs::write(
        dir.join(format!("tests/{module}.rs")),
        emit::starter_test(&krate, atomic),
    )
    .map_err(io)?;
    std::fs::write(dir.join(".gitignore"), "/target\n/.coolc\n").map_err(io)?;
    eprintln!(
        "coolc: created {}: `cargo run` inside it starts the component; edit {} and run `coolc compile {} -o .` there",
        dir.display(),
        Path::new("components")
            .join(cool_file_name(&type_name))
            .display(),
        Path::new("components")
            .join(cool_file_name(&type_name))
            .display(),
    );
    Ok(())
}

/// Why `name`, given for a package, cannot be one: as written, or as the package
/// name the crate gets from it (lowercase, `-` separated: `Type` is `type`).
fn name_error(name: &str) -> Option<String> {
    if let Some(why) = package_name_error(name) {
        return Some(why.to_owned());
    }
    let package = lower::package_name(name);
    package_name_error(&package)
        .map(|why| format!("as a package name it is `{package}`, and {why}"))
}

/// Why `name` cannot be the package name `coolc new` gives the crate (the rules of
/// `cargo new`), or `None` when it can.
pub(crate) fn package_name_error(name: &str) -> Option<&'static str> {
    let Some(first) = name.chars().next() else {
        return Some("the name cannot be empty");
    };
    Some(if first.is_ascii_digit() {
        "the name cannot start with a digit"
    } else if !(first.is_ascii_alphabetic() || first == '_') {
        "the name must start with a letter or `_`"
    } else if !name
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        "only ASCII letters, digits, `-` and `_` may be used"
    } else if ident::is_keyword(name) {
        "it is a Rust keyword"
    } else if ["test", "std", "core", "alloc", "proc_macro"].contains(&name) {
        "it is the name of a crate of Rust's standard library"
    } else if ["coolbot", "serde"].contains(&name) {
        "it is the name of a dependency of the generated crate"
    } else {
        return None;
    })
}

fn cool_file_name(type_name: &str) -> String {
    format!("{}.cool", ident::snake_raw(type_name))
}

/// The description `coolc new` starts from: an atomic with a periodic state.
pub fn starter_description(type_name: &str) -> String {
    format!(
        r#"/// A starter component: counts its periods and stops after `limit` of them.
atomic {type_name} {{
    configuration {{
        /// How many periods to count before finishing.
        limit: u64 = 10;
    }}

    /// How many periods have elapsed.
    observable count: u64 = 0;

    /// Ticks once per period.
    output beat: tick;

    timing {{ period 100ms; }}

    automaton {{
        initial counting;
        /// Counting periods.
        state counting {{
            entry;
            periodic;
            may -> done;
        }}
        /// The count reached the limit.
        state done {{ entry; }}
    }}
}}
"#
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runtime_path_is_relative_inside_the_repository() {
        let runtime = Path::new("/repo/runtime");
        assert_eq!(
            runtime_path_from(runtime, Path::new("/repo/examples/motion")),
            Path::new("../../runtime")
        );
        assert_eq!(
            runtime_path_from(runtime, Path::new("/repo/x/../demo")),
            Path::new("../runtime")
        );
        assert_eq!(
            runtime_path_from(runtime, Path::new("/tmp/demo")),
            Path::new("/repo/runtime")
        );
    }
}
