//! Types and values: written types resolve, sizes are positive and bounded (what a
//! type holds inline, what a value builds), defaults match their declared type, timing
//! values are durations (or frequencies where a period is expected) and intervals are
//! ordered.

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
            array_size(checker, ty, inner, size);
        }
    }
}

/// The longest list a repeat default `[value; n]` of a list `[T]` builds, and the
/// most elements a value builds in all, nested lists and arrays counted together:
/// like a queue's size, allocated when the component starts.
pub(crate) const MAX_LIST_REPEAT: u64 = super::MAX_QUEUE_SIZE;

/// The most elements an array `[T; N]` holds, nested arrays and the packets it holds
/// counted together (`[[T; A]; B]` holds `A * B`, `[P; N]` holds `N` times what a
/// `P` holds): an array lives inline in its packet, on the stack of whoever builds
/// one.
pub(crate) const MAX_ARRAY_ELEMENTS: u64 = 1 << 16;

/// The most bytes a packet, a configuration block or a component's variables hold
/// inline. Each travels by value: a section that builds a packet and sends it holds
/// many copies of it on its thread's stack at once (about thirty in a debug build),
/// and a harness runs its component on the test's own thread, whose stack is Rust's
/// default 2 MiB. 32 KiB leaves room to spare there; larger data goes in lists, which
/// live on the heap.
pub(crate) const MAX_INLINE_BYTES: u64 = 32 << 10;

/// The most bytes a fifo's or a ufifo's initial queue takes, its size times its
/// packet's inline bytes: the queue is allocated whole.
pub(crate) const MAX_QUEUE_BYTES: u64 = 1 << 30;

/// About how many bytes a packet of type `ty` takes in a queue (inline, as
/// [`inline_bytes`] counts them; at least one).
pub(super) fn packet_size_of(checker: &mut Checker<'_, '_>, ty: &ast::Type) -> u128 {
    inline_bytes(checker, ty).max(1)
}

/// About how many bytes a value of `ty` takes inline, an upper bound where the layout
/// is Rust's to choose: a `String` or a list is three words, a `Time` or a `Duration`
/// 16 bytes, an optional its value and a word, an enum a word, a packet its fields
/// together rounded up to its alignment (as an array's elements are laid out, a packet
/// of a `u64` and a `bool` takes 16 bytes, not 9); a ROS message its fields as the
/// struct coolc generates for it holds them; an extern packet counts nothing (its size
/// is its own type's, not the description's).
fn inline_bytes(checker: &mut Checker<'_, '_>, ty: &ast::Type) -> u128 {
    inline_layout(checker, ty).0
}

/// The bytes a value of `ty` takes inline (as [`inline_bytes`]) and its alignment.
/// Every size is a multiple of its alignment, as Rust's are.
fn inline_layout(checker: &mut Checker<'_, '_>, ty: &ast::Type) -> (u128, u128) {
    match &ty.kind {
        ast::TypeKind::Prim(prim) => match prim {
            ast::Prim::Bool | ast::Prim::I8 | ast::Prim::U8 => (1, 1),
            ast::Prim::I16 | ast::Prim::U16 => (2, 2),
            ast::Prim::I32 | ast::Prim::U32 | ast::Prim::F32 => (4, 4),
            ast::Prim::I64 | ast::Prim::U64 | ast::Prim::F64 => (8, 8),
            ast::Prim::Time | ast::Prim::Duration => (16, 8),
            ast::Prim::String => (24, 8),
        },
        ast::TypeKind::List(_) => (24, 8),
        ast::TypeKind::Array(inner, size) => {
            let (bytes, align) = inline_layout(checker, inner);
            (u128::from(size.value).saturating_mul(bytes), align)
        }
        // A word more keeps the size a multiple of the alignment (at most a word).
        ast::TypeKind::Optional(inner) => {
            let (bytes, align) = inline_layout(checker, inner);
            (bytes.saturating_add(8), align)
        }
        ast::TypeKind::Named(name) => packet_layout(checker, &name.name),
    }
}

/// About how many bytes the packet or enum named `name` takes inline and its
/// alignment, counted once per packet; any other type counts nothing.
fn packet_layout(checker: &mut Checker<'_, '_>, name: &str) -> (u128, u128) {
    if let Some(known) = checker.packet_layouts.get(name) {
        return *known;
    }
    let model = checker.model;
    let item = model.symbols.defs.get(name).and_then(|def| {
        model
            .files
            .get(def.file.0 as usize)
            .and_then(|file| file.items.get(def.item))
    });
    let packet = match item {
        Some(ast::Item::Packet(packet)) => packet,
        Some(ast::Item::Enum(_)) => return (8, 8),
        Some(ast::Item::RosImport(import)) => {
            return crate::ros::TypeName::parse(&import.ros_name.value)
                .map_or((0, 1), |ros| ros_bytes(checker, &ros));
        }
        _ => return (0, 1),
    };
    // A packet holding itself by value is an error of its own: it counts nothing inside.
    checker.packet_layouts.insert(name.to_owned(), (0, 1));
    let mut total = 0u128;
    let mut align = 1u128;
    for field in &packet.fields {
        let (bytes, field_align) = inline_layout(checker, &field.ty);
        total = total.saturating_add(bytes);
        align = align.max(field_align);
    }
    let layout = (total.div_ceil(align).saturating_mul(align), align);
    checker.packet_layouts.insert(name.to_owned(), layout);
    layout
}

/// About how many bytes the ROS 2 message `name` takes inline and its alignment, as
/// the struct coolc generates for it lays it out (`T[N]` an array, `T[<=N]` and `T[]`
/// a `Vec`, a string a `String`), counted once per type; a type not loaded counts
/// nothing (it is reported where it is imported).
fn ros_bytes(checker: &mut Checker<'_, '_>, name: &crate::ros::TypeName) -> (u128, u128) {
    use crate::ros::msg::{Base, Cardinality};
    let key = format!("ros {name}");
    if let Some(known) = checker.packet_layouts.get(&key) {
        return *known;
    }
    let ros = checker.ros;
    let Some(message) = ros.get(name) else {
        return (0, 1);
    };
    // `.msg` files cannot refer to themselves (a cycle is reported when loading).
    checker.packet_layouts.insert(key.clone(), (0, 1));
    let mut total = 0u128;
    let mut align = 1u128;
    for field in &message.fields {
        let (bytes, field_align) = match field.ty.cardinality {
            Cardinality::Bounded(_) | Cardinality::Unbounded => (24, 8),
            Cardinality::Single | Cardinality::Array(_) => {
                let (bytes, field_align) = match &field.ty.base {
                    Base::Bool | Base::Byte | Base::Char | Base::Int8 | Base::Uint8 => (1, 1),
                    Base::Int16 | Base::Uint16 => (2, 2),
                    Base::Int32 | Base::Uint32 | Base::Float32 => (4, 4),
                    Base::Int64 | Base::Uint64 | Base::Float64 => (8, 8),
                    Base::String(_) | Base::WString(_) => (24, 8),
                    Base::Nested(nested) => ros_bytes(checker, nested),
                };
                match field.ty.cardinality {
                    Cardinality::Array(size) => {
                        (u128::from(size).saturating_mul(bytes), field_align)
                    }
                    _ => (bytes, field_align),
                }
            }
        };
        total = total.saturating_add(bytes);
        align = align.max(field_align);
    }
    let layout = (total.div_ceil(align).saturating_mul(align), align);
    checker.packet_layouts.insert(key, layout);
    layout
}

/// The elements a value of `ty` holds inline: the product of its nested array
/// lengths, a packet counting what its fields hold (through optionals; a list is a
/// heap allocation and counts one, as does any other type). `None` when something
/// in it is refused for its size already (an array or a packet beyond its bound),
/// so nothing holding it is reported again.
fn inline_elements(checker: &mut Checker<'_, '_>, ty: &ast::Type) -> Option<u128> {
    match &ty.kind {
        ast::TypeKind::Array(inner, size) => {
            if size.value > MAX_ARRAY_ELEMENTS {
                return None;
            }
            let total = u128::from(size.value).saturating_mul(inline_elements(checker, inner)?);
            (total <= u128::from(MAX_ARRAY_ELEMENTS)).then_some(total)
        }
        ast::TypeKind::Optional(inner) => inline_elements(checker, inner),
        ast::TypeKind::Named(name) => packet_elements(checker, &name.name),
        ast::TypeKind::Prim(_) | ast::TypeKind::List(_) => Some(1),
    }
}

/// The packet named `name`, if a packet has that name.
fn packet_def<'a>(checker: &Checker<'a, '_>, name: &str) -> Option<&'a ast::Packet> {
    let model = checker.model;
    let def = model.symbols.defs.get(name)?;
    match model
        .files
        .get(def.file.0 as usize)
        .and_then(|file| file.items.get(def.item))
    {
        Some(ast::Item::Packet(packet)) => Some(packet),
        _ => None,
    }
}

/// The elements packet `name` holds inline (at least one), counted once per packet;
/// any other type counts one.
fn packet_elements(checker: &mut Checker<'_, '_>, name: &str) -> Option<u128> {
    if let Some(known) = checker.packet_elements.get(name) {
        return *known;
    }
    let Some(packet) = packet_def(checker, name) else {
        return Some(1);
    };
    // A packet holding itself by value is an error of its own: it counts one inside.
    checker.packet_elements.insert(name.to_owned(), Some(1));
    let total = fields_elements(checker, &packet.fields)
        .map(|total| total.max(1))
        .filter(|_| packet_layout(checker, name).0 <= u128::from(MAX_INLINE_BYTES));
    checker.packet_elements.insert(name.to_owned(), total);
    total
}

/// The elements `fields` hold inline together; `None` when a field is refused for its
/// size already.
fn fields_elements(checker: &mut Checker<'_, '_>, fields: &[ast::Field]) -> Option<u128> {
    let mut total = 0u128;
    for field in fields {
        total = total.saturating_add(inline_elements(checker, &field.ty)?);
    }
    Some(total)
}

/// The factors of what an array type holds, outermost first, for a message:
/// `[[Row; 4]; 8]` is 8 × 4 × 65536 (a `Row`).
fn array_factors(checker: &mut Checker<'_, '_>, ty: &ast::Type, factors: &mut Vec<String>) {
    match &ty.kind {
        ast::TypeKind::Array(inner, size) => {
            factors.push(size.value.to_string());
            array_factors(checker, inner, factors);
        }
        ast::TypeKind::Optional(inner) => array_factors(checker, inner, factors),
        ast::TypeKind::Named(name) => {
            if let Some(elements) = packet_elements(checker, &name.name)
                && elements > 1
            {
                factors.push(format!("{elements} (a `{}`)", name.name));
            }
        }
        ast::TypeKind::Prim(_) | ast::TypeKind::List(_) => {}
    }
}

/// `[T; N]` holds at most [`MAX_ARRAY_ELEMENTS`], nested arrays and packets counted
/// together; reported once, at the outermost array that goes beyond.
fn array_size(
    checker: &mut Checker<'_, '_>,
    ty: &ast::Type,
    inner: &ast::Type,
    size: &ast::IntLit,
) {
    let max = MAX_ARRAY_ELEMENTS;
    if size.value > max {
        let diagnostic = checker
            .error(
                Code::SizeLimit,
                size.span,
                format!("an array length is at most {max}"),
            )
            .with_label("too long: an array lives inline, on the stack of whoever builds it")
            .with_help("use a list `[T]`, which lives on the heap and has no fixed length");
        checker.push(diagnostic);
        return;
    }
    let Some(inner_elements) = inline_elements(checker, inner) else {
        // Reported inside already.
        return;
    };
    let elements = u128::from(size.value).saturating_mul(inner_elements);
    if elements > u128::from(max) {
        let mut factors = Vec::new();
        array_factors(checker, ty, &mut factors);
        let diagnostic = checker
            .error(
                Code::SizeLimit,
                ty.span,
                format!(
                    "an array holds at most {max} elements, nested arrays and packets counted together"
                ),
            )
            .with_label(format!("{} = {elements} elements", factors.join(" × ")))
            .with_help("use a list `[T]` for the outer level, which lives on the heap");
        checker.push(diagnostic);
    }
}

/// A packet takes at most [`MAX_INLINE_BYTES`] inline, its fields counted together.
pub(super) fn packet_size(checker: &mut Checker<'_, '_>, packet: &ast::Packet) {
    record_size(
        checker,
        &packet.fields,
        packet.name.span,
        &format!("packet `{}` holds", packet.name.name),
    );
}

/// A configuration block takes at most [`MAX_INLINE_BYTES`] inline, its fields
/// counted together.
pub(super) fn configuration_size(
    checker: &mut Checker<'_, '_>,
    configuration: &ast::Configuration,
) {
    // The keyword, not the whole block: the largest field is labelled apart.
    let keyword = Span::new(
        configuration.span.start,
        (configuration.span.start + "configuration".len()).min(configuration.span.end),
    );
    record_size(
        checker,
        &configuration.fields,
        keyword,
        "a configuration block holds",
    );
}

/// A component's variables, held together in one record (its `Vars`, built with
/// `Default` as a configuration block is), take at most [`MAX_INLINE_BYTES`] inline,
/// counted together.
pub(super) fn variables_size(checker: &mut Checker<'_, '_>, component: &ast::Component) {
    let mut sizes = Vec::new();
    let mut types = Vec::new();
    for member in &component.members {
        let ast::Member::Variable(variable) = member else {
            continue;
        };
        let Some(ty) = &variable.ty else {
            continue;
        };
        if inline_elements(checker, ty).is_none() {
            // Reported inside already.
            return;
        }
        sizes.push((&variable.name, inline_bytes(checker, ty)));
        types.push(ty);
    }
    let what = format!("the variables of component `{}` hold", component.name.name);
    let why = "its variables together: they are one record, built on the stack of whoever makes the component";
    bytes_refused(
        checker,
        &sizes,
        &types,
        component.name.span,
        &what,
        why,
        "variable",
    );
}

fn record_size(checker: &mut Checker<'_, '_>, fields: &[ast::Field], span: Span, what: &str) {
    if fields_elements(checker, fields).is_none() {
        // Reported inside already.
        return;
    }
    let types: Vec<&ast::Type> = fields.iter().map(|field| &field.ty).collect();
    let sizes: Vec<(&ast::Ident, u128)> = fields
        .iter()
        .map(|field| (&field.name, inline_bytes(checker, &field.ty)))
        .collect();
    let why = "its fields together: it travels by value, and a thread's stack holds many copies of it at once";
    bytes_refused(checker, &sizes, &types, span, what, why, "field");
}

/// Whether any of `types` holds a packet that contains itself by value
/// ([`holds_self_containing`]).
fn holds_any_self_containing(checker: &Checker<'_, '_>, types: &[&ast::Type]) -> bool {
    let mut visited = std::collections::BTreeSet::new();
    types
        .iter()
        .any(|ty| holds_self_containing(checker, ty, &mut visited))
}

/// Reports `what` (a subject and its verb) if its members, of `sizes` bytes inline
/// each, hold more than [`MAX_INLINE_BYTES`] together: at `span`, labelled `why`, and
/// at the largest `member`; not if one of their `types` holds a packet that contains
/// itself (its size means nothing).
fn bytes_refused(
    checker: &mut Checker<'_, '_>,
    sizes: &[(&ast::Ident, u128)],
    types: &[&ast::Type],
    span: Span,
    what: &str,
    why: &str,
    member: &str,
) {
    let max = MAX_INLINE_BYTES;
    let total = sizes
        .iter()
        .fold(0u128, |total, (_, bytes)| total.saturating_add(*bytes));
    let Some((largest, most)) = sizes
        .iter()
        .copied()
        .reduce(|a, b| if b.1 > a.1 { b } else { a })
    else {
        return;
    };
    if total <= u128::from(max) || holds_any_self_containing(checker, types) {
        return;
    }
    let diagnostic = checker
        .error(
            Code::SizeLimit,
            span,
            format!(
                "{what} about {total} bytes inline, more than {max} ({} KiB)",
                max >> 10
            ),
        )
        .with_label(why)
        .with_secondary(
            largest.span,
            format!("the largest {member}: about {most} bytes"),
        )
        .with_help(format!(
            "hold such data as `{}` in lists (`[T]`), which live on the heap",
            largest.name
        ));
    checker.push(diagnostic);
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

/// The Rust path of an extern packet is a Rust type as rustc reads it (`syn` parses
/// it): a path (a leading `::`, `crate::`, `self::` or `super::` allowed, never
/// `Self`), with generic arguments that are types, lifetimes or constants, or a
/// tuple, an array or a slice of such types; no reference, pointer, trait object or
/// function type.
pub(super) fn extern_path(checker: &mut Checker<'_, '_>, def: &ast::ExternPacket) {
    if let Err(why) = rust_type_path(&def.rust_path.value) {
        let diagnostic = checker
            .error(
                Code::TypeMismatch,
                def.rust_path.span,
                format!("`{}` is not a Rust type path", def.rust_path.value),
            )
            .with_label(why)
            .with_help(
                "write a path such as \"image::RgbImage\" or \"pcl::PointCloud<pcl::PointXYZ>\"",
            );
        checker.push(diagnostic);
    }
}

/// `Ok` when `text` is a Rust type an extern packet can name (parsed by `syn`, as
/// rustc would), else why not.
fn rust_type_path(text: &str) -> Result<(), String> {
    if text.trim().is_empty() {
        return Err("empty: name a type".to_owned());
    }
    // (Rust's whitespace is ASCII here: a no-break space is not a gap to rustc.)
    if let Some(c) = text
        .chars()
        .find(|c| c.is_whitespace() && !c.is_ascii_whitespace())
    {
        return Err(format!(
            "`{}` (U+{:04X}) is no space rustc reads",
            c,
            u32::from(c)
        ));
    }
    let ty: syn::Type =
        syn::parse_str(text).map_err(|error| format!("not a Rust type: {error}"))?;
    packet_type(&ty, 0)
}

/// `Ok` when `ty` (at nesting `depth`) can be a packet's type: a path (no `Self`,
/// ending in a name), a tuple, an array or a slice of those, with generic arguments
/// that are types, lifetimes or constants.
fn packet_type(ty: &syn::Type, depth: usize) -> Result<(), String> {
    if depth > 32 {
        return Err("nested more than 32 deep".to_owned());
    }
    match ty {
        syn::Type::Path(path) if path.qself.is_none() => {
            let segments = &path.path.segments;
            if segments.first().is_some_and(|s| s.ident == "Self") {
                return Err("`Self` names no type outside an impl".to_owned());
            }
            let last = segments.last().ok_or("expected a name")?;
            if ["crate", "self", "super", "Self"]
                .iter()
                .any(|k| last.ident == k)
            {
                return Err(format!("`{}` names a module, not a type", last.ident));
            }
            for segment in segments {
                match &segment.arguments {
                    syn::PathArguments::None => {}
                    syn::PathArguments::AngleBracketed(arguments) => {
                        if arguments.colon2_token.is_some() {
                            return Err(
                                "write generic arguments without `::` (`Vec<u8>`)".to_owned()
                            );
                        }
                        for argument in &arguments.args {
                            match argument {
                                syn::GenericArgument::Type(ty) => packet_type(ty, depth + 1)?,
                                syn::GenericArgument::Lifetime(_)
                                | syn::GenericArgument::Const(_) => {}
                                _ => {
                                    return Err(
                                        "a generic argument is a type, a lifetime or a constant"
                                            .to_owned(),
                                    );
                                }
                            }
                        }
                    }
                    syn::PathArguments::Parenthesized(_) => {
                        return Err("a function trait is no packet type".to_owned());
                    }
                }
            }
            Ok(())
        }
        syn::Type::Tuple(tuple) => tuple
            .elems
            .iter()
            .try_for_each(|ty| packet_type(ty, depth + 1)),
        syn::Type::Array(array) => packet_type(&array.elem, depth + 1),
        syn::Type::Slice(slice) => packet_type(&slice.elem, depth + 1),
        syn::Type::Paren(paren) => packet_type(&paren.elem, depth + 1),
        syn::Type::Reference(_) | syn::Type::Ptr(_) => {
            Err("a packet owns its data: no reference or pointer".to_owned())
        }
        _ => Err("name a type by its path (`image::RgbImage`)".to_owned()),
    }
}

/// Checks that `expr` is a literal of type `expected`.
pub(super) fn value(checker: &mut Checker<'_, '_>, expr: &ast::Expr, expected: &Ty) {
    if let Err(error) = value_error(checker, expr, expected) {
        let diagnostic = error.diagnostic(checker);
        checker.push(diagnostic);
    }
}

/// Like [`value`], with `note` as the help of the error (why `expected` is asked),
/// for a value that must be of each of `expected`: the first type it does not fit
/// is reported, once.
pub(super) fn value_of_each(
    checker: &mut Checker<'_, '_>,
    expr: &ast::Expr,
    expected: &[&Ty],
    note: &str,
) {
    let before = checker.diagnostics.len();
    for ty in expected {
        let seen = checker.diagnostics.len();
        let result = value_error(checker, expr, ty);
        // What a check reports on the way (a repeat count, a size) an earlier type's
        // check may have reported already.
        let mut index = seen;
        while index < checker.diagnostics.len() {
            if checker.diagnostics[before..seen].contains(&checker.diagnostics[index]) {
                checker.diagnostics.remove(index);
            } else {
                index += 1;
            }
        }
        if let Err(mut error) = result {
            error.help = Some(note.to_owned());
            let diagnostic = error.diagnostic(checker);
            checker.push(diagnostic);
            return;
        }
    }
}

/// A value refused for its type: where, why, and what to do. Each is said of the
/// value refused, an element of a list as much as a whole value.
struct ValueError {
    span: Span,
    message: String,
    label: String,
    help: Option<String>,
}

impl ValueError {
    /// A value refused for `expected`, the type asked of it where it stands.
    fn new(span: Span, message: impl Into<String>, expected: &Ty, help: Option<String>) -> Self {
        ValueError {
            span,
            message: message.into(),
            label: format!("expected `{expected}`"),
            help,
        }
    }

    fn diagnostic(self, checker: &Checker<'_, '_>) -> crate::diagnostics::Diagnostic {
        let mut diagnostic = checker
            .error(Code::TypeMismatch, self.span, self.message)
            .with_label(self.label);
        if let Some(help) = self.help {
            diagnostic = diagnostic.with_help(help);
        }
        diagnostic
    }
}

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
    ValueError::new(
        expr.span,
        format!(
            "expected a value of type `{expected}`, found {}",
            describe(expr)
        ),
        expected,
        help,
    )
}

fn value_error(
    checker: &mut Checker<'_, '_>,
    expr: &ast::Expr,
    expected: &Ty,
) -> Result<(), ValueError> {
    use ast::ExprKind as E;
    let refused = |message: String| ValueError::new(expr.span, message, expected, None);
    if let Some(error) = double_negation(expr) {
        return Err(error);
    }
    match (expected, &expr.kind) {
        (Ty::Unknown, _) => Ok(()),
        (Ty::Optional(_), E::None) => Ok(()),
        (Ty::Optional(inner), _) => value_error(checker, expr, inner),
        (Ty::Bool, E::Bool(_)) | (Ty::Str, E::Str(_)) | (Ty::Duration, E::Duration(_)) => Ok(()),
        (Ty::Float(prim), E::Float(value)) => float_fits(*prim, *value).map_err(refused),
        (Ty::Float(prim), E::Unary(ast::UnaryOp::Neg, inner)) => match inner.kind {
            E::Float(value) => float_fits(*prim, -value).map_err(refused),
            // An integer literal is a whole float, within any float's range.
            E::Int(_) => Ok(()),
            _ => Err(mismatch(expr, expected, None)),
        },
        // An integer literal is a whole float: `max_speed: f64 = 1` means `1.0`.
        (Ty::Float(_), E::Int(_)) => Ok(()),
        (Ty::Int(prim), E::Int(n)) => int_fits(*prim, i128::from(*n)).map_err(refused),
        (Ty::Int(prim), E::Unary(ast::UnaryOp::Neg, inner)) => match inner.kind {
            E::Int(n) => int_fits(*prim, -i128::from(n)).map_err(refused),
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
            built_size(checker, expr, expected);
            for item in items {
                value_error(checker, item, inner)?;
            }
            Ok(())
        }
        (Ty::List(inner), E::Repeat(item, count)) => {
            positive(checker, count, "a repeat count");
            // Allocated when the value is built (a default, when the component starts).
            if count.value > MAX_LIST_REPEAT {
                let diagnostic = checker
                    .error(
                        Code::SizeLimit,
                        count.span,
                        format!("a list's repeat count is at most {MAX_LIST_REPEAT}"),
                    )
                    .with_label("too many: the list is allocated when its value is built")
                    .with_help("start with a shorter list: a list grows at run time");
                checker.push(diagnostic);
            } else {
                built_size(checker, expr, expected);
            }
            value_error(checker, item, inner)
        }
        (Ty::Array(inner, length), E::List(items)) => {
            built_size(checker, expr, expected);
            if items.len() as u64 != *length {
                return Err(ValueError::new(
                    expr.span,
                    format!(
                        "expected {length} elements for `{expected}`, found {}",
                        items.len()
                    ),
                    expected,
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
                return Err(ValueError::new(
                    count.span,
                    format!(
                        "expected {length} elements for `{expected}`, found {}",
                        count.value
                    ),
                    expected,
                    Some(format!("write `{length}`")),
                ));
            }
            built_size(checker, expr, expected);
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

/// The elements a list or array value builds, its nested lists and arrays counted
/// together (a repeat `[v; n]` builds `n` times what `v` builds, a literal the sum of
/// its elements' or one when empty, any other value one); `None` when it, or a value
/// in it, builds more than [`MAX_LIST_REPEAT`] (reported there).
fn built_elements(expr: &ast::Expr) -> Option<u128> {
    let total = match &expr.kind {
        ast::ExprKind::Repeat(item, count) => {
            if count.value > MAX_LIST_REPEAT {
                return None;
            }
            u128::from(count.value).saturating_mul(built_elements(item)?)
        }
        ast::ExprKind::List(items) => items.iter().try_fold(0u128, |sum, item| {
            Some(sum.saturating_add(built_elements(item)?))
        })?,
        _ => 1,
    };
    // An empty list still takes its place in the list holding it: `[[]; n]` builds
    // `n` (empty) lists.
    let total = total.max(1);
    (total <= u128::from(MAX_LIST_REPEAT)).then_some(total)
}

/// Whether `ty` holds an array type refused for its size ([`array_size`]): a value
/// of it is not counted, the type's error being the one to fix.
fn holds_refused_array(ty: &Ty) -> bool {
    /// The elements an array type holds inline, through optionals.
    fn inline(ty: &Ty) -> u128 {
        match ty {
            Ty::Array(inner, length) => u128::from(*length).saturating_mul(inline(inner)),
            Ty::Optional(inner) => inline(inner),
            _ => 1,
        }
    }
    match ty {
        Ty::Array(inner, _) => {
            inline(ty) > u128::from(MAX_ARRAY_ELEMENTS) || holds_refused_array(inner)
        }
        Ty::List(inner) | Ty::Optional(inner) => holds_refused_array(inner),
        _ => false,
    }
}

/// A list or array value builds at most [`MAX_LIST_REPEAT`] elements, nested lists
/// and arrays counted together (all are allocated when the value is built);
/// reported once, at the outermost value that goes beyond, and not for a value of
/// a type refused for its size already.
fn built_size(checker: &mut Checker<'_, '_>, expr: &ast::Expr, expected: &Ty) {
    let max = MAX_LIST_REPEAT;
    if holds_refused_array(expected) {
        return;
    }
    let (total, product) = match &expr.kind {
        ast::ExprKind::Repeat(item, count) if count.value <= max => {
            let Some(item_elements) = built_elements(item) else {
                return;
            };
            // The counts of the repeats nested in the first position, outermost first.
            let mut factors = vec![count.value.to_string()];
            let mut inner = &**item;
            while let ast::ExprKind::Repeat(next, count) = &inner.kind {
                factors.push(count.value.to_string());
                inner = next;
            }
            if let Some(rest) = built_elements(inner).filter(|n| *n > 1) {
                factors.push(rest.to_string());
            }
            let total = u128::from(count.value).saturating_mul(item_elements);
            (total, factors.join(" × "))
        }
        ast::ExprKind::List(items) => {
            let Some(parts) = items
                .iter()
                .map(built_elements)
                .collect::<Option<Vec<u128>>>()
            else {
                return;
            };
            let total = parts.iter().fold(0u128, |sum, n| sum.saturating_add(*n));
            let mut terms: Vec<String> = parts.iter().take(3).map(u128::to_string).collect();
            if parts.len() > 3 {
                terms.push(format!("... ({} values)", parts.len()));
            }
            (total, terms.join(" + "))
        }
        _ => return,
    };
    if total <= u128::from(max) {
        return;
    }
    let diagnostic = checker
        .error(
            Code::SizeLimit,
            expr.span,
            format!(
                "a value builds at most {max} elements, nested lists and arrays counted together"
            ),
        )
        .with_label(format!(
            "{product} = {total} elements, allocated when the value is built"
        ))
        .with_help("start with shorter lists: a list grows at run time");
    checker.push(diagnostic);
}

/// A `-` applied to a negated value (`- -5`, `-(-5)`): a constant is written with at
/// most one sign.
fn double_negation(expr: &ast::Expr) -> Option<ValueError> {
    let ast::ExprKind::Unary(ast::UnaryOp::Neg, inner) = &expr.kind else {
        return None;
    };
    let mut negations = 1usize;
    let mut operand = &**inner;
    while let ast::ExprKind::Unary(ast::UnaryOp::Neg, next) = &operand.kind {
        negations += 1;
        operand = next;
    }
    if negations < 2 {
        return None;
    }
    let text = match &operand.kind {
        ast::ExprKind::Int(n) => Some(n.to_string()),
        ast::ExprKind::Float(x) => Some(format!("{x:?}")),
        _ => None,
    };
    let help = match text {
        Some(text) if negations.is_multiple_of(2) => format!("write `{text}`"),
        Some(text) => format!("write `-{text}`"),
        None => "write the value with at most one `-`".to_owned(),
    };
    Some(ValueError {
        span: expr.span,
        message: format!("a constant takes at most one `-`, found {negations} in a row"),
        label: "more than one sign".to_owned(),
        help: Some(help),
    })
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

/// The highest frequency a period can be (its period, 0.5ns, rounds to 1ns), as
/// written in a description.
pub(crate) const HIGHEST_FREQUENCY: &str = "2000MHz";

/// About the lowest frequency a period can be (its period, about 1.8416e19ns, is
/// within 64 bits of nanoseconds; the lowest is 5.421010862427522e-11Hz), as written
/// in a description: a frequency takes no exponent.
pub(crate) const LOWEST_FREQUENCY: &str = "0.0000000000543Hz";

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
            let nanos = 1e9 / hertz;
            // The runtime counts time in u64 nanoseconds, down to one.
            #[allow(clippy::cast_precision_loss)] // A bound, compared as a float.
            let longest = u64::MAX as f64;
            let refused = if nanos.round() < 1.0 {
                Some(format!(
                    "shorter than 1ns (the highest frequency is `{HIGHEST_FREQUENCY}`)"
                ))
            } else if nanos >= longest {
                Some(format!(
                    "longer than 18446744073709551615ns, about 584 years (the lowest frequency is about `{LOWEST_FREQUENCY}`)"
                ))
            } else {
                None
            };
            if let Some(range) = refused {
                let diagnostic = checker
                    .error(
                        Code::SizeLimit,
                        expr.span,
                        if hertz.is_finite() {
                            format!("the period of `{hertz}Hz` is {range}")
                        } else {
                            format!("the period of this frequency is {range}")
                        },
                    )
                    .with_label("out of range: the runtime counts a period in whole nanoseconds, in 64 bits")
                    .with_help("give a period from 1ns to about 584 years, such as `10ms` or `100Hz`");
                checker.push(diagnostic);
                return None;
            }
            Some(nanos)
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
/// cycle): the generated struct would be infinitely large. True if it was reported
/// (its size means nothing then).
pub(super) fn recursive_packet(checker: &mut Checker<'_, '_>, packet: &ast::Packet) -> bool {
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
            return true;
        }
    }
    false
}

/// Whether a value of `ty` holds, by value, a packet that contains itself: its size
/// means nothing (that packet's own `recursive_packet` error says why), so nothing
/// holding it gets a size error too.
fn holds_self_containing(
    checker: &Checker<'_, '_>,
    ty: &ast::Type,
    visited: &mut std::collections::BTreeSet<String>,
) -> bool {
    match &ty.kind {
        ast::TypeKind::Prim(_) | ast::TypeKind::List(_) => false,
        ast::TypeKind::Array(inner, _) | ast::TypeKind::Optional(inner) => {
            holds_self_containing(checker, inner, visited)
        }
        ast::TypeKind::Named(name) => {
            if !visited.insert(name.name.clone()) {
                return false;
            }
            let Some(packet) = packet_def(checker, &name.name) else {
                return false;
            };
            let contains_itself = packet.fields.iter().any(|field| {
                contains_by_value(
                    checker,
                    &field.ty,
                    &name.name,
                    &mut Vec::new(),
                    &mut std::collections::BTreeSet::new(),
                )
            });
            contains_itself
                || packet
                    .fields
                    .iter()
                    .any(|field| holds_self_containing(checker, &field.ty, visited))
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

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::{HIGHEST_FREQUENCY, LOWEST_FREQUENCY};

    /// The codes of the diagnostics of a component whose period is `period`.
    fn period_codes(period: &str) -> Vec<&'static str> {
        let text = format!(
            "atomic A {{ timing {{ period {period}; }} automaton {{ initial s; state s {{ periodic; }} }} }}\n"
        );
        let analysis = crate::analyze(&["a.cool"], &|_: &Path| Ok(text.clone()));
        analysis
            .diagnostics
            .iter()
            .map(|d| d.code.as_str())
            .collect()
    }

    /// The frequencies the refusal names as the bounds are written as a description
    /// writes them, and are the bounds: accepted, and refused just beyond.
    #[test]
    fn the_frequency_bounds_named_are_valid_and_accepted() {
        assert_eq!(period_codes(HIGHEST_FREQUENCY), Vec::<&str>::new());
        assert_eq!(period_codes(LOWEST_FREQUENCY), Vec::<&str>::new());
        assert_eq!(period_codes("2001MHz"), ["coolc::check::size_limit"]);
        assert_eq!(
            period_codes("0.0000000000542Hz"),
            ["coolc::check::size_limit"]
        );
    }
}
