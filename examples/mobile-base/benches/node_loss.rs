//! Node loss to substitute running, and node return to the original back, with real
//! processes (`docs/performance.md`, "Remote instances"): a station node
//! (`--node station --serve`) runs the robot's wanderer; each round `kill -9`s it and
//! times, on the robot's output, the fallback substitution (from the kill), then
//! starts a new station and times the wanderer's recovery (from the spawn). The
//! robot's session lease bounds the first (`--lease`, here 1 s).
//!
//! ```sh
//! cargo bench -p mobile-base --features network --bench node_loss            # 20 rounds
//! cargo bench -p mobile-base --features network --bench node_loss -- --quick # 5 rounds
//! ```

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

const LEASE: &str = "1s";

fn free_port() -> u16 {
    coolbot_zenoh::free_loopback_port()
}

fn spawn(args: &[&str]) -> (Child, mpsc::Receiver<(Instant, String)>) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_mobile-base"))
        .args(args)
        .env("RUST_LOG", "error,coolbot_zenoh=info")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the example starts");
    let (lines, receiver) = mpsc::channel();
    for pipe in [
        Box::new(child.stdout.take().expect("piped")) as Box<dyn std::io::Read + Send>,
        Box::new(child.stderr.take().expect("piped")),
    ] {
        let lines = lines.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(pipe).lines() {
                let Ok(line) = line else { break };
                let _ = lines.send((Instant::now(), line));
            }
        });
    }
    (child, receiver)
}

fn wait(lines: &mpsc::Receiver<(Instant, String)>, wanted: &str) -> Instant {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match lines.recv_timeout(left) {
            Ok((at, line)) if line.contains(wanted) => return at,
            Ok(_) => {}
            Err(error) => panic!("no line with `{wanted}` within 60 s: {error}"),
        }
    }
}

fn percentile(sorted: &[Duration], p: f64) -> Duration {
    let index = ((sorted.len() as f64 - 1.0) * p).round() as usize;
    sorted[index.min(sorted.len() - 1)]
}

fn report(what: &str, mut samples: Vec<Duration>) {
    samples.sort();
    println!(
        "{what:<40} n={:<3} p50 {:>7.1} ms  p99 {:>7.1} ms  min {:>7.1} ms  max {:>7.1} ms",
        samples.len(),
        percentile(&samples, 0.5).as_secs_f64() * 1e3,
        percentile(&samples, 0.99).as_secs_f64() * 1e3,
        samples[0].as_secs_f64() * 1e3,
        samples[samples.len() - 1].as_secs_f64() * 1e3,
    );
}

fn main() {
    let quick = std::env::args().any(|arg| arg == "--quick");
    let rounds = if quick { 5 } else { 20 };
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
        LEASE,
    ];
    let (mut station, station_lines) = spawn(&station_args);
    let spawned = Instant::now();
    let (mut robot, robot_lines) = spawn(&[
        "--node",
        "robot",
        "--connect",
        &listen,
        "--no-multicast",
        "--lease",
        LEASE,
        "--duration",
        "3600s",
        "--output",
        "lines",
    ]);
    let built = wait(&station_lines, "built for another node");
    println!(
        "first remote instantiation: {:.1} ms from the robot's spawn (process start included)",
        built.duration_since(spawned).as_secs_f64() * 1e3
    );
    let mut losses = Vec::new();
    let mut returns = Vec::new();
    for _ in 0..rounds {
        // Let the wanderer run a little on the station.
        std::thread::sleep(Duration::from_millis(300));
        station.kill().expect("SIGKILL");
        let killed = Instant::now();
        let _ = station.wait();
        let substituted = wait(&robot_lines, "wanderer substituted by fallback");
        losses.push(substituted.duration_since(killed));
        let (next, lines) = spawn(&station_args);
        let started = Instant::now();
        station = next;
        let recovered = wait(&robot_lines, "robot: wanderer recovered");
        returns.push(recovered.duration_since(started));
        drop(lines);
    }
    report("kill -9 of the station -> fallback running", losses);
    report("station spawned -> wanderer recovered", returns);
    let _ = robot.kill();
    let _ = robot.wait();
    let _ = station.kill();
    let _ = station.wait();
}
