//! The example robot as a real process on ROS 2 (`--ros2`, `--features ros2`),
//! against a ROS 2 node written independently of ours: `zenoh-ros2-sdk` (PyPI),
//! through a Zenoh router of `eclipse-zenoh` (PyPI), as rmw_zenoh runs. The SDK's
//! subscribers receive `/scan` and `/odom` with plausible values; its `/cmd_vel`
//! Twists make the robot's supervisor hand the base to them (`teleoperated` on the
//! robot's monitoring port, printed in the status lines) and the base backs up as
//! commanded; a Twist that is not finite is refused; when the Twists stop the
//! wanderer drives again; the summary counts each topic and the rosbag2 bag of the run
//! holds the three topics.
//!
//! The Python and its processes: `tests/zenoh/tests/ros2_python` (the same as the
//! network layer's ROS 2 tests).
#![cfg(feature = "ros2")]

#[path = "../../../tests/zenoh/tests/ros2_python/mod.rs"]
mod ros2_python;

use std::io::{BufRead, BufReader, Read};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use ros2_python::{PATIENCE, ROUTER, Script, free_port, interfaces};
use rustix::process::{Pid, Signal, kill_process};
use serde_json::{Value, json};

/// A ROS 2 node of zenoh-ros2-sdk on the router at `port`: subscribers of `/scan`
/// and `/odom`, a publisher of `/cmd_vel`; it prints what it receives and publishes
/// a Twist for each `twist` order (`nan`: one whose forward speed is NaN).
const SDK: &str = r#"
import sys, json, math
from zenoh_ros2_sdk import get_registry
get_registry(sys.argv[2])
from zenoh_ros2_sdk import ROS2Subscriber, ROS2Publisher
port = int(sys.argv[1])

def out(**fields):
    print(json.dumps(fields), flush=True)

def on_scan(msg):
    out(kind="scan", frame=msg.header.frame_id, sec=msg.header.stamp.sec,
        angle_min=float(msg.angle_min), angle_max=float(msg.angle_max),
        angle_increment=float(msg.angle_increment), range_min=float(msg.range_min),
        range_max=float(msg.range_max), ranges=[float(r) for r in msg.ranges])

def on_odom(msg):
    p = msg.pose.pose
    q = p.orientation
    out(kind="odom", frame=msg.header.frame_id, child=msg.child_frame_id,
        sec=msg.header.stamp.sec, x=float(p.position.x), y=float(p.position.y),
        yaw=2.0 * math.atan2(float(q.z), float(q.w)))

scan = ROS2Subscriber("/scan", "sensor_msgs/msg/LaserScan", on_scan,
                      node_name="sdk_scan", router_port=port)
odom = ROS2Subscriber("/odom", "nav_msgs/msg/Odometry", on_odom,
                      node_name="sdk_odom", router_port=port)
pub = ROS2Publisher("/cmd_vel", "geometry_msgs/msg/Twist",
                    node_name="sdk_teleop", router_port=port)
Vector3 = pub.session_mgr.store.types["geometry_msgs/msg/Vector3"]
out(kind="ready")

for line in sys.stdin:
    order = json.loads(line)
    x = float("nan") if order["do"] == "nan" else order["x"]
    pub.publish(linear=Vector3(x=x, y=0.0, z=0.0),
                angular=Vector3(x=0.0, y=0.0, z=order.get("yaw", 0.0)))
"#;

/// Reads a rosbag2 bag with rosbags: each topic's type and message count.
const BAG: &str = r#"
import sys, json
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore
store = get_typestore(Stores.ROS2_JAZZY)
topics = {}
with Reader(sys.argv[1]) as reader:
    for connection, _, raw in reader.messages():
        store.deserialize_cdr(raw, connection.msgtype)
        entry = topics.setdefault(connection.topic, [connection.msgtype, 0])
        entry[1] += 1
print(json.dumps({"kind": "bag", "topics": topics}), flush=True)
"#;

/// The robot's process, its stdout lines as they come and all of it at the end.
struct Robot {
    child: Child,
    lines: mpsc::Receiver<String>,
    stdout: Option<std::thread::JoinHandle<String>>,
    stderr: Option<std::thread::JoinHandle<String>>,
}

impl Robot {
    fn start(args: &[String]) -> Robot {
        let mut child = Command::new(env!("CARGO_BIN_EXE_mobile-base"))
            .args(["--output", "lines", "--duration", "10min"])
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("the example starts");
        let out = child.stdout.take().expect("piped");
        let (sender, lines) = mpsc::channel();
        let stdout = std::thread::spawn(move || {
            let mut all = String::new();
            for line in BufReader::new(out).lines() {
                let Ok(line) = line else { break };
                all.push_str(&line);
                all.push('\n');
                let _ = sender.send(line);
            }
            all
        });
        let mut err = child.stderr.take().expect("piped");
        let stderr = std::thread::spawn(move || {
            let mut text = String::new();
            let _ = err.read_to_string(&mut text);
            text
        });
        Robot {
            child,
            lines,
            stdout: Some(stdout),
            stderr: Some(stderr),
        }
    }

    /// Whether a line containing `text` came within `wait`.
    fn saw(&self, text: &str, wait: Duration) -> bool {
        let deadline = Instant::now() + wait;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) if line.contains(text) => return true,
                Ok(_) => {}
                Err(_) => return false,
            }
        }
    }

    /// Stops it with SIGTERM; its whole stdout and stderr once it exited cleanly.
    fn stop(mut self) -> (String, String) {
        let pid = Pid::from_raw(i32::try_from(self.child.id()).expect("a pid")).expect("a pid");
        kill_process(pid, Signal::TERM).expect("signal sent");
        let deadline = Instant::now() + PATIENCE;
        let status = loop {
            if let Some(status) = self.child.try_wait().expect("waitable") {
                break status;
            }
            assert!(Instant::now() < deadline, "the robot did not exit");
            std::thread::sleep(Duration::from_millis(20));
        };
        let stdout = self.stdout.take().unwrap().join().expect("stdout read");
        let stderr = self.stderr.take().unwrap().join().expect("stderr read");
        assert!(status.success(), "{status}\n{stdout}\n{stderr}");
        (stdout, stderr)
    }
}

impl Drop for Robot {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The number after `label` on the summary's line that contains it.
fn count_after(stdout: &str, label: &str) -> u64 {
    let line = stdout
        .lines()
        .find(|line| line.contains(label))
        .unwrap_or_else(|| panic!("no `{label}` in the summary:\n{stdout}"));
    let rest = &line[line.find(label).unwrap() + label.len()..];
    rest.split_whitespace()
        .next()
        .and_then(|word| word.parse().ok())
        .unwrap_or_else(|| panic!("no count after `{label}`: {line}"))
}

fn angle_between(from: f64, to: f64) -> f64 {
    let turn = (to - from).rem_euclid(std::f64::consts::TAU);
    if turn > std::f64::consts::PI {
        turn - std::f64::consts::TAU
    } else {
        turn
    }
}

fn number(line: &Value, key: &str) -> f64 {
    line[key]
        .as_f64()
        .unwrap_or_else(|| panic!("no `{key}`: {line}"))
}

#[test]
fn the_robot_talks_ros_2_with_the_python_node_both_ways() {
    let port = free_port();
    let router = Script::start(ROUTER, &[port.to_string()]);
    router.next("ready");
    let bag: PathBuf =
        std::env::temp_dir().join(format!("mobile-base-ros2-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&bag);
    let robot = Robot::start(&[
        "--ros2".into(),
        "--ros-router".into(),
        format!("tcp/127.0.0.1:{port}"),
        "--record".into(),
        bag.to_string_lossy().into_owned(),
        "--record-format".into(),
        "ros2".into(),
    ]);
    let mut sdk = Script::start(SDK, &[port.to_string(), interfaces()]);
    sdk.next("ready");

    // `/scan`: the ultrasonic ring from the platform's centre, within its limits.
    let scan = sdk.next("scan");
    assert_eq!(scan["frame"], "base_link", "{scan}");
    assert!(scan["sec"].as_i64().unwrap() > 1_600_000_000, "{scan}");
    let (min, max) = (number(&scan, "range_min"), number(&scan, "range_max"));
    assert!(
        (min - 0.18).abs() < 1e-6 && (max - 3.18).abs() < 1e-5,
        "{scan}"
    );
    let ranges = scan["ranges"].as_array().unwrap();
    assert_eq!(ranges.len(), 8, "{scan}");
    for range in ranges {
        let range = range.as_f64().unwrap();
        assert!((min..=max + 1e-5).contains(&range), "{scan}");
    }
    let last = number(&scan, "angle_min") + 7.0 * number(&scan, "angle_increment");
    assert!((last - number(&scan, "angle_max")).abs() < 1e-5, "{scan}");

    // `/odom`: in the room (6 by 4 m), frames `odom` and `base_link`.
    let odom = sdk.next("odom");
    assert_eq!(
        (odom["frame"].as_str(), odom["child"].as_str()),
        (Some("odom"), Some("base_link")),
        "{odom}"
    );
    assert!(
        (0.0..=6.0).contains(&number(&odom, "x")) && (0.0..=4.0).contains(&number(&odom, "y")),
        "{odom}"
    );

    // A Twist that is not finite is refused (the summary counts it); then Twists
    // backing up straight until the robot's supervisor says `teleoperated`.
    sdk.order(json!({"do": "nan"}));
    let back = json!({"do": "twist", "x": -0.2, "yaw": 0.0});
    let deadline = Instant::now() + PATIENCE;
    loop {
        sdk.order(back.clone());
        if robot.saw(
            "robot: supervisor -> teleoperated",
            Duration::from_millis(100),
        ) {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "the robot never went teleoperated"
        );
    }

    // The base follows: it backs up along its heading, which the wanderer never does
    // (it drives forward, or turns on the spot).
    let start = loop {
        sdk.order(back.clone());
        if let Some(odom) = sdk.poll("odom", Duration::from_millis(100)) {
            break odom;
        }
        assert!(Instant::now() < deadline, "no odometry while teleoperated");
    };
    let (x0, y0, yaw0) = (
        number(&start, "x"),
        number(&start, "y"),
        number(&start, "yaw"),
    );
    loop {
        sdk.order(back.clone());
        if let Some(odom) = sdk.poll("odom", Duration::from_millis(100)) {
            let (x, y, yaw) = (number(&odom, "x"), number(&odom, "y"), number(&odom, "yaw"));
            // Along the heading it started with: negative is backwards.
            let along = (x - x0) * yaw0.cos() + (y - y0) * yaw0.sin();
            if along < -0.05 {
                assert!(
                    angle_between(yaw0, yaw).abs() < 0.2,
                    "it turned while backing up: {start} {odom}"
                );
                break;
            }
        }
        assert!(
            Instant::now() < deadline,
            "the base did not back up as commanded"
        );
    }

    // No more Twists: the wanderer drives again.
    assert!(
        robot.saw("robot: supervisor -> autonomous", PATIENCE),
        "the robot never went back to autonomous"
    );

    let (stdout, stderr) = robot.stop();
    assert!(
        stdout.contains("shutdown             clean"),
        "{stdout}\n{stderr}"
    );
    assert!(count_after(&stdout, "/scan out") > 0, "{stdout}");
    assert!(count_after(&stdout, "/odom out") > 0, "{stdout}");
    let received = count_after(&stdout, "/cmd_vel in");
    assert!(received > 0, "{stdout}");
    // (A pause of the machine longer than the teleop timeout between two Twists may
    // hand the base back and forth once more: first and last are what is sure.)
    let history = stdout
        .lines()
        .find_map(|line| line.strip_prefix("  robot supervisor     "))
        .and_then(|rest| rest.split(';').next())
        .unwrap_or_default();
    assert!(
        history.starts_with("autonomous -> teleoperated") && history.ends_with("-> autonomous"),
        "{stdout}"
    );
    // The Twists delivered reached `teleop`: the finite ones taken, the NaN refused
    // (its queue, 16 deep, drops the oldest, counted on its monitor, if the robot
    // stalls longer than 16 Twists take to come).
    let taken = count_after(&stdout, "outside commands");
    assert!(taken > 0 && taken < received, "{stdout}");
    assert!(
        stdout.contains(&format!("outside commands {taken} taken, 1 refused")),
        "{stdout}"
    );

    // The bag: rosbags reads every message of the three topics.
    let reader = Script::start(BAG, &[bag.to_string_lossy().into_owned()]);
    let read = reader.next("bag");
    let topics = &read["topics"];
    assert_eq!(topics["/scan"][0], "sensor_msgs/msg/LaserScan", "{read}");
    assert_eq!(topics["/odom"][0], "nav_msgs/msg/Odometry", "{read}");
    assert_eq!(topics["/cmd_vel"][0], "geometry_msgs/msg/Twist", "{read}");
    assert_eq!(topics["/cmd_vel"][1], received, "{read}");
    assert!(topics["/scan"][1].as_u64().unwrap() > 0, "{read}");
    drop(sdk);
    let _ = std::fs::remove_dir_all(&bag);
}
