//! The `when` rules of a compound's supervisor compiled to Rust over
//! `coolbot::View`: each condition is read from the checker's typed tree
//! ([`Typed`], by the one rule typer in `check::rules`), node by node, into a
//! boolean expression that is `false` when a value it reads is missing, with the read
//! keys that make the runtime evaluate it.

use super::super::{GEN_TYPES, Lowerer, duration_rust};
use crate::checked::model::{
    BinaryOp, Component, DEFAULT_STATES, Node, Prim, RESULTS, RTy, Ty, Typed, UnaryOp, VarKind,
};
use crate::ident;
use crate::ir;
use crate::lower::automaton::When;

/// The rules of compound `c`, from each `when` of its supervisor in order (its
/// condition typed by the checker).
pub(super) fn compile<'a>(
    lowerer: &Lowerer<'a>,
    c: &'a Component,
    when: &[When<'_>],
) -> Vec<ir::Rule> {
    let mut rules = Vec::new();
    for rule in when {
        let (state, condition, target) = (&rule.state, rule.condition, &rule.target);
        let mut scope = Scope {
            lowerer,
            component: c,
            state: state.clone(),
            reads: Vec::new(),
            uses_view: false,
            uses_vars: false,
        };
        let expr = scope.boolean(condition);
        let function = format!("__cool_rule_{}", rules.len());
        let reads: Vec<String> = scope
            .reads
            .iter()
            .map(|r| ident::string_literal(r))
            .collect();
        let call = match (scope.uses_view, scope.uses_vars) {
            (_, true) => format!(
                "{{ let vars = ::std::sync::Arc::clone(&vars); move |view: &::coolbot::View| {function}(view, &__cool_lock(&vars)) }}"
            ),
            (_, false) => function.clone(),
        };
        rules.push(ir::Rule {
            state: ident::string_literal(state),
            target: ident::string_literal(target),
            reads: format!("&[{}]", reads.join(", ")),
            view_param: if scope.uses_view { "view" } else { "_" }.to_owned(),
            vars_param: if scope.uses_vars {
                Some("vars".to_owned())
            } else {
                None
            },
            function,
            expr,
            call,
            doc: format!(
                "`when {}` in state `{state}` -> `{target}`",
                show(condition)
            ),
        });
    }

    rules
}

/// The `coolbot::TaskResult` pattern a `result` symbol (`check::model::RESULTS`)
/// stands for.
fn result_pattern(symbol: &str) -> Option<&'static str> {
    match symbol {
        "none" => Some("::coolbot::TaskResult::None"),
        "success" => Some("::coolbot::TaskResult::Success(_)"),
        "fail" => Some("::coolbot::TaskResult::Fail(_)"),
        _ => None,
    }
}

/// Where a typed node is missing (never in a checked model): an unknown type, which
/// reads as a missing value.
static UNKNOWN: Typed = Typed {
    ty: RTy::Unknown,
    node: Node::None,
    operands: Vec::new(),
};

/// Operand `index` of a typed node.
fn part(typed: &Typed, index: usize) -> &Typed {
    typed.operands.get(index).unwrap_or(&UNKNOWN)
}

/// The Rust path of enum `name` as a compound module sees it.
fn enum_path(name: &str) -> String {
    format!("{GEN_TYPES}{}", ident::camel(name))
}

/// The checker's type of an operand as the generated Rust can read it: a packet, a
/// list or anything else that is not a rule value becomes [`RTy::Unknown`] (so
/// comparisons with it are `false`); under `?` it stays `Optional(Other)`, read for
/// its presence only (the checker lets it compare with `none` only); `T??` reads as
/// `T?`.
fn readable(ty: &RTy) -> RTy {
    match ty {
        RTy::Optional(inner) if presence_only(inner) => {
            RTy::Optional(Box::new(RTy::Other(String::new())))
        }
        RTy::Optional(inner) => match readable(inner) {
            RTy::Unknown => RTy::Unknown,
            RTy::Optional(inner) => RTy::Optional(inner),
            inner => RTy::Optional(Box::new(inner)),
        },
        RTy::Other(_) | RTy::Symbol(_) | RTy::Unknown => RTy::Unknown,
        other => other.clone(),
    }
}

/// Whether an optional value of type `inner` is read for its presence only (a packet,
/// a list: nothing a rule compares but with `none`).
fn presence_only(inner: &RTy) -> bool {
    match inner {
        RTy::Other(_) => true,
        RTy::Optional(inner) => presence_only(inner),
        _ => false,
    }
}

/// Whether a type is unreadable: comparisons with it are `false`.
fn unreadable(ty: &RTy) -> bool {
    matches!(ty, RTy::Unknown | RTy::Other(_) | RTy::Symbol(_))
}

/// A rule operand: Rust text and its type.
#[derive(Clone, Debug)]
struct Operand {
    code: String,
    ty: RTy,
    /// `code` is an `Option` of the value (a read from the view that may be
    /// missing); `false` when `code` is the value itself.
    maybe: bool,
    /// An `f32` (or `f32?`) widened to `f64`: a float literal it is compared with is
    /// rounded to `f32` first.
    narrow: bool,
}

/// A compound's scope for rules and exports.
struct Scope<'a, 'b> {
    lowerer: &'b Lowerer<'a>,
    component: &'a Component,
    /// The rule's supervisor state (own `user_state` is known statically).
    state: String,
    reads: Vec<String>,
    uses_view: bool,
    uses_vars: bool,
}

/// A rule condition as written (for the generated documentation).
fn show(typed: &Typed) -> String {
    match &typed.node {
        Node::Int(n) => n.to_string(),
        Node::Float(x) => format!("{x:?}"),
        Node::Str(s) => format!("{s:?}"),
        Node::Bool(b) => b.to_string(),
        Node::Duration(ns) => match *ns {
            ns if ns > 0 && ns % 60_000_000_000 == 0 => format!("{}min", ns / 60_000_000_000),
            ns if ns > 0 && ns % 1_000_000_000 == 0 => format!("{}s", ns / 1_000_000_000),
            ns if ns > 0 && ns % 1_000_000 == 0 => format!("{}ms", ns / 1_000_000),
            ns if ns > 0 && ns % 1_000 == 0 => format!("{}us", ns / 1_000),
            ns => format!("{ns}ns"),
        },
        Node::Frequency(hz) => format!("{hz}Hz"),
        Node::Path(parts) => parts.join("."),
        Node::EnumValue { enum_name, variant } => format!("{enum_name}::{variant}"),
        Node::List => format!(
            "[{}]",
            typed
                .operands
                .iter()
                .map(show)
                .collect::<Vec<_>>()
                .join(", ")
        ),
        Node::Repeat(n) => format!("[{}; {n}]", show(part(typed, 0))),
        Node::None => "none".to_owned(),
        Node::Unary(UnaryOp::Not) => format!("!{}", show_operand(part(typed, 0))),
        Node::Unary(UnaryOp::Neg) => format!("-{}", show_operand(part(typed, 0))),
        Node::Binary(op @ (BinaryOp::And | BinaryOp::Or)) => {
            let side = |e: &Typed| {
                if needs_parens(*op, e) {
                    format!("({})", show(e))
                } else {
                    show(e)
                }
            };
            format!(
                "{} {} {}",
                side(part(typed, 0)),
                op.as_str(),
                side(part(typed, 1))
            )
        }
        Node::Binary(op) => format!(
            "{} {} {}",
            show_operand(part(typed, 0)),
            op.as_str(),
            show_operand(part(typed, 1))
        ),
    }
}

fn show_operand(typed: &Typed) -> String {
    match &typed.node {
        Node::Binary(..) => format!("({})", show(typed)),
        _ => show(typed),
    }
}

/// Whether `operand` of logical operator `op` needs parentheses: an `||` inside an
/// `&&` (comparisons and `&&` bind tighter than `||`, comparisons tighter than
/// `&&`).
fn needs_parens(op: BinaryOp, operand: &Typed) -> bool {
    op == BinaryOp::And && matches!(operand.node, Node::Binary(BinaryOp::Or))
}

impl Scope<'_, '_> {
    fn read(&mut self, name: String) {
        if !self.reads.contains(&name) {
            self.reads.push(name);
        }
    }

    /// A boolean Rust expression for the node `typed` (a missing or unreadable value
    /// makes the comparison that reads it `false`).
    fn boolean(&mut self, typed: &Typed) -> String {
        match &typed.node {
            Node::Binary(op @ (BinaryOp::And | BinaryOp::Or)) => {
                let l = self.logic_operand(*op, part(typed, 0));
                let r = self.logic_operand(*op, part(typed, 1));
                format!("{l} {} {r}", op.as_str())
            }
            Node::Binary(op) => self.comparison(*op, part(typed, 0), part(typed, 1)),
            Node::Unary(UnaryOp::Not) => {
                let inner = part(typed, 0);
                let text = self.boolean(inner);
                match &inner.node {
                    Node::Binary(..) => format!("!({text})"),
                    _ => format!("!{text}"),
                }
            }
            _ => {
                let operand = self.operand(typed);
                match (operand.ty, operand.maybe) {
                    (RTy::Bool, false) => operand.code,
                    (RTy::Bool, true) => format!("{}.unwrap_or(false)", operand.code),
                    _ => "false".to_owned(),
                }
            }
        }
    }

    /// An operand of `&&` or `||` (`op`): parenthesized only where Rust's precedence
    /// would read it otherwise (an `||` inside an `&&`).
    fn logic_operand(&mut self, op: BinaryOp, typed: &Typed) -> String {
        let text = self.boolean(typed);
        if needs_parens(op, typed) {
            format!("({text})")
        } else {
            text
        }
    }

    /// An operand of a comparison (or a bare boolean).
    fn operand(&mut self, typed: &Typed) -> Operand {
        let known = |code: String, ty: RTy| Operand {
            code,
            ty,
            maybe: false,
            narrow: false,
        };
        match &typed.node {
            Node::Int(n) => known(n.to_string(), RTy::Int),
            Node::Float(x) => known(format!("{x:?}"), RTy::Float),
            Node::Str(s) => known(ident::string_literal(s), RTy::Str),
            Node::Bool(b) => known(b.to_string(), RTy::Bool),
            Node::Duration(nanos) => known(
                duration_rust(u64::try_from(*nanos).unwrap_or(u64::MAX)),
                RTy::Duration,
            ),
            Node::None => known(String::new(), RTy::NoneLit),
            Node::EnumValue { enum_name, variant } => known(
                format!("{}::{}", enum_path(enum_name), ident::camel(variant)),
                RTy::Enum(enum_name.clone()),
            ),
            Node::Unary(UnaryOp::Neg) => match self.operand(part(typed, 0)) {
                Operand {
                    code,
                    ty: ty @ (RTy::Int | RTy::Float),
                    maybe: false,
                    narrow,
                } => Operand {
                    narrow,
                    ..known(format!("-{code}"), ty)
                },
                Operand {
                    code,
                    ty: ty @ (RTy::Int | RTy::Float),
                    maybe: true,
                    narrow,
                } => Operand {
                    code: format!("{code}.map(|value| -value)"),
                    ty,
                    maybe: true,
                    narrow,
                },
                _ => known(String::new(), RTy::Unknown),
            },
            Node::Unary(UnaryOp::Not) | Node::Binary(..) => {
                known(format!("({})", self.boolean(typed)), RTy::Bool)
            }
            Node::Path(segments) => match segments.as_slice() {
                [name] => self.own(name, &typed.ty),
                [instance, variable] => self.variable_operand(instance, variable, None, &typed.ty),
                _ => known(String::new(), RTy::Unknown),
            },
            Node::Frequency(_) | Node::List | Node::Repeat(_) => known(String::new(), RTy::Unknown),
        }
    }

    /// A bare name of type `ty`: an own variable, a mapped one, an own default
    /// variable, or a symbol (`ty` is then what the checker resolved it to).
    fn own(&mut self, name: &str, ty: &RTy) -> Operand {
        let unreadable = Operand {
            code: String::new(),
            ty: RTy::Unknown,
            maybe: false,
            narrow: false,
        };
        let component = self.component;
        let variable = component.variables.iter().find(|v| v.name == name);
        if let Some(v) = variable {
            return match (&v.written, &v.mapping) {
                (Some(declared), _) => {
                    if v.kind != VarKind::Local {
                        self.read(name.to_owned());
                    }
                    self.uses_vars = true;
                    let field = format!("vars.{}", ident::snake(name));
                    let has_default = v.value.is_some() || self.lowerer.ty_defaultable(declared);
                    let f64_field = holds_f64(declared);
                    let ty = readable(ty);
                    if !has_default {
                        // Held as `Option<T>` until set: read it as a missing value.
                        return own_value(&format!("{field}.as_ref()"), &ty, true, f64_field);
                    }
                    own_value(&field, &ty, false, f64_field)
                }
                (None, Some(path)) => match path.as_slice() {
                    // Read with `view.mapped(name)`, from the instance standing for
                    // `instance` now.
                    [instance, variable] => {
                        self.variable_operand(instance, variable, Some(name), ty)
                    }
                    _ => unreadable,
                },
                (None, None) => unreadable,
            };
        }
        match name {
            // Rules are evaluated while the compound runs.
            "state" => Operand {
                code: "::coolbot::State::Running".to_owned(),
                ty: RTy::State,
                maybe: false,
                narrow: false,
            },
            // A rule is evaluated in its own supervisor state.
            "user_state" => Operand {
                code: ident::string_literal(&self.state),
                ty: readable(ty),
                maybe: false,
                narrow: false,
            },
            // The compound's own default observables, copied into the view at each
            // supervision turn.
            "result" | "error" | "cpu_time" | "elapsed_time" | "quality" => {
                self.read(name.to_owned());
                self.uses_view = true;
                let (code, ty, maybe) = match name {
                    "result" => (
                        "::core::option::Option::Some(view.own_result())".to_owned(),
                        RTy::Result,
                        true,
                    ),
                    "error" => (
                        "view.own_error().unwrap_or(\"\")".to_owned(),
                        RTy::Str,
                        false,
                    ),
                    "quality" => ("view.own_quality()".to_owned(), readable(ty), false),
                    _ => (format!("view.own_{name}()"), RTy::Duration, false),
                };
                Operand {
                    code,
                    ty,
                    maybe,
                    narrow: false,
                }
            }
            _ => symbol(name, ty),
        }
    }

    /// `instance.variable` of type `ty`, read from the view; through mapped variable
    /// `mapped` when given and `variable` is one of the instance's own (a default
    /// variable, `state`..., is read on `instance` itself).
    fn variable_operand(
        &mut self,
        instance: &str,
        variable: &str,
        mapped: Option<&str>,
        ty: &RTy,
    ) -> Operand {
        let unreadable = Operand {
            code: String::new(),
            ty: RTy::Unknown,
            maybe: false,
            narrow: false,
        };
        let Some(target) = self
            .component
            .instances
            .iter()
            .find(|i| i.name == instance)
            .and_then(|i| self.lowerer.checked.component(&i.component))
        else {
            return unreadable;
        };
        let lit = ident::string_literal(instance);
        let maybe = |code: String, ty: RTy| Operand {
            code,
            ty,
            maybe: true,
            narrow: false,
        };
        let ty = readable(ty);
        if let Some(declared) = target.variables.iter().find(|v| v.name == variable) {
            let raw = match mapped {
                Some(name) => {
                    self.read(name.to_owned());
                    format!("view.mapped({})", ident::string_literal(name))
                }
                None => {
                    self.read(format!("{instance}.{variable}"));
                    format!("view.var({lit}, {})", ident::string_literal(variable))
                }
            };
            self.uses_view = true;
            let f64_field = declared.ty.as_ref().is_some_and(holds_f64);
            return match view_value(&raw, &ty) {
                Some(code) => Operand {
                    narrow: !f64_field && is_float(&ty),
                    ..maybe(code, ty)
                },
                None => unreadable,
            };
        }
        let code = match variable {
            "state" => format!("view.state({lit})"),
            "user_state" => format!("view.user_state({lit})"),
            "result" => format!("view.result({lit})"),
            // No error reads as the empty one: `error != "x"` holds then.
            "error" => {
                self.read(format!("{instance}.error"));
                self.uses_view = true;
                return Operand {
                    code: format!("view.error({lit}).unwrap_or(\"\")"),
                    ty: RTy::Str,
                    maybe: false,
                    narrow: false,
                };
            }
            "cpu_time" | "elapsed_time" | "quality" => {
                format!("view.monitor({lit}).map(|monitor| monitor.{variable})")
            }
            // No period (an aperiodic component) or bound reads as zero.
            "period" | "max_response" => {
                format!("view.monitor({lit}).map(|monitor| monitor.{variable}.unwrap_or_default())")
            }
            "priority" => {
                format!("view.monitor({lit}).map(|monitor| i128::from(monitor.priority))")
            }
            _ => return unreadable,
        };
        // (`cpu_time` and `elapsed_time` have no change event of their own: the
        // runtime counts them as changed every supervisor period.)
        self.read(format!("{instance}.{variable}"));
        self.uses_view = true;
        maybe(code, ty)
    }

    /// `left op right`, each with its typed node.
    fn comparison(&mut self, op: BinaryOp, left: &Typed, right: &Typed) -> String {
        let mut l = self.operand(left);
        let mut r = self.operand(right);
        if unreadable(&l.ty) || unreadable(&r.ty) {
            return "false".to_owned();
        }
        // An `f32` compared with a float literal: the literal rounded to `f32`, as the
        // variable holds it.
        if l.narrow
            && let Some(literal) = f32_literal(right)
        {
            r.code = literal;
        }
        if r.narrow
            && let Some(literal) = f32_literal(left)
        {
            l.code = literal;
        }
        // `user_state == on`: a missing user state (the automaton has not started)
        // differs from every state, for `!=` too.
        if matches!(l.ty, RTy::UserState(..)) && l.maybe != r.maybe {
            let (maybe, plain) = if l.maybe { (&l, &r) } else { (&r, &l) };
            return format!(
                "{} {} ::core::option::Option::Some({})",
                maybe.code,
                op.as_str(),
                plain.code
            );
        }
        // `x != v` is `!(x == v)`, also when a side is missing.
        if op == BinaryOp::Ne && (l.maybe || r.maybe) {
            return format!("!({})", self.compare(BinaryOp::Eq, l, r));
        }
        self.compare(op, l, r)
    }

    /// `l op r`, both operands resolved (`!=` over a missing value is handled by
    /// the caller).
    fn compare(&mut self, op: BinaryOp, mut l: Operand, mut r: Operand) -> String {
        let rust_op = op.as_str();
        // `x == none`, `x != none`.
        if r.ty == RTy::NoneLit {
            std::mem::swap(&mut l, &mut r);
        }
        if l.ty == RTy::NoneLit {
            let test = match op {
                BinaryOp::Ne => "is_some",
                _ => "is_none",
            };
            return match (&r.ty, r.maybe) {
                (RTy::Optional(_), false) => format!("{}.{test}()", r.code),
                (RTy::Optional(_), true) => {
                    format!("{}.is_some_and(|value| value.{test}())", r.code)
                }
                (RTy::Result, _) => {
                    let pattern = "::coolbot::TaskResult::None";
                    let negate = if op == BinaryOp::Ne { "!" } else { "" };
                    format!(
                        "{}.is_some_and(|result| {negate}::core::matches!(result, {pattern}))",
                        r.code
                    )
                }
                _ => "false".to_owned(),
            };
        }
        // `result == fail`: a pattern match.
        if l.ty == RTy::Result && r.ty == RTy::Result {
            return self.result_comparison(op, &l, &r);
        }
        let l_opt = matches!(l.ty, RTy::Optional(_));
        let r_opt = matches!(r.ty, RTy::Optional(_));
        // An ordering with an optional side: `none` satisfies none of them.
        if (l_opt || r_opt) && op != BinaryOp::Eq && op != BinaryOp::Ne {
            return ordering(rust_op, &l, &r);
        }
        // One optional side and one plain side: the plain side is wrapped in `Some`.
        let bind = |operand: &Operand, name: &str, wrap: bool| -> (String, String) {
            let owned_text = operand.ty == RTy::Optional(Box::new(RTy::Str));
            let value = if operand.maybe && owned_text {
                format!("{name}.as_deref()")
            } else if operand.maybe {
                name.to_owned()
            } else {
                operand.code.clone()
            };
            let value = if wrap {
                format!("::core::option::Option::Some({value})")
            } else {
                value
            };
            (operand.code.clone(), value)
        };
        let (l_source, l_value) = bind(&l, "left", r_opt && !l_opt);
        let (r_source, r_value) = bind(&r, "right", l_opt && !r_opt);
        let test = format!("{l_value} {rust_op} {r_value}");
        match (l.maybe, r.maybe) {
            (false, false) => test,
            (true, false) => format!("{l_source}.is_some_and(|left| {test})"),
            (false, true) => format!("{r_source}.is_some_and(|right| {test})"),
            (true, true) => {
                format!("{l_source}.zip({r_source}).is_some_and(|(left, right)| {test})")
            }
        }
    }

    /// A comparison of two results: by kind (`none`, `success`, `fail`).
    fn result_comparison(&mut self, op: BinaryOp, l: &Operand, r: &Operand) -> String {
        let negate = if op == BinaryOp::Ne { "!" } else { "" };
        // A symbol side is a pattern.
        let pattern = |operand: &Operand| -> Option<String> {
            (!operand.maybe).then(|| operand.code.clone())
        };
        match (pattern(l), pattern(r)) {
            (Some(p), None) | (None, Some(p)) => {
                let source = if l.maybe { &l.code } else { &r.code };
                format!("{source}.is_some_and(|result| {negate}::core::matches!(result, {p}))")
            }
            (None, None) => format!(
                "{}.zip({}).is_some_and(|(left, right)| ::core::mem::discriminant(left) {} ::core::mem::discriminant(right))",
                l.code,
                r.code,
                op.as_str()
            ),
            (Some(a), Some(b)) => (if (a == b) == (op != BinaryOp::Ne) {
                "true"
            } else {
                "false"
            })
            .to_owned(),
        }
    }
}

/// `l op r` for an ordering `op` with an optional side: every `Option` layer (a
/// missing read, an optional value) is opened with `is_some_and`, so a missing value
/// or `none` makes it `false`.
fn ordering(rust_op: &str, l: &Operand, r: &Operand) -> String {
    let layers = |operand: &Operand| {
        usize::from(matches!(operand.ty, RTy::Optional(_))) + usize::from(operand.maybe)
    };
    let value = |operand: &Operand, name: &str| {
        if layers(operand) == 0 {
            operand.code.clone()
        } else {
            name.to_owned()
        }
    };
    let open = |operand: &Operand, name: &str, inner: String| -> String {
        match layers(operand) {
            0 => inner,
            1 => format!("{}.is_some_and(|{name}| {inner})", operand.code),
            _ => format!(
                "{}.is_some_and(|{name}| {name}.is_some_and(|{name}| {inner}))",
                operand.code
            ),
        }
    };
    let test = format!("{} {rust_op} {}", value(l, "left"), value(r, "right"));
    open(l, "left", open(r, "right", test))
}

/// A float literal (`0.1`, `-0.1`) as an `f64` holding its `f32` rounding, or `None`
/// for anything else (and for a literal beyond `f32`'s range, which no `f32` equals).
fn f32_literal(typed: &Typed) -> Option<String> {
    let (negative, value) = match &typed.node {
        Node::Float(x) => (false, *x),
        Node::Unary(UnaryOp::Neg) => match &part(typed, 0).node {
            Node::Float(x) => (true, *x),
            _ => return None,
        },
        _ => return None,
    };
    // Rounding to `f32` is the point: the variable holds that rounding.
    let narrow = value as f32;
    if !narrow.is_finite() {
        return None;
    }
    let sign = if negative { "-" } else { "" };
    Some(format!("f64::from({sign}{narrow:?}_f32)"))
}

/// A symbol of the type the checker resolved it to (the other side's, without `?`).
fn symbol(name: &str, resolved: &RTy) -> Operand {
    let plain = |code: String, ty: RTy| Operand {
        code,
        ty,
        maybe: false,
        narrow: false,
    };
    match crate::checked::model::strip(resolved) {
        // The checker's names; `coolbot::State` variants are their camel case.
        RTy::State if DEFAULT_STATES.contains(&name) => plain(
            format!("::coolbot::State::{}", ident::camel(name)),
            RTy::State,
        ),
        ty @ RTy::UserState(_, states) if states.iter().any(|s| s == name) => {
            plain(ident::string_literal(name), ty.clone())
        }
        RTy::Result => match result_pattern(name).filter(|_| RESULTS.contains(&name)) {
            Some(pattern) => plain(pattern.to_owned(), RTy::Result),
            None => plain(String::new(), RTy::Unknown),
        },
        ty @ RTy::Quality(_, levels) => match levels.iter().position(|l| l == name) {
            Some(index) => plain(format!("{index}_usize"), ty.clone()),
            None => plain(String::new(), RTy::Unknown),
        },
        _ => plain(String::new(), RTy::Unknown),
    }
}

/// An own variable's field read as a rule operand (`maybe` when it is held as an
/// `Option` reference until set).
fn own_value(field: &str, ty: &RTy, maybe: bool, f64_field: bool) -> Operand {
    let unreadable = Operand {
        code: String::new(),
        ty: RTy::Unknown,
        maybe: false,
        narrow: false,
    };
    if maybe {
        // `Option<&T>`: only the types whose value can be copied out of a reference,
        // and an optional packet's presence.
        let code = match ty {
            RTy::Bool | RTy::Duration | RTy::Time | RTy::Enum(_) => format!("{field}.copied()"),
            RTy::Optional(inner) if matches!(inner.as_ref(), RTy::Other(_)) => {
                format!("{field}.map(|value| value.as_ref().map(|_| ()))")
            }
            _ => return unreadable,
        };
        return Operand {
            code,
            ty: ty.clone(),
            maybe: true,
            narrow: false,
        };
    }
    let code = match ty {
        RTy::Int => format!("i128::from({field})"),
        RTy::Float if f64_field => field.to_owned(),
        RTy::Float => format!("f64::from({field})"),
        RTy::Str => format!("{field}.as_str()"),
        RTy::Bool | RTy::Duration | RTy::Time | RTy::Enum(_) => field.to_owned(),
        RTy::Optional(inner) => match inner.as_ref() {
            RTy::Int => format!("{field}.map(i128::from)"),
            RTy::Float if f64_field => field.to_owned(),
            RTy::Float => format!("{field}.map(f64::from)"),
            RTy::Str => format!("{field}.as_deref()"),
            RTy::Bool | RTy::Duration | RTy::Time | RTy::Enum(_) => field.to_owned(),
            // Present or not (compared with `none` only).
            RTy::Other(_) => format!("{field}.as_ref().map(|_| ())"),
            _ => return unreadable,
        },
        _ => return unreadable,
    };
    let narrow = !f64_field && is_float(ty);
    Operand {
        code,
        ty: ty.clone(),
        maybe: false,
        narrow,
    }
}

/// Whether `ty` is a float or an optional float.
fn is_float(ty: &RTy) -> bool {
    match ty {
        RTy::Float => true,
        RTy::Optional(inner) => **inner == RTy::Float,
        _ => false,
    }
}

/// Reads an instance variable's `Option<&coolbot::Value>` (`raw`) as an `Option` of
/// the operand's Rust value.
fn view_value(raw: &str, ty: &RTy) -> Option<String> {
    let decode = |rust: &str| format!("{raw}.and_then(|value| <{rust}>::try_from(value).ok())");
    let serde = |rust: &str| {
        format!("{raw}.and_then(|value| super::__cool_from_value::<{rust}>(value).ok())")
    };
    Some(match ty {
        RTy::Bool => decode("bool"),
        RTy::Int => format!(
            "{raw}.and_then(|value| <i64>::try_from(value).map(i128::from).or_else(|_| <u64>::try_from(value).map(i128::from)).ok())"
        ),
        RTy::Float => decode("f64"),
        RTy::Str => format!(
            "{raw}.and_then(|value| match value {{ ::coolbot::Value::Str(text) => ::core::option::Option::Some(text.as_str()), _ => ::core::option::Option::None }})"
        ),
        RTy::Duration => decode("::std::time::Duration"),
        RTy::Time => decode("::coolbot::Time"),
        RTy::Enum(name) => serde(&enum_path(name)),
        RTy::Optional(inner) => match inner.as_ref() {
            RTy::Bool => serde("::core::option::Option<bool>"),
            RTy::Int => format!(
                "{}.map(|value| value.map(i128::from))",
                serde("::core::option::Option<i64>")
            ),
            RTy::Float => serde("::core::option::Option<f64>"),
            RTy::Duration => serde("::core::option::Option<::std::time::Duration>"),
            RTy::Time => serde("::core::option::Option<::coolbot::Time>"),
            RTy::Enum(name) => serde(&format!("::core::option::Option<{}>", enum_path(name))),
            // Owned: compared through `as_deref` (see `Scope::comparison`).
            RTy::Str => serde("::core::option::Option<::std::string::String>"),
            // Present or not (compared with `none` only): any value decodes.
            RTy::Other(_) => serde("::core::option::Option<::serde::de::IgnoredAny>"),
            _ => return None,
        },
        _ => return None,
    })
}

/// Whether a variable of type `ty` holds an `f64` or `f64?` (read as is; `f32`
/// widens).
fn holds_f64(ty: &Ty) -> bool {
    match ty {
        Ty::Float(prim) => *prim == Prim::F64,
        Ty::Optional(inner) => holds_f64(inner),
        _ => false,
    }
}
