//! What the tests that run the example binary as a process share: the binary started
//! with its lines followed, a line waited for with a deadline, a free port.

use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Generous: the machine is shared and may be loaded.
pub(crate) const PATIENCE: Duration = Duration::from_secs(60);

/// A process of the test's: killed (and reaped) when dropped, so that a test that
/// fails leaves none running behind it. Used as the `Child` it holds.
pub(crate) struct Process(std::process::Child);

impl From<std::process::Child> for Process {
    fn from(child: std::process::Child) -> Process {
        Process(child)
    }
}

impl std::ops::Deref for Process {
    type Target = std::process::Child;
    fn deref(&self) -> &std::process::Child {
        &self.0
    }
}

impl std::ops::DerefMut for Process {
    fn deref_mut(&mut self) -> &mut std::process::Child {
        &mut self.0
    }
}

impl Drop for Process {
    fn drop(&mut self) {
        // A child already waited for is not signalled again (`Child::kill`).
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A TCP port on loopback that nothing listens on.
#[cfg(feature = "network")]
pub(crate) fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|listener| listener.local_addr())
        .map(|address| address.port())
        .expect("a free port")
}

/// Starts the example binary with `args` and `RUST_LOG=log`, with no outlet tallies in
/// the user's state directory (its bridges are a placement's, which keep none anyway).
/// Every line of its stdout and stderr goes to `lines`, tagged with `who` when it is
/// not empty (`robot: ...`, `robot stderr: ...`; else `...`, `stderr: ...`); its stdout
/// is also kept in the string the returned thread ends with.
#[cfg(feature = "network")]
pub(crate) fn spawn(
    who: &'static str,
    args: &[&str],
    log: &str,
    lines: &mpsc::Sender<String>,
) -> (Process, std::thread::JoinHandle<String>) {
    use std::io::{BufRead, BufReader};
    use std::process::{Command, Stdio};

    let mut child = Command::new(env!("CARGO_BIN_EXE_mobile-base"))
        .args(args)
        .env("RUST_LOG", log)
        .env("COOLBOT_STATE_DIR", "")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the example starts");
    let (out_tag, err_tag) = if who.is_empty() {
        (String::new(), "stderr: ".to_owned())
    } else {
        (format!("{who}: "), format!("{who} stderr: "))
    };
    let stderr = child.stderr.take().expect("piped");
    let errors = lines.clone();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = errors.send(format!("{err_tag}{line}"));
        }
    });
    let stdout = child.stdout.take().expect("piped");
    let lines = lines.clone();
    let reader = std::thread::spawn(move || {
        let mut all = String::new();
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            all.push_str(&line);
            all.push('\n');
            let _ = lines.send(format!("{out_tag}{line}"));
        }
        all
    });
    (Process(child), reader)
}

/// A line waited for: what it says (for the message if it does not come), and what
/// holds of it.
#[cfg(feature = "network")]
pub(crate) type Wanted<'a> = (&'a str, &'a dyn Fn(&str) -> bool);

/// Waits until a line has come for each of `wanted`, in any order: lines that threads
/// of their own print (a supervisor's steps, the watcher of a process). At most
/// [`PATIENCE`] in all; returns the lines in the order of `wanted`. A line is taken by
/// the first of `wanted` still waiting that holds of it; the others are kept in
/// `seen`, and printed if a line does not come.
#[cfg(feature = "network")]
pub(crate) fn wait_lines<const N: usize>(
    lines: &mpsc::Receiver<String>,
    seen: &mut Vec<String>,
    wanted: [Wanted<'_>; N],
) -> [String; N] {
    let deadline = Instant::now() + PATIENCE;
    let mut found: [Option<String>; N] = std::array::from_fn(|_| None);
    while found.iter().any(Option::is_none) {
        let left = deadline.saturating_duration_since(Instant::now());
        match lines.recv_timeout(left) {
            Ok(line) => {
                let slot = wanted
                    .iter()
                    .zip(found.iter_mut())
                    .find(|((_, holds), slot)| slot.is_none() && holds(&line));
                match slot {
                    Some((_, slot)) => *slot = Some(line),
                    None => seen.push(line),
                }
            }
            Err(error) => {
                let missing: Vec<&str> = wanted
                    .iter()
                    .zip(&found)
                    .filter(|(_, line)| line.is_none())
                    .map(|((what, _), _)| *what)
                    .collect();
                panic!(
                    "no line {} within {PATIENCE:?} ({error}); seen:\n{}",
                    missing.join(", no line "),
                    seen.join("\n")
                )
            }
        }
    }
    found.map(|line| line.unwrap_or_default())
}

/// Waits for a line for which `wanted` holds, at most [`PATIENCE`]; the lines seen
/// meanwhile are kept in `seen`, and printed if none comes.
pub(crate) fn wait_line(
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
