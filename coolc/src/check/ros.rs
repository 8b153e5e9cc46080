//! ROS imports (`import ros "pkg/msg/Type" [as Name];`): the name an import gives is
//! not a type of the language, and an alias follows the naming rules of types. Whether
//! the type exists and its `.msg` files are well formed (the type's own name follows
//! ROS 2's rules) is `crate::ros`'s to say (`resolve::load_ros`).

use super::Checker;
use crate::ast;
use crate::diagnostics::Code;

/// The types of the language, which a written type always means: an import named
/// like one could never be named.
const BUILTIN_TYPES: &[&str] = &[
    "bool", "i8", "i16", "i32", "i64", "u8", "u16", "u32", "u64", "f32", "f64", "String", "Time",
    "Duration",
];

/// Checks the name one `import ros` gives.
pub(super) fn import(checker: &mut Checker<'_, '_>, import: &ast::RosImport) {
    // Without a name, the type's name is malformed: `load_ros` reports it.
    let Some(name) = &import.name else {
        return;
    };
    if BUILTIN_TYPES.contains(&name.name.as_str()) {
        let own = ast::RosImport::own_name(&import.ros_name).map_or("Type".into(), |n| n.name);
        let diagnostic = checker
            .error(
                Code::Duplicate,
                name.span,
                format!(
                    "`{}` is a type of the language: the imported type needs another name",
                    name.name
                ),
            )
            .with_label(format!(
                "`{}` written as a type means the language's",
                name.name
            ))
            .with_help(format!(
                "name it with `as`: `import ros \"{}\" as Ros{own};`",
                import.ros_name.value
            ));
        checker.push(diagnostic);
        return;
    }
    if let Some(alias) = &import.alias {
        super::names::type_name(checker, alias);
    }
}
