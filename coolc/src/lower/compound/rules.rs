//! The `when` rules of a compound's supervisor compiled to Rust over
//! `coolbot::View`: each condition is read from the checker's typed tree
//! ([`Typed`], by the one rule typer in `check::rules`), node by node, into a
//! boolean expression that is `false` when a value it reads is missing, with the read
//! keys that make the runtime evaluate it.

use super::super::{GEN_TYPES, Lowerer, duration_code};
use crate::checked::model::{
    BinaryOp, Component, DEFAULT_STATES, Node, Prim, RESULTS, RTy, Ty, Typed, UnaryOp, VarKind,
};
use crate::ident;
use crate::ir::{self, Code};
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
        let reads = Code::slice(scope.reads.iter().map(|r| Code::string(r)).collect());
        // A rule reading the own variables locks them for its evaluation.
        let call = if scope.uses_vars {
            let vars = || Code::atom("vars");
            Code::Block(
                vec![(
                    "vars".to_owned(),
                    Code::call("::std::sync::Arc::clone", vec![vars().reference()]),
                )],
                Box::new(Code::move_closure(
                    "view: &::coolbot::View",
                    Code::call(
                        function.as_str(),
                        vec![
                            Code::atom("view"),
                            Code::call("__cool_lock", vec![vars().reference()]).reference(),
                        ],
                    ),
                )),
            )
        } else {
            Code::atom(function.as_str())
        };
        rules.push(ir::Rule {
            state: ident::string_literal(state),
            target: ident::string_literal(target),
            reads,
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
fn result_pattern(symbol: &str) -> Option<Code> {
    let any = |variant: &str| Code::call(variant, vec![Code::atom("_")]);
    match symbol {
        "none" => Some(Code::atom("::coolbot::TaskResult::None")),
        "success" => Some(any("::coolbot::TaskResult::Success")),
        "fail" => Some(any("::coolbot::TaskResult::Fail")),
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

/// A rule operand: its Rust expression and its type.
#[derive(Clone, Debug)]
struct Operand {
    code: Code,
    ty: RTy,
    /// `code` is an `Option` of the value (a read from the view that may be
    /// missing); `false` when `code` is the value itself.
    maybe: bool,
    /// An `f32` (or `f32?`) widened to `f64`: a float literal it is compared with is
    /// rounded to `f32` first.
    narrow: bool,
}

impl Operand {
    /// The value `code` of type `ty`, present.
    fn known(code: Code, ty: RTy) -> Operand {
        Operand {
            code,
            ty,
            maybe: false,
            narrow: false,
        }
    }

    /// `code`, an `Option` of a value of type `ty` read from the view.
    fn maybe(code: Code, ty: RTy) -> Operand {
        Operand {
            maybe: true,
            ..Operand::known(code, ty)
        }
    }

    /// What generated code cannot read (a comparison with it is `false`; its code
    /// is never printed).
    fn unreadable() -> Operand {
        Operand::known(Code::atom(""), RTy::Unknown)
    }
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
    fn boolean(&mut self, typed: &Typed) -> Code {
        match &typed.node {
            Node::Binary(op @ (BinaryOp::And | BinaryOp::Or)) => {
                let l = self.logic_operand(*op, part(typed, 0));
                let r = self.logic_operand(*op, part(typed, 1));
                Code::binary(l, op.as_str(), r)
            }
            Node::Binary(op) => self.comparison(*op, part(typed, 0), part(typed, 1)),
            Node::Unary(UnaryOp::Not) => {
                let inner = part(typed, 0);
                let code = self.boolean(inner);
                match &inner.node {
                    Node::Binary(..) => Code::prefix("!", code.paren()),
                    _ => Code::prefix("!", code),
                }
            }
            _ => {
                let operand = self.operand(typed);
                match (operand.ty, operand.maybe) {
                    (RTy::Bool, false) => operand.code,
                    (RTy::Bool, true) => {
                        operand.code.method("unwrap_or", vec![Code::atom("false")])
                    }
                    _ => Code::atom("false"),
                }
            }
        }
    }

    /// An operand of `&&` or `||` (`op`): parenthesized only where Rust's precedence
    /// would read it otherwise (an `||` inside an `&&`).
    fn logic_operand(&mut self, op: BinaryOp, typed: &Typed) -> Code {
        let code = self.boolean(typed);
        if needs_parens(op, typed) {
            code.paren()
        } else {
            code
        }
    }

    /// An operand of a comparison (or a bare boolean).
    fn operand(&mut self, typed: &Typed) -> Operand {
        let known = Operand::known;
        match &typed.node {
            Node::Int(n) => known(Code::atom(n.to_string()), RTy::Int),
            Node::Float(x) => known(Code::atom(format!("{x:?}")), RTy::Float),
            Node::Str(s) => known(Code::string(s), RTy::Str),
            Node::Bool(b) => known(Code::atom(b.to_string()), RTy::Bool),
            Node::Duration(nanos) => known(
                duration_code(u64::try_from(*nanos).unwrap_or(u64::MAX)),
                RTy::Duration,
            ),
            Node::None => known(Code::atom(""), RTy::NoneLit),
            Node::EnumValue { enum_name, variant } => known(
                Code::atom(format!(
                    "{}::{}",
                    enum_path(enum_name),
                    ident::camel(variant)
                )),
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
                    ..known(Code::prefix("-", code), ty)
                },
                Operand {
                    code,
                    ty: ty @ (RTy::Int | RTy::Float),
                    maybe: true,
                    narrow,
                } => Operand {
                    narrow,
                    ..Operand::maybe(
                        code.method(
                            "map",
                            vec![Code::closure(
                                "value",
                                Code::prefix("-", Code::atom("value")),
                            )],
                        ),
                        ty,
                    )
                },
                _ => Operand::unreadable(),
            },
            Node::Unary(UnaryOp::Not) | Node::Binary(..) => {
                known(self.boolean(typed).paren(), RTy::Bool)
            }
            Node::Path(segments) => match segments.as_slice() {
                [name] => self.own(name, &typed.ty),
                [instance, variable] => self.variable_operand(instance, variable, None, &typed.ty),
                _ => Operand::unreadable(),
            },
            Node::Frequency(_) | Node::List | Node::Repeat(_) => Operand::unreadable(),
        }
    }

    /// A bare name of type `ty`: an own variable, a mapped one, an own default
    /// variable, or a symbol (`ty` is then what the checker resolved it to).
    fn own(&mut self, name: &str, ty: &RTy) -> Operand {
        let component = self.component;
        let variable = component.variables.iter().find(|v| v.name == name);
        if let Some(v) = variable {
            return match (&v.written, &v.mapping) {
                (Some(declared), _) => {
                    if v.kind != VarKind::Local {
                        self.read(name.to_owned());
                    }
                    self.uses_vars = true;
                    let field = Code::atom("vars").field(ident::snake(name));
                    let has_default = v.value.is_some() || self.lowerer.ty_defaultable(declared);
                    let f64_field = holds_f64(declared);
                    let ty = readable(ty);
                    if !has_default {
                        // Held as `Option<T>` until set: read it as a missing value.
                        return own_value(field.method("as_ref", Vec::new()), &ty, true, f64_field);
                    }
                    own_value(field, &ty, false, f64_field)
                }
                (None, Some(path)) => match path.as_slice() {
                    // Read with `view.mapped(name)`, from the instance standing for
                    // `instance` now.
                    [instance, variable] => {
                        self.variable_operand(instance, variable, Some(name), ty)
                    }
                    _ => Operand::unreadable(),
                },
                (None, None) => Operand::unreadable(),
            };
        }
        let view = |method: &str| Code::atom("view").method(method, Vec::new());
        match name {
            // Rules are evaluated while the compound runs.
            "state" => Operand::known(Code::atom("::coolbot::State::Running"), RTy::State),
            // A rule is evaluated in its own supervisor state.
            "user_state" => Operand::known(Code::string(&self.state), readable(ty)),
            // The compound's own default observables, copied into the view at each
            // supervision turn.
            "result" | "error" | "cpu_time" | "elapsed_time" | "quality" => {
                self.read(name.to_owned());
                self.uses_view = true;
                match name {
                    "result" => Operand::maybe(Code::core_some(view("own_result")), RTy::Result),
                    "error" => Operand::known(
                        view("own_error").method("unwrap_or", vec![Code::string("")]),
                        RTy::Str,
                    ),
                    "quality" => Operand::known(view("own_quality"), readable(ty)),
                    "cpu_time" => Operand::known(view("own_cpu_time"), RTy::Duration),
                    _ => Operand::known(view("own_elapsed_time"), RTy::Duration),
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
        let Some(target) = self
            .component
            .instances
            .iter()
            .find(|i| i.name == instance)
            .and_then(|i| self.lowerer.checked.component(&i.component))
        else {
            return Operand::unreadable();
        };
        let view = |method: &str, args: Vec<Code>| Code::atom("view").method(method, args);
        let lit = Code::string(instance);
        let ty = readable(ty);
        if let Some(declared) = target.variables.iter().find(|v| v.name == variable) {
            let raw = match mapped {
                Some(name) => {
                    self.read(name.to_owned());
                    view("mapped", vec![Code::string(name)])
                }
                None => {
                    self.read(format!("{instance}.{variable}"));
                    view("var", vec![lit, Code::string(variable)])
                }
            };
            self.uses_view = true;
            let f64_field = declared.ty.as_ref().is_some_and(holds_f64);
            return match view_value(raw, &ty) {
                Some(code) => Operand {
                    narrow: !f64_field && is_float(&ty),
                    ..Operand::maybe(code, ty)
                },
                None => Operand::unreadable(),
            };
        }
        let monitor = |read: Code| {
            view("monitor", vec![lit.clone()]).method("map", vec![Code::closure("monitor", read)])
        };
        let field = |name: &str| Code::atom("monitor").field(name);
        let code = match variable {
            "state" => view("state", vec![lit.clone()]),
            "user_state" => view("user_state", vec![lit.clone()]),
            "result" => view("result", vec![lit.clone()]),
            // No error reads as the empty one: `error != "x"` holds then.
            "error" => {
                self.read(format!("{instance}.error"));
                self.uses_view = true;
                return Operand::known(
                    view("error", vec![lit]).method("unwrap_or", vec![Code::string("")]),
                    RTy::Str,
                );
            }
            "cpu_time" | "elapsed_time" | "quality" => monitor(field(variable)),
            // No period (an aperiodic component) or bound reads as zero.
            "period" | "max_response" => {
                monitor(field(variable).method("unwrap_or_default", Vec::new()))
            }
            "priority" => monitor(Code::call("i128::from", vec![field("priority")])),
            _ => return Operand::unreadable(),
        };
        // (`cpu_time` and `elapsed_time` have no change event of their own: the
        // runtime counts them as changed every supervisor period.)
        self.read(format!("{instance}.{variable}"));
        self.uses_view = true;
        Operand::maybe(code, ty)
    }

    /// `left op right`, each with its typed node.
    fn comparison(&mut self, op: BinaryOp, left: &Typed, right: &Typed) -> Code {
        let mut l = self.operand(left);
        let mut r = self.operand(right);
        if unreadable(&l.ty) || unreadable(&r.ty) {
            return Code::atom("false");
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
            let (maybe, plain) = if l.maybe { (l, r) } else { (r, l) };
            return Code::binary(maybe.code, op.as_str(), Code::core_some(plain.code));
        }
        // `x != v` is `!(x == v)`, also when a side is missing.
        if op == BinaryOp::Ne && (l.maybe || r.maybe) {
            return Code::prefix("!", self.compare(BinaryOp::Eq, l, r).paren());
        }
        self.compare(op, l, r)
    }

    /// `l op r`, both operands resolved (`!=` over a missing value is handled by
    /// the caller).
    fn compare(&mut self, op: BinaryOp, mut l: Operand, mut r: Operand) -> Code {
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
                (RTy::Optional(_), false) => r.code.method(test, Vec::new()),
                (RTy::Optional(_), true) => r.code.method(
                    "is_some_and",
                    vec![Code::closure(
                        "value",
                        Code::atom("value").method(test, Vec::new()),
                    )],
                ),
                (RTy::Result, _) => r.code.method(
                    "is_some_and",
                    vec![Code::closure(
                        "result",
                        matches_result(op, Code::atom("::coolbot::TaskResult::None")),
                    )],
                ),
                _ => Code::atom("false"),
            };
        }
        // `result == fail`: a pattern match.
        if l.ty == RTy::Result && r.ty == RTy::Result {
            return result_comparison(op, l, r);
        }
        let l_opt = matches!(l.ty, RTy::Optional(_));
        let r_opt = matches!(r.ty, RTy::Optional(_));
        // An ordering with an optional side: `none` satisfies none of them.
        if (l_opt || r_opt) && op != BinaryOp::Eq && op != BinaryOp::Ne {
            return ordering(rust_op, l, r);
        }
        // One optional side and one plain side: the plain side is wrapped in `Some`.
        let bind = |operand: &Operand, name: &str, wrap: bool| -> Code {
            let owned_text = operand.ty == RTy::Optional(Box::new(RTy::Str));
            let value = if operand.maybe && owned_text {
                Code::atom(name).method("as_deref", Vec::new())
            } else if operand.maybe {
                Code::atom(name)
            } else {
                operand.code.clone()
            };
            if wrap { Code::core_some(value) } else { value }
        };
        let l_value = bind(&l, "left", r_opt && !l_opt);
        let r_value = bind(&r, "right", l_opt && !r_opt);
        let test = Code::binary(l_value, rust_op, r_value);
        let is_some_and = |source: Code, params: &str| {
            source.method("is_some_and", vec![Code::closure(params, test.clone())])
        };
        match (l.maybe, r.maybe) {
            (false, false) => test,
            (true, false) => is_some_and(l.code, "left"),
            (false, true) => is_some_and(r.code, "right"),
            (true, true) => is_some_and(l.code.method("zip", vec![r.code]), "(left, right)"),
        }
    }
}

/// `::core::matches!(result, pattern)`, negated for `!=` (`op`).
fn matches_result(op: BinaryOp, pattern: Code) -> Code {
    let test = Code::call("::core::matches!", vec![Code::atom("result"), pattern]);
    if op == BinaryOp::Ne {
        Code::prefix("!", test)
    } else {
        test
    }
}

/// A comparison of two results: by kind (`none`, `success`, `fail`).
fn result_comparison(op: BinaryOp, l: Operand, r: Operand) -> Code {
    // A symbol side is a pattern.
    match (l.maybe, r.maybe) {
        (true, false) | (false, true) => {
            let (source, pattern) = if l.maybe {
                (l.code, r.code)
            } else {
                (r.code, l.code)
            };
            source.method(
                "is_some_and",
                vec![Code::closure("result", matches_result(op, pattern))],
            )
        }
        (true, true) => {
            let discriminant =
                |name: &str| Code::call("::core::mem::discriminant", vec![Code::atom(name)]);
            l.code.method("zip", vec![r.code]).method(
                "is_some_and",
                vec![Code::closure(
                    "(left, right)",
                    Code::binary(discriminant("left"), op.as_str(), discriminant("right")),
                )],
            )
        }
        (false, false) => Code::atom(if (l.code == r.code) == (op != BinaryOp::Ne) {
            "true"
        } else {
            "false"
        }),
    }
}

/// `l op r` for an ordering `op` with an optional side: every `Option` layer (a
/// missing read, an optional value) is opened with `is_some_and`, so a missing value
/// or `none` makes it `false`.
fn ordering(rust_op: &'static str, l: Operand, r: Operand) -> Code {
    let layers = |operand: &Operand| {
        usize::from(matches!(operand.ty, RTy::Optional(_))) + usize::from(operand.maybe)
    };
    let value = |operand: &Operand, name: &str| {
        if layers(operand) == 0 {
            operand.code.clone()
        } else {
            Code::atom(name)
        }
    };
    let is_some_and = |source: Code, name: &str, inner: Code| {
        source.method("is_some_and", vec![Code::closure(name, inner)])
    };
    let open = |operand: &Operand, name: &str, inner: Code| -> Code {
        match layers(operand) {
            0 => inner,
            1 => is_some_and(operand.code.clone(), name, inner),
            _ => is_some_and(
                operand.code.clone(),
                name,
                is_some_and(Code::atom(name), name, inner),
            ),
        }
    };
    let test = Code::binary(value(&l, "left"), rust_op, value(&r, "right"));
    open(&l, "left", open(&r, "right", test))
}

/// A float literal (`0.1`, `-0.1`) as an `f64` holding its `f32` rounding, or `None`
/// for anything else (and for a literal beyond `f32`'s range, which no `f32` equals).
fn f32_literal(typed: &Typed) -> Option<Code> {
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
    Some(Code::call(
        "f64::from",
        vec![Code::atom(format!("{sign}{narrow:?}_f32"))],
    ))
}

/// A symbol of the type the checker resolved it to (the other side's, without `?`).
fn symbol(name: &str, resolved: &RTy) -> Operand {
    let plain = Operand::known;
    match crate::checked::model::strip(resolved) {
        // The checker's names; `coolbot::State` variants are their camel case.
        RTy::State if DEFAULT_STATES.contains(&name) => plain(
            Code::atom(format!("::coolbot::State::{}", ident::camel(name))),
            RTy::State,
        ),
        ty @ RTy::UserState(_, states) if states.iter().any(|s| s == name) => {
            plain(Code::string(name), ty.clone())
        }
        RTy::Result => match result_pattern(name).filter(|_| RESULTS.contains(&name)) {
            Some(pattern) => plain(pattern, RTy::Result),
            None => Operand::unreadable(),
        },
        ty @ RTy::Quality(_, levels) => match levels.iter().position(|l| l == name) {
            Some(index) => plain(Code::atom(format!("{index}_usize")), ty.clone()),
            None => Operand::unreadable(),
        },
        _ => Operand::unreadable(),
    }
}

/// An own variable's field read as a rule operand (`maybe` when it is held as an
/// `Option` reference until set).
fn own_value(field: Code, ty: &RTy, maybe: bool, f64_field: bool) -> Operand {
    // `value.as_ref().map(|_| ())`: whether an optional packet is present.
    let presence = |value: Code| {
        value
            .method("as_ref", Vec::new())
            .method("map", vec![Code::closure("_", Code::atom("()"))])
    };
    if maybe {
        // `Option<&T>`: only the types whose value can be copied out of a reference,
        // and an optional packet's presence.
        let code = match ty {
            RTy::Bool | RTy::Duration | RTy::Time | RTy::Enum(_) => {
                field.method("copied", Vec::new())
            }
            RTy::Optional(inner) if matches!(inner.as_ref(), RTy::Other(_)) => field.method(
                "map",
                vec![Code::closure("value", presence(Code::atom("value")))],
            ),
            _ => return Operand::unreadable(),
        };
        return Operand::maybe(code, ty.clone());
    }
    let code = match ty {
        RTy::Int => Code::call("i128::from", vec![field]),
        RTy::Float if f64_field => field,
        RTy::Float => Code::call("f64::from", vec![field]),
        RTy::Str => field.method("as_str", Vec::new()),
        RTy::Bool | RTy::Duration | RTy::Time | RTy::Enum(_) => field,
        RTy::Optional(inner) => match inner.as_ref() {
            RTy::Int => field.method("map", vec![Code::atom("i128::from")]),
            RTy::Float if f64_field => field,
            RTy::Float => field.method("map", vec![Code::atom("f64::from")]),
            RTy::Str => field.method("as_deref", Vec::new()),
            RTy::Bool | RTy::Duration | RTy::Time | RTy::Enum(_) => field,
            // Present or not (compared with `none` only).
            RTy::Other(_) => presence(field),
            _ => return Operand::unreadable(),
        },
        _ => return Operand::unreadable(),
    };
    Operand {
        narrow: !f64_field && is_float(ty),
        ..Operand::known(code, ty.clone())
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
fn view_value(raw: Code, ty: &RTy) -> Option<Code> {
    let value = || Code::atom("value");
    // `raw.and_then(|value| body)`.
    let and_then = |body: Code| {
        raw.clone()
            .method("and_then", vec![Code::closure("value", body)])
    };
    let try_from = |rust: &str| Code::call(format!("<{rust}>::try_from"), vec![value()]);
    let decode = |rust: &str| and_then(try_from(rust).method("ok", Vec::new()));
    let serde = |rust: &str| {
        and_then(
            Code::call(format!("super::__cool_from_value::<{rust}>"), vec![value()])
                .method("ok", Vec::new()),
        )
    };
    let widen = |rust: &str| try_from(rust).method("map", vec![Code::atom("i128::from")]);
    Some(match ty {
        RTy::Bool => decode("bool"),
        RTy::Int => and_then(
            widen("i64")
                .method("or_else", vec![Code::closure("_", widen("u64"))])
                .method("ok", Vec::new()),
        ),
        RTy::Float => decode("f64"),
        RTy::Str => and_then(Code::Match(
            Box::new(value()),
            vec![
                (
                    "::coolbot::Value::Str(text)".to_owned(),
                    Code::core_some(Code::atom("text").method("as_str", Vec::new())),
                ),
                ("_".to_owned(), Code::core_none()),
            ],
        )),
        RTy::Duration => decode("::std::time::Duration"),
        RTy::Time => decode("::coolbot::Time"),
        RTy::Enum(name) => serde(&enum_path(name)),
        RTy::Optional(inner) => match inner.as_ref() {
            RTy::Bool => serde("::core::option::Option<bool>"),
            RTy::Int => serde("::core::option::Option<i64>").method(
                "map",
                vec![Code::closure(
                    "value",
                    value().method("map", vec![Code::atom("i128::from")]),
                )],
            ),
            RTy::Float => serde("::core::option::Option<f64>"),
            RTy::Duration => serde("::core::option::Option<::std::time::Duration>"),
            RTy::Time => serde("::core::option::Option<::coolbot::Time>"),
            RTy::Enum(name) => serde(&format!("::core::option::Option<{}>", enum_path(name))),
            // Owned: compared through `as_deref` (see `Scope::compare`).
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
