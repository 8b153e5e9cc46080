//! Where the `.msg` file of a message type is found.
//!
//! A type `pkg/msg/Type` is looked up, first found wins, in
//! 1. each directory given explicitly, in order: `<dir>/<pkg>/msg/<Type>.msg`;
//! 2. each prefix of `AMENT_PREFIX_PATH` (when it is set), in order:
//!    `<prefix>/share/<pkg>/msg/<Type>.msg`, where a ROS 2 installation puts them;
//! 3. the types coolc ships ([`super::shipped`]).
//!
//! Files are read through a loader closure (as [`crate::analyze`] does), so tests run
//! on in-memory files.

use std::ffi::OsStr;
use std::io;
use std::path::{Path, PathBuf};

use super::names::TypeName;
use super::shipped;

/// The places searched for `.msg` files, in order.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Search {
    dirs: Vec<PathBuf>,
    prefixes: Vec<PathBuf>,
}

/// A `.msg` file found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Found {
    /// Its path (for a shipped type, `<shipped>/<pkg>/msg/<Type>.msg`).
    pub(crate) path: PathBuf,
    /// Its text.
    pub(crate) text: String,
}

/// Why a type's file was not found.
#[derive(Debug, thiserror::Error)]
pub(crate) enum LookupError {
    /// No place holds it.
    #[error("no `.msg` file defines `{name}`")]
    Missing {
        /// The type.
        name: TypeName,
        /// Every file looked for, in order, then `<shipped>/...` for the shipped set.
        searched: Vec<PathBuf>,
    },
    /// A file exists but could not be read.
    #[error("cannot read {}", path.display())]
    Unreadable {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: io::Error,
    },
}

/// The directory shipped types are shown under in diagnostics.
pub(crate) const SHIPPED_DIR: &str = "<shipped>";

impl Search {
    /// The shipped types only.
    pub fn new() -> Search {
        Search::default()
    }

    /// The explicit `dirs`, then the prefixes of `AMENT_PREFIX_PATH` if it is set in
    /// the environment, then the shipped types.
    pub fn from_env(dirs: impl IntoIterator<Item = PathBuf>) -> Search {
        let mut search = Search::new();
        for dir in dirs {
            search = search.with_dir(dir);
        }
        match std::env::var_os("AMENT_PREFIX_PATH") {
            Some(value) => search.with_ament_prefix_path(&value),
            None => search,
        }
    }

    /// Adds a directory of interface packages (`<dir>/<pkg>/msg/<Type>.msg`), after
    /// those already given.
    pub fn with_dir(mut self, dir: impl Into<PathBuf>) -> Search {
        self.dirs.push(dir.into());
        self
    }

    /// Adds the prefixes of an `AMENT_PREFIX_PATH` value (separated as the platform's
    /// `PATH`; empty entries skipped).
    pub fn with_ament_prefix_path(mut self, value: &OsStr) -> Search {
        self.prefixes
            .extend(std::env::split_paths(value).filter(|prefix| !prefix.as_os_str().is_empty()));
        self
    }

    /// The files looked at for `name`, in order (the shipped one last, under
    /// `SHIPPED_DIR`, whether or not it exists).
    pub fn candidates(&self, name: &TypeName) -> Vec<PathBuf> {
        let relative = name.relative_path();
        self.dirs
            .iter()
            .map(|dir| dir.join(&relative))
            .chain(
                self.prefixes
                    .iter()
                    .map(|prefix| prefix.join("share").join(&relative)),
            )
            .chain(std::iter::once(Path::new(SHIPPED_DIR).join(&relative)))
            .collect()
    }

    /// Finds and reads the file of `name`. A file the loader reports as not found is
    /// skipped; any other read error stops the search.
    pub(crate) fn find(
        &self,
        name: &TypeName,
        loader: &dyn Fn(&Path) -> io::Result<String>,
    ) -> Result<Found, LookupError> {
        let mut candidates = self.candidates(name);
        let shipped_path = candidates.pop().expect("the shipped candidate is last");
        for path in &candidates {
            match loader(path) {
                Ok(text) => {
                    return Ok(Found {
                        path: path.clone(),
                        text,
                    });
                }
                Err(error) if error.kind() == io::ErrorKind::NotFound => {}
                Err(source) => {
                    return Err(LookupError::Unreadable {
                        path: path.clone(),
                        source,
                    });
                }
            }
        }
        match shipped::find(name) {
            Some(text) => Ok(Found {
                path: shipped_path,
                text: text.to_owned(),
            }),
            None => {
                candidates.push(shipped_path);
                Err(LookupError::Missing {
                    name: name.clone(),
                    searched: candidates,
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candidates_are_dirs_then_ament_shares_then_shipped() {
        let value = std::env::join_paths(["/opt/a", "", "/opt/b"]).unwrap();
        let search = Search::new().with_dir("/x").with_ament_prefix_path(&value);
        let name = TypeName::parse("geometry_msgs/msg/Point").unwrap();
        let expected: Vec<PathBuf> = [
            "/x/geometry_msgs/msg/Point.msg",
            "/opt/a/share/geometry_msgs/msg/Point.msg",
            "/opt/b/share/geometry_msgs/msg/Point.msg",
            "<shipped>/geometry_msgs/msg/Point.msg",
        ]
        .iter()
        .map(PathBuf::from)
        .collect();
        assert_eq!(search.candidates(&name), expected);
    }
}
