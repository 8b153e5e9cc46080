//! Resolution: imports followed, top-level names to definitions.
//!
//! [`load`] reads the roots and, depth first, every file they import (paths relative
//! to the importing file, lexically normalised), parsing each as it is read (the
//! roots are read and parsed ahead, on every core: a file's id is its place in the
//! walk); an import cycle is reported with the whole cycle. [`load_ros`] then reads the ROS 2
//! message types the files import (`import ros`), and every type they reference.
//! [`Symbols`] is the table of top-level items (packets, enums, extern packets, ROS
//! imports, converters, components): one namespace across all files, because they all
//! end up in one generated crate. A file sees its own items and those of the files it
//! imports, directly or not. The same ROS type imported under the same name in several
//! files is one definition, seen from each of them.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Component, Path, PathBuf};

use crate::ast::{self, FileId, Span};
use crate::diagnostics::{Code, Diagnostic, closest};
use crate::par::par_map;
use crate::ros;
use crate::source::SourceMap;
use crate::syntax;

/// What [`load`] produced.
#[derive(Debug, Default)]
pub struct Loaded {
    /// Every file read.
    pub sources: SourceMap,
    /// Parsed files, in id order.
    pub files: Vec<ast::File>,
    /// For each file, the files it imports (that could be read).
    pub imports: Vec<Vec<FileId>>,
    /// Load and syntax diagnostics.
    pub diagnostics: Vec<Diagnostic>,
    /// Each `.cool` file read, by its identity (see [`load_with`]).
    identities: HashMap<PathBuf, FileId>,
}

/// Reads and parses `roots` and everything they import; a file is known by its path,
/// lexically normalised.
pub fn load<P: AsRef<Path>>(
    roots: &[P],
    loader: &dyn Fn(&Path) -> std::io::Result<String>,
) -> Loaded {
    load_with(roots, loader, &Path::to_path_buf)
}

/// Like [`load`], a file known by `identify(path)` (the path lexically normalised):
/// two paths with one identity are one file, loaded once (on a file system, the
/// canonical path: `a.cool` given as a root and imported as `/abs/a.cool`, or
/// reached through a symbolic link).
pub fn load_with<P: AsRef<Path>>(
    roots: &[P],
    loader: &dyn Fn(&Path) -> std::io::Result<String>,
    identify: &dyn Fn(&Path) -> PathBuf,
) -> Loaded {
    let mut loaded = Loaded::default();
    let mut ahead = parse_ahead(roots, loader);
    for root in roots {
        let path = normalize(root.as_ref());
        if loaded.identities.contains_key(&identify(&path)) {
            continue;
        }
        match read_file(&path, loader, &mut ahead) {
            Ok(text) => {
                let mut stack = Vec::new();
                let mut reader = Reader {
                    loader,
                    identify,
                    ahead: &mut ahead,
                };
                load_file(&mut loaded, path, text, &mut reader, &mut stack);
            }
            Err(error) => {
                let id = add_file(&mut loaded, path.clone(), String::new());
                loaded.identities.insert(identify(&path), id);
                loaded.diagnostics.push(
                    Diagnostic::error(
                        Code::ImportNotFound,
                        id,
                        Span::default(),
                        format!("cannot read `{}`: {error}", path.display()),
                    )
                    .with_help(
                        "check the path of the file given on the command line or to the builder",
                    ),
                );
            }
        }
    }
    loaded
}

/// The id a file parsed ahead of the walk has until the walk reaches it.
const UNPLACED: FileId = FileId(u32::MAX);

/// A file read, and parsed when it was read ahead (its id still [`UNPLACED`]).
struct Read {
    text: String,
    parsed: Option<(ast::File, Vec<Diagnostic>)>,
}

/// The roots read and parsed before the walk, on every core: the parse of a file
/// depends on its text alone, and the walk gives it its id.
fn parse_ahead<P: AsRef<Path>>(
    roots: &[P],
    loader: &dyn Fn(&Path) -> std::io::Result<String>,
) -> HashMap<PathBuf, Read> {
    let mut seen = BTreeSet::new();
    let texts: Vec<(PathBuf, String)> = roots
        .iter()
        .map(|root| normalize(root.as_ref()))
        .filter(|path| seen.insert(path.clone()))
        // A root that cannot be read is read again by the walk, which reports it.
        .filter_map(|path| loader(&path).ok().map(|text| (path, text)))
        .collect();
    let parsed = par_map(&texts, |(_, text)| syntax::parse(UNPLACED, text));
    texts
        .into_iter()
        .zip(parsed)
        .map(|((path, text), parsed)| {
            let parsed = Some(parsed);
            (path, Read { text, parsed })
        })
        .collect()
}

/// The text of `path`: read ahead, else through `loader`.
fn read_file(
    path: &Path,
    loader: &dyn Fn(&Path) -> std::io::Result<String>,
    ahead: &mut HashMap<PathBuf, Read>,
) -> std::io::Result<Read> {
    match ahead.remove(path) {
        Some(read) => Ok(read),
        None => loader(path).map(|text| Read { text, parsed: None }),
    }
}

/// How the walk reads the files it meets.
struct Reader<'a, 'b> {
    loader: &'a dyn Fn(&Path) -> std::io::Result<String>,
    identify: &'a dyn Fn(&Path) -> PathBuf,
    ahead: &'b mut HashMap<PathBuf, Read>,
}

/// `diagnostic`, and those related to it, in file `id` where they were in
/// [`UNPLACED`].
fn place(diagnostic: &mut Diagnostic, id: FileId) {
    if diagnostic.file == UNPLACED {
        diagnostic.file = id;
    }
    for related in &mut diagnostic.related {
        place(related, id);
    }
}

fn add_file(loaded: &mut Loaded, path: PathBuf, text: String) -> FileId {
    let id = loaded.sources.add(path, text);
    loaded.files.push(ast::File {
        id,
        items: Vec::new(),
    });
    loaded.imports.push(Vec::new());
    id
}

/// Loads one file, then its imports. `stack` holds the files being loaded, with the
/// import (file and span) that led to each, to report cycles.
fn load_file(
    loaded: &mut Loaded,
    path: PathBuf,
    read: Read,
    reader: &mut Reader<'_, '_>,
    stack: &mut Vec<FileId>,
) -> FileId {
    let id = add_file(loaded, path.clone(), read.text);
    loaded.identities.insert((reader.identify)(&path), id);
    let (file, diagnostics) = match read.parsed {
        Some((mut file, mut diagnostics)) => {
            file.id = id;
            for diagnostic in &mut diagnostics {
                place(diagnostic, id);
            }
            (file, diagnostics)
        }
        None => syntax::parse(id, loaded.sources.text(id)),
    };
    loaded.diagnostics.extend(diagnostics);
    let imports: Vec<ast::Import> = file
        .items
        .iter()
        .filter_map(|item| match item {
            ast::Item::Import(import) => Some(import.clone()),
            _ => None,
        })
        .collect();
    loaded.files[id.0 as usize] = file;
    stack.push(id);
    for import in imports {
        if let Some(diagnostic) = bad_import(id, &import) {
            loaded.diagnostics.push(diagnostic);
            continue;
        }
        let target = normalize(
            &path
                .parent()
                .unwrap_or(Path::new(""))
                .join(&import.path.value),
        );
        if let Some(&existing) = loaded.identities.get(&(reader.identify)(&target)) {
            if let Some(position) = stack.iter().position(|f| *f == existing) {
                let mut chain: Vec<String> = stack[position..]
                    .iter()
                    .map(|f| loaded.sources.display_path(*f))
                    .collect();
                chain.push(loaded.sources.display_path(existing));
                loaded.diagnostics.push(
                    Diagnostic::error(
                        Code::ImportCycle,
                        id,
                        import.path.span,
                        format!("import cycle: {}", chain.join(" -> ")),
                    )
                    .with_label("this import closes the cycle")
                    .with_help("move the shared items into a file that both import"),
                );
            }
            if !loaded.imports[id.0 as usize].contains(&existing) {
                loaded.imports[id.0 as usize].push(existing);
            }
            continue;
        }
        match read_file(&target, reader.loader, reader.ahead) {
            Ok(text) => {
                let imported = load_file(loaded, target, text, reader, stack);
                loaded.imports[id.0 as usize].push(imported);
            }
            Err(error) => loaded.diagnostics.push(
                Diagnostic::error(
                    Code::ImportNotFound,
                    id,
                    import.path.span,
                    format!("cannot read imported file `{}`: {error}", target.display()),
                )
                .with_label("imported here")
                .with_help("import paths are relative to the importing file"),
            ),
        }
    }
    stack.pop();
    id
}

/// An import names a `.cool` file by a path relative to the importing file: an
/// absolute path, or a file of another kind, is refused before anything is read.
fn bad_import(id: FileId, import: &ast::Import) -> Option<Diagnostic> {
    let written = Path::new(&import.path.value);
    let (message, label, help) = if written.has_root()
        || matches!(written.components().next(), Some(Component::Prefix(_)))
        || absolute_anywhere(&import.path.value)
    {
        (
            format!("import path `{}` is absolute", import.path.value),
            "absolute path",
            "an import path is relative to the importing file: write it from that file's directory (`../shared/sensors.cool`)".to_owned(),
        )
    } else if import.path.value.is_empty() {
        (
            "an import path cannot be empty".to_owned(),
            "empty path",
            "name a `.cool` file relative to the importing file: `import \"sensors.cool\";`"
                .to_owned(),
        )
    } else if written.extension().is_none_or(|ext| ext != "cool") {
        (
            format!("`{}` is not a `.cool` file", import.path.value),
            "not a `.cool` file",
            "`import` loads `.cool` descriptions; a ROS 2 message type is imported with `import ros \"package/msg/Type\";`".to_owned(),
        )
    } else {
        return None;
    };
    Some(
        Diagnostic::error(Code::BadImport, id, import.path.span, message)
            .with_label(label)
            .with_help(help),
    )
}

/// A path absolute on some system, whichever reads it: a description is read on Unix
/// and on Windows alike, so a drive (`C:\shared\x.cool`, or `C:x.cool`, relative to
/// that drive's current directory) or a leading separator (`\\server\x.cool`,
/// `\x.cool`) is refused on Unix too.
fn absolute_anywhere(path: &str) -> bool {
    let bytes = path.as_bytes();
    let drive = bytes.len() >= 2 && bytes[0].is_ascii_alphabetic() && bytes[1] == b':';
    drive || path.starts_with(['/', '\\'])
}

/// Reads the ROS 2 message types the loaded files import (`import ros`) and every type
/// they reference, through `search` (`docs/ros2.md`, "Where types are found"). Each
/// `.msg` file read joins the sources with an empty syntax tree (file ids stay indices
/// of `files`); its diagnostics join `loaded.diagnostics`, each with a note at the
/// `import ros` that needs the file. A type no file defines is reported at the import
/// (or the field of another `.msg` file) that names it.
pub fn load_ros(
    loaded: &mut Loaded,
    search: &ros::Search,
    loader: &dyn Fn(&Path) -> std::io::Result<String>,
) -> ros::Interfaces {
    let imports: Vec<(FileId, ast::StrLit)> = loaded
        .files
        .iter()
        .flat_map(|file| {
            file.items.iter().filter_map(|item| match item {
                ast::Item::RosImport(import) => Some((file.id, import.ros_name.clone())),
                _ => None,
            })
        })
        .collect();
    if imports.is_empty() {
        return ros::Interfaces::default();
    }
    let wanted: Vec<ros::Wanted<'_>> = imports
        .iter()
        .map(|(file, name)| ros::Wanted {
            name: &name.value,
            file: *file,
            span: name.span,
        })
        .collect();
    let first_new = loaded.sources.files().len();
    let interfaces = ros::load(search, &wanted, &mut loaded.sources, loader);
    for index in first_new..loaded.sources.files().len() {
        loaded.files.push(ast::File {
            id: FileId(index as u32),
            items: Vec::new(),
        });
        loaded.imports.push(Vec::new());
    }
    let needed = needed_by(&interfaces, &imports);
    for diagnostic in &interfaces.diagnostics {
        let mut diagnostic = diagnostic.clone();
        if let Some(((file, import), type_name)) = needed.get(&diagnostic.file) {
            let label = if *type_name == import.value {
                "imported here".to_owned()
            } else {
                format!("`{}` needs `{type_name}`", import.value)
            };
            diagnostic = diagnostic.with_other(*file, import.span, label);
        }
        loaded.diagnostics.push(diagnostic);
    }
    interfaces
}

/// For each `.msg` file loaded, the first import (in file order) that needs it, and the
/// name of the type the file defines.
fn needed_by<'i>(
    interfaces: &ros::Interfaces,
    imports: &'i [(FileId, ast::StrLit)],
) -> BTreeMap<FileId, (&'i (FileId, ast::StrLit), String)> {
    let mut needed = BTreeMap::new();
    for import in imports {
        let Ok(top) = ros::TypeName::parse(&import.1.value) else {
            continue;
        };
        let mut todo = vec![top];
        let mut seen = BTreeSet::new();
        while let Some(name) = todo.pop() {
            if !seen.insert(name.clone()) {
                continue;
            }
            let Some(message) = interfaces.get(&name) else {
                continue;
            };
            needed
                .entry(message.file)
                .or_insert_with(|| (import, name.to_string()));
            todo.extend(
                message
                    .fields
                    .iter()
                    .filter_map(|field| match &field.ty.base {
                        ros::msg::Base::Nested(nested) => Some(nested.clone()),
                        _ => None,
                    }),
            );
        }
    }
    needed
}

/// Removes `.` and resolves `..` lexically (never touching the filesystem).
pub fn normalize(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for component in path.components() {
        match component {
            Component::CurDir => {}
            Component::ParentDir => {
                let last = out.components().next_back();
                if matches!(last, Some(Component::Normal(_))) {
                    out.pop();
                } else {
                    out.push("..");
                }
            }
            other => out.push(other.as_os_str()),
        }
    }
    out
}

/// What a top-level name refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DefKind {
    /// `packet`
    Packet,
    /// `enum`
    Enum,
    /// `extern packet`
    ExternPacket,
    /// `import ros`
    RosMessage,
    /// `converter`
    Converter,
    /// `atomic` or `compound`
    Component,
}

impl DefKind {
    /// How the kind is named in messages.
    pub fn describe(self) -> &'static str {
        match self {
            DefKind::Packet => "packet",
            DefKind::Enum => "enum",
            DefKind::ExternPacket => "extern packet",
            DefKind::RosMessage => "ROS message type",
            DefKind::Converter => "converter",
            DefKind::Component => "component",
        }
    }
}

/// A top-level definition: where it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Def {
    /// What it is.
    pub kind: DefKind,
    /// The file it is in.
    pub file: FileId,
    /// Its index in that file's items.
    pub item: usize,
    /// The span of its name.
    pub name_span: Span,
}

/// The top-level symbol table.
#[derive(Clone, Debug, Default)]
pub struct Symbols {
    /// Every top-level name, first definition wins.
    pub defs: BTreeMap<String, Def>,
    /// For a name of `defs` that an `import ros` defines, the other files that import
    /// the same type under the same name: one definition, seen from each.
    pub shared: BTreeMap<String, BTreeSet<FileId>>,
    /// For each file, the files whose items it sees (itself included).
    pub visible: Vec<BTreeSet<FileId>>,
    /// Display paths by file id, for messages.
    pub paths: Vec<String>,
    /// Names defined in `.cool` files that were not loaded but lie in the directory of
    /// a loaded file ([`Symbols::add_siblings`]), with those files and what each
    /// defines: an unknown name found there gets help naming the import to add.
    pub siblings: BTreeMap<String, Vec<(PathBuf, DefKind)>>,
    /// The directory of each loaded file, by file id.
    pub dirs: Vec<PathBuf>,
    /// Each loaded file's path, by file id.
    pub files: Vec<PathBuf>,
    /// Names of `import ros` types whose `.msg` file was not found or not valid
    /// ([`Symbols::note_unloaded`]): never offered as "did you mean" (the import is
    /// what is misspelt).
    pub unloaded: BTreeSet<String>,
}

/// `path` without `.` components and with each `..` taken back (as far as it goes).
fn lexical(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for component in path.components() {
        match component {
            Component::CurDir => {}
            Component::ParentDir if out.file_name().is_some() => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out
}

/// The outcome of looking a name up from one file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lookup {
    /// Defined and visible.
    Found(Def),
    /// Defined in a file this one does not import.
    NotImported(Def),
    /// Not defined anywhere.
    Missing,
}

impl Symbols {
    /// Builds the table, reporting duplicate top-level names.
    pub fn build(
        sources: &SourceMap,
        files: &[ast::File],
        imports: &[Vec<FileId>],
        diagnostics: &mut Vec<Diagnostic>,
    ) -> Symbols {
        let mut symbols = Symbols {
            paths: sources
                .files()
                .iter()
                .map(|file| sources.display_path(file.id))
                .collect(),
            dirs: sources
                .files()
                .iter()
                .map(|file| file.path.parent().unwrap_or(Path::new("")).to_owned())
                .collect(),
            files: sources
                .files()
                .iter()
                .map(|file| file.path.clone())
                .collect(),
            ..Symbols::default()
        };
        // Imported files first, so a clash is reported in the file that imports (and
        // so sees) the earlier definition.
        for file in dependency_order(files.len(), imports)
            .into_iter()
            .filter_map(|index| files.get(index))
        {
            for (index, item) in file.items.iter().enumerate() {
                let Some((kind, name)) = def_of(item) else {
                    continue;
                };
                let def = Def {
                    kind,
                    file: file.id,
                    item: index,
                    name_span: name.span,
                };
                match symbols.defs.get(&name.name) {
                    Some(first) if same_ros_import(files, first, &def) => {
                        symbols
                            .shared
                            .entry(name.name.clone())
                            .or_default()
                            .insert(file.id);
                    }
                    Some(first) => diagnostics.push(
                        Diagnostic::error(
                            Code::Duplicate,
                            file.id,
                            name.span,
                            format!("`{}` is defined more than once", name.name),
                        )
                        .with_label(format!("{} `{}` defined again here", kind.describe(), name.name))
                        .with_other(first.file, first.name_span, format!("first defined here as a {}", first.kind.describe()))
                        .with_help(match item {
                            ast::Item::RosImport(import) => format!(
                                "give the imported type another name: `import ros \"{}\" as Other{};`",
                                import.ros_name.value, name.name
                            ),
                            _ => "every packet, enum, converter and component needs its own name, across all files".to_owned(),
                        }),
                    ),
                    None => {
                        symbols.defs.insert(name.name.clone(), def);
                    }
                }
            }
        }
        for file in files {
            let mut seen = BTreeSet::new();
            let mut todo = vec![file.id];
            while let Some(next) = todo.pop() {
                if seen.insert(next) {
                    todo.extend(imports.get(next.0 as usize).into_iter().flatten().copied());
                }
            }
            symbols.visible.push(seen);
        }
        symbols
    }

    /// Records which `import ros` names have no loaded type in `interfaces`.
    pub fn note_unloaded(&mut self, files: &[ast::File], interfaces: &ros::Interfaces) {
        for file in files {
            for item in &file.items {
                if let ast::Item::RosImport(import) = item
                    && let Some((_, name)) = def_of(item)
                    && !ros::TypeName::parse(&import.ros_name.value)
                        .is_ok_and(|ros| interfaces.get(&ros).is_some())
                {
                    self.unloaded.insert(name.name.clone());
                }
            }
        }
    }

    /// Records the top-level names of the `.cool` files next to the loaded ones that
    /// were not loaded: `list(dir)` gives the files of a directory, `loader` reads
    /// one. Only their names are kept (syntax errors in them are not reported: they
    /// are not part of the analysis).
    pub fn add_siblings(
        &mut self,
        sources: &SourceMap,
        list: &dyn Fn(&Path) -> Vec<PathBuf>,
        loader: &dyn Fn(&Path) -> std::io::Result<String>,
    ) {
        let dirs: BTreeSet<&PathBuf> = self.dirs.iter().collect();
        let mut found: BTreeMap<String, Vec<(PathBuf, DefKind)>> = BTreeMap::new();
        for dir in dirs {
            let mut paths: Vec<PathBuf> = list(dir)
                .into_iter()
                .filter(|path| path.extension().is_some_and(|e| e == "cool"))
                .map(|path| normalize(&path))
                .filter(|path| sources.find(path).is_none())
                .collect();
            paths.sort();
            for path in paths {
                let Ok(text) = loader(&path) else { continue };
                let (file, _) = syntax::parse(FileId(u32::MAX), &text);
                for item in &file.items {
                    if let Some((kind, name)) = def_of(item) {
                        found
                            .entry(name.name.clone())
                            .or_default()
                            .push((path.clone(), kind));
                    }
                }
            }
        }
        self.siblings = found;
    }

    /// The file next to `from`, not imported, that defines `name` as one of `accept`.
    fn sibling(&self, from: FileId, name: &str, accept: &[DefKind]) -> Option<String> {
        let dir = self.dirs.get(from.0 as usize)?;
        self.siblings
            .get(name)?
            .iter()
            .find(|(path, kind)| {
                accept.contains(kind) && path.parent().unwrap_or(Path::new("")) == dir
            })
            .and_then(|(path, _)| Some(path.file_name()?.to_string_lossy().into_owned()))
    }

    /// The path that imports the file `to` from the file `from`: relative to `from`'s
    /// directory, with `/` between components, as an `import` names it.
    fn import_path(&self, from: FileId, to: FileId) -> Option<String> {
        // Both absolute: a `..` left in a relative path would stand for a directory
        // whose name it does not say.
        let here = lexical(&std::path::absolute(self.dirs.get(from.0 as usize)?).ok()?);
        let there = lexical(&std::path::absolute(self.files.get(to.0 as usize)?).ok()?);
        let common = here
            .iter()
            .zip(there.iter())
            .take_while(|(a, b)| a == b)
            .count();
        let mut parts: Vec<String> = here.iter().skip(common).map(|_| "..".to_owned()).collect();
        parts.extend(
            there
                .iter()
                .skip(common)
                .map(|part| part.to_string_lossy().into_owned()),
        );
        Some(parts.join("/"))
    }

    /// Looks `name` up as seen from `from`.
    pub fn lookup(&self, from: FileId, name: &str) -> Lookup {
        let Some(def) = self.defs.get(name) else {
            return Lookup::Missing;
        };
        let Some(visible) = self.visible.get(from.0 as usize) else {
            return Lookup::Found(*def);
        };
        let shared = self.shared.get(name);
        if visible.contains(&def.file) || shared.is_some_and(|s| !s.is_disjoint(visible)) {
            Lookup::Found(*def)
        } else {
            Lookup::NotImported(*def)
        }
    }

    /// Resolves `name` to a definition of an accepted kind, or reports why not.
    pub fn resolve(
        &self,
        from: FileId,
        name: &ast::Ident,
        accept: &[DefKind],
        code: Code,
        what: &str,
        diagnostics: &mut Vec<Diagnostic>,
    ) -> Option<Def> {
        match self.lookup(from, &name.name) {
            Lookup::Found(def) if accept.contains(&def.kind) => Some(def),
            Lookup::Found(def) => {
                diagnostics.push(
                    Diagnostic::error(
                        code,
                        from,
                        name.span,
                        format!("`{}` is a {}, not a {what}", name.name, def.kind.describe()),
                    )
                    .with_label(format!("expected a {what}"))
                    .with_other(
                        def.file,
                        def.name_span,
                        format!("`{}` is defined here", name.name),
                    ),
                );
                None
            }
            Lookup::NotImported(def) => {
                let help = match self.import_path(from, def.file) {
                    Some(path) => format!(
                        "`{}` is defined in `{path}`: add `import \"{path}\";` to this file",
                        name.name
                    ),
                    None => format!(
                        "`{}` is defined in `{}`: import it",
                        name.name,
                        self.paths
                            .get(def.file.0 as usize)
                            .map_or("", String::as_str)
                    ),
                };
                diagnostics.push(
                    Diagnostic::error(
                        code,
                        from,
                        name.span,
                        format!("unknown {what} `{}`", name.name),
                    )
                    .with_label("not visible from this file")
                    .with_help(help),
                );
                None
            }
            Lookup::Missing => {
                let candidates = self
                    .defs
                    .iter()
                    .filter(|(name, def)| {
                        accept.contains(&def.kind) && !self.unloaded.contains(*name)
                    })
                    .map(|(name, _)| name.as_str());
                let mut diagnostic = Diagnostic::error(
                    code,
                    from,
                    name.span,
                    format!("unknown {what} `{}`", name.name),
                )
                .with_label("not found");
                let shipped = accept
                    .contains(&DefKind::RosMessage)
                    .then(|| ros::shipped::names().find(|ros| ros.name() == name.name))
                    .flatten();
                if let Some(file) = self.sibling(from, &name.name, accept) {
                    diagnostic = diagnostic.with_help(format!(
                        "`{}` is defined in `{file}` next to this file: add `import \"{file}\";`",
                        name.name
                    ));
                } else if let Some(near) = closest(&name.name, candidates) {
                    diagnostic = diagnostic.with_help(format!("did you mean `{near}`?"));
                } else if let Some(ros) = shipped {
                    diagnostic = diagnostic.with_help(format!(
                        "for the ROS 2 message type `{ros}`, add `import ros \"{ros}\";`"
                    ));
                }
                diagnostics.push(diagnostic);
                None
            }
        }
    }
}

/// Whether `second` imports the same ROS type under the same name as `first` (both are
/// then one definition).
fn same_ros_import(files: &[ast::File], first: &Def, second: &Def) -> bool {
    let ros_name = |def: &Def| match files.get(def.file.0 as usize)?.items.get(def.item)? {
        ast::Item::RosImport(import) => Some(import.ros_name.value.as_str()),
        _ => None,
    };
    ros_name(first).is_some_and(|name| ros_name(second) == Some(name))
}

/// What a top-level item defines, and its name (`None` for an import, and for a ROS
/// import whose name is not a name).
/// The name a top-level item defines, if it defines one.
pub(crate) fn def_name(item: &ast::Item) -> Option<&ast::Ident> {
    def_of(item).map(|(_, name)| name)
}

fn def_of(item: &ast::Item) -> Option<(DefKind, &ast::Ident)> {
    Some(match item {
        ast::Item::Import(_) => return None,
        ast::Item::RosImport(import) => (DefKind::RosMessage, import.name.as_ref()?),
        ast::Item::Packet(packet) => (DefKind::Packet, &packet.name),
        ast::Item::Enum(def) => (DefKind::Enum, &def.name),
        ast::Item::ExternPacket(def) => (DefKind::ExternPacket, &def.name),
        ast::Item::Converter(def) => (DefKind::Converter, &def.name),
        ast::Item::Component(def) => (DefKind::Component, &def.name),
    })
}

/// File indices with every file after the files it imports (cycles cut).
fn dependency_order(count: usize, imports: &[Vec<FileId>]) -> Vec<usize> {
    fn visit(index: usize, imports: &[Vec<FileId>], seen: &mut Vec<bool>, order: &mut Vec<usize>) {
        if index >= seen.len() || seen[index] {
            return;
        }
        seen[index] = true;
        for imported in imports.get(index).into_iter().flatten() {
            visit(imported.0 as usize, imports, seen, order);
        }
        order.push(index);
    }
    let mut seen = vec![false; count];
    let mut order = Vec::with_capacity(count);
    for index in 0..count {
        visit(index, imports, &mut seen, &mut order);
    }
    order
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalize_is_lexical() {
        assert_eq!(
            normalize(Path::new("a/./b/../c.cool")),
            PathBuf::from("a/c.cool")
        );
        assert_eq!(
            normalize(Path::new("../x.cool")),
            PathBuf::from("../x.cool")
        );
    }

    /// Roots parsed ahead get the ids of their place in the walk, and so do their
    /// syntax errors: `a` first, then `c` it imports, then `b`.
    #[test]
    fn roots_parsed_ahead_take_their_place_in_the_walk() {
        let texts: BTreeMap<&str, &str> = [
            ("a.cool", "import \"c.cool\";\npacket A { x: f64 }\n"),
            ("b.cool", "packet B { x: }\n"),
            ("c.cool", "packet C { x: f64 }\n"),
        ]
        .into_iter()
        .collect();
        let loader = |path: &Path| {
            texts
                .get(path.to_str().unwrap_or_default())
                .map(|text| (*text).to_owned())
                .ok_or_else(|| std::io::Error::from(std::io::ErrorKind::NotFound))
        };
        let loaded = load(&["a.cool", "b.cool"], &loader);
        let id = |name: &str| loaded.sources.find(Path::new(name)).unwrap();
        assert_eq!(
            [id("a.cool"), id("c.cool"), id("b.cool")],
            [FileId(0), FileId(1), FileId(2)]
        );
        for (index, file) in loaded.files.iter().enumerate() {
            assert_eq!(file.id, FileId(index as u32));
        }
        assert!(!loaded.diagnostics.is_empty());
        for diagnostic in &loaded.diagnostics {
            assert_eq!(diagnostic.file, id("b.cool"), "{diagnostic:?}");
        }
    }
}
