//! Components and the [`System`] that runs them: adding, connecting (with the kind,
//! cardinality and packet-type rules of the contract), starting and shutting down.

use std::any::TypeId;
use std::collections::HashMap;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use crate::automaton::{Atomic, Automaton, Driven};
use crate::clock::Clock;
use crate::handle::Handle;
use crate::monitor::TaskResult;
use crate::monitor::{DEFAULT_COMMAND_TIMEOUT, Monitor, Shared};
use crate::port::{
    ArrivalLabel, ErasedInput, ErasedOutput, InKind, InputPort, OutKind, OutputPort, Owner, Packet,
};
use crate::runner::Runner;
use crate::spec::{InputKind, OutputKind, OverflowPolicy, Spec, TimingSpec};
use crate::table::{Controllable, State};
use crate::value::Value;

/// How many commands may wait at one component's control port; a command beyond that
/// is rejected at once.
pub const CONTROL_CAPACITY: usize = 32;

/// How long [`System::shutdown`] (and dropping a system) waits for each thread.
pub const SHUTDOWN_TIMEOUT: Duration = Duration::from_secs(5);

/// The typed port handles of one component, registered in declaration order.
#[derive(Debug, Default)]
pub struct PortSet {
    inputs: Vec<ErasedInput>,
    outputs: Vec<ErasedOutput>,
}

impl PortSet {
    /// An empty set.
    pub fn new() -> PortSet {
        PortSet::default()
    }

    /// Register the next input port (declaration order, matching the spec).
    pub fn input(mut self, port: &impl InputPort) -> PortSet {
        self.inputs.push(port.erased());
        self
    }

    /// Register the next input port, already erased.
    pub(crate) fn erased_input(mut self, port: ErasedInput) -> PortSet {
        self.inputs.push(port);
        self
    }

    /// Register the next output port (declaration order, matching the spec).
    pub fn output(mut self, port: &impl OutputPort) -> PortSet {
        self.outputs.push(port.erased());
        self
    }

    /// Register the next output port, already erased.
    pub(crate) fn erased_output(mut self, port: ErasedOutput) -> PortSet {
        self.outputs.push(port);
        self
    }
}

/// An unstarted component: a name, its code and its ports.
pub struct Component {
    name: String,
    automaton: Box<dyn Driven>,
    ports: PortSet,
    /// The instance's own `timing` block, replacing the spec's.
    timing: Option<TimingSpec>,
    /// A compound's instances' handles (see [`Handle::instances`]).
    instances: Vec<Handle>,
    /// The instance's adaptation settings (`docs/runtime.md`, "Adaptation").
    adaptation: crate::adapt::AdaptConfig,
}

impl std::fmt::Debug for Component {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Component({}: {})",
            self.name,
            self.automaton.spec().type_name
        )
    }
}

impl Component {
    /// A component named `name` running `automaton` with `ports` (in the spec's
    /// declaration order). Generated `component(name, behavior)` functions call this.
    pub fn new(
        name: impl Into<String>,
        automaton: Box<dyn Automaton>,
        ports: PortSet,
    ) -> Component {
        Component::driven(name, Box::new(Atomic(automaton)), ports)
    }

    /// A component whose automaton has the compound hooks ([`Driven`]): a compound's.
    pub(crate) fn driven(
        name: impl Into<String>,
        automaton: Box<dyn Driven>,
        ports: PortSet,
    ) -> Component {
        Component {
            name: name.into(),
            automaton,
            ports,
            timing: None,
            instances: Vec::new(),
            adaptation: crate::adapt::AdaptConfig::default(),
        }
    }

    /// Whether it is a compound (it has instances of its own).
    pub(crate) fn is_compound(&self) -> bool {
        !self.instances.is_empty()
    }

    /// This component with its instances' handles (a compound's, declaration order),
    /// published through its [`Handle::instance`].
    pub(crate) fn with_instances(mut self, instances: Vec<Handle>) -> Component {
        self.instances = instances;
        self
    }

    /// This instance with its own `timing` block (a `.cool` instance's `timing { ... }`
    /// override): `timing` replaces the spec's block as a whole for this instance —
    /// period, max_period, max_response, priority and quality levels. The runner, the
    /// monitor and the watchdog use it wherever they would use `spec().timing`. To
    /// change only some fields, start from the spec's block:
    /// `TimingSpec { period: Some(ms(50)), ..SPEC.timing }`.
    pub fn with_timing(mut self, timing: TimingSpec) -> Component {
        self.timing = Some(timing);
        self
    }

    /// This instance with its own adaptation settings (paper 3.6; `docs/runtime.md`,
    /// "Adaptation"): [`AdaptConfig::off`](crate::AdaptConfig::off) turns it off,
    /// [`AdaptConfig::on`](crate::AdaptConfig::on) turns it on without a period
    /// interval (quality steps only), and the other fields tune its detection. By
    /// default adaptation is on where the timing block has a period interval.
    pub fn with_adaptation(mut self, adaptation: crate::adapt::AdaptConfig) -> Component {
        self.adaptation = adaptation;
        self
    }

    /// The instance's adaptation settings ([`Component::with_adaptation`]).
    pub fn adaptation(&self) -> crate::adapt::AdaptConfig {
        self.adaptation
    }

    /// The effective `timing` block: the instance's override if it has one
    /// ([`Component::with_timing`]), else the spec's.
    pub fn timing(&self) -> TimingSpec {
        self.timing.unwrap_or(self.automaton.spec().timing)
    }

    /// The instance name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The component's static shape.
    pub fn spec(&self) -> &'static Spec {
        self.automaton.spec()
    }

    /// The current value of variable `index` (before the component runs: its initial
    /// value, with an instance's overrides).
    pub(crate) fn automaton_get(&self, index: usize) -> Value {
        self.automaton.get(index)
    }

    /// The current configuration, if the automaton reports one.
    pub(crate) fn configuration(&self) -> Option<Value> {
        self.automaton.configuration()
    }
}

/// Errors of [`System`] operations other than connecting.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Two components with one name.
    #[error("a component named `{0}` already exists")]
    DuplicateName(String),
    /// A name that cannot be used in `instance.port` addresses.
    #[error("`{0}` is not a valid component name (non-empty, no `.`)")]
    InvalidName(String),
    /// The component's spec is inconsistent (a bug in the generator or a hand-written
    /// spec).
    #[error("component `{component}`: invalid spec")]
    InvalidSpec {
        /// The component.
        component: String,
        /// What is wrong.
        #[source]
        source: crate::spec::SpecError,
    },
    /// The registered ports do not match the spec.
    #[error("component `{component}`: {detail}")]
    PortMismatch {
        /// The component.
        component: String,
        /// What does not match.
        detail: String,
    },
    /// A port handle already belongs to another component.
    #[error("component `{component}`: port `{port}` already belongs to another component")]
    PortInUse {
        /// The component.
        component: String,
        /// The port.
        port: String,
    },
    /// No component with this name.
    #[error("no component named `{0}`")]
    UnknownComponent(String),
    /// The OS refused a thread.
    #[error("component `{component}`: cannot spawn its thread")]
    Spawn {
        /// The component.
        component: String,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A component did not reach a state in time.
    #[error("component `{component}` is {state}, did not become {wanted} within {waited:?}")]
    Timeout {
        /// The component.
        component: String,
        /// Its state when the wait ended.
        state: State,
        /// The state waited for.
        wanted: State,
        /// How long.
        waited: Duration,
    },
    /// A command was rejected.
    #[error(transparent)]
    Rejected(#[from] crate::monitor::Rejected),
    /// An execution group cannot be made or started ([`System::group`]).
    #[error("execution group `{group}`")]
    Group {
        /// The group.
        group: String,
        /// What is wrong with it.
        #[source]
        source: GroupError,
    },
}

/// Why an execution group ([`System::group`]) cannot be made or started.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum GroupError {
    /// A group with no member.
    #[error("it has no member")]
    Empty,
    /// A group name that is already a group's.
    #[error("a group of that name already exists")]
    DuplicateName,
    /// No component with this name.
    #[error("no component named `{0}`")]
    UnknownMember(String),
    /// A compound (or a remote instance's proxy): it supervises components on threads
    /// of their own and cannot share one.
    #[error("`{0}` is not an atomic component (a compound or a proxy runs on a thread of its own)")]
    NotAtomic(String),
    /// A component named twice, in this group or in two.
    #[error("`{member}` is already in group `{group}`")]
    TwiceGrouped {
        /// The component.
        member: String,
        /// The group it is in.
        group: String,
    },
    /// The component already runs on a thread of its own.
    #[error("`{0}` has already started on a thread of its own")]
    Started(String),
    /// A member pulls from another member: the pull would wait for a turn of the very
    /// thread that waits.
    #[error(
        "`{input}` pulls from `{output}`, a member of the same group: the pull would wait for its own thread"
    )]
    Pull {
        /// The pulling input's address.
        input: String,
        /// The answering output's address.
        output: String,
    },
    /// A member's `block` fifo fed by another member: a full queue would stop the very
    /// thread that empties it.
    #[error(
        "`{input}`, a `block` fifo, is fed by `{output}`, a member of the same group: a full queue would stop the thread that empties it (use `reject` or `drop_oldest`, or keep them apart)"
    )]
    Block {
        /// The blocking input's address.
        input: String,
        /// The feeding output's address.
        output: String,
    },
    /// A cycle of connections among members with no `last` or `poster` input on it.
    #[error(
        "its members' connections form a cycle through {0} with no `last` or `poster` input to break it"
    )]
    Cycle(String),
}

/// Why a connection could not be made or removed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConnectError {
    /// Not `instance.port`.
    #[error("`{address}` is not an `instance.port` address")]
    BadAddress {
        /// The address.
        address: String,
    },
    /// No such component.
    #[error("`{address}`: no component named `{instance}`")]
    UnknownInstance {
        /// The address.
        address: String,
        /// The instance name.
        instance: String,
    },
    /// No such port.
    #[error("`{address}`: component `{instance}` ({type_name}) has no {direction} port `{port}`")]
    UnknownPort {
        /// The address.
        address: String,
        /// The instance.
        instance: String,
        /// Its type.
        type_name: String,
        /// `input` or `output`.
        direction: &'static str,
        /// The port name.
        port: String,
    },
    /// The kinds cannot form a connection.
    #[error(
        "cannot connect {from_kind} output `{from}` to {to_kind} input `{to}`: a {from_kind} output connects only to {allowed} inputs"
    )]
    KindMismatch {
        /// The output address.
        from: String,
        /// The input address.
        to: String,
        /// The output kind.
        from_kind: &'static str,
        /// The input kind.
        to_kind: &'static str,
        /// What the output connects to.
        allowed: &'static str,
    },
    /// The connection breaks a cardinality rule.
    #[error("cannot connect `{from}` to `{to}`: {rule}")]
    Cardinality {
        /// The output address.
        from: String,
        /// The input address.
        to: String,
        /// The rule and how it is broken.
        rule: String,
    },
    /// The packet types differ.
    #[error(
        "cannot connect `{from}` to `{to}`: the output carries `{from_type}` but the input expects `{to_type}` (use a converter: connect_via)"
    )]
    TypeMismatch {
        /// The output address.
        from: String,
        /// The input address.
        to: String,
        /// The output's packet type.
        from_type: String,
        /// The input's packet type.
        to_type: String,
    },
    /// A converter's types do not match the ports.
    #[error(
        "cannot connect `{from}` to `{to}` via a converter `{converter}`: the ports carry `{ports}`"
    )]
    ConverterMismatch {
        /// The output address.
        from: String,
        /// The input address.
        to: String,
        /// The converter's types, `A -> B`.
        converter: String,
        /// The ports' packet types, `output type -> input type`.
        ports: String,
    },
    /// A pull input needs an output that answers pull requests.
    #[error("cannot connect `{from}` to pull input `{to}`: `{from}` is not declared `pull`")]
    PullMismatch {
        /// The output address.
        from: String,
        /// The input address.
        to: String,
    },
    /// A pull between two members of one execution group (the pull would wait for
    /// its own thread).
    #[error(
        "cannot connect `{from}` to pull input `{to}`: both run in execution group `{group}`, and a pull would wait for its own thread"
    )]
    PullInGroup {
        /// The output address.
        from: String,
        /// The input address.
        to: String,
        /// The group.
        group: String,
    },
    /// A `block` fifo fed by another member of its execution group (a full queue
    /// would stop the thread that empties it).
    #[error(
        "cannot connect `{from}` to `block` fifo `{to}`: both run in execution group `{group}`, and a full queue would stop the thread that empties it"
    )]
    BlockInGroup {
        /// The output address.
        from: String,
        /// The input address.
        to: String,
        /// The group.
        group: String,
    },
    /// Already connected.
    #[error("`{from}` is already connected to `{to}`")]
    AlreadyConnected {
        /// The output address.
        from: String,
        /// The input address.
        to: String,
    },
    /// Not connected.
    #[error("`{from}` is not connected to `{to}`")]
    NotConnected {
        /// The output address.
        from: String,
        /// The input address.
        to: String,
    },
}

/// How one component ended, in a [`Report`].
#[derive(Debug, Clone, PartialEq)]
pub struct ComponentReport {
    /// The instance name.
    pub name: String,
    /// Its last default-automaton state.
    pub state: State,
    /// Its last result.
    pub result: TaskResult,
    /// Its last error.
    pub error: Option<String>,
    /// Whether its thread was joined (false: never started, or still stuck in a
    /// section when the shutdown timeout expired).
    pub joined: bool,
    /// A panic that escaped the runtime's own code on that thread (a bug).
    pub thread_panic: Option<String>,
    /// A compound's instances (paths through nested compounds, `mid.leaf`) whose
    /// threads had not ended when the compound's did: stuck in a section past the
    /// compound's stop budget (`COMPOUND_STOP_TIMEOUT`). They end when their section
    /// returns. Empty for an atomic component.
    pub unjoined_instances: Vec<String>,
}

/// What [`System::shutdown`] returns.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Report {
    /// One entry per component, in the order they were added.
    pub components: Vec<ComponentReport>,
}

impl Report {
    /// Whether every started thread was joined without a runtime panic, compounds'
    /// instances included.
    pub fn clean(&self) -> bool {
        self.components.iter().all(|c| {
            c.thread_panic.is_none()
                && (c.joined || c.state == State::Starting)
                && c.unjoined_instances.is_empty()
        })
    }
}

/// One component inside a system.
struct Slot {
    /// The handle's name (one allocation for both, and for the system's index).
    name: Arc<str>,
    spec: &'static Spec,
    /// Holds the component's ports too (`Handle::inputs`, `Handle::outputs`).
    handle: Handle,
    /// Boxed: once the thread runs, the slot keeps only the pointer's room (the
    /// system's table holds one slot per component for its whole life).
    runner: Option<Box<Runner>>,
    /// The execution group it runs in (an index into `System::groups`).
    group: Option<usize>,
}

impl Slot {
    fn input(&self, port: usize) -> &ErasedInput {
        &self.handle.inputs[port].1
    }

    fn output(&self, port: usize) -> &ErasedOutput {
        &self.handle.outputs[port].1
    }
}

/// An execution group: components that run on one thread (`System::group`).
struct GroupSlot {
    name: String,
    /// Its members, as given.
    members: Vec<usize>,
    /// The group's thread, once started and until joined.
    join: Option<std::thread::JoinHandle<()>>,
}

/// One connection.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Link {
    from: (usize, usize),
    to: (usize, usize),
}

/// Runs components: each added component gets its own named thread when started.
pub struct System {
    slots: Vec<Slot>,
    names: HashMap<Arc<str>, usize>,
    links: Vec<Link>,
    /// Connections a compound makes when it starts, after its groups' threads have
    /// started: each group's data-flow order counts them as made.
    planned: Vec<Link>,
    /// The connections a compound's substitutes take when they stand in: an
    /// execution group orders its members with them too, when they leave an order
    /// (they never make a group refuse to start).
    stand_ins: Vec<Link>,
    groups: Vec<GroupSlot>,
    started: bool,
    /// The clock the components' timers read (`crate::clock`).
    clock: Clock,
}

impl Default for System {
    fn default() -> Self {
        System::new()
    }
}

impl std::fmt::Debug for System {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("System")
            .field("components", &self.names.keys().collect::<Vec<_>>())
            .finish()
    }
}

/// A component checked against its spec and wired to its monitor, control port and
/// doorbell, with its runner not started: what [`System::add`] keeps in a slot, and
/// what a harness (`crate::harness`) drives on the caller's thread.
pub(crate) struct Prepared {
    pub(crate) name: String,
    pub(crate) spec: &'static Spec,
    pub(crate) handle: Handle,
    pub(crate) inputs: Vec<ErasedInput>,
    pub(crate) outputs: Vec<ErasedOutput>,
    pub(crate) runner: Runner,
}

/// Check `component` (name, spec, ports) and build its monitor, control port, handle
/// and runner.
pub(crate) fn prepare(component: Component) -> Result<Prepared, Error> {
    let timing = component.timing();
    let Component {
        name,
        automaton,
        ports,
        timing: _,
        instances,
        adaptation,
    } = component;
    if name.is_empty() || name.contains('.') {
        return Err(Error::InvalidName(name));
    }
    let spec = automaton.spec();
    if let Err(source) = spec.validate_with(&timing) {
        return Err(Error::InvalidSpec {
            component: name,
            source,
        });
    }
    let mismatch = |detail: String| Error::PortMismatch {
        component: name.clone(),
        detail,
    };
    if ports.inputs.len() != spec.inputs.len() {
        return Err(mismatch(format!(
            "{} input ports registered, the spec declares {}",
            ports.inputs.len(),
            spec.inputs.len()
        )));
    }
    if ports.outputs.len() != spec.outputs.len() {
        return Err(mismatch(format!(
            "{} output ports registered, the spec declares {}",
            ports.outputs.len(),
            spec.outputs.len()
        )));
    }
    for (port, declared) in ports.inputs.iter().zip(spec.inputs) {
        if !kind_matches_input(declared.kind, port.kind) {
            return Err(mismatch(format!(
                "input `{}` is declared {:?} but registered as {}",
                declared.name,
                declared.kind,
                port.kind.name()
            )));
        }
    }
    for (port, declared) in ports.outputs.iter().zip(spec.outputs) {
        if !kind_matches_output(declared.kind, port.kind) {
            return Err(mismatch(format!(
                "output `{}` is declared {:?} but registered as {}",
                declared.name,
                declared.kind,
                port.kind.name()
            )));
        }
    }
    for (port, declared) in ports.inputs.iter().zip(spec.inputs) {
        if port.core.owner.get().is_some() {
            return Err(Error::PortInUse {
                component: name.clone(),
                port: declared.name.to_owned(),
            });
        }
    }
    for (port, declared) in ports.outputs.iter().zip(spec.outputs) {
        if port.core.owner.get().is_some() {
            return Err(Error::PortInUse {
                component: name.clone(),
                port: declared.name.to_owned(),
            });
        }
    }

    let monitor = Monitor::starting(name.clone(), spec, &timing);
    let named_inputs = spec
        .inputs
        .iter()
        .map(|i| i.name)
        .zip(
            ports
                .inputs
                .iter()
                .map(|input| Arc::clone(&input.core) as Arc<dyn crate::monitor::Losses>),
        )
        .collect();
    let shared = Arc::new(Shared::new(monitor, named_inputs));
    let bell = crate::wake::Doorbell::new();
    // Response times (paper 3.6) are measured for an aperiodic component with a
    // `max_response`, at the inputs an `on` transition handles.
    let labeled = timing.period.is_none() && timing.max_response.is_some();
    let labels: Vec<Option<Arc<ArrivalLabel>>> = (0..spec.inputs.len())
        .map(|index| {
            let handled = spec
                .states
                .iter()
                .any(|state| state.on.iter().any(|on| on.port == index));
            (labeled && handled).then(|| Arc::new(ArrivalLabel::default()))
        })
        .collect();
    for ((port, declared), label) in ports.inputs.iter().zip(spec.inputs).zip(&labels) {
        let owner = Owner {
            bell: Arc::clone(&bell),
            shared: Arc::downgrade(&shared),
            port_name: declared.name,
            label: label.clone(),
        };
        if port.core.owner.set(owner).is_err() {
            return Err(Error::PortInUse {
                component: name.clone(),
                port: declared.name.to_owned(),
            });
        }
    }
    for (port, declared) in ports.outputs.iter().zip(spec.outputs) {
        let owner = Owner {
            bell: Arc::clone(&bell),
            shared: Arc::downgrade(&shared),
            port_name: declared.name,
            label: None,
        };
        if port.core.owner.set(owner).is_err() {
            return Err(Error::PortInUse {
                component: name.clone(),
                port: declared.name.to_owned(),
            });
        }
    }
    for (port, declared) in ports.outputs.iter().zip(spec.outputs) {
        if declared.pull {
            port.core.accept_pulls();
        }
    }
    let control = crate::mailbox::Mailbox::new(CONTROL_CAPACITY);
    let handle = Handle {
        name: Arc::from(name.as_str()),
        shared: Arc::clone(&shared),
        control: Arc::clone(&control),
        bell: Arc::clone(&bell),
        join: Arc::new(Mutex::new(None)),
        command_timeout: DEFAULT_COMMAND_TIMEOUT,
        instances: instances.into(),
        inputs: spec
            .inputs
            .iter()
            .map(|i| i.name)
            .zip(ports.inputs.iter().cloned())
            .collect(),
        outputs: spec
            .outputs
            .iter()
            .map(|o| o.name)
            .zip(ports.outputs.iter().cloned())
            .collect(),
        spec,
    };
    let mut runner = Runner::new(
        Arc::clone(&handle.name),
        automaton,
        timing,
        adaptation,
        shared,
        control,
        bell,
        ports.inputs.iter().map(|p| Arc::clone(&p.core)).collect(),
        ports.outputs.iter().map(|p| Arc::clone(&p.core)).collect(),
    );
    runner.set_labels(labels);
    Ok(Prepared {
        name,
        spec,
        handle,
        inputs: exact(ports.inputs),
        outputs: exact(ports.outputs),
        runner,
    })
}

fn exact<T>(mut ports: Vec<T>) -> Vec<T> {
    ports.shrink_to_fit();
    ports
}

fn kind_matches_input(spec: InputKind, erased: InKind) -> bool {
    matches!(
        (spec, erased),
        (InputKind::Tick, InKind::Tick)
            | (InputKind::Fifo { .. }, InKind::Fifo)
            | (InputKind::Ufifo { .. }, InKind::Ufifo)
            | (InputKind::Last, InKind::Last)
            | (InputKind::Poster, InKind::Poster)
    )
}

fn kind_matches_output(spec: OutputKind, erased: OutKind) -> bool {
    matches!(
        (spec, erased),
        (OutputKind::Tick, OutKind::Tick)
            | (OutputKind::Data, OutKind::Data)
            | (OutputKind::Poster, OutKind::Poster)
    )
}

impl System {
    /// An empty system.
    pub fn new() -> System {
        System {
            slots: Vec::new(),
            names: HashMap::new(),
            links: Vec::new(),
            planned: Vec::new(),
            stand_ins: Vec::new(),
            groups: Vec::new(),
            started: false,
            clock: Clock::real(),
        }
    }

    /// A system whose components' timers read `clock` (`crate::clock`: a
    /// [`VirtualClock`](crate::VirtualClock) for tests that step time by hand).
    pub fn with_clock(clock: Clock) -> System {
        let mut system = System::new();
        system.clock = clock;
        system
    }

    /// Put the components on `clock` (before they start: a compound's inner system,
    /// when the compound is put on a clock).
    pub(crate) fn set_clock(&mut self, clock: Clock) {
        self.clock = clock;
    }

    /// The clock the components' timers read.
    pub fn clock(&self) -> &Clock {
        &self.clock
    }

    /// Add a component; it starts with the system (or at once if the system has
    /// started). Duplicate names and ports that do not match the spec are rejected.
    pub fn add(&mut self, component: Component) -> Result<Handle, Error> {
        if self.names.contains_key(component.name.as_str()) {
            return Err(Error::DuplicateName(component.name));
        }
        let Prepared {
            spec,
            handle,
            runner,
            ..
        } = prepare(component)?;
        let index = self.slots.len();
        let name = Arc::clone(&handle.name);
        self.names.insert(Arc::clone(&name), index);
        self.slots.push(Slot {
            name,
            spec,
            handle: handle.clone(),
            runner: Some(Box::new(runner)),
            group: None,
        });
        if self.started {
            self.spawn(index)?;
        }
        Ok(handle)
    }

    /// Put the components `members` (added, atomic, not started) on one thread named
    /// after the group (`docs/runtime.md`, "Execution groups"): from
    /// [`System::start`] on, the thread runs each member's turn in data-flow order
    /// (a member after those connected to its inputs, else in the order given), and
    /// a packet one member sends is seen by the next one in the same pass. Each
    /// member keeps its own automaton, control and monitoring ports, timing and
    /// faults. A pull between two members, and a cycle of connections with no `last`
    /// or `poster` input on it, are refused when the group starts.
    pub fn group(&mut self, name: &str, members: &[&str]) -> Result<(), Error> {
        let refuse = |source: GroupError| Error::Group {
            group: name.to_owned(),
            source,
        };
        if members.is_empty() {
            return Err(refuse(GroupError::Empty));
        }
        if self.groups.iter().any(|group| group.name == name) {
            return Err(refuse(GroupError::DuplicateName));
        }
        let mut indices: Vec<usize> = Vec::with_capacity(members.len());
        for member in members {
            let Some(&index) = self.names.get(*member) else {
                return Err(refuse(GroupError::UnknownMember((*member).to_owned())));
            };
            let slot = &self.slots[index];
            if let Some(group) = slot.group {
                return Err(refuse(GroupError::TwiceGrouped {
                    member: (*member).to_owned(),
                    group: self.groups[group].name.clone(),
                }));
            }
            if indices.contains(&index) {
                return Err(refuse(GroupError::TwiceGrouped {
                    member: (*member).to_owned(),
                    group: name.to_owned(),
                }));
            }
            let Some(runner) = &slot.runner else {
                return Err(refuse(GroupError::Started((*member).to_owned())));
            };
            if runner.supervises() {
                return Err(refuse(GroupError::NotAtomic((*member).to_owned())));
            }
            indices.push(index);
        }
        let group = self.groups.len();
        for index in &indices {
            self.slots[*index].group = Some(group);
        }
        self.groups.push(GroupSlot {
            name: name.to_owned(),
            members: indices,
            join: None,
        });
        Ok(())
    }

    /// The members of group `group` in the order they run: data-flow order over the
    /// connections among them, ties in the order given. When the members left all
    /// wait for one another (a cycle), one connection among them into a `last` or
    /// `poster` input is set aside (the one of the earliest member given), and the
    /// sort goes on; connections off the cycle keep their order.
    fn group_order(&self, group: usize, planned: &[Link]) -> Result<Vec<usize>, GroupError> {
        let members = &self.groups[group].members;
        let mut edges: Vec<&Link> = self
            .links
            .iter()
            .chain(planned)
            .filter(|link| {
                link.from.0 != link.to.0
                    && members.contains(&link.from.0)
                    && members.contains(&link.to.0)
            })
            .collect();
        for link in &edges {
            let input = &self.slots[link.to.0].spec.inputs[link.to.1];
            if input.pull {
                return Err(GroupError::Pull {
                    input: self.address(link.to, false),
                    output: self.address(link.from, true),
                });
            }
            if let InputKind::Fifo {
                policy: OverflowPolicy::Block,
                ..
            } = input.kind
            {
                return Err(GroupError::Block {
                    input: self.address(link.to, false),
                    output: self.address(link.from, true),
                });
            }
        }
        let mut left: Vec<usize> = members.clone();
        let mut order = Vec::with_capacity(left.len());
        while !left.is_empty() {
            let waits = |member: usize, edges: &[&Link]| {
                edges
                    .iter()
                    .any(|link| link.to.0 == member && left.contains(&link.from.0))
            };
            if let Some(position) = left.iter().position(|member| !waits(*member, &edges)) {
                order.push(left.remove(position));
                continue;
            }
            // Whether `to` is reached from `from` over the connections among the
            // members left: a connection `u -> v` is on a cycle when `v` reaches `u`.
            let reaches = |from: usize, to: usize, edges: &[&Link]| {
                let mut seen = vec![from];
                let mut next = vec![from];
                while let Some(at) = next.pop() {
                    if at == to {
                        return true;
                    }
                    for link in edges {
                        if link.from.0 == at
                            && left.contains(&link.to.0)
                            && !seen.contains(&link.to.0)
                        {
                            seen.push(link.to.0);
                            next.push(link.to.0);
                        }
                    }
                }
                false
            };
            let breaking = left.iter().find_map(|member| {
                edges.iter().position(|link| {
                    link.to.0 == *member
                        && left.contains(&link.from.0)
                        && matches!(
                            self.slots[link.to.0].input(link.to.1).kind,
                            InKind::Last | InKind::Poster
                        )
                        && reaches(link.to.0, link.from.0, &edges)
                })
            });
            match breaking {
                Some(edge) => {
                    edges.swap_remove(edge);
                }
                None => {
                    return Err(GroupError::Cycle(
                        left.iter()
                            .map(|index| format!("`{}`", self.slots[*index].name))
                            .collect::<Vec<_>>()
                            .join(", "),
                    ));
                }
            }
        }
        Ok(order)
    }

    /// Check every execution group's connections as its start will (a pull between
    /// members, a cycle with nothing to break it), with the connections `planned`
    /// (`(output, input)` addresses: a compound's, made when it starts, after its
    /// groups' threads have started) as if made; keep them, so that each group's
    /// data-flow order counts them when its thread starts; and the connections
    /// `stand_ins` its substitutes take when they stand in, which the order counts
    /// too when it can (see `System::stand_ins`).
    pub(crate) fn plan_groups(
        &mut self,
        planned: &[(&str, &str)],
        stand_ins: &[(&str, &str)],
    ) -> Result<(), Error> {
        let links = |ends: &[(&str, &str)]| -> Vec<Link> {
            ends.iter()
                .filter_map(|(from, to)| {
                    Some(Link {
                        from: self.parse(from, true).ok()?,
                        to: self.parse(to, false).ok()?,
                    })
                })
                .collect()
        };
        let (planned, stand_ins) = (links(planned), links(stand_ins));
        for group in 0..self.groups.len() {
            self.group_order(group, &planned)
                .map_err(|source| Error::Group {
                    group: self.groups[group].name.clone(),
                    source,
                })?;
        }
        self.planned = planned;
        self.stand_ins = stand_ins;
        Ok(())
    }

    /// `instance.port` of an output (`output`) or an input.
    fn address(&self, (slot, port): (usize, usize), output: bool) -> String {
        let spec = self.slots[slot].spec;
        let port = if output {
            spec.outputs[port].name
        } else {
            spec.inputs[port].name
        };
        format!("{}.{}", self.slots[slot].name, port)
    }

    /// Start group `group`'s thread with its members' runners.
    fn spawn_group(&mut self, group: usize) -> Result<(), Error> {
        if self.groups[group].join.is_some() {
            return Ok(());
        }
        let order = self
            .group_order(group, &self.planned)
            .map_err(|source| Error::Group {
                group: self.groups[group].name.clone(),
                source,
            })?;
        // A substitute among the members runs where its original's connections put
        // it, if those leave an order; otherwise the order stands as it is.
        let order = if self.stand_ins.is_empty() {
            order
        } else {
            let mut with = self.planned.clone();
            with.extend(self.stand_ins.iter().cloned());
            self.group_order(group, &with).unwrap_or(order)
        };
        let mut runners = Vec::with_capacity(order.len());
        for index in &order {
            if let Some(mut runner) = self.slots[*index].runner.take() {
                if !self.clock.is_real() {
                    runner.set_clock(self.clock.clone());
                    runner.join_clock();
                }
                runners.push(runner);
            }
        }
        let name = self.groups[group].name.clone();
        let body = crate::runner::group::Group::new(&name, runners);
        let join =
            crate::thread::spawn(&name, move || body.run()).map_err(|source| Error::Spawn {
                component: name.clone(),
                source,
            })?;
        for index in &order {
            let shared = &self.slots[*index].handle.shared;
            let _ = shared.thread.set(join.thread().id());
            shared.spawned.store(true, Ordering::Release);
        }
        self.groups[group].join = Some(join);
        Ok(())
    }

    fn spawn(&mut self, index: usize) -> Result<(), Error> {
        if let Some(group) = self.slots[index].group {
            return self.spawn_group(group);
        }
        let slot = &mut self.slots[index];
        let Some(mut runner) = slot.runner.take() else {
            return Ok(());
        };
        // (A compound puts its instances on the same clock.)
        if !self.clock.is_real() {
            runner.set_clock(self.clock.clone());
            runner.join_clock();
        }
        let join = crate::thread::spawn(&slot.name, move || runner.run()).map_err(|source| {
            Error::Spawn {
                component: slot.name.to_string(),
                source,
            }
        })?;
        let _ = slot.handle.shared.thread.set(join.thread().id());
        *slot
            .handle
            .join
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = Some(join);
        slot.handle.shared.spawned.store(true, Ordering::Release);
        Ok(())
    }

    /// Spawn every component's thread. Each runs its `start` hook and goes to `ready`
    /// (or `starting_error`); send `running` through its handle, or call
    /// [`System::run_all`], to run the user automata.
    pub fn start(&mut self) -> Result<(), Error> {
        self.started = true;
        for index in 0..self.slots.len() {
            self.spawn(index)?;
        }
        Ok(())
    }

    /// Start (if needed), wait for every component to leave `starting`, and command
    /// every `ready` component to `running`.
    pub fn run_all(&mut self) -> Result<(), Error> {
        self.start()?;
        // The commands go out as the components become ready and are all answered
        // afterwards, so that the components run their transitions in parallel.
        let mut posted = Vec::new();
        for slot in &self.slots {
            let monitor = slot
                .handle
                .wait_for(|m| m.state != State::Starting, SHUTDOWN_TIMEOUT)
                .map_err(|t| Error::Timeout {
                    component: slot.name.to_string(),
                    state: t.last.state,
                    wanted: State::Ready,
                    waited: t.waited,
                })?;
            if monitor.state == State::Ready {
                posted.push((
                    &slot.handle,
                    slot.handle
                        .post(crate::Command::SetState(Controllable::Running))?,
                ));
            }
        }
        for (handle, posted) in posted {
            handle.finish(posted)?;
        }
        Ok(())
    }

    /// The component at `path`: a component of this system (`"base"`) or an instance
    /// inside it, through nested compounds (`"base.motion"`, see [`Handle::instance`]).
    pub fn handle_at(&self, path: &str) -> Option<Handle> {
        let (first, rest) = match path.split_once('.') {
            Some((first, rest)) => (first, Some(rest)),
            None => (path, None),
        };
        let handle = self.handle(first)?;
        match rest {
            Some(rest) => handle.instance(rest),
            None => Some(handle),
        }
    }

    /// The control and monitoring ports of component `name`.
    pub fn handle(&self, name: &str) -> Option<Handle> {
        self.names
            .get(name)
            .map(|&index| self.slots[index].handle.clone())
    }

    /// The names of the components, in the order they were added.
    pub fn names(&self) -> Vec<&str> {
        self.slots.iter().map(|slot| &*slot.name).collect()
    }

    fn parse(&self, address: &str, output: bool) -> Result<(usize, usize), ConnectError> {
        let Some((instance, port)) = address.split_once('.') else {
            return Err(ConnectError::BadAddress {
                address: address.to_owned(),
            });
        };
        let Some(&index) = self.names.get(instance) else {
            return Err(ConnectError::UnknownInstance {
                address: address.to_owned(),
                instance: instance.to_owned(),
            });
        };
        let spec = self.slots[index].spec;
        let port_index = if output {
            spec.output_index(port)
        } else {
            spec.input_index(port)
        };
        match port_index {
            Some(port_index) => Ok((index, port_index)),
            None => Err(ConnectError::UnknownPort {
                address: address.to_owned(),
                instance: instance.to_owned(),
                type_name: spec.type_name.to_owned(),
                direction: if output { "output" } else { "input" },
                port: port.to_owned(),
            }),
        }
    }

    /// Resolve both ends and check every rule except the packet types.
    fn check(&self, from: &str, to: &str) -> Result<Link, ConnectError> {
        let (out_slot, out_port) = self.parse(from, true)?;
        let (in_slot, in_port) = self.parse(to, false)?;
        let link = Link {
            from: (out_slot, out_port),
            to: (in_slot, in_port),
        };
        let output = &self.slots[out_slot].output(out_port);
        let input = &self.slots[in_slot].input(in_port);
        let (from, to) = (from.to_owned(), to.to_owned());
        let allowed = match output.kind {
            OutKind::Tick => "tick",
            OutKind::Data => "last, fifo and ufifo",
            OutKind::Poster => "poster",
        };
        let kinds_ok = matches!(
            (output.kind, input.kind),
            (OutKind::Tick, InKind::Tick)
                | (OutKind::Poster, InKind::Poster)
                | (OutKind::Data, InKind::Last | InKind::Fifo | InKind::Ufifo)
        );
        if !kinds_ok {
            return Err(ConnectError::KindMismatch {
                from,
                to,
                from_kind: output.kind.name(),
                to_kind: input.kind.name(),
                allowed,
            });
        }
        if self.links.contains(&link) {
            return Err(ConnectError::AlreadyConnected { from, to });
        }
        let address = |(slot, port): (usize, usize), output: bool| {
            let spec = self.slots[slot].spec;
            let port = if output {
                spec.outputs[port].name
            } else {
                spec.inputs[port].name
            };
            format!("{}.{}", self.slots[slot].name, port)
        };
        match input.kind {
            InKind::Last | InKind::Poster => {
                if let Some(existing) = self.links.iter().find(|l| l.to == link.to) {
                    return Err(ConnectError::Cardinality {
                        from,
                        to,
                        rule: format!(
                            "a {} connection is 1 output to N inputs, and `{}` is already fed by `{}`",
                            input.kind.name(),
                            address(existing.to, false),
                            address(existing.from, true)
                        ),
                    });
                }
            }
            // A data output feeds any number of fifo and ufifo inputs (each with its
            // own queue), and a queue input takes any number of producers.
            InKind::Fifo | InKind::Ufifo | InKind::Tick => {}
        }
        let input_pull = self.slots[in_slot].spec.inputs[in_port].pull;
        let output_pull = self.slots[out_slot].spec.outputs[out_port].pull;
        if input_pull && !output_pull {
            return Err(ConnectError::PullMismatch { from, to });
        }
        if input_pull
            && out_slot != in_slot
            && let (Some(a), Some(b)) = (self.slots[out_slot].group, self.slots[in_slot].group)
            && a == b
        {
            return Err(ConnectError::PullInGroup {
                from,
                to,
                group: self.groups[a].name.clone(),
            });
        }
        if let InputKind::Fifo {
            policy: OverflowPolicy::Block,
            ..
        } = self.slots[in_slot].spec.inputs[in_port].kind
            && out_slot != in_slot
            && let (Some(a), Some(b)) = (self.slots[out_slot].group, self.slots[in_slot].group)
            && a == b
        {
            return Err(ConnectError::BlockInGroup {
                from,
                to,
                group: self.groups[a].name.clone(),
            });
        }
        Ok(link)
    }

    /// Connect output `from` to input `to` (both `instance.port`). Kinds, cardinality,
    /// the pull model and the packet types are checked. Works before and while running;
    /// no packet already queued is lost.
    pub fn connect(&mut self, from: &str, to: &str) -> Result<(), ConnectError> {
        let link = self.check(from, to)?;
        let output = &self.slots[link.from.0].output(link.from.1);
        let input = &self.slots[link.to.0].input(link.to.1);
        if output.type_id != input.type_id || !output.link(input) {
            return Err(ConnectError::TypeMismatch {
                from: from.to_owned(),
                to: to.to_owned(),
                from_type: output.type_name.to_owned(),
                to_type: input.type_name.to_owned(),
            });
        }
        self.links.push(link);
        Ok(())
    }

    /// Connect output `from` (packets of `A`) to input `to` (packets of `B`) through
    /// `convert` (a `.cool` `converter`), applied on the producer's thread at each send
    /// (data) or on the consumer's thread at each read (poster).
    pub fn connect_via<A: Packet, B: Packet>(
        &mut self,
        from: &str,
        to: &str,
        convert: impl Fn(&A) -> B + Send + Sync + 'static,
    ) -> Result<(), ConnectError> {
        let link = self.check(from, to)?;
        let output = &self.slots[link.from.0].output(link.from.1);
        let input = &self.slots[link.to.0].input(link.to.1);
        let linked = output.type_id == TypeId::of::<A>()
            && input.type_id == TypeId::of::<B>()
            && output.kind != OutKind::Tick
            && crate::port::link_converted::<A, B>(output, input, Arc::new(convert));
        if !linked {
            return Err(ConnectError::ConverterMismatch {
                from: from.to_owned(),
                to: to.to_owned(),
                converter: format!(
                    "{} -> {}",
                    std::any::type_name::<A>(),
                    std::any::type_name::<B>()
                ),
                ports: format!("{} -> {}", output.type_name, input.type_name),
            });
        }
        self.links.push(link);
        Ok(())
    }

    /// Remove the connection from `from` to `to`. Packets already queued at the input
    /// stay there; a last input keeps its local copy.
    pub fn disconnect(&mut self, from: &str, to: &str) -> Result<(), ConnectError> {
        let (out_slot, out_port) = self.parse(from, true)?;
        let (in_slot, in_port) = self.parse(to, false)?;
        let link = Link {
            from: (out_slot, out_port),
            to: (in_slot, in_port),
        };
        let Some(position) = self.links.iter().position(|l| *l == link) else {
            return Err(ConnectError::NotConnected {
                from: from.to_owned(),
                to: to.to_owned(),
            });
        };
        self.links.remove(position);
        let output = &self.slots[out_slot].output(out_port);
        let input = &self.slots[in_slot].input(in_port);
        output.unlink(input);
        Ok(())
    }

    /// The input port at `instance.port`.
    pub(crate) fn input_port(&self, address: &str) -> Result<ErasedInput, ConnectError> {
        let (slot, port) = self.parse(address, false)?;
        Ok(self.slots[slot].input(port).clone())
    }

    /// The output port at `instance.port`.
    pub(crate) fn output_port(&self, address: &str) -> Result<ErasedOutput, ConnectError> {
        let (slot, port) = self.parse(address, true)?;
        Ok(self.slots[slot].output(port).clone())
    }

    /// Replace the connection `old` (`(output, input)` addresses) by one from `from`
    /// to `to`, made by `make(output, input, same_output_old_input)`, so that no
    /// packet is lost: with the same output, `make` swaps the sink in one step and
    /// moves the packets queued at the old input (`ErasedOutput::relink`,
    /// `port::relink_converted`); with another output (a producer replaced), the new
    /// connection is made before the old one is removed, and the packets queued at
    /// the old input, if it changed too, are moved to the new one. Compounds use it
    /// when an instance's stand-in changes.
    pub(crate) fn replace_link(
        &mut self,
        old: (&str, &str),
        from: &str,
        to: &str,
        make: &dyn Fn(&ErasedOutput, &ErasedInput, Option<&ErasedInput>) -> bool,
    ) -> Result<(), ConnectError> {
        let old_link = Link {
            from: self.parse(old.0, true)?,
            to: self.parse(old.1, false)?,
        };
        let Some(position) = self.links.iter().position(|l| *l == old_link) else {
            return Err(ConnectError::NotConnected {
                from: old.0.to_owned(),
                to: old.1.to_owned(),
            });
        };
        self.links.remove(position);
        let link = match self.check(from, to) {
            Ok(link) => link,
            Err(error) => {
                self.links.insert(position, old_link);
                return Err(error);
            }
        };
        let output = &self.slots[link.from.0].output(link.from.1);
        let input = &self.slots[link.to.0].input(link.to.1);
        let old_output = &self.slots[old_link.from.0].output(old_link.from.1);
        let old_input = &self.slots[old_link.to.0].input(old_link.to.1);
        let made = if old_link.from == link.from {
            old_link.to == link.to || make(output, input, Some(old_input))
        } else if make(output, input, None) {
            old_output.unlink(old_input);
            if old_link.to != link.to {
                old_input.transfer_to(input);
            }
            true
        } else {
            false
        };
        if !made {
            self.links.insert(position, old_link);
            return Err(ConnectError::TypeMismatch {
                from: from.to_owned(),
                to: to.to_owned(),
                from_type: output.type_name.to_owned(),
                to_type: input.type_name.to_owned(),
            });
        }
        self.links.push(link);
        Ok(())
    }

    /// Empty the queues at every input of component `name` (retired by a compound),
    /// counting their packets as lost there (overflows, announced). Returns how many.
    pub(crate) fn discard_queued(&self, name: &str) -> u64 {
        self.slots
            .iter()
            .filter(|slot| &*slot.name == name)
            .flat_map(|slot| slot.handle.inputs.iter())
            .map(|(_, input)| input.discard_queued())
            .sum()
    }

    /// The packets the inputs of component `name` were left out of so far by a
    /// compound's exported input (it stalled in a redundant group).
    pub(crate) fn left_behind(&self, name: &str) -> u64 {
        self.slots
            .iter()
            .filter(|slot| &*slot.name == name)
            .flat_map(|slot| slot.handle.inputs.iter())
            .map(|(_, input)| input.core.left_behind())
            .sum()
    }

    /// The connections, as `(output address, input address)` pairs.
    pub fn connections(&self) -> Vec<(String, String)> {
        self.links
            .iter()
            .map(|link| {
                let out = &self.slots[link.from.0];
                let inp = &self.slots[link.to.0];
                (
                    format!("{}.{}", out.name, out.spec.outputs[link.from.1].name),
                    format!("{}.{}", inp.name, inp.spec.inputs[link.to.1].name),
                )
            })
            .collect()
    }

    /// Take every component to `dead` and join every thread. Dropping the system does
    /// the same. The system is consumed: nothing can be added or connected afterwards.
    ///
    /// ```compile_fail
    /// let system = coolbot::System::new();
    /// let report = system.shutdown();
    /// system.handle("motion"); // error: the system was moved into `shutdown`
    /// ```
    pub fn shutdown(mut self) -> Report {
        self.stop_all(crate::time::later(Instant::now(), SHUTDOWN_TIMEOUT))
    }

    /// [`System::shutdown`], giving up on threads not ended by `deadline` (a
    /// compound's shutdown of its instances, within its own budget).
    pub(crate) fn shutdown_by(mut self, deadline: Instant) -> Report {
        self.stop_all(deadline)
    }

    /// The components are about to be shut down: on a virtual clock, a section of
    /// theirs taking the clock's time (`Context::spend`) would wait for an advance
    /// that may never come; it returns now, and any later one at once.
    pub(crate) fn release_spending(&self) {
        if let Some(clock) = self.clock.as_virtual() {
            let bells: Vec<&Arc<crate::wake::Doorbell>> =
                self.slots.iter().map(|slot| &slot.handle.bell).collect();
            clock.release(&bells);
        }
    }

    fn stop_all(&mut self, deadline: Instant) -> Report {
        let mut report = Report::default();
        self.release_spending();
        // Tell everyone first, so that components stop in parallel.
        for slot in &self.slots {
            if slot.runner.is_none() {
                let (message, _answers) = crate::handle::ControlMessage::new(
                    crate::Command::SetState(Controllable::Dead),
                    false,
                );
                // A closed control queue: the component is dead already (a compound
                // that stops sends its instances to `dead` before its system stops).
                match slot.handle.post_control(message) {
                    Ok(()) | Err(crate::mailbox::PostError::Closed) => {}
                    Err(error) => tracing::warn!(
                        component = %slot.handle.name(),
                        "`dead` not queued at shutdown: {error:?}"
                    ),
                }
                slot.handle.bell.ring_command();
            }
        }
        // A group thread ends when its last member is dead.
        let mut group_ends: Vec<(bool, Option<String>)> = Vec::with_capacity(self.groups.len());
        for group in &mut self.groups {
            let end = match group.join.take() {
                None => (false, None),
                Some(join) => {
                    while !join.is_finished() && Instant::now() < deadline {
                        std::thread::sleep(Duration::from_millis(1));
                    }
                    if join.is_finished() {
                        match crate::thread::join(join) {
                            Ok(()) => (true, None),
                            Err(message) => (true, Some(message)),
                        }
                    } else {
                        group.join = Some(join);
                        (false, None)
                    }
                }
            };
            group_ends.push(end);
        }
        for slot in &mut self.slots {
            let mut joined = false;
            let mut thread_panic = None;
            if let Some(group) = slot.group {
                if slot.runner.take().is_none() {
                    (joined, thread_panic) = group_ends[group].clone();
                }
            } else if slot.runner.take().is_none() {
                match slot.handle.join_if_exited(deadline) {
                    Some(Ok(())) => joined = true,
                    Some(Err(message)) => {
                        joined = true;
                        thread_panic = Some(message);
                    }
                    // Already joined by a `dead` command, or stuck past the deadline.
                    None => {
                        joined = slot
                            .handle
                            .join
                            .lock()
                            .unwrap_or_else(PoisonError::into_inner)
                            .is_none()
                            && slot.handle.shared.state() == State::Dead
                    }
                }
            }
            let monitor = slot.handle.snapshot();
            let unjoined_instances = if monitor.state == State::Starting {
                Vec::new()
            } else {
                slot.handle.unended_instances()
            };
            report.components.push(ComponentReport {
                name: slot.name.to_string(),
                state: monitor.state,
                result: monitor.result,
                error: monitor.error,
                joined,
                thread_panic,
                unjoined_instances,
            });
        }
        self.slots.clear();
        self.names.clear();
        self.links.clear();
        self.groups.clear();
        report
    }
}

impl Drop for System {
    fn drop(&mut self) {
        if !self.slots.is_empty() {
            let _ = self.stop_all(crate::time::later(Instant::now(), SHUTDOWN_TIMEOUT));
        }
    }
}
