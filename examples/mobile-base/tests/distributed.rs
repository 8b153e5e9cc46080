//! The robot distributed over two processes, as its description says
//! (`instance wanderer: Wanderer on "station";`, `docs/distribution.md`): a station
//! node (`--node station --serve`) runs the wanderer the robot's compound places on
//! it; `kill -9` of the station is a fault of the wanderer's proxy, its local
//! substitute `fallback` drives the base meanwhile, and when the station is back the
//! recovery queue builds the wanderer there again and the fallback stands down.
#![cfg(feature = "network")]

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use rustix::process::{Pid, Signal, kill_process};

/// Generous: the machine is shared and may be loaded.
const PATIENCE: Duration = Duration::from_secs(60);

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|listener| listener.local_addr())
        .map(|address| address.port())
        .expect("a free port")
}

/// Starts the binary with `args`; every line of its stdout and stderr is sent on
/// the returned channel (tagged with `who`), and kept in the joined string.
fn spawn(
    who: &'static str,
    args: &[&str],
) -> (
    Child,
    mpsc::Receiver<String>,
    std::thread::JoinHandle<String>,
) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_mobile-base"))
        .args(args)
        .env("RUST_LOG", "warn,coolbot_zenoh=info")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the example starts");
    let (lines, receiver) = mpsc::channel();
    let stderr = child.stderr.take().expect("piped");
    let errors = lines.clone();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines() {
            let Ok(line) = line else { break };
            let _ = errors.send(format!("{who} stderr: {line}"));
        }
    });
    let stdout = child.stdout.take().expect("piped");
    let reader = std::thread::spawn(move || {
        let mut all = String::new();
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            all.push_str(&line);
            all.push('\n');
            let _ = lines.send(line);
        }
        all
    });
    (child, receiver, reader)
}

/// Waits for a line for which `wanted` holds; the lines seen meanwhile are kept in
/// `seen` (for the failure message).
fn wait_line(
    lines: &mpsc::Receiver<String>,
    seen: &mut Vec<String>,
    what: &str,
    wanted: impl Fn(&str) -> bool,
) -> String {
    let deadline = Instant::now() + PATIENCE;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match lines.recv_timeout(left) {
            Ok(line) if wanted(&line) => return line,
            Ok(line) => seen.push(line),
            Err(error) => panic!(
                "no line {what} within {PATIENCE:?} ({error}); seen:\n{}",
                seen.join("\n")
            ),
        }
    }
}

#[test]
fn the_wanderer_runs_on_the_station_and_the_fallback_drives_while_the_station_is_lost() {
    let port = free_port();
    let listen = format!("tcp/127.0.0.1:{port}");
    let station_args = [
        "--node",
        "station",
        "--serve",
        "--listen",
        &listen,
        "--no-multicast",
        "--lease",
        "1s",
    ];
    let (mut station, station_lines, _) = spawn("station", &station_args);
    let (robot, robot_lines, robot_out) = spawn(
        "robot",
        &[
            "--node",
            "robot",
            "--connect",
            &listen,
            "--no-multicast",
            "--lease",
            "1s",
            "--duration",
            "120s",
            "--output",
            "lines",
        ],
    );
    let mut seen = Vec::new();

    // The station built the wanderer for the robot; the robot's status lines show it
    // running (its proxy mirrors the remote user state) with the fallback standing by.
    wait_line(
        &station_lines,
        &mut seen,
        "of the station building the wanderer",
        |l| l.contains("built for another node") && l.contains("robot-robot-wanderer"),
    );
    wait_line(
        &robot_lines,
        &mut seen,
        "with the remote wanderer running",
        |l| l.contains(" wanderer=running/") && l.contains(" fallback=ready"),
    );

    // kill -9 the station: the proxy's node is lost, the fallback takes over.
    station.kill().expect("SIGKILL");
    let _ = station.wait();
    wait_line(&robot_lines, &mut seen, "saying the station is lost", |l| {
        l.contains("robot: wanderer failed: node `station` is lost")
    });
    wait_line(&robot_lines, &mut seen, "substituting the fallback", |l| {
        l.contains("robot: wanderer substituted by fallback")
    });
    wait_line(&robot_lines, &mut seen, "with the fallback driving", |l| {
        l.contains(" fallback=running/")
    });

    // The station is back: the wanderer is built there again and takes over.
    let (mut station, station_lines, _) = spawn("station", &station_args);
    wait_line(
        &station_lines,
        &mut seen,
        "of the new station building the wanderer",
        |l| l.contains("built for another node") && l.contains("robot-robot-wanderer"),
    );
    wait_line(
        &robot_lines,
        &mut seen,
        "saying the wanderer recovered",
        |l| l.contains("robot: wanderer recovered"),
    );
    wait_line(
        &robot_lines,
        &mut seen,
        "with the wanderer back and the fallback ready",
        |l| l.contains(" wanderer=running/") && l.contains(" fallback=ready"),
    );

    // SIGTERM: a clean shutdown, which releases the remote wanderer too.
    kill_process(Pid::from_child(&robot), Signal::TERM).expect("SIGTERM");
    let mut robot = robot;
    let status = robot.wait().expect("the robot exits");
    let out = robot_out.join().expect("stdout");
    assert!(status.success(), "{out}");
    assert!(out.contains("substitutions 1, recoveries 1"), "{out}");
    assert!(
        out.contains("clean: every component dead, every thread joined"),
        "{out}"
    );
    station.kill().expect("SIGKILL");
    let _ = station.wait();
}
