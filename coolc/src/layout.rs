//! rustfmt's layout, computed while rendering, for the shapes of Rust that the atomic
//! and user templates emit, so that those files need no formatter at run time.
//!
//! The templates are written in the layout `rustfmt` (edition 2024, default
//! configuration: `max_width` 100, block indentation) gives them; what depends on the
//! description (names, lists of states and ports, the `Spec` tables) is laid out here
//! with rustfmt's rules for those shapes: a struct literal stays on one line when its
//! fields take at most 18 columns (`struct_lit_width`), a call's arguments and an
//! array's items at most 60 (`fn_call_width`, `array_width`), a method chain at most
//! 60 (`chain_width`), and a lone struct-literal argument or array item "overflows"
//! (opens on the line of its parent). Anything these rules do not cover, or that
//! comes near the edge of them (a line over 100 columns, a list of short items that
//! rustfmt would pack several per line), clears [`Layout::ok`]: the caller then runs
//! the real formatter over the file. So a strange description costs time, never a
//! file that `cargo fmt` would change. `coolc/tests/rustfmt_clean.rs` checks the claim
//! against `rustfmt` on every fixture and example.

use std::cell::Cell;

/// rustfmt's `max_width`.
const MAX_WIDTH: usize = 100;
/// rustfmt's `struct_lit_width` (the default "small heuristics").
const STRUCT_LIT_WIDTH: usize = 18;
/// rustfmt's `fn_call_width` and `array_width`.
const LIST_WIDTH: usize = 60;
/// rustfmt's `chain_width`.
const CHAIN_WIDTH: usize = 60;
/// Array items at most this wide may be packed several per line by rustfmt
/// (`short_array_element_width_threshold`): such lists are not laid out here.
const SHORT_ITEM: usize = 10;

/// Lays out pieces of one file and records whether every piece is certain.
#[derive(Debug)]
pub struct Layout {
    ok: Cell<bool>,
}

impl Default for Layout {
    fn default() -> Layout {
        Layout {
            ok: Cell::new(true),
        }
    }
}

/// A Rust expression as the lowering writes it, split where rustfmt may break lines.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Node {
    /// Anything without a bracket rustfmt would break at: a path, literal, `-1`.
    Atom(String),
    /// `Path { field: value, ... }`.
    Struct(String, Vec<(String, Node)>),
    /// `callee(args)`.
    Call(String, Vec<Node>),
    /// `&[items]`, `[items]` or `::std::vec![items]`: the opening text, the items.
    List(String, Vec<Node>),
}

fn spaces(n: usize) -> String {
    " ".repeat(n)
}

impl Layout {
    /// Whether everything laid out so far is exactly what rustfmt would write.
    pub fn ok(&self) -> bool {
        self.ok.get()
    }

    /// Marks the file as needing a formatter. With `COOLC_LAYOUT_DEBUG` set, says
    /// where (to find which rule a description falls outside of).
    #[track_caller]
    fn fail(&self) {
        if std::env::var_os("COOLC_LAYOUT_DEBUG").is_some() {
            eprintln!(
                "coolc: layout left to the formatter at {}",
                std::panic::Location::caller()
            );
        }
        self.ok.set(false);
    }

    /// Doc-comment lines (`marker` is `///` or `//!`), each on its own line at
    /// `indent` and preceded by a newline; an empty line gets no trailing space.
    pub fn doc(&self, lines: &[String], indent: usize, marker: &str) -> String {
        let mut out = String::new();
        for line in lines {
            out.push('\n');
            out.push_str(&spaces(indent));
            out.push_str(marker);
            let line = line.trim_end();
            if !line.is_empty() {
                out.push(' ');
                out.push_str(line);
            }
        }
        out
    }

    /// `pub name: ty,`, a field declaration at indent 4.
    pub fn decl(&self, name: &str, ty: &str) -> String {
        self.line(4, &format!("pub {name}: {ty},"))
    }

    /// `#[serde(with = "adapter")]`, a field attribute at indent 4 (left to the
    /// formatter when it does not fit on one line).
    pub fn serde_with(&self, adapter: &str) -> String {
        self.line(4, &format!("#[serde(with = \"{adapter}\")]"))
    }

    /// A match arm `pattern => body,` at `indent`, `body` a short expression.
    pub fn arm(&self, indent: usize, pattern: &str, body: &str) -> String {
        if body.len() > CHAIN_WIDTH {
            self.fail();
        }
        self.line(indent, &format!("{pattern} => {body},"))
    }

    /// The statement `lhs = rhs;` at `indent`, `rhs` a call or chain of at most
    /// `chain_width` columns: on one line when it fits, else the right-hand side
    /// alone on the next line, indented (rustfmt's choice when that fits).
    pub fn assign(&self, indent: usize, lhs: &str, rhs: &str) -> String {
        if rhs.len() > CHAIN_WIDTH {
            self.fail();
        }
        let one = format!("{lhs} = {rhs};");
        if indent + one.len() <= MAX_WIDTH {
            return self.line(indent, &one);
        }
        format!(
            "{} =\n{}",
            self.line(indent, lhs),
            self.line(indent + 4, &format!("{rhs};"))
        )
    }

    /// A function signature `fn name(params) -> ret` followed by `end` (`;` or ` {`)
    /// at `indent`: on one line when it fits, else one parameter per line.
    pub fn signature(&self, indent: usize, signature: &str, end: &str) -> String {
        let one = format!("{signature}{end}");
        // A signature of exactly `max_width` columns gets rustfmt's odd layout with
        // the return type alone on the next line: left to rustfmt.
        match (indent + one.len()).cmp(&MAX_WIDTH) {
            std::cmp::Ordering::Less => return self.line(indent, &one),
            std::cmp::Ordering::Equal => {
                self.fail();
                return self.line(indent, &one);
            }
            std::cmp::Ordering::Greater => {}
        }
        let (Some(open), Some(close)) = (signature.find('('), signature.find(')')) else {
            self.fail();
            return self.line(indent, &one);
        };
        let params = &signature[open + 1..close];
        if params.contains(['(', ')']) {
            self.fail();
        }
        let mut out = self.line(indent, &signature[..=open]);
        for param in params.split(", ") {
            out.push('\n');
            out.push_str(&self.line(indent + 4, &format!("{param},")));
        }
        out.push('\n');
        out.push_str(&self.line(indent, &format!("{}{end}", &signature[close..])));
        out
    }

    /// A user-file stub: the method with its body, at indent 4.
    pub fn stub(&self, method: &crate::ir::Method) -> String {
        let mut out = self.signature(4, &method.user_signature, " {");
        for line in &method.stub_body {
            out.push('\n');
            if line.starts_with("//") {
                out.push_str(&spaces(8));
                out.push_str(line);
            } else if let Some(node) = parse(line) {
                out.push_str(&spaces(8));
                out.push_str(&self.node(&node, 8, 8, 0, false));
            } else {
                out.push_str(&self.short(8, line));
            }
        }
        out.push_str("\n    }");
        out
    }

    /// `Self { field: default, ... }`, the body of a `Default` impl at indent 8.
    pub fn defaults(&self, fields: &[crate::ir::Field]) -> String {
        let fields: Vec<(String, String)> = fields
            .iter()
            .map(|f| (f.name.clone(), f.default.clone()))
            .collect();
        self.struct_lit("Self", &fields, 8, 8, 0)
    }

    /// [`Layout::defaults`] of the variables.
    pub fn var_defaults(&self, vars: &[crate::ir::Var]) -> String {
        let fields: Vec<(String, String)> = vars
            .iter()
            .map(|v| (v.field.name.clone(), v.field.default.clone()))
            .collect();
        self.struct_lit("Self", &fields, 8, 8, 0)
    }

    /// `pub const ALL: [UserState; n] = [...];` at indent 4.
    pub fn all_states(&self, c: &crate::ir::Atomic) -> String {
        let head = format!("pub const ALL: [UserState; {}] = ", c.states.len());
        let list = Node::List(
            "[".to_owned(),
            c.states
                .iter()
                .map(|s| Node::Atom(format!("UserState::{}", s.variant)))
                .collect(),
        );
        format!("{head}{};", self.node(&list, 4, 4 + head.len(), 1, false))
    }

    /// `let var = Ty { field: ctor, ... };` at indent 4, for the port structs.
    pub fn ports_struct(&self, var: &str, ty: &str, ports: &[crate::ir::Port]) -> String {
        let head = format!("let {var} = ");
        let fields: Vec<(String, String)> = ports
            .iter()
            .map(|p| (p.field.clone(), p.ctor.clone()))
            .collect();
        format!(
            "{head}{};",
            self.struct_lit(ty, &fields, 4, 4 + head.len(), 1)
        )
    }

    /// `let ports = ::coolbot::PortSet::new().input(..)...;` at indent 4: one line
    /// within `chain_width`, else one call per line.
    pub fn port_set(&self, c: &crate::ir::Atomic) -> String {
        let mut calls = vec!["::coolbot::PortSet::new()".to_owned()];
        calls.extend(
            c.inputs
                .iter()
                .map(|p| format!(".input(&inputs.{})", p.field)),
        );
        calls.extend(
            c.outputs
                .iter()
                .map(|p| format!(".output(&outputs.{})", p.field)),
        );
        self.chain(4, "let ports = ", &calls, ";")
    }

    /// A choice arm of the glue's `choose`, at indent 12.
    pub fn choose_arm(&self, state: &usize, method: &str) -> String {
        let calls = [
            "behavior".to_owned(),
            format!(".{method}(&mut cx)"),
            ".map(|target| target.state().index())".to_owned(),
        ];
        self.chain(12, &format!("{state} => "), &calls, ",")
    }

    /// The method chain `calls` (the first is the receiver) after `head` at
    /// `indent`, then `tail`: on one line when it is at most `chain_width` wide and
    /// fits, else the receiver on the first line and one call per line below.
    fn chain(&self, indent: usize, head: &str, calls: &[String], tail: &str) -> String {
        let one: String = calls.concat();
        if calls.len() == 1
            || (one.len() <= CHAIN_WIDTH
                && indent + head.len() + one.len() + tail.len() <= MAX_WIDTH)
        {
            return self.line(indent, &format!("{head}{one}{tail}"));
        }
        let mut out = self.line(indent, &format!("{head}{}", calls[0]));
        for (i, call) in calls.iter().enumerate().skip(1) {
            out.push('\n');
            let end = if i + 1 == calls.len() { tail } else { "" };
            out.push_str(&self.line(indent + 4, &format!("{call}{end}")));
        }
        out
    }

    /// `text` as one line at `indent`: fine when it fits in `max_width`.
    pub fn line(&self, indent: usize, text: &str) -> String {
        if indent + text.len() > MAX_WIDTH || text.contains('\n') {
            self.fail();
        }
        format!("{}{text}", spaces(indent))
    }

    /// `text`, a call or method chain of at most `CHAIN_WIDTH` columns that rustfmt
    /// keeps on one line (at `indent`, as a whole line).
    pub fn short(&self, indent: usize, text: &str) -> String {
        let core = text.trim_end_matches([',', ';']);
        let core = core.rsplit_once(" = ").map_or(core, |(_, rhs)| rhs);
        let core = core.rsplit_once(" => ").map_or(core, |(_, rhs)| rhs);
        if core.len() > CHAIN_WIDTH {
            self.fail();
        }
        self.line(indent, text)
    }

    /// The expression `text` laid out with the first line starting at column `used`
    /// and continuation lines at `indent`, followed by `suffix` columns.
    #[cfg(test)]
    fn expr(&self, text: &str, indent: usize, used: usize, suffix: usize) -> String {
        match parse(text) {
            Some(node) => self.node(&node, indent, used, suffix, false),
            None => {
                self.fail();
                text.to_owned()
            }
        }
    }

    /// A struct literal `path { name: value, ... }` (values as the lowering writes
    /// them) laid out as the right-hand side starting at column `used`.
    pub fn struct_lit(
        &self,
        path: &str,
        fields: &[(String, String)],
        indent: usize,
        used: usize,
        suffix: usize,
    ) -> String {
        let mut parsed = Vec::new();
        for (name, value) in fields {
            match parse(value) {
                Some(node) => parsed.push((name.clone(), node)),
                None => {
                    self.fail();
                    parsed.push((name.clone(), Node::Atom(value.clone())));
                }
            }
        }
        self.node(
            &Node::Struct(path.to_owned(), parsed),
            indent,
            used,
            suffix,
            false,
        )
    }

    /// The `SPEC` static of an atomic component (see `templates/atomic.rs`).
    pub fn spec(&self, c: &crate::ir::Atomic) -> String {
        let s = |t: &str| Node::Atom(t.to_owned());
        let parsed = |t: &str| {
            parse(t).unwrap_or_else(|| {
                self.fail();
                Node::Atom(t.to_owned())
            })
        };
        let port = |kind: &str, p: &crate::ir::Port| {
            Node::Struct(
                format!("::coolbot::{kind}Spec"),
                vec![
                    ("name".to_owned(), literal(&p.cool_name)),
                    ("kind".to_owned(), parsed(&p.kind)),
                    ("packet".to_owned(), literal(&p.packet)),
                    ("pull".to_owned(), s(if p.pull { "true" } else { "false" })),
                ],
            )
        };
        let list = |items: Vec<Node>| Node::List("&[".to_owned(), items);
        let spec = Node::Struct(
            "::coolbot::Spec".to_owned(),
            vec![
                ("type_name".to_owned(), literal(&c.type_name)),
                ("doc".to_owned(), s(&c.doc_literal())),
                (
                    "states".to_owned(),
                    list(c.states.iter().map(|st| parsed(&st.spec)).collect()),
                ),
                ("initial".to_owned(), s(&c.initial.to_string())),
                (
                    "inputs".to_owned(),
                    list(c.inputs.iter().map(|p| port("Input", p)).collect()),
                ),
                (
                    "outputs".to_owned(),
                    list(c.outputs.iter().map(|p| port("Output", p)).collect()),
                ),
                (
                    "variables".to_owned(),
                    list(
                        c.vars
                            .iter()
                            .filter(|v| v.spec_index.is_some())
                            .map(|v| {
                                Node::Struct(
                                    "::coolbot::VarSpec".to_owned(),
                                    vec![
                                        ("name".to_owned(), literal(&v.field.cool_name)),
                                        (
                                            "kind".to_owned(),
                                            s(&format!("::coolbot::VarKind::{}", v.kind)),
                                        ),
                                        ("ty".to_owned(), literal(&v.cool_ty)),
                                        ("doc".to_owned(), s(&v.doc_literal())),
                                        ("range".to_owned(), s(&v.range)),
                                    ],
                                )
                            })
                            .collect(),
                    ),
                ),
                (
                    "exceptions".to_owned(),
                    list(c.exceptions.iter().map(|e| parsed(&e.spec)).collect()),
                ),
                ("timing".to_owned(), parsed(&c.timing)),
            ],
        );
        let head = "pub static SPEC: ::coolbot::Spec = ";
        format!("{head}{};", self.node(&spec, 0, head.len(), 1, false))
    }

    /// One-line form of `node` when rustfmt's width rules allow one (ignoring the
    /// room left on the line).
    fn flat(node: &Node) -> Option<String> {
        match node {
            Node::Atom(text) => Some(text.clone()),
            Node::Struct(path, fields) if fields.is_empty() => Some(format!("{path} {{}}")),
            Node::Struct(path, fields) => {
                let body = fields
                    .iter()
                    .map(|(name, value)| Self::flat(value).map(|v| format!("{name}: {v}")))
                    .collect::<Option<Vec<_>>>()?
                    .join(", ");
                (body.len() <= STRUCT_LIT_WIDTH).then(|| format!("{path} {{ {body} }}"))
            }
            Node::Call(callee, args) => {
                let inner = args
                    .iter()
                    .map(Self::flat)
                    .collect::<Option<Vec<_>>>()?
                    .join(", ");
                (inner.len() <= LIST_WIDTH).then(|| format!("{callee}({inner})"))
            }
            Node::List(open, items) => {
                let inner = items
                    .iter()
                    .map(Self::flat)
                    .collect::<Option<Vec<_>>>()?
                    .join(", ");
                (inner.len() <= LIST_WIDTH).then(|| format!("{open}{inner}]"))
            }
        }
    }

    /// `node` with its first line starting at column `used` (continuations at
    /// `indent`), `suffix` columns following it on its last line. A string literal
    /// that is a struct field's whole value may run past `max_width` (`long_string`),
    /// as rustfmt leaves it.
    fn node(
        &self,
        node: &Node,
        indent: usize,
        used: usize,
        suffix: usize,
        long_string: bool,
    ) -> String {
        if let Some(flat) = Self::flat(node) {
            if used + flat.len() + suffix <= MAX_WIDTH {
                return flat;
            }
            if long_string && matches!(node, Node::Atom(t) if t.starts_with('"')) {
                return flat;
            }
        }
        let inner = spaces(indent + 4);
        match node {
            Node::Atom(text) => {
                self.fail();
                text.clone()
            }
            Node::Struct(path, fields) => {
                if fields.is_empty() || used + path.len() + 2 > MAX_WIDTH {
                    self.fail();
                }
                let mut out = format!("{path} {{\n");
                for (name, value) in fields {
                    let start = indent + 4 + name.len() + 2;
                    out.push_str(&inner);
                    out.push_str(name);
                    out.push_str(": ");
                    out.push_str(&self.node(value, indent + 4, start, 1, true));
                    out.push_str(",\n");
                }
                out.push_str(&spaces(indent));
                out.push('}');
                out
            }
            Node::Call(callee, args) => match &args[..] {
                [arg @ (Node::Struct(..) | Node::List(..))] => {
                    let start = used + callee.len() + 1;
                    format!(
                        "{callee}({})",
                        self.node(arg, indent, start, suffix + 1, false)
                    )
                }
                _ => {
                    self.fail();
                    Self::one_line(node)
                }
            },
            Node::List(open, items) => match &items[..] {
                [item @ Node::Struct(..)] => {
                    let start = used + open.len();
                    format!(
                        "{open}{}]",
                        self.node(item, indent, start, suffix + 1, false)
                    )
                }
                _ => {
                    if items
                        .iter()
                        .any(|i| matches!(i, Node::Atom(t) if t.len() <= SHORT_ITEM))
                        || items.len() < 2
                    {
                        self.fail();
                    }
                    let mut out = format!("{open}\n");
                    for item in items {
                        out.push_str(&inner);
                        out.push_str(&self.node(item, indent + 4, indent + 4, 1, false));
                        out.push_str(",\n");
                    }
                    out.push_str(&spaces(indent));
                    out.push(']');
                    out
                }
            },
        }
    }

    /// `node` on one line whatever the width rules say (for failed layouts).
    fn one_line(node: &Node) -> String {
        match node {
            Node::Atom(text) => text.clone(),
            Node::Struct(path, fields) => format!(
                "{path} {{ {} }}",
                fields
                    .iter()
                    .map(|(n, v)| format!("{n}: {}", Self::one_line(v)))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            Node::Call(callee, args) => format!(
                "{callee}({})",
                args.iter()
                    .map(Self::one_line)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            Node::List(open, items) => format!(
                "{open}{}]",
                items
                    .iter()
                    .map(Self::one_line)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }
}

/// A string literal for `text`, as the lowering writes them.
fn literal(text: &str) -> Node {
    Node::Atom(crate::ident::string_literal(text))
}

/// Parses an expression of the shapes above; `None` for anything else (a method
/// chain, a closure, a repeat array, a char literal).
fn parse(text: &str) -> Option<Node> {
    let mut parser = Parser {
        text: text.as_bytes(),
        at: 0,
    };
    let node = parser.expr()?;
    parser.skip_spaces();
    (parser.at == parser.text.len()).then_some(node)
}

struct Parser<'a> {
    text: &'a [u8],
    at: usize,
}

impl Parser<'_> {
    fn peek(&self) -> Option<u8> {
        self.text.get(self.at).copied()
    }

    fn skip_spaces(&mut self) {
        while self.peek() == Some(b' ') {
            self.at += 1;
        }
    }

    fn eat(&mut self, s: &str) -> bool {
        if self.text[self.at..].starts_with(s.as_bytes()) {
            self.at += s.len();
            true
        } else {
            false
        }
    }

    fn text_from(&self, start: usize) -> Option<String> {
        String::from_utf8(self.text[start..self.at].to_vec()).ok()
    }

    fn expr(&mut self) -> Option<Node> {
        self.skip_spaces();
        let start = self.at;
        if self.eat("&[") || self.eat("[") {
            let open = self.text_from(start)?;
            let items_at = self.at;
            if let Some(items) = self.items(b']') {
                return Some(Node::List(open, items));
            }
            // `[item; count]` with a plain item: one atom, as rustfmt keeps it.
            self.at = items_at;
            self.expr()?;
            self.skip_spaces();
            if !self.eat(";") {
                return None;
            }
            while self.peek().is_some_and(|b| b != b']' && b != b'[') {
                self.at += 1;
            }
            if !self.eat("]") {
                return None;
            }
            return Some(Node::Atom(self.text_from(start)?));
        }
        // The head: up to a bracket or separator, string literals whole.
        while let Some(byte) = self.peek() {
            match byte {
                b'"' => self.string()?,
                b'{' | b'(' | b'[' | b',' | b')' | b']' | b'}' | b';' => break,
                b'\'' | b'|' | b'\n' => return None,
                _ => self.at += 1,
            }
        }
        let head = self.text_from(start)?.trim().to_owned();
        if head.is_empty() {
            return None;
        }
        // A field access or method call (not the point of a number): a chain, which
        // rustfmt breaks past `chain_width`.
        let chained = head
            .as_bytes()
            .windows(2)
            .any(|w| w[1] == b'.' && !w[0].is_ascii_digit())
            || head.starts_with('.');
        match self.peek() {
            Some(b'{') => {
                self.at += 1;
                let mut fields = Vec::new();
                loop {
                    self.skip_spaces();
                    if self.eat("}") {
                        break;
                    }
                    let name_start = self.at;
                    while self
                        .peek()
                        .is_some_and(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'#')
                    {
                        self.at += 1;
                    }
                    let name = self.text_from(name_start)?;
                    if name.is_empty() || !self.eat(": ") {
                        return None;
                    }
                    fields.push((name, self.expr()?));
                    self.skip_spaces();
                    if !self.eat(",") {
                        self.skip_spaces();
                        if !self.eat("}") {
                            return None;
                        }
                        break;
                    }
                }
                Some(Node::Struct(head, fields))
            }
            Some(b'(') if !chained => {
                self.at += 1;
                let args = self.items(b')')?;
                Some(Node::Call(head, args))
            }
            Some(b'(') => None,
            Some(b'[') if head.ends_with('!') => {
                self.at += 1;
                Some(Node::List(format!("{head}["), self.items(b']')?))
            }
            Some(b'[') => None,
            _ if chained && head.len() > CHAIN_WIDTH => None,
            _ => Some(Node::Atom(head)),
        }
    }

    /// Comma-separated expressions up to `close` (consumed).
    fn items(&mut self, close: u8) -> Option<Vec<Node>> {
        let mut items = Vec::new();
        loop {
            self.skip_spaces();
            if self.peek() == Some(close) {
                self.at += 1;
                return Some(items);
            }
            items.push(self.expr()?);
            self.skip_spaces();
            match self.peek() {
                Some(b',') => self.at += 1,
                Some(b) if b == close => {
                    self.at += 1;
                    return Some(items);
                }
                _ => return None,
            }
        }
    }

    fn string(&mut self) -> Option<()> {
        self.at += 1;
        while let Some(byte) = self.peek() {
            self.at += 1;
            match byte {
                b'\\' => self.at += 1,
                b'"' => return Some(()),
                _ => {}
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_lowering_shapes() {
        assert_eq!(
            parse("::coolbot::OnSpec { port: 0, target: 1 }"),
            Some(Node::Struct(
                "::coolbot::OnSpec".to_owned(),
                vec![
                    ("port".to_owned(), Node::Atom("0".to_owned())),
                    ("target".to_owned(), Node::Atom("1".to_owned()))
                ]
            ))
        );
        assert_eq!(
            parse("&[\"a, b\", 1.5]"),
            Some(Node::List(
                "&[".to_owned(),
                vec![
                    Node::Atom("\"a, b\"".to_owned()),
                    Node::Atom("1.5".to_owned())
                ]
            ))
        );
        assert_eq!(parse("a.b(c)"), None);
        assert_eq!(
            parse("[false; 8]"),
            Some(Node::Atom("[false; 8]".to_owned()))
        );
        assert_eq!(parse("f(|x| x)"), None);
    }

    #[test]
    fn struct_literals_follow_struct_lit_width() {
        let layout = Layout::default();
        assert_eq!(
            layout.expr("X { port: 0, target: 1 }", 0, 0, 0),
            "X { port: 0, target: 1 }"
        );
        assert_eq!(
            layout.expr("X { port: 10, target: 1 }", 0, 0, 0),
            "X {\n    port: 10,\n    target: 1,\n}"
        );
        assert_eq!(
            layout.expr("&[X { port: 10, target: 1 }]", 4, 4, 1),
            "&[X {\n        port: 10,\n        target: 1,\n    }]"
        );
        assert!(layout.ok());
    }

    #[test]
    fn uncertain_shapes_clear_ok() {
        let layout = Layout::default();
        let long = format!("&[{}]", vec!["1"; 40].join(", "));
        let _ = layout.expr(&long, 0, 0, 0);
        assert!(!layout.ok());
        let layout = Layout::default();
        let _ = layout.expr("a.b().c()", 0, 0, 0);
        assert!(!layout.ok());
    }
}
