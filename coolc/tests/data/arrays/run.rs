//! Runs the generated array types (`arrays.cool`): arrays longer than 32 elements
//! get their defaults, round-trip through serde (the way variables, configurations
//! and remote packets travel), and flow through a running system: a configuration
//! set through the control port, a scan sent from one component to another, a
//! controllable variable set and every observable one read on the monitoring port.

use std::time::Duration;

use arrays::generated::types::{Blob, Frame, LaserScan};
use arrays::generated::{recorder, scanner};
use coolbot::{Command, Monitor, System, Value};

const WAIT: Duration = Duration::from_secs(20);

fn variable(monitor: &Monitor, name: &str) -> Option<Value> {
    monitor
        .variables
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, v)| v.clone())
}

fn floats(value: Option<Value>) -> Option<Vec<f32>> {
    value?.to_serde().ok()
}

#[test]
fn long_arrays_get_their_defaults() {
    let scan = LaserScan::default();
    assert_eq!(scan.ranges, [0.0; 72]);
    assert_eq!(scan.grid, [[0; 40]; 2]);
    assert!(scan.names.iter().all(|name| name == "beam"));
    assert_eq!(scan.mask, None);
    assert!(scan.history.is_empty());
    let frame = Frame::default();
    assert_eq!(frame.scan, scan);
    assert_eq!(frame.weights, [1.5; 40]);

    let config = scanner::Config::default();
    assert_eq!(config.gains, [0.5; 72]);
    assert_eq!(config.offsets, [0.0; 50]);
    let vars = scanner::Vars::default();
    assert_eq!(vars.last, [0.0; 72]);
    assert_eq!(vars.limits, [0; 64]);
    assert_eq!(vars.frame, frame);
    assert_eq!(recorder::Vars::default().ranges, [0.0; 72]);
}

#[test]
fn byte_lists_encode_as_sequences_of_their_bytes_do() {
    let mut cells: [Vec<u8>; 40] = std::array::from_fn(|_| Vec::new());
    cells[39] = vec![9; 3];
    let blob = Blob {
        bytes: vec![1, 2, 255],
        parts: vec![vec![], vec![7; 5]],
        cells: Some(cells.clone()),
    };
    // The same fields as sequences serialized byte by byte (the long array through
    // `Same`: serde's own impls stop at 32 elements).
    #[derive(serde::Serialize)]
    struct Sequences {
        bytes: Vec<u8>,
        parts: Vec<Vec<u8>>,
        #[serde(with = "coolbot::serde_with::As::<Option<[coolbot::serde_with::Same; 40]>>")]
        cells: Option<[Vec<u8>; 40]>,
    }
    let sequences = Sequences {
        bytes: blob.bytes.clone(),
        parts: blob.parts.clone(),
        cells: Some(cells),
    };
    let cdr = coolbot::cdr::to_vec(&blob).unwrap();
    assert_eq!(cdr, coolbot::cdr::to_vec(&sequences).unwrap());
    assert_eq!(coolbot::cdr::from_slice::<Blob>(&cdr).unwrap(), blob);
    let value = Value::from_serde(&blob).unwrap();
    assert_eq!(value, Value::from_serde(&sequences).unwrap());
    let Value::Json(json) = &value else {
        panic!("not JSON: {value:?}")
    };
    assert_eq!(json["bytes"].as_array().unwrap().len(), 3);
    assert_eq!(json["bytes"][2], 255);
    assert_eq!(value.to_serde::<Blob>().unwrap(), blob);
}

#[test]
fn long_arrays_round_trip_through_serde() {
    let mut scan = LaserScan::default();
    for (i, range) in scan.ranges.iter_mut().enumerate() {
        *range = i as f32 * 0.25;
    }
    scan.grid[1][39] = 7;
    scan.names[32] = "last".to_owned();
    scan.mask = Some([3; 64]);
    scan.history = vec![scan.ranges, [1.0; 72]];
    let value = Value::from_serde(&scan).unwrap();
    let Value::Json(json) = &value else {
        panic!("not JSON: {value:?}")
    };
    // Every array is a sequence of all its elements.
    assert_eq!(json["ranges"].as_array().unwrap().len(), 72);
    assert_eq!(json["ranges"][71], 17.75);
    assert_eq!(json["grid"][1].as_array().unwrap().len(), 40);
    assert_eq!(json["mask"].as_array().unwrap().len(), 64);
    assert_eq!(json["history"][1].as_array().unwrap().len(), 72);
    let back: LaserScan = value.to_serde().unwrap();
    assert_eq!(back, scan);

    let frame = Frame {
        scan,
        weights: [2.0; 40],
    };
    let back: Frame = Value::from_serde(&frame).unwrap().to_serde().unwrap();
    assert_eq!(back, frame);

    let mut config = scanner::Config::default();
    config.offsets[49] = -1.0;
    let back: scanner::Config = Value::from_serde(&config).unwrap().to_serde().unwrap();
    assert_eq!(back, config);
    // A configuration naming only some fields keeps the defaults of the others.
    let partial: scanner::Config = Value::Record(vec![(
        "offsets".to_owned(),
        Value::List(vec![Value::Float(4.0); 50]),
    )])
    .to_serde()
    .unwrap();
    assert_eq!(partial.offsets, [4.0; 50]);
    assert_eq!(partial.gains, [0.5; 72]);
    // A sequence of the wrong length is an error, not a truncated array.
    let short = Value::Record(vec![(
        "gains".to_owned(),
        Value::List(vec![Value::Float(1.0); 71]),
    )]);
    assert!(short.to_serde::<scanner::Config>().is_err());
}

#[test]
fn long_arrays_flow_through_a_running_system() {
    let mut system = System::new();
    let scanner = system
        .add(scanner::component(
            "scanner",
            arrays::scanner::Scanner::default(),
        ))
        .unwrap();
    let recorder = system
        .add(recorder::component(
            "recorder",
            arrays::recorder::Recorder::default(),
        ))
        .unwrap();
    system.connect("scanner.scan", "recorder.scan").unwrap();
    system.run_all().unwrap();

    // Scans cross the connection: beam `i` is `0.5 * count`.
    let monitor = recorder
        .wait_for(
            |m| floats(variable(m, "ranges")).is_some_and(|r| r.len() == 72 && r[71] >= 1.0),
            WAIT,
        )
        .unwrap();
    let ranges = floats(variable(&monitor, "ranges")).unwrap();
    assert!(ranges.iter().all(|r| *r == ranges[0]), "{ranges:?}");

    // A new configuration of 72 gains through the control port.
    let gains: Vec<Value> = (0..72).map(|i| Value::Float(f64::from(i))).collect();
    scanner
        .command(Command::Configure(Value::Record(vec![(
            "gains".to_owned(),
            Value::List(gains),
        )])))
        .unwrap();
    let monitor = recorder
        .wait_for(
            |m| floats(variable(m, "ranges")).is_some_and(|r| r[1] > 0.0 && r[0] == 0.0),
            WAIT,
        )
        .unwrap();
    let ranges = floats(variable(&monitor, "ranges")).unwrap();
    assert_eq!(ranges[70], ranges[35] * 2.0, "{ranges:?}");

    // A controllable array of 64 elements, set and read back.
    scanner
        .command(Command::Set(
            "limits".to_owned(),
            Value::List(vec![Value::UInt(9); 64]),
        ))
        .unwrap();
    let monitor = scanner
        .wait_for(
            |m| {
                variable(m, "limits")
                    .and_then(|v| v.to_serde::<Vec<u16>>().ok())
                    .is_some_and(|l| l == vec![9; 64])
            },
            WAIT,
        )
        .unwrap();
    // The observable packet holding arrays reads back whole.
    let frame: Frame = variable(&monitor, "frame").unwrap().to_serde().unwrap();
    assert_eq!(frame.weights, [1.5; 40]);
    assert_eq!(frame.scan.ranges.len(), 72);
    assert_eq!(frame.scan.history.len(), 1);
    assert_eq!(floats(variable(&monitor, "last")).unwrap().len(), 72);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn a_supervisor_sets_a_long_array_through_its_typed_handle() {
    let rig = arrays::generated::rig::component("rig", arrays::rig::RigParts::default()).unwrap();
    let mut system = System::new();
    let rig = system.add(rig).unwrap();
    system.run_all().unwrap();
    let scanner = rig.instance("scanner").unwrap();
    scanner
        .wait_for(
            |m| {
                variable(m, "limits")
                    .and_then(|v| v.to_serde::<Vec<u16>>().ok())
                    .is_some_and(|l| l == vec![5; 64])
            },
            WAIT,
        )
        .unwrap();
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}
