//! Typed supervisor rules: `when` conditions are boolean expressions over the
//! compound's own variables and its instances' observable variables, including the
//! default ones. `state` compares with the default automaton's states, `user_state`
//! with the instance's user states, `result` with `none`/`success`/`fail`, `quality`
//! with the instance's quality levels; `error` is a `String`, `cpu_time` and
//! `elapsed_time` are durations. The compound's own default observables read the same
//! way (its `quality` with its own levels). An instance's observable and controllable
//! variables are readable, and its default controllable timing variables (`period`
//! and `max_response`, durations, zero when it has none; `priority`, an integer);
//! its `local` variables and `new_state` and `configuration` are not published where
//! rules are evaluated (`coolc::check::unreadable_in_rule`).
//! A bare name that is not a variable is a symbol, resolved against the other side of
//! the comparison. An instance's `quality` levels are those of its `timing` override
//! when it declares some.

use super::Checker;
use super::model::{
    Component, DEFAULT_CONTROLLABLES, DEFAULT_OBSERVABLES, DEFAULT_STATES, Model, Node, RESULTS,
    RTy, Ty, Typed, strip,
};
use crate::ast::{self, BinaryOp};
use crate::diagnostics::Code;

fn from_ty(ty: &Ty) -> RTy {
    match ty {
        Ty::Bool => RTy::Bool,
        Ty::Int(_) => RTy::Int,
        Ty::Float(_) => RTy::Float,
        Ty::Str => RTy::Str,
        Ty::Duration => RTy::Duration,
        Ty::Time => RTy::Time,
        Ty::Enum(name) => RTy::Enum(name.clone()),
        Ty::Optional(inner) => RTy::Optional(Box::new(from_ty(inner))),
        Ty::Unknown => RTy::Unknown,
        other => RTy::Other(format!("`{other}`")),
    }
}

impl Typed {
    /// The node `expr` with type `ty` and its typed operands.
    fn node(expr: &ast::Expr, ty: RTy, operands: Vec<Typed>) -> Typed {
        Typed {
            ty,
            node: Node::of(&expr.kind),
            operands,
        }
    }
}

/// Checks one `when` condition of `component`'s supervisor and returns it typed.
pub(super) fn rule(
    checker: &mut Checker<'_, '_>,
    component: &ast::Component,
    condition: &ast::Expr,
) -> Typed {
    let own = checker.model.resolved(&component.name.name);
    let mut typer = Typer {
        checker,
        component,
        own: &own,
    };
    let typed = typer.infer(condition);
    match &typed.ty {
        RTy::Bool | RTy::Unknown => {}
        RTy::Symbol(name) => typer.unknown_variable(name),
        other => {
            let help = typer
                .enum_variants(other)
                .unwrap_or_else(|| "compare it: `x == value`, `x > 3`".to_owned());
            let diagnostic = typer
                .checker
                .error(
                    Code::RuleType,
                    condition.span,
                    format!("a rule must be a boolean expression, but this is {other}"),
                )
                .with_label("not a bool")
                .with_help(help);
            typer.checker.push(diagnostic);
        }
    }
    typed
}

struct Typer<'c, 'a, 'd> {
    checker: &'c mut Checker<'a, 'd>,
    component: &'c ast::Component,
    own: &'c Component,
}

impl Typer<'_, '_, '_> {
    fn infer(&mut self, expr: &ast::Expr) -> Typed {
        use ast::ExprKind as E;
        let ty = match &expr.kind {
            E::Int(_) => RTy::Int,
            E::Float(_) => RTy::Float,
            E::Str(_) => RTy::Str,
            E::Bool(_) => RTy::Bool,
            E::Duration(_) => RTy::Duration,
            E::Frequency(_) => RTy::Other("a frequency".into()),
            E::None => RTy::NoneLit,
            E::List(_) | E::Repeat(..) => RTy::Other("a list".into()),
            E::EnumValue { enum_name, variant } => self.enum_value(enum_name, variant),
            E::Path(segments) => self.path(expr, segments),
            E::Unary(op, operand) => {
                let operand = self.operand(operand);
                let ty = match (op, &operand.ty) {
                    (_, RTy::Unknown) => RTy::Unknown,
                    (ast::UnaryOp::Not, RTy::Bool) => RTy::Bool,
                    (ast::UnaryOp::Neg, RTy::Int | RTy::Float | RTy::Duration) => {
                        operand.ty.clone()
                    }
                    (ast::UnaryOp::Not, ty) => {
                        self.mismatch(expr, format!("`!` needs a bool, found {ty}"))
                    }
                    (ast::UnaryOp::Neg, ty) => {
                        self.mismatch(expr, format!("`-` needs a number, found {ty}"))
                    }
                };
                return Typed::node(expr, ty, vec![operand]);
            }
            E::Binary(op @ (BinaryOp::And | BinaryOp::Or), left, right) => {
                let mut operands = Vec::with_capacity(2);
                for side in [left, right] {
                    let typed = self.operand(side);
                    if !matches!(typed.ty, RTy::Bool | RTy::Unknown) {
                        self.mismatch(
                            side,
                            format!("`{}` needs bool operands, found {}", op.as_str(), typed.ty),
                        );
                    }
                    operands.push(typed);
                }
                return Typed::node(expr, RTy::Bool, operands);
            }
            E::Binary(op, left, right) => return self.comparison(expr, *op, left, right),
        };
        // A leaf (a list's items stay untyped: no rule reads a list).
        Typed {
            ty,
            ..Typed::untyped(expr)
        }
    }

    /// Infers an operand; a bare symbol on its own is an unknown variable.
    fn operand(&mut self, expr: &ast::Expr) -> Typed {
        let mut typed = self.infer(expr);
        if let RTy::Symbol(name) = &typed.ty {
            let name = name.clone();
            self.unknown_variable(&name);
            typed.ty = RTy::Unknown;
        }
        typed
    }

    fn mismatch(&mut self, expr: &ast::Expr, message: String) -> RTy {
        let diagnostic = self
            .checker
            .error(Code::RuleType, expr.span, message)
            .with_label("ill-typed");
        self.checker.push(diagnostic);
        RTy::Unknown
    }

    fn enum_value(&mut self, enum_name: &ast::Ident, variant: &ast::Ident) -> RTy {
        let Some(def) = self.checker.model.enum_def(&enum_name.name) else {
            let candidates: Vec<&str> = self
                .checker
                .model
                .symbols
                .defs
                .iter()
                .filter(|(_, def)| def.kind == crate::resolve::DefKind::Enum)
                .map(|(name, _)| name.as_str())
                .collect();
            self.checker
                .unknown(Code::UnknownType, enum_name, "enum", "", candidates);
            return RTy::Unknown;
        };
        if !def.variants.iter().any(|v| v.name.name == variant.name) {
            let variants: Vec<&str> = def.variants.iter().map(|v| v.name.name.as_str()).collect();
            self.checker.unknown(
                Code::UnknownVariant,
                variant,
                "variant",
                &format!(" in enum `{}`", enum_name.name),
                variants,
            );
        }
        RTy::Enum(enum_name.name.clone())
    }

    /// `name` (own variable or own default variable) or `instance.variable`.
    fn path(&mut self, expr: &ast::Expr, segments: &[ast::Ident]) -> RTy {
        match segments {
            [name] => {
                if let Some(var) = self.own.variable(&name.name) {
                    return from_ty(&var.resolved_ty());
                }
                default_variable(&name.name, &self.component.name.name, self.own)
                    .unwrap_or_else(|| RTy::Symbol(name.clone()))
            }
            [instance, variable] => self.instance_variable(instance, variable),
            _ => self.mismatch(
                expr,
                "a rule names `variable` or `instance.variable`".into(),
            ),
        }
    }

    fn instance_variable(&mut self, instance_name: &ast::Ident, variable: &ast::Ident) -> RTy {
        let Some(instance) = Model::instance(self.component, &instance_name.name) else {
            let instances: Vec<&str> = self
                .component
                .members
                .iter()
                .filter_map(|m| match m {
                    ast::Member::Instance(i) => Some(i.name.name.as_str()),
                    _ => None,
                })
                .collect();
            self.checker.unknown(
                Code::UnknownInstance,
                instance_name,
                "instance",
                "",
                instances,
            );
            return RTy::Unknown;
        };
        if self
            .checker
            .model
            .component(&instance.component.name)
            .is_none()
        {
            return RTy::Unknown;
        }
        let interface = self.checker.model.resolved(&instance.component.name);
        match interface.variable(&variable.name) {
            Some(var) if var.kind != ast::VarKind::Local => return from_ty(&var.resolved_ty()),
            Some(_) => {
                let diagnostic = self
                    .checker
                    .error(
                        Code::UnreadableInRule,
                        variable.span,
                        format!(
                            "`{}` is a local variable of `{}`: it is not published, so a rule cannot read it",
                            variable.name, instance.component.name
                        ),
                    )
                    .with_label("local")
                    .with_help(
                        "rules read observable and controllable variables: declare it `observable`",
                    );
                self.checker.push(diagnostic);
                return RTy::Unknown;
            }
            None => {}
        }
        if let Some(ty) = timing_variable(&variable.name) {
            return ty;
        }
        if DEFAULT_CONTROLLABLES.contains(&variable.name.as_str()) {
            let diagnostic = self
                .checker
                .error(
                    Code::UnreadableInRule,
                    variable.span,
                    format!(
                        "`{}` is a default controllable variable that is not published: a rule cannot read it",
                        variable.name
                    ),
                )
                .with_label("not readable in a rule")
                .with_help(format!(
                    "rules read the default observable variables ({}), an instance's `period`, \
                     `max_response` and `priority`, and declared variables",
                    DEFAULT_OBSERVABLES
                        .iter()
                        .map(|name| format!("`{name}`"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ));
            self.checker.push(diagnostic);
            return RTy::Unknown;
        }
        if let Some(ty) = default_variable(&variable.name, &instance.component.name, &interface) {
            // An instance's `timing` override may declare its own quality levels.
            return match (ty, override_levels(instance)) {
                (RTy::Quality(component, _), Some(levels)) => RTy::Quality(component, levels),
                (ty, _) => ty,
            };
        }
        let candidates: Vec<&str> = interface
            .variables_by_name()
            .into_iter()
            .filter(|(_, v)| v.kind != ast::VarKind::Local)
            .map(|(n, _)| n)
            .chain(DEFAULT_OBSERVABLES.iter().copied())
            .collect();
        self.checker.unknown(
            Code::UnknownVariable,
            variable,
            "variable",
            &format!(
                " in `{}` (component `{}`)",
                instance_name.name, instance.component.name
            ),
            candidates,
        );
        RTy::Unknown
    }

    fn unknown_variable(&mut self, name: &ast::Ident) {
        let mut candidates: Vec<String> = self
            .own
            .variables_by_name()
            .keys()
            .map(|name| (*name).to_owned())
            .collect();
        candidates.extend(DEFAULT_OBSERVABLES.iter().map(|s| s.to_string()));
        let context = format!(" in `{}`", self.component.name.name);
        self.checker.unknown(
            Code::UnknownVariable,
            name,
            "variable",
            &context,
            candidates.iter().map(String::as_str),
        );
    }

    fn comparison(
        &mut self,
        expr: &ast::Expr,
        op: BinaryOp,
        left: &ast::Expr,
        right: &ast::Expr,
    ) -> Typed {
        let mut left_typed = self.infer(left);
        let mut right_typed = self.infer(right);
        // A bare name takes its meaning from the other side; the node records what
        // it resolved to, without the other side's `?`.
        match (&left_typed.ty, &right_typed.ty) {
            (RTy::Symbol(a), RTy::Symbol(_)) => {
                let a = a.clone();
                self.unknown_variable(&a);
                left_typed.ty = RTy::Unknown;
                right_typed.ty = RTy::Unknown;
            }
            (RTy::Symbol(symbol), other) => {
                let (symbol, other) = (symbol.clone(), other.clone());
                left_typed.ty = self.symbol(&symbol, &other);
            }
            (other, RTy::Symbol(symbol)) => {
                let (symbol, other) = (symbol.clone(), other.clone());
                right_typed.ty = self.symbol(&symbol, &other);
            }
            _ => {}
        }
        let typed =
            |left_typed, right_typed| Typed::node(expr, RTy::Bool, vec![left_typed, right_typed]);
        let (left_ty, right_ty) = (&left_typed.ty, &right_typed.ty);
        if matches!(left_ty, RTy::Unknown) || matches!(right_ty, RTy::Unknown) {
            return typed(left_typed, right_typed);
        }
        if !compatible(left_ty, right_ty) {
            let help = match (left_ty, right_ty) {
                (RTy::Float, RTy::Int) | (RTy::Int, RTy::Float) => {
                    let (int, float) = if matches!(left_ty, RTy::Int) {
                        (left, right)
                    } else {
                        (right, left)
                    };
                    Some(numbers_help(int, float))
                }
                _ => self
                    .enum_variants(left_ty)
                    .or_else(|| self.enum_variants(right_ty)),
            };
            let mut diagnostic = self
                .checker
                .error(
                    Code::RuleType,
                    right.span,
                    format!("cannot compare {left_ty} with {right_ty}"),
                )
                // Two labels that do not overlap (one over the whole comparison
                // would make the renderer draw the operands' arrows past its end).
                .with_label(format!("{right_ty}"))
                .with_secondary(left.span, format!("{left_ty}"));
            if let Some(help) = help {
                diagnostic = diagnostic.with_help(help);
            }
            self.checker.push(diagnostic);
            return typed(left_typed, right_typed);
        }
        let ordered = matches!(
            op,
            BinaryOp::Lt | BinaryOp::Le | BinaryOp::Gt | BinaryOp::Ge
        );
        if ordered
            && !matches!(
                strip(left_ty),
                RTy::Int | RTy::Float | RTy::Duration | RTy::Time
            )
        {
            let mut diagnostic = self
                .checker
                .error(
                    Code::RuleType,
                    expr.span,
                    format!(
                        "`{}` orders numbers, durations and times, not {left_ty}",
                        op.as_str()
                    ),
                )
                .with_label("ill-typed");
            if let Some(help) = self.enum_variants(left_ty) {
                diagnostic = diagnostic.with_help(help);
            }
            self.checker.push(diagnostic);
        }
        typed(left_typed, right_typed)
    }

    /// For an enum (or optional enum) type, help that lists its variants and how a
    /// rule compares with one.
    fn enum_variants(&self, ty: &RTy) -> Option<String> {
        let RTy::Enum(name) = strip(ty) else {
            return None;
        };
        let def = self.checker.model.enum_def(name)?;
        let variants: Vec<String> = def
            .variants
            .iter()
            .map(|v| format!("`{name}::{}`", v.name.name))
            .collect();
        let first = variants.first()?;
        Some(format!(
            "compare it with `==` or `!=` to a variant of `{name}`: {} (e.g. `== {}`)",
            variants.join(", "),
            first.trim_matches('`')
        ))
    }

    /// Resolves a bare name against the type it is compared with.
    fn symbol(&mut self, symbol: &ast::Ident, other: &RTy) -> RTy {
        let (domain, what, context): (Vec<String>, &str, String) = match strip(other) {
            RTy::State => (
                DEFAULT_STATES.iter().map(|s| s.to_string()).collect(),
                "default state",
                String::new(),
            ),
            RTy::UserState(component, states) => {
                (states.clone(), "user state", format!(" of `{component}`"))
            }
            RTy::Result => (
                RESULTS.iter().map(|s| s.to_string()).collect(),
                "result",
                String::new(),
            ),
            RTy::Quality(component, levels) => (
                levels.clone(),
                "quality level",
                format!(" of `{component}`"),
            ),
            RTy::Enum(name) => {
                let diagnostic = self
                    .checker
                    .error(
                        Code::RuleType,
                        symbol.span,
                        format!(
                            "enum values are written with their type: `{name}::{}`",
                            symbol.name
                        ),
                    )
                    .with_label("bare name")
                    .with_help(format!("write `{name}::{}`", symbol.name));
                self.checker.push(diagnostic);
                return RTy::Unknown;
            }
            RTy::Unknown => return RTy::Unknown,
            _ => {
                self.unknown_variable(symbol);
                return RTy::Unknown;
            }
        };
        if domain.contains(&symbol.name) {
            return strip(other).clone();
        }
        let code = if matches!(strip(other), RTy::State | RTy::UserState(..)) {
            Code::UnknownState
        } else {
            Code::RuleType
        };
        self.checker.unknown(
            code,
            symbol,
            what,
            &context,
            domain.iter().map(String::as_str),
        );
        RTy::Unknown
    }
}

fn compatible(a: &RTy, b: &RTy) -> bool {
    match (a, b) {
        (RTy::Optional(_), RTy::NoneLit) | (RTy::NoneLit, RTy::Optional(_)) => true,
        (RTy::Result, RTy::NoneLit) | (RTy::NoneLit, RTy::Result) => true,
        (RTy::Optional(x), y) | (y, RTy::Optional(x)) => compatible(x, y),
        (RTy::UserState(x, _), RTy::UserState(y, _)) | (RTy::Quality(x, _), RTy::Quality(y, _)) => {
            x == y
        }
        (RTy::Other(_), _) | (_, RTy::Other(_)) => false,
        _ => a == b,
    }
}

/// The type of an instance's default controllable timing variable, which its
/// monitoring port publishes: `period` and `max_response` (zero when it has none),
/// `priority`.
fn timing_variable(name: &str) -> Option<RTy> {
    match name {
        "period" | "max_response" => Some(RTy::Duration),
        "priority" => Some(RTy::Int),
        _ => None,
    }
}

/// The type of a default observable variable of `component`.
fn default_variable(name: &str, component: &str, interface: &Component) -> Option<RTy> {
    Some(match name {
        "state" => RTy::State,
        "user_state" => RTy::UserState(component.to_owned(), interface.user_states()),
        "result" => RTy::Result,
        "error" => RTy::Str,
        "cpu_time" | "elapsed_time" => RTy::Duration,
        "quality" => RTy::Quality(component.to_owned(), interface.quality()),
        _ => return None,
    })
}

/// The quality levels an instance's `timing { quality ... }` override declares.
fn override_levels(instance: &ast::Instance) -> Option<Vec<String>> {
    instance
        .timing
        .as_ref()?
        .entries
        .iter()
        .find_map(|entry| match entry {
            ast::TimingEntry::Quality(levels, _) => {
                Some(levels.iter().map(|level| level.name.clone()).collect())
            }
            _ => None,
        })
}

/// Help for comparing the integer `int` with the float `float`: the literal to
/// rewrite, or the variables' types.
fn numbers_help(int: &ast::Expr, float: &ast::Expr) -> String {
    let literal = |expr: &ast::Expr| match &expr.kind {
        ast::ExprKind::Unary(_, inner) => {
            matches!(inner.kind, ast::ExprKind::Int(_) | ast::ExprKind::Float(_))
        }
        kind => matches!(kind, ast::ExprKind::Int(_) | ast::ExprKind::Float(_)),
    };
    match (literal(int), literal(float)) {
        (true, _) => "write float literals with a point, e.g. `3.0`".to_owned(),
        (false, true) => {
            "the other side is an integer: compare it with an integer literal, e.g. `2` \
             (a rule compares numbers of one kind)"
                .to_owned()
        }
        (false, false) => "an integer and a float are not compared: give both variables one kind \
             (a rule compares numbers of one kind)"
            .to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::RTy;

    #[test]
    fn types_read_with_their_article() {
        let cases = [
            (RTy::Bool, "a bool"),
            (RTy::Int, "an integer"),
            (RTy::Str, "a string"),
            (RTy::Optional(Box::new(RTy::Float)), "an optional float"),
            (
                RTy::Optional(Box::new(RTy::Enum("Mode".into()))),
                "an optional `Mode` value",
            ),
            (
                RTy::UserState("Gate".into(), Vec::new()),
                "a user state of `Gate`",
            ),
            (RTy::Unknown, "an unknown type"),
            (RTy::NoneLit, "`none`"),
        ];
        for (ty, text) in cases {
            assert_eq!(ty.to_string(), text);
        }
    }
}
