//! A component written by hand exactly as `coolc` would generate it from:
//!
//! ```text
//! atomic Worker {
//!     configuration { scale: i64 = 1; }
//!     observable count: u64 = 0;
//!     controllable gain: i64 = 1;
//!     input data: fifo<u64>(4);
//!     input kick: tick;
//!     input feed: last<u64>;
//!     output out: data<u64>;
//!     timing { period 5ms; max_response 500ms; quality full, reduced; }
//!     exception flaky { retry 2 every 1ms; }
//!     exception fatal;
//!     exception detour { goto idle; }
//!     exception wobbly { degrade; }
//!     automaton {
//!         initial idle;
//!         state idle { entry; on data -> busy; on kick -> busy; }
//!         state busy {
//!             entry; periodic; exit;
//!             after 10s -> idle;
//!             after 10s without feed -> idle;
//!             may -> idle;
//!         }
//!     }
//! }
//! ```

use std::time::Duration;

use coolbot::port::{DataOut, FifoIn, LastIn, TickIn};
use coolbot::{
    AfterSpec, Automaton, Component, Context, ExceptionSpec, Fault, InputKind, InputSpec, OnSpec,
    OutputKind, OutputSpec, OverflowPolicy, PeriodicSpec, PlanStep, PortSet, Section,
    SectionResult, Spec, StateSpec, TimingSpec, Value, VarKind, VarSpec,
};

/// The `configuration` block.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Config {
    pub scale: i64,
}

impl Default for Config {
    fn default() -> Self {
        Config { scale: 1 }
    }
}

/// Observable, controllable and local variables.
#[derive(Debug, Clone, PartialEq)]
pub struct Vars {
    pub count: u64,
    pub gain: i64,
}

impl Default for Vars {
    fn default() -> Self {
        Vars { count: 0, gain: 1 }
    }
}

/// One typed handle per input port.
#[derive(Clone)]
pub struct Inputs {
    pub data: FifoIn<u64>,
    pub kick: TickIn,
    pub feed: LastIn<u64>,
}

/// One typed handle per output port.
#[derive(Clone)]
pub struct Outputs {
    pub out: DataOut<u64>,
}

/// The user automaton's states.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum UserState {
    Idle,
    Busy,
}

/// The targets `busy` may choose.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BusyMay {
    Idle,
}

/// The declared exceptions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Exception {
    Flaky,
    Fatal,
    Detour,
    Wobbly,
}

impl Exception {
    pub fn raise(self, message: impl Into<String>) -> Fault {
        Fault::exception(self as usize, message)
    }
}

/// What a section sees.
pub struct Cx<'a> {
    pub config: &'a Config,
    pub vars: &'a mut Vars,
    pub inputs: &'a Inputs,
    pub outputs: &'a Outputs,
    pub rt: &'a mut Context,
}

/// The stubs the user fills in.
pub trait Behavior: Send + 'static {
    /// Called in `starting`.
    fn start(&mut self, _cx: &mut Cx<'_>) -> SectionResult {
        Ok(())
    }
    /// Called when leaving the started world.
    fn stop(&mut self, _cx: &mut Cx<'_>) {}
    fn idle_entry(&mut self, cx: &mut Cx<'_>) -> SectionResult;
    fn busy_entry(&mut self, cx: &mut Cx<'_>) -> SectionResult;
    fn busy_periodic(&mut self, cx: &mut Cx<'_>) -> SectionResult;
    fn busy_exit(&mut self, cx: &mut Cx<'_>) -> SectionResult;
    fn busy_choose(&mut self, cx: &mut Cx<'_>) -> Option<BusyMay>;
    fn on_flaky(&mut self, cx: &mut Cx<'_>, message: &str);
    fn on_fatal(&mut self, cx: &mut Cx<'_>, message: &str);
    fn on_detour(&mut self, cx: &mut Cx<'_>, message: &str);
    fn on_wobbly(&mut self, cx: &mut Cx<'_>, message: &str);
}

pub const IDLE: usize = 0;
pub const BUSY: usize = 1;
pub const DATA: usize = 0;
pub const KICK: usize = 1;
pub const FEED: usize = 2;

pub static SPEC: Spec = Spec {
    type_name: "Worker",
    doc: "A test component.",
    states: &[
        StateSpec {
            name: "idle",
            entry: true,
            exit: false,
            periodic: None,
            on: &[
                OnSpec {
                    port: DATA,
                    target: BUSY,
                },
                OnSpec {
                    port: KICK,
                    target: BUSY,
                },
            ],
            after: &[],
            may: &[],
        },
        StateSpec {
            name: "busy",
            entry: true,
            exit: true,
            periodic: Some(PeriodicSpec { period: None }),
            on: &[],
            after: &[
                AfterSpec {
                    delay: Duration::from_secs(10),
                    without: None,
                    target: IDLE,
                },
                AfterSpec {
                    delay: Duration::from_secs(10),
                    without: Some(FEED),
                    target: IDLE,
                },
            ],
            may: &[IDLE],
        },
    ],
    initial: IDLE,
    inputs: &[
        InputSpec {
            name: "data",
            kind: InputKind::Fifo {
                capacity: 4,
                policy: OverflowPolicy::Reject,
            },
            packet: "u64",
            pull: false,
        },
        InputSpec {
            name: "kick",
            kind: InputKind::Tick,
            packet: "",
            pull: false,
        },
        InputSpec {
            name: "feed",
            kind: InputKind::Last,
            packet: "u64",
            pull: false,
        },
    ],
    outputs: &[OutputSpec {
        name: "out",
        kind: OutputKind::Data,
        packet: "u64",
        pull: false,
    }],
    variables: &[
        VarSpec {
            name: "count",
            kind: VarKind::Observable,
            ty: "u64",
            doc: "",
        },
        VarSpec {
            name: "gain",
            kind: VarKind::Controllable,
            ty: "i64",
            doc: "",
        },
    ],
    exceptions: &[
        ExceptionSpec {
            name: "flaky",
            description: "",
            plan: &[PlanStep::Retry {
                count: 2,
                every: Duration::from_millis(1),
            }],
        },
        ExceptionSpec {
            name: "fatal",
            description: "",
            plan: &[],
        },
        ExceptionSpec {
            name: "detour",
            description: "",
            plan: &[PlanStep::Goto(IDLE)],
        },
        ExceptionSpec {
            name: "wobbly",
            description: "",
            plan: &[PlanStep::Degrade],
        },
    ],
    timing: TimingSpec {
        period: Some(Duration::from_millis(5)),
        max_period: None,
        max_response: Some(Duration::from_millis(500)),
        priority: 0,
        qualities: &["full", "reduced"],
    },
};

/// The glue: implements the runtime's index-based automaton over `Behavior`.
struct Glue<B> {
    /// `&SPEC` in generated code; tests may swap in a variant with other timings.
    spec: &'static Spec,
    behavior: B,
    config: Config,
    vars: Vars,
    inputs: Inputs,
    outputs: Outputs,
}

impl<B: Behavior> Glue<B> {
    fn cx<'a>(&'a mut self, rt: &'a mut Context) -> (&'a mut B, Cx<'a>) {
        let cx = Cx {
            config: &self.config,
            vars: &mut self.vars,
            inputs: &self.inputs,
            outputs: &self.outputs,
            rt,
        };
        (&mut self.behavior, cx)
    }
}

impl<B: Behavior> Automaton for Glue<B> {
    fn spec(&self) -> &'static Spec {
        self.spec
    }

    fn start(&mut self, rt: &mut Context) -> Result<(), Fault> {
        let (behavior, mut cx) = self.cx(rt);
        behavior.start(&mut cx)
    }

    fn stop(&mut self, rt: &mut Context) {
        let (behavior, mut cx) = self.cx(rt);
        behavior.stop(&mut cx)
    }

    fn section(&mut self, state: usize, section: Section, rt: &mut Context) -> Result<(), Fault> {
        let (behavior, mut cx) = self.cx(rt);
        match (state, section) {
            (IDLE, Section::Entry) => behavior.idle_entry(&mut cx),
            (BUSY, Section::Entry) => behavior.busy_entry(&mut cx),
            (BUSY, Section::Periodic) => behavior.busy_periodic(&mut cx),
            (BUSY, Section::Exit) => behavior.busy_exit(&mut cx),
            _ => Ok(()),
        }
    }

    fn choose(&mut self, state: usize, rt: &mut Context) -> Option<usize> {
        let (behavior, mut cx) = self.cx(rt);
        match state {
            BUSY => behavior.busy_choose(&mut cx).map(|may| match may {
                BusyMay::Idle => IDLE,
            }),
            _ => None,
        }
    }

    fn exception(&mut self, exception: usize, message: &str, rt: &mut Context) {
        let (behavior, mut cx) = self.cx(rt);
        match exception {
            0 => behavior.on_flaky(&mut cx, message),
            1 => behavior.on_fatal(&mut cx, message),
            2 => behavior.on_detour(&mut cx, message),
            3 => behavior.on_wobbly(&mut cx, message),
            _ => {}
        }
    }

    fn answer(&mut self, _output: usize, _rt: &mut Context) -> Result<(), Fault> {
        Ok(())
    }

    fn configure(&mut self, configuration: &Value) -> Result<(), String> {
        self.config = configuration.to_serde()?;
        Ok(())
    }

    fn set(&mut self, variable: usize, value: &Value) -> Result<(), String> {
        match variable {
            1 => {
                self.vars.gain = i64::try_from(value).map_err(|e| e.to_string())?;
                Ok(())
            }
            _ => Err(format!("variable #{variable} is not controllable")),
        }
    }

    fn get(&self, variable: usize) -> Value {
        match variable {
            0 => Value::from(self.vars.count),
            1 => Value::from(self.vars.gain),
            _ => Value::Unit,
        }
    }
}

/// An unstarted Worker named `name`; also returns clones of its ports.
pub fn component(name: &str, behavior: impl Behavior) -> (Component, Inputs, Outputs) {
    component_with(
        name,
        behavior,
        &SPEC,
        FifoIn::new(4, OverflowPolicy::Reject),
    )
}

/// A Worker with another spec (same states and ports, other timings) and data fifo.
pub fn component_with(
    name: &str,
    behavior: impl Behavior,
    spec: &'static Spec,
    data: FifoIn<u64>,
) -> (Component, Inputs, Outputs) {
    let inputs = Inputs {
        data,
        kick: TickIn::new(),
        feed: LastIn::new(),
    };
    let outputs = Outputs {
        out: DataOut::new(),
    };
    let ports = PortSet::new()
        .input(&inputs.data)
        .input(&inputs.kick)
        .input(&inputs.feed)
        .output(&outputs.out);
    let glue = Glue {
        spec,
        behavior,
        config: Config::default(),
        vars: Vars::default(),
        inputs: inputs.clone(),
        outputs: outputs.clone(),
    };
    (Component::new(name, Box::new(glue), ports), inputs, outputs)
}

/// A copy of SPEC whose `busy` state has other `after` transitions (leaked).
pub fn spec_with_busy_after(after: Vec<AfterSpec>) -> &'static Spec {
    let mut states = SPEC.states.to_vec();
    states[BUSY].after = Box::leak(after.into_boxed_slice());
    let mut spec = SPEC;
    spec.states = Box::leak(states.into_boxed_slice());
    Box::leak(Box::new(spec))
}
