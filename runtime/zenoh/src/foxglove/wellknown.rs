//! Echoed packets as Foxglove's well-known messages, so that the 3D panel draws
//! them: a mapping file (`coolctl foxglove --map FILE`, TOML) names the outputs and
//! the fields that hold a pose or a scan.
//!
//! ```toml
//! [[pose]]                       # -> foxglove.PoseInFrame, foxglove.FrameTransform
//!                                #    and foxglove.PosesInFrame (the path)
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
//! A pose's path is the poses the output sent while a client watched it, one kept each
//! time the pose moved [`PATH_STEP`] or turned [`PATH_TURN`] from the last one kept,
//! the newest [`PATH_POINTS`]; a message goes out only when a pose is kept.
//!
//! Each mapping may name `stamp`, a field holding nanoseconds since the Unix epoch
//! (a `Time`); without it a message is stamped when the output sent the packet. A packet
//! a mapping does not fit (a field missing or not a number) is dropped, counted and
//! warned about.

use std::borrow::Cow;
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, PoisonError};

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

/// How far a pose moves from the last one its path kept before the path keeps it (m).
pub const PATH_STEP: f64 = 0.05;

/// How far a pose turns from the last one its path kept before the path keeps it (rad).
pub const PATH_TURN: f64 = 0.2;

/// The most poses a path holds (the oldest go first).
pub const PATH_POINTS: usize = 500;

/// The poses a path channel has kept (`x`, `y`, `yaw`), shared by its clones: one
/// channel's.
#[derive(Debug, Clone, Default)]
pub(super) struct Trail(Arc<Mutex<Kept>>);

#[derive(Debug, Default)]
struct Kept {
    poses: VecDeque<[f64; 3]>,
    /// A client subscribed since the last message: the next pose sends the path
    /// whether it is kept or not.
    resend: bool,
}

impl PartialEq for Trail {
    fn eq(&self, other: &Trail) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}

impl Trail {
    fn lock(&self) -> std::sync::MutexGuard<'_, Kept> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Keeps `pose` if it moved or turned far enough from the last one kept; the poses
    /// kept if it was kept, or if a client subscribed since the last message.
    fn keep(&self, pose: [f64; 3]) -> Option<Vec<[f64; 3]>> {
        let mut kept = self.lock();
        let far = kept.poses.back().is_none_or(|last| {
            let moved = (pose[0] - last[0]).hypot(pose[1] - last[1]);
            let turn = pose[2] - last[2];
            let turned = turn.sin().atan2(turn.cos()).abs();
            moved >= PATH_STEP || turned >= PATH_TURN
        });
        if far {
            if kept.poses.len() == PATH_POINTS {
                kept.poses.pop_front();
            }
            kept.poses.push_back(pose);
        } else if !kept.resend {
            return None;
        }
        kept.resend = false;
        Some(kept.poses.iter().copied().collect())
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
    /// A `foxglove.PosesInFrame`: the pose's path.
    Path(PoseMap, Trail),
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
            let at = field(packet, path);
            // Nanoseconds since the epoch (a `coolbot::Time`), or a ROS 2
            // `builtin_interfaces/Time` (`sec`, `nanosec`: a `header.stamp`).
            if let Some(nanos) = at.and_then(Value::as_u64) {
                return Ok(Stamp {
                    sec: nanos / 1_000_000_000,
                    nsec: (nanos % 1_000_000_000) as u32,
                });
            }
            let part = |name: &str| at.and_then(|at| at.get(name)).and_then(Value::as_u64);
            match (part("sec"), part("nanosec")) {
                (Some(sec), Some(nsec)) if nsec < 1_000_000_000 => Ok(Stamp {
                    sec,
                    nsec: nsec as u32,
                }),
                _ => Err(format!(
                    "no time stamp at `{path}` (nanoseconds, or `sec` and `nanosec` of a ROS 2 time)"
                )),
            }
        }
    }
}

/// The pose (`x`, `y`, `yaw`) a pose mapping reads in `packet`.
fn pose_of(packet: &Value, map: &PoseMap) -> Result<[f64; 3], String> {
    Ok([
        number(packet, &map.x)?,
        number(packet, &map.y)?,
        number(packet, &map.yaw)?,
    ])
}

/// A `foxglove.Pose` in the plane.
fn pose_json([x, y, yaw]: [f64; 3]) -> Value {
    json!({
        "position": { "x": x, "y": y, "z": 0.0 },
        "orientation": yaw_quaternion(yaw),
    })
}

/// The quaternion of a rotation by `yaw` about z.
fn yaw_quaternion(yaw: f64) -> Value {
    json!({ "x": 0.0, "y": 0.0, "z": (yaw / 2.0).sin(), "w": (yaw / 2.0).cos() })
}

impl Transform {
    /// A client subscribed to its channel: a path sends what it holds with the next
    /// packet, kept or not.
    pub(super) fn subscribed(&self) {
        if let Transform::Path(_, trail) = self {
            trail.lock().resend = true;
        }
    }

    /// The last client left its channel: a path forgets its poses (the next client's
    /// starts anew, not joined to where the robot was then).
    pub(super) fn unwatched(&self) {
        if let Transform::Path(_, trail) = self {
            *trail.lock() = Kept::default();
        }
    }

    /// The message of `packet` (its JSON as the node wrote it), sent at `sent`, as
    /// the channel sends it (None: nothing to send, a path that kept no pose), or why
    /// the packet does not fit. The packet itself is passed on as written, and wrapped
    /// by writing around it; only the well-known messages read it.
    pub(super) fn message<'p>(
        &self,
        packet: &'p RawValue,
        sent: coolbot::Time,
    ) -> Result<Option<Cow<'p, [u8]>>, String> {
        match self {
            Transform::Raw { wrap: false } => Ok(Some(Cow::Borrowed(packet.get().as_bytes()))),
            Transform::Raw { wrap: true } => {
                const OPEN: &[u8] = b"{\"value\":";
                let mut message = Vec::with_capacity(OPEN.len() + packet.get().len() + 1);
                message.extend_from_slice(OPEN);
                message.extend_from_slice(packet.get().as_bytes());
                message.push(b'}');
                Ok(Some(Cow::Owned(message)))
            }
            Transform::Pose(_) | Transform::Tf(_) | Transform::Scan(_) | Transform::Path(..) => {
                let packet: Value =
                    serde_json::from_str(packet.get()).map_err(|error| error.to_string())?;
                let Some(message) = self.apply(packet, sent)? else {
                    return Ok(None);
                };
                serde_json::to_vec(&message)
                    .map(|bytes| Some(Cow::Owned(bytes)))
                    .map_err(|error| error.to_string())
            }
        }
    }

    /// The message of `packet`, sent at `sent` (None: nothing to send), or why the
    /// packet does not fit.
    pub(super) fn apply(
        &self,
        packet: Value,
        sent: coolbot::Time,
    ) -> Result<Option<Value>, String> {
        let message = match self {
            Transform::Raw { wrap: true } => json!({ "value": packet }),
            Transform::Raw { wrap: false } => packet,
            Transform::Pose(map) => {
                let pose = pose_json(pose_of(&packet, map)?);
                json!({
                    "timestamp": stamp(&packet, map.stamp.as_deref(), sent)?,
                    "frame_id": map.frame,
                    "pose": pose,
                })
            }
            Transform::Tf(map) => {
                let [x, y, yaw] = pose_of(&packet, map)?;
                json!({
                    "timestamp": stamp(&packet, map.stamp.as_deref(), sent)?,
                    "parent_frame_id": map.frame,
                    "child_frame_id": map.child,
                    "translation": { "x": x, "y": y, "z": 0.0 },
                    "rotation": yaw_quaternion(yaw),
                })
            }
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
                json!({
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
                })
            }
            Transform::Path(map, trail) => {
                // Read whole before a pose is kept: a packet that does not fit adds
                // nothing to the path.
                let pose = pose_of(&packet, map)?;
                let timestamp = stamp(&packet, map.stamp.as_deref(), sent)?;
                let Some(poses) = trail.keep(pose) else {
                    return Ok(None);
                };
                let poses: Vec<Value> = poses.into_iter().map(pose_json).collect();
                json!({ "timestamp": timestamp, "frame_id": map.frame, "poses": poses })
            }
        };
        Ok(Some(message))
    }

    /// The schema name and JSON Schema of its messages (None: the packet's own).
    pub(super) fn schema(&self) -> Option<(&'static str, Value)> {
        match self {
            Transform::Raw { .. } => None,
            Transform::Pose(_) => Some(("foxglove.PoseInFrame", pose_in_frame_schema())),
            Transform::Tf(_) => Some(("foxglove.FrameTransform", frame_transform_schema())),
            Transform::Scan(_) => Some(("foxglove.LaserScan", laser_scan_schema())),
            Transform::Path(..) => Some(("foxglove.PosesInFrame", poses_in_frame_schema())),
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
            Transform::Path(..) => "/path",
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

/// `foxglove.PosesInFrame` in JSON Schema.
pub fn poses_in_frame_schema() -> Value {
    json!({
        "$schema": coolbot::schema::DIALECT,
        "title": "foxglove.PosesInFrame",
        "type": "object",
        "properties": {
            "timestamp": time_schema(),
            "frame_id": { "type": "string" },
            "poses": { "type": "array", "items": pose_schema() },
        },
        "required": ["timestamp", "frame_id", "poses"],
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
    fn a_stamp_is_nanoseconds_or_a_ros_time() {
        let at = |time: Value| stamp(&json!({ "h": { "stamp": time } }), Some("h.stamp"), SENT);
        let ros = at(json!({ "sec": 3, "nanosec": 7 })).unwrap();
        assert_eq!((ros.sec, ros.nsec), (3, 7));
        let nanos = at(json!(3_000_000_007u64)).unwrap();
        assert_eq!((nanos.sec, nanos.nsec), (3, 7));
        for wrong in [
            json!({ "sec": -1, "nanosec": 7 }),
            json!({ "sec": 3, "nanosec": 1_000_000_000u64 }),
            json!("now"),
        ] {
            let refused = at(wrong.clone()).unwrap_err();
            assert!(
                refused.starts_with("no time stamp at `h.stamp`"),
                "{wrong}: {refused}"
            );
        }
        let sent = stamp(&json!({}), None, SENT).unwrap();
        assert_eq!((sent.sec, sent.nsec), (5, 11));
    }

    #[test]
    fn a_pose_is_a_pose_in_frame_and_a_transform() {
        let packet = json!({ "x": 1.5, "at": { "y": -2.0 }, "theta": std::f64::consts::PI,
            "stamp": 3_000_000_007u64 });
        let pose = Transform::Pose(pose_map())
            .apply(packet.clone(), SENT)
            .unwrap()
            .expect("a message per packet");
        assert_eq!(pose["frame_id"], "odom");
        assert_eq!(pose["timestamp"], json!({ "sec": 3, "nsec": 7 }));
        assert_eq!(
            pose["pose"]["position"],
            json!({ "x": 1.5, "y": -2.0, "z": 0.0 })
        );
        let q = &pose["pose"]["orientation"];
        assert!((q["z"].as_f64().unwrap() - 1.0).abs() < 1e-12, "{q}");
        assert!(q["w"].as_f64().unwrap().abs() < 1e-12, "{q}");
        let tf = Transform::Tf(pose_map())
            .apply(packet, SENT)
            .unwrap()
            .expect("a message per packet");
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
            .unwrap()
            .expect("a message per packet");
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

    #[test]
    fn a_path_keeps_a_pose_each_step_or_turn_and_its_newest_ones() {
        let path = Transform::Path(pose_map(), Trail::default());
        let at = |x: f64, theta: f64| {
            path.apply(
                json!({ "x": x, "at": { "y": 0.0 }, "theta": theta, "stamp": 1 }),
                SENT,
            )
            .unwrap()
        };
        let first = at(0.0, 0.0).expect("the first pose is kept");
        assert_eq!(first["frame_id"], "odom");
        assert_eq!(first["poses"].as_array().unwrap().len(), 1);
        assert!(at(PATH_STEP / 2.0, PATH_TURN / 2.0).is_none(), "too close");
        let moved = at(PATH_STEP, 0.0).expect("a step away");
        assert_eq!(moved["poses"][1]["position"]["x"], PATH_STEP);
        // A turn from +179 to -179 degrees is 2 degrees, not 358.
        let pi = std::f64::consts::PI;
        at(PATH_STEP, pi - 0.01).expect("turned");
        assert!(
            at(PATH_STEP, -pi + 0.01).is_none(),
            "a small turn across pi"
        );
        // A clone is the same channel's path: it keeps one trail.
        let clone = path.clone();
        assert_eq!(clone, path);
        // A client that subscribes gets the path with the next pose, kept or not.
        path.subscribed();
        let again = at(PATH_STEP, -pi + 0.01).expect("sent again to the new client");
        assert_eq!(again["poses"].as_array().unwrap().len(), 3);
        assert!(at(PATH_STEP, -pi + 0.01).is_none(), "once");
        // A packet that does not fit (no stamp) adds nothing.
        let unfit = path.apply(json!({ "x": 9.0, "at": { "y": 0.0 }, "theta": 0.0 }), SENT);
        assert!(unfit.is_err());
        assert_eq!(
            at(PATH_STEP, -pi + 0.01),
            None,
            "the pose at x = 9 was not kept"
        );
        // Nobody watches: the path starts anew.
        path.unwatched();
        let anew = at(5.0, 0.0).expect("the first pose again");
        assert_eq!(anew["poses"].as_array().unwrap().len(), 1);
        assert_ne!(Transform::Path(pose_map(), Trail::default()), path);
        let mut last = None;
        for step in 0..PATH_POINTS + 10 {
            last = at(2.0 + step as f64, 0.0).or(last);
        }
        let poses = last.expect("kept")["poses"].as_array().unwrap().clone();
        assert_eq!(poses.len(), PATH_POINTS);
        assert_eq!(
            poses[PATH_POINTS - 1]["position"]["x"],
            2.0 + (PATH_POINTS + 9) as f64
        );
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
            .unwrap()
            .expect("a message per packet");
        assert!(matches!(message, Cow::Borrowed(_)), "copied");
        assert_eq!(&*message, br#"{"z":1,"a":[2.5,"x"]}"#);
        let number = raw("42");
        let wrapped = Transform::Raw { wrap: true }
            .message(&number, SENT)
            .unwrap()
            .expect("a message per packet");
        assert_eq!(&*wrapped, br#"{"value":42}"#);
        let wrapped = Transform::Raw { wrap: true }
            .message(&packet, SENT)
            .unwrap()
            .expect("a message per packet");
        let value: Value = serde_json::from_slice(&wrapped).expect("JSON");
        assert_eq!(value, json!({ "value": { "z": 1, "a": [2.5, "x"] } }));
    }

    #[test]
    fn a_mapped_packet_is_read_and_its_message_written() {
        let packet = raw(r#"{"x":1.5,"at":{"y":-2.0},"theta":0.0,"stamp":3000000007}"#);
        let message = Transform::Pose(pose_map())
            .message(&packet, SENT)
            .unwrap()
            .expect("a message per packet");
        let pose: Value = serde_json::from_slice(&message).expect("JSON");
        assert_eq!(
            pose,
            Transform::Pose(pose_map())
                .apply(serde_json::from_str(packet.get()).unwrap(), SENT)
                .unwrap()
                .expect("a message per packet")
        );
        let unfit = raw(r#"{"x":1.0,"theta":0.0,"stamp":1}"#);
        assert_eq!(
            Transform::Tf(pose_map()).message(&unfit, SENT).unwrap_err(),
            "no number at `at.y`"
        );
    }

    /// The example's layout draws what `coolctl foxglove --map map.toml` serves for
    /// the robot run as `--node robot`: the mapped outputs, the monitoring of the
    /// motion controller, the range server and its simulated backup, the log.
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
            // A filter on the message first (`{state=="running"}`) reads its state.
            let fields = match fields.strip_prefix("{") {
                Some(filter) => {
                    let (filter, rest) = filter.split_once('}').expect("a closed filter");
                    assert!(filter.starts_with("state=="), "{filter}");
                    rest
                }
                None => fields,
            };
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
                "/robot/robot.base.sim_ranges/monitor",
            ]
            .contains(&topic);
            pose("/pose")
                || pose("/tf")
                || pose("/path")
                || scan
                || monitor
                || topic == super::super::LOG_TOPIC
        };
        for topic in &topics {
            assert!(
                served(topic),
                "the layout reads `{topic}`, which is not served"
            );
        }
        assert_eq!(topics.len(), 8, "{topics:?}");
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
