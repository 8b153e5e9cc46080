//! The checked model: an [`crate::Analysis`] without errors, and the model the
//! checker resolved and ran over.
//!
//! A [`Checked`] can only be obtained from [`crate::Analysis::checked`], which refuses
//! an analysis with errors: `lower` and `diagram` take one, so "generate only from
//! descriptions that passed the checker" is a type, not a convention each caller must
//! remember. It holds no syntax tree: [`model`] is every component, packet, enum,
//! extern packet, ROS import and converter resolved ([`Checked::components`],
//! [`Checked::types`], [`Checked::converters`]), each component once, by the model
//! the checks consult (ports with their kinds and packet types through exports,
//! variables with their types through mappings, its adaptation tuning, every `when`
//! rule typed by the one rule typer, `check::rules`), every value evaluated; and
//! every ROS 2 message type read ([`Checked::ros_messages`], with its hash). `lower`
//! and `diagram` read only this model (a `when` condition is its typed tree), never a
//! syntax tree, and look no name up.

pub(crate) use crate::check::model;

use std::collections::BTreeMap;

use crate::check::Resolved;
use crate::diagnostics::{self, Diagnostic, RenderOptions};
use crate::source::SourceMap;

/// Descriptions that passed every check (warnings aside), with what the checker
/// resolved.
#[derive(Clone, Debug)]
pub struct Checked {
    sources: SourceMap,
    warnings: Vec<Diagnostic>,
    /// Every component, resolved, in source order.
    components: Vec<model::Component>,
    /// Index into `components` by name.
    by_name: BTreeMap<String, usize>,
    /// Every packet, enum and extern packet, resolved, in source order.
    types: Vec<model::TypeDef>,
    /// Every converter, resolved, in source order.
    converters: Vec<model::Converter>,
    /// Every ROS 2 message type imported or referenced, by name.
    ros: Vec<model::RosMessage>,
}

impl Checked {
    /// Only [`crate::Analysis::checked`] builds one, after finding no error.
    pub(crate) fn new(
        sources: SourceMap,
        warnings: Vec<Diagnostic>,
        resolved: Resolved,
        ros: crate::ros::Interfaces,
    ) -> Checked {
        // Every type loaded has a hash and a definition: none has an error in a checked
        // analysis.
        let ros = ros
            .messages()
            .filter_map(|message| {
                Some(model::RosMessage {
                    message: message.clone(),
                    hash: ros.hash(&message.name)?,
                    definition: ros.definition(&message.name, &sources)?,
                })
            })
            .collect();
        let Resolved {
            components,
            types,
            converters,
        } = resolved;
        let by_name = components
            .iter()
            .enumerate()
            .map(|(index, component)| (component.name.clone(), index))
            .collect();
        Checked {
            sources,
            warnings,
            components,
            by_name,
            types,
            converters,
            ros,
        }
    }

    /// Every packet, enum, extern packet and ROS import, in source order (files in
    /// `FileId` order), each once.
    pub(crate) fn types(&self) -> &[model::TypeDef] {
        &self.types
    }

    /// Every converter, in source order, each once.
    pub(crate) fn converters(&self) -> &[model::Converter] {
        &self.converters
    }

    /// Every ROS 2 message type the descriptions import (`import ros`), and every type
    /// those reference, directly or not: each once, by package and name.
    pub(crate) fn ros_messages(&self) -> &[model::RosMessage] {
        &self.ros
    }

    /// The packet, enum, extern packet or ROS import named `name`.
    pub(crate) fn type_def(&self, name: &str) -> Option<&model::TypeDef> {
        self.types.iter().find(|def| def.name() == name)
    }

    /// The resolved component named `name`.
    pub(crate) fn component(&self, name: &str) -> Option<&model::Component> {
        self.components.get(*self.by_name.get(name)?)
    }

    /// Every resolved component, in source order (files in `FileId` order), each
    /// once.
    pub(crate) fn components(&self) -> impl Iterator<Item = &model::Component> {
        self.components.iter()
    }

    /// Every loaded file; `FileId(i)` is `sources().files()[i]`.
    pub fn sources(&self) -> &SourceMap {
        &self.sources
    }

    /// The warnings (a checked analysis has no error).
    pub fn warnings(&self) -> &[Diagnostic] {
        &self.warnings
    }

    /// Renders the warnings (graphical or JSON, see [`RenderOptions`]).
    pub fn render(&self, options: RenderOptions) -> String {
        diagnostics::render(&self.sources, &self.warnings, options)
    }
}

#[cfg(test)]
mod tests {
    use crate::checked::model::RTy;
    use crate::checked::model::{BinaryOp, Node, StateMember};

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
        let compound = checked.component("C").expect("C");
        let automaton = compound.automaton.as_ref().expect("a supervisor");
        let Some(StateMember::When {
            condition: typed, ..
        }) = automaton.states[0].members.first()
        else {
            panic!("a typed when rule: {automaton:?}");
        };
        assert_eq!(typed.ty, RTy::Bool);
        let [state, level] = typed.operands.as_slice() else {
            panic!("`&&` has two operands: {typed:?}");
        };
        // `running_error` is a bare name: the checker resolved it to a state.
        let types: Vec<&RTy> = state.operands.iter().map(|t| &t.ty).collect();
        assert_eq!(types, [&RTy::State, &RTy::State]);
        let types: Vec<&RTy> = level.operands.iter().map(|t| &t.ty).collect();
        assert_eq!(types, [&RTy::Optional(Box::new(RTy::Float)), &RTy::Float]);
        // The typed tree is the expression: each node says what it is.
        assert_eq!(typed.node, Node::Binary(BinaryOp::And));
        assert_eq!(state.node, Node::Binary(BinaryOp::Eq));
        assert_eq!(
            state.operands[0].node,
            Node::Path(vec!["a".to_owned(), "state".to_owned()])
        );
        assert_eq!(
            state.operands[1].node,
            Node::Path(vec!["running_error".to_owned()])
        );
        assert_eq!(level.operands[1].node, Node::Float(0.5));
        assert!(
            checked
                .component("A")
                .is_some_and(|a| a.variables.iter().any(|v| v.name == "level"))
        );
        assert!(checked.component("A").is_some() && checked.type_def("A").is_none());
    }
}
