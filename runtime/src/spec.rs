//! The static shape of a component, as `coolc` emits it (`pub static SPEC: coolbot::Spec`).
//!
//! Every type here is const-constructible: only `&'static` slices and strings,
//! [`Duration`], [`Option`], integers and booleans. Indices are positions in the
//! corresponding slices (a state id is an index into [`Spec::states`], an input port id
//! an index into [`Spec::inputs`], and so on), in declaration order.

use std::time::Duration;

/// The static description of one component type.
#[derive(Debug, Clone, Copy)]
pub struct Spec {
    /// The component type's name, as written in the `.cool` file.
    pub type_name: &'static str,
    /// The `///` documentation of the component.
    pub doc: &'static str,
    /// The user automaton (index = user state id).
    pub states: &'static [StateSpec],
    /// Index of the initial user state.
    pub initial: usize,
    /// Input ports, in declaration order (index = input port id).
    pub inputs: &'static [InputSpec],
    /// Output ports, in declaration order (index = output port id).
    pub outputs: &'static [OutputSpec],
    /// Observable and controllable user variables (index = variable id).
    pub variables: &'static [VarSpec],
    /// Declared exceptions (index = exception id).
    pub exceptions: &'static [ExceptionSpec],
    /// The `timing` block.
    pub timing: TimingSpec,
}

/// A hand-written spec is built in a `static` from [`Spec::new`] and the `with_`
/// methods, each a `const fn`, so that it says only what the component has:
///
/// ```
/// use coolbot::{InputKind, InputSpec, OutputKind, OutputSpec, Spec, StateSpec};
///
/// static RELAY: Spec = Spec::new("Relay", "passes every packet on")
///     .with_states(&[StateSpec::new("work").with_entry()])
///     .with_inputs(&[InputSpec::new("input", InputKind::Last, "Reading")])
///     .with_outputs(&[OutputSpec::new("output", OutputKind::Data, "Reading")]);
/// assert!(RELAY.validate().is_ok());
/// ```
impl Spec {
    /// A component type with nothing but its name and documentation: no user states
    /// (only the default automaton), ports, variables or exceptions, and no timing.
    pub const fn new(type_name: &'static str, doc: &'static str) -> Spec {
        Spec {
            type_name,
            doc,
            states: &[],
            initial: 0,
            inputs: &[],
            outputs: &[],
            variables: &[],
            exceptions: &[],
            timing: TimingSpec::NONE,
        }
    }

    /// With these user states; the first is the initial one (see
    /// [`Spec::with_initial`]).
    pub const fn with_states(mut self, states: &'static [StateSpec]) -> Spec {
        self.states = states;
        self
    }

    /// With user state `initial` as the initial one.
    pub const fn with_initial(mut self, initial: usize) -> Spec {
        self.initial = initial;
        self
    }

    /// With these input ports.
    pub const fn with_inputs(mut self, inputs: &'static [InputSpec]) -> Spec {
        self.inputs = inputs;
        self
    }

    /// With these output ports.
    pub const fn with_outputs(mut self, outputs: &'static [OutputSpec]) -> Spec {
        self.outputs = outputs;
        self
    }

    /// With these observable and controllable variables.
    pub const fn with_variables(mut self, variables: &'static [VarSpec]) -> Spec {
        self.variables = variables;
        self
    }

    /// With these exceptions.
    pub const fn with_exceptions(mut self, exceptions: &'static [ExceptionSpec]) -> Spec {
        self.exceptions = exceptions;
        self
    }

    /// With this `timing` block.
    pub const fn with_timing(mut self, timing: TimingSpec) -> Spec {
        self.timing = timing;
        self
    }

    /// The index of the user state called `name`.
    pub fn state_index(&self, name: &str) -> Option<usize> {
        self.states.iter().position(|state| state.name == name)
    }

    /// The index of the input port called `name`.
    pub fn input_index(&self, name: &str) -> Option<usize> {
        self.inputs.iter().position(|input| input.name == name)
    }

    /// The index of the output port called `name`.
    pub fn output_index(&self, name: &str) -> Option<usize> {
        self.outputs.iter().position(|output| output.name == name)
    }

    /// The index of the variable called `name`.
    pub fn variable_index(&self, name: &str) -> Option<usize> {
        self.variables
            .iter()
            .position(|variable| variable.name == name)
    }

    /// Check that every index in the spec points at something that exists and that
    /// every periodic section has a period. `System::add` refuses a spec that fails.
    pub fn validate(&self) -> Result<(), SpecError> {
        self.validate_with(&self.timing)
    }

    /// [`Spec::validate`] with an instance's own timing block in place of the spec's
    /// (see `Component::with_timing`): a periodic section may take its period from it.
    pub fn validate_with(&self, timing: &TimingSpec) -> Result<(), SpecError> {
        let states = self.states.len();
        // No state: a component without a user automaton (it serves pulls in
        // `running`); its `initial` is then 0.
        if self.initial >= states.max(1) {
            return Err(SpecError::Initial {
                initial: self.initial,
                states,
            });
        }
        for state in self.states {
            let name = state.name;
            for on in state.on {
                if on.port >= self.inputs.len() {
                    return Err(SpecError::OnPort {
                        state: name,
                        port: on.port,
                    });
                }
                if on.target >= states {
                    return Err(SpecError::OnTarget {
                        state: name,
                        target: on.target,
                    });
                }
            }
            for after in state.after {
                if after.target >= states {
                    return Err(SpecError::AfterTarget {
                        state: name,
                        target: after.target,
                    });
                }
                if after.without.is_some_and(|port| port >= self.inputs.len()) {
                    return Err(SpecError::AfterWithout { state: name });
                }
            }
            if let Some(&target) = state.may.iter().find(|target| **target >= states) {
                return Err(SpecError::MayTarget {
                    state: name,
                    target,
                });
            }
            if let Some(periodic) = state.periodic {
                match periodic.period.or(timing.period) {
                    None => return Err(SpecError::NoPeriod { state: name }),
                    Some(period) if period.is_zero() => {
                        return Err(SpecError::ZeroPeriod { state: name });
                    }
                    Some(_) => {}
                }
            }
        }
        for exception in self.exceptions {
            for step in exception.plan {
                if let PlanStep::Goto(target) = step
                    && *target >= states
                {
                    return Err(SpecError::GotoTarget {
                        exception: exception.name,
                        target: *target,
                    });
                }
            }
        }
        for input in self.inputs {
            match input.kind {
                InputKind::Fifo { capacity: 0, .. } => {
                    return Err(SpecError::FifoCapacity { input: input.name });
                }
                InputKind::Ufifo { initial: 0, .. } => {
                    return Err(SpecError::UfifoInitial { input: input.name });
                }
                _ => {}
            }
        }
        Ok(())
    }
}

/// What is wrong with a [`Spec`] ([`Spec::validate`]): an index that points at nothing,
/// or a setting no component can run with (a bug in the generator or in a
/// hand-written spec).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SpecError {
    /// The initial state does not exist.
    #[error("initial state #{initial} does not exist ({states} states)")]
    Initial {
        /// The initial state's index.
        initial: usize,
        /// How many states the spec has.
        states: usize,
    },
    /// An `on` names an input that does not exist.
    #[error("state `{state}`: `on` names input #{port}, which does not exist")]
    OnPort {
        /// The state.
        state: &'static str,
        /// The input's index.
        port: usize,
    },
    /// An `on` targets a state that does not exist.
    #[error("state `{state}`: `on` targets state #{target}, which does not exist")]
    OnTarget {
        /// The state.
        state: &'static str,
        /// The target's index.
        target: usize,
    },
    /// An `after` targets a state that does not exist.
    #[error("state `{state}`: `after` targets state #{target}, which does not exist")]
    AfterTarget {
        /// The state.
        state: &'static str,
        /// The target's index.
        target: usize,
    },
    /// An `after ... without` names an input that does not exist.
    #[error("state `{state}`: `after ... without` names an input that does not exist")]
    AfterWithout {
        /// The state.
        state: &'static str,
    },
    /// A `may` target that does not exist.
    #[error("state `{state}`: `may` targets state #{target}, which does not exist")]
    MayTarget {
        /// The state.
        state: &'static str,
        /// The target's index.
        target: usize,
    },
    /// A periodic section without a period.
    #[error("state `{state}` has a periodic section but neither it nor the component has a period")]
    NoPeriod {
        /// The state.
        state: &'static str,
    },
    /// A periodic section with a zero period.
    #[error("state `{state}`: a period must be positive")]
    ZeroPeriod {
        /// The state.
        state: &'static str,
    },
    /// An exception plan's `goto` targets a state that does not exist.
    #[error("exception `{exception}`: `goto` targets state #{target}, which does not exist")]
    GotoTarget {
        /// The exception.
        exception: &'static str,
        /// The target's index.
        target: usize,
    },
    /// A fifo input of capacity 0.
    #[error("input `{input}`: a fifo needs a capacity of at least 1")]
    FifoCapacity {
        /// The input.
        input: &'static str,
    },
    /// A ufifo input of initial size 0.
    #[error("input `{input}`: a ufifo needs an initial size of at least 1")]
    UfifoInitial {
        /// The input.
        input: &'static str,
    },
}

/// One state of the user automaton.
#[derive(Debug, Clone, Copy)]
pub struct StateSpec {
    /// The state's name.
    pub name: &'static str,
    /// Whether the state has an entry section.
    pub entry: bool,
    /// Whether the state has an exit section.
    pub exit: bool,
    /// The periodic section, if the state has one.
    pub periodic: Option<PeriodicSpec>,
    /// `on port -> target` transitions, in declaration order.
    pub on: &'static [OnSpec],
    /// `after D [without port] -> target` transitions, in declaration order.
    pub after: &'static [AfterSpec],
    /// The targets the state's `choose` may return (`may -> a, b;`).
    pub may: &'static [usize],
}

impl StateSpec {
    /// A state called `name` with no sections and no transitions.
    pub const fn new(name: &'static str) -> StateSpec {
        StateSpec {
            name,
            entry: false,
            exit: false,
            periodic: None,
            on: &[],
            after: &[],
            may: &[],
        }
    }

    /// With an entry section.
    pub const fn with_entry(mut self) -> StateSpec {
        self.entry = true;
        self
    }

    /// With an exit section.
    pub const fn with_exit(mut self) -> StateSpec {
        self.exit = true;
        self
    }

    /// With a periodic section at `period`, or at the component's period if `None`.
    pub const fn with_periodic(mut self, period: Option<Duration>) -> StateSpec {
        self.periodic = Some(PeriodicSpec { period });
        self
    }

    /// With these `on port -> target` transitions.
    pub const fn with_on(mut self, on: &'static [OnSpec]) -> StateSpec {
        self.on = on;
        self
    }

    /// With these `after` transitions.
    pub const fn with_after(mut self, after: &'static [AfterSpec]) -> StateSpec {
        self.after = after;
        self
    }

    /// With these targets its `choose` may return.
    pub const fn with_may(mut self, may: &'static [usize]) -> StateSpec {
        self.may = may;
        self
    }
}

/// A periodic section.
#[derive(Debug, Clone, Copy)]
pub struct PeriodicSpec {
    /// The state's own period (`periodic 20ms;`), or `None` for the component period.
    pub period: Option<Duration>,
}

/// `on port -> target`: a packet or event arriving on input `port` moves the user
/// automaton to `target`.
#[derive(Debug, Clone, Copy)]
pub struct OnSpec {
    /// The input port id.
    pub port: usize,
    /// The target user state id.
    pub target: usize,
}

/// `after delay -> target` (time in state) or `after delay without port -> target`
/// (a watchdog: no packet on `port` for `delay`).
#[derive(Debug, Clone, Copy)]
pub struct AfterSpec {
    /// The delay.
    pub delay: Duration,
    /// The watched input port id, for a watchdog.
    pub without: Option<usize>,
    /// The target user state id.
    pub target: usize,
}

/// One input port.
#[derive(Debug, Clone, Copy)]
pub struct InputSpec {
    /// The port's name.
    pub name: &'static str,
    /// The kind of input end.
    pub kind: InputKind,
    /// The packet type's name as written in the description (informational).
    pub packet: &'static str,
    /// Whether the input uses the pull model.
    pub pull: bool,
}

impl InputSpec {
    /// An input of this kind carrying packets of the type called `packet`, not pulled.
    pub const fn new(name: &'static str, kind: InputKind, packet: &'static str) -> InputSpec {
        InputSpec {
            name,
            kind,
            packet,
            pull: false,
        }
    }

    /// Using the pull model.
    pub const fn pulled(mut self) -> InputSpec {
        self.pull = true;
        self
    }
}

/// The kinds of input port (paper 3.2, Figure 3).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputKind {
    /// Events only: a counter of event packets.
    Tick,
    /// A bounded queue.
    Fifo {
        /// The queue's capacity in packets.
        capacity: usize,
        /// What a full queue does with a new packet.
        policy: OverflowPolicy,
    },
    /// A queue that grows by `initial` packets when full, up to `max` if given.
    Ufifo {
        /// The initial capacity, also the growth step.
        initial: usize,
        /// The largest capacity, if any.
        max: Option<usize>,
    },
    /// A local copy of the latest packet.
    Last,
    /// Reads the producer's posted value.
    Poster,
}

/// What a full fifo does with a new packet. Every lost packet is counted on the
/// monitoring port and announced as a [`crate::MonitorEvent::Overflow`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum OverflowPolicy {
    /// The new packet is rejected (lost) and counted. The default.
    #[default]
    Reject,
    /// The oldest queued packet is dropped (lost, counted) to make room.
    DropOldest,
    /// The producer blocks until there is room, up to a timeout
    /// ([`crate::port::DEFAULT_BLOCK_TIMEOUT`] unless set on the port); then the new
    /// packet is rejected and counted.
    Block,
}

/// One output port.
#[derive(Debug, Clone, Copy)]
pub struct OutputSpec {
    /// The port's name.
    pub name: &'static str,
    /// The kind of output end.
    pub kind: OutputKind,
    /// The packet type's name as written in the description (informational).
    pub packet: &'static str,
    /// Whether the output answers pull requests.
    pub pull: bool,
}

impl OutputSpec {
    /// An output of this kind carrying packets of the type called `packet`, answering
    /// no pull requests.
    pub const fn new(name: &'static str, kind: OutputKind, packet: &'static str) -> OutputSpec {
        OutputSpec {
            name,
            kind,
            packet,
            pull: false,
        }
    }

    /// Answering pull requests.
    pub const fn pulled(mut self) -> OutputSpec {
        self.pull = true;
        self
    }
}

/// The kinds of output port.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputKind {
    /// Event packets to tick inputs.
    Tick,
    /// Data packets to last, fifo and ufifo inputs.
    Data,
    /// A posted value read by poster inputs.
    Poster,
}

/// A user variable published on the monitoring port or set through the control port.
#[derive(Debug, Clone, Copy)]
pub struct VarSpec {
    /// The variable's name.
    pub name: &'static str,
    /// Observable or controllable.
    pub kind: VarKind,
    /// The variable's type as written in the description (informational).
    pub ty: &'static str,
    /// The variable's documentation.
    pub doc: &'static str,
    /// The values a controllable variable may be set to, when its description bounds
    /// them (`in low..=high`): a set outside is refused, whoever asks.
    pub range: Option<VarRange>,
}

impl VarSpec {
    /// A variable of this kind whose values are of the type called `ty`, with no
    /// documentation and no range.
    pub const fn new(name: &'static str, kind: VarKind, ty: &'static str) -> VarSpec {
        VarSpec {
            name,
            kind,
            ty,
            doc: "",
            range: None,
        }
    }
}

/// The values a controllable variable may be set to, both ends included
/// (`controllable max_speed: f64 = 0.5 in 0.0..=1.0;`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum VarRange {
    /// An integer variable's range.
    Int(i128, i128),
    /// An `f64` variable's range.
    Float(f64, f64),
    /// An `f32` variable's range: a value is judged as the `f32` it is stored as.
    F32(f32, f32),
}

/// A value a ranged variable refuses ([`VarRange::check`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OutOfRange {
    /// A number outside the range.
    #[error("{value} is outside its range {range}")]
    Outside {
        /// The value refused, as a number.
        value: String,
        /// The range.
        range: VarRange,
    },
    /// Not a number: a ranged variable takes numbers only.
    #[error("a {kind} is not a number, and the variable takes numbers in {range}")]
    NotANumber {
        /// The kind of value given ([`crate::Value::kind_name`]).
        kind: &'static str,
        /// The range.
        range: VarRange,
    },
}

/// A number, however a value carries it.
enum Number {
    Int(i128),
    Float(f64),
}

impl Number {
    /// The number `value` holds: an integer, a float, or a JSON number (what a command
    /// decoded from JSON may carry); `None` for anything else.
    fn of(value: &crate::Value) -> Option<Number> {
        use crate::Value;
        match value {
            Value::Int(v) => Some(Number::Int(i128::from(*v))),
            Value::UInt(v) => Some(Number::Int(i128::from(*v))),
            Value::Float(v) => Some(Number::Float(*v)),
            Value::Json(serde_json::Value::Number(n)) => n
                .as_i64()
                .map(|v| Number::Int(i128::from(v)))
                .or_else(|| n.as_u64().map(|v| Number::Int(i128::from(v))))
                .or_else(|| n.as_f64().map(Number::Float)),
            _ => None,
        }
    }

    #[allow(clippy::cast_precision_loss)]
    fn float(&self) -> f64 {
        match *self {
            Number::Int(v) => v as f64,
            Number::Float(v) => v,
        }
    }
}

impl VarRange {
    /// Whether `value` lies in the range: a number of any kind (NaN lies in no range);
    /// anything else is refused, since a ranged variable is a number.
    pub fn check(&self, value: &crate::Value) -> Result<(), OutOfRange> {
        let Some(number) = Number::of(value) else {
            return Err(OutOfRange::NotANumber {
                kind: value.kind_name(),
                range: *self,
            });
        };
        #[allow(clippy::cast_possible_truncation)]
        let (inside, shown) = match (*self, &number) {
            (VarRange::Int(low, high), Number::Int(v)) => ((low..=high).contains(v), v.to_string()),
            // A float for an integer variable: its conversion refuses it.
            (VarRange::Int(..), Number::Float(_)) => (true, String::new()),
            (VarRange::Float(low, high), number) => {
                let v = number.float();
                ((low..=high).contains(&v), format!("{v:?}"))
            }
            (VarRange::F32(low, high), number) => {
                let v = number.float() as f32;
                ((low..=high).contains(&v), format!("{v:?}"))
            }
        };
        if inside {
            return Ok(());
        }
        Err(OutOfRange::Outside {
            value: shown,
            range: *self,
        })
    }
}

impl std::fmt::Display for VarRange {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            VarRange::Int(low, high) => write!(f, "{low}..={high}"),
            VarRange::Float(low, high) => write!(f, "{low:?}..={high:?}"),
            VarRange::F32(low, high) => write!(f, "{low:?}..={high:?}"),
        }
    }
}

/// Whether a variable is read-only from outside or also settable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VarKind {
    /// Published on the monitoring port.
    Observable,
    /// Published on the monitoring port and set through the control port.
    Controllable,
}

/// A declared exception and its continuity plan.
#[derive(Debug, Clone, Copy)]
pub struct ExceptionSpec {
    /// The exception's name.
    pub name: &'static str,
    /// Its description.
    pub description: &'static str,
    /// The continuity plan, run in order; an empty plan means running error.
    pub plan: &'static [PlanStep],
}

/// One step of a continuity plan (paper 3.5).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlanStep {
    /// Run the failing section again, up to `count` times, `every` apart.
    Retry {
        /// How many more attempts.
        count: u32,
        /// The pause before each attempt.
        every: Duration,
    },
    /// Move the user automaton to this state.
    Goto(usize),
    /// Log the exception and go on.
    Ignore,
    /// Lower the quality level by one (fails at the lowest level).
    Degrade,
}

/// The `timing` block.
#[derive(Debug, Clone, Copy)]
pub struct TimingSpec {
    /// The nominal period.
    pub period: Option<Duration>,
    /// The longest period degradation may stretch to.
    pub max_period: Option<Duration>,
    /// The longest a section may run (the maximum delay to handle an input event).
    pub max_response: Option<Duration>,
    /// The priority: 0 leaves the thread as the OS created it; above 0, real-time
    /// scheduling where permitted; below 0, a higher nice value (`docs/runtime.md`,
    /// "Priority"; what holds is published as [`crate::OsPriority`]).
    pub priority: i32,
    /// Quality levels, best first.
    pub qualities: &'static [&'static str],
}

impl TimingSpec {
    /// A timing block with nothing set.
    pub const NONE: TimingSpec = TimingSpec {
        period: None,
        max_period: None,
        max_response: None,
        priority: 0,
        qualities: &[],
    };
}
