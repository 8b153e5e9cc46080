//! `--drivers`: the robot with its range server in a process of its own (the node
//! `drivers`, started by the robot: this binary with `--node drivers --serve`), two OS
//! processes on loopback. The robot behaves as in one process: the scans arrive and
//! are taken where the robot is, the wanderer keeps clear of the obstacles. `kill -9`
//! of the drivers process is a fault of the range server's proxy: the base substitutes
//! the simulated range server, the robot starts the drivers process again, and the
//! recovery queue brings the range server back on it.
#![cfg(feature = "network")]

use std::collections::HashSet;
use std::sync::mpsc;

use coolbot::record::Reader;
use mobile_base::RECORDED_PORTS;
use mobile_base::generated::types::{Pose2D, RangeScan};
use mobile_base::sensing;
use mobile_base::world::{Pose, World};
use rustix::process::{Pid, Signal, kill_process};

use crate::support::{free_port, spawn, wait_line, wait_lines};

/// The pid in a line `... drivers process <pid> started ...`.
fn started_pid(line: &str) -> u32 {
    line.split("drivers process ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .and_then(|pid| pid.parse().ok())
        .unwrap_or_else(|| panic!("no pid in {line:?}"))
}

/// The number after `label` in `text` (the summary's figures).
fn figure(text: &str, label: &str) -> f64 {
    text.split(label)
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|number| number.trim_end_matches([',', ';']).parse().ok())
        .unwrap_or_else(|| panic!("no figure after {label:?} in:\n{text}"))
}

/// A scan's infrared ranges and bumpers: what every reading refreshes, at any quality.
type Seen = ([f32; 8], [bool; 4]);

/// What the sensors of a robot at `pose` see, noise-free.
fn seen_from(world: &World, pose: &Pose2D) -> Seen {
    let pose = Pose {
        x: pose.x,
        y: pose.y,
        theta: pose.theta,
    };
    let scan = sensing::scan(coolbot::Time::default(), &world.sense(pose, 0.8, 3.0));
    (scan.ir, scan.bumpers)
}

#[test]
fn with_drivers_the_range_server_runs_in_its_own_process_and_a_kill_9_is_substituted_and_recovered()
{
    let dir = std::env::temp_dir().join(format!("mobile-base-drivers-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let recording = dir.join("run.mcap");
    let listen = format!("tcp/127.0.0.1:{}", free_port());
    let (sender, lines) = mpsc::channel();
    let (mut robot, out) = spawn(
        "",
        &[
            "--drivers",
            "--node",
            "robot",
            "--listen",
            &listen,
            "--no-multicast",
            "--lease",
            "1s",
            "--duration",
            "120s",
            "--output",
            "lines",
            "--noise",
            "0",
            "--record",
            recording.to_str().expect("a UTF-8 path"),
        ],
        "warn",
        &sender,
    );
    // Only the robot's pipes hold a sender: its early end fails the waits at once.
    drop(sender);
    let mut seen = Vec::new();
    let says = |text: &'static str| move |l: &str| l.contains(text);
    let status = |a: &'static str, b: &'static str| {
        move |l: &str| l.starts_with('[') && l.contains(a) && l.contains(b)
    };

    // The robot started the drivers process, whose node serves; the range server runs
    // there (behind its proxy here), the simulated one stands by.
    let first = started_pid(&wait_line(
        &lines,
        &mut seen,
        "of the drivers process started",
        |l| l.contains("drivers process ") && l.contains(" started"),
    ));
    wait_line(
        &lines,
        &mut seen,
        "with the range server streaming and the simulated one ready",
        status(" ranges=running/", " sim_ranges=ready"),
    );

    // kill -9 of the drivers process: the proxy fails on the loss of the node, the
    // simulated range server stands in; the robot starts the process again, and the
    // range server comes back on it.
    kill_process(Pid::from_raw(first as i32).expect("a pid"), Signal::KILL).expect("SIGKILL");
    // The supervisor's steps and the watcher's lines on the process come from threads
    // of their own: in any order.
    let ending = format!("drivers process {first} ended");
    let first_started = format!("drivers process {first} ");
    let [_, _, ended, again] = wait_lines(
        &lines,
        &mut seen,
        [
            (
                "saying the drivers node is lost",
                &says("base: ranges failed: node `drivers` is lost"),
            ),
            (
                "substituting the simulated range server",
                &says("base: ranges substituted by sim_ranges"),
            ),
            ("of the drivers process ended", &|l: &str| {
                l.contains(&ending)
            }),
            ("of a drivers process started again", &|l: &str| {
                l.contains("drivers process ")
                    && l.contains(" started")
                    && !l.contains(&first_started)
            }),
        ],
    );
    assert!(ended.contains("killed by signal 9"), "{ended}");
    let second = started_pid(&again);
    assert_ne!(second, first);
    wait_line(
        &lines,
        &mut seen,
        "saying the range server recovered",
        says("base: ranges recovered"),
    );
    wait_line(
        &lines,
        &mut seen,
        "with the range server back and the simulated one ready",
        status(" ranges=running/", " sim_ranges=ready"),
    );

    // SIGTERM: a clean shutdown, which stops the drivers process too.
    kill_process(Pid::from_child(&robot), Signal::TERM).expect("SIGTERM");
    let exit = robot.wait().expect("the robot exits");
    let out = out.join().expect("stdout");
    assert!(exit.success(), "{out}");
    assert!(out.contains("substitutions 1, recoveries 1"), "{out}");
    assert!(
        out.contains("drivers process      started 2 times, 1 ended while the robot ran (killed by signal 9); at the end: exit status 0"),
        "{out}"
    );
    assert!(
        out.contains("clean: every component dead, every thread joined"),
        "{out}"
    );
    assert!(
        std::fs::read_dir(format!("/proc/{second}")).is_err(),
        "the drivers process {second} ended with the robot"
    );

    let summary = &out[out.find("summary after").expect("a summary")..];
    // The wanderer kept clear as in one process (`tests/robot.rs`, `assert_safe`):
    // the robot moved, never touched an obstacle, and stopped for what came within the
    // emergency distance ahead (0.3 m, less a margin).
    let travelled = figure(summary, "distance travelled");
    assert!(travelled > 0.2, "the robot hardly moved: {summary}");
    assert_eq!(figure(summary, "; contacts"), 0.0, "{summary}");
    let ahead = figure(summary, "m from an obstacle,");
    let emergencies = figure(summary, "emergencies");
    assert!(emergencies > 0.0 || ahead > 0.25, "{summary}");
    // Both range servers published: the real one before and after, the simulated one
    // while it stood in.
    assert!(
        figure(summary, "scans                ranges") > 0.0,
        "{summary}"
    );
    assert!(figure(summary, ", sim_ranges") > 0.0, "{summary}");

    // The scans reflect the robot's motion: each was taken where the odometry said the
    // robot was (the world seen from one of the poses the motion controller published),
    // from many poses along the way. The recording holds every pose from the first.
    let reader = Reader::open(&recording).expect("the recording opens");
    let poses: Vec<Pose2D> = reader
        .packets::<Pose2D>(RECORDED_PORTS[0])
        .map(|item| item.expect("a pose").1)
        .collect();
    let scans: Vec<RangeScan> = Reader::open(&recording)
        .expect("opens")
        .packets::<RangeScan>(RECORDED_PORTS[1])
        .map(|item| item.expect("a scan").1)
        .collect();
    assert!(
        out.contains(&format!(
            "{} {} recorded, 0 lost",
            RECORDED_PORTS[0],
            poses.len()
        )),
        "every pose recorded: {out}"
    );
    assert!(scans.len() > 20, "{} scans", scans.len());
    let world = World::example();
    let places: Vec<Seen> = poses.iter().map(|pose| seen_from(&world, pose)).collect();
    let mut matched = HashSet::new();
    for (i, scan) in scans.iter().enumerate() {
        let found = places
            .iter()
            .position(|seen| *seen == (scan.ir, scan.bumpers));
        let at = found.unwrap_or_else(|| {
            panic!(
                "scan {i} of {} was taken at no pose the robot had: {scan:?}",
                scans.len()
            )
        });
        matched.insert(at);
    }
    assert!(
        matched.len() > 10,
        "the scans were taken at {} poses of {}",
        matched.len(),
        poses.len()
    );
    let _ = std::fs::remove_dir_all(&dir);
}
