//! ROS 2 topics on the rmw_zenoh wire, against an implementation written
//! independently of ours: `zenoh-ros2-sdk` (PyPI), a ROS 2 node over Zenoh without
//! ROS, through a Zenoh router run by `eclipse-zenoh` (PyPI), as rmw_zenoh runs.
//! Its subscriber receives our `/scan` with the values sent; its publisher's
//! `/cmd_vel` reaches our input with the values sent; its graph discovery (the
//! liveliness tokens, as `ros2 topic info -v` reads them) sees our node's publisher
//! and subscription with their types, hashes and QoS; a message on our key that does
//! not decode is counted at the subscription's `network` input, not delivered.
//!
//! The Python is `$COOLBOT_PYTHON`, else `target/pyenv/bin/python`; `.ci/run` makes
//! it. Without it these tests fail, saying how to set it up (`ros2_python`, shared
//! with the example robot's test against the same node).

mod ros2_python;

use std::time::Duration;

use coolbot::crossbeam_channel;
use coolbot::port::{DataOut, FifoIn};
use coolbot::ros::RosType;
use coolbot::{ConnectError, System};
use coolbot_zenoh::ros2::{self, Participant, RosError, RosOptions};
use coolbot_zenoh_tests::generated::types::ros::builtin_interfaces::Time;
use coolbot_zenoh_tests::generated::types::ros::std_msgs::Header;
use coolbot_zenoh_tests::generated::types::{LaserScan, Ranges, Speed, Twist};
use coolbot_zenoh_tests::generated::{drive, lidar, ranger, wheels};
use coolbot_zenoh_tests::support::{Hand, PATIENCE, free_port, wait_until};
use ros2_python::{ROUTER, Script, interfaces};
use serde_json::{Value, json};
use zenoh::Wait;

/// A ROS 2 node of zenoh-ros2-sdk on the router at `port`: a subscriber of `/scan`
/// and a publisher of `/cmd_vel`, the message definitions read from `dir`; it prints
/// what it receives and does what each line of stdin says.
const SDK: &str = r#"
import sys, json
from zenoh_ros2_sdk import get_registry
get_registry(sys.argv[2])
from zenoh_ros2_sdk import ROS2Subscriber, ROS2Publisher, get_topic_info
port = int(sys.argv[1])

def out(**fields):
    print(json.dumps(fields), flush=True)

def on_scan(msg):
    out(kind="scan", frame=msg.header.frame_id, sec=msg.header.stamp.sec,
        nanosec=msg.header.stamp.nanosec, angle_min=float(msg.angle_min),
        angle_increment=float(msg.angle_increment), range_max=float(msg.range_max),
        ranges=[float(r) for r in msg.ranges])

sub = ROS2Subscriber("/scan", "sensor_msgs/msg/LaserScan", on_scan,
                     node_name="sdk_listener", router_port=port)
pub = ROS2Publisher("/cmd_vel", "geometry_msgs/msg/Twist",
                    node_name="sdk_talker", router_port=port)
Vector3 = pub.session_mgr.store.types["geometry_msgs/msg/Vector3"]
out(kind="ready", scan_hash=sub.type_hash, twist_hash=pub.type_hash)

def endpoints(items):
    return [dict(node=e.node_name, namespace=e.node_namespace, type=e.topic_type,
                 hash=e.type_hash, qos=e.qos) for e in items]

for line in sys.stdin:
    order = json.loads(line)
    if order["do"] == "twist":
        pub.publish(linear=Vector3(x=order["x"], y=0.0, z=0.0),
                    angular=Vector3(x=0.0, y=0.0, z=order["yaw"]))
    elif order["do"] == "garbage":
        pub.session_mgr.session.put(pub.keyexpr, bytes([0, 1, 0, 0, 7]))
    elif order["do"] == "info":
        info = get_topic_info(order["topic"], router_port=port, verbose=True, timeout=1.0)
        if info is None:
            out(kind="info", topic=order["topic"], publishers=[], subscribers=[])
        else:
            out(kind="info", topic=order["topic"], publishers=endpoints(info.publishers),
                subscribers=endpoints(info.subscribers))
"#;

fn scan(sec: i32) -> LaserScan {
    LaserScan {
        header: Header {
            stamp: Time {
                sec,
                nanosec: 250_000_000,
            },
            frame_id: "laser".into(),
        },
        angle_min: -1.5,
        angle_max: 1.5,
        angle_increment: 0.75,
        range_max: 12.0,
        ranges: vec![1.0, 2.5, 3.25, 4.0, 0.5],
        ..LaserScan::default()
    }
}

/// The router, and a participant of ours on it (a session of its own, as
/// `ros2::router_config` makes), running a lidar publishing `/scan` and a drive
/// subscribed to `/cmd_vel`.
struct Robot {
    _router: Script,
    port: u16,
    ros: Participant,
    system: System,
    scans: DataOut<LaserScan>,
    commands: FifoIn<Twist>,
    _session: zenoh::Session,
}

fn robot() -> Robot {
    let port = free_port();
    let router = Script::start(ROUTER, &[port.to_string()]);
    router.next("ready");
    let config = ros2::router_config(&format!("tcp/127.0.0.1:{port}")).unwrap();
    let session = zenoh::open(config).wait().expect("a session on the router");
    let options = RosOptions {
        node: "coolbot_test".into(),
        ..RosOptions::default()
    };
    let ros = Participant::open(&session, &options).unwrap();
    let mut system = System::new();
    let (hand_scan, scans) = crossbeam_channel::bounded(1);
    let (hand_cmd, commands) = crossbeam_channel::bounded(1);
    system
        .add(lidar::component("lidar", Hand(hand_scan)))
        .unwrap();
    system
        .add(drive::component("drive", Hand(hand_cmd)))
        .unwrap();
    ros.publish::<LaserScan>(&mut system, "/scan", "lidar.scan")
        .unwrap();
    ros.subscribe::<Twist>(&mut system, "cmd_vel", "drive.cmd")
        .unwrap();
    system.run_all().unwrap();
    Robot {
        _router: router,
        port,
        ros,
        system,
        scans: scans.recv_timeout(PATIENCE).unwrap(),
        commands: commands.recv_timeout(PATIENCE).unwrap(),
        _session: session,
    }
}

fn sdk(port: u16) -> Script {
    Script::start(SDK, &[port.to_string(), interfaces()])
}

#[test]
fn topics_cross_both_ways_with_the_python_ros_2_node() {
    let robot = robot();
    let mut sdk = sdk(robot.port);
    let ready = sdk.next("ready");
    // The SDK computed each type's hash itself: the data keys match only if ours agree.
    assert_eq!(ready["scan_hash"], LaserScan::TYPE_HASH);
    assert_eq!(ready["twist_hash"], Twist::TYPE_HASH);

    // Ours to the SDK: scans until its subscriber has one (discovery takes a moment).
    let mut sent = 0;
    let received = loop {
        sent += 1;
        robot.scans.send(scan(sent));
        if let Some(line) = sdk.poll("scan", Duration::from_millis(100)) {
            break line;
        }
        assert!(sent < 300, "the SDK's subscriber received no scan");
    };
    let sec = received["sec"].as_i64().unwrap();
    assert!((1..=i64::from(sent)).contains(&sec), "{received}");
    assert_eq!(received["frame"], "laser");
    assert_eq!(received["nanosec"], 250_000_000);
    assert_eq!(received["angle_min"], -1.5);
    assert_eq!(received["angle_increment"], 0.75);
    assert_eq!(received["range_max"], 12.0);
    assert_eq!(received["ranges"], json!([1.0, 2.5, 3.25, 4.0, 0.5]));

    // The SDK's to ours: twists until the drive has one.
    let mut twist = None;
    for _ in 0..300 {
        sdk.order(json!({"do": "twist", "x": 0.25, "yaw": -0.5}));
        if wait_until(Duration::from_millis(100), || !robot.commands.is_empty()) {
            twist = robot.commands.drain().next();
            break;
        }
    }
    let twist = twist.expect("the SDK's twist reaches the drive");
    assert_eq!(twist.linear.x, 0.25);
    assert_eq!(twist.linear.y, 0.0);
    assert_eq!(twist.angular.z, -0.5);

    let counts = robot.ros.counts();
    assert_eq!(counts[0].topic, "/scan");
    assert_eq!(counts[0].direction, ros2::Direction::Out);
    assert_eq!(counts[0].messages, u64::from(sent as u32));
    assert_eq!(counts[1].topic, "/cmd_vel");
    assert_eq!(counts[1].direction, ros2::Direction::In);
    assert!(counts[1].messages >= 1);
    assert_eq!(counts[1].lost, 0);
    drop(sdk);
    assert!(robot.system.shutdown().clean());
}

#[test]
fn the_python_node_sees_ours_on_the_graph() {
    let robot = robot();
    let mut sdk = sdk(robot.port);
    sdk.next("ready");
    let mut endpoint = |topic: &str, side: &str| -> Value {
        let mut found = Value::Null;
        let seen = wait_until(PATIENCE, || {
            sdk.order(json!({"do": "info", "topic": topic}));
            let info = sdk.next("info");
            let ours = info[side]
                .as_array()
                .and_then(|list| list.iter().find(|e| e["node"] == "coolbot_test").cloned());
            match ours {
                Some(ours) => {
                    found = ours;
                    true
                }
                None => false,
            }
        });
        assert!(seen, "our {side} of {topic} is not on the graph");
        found
    };
    let publisher = endpoint("/scan", "publishers");
    assert_eq!(publisher["type"], "sensor_msgs/msg/LaserScan");
    assert_eq!(publisher["hash"], LaserScan::TYPE_HASH);
    assert_eq!(publisher["namespace"], "/");
    assert_eq!(publisher["qos"], "::,10:,:,:,,");
    let subscription = endpoint("/cmd_vel", "subscribers");
    assert_eq!(subscription["type"], "geometry_msgs/msg/Twist");
    assert_eq!(subscription["hash"], Twist::TYPE_HASH);
}

#[test]
fn a_message_that_does_not_decode_is_counted_not_delivered() {
    let robot = robot();
    let mut sdk = sdk(robot.port);
    sdk.next("ready");
    let subscription = robot.system.handle("ros2_sub_cmd_vel").unwrap();
    let events = subscription.subscribe();
    let counted = wait_until(PATIENCE, || {
        sdk.order(json!({"do": "garbage"}));
        wait_until(Duration::from_millis(100), || {
            subscription.snapshot().overflows > 0
        })
    });
    assert!(counted, "the bad message is not counted");
    let lost = robot.ros.counts()[1].lost;
    assert!(lost >= 1);
    assert_eq!(
        subscription.snapshot().port_overflows[0],
        ("network".to_owned(), lost)
    );
    assert!(
        events
            .try_iter()
            .any(|event| matches!(event, coolbot::MonitorEvent::Overflow { ref port, .. } if port == "network")),
        "no overflow event on the monitoring port"
    );
    assert!(robot.commands.is_empty(), "a bad message was delivered");
    assert_eq!(robot.ros.counts()[1].messages, 0);
    drop(sdk);
    assert!(robot.system.shutdown().clean());
}

#[test]
fn a_port_of_another_type_is_a_typed_error() {
    let port = free_port();
    let mut config = zenoh::Config::default();
    config.insert_json5("mode", "\"peer\"").unwrap();
    config
        .insert_json5("listen/endpoints", &format!("[\"tcp/127.0.0.1:{port}\"]"))
        .unwrap();
    config
        .insert_json5("scouting/multicast/enabled", "false")
        .unwrap();
    let session = zenoh::open(config).wait().unwrap();
    let ros = Participant::open(&session, &RosOptions::default()).unwrap();
    let mut system = System::new();
    let (hand, _) = crossbeam_channel::bounded(1);
    system.add(lidar::component("lidar", Hand(hand))).unwrap();
    let error = ros
        .publish::<Twist>(&mut system, "/scan", "lidar.scan")
        .unwrap_err();
    let RosError::Connect {
        port,
        topic,
        source,
    } = &error
    else {
        panic!("{error:?}");
    };
    assert_eq!((port.as_str(), topic.as_str()), ("lidar.scan", "/scan"));
    assert!(
        matches!(**source, ConnectError::TypeMismatch { .. }),
        "{source:?}"
    );
    let error = ros
        .publish::<LaserScan>(&mut system, "/bad topic", "lidar.scan")
        .unwrap_err();
    assert!(matches!(error, RosError::Name(_)), "{error:?}");
    assert!(
        ros2::router_config("tcp/192.0.2.1:7447").is_err(),
        "a router off loopback without a security file"
    );
}

/// The program's own packets cross through converters: its ranges go out as
/// `LaserScan`, the SDK's `Twist` comes in as its `Speed`.
#[test]
fn converters_carry_the_programs_own_packets() {
    let port = free_port();
    let _router = Script::start(ROUTER, &[port.to_string()]);
    _router.next("ready");
    let config = ros2::router_config(&format!("tcp/127.0.0.1:{port}")).unwrap();
    let session = zenoh::open(config).wait().unwrap();
    let ros = Participant::open(&session, &RosOptions::default()).unwrap();
    let mut system = System::new();
    let (hand_ranges, ranges) = crossbeam_channel::bounded(1);
    let (hand_speed, speeds) = crossbeam_channel::bounded(1);
    system
        .add(ranger::component("ranger", Hand(hand_ranges)))
        .unwrap();
    system
        .add(wheels::component("wheels", Hand(hand_speed)))
        .unwrap();
    ros.publish_via(&mut system, "/scan", "ranger.ranges", |r: &Ranges| {
        LaserScan {
            header: Header {
                stamp: Time {
                    sec: r.seq as i32,
                    nanosec: 0,
                },
                frame_id: "ranger".into(),
            },
            ranges: vec![r.near, r.far],
            ..LaserScan::default()
        }
    })
    .unwrap();
    ros.subscribe_via(&mut system, "/cmd_vel", "wheels.speed", |t: &Twist| Speed {
        forward: t.linear.x,
        turn: t.angular.z,
    })
    .unwrap();
    system.run_all().unwrap();
    let ranges: DataOut<Ranges> = ranges.recv_timeout(PATIENCE).unwrap();
    let speeds: FifoIn<Speed> = speeds.recv_timeout(PATIENCE).unwrap();
    let mut sdk = sdk(port);
    sdk.next("ready");
    let mut seq = 0;
    let received = loop {
        seq += 1;
        ranges.send(Ranges {
            seq,
            near: 0.5,
            far: 7.25,
        });
        if let Some(line) = sdk.poll("scan", Duration::from_millis(100)) {
            break line;
        }
        assert!(seq < 300, "the SDK's subscriber received no scan");
    };
    assert_eq!(received["frame"], "ranger");
    assert_eq!(received["ranges"], json!([0.5, 7.25]));
    let mut speed = None;
    for _ in 0..300 {
        sdk.order(json!({"do": "twist", "x": 0.75, "yaw": 0.125}));
        if wait_until(Duration::from_millis(100), || !speeds.is_empty()) {
            speed = speeds.drain().next();
            break;
        }
    }
    let speed = speed.expect("the SDK's twist reaches the wheels");
    assert_eq!((speed.forward, speed.turn), (0.75, 0.125));
    drop(sdk);
    assert!(system.shutdown().clean());
}
