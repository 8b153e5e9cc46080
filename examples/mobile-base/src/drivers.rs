//! `--drivers`: the range server in a process of its own on the same host, the node
//! `drivers` (`docs/distribution.md`, "A driver in a process of its own").
//!
//! The robot is then `IsolatedRobot`, whose base places its range server `on
//! "drivers"`. The robot's process starts the drivers process itself: the same
//! binary, `--node drivers --serve`, connected to the robot's node, with the run's
//! sensor settings (noise, seed, scan rate, and what is left of the injected fault and
//! processor shortage, on the robot's clock). [`Keeper`] keeps it: when the process
//! ends while the robot runs (`kill -9`, a crash of the driver), the compound
//! substitutes its range server, and the keeper starts the process again, whose node
//! the recovery queue builds the range server on. At the end of the run the keeper
//! stops it (SIGTERM). A drivers process also ends by itself when the robot's process
//! is gone (`--parent`).

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, mpsc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::world::{FaultKind, Overload, SensorFault};

/// The node name of the drivers process.
pub const NODE: &str = "drivers";

/// What the drivers process prints once its node serves (`crate::serve`).
pub const SERVING: &str = "node `drivers` on the network: serving";

/// How long the first drivers process may take to serve before the robot gives up.
const FIRST_START: Duration = Duration::from_secs(30);

/// The pause before a drivers process that ended is started again, so that one that
/// fails at once is not started in a busy loop.
const RESTART_PAUSE: Duration = Duration::from_millis(200);

/// How long a drivers process has to end after SIGTERM before it is killed.
const STOP_GRACE: Duration = Duration::from_secs(5);

/// How the robot starts its drivers process.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Drivers {
    /// The program to start (this binary: `std::env::current_exe`).
    pub program: PathBuf,
}

/// The run's settings the drivers process gets, on the robot's clock.
#[derive(Clone, Debug)]
pub struct Settings {
    /// The robot node's endpoints, which the drivers process connects to.
    pub connect: Vec<String>,
    /// The Zenoh session lease, as the robot's.
    pub lease: Duration,
    /// `--noise`.
    pub noise: Option<f64>,
    /// `--seed`.
    pub seed: u64,
    /// `--scan-rate`.
    pub scan_rate: Option<f64>,
    /// The injected sensor fault, from the start of the robot's run.
    pub fault: Option<SensorFault>,
    /// The simulated processor shortage, from the start of the robot's run.
    pub load: Option<Overload>,
}

/// A duration as the command line reads it.
fn duration(d: Duration) -> String {
    format!("{}us", d.as_micros())
}

impl Settings {
    /// The command line of a drivers process started `now` into the robot's run: the
    /// fault and the shortage shifted to its clock, or left out once they are over.
    pub fn args(&self, now: Duration) -> Vec<String> {
        let mut args: Vec<String> = ["--node", NODE, "--serve", "--no-multicast"]
            .map(String::from)
            .to_vec();
        for endpoint in &self.connect {
            args.extend(["--connect".to_owned(), endpoint.clone()]);
        }
        args.extend([
            "--lease".to_owned(),
            duration(self.lease),
            "--parent".to_owned(),
            std::process::id().to_string(),
            "--seed".to_owned(),
            self.seed.to_string(),
        ]);
        if let Some(noise) = self.noise {
            args.extend(["--noise".to_owned(), noise.to_string()]);
        }
        if let Some(rate) = self.scan_rate {
            args.extend(["--scan-rate".to_owned(), rate.to_string()]);
        }
        if let Some(fault) = self.fault {
            let end = fault.after + fault.outage;
            if end > now {
                let start = fault.after.max(now);
                args.extend([
                    "--fault-after".to_owned(),
                    duration(start - now),
                    "--outage".to_owned(),
                    duration(end - start),
                    "--fault".to_owned(),
                    match fault.kind {
                        FaultKind::Raise => "raise",
                        FaultKind::Panic => "panic",
                    }
                    .to_owned(),
                ]);
            }
        }
        if let Some(load) = self.load
            && load.until > now
        {
            let from = load.from.max(now) - now;
            args.extend([
                "--load".to_owned(),
                format!("{}..{}", duration(from), duration(load.until - now)),
            ]);
        }
        args
    }
}

/// Why the drivers process could not be started, or its node did not serve.
#[derive(Debug, thiserror::Error)]
pub enum DriversError {
    /// The program did not start.
    #[error("the drivers process `{program}` does not start")]
    Spawn {
        /// The program.
        program: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A thread (the keeper, or one reading the process's output) did not start.
    #[error("a thread for the drivers process does not start")]
    Thread(#[source] std::io::Error),
    /// The first process did not say that its node serves in time.
    #[error("the drivers process did not serve within {within:?} ({how})")]
    NotServing {
        /// How long it was given.
        within: Duration,
        /// How it ended (it is killed if it had not).
        how: String,
    },
}

/// What became of the drivers processes of a run (the summary's line).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DriversReport {
    /// How many were started.
    pub started: u32,
    /// How each one that ended while the robot ran ended (`killed by signal 9`).
    pub ended: Vec<String>,
    /// How the last one ended when the run stopped it.
    pub stopped: Option<String>,
}

/// An exit status in words.
fn ending(status: ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt;
    match (status.code(), status.signal()) {
        (Some(code), _) => format!("exit status {code}"),
        (None, Some(signal)) => format!("killed by signal {signal}"),
        (None, None) => status.to_string(),
    }
}

/// Starts a drivers process; its output goes to `lines`, each line prefixed, and the
/// line that says it serves also to `serving`.
fn spawn(
    program: &Path,
    args: &[String],
    lines: &mpsc::Sender<String>,
    serving: Option<mpsc::Sender<()>>,
) -> Result<Child, DriversError> {
    let mut child = Command::new(program)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|source| DriversError::Spawn {
            program: program.to_owned(),
            source,
        })?;
    let pid = child.id();
    let forward = |stream: Box<dyn Read + Send>, serving: Option<mpsc::Sender<()>>| {
        let lines = lines.clone();
        std::thread::Builder::new()
            .name("drivers-output".to_owned())
            .spawn(move || {
                for line in BufReader::new(stream).lines().map_while(Result::ok) {
                    if line.starts_with(SERVING)
                        && let Some(serving) = &serving
                    {
                        let _ = serving.send(());
                    }
                    let _ = lines.send(format!("drivers {pid}: {line}"));
                }
            })
    };
    let stdout = child
        .stdout
        .take()
        .map(|s| Box::new(s) as Box<dyn Read + Send>);
    let stderr = child
        .stderr
        .take()
        .map(|s| Box::new(s) as Box<dyn Read + Send>);
    for (stream, serving) in [(stdout, serving), (stderr, None)] {
        if let Some(stream) = stream {
            forward(stream, serving).map_err(DriversError::Thread)?;
        }
    }
    let _ = lines.send(format!("drivers process {pid} started (node `{NODE}`)"));
    Ok(child)
}

/// The drivers process of a run, kept running until [`Keeper::stop`].
#[derive(Debug)]
pub struct Keeper {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<DriversReport>>,
}

impl Keeper {
    /// Starts the drivers process and waits until its node serves; then keeps it: a
    /// process that ends is started again, with `settings` as they stand at that moment
    /// of the run (`clock`: the time into the run). What the processes print, and
    /// each start and end, go to `lines`.
    pub fn start(
        drivers: &Drivers,
        settings: Settings,
        clock: impl Fn() -> Duration + Send + 'static,
        lines: mpsc::Sender<String>,
    ) -> Result<Keeper, DriversError> {
        let (serving, served) = mpsc::channel();
        let program = drivers.program.clone();
        let mut child = spawn(&program, &settings.args(clock()), &lines, Some(serving))?;
        let deadline = Instant::now() + FIRST_START;
        loop {
            if served.recv_timeout(Duration::from_millis(20)).is_ok() {
                break;
            }
            let ended = child.try_wait().ok().flatten();
            if ended.is_some() || Instant::now() >= deadline {
                let _ = child.kill();
                let status = child.wait().map(ending).unwrap_or_default();
                return Err(DriversError::NotServing {
                    within: FIRST_START,
                    how: if ended.is_some() {
                        status
                    } else {
                        "killed".to_owned()
                    },
                });
            }
        }
        let stop = Arc::new(AtomicBool::new(false));
        let stopping = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name("drivers-keeper".to_owned())
            .spawn(move || keep(child, &program, &settings, &clock, &lines, &stopping))
            .map_err(DriversError::Thread)?;
        Ok(Keeper {
            stop,
            thread: Some(thread),
        })
    }

    /// Stops the drivers process (SIGTERM, then SIGKILL after a grace period) and says
    /// what became of every one the run started.
    pub fn stop(mut self) -> DriversReport {
        self.stop.store(true, Ordering::Release);
        self.thread
            .take()
            .and_then(|thread| thread.join().ok())
            .unwrap_or_default()
    }
}

impl Drop for Keeper {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// The keeper's thread: watches the process, starts it again when it ends, stops it
/// when told.
fn keep(
    mut child: Child,
    program: &Path,
    settings: &Settings,
    clock: &dyn Fn() -> Duration,
    lines: &mpsc::Sender<String>,
    stop: &AtomicBool,
) -> DriversReport {
    let mut report = DriversReport {
        started: 1,
        ..DriversReport::default()
    };
    loop {
        if stop.load(Ordering::Acquire) {
            report.stopped = Some(terminate(&mut child));
            let _ = lines.send(format!(
                "drivers process {} stopped: {}",
                child.id(),
                report.stopped.as_deref().unwrap_or_default()
            ));
            return report;
        }
        match child.try_wait() {
            Ok(Some(status)) => {
                let how = ending(status);
                let _ = lines.send(format!(
                    "drivers process {} ended: {how}; starting it again",
                    child.id()
                ));
                report.ended.push(how);
                std::thread::sleep(RESTART_PAUSE);
                loop {
                    if stop.load(Ordering::Acquire) {
                        return report;
                    }
                    match spawn(program, &settings.args(clock()), lines, None) {
                        Ok(next) => {
                            child = next;
                            report.started += 1;
                            break;
                        }
                        Err(error) => {
                            let _ = lines.send(coolbot::Chain(&error).to_string());
                            std::thread::sleep(RESTART_PAUSE);
                        }
                    }
                }
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(20)),
            Err(error) => {
                let _ = lines.send(format!("the drivers process cannot be watched: {error}"));
                std::thread::sleep(Duration::from_millis(200));
            }
        }
    }
}

/// Asks `child` to end (SIGTERM: its node leaves cleanly), and kills it if it has not
/// within [`STOP_GRACE`]. How it ended.
fn terminate(child: &mut Child) -> String {
    if let Ok(Some(status)) = child.try_wait() {
        return ending(status);
    }
    if let Some(pid) = rustix::process::Pid::from_raw(child.id() as i32) {
        let _ = rustix::process::kill_process(pid, rustix::process::Signal::TERM);
    }
    let deadline = Instant::now() + STOP_GRACE;
    while Instant::now() < deadline {
        if let Ok(Some(status)) = child.try_wait() {
            return ending(status);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let _ = child.kill();
    child.wait().map(ending).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings() -> Settings {
        Settings {
            connect: vec!["tcp/127.0.0.1:7447".to_owned()],
            lease: Duration::from_secs(2),
            noise: Some(0.0),
            seed: 3,
            scan_rate: None,
            fault: Some(SensorFault {
                after: Duration::from_secs(3),
                outage: Duration::from_secs(2),
                kind: FaultKind::Panic,
            }),
            load: Some(Overload {
                from: Duration::from_secs(4),
                until: Duration::from_secs(9),
            }),
        }
    }

    fn after<'a>(args: &'a [String], flag: &str) -> Option<&'a str> {
        let at = args.iter().position(|a| a == flag)?;
        args.get(at + 1).map(String::as_str)
    }

    #[test]
    fn a_process_started_later_gets_what_is_left_of_the_fault_and_the_shortage() {
        let settings = settings();
        let first = settings.args(Duration::ZERO);
        assert_eq!(after(&first, "--node"), Some(NODE));
        assert_eq!(after(&first, "--connect"), Some("tcp/127.0.0.1:7447"));
        assert_eq!(after(&first, "--noise"), Some("0"));
        assert_eq!(after(&first, "--fault-after"), Some("3000000us"));
        assert_eq!(after(&first, "--outage"), Some("2000000us"));
        assert_eq!(after(&first, "--fault"), Some("panic"));
        assert_eq!(after(&first, "--load"), Some("4000000us..9000000us"));
        // Started 4 s in: the outage is under way (1 s left), the shortage starts now.
        let later = settings.args(Duration::from_secs(4));
        assert_eq!(after(&later, "--fault-after"), Some("0us"));
        assert_eq!(after(&later, "--outage"), Some("1000000us"));
        assert_eq!(after(&later, "--load"), Some("0us..5000000us"));
        // Started 10 s in: both are over.
        let over = settings.args(Duration::from_secs(10));
        assert_eq!(after(&over, "--fault-after"), None);
        assert_eq!(after(&over, "--load"), None);
    }
}
