//! Components coolc never generates, on hand-built specs: the runtime's refusal of
//! inconsistent specs and of ports that do not match their spec, a spec without the
//! period its periodic state needs (accepted with an instance's timing), and a `tick`
//! output declared `pull` (coolc refuses it: `coolc::check::connect_kind`; the runtime
//! answers it). Every other runtime test runs generated components (`tests/runtime/`).

use std::time::Duration;

use coolbot::port::{FifoIn, LastIn, TickIn, TickOut};
use coolbot::{
    Automaton, Chain, Component, Context, Error, Fault, InputKind, InputSpec, OnSpec, OutputKind,
    OutputSpec, OverflowPolicy, PeriodicSpec, PlanStep, PortSet, Section, Spec, SpecError,
    StateSpec, System, TimingSpec,
};

/// A valid spec the tests break one field at a time: states `idle` (`on data`, `on
/// kick -> busy`) and `busy` (periodic, `may -> idle`), inputs `data` (fifo of 4),
/// `kick` (tick) and `feed` (last), a 5 ms period.
static BASE: Spec = Spec {
    type_name: "Base",
    doc: "",
    states: &[
        StateSpec {
            name: "idle",
            entry: true,
            exit: false,
            periodic: None,
            on: &[OnSpec { port: 0, target: 1 }, OnSpec { port: 1, target: 1 }],
            after: &[],
            may: &[],
        },
        StateSpec {
            name: "busy",
            entry: true,
            exit: true,
            periodic: Some(PeriodicSpec { period: None }),
            on: &[],
            after: &[],
            may: &[0],
        },
    ],
    initial: 0,
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
    outputs: &[],
    variables: &[],
    exceptions: &[],
    timing: TimingSpec {
        period: Some(Duration::from_millis(5)),
        ..TimingSpec::NONE
    },
};

/// Code that does nothing, claiming `spec`.
struct Bare(&'static Spec);

impl Automaton for Bare {
    fn spec(&self) -> &'static Spec {
        self.0
    }
}

fn leak<T>(items: Vec<T>) -> &'static [T] {
    Box::leak(items.into_boxed_slice())
}

/// A component `w` claiming `spec`, with `BASE`'s ports registered.
fn bare(spec: &'static Spec) -> Component {
    let data = FifoIn::<u64>::new(4, OverflowPolicy::Reject);
    let kick = TickIn::new();
    let feed = LastIn::<u64>::new();
    let ports = PortSet::new().input(&data).input(&kick).input(&feed);
    Component::new("w", Box::new(Bare(spec)), ports)
}

/// Adds [`bare`]`(spec)` to a new system.
fn add_with(spec: Spec) -> Result<(), Error> {
    let spec: &'static Spec = Box::leak(Box::new(spec));
    System::new().add(bare(spec)).map(|_| ())
}

fn with_states(edit: impl FnOnce(&mut Vec<StateSpec>)) -> Spec {
    let mut states = BASE.states.to_vec();
    edit(&mut states);
    let mut spec = BASE;
    spec.states = leak(states);
    spec
}

#[test]
fn the_base_spec_is_valid() {
    assert_eq!(BASE.validate(), Ok(()));
    assert!(add_with(BASE).is_ok());
}

#[test]
fn inconsistent_specs_are_refused_with_a_reason() {
    let mut spec = BASE;
    spec.initial = 9;
    let refused = add_with(spec).unwrap_err();
    // The message says what failed; the spec's fault is its source, shown once.
    assert_eq!(refused.to_string(), "component `w`: invalid spec");
    let source = std::error::Error::source(&refused).expect("the spec's fault");
    assert_eq!(
        source.downcast_ref::<SpecError>(),
        Some(&SpecError::Initial {
            initial: 9,
            states: 2
        })
    );
    assert_eq!(
        Chain(&refused).to_string(),
        "component `w`: invalid spec: initial state #9 does not exist (2 states)"
    );
    let spec = with_states(|states| states[0].on = &[OnSpec { port: 7, target: 0 }]);
    assert_eq!(
        spec.validate().unwrap_err().to_string(),
        "state `idle`: `on` names input #7, which does not exist"
    );
    let spec = with_states(|states| states[0].may = &[5]);
    assert_eq!(
        spec.validate().unwrap_err().to_string(),
        "state `idle`: `may` targets state #5, which does not exist"
    );
    let mut spec = with_states(|states| states[0].periodic = Some(PeriodicSpec { period: None }));
    spec.timing = TimingSpec::NONE;
    assert_eq!(spec.validate(), Err(SpecError::NoPeriod { state: "idle" }));
    assert_eq!(
        spec.validate().unwrap_err().to_string(),
        "state `idle` has a periodic section but neither it nor the component has a period"
    );
    let mut spec = BASE;
    spec.exceptions = &[coolbot::ExceptionSpec {
        name: "x",
        description: "",
        plan: &[PlanStep::Goto(4)],
    }];
    assert_eq!(
        spec.validate().unwrap_err().to_string(),
        "exception `x`: `goto` targets state #4, which does not exist"
    );
    let mut spec = BASE;
    spec.inputs = leak(vec![
        InputSpec {
            name: "data",
            kind: InputKind::Fifo {
                capacity: 0,
                policy: OverflowPolicy::Reject,
            },
            packet: "u64",
            pull: false,
        },
        BASE.inputs[1],
        BASE.inputs[2],
    ]);
    assert_eq!(
        spec.validate().unwrap_err().to_string(),
        "input `data`: a fifo needs a capacity of at least 1"
    );
}

#[test]
fn registered_ports_must_match_the_declared_kinds() {
    let mut spec = BASE;
    spec.inputs = leak(vec![BASE.inputs[1], BASE.inputs[0], BASE.inputs[2]]);
    let err = add_with(spec).unwrap_err();
    assert_eq!(
        err.to_string(),
        "component `w`: input `kick` is declared Tick but registered as fifo"
    );
}

/// (From `faults.rs`: the name checks stay there, on generated components.)
#[test]
fn components_with_bad_ports_are_refused() {
    let empty = Component::new("empty", Box::new(Bare(&BASE)), PortSet::new());
    let err = System::new().add(empty).unwrap_err();
    assert_eq!(
        err.to_string(),
        "component `empty`: 0 input ports registered, the spec declares 3"
    );
}

/// `BASE` without a `timing` block: its periodic `busy` state has no period, so the
/// spec alone is refused (coolc refuses such a description: `periodic_without_period`).
static UNTIMED: Spec = Spec {
    timing: TimingSpec::NONE,
    ..BASE
};

const OVERRIDE: TimingSpec = TimingSpec {
    period: Some(Duration::from_millis(20)),
    max_period: Some(Duration::from_millis(40)),
    max_response: Some(Duration::from_millis(300)),
    priority: 7,
    qualities: &["full", "reduced", "minimal"],
};

/// (From `timing_override.rs`, whose other test runs a generated component.)
#[test]
fn a_spec_without_a_period_is_accepted_with_an_instance_period() {
    let mut system = System::new();
    let refused = system.add(bare(&UNTIMED)).unwrap_err();
    assert_eq!(
        Chain(&refused).to_string(),
        "component `w`: invalid spec: state `busy` has a periodic section but neither it nor the component has a period"
    );
    let component = bare(&UNTIMED).with_timing(OVERRIDE);
    assert_eq!(component.timing().period, OVERRIDE.period);
    assert_eq!(component.spec().timing.period, None);
    let handle = system.add(component).expect("accepted with the override");
    let monitor = handle.snapshot();
    assert_eq!(monitor.period, Some(Duration::from_millis(20)));
    assert_eq!(monitor.max_response, Some(Duration::from_millis(300)));
    assert_eq!(monitor.priority, 7);
}

/// A component with no state and one `tick` output declared `pull`.
static TICK_PRODUCER: Spec = Spec {
    type_name: "TickProducer",
    doc: "",
    states: &[],
    initial: 0,
    inputs: &[],
    outputs: &[OutputSpec {
        name: "tick",
        kind: OutputKind::Tick,
        packet: "",
        pull: true,
    }],
    variables: &[],
    exceptions: &[],
    timing: TimingSpec::NONE,
};

/// A component with no state and one `tick` input declared `pull` (coolc accepts
/// this declaration, but no output it accepts can be connected to it).
static TICK_CONSUMER: Spec = Spec {
    type_name: "TickConsumer",
    doc: "",
    states: &[],
    initial: 0,
    inputs: &[InputSpec {
        name: "t",
        kind: InputKind::Tick,
        packet: "",
        pull: true,
    }],
    outputs: &[],
    variables: &[],
    exceptions: &[],
    timing: TimingSpec::NONE,
};

/// `TICK_PRODUCER`'s code: each pull request is answered with one tick.
struct TickAnswer(TickOut);

impl Automaton for TickAnswer {
    fn spec(&self) -> &'static Spec {
        &TICK_PRODUCER
    }
    fn answer(&mut self, _output: usize, _cx: &mut Context) -> Result<(), Fault> {
        self.0.emit();
        Ok(())
    }
}

/// (From `pull.rs::fifo_poster_and_tick_inputs_pull_too`, whose fifo and poster
/// inputs pull from a generated producer.)
#[test]
fn a_tick_input_pulls_from_a_tick_output_declared_pull() {
    let tick = TickOut::new();
    let t = TickIn::new();
    let mut system = System::new();
    let producer = Component::new(
        "p",
        Box::new(TickAnswer(tick.clone())),
        PortSet::new().output(&tick),
    );
    system.add(producer).expect("p");
    let consumer = Component::new(
        "c",
        Box::new(Bare(&TICK_CONSUMER)),
        PortSet::new().input(&t),
    );
    system.add(consumer).expect("c");
    system.run_all().expect("run");
    system.connect("p.tick", "c.t").expect("t");
    assert_eq!(t.pull(Duration::from_secs(10)), Ok(1));
    assert!(system.shutdown().clean());
}

/// A supervisor claiming a spec without states.
struct Stateless;

static STATELESS: Spec = Spec {
    type_name: "Stateless",
    doc: "",
    states: &[],
    initial: 0,
    inputs: &[],
    outputs: &[],
    variables: &[],
    exceptions: &[],
    timing: TimingSpec::NONE,
};

impl coolbot::Supervisor for Stateless {
    fn spec(&self) -> &'static Spec {
        &STATELESS
    }
    fn section(
        &mut self,
        _state: usize,
        _section: Section,
        _cx: &mut coolbot::SupervisorCx<'_>,
    ) -> coolbot::SectionResult {
        Ok(())
    }
}

/// An atomic component may have no automaton; a supervisor may not (coolc gives a
/// compound without a `supervisor` block a state of its own).
#[test]
fn a_supervisor_without_states_is_refused() {
    let Err(error) = coolbot::CompoundBuilder::new("cell", Stateless).build() else {
        panic!("a supervisor without states was accepted");
    };
    assert_eq!(
        error.to_string(),
        "compound `cell`: the supervisor has no state"
    );
}

/// A supervisor with one state and nothing to do.
struct Watching;

static WATCHING: Spec = Spec {
    type_name: "Watching",
    doc: "",
    states: &[StateSpec {
        name: "watching",
        entry: false,
        exit: false,
        periodic: None,
        on: &[],
        after: &[],
        may: &[],
    }],
    initial: 0,
    inputs: &[],
    outputs: &[],
    variables: &[],
    exceptions: &[],
    timing: TimingSpec::NONE,
};

impl coolbot::Supervisor for Watching {
    fn spec(&self) -> &'static Spec {
        &WATCHING
    }
}

/// Each error says what failed and keeps its cause as its source: the compound, the
/// instance's refusal, the spec's fault, each shown once in the chain.
#[test]
fn a_compound_refusing_an_instance_keeps_the_chain() {
    let mut spec = BASE;
    spec.initial = 9;
    let spec: &'static Spec = Box::leak(Box::new(spec));
    let Err(error) = coolbot::CompoundBuilder::new("cell", Watching)
        .instance(bare(spec))
        .build()
    else {
        panic!("an instance with a bad spec was accepted");
    };
    assert_eq!(error.to_string(), "compound `cell`");
    assert_eq!(
        Chain(&error).to_string(),
        "compound `cell`: component `w`: invalid spec: initial state #9 does not exist (2 states)"
    );
}
