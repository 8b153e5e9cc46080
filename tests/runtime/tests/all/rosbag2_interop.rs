//! rosbag2 recordings (`coolbot::record`, `RecordFormat::Ros2`) against
//! implementations we did not write: a bag we record of `sensor_msgs/msg/LaserScan`
//! (the struct coolc generates, `cool/record.cool`) opens in rosbags' rosbag2
//! `Reader` (PyPI 0.11.x), whose types come from the bag's own message definitions,
//! and every message deserializes to the values sent; mcap-ros2-support's
//! `DecoderFactory` (PyPI 0.6) decodes every message of its MCAP file from its
//! `ros2msg` schema; and a bag rosbags writes replays into a component's harness.
//!
//! The Python with both is `$COOLBOT_PYTHON`, else `target/pyenv/bin/python`;
//! `.ci/run` makes it. Without it these tests fail, saying how to set it up.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use coolbot::System;
use coolbot::crossbeam_channel::{self, Sender};
use coolbot::harness::Harness;
use coolbot::harness::replay::Replay;
use coolbot::port::{DataOut, FifoIn};
use coolbot::record::{RecordFormat, Recorder};
use coolbot::ros::RosType;
use coolbot_runtime_tests::generated::types::LaserScan;
use coolbot_runtime_tests::generated::types::ros::builtin_interfaces::Time;
use coolbot_runtime_tests::generated::types::ros::std_msgs::Header;
use coolbot_runtime_tests::generated::{record_scan_sink, record_scan_source};

const SETUP: &str =
    "the rosbag2 interoperability tests need a Python with rosbags 0.11 and mcap-ros2-support 0.6:
    python3 -m venv target/pyenv
    target/pyenv/bin/pip install rosbags==0.11.9 mcap==1.6.0 mcap-ros2-support==0.6.0
then run the tests from the repository root, or set COOLBOT_PYTHON to that python";

const WAIT: Duration = Duration::from_secs(20);

fn python() -> PathBuf {
    if let Some(python) = std::env::var_os("COOLBOT_PYTHON") {
        return python.into();
    }
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/pyenv/bin/python");
    if venv.exists() {
        return venv;
    }
    panic!("COOLBOT_PYTHON is not set and target/pyenv does not exist: {SETUP}");
}

/// Runs `script` with `args`; its standard output as JSON.
fn run_python(script: &str, args: &[&Path]) -> serde_json::Value {
    let python = python();
    let output = Command::new(&python)
        .arg("-c")
        .arg(script)
        .args(args)
        .output()
        .unwrap_or_else(|error| panic!("cannot run {}: {error}: {SETUP}", python.display()));
    assert!(
        output.status.success(),
        "{} failed: {}",
        python.display(),
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).expect("the script prints JSON")
}

/// What the Python scripts print of a `LaserScan`, each float as its IEEE bits (exact
/// whatever the JSON parser).
const SCAN_PY: &str = r#"
import struct
def bits(values):
    return [struct.unpack('<I', struct.pack('<f', float(v)))[0] for v in values]
def scan(m):
    return {'sec': int(m.header.stamp.sec), 'nanosec': int(m.header.stamp.nanosec),
            'frame': m.header.frame_id,
            'angles': bits([m.angle_min, m.angle_max, m.angle_increment]),
            'times': bits([m.time_increment, m.scan_time]),
            'limits': bits([m.range_min, m.range_max]),
            'ranges': bits(m.ranges), 'intensities': bits(m.intensities)}
"#;

/// [`SCAN_PY`] of a scan, in Rust.
fn expected(scan: &LaserScan) -> serde_json::Value {
    let bits = |values: &[f32]| values.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    serde_json::json!({
        "sec": scan.header.stamp.sec,
        "nanosec": scan.header.stamp.nanosec,
        "frame": scan.header.frame_id,
        "angles": bits(&[scan.angle_min, scan.angle_max, scan.angle_increment]),
        "times": bits(&[scan.time_increment, scan.scan_time]),
        "limits": bits(&[scan.range_min, scan.range_max]),
        "ranges": bits(&scan.ranges),
        "intensities": bits(&scan.intensities),
    })
}

/// Scan `n`: distinct values, some not exact in binary.
fn scan(n: u16) -> LaserScan {
    LaserScan {
        header: Header {
            stamp: Time {
                sec: 1_700_000_000 + i32::from(n),
                nanosec: 123_456_789,
            },
            frame_id: format!("laser_{n}"),
        },
        angle_min: -1.1,
        angle_max: 1.2,
        angle_increment: 0.1,
        time_increment: 1e-4,
        scan_time: 0.1,
        range_min: 0.05,
        range_max: 30.0,
        ranges: (0..720_u16)
            .map(|i| f32::from(n) + f32::from(i) * 0.01)
            .collect(),
        intensities: vec![f32::from(n), 0.3],
    }
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("coolbot-rosbag2-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Hands the `RecordScanSource`'s output to the test when it starts.
struct HandScan(Sender<DataOut<LaserScan>>);

impl record_scan_source::Behavior for HandScan {
    fn start(&mut self, cx: &mut record_scan_source::Cx<'_>) -> coolbot::SectionResult {
        let _ = self.0.send(cx.outputs.scan.clone());
        Ok(())
    }
}

/// Hands the `RecordScanSink`'s input to the test when it starts.
struct HandScans(Sender<FifoIn<LaserScan>>);

impl record_scan_sink::Behavior for HandScans {
    fn start(&mut self, cx: &mut record_scan_sink::Cx<'_>) -> coolbot::SectionResult {
        let _ = self.0.send(cx.inputs.scans.clone());
        Ok(())
    }
}

/// Opens the bag with rosbags' `Reader`, its types made from the bag's own message
/// definitions, and the bag's MCAP file with mcap's reader and mcap-ros2-support's
/// decoders.
const READ_BAG: &str = r#"
import json, sys
from importlib.metadata import version
from pathlib import Path
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

bag = Path(sys.argv[1])
store = get_typestore(Stores.EMPTY)
out = {'versions': [version('rosbags'), version('mcap-ros2-support')]}
with Reader(bag) as reader:
    out['topics'] = [[c.topic, c.msgtype, c.digest, c.msgcount,
                      c.ext.serialization_format, len(c.ext.offered_qos_profiles)]
                     for c in reader.connections]
    for c in reader.connections:
        store.register(get_types_from_msg(c.msgdef.data, c.msgtype))
    out['rosbags'] = [[c.topic, t, scan(store.deserialize_cdr(raw, c.msgtype))]
                      for c, t, raw in reader.messages()]
(mcap_file,) = bag.glob('*.mcap')
with mcap_file.open('rb') as f:
    mcap = make_reader(f, decoder_factories=[DecoderFactory()])
    out['profile'] = mcap.get_header().profile
    out['mcap'] = [[channel.topic, message.log_time, scan(decoded)]
                   for _, channel, message, decoded in mcap.iter_decoded_messages()]
json.dump(out, sys.stdout)
"#;

#[test]
fn our_bag_opens_in_rosbags_and_every_message_decodes_in_rosbags_and_mcap_ros2() {
    let dir = temp_dir("ours");
    let bag = dir.join("scans");
    let sent: Vec<LaserScan> = (1..=3).map(scan).collect();
    {
        let mut system = System::new();
        let (hand, out) = crossbeam_channel::bounded(1);
        system
            .add(record_scan_source::component("laser", HandScan(hand)))
            .unwrap();
        system.run_all().unwrap();
        let out = out.recv_timeout(WAIT).expect("the source started");
        let mut recorder = Recorder::new().format(RecordFormat::Ros2);
        recorder
            .tap_ros_on::<LaserScan>(&system, "laser.scan", "/scan")
            .unwrap();
        let recording = recorder.start(&bag).unwrap();
        for scan in &sent {
            out.send(scan.clone());
        }
        assert_eq!(recording.finish().unwrap().ports[0].recorded, 3);
    }
    let answer = run_python(&format!("{SCAN_PY}{READ_BAG}"), &[&bag]);
    assert!(answer["versions"][0].as_str().unwrap().starts_with("0.11."));
    assert!(answer["versions"][1].as_str().unwrap().starts_with("0.6."));
    assert_eq!(answer["profile"], "ros2");
    assert_eq!(
        answer["topics"],
        serde_json::json!([[
            "/scan",
            "sensor_msgs/msg/LaserScan",
            LaserScan::TYPE_HASH,
            3,
            "cdr",
            1
        ]])
    );
    let expected: Vec<serde_json::Value> = sent.iter().map(expected).collect();
    for reader in ["rosbags", "mcap"] {
        let messages = answer[reader].as_array().unwrap();
        let scans: Vec<&serde_json::Value> = messages.iter().map(|m| &m[2]).collect();
        assert_eq!(scans, expected.iter().collect::<Vec<_>>(), "{reader}");
        assert!(messages.iter().all(|m| m[0] == "/scan"), "{reader}");
    }
}

/// Writes a rosbag2 bag (version 9, MCAP) with rosbags' `Writer` and its Jazzy
/// types: each scan of `argv[2]` (JSON) on `/scan`, 10 ms apart.
const WRITE_BAG: &str = r#"
import json, sys
import numpy
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

store = get_typestore(Stores.ROS2_JAZZY)
LaserScan = store.types['sensor_msgs/msg/LaserScan']
Header = store.types['std_msgs/msg/Header']
Time = store.types['builtin_interfaces/msg/Time']
scans = json.loads(sys.argv[2])
with Writer(sys.argv[1], version=9, storage_plugin=StoragePlugin.MCAP) as writer:
    connection = writer.add_connection('/scan', LaserScan.__msgtype__, typestore=store)
    for i, s in enumerate(scans):
        message = LaserScan(
            header=Header(stamp=Time(sec=s['sec'], nanosec=s['nanosec']), frame_id=s['frame']),
            angle_min=s['angle_min'], angle_max=s['angle_max'],
            angle_increment=s['angle_increment'], time_increment=s['time_increment'],
            scan_time=s['scan_time'], range_min=s['range_min'], range_max=s['range_max'],
            ranges=numpy.array(s['ranges'], dtype=numpy.float32),
            intensities=numpy.array(s['intensities'], dtype=numpy.float32))
        writer.write(connection, 1_700_000_000_000_000_000 + i * 10_000_000,
                     store.serialize_cdr(message, LaserScan.__msgtype__))
print('{}')
"#;

#[test]
fn a_bag_rosbags_wrote_replays_into_a_harness() {
    let dir = temp_dir("theirs");
    let bag = dir.join("theirs");
    let sent: Vec<LaserScan> = (4..=6).map(scan).collect();
    // Each f32 as the f64 of the same value: numpy makes the same f32 of it.
    let values: Vec<serde_json::Value> = sent
        .iter()
        .map(|s| {
            serde_json::json!({
                "sec": s.header.stamp.sec, "nanosec": s.header.stamp.nanosec,
                "frame": s.header.frame_id,
                "angle_min": f64::from(s.angle_min), "angle_max": f64::from(s.angle_max),
                "angle_increment": f64::from(s.angle_increment),
                "time_increment": f64::from(s.time_increment),
                "scan_time": f64::from(s.scan_time),
                "range_min": f64::from(s.range_min), "range_max": f64::from(s.range_max),
                "ranges": s.ranges.iter().map(|v| f64::from(*v)).collect::<Vec<_>>(),
                "intensities": s.intensities.iter().map(|v| f64::from(*v)).collect::<Vec<_>>(),
            })
        })
        .collect();
    let values = serde_json::Value::Array(values).to_string();
    run_python(WRITE_BAG, &[&bag, Path::new(&values)]);

    let (hand, scans) = crossbeam_channel::bounded(1);
    let mut harness =
        Harness::running(record_scan_sink::component("sink", HandScans(hand))).unwrap();
    let scans = scans.recv_timeout(WAIT).expect("the sink started");
    let mut replay = Replay::open(&bag).unwrap();
    assert_eq!(replay.header().ports[0].path, "/scan");
    replay
        .route::<LaserScan>("/scan", &harness, "scans")
        .unwrap();
    let replayed = replay.play(&mut harness).unwrap();
    assert_eq!(replayed.sent["/scan"], 3);
    let (first, last) = replayed.span.unwrap();
    assert_eq!(last - first, Duration::from_millis(20), "recorded spacing");
    assert_eq!(harness.elapsed(), Duration::from_millis(20));
    assert_eq!(scans.drain().collect::<Vec<_>>(), sent);
}
