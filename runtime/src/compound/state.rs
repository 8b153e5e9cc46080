//! The compound automaton's state: the inner [`System`] of instances, the compound's
//! record of each instance (its policy, its place in the arrangement), the supervisor,
//! its rules and view, and the supervision steps taken; with the few helpers every
//! part of the compound uses (a step, a fault, a refreshed monitor).

use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use crossbeam_channel::Receiver;

use crate::automaton::Fault;
use crate::clock::Clock;
use crate::commander::Commander;
use crate::handle::{Handle, Posted};
use crate::monitor::{Command, MonitorEvent, Step, Supervision};
use crate::port::ErasedInput;
use crate::spec::Spec;
use crate::system::System;
use crate::table::Controllable;

use super::coordinator::Coordinator;
use super::error::{PolicyFault, RunError};
use super::exports::Export;
use super::links::{Link, MergedPort};
use super::policy::{Budget, PendingRestart, Policy, Recovering};
use super::reads::{Changed, Reads};
use super::supervisor::Supervisor;
use super::view::{Rule, View};

/// Where an instance stands in the compound's arrangement.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Status {
    /// Part of the arrangement: runs when the compound runs.
    Active,
    /// A declared substitute not in use: started (`ready`), not running.
    Standby,
    /// In the recovery queue.
    Recovering,
    /// Its recovery deadline expired: commanded to `dead`.
    Destroyed,
}

pub(super) struct Instance {
    pub(super) name: String,
    pub(super) spec: &'static Spec,
    /// Its quality levels: its component's, or its `timing` override's.
    pub(super) levels: usize,
    pub(super) handle: Handle,
    pub(super) policy: Policy,
    /// The instance this one substitutes.
    pub(super) substitutes: Option<usize>,
    /// This instance's substitute.
    pub(super) substitute: Option<usize>,
    /// Its redundant group.
    pub(super) group: Option<usize>,
    pub(super) status: Status,
    /// When the `restart` policy last restarted it (within the budget's window).
    pub(super) restarts: std::collections::VecDeque<Instant>,
    /// A restart decided but not done yet (backoff, or the instance is stuck).
    pub(super) pending: Option<PendingRestart>,
    /// Its current fault was handled (its policy ran): cleared when it leaves
    /// `running_error`/`starting_error`, or is commanded back to `running`. Later
    /// events of the same fault (a watchdog trip, then the section's return) are not
    /// a new fault.
    pub(super) handled: bool,
    /// The packets a compound's exported input had left it out of when it last
    /// joined its redundant group (its start, or its recovery): more since then puts
    /// it out of step (`in_step`).
    pub(super) left_at_join: u64,
    /// The recovery queue's command to run again, posted and not answered yet.
    pub(super) retry: Option<Posted>,
}

impl Instance {
    /// Whether its policy handles its failing to start (at the compound's start)
    /// without failing the compound, as it handles a later fault: `substitute` (its
    /// substitute stands in), `ignore`, or a member of a redundant group. Under
    /// `propagate`, or `restart` (nothing restarts from `starting_error`), and for a
    /// substitute, the compound cannot start.
    pub(super) fn handles_start_failure(&self) -> bool {
        self.substitutes.is_none()
            && (self.group.is_some()
                || self.policy == Policy::Ignore
                || (self.policy == Policy::Substitute && self.substitute.is_some()))
    }
}

/// A variable of the compound mapped onto an instance's.
pub(super) struct Mapped {
    pub(super) instance: usize,
    pub(super) variable: String,
}

/// The code of a compound component, driven by the runner like any automaton.
pub(super) struct Compound {
    pub(super) name: String,
    pub(super) spec: &'static Spec,
    /// Index of the first own variable in `spec.variables` (mapped ones come first).
    pub(super) own_offset: usize,
    pub(super) system: Option<System>,
    pub(super) instances: Vec<Instance>,
    pub(super) groups: Vec<Vec<usize>>,
    /// Each redundant group's leader (its merged streams carry its packets): changes
    /// only when the leader fails.
    pub(super) leaders: Vec<usize>,
    /// The merged data outputs of redundant groups, made at the first wiring.
    pub(super) merges: Vec<MergedPort>,
    /// The consumers linked to a merged output: `(merge, declared link, input
    /// address, input)`.
    pub(super) merged: Vec<(usize, usize, String, ErasedInput)>,
    /// The connections made to redundant members' inputs (every live member).
    pub(super) fanned: Vec<(String, String)>,
    /// Declared connections.
    pub(super) links: Vec<Link>,
    /// The connections made now (declared ones with each instance routed to whoever
    /// stands for it, with their converters).
    /// The connection made for each declared link (`links`, same order), between the
    /// instances standing for its ends; `None` where none is (not made yet, or the
    /// same ends as an earlier link's).
    pub(super) wired: Vec<Option<Link>>,
    pub(super) mapped: Vec<Mapped>,
    pub(super) supervisor: Box<dyn Supervisor>,
    pub(super) rules: Vec<Rule>,
    /// Monitoring events of each instance (subscribed at the first start), with a
    /// flag its publisher sets before ringing the compound: a turn looks only at the
    /// instances that have news.
    pub(super) events: Vec<(Receiver<MonitorEvent>, Arc<AtomicBool>)>,
    /// What the rules read (`inst.field`, a mapped or own variable, an own default),
    /// resolved to ids.
    pub(super) reads: Reads,
    /// The read keys that changed in the current supervision turn.
    pub(super) changed: Changed,
    pub(super) view: View,
    /// The supervisor state whose rules were last evaluated.
    pub(super) evaluated_in: Option<usize>,
    /// The supervisor entered a state (by a rule, `after`, `on`, ...): the thread takes
    /// one more turn at once to evaluate the new state's rules (nothing else may wake
    /// it).
    pub(super) fresh: bool,
    /// A supervisor section ran since the last turn: it may have changed variables the
    /// runtime cannot see (`local` ones, or any state of a hand-written supervisor), so
    /// the next turn, taken at once, evaluates every rule of the current state.
    pub(super) sectioned: bool,
    pub(super) queue: Vec<Recovering>,
    pub(super) retry_every: Duration,
    pub(super) deadline: Duration,
    pub(super) budget: Budget,
    pub(super) started: bool,
    pub(super) exports: Vec<Box<dyn Export>>,
    /// Supervision steps taken since the last call returned (published by the runner).
    pub(super) steps: Vec<Supervision>,
    /// Another instance started standing for one with mapped variables: rules reading
    /// them are evaluated on the next turn.
    pub(super) restood: bool,
    /// Adaptation (paper 3.6): `None` when turned off.
    pub(super) coordinator: Option<Coordinator>,
    /// What the supervisor's sections command the instances with.
    pub(super) commander: Commander,
    /// Some rule reads the compound's own `result`, `error`, `quality`, `cpu_time`
    /// or `elapsed_time`: each turn copies them into the view.
    pub(super) reads_own: bool,
    /// An active instance failed while the compound was suspended: its policy runs
    /// on the compound's next running turn.
    pub(super) deferred_faults: bool,
    /// When the time reads are next due.
    pub(super) next_timed: Option<Instant>,
    /// Stand-in moves `(from, to)` whose waiting pull requests have not followed yet
    /// (they follow once a rewiring completes).
    pub(super) moves: Vec<(usize, usize)>,
    /// The clock its timers read (the runner's: a virtual one in tests), which its
    /// instances run on too.
    pub(super) clock: Clock,
    /// On a virtual clock, how its thread waits in the clock's time (for the answer
    /// to a recovery retry): set at each supervision turn.
    pub(super) clock_wait: Option<crate::clock::ClockWait>,
    /// Shutting down: when its instances' `dead` and the joins of their threads are
    /// given up on (`COMPOUND_STOP_TIMEOUT` after the compound's `stop` began).
    pub(super) stop_by: Option<Instant>,
}

pub(super) fn command(handle: &Handle, target: Controllable) -> Result<(), Fault> {
    handle
        .command(Command::SetState(target))
        .map_err(|rejected| RunError::from(rejected).into())
}

impl Compound {
    /// Record a supervision step about instance `index` for the monitoring port.
    pub(super) fn step(&mut self, index: usize, step: Step, detail: impl Into<String>) {
        let supervision = Supervision {
            instance: self.instances[index].name.clone(),
            step,
            detail: detail.into(),
        };
        if supervision.step.is_routine() {
            tracing::debug!(compound = %self.name, "{supervision}");
        } else {
            tracing::info!(compound = %self.name, "{supervision}");
        }
        self.steps.push(supervision);
    }

    /// A fault raised while handling instance `index` (a rewiring or a command that
    /// failed after a step was recorded): recorded as `Propagated` with the reason,
    /// unless the last step recorded is that fault's `Propagated` already.
    pub(super) fn propagated(&mut self, index: usize, fault: Fault) -> Fault {
        let recorded = self
            .steps
            .last()
            .is_some_and(|last| last.step == Step::Propagated);
        if !recorded {
            self.step(index, Step::Propagated, fault.text().to_owned());
        }
        fault
    }

    pub(super) fn fault(&self, why: PolicyFault) -> Fault {
        crate::limited!(
            &self.name,
            |held| tracing::warn!(compound = %self.name, "{why}{held}")
        );
        RunError::from(why).into()
    }

    /// Bring the view's monitor of instance `index` up to date, in place.
    pub(super) fn refresh(&mut self, index: usize) {
        self.instances[index]
            .handle
            .shared
            .snapshot_into(&mut self.view.instances[index]);
    }
}
