//! `coolbot::cdr` against an implementation we did not write: rosbags' (PyPI, 0.11.x)
//! CDR of its ROS 2 Jazzy types. For hand-written Rust structs of `LaserScan`, `Imu`,
//! `Odometry` and `Twist` (fields in the `.msg` order, fixed arrays as serde tuples),
//! the bytes we encode deserialize in rosbags to the values we set, the bytes rosbags
//! serializes from those values decode in ours to the same values, and both are the
//! same bytes.
//!
//! The Python with rosbags is `$COOLBOT_PYTHON`, else `target/pyenv/bin/python`;
//! `.ci/run` makes it. Without it these tests fail, saying how to set it up.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use serde::{Deserialize, Serialize};
use serde_with::{As, Same};

const SETUP: &str = "the ROS 2 interoperability tests need a Python with rosbags 0.11:
    python3 -m venv target/pyenv
    target/pyenv/bin/pip install rosbags==0.11.9
then run the tests from the repository root, or set COOLBOT_PYTHON to that python";

/// For each case `{"type", "ours": hex, "value": JSON}`: rosbags' decoding of `ours`
/// (as JSON, each float as `{"f64": its IEEE bits}`, exact whatever the JSON parser)
/// and its serialization of `value` (as hex).
const SCRIPT: &str = r#"
import json, struct, sys
from importlib.metadata import version
import numpy
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_typestore

store = get_typestore(Stores.ROS2_JAZZY)
DTYPES = {'bool': numpy.bool_, 'byte': numpy.uint8, 'char': numpy.uint8,
          'int8': numpy.int8, 'uint8': numpy.uint8, 'int16': numpy.int16,
          'uint16': numpy.uint16, 'int32': numpy.int32, 'uint32': numpy.uint32,
          'int64': numpy.int64, 'uint64': numpy.uint64, 'float32': numpy.float32,
          'float64': numpy.float64}

def build(typename, value):
    fields = store.fielddefs[typename][1]
    return store.types[typename](**{n: build_field(d, value[n]) for n, d in fields})

def build_field(desc, value):
    kind, rest = desc
    if kind == Nodetype.BASE:
        return value
    if kind == Nodetype.NAME:
        return build(rest, value)
    sub = rest[0]
    if sub[0] == Nodetype.BASE and sub[1][0] != 'string':
        return numpy.array(value, dtype=DTYPES[sub[1][0]])
    return [build_field(sub, v) for v in value]

def dump(typename, message):
    fields = store.fielddefs[typename][1]
    return {n: dump_field(d, getattr(message, n)) for n, d in fields}

def scalar(value):
    value = value.item() if hasattr(value, 'item') else value
    if isinstance(value, float):
        return {'f64': struct.unpack('<Q', struct.pack('<d', value))[0]}
    return value

def dump_field(desc, value):
    kind, rest = desc
    if kind == Nodetype.BASE:
        return scalar(value)
    if kind == Nodetype.NAME:
        return dump(rest, value)
    if isinstance(value, numpy.ndarray):
        return [scalar(v) for v in value.tolist()]
    return [dump_field(rest[0], v) for v in value]

results = []
for case in json.load(sys.stdin)['cases']:
    typename = case['type']
    decoded = store.deserialize_cdr(bytes.fromhex(case['ours']), typename)
    encoded = store.serialize_cdr(build(typename, case['value']), typename)
    results.append({'decoded': dump(typename, decoded), 'theirs': bytes(encoded).hex()})
json.dump({'rosbags': version('rosbags'), 'results': results}, sys.stdout)
"#;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Time {
    sec: i32,
    nanosec: u32,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Header {
    stamp: Time,
    frame_id: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct LaserScan {
    header: Header,
    angle_min: f32,
    angle_max: f32,
    angle_increment: f32,
    time_increment: f32,
    scan_time: f32,
    range_min: f32,
    range_max: f32,
    ranges: Vec<f32>,
    intensities: Vec<f32>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Vector3 {
    x: f64,
    y: f64,
    z: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Quaternion {
    x: f64,
    y: f64,
    z: f64,
    w: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Imu {
    header: Header,
    orientation: Quaternion,
    orientation_covariance: [f64; 9],
    angular_velocity: Vector3,
    angular_velocity_covariance: [f64; 9],
    linear_acceleration: Vector3,
    linear_acceleration_covariance: [f64; 9],
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Pose {
    position: Vector3,
    orientation: Quaternion,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct PoseWithCovariance {
    pose: Pose,
    #[serde(with = "As::<[Same; 36]>")]
    covariance: [f64; 36],
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Twist {
    linear: Vector3,
    angular: Vector3,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct TwistWithCovariance {
    twist: Twist,
    #[serde(with = "As::<[Same; 36]>")]
    covariance: [f64; 36],
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Odometry {
    header: Header,
    child_frame_id: String,
    pose: PoseWithCovariance,
    twist: TwistWithCovariance,
}

fn header(frame: &str) -> Header {
    Header {
        stamp: Time {
            sec: 1_700_000_123,
            nanosec: 456_789_012,
        },
        frame_id: frame.into(),
    }
}

fn vector(x: f64, y: f64, z: f64) -> Vector3 {
    Vector3 { x, y, z }
}

/// Distinct values, some not exact in binary (0.1), so that a field read from the
/// wrong place or width shows.
fn covariance<const N: usize>(scale: f64) -> [f64; N] {
    std::array::from_fn(|i| scale * (i as f64 + 0.1))
}

fn scan() -> LaserScan {
    LaserScan {
        header: header("laser"),
        angle_min: -2.356_194_5,
        angle_max: 2.356_194_5,
        angle_increment: 0.1,
        time_increment: 1.0e-4,
        scan_time: 0.1,
        range_min: 0.05,
        range_max: 30.0,
        ranges: (0..47).map(|i| 0.5 + i as f32 * 0.013).collect(),
        intensities: vec![100.0, 0.25, 7.0],
    }
}

fn imu() -> Imu {
    Imu {
        header: header("imu_link"),
        orientation: Quaternion {
            x: 0.1,
            y: -0.2,
            z: 0.3,
            w: 0.927,
        },
        orientation_covariance: covariance(1.0),
        angular_velocity: vector(0.01, -0.02, 0.5),
        angular_velocity_covariance: covariance(2.0),
        linear_acceleration: vector(0.1, 0.2, 9.81),
        linear_acceleration_covariance: covariance(3.0),
    }
}

fn odometry() -> Odometry {
    Odometry {
        header: header("odom"),
        child_frame_id: "base_link".into(),
        pose: PoseWithCovariance {
            pose: Pose {
                position: vector(1.5, -2.25, 0.0),
                orientation: Quaternion {
                    x: 0.0,
                    y: 0.0,
                    z: 0.383,
                    w: 0.924,
                },
            },
            covariance: covariance(0.5),
        },
        twist: TwistWithCovariance {
            twist: twist(),
            covariance: covariance(0.25),
        },
    }
}

fn twist() -> Twist {
    Twist {
        linear: vector(0.4, 0.0, 0.0),
        angular: vector(0.0, 0.0, -0.7),
    }
}

fn python() -> PathBuf {
    if let Some(python) = std::env::var_os("COOLBOT_PYTHON") {
        return python.into();
    }
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/pyenv/bin/python");
    if venv.exists() {
        return venv;
    }
    panic!("COOLBOT_PYTHON is not set and target/pyenv does not exist: {SETUP}");
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex(text: &str) -> Vec<u8> {
    (0..text.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&text[i..i + 2], 16).unwrap())
        .collect()
}

/// `value` with each `{"f64": bits}` made the float of those bits.
fn exact_floats(value: serde_json::Value) -> serde_json::Value {
    use serde_json::Value;
    match value {
        Value::Object(map) => match map.get("f64").and_then(Value::as_u64) {
            Some(bits) if map.len() == 1 => {
                Value::Number(serde_json::Number::from_f64(f64::from_bits(bits)).unwrap())
            }
            _ => Value::Object(map.into_iter().map(|(k, v)| (k, exact_floats(v))).collect()),
        },
        Value::Array(items) => Value::Array(items.into_iter().map(exact_floats).collect()),
        other => other,
    }
}

/// One message type's case: what rosbags made of our bytes, and its own bytes.
struct Answer {
    decoded: serde_json::Value,
    theirs: Vec<u8>,
}

/// Runs the script over `(type name, our bytes, the value as JSON)` cases.
fn rosbags(cases: &[(&str, Vec<u8>, serde_json::Value)]) -> Vec<Answer> {
    let python = python();
    let mut child = Command::new(&python)
        .args(["-c", SCRIPT])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|error| panic!("cannot run {}: {error}; {SETUP}", python.display()));
    let cases: Vec<serde_json::Value> = cases
        .iter()
        .map(|(name, ours, value)| serde_json::json!({"type": name, "ours": hex(ours), "value": value}))
        .collect();
    let request = serde_json::json!({ "cases": cases });
    child
        .stdin
        .take()
        .unwrap()
        .write_all(request.to_string().as_bytes())
        .unwrap();
    let output = child.wait_with_output().unwrap();
    assert!(
        output.status.success(),
        "{} failed: {}\n{SETUP}",
        python.display(),
        String::from_utf8_lossy(&output.stderr)
    );
    let answer: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let version = answer["rosbags"].as_str().unwrap();
    assert!(version.starts_with("0.11."), "rosbags {version}; {SETUP}");
    answer["results"]
        .as_array()
        .unwrap()
        .iter()
        .map(|result| Answer {
            decoded: exact_floats(result["decoded"].clone()),
            theirs: unhex(result["theirs"].as_str().unwrap()),
        })
        .collect()
}

/// Checks one type both ways.
fn check<T>(name: &str, value: &T, answer: &Answer)
where
    T: Serialize + for<'de> Deserialize<'de> + PartialEq + std::fmt::Debug,
{
    // rosbags read our bytes as the values we set (read back into T: a float32 read as
    // a Python float is the same f32).
    let seen: T = serde_json::from_value(answer.decoded.clone())
        .unwrap_or_else(|error| panic!("{name}: {error}: {}", answer.decoded));
    assert_eq!(&seen, value, "{name}: rosbags read our bytes otherwise");
    // Its bytes decode in ours to the same values.
    let decoded: T = coolbot::cdr::from_slice(&answer.theirs).unwrap();
    assert_eq!(&decoded, value, "{name}: we read rosbags' bytes otherwise");
    // And they are the very bytes we write.
    assert_eq!(
        coolbot::cdr::to_vec(value).unwrap(),
        answer.theirs,
        "{name}: our bytes differ from rosbags'"
    );
}

#[test]
fn our_cdr_and_rosbags_read_each_others_bytes() {
    let cases = [
        (
            "sensor_msgs/msg/LaserScan",
            coolbot::cdr::to_vec(&scan()).unwrap(),
            serde_json::to_value(scan()).unwrap(),
        ),
        (
            "sensor_msgs/msg/Imu",
            coolbot::cdr::to_vec(&imu()).unwrap(),
            serde_json::to_value(imu()).unwrap(),
        ),
        (
            "nav_msgs/msg/Odometry",
            coolbot::cdr::to_vec(&odometry()).unwrap(),
            serde_json::to_value(odometry()).unwrap(),
        ),
        (
            "geometry_msgs/msg/Twist",
            coolbot::cdr::to_vec(&twist()).unwrap(),
            serde_json::to_value(twist()).unwrap(),
        ),
    ];
    let answers = rosbags(&cases);
    assert_eq!(answers.len(), 4);
    check("LaserScan", &scan(), &answers[0]);
    check("Imu", &imu(), &answers[1]);
    check("Odometry", &odometry(), &answers[2]);
    check("Twist", &twist(), &answers[3]);
}
