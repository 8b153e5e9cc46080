//! The `mobile-base` binary as an operator runs it (`coolbot::process`): stopped by
//! SIGTERM or SIGINT it shuts down cleanly and exits 0; a panic the runtime catches
//! in a component prints one line, never the default message and backtrace.

use std::io::{BufRead, BufReader, Read};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use rustix::process::{Pid, Signal, kill_process};

use crate::support::{PATIENCE, Process, wait_line};

fn robot(args: &[&str]) -> Process {
    Command::new(env!("CARGO_BIN_EXE_mobile-base"))
        .args(["--output", "lines"])
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the example starts")
        .into()
}

/// Reads `child`'s stdout on a thread: each line is sent, and all of it returned
/// once the pipe closes.
fn follow(child: &mut Child) -> (mpsc::Receiver<String>, std::thread::JoinHandle<String>) {
    let stdout = child.stdout.take().expect("piped");
    let (lines, receiver) = mpsc::channel();
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
    (receiver, reader)
}

fn stderr_of(child: &mut Child) -> std::thread::JoinHandle<String> {
    let mut stderr = child.stderr.take().expect("piped");
    std::thread::spawn(move || {
        let mut text = String::new();
        let _ = stderr.read_to_string(&mut text);
        text
    })
}

fn wait_exit(child: &mut Child) -> std::process::ExitStatus {
    let deadline = Instant::now() + PATIENCE;
    loop {
        if let Some(status) = child.try_wait().expect("waitable") {
            return status;
        }
        if Instant::now() >= deadline {
            let _ = child.kill();
            panic!("the example did not exit within {PATIENCE:?} of the signal");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn stopped_by(signal: Signal, name: &str) {
    let mut child = robot(&["--duration", "10min"]);
    let (lines, stdout) = follow(&mut child);
    let stderr = stderr_of(&mut child);
    // Running: a first status line came out.
    wait_line(&lines, &mut Vec::new(), "of the robot running", |line| {
        line.starts_with('[') && line.contains("robot=")
    });
    let pid = Pid::from_raw(i32::try_from(child.id()).expect("a pid")).expect("a pid");
    kill_process(pid, signal).expect("signal sent");
    let status = wait_exit(&mut child);
    let stdout = stdout.join().expect("stdout read");
    let stderr = stderr.join().expect("stderr read");
    assert!(status.success(), "{status}\n{stdout}\n{stderr}");
    assert!(stdout.contains("(interrupted)"), "{stdout}");
    assert!(
        stdout.contains("shutdown             clean: every component dead, every thread joined"),
        "{stdout}"
    );
    assert!(
        stdout.contains("after shutdown       robot=dead base=dead wanderer=dead; every component released the platform: yes"),
        "{stdout}"
    );
    assert!(stdout.contains(&format!("stopped by {name}")), "{stdout}");
}

#[test]
fn sigterm_stops_the_robot_cleanly() {
    stopped_by(Signal::TERM, "SIGTERM");
}

#[test]
fn sigint_stops_the_robot_cleanly() {
    stopped_by(Signal::INT, "SIGINT");
}

#[test]
fn a_caught_panic_prints_one_line() {
    let mut child = robot(&[
        "--duration",
        "3s",
        "--fault",
        "panic",
        "--fault-after",
        "1s",
        "--outage",
        "1s",
    ]);
    let (_lines, stdout) = follow(&mut child);
    let stderr = stderr_of(&mut child);
    let status = wait_exit(&mut child);
    let stdout = stdout.join().expect("stdout read");
    let stderr = stderr.join().expect("stderr read");
    assert!(status.success(), "{status}\n{stdout}\n{stderr}");
    // Each panic the base's supervisor saw (as `ranges failed: panic in ...`) printed
    // exactly one line on stderr, naming the component, its states and the message.
    let caught: Vec<&str> = stderr
        .lines()
        .filter(|line| line.starts_with("panic caught in "))
        .collect();
    let failures = stdout
        .lines()
        .filter(|line| line.trim_start().starts_with(|c: char| c.is_ascii_digit()))
        .filter(|line| line.contains("base: ranges failed: panic in"))
        .count();
    // Each step is listed twice: as it happened, and in the summary.
    assert_eq!(failures % 2, 0, "{stdout}");
    assert!(failures >= 2, "the fault was not injected:\n{stdout}");
    assert_eq!(caught.len(), failures / 2, "{stderr}\n{stdout}");
    for line in &caught {
        assert!(
            line.starts_with("panic caught in robot.base.ranges (running, streaming): sensor driver crashed: the ir/us board reset at "),
            "{line}"
        );
    }
    // Never the default hook's message nor a backtrace.
    assert!(!stderr.contains("panicked at"), "{stderr}");
    assert!(!stderr.contains("backtrace"), "{stderr}");
}
