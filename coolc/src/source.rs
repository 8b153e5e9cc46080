//! The source map: every file `coolc` read, by [`FileId`].
//!
//! Files are added in the order they are loaded (roots first, then imports depth
//! first), so ids, and therefore diagnostic order, are deterministic. The source map
//! never touches the filesystem: the caller of [`crate::analyze`] passes a loader.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::ast::FileId;

/// One loaded file.
#[derive(Clone, Debug)]
pub struct SourceFile {
    /// Its id.
    pub id: FileId,
    /// The path it was loaded from (as given or joined from an import).
    pub path: PathBuf,
    /// The text.
    pub text: Arc<str>,
}

/// All loaded files.
#[derive(Clone, Debug, Default)]
pub struct SourceMap {
    files: Vec<SourceFile>,
    by_path: HashMap<PathBuf, FileId>,
}

impl SourceMap {
    /// An empty map.
    pub fn new() -> Self {
        SourceMap::default()
    }

    /// Adds a file and returns its id.
    pub fn add(&mut self, path: impl Into<PathBuf>, text: impl Into<Arc<str>>) -> FileId {
        let id = FileId(u32::try_from(self.files.len()).unwrap_or(u32::MAX));
        let path = path.into();
        self.by_path.entry(path.clone()).or_insert(id);
        self.files.push(SourceFile {
            id,
            path,
            text: text.into(),
        });
        id
    }

    /// The id of an already loaded path.
    pub fn find(&self, path: &Path) -> Option<FileId> {
        self.by_path.get(path).copied()
    }

    /// All files in id order.
    pub fn files(&self) -> &[SourceFile] {
        &self.files
    }

    /// One file. Unknown ids give an empty stand-in rather than a panic.
    pub fn get(&self, id: FileId) -> Option<&SourceFile> {
        self.files.get(id.0 as usize)
    }

    /// The text of a file (empty for an unknown id).
    pub fn text(&self, id: FileId) -> &str {
        self.get(id).map(|file| &*file.text).unwrap_or("")
    }

    /// The text of a file, shared.
    pub fn shared_text(&self, id: FileId) -> Arc<str> {
        self.get(id)
            .map(|file| file.text.clone())
            .unwrap_or_else(|| Arc::from(""))
    }

    /// The path of a file (empty for an unknown id).
    pub fn path(&self, id: FileId) -> &Path {
        self.get(id)
            .map(|file| file.path.as_path())
            .unwrap_or(Path::new(""))
    }

    /// The path as shown in diagnostics: `/` separators on every platform.
    pub fn display_path(&self, id: FileId) -> String {
        self.path(id).to_string_lossy().replace('\\', "/")
    }

    /// 1-based line and column (in chars) of a byte offset.
    pub fn line_col(&self, id: FileId, offset: usize) -> (usize, usize) {
        let text = self.text(id);
        let offset = offset.min(text.len());
        let mut line = 1;
        let mut line_start = 0;
        for (index, ch) in text.char_indices() {
            if index >= offset {
                break;
            }
            if ch == '\n' {
                line += 1;
                line_start = index + 1;
            }
        }
        let column = text
            .get(line_start..offset)
            .map(|s| s.chars().count())
            .unwrap_or(0)
            + 1;
        (line, column)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_col_counts_from_one() {
        let mut map = SourceMap::new();
        let id = map.add("a.cool", "ab\ncd");
        assert_eq!(map.line_col(id, 0), (1, 1));
        assert_eq!(map.line_col(id, 4), (2, 2));
        assert_eq!(map.find(Path::new("a.cool")), Some(id));
    }
}
