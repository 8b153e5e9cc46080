//! Graphviz DOT output: `dot -Tsvg` draws it.
//!
//! Every id is a quoted string. Labels are escaped for DOT strings (`"` and `\`);
//! instance nodes with ports have HTML-like labels (a table with a cell per port,
//! escaped for HTML: `< > & "`), so a port such as `command: fifo<Twist>(16)` shows as
//! written (records are avoided: `dot` cannot lay out some edges between them). An edge to a group ends at a node inside it, clipped at the group's frame
//! (`lhead`/`ltail` with `compound=true`).

use std::collections::BTreeMap;

use super::{Diagram, EdgeStyle, End, Group, Item, Node, Shape};

/// The DOT text of one diagram.
pub(crate) fn render(diagram: &Diagram) -> String {
    let mut anchors = BTreeMap::new();
    collect_anchors(&diagram.items, &mut anchors);
    let mut out = String::new();
    out.push_str(&format!("digraph {} {{\n", quote(&diagram.title())));
    out.push_str(&format!(
        "  graph [rankdir={}, compound=true, fontname=\"Helvetica\", fontsize=12, labelloc=t, label={}];\n",
        if diagram.left_to_right { "LR" } else { "TB" },
        quote(&diagram.title())
    ));
    out.push_str("  node [fontname=\"Helvetica\", fontsize=10];\n");
    out.push_str("  edge [fontname=\"Helvetica\", fontsize=9];\n");
    for item in &diagram.items {
        write_item(&mut out, item, 1);
    }
    for edge in &diagram.edges {
        let mut attributes = Vec::new();
        let (from, ltail) = end_text(&edge.from, &anchors, true);
        let (to, lhead) = end_text(&edge.to, &anchors, false);
        if !edge.label.is_empty() {
            attributes.push(format!("label={}", quote(&edge.label.join("\n"))));
        }
        match edge.style {
            EdgeStyle::Solid => {}
            EdgeStyle::Dashed => attributes.push("style=dashed".to_owned()),
            EdgeStyle::Dotted => attributes.push("style=dotted".to_owned()),
        }
        if let Some(cluster) = ltail {
            attributes.push(format!("ltail={}", quote(&cluster)));
        }
        if let Some(cluster) = lhead {
            attributes.push(format!("lhead={}", quote(&cluster)));
        }
        if attributes.is_empty() {
            out.push_str(&format!("  {from} -> {to};\n"));
        } else {
            out.push_str(&format!("  {from} -> {to} [{}];\n", attributes.join(", ")));
        }
    }
    out.push_str("}\n");
    out
}

/// For each group, the first node inside it (edges to a group end there).
fn collect_anchors(items: &[Item], anchors: &mut BTreeMap<String, String>) -> Option<String> {
    let mut first = None;
    for item in items {
        let found = match item {
            Item::Node(node) => Some(node.id.clone()),
            Item::Group(group) => {
                let inner = collect_anchors(&group.items, anchors);
                if let Some(inner) = &inner {
                    anchors.insert(group.id.clone(), inner.clone());
                }
                inner
            }
        };
        if first.is_none() {
            first = found;
        }
    }
    first
}

/// An edge end as DOT text, and the cluster to clip at when it is a group.
fn end_text(end: &End, anchors: &BTreeMap<String, String>, tail: bool) -> (String, Option<String>) {
    if let Some(anchor) = anchors.get(&end.id) {
        return (quote(anchor), Some(cluster_name(&end.id)));
    }
    let compass = if tail { "e" } else { "w" };
    match &end.port {
        Some(port) => (
            format!("{}:{}:{compass}", quote(&end.id), quote(port)),
            None,
        ),
        None => (quote(&end.id), None),
    }
}

fn cluster_name(id: &str) -> String {
    format!("cluster_{id}")
}

fn write_item(out: &mut String, item: &Item, depth: usize) {
    match item {
        Item::Node(node) => write_node(out, node, depth),
        Item::Group(group) => write_group(out, group, depth),
    }
}

fn write_group(out: &mut String, group: &Group, depth: usize) {
    let indent = "  ".repeat(depth);
    out.push_str(&format!(
        "{indent}subgraph {} {{\n",
        quote(&cluster_name(&group.id))
    ));
    let mut style = Vec::new();
    if group.dashed {
        style.push("dashed");
    }
    if group.rounded {
        style.push("rounded");
    }
    if style.is_empty() {
        out.push_str(&format!(
            "{indent}  graph [label={}];\n",
            quote(&group.label.join("\n"))
        ));
    } else {
        out.push_str(&format!(
            "{indent}  graph [label={}, style={}];\n",
            quote(&group.label.join("\n")),
            quote(&style.join(","))
        ));
    }
    for item in &group.items {
        write_item(out, item, depth + 1);
    }
    out.push_str(&format!("{indent}}}\n"));
}

fn write_node(out: &mut String, node: &Node, depth: usize) {
    let indent = "  ".repeat(depth);
    let mut attributes = Vec::new();
    let mut styles = Vec::new();
    match (&node.ports, node.shape) {
        (Some(ports), _) => {
            attributes.push("shape=plain".to_owned());
            attributes.push(format!("label=<{}>", html_table(node, ports)));
        }
        (None, Shape::Initial) => {
            attributes.push("shape=circle".to_owned());
            attributes.push("width=0.2".to_owned());
            attributes.push("fixedsize=true".to_owned());
            attributes.push("label=\"\"".to_owned());
            styles.push("filled");
            attributes.push("fillcolor=black".to_owned());
        }
        (None, shape) => {
            let (name, style) = match shape {
                Shape::Box => ("box", None),
                Shape::Rounded => ("box", Some("rounded")),
                Shape::Port => ("box", Some("rounded")),
                Shape::Note => ("note", None),
                Shape::Initial => ("circle", None),
            };
            attributes.push(format!("shape={name}"));
            styles.extend(style);
            if shape == Shape::Port {
                attributes.push("height=0.3".to_owned());
            }
            attributes.push(format!("label={}", quote(&node.lines.join("\n"))));
        }
    }
    if node.dashed && node.ports.is_none() {
        styles.push("dashed");
    }
    if !styles.is_empty() {
        attributes.push(format!("style={}", quote(&styles.join(","))));
    }
    out.push_str(&format!(
        "{indent}{} [{}];\n",
        quote(&node.id),
        attributes.join(", ")
    ));
}

/// An instance with its ports: a table of three columns (inputs, the name, outputs),
/// each port a cell edges can end at.
fn html_table(node: &Node, ports: &super::Ports) -> String {
    let rows = ports.inputs.len().max(ports.outputs.len()).max(1);
    let style = if node.dashed { " STYLE=\"dashed\"" } else { "" };
    let mut out =
        format!("<TABLE BORDER=\"1\" CELLBORDER=\"1\" CELLSPACING=\"0\" CELLPADDING=\"4\"{style}>");
    let title = node
        .lines
        .iter()
        .map(|line| html_escape(line))
        .collect::<Vec<_>>()
        .join("<BR/>");
    for row in 0..rows {
        out.push_str("<TR>");
        if !ports.inputs.is_empty() {
            out.push_str(&port_cell(ports.inputs.get(row), "LEFT"));
        }
        if row == 0 {
            out.push_str(&format!("<TD ROWSPAN=\"{rows}\"><B>{title}</B></TD>"));
        }
        if !ports.outputs.is_empty() {
            out.push_str(&port_cell(ports.outputs.get(row), "RIGHT"));
        }
        out.push_str("</TR>");
    }
    out.push_str("</TABLE>");
    out
}

fn port_cell(port: Option<&(String, String)>, align: &str) -> String {
    match port {
        Some((id, label)) => format!(
            "<TD PORT=\"{}\" ALIGN=\"{align}\">{}</TD>",
            html_escape(id),
            html_escape(label)
        ),
        None => "<TD BORDER=\"0\"></TD>".to_owned(),
    }
}

/// Escapes text for an HTML-like label (`<`, `>`, `&`, `"`).
pub(crate) fn html_escape(text: &str) -> String {
    let mut out = String::new();
    for c in text.chars() {
        match c {
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '&' => out.push_str("&amp;"),
            '"' => out.push_str("&quot;"),
            '\n' => out.push_str("<BR/>"),
            c => out.push(c),
        }
    }
    out
}

/// A DOT quoted string: `"` and `\` escaped, newlines as `\n` (centred lines).
pub(crate) fn quote(text: &str) -> String {
    let mut out = String::from("\"");
    for c in text.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_and_html_labels_are_escaped() {
        assert_eq!(quote("say \"hi\"\\n"), "\"say \\\"hi\\\"\\\\n\"");
        assert_eq!(quote("a\nb"), "\"a\\nb\"");
        assert_eq!(
            html_escape("command: fifo<Twist>(16) {x|y} \"q\" && b"),
            "command: fifo&lt;Twist&gt;(16) {x|y} &quot;q&quot; &amp;&amp; b"
        );
    }
}
