//! Types and values: written types resolve, sizes are positive, defaults match their
//! declared type, timing values are durations (or frequencies where a period is
//! expected) and intervals are ordered.

use super::Checker;
use super::model::Ty;
use crate::ast::{self, Span};
use crate::diagnostics::Code;
use crate::resolve::DefKind;

/// Resolves every name inside a written type and rejects `[T; 0]`.
pub(super) fn ty(checker: &mut Checker<'_, '_>, ty: &ast::Type) {
    match &ty.kind {
        ast::TypeKind::Prim(_) => {}
        ast::TypeKind::Named(name) => {
            let symbols = checker.model.symbols;
            symbols.resolve(
                checker.file,
                name,
                &[
                    DefKind::Packet,
                    DefKind::Enum,
                    DefKind::ExternPacket,
                    DefKind::RosMessage,
                ],
                Code::UnknownType,
                "type",
                checker.diagnostics,
            );
        }
        ast::TypeKind::List(inner) | ast::TypeKind::Optional(inner) => self::ty(checker, inner),
        ast::TypeKind::Array(inner, size) => {
            self::ty(checker, inner);
            positive(checker, size, "an array length");
        }
    }
}

/// Rejects a zero size or count.
pub(super) fn positive(checker: &mut Checker<'_, '_>, value: &ast::IntLit, what: &str) {
    if value.value == 0 {
        let diagnostic = checker
            .error(
                Code::ZeroSize,
                value.span,
                format!("{what} must be at least 1"),
            )
            .with_label("zero here");
        checker.push(diagnostic);
    }
}

/// A packet or configuration field: name, type, default.
pub(super) fn field(checker: &mut Checker<'_, '_>, field: &ast::Field) {
    super::names::value_name(checker, &field.name);
    ty(checker, &field.ty);
    if let Some(default) = &field.default {
        let expected = checker.model.ty(&field.ty);
        value(checker, default, &expected);
    }
}

/// The Rust path of an extern packet must not be empty.
pub(super) fn extern_path(checker: &mut Checker<'_, '_>, def: &ast::ExternPacket) {
    let path = def.rust_path.value.trim();
    let mut depth = 0i32;
    let balanced = path.chars().all(|c| {
        match c {
            '<' => depth += 1,
            '>' => depth -= 1,
            _ => {}
        }
        depth >= 0
    }) && depth == 0;
    let valid = balanced
        && path
            .chars()
            .next()
            .is_some_and(|c| c.is_alphabetic() || c == '_' || c == ':')
        && path
            .chars()
            .all(|c| c.is_alphanumeric() || "_:<>, &'[];".contains(c))
        && !path.ends_with(':');
    if !valid {
        let diagnostic = checker
            .error(
                Code::TypeMismatch,
                def.rust_path.span,
                format!("`{}` is not a Rust type path", def.rust_path.value),
            )
            .with_label("expected a path such as \"image::RgbImage\"");
        checker.push(diagnostic);
    }
}

/// Checks that `expr` is a literal of type `expected`.
pub(super) fn value(checker: &mut Checker<'_, '_>, expr: &ast::Expr, expected: &Ty) {
    if let Err((span, message, help)) = value_error(checker, expr, expected) {
        let mut diagnostic = checker
            .error(Code::TypeMismatch, span, message)
            .with_label(format!("expected `{expected}`"));
        if let Some(help) = help {
            diagnostic = diagnostic.with_help(help);
        }
        checker.push(diagnostic);
    }
}

type ValueError = (Span, String, Option<String>);

pub(super) fn describe(expr: &ast::Expr) -> &'static str {
    match &expr.kind {
        ast::ExprKind::Int(_) => "an integer",
        ast::ExprKind::Float(_) => "a float",
        ast::ExprKind::Str(_) => "a string",
        ast::ExprKind::Bool(_) => "a bool",
        ast::ExprKind::Duration(_) => "a duration",
        ast::ExprKind::Frequency(_) => "a frequency",
        ast::ExprKind::Path(_) => "a name",
        ast::ExprKind::EnumValue { .. } => "an enum value",
        ast::ExprKind::List(_) | ast::ExprKind::Repeat(..) => "a list",
        ast::ExprKind::None => "`none`",
        ast::ExprKind::Unary(ast::UnaryOp::Neg, _) => "a negative number",
        ast::ExprKind::Unary(..) | ast::ExprKind::Binary(..) => "an expression",
    }
}

fn mismatch(expr: &ast::Expr, expected: &Ty, help: Option<String>) -> ValueError {
    (
        expr.span,
        format!(
            "expected a value of type `{expected}`, found {}",
            describe(expr)
        ),
        help,
    )
}

fn value_error(
    checker: &mut Checker<'_, '_>,
    expr: &ast::Expr,
    expected: &Ty,
) -> Result<(), ValueError> {
    use ast::ExprKind as E;
    match (expected, &expr.kind) {
        (Ty::Unknown, _) => Ok(()),
        (Ty::Optional(_), E::None) => Ok(()),
        (Ty::Optional(inner), _) => value_error(checker, expr, inner),
        (Ty::Bool, E::Bool(_)) | (Ty::Str, E::Str(_)) | (Ty::Duration, E::Duration(_)) => Ok(()),
        (Ty::Float(prim), E::Float(value)) => {
            float_fits(*prim, *value).map_err(|message| (expr.span, message, None))
        }
        (Ty::Float(prim), E::Unary(ast::UnaryOp::Neg, inner)) => match inner.kind {
            E::Float(value) => {
                float_fits(*prim, -value).map_err(|message| (expr.span, message, None))
            }
            // An integer literal is a whole float, within any float's range.
            E::Int(_) => Ok(()),
            _ => Err(mismatch(expr, expected, None)),
        },
        // An integer literal is a whole float: `max_speed: f64 = 1` means `1.0`.
        (Ty::Float(_), E::Int(_)) => Ok(()),
        (Ty::Int(prim), E::Int(n)) => {
            int_fits(*prim, i128::from(*n)).map_err(|message| (expr.span, message, None))
        }
        (Ty::Int(prim), E::Unary(ast::UnaryOp::Neg, inner)) => match inner.kind {
            E::Int(n) => {
                int_fits(*prim, -i128::from(n)).map_err(|message| (expr.span, message, None))
            }
            _ => Err(mismatch(expr, expected, None)),
        },
        (Ty::Int(_), E::Float(_)) => Err(mismatch(
            expr,
            expected,
            Some("integers are written without a point".into()),
        )),
        (Ty::Enum(name), E::EnumValue { enum_name, variant }) => {
            if enum_name.name != *name {
                return Err(mismatch(
                    expr,
                    expected,
                    Some(format!("write `{name}::...`")),
                ));
            }
            let variants: Vec<String> = checker
                .model
                .enum_def(name)
                .map(|def| def.variants.iter().map(|v| v.name.name.clone()).collect())
                .unwrap_or_default();
            if !variants.contains(&variant.name) {
                checker.unknown(
                    Code::UnknownVariant,
                    variant,
                    "variant",
                    &format!(" in enum `{name}`"),
                    variants.iter().map(String::as_str),
                );
            }
            Ok(())
        }
        (Ty::Enum(name), E::Path(segments)) if segments.len() == 1 => Err(mismatch(
            expr,
            expected,
            Some(format!(
                "enum values are written with their type: `{name}::{}`",
                segments[0].name
            )),
        )),
        (Ty::List(inner), E::List(items)) => {
            for item in items {
                value_error(checker, item, inner)?;
            }
            Ok(())
        }
        (Ty::List(inner), E::Repeat(item, count)) => {
            positive(checker, count, "a repeat count");
            value_error(checker, item, inner)
        }
        (Ty::Array(inner, length), E::List(items)) => {
            if items.len() as u64 != *length {
                return Err((
                    expr.span,
                    format!(
                        "expected {length} elements for `{expected}`, found {}",
                        items.len()
                    ),
                    Some(format!("write `[value; {length}]` to repeat one value")),
                ));
            }
            for item in items {
                value_error(checker, item, inner)?;
            }
            Ok(())
        }
        (Ty::Array(inner, length), E::Repeat(item, count)) => {
            if count.value != *length {
                return Err((
                    count.span,
                    format!(
                        "expected {length} elements for `{expected}`, found {}",
                        count.value
                    ),
                    Some(format!("write `{length}`")),
                ));
            }
            value_error(checker, item, inner)
        }
        (Ty::Time, _) => Err(mismatch(
            expr,
            expected,
            Some("`Time` values have no literal; leave the default out".into()),
        )),
        (Ty::Ros { .. }, _) => Err(mismatch(
            expr,
            expected,
            Some("ROS message types have no literal; leave the default out (the type's own defaults apply)".into()),
        )),
        (Ty::Packet(_) | Ty::Extern(_), _) => Err(mismatch(
            expr,
            expected,
            Some("packets have no literal; put defaults on the packet's fields".into()),
        )),
        (Ty::Duration, E::Int(n)) => Err(mismatch(
            expr,
            expected,
            Some(format!("add a unit, e.g. `{n}ms`")),
        )),
        _ => Err(mismatch(expr, expected, None)),
    }
}

/// A float literal `rustc` accepts for `prim`: an `f32` literal that rounds to
/// infinity is refused (`f64` literals beyond `f64` are refused when read).
fn float_fits(prim: ast::Prim, value: f64) -> Result<(), String> {
    #[allow(clippy::cast_possible_truncation)] // Rounding to `f32` is the question.
    if prim == ast::Prim::F32 && (value as f32).is_infinite() {
        return Err(format!(
            "{value:e} does not fit in `f32` (-{max:e}..={max:e})",
            max = f32::MAX
        ));
    }
    Ok(())
}

fn int_fits(prim: ast::Prim, value: i128) -> Result<(), String> {
    use ast::Prim::*;
    let (min, max): (i128, i128) = match prim {
        I8 => (i8::MIN.into(), i8::MAX.into()),
        I16 => (i16::MIN.into(), i16::MAX.into()),
        I32 => (i32::MIN.into(), i32::MAX.into()),
        I64 => (i64::MIN.into(), i64::MAX.into()),
        U8 => (0, u8::MAX.into()),
        U16 => (0, u16::MAX.into()),
        U32 => (0, u32::MAX.into()),
        _ => (0, u64::MAX.into()),
    };
    if value < min || value > max {
        return Err(format!(
            "{value} does not fit in `{}` ({min}..={max})",
            super::model::prim_name(prim)
        ));
    }
    Ok(())
}

/// A period: a duration or frequency, not zero; returns it in nanoseconds.
pub(super) fn period(checker: &mut Checker<'_, '_>, expr: &ast::Expr) -> Option<f64> {
    match expr.kind {
        ast::ExprKind::Duration(nanos) => {
            if nanos == 0 {
                zero(checker, expr.span, "a period");
                return None;
            }
            Some(nanos as f64)
        }
        ast::ExprKind::Frequency(hertz) => {
            if hertz <= 0.0 {
                zero(checker, expr.span, "a frequency");
                return None;
            }
            Some(1e9 / hertz)
        }
        _ => {
            let diagnostic = checker
                .error(
                    Code::TypeMismatch,
                    expr.span,
                    format!("expected a period, found {}", describe(expr)),
                )
                .with_label("expected a duration such as `10ms` or a frequency such as `100Hz`");
            checker.push(diagnostic);
            None
        }
    }
}

/// A delay: a duration, not zero.
pub(super) fn duration(checker: &mut Checker<'_, '_>, expr: &ast::Expr, what: &str) {
    match expr.kind {
        ast::ExprKind::Duration(0) => zero(checker, expr.span, what),
        ast::ExprKind::Duration(_) => {}
        _ => {
            let help = match expr.kind {
                ast::ExprKind::Int(n) => Some(format!("add a unit, e.g. `{n}ms`")),
                _ => None,
            };
            let mut diagnostic = checker
                .error(
                    Code::TypeMismatch,
                    expr.span,
                    format!("expected a duration for {what}, found {}", describe(expr)),
                )
                .with_label("expected a duration such as `500ms`");
            if let Some(help) = help {
                diagnostic = diagnostic.with_help(help);
            }
            checker.push(diagnostic);
        }
    }
}

fn zero(checker: &mut Checker<'_, '_>, span: Span, what: &str) {
    let diagnostic = checker
        .error(Code::ZeroSize, span, format!("{what} must not be zero"))
        .with_label("zero here");
    checker.push(diagnostic);
}

/// A `timing` block: periods, response time, priority, quality levels, each once.
pub(super) fn timing(checker: &mut Checker<'_, '_>, timing: &ast::Timing) {
    let mut seen: Vec<(&'static str, Span)> = Vec::new();
    for entry in &timing.entries {
        let (name, span) = match entry {
            ast::TimingEntry::Period(interval) => {
                self::interval(checker, interval);
                ("period", interval.span)
            }
            ast::TimingEntry::MaxResponse(expr) => {
                duration(checker, expr, "`max_response`");
                ("max_response", expr.span)
            }
            ast::TimingEntry::Priority(expr) => {
                if !matches!(expr.kind, ast::ExprKind::Int(0..=99)) {
                    let diagnostic = checker
                        .error(
                            Code::TypeMismatch,
                            expr.span,
                            format!("expected a priority from 0 to 99, found {}", describe(expr)),
                        )
                        .with_label("expected an integer in 0..=99");
                    checker.push(diagnostic);
                }
                ("priority", expr.span)
            }
            ast::TimingEntry::Quality(levels, span) => {
                for level in levels {
                    super::names::value_name(checker, level);
                }
                super::names::duplicates(checker, levels, "quality level");
                super::names::rust_clashes(
                    checker,
                    levels,
                    "quality level",
                    &[super::names::snake, super::names::camel],
                );
                ("quality", *span)
            }
        };
        if let Some((_, first)) = seen.iter().find(|(seen_name, _)| *seen_name == name) {
            let diagnostic = checker
                .error(
                    Code::RepeatedBlock,
                    span,
                    format!("`{name}` is given more than once in this `timing` block"),
                )
                .with_label("given again here")
                .with_secondary(*first, "first given here");
            checker.push(diagnostic);
        } else {
            seen.push((name, span));
        }
    }
}

/// `lo..hi`: both periods, `lo <= hi`.
fn interval(checker: &mut Checker<'_, '_>, interval: &ast::Interval) {
    let lo = period(checker, &interval.lo);
    let hi = interval.hi.as_ref().and_then(|hi| period(checker, hi));
    if let (Some(lo), Some(hi), Some(hi_expr)) = (lo, hi, &interval.hi)
        && hi < lo
    {
        let diagnostic = checker
            .error(
                Code::ReversedInterval,
                interval.span,
                "the interval's upper bound is shorter than its lower bound",
            )
            .with_label("reversed interval")
            .with_secondary(hi_expr.span, "this bound is the shorter period")
            .with_help("write the nominal (shortest) period first: `period 10ms..40ms;`");
        checker.push(diagnostic);
    }
}

/// A packet may not contain itself by value, directly or through other packets'
/// fields, arrays or optionals (a list `[T]` is a heap allocation and breaks the
/// cycle): the generated struct would be infinitely large.
pub(super) fn recursive_packet(checker: &mut Checker<'_, '_>, packet: &ast::Packet) {
    for field in &packet.fields {
        let mut chain = vec![packet.name.name.clone()];
        let mut visited = std::collections::BTreeSet::new();
        if contains_by_value(
            checker,
            &field.ty,
            &packet.name.name,
            &mut chain,
            &mut visited,
        ) {
            let diagnostic = checker
                .error(
                    Code::RecursivePacket,
                    field.ty.span,
                    format!(
                        "packet `{}` contains itself: {}",
                        packet.name.name,
                        chain.join(" -> ")
                    ),
                )
                .with_label("contains the packet by value")
                .with_help("hold it in a list (`[T]`), which is allocated on the heap");
            checker.push(diagnostic);
            return;
        }
    }
}

fn contains_by_value(
    checker: &Checker<'_, '_>,
    ty: &ast::Type,
    target: &str,
    chain: &mut Vec<String>,
    visited: &mut std::collections::BTreeSet<String>,
) -> bool {
    match &ty.kind {
        ast::TypeKind::Prim(_) | ast::TypeKind::List(_) => false,
        ast::TypeKind::Array(inner, _) | ast::TypeKind::Optional(inner) => {
            contains_by_value(checker, inner, target, chain, visited)
        }
        ast::TypeKind::Named(name) => {
            if name.name == target {
                chain.push(name.name.clone());
                return true;
            }
            if !visited.insert(name.name.clone()) {
                return false;
            }
            let Some(def) = checker.model.symbols.defs.get(&name.name) else {
                return false;
            };
            let Some(ast::Item::Packet(inner)) = checker
                .model
                .files
                .get(def.file.0 as usize)
                .and_then(|file| file.items.get(def.item))
            else {
                return false;
            };
            chain.push(name.name.clone());
            for field in &inner.fields {
                if contains_by_value(checker, &field.ty, target, chain, visited) {
                    return true;
                }
            }
            chain.pop();
            false
        }
    }
}
