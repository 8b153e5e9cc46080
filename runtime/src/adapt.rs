//! Adaptation (paper 3.6): graceful degradation when a component runs out of time, and
//! promotion back to nominal when time is spare.
//!
//! Three parts live here, all free of threads and clocks so that they can be tested as
//! pure functions:
//!
//! - [`Ladder`]: a component's degradation levels. Level 0 is nominal (the timing
//!   block's `period`, quality 0); the first levels stretch the period in equal steps
//!   up to `max_period` (frequency degradation), the next ones lower the quality one
//!   level at a time at `max_period` (quality degradation).
//! - `Detector`: per component, fed one observation per periodic section (how long
//!   the section ran, whether it missed its deadline). It turns them into a
//!   [`Pressure`] verdict with hysteresis: a time violation needs
//!   [`AdaptConfig::violations`] bad periods among the last [`AdaptConfig::window`],
//!   spare time needs [`AdaptConfig::spare_periods`] consecutive periods that finished
//!   within [`AdaptConfig::spare_ratio`] of the period one promotion would give; after
//!   every change of level the detector ignores [`AdaptConfig::hold_periods`] periods,
//!   and a promotion that is followed by a violation doubles the spare run needed next
//!   time (up to [`AdaptConfig::max_backoff`]).
//! - [`decide`]: the supervisor's policy (Figures 6 and 7) over a snapshot of its
//!   instances ([`Member`]) and its homogeneity interval ([`Levels`]), returning one
//!   [`Decision`]. The choice of the instance to degrade or promote is a [`Selector`].
//!
//! The runner (`runner.rs`) runs the detector and, for a component that no compound
//! supervises, applies the ladder locally; a compound (`compound/adaptation.rs`) runs [`decide`]
//! on its instances' verdicts and commands their levels through their control ports
//! ([`crate::Command::SetDegradation`]). `docs/runtime.md`, "Adaptation", tells the
//! whole story.

use std::collections::VecDeque;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::spec::TimingSpec;

/// How many adaptation steps [`AdaptStatus::history`] keeps.
pub const ADAPTATION_HISTORY: usize = 32;

/// The most period steps a ladder has ([`AdaptConfig::period_steps`] is clamped to it).
pub const MAX_PERIOD_STEPS: u32 = 1000;

/// The widest violation window ([`AdaptConfig::window`] is clamped to it).
pub const MAX_WINDOW: u32 = 1000;

/// The largest spare-run multiplier ([`AdaptConfig::max_backoff`] is clamped to it).
pub const MAX_BACKOFF: u32 = 1024;

/// The most periods of [`AdaptConfig::hold_periods`] and [`AdaptConfig::spare_periods`].
pub const MAX_PERIODS: u32 = 100_000;

/// The adaptation settings of a component ([`crate::Component::with_adaptation`]) or
/// of a compound's supervisor ([`crate::CompoundBuilder::adaptation`]). Counts are in
/// periods of the component concerned. It travels with a remote instantiation
/// (missing fields take their defaults; the runtime clamps what it is given).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct AdaptConfig {
    /// `Some(false)` turns adaptation off; `Some(true)` turns it on; `None` (the
    /// default) leaves it on where the timing block has a period interval
    /// (`period 10ms..40ms`), or no period, a `max_response` and quality levels (an
    /// aperiodic component degrades its quality on late responses), and off elsewhere. A compound's supervisor is on unless
    /// `Some(false)`.
    pub enabled: Option<bool>,
    /// Bad periods (a missed deadline, or a section longer than the period) among the
    /// last [`AdaptConfig::window`] that make a time violation. Default 2.
    pub violations: u32,
    /// The sliding window of periods for [`AdaptConfig::violations`]. Default 4.
    pub window: u32,
    /// A period is spare when its section ran at most this fraction of the period the
    /// next promotion would give. Default 0.75.
    pub spare_ratio: f64,
    /// Consecutive spare periods that make spare time. Default 20.
    pub spare_periods: u32,
    /// Periods ignored after every change of level (the hold-down). Default 5.
    pub hold_periods: u32,
    /// Equal steps from `period` to `max_period`. Default 3.
    pub period_steps: u32,
    /// The largest multiplier of [`AdaptConfig::spare_periods`] after promotions that
    /// failed (a violation came within the spare window after them). Default 8.
    pub max_backoff: u32,
    /// Compounds: the width of the homogeneity interval `[floor, cap]`. Default 1.
    pub width: u32,
    /// Compounds: what the top-level supervisor does when degradation is exhausted.
    pub reconfiguration: Reconfiguration,
    /// Equalization (`crate::equalize`): whether a periodic component whose adaptation
    /// is on may have its phase moved when its sections coincide with others' on a
    /// busy processor. Default true.
    pub equalize: bool,
    /// Whether promotion also needs the idle probe's spare time on the processor
    /// (`crate::idle`), besides short sections. Default true; false judges spare time
    /// from the component's own sections only (a machine whose idle time other
    /// processes legitimately take, or tests that must not depend on the machine).
    pub idle_probe: bool,
}

impl Default for AdaptConfig {
    fn default() -> AdaptConfig {
        AdaptConfig {
            enabled: None,
            violations: 2,
            window: 4,
            spare_ratio: 0.75,
            spare_periods: 20,
            hold_periods: 5,
            period_steps: 3,
            max_backoff: 8,
            width: 1,
            reconfiguration: Reconfiguration::Report,
            equalize: true,
            idle_probe: true,
        }
    }
}

impl AdaptConfig {
    /// Adaptation turned off.
    pub fn off() -> AdaptConfig {
        AdaptConfig {
            enabled: Some(false),
            ..AdaptConfig::default()
        }
    }

    /// Adaptation turned on, whatever the timing block.
    pub fn on() -> AdaptConfig {
        AdaptConfig {
            enabled: Some(true),
            ..AdaptConfig::default()
        }
    }

    /// The settings made safe to use: every count at least 1, `violations` at most
    /// `window` (more could never be counted: detection would be off without a word),
    /// `window` at most [`MAX_WINDOW`], `period_steps` at most [`MAX_PERIOD_STEPS`],
    /// `max_backoff` at most [`MAX_BACKOFF`], `spare_ratio` a finite number in
    /// `0.0..=1.0` (0 when not a number), `hold_periods` and `spare_periods` at most
    /// [`MAX_PERIODS`]. The runtime applies this to every configuration it is given
    /// (a component's and a compound's), so an odd value never panics nor loops long.
    #[must_use]
    pub fn sanitized(self) -> AdaptConfig {
        let window = self.window.clamp(1, MAX_WINDOW);
        AdaptConfig {
            violations: self.violations.clamp(1, window),
            window,
            spare_ratio: if self.spare_ratio.is_nan() {
                0.0
            } else {
                self.spare_ratio.clamp(0.0, 1.0)
            },
            spare_periods: self.spare_periods.clamp(1, MAX_PERIODS),
            hold_periods: self.hold_periods.min(MAX_PERIODS),
            period_steps: self.period_steps.clamp(1, MAX_PERIOD_STEPS),
            max_backoff: self.max_backoff.clamp(1, MAX_BACKOFF),
            width: self.width.max(1),
            ..self
        }
    }

    /// Whether detection runs for a component with timing block `timing`: by default
    /// where there is something to adapt to a violation, a period interval, or, for an
    /// aperiodic component with a `max_response` (whose late responses are its
    /// violations), quality levels.
    pub(crate) fn enabled_for(&self, timing: &TimingSpec) -> bool {
        self.enabled.unwrap_or_else(|| {
            let interval =
                matches!((timing.period, timing.max_period), (Some(p), Some(m)) if m > p);
            let responsive = timing.period.is_none()
                && timing.max_response.is_some()
                && timing.qualities.len() > 1;
            interval || responsive
        })
    }
}

/// What the top-level supervisor does when every instance is at the highest level and
/// time violations persist (paper: "component suspension or system reconfiguration").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum Reconfiguration {
    /// Publish [`AdaptAction::Exhausted`] (once, until something changes); nothing
    /// else. The default: suspending a part of a robot is the application's call.
    #[default]
    Report,
    /// Suspend the lowest-priority running instance whose priority is below that of
    /// every violating instance (published as [`AdaptAction::Suspended`]); it is
    /// resumed first when time is spare again. With no such instance: `Exhausted`.
    SuspendLowestPriority,
}

/// A component's verdict on its own timing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum Pressure {
    /// Neither: the component keeps its level.
    #[default]
    Nominal,
    /// Time violations: the component asks to be degraded (a compound: "notify
    /// higher level", every instance is at its current maximum level).
    Violation,
    /// Spare time: the component could be promoted (a compound: all its instances are
    /// at or below its floor, its level can be lowered at no cost).
    Spare,
}

/// What an adaptation step did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum AdaptAction {
    /// A level went up (a longer period or a lower quality).
    Degraded,
    /// A level went down (back towards nominal).
    Promoted,
    /// A compound raised its current maximum degradation level (top level only).
    CapRaised,
    /// A compound lowered its current minimum degradation level (top level only).
    FloorLowered,
    /// A compound told its own supervisor that its instances are all at its maximum
    /// level and violations persist.
    NotifiedHigher,
    /// A compound told its own supervisor that it has spare time.
    ReportedSpare,
    /// Every instance is at the highest level and violations persist.
    Exhausted,
    /// Reconfiguration: an instance was suspended.
    Suspended,
    /// An instance suspended by adaptation was resumed.
    Resumed,
    /// Equalization moved the component's phase: its periodic sections coincided with
    /// other components' on a busy processor (`crate::equalize`). The level stays.
    Equalized,
}

/// One adaptation step, published as [`crate::MonitorEvent::Adaptation`] and kept in
/// [`AdaptStatus::history`] of the component that took it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Adaptation {
    /// The component whose level changed (the component itself, or a compound's
    /// instance); the compound itself for its own steps.
    pub component: String,
    /// What happened.
    pub action: AdaptAction,
    /// The level before (for a compound's own steps: the cap or floor before).
    pub from: u32,
    /// The level after.
    pub to: u32,
    /// The period the step gave, when the component applied it itself.
    pub period: Option<Duration>,
    /// The quality the step gave, when the component applied it itself.
    pub quality: Option<usize>,
    /// Why, in words.
    pub detail: String,
}

impl std::fmt::Display for Adaptation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} {:?} {} -> {}",
            self.component, self.action, self.from, self.to
        )?;
        if let Some(period) = self.period {
            write!(f, " (period {period:?}")?;
            if let Some(quality) = self.quality {
                write!(f, ", quality {quality}")?;
            }
            f.write_str(")")?;
        }
        if !self.detail.is_empty() {
            write!(f, ": {}", self.detail)?;
        }
        Ok(())
    }
}

/// The adaptation part of the monitoring port ([`crate::Monitor::adaptation`]).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct AdaptStatus {
    /// Whether detection runs (a compound: whether its supervisor adapts).
    pub enabled: bool,
    /// The current level: an atomic component's place on its [`Ladder`]; a compound's
    /// current maximum degradation level (the cap its instances may reach).
    pub level: u32,
    /// The highest level: an atomic component's ladder top; a compound's highest
    /// instance ladder top.
    pub max_level: u32,
    /// Compounds: the homogeneity interval's lower end (no instance is promoted below
    /// it until every instance reached it).
    pub floor: u32,
    /// An atomic component: the lowest level adaptation promotes it to, where the
    /// period and quality set by other means stand ([`Floor`], [`Ladder::toward`]; 0
    /// when nothing set them). 0 for a compound.
    #[serde(default)]
    pub min_level: u32,
    /// The periods a supervisor waits after a time violation before it promotes (the
    /// detector's `hold_periods + window + 1`): a compound settles for the longest of
    /// its instances' (0 for a compound itself).
    #[serde(default)]
    pub settle_periods: u32,
    /// The current verdict.
    pub pressure: Pressure,
    /// Section time over period, smoothed (an atomic component's demand; 0 for a
    /// compound).
    pub load: f64,
    /// The share of a core the component's thread used (its CPU time over wall-clock
    /// time between the monitor's CPU time readings), smoothed: the paper's "CPU time
    /// versus elapsed time" load profile (0 for a compound).
    #[serde(default)]
    pub cpu_share: f64,
    /// The last [`ADAPTATION_HISTORY`] steps, oldest first.
    pub history: Vec<Adaptation>,
    /// How many steps in all.
    pub steps: u64,
}

/// A component's degradation levels: period steps first, then quality steps.
///
/// The ladder has two axes, the period (its steps, index 0 to
/// [`Ladder::period_steps`]) and the quality (0 to `qualities - 1`), and a component's
/// level is the sum of its period index and its quality: level 0 is nominal, the top
/// is the longest period at the lowest quality. Adaptation walks the ladder along
/// [`Ladder::setting`] (period steps first, then quality), but a period or quality set
/// by other means (a command, a `degrade` plan step, the component's own `set_period`)
/// can put a component off that path, say at the nominal period with a lower quality.
/// [`Ladder::level_of`] gives such a point its level and [`Ladder::toward`] moves from
/// it one axis at a time: a degradation stretches the period first, a promotion raises
/// the quality first and never lengthens the period.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ladder {
    /// The nominal period (`None`: no period, no frequency steps).
    pub period: Option<Duration>,
    /// The longest period.
    pub max_period: Option<Duration>,
    /// Frequency steps (0 without a period interval).
    pub period_steps: u32,
    /// Quality levels (at least 1).
    pub qualities: u32,
}

/// A point on a ladder's two axes: what adaptation applies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Setting {
    /// The period (`None` for a component without one).
    pub period: Option<Duration>,
    /// The quality level (0 is the best).
    pub quality: usize,
}

/// The lowest setting promotions may reach: the period and quality set by other means
/// (a command, a `degrade` plan step, the component's own `set_period`), which
/// adaptation does not undo (`docs/runtime.md`, "Adaptation").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Floor {
    /// Promotions do not shorten the period below this.
    pub period: Option<Duration>,
    /// Promotions do not raise the quality above this one (a lower index is better).
    pub quality: usize,
}

impl Ladder {
    /// The ladder of a timing block, with `steps` period steps when it has a period
    /// interval (at least 1, at most [`MAX_PERIOD_STEPS`], and at most one per
    /// nanosecond of the interval, so that every step is a longer period).
    pub fn new(timing: &TimingSpec, steps: u32) -> Ladder {
        let span = match (timing.period, timing.max_period) {
            (Some(p), Some(m)) if m > p => Some(m - p),
            _ => None,
        };
        let steps = span.map_or(0, |span| {
            let nanos = u32::try_from(span.as_nanos()).unwrap_or(u32::MAX);
            steps.clamp(1, MAX_PERIOD_STEPS).min(nanos)
        });
        Ladder {
            period: timing.period,
            max_period: span.and(timing.max_period),
            period_steps: steps,
            qualities: u32::try_from(timing.qualities.len().max(1)).unwrap_or(u32::MAX),
        }
    }

    /// The highest level.
    pub fn max_level(&self) -> u32 {
        self.period_steps
            .saturating_add(self.qualities.saturating_sub(1))
    }

    /// The period and quality of `level` on the nominal path (clamped to the ladder):
    /// the period steps first, then the quality steps at the longest period.
    pub fn setting(&self, level: u32) -> (Option<Duration>, usize) {
        let level = level.min(self.max_level());
        if level <= self.period_steps {
            (self.period_at(level), 0)
        } else {
            (
                self.max_period.or(self.period),
                (level - self.period_steps) as usize,
            )
        }
    }

    /// The period of step `step` (`nominal + span * step / steps`, in whole
    /// nanoseconds: every step is strictly longer than the one before).
    fn period_at(&self, step: u32) -> Option<Duration> {
        let (Some(period), Some(max)) = (self.period, self.max_period) else {
            return self.period;
        };
        if self.period_steps == 0 {
            return Some(period);
        }
        let span = (max - period).as_nanos();
        let offset = span * u128::from(step.min(self.period_steps)) / u128::from(self.period_steps);
        Some(period.saturating_add(Duration::from_nanos(
            u64::try_from(offset).unwrap_or(u64::MAX),
        )))
    }

    /// The period index of `period`: the first step at least as long (0 for a period
    /// at or below nominal, `period_steps` at or beyond the longest). Computed
    /// directly, not searched.
    fn period_index(&self, period: Option<Duration>) -> u32 {
        let (Some(period), Some(nominal), Some(max)) = (period, self.period, self.max_period)
        else {
            return 0;
        };
        if self.period_steps == 0 || period <= nominal {
            return 0;
        }
        if period >= max {
            return self.period_steps;
        }
        // The least k with floor(span * k / steps) >= offset, that is span * k >=
        // offset * steps (offset is whole nanoseconds).
        let span = (max - nominal).as_nanos();
        let offset = (period - nominal).as_nanos();
        let k = (offset * u128::from(self.period_steps)).div_ceil(span);
        u32::try_from(k).unwrap_or(u32::MAX).min(self.period_steps)
    }

    /// The level of a period and quality, wherever they came from: the period's index
    /// (the first step at least as long) plus the quality (clamped to the ladder).
    pub fn level_of(&self, period: Option<Duration>, quality: usize) -> u32 {
        let quality = u32::try_from(quality)
            .unwrap_or(u32::MAX)
            .min(self.qualities.saturating_sub(1));
        self.period_index(period).saturating_add(quality)
    }

    /// The level of the lowest setting `floor` allows.
    pub fn floor_level(&self, floor: Floor) -> u32 {
        self.level_of(floor.period, floor.quality)
    }

    /// Move from `now` towards level `target`, one axis at a time, and never past
    /// `floor` on the way down:
    ///
    /// - a degradation stretches the period first (to the step of the target level,
    ///   never shorter than it is), then lowers the quality;
    /// - a promotion raises the quality first (not above `floor.quality`), then
    ///   shortens the period step by step (never longer than it is, never shorter
    ///   than `floor.period`).
    ///
    /// The result's level ([`Ladder::level_of`]) is `target` clamped to the ladder,
    /// or the floor's level when the floor stops a promotion. From a point on the
    /// nominal path the result is [`Ladder::setting`]`(target)`.
    pub fn toward(&self, now: Setting, target: u32, floor: Floor) -> Setting {
        let target = target.min(self.max_level());
        let top_quality = self.qualities.saturating_sub(1) as usize;
        let quality = now.quality.min(top_quality);
        let index = self.period_index(now.period);
        let level = index.saturating_add(quality as u32);
        if target > level {
            let index_to = index.saturating_add(target - level).min(self.period_steps);
            let stretch = self.period_at(index_to);
            let period = match (now.period, stretch) {
                (Some(now), Some(step)) if index_to > 0 => Some(now.max(step)),
                (None, step) if index_to > 0 => step,
                (now, _) => now,
            };
            let left = (target - level) - (index_to - index);
            Setting {
                period,
                quality: quality.saturating_add(left as usize).min(top_quality),
            }
        } else if target < level {
            let down = level - target;
            let floor_quality = floor.quality.min(top_quality);
            let raise = (quality.saturating_sub(floor_quality) as u32).min(down);
            let left = down - raise;
            let floor_index = self.period_index(floor.period);
            let index_to = index.saturating_sub(left).max(floor_index.min(index));
            let period = if index_to < index {
                let step = self.period_at(index_to);
                match (now.period, step) {
                    (Some(now), Some(step)) => {
                        let step = floor.period.map_or(step, |f| step.max(f));
                        Some(now.min(step))
                    }
                    (now, _) => now,
                }
            } else {
                now.period
            };
            Setting {
                period,
                quality: quality - raise as usize,
            }
        } else {
            Setting {
                period: now.period,
                quality,
            }
        }
    }
}

/// One periodic section, as the detector sees it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Observation {
    /// How long the section ran.
    pub(crate) elapsed: Duration,
    /// The period it ran at.
    pub(crate) period: Duration,
    /// Whether it ended past its next deadline.
    pub(crate) missed: bool,
    /// The period one promotion would give (the spare test's reference).
    pub(crate) reference: Duration,
    /// Whether the idle probe saw spare time on the processor ([`crate::idle`]): a
    /// period is spare only then.
    pub(crate) idle: bool,
}

/// The per-component detector: observations in, a [`Pressure`] verdict out.
#[derive(Debug, Clone)]
pub(crate) struct Detector {
    config: AdaptConfig,
    /// Bad-period flags of the last `window` periods.
    recent: VecDeque<bool>,
    spare_run: u32,
    hold: u32,
    backoff: u32,
    /// Periods left in which a violation counts as a failed promotion.
    probation: u32,
    verdict: Pressure,
    load: f64,
}

impl Detector {
    pub(crate) fn new(config: AdaptConfig) -> Detector {
        Detector {
            config: config.sanitized(),
            recent: VecDeque::new(),
            spare_run: 0,
            hold: 0,
            backoff: 1,
            probation: 0,
            verdict: Pressure::Nominal,
            load: 0.0,
        }
    }

    pub(crate) fn load(&self) -> f64 {
        self.load
    }

    /// One periodic section; the new verdict if it changed.
    pub(crate) fn observe(&mut self, observation: Observation) -> Option<Pressure> {
        let ratio = observation.elapsed.as_secs_f64() / observation.period.as_secs_f64().max(1e-9);
        self.load = if self.load == 0.0 {
            ratio
        } else {
            0.75 * self.load + 0.25 * ratio
        };
        if self.hold > 0 {
            self.hold -= 1;
            return None;
        }
        if self.probation == 1 {
            // The last promotion held through its probation: forget earlier failures.
            self.backoff = 1;
        }
        self.probation = self.probation.saturating_sub(1);
        let bad = observation.missed || observation.elapsed > observation.period;
        self.recent.push_back(bad);
        while self.recent.len() > self.config.window.max(1) as usize {
            self.recent.pop_front();
        }
        let spare_limit = observation
            .reference
            .mul_f64(self.config.spare_ratio.max(0.0));
        if !bad && observation.idle && observation.elapsed <= spare_limit {
            self.spare_run = self.spare_run.saturating_add(1);
        } else {
            self.spare_run = 0;
        }
        let violations = self.recent.iter().filter(|bad| **bad).count();
        let needed = self
            .config
            .spare_periods
            .max(1)
            .saturating_mul(self.backoff);
        let verdict = if violations >= self.config.violations.max(1) as usize {
            if self.probation > 0 {
                // A promotion that did not hold: wait longer before the next one.
                self.backoff = self
                    .backoff
                    .saturating_mul(2)
                    .min(self.config.max_backoff.max(1));
                self.probation = 0;
            }
            Pressure::Violation
        } else if self.spare_run >= needed {
            Pressure::Spare
        } else {
            Pressure::Nominal
        };
        (verdict != self.verdict).then(|| {
            self.verdict = verdict;
            verdict
        })
    }

    /// The level changed (`promoted`: towards nominal): start afresh after a hold-down.
    /// Returns the verdict before (now `Nominal`).
    pub(crate) fn reset(&mut self, promoted: bool) -> Pressure {
        self.recent.clear();
        self.spare_run = 0;
        self.hold = self.config.hold_periods;
        if promoted {
            self.probation = self
                .config
                .hold_periods
                .saturating_add(self.config.spare_periods);
        }
        std::mem::replace(&mut self.verdict, Pressure::Nominal)
    }
}

/// One instance of a compound, as the policy sees it.
#[derive(Debug, Clone, PartialEq)]
pub struct Member {
    /// The instance name.
    pub name: String,
    /// Its `priority` (higher is more urgent).
    pub priority: i32,
    /// Its level (a compound instance: the cap granted to it).
    pub level: u32,
    /// Its highest level (0: it cannot be degraded).
    pub max_level: u32,
    /// The lowest level it may be promoted to: that of the period and quality set on
    /// it by other means (a command to the instance, its `degrade` plan step, its own
    /// `set_period`), which the supervisor does not undo. 0 when nothing set them.
    pub min_level: u32,
    /// Its verdict.
    pub pressure: Pressure,
    /// Its demand: section time over period.
    pub load: f64,
    /// Its computational demand: the share of a core its thread uses.
    pub cpu_share: f64,
    /// Its period now.
    pub period: Option<Duration>,
    /// Suspended by adaptation (reconfiguration).
    pub suspended: bool,
}

/// A supervisor's homogeneity interval and role.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Levels {
    /// The current maximum degradation level: no instance is degraded above it.
    pub cap: u32,
    /// The current minimum degradation level: no instance is promoted below it while
    /// another is above it.
    pub floor: u32,
    /// Whether this is the top-level supervisor (it raises its cap itself; a nested
    /// one notifies its own supervisor instead).
    pub top: bool,
    /// What to do when degradation is exhausted at the top.
    pub reconfiguration: Reconfiguration,
    /// No time violation for a while (the supervisor's settling time, see
    /// `docs/runtime.md`): promotion is allowed. A member that was just degraded
    /// shows no verdict during its hold-down; without this, another member could be
    /// promoted meanwhile and degraded again right after.
    pub settled: bool,
}

/// What [`decide`] asks the supervisor to do (indices into the members).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// Nothing to do.
    Hold,
    /// Degrade this member one level.
    Degrade(usize),
    /// Raise the cap by one (top level; the floor follows at `cap - width`).
    RaiseCap,
    /// Report the violation to the supervisor above (nested supervisors).
    NotifyHigher,
    /// Suspend this member (top level, reconfiguration).
    Suspend(usize),
    /// Degradation is exhausted; nothing left to do.
    Exhausted,
    /// Resume this member, suspended by adaptation.
    Resume(usize),
    /// Promote this member one level.
    Promote(usize),
    /// This member is above the cap (the cap was lowered from above): bring it to the
    /// cap, or to its [`Member::min_level`] when that is higher.
    Clamp(usize),
    /// Lower the floor by one (top level; the cap follows at `floor + width`).
    LowerFloor,
    /// Report spare time to the supervisor above (nested supervisors).
    ReportSpare,
}

impl Decision {
    /// The pressure a supervisor publishes about itself after this decision.
    pub fn pressure(self) -> Pressure {
        match self {
            Decision::NotifyHigher | Decision::Exhausted => Pressure::Violation,
            Decision::ReportSpare => Pressure::Spare,
            _ => Pressure::Nominal,
        }
    }
}

/// Chooses the instance to degrade or promote (paper 3.6.2: "actual selection criteria
/// is defined by the component's designer"). `candidates` are indices into `members`,
/// never empty; the answer must be one of them.
pub trait Selector: Send + 'static {
    /// The member to degrade among `candidates` (all below the cap).
    fn degrade(&self, members: &[Member], candidates: &[usize]) -> usize;

    /// The member to promote among `candidates` (all above the floor, with spare
    /// time). The default follows the paper: highest priority first, then the most
    /// degraded, then declaration order.
    fn promote(&self, members: &[Member], candidates: &[usize]) -> usize {
        let mut best = candidates[0];
        for &index in &candidates[1..] {
            let (a, b) = (&members[index], &members[best]);
            if (a.priority, a.level) > (b.priority, b.level) {
                best = index;
            }
        }
        best
    }
}

/// The default [`Selector`]: instances with a time violation first (degrading them
/// helps them directly), then the lowest priority (the urgent ones are spared), then
/// the highest load, then the shortest period, then declaration order.
#[derive(Debug, Clone, Copy, Default)]
pub struct ProtectPriority;

impl Selector for ProtectPriority {
    fn degrade(&self, members: &[Member], candidates: &[usize]) -> usize {
        pick(members, candidates, |a, b| {
            let violating = |m: &Member| m.pressure == Pressure::Violation;
            violating(a)
                .cmp(&violating(b))
                .then(b.priority.cmp(&a.priority))
                .then(a.load.total_cmp(&b.load))
                .then(period_key(b).cmp(&period_key(a)))
        })
    }
}

/// The paper's "fastest correction" [`Selector`]: instances with a time violation
/// first, then the highest priority, the highest computational demand (share of a
/// core, then section time over period), the shortest period.
#[derive(Debug, Clone, Copy, Default)]
pub struct FastestCorrection;

impl Selector for FastestCorrection {
    fn degrade(&self, members: &[Member], candidates: &[usize]) -> usize {
        pick(members, candidates, |a, b| {
            let violating = |m: &Member| m.pressure == Pressure::Violation;
            violating(a)
                .cmp(&violating(b))
                .then(a.priority.cmp(&b.priority))
                .then(a.cpu_share.total_cmp(&b.cpu_share))
                .then(a.load.total_cmp(&b.load))
                .then(period_key(b).cmp(&period_key(a)))
        })
    }
}

fn period_key(member: &Member) -> Duration {
    member.period.unwrap_or(Duration::MAX)
}

/// The first candidate that no later one beats (`better(a, b)` is `Greater` when `a`
/// is the better choice).
fn pick(
    members: &[Member],
    candidates: &[usize],
    better: impl Fn(&Member, &Member) -> std::cmp::Ordering,
) -> usize {
    let mut best = candidates[0];
    for &index in &candidates[1..] {
        if better(&members[index], &members[best]) == std::cmp::Ordering::Greater {
            best = index;
        }
    }
    best
}

/// The supervisor's policy (Figures 6 and 7), one decision at a time:
///
/// 1. a member above the cap (lowered from above) is brought to it (highest priority
///    first);
/// 2. on a time violation (any member's verdict): degrade a member below the cap
///    (chosen by `selector`); when all are at the cap (or their own top), a nested
///    supervisor notifies higher, the top one raises the cap up to the highest
///    member top, and beyond that reconfigures ([`Levels::reconfiguration`]);
/// 3. without violations, once settled ([`Levels::settled`]): resume a member suspended by adaptation once every running
///    member has spare time; promote a member above the floor that has spare time
///    (`selector`); when none is above the floor and one with spare time is degraded
///    (or all are nominal under a granted cap), the top supervisor lowers the floor, a
///    nested one reports spare time.
///
/// A member's [`Member::min_level`] (what was set on it by other means) is kept: it is
/// neither clamped nor promoted below it, and counts as at the floor when there.
///
/// A selector's answer that is not one of the candidates is ignored (the default
/// choice is taken): [`decide_explained`] says so.
pub fn decide(members: &[Member], levels: Levels, selector: &dyn Selector) -> Decision {
    decide_explained(members, levels, selector).0
}

/// [`decide`], with a note when the selector answered outside the candidates (its
/// answer was ignored and the default choice taken), for the supervisor to publish.
pub fn decide_explained(
    members: &[Member],
    levels: Levels,
    selector: &dyn Selector,
) -> (Decision, Option<String>) {
    let mut note = None;
    let decision = decide_inner(members, levels, selector, &mut note);
    (decision, note)
}

/// `answer` if it is one of `candidates`, else `fallback` with a note.
fn checked(
    answer: usize,
    candidates: &[usize],
    what: &str,
    fallback: impl FnOnce() -> usize,
    note: &mut Option<String>,
) -> usize {
    if candidates.contains(&answer) {
        return answer;
    }
    *note = Some(format!(
        "the selector chose {answer} to {what}, not one of the candidates {candidates:?}: ignored, the default choice taken"
    ));
    fallback()
}

fn decide_inner(
    members: &[Member],
    levels: Levels,
    selector: &dyn Selector,
    note: &mut Option<String>,
) -> Decision {
    let active: Vec<usize> = (0..members.len())
        .filter(|i| !members[*i].suspended)
        .collect();
    let above_cap: Vec<usize> = active
        .iter()
        .copied()
        .filter(|i| members[*i].level > levels.cap.max(members[*i].min_level))
        .collect();
    if let Some(&first) = above_cap.first() {
        let mut best = first;
        for &index in &above_cap {
            if members[index].priority > members[best].priority {
                best = index;
            }
        }
        return Decision::Clamp(best);
    }
    let violating: Vec<usize> = active
        .iter()
        .copied()
        .filter(|i| members[*i].pressure == Pressure::Violation)
        .collect();
    if !violating.is_empty() {
        let eligible: Vec<usize> = active
            .iter()
            .copied()
            .filter(|i| members[*i].level < levels.cap.min(members[*i].max_level))
            .collect();
        if !eligible.is_empty() {
            let answer = selector.degrade(members, &eligible);
            let chosen = checked(
                answer,
                &eligible,
                "degrade",
                || ProtectPriority.degrade(members, &eligible),
                note,
            );
            return Decision::Degrade(chosen);
        }
        if !levels.top {
            return Decision::NotifyHigher;
        }
        let highest = active.iter().map(|i| members[*i].max_level).max();
        if highest.is_some_and(|highest| levels.cap < highest) {
            return Decision::RaiseCap;
        }
        if levels.reconfiguration == Reconfiguration::SuspendLowestPriority {
            let urgent = violating.iter().map(|i| members[*i].priority).min();
            let victim = active
                .iter()
                .copied()
                .filter(|i| urgent.is_some_and(|urgent| members[*i].priority < urgent))
                .min_by_key(|i| (members[*i].priority, std::cmp::Reverse(*i)));
            if let Some(victim) = victim {
                return Decision::Suspend(victim);
            }
        }
        return Decision::Exhausted;
    }
    if !levels.settled {
        return Decision::Hold;
    }
    let spare = |i: &usize| members[*i].pressure == Pressure::Spare;
    if active.iter().all(spare)
        && let Some(resume) = (0..members.len())
            .filter(|i| members[*i].suspended)
            .max_by_key(|i| (members[*i].priority, std::cmp::Reverse(*i)))
    {
        return Decision::Resume(resume);
    }
    let promotable: Vec<usize> = active
        .iter()
        .copied()
        .filter(|i| members[*i].level > levels.floor.max(members[*i].min_level) && spare(i))
        .collect();
    if !promotable.is_empty() {
        let answer = selector.promote(members, &promotable);
        let chosen = checked(
            answer,
            &promotable,
            "promote",
            || ProtectPriority.promote(members, &promotable),
            note,
        );
        return Decision::Promote(chosen);
    }
    let none_above = active
        .iter()
        .all(|i| members[*i].level <= levels.floor.max(members[*i].min_level));
    let degraded_spare = active
        .iter()
        .any(|i| members[*i].level > members[*i].min_level && spare(i));
    let all_nominal = active
        .iter()
        .all(|i| members[*i].level <= members[*i].min_level);
    if levels.top {
        if none_above && levels.floor > 0 && degraded_spare {
            return Decision::LowerFloor;
        }
    } else if none_above && levels.cap > 0 && (degraded_spare || all_nominal) {
        return Decision::ReportSpare;
    }
    Decision::Hold
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: fn(u64) -> Duration = Duration::from_millis;

    fn timing(period: u64, max: u64, qualities: &'static [&'static str]) -> TimingSpec {
        TimingSpec {
            period: Some(MS(period)),
            max_period: Some(MS(max)),
            qualities,
            ..TimingSpec::NONE
        }
    }

    #[test]
    fn the_ladder_stretches_the_period_then_lowers_the_quality() {
        let ladder = Ladder::new(&timing(10, 40, &["full", "reduced", "minimal"]), 3);
        assert_eq!(ladder.max_level(), 5);
        let settings: Vec<_> = (0..=6).map(|level| ladder.setting(level)).collect();
        assert_eq!(
            settings,
            [
                (Some(MS(10)), 0),
                (Some(MS(20)), 0),
                (Some(MS(30)), 0),
                (Some(MS(40)), 0),
                (Some(MS(40)), 1),
                (Some(MS(40)), 2),
                (Some(MS(40)), 2),
            ]
        );
        // Back from what other means set.
        assert_eq!(ladder.level_of(Some(MS(10)), 0), 0);
        assert_eq!(ladder.level_of(Some(MS(15)), 0), 1);
        assert_eq!(ladder.level_of(Some(MS(100)), 0), 3);
        // Off the nominal path: the period's index plus the quality.
        assert_eq!(ladder.level_of(Some(MS(10)), 1), 1);
        assert_eq!(ladder.level_of(Some(MS(20)), 2), 3);
        assert_eq!(ladder.level_of(Some(MS(40)), 1), 4);
        // No interval: quality steps only; nothing at all: level 0 only.
        let quality_only = Ladder::new(
            &TimingSpec {
                qualities: &["a", "b"],
                ..timing(10, 10, &[])
            },
            3,
        );
        assert_eq!(quality_only.max_level(), 1);
        assert_eq!(quality_only.setting(1), (Some(MS(10)), 1));
        assert_eq!(Ladder::new(&TimingSpec::NONE, 3).max_level(), 0);
    }

    fn at(period: u64, quality: usize) -> Setting {
        Setting {
            period: Some(MS(period)),
            quality,
        }
    }

    #[test]
    fn from_off_the_path_a_promotion_raises_the_quality_first_and_never_lengthens_the_period() {
        let ladder = Ladder::new(&timing(10, 40, &["full", "reduced", "minimal"]), 3);
        let free = Floor::default();
        // Nominal period at quality 1 (a `degrade` plan step, `SetQuality(1)`): level 1,
        // promoted to nominal by the quality alone (the nominal path would say 40 ms).
        assert_eq!(ladder.toward(at(10, 1), 0, free), at(10, 0));
        // Every promotion from every point: one level down, the period never longer,
        // the quality changed only while above 0 and the period only after.
        for period in [5, 10, 12, 20, 25, 30, 35, 40, 100] {
            for quality in 0..3 {
                let now = at(period, quality);
                let level = ladder.level_of(now.period, now.quality);
                if level == 0 {
                    continue;
                }
                let to = ladder.toward(now, level - 1, free);
                assert_eq!(
                    ladder.level_of(to.period, to.quality),
                    level - 1,
                    "{now:?} -> {to:?}"
                );
                assert!(
                    to.period <= now.period,
                    "a promotion lengthened: {now:?} -> {to:?}"
                );
                assert!(to.quality <= now.quality, "{now:?} -> {to:?}");
                if quality > 0 {
                    assert_eq!(
                        to,
                        Setting {
                            quality: quality - 1,
                            ..now
                        },
                        "quality first"
                    );
                }
                // And a degradation: the period first while it can stretch.
                if level < ladder.max_level() {
                    let to = ladder.toward(now, level + 1, free);
                    assert_eq!(
                        ladder.level_of(to.period, to.quality),
                        level + 1,
                        "{now:?} -> {to:?}"
                    );
                    assert!(to.period >= now.period, "{now:?} -> {to:?}");
                    if ladder.period_index(now.period) < ladder.period_steps {
                        assert_eq!(to.quality, now.quality, "period first: {now:?} -> {to:?}");
                    } else {
                        // (35 ms is at the last step's index: stretched to 40 ms,
                        // then the quality.)
                        assert_eq!(to.period, now.period.max(Some(MS(40))), "{now:?} -> {to:?}");
                    }
                }
            }
        }
        // At 10 ms and quality 1, a degradation stretches the period (the nominal path
        // would say quality 2 at 40 ms, or exhausted).
        assert_eq!(ladder.toward(at(10, 1), 2, free), at(20, 1));
        // On the nominal path, `toward` walks it.
        for level in 0..=ladder.max_level() {
            let (period, quality) = ladder.setting(level);
            for target in 0..=ladder.max_level() {
                let (p, q) = ladder.setting(target);
                assert_eq!(
                    ladder.toward(Setting { period, quality }, target, free),
                    Setting {
                        period: p,
                        quality: q
                    },
                    "{level} -> {target}"
                );
            }
        }
    }

    #[test]
    fn promotions_stop_at_what_was_set_by_other_means() {
        let ladder = Ladder::new(&timing(10, 40, &["full", "reduced"]), 3);
        let pinned = Floor {
            period: None,
            quality: 1,
        };
        assert_eq!(ladder.floor_level(pinned), 1);
        // Degraded from there to (40 ms, 1), then promoted: the period comes back,
        // the quality stays.
        assert_eq!(ladder.toward(at(40, 1), 0, pinned), at(10, 1));
        let slow = Floor {
            period: Some(MS(35)),
            quality: 0,
        };
        assert_eq!(ladder.floor_level(slow), 3);
        assert_eq!(ladder.toward(at(40, 1), 0, slow), at(40, 0));
        assert_eq!(ladder.toward(at(35, 1), 0, slow), at(35, 0));
    }

    #[test]
    fn huge_period_steps_are_clamped_and_levels_are_computed_not_searched() {
        let t = timing(10, 40, &["full", "reduced"]);
        let ladder = Ladder::new(&t, u32::MAX);
        assert_eq!(ladder.period_steps, MAX_PERIOD_STEPS);
        assert_eq!(ladder.max_level(), MAX_PERIOD_STEPS + 1);
        assert_eq!(ladder.level_of(Some(MS(40)), 1), ladder.max_level());
        assert_eq!(ladder.level_of(Some(MS(25)), 0), MAX_PERIOD_STEPS / 2);
        // An interval of 3 ns has at most 3 steps, each a longer period.
        let tiny = TimingSpec {
            max_period: Some(MS(10) + Duration::from_nanos(3)),
            ..t
        };
        let ladder = Ladder::new(&tiny, 100);
        assert_eq!(ladder.period_steps, 3);
        for level in 0..=3 {
            let (period, quality) = ladder.setting(level);
            assert_eq!(ladder.level_of(period, quality), level);
        }
        // Every quality count and step count: no overflow.
        let ladder = Ladder {
            period: Some(MS(10)),
            max_period: Some(MS(40)),
            period_steps: u32::MAX,
            qualities: u32::MAX,
        };
        assert_eq!(ladder.max_level(), u32::MAX);
        let _ = ladder.level_of(Some(Duration::MAX), usize::MAX);
        let _ = ladder.toward(at(40, usize::MAX), u32::MAX, Floor::default());
    }

    #[test]
    fn odd_settings_are_made_safe() {
        let odd = AdaptConfig {
            violations: 5,
            window: 4,
            spare_ratio: f64::NAN,
            spare_periods: 0,
            period_steps: u32::MAX,
            max_backoff: u32::MAX,
            width: 0,
            hold_periods: u32::MAX,
            ..AdaptConfig::default()
        }
        .sanitized();
        assert_eq!((odd.violations, odd.window), (4, 4));
        assert_eq!(odd.spare_ratio, 0.0);
        assert_eq!(odd.spare_periods, 1);
        assert_eq!(odd.period_steps, MAX_PERIOD_STEPS);
        assert_eq!(odd.max_backoff, MAX_BACKOFF);
        assert_eq!(odd.width, 1);
        assert_eq!(odd.hold_periods, MAX_PERIODS);
        assert_eq!(AdaptConfig::default().sanitized(), AdaptConfig::default());
        // More violations than the window holds: detected once the window is full.
        let mut detector = Detector::new(AdaptConfig {
            violations: 5,
            window: 4,
            hold_periods: 0,
            ..AdaptConfig::default()
        });
        assert_eq!(run(&mut detector, 45, 10, 4), [Pressure::Violation]);
    }

    fn run(detector: &mut Detector, elapsed: u64, period: u64, times: usize) -> Vec<Pressure> {
        run_idle(detector, elapsed, period, times, true)
    }

    fn run_idle(
        detector: &mut Detector,
        elapsed: u64,
        period: u64,
        times: usize,
        idle: bool,
    ) -> Vec<Pressure> {
        (0..times)
            .filter_map(|_| {
                detector.observe(Observation {
                    elapsed: MS(elapsed),
                    period: MS(period),
                    missed: elapsed > period,
                    reference: MS(period),
                    idle,
                })
            })
            .collect()
    }

    #[test]
    fn short_sections_are_spare_time_only_while_the_idle_probe_sees_an_idle_cpu() {
        let mut detector = Detector::new(AdaptConfig {
            spare_periods: 3,
            hold_periods: 0,
            ..AdaptConfig::default()
        });
        // Short sections on a busy processor: no spare time, however many.
        assert_eq!(run_idle(&mut detector, 1, 10, 10, false), []);
        // Two idle periods, then a busy one: the run starts again.
        assert_eq!(run_idle(&mut detector, 1, 10, 2, true), []);
        assert_eq!(run_idle(&mut detector, 1, 10, 1, false), []);
        assert_eq!(run_idle(&mut detector, 1, 10, 2, true), []);
        assert_eq!(run_idle(&mut detector, 1, 10, 1, true), [Pressure::Spare]);
        // A busy processor ends spare time; violations do not need the probe.
        assert_eq!(
            run_idle(&mut detector, 1, 10, 1, false),
            [Pressure::Nominal]
        );
        assert_eq!(
            run_idle(&mut detector, 15, 10, 2, true),
            [Pressure::Violation]
        );
    }

    #[test]
    fn the_detector_needs_repeated_violations_and_a_sustained_spare_run() {
        let config = AdaptConfig {
            violations: 2,
            window: 4,
            spare_periods: 5,
            hold_periods: 2,
            ..AdaptConfig::default()
        };
        let mut detector = Detector::new(config);
        // One bad period is noise.
        assert_eq!(run(&mut detector, 15, 10, 1), []);
        assert_eq!(run(&mut detector, 5, 10, 1), []);
        assert_eq!(run(&mut detector, 15, 10, 1), [Pressure::Violation]);
        // A change of level: two periods ignored, then a fresh window.
        assert_eq!(detector.reset(false), Pressure::Violation);
        assert_eq!(run(&mut detector, 15, 10, 2), []);
        assert_eq!(run(&mut detector, 1, 10, 4), []);
        assert_eq!(run(&mut detector, 1, 10, 1), [Pressure::Spare]);
        // 8 ms of 10 is not spare at ratio 0.75: back to nominal.
        assert_eq!(run(&mut detector, 8, 10, 1), [Pressure::Nominal]);
    }

    #[test]
    fn a_promotion_that_fails_doubles_the_spare_run_needed_next() {
        let config = AdaptConfig {
            violations: 1,
            window: 1,
            spare_periods: 3,
            hold_periods: 0,
            max_backoff: 4,
            ..AdaptConfig::default()
        };
        let mut detector = Detector::new(config);
        assert_eq!(run(&mut detector, 1, 10, 3), [Pressure::Spare]);
        detector.reset(true);
        assert_eq!(run(&mut detector, 15, 10, 1), [Pressure::Violation]);
        detector.reset(false);
        // Now 6 spare periods are needed, not 3.
        assert_eq!(run(&mut detector, 1, 10, 5), []);
        assert_eq!(run(&mut detector, 1, 10, 1), [Pressure::Spare]);
        detector.reset(true);
        assert_eq!(run(&mut detector, 15, 10, 1), [Pressure::Violation]);
        detector.reset(false);
        // Capped at 4 times.
        assert_eq!(run(&mut detector, 1, 10, 11), []);
        assert_eq!(run(&mut detector, 1, 10, 1), [Pressure::Spare]);
        // A promotion that holds through its probation clears the backoff.
        detector.reset(true);
        assert_eq!(run(&mut detector, 1, 10, 3), [Pressure::Spare]);
        detector.reset(true);
        assert_eq!(run(&mut detector, 1, 10, 3), [Pressure::Spare]);
    }
}
