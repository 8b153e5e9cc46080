//! Why a command is refused ([`Refused`]): by a supervisor's commander before it is
//! sent, by the control port's ranges, or by the instance itself.

use std::time::Duration;

/// Why a command was refused: the reason of a supervisor's
/// [`CommandError`](crate::CommandError), and of a control port's range check
/// (`crate::ranges`).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum Refused {
    /// The compound has no instance of that name.
    #[error("the compound has no such instance")]
    UnknownInstance,
    /// The compound has not started its instances yet.
    #[error("the instances have not been started")]
    NotStarted,
    /// The instance is dead: its thread has ended (a `dead` command, or retired by the
    /// recovery queue).
    #[error("the instance is dead: its thread has ended")]
    Dead,
    /// The instance is inside a section that overran its `max_response`: it takes no
    /// command until the section returns.
    #[error("the instance is stuck in a section that overran its max_response")]
    Stuck,
    /// The instance did not take the command within the commander's timeout (a section
    /// still running); the command was withdrawn and has no effect.
    #[error(
        "the instance did not take the command within {waited:?} (busy in a section); withdrawn"
    )]
    Busy {
        /// How long the command waited.
        waited: Duration,
    },
    /// The instance's control queue is full.
    #[error("the instance's control queue is full")]
    QueueFull,
    /// The instance has no variable of that name.
    #[error("the instance has no variable `{0}`")]
    UnknownVariable(String),
    /// The variable is observable, not controllable.
    #[error("`{0}` is observable, not controllable")]
    NotControllable(String),
    /// The instance refused the value (its reason).
    #[error("the value was refused: {0}")]
    InvalidValue(String),
    /// The instance refused the configuration (its reason).
    #[error("the configuration was refused: {0}")]
    InvalidConfiguration(String),
    /// A zero period.
    #[error("a period must be positive")]
    ZeroPeriod,
    /// A period outside the range a command may set ([`crate::ranges`]).
    #[error("period {period:?} out of range: from {min:?} to {max:?}")]
    PeriodOutOfRange {
        /// The period asked for.
        period: Duration,
        /// The shortest allowed.
        min: Duration,
        /// The longest allowed.
        max: Duration,
    },
    /// A zero `max_response`.
    #[error("a max_response must be positive")]
    ZeroMaxResponse,
    /// A `max_response` outside the range a command may set ([`crate::ranges`]).
    #[error("max_response {max_response:?} out of range: from {min:?} to {max:?}")]
    MaxResponseOutOfRange {
        /// The bound asked for.
        max_response: Duration,
        /// The shortest allowed.
        min: Duration,
        /// The longest allowed.
        max: Duration,
    },
    /// A priority outside the range a command may set ([`crate::ranges`]).
    #[error("priority {priority} out of range: from {min} to {max}")]
    PriorityOutOfRange {
        /// The priority asked for.
        priority: i32,
        /// The lowest allowed.
        min: i32,
        /// The highest allowed.
        max: i32,
    },
    /// A real-time priority (positive) in a process that does not allow them
    /// ([`crate::ranges::realtime_priorities_allowed`]).
    #[error(
        "priority {priority} is a real-time priority, which this process does not allow \
         (COOLBOT_REALTIME_PRIORITIES=1 allows them)"
    )]
    RealtimePriority {
        /// The priority asked for.
        priority: i32,
    },
    /// A quality level the instance does not have.
    #[error("quality level {level} out of range: the instance has {levels} level(s)")]
    QualityOutOfRange {
        /// The level asked for.
        level: usize,
        /// How many levels the instance has.
        levels: usize,
    },
    /// The compound is shutting down (its way to `dead`: its supervisor's exit
    /// section and `stop`): no instance is brought to `running` then.
    #[error("the compound is shutting down: no instance is brought to running")]
    ShuttingDown,
    /// The instance rejected the command for another reason (its words).
    #[error("{0}")]
    Rejected(String),
}
