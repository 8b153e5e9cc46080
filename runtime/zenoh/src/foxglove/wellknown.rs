//! Echoed packets as Foxglove's well-known messages, so that the 3D panel draws
//! them: a mapping file (`coolctl foxglove --map FILE`, TOML) names the outputs and
//! the fields that hold a pose or a scan.
//!
//! ```toml
//! [[pose]]                       # -> foxglove.PoseInFrame and foxglove.FrameTransform
//! port = "*/robot.base.motion.pose"
//! x = "x"                        # the fields (dotted paths into the packet's JSON)
//! y = "y"
//! yaw = "theta"                  # radians, counter-clockwise
//! frame = "odom"                 # the frame the pose is in
//! child = "base_link"            # the frame the transform places at the pose
//!
//! [[laser_scan]]                 # -> foxglove.LaserScan
//! port = "*/robot.base.scan"
//! ranges = "us"                  # an array of numbers
//! start_angle = 0.0              # the first beam's angle (rad)
//! step = 0.7853981633974483      # between beams (rad)
//! range_offset = 0.18            # added to each range (a ring's radius)
//! frame = "base_link"
//! ```
//!
//! Each mapping may name `stamp`, a field holding nanoseconds since the Unix epoch
//! (a `Time`); without it a message is stamped when the output sent the packet. A packet
//! a mapping does not fit (a field missing or not a number) is dropped, counted and
//! warned about.

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use serde_json::value::RawValue;
use serde_json::{Value, json};

use super::channels::Stamp;

/// A mapping file.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Mappings {
    /// Outputs whose packets hold a 2-D pose.
    #[serde(default)]
    pub pose: Vec<PoseMap>,
    /// Outputs whose packets hold a fan of ranges.
    #[serde(default)]
    pub laser_scan: Vec<ScanMap>,
}

/// A 2-D pose in a packet.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseMap {
    /// The outputs, `NODE/PATH.PORT` with `*` for any characters.
    pub port: String,
    /// The field of the x coordinate (m).
    pub x: String,
    /// The field of the y coordinate (m).
    pub y: String,
    /// The field of the heading (rad, counter-clockwise).
    pub yaw: String,
    /// The frame the pose is in.
    pub frame: String,
    /// The frame the transform places at the pose.
    pub child: String,
    /// The field of the time stamp (nanoseconds since the Unix epoch).
    #[serde(default)]
    pub stamp: Option<String>,
}

/// A fan of ranges in a packet.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScanMap {
    /// The outputs, `NODE/PATH.PORT` with `*` for any characters.
    pub port: String,
    /// The field of the ranges (an array of numbers, m).
    pub ranges: String,
    /// The first beam's angle (rad).
    pub start_angle: f64,
    /// The angle between two beams (rad).
    pub step: f64,
    /// Added to every range (m).
    #[serde(default)]
    pub range_offset: f64,
    /// The frame of the scanner.
    pub frame: String,
    /// The field of the time stamp (nanoseconds since the Unix epoch).
    #[serde(default)]
    pub stamp: Option<String>,
}

/// A mapping file that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    /// It cannot be read.
    #[error("{}: cannot read", .path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// It is not TOML of the mapping's format.
    #[error("{}", .path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// The TOML error.
        #[source]
        source: toml::de::Error,
    },
}

impl Mappings {
    /// Read the mapping file at `path`.
    pub fn load(path: &Path) -> Result<Mappings, MapError> {
        let text = std::fs::read_to_string(path).map_err(|source| MapError::Read {
            path: path.to_owned(),
            source,
        })?;
        toml::from_str(&text).map_err(|source| MapError::Format {
            path: path.to_owned(),
            source,
        })
    }
}

/// What a channel makes of an echoed packet.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Transform {
    /// The packet itself; `wrap`: as `{"value": ...}` (not a JSON object).
    Raw { wrap: bool },
    /// A `foxglove.PoseInFrame`.
    Pose(PoseMap),
    /// A `foxglove.FrameTransform`.
    Tf(PoseMap),
    /// A `foxglove.LaserScan`.
    Scan(ScanMap),
}

/// The field at dotted `path` in `packet`.
fn field<'a>(packet: &'a Value, path: &str) -> Option<&'a Value> {
    path.split('.')
        .try_fold(packet, |value, key| value.get(key))
}

fn number(packet: &Value, path: &str) -> Result<f64, String> {
    field(packet, path)
        .and_then(Value::as_f64)
        .ok_or_else(|| format!("no number at `{path}`"))
}

fn stamp(packet: &Value, path: Option<&str>, sent: coolbot::Time) -> Result<Stamp, String> {
    match path {
        None => Ok(Stamp {
            sec: sent.as_nanos() / 1_000_000_000,
            nsec: (sent.as_nanos() % 1_000_000_000) as u32,
        }),
        Some(path) => {
            let nanos = field(packet, path)
                .and_then(Value::as_u64)
                .ok_or_else(|| format!("no time stamp (nanoseconds) at `{path}`"))?;
            Ok(Stamp {
                sec: nanos / 1_000_000_000,
                nsec: (nanos % 1_000_000_000) as u32,
            })
        }
    }
}

/// The quaternion of a rotation by `yaw` about z.
fn yaw_quaternion(yaw: f64) -> Value {
    json!({ "x": 0.0, "y": 0.0, "z": (yaw / 2.0).sin(), "w": (yaw / 2.0).cos() })
}

impl Transform {
    /// The message of `packet` (its JSON as the node wrote it), sent at `sent`, as
    /// the channel sends it, or why the packet does not fit. The packet itself is passed on as written,
    /// and wrapped by writing around it; only the well-known messages read it.
    pub(super) fn message<'p>(
        &self,
        packet: &'p RawValue,
        sent: coolbot::Time,
    ) -> Result<Cow<'p, [u8]>, String> {
        match self {
            Transform::Raw { wrap: false } => Ok(Cow::Borrowed(packet.get().as_bytes())),
            Transform::Raw { wrap: true } => {
                const OPEN: &[u8] = b"{\"value\":";
                let mut message = Vec::with_capacity(OPEN.len() + packet.get().len() + 1);
                message.extend_from_slice(OPEN);
                message.extend_from_slice(packet.get().as_bytes());
                message.push(b'}');
                Ok(Cow::Owned(message))
            }
            Transform::Pose(_) | Transform::Tf(_) | Transform::Scan(_) => {
                let packet: Value =
                    serde_json::from_str(packet.get()).map_err(|error| error.to_string())?;
                serde_json::to_vec(&self.apply(packet, sent)?)
                    .map(Cow::Owned)
                    .map_err(|error| error.to_string())
            }
        }
    }

    /// The message of `packet`, sent at `sent`, or why the packet does not fit.
    pub(super) fn apply(&self, packet: Value, sent: coolbot::Time) -> Result<Value, String> {
        match self {
            Transform::Raw { wrap: true } => Ok(json!({ "value": packet })),
            Transform::Raw { wrap: false } => Ok(packet),
            Transform::Pose(map) => Ok(json!({
                "timestamp": stamp(&packet, map.stamp.as_deref(), sent)?,
                "frame_id": map.frame,
                "pose": {
                    "position": {
                        "x": number(&packet, &map.x)?,
                        "y": number(&packet, &map.y)?,
                        "z": 0.0,
                    },
                    "orientation": yaw_quaternion(number(&packet, &map.yaw)?),
                },
            })),
            Transform::Tf(map) => Ok(json!({
                "timestamp": stamp(&packet, map.stamp.as_deref(), sent)?,
                "parent_frame_id": map.frame,
                "child_frame_id": map.child,
                "translation": {
                    "x": number(&packet, &map.x)?,
                    "y": number(&packet, &map.y)?,
                    "z": 0.0,
                },
                "rotation": yaw_quaternion(number(&packet, &map.yaw)?),
            })),
            Transform::Scan(map) => {
                let ranges = field(&packet, &map.ranges)
                    .and_then(Value::as_array)
                    .ok_or_else(|| format!("no array at `{}`", map.ranges))?
                    .iter()
                    .map(|range| {
                        range
                            .as_f64()
                            .map(|range| range + map.range_offset)
                            .ok_or_else(|| format!("`{}` holds a non-number", map.ranges))
                    })
                    .collect::<Result<Vec<f64>, String>>()?;
                let end = map.start_angle + map.step * ranges.len().saturating_sub(1) as f64;
                Ok(json!({
                    "timestamp": stamp(&packet, map.stamp.as_deref(), sent)?,
                    "frame_id": map.frame,
                    "pose": {
                        "position": { "x": 0.0, "y": 0.0, "z": 0.0 },
                        "orientation": yaw_quaternion(0.0),
                    },
                    "start_angle": map.start_angle,
                    "end_angle": end,
                    "ranges": ranges,
                    "intensities": [],
                }))
            }
        }
    }

    /// The schema name and JSON Schema of its messages (None: the packet's own).
    pub(super) fn schema(&self) -> Option<(&'static str, Value)> {
        match self {
            Transform::Raw { .. } => None,
            Transform::Pose(_) => Some(("foxglove.PoseInFrame", pose_in_frame_schema())),
            Transform::Tf(_) => Some(("foxglove.FrameTransform", frame_transform_schema())),
            Transform::Scan(_) => Some(("foxglove.LaserScan", laser_scan_schema())),
        }
    }

    /// The last chunk of its channel's topic (after the output's): none for the
    /// packet itself.
    pub(super) fn suffix(&self) -> &'static str {
        match self {
            Transform::Raw { .. } => "",
            Transform::Pose(_) => "/pose",
            Transform::Tf(_) => "/tf",
            Transform::Scan(_) => "/laser_scan",
        }
    }
}

fn number_schema() -> Value {
    json!({ "type": "number" })
}

fn vector3_schema() -> Value {
    json!({
        "title": "foxglove.Vector3",
        "type": "object",
        "properties": { "x": number_schema(), "y": number_schema(), "z": number_schema() },
        "required": ["x", "y", "z"],
    })
}

fn quaternion_schema() -> Value {
    json!({
        "title": "foxglove.Quaternion",
        "type": "object",
        "properties": {
            "x": number_schema(), "y": number_schema(), "z": number_schema(),
            "w": number_schema(),
        },
        "required": ["x", "y", "z", "w"],
    })
}

fn pose_schema() -> Value {
    let mut position = vector3_schema();
    position["title"] = json!("foxglove.Vector3");
    json!({
        "title": "foxglove.Pose",
        "type": "object",
        "properties": { "position": position, "orientation": quaternion_schema() },
        "required": ["position", "orientation"],
    })
}

fn time_schema() -> Value {
    json!({
        "type": "object",
        "title": "time",
        "properties": {
            "sec": { "type": "integer", "minimum": 0 },
            "nsec": { "type": "integer", "minimum": 0, "maximum": 999_999_999 },
        },
        "required": ["sec", "nsec"],
    })
}

/// `foxglove.PoseInFrame` in JSON Schema.
pub fn pose_in_frame_schema() -> Value {
    json!({
        "$schema": coolbot::schema::DIALECT,
        "title": "foxglove.PoseInFrame",
        "type": "object",
        "properties": {
            "timestamp": time_schema(),
            "frame_id": { "type": "string" },
            "pose": pose_schema(),
        },
        "required": ["timestamp", "frame_id", "pose"],
    })
}

/// `foxglove.FrameTransform` in JSON Schema.
pub fn frame_transform_schema() -> Value {
    json!({
        "$schema": coolbot::schema::DIALECT,
        "title": "foxglove.FrameTransform",
        "type": "object",
        "properties": {
            "timestamp": time_schema(),
            "parent_frame_id": { "type": "string" },
            "child_frame_id": { "type": "string" },
            "translation": vector3_schema(),
            "rotation": quaternion_schema(),
        },
        "required": ["timestamp", "parent_frame_id", "child_frame_id", "translation", "rotation"],
    })
}

/// `foxglove.LaserScan` in JSON Schema.
pub fn laser_scan_schema() -> Value {
    let numbers = json!({ "type": "array", "items": number_schema() });
    json!({
        "$schema": coolbot::schema::DIALECT,
        "title": "foxglove.LaserScan",
        "type": "object",
        "properties": {
            "timestamp": time_schema(),
            "frame_id": { "type": "string" },
            "pose": pose_schema(),
            "start_angle": number_schema(),
            "end_angle": number_schema(),
            "ranges": numbers,
            "intensities": numbers,
        },
        "required": ["timestamp", "frame_id", "pose", "start_angle", "end_angle", "ranges",
                     "intensities"],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// When the packets of the tests were sent.
    const SENT: coolbot::Time = coolbot::Time::from_nanos(5_000_000_011);

    fn pose_map() -> PoseMap {
        PoseMap {
            port: "*".to_owned(),
            x: "x".to_owned(),
            y: "at.y".to_owned(),
            yaw: "theta".to_owned(),
            frame: "odom".to_owned(),
            child: "base_link".to_owned(),
            stamp: Some("stamp".to_owned()),
        }
    }

    #[test]
    fn a_pose_is_a_pose_in_frame_and_a_transform() {
        let packet = json!({ "x": 1.5, "at": { "y": -2.0 }, "theta": std::f64::consts::PI,
            "stamp": 3_000_000_007u64 });
        let pose = Transform::Pose(pose_map())
            .apply(packet.clone(), SENT)
            .unwrap();
        assert_eq!(pose["frame_id"], "odom");
        assert_eq!(pose["timestamp"], json!({ "sec": 3, "nsec": 7 }));
        assert_eq!(
            pose["pose"]["position"],
            json!({ "x": 1.5, "y": -2.0, "z": 0.0 })
        );
        let q = &pose["pose"]["orientation"];
        assert!((q["z"].as_f64().unwrap() - 1.0).abs() < 1e-12, "{q}");
        assert!(q["w"].as_f64().unwrap().abs() < 1e-12, "{q}");
        let tf = Transform::Tf(pose_map()).apply(packet, SENT).unwrap();
        assert_eq!(tf["parent_frame_id"], "odom");
        assert_eq!(tf["child_frame_id"], "base_link");
        assert_eq!(tf["translation"]["y"], -2.0);
    }

    #[test]
    fn a_scan_is_a_laser_scan_with_its_angles_and_offset() {
        let map = ScanMap {
            port: "*".to_owned(),
            ranges: "us".to_owned(),
            start_angle: 0.0,
            step: 0.5,
            range_offset: 0.25,
            frame: "base_link".to_owned(),
            stamp: None,
        };
        let scan = Transform::Scan(map)
            .apply(json!({ "us": [1.0, 2.0, 3.0] }), SENT)
            .unwrap();
        // No stamp field: the time the output sent the packet.
        assert_eq!(scan["timestamp"], json!({ "sec": 5, "nsec": 11 }));
        assert_eq!(scan["ranges"], json!([1.25, 2.25, 3.25]));
        assert_eq!(scan["start_angle"], 0.0);
        assert_eq!(scan["end_angle"], 1.0);
        assert_eq!(scan["frame_id"], "base_link");
    }

    #[test]
    fn a_packet_the_mapping_does_not_fit_is_refused_with_the_field() {
        let error = Transform::Pose(pose_map())
            .apply(json!({ "x": 1.0, "theta": 0.0, "stamp": 1 }), SENT)
            .unwrap_err();
        assert_eq!(error, "no number at `at.y`");
    }

    fn raw(json: &str) -> Box<RawValue> {
        RawValue::from_string(json.to_owned()).expect("JSON")
    }

    #[test]
    fn a_packet_is_passed_on_as_written_and_wrapped_by_writing_around_it() {
        // Not in serde_json's key order: written anew, it would come out sorted.
        let packet = raw(r#"{"z":1,"a":[2.5,"x"]}"#);
        let message = Transform::Raw { wrap: false }
            .message(&packet, SENT)
            .unwrap();
        assert!(matches!(message, Cow::Borrowed(_)), "copied");
        assert_eq!(&*message, br#"{"z":1,"a":[2.5,"x"]}"#);
        let number = raw("42");
        let wrapped = Transform::Raw { wrap: true }
            .message(&number, SENT)
            .unwrap();
        assert_eq!(&*wrapped, br#"{"value":42}"#);
        let wrapped = Transform::Raw { wrap: true }
            .message(&packet, SENT)
            .unwrap();
        let value: Value = serde_json::from_slice(&wrapped).expect("JSON");
        assert_eq!(value, json!({ "value": { "z": 1, "a": [2.5, "x"] } }));
    }

    #[test]
    fn a_mapped_packet_is_read_and_its_message_written() {
        let packet = raw(r#"{"x":1.5,"at":{"y":-2.0},"theta":0.0,"stamp":3000000007}"#);
        let message = Transform::Pose(pose_map()).message(&packet, SENT).unwrap();
        let pose: Value = serde_json::from_slice(&message).expect("JSON");
        assert_eq!(
            pose,
            Transform::Pose(pose_map())
                .apply(serde_json::from_str(packet.get()).unwrap(), SENT)
                .unwrap()
        );
        let unfit = raw(r#"{"x":1.0,"theta":0.0,"stamp":1}"#);
        assert_eq!(
            Transform::Tf(pose_map()).message(&unfit, SENT).unwrap_err(),
            "no number at `at.y`"
        );
    }

    /// The example's layout draws what `coolctl foxglove --map map.toml` serves for
    /// the robot run as `--node robot`: the mapped outputs, the monitoring of the
    /// motion controller and the range server, the log.
    #[test]
    fn the_example_robots_layout_reads_served_topics() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/mobile-base/foxglove");
        let layout: Value = serde_json::from_str(
            &std::fs::read_to_string(dir.join("layout.json")).expect("the layout"),
        )
        .expect("JSON");
        let mappings = Mappings::load(&dir.join("map.toml")).expect("the mapping");
        let panels = &layout["configById"];
        let mut topics: Vec<String> = panels["3D!robot"]["topics"]
            .as_object()
            .expect("3D topics")
            .keys()
            .cloned()
            .collect();
        for path in panels["Plot!speed"]["paths"]
            .as_array()
            .expect("plot paths")
        {
            let (topic, fields) = message_path(path["value"].as_str().expect("a path"));
            assert!(fields.starts_with(".variables."), "{fields}");
            topics.push(topic);
        }
        topics.push(
            panels["RosOut!steps"]["topicToRender"]
                .as_str()
                .unwrap()
                .to_owned(),
        );
        let served = |topic: &str| {
            let pose = |suffix: &str| {
                topic
                    .strip_prefix('/')
                    .and_then(|t| t.strip_suffix(suffix))
                    .is_some_and(|port| {
                        mappings
                            .pose
                            .iter()
                            .any(|m| super::super::matches(&m.port, port))
                    })
            };
            let scan = topic
                .strip_prefix('/')
                .and_then(|t| t.strip_suffix("/laser_scan"))
                .is_some_and(|port| {
                    mappings
                        .laser_scan
                        .iter()
                        .any(|m| super::super::matches(&m.port, port))
                });
            let monitor = [
                "/robot/robot.base.motion/monitor",
                "/robot/robot.base.ranges/monitor",
            ]
            .contains(&topic);
            pose("/pose") || pose("/tf") || scan || monitor || topic == super::super::LOG_TOPIC
        };
        for topic in &topics {
            assert!(
                served(topic),
                "the layout reads `{topic}`, which is not served"
            );
        }
        assert_eq!(topics.len(), 6, "{topics:?}");
        assert!(panels.get("Parameters!robot").is_some());
    }

    /// A Foxglove message path's topic and the rest: an unquoted topic name is made of
    /// `/`, letters, digits, `_` and `-` only, so a topic with a dot in it is quoted
    /// (`"/robot/robot.base/monitor".variables.x`), `\\` and `\"` escaped inside.
    fn message_path(path: &str) -> (String, &str) {
        if let Some(quoted) = path.strip_prefix('"') {
            let mut topic = String::new();
            let mut chars = quoted.char_indices();
            while let Some((at, c)) = chars.next() {
                match c {
                    '"' => return (topic, &quoted[at + 1..]),
                    '\\' => topic.push(chars.next().expect("an escaped character").1),
                    c => topic.push(c),
                }
            }
            panic!("an unterminated quoted topic in `{path}`");
        }
        let end = path
            .find(|c: char| !(c.is_ascii_alphanumeric() || "/_-".contains(c)))
            .unwrap_or(path.len());
        (path[..end].to_owned(), &path[end..])
    }

    #[test]
    fn a_message_path_reads_its_topic_as_foxglove_does() {
        assert_eq!(
            message_path("/a/b.c.d"),
            ("/a/b".to_owned(), ".c.d"),
            "a dot ends an unquoted topic"
        );
        assert_eq!(message_path(r#""/a/b.c".d"#), ("/a/b.c".to_owned(), ".d"));
        assert_eq!(message_path(r#""/a\"b".d"#), ("/a\"b".to_owned(), ".d"));
    }

    #[test]
    fn the_example_robots_mapping_file_reads() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../examples/mobile-base/foxglove/map.toml");
        let mappings = Mappings::load(&path).expect("the example's mapping");
        assert_eq!(mappings.pose.len(), 1);
        assert_eq!(mappings.laser_scan.len(), 1);
    }
}
