//! rustfmt's layout of expressions, for [`Code`] trees: the rules of rustfmt's own
//! rewriting of calls and their overflowing last argument, arrays, struct literals,
//! method chains, binary operators, closures, blocks and `let` statements, with its
//! shapes (the width left on the line, the block indentation), ported for the shapes
//! `lower` builds. Edition 2024, default configuration.
//!
//! rustfmt tries layouts in turn and keeps the first that fits; a rewrite here
//! returns `None` exactly where rustfmt's does not fit, so the same layout is chosen.
//! What is not ported (a `match`, a comment, a shape the tree does not say enough
//! about) makes the printer [`Printer::unsure`]: the caller then leaves the code to
//! the formatter. Nothing here is guessed: a layout is returned only when it is
//! rustfmt's.

use std::cell::{Cell, RefCell};
use std::collections::HashMap;

use crate::ir::Code;

/// rustfmt's `max_width`.
const MAX_WIDTH: usize = 100;
/// rustfmt's `tab_spaces`.
const TAB: usize = 4;
/// rustfmt's `fn_call_width`.
const FN_CALL_WIDTH: usize = 60;
/// rustfmt's `array_width`.
const ARRAY_WIDTH: usize = 60;
/// rustfmt's `chain_width`.
const CHAIN_WIDTH: usize = 60;
/// rustfmt's `struct_lit_width`.
const STRUCT_LIT_WIDTH: usize = 18;
/// rustfmt's `short_array_element_width_threshold`.
const SHORT_ITEM: usize = 10;

/// The macros rustfmt lays out with their format string apart, and how many
/// arguments come before it.
const SPECIAL_MACROS: &[(&str, usize)] = &[
    ("eprint!", 0),
    ("eprintln!", 0),
    ("format!", 0),
    ("format_args!", 0),
    ("print!", 0),
    ("println!", 0),
    ("panic!", 0),
    ("unreachable!", 0),
    ("debug!", 0),
    ("error!", 0),
    ("info!", 0),
    ("warn!", 0),
    ("trace!", 0),
    ("assert!", 1),
    ("debug_assert!", 1),
    ("write!", 1),
    ("writeln!", 1),
    ("assert_eq!", 2),
    ("assert_ne!", 2),
    ("debug_assert_eq!", 2),
    ("debug_assert_ne!", 2),
];

/// An indentation: the block indentation and a visual alignment past it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
struct Indent {
    block: usize,
    align: usize,
}

impl Indent {
    fn width(self) -> usize {
        self.block + self.align
    }

    fn block_only(self) -> Indent {
        Indent {
            block: self.block,
            align: 0,
        }
    }

    fn block_indent(self) -> Indent {
        Indent {
            block: self.block + TAB,
            align: self.align,
        }
    }

    fn plus(self, delta: usize) -> Indent {
        Indent {
            block: self.block,
            align: self.align + delta,
        }
    }

    /// A newline and this indentation.
    fn newline(self) -> String {
        let mut text = String::with_capacity(self.width() + 1);
        text.push('\n');
        push_spaces(&mut text, self.width());
        text
    }
}

fn push_spaces(text: &mut String, n: usize) {
    text.extend(std::iter::repeat_n(' ', n));
}

/// Where an expression is written: the width left for it on its first line, the
/// indentation of its continuation lines and the columns used before it past that
/// indentation (rustfmt's `Shape`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) struct Shape {
    width: usize,
    indent: Indent,
    offset: usize,
}

impl Shape {
    /// A whole line at block indentation `indent`.
    pub(crate) fn line(indent: usize) -> Shape {
        Shape::indented(Indent {
            block: indent,
            align: 0,
        })
    }

    fn indented(indent: Indent) -> Shape {
        Shape {
            width: MAX_WIDTH.saturating_sub(indent.width()),
            indent,
            offset: indent.align,
        }
    }

    fn legacy(width: usize, indent: Indent) -> Shape {
        Shape {
            width,
            indent,
            offset: indent.align,
        }
    }

    fn with_max_width(self) -> Shape {
        Shape {
            width: MAX_WIDTH.saturating_sub(self.indent.width()),
            ..self
        }
    }

    fn visual_indent(self, delta: usize) -> Shape {
        let align = self.offset + delta;
        Shape {
            width: self.width,
            indent: Indent {
                block: self.indent.block,
                align,
            },
            offset: align,
        }
    }

    fn block_indent(self, delta: usize) -> Shape {
        if self.indent.align == 0 {
            Shape {
                width: self.width,
                indent: Indent {
                    block: self.indent.block + delta,
                    align: 0,
                },
                offset: 0,
            }
        } else {
            Shape {
                width: self.width,
                indent: self.indent.plus(delta),
                offset: self.indent.align + delta,
            }
        }
    }

    fn add_offset(self, delta: usize) -> Shape {
        Shape {
            offset: self.offset + delta,
            ..self
        }
    }

    fn block(self) -> Shape {
        Shape {
            indent: self.indent.block_only(),
            ..self
        }
    }

    /// This shape with `delta` columns less at the end of the line.
    pub(crate) fn sub_width(self, delta: usize) -> Option<Shape> {
        Some(Shape {
            width: self.width.checked_sub(delta)?,
            ..self
        })
    }

    fn shrink_left(self, delta: usize) -> Option<Shape> {
        Some(Shape {
            width: self.width.checked_sub(delta)?,
            indent: self.indent.plus(delta),
            offset: self.offset + delta,
        })
    }

    /// This shape after `delta` columns written on the line.
    pub(crate) fn offset_left(self, delta: usize) -> Option<Shape> {
        self.add_offset(delta).sub_width(delta)
    }

    fn used_width(self) -> usize {
        self.indent.block + self.offset
    }

    fn rhs_overhead(self) -> usize {
        MAX_WIDTH.saturating_sub(self.used_width() + self.width)
    }

    /// A newline and the indentation of the shape's offset.
    fn newline(self) -> String {
        Indent {
            block: self.indent.block,
            align: self.offset,
        }
        .newline()
    }
}

fn first_line_width(text: &str) -> usize {
    text.split('\n').next().map_or(0, str::len)
}

fn last_line_width(text: &str) -> usize {
    text.rsplit('\n').next().map_or(0, str::len)
}

fn trimmed_last_line_width(text: &str) -> usize {
    text.rsplit('\n').next().map_or(0, |l| l.trim().len())
}

fn newlines(text: &str) -> usize {
    text.bytes().filter(|&b| b == b'\n').count()
}

fn line_count(text: &str) -> usize {
    text.lines().count()
}

/// rustfmt's `last_line_extendable`: the last line holds only closing brackets.
fn last_line_extendable(text: &str) -> bool {
    if text.ends_with("\"#") {
        return true;
    }
    for c in text.chars().rev() {
        match c {
            '(' | ')' | ']' | '}' | '?' | '>' => {}
            '\n' => break,
            c if c.is_whitespace() => {}
            _ => return false,
        }
    }
    true
}

/// rustfmt's `wrap_str`: `text` when it fits `shape`.
fn fits(text: String, shape: Shape) -> Option<String> {
    if text.is_empty() {
        return Some(text);
    }
    if first_line_width(&text) > shape.width {
        return None;
    }
    if !text.contains('\n') {
        return Some(text);
    }
    if text.split('\n').skip(1).any(|line| line.len() > MAX_WIDTH) {
        return None;
    }
    if last_line_width(&text) > shape.used_width() + shape.width {
        return None;
    }
    Some(text)
}

/// What an [`Code::Atom`]'s text is, as far as rustfmt's rules ask.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Atom {
    /// A literal.
    Literal,
    /// A path of one segment (or `self`).
    Ident,
    /// A path of several segments.
    Path,
    /// A prefix operator (`-`, `!`, `*`, `&`, `&mut `) and what follows.
    Prefix,
    /// `receiver.field` (fields only).
    Field,
    /// `_`, in a pattern written as an expression.
    Underscore,
    /// `()`.
    Unit,
    /// Anything else.
    Other,
}

fn is_ident(text: &str) -> bool {
    let text = text.strip_prefix("r#").unwrap_or(text);
    if text == "_" {
        return false;
    }
    let mut chars = text.chars();
    chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// Whether `text` is a path: segments of identifiers, maybe with generic arguments
/// (`a::b::<T>`) or a qualified self (`<T as Trait>::f`).
fn is_path(text: &str) -> bool {
    let plain = text.strip_prefix("::").unwrap_or(text);
    if !plain.is_empty() && plain.split("::").all(is_ident) {
        return true;
    }
    if !(text.contains('<') && text.ends_with(|c: char| c.is_ascii_alphanumeric() || c == '_')) {
        return false;
    }
    let mut depth = 0usize;
    for c in text.chars() {
        match c {
            '<' => depth += 1,
            '>' => {
                depth = match depth.checked_sub(1) {
                    Some(depth) => depth,
                    None => return false,
                }
            }
            '(' | ')' | '[' | ']' | '{' | '}' | '"' | '\'' | '\n' => return false,
            ' ' | ',' | '&' | ';' if depth == 0 => return false,
            c if depth == 0 && !(c.is_ascii_alphanumeric() || c == '_' || c == ':') => {
                return false;
            }
            _ => {}
        }
    }
    depth == 0
}

/// Whether `text` is one string literal on one line.
fn is_string(text: &str) -> bool {
    let bytes = text.as_bytes();
    if bytes.len() < 2 || bytes[0] != b'"' || bytes[bytes.len() - 1] != b'"' || text.contains('\n')
    {
        return false;
    }
    // No unescaped quote inside.
    let mut escaped = false;
    for &b in &bytes[1..bytes.len() - 1] {
        match b {
            b'\\' if !escaped => escaped = true,
            b'"' if !escaped => return false,
            _ => escaped = false,
        }
    }
    !escaped
}

fn is_literal(text: &str) -> bool {
    is_string(text)
        || text == "true"
        || text == "false"
        || text.starts_with(|c: char| c.is_ascii_digit())
            && text
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '.')
}

fn atom_kind(text: &str) -> Atom {
    if text == "_" {
        Atom::Underscore
    } else if text == "()" {
        Atom::Unit
    } else if is_literal(text) {
        Atom::Literal
    } else if is_ident(text) {
        Atom::Ident
    } else if is_path(text) {
        Atom::Path
    } else if ["&mut ", "&", "*", "-", "!"]
        .iter()
        .any(|p| text.starts_with(p))
    {
        Atom::Prefix
    } else if text.contains('.') && text.split('.').all(is_ident) {
        Atom::Field
    } else {
        Atom::Other
    }
}

/// The operand of a prefix-operator atom.
fn prefix_operand(text: &str) -> &str {
    for prefix in ["&mut ", "&", "*", "-", "!"] {
        if let Some(rest) = text.strip_prefix(prefix) {
            return rest;
        }
    }
    text
}

/// A tree's address, the shape it is laid out in, and the printer's state
/// (`one_line_chain`, `in_macro`).
type MemoKey = (usize, Shape, bool, usize);

/// The ported rules, and whether anything not ported was met.
#[derive(Debug, Default)]
pub(crate) struct Printer {
    unsure: Cell<bool>,
    /// rustfmt's `force_one_line_chain`.
    one_line_chain: Cell<bool>,
    /// How many macro calls the current expression is inside.
    in_macro: Cell<usize>,
    /// Every closure laid out with a block rustfmt adds around its body.
    added_blocks: RefCell<Vec<String>>,
    /// The layouts of the trees met so far, by tree (its address: the trees outlive
    /// the printer), shape and state: rustfmt lays out a tree again in each layout
    /// it tries around it.
    memo: RefCell<HashMap<MemoKey, Option<String>>>,
}

/// How a list's items are laid out (rustfmt's `DefinitiveListTactic`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Tactic {
    Horizontal,
    Vertical,
    /// As many items on a line as fit.
    Mixed,
    /// A formatting macro's arguments: those before the format string on one line,
    /// the string on the next, the others after it.
    SpecialMacro(usize),
}

/// What kind of bracketed list a [`Printer::list`] lays out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ListKind {
    /// A function call or a tuple: `(...)`.
    Call,
    /// A macro call: `name!(...)`.
    Macro,
    /// An array: `[...]`.
    Array,
    /// A macro call with brackets (`vec![...]`), laid out as an array.
    BracketMacro,
}

impl Printer {
    /// Whether something rustfmt would lay out by rules not ported here was met:
    /// the layouts returned are then not to be trusted.
    #[cfg(test)]
    pub(crate) fn is_unsure(&self) -> bool {
        self.unsure.get()
    }

    /// Records that a rule not ported here decides the layout. With
    /// `COOLC_LAYOUT_DEBUG` set, says which.
    #[track_caller]
    fn unsure<T>(&self) -> Option<T> {
        if !self.unsure.get() && std::env::var_os("COOLC_LAYOUT_DEBUG").is_some() {
            eprintln!(
                "coolc: expression layout not ported at {}",
                std::panic::Location::caller()
            );
        }
        self.unsure.set(true);
        None
    }

    /// Whether `code` is simple for rustfmt (`is_simple_expr`).
    fn is_simple(&self, code: &Code) -> bool {
        match code {
            Code::Atom(text) => match atom_kind(text) {
                Atom::Literal | Atom::Ident | Atom::Field => true,
                Atom::Path | Atom::Underscore | Atom::Unit => false,
                Atom::Prefix => self.is_simple(&Code::atom(prefix_operand(text))),
                Atom::Other => self.unsure().unwrap_or(false),
            },
            Code::Repeat(item, _) => self.is_simple(item),
            Code::Unary(_, operand) | Code::Field(operand, _) | Code::Try(operand) => {
                self.is_simple(operand)
            }
            _ => false,
        }
    }

    /// rustfmt's `is_nested_call`.
    fn is_nested_call(&self, code: &Code) -> bool {
        match code {
            Code::Call(callee, _) => !callee.is_empty(),
            // A macro call with brackets.
            Code::List(open, _) => open.ends_with("!["),
            Code::Unary(_, operand) | Code::Try(operand) => self.is_nested_call(operand),
            Code::Atom(text) => match atom_kind(text) {
                Atom::Prefix => self.is_nested_call(&Code::atom(prefix_operand(text))),
                Atom::Other => self.unsure().unwrap_or(false),
                _ => false,
            },
            _ => false,
        }
    }

    /// rustfmt's `is_method_call`.
    fn is_method_call(code: &Code) -> bool {
        match code {
            Code::Method(..) => true,
            Code::Unary(_, operand) | Code::Try(operand) => Self::is_method_call(operand),
            _ => false,
        }
    }

    /// rustfmt's `can_be_overflowed_expr`, for the last of `count` items.
    fn can_overflow(&self, code: &Code, count: usize) -> bool {
        match code {
            Code::Closure(..) | Code::Block(..) => true,
            Code::Match(..)
            | Code::Struct(..)
            | Code::StructRest(..)
            | Code::Call(..)
            | Code::Method(..) => count == 1,
            Code::List(open, _) => match open.as_str() {
                "[" | "&[" => count == 1,
                open if open.ends_with("![") => count == 1,
                _ => self.unsure().unwrap_or(false),
            },
            Code::Unary(_, operand) | Code::Try(operand) => self.can_overflow(operand, count),
            Code::Atom(text) => match atom_kind(text) {
                Atom::Prefix => self.can_overflow(&Code::atom(prefix_operand(text)), count),
                // A tuple.
                Atom::Unit => count == 1,
                Atom::Other => self.unsure().unwrap_or(false),
                _ => false,
            },
            Code::Repeat(..) | Code::Field(..) | Code::Binary(..) | Code::Paren(..) => false,
            Code::Other(_) => self.unsure().unwrap_or(false),
        }
    }

    /// `code` laid out in `shape`, or `None` when it does not fit (as rustfmt's
    /// rewrite fails).
    pub(crate) fn expr(&self, code: &Code, shape: Shape) -> Option<String> {
        if self.unsure.get() {
            return None;
        }
        // Atoms are cheap, and some are made while printing (they would share
        // addresses): not remembered.
        if matches!(code, Code::Atom(_)) {
            return self.expr_uncached(code, shape);
        }
        let key = (
            std::ptr::from_ref(code) as usize,
            shape,
            self.one_line_chain.get(),
            self.in_macro.get(),
        );
        if let Some(known) = self.memo.borrow().get(&key) {
            return known.clone();
        }
        let result = self.expr_uncached(code, shape);
        self.memo.borrow_mut().insert(key, result.clone());
        result
    }

    fn expr_uncached(&self, code: &Code, shape: Shape) -> Option<String> {
        match code {
            Code::Atom(text) => match atom_kind(text) {
                // `a.b` is a chain of a field, `&a` a prefix operator on `a`.
                Atom::Field => self.chain(code, shape),
                Atom::Prefix => {
                    let operand = prefix_operand(text);
                    let op = &text[..text.len() - operand.len()];
                    let inner = shape.offset_left(op.len())?;
                    Some(format!("{op}{}", self.expr(&Code::atom(operand), inner)?))
                }
                _ => self.atom(text, shape),
            },
            Code::Other(_) | Code::Match(..) => self.unsure(),
            Code::Struct(path, fields) => self.struct_lit(path, fields, None, shape),
            Code::StructRest(path, fields, rest) => {
                self.struct_lit(path, fields, Some(rest), shape)
            }
            Code::Call(callee, args) => {
                if callee.is_empty() {
                    // A tuple: one element takes a trailing comma.
                    if args.len() < 2 {
                        return self.unsure();
                    }
                    return self.list("", ListKind::Call, args, shape);
                }
                // A macro's name is written whatever the room; a function's must fit.
                if let Some(name) = callee.strip_suffix('!') {
                    if !is_path(name) {
                        return self.unsure();
                    }
                    return self.list(callee, ListKind::Macro, args, shape);
                }
                let callee_text = self.atom(callee, shape)?;
                self.list(&callee_text, ListKind::Call, args, shape)
            }
            Code::List(open, items) => match open.as_str() {
                "[" => self.list("", ListKind::Array, items, shape),
                "&[" => {
                    let inner = shape.offset_left(1)?;
                    Some(format!(
                        "&{}",
                        self.list("", ListKind::Array, items, inner)?
                    ))
                }
                // `vec!` itself is laid out as an array, its trailing comma added:
                // not ported (coolc writes `::std::vec!`).
                open if open.ends_with("![")
                    && open != "vec!["
                    && is_path(&open[..open.len() - 2]) =>
                {
                    self.list(
                        &open[..open.len() - 1],
                        ListKind::BracketMacro,
                        items,
                        shape,
                    )
                }
                _ => self.unsure(),
            },
            Code::Repeat(..) => {
                let text = code.to_string();
                if text.len() <= shape.width {
                    Some(text)
                } else {
                    self.unsure()
                }
            }
            Code::Method(..) | Code::Field(..) | Code::Try(..) => self.chain(code, shape),
            Code::Unary(op, operand) => {
                let inner = shape.offset_left(op.len())?;
                Some(format!("{op}{}", self.expr(operand, inner)?))
            }
            Code::Binary(..) => self.binary(code, shape),
            Code::Paren(inner) => {
                let inner_shape = shape.offset_left(1)?.sub_width(1)?;
                Some(format!("({})", self.expr(inner, inner_shape)?))
            }
            Code::Closure(moves, params, body) => self.closure(*moves, params, body, shape),
            Code::Block(lets, tail) => self.block(lets, tail, shape, true),
        }
    }

    fn atom(&self, text: &str, shape: Shape) -> Option<String> {
        // Widths here are bytes: other characters are not ported.
        if text.contains('\n') || !text.is_ascii() {
            return self.unsure();
        }
        match atom_kind(text) {
            // Edition 2024 keeps a string literal of one line as it is, whatever the
            // room left (rustfmt's `rewrite_string_lit`).
            _ if text.len() <= shape.width || is_string(text) => Some(text.to_owned()),
            // rustfmt writes `_` whatever the room.
            Atom::Underscore => Some(text.to_owned()),
            // A path with generic arguments may break inside them.
            Atom::Path if text.contains('<') => self.unsure(),
            Atom::Literal | Atom::Ident | Atom::Path => None,
            _ => self.unsure(),
        }
    }

    /// A bracketed list after `ident` (rustfmt's `overflow::Context`): a call's
    /// arguments, a macro's, an array's items.
    fn list(&self, ident: &str, kind: ListKind, items: &[Code], shape: Shape) -> Option<String> {
        if matches!(kind, ListKind::Macro | ListKind::BracketMacro) {
            self.in_macro.set(self.in_macro.get() + 1);
            let result = self.list_inner(ident, kind, items, shape);
            self.in_macro.set(self.in_macro.get() - 1);
            // A macro call rustfmt cannot lay out keeps its text as written when that
            // fits: not ported.
            return result.or_else(|| self.unsure());
        }
        self.list_inner(ident, kind, items, shape)
    }

    fn list_inner(
        &self,
        ident: &str,
        kind: ListKind,
        items: &[Code],
        shape: Shape,
    ) -> Option<String> {
        let brackets = matches!(kind, ListKind::Array | ListKind::BracketMacro);
        let item_max_width = if brackets { ARRAY_WIDTH } else { FN_CALL_WIDTH };
        let used_width = ident.len();
        let one_line_width = shape.width.saturating_sub(used_width + 2);
        let one_line_shape = shape
            .offset_left(ident.len() + 1)
            .and_then(|s| s.sub_width(1))
            .unwrap_or(Shape { width: 0, ..shape });
        let nested = shape.block().block_indent(TAB).with_max_width();
        let nested_shape = Shape {
            width: nested.width.saturating_sub(1),
            ..nested
        };

        let mut rewrites: Vec<Option<String>> = items
            .iter()
            .map(|item| self.expr(item, nested_shape))
            .collect();
        if self.unsure.get() {
            return None;
        }
        let tactic = self.overflow_last(
            ident,
            kind,
            items,
            &mut rewrites,
            one_line_width,
            one_line_shape,
            nested_shape,
            item_max_width,
        )?;
        // Macros (and any list inside one) keep the trailing comma they were written
        // with: none.
        let trailing = tactic != Tactic::Horizontal && self.in_macro.get() == 0;
        let items_str = write_list(&rewrites, tactic, trailing, nested_shape)?;

        // rustfmt's `wrap_items`.
        let (open, close) = if brackets { ("[", "]") } else { ("(", ")") };
        let shape = Shape {
            width: shape.width.saturating_sub(last_line_width(ident)),
            ..shape
        };
        let extend_width = if items_str.is_empty() {
            2
        } else {
            first_line_width(&items_str) + 1
        };
        let mut result = String::with_capacity(ident.len() + items_str.len() + 16);
        result.push_str(ident);
        result.push_str(open);
        if tactic == Tactic::Horizontal && extend_width <= shape.width {
            result.push_str(&items_str);
        } else {
            if !items_str.is_empty() {
                result.push_str(&nested_shape.indent.newline());
                result.push_str(&items_str);
            }
            result.push_str(&shape.block().indent.newline());
        }
        result.push_str(close);
        Some(result)
    }

    /// rustfmt's `try_overflow_last_item`: the tactic, with the last item's rewrite
    /// overflowed (its first line on the line of the others) when that is chosen.
    #[allow(clippy::too_many_arguments)]
    fn overflow_last(
        &self,
        ident: &str,
        kind: ListKind,
        items: &[Code],
        rewrites: &mut [Option<String>],
        one_line_width: usize,
        one_line_shape: Shape,
        nested_shape: Shape,
        item_max_width: usize,
    ) -> Option<Tactic> {
        let count = items.len();
        let combine = count == 1 && ident.len() < TAB;
        let overflow = count > 0 && (combine || self.can_overflow(&items[count - 1], count));
        let placeholder = if overflow {
            let old = self.one_line_chain.get();
            if !combine && Self::is_method_call(&items[count - 1]) {
                self.one_line_chain.set(true);
            }
            let result = self
                .last_item_shape(items, rewrites, one_line_shape, item_max_width)
                .and_then(|shape| self.overflow_item(items, shape));
            self.one_line_chain.set(old);
            if let Some(text) = &result {
                rewrites[count - 1] = Some(text.split('\n').next().unwrap_or("").to_owned());
            }
            result
        } else {
            None
        };
        if self.unsure.get() {
            return None;
        }
        let limit = one_line_width.min(item_max_width);
        let mut tactic = definitive(rewrites, limit);
        match (overflow, tactic, placeholder) {
            (true, Tactic::Horizontal, Some(overflowed)) if count == 1 => {
                if newlines(&overflowed) == 1 {
                    let rewrite = self.expr(&items[0], nested_shape);
                    rewrites[0] = match rewrite {
                        Some(text) if !text.contains('\n') => Some(text),
                        _ => Some(overflowed),
                    };
                } else {
                    rewrites[0] = Some(overflowed);
                }
            }
            (true, Tactic::Horizontal, Some(overflowed)) => {
                rewrites[count - 1] = Some(overflowed);
            }
            _ if count > 0 => {
                rewrites[count - 1] = self.expr(&items[count - 1], nested_shape);
                let first = rewrites[0].as_deref().unwrap_or("");
                if count == 1
                    && one_line_width != 0
                    && !first.contains('\n')
                    && first.len() <= one_line_width
                {
                    tactic = Tactic::Horizontal;
                } else {
                    tactic = definitive(rewrites, limit);
                    if tactic == Tactic::Vertical {
                        let special = (kind == ListKind::Macro)
                            .then(|| SPECIAL_MACROS.iter().find(|(name, _)| *name == ident))
                            .flatten();
                        if let Some(&(_, before)) = special {
                            let all_simple = count > before
                                && items[..before].iter().all(|i| self.is_simple(i))
                                && items[before + 1..].iter().all(|i| self.is_simple(i));
                            // The arguments before the format string on the macro's
                            // line, the string on its own, the rest after it.
                            let width = nested_shape.width;
                            if all_simple
                                && definitive(&rewrites[..before], width) == Tactic::Horizontal
                                && definitive(&rewrites[before + 1..], width) == Tactic::Horizontal
                            {
                                tactic = Tactic::SpecialMacro(before);
                            }
                        } else if items.iter().all(|i| self.is_simple(i))
                            && rewrites
                                .iter()
                                .all(|r| r.as_deref().unwrap_or("").len() <= SHORT_ITEM)
                        {
                            tactic = Tactic::Mixed;
                        }
                    }
                }
            }
            _ => {}
        }
        if self.unsure.get() {
            return None;
        }
        Some(tactic)
    }

    /// rustfmt's `last_item_shape`.
    fn last_item_shape(
        &self,
        items: &[Code],
        rewrites: &[Option<String>],
        shape: Shape,
        max_width: usize,
    ) -> Option<Shape> {
        if items.len() == 1 && !self.is_nested_call(&items[0]) {
            return Some(shape);
        }
        let offset: usize = rewrites[..rewrites.len() - 1]
            .iter()
            .map(|r| 2 + r.as_deref().unwrap_or("").len())
            .sum();
        Shape {
            width: max_width.min(shape.width),
            ..shape
        }
        .offset_left(offset)
    }

    /// rustfmt's `rewrite_last_item_with_overflow`.
    fn overflow_item(&self, items: &[Code], shape: Shape) -> Option<String> {
        let last = items.last()?;
        match last {
            Code::Closure(moves, params, body) => {
                let closures = items
                    .iter()
                    .filter(|i| matches!(i, Code::Closure(..)))
                    .count();
                if closures > 1 {
                    return None;
                }
                self.last_closure(*moves, params, body, shape)
            }
            _ => self.expr(last, shape),
        }
    }

    /// A closure's `|params|` (rustfmt's `rewrite_closure_fn_decl`, without return
    /// types) and the columns it takes with the space after it.
    fn closure_prefix(&self, moves: bool, params: &str, shape: Shape) -> Option<(String, usize)> {
        let capture = if moves { "move " } else { "" };
        let nested = shape.shrink_left(capture.len())?.sub_width(4)?;
        let param_shape = nested.offset_left(1)?.visual_indent(0);
        // One parameter (a pattern, maybe typed); several are not ported.
        let mut depth = 0usize;
        for c in params.chars() {
            match c {
                '(' | '[' | '<' => depth += 1,
                ')' | ']' | '>' => depth = depth.saturating_sub(1),
                ',' if depth == 0 => return self.unsure(),
                _ => {}
            }
        }
        if params.len() > param_shape.width || params.len() > nested.width.saturating_sub(1) {
            return self.unsure();
        }
        let prefix = format!("{capture}|{params}|");
        let extra = prefix.len() + 1;
        Some((prefix, extra))
    }

    /// rustfmt's `rewrite_closure`.
    fn closure(&self, moves: bool, params: &str, body: &Code, shape: Shape) -> Option<String> {
        if self.in_macro.get() > 0 {
            return self.unsure();
        }
        let (prefix, extra) = self.closure_prefix(moves, params, shape)?;
        let body_shape = shape.offset_left(extra)?;
        match body {
            Code::Block(lets, tail) => {
                let without = if lets.is_empty() {
                    let inner = Self::inner_expr(tail);
                    self.closure_expr(inner, &prefix, body_shape)
                } else {
                    self.closure_expr(body, &prefix, body_shape)
                };
                without.or_else(|| {
                    Some(format!(
                        "{prefix} {}",
                        self.block(lets, tail, body_shape, true)?
                    ))
                })
            }
            _ => self
                .closure_expr(body, &prefix, body_shape)
                .or_else(|| self.closure_with_block(body, &prefix, body_shape)),
        }
    }

    /// The expression a block of one expression holds (rustfmt's `get_inner_expr`).
    fn inner_expr(code: &Code) -> &Code {
        match code {
            Code::Block(lets, tail) if lets.is_empty() => Self::inner_expr(tail),
            _ => code,
        }
    }

    /// rustfmt's `rewrite_closure_expr`: the body on the closure's line, on one line
    /// unless it is block-like.
    fn closure_expr(&self, body: &Code, prefix: &str, shape: Shape) -> Option<String> {
        fn multi_line_allowed(code: &Code) -> bool {
            match code {
                Code::Match(..) | Code::Block(..) | Code::Struct(..) | Code::StructRest(..) => true,
                Code::Unary(_, operand) | Code::Try(operand) => multi_line_allowed(operand),
                _ => false,
            }
        }
        let text = self.expr(body, shape)?;
        if !multi_line_allowed(body) && text.contains('\n') {
            return None;
        }
        Some(format!("{prefix} {text}"))
    }

    /// rustfmt's `rewrite_closure_with_block`: the body alone in a block.
    fn closure_with_block(&self, body: &Code, prefix: &str, shape: Shape) -> Option<String> {
        // `veto_block`: a body whose left-most part is a block or a `match`.
        let mut left = body;
        while let Code::Call(..) | Code::Binary(..) | Code::Field(..) | Code::Try(..) = left {
            left = match left {
                // A call's left-most part is its callee, a path.
                Code::Call(..) => break,
                Code::Binary(l, _, _) => l,
                Code::Field(l, _) | Code::Try(l) => l,
                _ => break,
            };
        }
        let vetoable = matches!(
            body,
            Code::Call(..) | Code::Binary(..) | Code::Field(..) | Code::Try(..)
        );
        if vetoable && matches!(left, Code::Block(..) | Code::Match(..)) {
            return None;
        }
        let block = format!("{prefix} {}", self.block_body(&[], body, shape.indent)?);
        // rustfmt adds the block, and its next run reads a closure with a block
        // body, which it may lay out otherwise: a layout that keeps this one is not
        // certain to be rustfmt's own fixed point (see `Printer::checked`).
        self.added_blocks.borrow_mut().push(block.clone());
        Some(block)
    }

    /// rustfmt's `rewrite_last_closure`: a closure as the overflowing last argument.
    fn last_closure(&self, moves: bool, params: &str, body: &Code, shape: Shape) -> Option<String> {
        if self.in_macro.get() > 0 {
            return self.unsure();
        }
        let inner = match body {
            Code::Block(lets, tail) if lets.is_empty() => tail,
            _ => body,
        };
        if matches!(inner, Code::Match(..)) {
            return self.unsure();
        }
        let (_, extra) = self.closure_prefix(moves, params, shape)?;
        shape.offset_left(extra)?;
        self.closure(moves, params, body, shape)
    }

    /// A block `{ let ...; tail }` as an expression (rustfmt's `rewrite_block`): on
    /// one line when it is one short expression (`allow_single_line`), else its
    /// statements one per line.
    fn block(
        &self,
        lets: &[(String, Code)],
        tail: &Code,
        shape: Shape,
        allow_single_line: bool,
    ) -> Option<String> {
        if self.in_macro.get() > 0 {
            return self.unsure();
        }
        let text = self.block_body(lets, tail, shape.indent)?;
        if allow_single_line && lets.is_empty() && line_count(&text) <= 3 {
            let inner = shape.offset_left(0)?;
            if let Some(expr) = self.expr(tail, inner) {
                let one = format!("{{ {expr} }}");
                if one.len() <= shape.width && !one.contains('\n') {
                    return Some(one);
                }
            }
        }
        Some(text)
    }

    /// A block's statements, each on its own line one level in from `indent`.
    fn block_body(&self, lets: &[(String, Code)], tail: &Code, indent: Indent) -> Option<String> {
        let inner = indent.block_indent();
        let mut out = String::from("{");
        for (name, value) in lets {
            out.push_str(&inner.newline());
            out.push_str(&self.let_stmt(name, None, value, inner)?);
        }
        out.push_str(&inner.newline());
        match self.expr(tail, Shape::indented(inner)) {
            Some(text) => out.push_str(&text),
            // The statement keeps its source text: not ported.
            None => return self.unsure(),
        }
        out.push_str(&indent.newline());
        out.push('}');
        Some(out)
    }

    /// `let pattern: ty = value;` at `indent` (rustfmt's `Local` rewrite), without
    /// its indentation.
    fn let_stmt(
        &self,
        pattern: &str,
        ty: Option<&str>,
        value: &Code,
        indent: Indent,
    ) -> Option<String> {
        let shape = Shape::indented(indent);
        let mut result = String::from("let ");
        let pattern_shape = shape.offset_left(4)?.sub_width(1)?;
        if pattern.len() > pattern_shape.width {
            return self.unsure();
        }
        result.push_str(pattern);
        if let Some(ty) = ty {
            let ty_shape = shape.offset_left(result.len() + 2)?.sub_width(2)?;
            if ty.len() > ty_shape.width {
                return self.unsure();
            }
            result.push_str(": ");
            result.push_str(ty);
        }
        result.push_str(" =");
        let shape = shape.sub_width(1)?;
        let Some(rhs) = self.assign_rhs(&result, value, shape) else {
            return self.unsure();
        };
        result.push_str(&rhs);
        result.push(';');
        Some(result)
    }

    /// rustfmt's `rewrite_assign_rhs`: the right-hand side after `lhs` (which ends in
    /// `=`), with its leading space or line break.
    fn assign_rhs(&self, lhs: &str, value: &Code, shape: Shape) -> Option<String> {
        let used = last_line_width(lhs);
        let orig_shape = shape.offset_left(used + 1).unwrap_or(Shape {
            width: 0,
            offset: shape.offset + used + 1,
            ..shape
        });
        let orig = self.expr(value, orig_shape);
        if let Some(text) = &orig
            && !text.contains('\n')
            && text.len() <= orig_shape.width
        {
            return Some(format!(" {text}"));
        }
        let new_shape = Shape::indented(orig_shape.indent.block_indent())
            .sub_width(orig_shape.rhs_overhead())?;
        let new = self.expr(value, new_shape);
        let new_indent = orig_shape.indent.block_indent().newline();
        match (orig, new) {
            (Some(orig), Some(new)) if fits(new.clone(), new_shape).is_none() => {
                Some(format!(" {orig}"))
            }
            (Some(orig), Some(new)) if prefer_next_line(&orig, &new) => {
                Some(format!("{new_indent}{new}"))
            }
            (None, Some(new)) => Some(format!("{new_indent}{new}")),
            (None, None) => None,
            (Some(orig), _) => Some(format!(" {orig}")),
        }
    }

    /// rustfmt's chains (`rewrite_chain`, block indentation): method calls, fields
    /// and `?`.
    fn chain(&self, code: &Code, shape: Shape) -> Option<String> {
        // The items from the parent out, each with its `?` count.
        let mut items: Vec<(Link<'_>, usize)> = Vec::new();
        let mut tries = 0;
        let mut node = code;
        loop {
            match node {
                Code::Try(inner) => {
                    tries += 1;
                    node = inner;
                }
                Code::Method(receiver, method, args) => {
                    items.push((Link::Method(method, args), tries));
                    tries = 0;
                    node = receiver;
                }
                Code::Field(receiver, field) => {
                    items.push((Link::Field(field), tries));
                    tries = 0;
                    node = receiver;
                }
                // `a.b` written as one atom is a chain of a field for rustfmt.
                Code::Atom(text) if atom_kind(text) == Atom::Field => {
                    let parts: Vec<&str> = text.split('.').collect();
                    for (i, part) in parts.iter().enumerate().skip(1).rev() {
                        let part_tries = if i + 1 == parts.len() { tries } else { 0 };
                        items.push((Link::Field(part), part_tries));
                    }
                    items.push((Link::Root(parts[0]), 0));
                    break;
                }
                _ => {
                    items.push((Link::Parent(node), tries));
                    break;
                }
            }
        }
        items.reverse();
        let (parent, children) = items.split_first()?;
        if children.is_empty() {
            return self.link(parent, shape);
        }
        let child_count = children.len();

        // The root: the parent and the children that fit in a tab's width after it.
        let mut root = self.link(parent, shape)?;
        let mut ends_with_block = match parent.0 {
            Link::Parent(parent_code) => self.is_block_like(parent_code, &root),
            _ => false,
        };
        let tab_width = TAB.saturating_sub(shape.offset);
        let mut children = children;
        while root.len() <= tab_width && !root.contains('\n') {
            let item = &children[0];
            let item_shape = shape.offset_left(root.len())?;
            match self.link(item, item_shape) {
                Some(text) => root.push_str(&text),
                None => break,
            }
            ends_with_block = last_line_extendable(&root);
            children = &children[1..];
            if children.is_empty() {
                break;
            }
        }
        if children.is_empty() {
            return fits(root, shape);
        }

        let child_shape = if ends_with_block {
            shape.block_indent(0)
        } else {
            shape.block_indent(TAB)
        }
        .with_max_width();
        let mut rewrites = vec![root];
        let (last, middle) = children.split_last()?;
        for item in middle {
            rewrites.push(self.link(item, child_shape)?);
        }

        // rustfmt's `format_last_child`.
        let last_tries = last.1;
        let extendable = last_line_extendable(&rewrites[0]);
        let almost_total = if extendable {
            last_line_width(&rewrites[0])
        } else {
            rewrites.iter().map(String::len).sum()
        } + last_tries;
        let one_line_budget = if child_count == 1 {
            shape.width
        } else {
            shape.width.min(CHAIN_WIDTH)
        }
        .saturating_sub(almost_total);
        let all_in_one_line = rewrites.iter().all(|r| !r.contains('\n')) && one_line_budget > 0;
        let last_shape = if all_in_one_line {
            shape.sub_width(last_tries)?
        } else if extendable {
            child_shape.sub_width(last_tries)?
        } else {
            child_shape.sub_width(shape.rhs_overhead() + last_tries)?
        };
        let mut fits_single_line = false;
        let mut last_text = None;
        if (all_in_one_line || extendable)
            && let Some(one_line_shape) = last_shape.offset_left(almost_total)
            && let Some(rewrite) = self.link(last, one_line_shape)
        {
            let lines = line_count(&rewrite);
            let could_fit = first_line_width(&rewrite) <= one_line_budget;
            if could_fit && lines >= 5 {
                last_text = Some(rewrite);
                fits_single_line = all_in_one_line;
            } else {
                let own_shape = child_shape.sub_width(shape.rhs_overhead() + last_tries)?;
                match self.link(last, own_shape) {
                    Some(new) if !could_fit => last_text = Some(new),
                    Some(new) if line_count(&new) >= lines => {
                        last_text = Some(rewrite);
                        fits_single_line = could_fit && all_in_one_line;
                    }
                    Some(new) => last_text = Some(new),
                    None => {
                        last_text = Some(rewrite);
                        fits_single_line = could_fit && all_in_one_line;
                    }
                }
            }
        }
        // rustfmt evaluates this rewrite whether or not it uses it, and fails with it.
        let fallback = self.link(last, last_shape)?;
        rewrites.push(last_text.unwrap_or(fallback));

        // rustfmt's `join_rewrites`.
        let connector = if fits_single_line {
            String::new()
        } else {
            if self.one_line_chain.get() {
                return None;
            }
            child_shape.newline()
        };
        let mut result = rewrites[0].clone();
        for rewrite in &rewrites[1..] {
            result.push_str(&connector);
            result.push_str(rewrite);
        }
        fits(result, shape)
    }

    /// One item of a chain with its `?`s.
    fn link(&self, (link, tries): &(Link<'_>, usize), shape: Shape) -> Option<String> {
        let shape = shape.sub_width(*tries)?;
        let mut text = match link {
            Link::Parent(code) => self.expr(code, shape)?,
            Link::Root(name) => self.atom(name, shape)?,
            Link::Method(method, args) => {
                let callee = format!(".{method}");
                self.list(&callee, ListKind::Call, args, shape)?
            }
            Link::Field(field) => format!(".{field}"),
        };
        for _ in 0..*tries {
            text.push('?');
        }
        Some(text)
    }

    /// rustfmt's `is_block_expr`: whether `code`, written as `text`, ends in a line
    /// of closing brackets.
    fn is_block_like(&self, code: &Code, text: &str) -> bool {
        match code {
            // `&[...]` is a reference: not block-like.
            Code::List(open, _) if open.starts_with('&') => false,
            Code::Unary(op, _) if op.starts_with('&') => false,
            Code::Call(..)
            | Code::Method(..)
            | Code::List(..)
            | Code::Struct(..)
            | Code::StructRest(..)
            | Code::Block(..)
            | Code::Match(..) => text.contains('\n'),
            Code::Paren(inner) | Code::Unary(_, inner) | Code::Try(inner) => {
                self.is_block_like(inner, text)
            }
            Code::Binary(_, _, right) => self.is_block_like(right, text),
            // A body of one expression in a block loses its braces when it fits on
            // the closure's line: which one the text shows is not known here.
            Code::Closure(_, _, body) => match body.as_ref() {
                Code::Block(lets, _) if lets.is_empty() && text.contains('\n') => {
                    self.unsure().unwrap_or(false)
                }
                _ => self.is_block_like(body, text),
            },
            Code::Atom(_) | Code::Repeat(..) | Code::Field(..) => false,
            Code::Other(_) => self.unsure().unwrap_or(false),
        }
    }

    /// Binary operators (rustfmt's `rewrite_all_pairs`, then `rewrite_pair`).
    fn binary(&self, code: &Code, shape: Shape) -> Option<String> {
        let Code::Binary(left, op, right) = code else {
            return None;
        };
        self.all_pairs(code, shape)
            .or_else(|| self.pair(left, op, right, shape))
    }

    /// The operands of `code` flattened through its left side while the operator is
    /// `code`'s, with the operators between them.
    fn flatten(code: &Code) -> (Vec<&Code>, Vec<&'static str>) {
        let Code::Binary(_, top, _) = code else {
            return (vec![code], Vec::new());
        };
        let mut lefts = Vec::new();
        let mut node = code;
        while let Code::Binary(left, op, _) = node
            && op == top
        {
            lefts.push(node);
            node = left;
        }
        let mut operands = vec![node];
        let mut ops = Vec::new();
        for parent in lefts.into_iter().rev() {
            if let Code::Binary(_, op, right) = parent {
                ops.push(*op);
                operands.push(right);
            }
        }
        (operands, ops)
    }

    fn all_pairs(&self, code: &Code, shape: Shape) -> Option<String> {
        let (operands, ops) = Self::flatten(code);
        // Each operand's own rewrite (rustfmt's `default_rewrite`).
        let rewrites: Vec<Option<String>> = operands
            .iter()
            .enumerate()
            .map(|(i, operand)| {
                if i == 0 {
                    return self.expr(operand, shape);
                }
                let sep = ops[i - 1].len();
                let nested = shape
                    .block_indent(TAB)
                    .with_max_width()
                    .sub_width(shape.rhs_overhead())?;
                self.expr(operand, nested.offset_left(sep + 1)?)
            })
            .collect();
        if self.unsure.get() {
            return None;
        }
        self.pairs_one_line(&operands, &ops, &rewrites, shape)
            .or_else(|| self.pairs_multi_line(&operands, &ops, &rewrites, shape))
    }

    fn pairs_one_line(
        &self,
        operands: &[&Code],
        ops: &[&str],
        rewrites: &[Option<String>],
        shape: Shape,
    ) -> Option<String> {
        let mut result = String::new();
        for (rewrite, op) in rewrites.iter().zip(ops) {
            let rewrite = rewrite.as_ref()?;
            if rewrite.contains('\n') || result.len() > shape.width {
                return None;
            }
            result.push_str(rewrite);
            result.push(' ');
            result.push_str(op);
            result.push(' ');
        }
        let prefix_len = result.len();
        let last = operands.last()?;
        let last_shape = shape.block().offset_left(last_line_width(&result))?;
        let last_text = self.expr(last, last_shape)?;
        result.push_str(&last_text);
        if first_line_width(&result) > shape.width {
            return None;
        }
        // A last operand laid out on several lines only when it opens a block, or
        // when it does not start with `(` after a short first part.
        if result.contains('\n')
            && !last_text.starts_with('{')
            && (last_text.starts_with('(') || prefix_len > TAB)
        {
            return None;
        }
        fits(result, shape)
    }

    fn pairs_multi_line(
        &self,
        operands: &[&Code],
        ops: &[&str],
        rewrites: &[Option<String>],
        shape: Shape,
    ) -> Option<String> {
        let nested = shape
            .block_indent(TAB)
            .with_max_width()
            .sub_width(shape.rhs_overhead())?;
        let indent = nested.indent.newline();
        let mut result = rewrites[0].clone()?;
        for ((operand, rewrite), op) in operands[1..].iter().zip(&rewrites[1..]).zip(ops) {
            let offset = if result.contains('\n') {
                0
            } else {
                shape.used_width()
            };
            if last_line_width(&result) + offset <= nested.used_width()
                && let Some(line_shape) =
                    shape.offset_left(op.len() + 2 + trimmed_last_line_width(&result))
                && let Some(text) = self.expr(operand, line_shape)
            {
                result.push(' ');
                result.push_str(op);
                result.push(' ');
                result.push_str(&text);
                continue;
            }
            result.push_str(&indent);
            result.push_str(op);
            result.push(' ');
            result.push_str(rewrite.as_ref()?);
        }
        Some(result)
    }

    /// rustfmt's `rewrite_pair` with the operator in front of the second line.
    fn pair(&self, left: &Code, op: &str, right: &Code, shape: Shape) -> Option<String> {
        let infix = format!(" {op} ");
        let left_shape = Shape {
            width: MAX_WIDTH.saturating_sub(shape.used_width()),
            ..shape
        };
        let left_text = self.expr(left, left_shape)?;
        let same_line = shape
            .offset_left(last_line_width(&left_text) + infix.len())
            .and_then(|s| self.expr(right, s));
        if let Some(right_text) = &same_line {
            let allow = left_text.len() <= TAB
                || right_text
                    .lines()
                    .next()
                    .is_some_and(|first| first.ends_with('{'));
            if (!right_text.contains('\n') || allow)
                && last_line_width(&left_text) + infix.len() + first_line_width(right_text)
                    <= shape.width
            {
                return Some(format!("{left_text}{infix}{right_text}"));
            }
        }
        let right_shape = Shape::indented(shape.indent.block_indent())
            .sub_width(shape.rhs_overhead())?
            .offset_left(op.len() + 1)?;
        let right_text = self.expr(right, right_shape)?;
        Some(format!(
            "{left_text}{}{op} {right_text}",
            right_shape.indent.newline()
        ))
    }

    /// A struct literal (rustfmt's `rewrite_struct_lit`), with the rest of its fields
    /// from `base` when there is one.
    fn struct_lit(
        &self,
        path: &str,
        fields: &[(String, Code)],
        base: Option<&Code>,
        shape: Shape,
    ) -> Option<String> {
        let path_shape = shape.sub_width(2)?;
        let path_text = self.atom(path, path_shape)?;
        if fields.is_empty() && base.is_none() {
            return Some(format!("{path_text} {{}}"));
        }
        // rustfmt's `struct_lit_shape`.
        let v = shape.block_indent(TAB);
        let v_shape = Shape {
            width: MAX_WIDTH.saturating_sub(v.indent.width()),
            ..v
        };
        let h_shape = shape
            .width
            .checked_sub(path_text.len() + 3 + 2)
            .map(|w| Shape::legacy(w.min(STRUCT_LIT_WIDTH), shape.indent));
        let one_line_width = h_shape.map_or(0, |s| s.width);

        let mut items: Vec<Option<String>> = Vec::with_capacity(fields.len() + 1);
        for (name, value) in fields {
            items.push(self.field(name, value, v_shape.sub_width(1)?));
        }
        if let Some(base) = base {
            items.push(
                v_shape
                    .offset_left(2)
                    .and_then(|s| self.expr(base, s))
                    .map(|text| format!("..{text}")),
            );
        }
        if self.unsure.get() {
            return None;
        }
        let tactic = match h_shape {
            Some(h) => definitive(&items, h.width),
            None => Tactic::Vertical,
        };
        let nested_shape = match tactic {
            Tactic::Horizontal => h_shape?,
            _ => v_shape,
        };
        let trailing = tactic == Tactic::Vertical && base.is_none() && self.in_macro.get() == 0;
        let fields_text = write_list(&items, tactic, trailing, nested_shape)?;
        // rustfmt's `wrap_struct_field`.
        if fields_text.contains('\n') || fields_text.len() > one_line_width {
            Some(format!(
                "{path_text} {{{}{fields_text}{}}}",
                v_shape.indent.newline(),
                shape.indent.newline()
            ))
        } else {
            Some(format!("{path_text} {{ {fields_text} }}"))
        }
    }

    /// `name: value` of a struct literal (rustfmt's `rewrite_field`).
    fn field(&self, name: &str, value: &Code, shape: Shape) -> Option<String> {
        let value_shape = shape.offset_left(name.len() + 2)?;
        // `use_field_init_shorthand` is off by default: `name: name` stays.
        match self.expr(value, value_shape) {
            Some(text) => Some(format!("{name}: {text}")),
            None => {
                let indent = shape.indent.block_indent();
                let text = self.expr(value, Shape::indented(indent))?;
                Some(format!("{name}:\n{}{text}", " ".repeat(indent.width())))
            }
        }
    }

    /// `code` as the statement `code;` or a block's tail expression (`tail` empty) at
    /// block indentation `indent`, without that indentation; `None` when rustfmt
    /// would keep the statement as written or lay it out by rules not ported here.
    pub(crate) fn statement(&self, indent: usize, code: &Code, tail: &str) -> Option<String> {
        let shape = Shape::line(indent).sub_width(tail.len())?;
        let text = match code {
            // A block statement is never put on one line.
            Code::Block(lets, last) if !tail.is_empty() => self.block(lets, last, shape, false)?,
            _ => self.expr(code, shape)?,
        };
        self.checked(format!("{text}{tail}"), indent)
    }

    /// `let pattern: ty = value;` at block indentation `indent`, without that
    /// indentation.
    pub(crate) fn let_statement(
        &self,
        indent: usize,
        pattern: &str,
        ty: Option<&str>,
        value: &Code,
    ) -> Option<String> {
        let text = self.let_stmt(
            pattern,
            ty,
            value,
            Indent {
                block: indent,
                align: 0,
            },
        )?;
        self.checked(text, indent)
    }

    /// `lhs value;`, where `lhs` ends in `=` (a `const` or `static` item), at
    /// block indentation `indent`, without that indentation.
    pub(crate) fn assign(&self, indent: usize, lhs: &str, value: &Code) -> Option<String> {
        let shape = Shape::line(indent).sub_width(1)?;
        let Some(rhs) = self.assign_rhs(lhs, value, shape) else {
            return self.unsure();
        };
        // A string literal too long for any line stays on the line of its `=`.
        let string = matches!(value, Code::Atom(text) if is_string(text));
        self.checked_width(format!("{lhs}{rhs};"), indent, !string)
    }

    /// `text` unless something unsure was met or a line of it (the first at
    /// `indent`) runs past `max_width`.
    fn checked(&self, text: String, indent: usize) -> Option<String> {
        self.checked_width(text, indent, true)
    }

    /// [`Printer::checked`], with lines past `max_width` allowed unless `width`.
    fn checked_width(&self, text: String, indent: usize, width: bool) -> Option<String> {
        if self.unsure.get()
            || width
                && (indent + first_line_width(&text) > MAX_WIDTH
                    || text.split('\n').skip(1).any(|l| l.len() > MAX_WIDTH))
        {
            return self.unsure();
        }
        if self
            .added_blocks
            .borrow()
            .iter()
            .any(|block| text.contains(block.as_str()))
        {
            return self.unsure();
        }
        Some(text)
    }
}

/// One item of a chain.
#[derive(Clone, Copy, Debug)]
enum Link<'c> {
    /// The expression the chain starts from.
    Parent(&'c Code),
    /// A name the chain starts from (the first part of an atom `a.b`).
    Root(&'c str),
    /// `.method(args)`.
    Method(&'c str, &'c [Code]),
    /// `.field`.
    Field(&'c str),
}

/// rustfmt's `prefer_next_line` (default tactic).
fn prefer_next_line(orig: &str, next: &str) -> bool {
    let first_ends = |text: &str, c: char| text.lines().next().is_some_and(|l| l.ends_with(c));
    !next.contains('\n')
        || newlines(orig) > newlines(next) + 1
        || first_ends(orig, '(') && !first_ends(next, '(')
        || first_ends(orig, '{') && !first_ends(next, '{')
        || first_ends(orig, '[') && !first_ends(next, '[')
}

/// rustfmt's `definitive_tactic` for a list limited to `limit` columns on one line.
fn definitive(items: &[Option<String>], limit: usize) -> Tactic {
    let widths: usize = items.iter().map(|i| i.as_deref().map_or(0, str::len)).sum();
    let total = widths + 2 * items.len().saturating_sub(1);
    let multi_line = items
        .iter()
        .any(|i| i.as_deref().is_some_and(|t| t.contains('\n')));
    if total <= limit && !multi_line {
        Tactic::Horizontal
    } else {
        Tactic::Vertical
    }
}

/// rustfmt's `write_list` of comma-separated items in `shape`: on one line, one per
/// line at its indentation, or as many per line as fit (a vertical or mixed list
/// ends with a comma when `trailing`).
fn write_list(
    items: &[Option<String>],
    tactic: Tactic,
    trailing: bool,
    shape: Shape,
) -> Option<String> {
    let mut result = String::new();
    let count = items.len();
    let mut line_len = 0;
    // rustfmt's `trailing_separator` as `write_list` updates it: a mixed list that
    // has broken a line counts a comma after its last item.
    let mut broke = false;
    for (i, item) in items.iter().enumerate() {
        let item = item.as_deref()?;
        let first = i == 0;
        let last = i + 1 == count;
        let mut separate = !last || (trailing && tactic == Tactic::Vertical) || broke;
        if item.is_empty() {
            continue;
        }
        match tactic {
            Tactic::Horizontal if !first => result.push(' '),
            Tactic::Vertical if !first && !result.is_empty() => {
                result.push_str(&shape.indent.newline());
            }
            Tactic::SpecialMacro(before) => {
                if i == 0 {
                } else if i < before {
                    result.push(' ');
                } else if i <= before + 1 {
                    result.push_str(&shape.indent.newline());
                } else {
                    result.push(' ');
                }
            }
            Tactic::Mixed => {
                let width = item.len() + usize::from(separate);
                if line_len > 0 && line_len + 1 + width > shape.width {
                    result.push_str(&shape.indent.newline());
                    line_len = 0;
                    broke = true;
                } else if line_len > 0 {
                    result.push(' ');
                    line_len += 1;
                }
                if last {
                    separate = trailing;
                }
                line_len += width;
            }
            _ => {}
        }
        result.push_str(item);
        if separate {
            result.push(',');
        }
    }
    Some(result)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn print(code: &Code, indent: usize) -> Option<String> {
        Printer::default().statement(indent, code, ";")
    }

    #[test]
    fn a_chain_breaks_past_chain_width() {
        let code = Code::atom("view")
            .method("state", vec![Code::string("w1")])
            .method(
                "is_some_and",
                vec![Code::closure(
                    "left",
                    Code::binary(
                        Code::atom("left"),
                        "==",
                        Code::atom("::coolbot::State::RunningError"),
                    ),
                )],
            );
        assert_eq!(
            print(&code, 4).unwrap(),
            "view.state(\"w1\")\n        .is_some_and(|left| left == ::coolbot::State::RunningError);"
        );
    }

    #[test]
    fn a_match_is_not_ported() {
        let code = Code::Match(Box::new(Code::atom("x")), vec![]);
        let printer = Printer::default();
        assert_eq!(printer.statement(4, &code, ";"), None);
        assert!(printer.is_unsure());
    }

    /// A deterministic generator of expression trees (xorshift).
    struct Gen(u64);

    impl Gen {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0
        }

        fn below(&mut self, n: usize) -> usize {
            (self.next() % n as u64) as usize
        }

        fn name(&mut self) -> String {
            const NAMES: &[&str] = &[
                "x",
                "view",
                "vars",
                "self",
                "name",
                "registry",
                "value",
                "harness",
                "left",
                "supervisor",
                "a_rather_long_variable_name",
                "configuration_of_the_component",
            ];
            NAMES[self.below(NAMES.len())].to_owned()
        }

        fn path(&mut self) -> String {
            const PATHS: &[&str] = &[
                "Some",
                "f64::from",
                "i128::from",
                "::coolbot::State::Running",
                "::core::option::Option::Some",
                "::std::time::Duration::from_nanos",
                "super::worker00001::component_with",
                "::coolbot::CompoundBuilder::new",
                "::out1::generated::assembly0099::register",
                "::out1::assembly0099::Assembly0099Parts::default",
                "::std::sync::Arc::clone",
                "__cool_lock",
            ];
            PATHS[self.below(PATHS.len())].to_owned()
        }

        fn atom(&mut self) -> Code {
            match self.below(8) {
                6 => {
                    let n = 1 + self.below(30);
                    Code::atom(format!("n{}", "x".repeat(n)))
                }
                7 => {
                    let n = 1 + self.below(30);
                    Code::atom(format!("::p::{}", "y".repeat(n)))
                }
                0 => Code::atom(self.name()),
                1 => Code::atom(self.path()),
                2 => Code::atom(format!("{}", self.next() % 100_000_000_000)),
                3 => {
                    let n = self.below(40);
                    let escape = if self.below(4) == 0 { "\\\"" } else { "" };
                    Code::atom(format!("\"{escape}{}\"", "w".repeat(n)))
                }
                4 => Code::atom("false"),
                _ => Code::atom("0.5"),
            }
        }

        /// An operand of a method call, field, `?` or operator: parenthesized when
        /// Rust would read it otherwise.
        fn operand(&mut self, depth: usize, tight: bool) -> Code {
            self.operand_of(depth, tight, false)
        }

        /// The receiver of a method call, field or `?` (which bind tighter than a
        /// prefix operator).
        fn receiver(&mut self, depth: usize) -> Code {
            self.operand_of(depth, true, true)
        }

        fn operand_of(&mut self, depth: usize, tight: bool, postfix: bool) -> Code {
            let code = self.code(depth);
            let wrap = match &code {
                Code::Closure(..) | Code::Block(..) => true,
                Code::Unary(..) => postfix,
                Code::List(open, _) => postfix && open.starts_with('&'),
                // Under `&&` or `||`: a comparison binds tighter, the other operator
                // is parenthesized.
                Code::Binary(_, op, _) => tight || matches!(*op, "&&" | "||"),
                _ => false,
            };
            if wrap { code.paren() } else { code }
        }

        fn code(&mut self, depth: usize) -> Code {
            if depth == 0 {
                return self.atom();
            }
            let args = |g: &mut Gen, max: usize| -> Vec<Code> {
                let n = g.below(max + 1);
                (0..n).map(|_| g.code(depth - 1)).collect()
            };
            match self.below(13) {
                0 | 1 => self.atom(),
                2 | 3 if self.below(4) == 0 => {
                    // A formatting macro with simple arguments around its string.
                    const MACROS: &[(&str, usize)] = &[
                        ("panic!", 0),
                        ("format!", 0),
                        ("assert!", 1),
                        ("assert_eq!", 2),
                    ];
                    let (name, before) = MACROS[self.below(MACROS.len())];
                    let simple = |g: &mut Gen| match g.below(3) {
                        0 => Code::atom(g.name()),
                        1 => Code::atom(format!("{}", g.next() % 1000)),
                        _ => Code::atom(format!("n{}", "x".repeat(1 + g.below(30)))),
                    };
                    let mut items: Vec<Code> = (0..before).map(|_| simple(self)).collect();
                    let n = self.below(70);
                    items.push(Code::atom(format!("\"{} {{}}\"", "f".repeat(n))));
                    for _ in 0..self.below(3) {
                        items.push(simple(self));
                    }
                    Code::Call(name.to_owned(), items)
                }
                2 | 3 => {
                    let callee = if self.below(4) == 0 {
                        const MACROS: &[&str] = &[
                            "::core::matches!",
                            "format!",
                            "assert_eq!",
                            "assert!",
                            "some_macro!",
                        ];
                        MACROS[self.below(MACROS.len())].to_owned()
                    } else {
                        self.path()
                    };
                    Code::Call(callee, args(self, 4))
                }
                4 | 5 => {
                    let receiver = self.receiver(depth - 1);
                    const METHODS: &[&str] = &[
                        "is_some_and",
                        "map",
                        "unwrap_or",
                        "with_timing",
                        "rule",
                        "instance",
                        "connect",
                        "ok",
                    ];
                    let method = METHODS[self.below(METHODS.len())];
                    receiver.method(method, args(self, 3))
                }
                6 => self.receiver(depth - 1).field("faults"),
                7 => self.receiver(depth - 1).try_op(),
                8 => {
                    const OPS: &[&str] = &["==", "&&", "||", ">", "!="];
                    let op = OPS[self.below(OPS.len())];
                    let comparison = !matches!(op, "&&" | "||");
                    // `a || b || c`: the same operator, flattened by rustfmt.
                    let left = if !comparison && self.below(2) == 0 {
                        Code::binary(
                            self.operand(depth - 1, true),
                            op,
                            self.operand(depth - 1, true),
                        )
                    } else {
                        self.operand(depth - 1, comparison)
                    };
                    Code::binary(left, op, self.operand(depth - 1, comparison))
                }
                9 => {
                    const PARAMS: &[&str] =
                        &["left", "(left, right)", "view: &::coolbot::View", "_"];
                    let params = PARAMS[self.below(PARAMS.len())];
                    let body = self.code(depth - 1);
                    if self.below(2) == 0 {
                        Code::closure(params, body)
                    } else {
                        Code::move_closure(params, Code::Block(Vec::new(), Box::new(body)))
                    }
                }
                10 => {
                    let fields = (0..self.below(4))
                        .map(|i| (format!("field{i}"), self.code(depth - 1)))
                        .collect();
                    if self.below(2) == 0 {
                        Code::Struct("super::worker00000::Config".to_owned(), fields)
                    } else {
                        Code::StructRest(
                            "::coolbot::TimingSpec".to_owned(),
                            fields,
                            Box::new(Code::atom("super::worker00000::SPEC.timing")),
                        )
                    }
                }
                11 => {
                    let choice = self.below(3);
                    if choice == 2 {
                        Code::List("::std::vec![".to_owned(), args(self, 4))
                    } else if choice == 0 {
                        Code::slice(args(self, 4))
                    } else {
                        // Many short items: rustfmt packs them (`Mixed`).
                        let n = self.below(30);
                        let items = (0..n)
                            .map(|_| {
                                let digits = 1 + self.below(12);
                                Code::atom("7".repeat(digits))
                            })
                            .collect();
                        match self.below(3) {
                            0 => Code::slice(items),
                            1 => Code::List("::std::vec![".to_owned(), items),
                            _ => Code::Call(self.path(), items),
                        }
                    }
                }
                _ => {
                    let lets = (0..self.below(3))
                        .map(|i| (format!("v{i}"), self.code(depth - 1)))
                        .collect();
                    let tail = self.code(depth - 1);
                    if self.below(2) == 0 {
                        Code::Block(lets, Box::new(tail))
                    } else {
                        Code::prefix("!", self.operand(depth - 1, true))
                    }
                }
            }
        }
    }

    /// rustfmt's output for `text`.
    fn rustfmt(text: &str) -> String {
        use std::io::Write;
        use std::process::{Command, Stdio};
        let mut child = Command::new("rustfmt")
            .args(["--edition", "2024", "--emit", "stdout", "--quiet"])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect(
                "rustfmt is the reference of this test: install it (rustup component add rustfmt)",
            );
        let mut stdin = child.stdin.take().unwrap();
        let input = text.to_owned();
        let writer = std::thread::spawn(move || stdin.write_all(input.as_bytes()));
        let output = child.wait_with_output().unwrap();
        writer.join().unwrap().unwrap();
        assert!(output.status.success(), "rustfmt failed on:\n{text}");
        String::from_utf8(output.stdout).unwrap()
    }

    /// Random trees laid out as statements at several indentations: wherever the
    /// printer is sure, its layout is rustfmt's, byte for byte; and it is sure of
    /// most of them.
    #[test]
    fn random_trees_are_laid_out_as_rustfmt_does() {
        let mut generator = Gen(0x5EED_C001);
        let mut cases = Vec::new();
        for case in 0..4000 {
            let code = generator.code(1 + case % 5);
            let indent = 4 * (1 + generator.below(6));
            let form = generator.below(3);
            cases.push((code, indent, form));
        }
        let mut input = String::new();
        let mut expected = Vec::new();
        for (index, (code, indent, form)) in cases.iter().enumerate() {
            let printer = Printer::default();
            let text = match form {
                0 => printer.statement(*indent, code, ";"),
                1 => printer.statement(*indent, code, ""),
                _ => printer.let_statement(*indent, "result", None, code),
            };
            // Nested `if` blocks put the statement at its indentation.
            let open = (*indent / 4).saturating_sub(1);
            let mut item = format!("fn case{index}() {{\n");
            for level in 0..open {
                item.push_str(&" ".repeat(4 * (level + 1)));
                item.push_str("if x {\n");
            }
            let one_line = match form {
                0 => format!("{code};"),
                1 => code.to_string(),
                _ => format!("let result = {code};"),
            };
            item.push_str(&" ".repeat(*indent));
            item.push_str(text.as_deref().unwrap_or(&one_line));
            item.push('\n');
            for level in (0..open).rev() {
                item.push_str(&" ".repeat(4 * (level + 1)));
                item.push_str("}\n");
            }
            item.push_str("}\n");
            expected.push(text.map(|_| item.clone()));
            input.push_str(&item);
            input.push('\n');
        }
        let output = rustfmt(&input);
        let items: Vec<&str> = output.split("\nfn case").collect();
        assert_eq!(items.len(), cases.len());
        let mut sure = 0;
        let mut wrong = Vec::new();
        for (index, (item, expected)) in items.iter().zip(&expected).enumerate() {
            let Some(expected) = expected else {
                continue;
            };
            sure += 1;
            let item = if index == 0 {
                format!("{item}\n")
            } else {
                format!("fn case{item}\n")
            };
            let expected = expected.clone();
            if item.trim_end() != expected.trim_end() {
                wrong.push(format!("--- printed\n{expected}--- rustfmt\n{item}"));
            }
        }
        assert!(
            wrong.is_empty(),
            "{} of {sure} differ; the first:\n{}",
            wrong.len(),
            wrong.iter().take(3).cloned().collect::<Vec<_>>().join("\n")
        );
        assert!(
            sure * 2 > cases.len(),
            "sure of only {sure} of {}",
            cases.len()
        );
    }
}
