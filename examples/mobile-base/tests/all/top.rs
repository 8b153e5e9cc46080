//! `coolctl top` as an operator uses it: in a terminal (tmux, 160x45) against the
//! example robot on the network (`--node robot`, its wanderer on a station), the
//! screen shows every component of both nodes, and the supervision step of a fault
//! (`--fault-after`) as it happens; `q` quits. `.ci/run` installs tmux.
#![cfg(feature = "network")]

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::support::{PATIENCE, Process, free_port};

fn example(args: &[&str]) -> Process {
    Command::new(env!("CARGO_BIN_EXE_mobile-base"))
        .args(args)
        // No outlet tallies in the user's state directory (its bridges are a
        // placement's, which keep none anyway).
        .env("COOLBOT_STATE_DIR", "")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("the example starts")
        .into()
}

/// `coolctl`, built next to the example by `cargo test --workspace`.
fn coolctl() -> PathBuf {
    let path = PathBuf::from(env!("CARGO_BIN_EXE_mobile-base")).with_file_name("coolctl");
    assert!(
        path.exists(),
        "{} is not built: run the workspace's tests (cargo test --workspace), or build it \
         first (cargo build -p coolbot-zenoh --bin coolctl)",
        path.display()
    );
    path
}

/// A tmux server of this test's own.
struct Tmux(String);

impl Tmux {
    fn run(&self, args: &[&str]) -> String {
        let output = Command::new("tmux")
            .args(["-L", &self.0])
            .args(args)
            .output()
            .expect("tmux runs (apt-get install tmux)");
        String::from_utf8_lossy(&output.stdout).into_owned()
    }

    fn screen(&self) -> String {
        self.run(&["capture-pane", "-p", "-t", "top"])
    }

    /// Waits until the screen shows every one of `wanted`; the screen.
    fn wait_for(&self, wanted: &[&str]) -> String {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let screen = self.screen();
            if wanted.iter().all(|w| screen.contains(w)) {
                return screen;
            }
            assert!(
                Instant::now() < deadline,
                "the screen never showed {wanted:?}:\n{screen}"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

impl Drop for Tmux {
    fn drop(&mut self) {
        self.run(&["kill-server"]);
    }
}

#[test]
fn coolctl_top_in_a_terminal_shows_both_nodes_and_the_substitution_as_it_happens() {
    // A machine without tmux cannot run this test (`.ci/run` installs it): say so.
    if Command::new("tmux").arg("-V").output().is_err() {
        eprintln!("skipped: tmux is not installed (apt-get install tmux)");
        return;
    }
    let (station_port, robot_port) = (free_port(), free_port());
    let station_endpoint = format!("tcp/127.0.0.1:{station_port}");
    let robot_endpoint = format!("tcp/127.0.0.1:{robot_port}");
    let mut station = example(&[
        "--node",
        "station",
        "--serve",
        "--listen",
        &station_endpoint,
        "--no-multicast",
    ]);
    let mut robot = example(&[
        "--node",
        "robot",
        "--listen",
        &robot_endpoint,
        "--connect",
        &station_endpoint,
        "--no-multicast",
        "--duration",
        "120s",
        "--fault-after",
        "4s",
        "--output",
        "lines",
    ]);
    let tmux = Tmux(format!("coolbot-top-{}", std::process::id()));
    let command = format!(
        "{} --connect {robot_endpoint} --no-multicast top --refresh 300ms",
        coolctl().display()
    );
    tmux.run(&[
        "new-session",
        "-d",
        "-s",
        "top",
        "-x",
        "160",
        "-y",
        "45",
        &command,
    ]);
    // Both nodes' components, the robot's as a tree.
    let screen = tmux.wait_for(&[
        "robot/robot",
        "  base",
        "    motion",
        "  wanderer",
        "station/5-robot-robot-wanderer-",
        "running",
    ]);
    assert!(screen.contains("coolctl top: components"), "{screen}");
    // The range server fails at 4 s: the base's supervisor substitutes it, live.
    tmux.wait_for(&["robot/robot.base: supervision: ranges substituted by sim_ranges"]);
    // Keys: the selection starts on the robot; suspend it and run it again, each
    // answered on the status line.
    tmux.run(&["send-keys", "-t", "top", "s"]);
    tmux.wait_for(&["robot/robot: suspend: accepted"]);
    tmux.run(&["send-keys", "-t", "top", "r"]);
    tmux.wait_for(&["robot/robot: run: accepted"]);
    // A controllable variable of the base (one row down), typed at the prompt.
    tmux.run(&["send-keys", "-t", "top", "Down", "v"]);
    tmux.run(&["send-keys", "-t", "top", "-l", "max_speed=0.3"]);
    tmux.run(&["send-keys", "-t", "top", "Enter"]);
    tmux.wait_for(&["robot/robot.base: max_speed=0.3: accepted"]);
    tmux.run(&["send-keys", "-t", "top", "q"]);
    let deadline = Instant::now() + PATIENCE;
    while tmux.run(&["list-sessions"]).contains("top:") {
        assert!(Instant::now() < deadline, "`q` did not quit top");
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = robot.kill();
    let _ = robot.wait();
    let _ = station.kill();
    let _ = station.wait();
}
