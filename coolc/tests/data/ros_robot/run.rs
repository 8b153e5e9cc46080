//! Runs the generated `Robot` (`robot.cool`): a ROS 2 `LaserScan` sent through a port,
//! through a converter into the project's own packet; and checks the generated ROS 2
//! types against rosbags (PyPI, 0.11.x): the CDR bytes `coolbot::cdr` writes for a
//! `LaserScan`, an `Imu`, an `Odometry` and types with every `.msg` feature
//! deserialize in rosbags to the values set, and rosbags' bytes for those values
//! decode to the same values.
//!
//! The Python with rosbags is `$COOLBOT_PYTHON`; the `.msg` files of the test types
//! are in `$COOLBOT_TEST_MSGS`. The coolc test that builds this crate sets both.

use std::io::Write;
use std::process::{Command, Stdio};
use std::time::Duration;

use coolbot::ros::RosType;
use coolbot::{Monitor, State, System, Value};
use robot::converters::Convert;
use robot::generated::types::ros::builtin_interfaces::{Duration as RosDuration, Time};
use robot::generated::types::ros::coolbot_test::{Inner, Nothing};
use robot::generated::types::ros::geometry_msgs::{
    Point, Pose, PoseWithCovariance, Quaternion, Twist, TwistWithCovariance, Vector3,
};
use robot::generated::types::ros::std_msgs::Header;
use robot::generated::types::{Everything, Imu, Keywords, LaserScan, Odometry, Reading};
use robot::generated::{laser, robot as robot_compound};
use robot::robot::RobotParts;
use serde::Serialize;
use serde::de::DeserializeOwned;

const WAIT: Duration = Duration::from_secs(20);

fn variable(monitor: &Monitor, name: &str) -> Value {
    monitor
        .variables
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, v)| v.clone())
        .unwrap_or_else(|| panic!("no variable {name} in {monitor:?}"))
}

fn count(monitor: &Monitor, name: &str) -> u64 {
    u64::try_from(&variable(monitor, name)).unwrap_or(0)
}

#[test]
fn a_scan_reaches_the_planner_through_its_converter_and_the_logger_as_sent() {
    let component = robot_compound::component::<Convert>("robot", RobotParts::default()).unwrap();
    let mut system = System::new();
    let robot = system.add(component).unwrap();
    system.run_all().unwrap();
    let monitor = robot
        .wait_for(
            |m| count(m, "received") >= 3 && count(m, "logged") >= 3,
            WAIT,
        )
        .unwrap();
    assert_eq!(monitor.state, State::Running);
    // Scan `n` is stamped `n` and its nearest range is `n + 1`: the converter read
    // the scan the laser sent.
    let stamp = i64::try_from(&variable(&monitor, "stamp")).unwrap();
    let nearest = f64::try_from(&variable(&monitor, "nearest")).unwrap();
    assert!(stamp >= 1, "{monitor:?}");
    assert_eq!(nearest, stamp as f64 + 1.0, "{monitor:?}");
    assert_eq!(variable(&monitor, "frame"), Value::Str("laser".into()));
    assert_eq!(count(&monitor, "beams"), 8);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn the_laser_alone_sends_its_scans_in_its_harness() {
    let mut harness = laser::Harness::running(robot::laser::Laser::default()).unwrap();
    harness.advance(Duration::from_millis(10)).unwrap();
    let sent = harness.sent_scan().unwrap();
    assert!(sent.len() >= 2, "{sent:?}");
    assert_eq!(sent[0], robot::laser::scan(1));
    assert_eq!(sent[1], robot::laser::scan(2));
}

#[test]
fn each_type_carries_its_names_hash_constants_and_defaults() {
    assert_eq!(LaserScan::NAME, "sensor_msgs/msg/LaserScan");
    assert_eq!(LaserScan::DDS_NAME, "sensor_msgs::msg::dds_::LaserScan_");
    assert_eq!(
        LaserScan::TYPE_HASH,
        "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828"
    );
    assert_eq!(<Header as RosType>::NAME, "std_msgs/msg/Header");
    // An inherent constant of the `.msg` named like the trait's is the `.msg`'s.
    assert_eq!(Everything::NAME, "coolbot # not a comment");
    assert_eq!(<Everything as RosType>::NAME, "coolbot_test/msg/Everything");
    assert_eq!((Everything::MODE_SLOW, Everything::MODE_FAST), (0_u8, 1_u8));
    assert_eq!(Everything::LOWEST, i64::MIN);
    assert_eq!(Everything::PI.to_string(), "3.14159");
    const { assert!(Everything::ON) };
    assert_eq!(Nothing::ONLY_A_CONSTANT, 1);
    assert_eq!(Reading::KIND_RANGE, 1);

    let everything = Everything::default();
    assert_eq!(
        (everything.small, everything.level, everything.count),
        (-1, 255, -7)
    );
    assert_eq!((everything.ratio, everything.gain), (1.5, 1.0));
    assert_eq!(everything.text, "hello, world");
    assert_eq!(everything.label, "short");
    assert_eq!(everything.triple, [1.0, 2.0, 3.0]);
    assert_eq!(everything.few, [1, 2]);
    assert_eq!(everything.words, ["a,b", "c"]);
    assert!(everything.data.is_empty() && everything.tags.is_empty());
    assert_eq!(everything.inner.orientation.w, 1.0);
    assert_eq!(Quaternion::default().w, 1.0);
    assert_eq!(PoseWithCovariance::default().covariance, [0.0; 36]);
    let reading = Reading::default();
    assert_eq!((reading.grade, reading.r#type), (b'a', 1));
    assert_eq!(reading.samples, [0.0; 40]);
    let keywords = Keywords::default();
    assert!(keywords.r#loop);
    assert_eq!(keywords.r#move, "on");
    // Keyword fields keep their `.msg` names outside Rust.
    let json = serde_json::to_value(Keywords {
        self_: 1,
        r#type: 2,
        ..Keywords::default()
    })
    .unwrap();
    assert_eq!(
        json,
        serde_json::json!({"self": 1, "type": 2, "loop": true, "move": "on"})
    );
    // A message without fields is sent as the one byte rosidl gives it.
    assert_eq!(
        coolbot::cdr::to_vec(&Nothing::default()).unwrap(),
        [0, 1, 0, 0, 0]
    );
}

#[test]
fn a_value_over_a_bound_of_its_msg_is_refused_when_decoded() {
    let fits = full_everything();
    let bytes = coolbot::cdr::to_vec(&fits).unwrap();
    assert_eq!(
        coolbot::cdr::from_slice::<Everything>(&bytes).unwrap(),
        fits
    );
    let changes: [fn(&mut Everything); 5] = [
        |e| e.few = vec![0; 6],
        |e| e.label = "eleven char".into(),
        |e| e.tags.push("x".into()),
        |e| e.tags[0] = "five!".into(),
        |e| e.pair[1] = "five!".into(),
    ];
    for change in changes {
        let mut over = fits.clone();
        change(&mut over);
        let bytes = coolbot::cdr::to_vec(&over).unwrap();
        assert!(
            coolbot::cdr::from_slice::<Everything>(&bytes).is_err(),
            "{over:?}"
        );
        let json = serde_json::to_string(&over).unwrap();
        assert!(serde_json::from_str::<Everything>(&json).is_err(), "{json}");
    }
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
    std::array::from_fn(|i| scale * (f64::from(u8::try_from(i).unwrap()) + 0.1))
}

fn quaternion(x: f64, y: f64, z: f64, w: f64) -> Quaternion {
    Quaternion { x, y, z, w }
}

fn scan() -> LaserScan {
    LaserScan {
        time_increment: 1.0e-4,
        scan_time: 0.1,
        intensities: vec![100.0, 0.25, 7.0],
        ..robot::laser::scan(47)
    }
}

fn imu() -> Imu {
    Imu {
        header: header("imu_link"),
        orientation: quaternion(0.1, -0.2, 0.3, 0.927),
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
                position: Point {
                    x: 1.5,
                    y: -2.25,
                    z: 0.0,
                },
                orientation: quaternion(0.0, 0.0, 0.383, 0.924),
            },
            covariance: covariance(0.5),
        },
        twist: TwistWithCovariance {
            twist: Twist {
                linear: vector(0.4, 0.0, 0.0),
                angular: vector(0.0, 0.0, -0.7),
            },
            covariance: covariance(0.25),
        },
    }
}

/// Every field set, none to its default.
fn full_everything() -> Everything {
    let inner = |id| Inner {
        id,
        orientation: quaternion(0.5, -0.5, 0.25, 0.625),
    };
    Everything {
        flag: true,
        // rosbags reads and writes a single `byte` as a signed one: the same octet.
        raw: 0x7e,
        small: -100,
        level: 17,
        i16: -30_000,
        u16: 60_000,
        count: -2_000_000_000,
        u32: 4_000_000_000,
        i64: i64::MIN + 1,
        u64: u64::MAX - 1,
        ratio: -0.3,
        gain: 1e-300,
        text: "ünïcödé, and # not a comment".into(),
        label: "ten chars!".into(),
        triple: [0.1, -0.2, 1e10],
        few: vec![5, -4, 3, -2, 1],
        data: vec![0, 1, 254, 255],
        words: vec![String::new(), "two words".into(), "x".into()],
        tags: vec!["abcd".into(), "é".into(), String::new()],
        pair: ["left".into(), "r".into()],
        inner: inner(1),
        inners: [inner(2), inner(3)],
        some_inners: vec![inner(4), inner(5)],
        header: header("everything"),
        points: vec![
            Point {
                x: 1.0,
                y: 2.0,
                z: 3.0,
            },
            Point {
                x: -1.0,
                y: -2.0,
                z: -3.5,
            },
        ],
        durations: vec![RosDuration {
            sec: -5,
            nanosec: 999_999_999,
        }],
        nothing: Nothing::default(),
    }
}

fn reading() -> Reading {
    Reading {
        grade: b'z',
        r#type: 7,
        samples: std::array::from_fn(|i| f32::from(u8::try_from(i).unwrap()) * 0.5 - 3.0),
        stamps: vec![
            Time { sec: 1, nanosec: 2 },
            Time {
                sec: -3,
                nanosec: 4,
            },
        ],
    }
}

/// For each case `{"type", "ours": hex, "value": JSON}`: rosbags' decoding of `ours`
/// (as JSON, each float as `{"f64": its IEEE bits}`, exact whatever the JSON parser)
/// and its serialization of `value` (as hex). The types of `register` (name to `.msg`
/// text) join its Jazzy type store first.
const SCRIPT: &str = r#"
import json, struct, sys
from importlib.metadata import version
import numpy
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

request = json.load(sys.stdin)
store = get_typestore(Stores.ROS2_JAZZY)
types = {}
for name, text in request['register'].items():
    types.update(get_types_from_msg(text, name))
store.register(types)
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
for case in request['cases']:
    typename = case['type']
    decoded = store.deserialize_cdr(bytes.fromhex(case['ours']), typename)
    encoded = store.serialize_cdr(build(typename, case['value']), typename)
    results.append({'decoded': dump(typename, decoded), 'theirs': bytes(encoded).hex()})
json.dump({'rosbags': version('rosbags'), 'results': results}, sys.stdout)
"#;

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

/// Checks what rosbags made of a case: its decoding of our bytes, and its own bytes.
type Check = Box<dyn Fn(&serde_json::Value, &[u8])>;

/// One case: a value of a generated type, its bytes and its JSON.
struct Case {
    ros_name: &'static str,
    ours: Vec<u8>,
    value: serde_json::Value,
    check: Check,
}

fn case<T>(value: T) -> Case
where
    T: RosType + Serialize + DeserializeOwned + PartialEq + std::fmt::Debug + 'static,
{
    let ours = coolbot::cdr::to_vec(&value).unwrap();
    let json = serde_json::to_value(&value).unwrap();
    let mine = ours.clone();
    Case {
        ros_name: T::NAME,
        ours,
        value: json,
        check: Box::new(move |decoded, theirs| {
            let name = T::NAME;
            // rosbags read our bytes as the values we set.
            let seen: T = serde_json::from_value(decoded.clone())
                .unwrap_or_else(|error| panic!("{name}: {error}: {decoded}"));
            assert_eq!(seen, value, "{name}: rosbags read our bytes otherwise");
            // Its bytes decode in ours to the same values.
            let back: T = coolbot::cdr::from_slice(theirs).unwrap();
            assert_eq!(back, value, "{name}: we read rosbags' bytes otherwise");
            // And they are the very bytes we write.
            assert_eq!(mine, theirs, "{name}: our bytes differ from rosbags'");
        }),
    }
}

#[test]
fn cdr_of_the_generated_types_reads_in_rosbags_and_back() {
    let python =
        std::env::var_os("COOLBOT_PYTHON").expect("COOLBOT_PYTHON names a Python with rosbags");
    let msgs = std::path::PathBuf::from(
        std::env::var_os("COOLBOT_TEST_MSGS").expect("COOLBOT_TEST_MSGS names the test .msg files"),
    );
    let register: serde_json::Map<String, serde_json::Value> = [
        "coolbot_test/msg/Everything",
        "coolbot_test/msg/Inner",
        "coolbot_test/msg/Nothing",
        "robot_msgs/msg/Reading",
    ]
    .iter()
    .map(|name| {
        let path = msgs.join(format!("{name}.msg"));
        let text = std::fs::read_to_string(&path)
            .unwrap_or_else(|error| panic!("{}: {error}", path.display()));
        ((*name).to_owned(), serde_json::Value::String(text))
    })
    .collect();
    let cases = [
        case(scan()),
        case(imu()),
        case(odometry()),
        case(full_everything()),
        case(Everything::default()),
        case(reading()),
    ];
    let request = serde_json::json!({
        "register": register,
        "cases": cases
            .iter()
            .map(|c| serde_json::json!({"type": c.ros_name, "ours": hex(&c.ours), "value": c.value}))
            .collect::<Vec<_>>(),
    });
    let mut child = Command::new(&python)
        .args(["-c", SCRIPT])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|error| panic!("cannot run {}: {error}", python.display()));
    child
        .stdin
        .take()
        .unwrap()
        .write_all(request.to_string().as_bytes())
        .unwrap();
    let output = child.wait_with_output().unwrap();
    assert!(
        output.status.success(),
        "{} failed: {}",
        python.display(),
        String::from_utf8_lossy(&output.stderr)
    );
    let answer: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert!(answer["rosbags"].as_str().unwrap().starts_with("0.11."));
    let results = answer["results"].as_array().unwrap();
    assert_eq!(results.len(), cases.len());
    for (case, result) in cases.iter().zip(results) {
        let decoded = exact_floats(result["decoded"].clone());
        let theirs = unhex(result["theirs"].as_str().unwrap());
        (case.check)(&decoded, &theirs);
    }
}
