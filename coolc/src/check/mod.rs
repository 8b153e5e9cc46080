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
//! (instances, connections, interfaces, containment) and `rules` (typed supervisor
//! rule expressions). `model` computes what a component offers to others (ports,
//! variables, states), looking through compounds' exported ports.

mod automaton;
mod component;
mod compound;
pub mod model;
mod names;
mod rules;
mod values;

use std::collections::BTreeSet;

use crate::ast::{self, FileId, Span};
use crate::diagnostics::{Code, Diagnostic, closest};
use crate::resolve::Symbols;

/// Runs every check over every file.
pub fn check(files: &[ast::File], symbols: &Symbols, diagnostics: &mut Vec<Diagnostic>) {
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
        diagnostics,
        file: FileId(0),
        incomplete: false,
    };
    for file in files {
        checker.file = file.id;
        checker.incomplete = incomplete.contains(&file.id);
        for item in &file.items {
            checker.item(item);
        }
    }
    compound::self_containing(&mut checker, files);
}

/// The state shared by the checks: the model and where diagnostics go.
pub(crate) struct Checker<'a, 'd> {
    pub(crate) model: &'a model::Model<'a>,
    pub(crate) diagnostics: &'d mut Vec<Diagnostic>,
    /// The file being checked.
    pub(crate) file: FileId,
    /// The file being checked has syntax errors (parts of it are missing).
    pub(crate) incomplete: bool,
}

impl Checker<'_, '_> {
    fn item(&mut self, item: &ast::Item) {
        match item {
            ast::Item::Import(_) => {}
            ast::Item::Packet(packet) => {
                names::type_name(self, &packet.name);
                names::duplicates(self, packet.fields.iter().map(|f| &f.name), "field");
                for field in &packet.fields {
                    values::field(self, field);
                }
                values::recursive_packet(self, packet);
            }
            ast::Item::Enum(def) => {
                names::type_name(self, &def.name);
                names::duplicates(self, def.variants.iter().map(|v| &v.name), "variant");
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
