//! A compound supervisor's adaptation (paper 3.6, Figures 6 and 7): the homogeneity
//! interval of its instances' degradation levels, what it asks of them, and the
//! settling time and reconfiguration backoff between decisions.

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use crate::adapt::{
    AdaptAction, AdaptConfig, Adaptation, Decision, Levels, Member, Pressure, Selector,
};
use crate::automaton::Context;
use crate::monitor::{Command, Handle, Monitor};
use crate::table::{Controllable, State};

use super::DEFAULT_SUPERVISION_PERIOD;
use super::component::{Compound, Status};

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

impl Compound {
    /// Set up adaptation at the first start: the cap (top level: the interval's
    /// width; nested: 0, until the supervisor above grants a level) and the published
    /// status.
    pub(super) fn adapt_start(&mut self, cx: &mut Context) {
        let max_level = self.adaptive_max_level();
        let Some(coordinator) = self.coordinator.as_mut() else {
            return;
        };
        coordinator.max_level = max_level;
        let managed = cx
            .shared
            .as_ref()
            .is_some_and(|shared| shared.adapt_managed.load(Ordering::Acquire));
        if !coordinator.initialized {
            coordinator.initialized = true;
            coordinator.cap = if managed {
                0
            } else {
                coordinator.config.width.min(max_level)
            };
            coordinator.floor = 0;
        }
        coordinator.dirty = true;
        let (cap, floor) = (coordinator.cap, coordinator.floor);
        if let Some(shared) = &cx.shared {
            shared.quietly(|monitor| {
                let status = &mut monitor.adaptation;
                status.enabled = true;
                status.level = cap;
                status.floor = floor;
                status.max_level = max_level;
            });
        }
    }

    /// The highest ladder top among the instances that adapt.
    pub(super) fn adaptive_max_level(&self) -> u32 {
        self.view
            .instances
            .iter()
            .filter(|m| m.adaptation.enabled)
            .map(|m| m.adaptation.max_level)
            .max()
            .unwrap_or(0)
    }

    /// The instances taking part in adaptation, as the policy sees them: those
    /// active and running with adaptation on, and those suspended by adaptation.
    pub(super) fn members(&mut self) -> (Vec<Member>, Vec<usize>) {
        let now = Instant::now();
        let Some(coordinator) = self.coordinator.as_mut() else {
            return (Vec::new(), Vec::new());
        };
        let mut members = Vec::new();
        let mut indices = Vec::new();
        for (index, instance) in self.instances.iter().enumerate() {
            let monitor = &self.view.instances[index];
            let suspended = coordinator.suspended[index];
            let running = instance.status == Status::Active && monitor.state == State::Running;
            if !monitor.adaptation.enabled || !(running || suspended) {
                continue;
            }
            let mut level = monitor.adaptation.level;
            let mut pressure = monitor.adaptation.pressure;
            if let Some((commanded, since)) = coordinator.pending[index] {
                if commanded == level || now.saturating_duration_since(since) > DEFAULT_PENDING {
                    coordinator.pending[index] = None;
                } else {
                    // Not applied yet: its verdict is about the level before.
                    level = commanded;
                    pressure = Pressure::Nominal;
                }
            }
            members.push(Member {
                name: instance.name.clone(),
                priority: monitor.priority,
                level,
                max_level: monitor.adaptation.max_level,
                min_level: monitor.adaptation.min_level,
                pressure,
                load: monitor.adaptation.load,
                cpu_share: monitor.adaptation.cpu_share,
                period: monitor.period,
                suspended,
            });
            indices.push(index);
        }
        (members, indices)
    }

    /// One adaptation turn: decide (Figures 6 and 7) and act, until an instance was
    /// commanded or nothing is left to do. Commands are posted without waiting (an
    /// instance in a long section takes them when it returns).
    pub(super) fn adapt_turn(&mut self, cx: &mut Context) {
        let max_level = self.adaptive_max_level();
        let managed = cx
            .shared
            .as_ref()
            .is_some_and(|shared| shared.adapt_managed.load(Ordering::Acquire));
        let shared = cx.shared.clone();
        let publish = |step: Adaptation, cap: u32, floor: u32| {
            if let Some(shared) = &shared {
                shared.adaptation_step(step, |status| {
                    status.level = cap;
                    status.floor = floor;
                });
            }
        };
        if let Some(coordinator) = self.coordinator.as_mut() {
            coordinator.dirty = false;
            coordinator.max_level = max_level;
        }
        let mut decision = Decision::Hold;
        for _ in 0..8 {
            let (members, indices) = self.members();
            let Some(coordinator) = self.coordinator.as_mut() else {
                return;
            };
            let now = Instant::now();
            if let Some(resumed) = coordinator.resumed_at
                && now.saturating_duration_since(resumed)
                    > coordinator.settling(&members, &self.view.instances, &indices)
            {
                // The last resume held through a settling time: no backoff any more.
                coordinator.resumed_at = None;
                coordinator.backoff = 1;
            }
            if members.iter().any(|m| m.pressure == Pressure::Violation) {
                coordinator.settle(&members, &self.view.instances, &indices, now);
            }
            let settled = match coordinator.settle_until {
                Some(until) if now < until => false,
                Some(_) => {
                    coordinator.settle_until = None;
                    true
                }
                None => true,
            };
            let levels = Levels {
                cap: coordinator.cap,
                floor: coordinator.floor,
                top: !managed,
                reconfiguration: coordinator.config.reconfiguration,
                settled,
            };
            let (decided, note) =
                crate::adapt::decide_explained(&members, levels, &*coordinator.selector);
            decision = decided;
            if let Some(note) = &note {
                tracing::warn!(compound = %self.name, "adaptation: {note}");
            }
            let noted = |detail: String| match &note {
                Some(note) => format!("{detail} ({note})"),
                None => detail,
            };
            if decision != Decision::Exhausted {
                coordinator.exhausted = false;
            }
            let (cap, floor, width) =
                (coordinator.cap, coordinator.floor, coordinator.config.width);
            let own = |action, from, to, detail: String| Adaptation {
                component: self.name.clone(),
                action,
                from,
                to,
                period: None,
                quality: None,
                detail,
            };
            let violators = || {
                members
                    .iter()
                    .filter(|m| m.pressure == Pressure::Violation)
                    .map(|m| m.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            match decision {
                Decision::RaiseCap => {
                    coordinator.cap = cap + 1;
                    coordinator.floor = (cap + 1).saturating_sub(width);
                    let detail = format!(
                        "every instance at the current maximum; time violation at {}",
                        violators()
                    );
                    publish(
                        own(AdaptAction::CapRaised, cap, cap + 1, detail),
                        cap + 1,
                        coordinator.floor,
                    );
                    continue;
                }
                Decision::LowerFloor => {
                    coordinator.floor = floor - 1;
                    coordinator.cap = (floor - 1 + width).min(max_level.max(width));
                    let detail = "every instance at the current minimum, spare time".to_owned();
                    publish(
                        own(AdaptAction::FloorLowered, floor, floor - 1, detail),
                        coordinator.cap,
                        floor - 1,
                    );
                    continue;
                }
                Decision::Degrade(m) | Decision::Promote(m) | Decision::Clamp(m) => {
                    let member = &members[m];
                    let (to, action, detail) = match decision {
                        Decision::Degrade(_) => (
                            member.level.saturating_add(1),
                            AdaptAction::Degraded,
                            noted(format!("time violation at {}", violators())),
                        ),
                        Decision::Promote(_) => (
                            member.level.saturating_sub(1),
                            AdaptAction::Promoted,
                            noted("spare time".to_owned()),
                        ),
                        _ => (
                            cap.max(member.min_level),
                            AdaptAction::Promoted,
                            format!("above the current maximum level {cap}"),
                        ),
                    };
                    let index = indices[m];
                    coordinator.pending[index] = Some((to, Instant::now()));
                    let step = Adaptation {
                        component: member.name.clone(),
                        action,
                        from: member.level,
                        to,
                        period: None,
                        quality: None,
                        detail,
                    };
                    publish(step, cap, floor);
                    post(&self.instances[index].handle, Command::SetDegradation(to));
                }
                Decision::Suspend(m) | Decision::Resume(m) => {
                    let index = indices[m];
                    let suspend = matches!(decision, Decision::Suspend(_));
                    coordinator.suspended[index] = suspend;
                    if suspend {
                        coordinator.suspended_now(&members, &self.view.instances, &indices, now);
                    } else {
                        coordinator.resumed_at = Some(now);
                    }
                    let (action, target, detail) = if suspend {
                        (
                            AdaptAction::Suspended,
                            Controllable::Suspended,
                            format!("degradation exhausted; time violation at {}", violators()),
                        )
                    } else {
                        (
                            AdaptAction::Resumed,
                            Controllable::Running,
                            "spare time".to_owned(),
                        )
                    };
                    let level = members[m].level;
                    let step = Adaptation {
                        component: members[m].name.clone(),
                        action,
                        from: level,
                        to: level,
                        period: None,
                        quality: None,
                        detail,
                    };
                    publish(step, cap, floor);
                    post(&self.instances[index].handle, Command::SetState(target));
                }
                Decision::Exhausted if !coordinator.exhausted => {
                    coordinator.exhausted = true;
                    let detail = format!(
                        "every instance at the highest level; time violation at {}",
                        violators()
                    );
                    publish(own(AdaptAction::Exhausted, cap, cap, detail), cap, floor);
                }
                Decision::NotifyHigher | Decision::ReportSpare => {
                    let pressure = decision.pressure();
                    let already = shared
                        .as_ref()
                        .is_some_and(|s| s.snapshot().adaptation.pressure == pressure);
                    if !already {
                        let (action, detail) = if pressure == Pressure::Violation {
                            (
                                AdaptAction::NotifiedHigher,
                                format!(
                                    "every instance at the current maximum level {cap}; time violation at {}",
                                    violators()
                                ),
                            )
                        } else {
                            (
                                AdaptAction::ReportedSpare,
                                "spare time; no instance above the current minimum".to_owned(),
                            )
                        };
                        publish(own(action, cap, cap, detail), cap, floor);
                    }
                }
                Decision::Exhausted | Decision::Hold => {}
            }
            break;
        }
        if let Some(shared) = &shared {
            shared.set_pressure(decision.pressure(), 0.0);
            let (cap, floor) = self
                .coordinator
                .as_ref()
                .map_or((0, 0), |c| (c.cap, c.floor));
            shared.quietly(|monitor| {
                monitor.adaptation.level = cap;
                monitor.adaptation.floor = floor;
                monitor.adaptation.max_level = max_level;
            });
        }
    }
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
        let until = crate::thread::later(now, self.settling(members, monitors, indices));
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

/// How long a level commanded to an instance is taken as applied before its monitor
/// shows it (a command the instance rejected is forgotten after this).
pub(super) const DEFAULT_PENDING: Duration = Duration::from_secs(2);

/// Queue `command` at `handle` without waiting for the answer (the supervisor never
/// waits for an instance in a long section).
pub(super) fn post(handle: &Handle, command: Command) {
    if let Err(rejected) = handle.post(command) {
        tracing::warn!("adaptation: {rejected}");
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
