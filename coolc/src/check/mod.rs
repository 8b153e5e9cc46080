//! Checks: every rule of the language, one small function per rule.
//!
//! [`check`] walks every file and item in source order and runs the checks that
//! apply; diagnostics are collected, no check stops the others. A name that failed to
//! resolve yields one diagnostic, and the checks that would depend on it stay quiet
//! (types resolve to [`model::Ty::Unknown`], which matches everything).
//!
//! The submodules group the rules: `names` (keywords, naming, duplicates), `values`
//! (types, defaults, sizes, timing), `component` (members and their placement),
//! `automaton` (states, transitions, reachability, periods, plans), `compound`
//! (instances, connections, interfaces, containment), `thread` (execution groups),
//! `adaptation` (`adaptation` blocks), `ros` (the names `import ros` gives) and
//! `rules` (typed supervisor rule expressions). `model` is the one semantic model the
//! checks consult: each component resolved once (ports through exports, variables
//! through mappings, settings evaluated).
//!
//! The model the checks ran over is kept: [`check`] returns a [`Resolved`] (every
//! component, type and converter, each `when` rule with its typed tree), which
//! `crate::Checked` hands to `lower` and `diagram` once there are no errors.

mod adaptation;
mod automaton;
mod component;
mod compound;
pub mod model;
mod names;
mod response;
mod ros;
mod rules;
mod thread;
mod values;

use std::collections::{BTreeMap, BTreeSet};

use model::Typed;

use crate::ast::{self, FileId, Span};
use crate::diagnostics::{Code, Diagnostic, closest};
use crate::resolve::Symbols;

/// The largest `fifo` or `ufifo` size (packets): the runtime allocates a queue's
/// size when the component starts, so a larger one would fail there, not here.
pub(crate) const MAX_QUEUE_SIZE: u64 = 1 << 20;

/// What the checks resolved: the model `lower` and `diagram` read (through
/// `crate::Checked`, which exists only when there are no errors).
#[derive(Clone, Debug, Default)]
pub struct Resolved {
    /// Every component, resolved, in source order.
    pub(crate) components: Vec<model::Component>,
    /// Every packet, enum, extern packet and ROS import, in source order.
    pub(crate) types: Vec<model::TypeDef>,
    /// Every converter, in source order.
    pub(crate) converters: Vec<model::Converter>,
}

/// Runs every check over every file and returns the model they checked.
pub fn check(
    files: &[ast::File],
    symbols: &Symbols,
    ros: &crate::ros::Interfaces,
    diagnostics: &mut Vec<Diagnostic>,
) -> Resolved {
    let model = model::Model::new(files, symbols);
    // A file with syntax errors lost what failed to parse: checks that need the whole
    // picture (reachability) would only report the loss again.
    let incomplete: BTreeSet<FileId> = diagnostics
        .iter()
        .filter(|d| d.code.as_str().starts_with("coolc::syntax::"))
        .map(|d| d.file)
        .collect();
    let mut checker = Checker {
        model: &model,
        ros,
        diagnostics,
        file: FileId(0),
        incomplete: false,
        rules: BTreeMap::new(),
        packet_elements: BTreeMap::new(),
        packet_layouts: BTreeMap::new(),
    };
    for file in files {
        checker.file = file.id;
        checker.incomplete = incomplete.contains(&file.id);
        for item in &file.items {
            checker.item(item);
        }
    }
    let (types, converters) = model.types();
    component::configuration_defaults(&mut checker, files, &types);
    compound::self_containing(&mut checker, files);
    component::crate_versions(&mut checker, files);
    // Top-level names are one namespace (resolve reports them equal as written); in
    // Rust they are types.
    let top_level: Vec<(FileId, &ast::Ident)> = files
        .iter()
        .flat_map(|file| {
            file.items
                .iter()
                .filter_map(crate::resolve::def_name)
                .map(move |name| (file.id, name))
        })
        .collect();
    names::clashes(&mut checker, top_level, "type", &[names::camel]);
    let rules = std::mem::take(&mut checker.rules);
    Resolved {
        components: model.finish(&rules),
        types,
        converters,
    }
}

/// The state shared by the checks: the model and where diagnostics go.
pub(crate) struct Checker<'a, 'd> {
    pub(crate) model: &'a model::Model<'a>,
    /// The ROS 2 message types loaded (what `import ros` names).
    pub(crate) ros: &'a crate::ros::Interfaces,
    pub(crate) diagnostics: &'d mut Vec<Diagnostic>,
    /// The file being checked.
    pub(crate) file: FileId,
    /// The file being checked has syntax errors (parts of it are missing).
    pub(crate) incomplete: bool,
    /// The `when` conditions typed so far.
    pub(crate) rules: BTreeMap<(FileId, Span), Typed>,
    /// The elements each packet counted so far holds inline (`None`: something in it
    /// is refused for its size already), by name.
    pub(crate) packet_elements: BTreeMap<String, Option<u128>>,
    /// About how many bytes each packet counted so far holds inline, and its
    /// alignment, by name.
    pub(crate) packet_layouts: BTreeMap<String, (u128, u128)>,
}

impl Checker<'_, '_> {
    fn item(&mut self, item: &ast::Item) {
        match item {
            ast::Item::Import(_) => {}
            ast::Item::RosImport(import) => ros::import(self, import),
            ast::Item::Packet(packet) => {
                names::type_name(self, &packet.name);
                names::duplicates(self, packet.fields.iter().map(|f| &f.name), "field");
                names::rust_clashes(
                    self,
                    packet.fields.iter().map(|f| &f.name),
                    "field",
                    &[names::snake],
                );
                for field in &packet.fields {
                    values::field(self, field);
                }
                if !values::recursive_packet(self, packet) {
                    values::packet_size(self, packet);
                }
            }
            ast::Item::Enum(def) => {
                names::type_name(self, &def.name);
                names::duplicates(self, def.variants.iter().map(|v| &v.name), "variant");
                names::rust_clashes(
                    self,
                    def.variants.iter().map(|v| &v.name),
                    "variant",
                    &[names::camel],
                );
                for variant in &def.variants {
                    names::type_name(self, &variant.name);
                }
            }
            ast::Item::ExternPacket(def) => {
                names::type_name(self, &def.name);
                values::extern_path(self, def);
            }
            ast::Item::Converter(def) => {
                names::type_name(self, &def.name);
                values::ty(self, &def.from);
                values::ty(self, &def.to);
            }
            ast::Item::Component(component) => component::component(self, component),
        }
    }

    /// Pushes a diagnostic.
    pub(crate) fn push(&mut self, diagnostic: Diagnostic) {
        self.diagnostics.push(diagnostic);
    }

    /// An error in the current file.
    pub(crate) fn error(&self, code: Code, span: Span, message: impl Into<String>) -> Diagnostic {
        Diagnostic::error(code, self.file, span, message)
    }

    /// Reports an unknown name with "did you mean" help.
    pub(crate) fn unknown<'n>(
        &mut self,
        code: Code,
        name: &ast::Ident,
        what: &str,
        context: &str,
        candidates: impl IntoIterator<Item = &'n str>,
    ) {
        let candidates: Vec<&str> = candidates.into_iter().collect();
        let mut diagnostic = self
            .error(
                code,
                name.span,
                format!("unknown {what} `{}`{context}", name.name),
            )
            .with_label(format!("no {what} with this name"));
        if let Some(near) = closest(&name.name, candidates.iter().copied()) {
            diagnostic = diagnostic.with_help(format!("did you mean `{near}`?"));
        } else if !candidates.is_empty() && candidates.len() <= 8 {
            let list: Vec<String> = candidates.iter().map(|c| format!("`{c}`")).collect();
            diagnostic = diagnostic.with_help(format!("known: {}", list.join(", ")));
        }
        self.push(diagnostic);
    }
}
