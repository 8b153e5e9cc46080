//! Why a compound could not be built ([`CompoundError`]), and why a running compound
//! fails (`RunError`, `ExportError`): each keeps its source; a running compound's
//! error becomes its fault ([`Fault`](crate::Fault)'s `From` keeps the whole chain as
//! the compound's `error` text).

use std::time::Duration;

use crate::monitor::{Rejected, Timeout};
use crate::remote::NetworkError;
use crate::spec::SpecError;
use crate::system::{ConnectError, Error as SystemError};
use crate::table::State;

/// Why a compound could not be built.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CompoundError {
    /// The supervisor has no state.
    #[error("compound `{compound}`: the supervisor has no state")]
    NoSupervisorState {
        /// The compound.
        compound: String,
    },
    /// The supervisor's spec is inconsistent.
    #[error("compound `{compound}`: supervisor")]
    Supervisor {
        /// The compound.
        compound: String,
        /// What is wrong.
        #[source]
        source: SpecError,
    },
    /// An instance could not be added (duplicate name, bad spec, ports), or instances
    /// could not share a thread (an execution group).
    #[error("compound `{compound}`")]
    Instance {
        /// The compound.
        compound: String,
        /// The inner system's refusal.
        #[source]
        source: Box<SystemError>,
    },
    /// An instance declared `on "node"` could not be placed there.
    #[error("compound `{compound}`: instance `{instance}` cannot be placed on node `{node}`")]
    Placement {
        /// The compound.
        compound: String,
        /// The instance.
        instance: String,
        /// The node.
        node: String,
        /// Why: the network layer's error (`crate::remote::Placer`).
        #[source]
        source: NetworkError,
    },
    /// A name that does not resolve.
    #[error("compound `{compound}`: {what} `{name}` does not exist")]
    Unknown {
        /// The compound.
        compound: String,
        /// What kind of thing (`instance`, `state`, `variable`, ...).
        what: &'static str,
        /// The name.
        name: String,
    },
    /// A connection breaks the connection rules.
    #[error("compound `{compound}`")]
    Connect {
        /// The compound.
        compound: String,
        /// The connection's refusal.
        #[source]
        source: Box<ConnectError>,
    },
    /// An export names no port of the instance, or one of another kind or packet
    /// type than the export asks for.
    #[error(
        "compound `{compound}`: cannot export `{target}`: no such {direction}, or not a {kinds} {direction}{packets}"
    )]
    Export {
        /// The compound.
        compound: String,
        /// The instance port (`instance.port`).
        target: String,
        /// `input` or `output`.
        direction: &'static str,
        /// The kinds the export takes (`fifo, ufifo, last, poster`, ...).
        kinds: &'static str,
        /// The packet type asked for (` of `T``), empty for ticks.
        packets: String,
    },
    /// A substitution or redundancy whose members differ in interface, or that
    /// overlaps another.
    #[error("compound `{compound}`: {detail}")]
    Arrangement {
        /// The compound.
        compound: String,
        /// What is wrong.
        detail: String,
    },
}

/// Why a running compound fails at (re)wiring or (re)starting its instances.
#[derive(Debug, thiserror::Error)]
pub(super) enum RunError {
    /// Its inner system refused a connection while wiring the arrangement.
    #[error("compound `{compound}`")]
    Wiring {
        compound: String,
        #[source]
        source: ConnectError,
    },
    /// Its instances' threads could not be started.
    #[error("compound `{compound}`")]
    Start {
        compound: String,
        #[source]
        source: SystemError,
    },
    /// An exported port could not follow the instance port it stands for.
    #[error("compound `{compound}`: `{target}`")]
    Export {
        compound: String,
        target: String,
        #[source]
        source: ExportError,
    },
    /// A consumer does not match a redundant group's merged output.
    #[error("compound `{compound}`: the merged output of `{port}` does not match `{to}`")]
    MergedConsumer {
        compound: String,
        port: String,
        to: String,
    },
    /// A redundant member's output does not match its group's.
    #[error("compound `{compound}`: `{output}` does not match its group's")]
    MergedMember { compound: String, output: String },
    /// An instance stuck in an overrun section cannot be restarted with the compound.
    #[error(
        "instance `{instance}` cannot restart: it is stuck in a section that overran its max_response"
    )]
    Stuck { instance: String },
    /// An instance did not leave `starting` in time.
    #[error(transparent)]
    StartTimeout(#[from] Timeout),
    /// An instance went to `starting_error`.
    #[error("instance `{instance}` could not start: {error}")]
    CouldNotStart { instance: String, error: String },
    /// An instance did not come back to `ready` for the compound's restart.
    #[error("instance `{instance}` could not restart: it is {state}")]
    CouldNotRestart { instance: String, state: State },
    /// An instance rejected a command of the compound's own (its policies, its
    /// state following the compound's).
    #[error(transparent)]
    Command(#[from] Rejected),
    /// A fault policy gave up on an instance.
    #[error(transparent)]
    Policy(#[from] PolicyFault),
}

/// Why a compound's fault policy gives up on an instance, so that the compound fails
/// (the instance's own error is its text, as its monitoring port published it).
#[derive(Debug, thiserror::Error)]
pub(super) enum PolicyFault {
    /// No member of a redundant group is left live and in step.
    #[error(
        "every member of the redundant group of `{instance}` failed or is out of step; last: {error}"
    )]
    GroupLost { instance: String, error: String },
    /// Its policy is `propagate` (or it is a substitute in use).
    #[error("instance `{instance}` failed: {error}")]
    Failed { instance: String, error: String },
    /// `restart` cannot restart from `starting_error`.
    #[error("instance `{instance}` failed to restart: {error}")]
    CannotRestart { instance: String, error: String },
    /// The `restart` policy's budget is spent.
    #[error(
        "instance `{instance}` failed again after {restarts} restart(s) within {window:?} (restart budget spent): {error}"
    )]
    BudgetSpent {
        instance: String,
        restarts: usize,
        window: Duration,
        error: String,
    },
    /// A restart is due but the instance is stuck in an overrun section.
    #[error(
        "instance `{instance}` cannot be restarted: it is stuck in a section that overran its max_response, for over {deadline:?}"
    )]
    Stuck {
        instance: String,
        deadline: Duration,
    },
    /// The recovery deadline expired and nothing stands for the instance.
    #[error("instance `{instance}` did not recover within {deadline:?} and nothing stands for it")]
    NotRecovered {
        instance: String,
        deadline: Duration,
    },
}

/// Why an exported port could not follow an instance port.
#[derive(Debug, thiserror::Error)]
pub(super) enum ExportError {
    /// An exported output was asked to follow inputs.
    #[error("not an exported input")]
    NotAnInput,
    /// An exported input was asked to follow an output.
    #[error("not an exported output")]
    NotAnOutput,
    /// The instance port is not of the exported port's kind and packet type.
    #[error("the exported {0} does not match the instance's")]
    Mismatch(&'static str),
    /// The instance port could not be found.
    #[error(transparent)]
    Port(#[from] ConnectError),
}
