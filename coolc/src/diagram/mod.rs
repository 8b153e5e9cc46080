//! Diagrams of checked descriptions, after the paper's figures: the interface of a
//! component (its ports and the default ports `c` and `m`, Figure 1), the structure
//! of a compound (instances, connections, Figure 5), and a user automaton or
//! supervisor, optionally inside the default automaton's `running` state (Figures 2
//! and 4).
//!
//! Each view builds a [`Diagram`] (nodes, nested groups, edges: no format in it), which
//! `dot` and `mermaid` print. It takes a [`Checked`] model (there are no errors,
//! names resolve) and finds components through it; output depends only on the
//! descriptions (source order, identifiers from names), never on hashing or
//! addresses.

use crate::ast::FileId;
use crate::checked::Checked;
use crate::checked::model::{Component, ComponentKind};

pub(crate) mod dot;
pub(crate) mod mermaid;
pub(crate) mod text;
mod views;

/// Which drawing of a component.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum View {
    /// Its ports, by kind and direction, with the default ports and variables.
    Interface,
    /// A compound's instances and connections.
    Structure,
    /// Its user automaton (an atomic's) or supervisor (a compound's).
    Automaton,
}

impl View {
    /// The view's name on the command line.
    pub(crate) fn name(self) -> &'static str {
        match self {
            View::Interface => "interface",
            View::Structure => "structure",
            View::Automaton => "automaton",
        }
    }
}

/// What to draw.
#[derive(Clone, Debug, Default)]
pub struct Options {
    /// One component by name (any loaded file); `None`: every component of the root
    /// files.
    pub component: Option<String>,
    /// The views; empty means every view that applies to each component.
    pub views: Vec<View>,
    /// Draw a user automaton inside the default automaton's `running` state.
    pub default_automaton: bool,
}

/// Why the diagrams asked for cannot be drawn.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SelectError {
    /// No component by that name.
    #[error("no component named `{name}` (known: {known})")]
    UnknownComponent {
        /// The name asked for.
        name: String,
        /// The components loaded, comma-separated.
        known: String,
    },
    /// A view that does not apply to the component.
    #[error("`{component}` is atomic: it has no {view} view (try interface or automaton)")]
    NotApplicable {
        /// The component.
        component: String,
        /// The view.
        view: &'static str,
    },
    /// Nothing to draw.
    #[error("the files define no component to draw")]
    Nothing,
}

/// One diagram: a title, a direction and a tree of groups with edges.
#[derive(Clone, Debug, PartialEq)]
pub struct Diagram {
    /// The component drawn.
    pub(crate) component: String,
    /// The view.
    pub(crate) view: View,
    /// Left to right (`true`) or top to bottom.
    pub(crate) left_to_right: bool,
    /// The top-level items (a group without a frame).
    pub(crate) items: Vec<Item>,
    /// Every edge, in a stable order.
    pub(crate) edges: Vec<Edge>,
}

impl Diagram {
    /// `MobileBase · structure`.
    pub fn title(&self) -> String {
        format!("{} · {}", self.component, self.view.name())
    }
}

/// A node or a group of items.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Item {
    /// A node.
    Node(Node),
    /// A framed group (a cluster).
    Group(Group),
}

/// A framed group of items: a nested compound, a redundant group, a state holding
/// an automaton.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Group {
    /// Unique in the diagram (shared with nodes' ids).
    pub(crate) id: String,
    /// Label lines.
    pub(crate) label: Vec<String>,
    /// Dashed frame (redundant groups).
    pub(crate) dashed: bool,
    /// Rounded frame (states).
    pub(crate) rounded: bool,
    /// What it holds.
    pub(crate) items: Vec<Item>,
}

/// How a node is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Shape {
    /// A rectangle (components, instances).
    Box,
    /// A rounded rectangle (states).
    Rounded,
    /// A stadium (ports).
    Port,
    /// A note (variables, policies).
    Note,
    /// The initial-state dot.
    Initial,
}

/// A node.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Node {
    /// Unique in the diagram.
    pub(crate) id: String,
    /// Label lines (the first is the name).
    pub(crate) lines: Vec<String>,
    /// Its shape.
    pub(crate) shape: Shape,
    /// Dashed outline (default ports).
    pub(crate) dashed: bool,
    /// Ports drawn on the node (DOT records); edges may end at them.
    pub(crate) ports: Option<Ports>,
}

/// The ports drawn on an instance node: inputs on the left, outputs on the right.
#[derive(Clone, Debug, PartialEq, Default)]
pub(crate) struct Ports {
    /// `(port id, label)`.
    pub(crate) inputs: Vec<(String, String)>,
    /// `(port id, label)`.
    pub(crate) outputs: Vec<(String, String)>,
}

/// How an edge is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum EdgeStyle {
    /// A plain arrow.
    Solid,
    /// A dashed arrow (`may` transitions, substitutions).
    Dashed,
    /// A dotted arrow (exported ports to what they stand for).
    Dotted,
}

/// An edge between nodes (or node ports, or groups).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Edge {
    /// Where it starts.
    pub(crate) from: End,
    /// Where it ends.
    pub(crate) to: End,
    /// Label lines.
    pub(crate) label: Vec<String>,
    /// Where ports are not drawn on nodes (mermaid), the port names it joins, shown
    /// first in the label.
    pub(crate) ports: Option<String>,
    /// Its style.
    pub(crate) style: EdgeStyle,
}

/// One end of an edge: a node, a port of a node, or a group.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct End {
    /// A node or group id.
    pub(crate) id: String,
    /// A port id of that node.
    pub(crate) port: Option<String>,
}

impl End {
    /// The node or group `id`.
    pub(crate) fn node(id: impl Into<String>) -> End {
        End {
            id: id.into(),
            port: None,
        }
    }
}

/// The output formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Graphviz DOT: one `digraph` per diagram.
    Dot,
    /// Mermaid flowchart: exactly one diagram.
    Mermaid,
    /// Markdown: a heading and a fenced mermaid block per diagram (renders on GitHub).
    Markdown,
}

/// Why diagrams cannot be printed in a format.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum FormatError {
    /// Mermaid holds one diagram per text.
    #[error(
        "{0} diagrams asked for, and a mermaid text holds one: choose one component and one view, or use --format markdown or dot"
    )]
    SeveralMermaid(usize),
}

/// Prints `diagrams` in `format`.
pub fn render(diagrams: &[Diagram], format: Format) -> Result<String, FormatError> {
    match format {
        Format::Dot => Ok(diagrams
            .iter()
            .map(dot::render)
            .collect::<Vec<_>>()
            .join("\n")),
        Format::Mermaid => match diagrams {
            [one] => Ok(mermaid::render(one)),
            _ => Err(FormatError::SeveralMermaid(diagrams.len())),
        },
        Format::Markdown => {
            let mut out = String::new();
            for (index, diagram) in diagrams.iter().enumerate() {
                if index > 0 {
                    out.push('\n');
                }
                out.push_str(&format!(
                    "## {}\n\n```mermaid\n{}```\n",
                    diagram.title(),
                    mermaid::render(diagram)
                ));
            }
            Ok(out)
        }
    }
}

/// The diagrams `options` ask for, from checked descriptions whose first `roots` files
/// are the root files.
pub fn diagrams(
    checked: &Checked,
    roots: usize,
    options: &Options,
) -> Result<Vec<Diagram>, SelectError> {
    let model = views::Lookup::new(checked);
    let chosen: Vec<&Component> = match &options.component {
        Some(name) => match model.component(name) {
            Some(component) => vec![component],
            None => {
                return Err(SelectError::UnknownComponent {
                    name: name.clone(),
                    known: model.names().join(", "),
                });
            }
        },
        None => checked
            .components()
            .filter(|component| (component.file.0 as usize) < roots || component.file == FileId(0))
            .collect(),
    };
    if chosen.is_empty() {
        return Err(SelectError::Nothing);
    }
    let mut out = Vec::new();
    for component in chosen {
        let compound = component.kind == ComponentKind::Compound;
        let views: Vec<View> = if options.views.is_empty() {
            if compound {
                vec![View::Interface, View::Structure, View::Automaton]
            } else {
                vec![View::Interface, View::Automaton]
            }
        } else {
            options.views.clone()
        };
        for view in views {
            match view {
                View::Interface => out.push(model.interface(component)),
                View::Structure if compound => out.push(model.structure(component)),
                View::Structure => {
                    // Asked for one component by name: say why nothing comes; over
                    // every component, the atomic ones simply have no structure.
                    if options.component.is_some() {
                        return Err(SelectError::NotApplicable {
                            component: component.name.clone(),
                            view: view.name(),
                        });
                    }
                }
                View::Automaton => out.push(model.automaton(component, options.default_automaton)),
            }
        }
    }
    if out.is_empty() {
        return Err(SelectError::Nothing);
    }
    Ok(out)
}

/// Ids that stay unique: `base`, `base.motion`, `base.motion:in.command`.
fn join(prefix: &str, name: &str) -> String {
    if prefix.is_empty() {
        name.to_owned()
    } else {
        format!("{prefix}.{name}")
    }
}
