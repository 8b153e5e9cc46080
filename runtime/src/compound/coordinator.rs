//! What a compound supervisor's adaptation remembers between turns (its homogeneity
//! interval, what it asked of its instances), and the settling time and
//! reconfiguration backoff between its decisions.

use std::time::{Duration, Instant};

use crate::adapt::{AdaptConfig, Member, Selector};
use crate::monitor::Monitor;

use super::supervisor::DEFAULT_SUPERVISION_PERIOD;

/// A compound supervisor's adaptation state: its homogeneity interval and what it has
/// asked of its instances.
pub(super) struct Coordinator {
    pub(super) config: AdaptConfig,
    pub(super) selector: Box<dyn Selector>,
    /// The current maximum degradation level (the compound's own level).
    pub(super) cap: u32,
    /// The current minimum degradation level.
    pub(super) floor: u32,
    /// The cap and floor were set up at the first start (top level: `width`; nested:
    /// 0 until its supervisor grants more).
    pub(super) initialized: bool,
    /// Something adaptation reads changed: decide on the next turn.
    pub(super) dirty: bool,
    /// `Exhausted` was published for the current violation.
    pub(super) exhausted: bool,
    /// Instances suspended by adaptation (reconfiguration).
    pub(super) suspended: Vec<bool>,
    /// Levels commanded and not yet seen on the instance's monitor, with when.
    pub(super) pending: Vec<Option<(u32, Instant)>>,
    /// The highest ladder top among the instances (published).
    pub(super) max_level: u32,
    /// Until when promotion waits: the settling time after the last time violation
    /// seen or degradation decided.
    pub(super) settle_until: Option<Instant>,
    /// Reconfiguration: the settling time's multiplier after a suspension (doubled
    /// when a suspension follows a resume within the settling time, up to
    /// `max_backoff`; back to 1 after a resume that held).
    pub(super) backoff: u32,
    /// When the last instance suspended by adaptation was resumed.
    pub(super) resumed_at: Option<Instant>,
}

impl Coordinator {
    /// The settling time: `settle_periods` of the slowest member's cycles (its period,
    /// plus its section's overrun while it is late), where `settle_periods` is the
    /// longest of the members' own (`hold_periods + window + 1` of their detectors,
    /// published as [`crate::adapt::AdaptStatus::settle_periods`]) and the
    /// compound's configuration's, so that a member with a longer hold-down is not
    /// taken as settled before it can show a verdict; times the reconfiguration
    /// backoff.
    pub(super) fn settling(
        &self,
        members: &[Member],
        monitors: &[Monitor],
        indices: &[usize],
    ) -> Duration {
        let cycle = members
            .iter()
            .filter_map(|m| Some(m.period?.mul_f64(1.0 + m.load.clamp(0.0, 10.0))))
            .max()
            .unwrap_or(DEFAULT_SUPERVISION_PERIOD);
        let periods = settle_periods(
            &self.config,
            indices
                .iter()
                .filter_map(|i| monitors.get(*i))
                .map(|m| m.adaptation.settle_periods),
        );
        cycle
            .saturating_mul(periods)
            .saturating_mul(self.backoff.max(1))
    }

    /// A time violation now: promotion waits for the settling time, long enough for
    /// a member degraded now to pass its hold-down and fill its detection window.
    pub(super) fn settle(
        &mut self,
        members: &[Member],
        monitors: &[Monitor],
        indices: &[usize],
        now: Instant,
    ) {
        let until = crate::time::later(now, self.settling(members, monitors, indices));
        self.settle_until = Some(self.settle_until.map_or(until, |before| before.max(until)));
    }

    /// An instance was suspended now (reconfiguration): a suspension that follows a
    /// resume within the settling time shows the resume was premature, so the next
    /// resume waits twice as long (up to `max_backoff` times); otherwise the backoff
    /// starts again. Without this, a load that comes and goes would suspend and resume
    /// an instance forever at the settling time's pace.
    pub(super) fn suspended_now(
        &mut self,
        members: &[Member],
        monitors: &[Monitor],
        indices: &[usize],
        now: Instant,
    ) {
        let window = self.settling(members, monitors, indices);
        let premature = self
            .resumed_at
            .is_some_and(|resumed| now.saturating_duration_since(resumed) <= window);
        self.backoff = next_backoff(self.backoff, premature, self.config.max_backoff);
        self.settle(members, monitors, indices, now);
    }
}

/// The periods a supervisor settles for: the longest of its own configuration's
/// `hold_periods + window + 1` and its members' (`published`).
pub(super) fn settle_periods(own: &AdaptConfig, published: impl IntoIterator<Item = u32>) -> u32 {
    let own = own
        .hold_periods
        .saturating_add(own.window)
        .saturating_add(1);
    published.into_iter().fold(own, u32::max)
}

/// The reconfiguration backoff after a suspension: doubled when the suspension
/// followed a resume too soon (`premature`), up to `max` (at least 1); 1 otherwise.
pub(super) fn next_backoff(backoff: u32, premature: bool, max: u32) -> u32 {
    if premature {
        backoff.saturating_mul(2).min(max.max(1))
    } else {
        1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_compound_settles_for_its_slowest_settling_member() {
        let own = AdaptConfig::default(); // 5 + 4 + 1
        assert_eq!(settle_periods(&own, []), 10);
        assert_eq!(settle_periods(&own, [6, 44, 0]), 44);
        assert_eq!(settle_periods(&own, [6]), 10);
        let huge = AdaptConfig {
            hold_periods: u32::MAX,
            ..own
        };
        assert_eq!(settle_periods(&huge, [1]), u32::MAX);
    }

    #[test]
    fn a_premature_resume_doubles_the_wait_before_the_next_one() {
        // Suspended, resumed, suspended again at once: 2, 4, 8, then the maximum.
        let backoffs: Vec<u32> = (0..5)
            .scan(1, |backoff, _| {
                *backoff = next_backoff(*backoff, true, 8);
                Some(*backoff)
            })
            .collect();
        assert_eq!(backoffs, [2, 4, 8, 8, 8]);
        // A resume that held: back to 1.
        assert_eq!(next_backoff(8, false, 8), 1);
        // No overflow, and a zero maximum still means "no backoff".
        assert_eq!(next_backoff(u32::MAX, true, u32::MAX), u32::MAX);
        assert_eq!(next_backoff(4, true, 0), 1);
    }
}
