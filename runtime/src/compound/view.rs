//! What a supervisor's rules read: the [`View`] of the instances' monitors, the
//! mapped variables, the supervisor's own variables and the compound's own defaults;
//! and a rule itself (a state, a test over the view, a target, what it reads).

use std::collections::HashMap;
use std::time::Duration;

use crate::monitor::Monitor;
use crate::monitor::TaskResult;
use crate::table::State;
use crate::value::Value;

/// The variables rules read: every instance's monitor (its `state`, `user_state`,
/// `result`, `error` and variables) and the supervisor's own variables.
#[derive(Debug, Clone, Default)]
pub struct View {
    pub(super) instances: Vec<Monitor>,
    /// Each instance's position in `instances`, by name: a rule's lookup costs one
    /// hash, not a scan of every instance.
    pub(super) positions: HashMap<String, usize>,
    pub(super) own: Vec<(String, Value)>,
    /// The compound's mapped variables: name -> (declared instance, its variable).
    pub(super) mapped: HashMap<String, (usize, String)>,
    /// The instance standing for each instance now (itself, its substitute, or its
    /// redundant group's live member).
    pub(super) standing: Vec<usize>,
    /// The compound's own default observable variables, as last seen.
    pub(super) compound: Own,
}

/// The compound's own default observable variables that rules read (`result`,
/// `error`, `quality`, `cpu_time`, `elapsed_time`), copied from its monitoring port
/// at each supervision turn of a compound whose rules read them.
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct Own {
    pub(super) result: TaskResult,
    pub(super) error: Option<String>,
    pub(super) quality: usize,
    pub(super) cpu_time: Duration,
    pub(super) elapsed_time: Duration,
}

/// The read keys of the compound's own default variables (`CompoundBuilder::rule`).
pub(super) const OWN_DEFAULTS: [&str; 5] =
    ["result", "error", "quality", "cpu_time", "elapsed_time"];

/// Whether read key `read` names a time (`cpu_time`, `elapsed_time`, own or an
/// instance's), which changes without an event: such rules are evaluated every
/// supervisor period.
pub(super) fn is_timed(read: &str) -> bool {
    let field = read.rsplit_once('.').map_or(read, |(_, field)| field);
    matches!(field, "cpu_time" | "elapsed_time")
}

impl View {
    /// The monitor of instance `instance`, as last seen.
    pub fn monitor(&self, instance: &str) -> Option<&Monitor> {
        self.positions
            .get(instance)
            .and_then(|index| self.instances.get(*index))
    }

    /// `instance.state`.
    pub fn state(&self, instance: &str) -> Option<State> {
        self.monitor(instance).map(|m| m.state)
    }

    /// `instance.user_state`.
    pub fn user_state(&self, instance: &str) -> Option<&str> {
        self.monitor(instance).and_then(|m| m.user_state.as_deref())
    }

    /// `instance.result`.
    pub fn result(&self, instance: &str) -> Option<&TaskResult> {
        self.monitor(instance).map(|m| &m.result)
    }

    /// `instance.error`.
    pub fn error(&self, instance: &str) -> Option<&str> {
        self.monitor(instance).and_then(|m| m.error.as_deref())
    }

    /// A user variable of an instance.
    pub fn var(&self, instance: &str, variable: &str) -> Option<&Value> {
        self.monitor(instance)?
            .variables
            .iter()
            .find(|(name, _)| name == variable)
            .map(|(_, value)| value)
    }

    /// A mapped variable of the compound (`observable odometry = motion.odometry;`),
    /// read from the instance standing for the declared one now: the instance itself,
    /// its substitute while the substitute stands in, or its redundant group's live
    /// member. `None` if `name` is not a mapped variable. A rule reading it lists
    /// `name` in its `reads`: it is evaluated when the variable changes at the
    /// instance standing in, and when another instance starts standing in.
    pub fn mapped(&self, name: &str) -> Option<&Value> {
        let (declared, variable) = self.mapped.get(name)?;
        let standing = self.standing.get(*declared).copied().unwrap_or(*declared);
        self.instances
            .get(standing)?
            .variables
            .iter()
            .find(|(name, _)| name == variable)
            .map(|(_, value)| value)
    }

    /// The compound's own `result` (what its supervisor's sections set with
    /// [`Context::set_result`](crate::Context::set_result)), as of the current supervision turn.
    pub fn own_result(&self) -> &TaskResult {
        &self.compound.result
    }

    /// The compound's own `error`: its last error, kept until a restart succeeds.
    pub fn own_error(&self) -> Option<&str> {
        self.compound.error.as_deref()
    }

    /// The compound's own `quality` level (0 = best).
    pub fn own_quality(&self) -> usize {
        self.compound.quality
    }

    /// The compound's own `cpu_time` (its thread's CPU time).
    pub fn own_cpu_time(&self) -> Duration {
        self.compound.cpu_time
    }

    /// The compound's own `elapsed_time` (wall-clock time in its supervisor's code).
    pub fn own_elapsed_time(&self) -> Duration {
        self.compound.elapsed_time
    }

    /// One of the supervisor's own variables.
    pub fn own(&self, variable: &str) -> Option<&Value> {
        self.own
            .iter()
            .find(|(name, _)| name == variable)
            .map(|(_, value)| value)
    }
}

pub(super) type Test = Box<dyn Fn(&View) -> bool + Send>;

/// One rule: in supervisor state `state`, when `test` holds, go to `target`.
pub(super) struct Rule {
    pub(super) state: usize,
    pub(super) target: usize,
    /// The ids of the keys it reads ([`Reads`](super::reads::Reads)), ascending.
    pub(super) reads: Vec<usize>,
    pub(super) test: Test,
}
