//! Python processes for the tests against ROS 2 implementations written
//! independently of ours: the Python (`$COOLBOT_PYTHON`, else the repository's
//! `target/pyenv`), a Zenoh router of `eclipse-zenoh`, and [`Script`], a process that
//! prints JSON lines and reads orders on stdin. Included by `tests/zenoh/tests/ros2.rs`
//! and by the example robot's `examples/mobile-base/tests/ros2.rs`
//! (`#[path]`); both crates sit two directories below the repository's root, which
//! the paths here count from.

// Each including test uses part of it.
#![allow(dead_code)]

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::time::{Duration, Instant};

use coolbot::crossbeam_channel::{self, Receiver};
use serde_json::Value;

/// How long a line is waited for: generous, the machine is shared.
pub const PATIENCE: Duration = Duration::from_secs(30);

/// The repository's root.
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The ROS 2 message definitions coolc ships (`coolc/interfaces`), for the SDK's
/// type registry.
pub fn interfaces() -> String {
    root()
        .join("coolc/interfaces")
        .to_string_lossy()
        .into_owned()
}

/// A free TCP port on loopback.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|listener| listener.local_addr())
        .map(|address| address.port())
        .expect("a free loopback port")
}

/// How to make the Python these tests run.
pub const SETUP: &str = "python3 -m venv target/pyenv && target/pyenv/bin/pip install \
zenoh-ros2-sdk==0.1.8 eclipse-zenoh==1.10.2, then run the tests from the repository \
root, or set COOLBOT_PYTHON to that python";

/// The Python with the packages: `$COOLBOT_PYTHON`, else `target/pyenv`'s; a panic
/// saying how to make it when neither exists.
pub fn python() -> PathBuf {
    if let Some(python) = std::env::var_os("COOLBOT_PYTHON") {
        return python.into();
    }
    let venv = root().join("target/pyenv/bin/python");
    if venv.exists() {
        return venv;
    }
    panic!("COOLBOT_PYTHON is not set and target/pyenv does not exist: {SETUP}");
}

/// A Zenoh router on `port` (eclipse-zenoh), until stdin closes.
pub const ROUTER: &str = r#"
import sys, zenoh
port = sys.argv[1]
config = zenoh.Config()
config.insert_json5("mode", '"router"')
config.insert_json5("listen/endpoints", f'["tcp/127.0.0.1:{port}"]')
config.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(config)
print('{"kind": "ready"}', flush=True)
sys.stdin.read()
session.close()
"#;

/// A Python process and the JSON lines it prints.
pub struct Script {
    child: Child,
    stdin: Option<ChildStdin>,
    lines: Receiver<Value>,
}

impl Script {
    /// Runs `script` with `args`; its JSON lines are read on a thread.
    pub fn start(script: &str, args: &[String]) -> Script {
        let mut child = Command::new(python())
            .arg("-c")
            .arg(script)
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .unwrap_or_else(|error| panic!("cannot run python ({error}): {SETUP}"));
        let stdout = child.stdout.take().expect("piped stdout");
        let (sender, lines) = crossbeam_channel::unbounded();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if let Ok(value) = serde_json::from_str::<Value>(&line) {
                    let _ = sender.send(value);
                }
            }
        });
        let stdin = child.stdin.take();
        Script {
            child,
            stdin,
            lines,
        }
    }

    /// The next line of `kind`, skipping others, within the patience.
    pub fn next(&self, kind: &str) -> Value {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let line = self
                .lines
                .recv_timeout(left)
                .unwrap_or_else(|_| panic!("no `{kind}` line from the python process"));
            if line["kind"] == kind {
                return line;
            }
        }
    }

    /// The next line of `kind` within `wait`, if any.
    pub fn poll(&self, kind: &str, wait: Duration) -> Option<Value> {
        while let Ok(line) = self.lines.recv_timeout(wait) {
            if line["kind"] == kind {
                return Some(line);
            }
        }
        None
    }

    /// Writes `order` as a line on its stdin.
    pub fn order(&mut self, order: Value) {
        let stdin = self.stdin.as_mut().expect("stdin open");
        writeln!(stdin, "{order}").expect("the python process reads its orders");
    }
}

impl Drop for Script {
    fn drop(&mut self) {
        drop(self.stdin.take());
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
