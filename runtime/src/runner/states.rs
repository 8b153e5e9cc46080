//! The default automaton's actions and the user automaton: states, sections, choices.

use super::*;

impl Runner {
    // -----------------------------------------------------------------------------
    // The default automaton.

    /// Run the table's outcome for `event`.
    pub(super) fn apply(&mut self, event: Event) {
        let Outcome::Go { to, actions } = next(self.state, event) else {
            return;
        };
        let from = self.state;
        // On the way to `dead`, every call that remains (an exit section, `stop`) is
        // told so (`Context::stopping`); nothing comes back from `dead`.
        self.cx.stopping = to == State::Dead;
        self.run_actions(to, actions);
        if self.supervised {
            let now = self.state;
            if let Err(panic) = self.call(|automaton, cx| automaton.after_transition(from, now, cx))
            {
                self.set_error(Some(format!("panic after a transition: {panic}")));
            }
        }
    }

    /// Compound components, while suspended: observe the instances (their events keep
    /// the compound's view and mapped variables current); nothing acts.
    pub(super) fn observe_instances(&mut self) {
        if let Err(panic) = self.call(|automaton, cx| automaton.observe(cx)) {
            self.set_error(Some(format!("panic in the supervisor: {panic}")));
        }
    }

    /// Compound components: let the instances run before the user automaton is entered
    /// or resumed; false (and `running_error`) if they could not.
    pub(super) fn before_running(&mut self) -> bool {
        if !self.supervised {
            return true;
        }
        let message = match self.call(|automaton, cx| automaton.before_running(cx)) {
            Ok(Ok(())) => return true,
            Ok(Err(fault)) => fault.text().to_owned(),
            Err(panic) => format!("panic before running: {panic}"),
        };
        self.set_error(Some(message));
        self.run_stop();
        self.set_state(State::RunningError);
        false
    }

    pub(super) fn run_actions(&mut self, to: State, actions: &[Action]) {
        for action in actions {
            match action {
                Action::Start => {
                    self.set_state(State::Starting);
                    // A restart leaves the user automaton of the failed run behind.
                    self.user_entered = false;
                    self.pending_choice = None;
                    self.retrying = None;
                    self.publish_user(None);
                    if let Err(message) = self.run_start() {
                        self.set_error(Some(message));
                        self.set_state(State::StartingError);
                        return;
                    }
                }
                Action::Stop => self.run_stop(),
                Action::ExitUser => {
                    if let Err(message) = self.exit_user() {
                        self.set_error(Some(message));
                        if to != State::Dead {
                            self.run_stop();
                            self.set_state(State::RunningError);
                            return;
                        }
                    }
                }
                Action::ResetUser => {
                    self.user = self.spec.initial;
                    self.user_entered = false;
                    self.pending_choice = None;
                    self.retrying = None;
                    let initial = (!self.spec.states.is_empty()).then_some(self.spec.initial);
                    self.publish_user(initial);
                }
                // The user automaton runs inside `running`: set the state first.
                Action::EnterUser => {
                    if !self.before_running() {
                        return;
                    }
                    self.set_state(to);
                    // Packets that came while it did not run (queued while `ready`,
                    // or moved to it as a substitute) are arrivals in its initial
                    // state; their wait is not a response time.
                    self.arrivals_count_on_entry = true;
                    for label in self.labels.iter().flatten() {
                        let _ = label.take();
                    }
                    self.enter(self.spec.initial, self.time.now());
                    return;
                }
                Action::ResumeUser => {
                    if !self.before_running() {
                        return;
                    }
                    // Packets that waited while it was suspended: their wait is not a
                    // response time.
                    for label in self.labels.iter().flatten() {
                        let _ = label.take();
                    }
                    self.set_state(to);
                    self.resume();
                    return;
                }
            }
        }
        if to == State::Suspended && self.state == State::Running {
            self.suspended_at = Some(self.time.now());
        }
        self.set_state(to);
    }

    pub(super) fn resume(&mut self) {
        if !self.user_entered {
            self.enter(self.user, self.time.now());
            return;
        }
        // Time in a state stops while suspended: shift the timers by the pause.
        let now = self.time.now();
        if let Some(since) = self.suspended_at.take() {
            let pause = now.saturating_duration_since(since);
            self.entered_at += pause;
            self.cx.entered_at = self.entered_at;
            for track in &mut self.tracks {
                track.last_arrival += pause;
            }
            // A section's retry waits on as a timer does, and a periodic deadline it
            // failed at moves with it: the pause is no missed deadline.
            if let Some(retrying) = self.retrying.as_mut() {
                retrying.due = later(retrying.due, pause);
                // (Time suspended is no response time.)
                if let Some(arrived) = retrying.arrived.as_mut() {
                    *arrived = later(*arrived, pause);
                }
                if let Then::Periodic { deadline, .. } = &mut retrying.then {
                    *deadline = later(*deadline, pause);
                }
            }
        }
        self.next_periodic = self
            .period_of(self.user)
            .map(|period| self.deadline_after(now, period));
    }

    pub(super) fn set_state(&mut self, to: State) {
        if self.state == to {
            return;
        }
        self.state = to;
        self.update_cpu(true);
        // The monitor may be there already: the watchdog moved it to `running_error`
        // while a section overran.
        self.shared.update(|monitor| {
            let from = monitor.state;
            if from == to {
                return Vec::new();
            }
            monitor.state = to;
            vec![MonitorEvent::State { from, to }]
        });
    }

    /// Set the error on the monitor; a new one is logged (the same error again, as
    /// each failed retry of a recovery sets it, is not, and a component's errors are
    /// logged at most every `log::EVERY`, with the count held back).
    pub(super) fn set_error(&mut self, error: Option<String>) {
        let mut new = false;
        self.shared.update(|monitor| {
            if monitor.error == error {
                return Vec::new();
            }
            new = true;
            monitor.error.clone_from(&error);
            vec![MonitorEvent::Error(error.clone())]
        });
        if new && let Some(message) = &error {
            crate::limited!(
                &self.cx.name,
                |held| tracing::warn!(component = %self.cx.name, "{message}{held}")
            );
        }
    }

    pub(super) fn publish_user(&mut self, state: Option<usize>) {
        if self.published_user == state {
            return;
        }
        self.published_user = state;
        let name = state.map(|index| self.spec.states[index].name);
        self.shared.update(|monitor| {
            if monitor.user_state.as_deref() == name {
                return Vec::new();
            }
            let name = name.map(str::to_owned);
            monitor.user_state.clone_from(&name);
            vec![MonitorEvent::UserState(name)]
        });
    }

    // -----------------------------------------------------------------------------
    // The user automaton.

    /// Leave the current user state (its exit section), as part of a default-automaton
    /// transition.
    pub(super) fn exit_user(&mut self) -> Result<(), String> {
        // A state whose entry waits for a retry was never entered: its exit does not
        // run (on a thread that slept through the retries, the command came after
        // them, to a state entered or to `running_error`).
        let entering = self
            .retrying
            .as_ref()
            .is_some_and(|retrying| matches!(retrying.then, Then::Entered));
        let result = if self.user_entered && !entering && self.spec.states[self.user].exit {
            // (A transition of the default automaton ends before the next command:
            // a retry waits on the thread, in a group too.)
            match self.section_with_plan(self.user, Section::Exit, None) {
                Recovery::Failed(message) => Err(message),
                Recovery::Recovered | Recovery::Goto(_) | Recovery::Later => Ok(()),
            }
        } else {
            Ok(())
        };
        self.user_entered = false;
        self.next_periodic = None;
        self.pending_choice = None;
        self.retrying = None;
        self.publish_user(None);
        result
    }

    /// A user transition to `target`: the exit section of the current state, then the
    /// entry of `target`.
    pub(super) fn goto(&mut self, target: usize, now: Instant) {
        if target >= self.spec.states.len() {
            self.fail(format!("transition to unknown user state #{target}"));
            return;
        }
        if self.user_entered && self.spec.states[self.user].exit {
            let then = Some(Then::Enter { target });
            match self.section_with_plan(self.user, Section::Exit, then) {
                // Retried later: `target` is entered once the retries are over.
                Recovery::Later => {}
                outcome => self.exited(target, now, outcome),
            }
            return;
        }
        self.enter(target, now);
    }

    /// After the exit section of a user transition to `target` and its plan's
    /// `outcome` (a `goto` in the plan is no other target: the transition goes on),
    /// at `now`.
    pub(super) fn exited(&mut self, target: usize, now: Instant, outcome: Recovery) {
        if let Recovery::Failed(message) = outcome {
            self.fail(message);
            return;
        }
        if self.state == State::Running {
            self.enter(target, now);
        }
    }

    /// Enter user state `target` and run its entry section.
    pub(super) fn enter(&mut self, target: usize, now: Instant) {
        if self.spec.states.is_empty() {
            // No user automaton: `running` only serves pull requests.
            return;
        }
        self.user = target;
        self.user_entered = true;
        self.entered_at = now;
        self.cx.entered_at = now;
        self.suspended_at = None;
        self.pending_choice = None;
        self.retrying = None;
        let unseen_count = std::mem::take(&mut self.arrivals_count_on_entry);
        for (index, input) in self.inputs.iter().enumerate() {
            let arrivals = input.arrivals();
            // (Not on an event input: a tick count moved to it with a connection may
            // hold events that its previous consumer already acted on.)
            let data = !matches!(
                self.spec.inputs.get(index).map(|spec| spec.kind),
                Some(InputKind::Tick) | None
            );
            let track = &mut self.tracks[index];
            track.pending = unseen_count && data && arrivals != track.seen;
            track.seen = arrivals;
            track.last_arrival = now;
            // Arrivals before the state was entered are no events in it: their stamp
            // would time a later packet's response from them.
            if !track.pending
                && let Some(Some(label)) = self.labels.get(index)
            {
                let _ = label.take();
            }
        }
        self.next_periodic = self
            .period_of(target)
            .map(|period| self.deadline_after(now, period));
        if self.supervised {
            // The supervisor evaluates the new state's rules on its next turn (its
            // `wake_at` asks for that turn at once).
            self.automaton.entered(target);
        }
        self.publish_user(Some(target));
        let outcome = if self.spec.states[target].entry {
            self.section_with_plan(target, Section::Entry, Some(Then::Entered))
        } else {
            Recovery::Recovered
        };
        self.entered(target, outcome);
    }

    /// After the entry section of `state` and its plan's `outcome`: its `choose`.
    pub(super) fn entered(&mut self, state: usize, outcome: Recovery) {
        match outcome {
            Recovery::Recovered => self.choose(state),
            // Retried later: the state is entered once the retries are over.
            Recovery::Later => {}
            Recovery::Goto(target) => self.pending_choice = Some(target),
            Recovery::Failed(message) => self.fail(message),
        }
    }

    /// Run the periodic section due at `deadline`; schedule the next one.
    pub(super) fn periodic(&mut self, deadline: Instant) {
        let state = self.user;
        let Some(period) = self.period_of(state) else {
            self.next_periodic = None;
            return;
        };
        self.reanchored = false;
        self.cx.deadline = Some(deadline);
        let then = Then::Periodic { deadline, period };
        let outcome = self.section_with_plan(state, Section::Periodic, Some(then));
        self.cx.deadline = None;
        self.periodic_done(state, deadline, period, outcome);
    }

    /// After the periodic section of `state` due at `deadline` (of a `period`) and its
    /// plan's `outcome`: schedule the next one, adapt, choose.
    pub(super) fn periodic_done(
        &mut self,
        state: usize,
        deadline: Instant,
        period: Duration,
        outcome: Recovery,
    ) {
        let mut missed_any = false;
        match outcome {
            Recovery::Recovered => {}
            // Retried later: the next deadline is scheduled once the retries are over
            // (those they took are missed), as on a thread of its own.
            Recovery::Later => return,
            Recovery::Goto(target) => self.pending_choice = Some(target),
            Recovery::Failed(message) => {
                self.fail(message);
                return;
            }
        }
        if self.state != State::Running || self.user != state {
            return;
        }
        if !self.reanchored {
            // Absolute deadlines: the next one is a period after this one, not after now
            // (the clock as the section's call ended).
            let now = self.clock;
            let mut next = later(deadline, period);
            if next <= now {
                let late = now.duration_since(next).as_nanos();
                let missed = u64::try_from(late / period.as_nanos().max(1))
                    .unwrap_or(u64::MAX)
                    .saturating_add(1);
                missed_any = true;
                self.shared.update(|monitor| {
                    monitor.missed_deadlines = monitor.missed_deadlines.saturating_add(missed);
                    vec![MonitorEvent::MissedDeadline {
                        missed,
                        total: monitor.missed_deadlines,
                    }]
                });
                next = self.deadline_after(now, period);
            }
            self.next_periodic = Some(next);
        }
        if self.adapt.as_ref().is_some_and(|adapt| adapt.enabled) {
            self.observe(self.last_took, period, missed_any);
            self.equalize(deadline, period, !self.reanchored && !missed_any);
        }
        if self.pending_choice.is_none() {
            self.choose(state);
        }
    }

    /// Equalization (`crate::equalize`): feed the seat this periodic section (when
    /// `on_time`: a period that missed its deadline or was re-anchored says nothing of
    /// its phase); when it says so, delay the next deadline once and publish an
    /// `Equalized` step.
    pub(super) fn equalize(&mut self, deadline: Instant, period: Duration, on_time: bool) {
        let Some(adapt) = self.adapt.as_mut() else {
            return;
        };
        if !adapt.equalize || !self.time.is_real() {
            return; // (Phases on a virtual clock say nothing about the processor.)
        }
        // CPU time and waits since the previous periodic section ended.
        let stats = adapt
            .stats
            .get_or_insert_with(ThreadStats::of_current_thread);
        let Some((cpu, waited)) = stats.since_last() else {
            return;
        };
        if !on_time {
            return;
        }
        // Without the OS's figure: the elapsed time the thread did not spend on a CPU
        // while its section ran.
        let waited = waited.unwrap_or_else(|| self.last_took.saturating_sub(cpu));
        let name = &self.cx.name;
        let seat = adapt
            .seat
            .get_or_insert_with(|| Board::process().seat(name, EqualizeConfig::default()));
        let Some(shift) = seat.observe(Activation {
            deadline,
            cpu,
            waited,
            period,
        }) else {
            return;
        };
        let level = adapt.level;
        if let Some(next) = self.next_periodic.as_mut() {
            *next = later(*next, shift.delay);
        }
        let step = Adaptation {
            component: self.cx.name.to_string(),
            action: AdaptAction::Equalized,
            from: level,
            to: level,
            period: self.cx.period,
            quality: Some(self.cx.quality),
            detail: format!(
                "phase moved {:?} later: its sections coincided with {}'s",
                shift.delay,
                shift.away_from.join("'s, ")
            ),
        };
        self.shared.adaptation_step(step, true, |_| {});
    }

    /// Re-anchor the periodic deadline on the current period, from now.
    pub(super) fn reanchor(&mut self) {
        // (While a periodic section waits for its retry, the next deadline is set when
        // the retries are over, with the period then.)
        let retrying_periodic = self
            .retrying
            .as_ref()
            .is_some_and(|retrying| matches!(retrying.then, Then::Periodic { .. }));
        if self.user_entered && self.state == State::Running && !retrying_periodic {
            self.next_periodic = self
                .period_of(self.user)
                .map(|period| self.deadline_after(self.time.now(), period));
            self.reanchored = true;
        }
    }

    /// Ask the user's `choose` for a `may` target.
    pub(super) fn choose(&mut self, state: usize) {
        let may = self.spec.states[state].may;
        if may.is_empty() || self.state != State::Running || self.user != state {
            return;
        }
        match self.call(|automaton, cx| automaton.choose(state, cx)) {
            Ok(None) => {}
            Ok(Some(target)) if may.contains(&target) => self.pending_choice = Some(target),
            Ok(Some(target)) => self.fail(format!(
                "choose in state `{}` returned #{target}, not one of its `may` targets",
                self.spec.states[state].name
            )),
            Err(panic) => self.fail(format!(
                "panic in choose of state `{}`: {panic}",
                self.spec.states[state].name
            )),
        }
    }

    /// Answer waiting pull requests; true if there were any.
    pub(super) fn serve_pulls(&mut self) -> bool {
        let mut served = false;
        for index in 0..self.outputs.len() {
            let output = Arc::clone(&self.outputs[index]);
            let answers = self.spec.outputs.get(index).is_some_and(|spec| spec.pull);
            while let Some(requester) = output.next_request() {
                served = true;
                if !answers {
                    continue; // Not a pull output: the request is dropped.
                }
                output.begin_answer(requester);
                let result = self.call(|automaton, cx| automaton.answer(index, cx));
                output.end_answer();
                let failure = match result {
                    Ok(Ok(())) => continue,
                    Ok(Err(fault)) => Failure::Fault(fault),
                    Err(panic) => Failure::Panic(panic),
                };
                match self.recover(self.user, None, failure, None) {
                    // (`Later` is a section's only: this is no section.)
                    Recovery::Recovered | Recovery::Later => {}
                    Recovery::Goto(target) => {
                        self.pending_choice = Some(target);
                        return true;
                    }
                    Recovery::Failed(message) => {
                        self.fail(format!(
                            "answering a pull request on `{}`: {message}",
                            self.spec.outputs[index].name
                        ));
                        return true;
                    }
                }
            }
        }
        served
    }
}
