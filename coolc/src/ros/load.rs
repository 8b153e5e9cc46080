//! Loads message types and every type they reference: each file found
//! (`lookup`), added to the [`SourceMap`] and parsed ([`super::parse`]), its
//! nested types loaded in turn. A type no place defines is a diagnostic at the
//! reference that needs it, naming every file looked for; types that contain
//! themselves are a diagnostic at the field that closes the circle.
//!
//! **Invariant:** every wanted type is looked up and every file read is parsed;
//! nothing stops at the first error.

use std::collections::{BTreeMap, HashSet, VecDeque};
use std::io;
use std::path::Path;

use crate::ast::{FileId, Span};
use crate::diagnostics::{Code, Diagnostic, Severity};
use crate::source::SourceMap;

use super::definition;
use super::description::{self, TypeDescription};
use super::hash::TypeHash;
use super::lookup::{LookupError, Search};
use super::msg::{Base, Message};
use super::names::TypeName;
use super::parse::parse;
use super::shipped;

/// A type asked for, and where it was asked for (diagnostics point there).
#[derive(Clone, Copy, Debug)]
pub struct Wanted<'a> {
    /// Its full name, `pkg/msg/Type`.
    pub name: &'a str,
    /// The file that asks for it.
    pub file: FileId,
    /// Where in that file.
    pub span: Span,
}

/// What [`load`] read: every message type loaded, and every problem found.
#[derive(Clone, Debug, Default)]
pub struct Interfaces {
    messages: BTreeMap<TypeName, Message>,
    /// Every diagnostic: each file's parse diagnostics in load order, then missing
    /// types, then circles.
    pub diagnostics: Vec<Diagnostic>,
}

/// Loads `wanted` and every type they reference, through `search`; files read with
/// `loader` are added to `sources`.
pub fn load(
    search: &Search,
    wanted: &[Wanted<'_>],
    sources: &mut SourceMap,
    loader: &dyn Fn(&Path) -> io::Result<String>,
) -> Interfaces {
    let mut interfaces = Interfaces::default();
    let mut missing = Vec::new();
    let mut queue = VecDeque::new();
    for want in wanted {
        match TypeName::parse(want.name) {
            Ok(name) => queue.push_back((name, want.file, want.span)),
            Err(error) => {
                let help = match want.name.split('/').collect::<Vec<_>>()[..] {
                    [package, name] => format!("write `{package}/msg/{name}`"),
                    _ => "a ROS 2 message type is named `<package>/msg/<Type>`, as `sensor_msgs/msg/LaserScan`".to_owned(),
                };
                missing.push(
                    Diagnostic::error(Code::UnknownType, want.file, want.span, error.to_string())
                        .with_help(help),
                );
            }
        }
    }
    let mut seen = HashSet::new();
    while let Some((name, file, span)) = queue.pop_front() {
        if !seen.insert(name.clone()) {
            continue;
        }
        match search.find(&name, loader) {
            Ok(found) => {
                let id = match sources.find(&found.path) {
                    Some(id) => id,
                    None => sources.add(found.path, found.text),
                };
                let (message, diagnostics) = parse(&name, id, sources.text(id));
                interfaces.diagnostics.extend(diagnostics);
                for field in &message.fields {
                    if let Base::Nested(nested) = &field.ty.base {
                        queue.push_back((nested.clone(), id, field.ty_span));
                    }
                }
                interfaces.messages.insert(name, message);
            }
            Err(error) => missing.push(not_found(error, file, span)),
        }
    }
    interfaces.diagnostics.extend(missing);
    let circles = interfaces.circles();
    interfaces.diagnostics.extend(circles);
    interfaces
}

fn not_found(error: LookupError, file: FileId, span: Span) -> Diagnostic {
    let message = error.to_string();
    match error {
        LookupError::Missing { name, searched } => {
            let mut help = String::from("looked for");
            for path in &searched {
                help.push_str("\n  ");
                help.push_str(&path.to_string_lossy());
            }
            if name.name() == "Header" && name.package() != "std_msgs" {
                help.push_str("\nthe standard header is `std_msgs/Header`");
            } else if let Some(near) = shipped::nearest(&name) {
                help.push_str(&format!("\ndid you mean `{near}`?"));
            } else {
                help.push_str(&format!(
                    "\na type coolc does not ship is read from a directory that holds \
                     `{}/msg/{}.msg`: give it with `--ros-path DIR` (`Builder::ros_path` in a \
                     build script), or source the ROS 2 workspace that has it \
                     (`AMENT_PREFIX_PATH`)",
                    name.package(),
                    name.name()
                ));
            }
            Diagnostic::error(Code::UnknownType, file, span, message).with_help(help)
        }
        LookupError::Unreadable { source, .. } => Diagnostic::error(
            Code::ImportNotFound,
            file,
            span,
            format!("{message}: {source}"),
        ),
    }
}

impl Interfaces {
    /// A loaded type.
    pub fn get(&self, name: &TypeName) -> Option<&Message> {
        self.messages.get(name)
    }

    /// Every loaded type, by name.
    pub fn messages(&self) -> impl Iterator<Item = &Message> {
        self.messages.values()
    }

    /// True when at least one diagnostic is an error.
    pub fn has_errors(&self) -> bool {
        self.diagnostics
            .iter()
            .any(|d| d.severity == Severity::Error)
    }

    /// The type description of `name`: `None` when it, or a type it references, was
    /// not loaded or has an error in its file.
    pub fn description(&self, name: &TypeName) -> Option<TypeDescription> {
        let description = description::describe(name, |name| self.get(name))?;
        let files: HashSet<FileId> = std::iter::once(&description.type_description)
            .chain(&description.referenced_type_descriptions)
            .filter_map(|d| TypeName::parse(&d.type_name).ok())
            .filter_map(|name| self.get(&name).map(|m| m.file))
            .collect();
        let clean = !self
            .diagnostics
            .iter()
            .any(|d| d.severity == Severity::Error && files.contains(&d.file));
        clean.then_some(description)
    }

    /// The RIHS01 hash of `name` (see [`Interfaces::description`] for `None`).
    pub fn hash(&self, name: &TypeName) -> Option<TypeHash> {
        self.description(name).map(|d| TypeHash::of(&d))
    }

    /// The full message definition of `name` as rosbag2 writes it in a bag
    /// ([`super::definition`]), from the texts in `sources` (where [`load`] put them);
    /// `None` as for [`Interfaces::description`].
    pub(crate) fn definition(&self, name: &TypeName, sources: &SourceMap) -> Option<String> {
        self.description(name)?;
        let get = |name: &TypeName| {
            self.get(name)
                .map(|message| (message, sources.text(message.file)))
        };
        definition::full_text(name, &get)
    }

    /// A diagnostic for each circle of types containing themselves, at the field that
    /// closes it.
    fn circles(&self) -> Vec<Diagnostic> {
        #[derive(Clone, Copy, PartialEq)]
        enum Mark {
            Open,
            Done,
        }
        fn visit<'a>(
            interfaces: &'a Interfaces,
            name: &'a TypeName,
            path: &mut Vec<&'a TypeName>,
            marks: &mut BTreeMap<&'a TypeName, Mark>,
            out: &mut Vec<Diagnostic>,
        ) {
            let Some(message) = interfaces.get(name) else {
                return;
            };
            marks.insert(name, Mark::Open);
            path.push(name);
            for field in &message.fields {
                let Base::Nested(next) = &field.ty.base else {
                    continue;
                };
                match marks.get(next) {
                    Some(Mark::Open) => {
                        let from = path.iter().position(|n| *n == next).unwrap_or(0);
                        let chain: Vec<String> = path[from..]
                            .iter()
                            .chain(std::iter::once(&next))
                            .map(|n| n.to_string())
                            .collect();
                        out.push(
                            Diagnostic::error(
                                Code::RecursivePacket,
                                message.file,
                                field.ty_span,
                                format!("`{next}` contains itself: {}", chain.join(" -> ")),
                            )
                            .with_label("closes the circle"),
                        );
                    }
                    Some(Mark::Done) => {}
                    None => visit(interfaces, next, path, marks, out),
                }
            }
            path.pop();
            marks.insert(name, Mark::Done);
        }
        let mut marks = BTreeMap::new();
        let mut out = Vec::new();
        for name in self.messages.keys() {
            if !marks.contains_key(name) {
                visit(self, name, &mut Vec::new(), &mut marks, &mut out);
            }
        }
        out
    }
}
