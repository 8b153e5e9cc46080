//! One supervision turn of a running compound: pass on what arrived at its exported
//! inputs, take its instances' monitoring events (applying the fault policies), run
//! the recovery queue and pending restarts, refresh the view, evaluate the rules.

use std::collections::{BTreeSet, HashMap, HashSet};
use std::sync::atomic::Ordering;

use crate::automaton::{Context, Fault};
use crate::monitor::MonitorEvent;
use crate::table::State;

use super::state::{Compound, Status};
use super::supervisor::DEFAULT_SUPERVISION_PERIOD;
use super::view::{Own, Rule, View};

/// Copy the compound's own default variables (`result`, `error`, `quality`, its
/// times) from its monitoring port into `view`; the keys whose value changed go into
/// `changed`.
pub(super) fn refresh_own_defaults(view: &mut View, cx: &Context, changed: &mut HashSet<String>) {
    let Some(shared) = &cx.shared else {
        return;
    };
    let mut now = Own::default();
    shared.quietly(|monitor| {
        now = Own {
            result: monitor.result.clone(),
            error: monitor.error.clone(),
            quality: monitor.quality,
            cpu_time: monitor.cpu_time,
            elapsed_time: shared.elapsed(),
        };
    });
    let before = std::mem::replace(&mut view.compound, now);
    let after = &view.compound;
    for (key, differs) in [
        ("result", before.result != after.result),
        ("error", before.error != after.error),
        ("quality", before.quality != after.quality),
    ] {
        if differs {
            changed.insert(key.to_owned());
        }
    }
}

/// The rule of supervisor state `state` that fires, if any: the first that holds in
/// declaration order, among all the state's rules when `all` (the state was just
/// entered, or a supervisor section ran: it may have changed what no `reads` names,
/// its `local` variables), else among the rules reading a variable in `changed`.
pub(super) fn fire(
    rules: &[Rule],
    by_read: &HashMap<String, Vec<usize>>,
    view: &View,
    state: usize,
    all: bool,
    changed: &HashSet<String>,
) -> Option<usize> {
    let holds = |rule: &&Rule| rule.state == state && (rule.test)(view);
    if all {
        rules.iter().find(holds).map(|rule| rule.target)
    } else {
        // Only the rules reading a changed variable, in declaration order.
        let mut candidates: Vec<usize> = changed
            .iter()
            .filter_map(|read| by_read.get(read))
            .flatten()
            .copied()
            .collect();
        candidates.sort_unstable();
        candidates.dedup();
        candidates
            .into_iter()
            .map(|index| &rules[index])
            .find(holds)
            .map(|rule| rule.target)
    }
}

impl Compound {
    /// Copy the compound's own default variables into the view (when a rule reads
    /// them) and, every supervisor period, count the time reads as changed.
    pub(super) fn refresh_compound(&mut self, cx: &Context, changed: &mut HashSet<String>) {
        if self.reads_own {
            refresh_own_defaults(&mut self.view, cx, changed);
        }
        if self.timed.is_empty() {
            return;
        }
        let now = self.clock.now();
        if self.next_timed.is_none_or(|due| now >= due) {
            let period = cx.period().unwrap_or(DEFAULT_SUPERVISION_PERIOD);
            self.next_timed = Some(crate::time::later(now, period));
            // An instance publishes its times without an event: read the snapshot of
            // every instance a time read names, so the rules see their times now.
            let named: BTreeSet<usize> = self
                .timed
                .iter()
                .filter_map(|key| key.split_once('.'))
                .filter_map(|(instance, _)| self.view.positions.get(instance).copied())
                .collect();
            for index in named {
                self.refresh(index);
            }
            changed.extend(self.timed.iter().cloned());
        }
    }

    pub(super) fn refresh_own(&mut self, changed: &mut HashSet<String>) {
        for (index, (name, value)) in self.view.own.iter_mut().enumerate() {
            let now = self.supervisor.get(index);
            if *value != now {
                *value = now;
                changed.insert(name.clone());
            }
        }
    }

    /// Take the instances' events and refresh the view; run the policies of the
    /// instances that failed if `act` (otherwise, while the compound is suspended,
    /// they wait for it to run: `deferred_faults`); return the variables that changed.
    pub(super) fn take_events(&mut self, act: bool) -> Result<HashSet<String>, Fault> {
        let mut changed = HashSet::new();
        for index in 0..self.events.len() {
            // Cleared before the channel is read: an event sent after the read sets it
            // again (it is set before the ring).
            let flag = &self.events[index].1;
            if !flag.load(Ordering::Acquire) || !flag.swap(false, Ordering::AcqRel) {
                continue;
            }
            let mut seen = false;
            let failure =
                |state: State| matches!(state, State::RunningError | State::StartingError);
            while let Ok(event) = self.events[index].0.try_recv() {
                seen = true;
                let instance = &mut self.instances[index];
                let name = &instance.name;
                let key = match event {
                    MonitorEvent::State { from, to } => {
                        if let Some(coordinator) = self.coordinator.as_mut() {
                            coordinator.dirty = true;
                        }
                        if failure(from) && !failure(to) {
                            // It left its fault: the next one is a new fault.
                            instance.handled = false;
                        }
                        format!("{name}.state")
                    }
                    MonitorEvent::Quality(_) => format!("{name}.quality"),
                    MonitorEvent::Period(_) => format!("{name}.period"),
                    MonitorEvent::MaxResponse(_) => format!("{name}.max_response"),
                    MonitorEvent::Priority(_) => format!("{name}.priority"),
                    MonitorEvent::Pressure(_) | MonitorEvent::Adaptation(_) => {
                        if let Some(coordinator) = self.coordinator.as_mut() {
                            coordinator.dirty = true;
                        }
                        continue;
                    }
                    MonitorEvent::UserState(_) => format!("{name}.user_state"),
                    MonitorEvent::Result(_) => format!("{name}.result"),
                    MonitorEvent::Error(_) => format!("{name}.error"),
                    MonitorEvent::Variable { name: variable, .. } => {
                        // A mapped variable changes with it if this instance stands
                        // for the declared one.
                        for (mapped, (declared, target)) in &self.view.mapped {
                            if *target == variable
                                && self.view.standing.get(*declared) == Some(&index)
                            {
                                changed.insert(mapped.clone());
                            }
                        }
                        format!("{name}.{variable}")
                    }
                    _ => continue,
                };
                changed.insert(key);
            }
            if !seen {
                continue;
            }
            self.refresh(index);
            let state = self.view.instances[index].state;
            let failed = failure(state);
            if !failed {
                self.instances[index].handled = false;
            }
            match self.instances[index].status {
                Status::Active if failed && !self.instances[index].handled && !act => {
                    self.deferred_faults = true;
                }
                Status::Active if failed && !self.instances[index].handled => {
                    self.instances[index].handled = true;
                    let outcome = self.failed(index);
                    outcome.map_err(|fault| self.propagated(index, fault))?;
                }
                Status::Recovering if failed => {
                    if let Some(entry) = self.queue.iter_mut().find(|e| e.instance == index) {
                        entry.probation = false;
                    }
                }
                _ => {}
            }
        }
        Ok(changed)
    }
}

impl Compound {
    /// One supervision turn: exports, instance events and policies, the recovery
    /// queue, then the rules of supervisor state `state`.
    pub(super) fn supervise_turn(
        &mut self,
        state: usize,
        cx: &Context,
    ) -> Result<Option<usize>, Fault> {
        let now = self.clock.now();
        for export in &mut self.exports {
            export.forward(now);
        }
        self.fresh = false;
        let mut changed = self.take_events(true)?;
        if self.keep_in_step() {
            self.rewire()?;
        }
        if std::mem::take(&mut self.deferred_faults) {
            self.deferred_policies()?;
        }
        if !self.queue.is_empty() {
            self.recover(self.clock.now())?;
        }
        if self.instances.iter().any(|i| i.pending.is_some()) {
            self.restarts_due(self.clock.now())?;
        }
        self.refresh_own(&mut changed);
        self.refresh_compound(cx, &mut changed);
        if std::mem::take(&mut self.restood) {
            changed.extend(self.view.mapped.keys().cloned());
        }
        let entered = self.evaluated_in != Some(state);
        // After a supervisor section every rule of the state is evaluated: the section
        // may have changed what no `reads` names (its `local` variables).
        let sectioned = std::mem::take(&mut self.sectioned);
        if !entered && !sectioned && changed.is_empty() {
            return Ok(None);
        }
        self.evaluated_in = Some(state);
        let fired = fire(
            &self.rules,
            &self.by_read,
            &self.view,
            state,
            entered || sectioned,
            &changed,
        );
        Ok(fired)
    }
}

impl Compound {
    /// A turn while the compound is suspended: monitoring is observation, so it goes
    /// on (the instances' events are taken, the view and the compound's mapped
    /// variables follow them, and its own monitoring port publishes them); nothing
    /// acts: no packet is passed on at exported inputs, no policy runs (an instance
    /// that fails meanwhile is handled when the compound runs again), no recovery
    /// retry, restart, rule or adaptation decision.
    pub(super) fn observe_turn(&mut self) {
        if let Err(fault) = self.take_events(false) {
            // (Without policies nothing in it fails.)
            crate::limited!(
                &self.name,
                |held| tracing::warn!(compound = %self.name, "{fault}{held}")
            );
        }
    }

    /// The policies of the active instances that failed while the compound was
    /// suspended, now that it runs.
    fn deferred_policies(&mut self) -> Result<(), Fault> {
        for index in 0..self.instances.len() {
            let state = self.view.instances[index].state;
            let failed = matches!(state, State::RunningError | State::StartingError);
            if self.instances[index].status == Status::Active
                && failed
                && !self.instances[index].handled
            {
                self.instances[index].handled = true;
                let outcome = self.failed(index);
                outcome.map_err(|fault| self.propagated(index, fault))?;
            }
        }
        Ok(())
    }
}
