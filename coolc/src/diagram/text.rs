//! Port kinds and values printed back as `.cool` text, for diagram labels (types
//! print as written through their `Display`).

use crate::checked::model::{
    BinaryOp, Declared, Duration, InputKind, Node, OutputKind, PortRef, Typed, UnaryOp, Value,
    Written, duration_text as duration,
};

/// An input's kind as written (`fifo<Twist>(16, drop_oldest)`, `tick`), with ` pull`.
pub(crate) fn input_kind(input: &Declared<InputKind>) -> String {
    let kind = match &input.kind {
        InputKind::Tick => "tick".to_owned(),
        InputKind::Fifo { ty, size, policy } => match policy {
            Some(policy) => format!("fifo<{ty}>({size}, {})", policy.name()),
            None => format!("fifo<{ty}>({size})"),
        },
        InputKind::Ufifo { ty, size, max } => match max {
            Some(max) => format!("ufifo<{ty}>({size}, max {max})"),
            None => format!("ufifo<{ty}>({size})"),
        },
        InputKind::Last(ty) => format!("last<{ty}>"),
        InputKind::Poster(ty) => format!("poster<{ty}>"),
    };
    with_pull(kind, input.pull)
}

/// An output's kind as written (`data<Pose2D>`, `tick`), with ` pull`.
pub(crate) fn output_kind(output: &Declared<OutputKind>) -> String {
    let kind = match &output.kind {
        OutputKind::Tick => "tick".to_owned(),
        OutputKind::Data(ty) => format!("data<{ty}>"),
        OutputKind::Poster(ty) => format!("poster<{ty}>"),
    };
    with_pull(kind, output.pull)
}

fn with_pull(kind: String, pull: bool) -> String {
    if pull { format!("{kind} pull") } else { kind }
}

/// `instance.port`, or `port`.
pub(crate) fn port_ref(port: &PortRef) -> String {
    match &port.instance {
        Some(instance) => format!("{}.{}", instance.name, port.port),
        None => port.port.clone(),
    }
}

/// `lo` or `lo..hi`.
pub(crate) fn interval(lo: &Duration, hi: Option<&Duration>) -> String {
    match hi {
        Some(hi) => format!("{}..{}", time(lo), time(hi)),
        None => time(lo),
    }
}

/// A duration or frequency as written (`500ms`, `100Hz`).
pub(crate) fn time(time: &Duration) -> String {
    match time.written {
        Written::Nanos(nanos) => duration(nanos),
        Written::Hertz(hertz) => frequency(hertz),
    }
}

fn float(value: f64) -> String {
    let text = format!("{value}");
    if text.contains(['.', 'e', 'E', 'i', 'N']) {
        text
    } else {
        format!("{text}.0")
    }
}

fn frequency(hertz: f64) -> String {
    if hertz >= 1000.0 && (hertz / 1000.0).fract() == 0.0 {
        format!("{}kHz", hertz / 1000.0)
    } else {
        format!("{hertz}Hz")
    }
}

fn string(text: &str) -> String {
    let mut out = String::from("\"");
    for c in text.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\t' => out.push_str("\\t"),
            '\r' => out.push_str("\\r"),
            c if c.is_control() => out.push_str(&format!("\\u{{{:X}}}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// A constant value as `.cool` writes it.
pub(crate) fn value(value: &Value) -> String {
    match value {
        Value::Bool(value) => value.to_string(),
        Value::Int(value) => value.to_string(),
        Value::Float(value) => float(*value),
        Value::Str(text) => string(text),
        Value::Duration(duration) => time(duration),
        Value::Enum { ty, variant } => format!("{ty}::{variant}"),
        Value::List(items) => {
            let items: Vec<String> = items.iter().map(self::value).collect();
            format!("[{}]", items.join(", "))
        }
        Value::Repeat(item, count) => format!("[{}; {count}]", self::value(item)),
        Value::None => "none".to_owned(),
        Value::Invalid => "?".to_owned(),
    }
}

/// How tightly an expression binds (higher binds tighter).
fn precedence(expr: &Typed) -> u8 {
    match &expr.node {
        Node::Binary(BinaryOp::Or) => 1,
        Node::Binary(BinaryOp::And) => 2,
        Node::Binary(_) => 3,
        Node::Unary(_) => 4,
        _ => 5,
    }
}

/// A rule expression as written, with the parentheses its shape needs.
pub(crate) fn expr(expr: &Typed) -> String {
    let operand = |index: usize| expr.operands.get(index);
    match &expr.node {
        Node::Int(value) => value.to_string(),
        Node::Float(value) => float(*value),
        Node::Str(text) => string(text),
        Node::Bool(value) => value.to_string(),
        Node::Duration(nanos) => duration(*nanos),
        Node::Frequency(hertz) => frequency(*hertz),
        Node::Path(parts) => parts.join("."),
        Node::EnumValue { enum_name, variant } => format!("{enum_name}::{variant}"),
        Node::List => {
            let items: Vec<String> = expr.operands.iter().map(self::expr).collect();
            format!("[{}]", items.join(", "))
        }
        Node::Repeat(count) => format!(
            "[{}; {count}]",
            operand(0).map_or_else(String::new, self::expr)
        ),
        Node::None => "none".to_owned(),
        Node::Unary(op) => {
            let op = match op {
                UnaryOp::Not => "!",
                UnaryOp::Neg => "-",
            };
            format!("{op}{}", operand_text(operand(0), 4, false))
        }
        Node::Binary(op) => {
            let own = precedence(expr);
            // Comparisons do not chain: a comparison operand of a comparison keeps its
            // parentheses on both sides.
            let strict = own == 3;
            format!(
                "{} {} {}",
                operand_text(operand(0), own, strict),
                op.as_str(),
                operand_text(operand(1), own, true)
            )
        }
    }
}

fn operand_text(operand: Option<&Typed>, parent: u8, strict: bool) -> String {
    let Some(operand) = operand else {
        return String::new();
    };
    let own = precedence(operand);
    if own < parent || (strict && own == parent) {
        format!("({})", expr(operand))
    } else {
        expr(operand)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::checked::model::StateMember;

    fn condition(text: &str) -> String {
        let source = format!(
            "atomic A {{ observable x: u32 = 0; observable y: bool = true; automaton {{ initial s; state s {{ }} }} }}\ncompound C {{ instance a: A; observable f: u32 = 0; supervisor {{ initial s; state s {{ when {text} -> s; }} }} }}"
        );
        let checked = crate::analyze_text("c.cool", &source)
            .checked()
            .unwrap_or_else(|a| panic!("{}", a.render(crate::RenderOptions::plain())));
        let automaton = checked
            .component("C")
            .and_then(|c| c.automaton.as_ref())
            .expect("supervisor");
        match &automaton.states[0].members[0] {
            StateMember::When { condition, .. } => expr(condition),
            other => panic!("not a rule: {other:?}"),
        }
    }

    #[test]
    fn expressions_print_back_with_the_parentheses_they_need() {
        for text in [
            "a.x > 3 || f == 2 && a.y",
            "(a.x > 3 || f == 2) && a.y",
            "!(a.y && f != 0)",
            "a.state == running_error",
            "a.elapsed_time > 2s",
            "a.error == \"say \\\"hi\\\"\"",
        ] {
            assert_eq!(condition(text), text);
        }
    }

    #[test]
    fn durations_take_the_largest_unit_that_divides_them() {
        assert_eq!(duration(60_000_000_000), "1min");
        assert_eq!(duration(1_500_000_000), "1500ms");
        assert_eq!(duration(250), "250ns");
        assert_eq!(duration(500_000), "500us");
        assert_eq!(duration(0), "0s");
        assert_eq!(frequency(1000.0), "1kHz");
        assert_eq!(frequency(10.0), "10Hz");
        assert_eq!(float(1.0), "1.0");
        assert_eq!(float(0.0015), "0.0015");
    }
}
