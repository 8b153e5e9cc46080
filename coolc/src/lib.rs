//! `coolc`: the compiler for CoolBOT `.cool` component descriptions.
//!
//! The pipeline is `syntax` -> `resolve` -> `check` -> `lower` -> `emit`; see
//! `ARCHITECTURE.md` at the repository root.
//!
//! The front end is one call, [`analyze`]: it loads the root files through a loader
//! closure (only the CLI and the `Builder` pass one that reads the filesystem; tests
//! pass in-memory files), follows `import`s relative to the importing file, parses,
//! resolves and checks everything, and returns an [`Analysis`]: the [`SourceMap`], one
//! [`ast::File`] per loaded file (`files[i].id == FileId(i)`) and every diagnostic,
//! in a deterministic order.
//!
//! ```
//! use std::path::Path;
//! let files = [("main.cool", "packet Pose { x: f64, y: f64 }")];
//! let loader = |path: &Path| -> std::io::Result<String> {
//!     files
//!         .iter()
//!         .find(|(name, _)| Path::new(name) == path)
//!         .map(|(_, text)| text.to_string())
//!         .ok_or_else(|| std::io::Error::from(std::io::ErrorKind::NotFound))
//! };
//! let analysis = coolc::analyze(&["main.cool"], &loader);
//! let checked = analysis
//!     .checked()
//!     .unwrap_or_else(|analysis| panic!("{}", analysis.render(coolc::RenderOptions::plain())));
//! let krate = coolc::lower::lower(&checked, &coolc::lower::Options::default());
//! assert!(coolc::emit::single_file(&krate).contains("pub struct Pose {"));
//! ```
#![deny(missing_docs)]

pub mod ast;
pub mod builder;
pub(crate) mod check;
pub(crate) mod checked;
pub mod cli;
pub mod diagnostics;
pub mod diagram;
pub mod emit;
pub mod fingerprint;
pub(crate) mod ident;
pub mod ir;
mod layout;
pub mod lower;
pub(crate) mod manifest;
pub mod merge;
mod par;
pub(crate) mod resolve;
pub mod ros;
pub(crate) mod source;
pub mod syntax;

use std::path::Path;

pub use builder::Builder;
pub use checked::Checked;
pub use diagnostics::{Diagnostic, RenderFormat, RenderOptions, Severity};
pub use source::SourceMap;

/// The result of [`analyze`]: what was read, what was parsed, what is wrong.
#[derive(Clone, Debug)]
pub struct Analysis {
    /// Every loaded file; `FileId(i)` is `sources.files()[i]`.
    pub sources: SourceMap,
    /// One syntax tree per loaded file, in `FileId` order (roots first, then imports
    /// depth first, then the `.msg` files of `import ros` types, each with no item).
    pub files: Vec<ast::File>,
    /// Every diagnostic: syntax errors per file in file order, then resolution and
    /// check diagnostics.
    pub diagnostics: Vec<Diagnostic>,
    /// What the checker resolved (handed on by [`Analysis::checked`]).
    resolved: check::Resolved,
    /// The ROS 2 message types imported (`import ros`) and every type they reference.
    ros: ros::Interfaces,
}

impl Analysis {
    /// True when at least one diagnostic is an error.
    pub fn has_errors(&self) -> bool {
        self.diagnostics
            .iter()
            .any(|d| d.severity == Severity::Error)
    }

    /// The number of errors.
    pub fn error_count(&self) -> usize {
        self.diagnostics
            .iter()
            .filter(|d| d.severity == Severity::Error)
            .count()
    }

    /// Renders every diagnostic (graphical or JSON, see [`RenderOptions`]).
    pub fn render(&self, options: RenderOptions) -> String {
        diagnostics::render(&self.sources, &self.diagnostics, options)
    }

    /// The checked model when there is no error (what `lower` and `diagram` take);
    /// the analysis itself otherwise (boxed: it is large), to report its diagnostics.
    pub fn checked(self) -> Result<Checked, Box<Analysis>> {
        if self.has_errors() {
            return Err(Box::new(self));
        }
        Ok(Checked::new(
            self.sources,
            self.diagnostics,
            self.resolved,
            self.ros,
        ))
    }

    /// The model of an analysis with errors, for tests that lower what the checker
    /// rejects (defence in depth: lowering escapes what it must even then).
    #[cfg(test)]
    pub(crate) fn assume_checked(self) -> Checked {
        Checked::new(self.sources, self.diagnostics, self.resolved, self.ros)
    }
}

/// Loads, parses, resolves and checks `roots` and everything they import.
///
/// `loader` reads one file; it receives the root paths as given and import paths
/// joined to the importing file's directory (lexically normalised). A root or import
/// it cannot read is a diagnostic, never a panic. ROS 2 message types (`import ros`)
/// are found among the ones coolc ships only ([`analyze_with`] takes other places).
pub fn analyze<P: AsRef<Path>>(
    roots: &[P],
    loader: &dyn Fn(&Path) -> std::io::Result<String>,
) -> Analysis {
    analyze_with_siblings(roots, loader, &|_| Vec::new())
}

/// Like [`analyze`]; `list(dir)` gives the files of a directory, so that an unknown
/// name defined in a `.cool` file next to the file using it, which that file does not
/// import, gets help naming the `import` to add. Those files are only scanned for
/// their item names, not analyzed.
pub fn analyze_with_siblings<P: AsRef<Path>>(
    roots: &[P],
    loader: &dyn Fn(&Path) -> std::io::Result<String>,
    list: &dyn Fn(&Path) -> Vec<std::path::PathBuf>,
) -> Analysis {
    analyze_with(roots, loader, list, &ros::Search::new())
}

/// Like [`analyze_with_siblings`]; the `.msg` files of the ROS 2 message types the
/// descriptions import (`import ros`) are looked up through `ros` (`docs/ros2.md`,
/// "Where types are found"), read with `loader` and added to the sources.
pub fn analyze_with<P: AsRef<Path>>(
    roots: &[P],
    loader: &dyn Fn(&Path) -> std::io::Result<String>,
    list: &dyn Fn(&Path) -> Vec<std::path::PathBuf>,
    ros: &ros::Search,
) -> Analysis {
    analyze_loaded(resolve::load(roots, loader), loader, list, ros)
}

/// Like [`analyze_with`], reading the files from the file system and listing
/// directories with `std::fs`: a file is known by its canonical path, so one reached
/// through two paths (a root given as `robot.cool` and as `/work/robot.cool`, a
/// directory reached through a symbolic link) is loaded once.
pub fn analyze_files<P: AsRef<Path>>(roots: &[P], ros: &ros::Search) -> Analysis {
    let loader = |path: &Path| std::fs::read_to_string(path);
    let identify = |path: &Path| std::fs::canonicalize(path).unwrap_or_else(|_| path.to_owned());
    analyze_loaded(
        resolve::load_with(roots, &loader, &identify),
        &loader,
        &builder::files_in,
        ros,
    )
}

fn analyze_loaded(
    mut loaded: resolve::Loaded,
    loader: &dyn Fn(&Path) -> std::io::Result<String>,
    list: &dyn Fn(&Path) -> Vec<std::path::PathBuf>,
    ros: &ros::Search,
) -> Analysis {
    let interfaces = resolve::load_ros(&mut loaded, ros, loader);
    let mut symbols = resolve::Symbols::build(
        &loaded.sources,
        &loaded.files,
        &loaded.imports,
        &mut loaded.diagnostics,
    );
    symbols.note_unloaded(&loaded.files, &interfaces);
    symbols.add_siblings(&loaded.sources, list, loader);
    let resolved = check::check(
        &loaded.files,
        &symbols,
        &interfaces,
        &mut loaded.diagnostics,
    );
    Analysis {
        sources: loaded.sources,
        files: loaded.files,
        diagnostics: loaded.diagnostics,
        resolved,
        ros: interfaces,
    }
}

/// Analyzes in-memory text as one root file named `path` (imports resolve against
/// nothing and fail). Handy for tests and editors.
pub fn analyze_text(path: &str, text: &str) -> Analysis {
    let text = text.to_owned();
    let root = Path::new(path).to_owned();
    analyze(&[path], &move |p: &Path| {
        if p == root {
            Ok(text.clone())
        } else {
            Err(std::io::Error::from(std::io::ErrorKind::NotFound))
        }
    })
}

/// Phase timings on stderr when `COOLC_TIMINGS` is set (to see where a compile's time
/// goes); nothing otherwise.
#[derive(Debug)]
pub(crate) struct Timings {
    last: Option<std::time::Instant>,
}

impl Timings {
    /// Timings that print only when `COOLC_TIMINGS` is set.
    pub(crate) fn from_env() -> Timings {
        Timings {
            last: std::env::var_os("COOLC_TIMINGS").map(|_| std::time::Instant::now()),
        }
    }

    /// Prints the time since the last span (or the start) under `name`.
    pub(crate) fn span(&mut self, name: &str) {
        if let Some(last) = self.last {
            let now = std::time::Instant::now();
            eprintln!(
                "coolc: {:7.1} ms  {name}",
                now.duration_since(last).as_secs_f64() * 1e3
            );
            self.last = Some(now);
        }
    }
}
