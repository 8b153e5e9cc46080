//! ROS 2 names: the naming rules of packages, messages, fields and constants, and
//! [`TypeName`], the name of one message type.
//!
//! The rules are rosidl's (`rosidl_adapter.parser`):
//! - a package or field name is lower snake case: `[a-z][a-z0-9_]*`, with no `__`
//!   and no trailing `_`;
//! - a message name is upper camel case: `[A-Z][A-Za-z0-9]*`;
//! - a constant name is upper snake case: `[A-Z][A-Z0-9_]*`, with no `__` and no
//!   trailing `_`.

use std::fmt;
use std::path::PathBuf;

/// True for a valid package name (`sensor_msgs`).
pub(crate) fn is_package_name(name: &str) -> bool {
    snake(
        name,
        |c| c.is_ascii_lowercase(),
        |c| c.is_ascii_lowercase() || c.is_ascii_digit(),
    )
}

/// True for a valid field name (`angle_min`): the package rule.
pub(crate) fn is_field_name(name: &str) -> bool {
    is_package_name(name)
}

/// True for a valid constant name (`STATUS_FIX`).
pub(crate) fn is_constant_name(name: &str) -> bool {
    snake(
        name,
        |c| c.is_ascii_uppercase(),
        |c| c.is_ascii_uppercase() || c.is_ascii_digit(),
    )
}

/// True for a valid message name (`LaserScan`).
pub(crate) fn is_message_name(name: &str) -> bool {
    let mut chars = name.chars();
    chars.next().is_some_and(|c| c.is_ascii_uppercase()) && chars.all(|c| c.is_ascii_alphanumeric())
}

/// A first character `first` accepts, then characters `rest` accepts or `_`, never
/// two `_` in a row nor one at the end.
fn snake(name: &str, first: impl Fn(char) -> bool, rest: impl Fn(char) -> bool) -> bool {
    let mut chars = name.chars();
    if !chars.next().is_some_and(first) {
        return false;
    }
    let mut previous_underscore = false;
    for c in chars {
        if c == '_' {
            if previous_underscore {
                return false;
            }
            previous_underscore = true;
        } else if rest(c) {
            previous_underscore = false;
        } else {
            return false;
        }
    }
    !previous_underscore
}

/// The name of a message type: its package and its name (`sensor_msgs/msg/LaserScan`).
///
/// Both parts follow the naming rules: a `TypeName` is only made by
/// `TypeName::new` or [`TypeName::parse`], which check them.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct TypeName {
    package: String,
    name: String,
}

/// Why a text is not a message type name.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum BadTypeName {
    /// Not of the form `<package>/msg/<Type>`.
    #[error("`{0}` is not of the form `<package>/msg/<Type>`")]
    Form(String),
    /// The package part breaks the package naming rule.
    #[error("`{0}` is not a valid package name (lower snake case: `[a-z][a-z0-9_]*`)")]
    Package(String),
    /// The type part breaks the message naming rule.
    #[error("`{0}` is not a valid message name (upper camel case: `[A-Z][A-Za-z0-9]*`)")]
    Message(String),
}

impl TypeName {
    /// The type `name` of `package`, if both follow the naming rules.
    pub(crate) fn new(package: &str, name: &str) -> Result<TypeName, BadTypeName> {
        if !is_package_name(package) {
            return Err(BadTypeName::Package(package.to_owned()));
        }
        if !is_message_name(name) {
            return Err(BadTypeName::Message(name.to_owned()));
        }
        Ok(TypeName {
            package: package.to_owned(),
            name: name.to_owned(),
        })
    }

    /// Parses the full form, `<package>/msg/<Type>`.
    pub fn parse(text: &str) -> Result<TypeName, BadTypeName> {
        match text.split('/').collect::<Vec<_>>()[..] {
            [package, "msg", name] => TypeName::new(package, name),
            _ => Err(BadTypeName::Form(text.to_owned())),
        }
    }

    /// The package (`sensor_msgs`).
    pub(crate) fn package(&self) -> &str {
        &self.package
    }

    /// The type's own name (`LaserScan`).
    pub(crate) fn name(&self) -> &str {
        &self.name
    }

    /// The DDS type name, which rmw implementations put on the wire
    /// (`sensor_msgs::msg::dds_::LaserScan_`).
    pub fn dds_name(&self) -> String {
        format!("{}::msg::dds_::{}_", self.package, self.name)
    }

    /// The file's path below a root of interface packages (`sensor_msgs/msg/LaserScan.msg`).
    pub fn relative_path(&self) -> PathBuf {
        [&self.package, "msg", &format!("{}.msg", self.name)]
            .iter()
            .collect()
    }
}

/// The full form, `sensor_msgs/msg/LaserScan`: the type name of type descriptions.
impl fmt::Display for TypeName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/msg/{}", self.package, self.name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn package_and_field_names_are_lower_snake_case() {
        for good in ["a", "sensor_msgs", "a1", "x_2_y"] {
            assert!(is_package_name(good), "{good}");
        }
        for bad in ["", "A", "_a", "a_", "a__b", "1a", "aB", "a-b"] {
            assert!(!is_package_name(bad), "{bad}");
        }
    }

    #[test]
    fn constant_names_are_upper_snake_case() {
        for good in ["A", "FOO", "FOO_BAR", "A1", "X_2"] {
            assert!(is_constant_name(good), "{good}");
        }
        for bad in ["", "a", "_A", "A_", "A__B", "1A", "Ab"] {
            assert!(!is_constant_name(bad), "{bad}");
        }
    }

    #[test]
    fn message_names_are_upper_camel_case() {
        for good in ["A", "LaserScan", "Vector3", "ABC"] {
            assert!(is_message_name(good), "{good}");
        }
        for bad in ["", "laserScan", "Laser_Scan", "3D"] {
            assert!(!is_message_name(bad), "{bad}");
        }
    }

    #[test]
    fn type_names_print_their_full_and_dds_forms() {
        let name = TypeName::parse("sensor_msgs/msg/LaserScan").unwrap();
        assert_eq!(name.to_string(), "sensor_msgs/msg/LaserScan");
        assert_eq!(name.dds_name(), "sensor_msgs::msg::dds_::LaserScan_");
        assert_eq!(
            name.relative_path(),
            PathBuf::from("sensor_msgs/msg/LaserScan.msg")
        );
        assert_eq!(
            TypeName::parse("sensor_msgs/LaserScan"),
            Err(BadTypeName::Form("sensor_msgs/LaserScan".into()))
        );
        assert_eq!(
            TypeName::parse("Sensor/msg/LaserScan"),
            Err(BadTypeName::Package("Sensor".into()))
        );
        assert_eq!(
            TypeName::parse("sensor_msgs/msg/laser"),
            Err(BadTypeName::Message("laser".into()))
        );
    }
}
