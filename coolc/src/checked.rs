//! The checked model: an [`crate::Analysis`] without errors, and everything the checker
//! resolved in it.
//!
//! A [`Checked`] can only be obtained from [`crate::Analysis::checked`], which refuses
//! an analysis with errors: `lower` and `diagram` take one, so "generate only from
//! descriptions that passed the checker" is a type, not a convention each caller must
//! remember. Its lookups are the checker's: the symbol table (components, types and
//! converters by name, each with its file), every component's interface (ports with
//! their kinds and packet types through exports, variables with their types through
//! mappings, configuration, states, quality levels) and every `when` rule typed by the
//! one rule typer (`check::rules`).
//!
//! On top of them, [`model`] holds every component resolved ([`Checked::component`],
//! [`Checked::components`]), built once by `build`. `diagram` and the lowering of
//! atomic components read only that; the lowering of compounds and of types still
//! reads the syntax trees ([`Checked::ast_component`], [`Checked::files`]).

mod build;
pub mod model;

use std::collections::BTreeMap;

use crate::ast::{self, FileId};
use crate::check::model::{Interface, Tuning, Ty};
use crate::check::{Resolved, Typed};
use crate::diagnostics::{self, Diagnostic, RenderOptions};
use crate::resolve::DefKind;
use crate::source::SourceMap;

/// Descriptions that passed every check (warnings aside), with what the checker
/// resolved.
#[derive(Clone, Debug)]
pub struct Checked {
    sources: SourceMap,
    files: Vec<ast::File>,
    warnings: Vec<Diagnostic>,
    resolved: Resolved,
    /// Every component, resolved, in source order.
    components: Vec<model::Component>,
    /// Index into `components` by name.
    by_name: BTreeMap<String, usize>,
}

/// A type definition, as the symbol table finds it.
#[derive(Clone, Copy, Debug)]
pub enum TypeDef<'a> {
    /// `packet`
    Packet(&'a ast::Packet),
    /// `enum`
    Enum(&'a ast::EnumDef),
    /// `extern packet`
    Extern(&'a ast::ExternPacket),
}

impl Checked {
    /// Only [`crate::Analysis::checked`] builds one, after finding no error.
    pub(crate) fn new(
        sources: SourceMap,
        files: Vec<ast::File>,
        warnings: Vec<Diagnostic>,
        resolved: Resolved,
    ) -> Checked {
        let components = build::components(&files, &resolved);
        let by_name = components
            .iter()
            .enumerate()
            .map(|(index, component)| (component.name.clone(), index))
            .collect();
        Checked {
            sources,
            files,
            warnings,
            resolved,
            components,
            by_name,
        }
    }

    /// The resolved component named `name`.
    pub fn component(&self, name: &str) -> Option<&model::Component> {
        self.components.get(*self.by_name.get(name)?)
    }

    /// Every resolved component, in source order (files in `FileId` order), each
    /// once.
    pub fn components(&self) -> impl Iterator<Item = &model::Component> {
        self.components.iter()
    }

    /// Every loaded file; `FileId(i)` is `sources().files()[i]`.
    pub fn sources(&self) -> &SourceMap {
        &self.sources
    }

    /// One syntax tree per loaded file, in `FileId` order (roots first).
    pub fn files(&self) -> &[ast::File] {
        &self.files
    }

    /// The warnings (a checked analysis has no error).
    pub fn warnings(&self) -> &[Diagnostic] {
        &self.warnings
    }

    /// Renders the warnings (graphical or JSON, see [`RenderOptions`]).
    pub fn render(&self, options: RenderOptions) -> String {
        diagnostics::render(&self.sources, &self.warnings, options)
    }

    fn item(&self, name: &str, kind: DefKind) -> Option<(FileId, &ast::Item)> {
        let def = self.resolved.symbols.defs.get(name)?;
        if def.kind != kind {
            return None;
        }
        let item = self.files.get(def.file.0 as usize)?.items.get(def.item)?;
        Some((def.file, item))
    }

    /// The syntax tree of the component named `name`, with its file (what `lower`
    /// still reads; `diagram` reads only [`Checked::component`]).
    pub fn ast_component(&self, name: &str) -> Option<(FileId, &ast::Component)> {
        match self.item(name, DefKind::Component)? {
            (file, ast::Item::Component(component)) => Some((file, component)),
            _ => None,
        }
    }

    /// The syntax tree of every component, in source order (files in `FileId`
    /// order), each once.
    pub fn ast_components(&self) -> impl Iterator<Item = (FileId, &ast::Component)> {
        self.files.iter().flat_map(move |file| {
            file.items.iter().filter_map(move |item| match item {
                ast::Item::Component(component)
                    if self
                        .ast_component(&component.name.name)
                        .is_some_and(|(at, _)| at == file.id) =>
                {
                    Some((file.id, component))
                }
                _ => None,
            })
        })
    }

    /// The packet, enum or extern packet named `name`.
    pub fn type_def(&self, name: &str) -> Option<TypeDef<'_>> {
        let def = self.resolved.symbols.defs.get(name)?;
        let item = self.files.get(def.file.0 as usize)?.items.get(def.item)?;
        match item {
            ast::Item::Packet(packet) => Some(TypeDef::Packet(packet)),
            ast::Item::Enum(def) => Some(TypeDef::Enum(def)),
            ast::Item::ExternPacket(def) => Some(TypeDef::Extern(def)),
            _ => None,
        }
    }

    /// The converter named `name`.
    pub fn converter(&self, name: &str) -> Option<&ast::Converter> {
        match self.item(name, DefKind::Converter)? {
            (_, ast::Item::Converter(converter)) => Some(converter),
            _ => None,
        }
    }

    /// The interface of component `name`: what it offers to the compounds that
    /// nest it.
    pub fn interface(&self, name: &str) -> Option<&Interface> {
        self.resolved.interfaces.get(name)
    }

    /// The adaptation tuning of instance `instance`: its component's own
    /// `adaptation` block with the instance's block (if any) laid on it.
    pub fn instance_tuning(&self, instance: &ast::Instance) -> Tuning {
        let own = self
            .interface(&instance.component.name)
            .map(|interface| interface.adaptation.clone())
            .unwrap_or_default();
        match instance.adaptation.first() {
            Some(block) => own.overlaid(&Tuning::of(block)),
            None => own,
        }
    }

    /// The resolved type of a written type.
    pub fn ty(&self, ty: &ast::Type) -> Ty {
        crate::check::model::Model::new(&self.files, &self.resolved.symbols).ty(ty)
    }

    /// The `when` condition `condition` of a supervisor in `file`, typed.
    pub fn rule(&self, file: FileId, condition: &ast::Expr) -> Option<&Typed> {
        self.resolved.rules.get(&(file, condition.span))
    }
}

#[cfg(test)]
mod tests {
    use crate::ast;
    use crate::check::RTy;

    #[test]
    fn rules_are_typed_with_their_symbols_resolved() {
        let checked = crate::analyze_text(
            "t.cool",
            "atomic A { observable level: f32? = none; automaton { initial on; state on { entry; } } }\n\
             compound C { instance a: A; supervisor { initial s; state s {\n\
                 when a.state == running_error && a.level > 0.5 -> s;\n\
             } } }",
        )
        .checked()
        .unwrap_or_else(|analysis| panic!("{}", analysis.render(crate::RenderOptions::plain())));
        let (file, compound) = checked.ast_component("C").expect("C");
        let condition = compound
            .members
            .iter()
            .find_map(|member| match member {
                ast::Member::Automaton(automaton) => {
                    automaton.states[0].members.iter().find_map(|m| match m {
                        ast::StateMember::When { condition, .. } => Some(condition),
                        _ => None,
                    })
                }
                _ => None,
            })
            .expect("a when rule");
        let typed = checked.rule(file, condition).expect("typed by the checker");
        assert_eq!(typed.ty, RTy::Bool);
        let [state, level] = typed.operands.as_slice() else {
            panic!("`&&` has two operands: {typed:?}");
        };
        // `running_error` is a bare name: the checker resolved it to a state.
        let types: Vec<&RTy> = state.operands.iter().map(|t| &t.ty).collect();
        assert_eq!(types, [&RTy::State, &RTy::State]);
        let types: Vec<&RTy> = level.operands.iter().map(|t| &t.ty).collect();
        assert_eq!(types, [&RTy::Optional(Box::new(RTy::Float)), &RTy::Float]);
        assert!(
            checked
                .interface("A")
                .is_some_and(|a| a.variables.contains_key("level"))
        );
        assert!(checked.component("A").is_some() && checked.converter("A").is_none());
    }
}
