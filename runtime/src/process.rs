//! A process an operator can run (the `process` feature, on by default): what a
//! CoolBOT program's `main` sets up once with [`Process::init`].
//!
//! - **Logs**: the runtime's `tracing` events (and the program's) are printed through
//!   `tracing-subscriber`, filtered by `RUST_LOG` (default [`DEFAULT_LOG`]), on stderr,
//!   or kept for a display that owns the terminal ([`capture_output`]).
//! - **Signals**: SIGINT and SIGTERM (what Ctrl-C, systemd, docker and launch tools
//!   send) ask the program to stop: [`Process::stop_requested`] turns true, the program
//!   leaves its loop and shuts its system down ([`Process::shutdown`]: every component
//!   dead, every thread joined). A second signal while stopping ends the process at
//!   once (exit status 128 + the signal's number).
//! - **Panics**: a panic in a component's code is caught by the runtime, which
//!   publishes it as the component's error and lets its supervisor act; under this
//!   module's panic hook it prints one line, `panic caught in <path> (<state>, <user
//!   state>): <message> at <file>:<line>`, instead of the default message and
//!   backtrace. The components known are those of the systems and handles given to
//!   [`watch_system`] / [`watch`] ([`Process::shutdown`] forgets them). Any other panic
//!   (the main thread, a thread of the program's own) prints in full, as without the
//!   hook.
//!
//! A panic of the runtime's own code on a component thread (a runtime bug, which
//! escapes to the thread's top) prints the same single line when it happens; the
//! shutdown report names it (`ComponentReport::thread_panic`) and
//! [`Shutdown`] says the shutdown was not clean.

use std::collections::VecDeque;
use std::fmt;
use std::io::Write as _;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock, PoisonError, RwLock};
use std::time::{Duration, Instant};

use crate::{Handle, Report, State, System};

/// The log filter when `RUST_LOG` is not set: the runtime's and the program's
/// information, warnings and errors; Zenoh (the network layer's transport) only from
/// warnings up.
pub const DEFAULT_LOG: &str = "info,zenoh=warn";

/// How many lines [`capture_output`] keeps before dropping the oldest (counted).
pub const CAPTURE_CAPACITY: usize = 1000;

/// Why [`Process::init`] failed.
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    /// A signal handler could not be installed.
    #[error("cannot handle {signal}")]
    Signal {
        /// The signal's name.
        signal: &'static str,
        /// What the OS said.
        #[source]
        source: std::io::Error,
    },
}

/// The signal that asked the process to stop.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Signal {
    /// SIGINT (Ctrl-C).
    Interrupt,
    /// SIGTERM (systemd, docker, `kill`).
    Terminate,
}

impl fmt::Display for Signal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Signal::Interrupt => "SIGINT",
            Signal::Terminate => "SIGTERM",
        })
    }
}

/// How [`Process::init`] sets the process up.
#[derive(Clone, Debug)]
pub struct ProcessBuilder {
    default_log: String,
    logs: bool,
}

impl ProcessBuilder {
    /// The log filter used when `RUST_LOG` is not set (`EnvFilter` syntax, e.g.
    /// `"warn"` or `"info,coolbot=debug"`); [`DEFAULT_LOG`] by default.
    pub fn default_log(mut self, filter: &str) -> ProcessBuilder {
        filter.clone_into(&mut self.default_log);
        self
    }

    /// Whether to install the `tracing` subscriber (true by default; false for a
    /// program that installs its own).
    pub fn logs(mut self, on: bool) -> ProcessBuilder {
        self.logs = on;
        self
    }

    /// Install the logger (unless a global subscriber is already set: it stays), the
    /// panic hook (once per process) and the SIGINT and SIGTERM handlers (withdrawn
    /// when the [`Process`] is dropped).
    pub fn init(self) -> Result<Process, ProcessError> {
        if self.logs {
            install_logger(&self.default_log);
        }
        install_panic_hook();
        Process::with_signals()
    }
}

/// What [`Process::init`] set up: the stop request and the signal handlers.
#[derive(Debug)]
pub struct Process {
    stop: Arc<AtomicBool>,
    interrupted: Arc<AtomicBool>,
    terminated: Arc<AtomicBool>,
    handlers: Vec<signal_hook::SigId>,
}

impl Process {
    /// [`ProcessBuilder`] with its defaults: logs filtered by `RUST_LOG` (default
    /// [`DEFAULT_LOG`]), the panic hook, SIGINT and SIGTERM handled.
    pub fn builder() -> ProcessBuilder {
        ProcessBuilder {
            default_log: DEFAULT_LOG.to_owned(),
            logs: true,
        }
    }

    /// `Process::builder().init()`.
    pub fn init() -> Result<Process, ProcessError> {
        Process::builder().init()
    }

    fn with_signals() -> Result<Process, ProcessError> {
        use signal_hook::consts::{SIGINT, SIGTERM};
        let stop = Arc::new(AtomicBool::new(false));
        let interrupted = Arc::new(AtomicBool::new(false));
        let terminated = Arc::new(AtomicBool::new(false));
        let mut process = Process {
            stop,
            interrupted,
            terminated,
            handlers: Vec::new(),
        };
        for (signal, name, which) in [
            (SIGINT, "SIGINT", Arc::clone(&process.interrupted)),
            (SIGTERM, "SIGTERM", Arc::clone(&process.terminated)),
        ] {
            let failed = |source| ProcessError::Signal {
                signal: name,
                source,
            };
            // Registered first, so that it sees the flag as the previous signal left
            // it: the first signal asks to stop, a second one ends the process.
            let forced = signal_hook::flag::register_conditional_shutdown(
                signal,
                128 + signal,
                Arc::clone(&process.stop),
            )
            .map_err(failed)?;
            process.handlers.push(forced);
            let which = signal_hook::flag::register(signal, which).map_err(failed)?;
            process.handlers.push(which);
            let stop =
                signal_hook::flag::register(signal, Arc::clone(&process.stop)).map_err(failed)?;
            process.handlers.push(stop);
        }
        Ok(process)
    }

    /// The flag the signal handlers set: a loop that polls an `AtomicBool` takes it
    /// as is.
    pub fn stop_flag(&self) -> Arc<AtomicBool> {
        Arc::clone(&self.stop)
    }

    /// Whether a signal (or [`Process::request_stop`]) asked the process to stop.
    pub fn stop_requested(&self) -> bool {
        self.stop.load(Ordering::Acquire)
    }

    /// Ask the process to stop as a signal would (a second signal then ends it at
    /// once).
    pub fn request_stop(&self) {
        self.stop.store(true, Ordering::Release);
    }

    /// The signal that asked the process to stop, if one did (SIGTERM if both came).
    pub fn signal(&self) -> Option<Signal> {
        if self.terminated.load(Ordering::Acquire) {
            Some(Signal::Terminate)
        } else if self.interrupted.load(Ordering::Acquire) {
            Some(Signal::Interrupt)
        } else {
            None
        }
    }

    /// Wait until the process is asked to stop or `timeout` passes (looking every
    /// 10 ms); returns whether it was asked to stop.
    pub fn wait(&self, timeout: Duration) -> bool {
        let deadline = Instant::now().checked_add(timeout);
        loop {
            if self.stop_requested() {
                return true;
            }
            let left = match deadline {
                Some(deadline) => deadline.saturating_duration_since(Instant::now()),
                None => Duration::from_millis(10),
            };
            if left.is_zero() {
                return false;
            }
            std::thread::sleep(left.min(Duration::from_millis(10)));
        }
    }

    /// Shut `system` down ([`System::shutdown`]: every component to `dead`, every
    /// thread joined), forget its components ([`forget_system`]), and say whether
    /// it was clean; the outcome is logged too.
    pub fn shutdown(&self, system: System) -> Shutdown {
        forget_system(&system);
        let shutdown = Shutdown {
            report: system.shutdown(),
            signal: self.signal(),
        };
        if shutdown.clean() {
            tracing::info!("{shutdown}");
        } else {
            tracing::error!("{shutdown}");
        }
        shutdown
    }
}

impl Drop for Process {
    fn drop(&mut self) {
        for id in self.handlers.drain(..) {
            signal_hook::low_level::unregister(id);
        }
    }
}

/// What [`Process::shutdown`] found.
#[derive(Clone, Debug, PartialEq)]
pub struct Shutdown {
    /// The system's report.
    pub report: Report,
    /// The signal that asked the process to stop, if one did.
    pub signal: Option<Signal>,
}

impl Shutdown {
    /// Every component that started is dead and its thread joined, and no panic
    /// escaped the runtime's code.
    pub fn clean(&self) -> bool {
        self.report.clean()
            && self
                .report
                .components
                .iter()
                .all(|c| c.state == State::Dead || (c.state == State::Starting && !c.joined))
    }
}

impl fmt::Display for Shutdown {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let components = &self.report.components;
        let joined = components.iter().filter(|c| c.joined).count();
        let dead = components.iter().filter(|c| c.state == State::Dead).count();
        if self.clean() {
            write!(
                f,
                "shutdown clean: {dead} of {} components dead, {joined} threads joined",
                components.len()
            )?;
        } else {
            let problems: Vec<String> = components
                .iter()
                .filter(|c| !c.joined || c.state != State::Dead || c.thread_panic.is_some())
                .map(|c| {
                    let mut text = format!("{} {}", c.name, c.state);
                    if !c.joined {
                        text.push_str(", thread not joined");
                    }
                    if let Some(panic) = &c.thread_panic {
                        text.push_str(&format!(", runtime panic: {panic}"));
                    }
                    text
                })
                .collect();
            write!(f, "shutdown NOT clean: {}", problems.join("; "))?;
        }
        if let Some(signal) = self.signal {
            write!(f, " (asked by {signal})")?;
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------
// Output: stderr, or captured for a display that owns the terminal.

/// Lines kept while output is captured, and how many were dropped.
struct Captured {
    lines: VecDeque<String>,
    dropped: u64,
}

fn captured() -> &'static Mutex<Option<Captured>> {
    static CAPTURED: Mutex<Option<Captured>> = Mutex::new(None);
    &CAPTURED
}

/// Keep the log lines and the panic lines of [`Process`] instead of printing them
/// (`true`), for a display that owns the terminal and shows them ([`take_output`]);
/// `false` prints what is left on stderr and prints from then on. Beyond
/// [`CAPTURE_CAPACITY`] lines waiting, the oldest are dropped and counted (the count
/// is the first line [`take_output`] returns next).
pub fn capture_output(on: bool) {
    let left = {
        let mut slot = captured().lock().unwrap_or_else(PoisonError::into_inner);
        if on {
            slot.get_or_insert_with(|| Captured {
                lines: VecDeque::new(),
                dropped: 0,
            });
            None
        } else {
            slot.take()
        }
    };
    if let Some(left) = left {
        let mut stderr = std::io::stderr().lock();
        for line in drain(left) {
            let _ = writeln!(stderr, "{line}");
        }
    }
}

fn drain(mut captured: Captured) -> Vec<String> {
    let mut lines = Vec::with_capacity(captured.lines.len() + 1);
    if captured.dropped > 0 {
        lines.push(format!(
            "({} output lines dropped: the display fell behind)",
            captured.dropped
        ));
    }
    lines.extend(captured.lines.drain(..));
    lines
}

/// The lines captured since the last call (empty when output is not captured).
pub fn take_output() -> Vec<String> {
    let mut slot = captured().lock().unwrap_or_else(PoisonError::into_inner);
    match slot.as_mut() {
        Some(captured) => {
            let taken = Captured {
                lines: std::mem::take(&mut captured.lines),
                dropped: std::mem::take(&mut captured.dropped),
            };
            drain(taken)
        }
        None => Vec::new(),
    }
}

/// Print `text` (one or more lines) on stderr, or keep it while output is captured.
/// Never blocks on a lock held by the calling thread (a panic hook may call it).
fn emit(text: &str) {
    let mut slot = match captured().try_lock() {
        Ok(slot) => slot,
        Err(std::sync::TryLockError::Poisoned(poisoned)) => poisoned.into_inner(),
        Err(std::sync::TryLockError::WouldBlock) => {
            // Held for a moment by another thread, or by this one (a panic while
            // emitting): stderr, rather than a wait that might never end.
            let _ = std::io::stderr().lock().write_all(text.as_bytes());
            return;
        }
    };
    match slot.as_mut() {
        Some(captured) => {
            for line in text.lines() {
                if captured.lines.len() >= CAPTURE_CAPACITY {
                    captured.lines.pop_front();
                    captured.dropped += 1;
                }
                captured.lines.push_back(line.to_owned());
            }
        }
        None => {
            drop(slot);
            let _ = std::io::stderr().lock().write_all(text.as_bytes());
        }
    }
}

/// One log event's text, handed to [`emit`] whole when the subscriber is done with it.
#[derive(Default)]
struct EventWriter {
    text: Vec<u8>,
}

impl std::io::Write for EventWriter {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        self.text.extend_from_slice(bytes);
        Ok(bytes.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Drop for EventWriter {
    fn drop(&mut self) {
        if !self.text.is_empty() {
            emit(&String::from_utf8_lossy(&self.text));
        }
    }
}

/// Install the `tracing` subscriber of [`Process::init`] alone, for a program that
/// needs no signal handling of its own (a command-line tool): lines on stderr, or
/// kept while output is captured ([`capture_output`]), filtered by `RUST_LOG`, else
/// by `default` (`EnvFilter` syntax). A subscriber set before stays.
pub fn init_logs(default: &str) {
    install_logger(default);
}

/// The `tracing` subscriber: `RUST_LOG`, else `default`; a `RUST_LOG` that does not
/// parse is reported and `default` used. A subscriber set before stays.
fn install_logger(default: &str) {
    use tracing_subscriber::EnvFilter;
    let mut complaint = None;
    let filter = match std::env::var("RUST_LOG") {
        Ok(text) if !text.trim().is_empty() => EnvFilter::try_new(&text).unwrap_or_else(|error| {
            complaint = Some(format!("RUST_LOG=`{text}` ignored: {error}"));
            EnvFilter::new(default)
        }),
        _ => EnvFilter::new(default),
    };
    let installed = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(EventWriter::default)
        .with_ansi(false)
        .try_init()
        .is_ok();
    if let (true, Some(complaint)) = (installed, complaint) {
        tracing::warn!("{complaint}");
    }
}

// ---------------------------------------------------------------------------------
// Panics.

fn watched() -> &'static RwLock<Vec<Handle>> {
    static WATCHED: RwLock<Vec<Handle>> = RwLock::new(Vec::new());
    &WATCHED
}

/// Let the panic hook name the component behind `handle` and those nested inside it
/// (a compound's instances at any depth) when their code panics.
pub fn watch(handle: &Handle) {
    let mut watched = watched().write().unwrap_or_else(PoisonError::into_inner);
    if !watched
        .iter()
        .any(|h| Arc::ptr_eq(&h.shared, &handle.shared))
    {
        watched.push(handle.clone());
    }
}

/// [`watch`] every component of `system`.
pub fn watch_system(system: &System) {
    for name in system.names() {
        if let Some(handle) = system.handle(name) {
            watch(&handle);
        }
    }
}

/// Undo [`watch`] for `handle`.
pub fn forget(handle: &Handle) {
    watched()
        .write()
        .unwrap_or_else(PoisonError::into_inner)
        .retain(|h| !Arc::ptr_eq(&h.shared, &handle.shared));
}

/// Undo [`watch_system`].
pub fn forget_system(system: &System) {
    for name in system.names() {
        if let Some(handle) = system.handle(name) {
            forget(&handle);
        }
    }
}

/// The watched component whose thread is the calling one: its dotted path and
/// handle. Matched by the member whose turn runs on an execution group's thread,
/// else by thread id, else (a restarted instance runs on a new thread) by
/// the thread's name `cool:<name>` when one component only has that name.
fn current_component() -> Option<(String, Handle)> {
    fn walk(handle: &Handle, path: String, out: &mut Vec<(String, Handle)>) {
        for instance in handle.instances.iter() {
            walk(instance, format!("{path}.{}", instance.name), out);
        }
        out.push((path, handle.clone()));
    }
    let watched = watched().try_read().ok()?;
    let mut all = Vec::new();
    for root in watched.iter() {
        walk(root, root.name.to_string(), &mut all);
    }
    drop(watched);
    // On an execution group's thread, the member whose turn it is; on a
    // component's own thread, the component whose thread it is.
    let thread = std::thread::current();
    if let Some(found) = all.iter().find(|(_, h)| {
        crate::monitor::turn_is(&h.shared)
            .unwrap_or_else(|| h.shared.thread.get() == Some(&thread.id()))
    }) {
        return Some(found.clone());
    }
    let name = thread.name()?.strip_prefix("cool:")?;
    let mut named = all.into_iter().filter(|(_, h)| &*h.name == name);
    match (named.next(), named.next()) {
        (Some(found), None) => Some(found),
        _ => None,
    }
}

/// The line printed for a panic in the code of the component at `path`.
fn panic_line(
    path: &str,
    states: Option<(State, Option<String>)>,
    message: &str,
    location: Option<String>,
) -> String {
    let states = match states {
        Some((state, Some(user))) => format!(" ({state}, {user})"),
        Some((state, None)) => format!(" ({state})"),
        None => String::new(),
    };
    let at = location.map(|l| format!(" at {l}")).unwrap_or_default();
    let message = message.replace('\n', " ");
    format!("panic caught in {path}{states}: {message}{at}\n")
}

/// The message of a panic.
fn message(info: &std::panic::PanicHookInfo<'_>) -> String {
    crate::thread::panic_message(info.payload())
}

/// Install the hook once: one line for a panic on a watched component's thread, the
/// previous hook (the default: message and backtrace) for every other panic.
fn install_panic_hook() {
    static INSTALLED: OnceLock<()> = OnceLock::new();
    INSTALLED.get_or_init(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| match current_component() {
            Some((path, handle)) => emit(&panic_line(
                &path,
                handle.shared.peek_states(),
                &message(info),
                info.location()
                    .map(|l| format!("{}:{}", l.file(), l.line())),
            )),
            None => previous(info),
        }));
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_line_names_component_states_message_and_place() {
        assert_eq!(
            panic_line(
                "robot.base.ranges",
                Some((State::Running, Some("scanning".to_owned()))),
                "board\nreset",
                Some("src/ranges.rs:68".to_owned())
            ),
            "panic caught in robot.base.ranges (running, scanning): board reset at src/ranges.rs:68\n"
        );
        assert_eq!(panic_line("x", None, "m", None), "panic caught in x: m\n");
    }

    #[test]
    fn captured_output_is_bounded_and_counts_drops() {
        capture_output(true);
        for i in 0..CAPTURE_CAPACITY + 3 {
            emit(&format!("line {i}\n"));
        }
        let lines = take_output();
        assert_eq!(lines.len(), CAPTURE_CAPACITY + 1);
        assert!(
            lines[0].starts_with("(3 output lines dropped"),
            "{}",
            lines[0]
        );
        assert_eq!(lines[1], "line 3");
        assert!(take_output().is_empty());
        capture_output(false);
        assert!(take_output().is_empty());
    }
}
