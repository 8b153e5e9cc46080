//! User calls: `catch_unwind`, timing, publication, continuity plans.

use super::*;

impl Runner {
    // -----------------------------------------------------------------------------
    // User calls.

    /// Run one user call under `catch_unwind`, account its time, publish its changes.
    pub(super) fn call<R>(
        &mut self,
        body: impl FnOnce(&mut dyn Driven, &mut Context) -> R,
    ) -> Result<R, String> {
        self.call_watched(None, body)
            .map_err(|failure| match failure {
                Failure::Panic(message) | Failure::Overrun(message) => message,
                Failure::Fault(fault) => fault.text().to_owned(),
            })
    }

    /// [`Runner::call`] for the section `watched` (state, section): the max_response
    /// watchdog watches it, and a section that overran (tripped by the watchdog, or
    /// returning late) fails with [`Failure::Overrun`], its outcome discarded.
    pub(super) fn call_watched<R>(
        &mut self,
        watched: Option<(usize, Section)>,
        body: impl FnOnce(&mut dyn Driven, &mut Context) -> R,
    ) -> Result<R, Failure> {
        // Without a watchdog (no max_response), the call starts from the turn's clock
        // reading (taken at most a few hundred nanoseconds of runner work ago, or at
        // the end of the previous call): one clock read per call saved on the
        // per-packet path. The watchdog gets a reading of its own.
        let started = if self.watch.is_some() {
            self.time.now()
        } else {
            self.clock
        };
        if let (Some((state, section)), Some(watch)) = (watched, &self.watch) {
            watch.begin(started, state, section);
        }
        let automaton = &mut *self.automaton;
        let cx = &mut self.cx;
        cx.in_section = watched.is_some();
        let result = catch_unwind(AssertUnwindSafe(|| body(automaton, cx)));
        self.cx.in_section = false;
        let tripped = watched.is_some() && self.watch.as_ref().is_some_and(|watch| watch.end());
        self.clock = self.time.now();
        let took = self.clock.saturating_duration_since(started);
        self.last_took = took;
        // Elapsed time is accumulated here and published before the thread waits
        // (`update_cpu_from`), off the per-call path.
        self.elapsed = self.elapsed.saturating_add(crate::time::nanos(took));
        let bound = self.max_response.filter(|bound| tripped || took > *bound);
        if bound.is_some() && !tripped {
            // (A tripped call was counted by the watchdog.)
            self.shared.update(|monitor| {
                monitor.overruns += 1;
                vec![MonitorEvent::Overrun {
                    took,
                    total: monitor.overruns,
                }]
            });
        }
        if let (Some((state, section)), Some(bound)) = (watched, bound) {
            self.discard_requests();
            self.after_call();
            return Err(Failure::Overrun(format!(
                "overrun in state `{}` ({section:?} section): {} {took:?}, max_response {bound:?}; its outcome was discarded",
                self.spec.states[state].name,
                if tripped { "returned after" } else { "ran" },
            )));
        }
        self.after_call();
        result.map_err(|payload| Failure::Panic(panic_message(payload.as_ref())))
    }

    /// Forget what an overrun section asked of the runtime (`end`, a result, a period):
    /// the published values stay.
    pub(super) fn discard_requests(&mut self) {
        self.cx.end_requested = false;
        if self.cx.result_changed || self.cx.period_changed {
            let monitor = self.shared.snapshot();
            if self.cx.result_changed {
                self.cx.result_changed = false;
                self.cx.result = monitor.result;
            }
            if self.cx.period_changed {
                self.cx.period_changed = false;
                self.cx.period = monitor.period;
            }
        }
    }

    /// Publish what the last call changed in the context and the variables.
    pub(super) fn after_call(&mut self) {
        if !self.cx.supervision.is_empty() {
            let steps = std::mem::take(&mut self.cx.supervision);
            self.shared.update(|monitor| {
                monitor.supervision_steps += steps.len() as u64;
                monitor.supervision.extend(steps.iter().cloned());
                let excess = monitor
                    .supervision
                    .len()
                    .saturating_sub(crate::monitor::SUPERVISION_HISTORY);
                monitor.supervision.drain(..excess);
                steps.into_iter().map(MonitorEvent::Supervision).collect()
            });
        }
        if self.cx.result_changed {
            self.cx.result_changed = false;
            let result = self.cx.result.clone();
            self.shared.update(|monitor| {
                monitor.result = result.clone();
                vec![MonitorEvent::Result(result)]
            });
        }
        if self.cx.period_changed {
            self.cx.period_changed = false;
            let period = self.cx.period;
            self.reanchor();
            // The level first: the `Period` event then shows where it stands.
            self.resync_level(
                "period set through the control port or by the component",
                Pin::Period,
            );
            self.shared.update(|monitor| {
                monitor.period = period;
                vec![MonitorEvent::Period(period)]
            });
        }
        self.publish_variables();
    }

    /// Publish the variables the automaton reports as changed
    /// ([`Automaton::changed_variables`](crate::Automaton::changed_variables)) whose
    /// values differ from the published ones, one event each, in index order. A
    /// panicking report keeps what it reported before the panic, and a panicking
    /// `get` leaves its variable unpublished.
    pub(super) fn publish_variables(&mut self) {
        if self.spec.variables.is_empty() {
            return;
        }
        let mut reported = std::mem::take(&mut self.reported);
        reported.clear();
        let automaton = &mut *self.automaton;
        let _ = catch_unwind(AssertUnwindSafe(|| {
            automaton.changed_variables(&mut crate::automaton::Changes {
                reported: &mut reported,
            })
        }));
        if reported.is_empty() {
            self.reported = reported;
            return;
        }
        let automaton = &*self.automaton;
        for (index, value) in &mut reported {
            if value.is_none() {
                *value = catch_unwind(AssertUnwindSafe(|| automaton.get(*index))).ok();
            }
        }
        if !reported.is_sorted_by_key(|(index, _)| *index) {
            reported.sort_by_key(|(index, _)| *index);
        }
        let spec = self.spec;
        self.shared.update(|monitor| {
            let mut events = Vec::new();
            for (index, value) in reported.drain(..) {
                let (Some(value), Some(slot)) = (value, monitor.variables.get_mut(index)) else {
                    continue;
                };
                if slot.1 != value {
                    slot.1 = value.clone();
                    events.push(MonitorEvent::Variable {
                        name: spec.variables[index].name.to_owned(),
                        value,
                    });
                }
            }
            events
        });
        self.reported = reported;
    }

    /// Publish the elapsed time (if it changed) and the thread's CPU time (a system
    /// call: at most once per `CPU_TIME_REFRESH` unless `force`).
    pub(super) fn update_cpu(&mut self, force: bool) {
        self.update_cpu_from(force, &mut thread_cpu_time);
    }

    /// Publish the elapsed time (if it changed) and no CPU time: a harness runs the
    /// component on the test's thread, whose CPU time is not the component's.
    pub(crate) fn publish_elapsed(&mut self) {
        self.update_cpu_from(false, &mut || None);
    }

    /// [`Runner::update_cpu`], with the thread's CPU time read by `read_cpu` (an
    /// execution group reads it once for all its members).
    pub(super) fn update_cpu_from(
        &mut self,
        force: bool,
        read_cpu: &mut dyn FnMut() -> Option<Duration>,
    ) {
        if self.mirrors_times {
            return;
        }
        let refresh_cpu = force || self.clock >= self.cpu_due;
        let cpu = if refresh_cpu {
            self.cpu_due = self.time.now() + CPU_TIME_REFRESH;
            read_cpu()
        } else {
            None
        };
        if cpu.is_none() && self.elapsed == self.elapsed_published {
            return;
        }
        let delta = self.elapsed.saturating_sub(self.elapsed_published);
        self.elapsed_published = self.elapsed;
        let elapsed = self.elapsed;
        // In an execution group the thread's CPU time is shared out among the members
        // in proportion to the time spent in their calls.
        let cpu = match &self.group {
            None => cpu,
            Some(membership) => {
                let total = membership.shared.add_elapsed(delta);
                cpu.map(|cpu| {
                    if total == 0 {
                        Duration::ZERO
                    } else {
                        cpu.mul_f64((elapsed as f64 / total as f64).min(1.0))
                    }
                })
            }
        };
        self.shared.set_elapsed(elapsed);
        let clock = self.clock;
        let load = self.adapt.as_mut().map(|adapt| {
            if let Some(cpu) = cpu {
                adapt.profile(cpu, clock);
            }
            (adapt.detector.load(), adapt.cpu_share)
        });
        if cpu.is_none() && load.is_none() {
            return;
        }
        self.shared.quietly(|monitor| {
            if let Some((load, cpu_share)) = load {
                monitor.adaptation.load = load;
                monitor.adaptation.cpu_share = cpu_share;
            }
            if let Some(cpu) = cpu {
                monitor.cpu_time = cpu;
            }
        });
    }

    pub(super) fn run_start(&mut self) -> Result<(), String> {
        // A ranged variable starts inside its range, however its value was given (an
        // instance's override, the variables a component was built with).
        for (index, variable) in self.spec.variables.iter().enumerate() {
            let Some(range) = variable.range else {
                continue;
            };
            let automaton = &*self.automaton;
            let Ok(value) = catch_unwind(AssertUnwindSafe(|| automaton.get(index))) else {
                continue;
            };
            if let Err(outside @ crate::OutOfRange::Outside { .. }) = range.check(&value) {
                return Err(format!(
                    "the initial value of `{}`: {outside}",
                    variable.name
                ));
            }
        }
        match self.call(|automaton, cx| automaton.start(cx)) {
            Ok(Ok(())) => {
                self.set_error(None);
                Ok(())
            }
            Ok(Err(fault)) => Err(format!("start failed: {fault}")),
            Err(panic) => Err(format!("panic in start: {panic}")),
        }
    }

    pub(super) fn run_stop(&mut self) {
        if let Err(panic) = self.call(|automaton, cx| automaton.stop(cx)) {
            self.set_error(Some(format!("panic in stop: {panic}")));
        }
    }

    pub(super) fn run_section(&mut self, state: usize, section: Section) -> Result<(), Failure> {
        match self.call_watched(Some((state, section)), |automaton, cx| {
            automaton.section(state, section, cx)
        }) {
            Ok(Ok(())) => Ok(()),
            Ok(Err(fault)) => Err(Failure::Fault(fault)),
            Err(failure) => Err(failure),
        }
    }

    /// Run a section and its continuity plan if it fails. With `then` (what the
    /// section is part of), a `retry` runs it again later, as a timer
    /// ([`Recovery::Later`]); without (a command's transition, whose reply waits for
    /// it), a retry waits on the thread.
    pub(super) fn section_with_plan(
        &mut self,
        state: usize,
        section: Section,
        then: Option<Then>,
    ) -> Recovery {
        match self.run_section(state, section) {
            Ok(()) => Recovery::Recovered,
            Err(failure) => self.recover(state, Some(section), failure, then),
        }
    }

    /// Run the continuity plan for a failure in `state` (paper 3.5); `then` as for
    /// [`Runner::section_with_plan`].
    pub(super) fn recover(
        &mut self,
        state: usize,
        section: Option<Section>,
        failure: Failure,
        then: Option<Then>,
    ) -> Recovery {
        let place = match (self.spec.states.get(state), section) {
            (Some(spec), Some(section)) => format!("state `{}` ({section:?} section)", spec.name),
            (Some(spec), None) => format!("state `{}`", spec.name),
            // No user automaton (a component that only answers pulls): no state to name.
            (None, _) => "`running`".to_owned(),
        };
        let fault = match failure {
            Failure::Panic(message) => {
                return Recovery::Failed(format!("panic in {place}: {message}"));
            }
            // No continuity plan for an overrun: its outcome is discarded.
            Failure::Overrun(message) => return Recovery::Failed(message),
            Failure::Fault(fault) => fault,
        };
        let Some(index) = fault
            .exception_index()
            .filter(|index| *index < self.spec.exceptions.len())
        else {
            return Recovery::Failed(format!("fault in {place}: {}", fault.text()));
        };
        let exception = &self.spec.exceptions[index];
        let message = fault.text().to_owned();
        if let Err(panic) = self.call(|automaton, cx| automaton.exception(index, &message, cx)) {
            return Recovery::Failed(format!(
                "panic in the handler of exception `{}`: {panic}",
                exception.name
            ));
        }
        self.follow_plan(state, section, (index, 0), then, &place, &message)
    }

    /// Follow the continuity plan of exception `index` from its step `from` (`plan`),
    /// for a failure in `section` of `state` (at `place`, saying `message`; `then` as
    /// for [`Runner::section_with_plan`]).
    fn follow_plan(
        &mut self,
        state: usize,
        section: Option<Section>,
        (index, from): (usize, usize),
        then: Option<Then>,
        place: &str,
        message: &str,
    ) -> Recovery {
        let exception = &self.spec.exceptions[index];
        for (at, step) in exception.plan.iter().enumerate().skip(from) {
            match *step {
                PlanStep::Ignore => {
                    crate::limited!(
                        (&self.cx.name, exception.name),
                        |held| tracing::warn!(component = %self.cx.name, "exception `{}` in {place} ignored: {message}{held}", exception.name)
                    );
                    return Recovery::Recovered;
                }
                PlanStep::Goto(target) if target < self.spec.states.len() => {
                    return Recovery::Goto(target);
                }
                PlanStep::Goto(_) => {}
                PlanStep::Degrade => {
                    if self.cx.quality + 1 < self.timing.qualities.len() {
                        let quality = self.cx.quality + 1;
                        self.quality_by_other_means(quality, "a `degrade` continuity plan step");
                        return Recovery::Recovered;
                    }
                }
                PlanStep::Retry { count, every } => {
                    let Some(section) = section else { continue };
                    if count == 0 {
                        continue;
                    }
                    // The section is run again when due, a timer: commands are
                    // handled meanwhile (in an execution group, the other members
                    // run).
                    if let Some(then) = then {
                        self.retrying = Some(Retrying {
                            state,
                            exception: index,
                            step: at,
                            left: count,
                            every,
                            due: later(self.clock, every),
                            then,
                            arrived: None,
                            place: place.to_owned(),
                            message: message.to_owned(),
                        });
                        return Recovery::Later;
                    }
                    for _ in 0..count {
                        match self.time.as_virtual().filter(|_| self.harnessed) {
                            // A harness's clock is the component's own: the retry
                            // waits on it, not in real time.
                            Some(clock) => {
                                let _ = clock.advance_with_timeout(every, Duration::ZERO);
                            }
                            None => std::thread::sleep(every),
                        }
                        self.clock = self.time.now();
                        match self.run_section(state, section) {
                            Ok(()) => return Recovery::Recovered,
                            Err(failure) => {
                                if let Some(failed) = beyond_plan(failure, place) {
                                    return failed;
                                }
                            }
                        }
                    }
                }
            }
        }
        Recovery::Failed(format!(
            "exception `{}` in {place}: {message}",
            exception.name
        ))
    }

    /// The retry that is due ([`Retrying`]): run the section again; if it fails, the
    /// next retry is due `every` later, or, none left, the rest of the plan follows;
    /// then what the section is part of goes on ([`Then`]). True: it ran.
    pub(super) fn retry_due(&mut self) -> bool {
        let Some(retrying) = self.retrying.take() else {
            return false;
        };
        let (state, then, arrived) = (retrying.state, retrying.then, retrying.arrived);
        let section = then.section();
        if let Then::Periodic { deadline, .. } = then {
            self.cx.deadline = Some(deadline);
        }
        let attempt = self.run_section(state, section);
        self.cx.deadline = None;
        let outcome = if attempt.is_ok() {
            Recovery::Recovered
        } else if let Some(failed) = attempt.err().and_then(|f| beyond_plan(f, &retrying.place)) {
            failed
        } else if retrying.left > 1 {
            self.retrying = Some(Retrying {
                left: retrying.left - 1,
                due: later(self.clock, retrying.every),
                ..retrying
            });
            return true;
        } else {
            self.follow_plan(
                state,
                Some(section),
                (retrying.exception, retrying.step + 1),
                Some(then),
                &retrying.place,
                &retrying.message,
            )
        };
        match (then, outcome) {
            // Another `retry` step of the plan.
            (_, Recovery::Later) => {}
            (Then::Periodic { deadline, period }, outcome) => {
                // (The period now, if it was set meanwhile: a suspended component's
                // new period is not applied until it runs.)
                let period = self.period_of(state).unwrap_or(period);
                self.periodic_done(state, deadline, period, outcome);
            }
            (Then::Entered, outcome) => self.entered(state, outcome),
            (Then::Enter { target }, outcome) => self.exited(target, self.clock, outcome),
        }
        self.respond_when_done(arrived);
        true
    }

    /// The transition an input's arrival `arrived` caused is over unless a section of
    /// it waits for a retry: measure the response time now, or when that retry's
    /// transition is over.
    pub(super) fn respond_when_done(&mut self, arrived: Option<Instant>) {
        let Some(arrived) = arrived else { return };
        match self.retrying.as_mut() {
            Some(retrying) if matches!(retrying.then, Then::Entered | Then::Enter { .. }) => {
                retrying.arrived = Some(arrived);
            }
            _ => self.responded(arrived),
        }
    }

    /// A failure no plan recovered: `running_error`.
    pub(super) fn fail(&mut self, message: String) {
        self.set_error(Some(message));
        self.apply(Event::Fault);
    }
}

/// A retried attempt that panicked or overran: no continuity plan goes on for it
/// (`Runner::recover`), the component fails. `None` for a fault, which the plan's
/// retries are for.
fn beyond_plan(failure: Failure, place: &str) -> Option<Recovery> {
    match failure {
        Failure::Fault(_) => None,
        Failure::Panic(message) => Some(Recovery::Failed(format!("panic in {place}: {message}"))),
        Failure::Overrun(message) => Some(Recovery::Failed(message)),
    }
}

/// The calling thread's CPU time (a system call); `None` where it cannot be read.
pub(super) fn thread_cpu_time() -> Option<Duration> {
    cpu_time::ThreadTime::try_now()
        .ok()
        .map(|time| time.as_duration())
}
