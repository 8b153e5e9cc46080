//! The one place component threads are spawned and joined.

use std::any::Any;
use std::io;
use std::thread::{Builder, JoinHandle};
use std::time::{Duration, Instant};

/// Spawn a named thread (`cool:<name>`; the OS may truncate the name).
pub(crate) fn spawn(
    name: &str,
    body: impl FnOnce() + Send + 'static,
) -> io::Result<JoinHandle<()>> {
    Builder::new().name(format!("cool:{name}")).spawn(body)
}

/// Join a thread; a panic that escaped it (a runtime bug: user code runs under
/// `catch_unwind`) is reported as its message.
pub(crate) fn join(handle: JoinHandle<()>) -> Result<(), String> {
    handle
        .join()
        .map_err(|payload| panic_message(payload.as_ref()))
}

/// The message of a panic payload.
pub(crate) fn panic_message(payload: &(dyn Any + Send)) -> String {
    if let Some(message) = payload.downcast_ref::<&str>() {
        (*message).to_owned()
    } else if let Some(message) = payload.downcast_ref::<String>() {
        message.clone()
    } else {
        "panic with a non-string payload".to_owned()
    }
}

/// `start + delay`, saturating at about a century from `start` instead of panicking on
/// an absurd delay (a `Duration::MAX` timeout means "practically never").
pub(crate) fn later(start: Instant, delay: Duration) -> Instant {
    const CENTURY: Duration = Duration::from_secs(100 * 365 * 24 * 3600);
    start.checked_add(delay.min(CENTURY)).unwrap_or(start)
}
