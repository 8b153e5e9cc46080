//! A type's full message definition as rosbag2 writes it in a bag (an MCAP schema of
//! encoding `ros2msg`): the type's own `.msg` text, then, for each type it references
//! directly or not and not written yet, a line of 80 `=`, a line `MSG: pkg/Type` and
//! that type's text. The order is rosbag2's (`LocalMessageDefinitionSource`): depth
//! first from the type, each type's references in the byte order of their names.

use std::collections::{BTreeSet, HashSet};

use super::msg::{Base, Message};
use super::names::TypeName;

/// The line between two definitions.
pub(crate) const SEPARATOR: &str =
    "================================================================================";

/// The full definition of `name`, from each type's message and `.msg` text given by
/// `get`; `None` when it, or a type it references, is not there.
pub(crate) fn full_text<'a>(
    name: &TypeName,
    get: &dyn Fn(&TypeName) -> Option<(&'a Message, &'a str)>,
) -> Option<String> {
    let mut seen = HashSet::new();
    let mut out = String::new();
    append(name, get, &mut seen, &mut out)?;
    Some(out)
}

fn append<'a>(
    name: &TypeName,
    get: &dyn Fn(&TypeName) -> Option<(&'a Message, &'a str)>,
    seen: &mut HashSet<TypeName>,
    out: &mut String,
) -> Option<()> {
    let (message, text) = get(name)?;
    out.push_str(text);
    // rosbag2 names a reference as the file writes it, with the package added to a
    // name of the same package: `pkg/Type`, sorted as strings.
    let references: BTreeSet<(String, &TypeName)> = message
        .fields
        .iter()
        .filter_map(|field| match &field.ty.base {
            Base::Nested(nested) => {
                Some((format!("{}/{}", nested.package(), nested.name()), nested))
            }
            _ => None,
        })
        .collect();
    for (written, nested) in references {
        if seen.insert(nested.clone()) {
            out.push('\n');
            out.push_str(SEPARATOR);
            out.push_str("\nMSG: ");
            out.push_str(&written);
            out.push('\n');
            append(nested, get, seen, out)?;
        }
    }
    Some(())
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;
    use crate::ast::FileId;
    use crate::ros::parse::parse;

    #[test]
    fn references_follow_depth_first_in_name_order_each_once() {
        let files = [
            ("a/msg/Top", "# top\nb/Mid mid\nZed z\nb/Leaf[] leaves\n"),
            ("b/msg/Mid", "b/Leaf leaf\nint8 x\n"),
            ("b/msg/Leaf", "float64 v\n"),
            ("a/msg/Zed", "string s\n"),
        ];
        let mut messages = BTreeMap::new();
        for (index, (name, text)) in files.into_iter().enumerate() {
            let name = TypeName::parse(name).unwrap();
            let file = FileId(u32::try_from(index).unwrap());
            let (message, diagnostics) = parse(&name, file, text);
            assert!(diagnostics.is_empty(), "{diagnostics:?}");
            messages.insert(name, (message, text));
        }
        let get = |name: &TypeName| messages.get(name).map(|(m, t)| (m, *t));
        let top = TypeName::parse("a/msg/Top").unwrap();
        let rule = "=".repeat(80);
        assert_eq!(
            full_text(&top, &get).unwrap(),
            format!(
                "# top\nb/Mid mid\nZed z\nb/Leaf[] leaves\n\
                 \n{rule}\nMSG: a/Zed\nstring s\n\
                 \n{rule}\nMSG: b/Leaf\nfloat64 v\n\
                 \n{rule}\nMSG: b/Mid\nb/Leaf leaf\nint8 x\n"
            )
        );
        let missing = TypeName::parse("a/msg/Missing").unwrap();
        assert_eq!(full_text(&missing, &get), None);
    }
}
