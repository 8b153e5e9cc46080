//! One supervision turn of a running compound: pass on what arrived at its exported
//! inputs, take its instances' monitoring events (applying the fault policies), run
//! the recovery queue and pending restarts, refresh the view, evaluate the rules.

use std::sync::atomic::Ordering;

use crate::automaton::{Context, Fault};
use crate::monitor::{MonitorEvent, Step};
use crate::table::State;

use super::reads::{Changed, Reads};
use super::state::{Compound, Status};
use super::supervisor::DEFAULT_SUPERVISION_PERIOD;
use super::view::{Rule, View};

/// Copy the compound's own default variables (`result`, `error`, `quality`, its
/// times) from its monitoring port into `view`; the keys whose value changed (of
/// those `reads` names) go into `changed`.
pub(super) fn refresh_own_defaults(
    view: &mut View,
    cx: &Context,
    reads: &Reads,
    changed: &mut Changed,
) {
    let Some(shared) = &cx.shared else {
        return;
    };
    let now = &mut view.compound;
    let (mut result, mut error, mut quality) = (false, false, false);
    shared.quietly(|monitor| {
        result = now.result != monitor.result;
        if result {
            now.result.clone_from(&monitor.result);
        }
        error = now.error != monitor.error;
        if error {
            now.error.clone_from(&monitor.error);
        }
        quality = now.quality != monitor.quality;
        now.quality = monitor.quality;
        now.cpu_time = monitor.cpu_time;
    });
    now.elapsed_time = shared.elapsed();
    for (id, differs) in [
        (reads.own_result, result),
        (reads.own_error, error),
        (reads.own_quality, quality),
    ] {
        if differs {
            changed.insert(id);
        }
    }
}

/// The rule of supervisor state `state` that fires, if any: the first that holds in
/// declaration order, among all the state's rules when `all` (the state was just
/// entered, or a supervisor section ran: it may have changed what no `reads` names,
/// its `local` variables), else among the rules reading a key in `changed`.
pub(super) fn fire(
    rules: &[Rule],
    view: &View,
    state: usize,
    all: bool,
    changed: &Changed,
) -> Option<usize> {
    rules
        .iter()
        .filter(|rule| rule.state == state)
        .filter(|rule| all || rule.reads.iter().any(|id| changed.contains(*id)))
        .find(|rule| (rule.test)(view))
        .map(|rule| rule.target)
}

impl Compound {
    /// Copy the compound's own default variables into the view (when a rule reads
    /// them) and, every supervisor period, count the time reads as changed.
    pub(super) fn refresh_compound(&mut self, cx: &Context) {
        if self.reads_own {
            refresh_own_defaults(&mut self.view, cx, &self.reads, &mut self.changed);
        }
        if self.reads.timed.is_empty() {
            return;
        }
        let now = self.clock.now();
        if self.next_timed.is_none_or(|due| now >= due) {
            let period = cx.period().unwrap_or(DEFAULT_SUPERVISION_PERIOD);
            self.next_timed = Some(crate::time::later(now, period));
            // An instance publishes its times without an event: read the snapshot of
            // every instance a time read names, so the rules see their times now.
            for at in 0..self.reads.timed_instances.len() {
                self.refresh(self.reads.timed_instances[at]);
            }
            self.changed.extend(self.reads.timed.iter().copied());
        }
    }

    pub(super) fn refresh_own(&mut self) {
        for (index, (_, value)) in self.view.own.iter_mut().enumerate() {
            let now = self.supervisor.get(index);
            if *value != now {
                *value = now;
                self.changed.insert(self.reads.own[index]);
            }
        }
    }

    /// The keys that change with instance `index`'s variable `variable`: its own
    /// (`inst.variable`), and the mapped variables it maps while this instance stands
    /// for the instance they are declared on.
    fn variable_changed(&mut self, index: usize, variable: &str) {
        let reads = &self.reads.instances[index];
        if let Some(known) = reads.variables.iter().find(|v| v.name == variable) {
            self.changed.insert(known.key);
            for (declared, id) in &known.mapped {
                if self.view.standing.get(*declared) == Some(&index) {
                    self.changed.insert(Some(*id));
                }
            }
            return;
        }
        // A variable its spec does not declare (nothing a rule was checked to read
        // names it, but its key may still be one).
        let name = &self.instances[index].name;
        self.changed
            .insert(self.reads.id(&format!("{name}.{variable}")));
        for (at, m) in self.mapped.iter().enumerate() {
            if m.variable == variable && self.view.standing.get(m.instance) == Some(&index) {
                self.changed.insert(self.reads.mapped[at]);
            }
        }
    }

    /// Take the instances' events and refresh the view; run the policies of the
    /// instances that failed if `act` (otherwise, while the compound is suspended,
    /// they wait for it to run: `deferred_faults`). The read keys that changed are
    /// in `changed` (what it held before is forgotten).
    pub(super) fn take_events(&mut self, act: bool) -> Result<(), Fault> {
        self.changed.clear();
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
                let reads = &self.reads.instances[index];
                let key = match event {
                    MonitorEvent::State { from, to } => {
                        if let Some(coordinator) = self.coordinator.as_mut() {
                            coordinator.dirty = true;
                        }
                        if failure(from) && !failure(to) {
                            // It left its fault: the next one is a new fault.
                            self.instances[index].handled = false;
                        }
                        reads.state
                    }
                    MonitorEvent::Quality(_) => reads.quality,
                    MonitorEvent::Period(_) => reads.period,
                    MonitorEvent::MaxResponse(_) => reads.max_response,
                    MonitorEvent::Priority(_) => reads.priority,
                    MonitorEvent::Pressure(_) | MonitorEvent::Adaptation(_) => {
                        if let Some(coordinator) = self.coordinator.as_mut() {
                            coordinator.dirty = true;
                        }
                        continue;
                    }
                    MonitorEvent::UserState(_) => reads.user_state,
                    MonitorEvent::Result(_) => reads.result,
                    MonitorEvent::Error(_) => reads.error,
                    MonitorEvent::Variable { name, .. } => {
                        self.variable_changed(index, &name);
                        continue;
                    }
                    _ => continue,
                };
                self.changed.insert(key);
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
                    // Restarted by a retry, it failed again before it could count as
                    // recovered: a step says so; the next retry comes as before.
                    let on_probation = self
                        .queue
                        .iter_mut()
                        .find(|e| e.instance == index)
                        .is_some_and(|entry| std::mem::take(&mut entry.probation));
                    if on_probation {
                        let error = self.view.instances[index].error.clone().unwrap_or_default();
                        self.step(
                            index,
                            Step::Failed,
                            format!("again, on probation after a retry: {error}"),
                        );
                    }
                }
                _ => {}
            }
        }
        Ok(())
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
        self.take_events(true)?;
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
        self.refresh_own();
        self.refresh_compound(cx);
        if std::mem::take(&mut self.restood) {
            for at in 0..self.reads.mapped.len() {
                self.changed.insert(self.reads.mapped[at]);
            }
        }
        let entered = self.evaluated_in != Some(state);
        // After a supervisor section every rule of the state is evaluated: the section
        // may have changed what no `reads` names (its `local` variables).
        let sectioned = std::mem::take(&mut self.sectioned);
        if !entered && !sectioned && self.changed.is_empty() {
            return Ok(None);
        }
        self.evaluated_in = Some(state);
        let fired = fire(
            &self.rules,
            &self.view,
            state,
            entered || sectioned,
            &self.changed,
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
