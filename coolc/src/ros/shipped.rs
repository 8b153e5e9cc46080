//! The interface definitions coolc ships: the common types its examples and tests
//! use, written from the ROS 2 interface definitions (field names, types, order and
//! constants as there) and compiled into the binary, so that coolc reads them with no
//! ROS installed. They are the last place a type is looked up (see
//! `lookup`); the files are under `coolc/interfaces/<package>/msg/`.

use super::names::TypeName;
use crate::diagnostics::closest;

/// Every shipped type: its package, its name and its `.msg` text, by package and name.
pub(crate) const SHIPPED: &[(&str, &str, &str)] = &[
    (
        "builtin_interfaces",
        "Duration",
        include_str!("../../interfaces/builtin_interfaces/msg/Duration.msg"),
    ),
    (
        "builtin_interfaces",
        "Time",
        include_str!("../../interfaces/builtin_interfaces/msg/Time.msg"),
    ),
    (
        "geometry_msgs",
        "Point",
        include_str!("../../interfaces/geometry_msgs/msg/Point.msg"),
    ),
    (
        "geometry_msgs",
        "Pose",
        include_str!("../../interfaces/geometry_msgs/msg/Pose.msg"),
    ),
    (
        "geometry_msgs",
        "PoseStamped",
        include_str!("../../interfaces/geometry_msgs/msg/PoseStamped.msg"),
    ),
    (
        "geometry_msgs",
        "PoseWithCovariance",
        include_str!("../../interfaces/geometry_msgs/msg/PoseWithCovariance.msg"),
    ),
    (
        "geometry_msgs",
        "Quaternion",
        include_str!("../../interfaces/geometry_msgs/msg/Quaternion.msg"),
    ),
    (
        "geometry_msgs",
        "Transform",
        include_str!("../../interfaces/geometry_msgs/msg/Transform.msg"),
    ),
    (
        "geometry_msgs",
        "TransformStamped",
        include_str!("../../interfaces/geometry_msgs/msg/TransformStamped.msg"),
    ),
    (
        "geometry_msgs",
        "Twist",
        include_str!("../../interfaces/geometry_msgs/msg/Twist.msg"),
    ),
    (
        "geometry_msgs",
        "TwistStamped",
        include_str!("../../interfaces/geometry_msgs/msg/TwistStamped.msg"),
    ),
    (
        "geometry_msgs",
        "TwistWithCovariance",
        include_str!("../../interfaces/geometry_msgs/msg/TwistWithCovariance.msg"),
    ),
    (
        "geometry_msgs",
        "Vector3",
        include_str!("../../interfaces/geometry_msgs/msg/Vector3.msg"),
    ),
    (
        "nav_msgs",
        "Odometry",
        include_str!("../../interfaces/nav_msgs/msg/Odometry.msg"),
    ),
    (
        "sensor_msgs",
        "Imu",
        include_str!("../../interfaces/sensor_msgs/msg/Imu.msg"),
    ),
    (
        "sensor_msgs",
        "LaserScan",
        include_str!("../../interfaces/sensor_msgs/msg/LaserScan.msg"),
    ),
    (
        "std_msgs",
        "Header",
        include_str!("../../interfaces/std_msgs/msg/Header.msg"),
    ),
];

/// The `.msg` text of a shipped type.
pub(crate) fn find(name: &TypeName) -> Option<&'static str> {
    SHIPPED
        .iter()
        .find(|(package, type_name, _)| *package == name.package() && *type_name == name.name())
        .map(|(_, _, text)| *text)
}

/// The names of every shipped type, by package and name.
pub fn names() -> impl Iterator<Item = TypeName> {
    SHIPPED.iter().map(|(package, name, _)| {
        TypeName::new(package, name).expect("a shipped type has a valid name")
    })
}

/// The shipped type whose name is nearest `name` (`Twistt` for `Twist`, in the same
/// package; else the same type in the nearest package), for "did you mean" help.
pub(crate) fn nearest(name: &TypeName) -> Option<TypeName> {
    let same_package: Vec<&str> = SHIPPED
        .iter()
        .filter(|(package, _, _)| *package == name.package())
        .map(|(_, type_name, _)| *type_name)
        .collect();
    if let Some(near) = closest(name.name(), same_package) {
        return TypeName::new(name.package(), near).ok();
    }
    let same_type: Vec<&str> = SHIPPED
        .iter()
        .filter(|(_, type_name, _)| *type_name == name.name())
        .map(|(package, _, _)| *package)
        .collect();
    closest(name.package(), same_type).and_then(|near| TypeName::new(near, name.name()).ok())
}
