//! Recordings in rosbag2's format ([`RecordFormat::Ros2`]): a bag directory holding
//! one MCAP file of profile `ros2` and the bag's `metadata.yaml`, as `ros2 bag record
//! -s mcap` writes them on ROS 2 Jazzy (metadata version 9). What is rosbag2's here:
//! the topic names a port gets, the QoS profiles its channel offers, and the bag's
//! metadata text.

use std::fmt;
use std::str::FromStr;

use super::RecordError;

/// The format of a recording ([`super::Recorder::format`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RecordFormat {
    /// CoolBOT's own: one MCAP file, every message JSON with its JSON Schema, the
    /// monitoring events and the losses as channels of their own (`coolbot`).
    #[default]
    Coolbot,
    /// rosbag2's: a bag directory with one MCAP file of profile `ros2` (`ros2msg`
    /// schemas, `cdr` messages) and `metadata.yaml`, only ports of ROS 2 message
    /// types, each on its ROS 2 topic (`ros2`).
    Ros2,
}

impl RecordFormat {
    /// Its name, as [`FromStr`] reads it: `coolbot` or `ros2`.
    pub fn name(self) -> &'static str {
        match self {
            RecordFormat::Coolbot => "coolbot",
            RecordFormat::Ros2 => "ros2",
        }
    }
}

impl fmt::Display for RecordFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A name that is not a recording format.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` is not a recording format (known: coolbot, ros2)")]
pub struct UnknownFormat(pub String);

impl FromStr for RecordFormat {
    type Err = UnknownFormat;

    fn from_str(name: &str) -> Result<RecordFormat, UnknownFormat> {
        match name {
            "coolbot" => Ok(RecordFormat::Coolbot),
            "ros2" => Ok(RecordFormat::Ros2),
            other => Err(UnknownFormat(other.to_owned())),
        }
    }
}

/// The QoS profiles every channel of a rosbag2 recording offers (its
/// `offered_qos_profiles` metadata), as rosbag2 Jazzy writes them: one profile, an
/// rclcpp publisher's default (keep last 10, reliable, volatile, automatic
/// liveliness), with the durations ROS 2 reports for "not set" (infinite). `ros2 bag
/// play` publishes a topic with the reliability and durability its offers agree on.
pub const OFFERED_QOS_PROFILES: &str = "- history: keep_last
  depth: 10
  reliability: reliable
  durability: volatile
  deadline:
    sec: 9223372036
    nsec: 854775807
  lifespan:
    sec: 9223372036
    nsec: 854775807
  liveliness: automatic
  liveliness_lease_duration:
    sec: 9223372036
    nsec: 854775807
  avoid_ros_namespace_conventions: false";

/// The metadata version rosbag2 Jazzy writes.
const METADATA_VERSION: u32 = 9;

/// What a port recorded in a rosbag2 recording is: its topic and its type's names.
#[derive(Debug, Clone)]
pub(super) struct RosTopic {
    /// The ROS 2 topic name (`/scan`).
    pub(super) topic: String,
    /// `RosType::NAME`.
    pub(super) type_name: &'static str,
    /// `RosType::TYPE_HASH`.
    pub(super) hash: &'static str,
    /// `RosType::MESSAGE_DEFINITION`.
    pub(super) definition: &'static str,
}

/// The topic a port's path names by default: `/` and the path's parts joined by
/// `/` (`robot.base.scan` is `/robot/base/scan`).
pub(super) fn topic_of(path: &str) -> String {
    format!("/{}", path.replace('.', "/"))
}

/// Checks a fully qualified ROS 2 topic name as ROS 2 does
/// (`rmw_validate_full_topic_name`).
pub(super) fn check_topic(topic: &str) -> Result<(), RecordError> {
    let bad = |reason| {
        Err(RecordError::BadTopic {
            topic: topic.to_owned(),
            reason,
        })
    };
    let Some(rest) = topic.strip_prefix('/') else {
        return bad("it must start with `/`");
    };
    if rest.is_empty() {
        return bad("it names no topic");
    }
    if rest.ends_with('/') {
        return bad("it must not end with `/`");
    }
    for token in rest.split('/') {
        if token.is_empty() {
            return bad("it must not hold `//`");
        }
        if !token
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_')
        {
            return bad("only letters, digits, `_` and `/` are allowed");
        }
        if token.as_bytes()[0].is_ascii_digit() {
            return bad("a part must not start with a digit");
        }
    }
    Ok(())
}

/// One topic of a bag, as its metadata lists it.
pub(super) struct TopicCount<'a> {
    pub(super) topic: &'a RosTopic,
    pub(super) messages: u64,
}

/// The bag's metadata as rosbag2 writes it (the map under
/// `rosbag2_bagfile_information` in `metadata.yaml`, and the `serialized_metadata`
/// of the MCAP metadata record `rosbag2`), in yaml-cpp's block layout.
pub(super) fn bag_metadata(
    file: &str,
    topics: &[TopicCount<'_>],
    start_ns: u64,
    duration_ns: u64,
) -> String {
    use std::fmt::Write;
    let total: u64 = topics.iter().map(|t| t.messages).sum();
    // (A JSON string is a YAML double-quoted scalar.)
    let file = serde_json::to_string(file).unwrap_or_default();
    let mut out = String::new();
    let _ = writeln!(out, "version: {METADATA_VERSION}");
    out.push_str("storage_identifier: mcap\n");
    let _ = writeln!(out, "duration:\n  nanoseconds: {duration_ns}");
    let _ = writeln!(out, "starting_time:\n  nanoseconds_since_epoch: {start_ns}");
    let _ = writeln!(out, "message_count: {total}");
    if topics.is_empty() {
        out.push_str("topics_with_message_count:\n  []\n");
    } else {
        out.push_str("topics_with_message_count:\n");
    }
    for count in topics {
        let topic = count.topic;
        let _ = writeln!(out, "  - topic_metadata:");
        let _ = writeln!(out, "      name: {}", topic.topic);
        let _ = writeln!(out, "      type: {}", topic.type_name);
        let _ = writeln!(out, "      serialization_format: cdr");
        let _ = writeln!(out, "      offered_qos_profiles:");
        for line in OFFERED_QOS_PROFILES.lines() {
            let _ = writeln!(out, "        {line}");
        }
        let _ = writeln!(out, "      type_description_hash: {}", topic.hash);
        let _ = writeln!(out, "    message_count: {}", count.messages);
    }
    out.push_str("compression_format: \"\"\ncompression_mode: \"\"\n");
    let _ = writeln!(out, "relative_file_paths:\n  - {file}");
    let _ = writeln!(out, "files:\n  - path: {file}");
    let _ = writeln!(
        out,
        "    starting_time:\n      nanoseconds_since_epoch: {start_ns}"
    );
    let _ = writeln!(out, "    duration:\n      nanoseconds: {duration_ns}");
    let _ = writeln!(out, "    message_count: {total}");
    out.push_str("custom_data: ~\nros_distro: coolbot");
    out
}

/// `metadata.yaml`: the bag's metadata under `rosbag2_bagfile_information`.
pub(super) fn metadata_yaml(metadata: &str) -> String {
    let mut out = String::from("rosbag2_bagfile_information:\n");
    for line in metadata.lines() {
        out.push_str("  ");
        out.push_str(line);
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_path_names_its_topic_and_ros_2_rules_are_kept() {
        assert_eq!(topic_of("robot.base.scan"), "/robot/base/scan");
        assert!(check_topic("/robot/base/scan").is_ok());
        assert!(check_topic("/scan_2").is_ok());
        for bad in ["scan", "/", "/scan/", "/a//b", "/a-b", "/2d", "/a/9b", "/é"] {
            assert!(
                matches!(check_topic(bad), Err(RecordError::BadTopic { .. })),
                "{bad}"
            );
        }
    }

    #[test]
    fn a_format_is_read_by_its_name() {
        for format in [RecordFormat::Coolbot, RecordFormat::Ros2] {
            assert_eq!(format.name().parse::<RecordFormat>(), Ok(format));
        }
        assert_eq!(
            "rosbag".parse::<RecordFormat>(),
            Err(UnknownFormat("rosbag".into()))
        );
    }
}
