//! A compound supervisor's adaptation (paper 3.6, Figures 6 and 7): the homogeneity
//! interval of its instances' degradation levels, what it asks of them, and the
//! settling time and reconfiguration backoff between decisions.

use std::sync::atomic::Ordering;
use std::time::Duration;

use crate::adapt::{AdaptAction, Adaptation, Decision, Levels, Member, Pressure};
use crate::automaton::Context;
use crate::handle::Handle;
use crate::monitor::Command;
use crate::table::{Controllable, State};

use super::state::{Compound, Status};

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
        let now = self.clock.now();
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
                shared.adaptation_step(step, true, |status| {
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
            let now = self.clock.now();
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
                crate::limited!(
                    &self.name,
                    |held| tracing::warn!(compound = %self.name, "adaptation: {note}{held}")
                );
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
                    coordinator.pending[index] = Some((to, self.clock.now()));
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

/// How long a level commanded to an instance is taken as applied before its monitor
/// shows it (a command the instance rejected is forgotten after this).
pub(super) const DEFAULT_PENDING: Duration = Duration::from_secs(2);

/// Queue `command` at `handle` without waiting for the answer (the supervisor never
/// waits for an instance in a long section).
pub(super) fn post(handle: &Handle, command: Command) {
    if let Err(rejected) = handle.post_by_supervisor(command) {
        crate::limited!(handle.name(), |held| tracing::warn!(
            "adaptation: {rejected}{held}"
        ));
    }
}
