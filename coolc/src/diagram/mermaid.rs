//! Mermaid flowchart output (GitHub renders it in Markdown).
//!
//! Mermaid ids are restricted (and some words, such as `end`, break a flowchart), so
//! every node and group gets a generated id (`n0`, `g0`) in order of appearance, and
//! the names live in the labels. Labels are quoted, with `"`, `<`, `>`, `&`, `#` and
//! `|` written as mermaid entity codes so that `fifo<Twist>(16)` shows as written.
//! Ports are not drawn on nodes: an edge's label starts with the ports it joins.

use std::collections::BTreeMap;

use super::{Diagram, EdgeStyle, Group, Item, Node, Shape};

/// The mermaid text of one diagram.
pub(crate) fn render(diagram: &Diagram) -> String {
    let mut ids = Ids::default();
    let mut out = String::new();
    out.push_str(&format!("%% {}\n", diagram.title().replace('\n', " ")));
    out.push_str(&format!(
        "flowchart {}\n",
        if diagram.left_to_right { "LR" } else { "TB" }
    ));
    let mut styles = Vec::new();
    for item in &diagram.items {
        write_item(&mut out, item, 1, &mut ids, &mut styles);
    }
    for edge in &diagram.edges {
        let from = ids.get(&edge.from.id);
        let to = ids.get(&edge.to.id);
        let mut label: Vec<String> = Vec::new();
        if let Some(ports) = &edge.ports {
            label.push(ports.clone());
        }
        label.extend(edge.label.iter().cloned());
        let arrow = match edge.style {
            EdgeStyle::Solid => "-->",
            EdgeStyle::Dashed | EdgeStyle::Dotted => "-.->",
        };
        if label.is_empty() {
            out.push_str(&format!("  {from} {arrow} {to}\n"));
        } else {
            out.push_str(&format!("  {from} {arrow}|{}| {to}\n", text(&label)));
        }
    }
    if styles.iter().any(|(_, class)| *class == "initial") {
        out.push_str("  classDef initial fill:#000,stroke:#000\n");
    }
    if styles.iter().any(|(_, class)| *class == "dashed") {
        out.push_str("  classDef dashed stroke-dasharray:5 5\n");
    }
    for (id, class) in &styles {
        out.push_str(&format!("  class {id} {class}\n"));
    }
    out
}

/// Generated ids, by the diagram's ids.
#[derive(Default)]
struct Ids {
    map: BTreeMap<String, String>,
    nodes: usize,
    groups: usize,
}

impl Ids {
    fn node(&mut self, id: &str) -> String {
        let next = format!("n{}", self.nodes);
        self.nodes += 1;
        self.map.entry(id.to_owned()).or_insert(next).clone()
    }

    fn group(&mut self, id: &str) -> String {
        let next = format!("g{}", self.groups);
        self.groups += 1;
        self.map.entry(id.to_owned()).or_insert(next).clone()
    }

    /// The generated id of `id` (a dangling end would be a diagram bug: it gets an id
    /// of its own, which mermaid draws as a lone node rather than failing).
    fn get(&mut self, id: &str) -> String {
        if let Some(found) = self.map.get(id) {
            return found.clone();
        }
        self.node(id)
    }
}

fn write_item(
    out: &mut String,
    item: &Item,
    depth: usize,
    ids: &mut Ids,
    styles: &mut Vec<(String, &'static str)>,
) {
    match item {
        Item::Node(node) => write_node(out, node, depth, ids, styles),
        Item::Group(group) => write_group(out, group, depth, ids, styles),
    }
}

fn write_group(
    out: &mut String,
    group: &Group,
    depth: usize,
    ids: &mut Ids,
    styles: &mut Vec<(String, &'static str)>,
) {
    let indent = "  ".repeat(depth);
    let id = ids.group(&group.id);
    out.push_str(&format!("{indent}subgraph {id} [{}]\n", text(&group.label)));
    for item in &group.items {
        write_item(out, item, depth + 1, ids, styles);
    }
    out.push_str(&format!("{indent}end\n"));
    if group.dashed {
        styles.push((id, "dashed"));
    }
}

fn write_node(
    out: &mut String,
    node: &Node,
    depth: usize,
    ids: &mut Ids,
    styles: &mut Vec<(String, &'static str)>,
) {
    let indent = "  ".repeat(depth);
    let id = ids.node(&node.id);
    let label = text(&node.lines);
    let shape = match node.shape {
        Shape::Box => format!("[{label}]"),
        Shape::Rounded => format!("({label})"),
        Shape::Port => format!("([{label}])"),
        Shape::Note => format!(">{label}]"),
        Shape::Initial => "((\" \"))".to_owned(),
    };
    out.push_str(&format!("{indent}{id}{shape}\n"));
    if node.shape == Shape::Initial {
        styles.push((id.clone(), "initial"));
    }
    if node.dashed {
        styles.push((id, "dashed"));
    }
}

/// Lines as one quoted mermaid label.
fn text(lines: &[String]) -> String {
    let lines: Vec<String> = lines.iter().map(|line| escape(line)).collect();
    format!("\"{}\"", lines.join("<br/>"))
}

/// Escapes one line for a quoted mermaid label.
pub(crate) fn escape(line: &str) -> String {
    let mut out = String::new();
    for c in line.chars() {
        match c {
            '"' => out.push_str("#quot;"),
            '<' => out.push_str("#lt;"),
            '>' => out.push_str("#gt;"),
            '&' => out.push_str("#amp;"),
            '#' => out.push_str("#35;"),
            '|' => out.push_str("#124;"),
            '\n' => out.push_str("<br/>"),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_are_escaped_with_entity_codes() {
        assert_eq!(
            escape("fifo<Twist>(16) | \"q\" && #1"),
            "fifo#lt;Twist#gt;(16) #124; #quot;q#quot; #amp;#amp; #35;1"
        );
    }
}
