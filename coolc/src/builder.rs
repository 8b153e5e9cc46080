//! [`Builder`]: compiling `.cool` descriptions from a `build.rs`, as `prost-build`
//! and `tonic-build` do for their inputs.
//!
//! ```no_run
//! // build.rs: `main` of the build script.
//! coolc::Builder::new().compile(&["components/base.cool"]).unwrap();
//! ```
//!
//! ```text
//! // src/lib.rs
//! pub mod generated {
//!     include!(concat!(env!("OUT_DIR"), "/cool.rs"));
//! }
//! ```
//!
//! The generated modules (`types` and one per component) land in one file,
//! `$OUT_DIR/cool.rs`; include it inside a module named `generated` so that user code
//! refers to `crate::generated::<component>::Behavior` exactly as in crates written
//! by `coolc compile`. The crate needs `coolbot`, `serde` (with `derive`) and
//! `serde_json` as dependencies, and the crates named by `link crate`; the builder
//! prints `cargo:rustc-link-lib` for every `link system`. It writes no user stub files:
//! `coolc compile` (or the rustc error naming each missing `Behavior` method) tells
//! you what to implement.
//!
//! The file is not formatted by default: nobody reads it, and formatting is most of
//! the cost of emission (the 1,000-component benchmark set emits several times
//! faster unformatted; see `docs/performance.md`). It is the same Rust either way.
//! Turn formatting on with [`Builder::format`] to read the file (`prettyplease`, in
//! process).

use std::path::{Path, PathBuf};

use crate::emit::Formatting;
use crate::{RenderOptions, emit, lower};

/// Why a [`Builder`] failed. Its `Debug` is its `Display`, so that
/// `Builder::compile(..).unwrap()` in a build script shows the diagnostics as rendered.
#[derive(thiserror::Error)]
pub enum BuildError {
    /// The descriptions have errors; the rendered diagnostics are inside.
    #[error("the .cool descriptions have errors:\n{0}")]
    Diagnostics(String),
    /// A directory given with [`Builder::ros_path`] is not a directory.
    #[error("ros_path {}: not a directory", path.display())]
    RosPath {
        /// The path given.
        path: PathBuf,
    },
    /// `OUT_DIR` is not set and no output directory was given.
    #[error("OUT_DIR is not set: call Builder::out_dir or run from a build script")]
    NoOutDir,
    /// Writing the output failed.
    #[error("cannot write {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
}

impl std::fmt::Debug for BuildError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        std::fmt::Display::fmt(self, f)
    }
}

/// Compiles descriptions into `$OUT_DIR/cool.rs` from a build script.
#[derive(Clone, Debug, Default)]
pub struct Builder {
    out_dir: Option<PathBuf>,
    file_name: Option<String>,
    cargo_output: bool,
    format: bool,
    ros_paths: Vec<PathBuf>,
}

impl Builder {
    /// A builder writing `cool.rs` into `OUT_DIR` and printing `cargo:` directives.
    pub fn new() -> Builder {
        Builder {
            out_dir: None,
            file_name: None,
            cargo_output: true,
            format: false,
            ros_paths: Vec::new(),
        }
    }

    /// Writes into `dir` instead of `OUT_DIR`.
    pub fn out_dir(mut self, dir: impl Into<PathBuf>) -> Builder {
        self.out_dir = Some(dir.into());
        self
    }

    /// Names the output file (default `cool.rs`).
    pub fn file_name(mut self, name: impl Into<String>) -> Builder {
        self.file_name = Some(name.into());
        self
    }

    /// Whether to print `cargo:rerun-if-changed` and `cargo:rustc-link-lib` lines
    /// (default true; turn off outside build scripts).
    pub fn cargo_output(mut self, on: bool) -> Builder {
        self.cargo_output = on;
        self
    }

    /// Whether to format the output file with `prettyplease` (default false: the
    /// file is valid, warning-free Rust either way, and unformatted it is written
    /// several times faster; turn it on to read the generated code).
    pub fn format(mut self, on: bool) -> Builder {
        self.format = on;
        self
    }

    /// Adds a directory of ROS 2 interface packages (`dir/<package>/msg/<Type>.msg`)
    /// where `import ros` types are looked up, after those already given and before
    /// `AMENT_PREFIX_PATH` and the types coolc ships (as `coolc --ros-path`).
    pub fn ros_path(mut self, dir: impl Into<PathBuf>) -> Builder {
        self.ros_paths.push(dir.into());
        self
    }

    /// Compiles `files` (and their imports). On success returns the written path; on
    /// errors returns them rendered, and a build script that unwraps fails the build
    /// showing them.
    pub fn compile<P: AsRef<Path>>(&self, files: &[P]) -> Result<PathBuf, BuildError> {
        if let Some(path) = self.ros_paths.iter().find(|path| !path.is_dir()) {
            return Err(BuildError::RosPath { path: path.clone() });
        }
        // With the sibling scan the CLI does: an unknown name that a `.cool` file next
        // to the one using it defines gets help naming the `import` to add.
        let analysis = crate::analyze_files(
            files,
            &crate::ros::Search::from_env(self.ros_paths.iter().cloned()),
        );
        if self.cargo_output {
            for line in self.rerun_lines(&analysis.sources) {
                println!("{line}");
            }
        }
        let checked = analysis
            .checked()
            .map_err(|analysis| BuildError::Diagnostics(analysis.render(RenderOptions::plain())))?;
        if self.cargo_output && !checked.warnings().is_empty() {
            for line in checked.render(RenderOptions::plain()).lines() {
                println!("cargo:warning={line}");
            }
        }
        let options = lower::Options {
            sources: files
                .iter()
                .map(|f| f.as_ref().display().to_string())
                .collect(),
            inputs: crate::fingerprint::inputs(checked.sources().files()),
            ..lower::Options::default()
        };
        let krate = lower::lower(&checked, &options);
        if self.cargo_output {
            for lib in &krate.system_libs {
                println!("cargo:rustc-link-lib={lib}");
            }
        }
        let dir = match &self.out_dir {
            Some(dir) => dir.clone(),
            None => std::env::var_os("OUT_DIR")
                .map(PathBuf::from)
                .ok_or(BuildError::NoOutDir)?,
        };
        let path = dir.join(self.file_name.as_deref().unwrap_or("cool.rs"));
        let formatting = if self.format {
            Formatting::Formatted
        } else {
            Formatting::Unformatted
        };
        std::fs::create_dir_all(&dir)
            .and_then(|()| std::fs::File::create(&path))
            .and_then(|file| {
                emit::write_single_file_with(&krate, formatting, &mut std::io::BufWriter::new(file))
            })
            .map_err(|source| BuildError::Io {
                path: path.clone(),
                source,
            })?;
        Ok(path)
    }
}

impl Builder {
    /// The `cargo:rerun-if-*` lines of a compile that read `sources`: each file read
    /// but the shipped `.msg` files (not files: cargo would run the script again on
    /// every build), each directory given with [`Builder::ros_path`] (for a type
    /// added to it), and `AMENT_PREFIX_PATH`.
    fn rerun_lines(&self, sources: &crate::SourceMap) -> Vec<String> {
        let files = sources
            .files()
            .iter()
            .filter(|file| !file.path.starts_with(crate::ros::lookup::SHIPPED_DIR))
            .map(|file| &file.path);
        files
            .chain(&self.ros_paths)
            .map(|path| format!("cargo:rerun-if-changed={}", path.display()))
            .chain(std::iter::once(
                "cargo:rerun-if-env-changed=AMENT_PREFIX_PATH".to_owned(),
            ))
            .collect()
    }
}

/// The files of directory `dir` (`""` is the current directory), for the help on an
/// unknown name that a file next to the one using it defines (the CLI lists
/// directories the same way).
pub(crate) fn files_in(dir: &Path) -> Vec<PathBuf> {
    let read = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    let Ok(entries) = std::fs::read_dir(read) else {
        return Vec::new();
    };
    entries
        .filter_map(Result::ok)
        .map(|entry| dir.join(entry.file_name()))
        .collect()
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::Builder;

    #[test]
    fn a_build_script_watches_every_file_read_but_the_shipped_ones() {
        let files = [
            ("robot.cool", "import ros \"my_msgs/msg/Reading\";\n"),
            ("ros/my_msgs/msg/Reading.msg", "std_msgs/Header header\n"),
        ];
        let loader = |path: &Path| {
            files
                .iter()
                .find(|(name, _)| Path::new(name) == path)
                .map(|(_, text)| text.to_string())
                .ok_or_else(|| std::io::Error::from(std::io::ErrorKind::NotFound))
        };
        let builder = Builder::new().ros_path("ros");
        let search = crate::ros::Search::new().with_dir("ros");
        let analysis = crate::analyze_with(&["robot.cool"], &loader, &|_| Vec::new(), &search);
        assert!(!analysis.has_errors());
        assert_eq!(
            builder.rerun_lines(&analysis.sources),
            [
                "cargo:rerun-if-changed=robot.cool",
                "cargo:rerun-if-changed=ros/my_msgs/msg/Reading.msg",
                "cargo:rerun-if-changed=ros",
                "cargo:rerun-if-env-changed=AMENT_PREFIX_PATH",
            ]
        );
    }
}
