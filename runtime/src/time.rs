//! Instants: the process's time origin, which watch times and arrival labels count
//! from, saturating addition, and durations as nanoseconds. The bottom layer: it uses
//! nothing of the crate.

use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// The instant all watch times count from (a virtual clock takes it before its own
/// start, so that its instants are never before it).
pub(crate) fn epoch() -> Instant {
    static EPOCH: OnceLock<Instant> = OnceLock::new();
    *EPOCH.get_or_init(Instant::now)
}

/// `start + delay`, saturating at about a century from `start` instead of panicking on
/// an absurd delay (a `Duration::MAX` timeout means "practically never").
pub(crate) fn later(start: Instant, delay: Duration) -> Instant {
    const CENTURY: Duration = Duration::from_secs(100 * 365 * 24 * 3600);
    start.checked_add(delay.min(CENTURY)).unwrap_or(start)
}

/// `duration` in nanoseconds, saturating at `u64::MAX` (about 584 years).
pub(crate) fn nanos(duration: Duration) -> u64 {
    u64::try_from(duration.as_nanos()).unwrap_or(u64::MAX)
}
