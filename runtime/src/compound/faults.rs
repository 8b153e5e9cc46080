//! What a compound does when an instance fails: the policies (propagate, restart,
//! substitute, ignore), the `restart` policy's budget and backoff, and the recovery
//! queue (retries, recoveries, retirement at the deadline).

use std::time::{Duration, Instant};

use crate::automaton::Fault;
use crate::monitor::{Command, Step};

/// How long a recovery retry waits for the instance's answer before the compound's
/// thread goes on (the answer is looked at again at the next retry). On a virtual
/// clock it waits until the clock moves instead, in the clock's time: an instance
/// that restarts at the clock's time answers at that time, whatever real time it
/// takes.
const RETRY_LOOK: Duration = Duration::from_millis(10);
use crate::table::{Controllable, State};

use super::error::{PolicyFault, RunError};
use super::in_step::takeover;
use super::policy::{PendingRestart, Policy, Recovering};
use super::state::{Compound, Status, command};

impl Compound {
    pub(super) fn enqueue(&mut self, index: usize) {
        let now = self.clock.now();
        self.instances[index].status = Status::Recovering;
        self.queue.push(Recovering {
            instance: index,
            since: now,
            next: crate::time::later(now, self.retry_every),
            probation: false,
        });
    }

    /// Whether the arrangement can go on without instance `index`.
    pub(super) fn covered(&self, index: usize) -> bool {
        let instance = &self.instances[index];
        if let Some(group) = instance.group {
            return self.groups[group]
                .iter()
                .any(|m| self.instances[*m].status == Status::Active && !self.failing(*m));
        }
        instance
            .substitute
            .is_some_and(|s| self.instances[s].status == Status::Active)
    }

    /// Instance `index` went to `running_error` (or `starting_error`): its policy.
    pub(super) fn failed(&mut self, index: usize) -> Result<(), Fault> {
        let monitor = self.view.instances[index].clone();
        let name = self.instances[index].name.clone();
        let error = monitor.error.clone().unwrap_or_default();
        self.step(index, Step::Failed, error.clone());
        if let Some(group) = self.instances[index].group {
            // A redundant member: its inputs are disconnected; if it led the group,
            // the next live member leads (the merged streams go on from its backlog).
            let leader = self.leaders[group] == index;
            self.enqueue(index);
            self.step(index, Step::Enqueued, "");
            // Members left out of packets are out of step: they cannot lead.
            self.keep_in_step();
            if !self.covered(index) {
                self.step(
                    index,
                    Step::Propagated,
                    "no member of its redundant group is left in step",
                );
                return Err(self.fault(PolicyFault::GroupLost {
                    instance: name,
                    error,
                }));
            }
            let standing = self.groups[group]
                .iter()
                .copied()
                .find(|m| self.can_lead(*m));
            if leader && let Some(member) = standing {
                let by = self.instances[member].name.clone();
                let (replayed, missing) = self.lead(group, member);
                self.rewire()
                    .map_err(|fault| self.propagated(index, fault))?;
                if missing > 0 {
                    crate::limited!(
                        &self.name,
                        |held| tracing::warn!(compound = %self.name, "{missing} packet(s) missing from the stream of `{by}`'s group{held}")
                    );
                }
                self.step(index, Step::Substituted { by }, takeover(replayed, missing));
            } else {
                self.rewire()
                    .map_err(|fault| self.propagated(index, fault))?;
            }
            return Ok(());
        }
        let policy = if self.instances[index].substitutes.is_some() {
            // A substitute in use fails: nothing stands for it.
            Policy::Propagate
        } else {
            self.instances[index].policy
        };
        match policy {
            Policy::Ignore => {
                self.step(index, Step::Ignored, "");
                Ok(())
            }
            Policy::Propagate => {
                self.step(index, Step::Propagated, "");
                Err(self.fault(PolicyFault::Failed {
                    instance: name,
                    error,
                }))
            }
            Policy::Restart if monitor.state == State::RunningError => {
                self.schedule_restart(index, &error)
            }
            Policy::Restart => {
                self.step(
                    index,
                    Step::Propagated,
                    "it cannot restart from starting_error",
                );
                Err(self.fault(PolicyFault::CannotRestart {
                    instance: name,
                    error,
                }))
            }
            Policy::Substitute => {
                self.enqueue(index);
                self.step(index, Step::Enqueued, "");
                if let Some(substitute) = self.instances[index].substitute
                    && self.instances[substitute].status == Status::Standby
                {
                    self.instances[substitute].status = Status::Active;
                    self.instances[substitute].handled = false;
                    self.rewire()
                        .and_then(|()| {
                            command(&self.instances[substitute].handle, Controllable::Running)
                        })
                        .map_err(|fault| self.propagated(index, fault))?;
                    let by = self.instances[substitute].name.clone();
                    self.step(index, Step::Substituted { by }, "");
                }
                Ok(())
            }
        }
    }

    /// The `restart` policy for instance `index`, which failed with `error`: a restart
    /// now or after the backoff, or the fault propagates once the budget is spent.
    pub(super) fn schedule_restart(&mut self, index: usize, error: &str) -> Result<(), Fault> {
        let now = self.clock.now();
        let budget = self.budget;
        let instance = &mut self.instances[index];
        if instance.pending.is_some() {
            return Ok(()); // Already decided (another event of the same fault).
        }
        while instance
            .restarts
            .front()
            .is_some_and(|t| now.saturating_duration_since(*t) >= budget.window)
        {
            instance.restarts.pop_front();
        }
        let done = instance.restarts.len();
        if u32::try_from(done).unwrap_or(u32::MAX) >= budget.restarts {
            let name = instance.name.clone();
            self.step(
                index,
                Step::Propagated,
                format!(
                    "restart budget spent: {done} restart(s) within {:?}",
                    budget.window
                ),
            );
            return Err(self.fault(PolicyFault::BudgetSpent {
                instance: name,
                restarts: done,
                window: budget.window,
                error: error.to_owned(),
            }));
        }
        instance.pending = Some(PendingRestart {
            since: now,
            due: crate::time::later(now, budget.delay(done)),
        });
        self.restarts_due(now)
    }

    /// Do the decided restarts that are due; propagate a stuck instance's fault once
    /// it has been stuck for the recovery deadline.
    pub(super) fn restarts_due(&mut self, now: Instant) -> Result<(), Fault> {
        for index in 0..self.instances.len() {
            let Some(pending) = self.instances[index].pending else {
                continue;
            };
            let instance = &self.instances[index];
            if instance.handle.is_stuck() {
                if now >= crate::time::later(pending.since, self.deadline) {
                    let name = instance.name.clone();
                    self.instances[index].pending = None;
                    self.step(
                        index,
                        Step::Propagated,
                        "stuck in a section that overran its max_response",
                    );
                    return Err(self.fault(PolicyFault::Stuck {
                        instance: name,
                        deadline: self.deadline,
                    }));
                }
                continue;
            }
            if now < pending.due {
                continue;
            }
            let instance = &mut self.instances[index];
            instance.pending = None;
            if instance.handle.state() != State::RunningError {
                continue; // Someone else brought it back meanwhile.
            }
            instance.restarts.push_back(now);
            let handle = instance.handle.clone();
            let waited = now.saturating_duration_since(pending.since);
            let detail = if waited.is_zero() {
                String::new()
            } else {
                format!("after {waited:?}")
            };
            self.step(index, Step::Restarted, detail);
            command(&handle, Controllable::Running)
                .map_err(|fault| self.propagated(index, fault))?;
            self.instances[index].handled = false;
        }
        Ok(())
    }

    /// The recovery queue's due work: restart, recognize recoveries, destroy at the
    /// deadline.
    pub(super) fn recover(&mut self, now: Instant) -> Result<(), Fault> {
        let mut position = 0;
        while position < self.queue.len() {
            let entry = self.queue[position];
            if now < entry.next && now < crate::time::later(entry.since, self.deadline) {
                position += 1;
                continue;
            }
            let index = entry.instance;
            let state = self.instances[index].handle.state();
            if entry.probation && state == State::Running {
                // Recovered: the arrangement before the fault comes back (a redundant
                // member joins its group again, not leading it: its merged lanes count
                // on from the streams' numbers).
                self.queue.remove(position);
                self.instances[index].status = Status::Active;
                // Its view shows it running now (its events may not have been taken
                // yet): a failed member does not cover nor lead its group.
                self.refresh(index);
                if let Some(group) = self.instances[index].group {
                    let lane = self.groups[group].iter().position(|m| *m == index);
                    for merged in self.merges.iter().filter(|m| m.group == group) {
                        merged.merge.rejoin(lane.unwrap_or(0));
                    }
                    self.joined(index);
                }
                let rewired = if let Some(substitute) = self.instances[index].substitute
                    && self.instances[substitute].status == Status::Active
                {
                    self.instances[substitute].status = Status::Standby;
                    self.rewire().and_then(|()| {
                        command(&self.instances[substitute].handle, Controllable::Ready)
                    })
                } else {
                    self.rewire()
                };
                rewired.map_err(|fault| self.propagated(index, fault))?;
                self.step(index, Step::Recovered, "");
                continue;
            }
            if now >= crate::time::later(entry.since, self.deadline) {
                self.queue.remove(position);
                let name = self.instances[index].name.clone();
                self.instances[index].status = Status::Destroyed;
                // A retry not taken yet never runs it again; one under way (a slow
                // `start`) is followed by `dead`.
                if let Some(retry) = self.instances[index].retry.take() {
                    retry.withdraw();
                }
                let moves = self.update_standing();
                self.moves.extend(moves);
                // Sent without waiting: its thread takes it as soon as it can (after a
                // section or a restart under way), whenever that is, and the
                // compound's thread goes on.
                let handle = &self.instances[index].handle;
                if let Err(rejected) = handle.post(Command::SetState(Controllable::Dead)) {
                    tracing::warn!(compound = %self.name, "{rejected}");
                }
                // What is still queued at its inputs will never be read: lost there,
                // counted and announced (on its monitoring port).
                let lost = self
                    .system
                    .as_ref()
                    .map_or(0, |system| system.discard_queued(&name));
                self.refresh(index);
                let mut detail = format!("not recovered within {:?}", self.deadline);
                if lost > 0 {
                    detail.push_str(&format!("; {lost} packet(s) left at its inputs lost"));
                }
                self.step(index, Step::Retired, detail);
                if !self.covered(index) {
                    self.step(index, Step::Propagated, "nothing stands for it");
                    return Err(self.fault(PolicyFault::NotRecovered {
                        instance: name,
                        deadline: self.deadline,
                    }));
                }
                continue;
            }
            // Due for a retry: restart it, on probation until the next retry (not while
            // it is stuck in an overrun section: a command would wait for it). The
            // command is posted, and its answer looked at for a moment only: an
            // instance busy in a section answers at a later retry, while the
            // compound's thread goes on passing packets. Every attempt is a step, so
            // an operator sees recovery being tried.
            let attempt = if self.instances[index].handle.is_stuck() {
                Some(Err(
                    "still stuck in a section past its max_response".to_owned()
                ))
            } else {
                self.retry_command(index)
            };
            let Some(attempt) = attempt else {
                // Not answered yet: looked at again at the next retry.
                let entry = &mut self.queue[position];
                entry.next = crate::time::later(now, self.retry_every);
                position += 1;
                continue;
            };
            let restarted = attempt.is_ok();
            match attempt {
                Ok(()) => {
                    self.instances[index].handled = false;
                    self.step(index, Step::Retried, "");
                }
                Err(why) => self.step(index, Step::RetryFailed, why),
            }
            let entry = &mut self.queue[position];
            entry.probation = restarted;
            entry.next = crate::time::later(now, self.retry_every);
            position += 1;
        }
        Ok(())
    }

    /// The recovery queue's command to instance `index` to run again: posted if none
    /// is on its way, then its answer looked at for `RETRY_LOOK` at most. `None`
    /// while unanswered; else whether the instance is `running` now, or why not.
    fn retry_command(&mut self, index: usize) -> Option<Result<(), String>> {
        let instance = &mut self.instances[index];
        let mut posted = match instance.retry.take() {
            Some(posted) => posted,
            None => match instance.handle.post_on_clock(
                Command::SetState(Controllable::Running),
                self.clock_wait.as_ref(),
            ) {
                Ok(posted) => posted,
                Err(rejected) => {
                    return Some(Err(Fault::from(RunError::from(rejected)).text().to_owned()));
                }
            },
        };
        let Some(answer) = instance.handle.poll(&mut posted, RETRY_LOOK) else {
            instance.retry = Some(posted);
            return None;
        };
        Some(match answer {
            Err(rejected) => Err(Fault::from(RunError::from(rejected)).text().to_owned()),
            Ok(()) => match instance.handle.state() {
                State::Running => Ok(()),
                state => Err(format!("{state} after the restart")),
            },
        })
    }
}
