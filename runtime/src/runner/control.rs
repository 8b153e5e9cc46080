//! The control port: commands, priority, quality.

use super::*;

impl Runner {
    // -----------------------------------------------------------------------------
    // Control port.

    pub(super) fn handle_control(&mut self, message: ControlMessage) {
        if !message.take() {
            return; // Withdrawn by a sender that gave up waiting.
        }
        let reply = |answer: Reply| message.answer(answer);
        // Out of range, whoever sends it and whatever stands behind this component
        // (a proxy's remote instance checks again on its own node).
        if let Err(refused) = crate::ranges::command(&message.command) {
            return reply(Reply::Rejected(refused.to_string()));
        }
        // A remote instance's proxy answers some commands itself (`crate::remote`);
        // only supervised automata (compounds, proxies) have anything to say.
        if self.supervised {
            match self.automaton.forward(&message.command) {
                None => {}
                Some(Ok(())) => return reply(Reply::Done),
                Some(Err(error)) => return reply(Reply::Rejected(Chain(&*error).to_string())),
            }
        }
        match &*message.command {
            Command::SetState(target) => match next(self.state, Event::Command(*target)) {
                Outcome::Go { .. } => {
                    reply(Reply::Accepted);
                    let answers = message.reply.mailbox();
                    let notice = message.notice.as_ref().map(|notice| notice.0.clone());
                    self.cx.transition_waiter = Some(TransitionWaiter(
                        Box::new(move || {
                            let _ = answers.post(Reply::TakingClockTime);
                        }),
                        notice,
                    ));
                    self.apply(Event::Command(*target));
                    self.cx.transition_waiter = None;
                    reply(Reply::Done);
                }
                Outcome::Stay => reply(Reply::Done),
                Outcome::Reject(reason) => reply(Reply::Rejected(reason.to_owned())),
                // The loop never reads commands while `start` runs, so this is not
                // reached; answering keeps the sender from waiting anyway.
                Outcome::Defer | Outcome::Impossible => reply(Reply::Rejected(format!(
                    "not applicable in state {}",
                    self.state
                ))),
            },
            Command::Configure(configuration) => {
                let configuration = configuration.clone();
                match self.call(|automaton, _| automaton.configure(&configuration)) {
                    Ok(Ok(())) => {
                        self.shared.publish(MonitorEvent::Configured);
                        reply(Reply::Done);
                    }
                    Ok(Err(refused)) => reply(Reply::Rejected(format!(
                        "invalid configuration: {}",
                        excerpt(&Chain(&refused).to_string(), REASON_CHARS)
                    ))),
                    Err(panic) => reply(Reply::Rejected(format!(
                        "panic in configure: {}",
                        excerpt(&panic, REASON_CHARS)
                    ))),
                }
            }
            Command::Set(name, value) => match self.spec.variable_index(name) {
                None => {
                    // What can be set, and what else the name may be meant for.
                    let settable: Vec<&str> = self
                        .spec
                        .variables
                        .iter()
                        .filter(|variable| variable.kind == VarKind::Controllable)
                        .map(|variable| variable.name)
                        .collect();
                    /// How many of them the reason names.
                    const NAMED: usize = 8;
                    let has = match settable.len() {
                        0 => "it has no controllable variable".to_owned(),
                        n if n <= NAMED => {
                            format!("its controllable variables: {}", settable.join(", "))
                        }
                        n => format!(
                            "its controllable variables: {} and {} more",
                            settable[..NAMED].join(", "),
                            n - NAMED
                        ),
                    };
                    reply(Reply::Rejected(format!(
                        "no variable `{}` ({has}; a configuration field is changed with \
                         `configure`)",
                        excerpt(name, EXCERPT_CHARS)
                    )))
                }
                Some(index) if self.spec.variables[index].kind != VarKind::Controllable => reply(
                    Reply::Rejected(format!("`{name}` is observable, not controllable")),
                ),
                // Outside its declared range: refused, whoever asks (a supervisor,
                // coolctl, a remote compound), before the component sees it.
                Some(index)
                    if self.spec.variables[index]
                        .range
                        .is_some_and(|range| range.check(value).is_err()) =>
                {
                    let outside = self.spec.variables[index]
                        .range
                        .map(|range| range.check(value));
                    reply(Reply::Rejected(match outside {
                        Some(Err(outside)) => format!("invalid value for `{name}`: {outside}"),
                        _ => format!("invalid value for `{name}`"),
                    }))
                }
                Some(index) => {
                    let value = value.clone();
                    match self.call(|automaton, _| automaton.set(index, &value)) {
                        Ok(Ok(())) => reply(Reply::Done),
                        Ok(Err(refused)) => reply(Reply::Rejected(format!(
                            "invalid value for `{name}`: {}",
                            excerpt(&Chain(&refused).to_string(), REASON_CHARS)
                        ))),
                        Err(panic) => reply(Reply::Rejected(format!(
                            "panic in set: {}",
                            excerpt(&panic, REASON_CHARS)
                        ))),
                    }
                }
            },
            // (In range: checked above.)
            Command::SetPeriod(period) => {
                self.cx.set_period(*period);
                self.after_call();
                reply(Reply::Done);
            }
            Command::SetMaxResponse(bound) => {
                self.max_response = Some(*bound);
                match &self.watch {
                    Some(watch) => watch.set_limit(Some(*bound)),
                    None => {
                        self.watch = Some(Watch::new(
                            self.spec,
                            Arc::clone(&self.shared),
                            Some(*bound),
                            &self.time,
                        ));
                    }
                }
                let bound = *bound;
                self.shared.update(|monitor| {
                    if monitor.max_response == Some(bound) {
                        return Vec::new();
                    }
                    monitor.max_response = Some(bound);
                    vec![MonitorEvent::MaxResponse(Some(bound))]
                });
                reply(Reply::Done);
            }
            Command::SetPriority(priority) => {
                let priority = *priority;
                self.shared.update(|monitor| {
                    if monitor.priority == priority {
                        return Vec::new();
                    }
                    monitor.priority = priority;
                    vec![MonitorEvent::Priority(priority)]
                });
                self.apply_priority(priority);
                reply(Reply::Done);
            }
            Command::SetQuality(quality) => {
                let levels = self.timing.qualities.len().max(1);
                if *quality >= levels {
                    reply(Reply::Rejected(format!(
                        "quality {quality} out of range: {levels} level(s)"
                    )));
                } else {
                    self.quality_by_other_means(*quality, "quality set through the control port");
                    reply(Reply::Done);
                }
            }
            Command::SetDegradation(level) => {
                let level = *level;
                if self.supervised {
                    match self.call(|automaton, cx| automaton.set_degradation(level, cx)) {
                        Ok(Ok(())) => reply(Reply::Done),
                        Ok(Err(refused)) => reply(Reply::Rejected(refused.to_string())),
                        Err(panic) => reply(Reply::Rejected(format!(
                            "panic in set_degradation: {panic}"
                        ))),
                    }
                } else {
                    // An instance whose compound manages its level, commanded by
                    // someone else (an operator): the level is set by other means, as
                    // a period or quality is, and its supervisor keeps it (neither
                    // clamps it nor promotes below it) until the same means move it.
                    let pinned = !message.by_supervisor
                        && self
                            .shared
                            .adapt_managed
                            .load(std::sync::atomic::Ordering::Acquire);
                    match self.adapt.as_ref().map(|adapt| adapt.ladder.max_level()) {
                        None | Some(0) => reply(Reply::Rejected(
                            "no adaptation levels: the timing block has no period interval and fewer than two quality levels".to_owned(),
                        )),
                        Some(max) if level > max => reply(Reply::Rejected(
                            DegradationRefused::OutOfRange { level, max }.to_string(),
                        )),
                        Some(_) if pinned => {
                            self.pin_level(level);
                            reply(Reply::Done);
                        }
                        Some(_) if level < self.floor_level() => reply(Reply::Rejected(format!(
                            "degradation level {level} is below {}, where the period and quality set by other means stand (SetPeriod and SetQuality move them)",
                            self.floor_level()
                        ))),
                        // (A level its supervisor commands is logged by the
                        // supervisor's own step.)
                        Some(_) if message.by_supervisor => {
                            self.set_level(level, "commanded by its supervisor", false);
                            reply(Reply::Done);
                        }
                        Some(_) => {
                            self.set_level(level, "commanded through the control port", true);
                            reply(Reply::Done);
                        }
                    }
                }
            }
        }
    }

    /// Apply `priority` to this thread and publish what holds (an event and a log line
    /// when it changed; a refusal never fails the component).
    pub(super) fn apply_priority(&mut self, priority: i32) {
        if let Some(membership) = &self.group {
            // An execution group's thread runs at the highest priority its members ask
            // for; what holds is published on every member's monitor.
            membership.shared.apply_priority(membership.index, priority);
            return;
        }
        let Some(scheduling) = self.scheduling.as_mut() else {
            return;
        };
        let applied = scheduling.apply(priority);
        match &applied {
            OsPriority::Inherited => {}
            OsPriority::NotApplied(why) => crate::limited!(&self.cx.name, |held| tracing::warn!(
                component = %self.cx.name,
                "priority {priority} not applied to the thread: {why}{held}"
            )),
            how => {
                tracing::info!(component = %self.cx.name, "priority {priority} applied: {how:?}")
            }
        }
        self.shared.update(|monitor| {
            if monitor.os_priority == applied {
                return Vec::new();
            }
            monitor.os_priority = applied.clone();
            vec![MonitorEvent::OsPriority(applied)]
        });
    }

    /// A quality set by a command or a `degrade` plan step: the adaptation level and
    /// floor follow it (before the `Quality` event, which then shows them).
    pub(super) fn quality_by_other_means(&mut self, quality: usize, why: &str) {
        self.cx.quality = quality;
        self.resync_level(why, Pin::Quality);
        self.set_quality(quality);
    }

    pub(super) fn set_quality(&mut self, quality: usize) {
        self.cx.quality = quality;
        self.shared.update(|monitor| {
            monitor.quality = quality;
            vec![MonitorEvent::Quality(quality)]
        });
    }
}
