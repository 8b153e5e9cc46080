//! What a description sets for failing instances: the [`Policy`] per instance, the
//! `restart` policy's budget and backoff, and an entry of the recovery queue.

use std::time::{Duration, Instant};

/// The default restart budget ([`CompoundBuilder::restart_budget`](crate::CompoundBuilder::restart_budget)): at most this many
/// restarts of one instance ...
pub const DEFAULT_RESTARTS: u32 = 5;
/// ... within this window; one more failure in the window propagates.
pub const DEFAULT_RESTART_WINDOW: Duration = Duration::from_secs(10);
/// The default restart backoff ([`CompoundBuilder::restart_backoff`](crate::CompoundBuilder::restart_backoff)): the first
/// restart in a window is immediate, the second waits this long, each further one
/// twice as long as the one before ...
pub const DEFAULT_BACKOFF: Duration = Duration::from_millis(10);
/// ... up to this.
pub const DEFAULT_BACKOFF_MAX: Duration = Duration::from_secs(1);

/// What a compound does when one of its instances goes to `running_error`
/// (`on error inst: <policy>;`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Policy {
    /// The compound goes to `running_error` too; its own supervisor (its parent) hears
    /// it on the compound's monitoring port. The default.
    #[default]
    Propagate,
    /// The instance is commanded back to `running` (a restart through `start`), within
    /// the compound's restart budget ([`CompoundBuilder::restart_budget`](crate::CompoundBuilder::restart_budget), with a
    /// backoff: [`CompoundBuilder::restart_backoff`](crate::CompoundBuilder::restart_backoff)); a failure beyond the budget
    /// propagates. An instance stuck in a section that overran `max_response` is
    /// restarted when the section returns.
    Restart,
    /// The declared substitute takes the instance's place and the instance goes into
    /// the recovery queue (without a substitute: the recovery queue only).
    Substitute,
    /// Nothing happens; the instance stays in `running_error` (rules can see it).
    Ignore,
}

/// A restart the `restart` policy has decided.
#[derive(Debug, Clone, Copy)]
pub(super) struct PendingRestart {
    /// When the fault was seen.
    pub(super) since: Instant,
    /// Not before then (the backoff).
    pub(super) due: Instant,
}

/// The `restart` policy's limits.
#[derive(Debug, Clone, Copy)]
pub(super) struct Budget {
    pub(super) restarts: u32,
    pub(super) window: Duration,
    pub(super) backoff: Duration,
    pub(super) backoff_max: Duration,
}

impl Budget {
    /// The backoff before restart number `done + 1` within the window.
    pub(super) fn delay(&self, done: usize) -> Duration {
        if done == 0 {
            return Duration::ZERO;
        }
        let doublings = u32::try_from(done - 1).unwrap_or(u32::MAX).min(30);
        self.backoff
            .saturating_mul(1 << doublings)
            .min(self.backoff_max)
    }
}

/// An entry of the recovery queue.
#[derive(Debug, Clone, Copy)]
pub(super) struct Recovering {
    pub(super) instance: usize,
    pub(super) since: Instant,
    pub(super) next: Instant,
    /// Restarted at the last retry: recovered if still running at the next one.
    pub(super) probation: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_backoff_doubles_from_the_second_restart_up_to_its_maximum() {
        let budget = Budget {
            restarts: 10,
            window: Duration::from_secs(10),
            backoff: Duration::from_millis(10),
            backoff_max: Duration::from_millis(50),
        };
        let delays: Vec<_> = (0..6).map(|done| budget.delay(done)).collect();
        assert_eq!(
            delays,
            [0, 10, 20, 40, 50, 50].map(Duration::from_millis).to_vec()
        );
        // No overflow however many restarts were done.
        assert_eq!(budget.delay(usize::MAX), Duration::from_millis(50));
    }
}
