//! rustfmt's layout, computed while rendering, for the shapes of Rust that the
//! templates emit (every file of a crate but `build.rs`), so that those files need no
//! formatter at run time.
//!
//! The templates are written in the layout `rustfmt` (edition 2024, default
//! configuration: `max_width` 100, block indentation) gives them; what depends on the
//! description (names, lists of states and ports, the `Spec` tables) is laid out here
//! with rustfmt's rules for those shapes: a struct literal stays on one line when its
//! fields take at most 18 columns (`struct_lit_width`), a call's arguments and an
//! array's items at most 60 (`fn_call_width`, `array_width`), a method chain at most
//! 60 (`chain_width`), and a lone struct-literal argument or array item "overflows"
//! (opens on the line of its parent). Expressions come as the [`Code`] trees `lower`
//! built (no Rust text is parsed here), and each template piece is named for what it
//! prints, its indentation fixed here. A whole statement or expression (a rule's
//! condition, a compound's builder chain, the starter `main`'s calls, a stub's value)
//! goes to [`expr`], rustfmt's own rules for expressions ported. Anything these rules do not cover, or that
//! comes near the edge of them (a line over 100 columns, a list of short items that
//! rustfmt would pack several per line), clears [`Layout::ok`]: the caller then runs
//! the real formatter over the file, or over the one top-level item it happened in
//! when the template marked that item (see [`Layout::begin_item`]: rustfmt lays out
//! each top-level item on its own, so the item comes out as it would in the whole
//! file). So a strange description costs time, never a
//! file that `cargo fmt` would change. `coolc/tests/all/rustfmt_clean.rs` checks the claim
//! against `rustfmt` on every fixture and example.

use std::cell::Cell;

use crate::ir::{Code, StubLine};

pub(crate) mod expr;

/// rustfmt's `max_width`.
const MAX_WIDTH: usize = 100;

/// The indent of a member of an `impl` in a ROS 2 package's module (`ros::<package>`).
const ROS_MEMBER: usize = 12;
/// rustfmt's `struct_lit_width` (the default "small heuristics").
const STRUCT_LIT_WIDTH: usize = 18;
/// rustfmt's `fn_call_width` and `array_width`.
const LIST_WIDTH: usize = 60;
/// rustfmt's `chain_width`.
const CHAIN_WIDTH: usize = 60;
/// Array items at most this wide may be packed several per line by rustfmt
/// (`short_array_element_width_threshold`): such lists are not laid out here.
const SHORT_ITEM: usize = 10;

/// The line that opens an item whose layout is decided on its own (see
/// [`Layout::begin_item`]).
pub(crate) const ITEM_BEGIN: &str = "\u{1}coolc-item\u{1}";
/// The line that closes such an item when it is in rustfmt's layout.
pub(crate) const ITEM_END: &str = "\u{1}coolc-item-end\u{1}";
/// The line that closes such an item when the formatter must lay it out.
pub(crate) const ITEM_END_FORMAT: &str = "\u{1}coolc-item-format\u{1}";

/// Lays out pieces of one file and records whether every piece is certain: of the
/// whole file, or of the top-level item being rendered (see [`Layout::begin_item`]).
#[derive(Debug)]
pub struct Layout {
    ok: Cell<bool>,
    /// Inside an item: whether a piece of it is uncertain.
    item: Cell<Option<bool>>,
}

impl Default for Layout {
    fn default() -> Layout {
        Layout {
            ok: Cell::new(true),
            item: Cell::new(None),
        }
    }
}

fn spaces(n: usize) -> String {
    " ".repeat(n)
}

fn push_spaces(out: &mut String, n: usize) {
    out.extend(std::iter::repeat_n(' ', n));
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
        match self.item.get() {
            Some(_) => self.item.set(Some(true)),
            None => self.ok.set(false),
        }
    }

    /// Opens a top-level item (its doc comment, attributes and body, up to
    /// [`Layout::end_item`]) whose pieces are judged on their own: when one of them
    /// is uncertain, the formatter lays out that item alone, not the file. rustfmt
    /// formats each top-level item on its own, so its text is the same either way.
    /// The marker is a line of its own, removed at emission.
    pub fn begin_item(&self) -> &'static str {
        self.item.set(Some(false));
        ITEM_BEGIN
    }

    /// Closes the item [`Layout::begin_item`] opened: the marker says whether the
    /// formatter must lay it out.
    pub fn end_item(&self) -> &'static str {
        match self.item.take() {
            Some(true) => ITEM_END_FORMAT,
            _ => ITEM_END,
        }
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
                for c in line.chars() {
                    if comment_safe(c) {
                        out.push(c);
                    } else {
                        out.push_str(&c.escape_unicode().to_string());
                    }
                }
            }
        }
        out
    }

    /// The module's `//!` doc lines.
    pub fn module_doc(&self, lines: &[String]) -> String {
        self.doc(lines, 0, "//!")
    }

    /// An item's `///` doc lines.
    pub fn item_doc(&self, lines: &[String]) -> String {
        self.doc(lines, 0, "///")
    }

    /// A member's `///` doc lines (a field, variant or method, at indent 4).
    pub fn member_doc(&self, lines: &[String]) -> String {
        self.doc(lines, 4, "///")
    }

    /// An enum variant `Name,`.
    pub fn variant(&self, name: &str) -> String {
        self.line(4, &format!("{name},"))
    }

    /// The arm `Enum::Variant => index,` of an `index` method.
    pub fn index_arm(&self, ty: &str, variant: &str, index: &usize) -> String {
        self.arm(12, &format!("{ty}::{variant}"), &index.to_string())
    }

    /// The arm `UserState::Variant => "name",` of `UserState::name`.
    pub fn name_arm(&self, variant: &str, name: &str) -> String {
        self.arm(12, &format!("UserState::{variant}"), &format!("{name:?}"))
    }

    /// The arm `May::Variant => UserState::ALL[index],` of a `may` enum's `state`.
    pub fn may_arm(&self, may_enum: &str, variant: &str, index: &usize) -> String {
        self.arm(
            12,
            &format!("{may_enum}::{variant}"),
            &format!("UserState::ALL[{index}]"),
        )
    }

    /// A required method of `Behavior`: its signature and `;`.
    pub fn declaration(&self, signature: &str) -> String {
        self.signature(4, signature, ";")
    }

    /// An arm of the glue's `section` dispatch.
    pub fn section_arm(&self, pattern: &str, call: &Code) -> String {
        self.arm(12, pattern, &call.to_string())
    }

    /// The glue's call of the only exception handler.
    pub fn exception_call(&self, handler: &str) -> String {
        self.short(12, &format!("behavior.{handler}(&mut cx, message);"))
    }

    /// An arm of the glue's exception dispatch.
    pub fn exception_arm(&self, index: &usize, handler: &str) -> String {
        self.arm(
            12,
            &index.to_string(),
            &format!("behavior.{handler}(&mut cx, message)"),
        )
    }

    /// The body of an arm of the glue's `answer`: the pull answer, then its send.
    pub fn answer(&self, arm: &crate::ir::AnswerArm) -> String {
        format!(
            "{}\n{}",
            self.short(
                16,
                &format!("let packet = behavior.{}(&mut cx)?;", arm.method)
            ),
            self.short(
                16,
                &format!("cx.outputs.{}.{}(packet);", arm.field, arm.send)
            )
        )
    }

    /// The assignment of an arm of the glue's `set`.
    pub fn set_var(&self, var: &crate::ir::Var) -> String {
        self.assign(
            16,
            &format!("self.vars.{}", var.field.name),
            &var.from_value.clone().try_op().to_string(),
        )
    }

    /// The assignment of an arm of the compound's `set` (its variables locked as
    /// `vars`).
    pub fn set_locked_var(&self, var: &crate::ir::Var) -> String {
        self.assign(
            16,
            &format!("vars.{}", var.field.name),
            &var.from_value.clone().try_op().to_string(),
        )
    }

    /// An arm of the glue's `get`.
    pub fn get_arm(&self, index: &usize, var: &crate::ir::Var) -> String {
        self.short(12, &format!("{index} => {},", var.to_value))
    }

    /// A method of the typed harness, up to its closing brace: doc, signature, body.
    pub fn harness_method(&self, doc: &[String], signature: &str, body: &[StubLine]) -> String {
        let mut out = self.member_doc(doc);
        out.push('\n');
        out.push_str(&self.signature(4, signature, " {"));
        for line in body {
            out.push('\n');
            out.push_str(&self.body_line(line));
        }
        out
    }

    /// `name: ty,`, a private field declaration at indent 4.
    pub fn private_decl(&self, name: &str, ty: &str) -> String {
        self.line(4, &format!("{name}: {ty},"))
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

    /// A field's `#[serde(with = "adapter")]`, in a struct item at `item`.
    pub fn field_serde_with(&self, item: &usize, adapter: &str) -> String {
        self.line(*item + 4, &format!("#[serde(with = \"{adapter}\")]"))
    }

    /// A field's `#[serde(rename = "name")]`, in a struct item at `item`.
    pub fn field_rename(&self, item: &usize, name: &str) -> String {
        self.serde_rename(*item + 4, name)
    }

    /// An enum variant's `#[serde(rename = "name")]`, in an enum at the top of a module.
    pub fn variant_rename(&self, name: &str) -> String {
        self.serde_rename(4, name)
    }

    fn serde_rename(&self, indent: usize, name: &str) -> String {
        self.line(indent, &format!("#[serde(rename = \"{name}\")]"))
    }

    /// A packet field's declaration `pub name: ty,`, in a struct item at `item`.
    pub fn field_decl(&self, item: &usize, f: &crate::ir::Field) -> String {
        self.line(*item + 4, &format!("pub {}: {},", f.name, f.ty))
    }

    /// A field's doc comment, in a struct item at `item`.
    pub fn field_doc(&self, lines: &[String], item: &usize) -> String {
        self.doc(lines, *item + 4, "///")
    }

    /// The indentation `indent` before a fixed piece of a template.
    pub fn open(&self, indent: &usize) -> String {
        spaces(*indent)
    }

    /// Doc-comment lines of an item at the top of a module (see [`Layout::doc_lines`]).
    pub fn item_doc_lines(&self, lines: &[String]) -> String {
        self.doc_lines(lines, &0)
    }

    /// Doc-comment lines at `indent`, each followed by a newline (nothing when there
    /// are none): what comes before an item's attributes.
    pub fn doc_lines(&self, lines: &[String], indent: &usize) -> String {
        let mut out = self.doc(lines, *indent, "///");
        if !out.is_empty() {
            out.remove(0);
            out.push('\n');
        }
        out
    }

    /// `#[derive(items)]` at `indent` (rustfmt's `format_derive`): on one line when
    /// it fits, else one item per line when they do not fit on one line of their own
    /// (which is left to the formatter).
    pub fn derive(&self, indent: usize, items: &[&str]) -> String {
        let joined = items.join(", ");
        // The list is laid out with a trailing comma, removed on one line.
        let listed = joined.len() + 1;
        let argument_width = MAX_WIDTH.saturating_sub(indent + 4);
        let one_line_budget = MAX_WIDTH.saturating_sub(indent + "#[derive()]".len() + 3);
        let pad = spaces(indent);
        if joined.len() <= argument_width && listed <= one_line_budget {
            return self.line(indent, &format!("#[derive({joined})]"));
        }
        if joined.len() <= argument_width {
            // rustfmt puts the items on one line of their own: not written here.
            self.fail();
        }
        let mut out = format!("{pad}#[derive(");
        for item in items {
            out.push('\n');
            out.push_str(&self.line(indent + 4, &format!("{item},")));
        }
        out.push('\n');
        out.push_str(&pad);
        out.push_str(")]");
        out
    }

    /// A packet's derives at `indent`.
    pub fn packet_derive(&self, p: &crate::ir::Packet, indent: &usize) -> String {
        let mut items = vec![
            "Clone",
            "Debug",
            "PartialEq",
            "::serde::Serialize",
            "::serde::Deserialize",
        ];
        if p.derives_default() {
            items.push("Default");
        }
        self.derive(*indent, &items)
    }

    /// An enum's derives.
    pub fn enum_derive(&self, e: &crate::ir::Enum) -> String {
        let mut items = vec![
            "Clone",
            "Copy",
            "Debug",
            "PartialEq",
            "Eq",
            "Hash",
            "PartialOrd",
            "Ord",
            "::serde::Serialize",
            "::serde::Deserialize",
        ];
        if !e.variants.is_empty() {
            items.push("Default");
        }
        self.derive(0, &items)
    }

    /// `pub type Name = path;` of an extern packet or a ROS import.
    pub fn type_alias(&self, e: &crate::ir::Extern) -> String {
        self.line(0, &format!("pub type {} = {};", e.name, e.path))
    }

    /// `Self { field: default, ... }`, the body of the `Default` impl of a packet item
    /// at `item`.
    pub fn default_body(&self, fields: &[crate::ir::Field], item: &usize) -> String {
        let indent = *item + 8;
        let fields: Vec<(String, Code)> = fields
            .iter()
            .map(|f| (f.name.clone(), f.default.clone()))
            .collect();
        self.statement(indent, &Code::Struct("Self".to_owned(), fields), "")
    }

    /// An associated constant `lhs value;` of a ROS 2 message type (in its `impl` in
    /// its package's module of `ros`), `lhs` ending in `=`, `value` a literal.
    pub fn ros_const(&self, lhs: &str, value: &str) -> String {
        self.const_item(ROS_MEMBER, lhs, value)
    }

    /// A ROS 2 constant's doc comment (see [`Layout::ros_const`]).
    pub fn ros_const_doc(&self, lines: &[String]) -> String {
        self.doc(lines, ROS_MEMBER, "///")
    }

    /// `lhs value;` at `indent`, `lhs` ending in `=` (a constant), `value` a
    /// literal.
    fn const_item(&self, indent: usize, lhs: &str, value: &str) -> String {
        let printer = expr::Printer::default();
        match printer.assign(indent, lhs, &Code::atom(value)) {
            Some(text) => format!("{}{text}", spaces(indent)),
            None => {
                self.fail();
                format!("{}{lhs} {value};", spaces(indent))
            }
        }
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
            out.push_str(&self.body_line(line));
        }
        out.push_str("\n    }");
        out
    }

    /// One line of a method's body, at indent 8.
    fn body_line(&self, line: &StubLine) -> String {
        match line {
            StubLine::Comment(text) => format!("{}{text}", spaces(8)),
            StubLine::Value(code) => self.statement(8, code, ""),
            StubLine::Let(name, value) => self.let_statement(8, name, None, value),
            StubLine::Statement(_) => self.short(8, &line.to_string()),
        }
    }

    /// `Self { field: default, ... }`, the body of a `Default` impl at indent 8.
    pub fn defaults(&self, fields: &[crate::ir::Field]) -> String {
        let fields: Vec<(String, Code)> = fields
            .iter()
            .map(|f| (f.name.clone(), f.default.clone()))
            .collect();
        self.struct_lit("Self", fields, 8, 8, 0)
    }

    /// [`Layout::defaults`] of the variables.
    pub fn var_defaults(&self, vars: &[crate::ir::Var]) -> String {
        let fields: Vec<(String, Code)> = vars
            .iter()
            .map(|v| (v.field.name.clone(), v.field.default.clone()))
            .collect();
        self.struct_lit("Self", fields, 8, 8, 0)
    }

    /// `pub const ALL: [UserState; n] = [...];` at indent 4.
    pub fn all_states(&self, c: &crate::ir::Atomic) -> String {
        self.all_of(&c.states)
    }

    /// [`Layout::all_states`] of a compound's supervisor.
    pub fn all_supervisor_states(&self, c: &crate::ir::Compound) -> String {
        self.all_of(&c.states)
    }

    fn all_of(&self, states: &[crate::ir::State]) -> String {
        let head = format!("pub const ALL: [UserState; {}] = ", states.len());
        let list = Code::List(
            "[".to_owned(),
            states
                .iter()
                .map(|s| Code::Atom(format!("UserState::{}", s.variant)))
                .collect(),
        );
        format!("{head}{};", self.node(&list, 4, 4 + head.len(), 1, false))
    }

    /// `let var = Ty { field: ctor, ... };` at indent 4, for the port structs.
    pub fn ports_struct(&self, var: &str, ty: &str, ports: &[crate::ir::Port]) -> String {
        let head = format!("let {var} = ");
        let fields: Vec<(String, Code)> = ports
            .iter()
            .map(|p| (p.field.clone(), p.ctor.clone()))
            .collect();
        format!(
            "{head}{};",
            self.struct_lit(ty, fields, 4, 4 + head.len(), 1)
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
        self.choose_arm_of("behavior", *state, method)
    }

    /// A choice arm of the compound's `choose` (the user supervisor's method), at
    /// indent 12.
    pub fn supervisor_choose_arm(&self, state: &usize, method: &str) -> String {
        self.choose_arm_of("supervisor", *state, method)
    }

    fn choose_arm_of(&self, root: &str, state: usize, method: &str) -> String {
        let calls = [
            root.to_owned(),
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

    /// A struct literal `path { name: value, ... }` laid out as the right-hand side
    /// starting at column `used`.
    pub fn struct_lit(
        &self,
        path: &str,
        fields: Vec<(String, Code)>,
        indent: usize,
        used: usize,
        suffix: usize,
    ) -> String {
        self.node(
            &Code::Struct(path.to_owned(), fields),
            indent,
            used,
            suffix,
            false,
        )
    }

    /// The `SPEC` static of a component (see `templates/atomic.rs`): `spec`, the
    /// `coolbot::Spec` literal `lower` built.
    pub fn spec(&self, spec: &Code) -> String {
        let head = "pub static SPEC: ::coolbot::Spec = ";
        format!("{head}{};", self.node(spec, 0, head.len(), 1, false))
    }

    /// `pub const NAME: &[(&str, &str)] = &[("a", "b"), ...];`, a table of pairs of
    /// names at indent 0.
    pub fn pairs<'p>(
        &self,
        name: &str,
        pairs: impl IntoIterator<Item = (&'p str, &'p str)>,
    ) -> String {
        let head = format!("pub const {name}: &[(&str, &str)] =");
        let list = Code::slice(
            pairs
                .into_iter()
                .map(|(a, b)| {
                    Code::call(
                        "",
                        vec![
                            Code::atom(format!("\"{a}\"")),
                            Code::atom(format!("\"{b}\"")),
                        ],
                    )
                })
                .collect(),
        );
        // On the line of its name when it fits, else alone on the next line when it
        // fits there (rustfmt's choice), else one pair per line.
        if let Some(flat) = Self::flat(&list) {
            let same_line = format!("{head} {flat};");
            if same_line.len() <= MAX_WIDTH {
                return same_line;
            }
            let next_line = format!("    {flat};");
            if next_line.len() <= MAX_WIDTH {
                return format!("{head}\n{next_line}");
            }
        }
        format!("{head} {};", self.node(&list, 0, head.len() + 1, 1, false))
    }

    /// A mapped controllable variable's field of `Mapped`, at indent 4.
    pub fn mapped_decl(&self, m: &crate::ir::MappedField) -> String {
        self.decl(&m.name, &format!("::core::option::Option<{}>", m.ty))
    }

    /// An instance's method of the `Parts` trait, at indent 4.
    pub fn part_declaration(&self, i: &crate::ir::Instance, module: &str) -> String {
        let bound = if i.compound { "Parts" } else { "Behavior" };
        self.declaration(&format!(
            "fn {}(&mut self) -> impl super::{module}::{bound}",
            i.method
        ))
    }

    /// A method's signature and its ` {` in an `impl` block (see [`Layout::open_fn_at`]).
    pub fn open_method(&self, signature: &str) -> String {
        self.open_fn_at(4, signature)
    }

    /// A free function's signature and its ` {`, an item of a module.
    pub fn open_item_fn(&self, signature: &str) -> String {
        self.open_fn_at(0, signature)
    }

    /// A signature at `indent` followed by ` {` (see [`Layout::signature`]; one of
    /// exactly `max_width` columns stays on its line).
    fn open_fn_at(&self, indent: usize, signature: &str) -> String {
        let one = format!("{signature} {{");
        if indent + one.len() == MAX_WIDTH {
            return self.line(indent, &one);
        }
        self.signature(indent, signature, " {")
    }

    /// `path {\n field: value,\n}` at indent 8, the body of an accessor returning a
    /// handle whose one field borrows from `self` (always over `struct_lit_width`).
    pub fn handle_lit(&self, path: &str, field: &str, value: &str) -> String {
        let lit = Code::Struct(path.to_owned(), vec![(field.to_owned(), Code::atom(value))]);
        format!("{}{}", spaces(8), self.node(&lit, 8, 8, 0, false))
    }

    /// `receiver.method(args)` then `tail` at `indent`, `receiver` a root and one
    /// field (`self.commander`: with the call, a chain of two links): on one line
    /// within `chain_width`, else the receiver alone and the call on the next line.
    pub fn field_call(
        &self,
        indent: usize,
        receiver: &str,
        method: &str,
        args: &[Code],
        tail: &str,
    ) -> String {
        let Some(call) = Self::one_line(&Code::call(method, args.to_vec())) else {
            // Arguments too wide for one line: the call stays on the receiver's line
            // and they go one per line (rustfmt's choice for two or more of them).
            if args.len() < 2 {
                self.fail();
            }
            let mut out = self.line(indent, &format!("{receiver}.{method}("));
            for arg in args {
                out.push('\n');
                out.push_str(&self.expr_line(indent + 4, arg, ","));
            }
            out.push('\n');
            out.push_str(&self.line(indent, &format!("){tail}")));
            return out;
        };
        let one = format!("{receiver}.{call}");
        if one.len() <= CHAIN_WIDTH && indent + one.len() + tail.len() <= MAX_WIDTH {
            return self.line(indent, &format!("{one}{tail}"));
        }
        format!(
            "{}\n{}",
            self.line(indent, receiver),
            self.line(indent + 4, &format!(".{call}{tail}"))
        )
    }

    /// [`Layout::field_call`] at indent 8 (a method's whole body) whose arguments
    /// are the instance's name (a string literal), then the paths or short
    /// expressions `rest` (separated by `, `).
    pub fn instance_call(
        &self,
        receiver: &str,
        method: &str,
        instance: &str,
        rest: &str,
    ) -> String {
        let mut args = vec![Code::atom(format!("\"{instance}\""))];
        args.extend(
            rest.split(", ")
                .filter(|arg| !arg.is_empty())
                .map(Code::atom),
        );
        self.field_call(8, receiver, method, &args, "")
    }

    /// [`Layout::instance_call`] with a setter's arguments (the variable's name and
    /// value).
    pub fn setter_call(
        &self,
        receiver: &str,
        method: &str,
        instance: &str,
        setter: &crate::ir::Setter,
    ) -> String {
        let mut args = vec![Code::atom(format!("\"{instance}\""))];
        args.extend(setter.args());
        self.field_call(8, receiver, method, &args, "")
    }

    /// `registrar.port::<packet>(TYPE_NAME, "port");` at indent 4.
    pub fn register_port(&self, packet: &str, port: &str) -> String {
        let call = Code::atom("registrar").method(
            format!("port::<{packet}>"),
            vec![Code::atom("TYPE_NAME"), Code::atom(format!("\"{port}\""))],
        );
        self.expr_line(4, &call, ";")
    }

    /// `code` then `tail` as one line at `indent`, when rustfmt keeps it on one line
    /// (see [`Layout::one_line`]).
    pub fn expr_line(&self, indent: usize, code: &Code, tail: &str) -> String {
        match Self::one_line(code) {
            Some(text) => self.line(indent, &format!("{text}{tail}")),
            None => {
                self.fail();
                format!("{}{code}{tail}", spaces(indent))
            }
        }
    }

    /// One call `.method(args)` of the compound builder's chain, at indent 8 (`last`:
    /// followed by the `)` of `Ok(`): on one line when it fits, else one argument per
    /// line. A lone argument too long for the line, or a closure last, is left to
    /// the formatter (rustfmt may open it on the call's line).
    pub fn builder_step(&self, step: &Code, last: &bool) -> String {
        let tail = if *last { ")" } else { "" };
        let Code::Call(method, args) = step else {
            self.fail();
            return format!("{}.{step}{tail}", spaces(8));
        };
        if let Some(text) = Self::one_line(step)
            && 8 + 1 + text.len() + tail.len() <= MAX_WIDTH
        {
            return format!("{}.{text}{tail}", spaces(8));
        }
        if args.len() < 2
            || matches!(
                args.last(),
                Some(Code::Closure(..) | Code::Block(..) | Code::Match(..))
            )
        {
            self.fail();
        }
        let mut out = self.line(8, &format!(".{method}("));
        for arg in args {
            out.push('\n');
            out.push_str(&self.expr_line(12, arg, ","));
        }
        out.push('\n');
        out.push_str(&self.line(8, &format!("){tail}")));
        out
    }

    /// `code;`, a statement of a free function's body.
    pub fn body_statement(&self, code: &Code) -> String {
        self.statement(4, code, ";")
    }

    /// `code;`, a statement of a trait method's body.
    pub fn method_statement(&self, code: &Code) -> String {
        self.statement(8, code, ";")
    }

    /// `let pattern = value;`, a statement of a free function's body.
    pub fn body_let(&self, pattern: &str, value: &Code) -> String {
        self.let_statement(4, pattern, None, value)
    }

    /// `code` then `tail` as a statement (`tail` is `;`) or a block's tail
    /// expression (`tail` empty) at `indent`, in rustfmt's layout of expressions
    /// (`expr`); left to the formatter when that layout is not certain.
    fn statement(&self, indent: usize, code: &Code, tail: &str) -> String {
        let printer = expr::Printer::default();
        match printer.statement(indent, code, tail) {
            Some(text) => format!("{}{text}", spaces(indent)),
            None => {
                if std::env::var_os("COOLC_LAYOUT_DEBUG").is_some() {
                    eprintln!("coolc: not laid out: {code}{tail}");
                }
                self.fail();
                format!("{}{code}{tail}", spaces(indent))
            }
        }
    }

    /// `let pattern: ty = value;` at `indent` (see [`Layout::statement`]).
    fn let_statement(
        &self,
        indent: usize,
        pattern: &str,
        ty: Option<&str>,
        value: &Code,
    ) -> String {
        let printer = expr::Printer::default();
        match printer.let_statement(indent, pattern, ty, value) {
            Some(text) => format!("{}{text}", spaces(indent)),
            None => {
                self.fail();
                let ty = ty.map_or(String::new(), |ty| format!(": {ty}"));
                format!("{}let {pattern}{ty} = {value};", spaces(indent))
            }
        }
    }

    /// `let handles: [coolbot::Handle; n] = [...];` of the starter `main`: each of
    /// `roots` added to the system, its error mapped to a message.
    pub fn handles(&self, roots: &[Code]) -> String {
        let items = roots
            .iter()
            .map(|root| {
                let message = Code::call(
                    "format!",
                    vec![
                        Code::string("cannot add a component: {}"),
                        Code::call("coolbot::Chain", vec![Code::atom("&e")]),
                    ],
                );
                Code::atom("system")
                    .method("add", vec![root.clone()])
                    .method("map_err", vec![Code::closure("e", message)])
                    .try_op()
            })
            .collect();
        let ty = format!("[coolbot::Handle; {}]", roots.len());
        self.let_statement(4, "handles", Some(&ty), &Code::List("[".to_owned(), items))
    }

    /// The first line of test function `name` (no parameters).
    pub fn test_fn(&self, name: &str) -> String {
        self.line(0, &format!("fn {name}() {{"))
    }

    /// The body of a rule's function: its condition.
    pub fn rule_body(&self, r: &crate::ir::Rule) -> String {
        self.statement(4, &r.expr, "")
    }

    /// The tail of the compound's `builder_with`: the runtime's builder and its
    /// chain of steps (instances, connections, policies, rules), in `Ok(...)`.
    pub fn builder_chain(&self, c: &crate::ir::Compound) -> String {
        let mut chain = Code::call(
            "::coolbot::CompoundBuilder::new",
            vec![Code::atom("name"), Code::atom("supervisor")],
        );
        for step in c.builder_steps() {
            chain = match step {
                crate::ir::BuilderStep::Instance(i, build) => match &i.node {
                    Some(node) => chain.method(
                        "instance_on",
                        vec![Code::atom(format!("\"{node}\"")), build.clone()],
                    ),
                    None => chain.method("instance", vec![build.clone()]),
                },
                crate::ir::BuilderStep::Connect(k) => {
                    let Code::Call(method, args) = Self::connect_call(k) else {
                        unreachable!("a connection is a call");
                    };
                    chain.method(method, args)
                }
                crate::ir::BuilderStep::Step(Code::Call(method, args)) => {
                    chain.method(method.as_str(), args.clone())
                }
                crate::ir::BuilderStep::Step(other) => {
                    self.fail();
                    chain.method(other.to_string(), Vec::new())
                }
                crate::ir::BuilderStep::Rule(r) => chain.method(
                    "rule",
                    vec![
                        Code::atom(r.state.clone()),
                        Code::atom(r.target.clone()),
                        r.reads.clone(),
                        r.call.clone(),
                    ],
                ),
            };
        }
        self.statement(4, &Code::call("Ok", vec![chain]), "")
    }

    /// `connect(from, to)` or `connect_via(from, to, converter)`.
    fn connect_call(k: &crate::ir::Connection) -> Code {
        let mut args = vec![
            Code::atom(format!("\"{}\"", k.from)),
            Code::atom(format!("\"{}\"", k.to)),
        ];
        let method = match &k.via {
            Some(method) => {
                args.push(Code::atom(format!(
                    "<C as super::types::Converters>::{method}"
                )));
                "connect_via"
            }
            None => "connect",
        };
        Code::call(method, args)
    }

    /// `.instance(build)` or `.instance_on("node", build)` of the builder's chain.
    pub fn instance_step(&self, i: &crate::ir::Instance, build: &Code, last: &bool) -> String {
        let step = match &i.node {
            Some(node) => Code::call(
                "instance_on",
                vec![Code::atom(format!("\"{node}\"")), build.clone()],
            ),
            None => Code::call("instance", vec![build.clone()]),
        };
        self.builder_step(&step, last)
    }

    /// `.connect(from, to)` or `.connect_via(from, to, converter)` of the builder's
    /// chain.
    pub fn connect_step(&self, k: &crate::ir::Connection, last: &bool) -> String {
        self.builder_step(&Self::connect_call(k), last)
    }

    /// `.rule(state, target, reads, test)` of the builder's chain.
    pub fn rule_step(&self, r: &crate::ir::Rule, last: &bool) -> String {
        let step = Code::call(
            "rule",
            vec![
                Code::atom(r.state.clone()),
                Code::atom(r.target.clone()),
                r.reads.clone(),
                r.call.clone(),
            ],
        );
        self.builder_step(&step, last)
    }

    /// The first line of the compound harness's `new`: the builder, its error
    /// mapped by a closure that opens on this line.
    pub fn harness_builder(&self, c: &crate::ir::Compound) -> String {
        let call = format!(
            "builder{}(\"{}\", parts)",
            c.turbofish(),
            c.module.trim_start_matches("r#")
        );
        self.line(8, &format!("let builder = {call}.map_err(|error| {{"))
    }

    /// One-line form of `code` when rustfmt keeps it on one line: every call's
    /// arguments within `fn_call_width`, every chain of two links or more within
    /// `chain_width`, every struct literal within `struct_lit_width`. `None` for the
    /// shapes these rules do not cover (closures, blocks, `match`, a struct with a
    /// rest) and for what rustfmt would break.
    fn one_line(code: &Code) -> Option<String> {
        let text = match code {
            Code::Atom(text) => text.clone(),
            Code::Struct(..) | Code::List(..) | Code::Repeat(..) => {
                if Self::has_other(code) {
                    return None;
                }
                Self::flat(code)?
            }
            Code::Call(callee, args) => {
                format!("{callee}({})", Self::args_line(args)?)
            }
            Code::Method(receiver, method, args) => {
                format!(
                    "{}.{method}({})",
                    Self::one_line(receiver)?,
                    Self::args_line(args)?
                )
            }
            Code::Field(receiver, field) => format!("{}.{field}", Self::one_line(receiver)?),
            Code::Try(operand) => format!("{}?", Self::one_line(operand)?),
            Code::Unary(op, operand) => format!("{op}{}", Self::one_line(operand)?),
            Code::Binary(left, op, right) => {
                format!("{} {op} {}", Self::one_line(left)?, Self::one_line(right)?)
            }
            Code::Paren(inner) => format!("({})", Self::one_line(inner)?),
            Code::StructRest(..)
            | Code::Closure(..)
            | Code::Block(..)
            | Code::Match(..)
            | Code::Other(_) => return None,
        };
        if Self::links(code) >= 2 && text.len() > CHAIN_WIDTH {
            return None;
        }
        Some(text)
    }

    /// The arguments of a call on one line, within `fn_call_width`.
    fn args_line(args: &[Code]) -> Option<String> {
        let text = args
            .iter()
            .map(Self::one_line)
            .collect::<Option<Vec<_>>>()?
            .join(", ");
        (text.len() <= LIST_WIDTH).then_some(text)
    }

    /// How many links (method calls and fields) the chain `code` ends has.
    fn links(code: &Code) -> usize {
        match code {
            Code::Method(receiver, ..) | Code::Field(receiver, _) => 1 + Self::links(receiver),
            Code::Try(operand) => Self::links(operand),
            _ => 0,
        }
    }

    /// One-line form of `node` when rustfmt's width rules allow one (ignoring the
    /// room left on the line).
    fn flat(node: &Code) -> Option<String> {
        match node {
            Code::Atom(text) => Some(text.clone()),
            Code::Struct(path, fields) if fields.is_empty() => Some(format!("{path} {{}}")),
            Code::Struct(path, fields) => {
                let body = fields
                    .iter()
                    .map(|(name, value)| Self::flat(value).map(|v| format!("{name}: {v}")))
                    .collect::<Option<Vec<_>>>()?
                    .join(", ");
                (body.len() <= STRUCT_LIT_WIDTH).then(|| format!("{path} {{ {body} }}"))
            }
            Code::Call(callee, args) => {
                let inner = args
                    .iter()
                    .map(Self::flat)
                    .collect::<Option<Vec<_>>>()?
                    .join(", ");
                (inner.len() <= LIST_WIDTH).then(|| format!("{callee}({inner})"))
            }
            Code::List(open, items) => {
                let inner = items
                    .iter()
                    .map(Self::flat)
                    .collect::<Option<Vec<_>>>()?
                    .join(", ");
                (inner.len() <= LIST_WIDTH).then(|| format!("{open}{inner}]"))
            }
            // Kept on one line, or a shape these rules do not cover.
            _ => Some(node.to_string()),
        }
    }

    /// The width of [`Layout::flat`]'s form of `node`, computed without writing it.
    fn flat_width(node: &Code) -> Option<usize> {
        let list = |items: &[Code]| -> Option<usize> {
            let mut width = 2 * items.len().saturating_sub(1);
            for item in items {
                width += Self::flat_width(item)?;
            }
            Some(width)
        };
        match node {
            Code::Atom(text) => Some(text.len()),
            Code::Struct(path, fields) if fields.is_empty() => Some(path.len() + 3),
            Code::Struct(path, fields) => {
                let mut body = 2 * (fields.len() - 1);
                for (name, value) in fields {
                    body += name.len() + 2 + Self::flat_width(value)?;
                }
                (body <= STRUCT_LIT_WIDTH).then_some(path.len() + 5 + body)
            }
            Code::Call(callee, args) => {
                let inner = list(args)?;
                (inner <= LIST_WIDTH).then_some(callee.len() + 2 + inner)
            }
            Code::List(open, items) => {
                let inner = list(items)?;
                (inner <= LIST_WIDTH).then_some(open.len() + 1 + inner)
            }
            // Kept on one line, or a shape these rules do not cover.
            _ => Some(node.to_string().len()),
        }
    }

    /// `node` with its first line starting at column `used` (continuations at
    /// `indent`), `suffix` columns following it on its last line. A string literal
    /// that is a struct field's whole value may run past `max_width` (`long_string`),
    /// as rustfmt leaves it.
    fn node(
        &self,
        node: &Code,
        indent: usize,
        used: usize,
        suffix: usize,
        long_string: bool,
    ) -> String {
        if Self::has_other(node) {
            self.fail();
        }
        let mut out = String::new();
        self.node_into(node, indent, used, suffix, long_string, &mut out);
        out
    }

    /// [`Layout::node`], written at the end of `out`.
    fn node_into(
        &self,
        node: &Code,
        indent: usize,
        used: usize,
        suffix: usize,
        long_string: bool,
        out: &mut String,
    ) {
        use std::fmt::Write as _;
        if let Some(width) = Self::flat_width(node)
            && (used + width + suffix <= MAX_WIDTH
                || long_string && matches!(node, Code::Atom(t) if t.starts_with('"')))
        {
            // The one-line form is the tree's own printing.
            let _ = write!(out, "{node}");
            return;
        }
        match node {
            Code::Atom(_) | Code::Repeat(..) => {
                self.fail();
                let _ = write!(out, "{node}");
            }
            Code::Struct(path, fields) => {
                if fields.is_empty() || used + path.len() + 2 > MAX_WIDTH {
                    self.fail();
                }
                out.push_str(path);
                out.push_str(" {\n");
                for (name, value) in fields {
                    let start = indent + 4 + name.len() + 2;
                    push_spaces(out, indent + 4);
                    out.push_str(name);
                    out.push_str(": ");
                    self.node_into(value, indent + 4, start, 1, true, out);
                    out.push_str(",\n");
                }
                push_spaces(out, indent);
                out.push('}');
            }
            Code::Call(callee, args) => match &args[..] {
                [arg @ (Code::Struct(..) | Code::List(..))] => {
                    let start = used + callee.len() + 1;
                    out.push_str(callee);
                    out.push('(');
                    self.node_into(arg, indent, start, suffix + 1, false, out);
                    out.push(')');
                }
                _ => {
                    self.fail();
                    let _ = write!(out, "{node}");
                }
            },
            Code::List(open, items) => match &items[..] {
                [item @ Code::Struct(..)] => {
                    let start = used + open.len();
                    out.push_str(open);
                    self.node_into(item, indent, start, suffix + 1, false, out);
                    out.push(']');
                }
                _ => {
                    if items.iter().any(|i| {
                        matches!(i, Code::Atom(_) | Code::Repeat(..))
                            && i.to_string().len() <= SHORT_ITEM
                    }) || items.len() < 2
                    {
                        self.fail();
                    }
                    out.push_str(open);
                    out.push('\n');
                    for item in items {
                        push_spaces(out, indent + 4);
                        self.node_into(item, indent + 4, indent + 4, 1, false, out);
                        out.push_str(",\n");
                    }
                    push_spaces(out, indent);
                    out.push(']');
                }
            },
            // A shape these rules do not cover (`has_other` failed already).
            _ => {
                self.fail();
                let _ = write!(out, "{node}");
            }
        }
    }

    /// Whether `node` holds a shape these rules do not cover.
    fn has_other(node: &Code) -> bool {
        match node {
            Code::Atom(_) => false,
            Code::Repeat(item, _) => Self::has_other(item),
            Code::Struct(_, fields) => fields.iter().any(|(_, value)| Self::has_other(value)),
            Code::Call(_, items) | Code::List(_, items) => items.iter().any(Self::has_other),
            _ => Self::uncovered(node),
        }
    }

    /// Whether `node` itself is a shape these rules do not cover (a closure, a
    /// method call, an operator...): the formatter lays it out.
    fn uncovered(node: &Code) -> bool {
        match node {
            Code::Atom(_)
            | Code::Struct(..)
            | Code::Call(..)
            | Code::List(..)
            | Code::Repeat(..) => false,
            Code::StructRest(..)
            | Code::Method(..)
            | Code::Field(..)
            | Code::Try(_)
            | Code::Unary(..)
            | Code::Binary(..)
            | Code::Paren(_)
            | Code::Closure(..)
            | Code::Block(..)
            | Code::Match(..)
            | Code::Other(_) => true,
        }
    }
}

/// Whether `c` may stand in a Rust comment as it is: not a control character (a
/// carriage return ends no line there, and rustc refuses one alone), nor a character
/// that changes the direction of the text around it (rustc denies those in comments,
/// `text_direction_codepoint_in_comment`). The others are written as their escape
/// (`\u{202e}`).
fn comment_safe(c: char) -> bool {
    (!c.is_control() || c == '\t')
        && !matches!(c, '\u{202A}'..='\u{202E}' | '\u{2066}'..='\u{2069}')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn doc_lines_escape_what_a_comment_cannot_hold() {
        let lines = vec!["left \u{202E}right\r and\ttab \u{1b}[31m é".to_owned()];
        assert_eq!(
            Layout::default().doc(&lines, 0, "///"),
            "\n/// left \\u{202e}right\\u{d} and\ttab \\u{1b}[31m é"
        );
    }

    fn on_spec(port: &str) -> Code {
        Code::structure(
            "X",
            vec![("port", Code::atom(port)), ("target", Code::atom("1"))],
        )
    }

    #[test]
    fn code_prints_on_one_line_as_written() {
        let code = Code::slice(vec![on_spec("0"), Code::string("a, b")]);
        assert_eq!(code.to_string(), "&[X { port: 0, target: 1 }, \"a, b\"]");
        assert_eq!(
            Code::call("f", vec![Code::closure("x", Code::atom("x"))]).to_string(),
            "f(|x| x)"
        );
    }

    #[test]
    fn struct_literals_follow_struct_lit_width() {
        let layout = Layout::default();
        assert_eq!(
            layout.node(&on_spec("0"), 0, 0, 0, false),
            "X { port: 0, target: 1 }"
        );
        assert_eq!(
            layout.node(&on_spec("10"), 0, 0, 0, false),
            "X {\n    port: 10,\n    target: 1,\n}"
        );
        assert_eq!(
            layout.node(&Code::slice(vec![on_spec("10")]), 4, 4, 1, false),
            "&[X {\n        port: 10,\n        target: 1,\n    }]"
        );
        assert!(layout.ok());
    }

    #[test]
    fn uncertain_shapes_clear_ok() {
        let layout = Layout::default();
        let long = Code::slice(vec![Code::atom("1"); 40]);
        let _ = layout.node(&long, 0, 0, 0, false);
        assert!(!layout.ok());
        let layout = Layout::default();
        let _ = layout.node(
            &Code::call("f", vec![Code::closure("x", Code::atom("x"))]),
            0,
            0,
            0,
            false,
        );
        assert!(!layout.ok());
    }
}
