//! Reads the text of one `.msg` file into a [`Message`].
//!
//! The format is rosidl's (`rosidl_adapter.parser`): one field or constant a line,
//! `#` starting a comment, blank lines ignored.
//!
//! ```text
//! uint8 MODE_FAST=1           # a constant: TYPE NAME=VALUE
//! string NAME="x"
//! float64 x                   # a field: TYPE NAME
//! float64 y 1.0               # a field with a default value: TYPE NAME VALUE
//! int32[] a [1, 2]
//! ```
//!
//! A `#` inside a quoted value (`string S "a#b"`) belongs to the value. Field and
//! constant types are primitives (`bool byte char int8..uint64 float32 float64 string
//! wstring`), bounded strings (`string<=N`), message types of the same package
//! (`Point`) or of another (`std_msgs/Header`), and arrays of any of them: fixed
//! (`T[N]`), bounded (`T[<=N]`) or unbounded (`T[]`).
//!
//! **Invariant:** parsing never fails: it returns what it could read and a
//! diagnostic, with its span in the file, for everything wrong; a line with an error
//! adds no field or constant.

use std::collections::HashMap;

use crate::ast::{FileId, Span};
use crate::diagnostics::{Code, Diagnostic, closest};

use super::msg::{Base, Cardinality, Constant, Field, FieldType, Message, Value};
use super::names::{self, TypeName};

/// Reads the file `file` (text `text`) defining the type `name`: the message and
/// every problem found, in file order.
pub fn parse(name: &TypeName, file: FileId, text: &str) -> (Message, Vec<Diagnostic>) {
    let mut parser = Parser {
        package: name.package(),
        file,
        diagnostics: Vec::new(),
    };
    let mut fields = Vec::new();
    let mut constants = Vec::new();
    let mut offset = 0;
    for raw in text.split_inclusive('\n') {
        let start = offset;
        offset += raw.len();
        let line = raw.trim_end_matches(['\n', '\r']);
        match parser.line(start, &line[..comment_start(line)]) {
            Some(Item::Field(field)) => fields.push(field),
            Some(Item::Constant(constant)) => constants.push(constant),
            None => {}
        }
    }
    parser.duplicates("field", fields.iter().map(|f| (&f.name, f.name_span)));
    parser.duplicates("constant", constants.iter().map(|c| (&c.name, c.name_span)));
    let message = Message {
        name: name.clone(),
        file,
        constants,
        fields,
    };
    (message, parser.diagnostics)
}

/// What one line defines.
enum Item {
    Field(Field),
    Constant(Constant),
}

fn is_blank(c: char) -> bool {
    c == ' ' || c == '\t'
}

/// Where the comment of a line starts (its length if it has none): at the first `#`
/// outside a quoted value. A quote opens a value only at its start (after a blank,
/// `=`, `[` or `,`), so the apostrophe of `it's` opens nothing.
fn comment_start(line: &str) -> usize {
    let mut quote = None;
    let mut escaped = false;
    let mut previous = None;
    for (index, c) in line.char_indices() {
        match quote {
            Some(open) => {
                if escaped {
                    escaped = false;
                } else if c == '\\' {
                    escaped = true;
                } else if c == open {
                    quote = None;
                }
            }
            None if c == '#' => return index,
            None => {
                let at_value_start =
                    previous.is_none_or(|p: char| is_blank(p) || matches!(p, '=' | '[' | ','));
                if matches!(c, '"' | '\'') && at_value_start {
                    quote = Some(c);
                }
            }
        }
        previous = Some(c);
    }
    line.len()
}

struct Parser<'a> {
    package: &'a str,
    file: FileId,
    diagnostics: Vec<Diagnostic>,
}

impl Parser<'_> {
    fn error(&mut self, code: Code, span: Span, message: impl Into<String>) -> &mut Diagnostic {
        self.diagnostics
            .push(Diagnostic::error(code, self.file, span, message));
        self.diagnostics.last_mut().expect("just pushed")
    }

    /// One line without its comment; `start` is its offset in the file.
    fn line(&mut self, start: usize, code: &str) -> Option<Item> {
        let at = |from: usize, to: usize| Span::new(start + from, start + to);
        let after = |from: usize, what: fn(char) -> bool| {
            code[from..].find(what).map_or(code.len(), |i| from + i)
        };
        let ty_start = code.find(|c| !is_blank(c))?;
        let ty_end = after(ty_start, is_blank);
        let ty_text = &code[ty_start..ty_end];
        let ty_span = at(ty_start, ty_end);
        let name_start = after(ty_end, |c| !is_blank(c));
        if name_start == code.len() {
            let message = format!("expected a field or constant name after the type `{ty_text}`");
            self.error(Code::UnexpectedToken, ty_span, message);
            return None;
        }
        let name_end = after(name_start, |c| is_blank(c) || c == '=');
        let name = &code[name_start..name_end];
        let name_span = at(name_start, name_end);
        let rest = after(name_end, |c| !is_blank(c));
        let text_end = code.trim_end_matches(is_blank).len();
        if code[rest..].starts_with('=') {
            let equals = at(rest, rest + 1);
            if name.is_empty() {
                self.error(
                    Code::UnexpectedToken,
                    equals,
                    "expected a constant name before `=`",
                );
                return None;
            }
            let value_start = after(rest + 1, |c| !is_blank(c));
            let value = &code[value_start..text_end.max(value_start)];
            let value_span = at(value_start, value_start + value.len());
            self.constant(ty_text, ty_span, name, name_span, value, value_span, equals)
                .map(Item::Constant)
        } else {
            let default = (rest < text_end).then(|| (&code[rest..text_end], at(rest, text_end)));
            self.field(ty_text, ty_span, name, name_span, default)
                .map(Item::Field)
        }
    }

    fn field(
        &mut self,
        ty_text: &str,
        ty_span: Span,
        name: &str,
        name_span: Span,
        default: Option<(&str, Span)>,
    ) -> Option<Field> {
        let ty = self.field_type(ty_text, ty_span);
        let named = self.check_name(name, name_span, "field", names::is_field_name);
        let ty = ty?;
        let default = match default {
            Some((text, span)) => Some((self.value(&ty, text, span)?, span)),
            None => None,
        };
        named.then(|| Field {
            name: name.to_owned(),
            name_span,
            ty,
            ty_span,
            default,
        })
    }

    fn constant(
        &mut self,
        ty_text: &str,
        ty_span: Span,
        name: &str,
        name_span: Span,
        value: &str,
        value_span: Span,
        equals: Span,
    ) -> Option<Constant> {
        let ty = self.field_type(ty_text, ty_span);
        let named = self.check_name(name, name_span, "constant", names::is_constant_name);
        let ty = ty?;
        if ty.cardinality != Cardinality::Single {
            self.error(
                Code::MisplacedMember,
                ty_span,
                format!("the constant `{name}` is of an array type, `{ty}`"),
            )
            .help = Some("a constant has a primitive type: bool, byte, char, an integer or float type, string or wstring".into());
            return None;
        }
        match &ty.base {
            Base::Nested(_) | Base::String(Some(_)) | Base::WString(Some(_)) => {
                self.error(
                    Code::MisplacedMember,
                    ty_span,
                    format!("the constant `{name}` is of type `{ty}`, not a primitive type"),
                )
                .help = Some("a constant has a primitive type: bool, byte, char, an integer or float type, string or wstring".into());
                return None;
            }
            _ => {}
        }
        if value.is_empty() {
            self.error(
                Code::UnexpectedToken,
                equals,
                format!("the constant `{name}` has no value after `=`"),
            );
            return None;
        }
        let value = self.scalar(&ty.base, value, value_span)?;
        named.then(|| Constant {
            name: name.to_owned(),
            name_span,
            ty: ty.base,
            ty_span,
            value,
            value_span,
        })
    }

    fn check_name(&mut self, name: &str, span: Span, what: &str, rule: fn(&str) -> bool) -> bool {
        if rule(name) {
            return true;
        }
        let help = if what == "field" {
            "field names are lower snake case: `[a-z][a-z0-9_]*`, no `__`, no `_` at the end"
        } else {
            "constant names are upper snake case: `[A-Z][A-Z0-9_]*`, no `__`, no `_` at the end"
        };
        self.error(
            Code::Naming,
            span,
            format!("`{name}` is not a valid {what} name"),
        )
        .help = Some(help.into());
        false
    }

    /// A type: a base type, then `[N]`, `[<=N]` or `[]`.
    fn field_type(&mut self, text: &str, span: Span) -> Option<FieldType> {
        let (base_text, cardinality) = match text.find('[') {
            Some(open) => {
                let bracket = &text[open..];
                let bracket_span = Span::new(span.start + open, span.end);
                let inside = bracket
                    .strip_suffix(']')
                    .map(|b| &b[1..])
                    .filter(|inside| !inside.contains(['[', ']']));
                let Some(inside) = inside else {
                    self.error(
                        Code::UnexpectedToken,
                        bracket_span,
                        format!("`{bracket}` is not an array suffix"),
                    )
                    .help = Some(
                        "an array is `T[N]` (fixed), `T[<=N]` (bounded) or `T[]` (unbounded); arrays of arrays do not exist".into(),
                    );
                    return None;
                };
                let inside_start = bracket_span.start + 1;
                let cardinality = if inside.is_empty() {
                    Cardinality::Unbounded
                } else if let Some(bound) = inside.strip_prefix("<=") {
                    let at = Span::new(inside_start + 2, bracket_span.end - 1);
                    Cardinality::Bounded(self.size(bound, at)?)
                } else {
                    let at = Span::new(inside_start, bracket_span.end - 1);
                    Cardinality::Array(self.size(inside, at)?)
                };
                (&text[..open], cardinality)
            }
            None => (text, Cardinality::Single),
        };
        let base_span = Span::new(span.start, span.start + base_text.len());
        let base = self.base(base_text, base_span)?;
        Some(FieldType { base, cardinality })
    }

    /// An array size or a string bound: a decimal integer above 0.
    fn size(&mut self, text: &str, span: Span) -> Option<u64> {
        if !text.is_empty() && text.bytes().all(|b| b.is_ascii_digit()) {
            match text.parse::<u64>() {
                Ok(0) => {
                    self.error(Code::ZeroSize, span, "a size or bound must be above 0");
                }
                Ok(size) => return Some(size),
                Err(_) => {
                    self.error(
                        Code::InvalidNumber,
                        span,
                        format!("`{text}` is too large for a size"),
                    );
                }
            }
        } else {
            self.error(
                Code::InvalidNumber,
                span,
                format!("`{text}` is not a size: a size is a decimal integer above 0"),
            );
        }
        None
    }

    fn base(&mut self, text: &str, span: Span) -> Option<Base> {
        if let Some(base) = Base::primitive(text) {
            return Some(base);
        }
        for (keyword, wide) in [("string", false), ("wstring", true)] {
            if let Some(bound) = text
                .strip_prefix(keyword)
                .and_then(|t| t.strip_prefix("<="))
            {
                let at = Span::new(span.start + keyword.len() + 2, span.end);
                let bound = Some(self.size(bound, at)?);
                return Some(if wide {
                    Base::WString(bound)
                } else {
                    Base::String(bound)
                });
            }
        }
        if text.is_empty() {
            self.error(Code::UnexpectedToken, span, "expected a type before `[`");
            return None;
        }
        let parts: Vec<&str> = text.split('/').collect();
        let name = match parts[..] {
            [name] if names::is_message_name(name) => TypeName::new(self.package, name),
            [pkg, name] => TypeName::new(pkg, name),
            [pkg, "msg", name] => {
                self.error(
                    Code::UnknownType,
                    span,
                    format!(
                        "a `.msg` file names another package's type without `msg/`: `{pkg}/{name}`"
                    ),
                )
                .help = Some(format!("write `{pkg}/{name}`"));
                return None;
            }
            [name] => {
                self.unknown_type(name, span);
                return None;
            }
            _ => {
                self.error(Code::UnknownType, span, format!("`{text}` is not a type"))
                    .help =
                    Some("a message type is `Type` (this package) or `package/Type`".into());
                return None;
            }
        };
        match name {
            Ok(name) => Some(Base::Nested(name)),
            Err(error) => {
                self.error(Code::UnknownType, span, error.to_string());
                None
            }
        }
    }

    fn unknown_type(&mut self, name: &str, span: Span) {
        let ros1 = match name {
            "time" => Some("builtin_interfaces/Time"),
            "duration" => Some("builtin_interfaces/Duration"),
            _ => None,
        };
        let diagnostic = self.error(Code::UnknownType, span, format!("unknown type `{name}`"));
        diagnostic.help = Some(match ros1 {
            Some(ros2) => format!("`{name}` is a ROS 1 type; ROS 2 has `{ros2}`"),
            None => match alias(name)
                .or_else(|| closest(name, Base::PRIMITIVES.iter().map(|(k, _)| *k)))
            {
                Some(near) => format!("did you mean `{near}`?"),
                None => "a type is a primitive (bool, byte, char, int8..uint64, float32, float64, string, wstring), `Type` of this package or `package/Type`".into(),
            },
        });
    }

    /// A field's default value.
    fn value(&mut self, ty: &FieldType, text: &str, span: Span) -> Option<Value> {
        if let Base::Nested(name) = &ty.base {
            self.nested_default(name, span);
            return None;
        }
        match ty.cardinality {
            Cardinality::Single => self.scalar(&ty.base, text, span),
            cardinality => self.array(ty, cardinality, text, span),
        }
    }

    fn nested_default(&mut self, name: &TypeName, span: Span) {
        self.error(
            Code::MisplacedMember,
            span,
            format!("a field of the message type `{name}` cannot have a default value"),
        )
        .help =
            Some("only fields of primitive types (and arrays of them) have default values".into());
    }

    /// `[a, b, c]`, its element count checked against the type.
    fn array(
        &mut self,
        ty: &FieldType,
        cardinality: Cardinality,
        text: &str,
        span: Span,
    ) -> Option<Value> {
        let Some(inner) = text.strip_prefix('[').and_then(|t| t.strip_suffix(']')) else {
            self.error(
                Code::TypeMismatch,
                span,
                format!("the default of a `{ty}` is written `[a, b, ...]`"),
            );
            return None;
        };
        let inner_start = span.start + 1;
        let strings = matches!(ty.base, Base::String(_) | Base::WString(_));
        let elements = match split_elements(inner, strings) {
            Ok(elements) => elements,
            Err(at) => {
                let at = Span::new(inner_start + at, inner_start + at + 1);
                self.error(
                    Code::UnexpectedToken,
                    at,
                    "expected `,` or the end of the array after a quoted string",
                );
                return None;
            }
        };
        let count = elements.len() as u64;
        let wrong = match cardinality {
            Cardinality::Array(size) if count != size => Some(format!(
                "a `{ty}` has exactly {size} elements, this default {count}"
            )),
            Cardinality::Bounded(bound) if count > bound => Some(format!(
                "a `{ty}` has at most {bound} elements, this default {count}"
            )),
            _ => None,
        };
        if let Some(message) = wrong {
            self.error(Code::TypeMismatch, span, message);
            return None;
        }
        let mut values = Vec::with_capacity(elements.len());
        let mut failed = false;
        for (from, to) in elements {
            let at = Span::new(inner_start + from, inner_start + to);
            match self.scalar(&ty.base, &inner[from..to], at) {
                Some(value) => values.push(value),
                None => failed = true,
            }
        }
        (!failed).then_some(Value::Array(values))
    }

    /// One value of a base type (a constant's, a scalar default or an element).
    fn scalar(&mut self, base: &Base, text: &str, span: Span) -> Option<Value> {
        match base {
            Base::Byte
            | Base::Char
            | Base::Int8
            | Base::Uint8
            | Base::Int16
            | Base::Uint16
            | Base::Int32
            | Base::Uint32
            | Base::Int64
            | Base::Uint64 => self.integer(base, text, span),
            Base::Bool => match text.to_ascii_lowercase().as_str() {
                "true" | "1" => Some(Value::Bool(true)),
                "false" | "0" => Some(Value::Bool(false)),
                _ => {
                    self.error(
                        Code::TypeMismatch,
                        span,
                        format!("`{text}` is not a bool: write `true`, `false`, `1` or `0`"),
                    );
                    None
                }
            },
            Base::Float32 | Base::Float64 => {
                match text.parse::<f64>() {
                    // Rust's rule for a literal: it must not round to infinity.
                    Ok(value)
                        if *base == Base::Float32
                            && value.is_finite()
                            && (value as f32).is_infinite() =>
                    {
                        self.error(
                            Code::InvalidNumber,
                            span,
                            format!("`{text}` does not fit a `float32` (at most {:e})", f32::MAX),
                        );
                        None
                    }
                    Ok(value) => Some(Value::Float(value)),
                    Err(_) => {
                        self.error(
                        Code::TypeMismatch,
                        span,
                        format!("`{text}` is not a number (a `{base}` is, with `.` as the separator)"),
                    );
                        None
                    }
                }
            }
            Base::String(bound) | Base::WString(bound) => {
                let Some(value) = unquote(text) else {
                    self.error(
                        Code::TypeMismatch,
                        span,
                        "a quote inside a quoted string must be escaped with `\\`",
                    );
                    return None;
                };
                // ROS 2 bounds a string in bytes (a `char` is a byte).
                let length = value.len() as u64;
                if let Some(bound) = bound.filter(|bound| length > *bound) {
                    self.error(
                        Code::TypeMismatch,
                        span,
                        format!("this string has {length} bytes; a `{base}` holds at most {bound}"),
                    );
                    return None;
                }
                Some(Value::String(value))
            }
            Base::Nested(name) => {
                self.nested_default(name, span);
                None
            }
        }
    }

    fn integer(&mut self, base: &Base, text: &str, span: Span) -> Option<Value> {
        let (min, max) = base.integer_range().expect("an integer type has a range");
        let Some(value) = parse_integer(text) else {
            self.error(
                Code::TypeMismatch,
                span,
                format!("`{text}` is not an integer (a `{base}` is)"),
            );
            return None;
        };
        if value < min || value > max {
            self.error(
                Code::InvalidNumber,
                span,
                format!("`{text}` does not fit a `{base}` ({min} to {max})"),
            );
            return None;
        }
        Some(Value::Int(value))
    }

    /// A duplicate name is reported at its second definition.
    fn duplicates<'n>(&mut self, what: &str, items: impl Iterator<Item = (&'n String, Span)>) {
        let mut seen: HashMap<&str, Span> = HashMap::new();
        for (name, span) in items {
            if let Some(first) = seen.get(name.as_str()) {
                let first = *first;
                let diagnostic = Diagnostic::error(
                    Code::Duplicate,
                    self.file,
                    span,
                    format!("the {what} `{name}` is defined twice"),
                )
                .with_secondary(first, "first defined here");
                self.diagnostics.push(diagnostic);
            } else {
                seen.insert(name, span);
            }
        }
    }
}

/// The `.msg` type meant by a type name of another language.
fn alias(name: &str) -> Option<&'static str> {
    Some(match name {
        "float" => "float32",
        "double" => "float64",
        "int" => "int32",
        "uint" | "unsigned" => "uint32",
        "short" => "int16",
        "long" => "int64",
        "boolean" => "bool",
        "octet" => "byte",
        "str" => "string",
        _ => return None,
    })
}

/// An integer as Python's `int` reads it (rosidl's rule): decimal (leading zeros
/// allowed) or `0x`, `0o`, `0b` with a sign.
fn parse_integer(text: &str) -> Option<i128> {
    let (negative, digits) = match text.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, text.strip_prefix('+').unwrap_or(text)),
    };
    let lower = digits.to_ascii_lowercase();
    let (radix, digits) = [("0x", 16), ("0o", 8), ("0b", 2)]
        .iter()
        .find_map(|(prefix, radix)| lower.strip_prefix(prefix).map(|rest| (*radix, rest)))
        .unwrap_or((10, lower.as_str()));
    if digits.is_empty() || !digits.chars().all(|c| c.is_digit(radix)) {
        return None;
    }
    let value = i128::from_str_radix(digits, radix).ok()?;
    Some(if negative { -value } else { value })
}

/// A string value as rosidl reads it: quotes (`"` or `'`) around it are removed when
/// both ends have the same one, and then `\"` (or `\'`) stands for the quote. `None`
/// when an unescaped quote of that kind stands inside.
fn unquote(text: &str) -> Option<String> {
    for quote in ['"', '\''] {
        let Some(inner) = text.strip_prefix(quote).and_then(|t| t.strip_suffix(quote)) else {
            continue;
        };
        let mut out = String::with_capacity(inner.len());
        let mut chars = inner.chars().peekable();
        while let Some(c) = chars.next() {
            if c == '\\' && chars.peek() == Some(&quote) {
                out.push(quote);
                chars.next();
            } else if c == quote {
                return None;
            } else {
                out.push(c);
            }
        }
        return Some(out);
    }
    Some(text.to_owned())
}

/// The byte ranges of an array value's elements (trimmed), between its brackets. A
/// string element may be quoted and then hold commas; `Err` gives the offset of what
/// follows a closing quote when it is neither `,` nor the end.
fn split_elements(inner: &str, strings: bool) -> Result<Vec<(usize, usize)>, usize> {
    let mut elements = Vec::new();
    if inner.trim_matches(is_blank).is_empty() {
        return Ok(elements);
    }
    let skip_blanks = |from: usize| {
        inner[from..]
            .find(|c| !is_blank(c))
            .map_or(inner.len(), |i| from + i)
    };
    let mut at = 0;
    loop {
        let start = skip_blanks(at);
        let quote = inner[start..]
            .chars()
            .next()
            .filter(|c| strings && matches!(c, '"' | '\''));
        let end = match quote.and_then(|q| closing_quote(&inner[start..], q)) {
            Some(close) => {
                let end = start + close + 1;
                let next = skip_blanks(end);
                if next < inner.len() && !inner[next..].starts_with(',') {
                    return Err(next);
                }
                end
            }
            None => {
                let comma = inner[start..].find(',').map_or(inner.len(), |i| start + i);
                start + inner[start..comma].trim_end_matches(is_blank).len()
            }
        };
        elements.push((start, end));
        match inner[end..].find(',') {
            Some(comma) => at = end + comma + 1,
            None => return Ok(elements),
        }
    }
}

/// The offset of the quote closing the one that opens `text` (escapes skipped).
fn closing_quote(text: &str, quote: char) -> Option<usize> {
    let mut escaped = false;
    for (index, c) in text.char_indices().skip(1) {
        if escaped {
            escaped = false;
        } else if c == '\\' {
            escaped = true;
        } else if c == quote {
            return Some(index);
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integers_read_as_python_reads_them() {
        assert_eq!(parse_integer("42"), Some(42));
        assert_eq!(parse_integer("-0x10"), Some(-16));
        assert_eq!(parse_integer("+0b101"), Some(5));
        assert_eq!(parse_integer("0o17"), Some(15));
        assert_eq!(parse_integer("007"), Some(7));
        assert_eq!(parse_integer("1.5"), None);
        assert_eq!(parse_integer("0x"), None);
        assert_eq!(parse_integer(""), None);
    }

    #[test]
    fn comments_start_outside_quoted_values() {
        assert_eq!(comment_start("int32 a # x"), 8);
        assert_eq!(comment_start("string S=\"a#b\" # c"), 15);
        assert_eq!(comment_start("string s it's # c"), 14);
        assert_eq!(comment_start("string s 'a\\'#' #"), 16);
        assert_eq!(comment_start("int32 a"), 7);
    }

    #[test]
    fn string_elements_may_hold_commas_when_quoted() {
        let inner = r#" "a,b" , c ,'d' "#;
        let parts: Vec<&str> = split_elements(inner, true)
            .unwrap()
            .into_iter()
            .map(|(from, to)| &inner[from..to])
            .collect();
        assert_eq!(parts, [r#""a,b""#, "c", "'d'"]);
        assert_eq!(split_elements(r#""a" b"#, true), Err(4));
        assert_eq!(split_elements(" ", false), Ok(vec![]));
    }
}
