//! Compound components (paper 3.4, 3.5): local instances, their connections, a
//! supervisor whose rules watch the instances, and the fault policies (propagate,
//! restart, substitute, ignore) with the recovery queue and redundant groups.
//!
//! A compound is built by [`CompoundBuilder::build`] into an ordinary [`Component`]:
//! it runs on its own thread through the same runner, default automaton
//! ([`crate::table::next`]), control and monitoring ports as an atomic component, so
//! nothing outside can tell them apart. Its code is a `Compound` automaton that owns
//! an inner [`System`] with the instances; the runner's compound hooks
//! ([`Automaton::before_running`], [`Automaton::after_transition`],
//! [`Automaton::supervise`], [`Automaton::wake_at`]) let the instances follow the
//! compound's state and let the supervisor react to their monitoring events.
//! `docs/runtime.md` ("Compound components and supervisors") tells the semantics.

use std::collections::{BTreeSet, HashMap, HashSet};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crossbeam_channel::Receiver;

use crate::adapt::{
    AdaptAction, AdaptConfig, Adaptation, Decision, Levels, Member, Pressure, ProtectPriority,
    Selector,
};
use crate::automaton::{Automaton, Context, Fault, Section, SectionResult, TaskResult};
use crate::commander::{Commander, DEFAULT_SUPERVISOR_COMMAND_TIMEOUT};
use crate::monitor::{Command, Handle, Monitor, MonitorEvent, Step, Supervision};
use crate::port::{
    DataOut, ErasedInput, ErasedOutput, FifoIn, InputPort, LastIn, MergeEnd, OutputPort, Packet,
    Parcel, PosterIn, PosterOut, PullRoute, TickIn, TickOut, UfifoIn,
};
use crate::spec::{InputKind, InputSpec, OutputKind, OutputSpec};
use crate::spec::{Spec, VarKind, VarSpec};
use crate::system::{Component, ConnectError, PortSet, System};
use crate::table::{Controllable, State};
use crate::value::Value;

/// How soon the compound's thread retries passing on packets that an instance's full
/// `Block` fifo could not take (they wait at the compound's exported input).
const EXPORT_RETRY: Duration = Duration::from_millis(1);

/// The period of a supervisor's `periodic;` sections when neither the state nor the
/// supervisor's `timing` gives one (`docs/language.md`, "The supervisor").
pub const DEFAULT_SUPERVISION_PERIOD: Duration = Duration::from_millis(100);

/// How long a compound waits for one of its instances to leave `starting`.
pub const INSTANCE_START_TIMEOUT: Duration = Duration::from_secs(5);

/// The default restart budget ([`CompoundBuilder::restart_budget`]): at most this many
/// restarts of one instance ...
pub const DEFAULT_RESTARTS: u32 = 5;
/// ... within this window; one more failure in the window propagates.
pub const DEFAULT_RESTART_WINDOW: Duration = Duration::from_secs(10);
/// The default restart backoff ([`CompoundBuilder::restart_backoff`]): the first
/// restart in a window is immediate, the second waits this long, each further one
/// twice as long as the one before ...
pub const DEFAULT_BACKOFF: Duration = Duration::from_millis(10);
/// ... up to this.
pub const DEFAULT_BACKOFF_MAX: Duration = Duration::from_secs(1);

/// What a compound does when one of its instances goes to `running_error`
/// (`on error inst: <policy>;`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Policy {
    /// The compound goes to `running_error` too; its own supervisor (its parent) hears
    /// it on the compound's monitoring port. The default.
    #[default]
    Propagate,
    /// The instance is commanded back to `running` (a restart through `start`), within
    /// the compound's restart budget ([`CompoundBuilder::restart_budget`], with a
    /// backoff: [`CompoundBuilder::restart_backoff`]); a failure beyond the budget
    /// propagates. An instance stuck in a section that overran `max_response` is
    /// restarted when the section returns.
    Restart,
    /// The declared substitute takes the instance's place and the instance goes into
    /// the recovery queue (without a substitute: the recovery queue only).
    Substitute,
    /// Nothing happens; the instance stays in `running_error` (rules can see it).
    Ignore,
}

/// The supervisor of a compound: its user automaton (states and sections, like an
/// atomic component's) and its own variables. Transitions are fired by rules
/// ([`CompoundBuilder::rule`]), not by ports.
pub trait Supervisor: Send + 'static {
    /// The supervisor's shape: `states` (with their `on`, `after` and `may`),
    /// `initial`, its own `variables` and `timing` (a period for periodic sections).
    /// Its ports are replaced by the ones the builder exports; exceptions are not
    /// used.
    fn spec(&self) -> &'static Spec;

    /// Run one section of one supervisor state.
    fn section(
        &mut self,
        _state: usize,
        _section: Section,
        _cx: &mut SupervisorCx<'_>,
    ) -> SectionResult {
        Ok(())
    }

    /// The value of own variable `variable` (an index into `spec().variables`).
    fn get(&self, _variable: usize) -> Value {
        Value::Unit
    }

    /// Set own controllable variable `variable`.
    fn set(&mut self, variable: usize, _value: &Value) -> Result<(), String> {
        Err(format!("variable #{variable} cannot be set"))
    }

    /// For states with `may` (`spec().states[state].may`): called after each entry or
    /// periodic section of `state`, the target to go to (one of the state's `may`
    /// targets, an index into `spec().states`), if any. The default stays.
    fn choose(&mut self, _state: usize, _cx: &mut SupervisorCx<'_>) -> Option<usize> {
        None
    }
}

/// What a supervisor section sees: the runtime context, the view of the instances'
/// monitors, and the commander of its instances.
pub struct SupervisorCx<'a> {
    /// Time, result, end, period of the compound.
    pub rt: &'a mut Context,
    /// The instances' monitors and the supervisor's own variables, as last seen.
    pub view: &'a View,
    /// Commands to the instances (state, variables, configuration, period,
    /// quality), each answered, each a supervision step (`crate::commander`).
    pub instances: &'a mut Commander,
}

/// The variables rules read: every instance's monitor (its `state`, `user_state`,
/// `result`, `error` and variables) and the supervisor's own variables.
#[derive(Debug, Clone, Default)]
pub struct View {
    instances: Vec<Monitor>,
    /// Each instance's position in `instances`, by name: a rule's lookup costs one
    /// hash, not a scan of every instance.
    positions: HashMap<String, usize>,
    own: Vec<(String, Value)>,
    /// The compound's mapped variables: name -> (declared instance, its variable).
    mapped: HashMap<String, (usize, String)>,
    /// The instance standing for each instance now (itself, its substitute, or its
    /// redundant group's live member).
    standing: Vec<usize>,
    /// The compound's own default observable variables, as last seen.
    compound: Own,
}

/// The compound's own default observable variables that rules read (`result`,
/// `error`, `quality`, `cpu_time`, `elapsed_time`), copied from its monitoring port
/// at each supervision turn of a compound whose rules read them.
#[derive(Debug, Clone, Default, PartialEq)]
struct Own {
    result: TaskResult,
    error: Option<String>,
    quality: usize,
    cpu_time: Duration,
    elapsed_time: Duration,
}

/// The read keys of the compound's own default variables (`CompoundBuilder::rule`).
const OWN_DEFAULTS: [&str; 5] = ["result", "error", "quality", "cpu_time", "elapsed_time"];

/// Whether read key `read` names a time (`cpu_time`, `elapsed_time`, own or an
/// instance's), which changes without an event: such rules are evaluated every
/// supervisor period.
fn is_timed(read: &str) -> bool {
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
    /// [`Context::set_result`]), as of the current supervision turn.
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

type Test = Box<dyn Fn(&View) -> bool + Send>;

/// How a converted connection is made, with the converter's packet types and function
/// captured: `System::connect_via` (no old connection), or in place of the connection
/// `Some((from, to))` in one step (`System::replace_link`).
type Via = Arc<
    dyn Fn(&mut System, Option<(&str, &str)>, &str, &str) -> Result<(), ConnectError> + Send + Sync,
>;

/// A converter's connection made between two erased ports directly (a redundant
/// group's merged output, which is no port of the inner system, to a consumer).
type LinkVia = Arc<dyn Fn(&ErasedOutput, &ErasedInput) -> bool + Send + Sync>;

/// A declared connection (`instance.port` ends), through a converter or not.
#[derive(Clone)]
struct Link {
    from: String,
    to: String,
    via: Option<Via>,
    link_via: Option<LinkVia>,
}

impl Link {
    fn ends(&self) -> (&str, &str) {
        (&self.from, &self.to)
    }
}

/// One rule: in supervisor state `state`, when `test` holds, go to `target`.
struct Rule {
    state: usize,
    target: usize,
    reads: Vec<String>,
    test: Test,
}

/// Why a compound could not be built.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CompoundError {
    /// The supervisor's spec is inconsistent.
    #[error("compound `{compound}`: supervisor: {detail}")]
    Supervisor {
        /// The compound.
        compound: String,
        /// What is wrong.
        detail: String,
    },
    /// An instance could not be added (duplicate name, bad spec, ports).
    #[error("compound `{compound}`: {detail}")]
    Instance {
        /// The compound.
        compound: String,
        /// The system's error.
        detail: String,
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
    #[error("compound `{compound}`: {detail}")]
    Connect {
        /// The compound.
        compound: String,
        /// The connection error.
        detail: String,
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

/// Where an instance stands in the compound's arrangement.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Status {
    /// Part of the arrangement: runs when the compound runs.
    Active,
    /// A declared substitute not in use: started (`ready`), not running.
    Standby,
    /// In the recovery queue.
    Recovering,
    /// Its recovery deadline expired: commanded to `dead`.
    Destroyed,
}

struct Instance {
    name: String,
    spec: &'static Spec,
    /// Its quality levels: its component's, or its `timing` override's.
    levels: usize,
    handle: Handle,
    policy: Policy,
    /// The instance this one substitutes.
    substitutes: Option<usize>,
    /// This instance's substitute.
    substitute: Option<usize>,
    /// Its redundant group.
    group: Option<usize>,
    status: Status,
    /// When the `restart` policy last restarted it (within the budget's window).
    restarts: std::collections::VecDeque<Instant>,
    /// A restart decided but not done yet (backoff, or the instance is stuck).
    pending: Option<PendingRestart>,
    /// Its current fault was handled (its policy ran): cleared when it leaves
    /// `running_error`/`starting_error`, or is commanded back to `running`. Later
    /// events of the same fault (a watchdog trip, then the section's return) are not
    /// a new fault.
    handled: bool,
}

/// A restart the `restart` policy has decided.
#[derive(Debug, Clone, Copy)]
struct PendingRestart {
    /// When the fault was seen.
    since: Instant,
    /// Not before then (the backoff).
    due: Instant,
}

/// The `restart` policy's limits.
#[derive(Debug, Clone, Copy)]
struct Budget {
    restarts: u32,
    window: Duration,
    backoff: Duration,
    backoff_max: Duration,
}

impl Budget {
    /// The backoff before restart number `done + 1` within the window.
    fn delay(&self, done: usize) -> Duration {
        if done == 0 {
            return Duration::ZERO;
        }
        let doublings = u32::try_from(done - 1).unwrap_or(u32::MAX).min(30);
        self.backoff
            .saturating_mul(1 << doublings)
            .min(self.backoff_max)
    }
}

/// An entry of the recovery queue.
#[derive(Debug, Clone, Copy)]
struct Recovering {
    instance: usize,
    since: Instant,
    next: Instant,
    /// Restarted at the last retry: recovered if still running at the next one.
    probation: bool,
}

/// A variable of the compound mapped onto an instance's.
struct Mapped {
    instance: usize,
    variable: String,
}

/// An exported port: the compound's own port, following the instance port it stands
/// for (or whoever stands for that instance now).
trait Export: Send {
    /// The instance port, as declared (`instance.port`).
    fn target(&self) -> &str;
    /// Inputs: move what arrived at the compound's port on to the instance's, without
    /// waiting: what a full `Block` fifo cannot take now stays at the compound's port.
    fn forward(&mut self) {}
    /// Inputs: packets stayed at the compound's port at the last `forward` (the
    /// compound's thread retries soon).
    fn held(&self) -> bool {
        false
    }
    /// Whether this is an exported input.
    fn is_input(&self) -> bool;
    /// Inputs: feed the instance inputs `inputs` (one, or every live member of a
    /// redundant group).
    fn follow_inputs(&mut self, _inputs: Vec<ErasedInput>) -> Result<(), String> {
        Err("not an exported input".to_owned())
    }
    /// Outputs: follow `output` (the instance's output, or a redundant group's merged
    /// stream).
    fn follow_output(&mut self, _output: ErasedOutput) -> Result<(), String> {
        Err("not an exported output".to_owned())
    }
}

/// A redundant group's data output merged into one stream (`port::MergeEnd`).
struct MergedPort {
    group: usize,
    port: String,
    merge: Arc<dyn MergeEnd>,
}

/// The compound's own end of an exported input of packets `T`, with the relay output
/// that feeds the instance's input.
enum Twin<T> {
    Fifo(FifoIn<T>, DataOut<T>),
    Ufifo(UfifoIn<T>, DataOut<T>),
    Last(LastIn<T>, DataOut<T>),
    Poster(PosterIn<T>, PosterOut<T>),
}

impl<T: Packet> Twin<T> {
    /// The compound's input, erased.
    fn input(&self) -> ErasedInput {
        match self {
            Twin::Fifo(input, _) => input.erased(),
            Twin::Ufifo(input, _) => input.erased(),
            Twin::Last(input, _) => input.erased(),
            Twin::Poster(input, _) => input.erased(),
        }
    }

    /// The relay, erased.
    fn relay(&self) -> ErasedOutput {
        match self {
            Twin::Fifo(_, relay) | Twin::Ufifo(_, relay) | Twin::Last(_, relay) => relay.erased(),
            Twin::Poster(_, relay) => relay.erased(),
        }
    }
}

/// An exported input of packets `T`: what arrives at the compound's port is passed on
/// through a relay output connected to the instance's input (a poster input's post is
/// posted again on a relay poster output).
struct InputExport<T> {
    target: String,
    twin: Twin<T>,
    linked: Vec<ErasedInput>,
    /// Packets stayed at the compound's port at the last `forward`.
    held: bool,
}

/// A relay whose pull requests (from the instance's `pull` input) become requests of
/// the compound's input `twin` to its own producers.
fn route_pulls(relay: &ErasedOutput, twin: &ErasedInput) {
    relay
        .core
        .set_route(PullRoute::Input(Arc::clone(&twin.core)));
}

/// Connect `relay` to the inputs `new`: one input replacing another moves there with
/// what is queued (a stand-in takes over); otherwise inputs no longer fed are
/// unlinked and new ones linked (a redundant group's live members).
fn follow_input(
    relay: &ErasedOutput,
    linked: &mut Vec<ErasedInput>,
    new: Vec<ErasedInput>,
) -> Result<(), String> {
    let mismatch = || "the exported input does not match the instance's".to_owned();
    if let ([old], [input]) = (linked.as_slice(), new.as_slice()) {
        if old.core.id != input.core.id && !relay.relink(old, input) {
            return Err(mismatch());
        }
        *linked = new;
        return Ok(());
    }
    for input in &new {
        if !linked.iter().any(|l| l.core.id == input.core.id) && !relay.link(input) {
            return Err(mismatch());
        }
    }
    for old in linked.iter() {
        if !new.iter().any(|n| n.core.id == old.core.id) {
            relay.unlink(old);
        }
    }
    *linked = new;
    Ok(())
}

impl<T: Packet> Export for InputExport<T> {
    fn target(&self) -> &str {
        &self.target
    }

    fn forward(&mut self) {
        // A fifo with the `Block` policy would make the compound's thread wait while
        // it is full (its instance may hang): only what it has room for goes now.
        let mut room = self
            .linked
            .iter()
            .filter_map(ErasedInput::room)
            .min()
            .unwrap_or(usize::MAX);
        // Packets pass on as they were queued: a packet its producer shares with
        // other inputs stays shared (no copy for the hop).
        self.held = match &self.twin {
            Twin::Fifo(input, relay) => {
                while room > 0
                    && let Some(packet) = input.recv_parcel()
                {
                    room -= 1;
                    relay.send_parcel(packet);
                }
                !input.is_empty()
            }
            Twin::Ufifo(input, relay) => {
                while room > 0
                    && let Some(packet) = input.recv_parcel()
                {
                    room -= 1;
                    relay.send_parcel(packet);
                }
                !input.is_empty()
            }
            // (Whether a new packet waits is not known without taking it: held while
            // the instance's input is full.)
            Twin::Last(..) if room == 0 => true,
            Twin::Last(input, relay) => {
                if let Some(packet) = input.take_new_shared() {
                    relay.send_parcel(Parcel::Shared(packet));
                }
                false
            }
            Twin::Poster(input, relay) => {
                if let Some(packet) = input.take_new() {
                    relay.post(packet);
                }
                false
            }
        };
    }

    fn held(&self) -> bool {
        self.held
    }

    fn is_input(&self) -> bool {
        true
    }

    fn follow_inputs(&mut self, inputs: Vec<ErasedInput>) -> Result<(), String> {
        follow_input(&self.twin.relay(), &mut self.linked, inputs)
    }
}

/// An exported tick input.
struct TickExport {
    target: String,
    twin: TickIn,
    relay: TickOut,
    linked: Vec<ErasedInput>,
}

impl Export for TickExport {
    fn target(&self) -> &str {
        &self.target
    }

    fn forward(&mut self) {
        for _ in 0..self.twin.take() {
            self.relay.emit();
        }
    }

    fn is_input(&self) -> bool {
        true
    }

    fn follow_inputs(&mut self, inputs: Vec<ErasedInput>) -> Result<(), String> {
        follow_input(&self.relay.erased(), &mut self.linked, inputs)
    }
}

/// An exported output (tick, data or poster): what the instance emits, sends or posts
/// goes out of the compound's port too, synchronously on the instance's thread (no
/// extra hop), and the pull requests the compound's port receives go to the
/// instance's output on behalf of the requesting input (`port::forward`).
struct OutputExport {
    target: String,
    twin: ErasedOutput,
    source: Option<(ErasedOutput, usize)>,
}

impl Export for OutputExport {
    fn target(&self) -> &str {
        &self.target
    }

    fn is_input(&self) -> bool {
        false
    }

    fn follow_output(&mut self, new: ErasedOutput) -> Result<(), String> {
        if let Some((old, id)) = &self.source {
            if old.core.id == new.core.id {
                return Ok(());
            }
            crate::port::unforward(old, *id);
        }
        self.source = None;
        let id = crate::port::forward(&new, &self.twin)
            .ok_or_else(|| "the exported output does not match the instance's".to_owned())?;
        self.source = Some((new, id));
        Ok(())
    }
}

/// Builds a compound component: instances, connections, mappings, policies,
/// supervisor rules. See the module documentation and `docs/runtime.md`.
pub struct CompoundBuilder {
    name: String,
    supervisor: Box<dyn Supervisor>,
    system: System,
    instances: Vec<Instance>,
    links: Vec<Link>,
    mapped: Vec<(String, String, VarKind)>,
    policies: Vec<(String, Policy)>,
    substitutes: Vec<(String, String)>,
    groups: Vec<Vec<String>>,
    rules: Vec<(String, String, Vec<String>, Test)>,
    retry_every: Duration,
    deadline: Duration,
    budget: Budget,
    errors: Vec<CompoundError>,
    exports: Vec<Box<dyn Export>>,
    inputs: Vec<InputSpec>,
    outputs: Vec<OutputSpec>,
    ports: PortSet,
    adaptation: AdaptConfig,
    selector: Box<dyn Selector>,
    command_timeout: Duration,
}

impl std::fmt::Debug for CompoundBuilder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "CompoundBuilder({})", self.name)
    }
}

impl CompoundBuilder {
    /// A compound instance named `name` whose supervisor is `supervisor`.
    pub fn new(name: impl Into<String>, supervisor: impl Supervisor) -> CompoundBuilder {
        CompoundBuilder {
            name: name.into(),
            supervisor: Box::new(supervisor),
            system: System::new(),
            instances: Vec::new(),
            links: Vec::new(),
            mapped: Vec::new(),
            policies: Vec::new(),
            substitutes: Vec::new(),
            groups: Vec::new(),
            rules: Vec::new(),
            retry_every: Duration::from_millis(500),
            deadline: Duration::from_secs(5),
            budget: Budget {
                restarts: DEFAULT_RESTARTS,
                window: DEFAULT_RESTART_WINDOW,
                backoff: DEFAULT_BACKOFF,
                backoff_max: DEFAULT_BACKOFF_MAX,
            },
            errors: Vec::new(),
            exports: Vec::new(),
            inputs: Vec::new(),
            outputs: Vec::new(),
            ports: PortSet::new(),
            adaptation: AdaptConfig::default(),
            selector: Box::new(ProtectPriority),
            command_timeout: DEFAULT_SUPERVISOR_COMMAND_TIMEOUT,
        }
    }

    /// How long a supervisor's command ([`SupervisorCx::instances`]) waits for an
    /// instance to take it (default [`DEFAULT_SUPERVISOR_COMMAND_TIMEOUT`]; at least
    /// 1 ms): an instance busy in a section longer than that has the command withdrawn
    /// and the section gets [`Refused::Busy`](crate::Refused::Busy).
    pub fn command_timeout(mut self, timeout: Duration) -> CompoundBuilder {
        self.command_timeout = timeout.max(Duration::from_millis(1));
        self
    }

    /// The supervisor's adaptation (paper 3.6; `docs/runtime.md`, "Adaptation"): on
    /// by default, coordinating the instances that adapt (those with a period
    /// interval, or turned on with [`Component::with_adaptation`]);
    /// [`AdaptConfig::off`] turns it off (the instances then detect and publish their
    /// verdicts, and nothing acts on them). [`AdaptConfig::width`] is the homogeneity
    /// interval's width and [`AdaptConfig::reconfiguration`] what the top-level
    /// supervisor does when degradation is exhausted; the detection fields are the
    /// instances' own ([`Component::with_adaptation`]).
    ///
    /// Odd values are made safe ([`AdaptConfig::sanitized`]).
    pub fn adaptation(mut self, adaptation: AdaptConfig) -> CompoundBuilder {
        self.adaptation = adaptation.sanitized();
        self
    }

    /// How the supervisor chooses the instance to degrade and the one to promote
    /// (default [`ProtectPriority`]; the paper's
    /// [`FastestCorrection`](crate::adapt::FastestCorrection), or your own).
    pub fn adaptation_selector(mut self, selector: impl Selector) -> CompoundBuilder {
        self.selector = Box::new(selector);
        self
    }

    /// The declared port at `target` (an input if `input`, else an output), if its
    /// kind is one of `kinds` and, for a port that carries packets, they are `T`.
    fn exported_port<T: 'static>(
        &mut self,
        target: &str,
        input: bool,
        kinds: &str,
    ) -> Option<(Option<InputSpec>, Option<OutputSpec>)> {
        let declared = target.split_once('.').and_then(|(instance, port)| {
            let spec = self.instances.iter().find(|i| i.name == instance)?.spec;
            Some(if input {
                (spec.inputs.iter().find(|i| i.name == port).copied(), None)
            } else {
                (None, spec.outputs.iter().find(|o| o.name == port).copied())
            })
        });
        let type_id = if input {
            self.system
                .input_port(target)
                .ok()
                .map(|p| (p.type_id, p.kind.name()))
        } else {
            self.system
                .output_port(target)
                .ok()
                .map(|p| (p.type_id, p.kind.name()))
        };
        let fits = match (&declared, type_id) {
            (Some(_), Some((type_id, kind))) => {
                kinds.split(", ").any(|k| k == kind)
                    && (kind == "tick" || type_id == std::any::TypeId::of::<T>())
            }
            _ => false,
        };
        if !fits {
            let direction = if input { "input" } else { "output" };
            let packets = if kinds == "tick" {
                String::new()
            } else {
                format!(" of `{}`", std::any::type_name::<T>())
            };
            self.errors.push(CompoundError::Connect {
                compound: self.name.clone(),
                detail: format!(
                    "cannot export `{target}`: no such {direction}, or not a {kinds} {direction}{packets}"
                ),
            });
            return None;
        }
        declared
    }

    /// `input name = instance.port;` for a fifo, ufifo, last or poster input of
    /// packets `T`, `pull` or not: the compound gets an input of the same kind, size
    /// and pull model; what arrives there is passed on to the instance (or its
    /// stand-in) by the compound's thread while the compound runs, and a pull request
    /// of the instance's input becomes a request of the compound's input to its
    /// producers.
    pub fn export_input<T: Packet>(mut self, name: &str, target: &str) -> CompoundBuilder {
        let Some((Some(declared), _)) =
            self.exported_port::<T>(target, true, "fifo, ufifo, last, poster")
        else {
            return self;
        };
        let twin: Twin<T> = match declared.kind {
            InputKind::Fifo { capacity, policy } => {
                Twin::Fifo(FifoIn::new(capacity, policy), DataOut::new())
            }
            InputKind::Ufifo { initial, max } => {
                Twin::Ufifo(UfifoIn::new(initial, max), DataOut::new())
            }
            InputKind::Poster => Twin::Poster(PosterIn::new(), PosterOut::new()),
            InputKind::Last | InputKind::Tick => Twin::Last(LastIn::new(), DataOut::new()),
        };
        let port = twin.input();
        route_pulls(&twin.relay(), &port);
        self.ports = std::mem::take(&mut self.ports).erased_input(port);
        self.inputs.push(InputSpec {
            name: leak_str(name),
            ..declared
        });
        self.exports.push(Box::new(InputExport {
            target: target.to_owned(),
            twin,
            linked: Vec::new(),
            held: false,
        }));
        self
    }

    /// `input name = instance.port;` for a tick input, `pull` or not.
    pub fn export_tick_input(mut self, name: &str, target: &str) -> CompoundBuilder {
        let Some((Some(declared), _)) = self.exported_port::<()>(target, true, "tick") else {
            return self;
        };
        let twin = TickIn::new();
        let relay = TickOut::new();
        route_pulls(&relay.erased(), &twin.erased());
        self.ports = std::mem::take(&mut self.ports).input(&twin);
        self.inputs.push(InputSpec {
            name: leak_str(name),
            ..declared
        });
        self.exports.push(Box::new(TickExport {
            target: target.to_owned(),
            twin,
            relay,
            linked: Vec::new(),
        }));
        self
    }

    /// `output name = instance.port;` for a data or poster output of packets `T`,
    /// `pull` or not: what the instance (or its stand-in, or its redundant group's
    /// leader) sends or posts goes out of the compound's port too, and pull requests
    /// to the compound's port go to the instance's output for the requesting input.
    pub fn export_output<T: Packet>(self, name: &str, target: &str) -> CompoundBuilder {
        self.export_output_of::<T>(name, target, "data, poster")
    }

    /// `output name = instance.port;` for a tick output, `pull` or not.
    pub fn export_tick_output(self, name: &str, target: &str) -> CompoundBuilder {
        self.export_output_of::<()>(name, target, "tick")
    }

    fn export_output_of<T: Packet>(
        mut self,
        name: &str,
        target: &str,
        kinds: &str,
    ) -> CompoundBuilder {
        let Some((_, Some(declared))) = self.exported_port::<T>(target, false, kinds) else {
            return self;
        };
        let twin = match declared.kind {
            OutputKind::Tick => TickOut::new().erased(),
            OutputKind::Data => DataOut::<T>::new().erased(),
            OutputKind::Poster => PosterOut::<T>::new().erased(),
        };
        self.ports = std::mem::take(&mut self.ports).erased_output(twin.clone());
        self.outputs.push(OutputSpec {
            name: leak_str(name),
            ..declared
        });
        self.exports.push(Box::new(OutputExport {
            target: target.to_owned(),
            twin,
            source: None,
        }));
        self
    }

    /// A local instance (an atomic component or another compound).
    pub fn instance(mut self, component: Component) -> CompoundBuilder {
        let name = component.name().to_owned();
        let spec = component.spec();
        let levels = component.timing().qualities.len();
        match self.system.add(component) {
            Ok(handle) => self.instances.push(Instance {
                name,
                spec,
                levels,
                handle,
                policy: Policy::Propagate,
                substitutes: None,
                substitute: None,
                group: None,
                status: Status::Active,
                restarts: std::collections::VecDeque::new(),
                pending: None,
                handled: false,
            }),
            Err(error) => self.errors.push(CompoundError::Instance {
                compound: self.name.clone(),
                detail: error.to_string(),
            }),
        }
        self
    }

    /// The control and monitoring ports of instance `name` (added with
    /// [`CompoundBuilder::instance`]): for tools and tests that watch a level below.
    /// Once built, the compound's own handle gives the same through
    /// [`Handle::instance`] (by dotted path, through nested compounds).
    pub fn instance_handle(&self, name: &str) -> Option<Handle> {
        self.instances
            .iter()
            .find(|i| i.name == name)
            .map(|i| i.handle.clone())
    }

    /// `connect from -> to;` between two instances (`instance.port` addresses).
    pub fn connect(mut self, from: &str, to: &str) -> CompoundBuilder {
        self.links.push(Link {
            from: from.to_owned(),
            to: to.to_owned(),
            via: None,
            link_via: None,
        });
        self
    }

    /// `connect from -> to via converter;` between two instances: output `from`
    /// (packets of `A`) feeds input `to` (packets of `B`) through `convert`, as
    /// [`System::connect_via`] does (applied on the producer's thread at each send, or
    /// on the consumer's thread at each read of a poster). The converter stays on the
    /// connection when substitution or recovery moves one of its ends to another
    /// instance, and the move loses no packet (the packets queued at a replaced input
    /// move with it, as for [`CompoundBuilder::connect`]). The packet types are checked when
    /// the compound starts (a mismatch takes it to `running_error` with the reason).
    pub fn connect_via<A: Packet, B: Packet>(
        mut self,
        from: &str,
        to: &str,
        convert: impl Fn(&A) -> B + Send + Sync + 'static,
    ) -> CompoundBuilder {
        let convert: Arc<dyn Fn(&A) -> B + Send + Sync> = Arc::new(convert);
        let direct = Arc::clone(&convert);
        let link_via: LinkVia = Arc::new(move |output: &ErasedOutput, input: &ErasedInput| {
            output.type_id == std::any::TypeId::of::<A>()
                && input.type_id == std::any::TypeId::of::<B>()
                && crate::port::link_converted::<A, B>(output, input, Arc::clone(&direct))
        });
        let via: Via = Arc::new(
            move |system: &mut System, old: Option<(&str, &str)>, from: &str, to: &str| {
                let Some(old) = old else {
                    let convert = Arc::clone(&convert);
                    return system.connect_via::<A, B>(from, to, move |packet: &A| convert(packet));
                };
                system.replace_link(old, from, to, &|output, input, old_input| {
                    output.type_id == std::any::TypeId::of::<A>()
                        && input.type_id == std::any::TypeId::of::<B>()
                        && crate::port::relink_converted::<A, B>(
                            output,
                            old_input,
                            input,
                            Arc::clone(&convert),
                        )
                })
            },
        );
        self.links.push(Link {
            from: from.to_owned(),
            to: to.to_owned(),
            via: Some(via),
            link_via: Some(link_via),
        });
        self
    }

    /// `observable name = instance.variable;`
    pub fn map_observable(mut self, name: &str, target: &str) -> CompoundBuilder {
        self.mapped
            .push((name.to_owned(), target.to_owned(), VarKind::Observable));
        self
    }

    /// `controllable name = instance.variable;` (set through the compound's control
    /// port, forwarded to the instance's).
    pub fn map_controllable(mut self, name: &str, target: &str) -> CompoundBuilder {
        self.mapped
            .push((name.to_owned(), target.to_owned(), VarKind::Controllable));
        self
    }

    /// `on error instance: policy;` (instances without one propagate).
    pub fn on_error(mut self, instance: &str, policy: Policy) -> CompoundBuilder {
        self.policies.push((instance.to_owned(), policy));
        self
    }

    /// `instance substitute: ... substitutes primary;`
    pub fn substitute(mut self, substitute: &str, primary: &str) -> CompoundBuilder {
        self.substitutes
            .push((substitute.to_owned(), primary.to_owned()));
        self
    }

    /// `redundant a, b, ...;`
    pub fn redundant(mut self, members: &[&str]) -> CompoundBuilder {
        self.groups
            .push(members.iter().map(|m| (*m).to_owned()).collect());
        self
    }

    /// `recovery { retry every R; deadline D; }` (defaults: 500 ms, 5 s).
    pub fn recovery(mut self, retry_every: Duration, deadline: Duration) -> CompoundBuilder {
        self.retry_every = retry_every.max(Duration::from_millis(1));
        self.deadline = deadline;
        self
    }

    /// The `restart` policy's budget: at most `restarts` restarts of one instance
    /// within any `window` (defaults [`DEFAULT_RESTARTS`] in
    /// [`DEFAULT_RESTART_WINDOW`]); a failure beyond that propagates (the compound goes
    /// to `running_error`, its error saying the budget is spent). `u32::MAX` restarts:
    /// no limit.
    pub fn restart_budget(mut self, restarts: u32, window: Duration) -> CompoundBuilder {
        self.budget.restarts = restarts;
        self.budget.window = window;
        self
    }

    /// The `restart` policy's backoff: within the budget's window the first restart of
    /// an instance is immediate, the second waits `initial`, each further one twice as
    /// long as the one before, at most `max` (defaults [`DEFAULT_BACKOFF`],
    /// [`DEFAULT_BACKOFF_MAX`]; zero: no backoff). The compound's thread does not
    /// sleep meanwhile: the restart is a timer.
    pub fn restart_backoff(mut self, initial: Duration, max: Duration) -> CompoundBuilder {
        self.budget.backoff = initial;
        self.budget.backoff_max = max.max(initial);
        self
    }

    /// `when <test> -> target;` in supervisor state `state`. `reads` names every
    /// variable the test reads (`instance.state`, `instance.user_state`,
    /// `instance.result`, `instance.error`, `instance.quality`, `instance.<variable>`,
    /// an own variable `name`, or a mapped variable `name` read with [`View::mapped`]): the rule is evaluated when one of them changes, and
    /// when the supervisor enters `state` (however it got there). The compound's own
    /// defaults are read as `result`, `error`, `quality`, `cpu_time` and
    /// `elapsed_time`. Times (`instance.cpu_time`, `instance.elapsed_time` and the
    /// compound's own) announce no change: a rule reading them is also evaluated once
    /// every supervisor period, on a fresh snapshot of the instances it names.
    pub fn rule(
        mut self,
        state: &str,
        target: &str,
        reads: &[&str],
        test: impl Fn(&View) -> bool + Send + 'static,
    ) -> CompoundBuilder {
        self.rules.push((
            state.to_owned(),
            target.to_owned(),
            reads.iter().map(|r| (*r).to_owned()).collect(),
            Box::new(test),
        ));
        self
    }

    fn unknown(&self, what: &'static str, name: &str) -> CompoundError {
        CompoundError::Unknown {
            compound: self.name.clone(),
            what,
            name: name.to_owned(),
        }
    }

    fn instance_index(&self, name: &str) -> Result<usize, CompoundError> {
        self.instances
            .iter()
            .position(|i| i.name == name)
            .ok_or_else(|| self.unknown("instance", name))
    }

    fn arrangement(&self, detail: String) -> CompoundError {
        CompoundError::Arrangement {
            compound: self.name.clone(),
            detail,
        }
    }

    /// Whether instances `a` and `b` can stand for each other: the same ports (by name,
    /// with their kind, packet type and pull model; queue sizes may differ) and the
    /// same observable and controllable variables (by name, with their kind and
    /// type), in any order. `coolc` checks the same (`coolc::check::interface_mismatch`).
    fn same_interface(&self, a: usize, b: usize) -> Result<(), CompoundError> {
        let (x, y) = (self.instances[a].spec, self.instances[b].spec);
        let inputs = |s: &Spec| {
            let mut ports: Vec<_> = s
                .inputs
                .iter()
                .map(|i| (i.name, std::mem::discriminant(&i.kind), i.packet, i.pull))
                .collect();
            ports.sort_by_key(|p| p.0);
            ports
        };
        let outputs = |s: &Spec| {
            let mut ports: Vec<_> = s
                .outputs
                .iter()
                .map(|o| (o.name, o.kind, o.packet, o.pull))
                .collect();
            ports.sort_by_key(|p| p.0);
            ports
        };
        let variables = |s: &Spec| {
            let mut variables: Vec<_> =
                s.variables.iter().map(|v| (v.name, v.kind, v.ty)).collect();
            variables.sort_by_key(|v| v.0);
            variables
        };
        if inputs(x) != inputs(y) || outputs(x) != outputs(y) || variables(x) != variables(y) {
            return Err(self.arrangement(format!(
                "`{}` ({}) and `{}` ({}) do not have the same interface (ports, their kinds and packets, variables)",
                self.instances[a].name, x.type_name, self.instances[b].name, y.type_name
            )));
        }
        Ok(())
    }

    /// The compound as a component, ready for [`System::add`] (or for another
    /// compound's [`CompoundBuilder::instance`]).
    pub fn build(mut self) -> Result<Component, CompoundError> {
        if let Some(error) = self.errors.first() {
            return Err(error.clone());
        }
        let mut own = *self.supervisor.spec();
        let unperiodic = own
            .states
            .iter()
            .any(|state| state.periodic.is_some_and(|p| p.period.is_none()));
        if unperiodic && own.timing.period.is_none() {
            own.timing.period = Some(DEFAULT_SUPERVISION_PERIOD);
        }
        let own = &own;
        if let Err(detail) = own.validate() {
            return Err(CompoundError::Supervisor {
                compound: self.name.clone(),
                detail,
            });
        }
        // Policies.
        for (name, policy) in std::mem::take(&mut self.policies) {
            let index = self.instance_index(&name)?;
            self.instances[index].policy = policy;
        }
        // Substitutes.
        for (substitute, primary) in std::mem::take(&mut self.substitutes) {
            let s = self.instance_index(&substitute)?;
            let p = self.instance_index(&primary)?;
            if s == p
                || self.instances[p].substitute.is_some()
                || self.instances[p].substitutes.is_some()
                || self.instances[s].substitutes.is_some()
                || self.instances[s].substitute.is_some()
            {
                return Err(self.arrangement(format!(
                    "`{substitute}` cannot substitute `{primary}`: one substitute per instance, a substitute substitutes one instance, and neither end of a substitution is in another"
                )));
            }
            self.same_interface(p, s)?;
            self.instances[p].substitute = Some(s);
            self.instances[s].substitutes = Some(p);
            self.instances[s].status = Status::Standby;
        }
        // Redundant groups.
        let groups = std::mem::take(&mut self.groups);
        let mut group_members = Vec::new();
        for (group, members) in groups.iter().enumerate() {
            let mut indices = Vec::new();
            for member in members {
                let index = self.instance_index(member)?;
                let instance = &self.instances[index];
                if instance.group.is_some()
                    || instance.substitute.is_some()
                    || instance.substitutes.is_some()
                {
                    return Err(self.arrangement(format!(
                        "`{member}` cannot be in a redundant group: it is already in one, or in a substitution"
                    )));
                }
                if let Some(first) = indices.first() {
                    self.same_interface(*first, index)?;
                }
                indices.push(index);
            }
            if indices.len() < 2 {
                return Err(
                    self.arrangement("a redundant group needs at least two members".to_owned())
                );
            }
            for index in &indices {
                self.instances[*index].group = Some(group);
            }
            group_members.push(indices);
        }
        // Connections: resolve the instances; the system checks the rest when wiring.
        for link in &self.links {
            let (from, to) = link.ends();
            for address in [from, to] {
                let Some((instance, _)) = address.split_once('.') else {
                    return Err(CompoundError::Connect {
                        compound: self.name.clone(),
                        detail: format!("`{address}` is not an `instance.port` address"),
                    });
                };
                self.instance_index(instance)?;
            }
        }
        // Mapped variables, then the supervisor's own.
        let mut variables = Vec::new();
        let mut mapped = Vec::new();
        for (name, target, kind) in &self.mapped {
            let Some((instance, variable)) = target.split_once('.') else {
                return Err(self.unknown("variable", target));
            };
            let index = self.instance_index(instance)?;
            let Some(declared) = self.instances[index]
                .spec
                .variables
                .iter()
                .find(|v| v.name == variable)
            else {
                return Err(self.unknown("variable", target));
            };
            if *kind == VarKind::Controllable && declared.kind != VarKind::Controllable {
                return Err(self.arrangement(format!(
                    "`{name}` is mapped as controllable onto `{target}`, which is observable"
                )));
            }
            variables.push(VarSpec {
                name: leak_str(name),
                kind: *kind,
                ty: declared.ty,
                doc: declared.doc,
            });
            mapped.push(Mapped {
                instance: index,
                variable: variable.to_owned(),
            });
        }
        variables.extend(own.variables.iter().copied());
        // Rules.
        let mut rules = Vec::new();
        for (state, target, reads, test) in std::mem::take(&mut self.rules) {
            let state_index = own
                .state_index(&state)
                .ok_or_else(|| self.unknown("supervisor state", &state))?;
            let target_index = own
                .state_index(&target)
                .ok_or_else(|| self.unknown("supervisor state", &target))?;
            for read in &reads {
                self.check_read(read, own)?;
            }
            rules.push(Rule {
                state: state_index,
                target: target_index,
                reads,
                test,
            });
        }
        let mut by_read: HashMap<String, Vec<usize>> = HashMap::new();
        for (index, rule) in rules.iter().enumerate() {
            for read in &rule.reads {
                let readers = by_read.entry(read.clone()).or_default();
                if readers.last() != Some(&index) {
                    readers.push(index);
                }
            }
        }
        let mut spec = *own;
        spec.variables = Box::leak(variables.into_boxed_slice());
        spec.inputs = Box::leak(std::mem::take(&mut self.inputs).into_boxed_slice());
        spec.outputs = Box::leak(std::mem::take(&mut self.outputs).into_boxed_slice());
        spec.exceptions = &[];
        let spec: &'static Spec = Box::leak(Box::new(spec));
        let view = View {
            instances: self.instances.iter().map(|i| i.handle.snapshot()).collect(),
            positions: self
                .instances
                .iter()
                .enumerate()
                .map(|(index, i)| (i.name.clone(), index))
                .collect(),
            own: own
                .variables
                .iter()
                .enumerate()
                .map(|(index, v)| (v.name.to_owned(), self.supervisor.get(index)))
                .collect(),
            mapped: self
                .mapped
                .iter()
                .zip(&mapped)
                .map(|((name, _, _), m)| (name.clone(), (m.instance, m.variable.clone())))
                .collect(),
            standing: (0..self.instances.len()).collect(),
            compound: Own::default(),
        };
        let reads_own = rules
            .iter()
            .flat_map(|rule| &rule.reads)
            .any(|read| OWN_DEFAULTS.contains(&read.as_str()));
        let timed: Vec<String> = by_read
            .keys()
            .filter(|read| is_timed(read))
            .cloned()
            .collect();
        let handles = self.instances.iter().map(|i| i.handle.clone()).collect();
        let commander = Commander::new(
            self.name.clone(),
            self.instances
                .iter()
                .map(|i| (i.name.clone(), i.handle.clone(), i.spec, i.levels)),
            self.command_timeout,
        );
        // The instances' runners only detect and publish: the compound decides (and,
        // with its adaptation off, nothing does).
        for instance in &self.instances {
            instance
                .handle
                .shared
                .adapt_managed
                .store(true, Ordering::Release);
        }
        let coordinator = (self.adaptation.enabled != Some(false)).then(|| Coordinator {
            config: self.adaptation,
            selector: self.selector,
            cap: 0,
            floor: 0,
            initialized: false,
            dirty: false,
            exhausted: false,
            suspended: vec![false; self.instances.len()],
            pending: vec![None; self.instances.len()],
            max_level: 0,
            settle_until: None,
            backoff: 1,
            resumed_at: None,
        });
        let compound = Compound {
            name: self.name.clone(),
            spec,
            own_offset: mapped.len(),
            system: Some(self.system),
            instances: self.instances,
            leaders: group_members.iter().map(|members| members[0]).collect(),
            groups: group_members,
            merges: Vec::new(),
            merged: Vec::new(),
            fanned: Vec::new(),
            links: self.links,
            wired: Vec::new(),
            mapped,
            supervisor: self.supervisor,
            by_read,
            rules,
            events: Vec::new(),
            view,
            evaluated_in: None,
            fresh: false,
            sectioned: false,
            queue: Vec::new(),
            retry_every: self.retry_every,
            deadline: self.deadline,
            budget: self.budget,
            started: false,
            exports: self.exports,
            steps: Vec::new(),
            restood: false,
            coordinator,
            commander,
            reads_own,
            timed,
            next_timed: None,
        };
        Ok(Component::new(self.name, Box::new(compound), self.ports).with_instances(handles))
    }

    fn check_read(&self, read: &str, own: &Spec) -> Result<(), CompoundError> {
        match read.split_once('.') {
            None if OWN_DEFAULTS.contains(&read) => Ok(()),
            None => own
                .variable_index(read)
                .map(|_| ())
                .or_else(|| {
                    self.mapped
                        .iter()
                        .any(|(name, _, _)| name == read)
                        .then_some(())
                })
                .ok_or_else(|| self.unknown("variable", read)),
            Some((instance, field)) => {
                let index = self.instance_index(instance)?;
                let default = matches!(
                    field,
                    "state"
                        | "user_state"
                        | "result"
                        | "error"
                        | "quality"
                        | "cpu_time"
                        | "elapsed_time"
                );
                if default || self.instances[index].spec.variable_index(field).is_some() {
                    Ok(())
                } else {
                    Err(self.unknown("variable", read))
                }
            }
        }
    }
}

fn leak_str(text: &str) -> &'static str {
    Box::leak(text.to_owned().into_boxed_str())
}

/// The code of a compound component, driven by the runner like any automaton.
struct Compound {
    name: String,
    spec: &'static Spec,
    /// Index of the first own variable in `spec.variables` (mapped ones come first).
    own_offset: usize,
    system: Option<System>,
    instances: Vec<Instance>,
    groups: Vec<Vec<usize>>,
    /// Each redundant group's leader (its merged streams carry its packets): changes
    /// only when the leader fails.
    leaders: Vec<usize>,
    /// The merged data outputs of redundant groups, made at the first wiring.
    merges: Vec<MergedPort>,
    /// The consumers linked to a merged output: `(merge, input address, input)`.
    merged: Vec<(usize, String, ErasedInput)>,
    /// The connections made to redundant members' inputs (every live member).
    fanned: Vec<(String, String)>,
    /// Declared connections.
    links: Vec<Link>,
    /// The connections made now (declared ones with each instance routed to whoever
    /// stands for it, with their converters).
    /// The connection made for each declared link (`links`, same order), between the
    /// instances standing for its ends; `None` where none is (not made yet, or the
    /// same ends as an earlier link's).
    wired: Vec<Option<Link>>,
    mapped: Vec<Mapped>,
    supervisor: Box<dyn Supervisor>,
    rules: Vec<Rule>,
    /// Monitoring events of each instance (subscribed at the first start), with a
    /// flag its publisher sets before ringing the compound: a turn looks only at the
    /// instances that have news.
    events: Vec<(Receiver<MonitorEvent>, Arc<AtomicBool>)>,
    /// The rules reading each variable (`inst.field` or an own variable), by index.
    by_read: HashMap<String, Vec<usize>>,
    view: View,
    /// The supervisor state whose rules were last evaluated.
    evaluated_in: Option<usize>,
    /// The supervisor entered a state (by a rule, `after`, `on`, ...): the thread takes
    /// one more turn at once to evaluate the new state's rules (nothing else may wake
    /// it).
    fresh: bool,
    /// A supervisor section ran since the last turn: it may have changed variables the
    /// runtime cannot see (`local` ones, or any state of a hand-written supervisor), so
    /// the next turn, taken at once, evaluates every rule of the current state.
    sectioned: bool,
    queue: Vec<Recovering>,
    retry_every: Duration,
    deadline: Duration,
    budget: Budget,
    started: bool,
    exports: Vec<Box<dyn Export>>,
    /// Supervision steps taken since the last call returned (published by the runner).
    steps: Vec<Supervision>,
    /// Another instance started standing for one with mapped variables: rules reading
    /// them are evaluated on the next turn.
    restood: bool,
    /// Adaptation (paper 3.6): `None` when turned off.
    coordinator: Option<Coordinator>,
    /// What the supervisor's sections command the instances with.
    commander: Commander,
    /// Some rule reads the compound's own `result`, `error`, `quality`, `cpu_time`
    /// or `elapsed_time`: each turn copies them into the view.
    reads_own: bool,
    /// The time reads (`cpu_time`, `elapsed_time`, own or an instance's) some rule
    /// names: they change without events, so they count as changed every supervisor
    /// period.
    timed: Vec<String>,
    /// When the time reads are next due.
    next_timed: Option<Instant>,
}

/// A compound supervisor's adaptation state: its homogeneity interval and what it has
/// asked of its instances.
struct Coordinator {
    config: AdaptConfig,
    selector: Box<dyn Selector>,
    /// The current maximum degradation level (the compound's own level).
    cap: u32,
    /// The current minimum degradation level.
    floor: u32,
    /// The cap and floor were set up at the first start (top level: `width`; nested:
    /// 0 until its supervisor grants more).
    initialized: bool,
    /// Something adaptation reads changed: decide on the next turn.
    dirty: bool,
    /// `Exhausted` was published for the current violation.
    exhausted: bool,
    /// Instances suspended by adaptation (reconfiguration).
    suspended: Vec<bool>,
    /// Levels commanded and not yet seen on the instance's monitor, with when.
    pending: Vec<Option<(u32, Instant)>>,
    /// The highest ladder top among the instances (published).
    max_level: u32,
    /// Until when promotion waits: the settling time after the last time violation
    /// seen or degradation decided.
    settle_until: Option<Instant>,
    /// Reconfiguration: the settling time's multiplier after a suspension (doubled
    /// when a suspension follows a resume within the settling time, up to
    /// `max_backoff`; back to 1 after a resume that held).
    backoff: u32,
    /// When the last instance suspended by adaptation was resumed.
    resumed_at: Option<Instant>,
}

fn command(handle: &Handle, target: Controllable) -> Result<(), Fault> {
    handle
        .command(Command::SetState(target))
        .map_err(|rejected| Fault::message(rejected.to_string()))
}

impl Compound {
    /// Record a supervision step about instance `index` for the monitoring port.
    fn step(&mut self, index: usize, step: Step, detail: impl Into<String>) {
        let detail = detail.into();
        let instance = self.instances[index].name.clone();
        tracing::info!(compound = %self.name, %instance, ?step, "{detail}");
        self.steps.push(Supervision {
            instance,
            step,
            detail,
        });
    }

    /// A fault raised while handling instance `index` (a rewiring or a command that
    /// failed after a step was recorded): recorded as `Propagated` with the reason,
    /// unless the last step recorded is that fault's `Propagated` already.
    fn propagated(&mut self, index: usize, fault: Fault) -> Fault {
        let recorded = self
            .steps
            .last()
            .is_some_and(|last| last.step == Step::Propagated);
        if !recorded {
            self.step(index, Step::Propagated, fault.text().to_owned());
        }
        fault
    }

    fn fault(&self, message: String) -> Fault {
        tracing::warn!(compound = %self.name, "{message}");
        Fault::message(message)
    }

    /// Who stands for instance `index` now.
    fn route(&self, index: usize) -> usize {
        let instance = &self.instances[index];
        if let Some(group) = instance.group {
            return self.leaders[group];
        }
        if let Some(substitute) = instance.substitute
            && instance.status != Status::Active
            && self.instances[substitute].status == Status::Active
        {
            return substitute;
        }
        index
    }

    fn routed(&self, address: &str) -> String {
        let Some((instance, port)) = address.split_once('.') else {
            return address.to_owned();
        };
        match self.instances.iter().position(|i| i.name == instance) {
            Some(index) => format!("{}.{port}", self.instances[self.route(index)].name),
            None => address.to_owned(),
        }
    }

    /// Make the connections match the arrangement: each declared connection between
    /// the instances standing for its ends now. A connection whose end moved (to a
    /// stand-in, or back) is replaced in one step, with the packets queued at a
    /// replaced input (`System::replace_link`): no packet is lost meanwhile.
    fn rewire(&mut self) -> Result<(), Fault> {
        self.update_standing();
        self.make_merges()?;
        let mut wanted: Vec<Option<Link>> = Vec::with_capacity(self.links.len());
        // Connections to a redundant group's inputs go to every live member; from a
        // group's data output, the merged stream feeds the consumers.
        let mut fanned: Vec<Link> = Vec::new();
        let mut merged: Vec<(usize, String, Option<LinkVia>)> = Vec::new();
        for link in &self.links {
            if let Some(merge) = self.merge_of(&link.from) {
                for to in self.fed(&link.to) {
                    merged.push((merge, to, link.link_via.clone()));
                }
                wanted.push(None);
                continue;
            }
            if self.in_group(&link.to) {
                let from = self.routed(&link.from);
                for to in self.fed(&link.to) {
                    fanned.push(Link {
                        from: from.clone(),
                        to,
                        via: link.via.clone(),
                        link_via: None,
                    });
                }
                wanted.push(None);
                continue;
            }
            let routed = Link {
                from: self.routed(&link.from),
                to: self.routed(&link.to),
                via: link.via.clone(),
                link_via: None,
            };
            let duplicate = wanted.iter().flatten().any(|w| w.ends() == routed.ends());
            wanted.push((!duplicate).then_some(routed));
        }
        self.wired.resize(self.links.len(), None);
        let Some(system) = self.system.as_mut() else {
            return Ok(());
        };
        let name = &self.name;
        let error = |e: ConnectError| Fault::message(format!("compound `{name}`: {e}"));
        let plain = |output: &ErasedOutput, input: &ErasedInput, old: Option<&ErasedInput>| {
            output.type_id == input.type_id
                && match old {
                    Some(old) => old.kind == input.kind && output.relink(old, input),
                    None => output.link(input),
                }
        };
        // A connection whose link now has the same ends as an earlier link's goes
        // first (unless another link still wants it); then each link's connection is
        // kept, replaced in one step, or made.
        for index in 0..self.wired.len() {
            if wanted[index].is_none()
                && let Some(link) = self.wired[index].take()
                && !wanted.iter().flatten().any(|w| w.ends() == link.ends())
            {
                system.disconnect(&link.from, &link.to).map_err(error)?;
            }
        }
        for (index, new) in wanted.iter().enumerate() {
            let Some(new) = new else {
                continue;
            };
            let old = self.wired[index].take();
            // The same connection may have been made for another link (whose ends it
            // had before): it is kept as it is.
            let made = self.wired.iter().flatten().any(|w| w.ends() == new.ends());
            match old {
                Some(old) if old.ends() == new.ends() => {}
                Some(old) if !made => {
                    let ends = (old.from.as_str(), old.to.as_str());
                    match &new.via {
                        Some(via) => via(system, Some(ends), &new.from, &new.to),
                        None => system.replace_link(ends, &new.from, &new.to, &plain),
                    }
                    .map_err(error)?;
                }
                old => {
                    if let Some(old) = old
                        && !wanted.iter().flatten().any(|w| w.ends() == old.ends())
                    {
                        system.disconnect(&old.from, &old.to).map_err(error)?;
                    }
                    if !made {
                        match &new.via {
                            Some(via) => via(system, None, &new.from, &new.to),
                            None => system.connect(&new.from, &new.to),
                        }
                        .map_err(error)?;
                    }
                }
            }
            self.wired[index] = Some(new.clone());
        }
        // Fanned connections: those no longer wanted go first (a poster or last input
        // takes one producer), then the new ones are made.
        let stale: Vec<(String, String)> = self
            .fanned
            .iter()
            .filter(|old| {
                !fanned
                    .iter()
                    .any(|new| new.ends() == (old.0.as_str(), old.1.as_str()))
            })
            .cloned()
            .collect();
        for (from, to) in stale {
            system.disconnect(&from, &to).map_err(error)?;
            self.fanned.retain(|old| *old != (from.clone(), to.clone()));
        }
        for new in &fanned {
            let ends = (new.from.clone(), new.to.clone());
            if self.fanned.contains(&ends) {
                continue;
            }
            match &new.via {
                Some(via) => via(system, None, &new.from, &new.to),
                None => system.connect(&new.from, &new.to),
            }
            .map_err(error)?;
            self.fanned.push(ends);
        }
        // The merged streams' consumers: new ones linked before stale ones unlinked.
        for (merge, to, via) in &merged {
            if self.merged.iter().any(|(m, t, _)| m == merge && t == to) {
                continue;
            }
            let input = system.input_port(to).map_err(error)?;
            let output = self.merges[*merge].merge.output();
            let linked = match via {
                Some(via) => via(&output, &input),
                None => output.type_id == input.type_id && output.link(&input),
            };
            if !linked {
                return Err(Fault::message(format!(
                    "compound `{name}`: the merged output of `{}` does not match `{to}`",
                    self.merges[*merge].port
                )));
            }
            self.merged.push((*merge, to.clone(), input));
        }
        let merges = &self.merges;
        self.merged.retain(|(merge, to, input)| {
            let keep = merged.iter().any(|(m, t, _)| m == merge && t == to);
            if !keep {
                merges[*merge].merge.output().unlink(input);
            }
            keep
        });
        for index in 0..self.exports.len() {
            let target = self.exports[index].target().to_owned();
            let Some(system) = self.system.as_ref() else {
                break;
            };
            let followed = if self.exports[index].is_input() {
                let inputs: Result<Vec<ErasedInput>, ConnectError> = self
                    .fed(&target)
                    .iter()
                    .map(|address| system.input_port(address))
                    .collect();
                inputs
                    .map_err(|e| e.to_string())
                    .and_then(|inputs| self.exports[index].follow_inputs(inputs))
            } else {
                let output = match self.merge_of(&target) {
                    Some(merge) => Ok(self.merges[merge].merge.output()),
                    None => system
                        .output_port(&self.routed(&target))
                        .map_err(|e| e.to_string()),
                };
                output.and_then(|output| self.exports[index].follow_output(output))
            };
            followed.map_err(|e| {
                Fault::message(format!("compound `{}`: `{target}`: {e}", self.name))
            })?;
        }
        Ok(())
    }

    /// Whether `address` (`instance.port`) is a port of a redundant group's member.
    fn in_group(&self, address: &str) -> bool {
        self.index_of(address)
            .is_some_and(|index| self.instances[index].group.is_some())
    }

    fn index_of(&self, address: &str) -> Option<usize> {
        let (instance, _) = address.split_once('.')?;
        self.instances.iter().position(|i| i.name == instance)
    }

    /// The inputs a connection or export to input `address` feeds now: for a member
    /// of a redundant group, the same input of every live member (of the leader if
    /// none is live); else the input of whoever stands for the instance.
    fn fed(&self, address: &str) -> Vec<String> {
        let (Some(index), Some((_, port))) = (self.index_of(address), address.split_once('.'))
        else {
            return vec![address.to_owned()];
        };
        match self.instances[index].group {
            Some(group) => {
                let live: Vec<String> = self.groups[group]
                    .iter()
                    .filter(|m| self.instances[**m].status == Status::Active)
                    .map(|m| format!("{}.{port}", self.instances[*m].name))
                    .collect();
                if live.is_empty() {
                    vec![format!(
                        "{}.{port}",
                        self.instances[self.leaders[group]].name
                    )]
                } else {
                    live
                }
            }
            None => vec![self.routed(address)],
        }
    }

    /// The merge of the data output at `address`, if it is a redundant member's.
    fn merge_of(&self, address: &str) -> Option<usize> {
        let index = self.index_of(address)?;
        let group = self.instances[index].group?;
        let (_, port) = address.split_once('.')?;
        self.merges
            .iter()
            .position(|m| m.group == group && m.port == port)
    }

    /// Make the merge of every redundant member's data output that a connection or an
    /// export reads (once: the lanes stay attached to the members' outputs).
    fn make_merges(&mut self) -> Result<(), Fault> {
        let Some(system) = self.system.as_ref() else {
            return Ok(());
        };
        let sources = self.links.iter().map(|link| link.from.clone()).chain(
            self.exports
                .iter()
                .filter(|e| !e.is_input())
                .map(|e| e.target().to_owned()),
        );
        let mut made = Vec::new();
        for address in sources {
            let (Some(index), Some((_, port))) = (self.index_of(&address), address.split_once('.'))
            else {
                continue;
            };
            let Some(group) = self.instances[index].group else {
                continue;
            };
            if self
                .merges
                .iter()
                .chain(&made)
                .any(|m: &MergedPort| m.group == group && m.port == port)
            {
                continue;
            }
            let members = &self.groups[group];
            let first = system
                .output_port(&format!("{}.{port}", self.instances[members[0]].name))
                .map_err(|e| Fault::message(format!("compound `{}`: {e}", self.name)))?;
            let Some(merge) = first.merge(members.len()) else {
                continue; // A tick or poster output: its consumers follow the leader.
            };
            for (lane, member) in members.iter().enumerate() {
                let output = system
                    .output_port(&format!("{}.{port}", self.instances[*member].name))
                    .map_err(|e| Fault::message(format!("compound `{}`: {e}", self.name)))?;
                if !merge.attach(lane, &output) {
                    return Err(Fault::message(format!(
                        "compound `{}`: `{}.{port}` does not match its group's",
                        self.name, self.instances[*member].name
                    )));
                }
            }
            let leader = members
                .iter()
                .position(|m| *m == self.leaders[group])
                .unwrap_or(0);
            merge.reset(leader);
            made.push(MergedPort {
                group,
                port: port.to_owned(),
                merge,
            });
        }
        self.merges.extend(made);
        Ok(())
    }

    /// Member `member` of redundant group `group` leads it from now on: the merged
    /// streams go on from its backlog. Returns the packets replayed and missing.
    fn lead(&mut self, group: usize, member: usize) -> (u64, u64) {
        self.leaders[group] = member;
        let lane = self.groups[group]
            .iter()
            .position(|m| *m == member)
            .unwrap_or(0);
        self.merges
            .iter()
            .filter(|m| m.group == group)
            .map(|m| m.merge.lead(lane))
            .fold((0, 0), |(r, g), (r2, g2)| (r + r2, g + g2))
    }

    /// Record who stands for each instance now in the view (for mapped variables);
    /// if that changed, rules reading mapped variables are evaluated on this turn.
    fn update_standing(&mut self) {
        let standing: Vec<usize> = (0..self.instances.len()).map(|i| self.route(i)).collect();
        if standing != self.view.standing {
            self.view.standing = standing;
            self.restood = true;
        }
    }

    fn refresh(&mut self, index: usize) {
        self.view.instances[index] = self.instances[index].handle.snapshot();
    }

    /// Copy the compound's own default variables into the view (when a rule reads
    /// them) and, every supervisor period, count the time reads as changed.
    fn refresh_compound(&mut self, cx: &Context, changed: &mut HashSet<String>) {
        if self.reads_own
            && let Some(shared) = &cx.shared
        {
            let mut now = Own::default();
            shared.quietly(|monitor| {
                now = Own {
                    result: monitor.result.clone(),
                    error: monitor.error.clone(),
                    quality: monitor.quality,
                    cpu_time: monitor.cpu_time,
                    elapsed_time: monitor.elapsed_time,
                };
            });
            let before = std::mem::replace(&mut self.view.compound, now);
            let after = &self.view.compound;
            for (key, differs) in [
                ("result", before.result != after.result),
                ("error", before.error != after.error),
                ("quality", before.quality != after.quality),
            ] {
                if differs {
                    changed.insert(key.to_owned());
                }
            }
        }
        if self.timed.is_empty() {
            return;
        }
        let now = Instant::now();
        if self.next_timed.is_none_or(|due| now >= due) {
            let period = cx.period().unwrap_or(DEFAULT_SUPERVISION_PERIOD);
            self.next_timed = Some(crate::thread::later(now, period));
            // An instance publishes its times without an event: read the snapshot of
            // every instance a time read names, so the rules see their times now.
            let named: BTreeSet<usize> = self
                .timed
                .iter()
                .filter_map(|key| key.split_once('.'))
                .filter_map(|(instance, _)| self.view.positions.get(instance).copied())
                .collect();
            for index in named {
                self.refresh(index);
            }
            changed.extend(self.timed.iter().cloned());
        }
    }

    fn refresh_own(&mut self, changed: &mut HashSet<String>) {
        for (index, (name, value)) in self.view.own.iter_mut().enumerate() {
            let now = self.supervisor.get(index);
            if *value != now {
                *value = now;
                changed.insert(name.clone());
            }
        }
    }

    /// Start the instances (first start) or bring them back to `ready` (a restart),
    /// and restore the declared arrangement.
    fn start_instances(&mut self, cx: &mut Context) -> Result<(), Fault> {
        if !self.started {
            if let Some(waker) = cx.waker() {
                self.events = self
                    .instances
                    .iter()
                    .map(|i| {
                        // Set: look at whatever came before the subscription too.
                        let flag = Arc::new(AtomicBool::new(true));
                        let events = i
                            .handle
                            .shared
                            .subscribe_flagged(waker.clone(), Arc::clone(&flag));
                        (events, flag)
                    })
                    .collect();
            }
            if let Some(system) = self.system.as_mut() {
                system
                    .start()
                    .map_err(|e| Fault::message(format!("compound `{}`: {e}", self.name)))?;
            }
            self.started = true;
        }
        self.queue.clear();
        for index in 0..self.instances.len() {
            let instance = &mut self.instances[index];
            instance.pending = None;
            instance.restarts.clear();
            instance.handled = false;
            if instance.status == Status::Destroyed {
                continue;
            }
            if instance.handle.is_stuck() {
                return Err(Fault::message(format!(
                    "instance `{}` cannot restart: it is stuck in a section that overran its max_response",
                    instance.name
                )));
            }
            instance.status = if instance.substitutes.is_some() {
                Status::Standby
            } else {
                Status::Active
            };
            let monitor = instance
                .handle
                .wait_for(|m| m.state != State::Starting, INSTANCE_START_TIMEOUT)
                .map_err(|t| Fault::message(t.to_string()))?;
            if monitor.state == State::StartingError {
                return Err(Fault::message(format!(
                    "instance `{}` could not start: {}",
                    instance.name,
                    monitor.error.unwrap_or_default()
                )));
            }
            if monitor.state != State::Ready {
                command(&instance.handle, Controllable::Ready)?;
                let state = instance.handle.state();
                if state != State::Ready {
                    return Err(Fault::message(format!(
                        "instance `{}` could not restart: it is {state}",
                        instance.name
                    )));
                }
            }
        }
        // Every redundant group is led by its first member again; its merged streams
        // count on from where they are.
        for group in 0..self.groups.len() {
            self.leaders[group] = self.groups[group][0];
        }
        for merged in &self.merges {
            merged.merge.reset(0);
        }
        // A destroyed instance's substitute keeps standing for it.
        for index in 0..self.instances.len() {
            if self.instances[index].status == Status::Destroyed
                && let Some(substitute) = self.instances[index].substitute
                && self.instances[substitute].status == Status::Standby
            {
                self.instances[substitute].status = Status::Active;
            }
            self.refresh(index);
        }
        self.rewire()
    }

    /// Bring every instance that runs (or is suspended) to `target`, last declared
    /// first.
    fn instances_to(&mut self, target: Controllable) {
        for instance in self.instances.iter().rev() {
            let state = instance.handle.state();
            let follows = match target {
                Controllable::Ready => matches!(state, State::Running | State::Suspended),
                Controllable::Suspended => {
                    state == State::Running
                        || (state == State::Ready && instance.status == Status::Active)
                }
                Controllable::Running | Controllable::Dead => false,
            };
            if follows && let Err(fault) = command(&instance.handle, target) {
                tracing::warn!(compound = %self.name, "{fault}");
            }
        }
    }

    fn enqueue(&mut self, index: usize) {
        let now = Instant::now();
        self.instances[index].status = Status::Recovering;
        self.queue.push(Recovering {
            instance: index,
            since: now,
            next: crate::thread::later(now, self.retry_every),
            probation: false,
        });
    }

    /// Whether the arrangement can go on without instance `index`.
    fn covered(&self, index: usize) -> bool {
        let instance = &self.instances[index];
        if let Some(group) = instance.group {
            return self.groups[group]
                .iter()
                .any(|m| self.instances[*m].status == Status::Active);
        }
        instance
            .substitute
            .is_some_and(|s| self.instances[s].status == Status::Active)
    }

    /// Instance `index` went to `running_error` (or `starting_error`): its policy.
    fn failed(&mut self, index: usize) -> Result<(), Fault> {
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
            if !self.covered(index) {
                self.step(
                    index,
                    Step::Propagated,
                    "no member of its redundant group is left",
                );
                return Err(self.fault(format!(
                    "every member of the redundant group of `{name}` failed; last: {error}"
                )));
            }
            let standing = self.groups[group]
                .iter()
                .copied()
                .find(|m| self.instances[*m].status == Status::Active);
            if leader && let Some(member) = standing {
                let by = self.instances[member].name.clone();
                let (replayed, missing) = self.lead(group, member);
                self.rewire()
                    .map_err(|fault| self.propagated(index, fault))?;
                let mut detail = String::new();
                if replayed > 0 {
                    detail = format!("{replayed} packet(s) of its backlog continued the stream");
                }
                if missing > 0 {
                    tracing::warn!(compound = %self.name, "{missing} packet(s) missing from the stream of `{by}`'s group");
                    detail.push_str(&format!(
                        "; {missing} packet(s) missing from the stream (beyond its backlog)"
                    ));
                }
                self.step(index, Step::Substituted { by }, detail);
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
                Err(self.fault(format!("instance `{name}` failed: {error}")))
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
                Err(self.fault(format!("instance `{name}` failed to restart: {error}")))
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
    fn schedule_restart(&mut self, index: usize, error: &str) -> Result<(), Fault> {
        let now = Instant::now();
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
            return Err(self.fault(format!(
                "instance `{name}` failed again after {done} restart(s) within {:?} (restart budget spent): {error}",
                budget.window
            )));
        }
        instance.pending = Some(PendingRestart {
            since: now,
            due: crate::thread::later(now, budget.delay(done)),
        });
        self.restarts_due(now)
    }

    /// Do the decided restarts that are due; propagate a stuck instance's fault once
    /// it has been stuck for the recovery deadline.
    fn restarts_due(&mut self, now: Instant) -> Result<(), Fault> {
        for index in 0..self.instances.len() {
            let Some(pending) = self.instances[index].pending else {
                continue;
            };
            let instance = &self.instances[index];
            if instance.handle.is_stuck() {
                if now >= crate::thread::later(pending.since, self.deadline) {
                    let name = instance.name.clone();
                    self.instances[index].pending = None;
                    self.step(
                        index,
                        Step::Propagated,
                        "stuck in a section that overran its max_response",
                    );
                    return Err(self.fault(format!(
                        "instance `{name}` cannot be restarted: it is stuck in a section that overran its max_response, for over {:?}",
                        self.deadline
                    )));
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
    fn recover(&mut self, now: Instant) -> Result<(), Fault> {
        let mut position = 0;
        while position < self.queue.len() {
            let entry = self.queue[position];
            if now < entry.next && now < crate::thread::later(entry.since, self.deadline) {
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
                if let Some(group) = self.instances[index].group {
                    let lane = self.groups[group].iter().position(|m| *m == index);
                    for merged in self.merges.iter().filter(|m| m.group == group) {
                        merged.merge.rejoin(lane.unwrap_or(0));
                    }
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
            if now >= crate::thread::later(entry.since, self.deadline) {
                self.queue.remove(position);
                let name = self.instances[index].name.clone();
                self.instances[index].status = Status::Destroyed;
                self.update_standing();
                let handle = &self.instances[index].handle;
                if handle.is_stuck() {
                    // Its thread takes the command when (if) the section returns.
                    if let Err(rejected) = handle.post(Command::SetState(Controllable::Dead)) {
                        tracing::warn!(compound = %self.name, "{rejected}");
                    }
                } else if let Err(fault) = command(handle, Controllable::Dead) {
                    tracing::warn!(compound = %self.name, "{fault}");
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
                    return Err(self.fault(format!(
                        "instance `{name}` did not recover within {:?} and nothing stands for it",
                        self.deadline
                    )));
                }
                continue;
            }
            // Due for a retry: restart it, on probation until the next retry (not while
            // it is stuck in an overrun section: a command would wait for it). Every
            // attempt is a step, so an operator sees recovery being tried.
            let handle = &self.instances[index].handle;
            let attempt = if handle.is_stuck() {
                Err("still stuck in a section past its max_response".to_owned())
            } else {
                match command(handle, Controllable::Running) {
                    Err(fault) => Err(fault.text().to_owned()),
                    Ok(()) => match handle.state() {
                        State::Running => Ok(()),
                        state => Err(format!("{state} after the restart")),
                    },
                }
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
            entry.next = crate::thread::later(now, self.retry_every);
            position += 1;
        }
        Ok(())
    }

    /// Take the instances' events; run policies; return the variables that changed.
    fn take_events(&mut self) -> Result<HashSet<String>, Fault> {
        let mut changed = HashSet::new();
        for index in 0..self.events.len() {
            // Cleared before the channel is read: an event sent after the read sets it
            // again (it is set before the ring).
            let flag = &self.events[index].1;
            if !flag.load(Ordering::Acquire) || !flag.swap(false, Ordering::AcqRel) {
                continue;
            }
            let mut seen = false;
            let failure =
                |state: State| matches!(state, State::RunningError | State::StartingError);
            while let Ok(event) = self.events[index].0.try_recv() {
                seen = true;
                let instance = &mut self.instances[index];
                let name = &instance.name;
                let key = match event {
                    MonitorEvent::State { from, to } => {
                        if let Some(coordinator) = self.coordinator.as_mut() {
                            coordinator.dirty = true;
                        }
                        if failure(from) && !failure(to) {
                            // It left its fault: the next one is a new fault.
                            instance.handled = false;
                        }
                        format!("{name}.state")
                    }
                    MonitorEvent::Quality(_) => format!("{name}.quality"),
                    MonitorEvent::Pressure(_) | MonitorEvent::Adaptation(_) => {
                        if let Some(coordinator) = self.coordinator.as_mut() {
                            coordinator.dirty = true;
                        }
                        continue;
                    }
                    MonitorEvent::UserState(_) => format!("{name}.user_state"),
                    MonitorEvent::Result(_) => format!("{name}.result"),
                    MonitorEvent::Error(_) => format!("{name}.error"),
                    MonitorEvent::Variable { name: variable, .. } => {
                        // A mapped variable changes with it if this instance stands
                        // for the declared one.
                        for (mapped, (declared, target)) in &self.view.mapped {
                            if *target == variable
                                && self.view.standing.get(*declared) == Some(&index)
                            {
                                changed.insert(mapped.clone());
                            }
                        }
                        format!("{name}.{variable}")
                    }
                    _ => continue,
                };
                changed.insert(key);
            }
            if !seen {
                continue;
            }
            self.refresh(index);
            let state = self.view.instances[index].state;
            let failed = failure(state);
            if !failed {
                self.instances[index].handled = false;
            }
            match self.instances[index].status {
                Status::Active if failed && !self.instances[index].handled => {
                    self.instances[index].handled = true;
                    let outcome = self.failed(index);
                    outcome.map_err(|fault| self.propagated(index, fault))?;
                }
                Status::Recovering if failed => {
                    if let Some(entry) = self.queue.iter_mut().find(|e| e.instance == index) {
                        entry.probation = false;
                    }
                }
                _ => {}
            }
        }
        Ok(changed)
    }
}

impl Automaton for Compound {
    fn spec(&self) -> &'static Spec {
        self.spec
    }

    fn start(&mut self, cx: &mut Context) -> Result<(), Fault> {
        self.evaluated_in = None;
        self.start_instances(cx)?;
        self.adapt_start(cx);
        Ok(())
    }

    fn stop(&mut self, _cx: &mut Context) {
        self.instances_to(Controllable::Ready);
    }

    fn section(&mut self, state: usize, section: Section, cx: &mut Context) -> Result<(), Fault> {
        self.sectioned = true;
        let mut scx = SupervisorCx {
            rt: cx,
            view: &self.view,
            instances: &mut self.commander,
        };
        let outcome = self.supervisor.section(state, section, &mut scx);
        // The commands it gave are steps, published when the call returns.
        cx.supervision.append(&mut self.commander.take_steps());
        outcome
    }

    fn choose(&mut self, state: usize, cx: &mut Context) -> Option<usize> {
        let mut scx = SupervisorCx {
            rt: cx,
            view: &self.view,
            instances: &mut self.commander,
        };
        let target = self.supervisor.choose(state, &mut scx);
        cx.supervision.append(&mut self.commander.take_steps());
        target
    }

    fn exception(&mut self, _exception: usize, _message: &str, _cx: &mut Context) {}

    fn answer(&mut self, _output: usize, _cx: &mut Context) -> Result<(), Fault> {
        Ok(())
    }

    fn configure(&mut self, _configuration: &Value) -> Result<(), String> {
        Err("a compound has no configuration of its own; configure its instances".to_owned())
    }

    fn set(&mut self, variable: usize, value: &Value) -> Result<(), String> {
        if let Some(mapped) = self.mapped.get(variable) {
            let target = self.route(mapped.instance);
            return self.instances[target]
                .handle
                .command(Command::Set(mapped.variable.clone(), value.clone()))
                .map_err(|rejected| rejected.reason);
        }
        self.supervisor.set(variable - self.own_offset, value)
    }

    fn get(&self, variable: usize) -> Value {
        if let Some(mapped) = self.mapped.get(variable) {
            let target = self.route(mapped.instance);
            return self.view.instances[target]
                .variables
                .iter()
                .find(|(name, _)| *name == mapped.variable)
                .map_or(Value::Unit, |(_, value)| value.clone());
        }
        self.supervisor.get(variable - self.own_offset)
    }

    fn before_running(&mut self, _cx: &mut Context) -> Result<(), Fault> {
        // The supervisor enters (or resumes) a state: its rules are evaluated afresh.
        self.evaluated_in = None;
        for (index, instance) in self.instances.iter().enumerate() {
            let held = self
                .coordinator
                .as_ref()
                .is_some_and(|c| c.suspended[index]);
            if instance.status == Status::Active
                && !held
                && matches!(instance.handle.state(), State::Ready | State::Suspended)
            {
                command(&instance.handle, Controllable::Running)?;
            }
        }
        Ok(())
    }

    fn after_transition(&mut self, _from: State, to: State, _cx: &mut Context) {
        match to {
            State::Ready => self.instances_to(Controllable::Ready),
            State::Suspended => self.instances_to(Controllable::Suspended),
            State::Dead => {
                if let Some(system) = self.system.take() {
                    let report = system.shutdown();
                    if !report.clean() {
                        tracing::warn!(compound = %self.name, "instances not joined: {report:?}");
                    }
                }
            }
            _ => {}
        }
    }

    fn supervises(&self) -> bool {
        true
    }

    fn supervise(&mut self, state: usize, cx: &mut Context) -> Result<Option<usize>, Fault> {
        let outcome = self.supervise_turn(state, cx);
        if let Some(coordinator) = self.coordinator.as_mut()
            && coordinator
                .settle_until
                .is_some_and(|until| Instant::now() >= until)
        {
            // Settled: promotion may be due.
            coordinator.settle_until = None;
            coordinator.dirty = true;
        }
        if outcome.is_ok() && self.coordinator.as_ref().is_some_and(|c| c.dirty) {
            self.adapt_turn(cx);
        }
        cx.supervision.append(&mut self.steps);
        outcome
    }

    fn set_degradation(&mut self, level: u32, cx: &mut Context) -> Result<(), String> {
        let name = self.name.clone();
        let Some(coordinator) = self.coordinator.as_mut() else {
            return Err("adaptation is off in this compound".to_owned());
        };
        if level > coordinator.max_level {
            return Err(format!(
                "degradation level {level} out of range: the highest is {}",
                coordinator.max_level
            ));
        }
        let from = coordinator.cap;
        coordinator.cap = level;
        coordinator.floor = level.saturating_sub(coordinator.config.width);
        coordinator.initialized = true;
        coordinator.dirty = true;
        if from != level {
            let step = Adaptation {
                component: name,
                action: if level > from {
                    AdaptAction::Degraded
                } else {
                    AdaptAction::Promoted
                },
                from,
                to: level,
                period: None,
                quality: None,
                detail: "current maximum level of the instances, set through the control port"
                    .to_owned(),
            };
            let floor = coordinator.floor;
            if let Some(shared) = &cx.shared {
                shared.adaptation_step(step, |status| {
                    status.level = level;
                    status.floor = floor;
                });
                // The verdict published so far was about the previous level: withdraw
                // it, as an atomic component does when its level changes, so that the
                // supervisor above does not act on it again before this compound's
                // next turn judges the new level.
                let load = shared.snapshot().adaptation.load;
                shared.set_pressure(Pressure::Nominal, load);
            }
        }
        Ok(())
    }

    fn entered(&mut self, state: usize) {
        // Whatever led there (a rule, `after`, `on`, `may`), the next turn, taken at
        // once, evaluates every rule of the entered state. (Re-entering the state
        // whose rules were evaluated last changes nothing they read: as before, only
        // changes make them evaluated again, so a rule leading back to its own state
        // does not fire in a loop.)
        if self.evaluated_in != Some(state) {
            self.fresh = true;
        }
    }

    fn wake_at(&self) -> Option<Instant> {
        let queue = self.queue.iter().map(|entry| {
            entry
                .next
                .min(crate::thread::later(entry.since, self.deadline))
        });
        // A stuck instance's return is an event; its deadline is a timer.
        let restarts = self.instances.iter().filter_map(|i| {
            let pending = i.pending?;
            Some(if i.handle.is_stuck() {
                crate::thread::later(pending.since, self.deadline)
            } else {
                pending.due
            })
        });
        let dirty = self.coordinator.as_ref().is_some_and(|c| c.dirty);
        let settle = self.coordinator.as_ref().and_then(|c| c.settle_until);
        let fresh = (self.fresh || self.sectioned || dirty).then(Instant::now);
        // Packets held at an exported input (the instance's `Block` fifo was full):
        // retried soon.
        let held = self
            .exports
            .iter()
            .any(|export| export.held())
            .then(|| crate::thread::later(Instant::now(), EXPORT_RETRY));
        queue
            .chain(restarts)
            .chain(fresh)
            .chain(held)
            .chain(settle)
            .chain(self.next_timed)
            .min()
    }
}

impl Compound {
    /// One supervision turn: exports, instance events and policies, the recovery
    /// queue, then the rules of supervisor state `state`.
    fn supervise_turn(&mut self, state: usize, cx: &Context) -> Result<Option<usize>, Fault> {
        for export in &mut self.exports {
            export.forward();
        }
        self.fresh = false;
        let mut changed = self.take_events()?;
        if !self.queue.is_empty() {
            self.recover(Instant::now())?;
        }
        if self.instances.iter().any(|i| i.pending.is_some()) {
            self.restarts_due(Instant::now())?;
        }
        self.refresh_own(&mut changed);
        self.refresh_compound(cx, &mut changed);
        if std::mem::take(&mut self.restood) {
            changed.extend(self.view.mapped.keys().cloned());
        }
        let entered = self.evaluated_in != Some(state);
        // After a supervisor section every rule of the state is evaluated: the section
        // may have changed what no `reads` names (its `local` variables).
        let sectioned = std::mem::take(&mut self.sectioned);
        if !entered && !sectioned && changed.is_empty() {
            return Ok(None);
        }
        self.evaluated_in = Some(state);
        let view = &self.view;
        let holds = |rule: &&Rule| rule.state == state && (rule.test)(view);
        let fired = if entered || sectioned {
            self.rules.iter().find(holds).map(|rule| rule.target)
        } else {
            // Only the rules reading a changed variable, in declaration order.
            let mut candidates: Vec<usize> = changed
                .iter()
                .filter_map(|read| self.by_read.get(read))
                .flatten()
                .copied()
                .collect();
            candidates.sort_unstable();
            candidates.dedup();
            candidates
                .into_iter()
                .map(|index| &self.rules[index])
                .find(holds)
                .map(|rule| rule.target)
        };
        Ok(fired)
    }
}

impl Compound {
    /// Set up adaptation at the first start: the cap (top level: the interval's
    /// width; nested: 0, until the supervisor above grants a level) and the published
    /// status.
    fn adapt_start(&mut self, cx: &mut Context) {
        let max_level = self.adaptive_max_level();
        let Some(coordinator) = self.coordinator.as_mut() else {
            return;
        };
        coordinator.max_level = max_level;
        let managed = cx
            .shared
            .as_ref()
            .is_some_and(|shared| shared.adapt_managed.load(Ordering::Acquire));
        if !coordinator.initialized {
            coordinator.initialized = true;
            coordinator.cap = if managed {
                0
            } else {
                coordinator.config.width.min(max_level)
            };
            coordinator.floor = 0;
        }
        coordinator.dirty = true;
        let (cap, floor) = (coordinator.cap, coordinator.floor);
        if let Some(shared) = &cx.shared {
            shared.quietly(|monitor| {
                let status = &mut monitor.adaptation;
                status.enabled = true;
                status.level = cap;
                status.floor = floor;
                status.max_level = max_level;
            });
        }
    }

    /// The highest ladder top among the instances that adapt.
    fn adaptive_max_level(&self) -> u32 {
        self.view
            .instances
            .iter()
            .filter(|m| m.adaptation.enabled)
            .map(|m| m.adaptation.max_level)
            .max()
            .unwrap_or(0)
    }

    /// The instances taking part in adaptation, as the policy sees them: those
    /// active and running with adaptation on, and those suspended by adaptation.
    fn members(&mut self) -> (Vec<Member>, Vec<usize>) {
        let now = Instant::now();
        let Some(coordinator) = self.coordinator.as_mut() else {
            return (Vec::new(), Vec::new());
        };
        let mut members = Vec::new();
        let mut indices = Vec::new();
        for (index, instance) in self.instances.iter().enumerate() {
            let monitor = &self.view.instances[index];
            let suspended = coordinator.suspended[index];
            let running = instance.status == Status::Active && monitor.state == State::Running;
            if !monitor.adaptation.enabled || !(running || suspended) {
                continue;
            }
            let mut level = monitor.adaptation.level;
            let mut pressure = monitor.adaptation.pressure;
            if let Some((commanded, since)) = coordinator.pending[index] {
                if commanded == level || now.saturating_duration_since(since) > DEFAULT_PENDING {
                    coordinator.pending[index] = None;
                } else {
                    // Not applied yet: its verdict is about the level before.
                    level = commanded;
                    pressure = Pressure::Nominal;
                }
            }
            members.push(Member {
                name: instance.name.clone(),
                priority: monitor.priority,
                level,
                max_level: monitor.adaptation.max_level,
                min_level: monitor.adaptation.min_level,
                pressure,
                load: monitor.adaptation.load,
                cpu_share: monitor.adaptation.cpu_share,
                period: monitor.period,
                suspended,
            });
            indices.push(index);
        }
        (members, indices)
    }

    /// One adaptation turn: decide (Figures 6 and 7) and act, until an instance was
    /// commanded or nothing is left to do. Commands are posted without waiting (an
    /// instance in a long section takes them when it returns).
    fn adapt_turn(&mut self, cx: &mut Context) {
        let max_level = self.adaptive_max_level();
        let managed = cx
            .shared
            .as_ref()
            .is_some_and(|shared| shared.adapt_managed.load(Ordering::Acquire));
        let shared = cx.shared.clone();
        let publish = |step: Adaptation, cap: u32, floor: u32| {
            if let Some(shared) = &shared {
                shared.adaptation_step(step, |status| {
                    status.level = cap;
                    status.floor = floor;
                });
            }
        };
        if let Some(coordinator) = self.coordinator.as_mut() {
            coordinator.dirty = false;
            coordinator.max_level = max_level;
        }
        let mut decision = Decision::Hold;
        for _ in 0..8 {
            let (members, indices) = self.members();
            let Some(coordinator) = self.coordinator.as_mut() else {
                return;
            };
            let now = Instant::now();
            if let Some(resumed) = coordinator.resumed_at
                && now.saturating_duration_since(resumed)
                    > coordinator.settling(&members, &self.view.instances, &indices)
            {
                // The last resume held through a settling time: no backoff any more.
                coordinator.resumed_at = None;
                coordinator.backoff = 1;
            }
            if members.iter().any(|m| m.pressure == Pressure::Violation) {
                coordinator.settle(&members, &self.view.instances, &indices, now);
            }
            let settled = match coordinator.settle_until {
                Some(until) if now < until => false,
                Some(_) => {
                    coordinator.settle_until = None;
                    true
                }
                None => true,
            };
            let levels = Levels {
                cap: coordinator.cap,
                floor: coordinator.floor,
                top: !managed,
                reconfiguration: coordinator.config.reconfiguration,
                settled,
            };
            let (decided, note) =
                crate::adapt::decide_explained(&members, levels, &*coordinator.selector);
            decision = decided;
            if let Some(note) = &note {
                tracing::warn!(compound = %self.name, "adaptation: {note}");
            }
            let noted = |detail: String| match &note {
                Some(note) => format!("{detail} ({note})"),
                None => detail,
            };
            if decision != Decision::Exhausted {
                coordinator.exhausted = false;
            }
            let (cap, floor, width) =
                (coordinator.cap, coordinator.floor, coordinator.config.width);
            let own = |action, from, to, detail: String| Adaptation {
                component: self.name.clone(),
                action,
                from,
                to,
                period: None,
                quality: None,
                detail,
            };
            let violators = || {
                members
                    .iter()
                    .filter(|m| m.pressure == Pressure::Violation)
                    .map(|m| m.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            match decision {
                Decision::RaiseCap => {
                    coordinator.cap = cap + 1;
                    coordinator.floor = (cap + 1).saturating_sub(width);
                    let detail = format!(
                        "every instance at the current maximum; time violation at {}",
                        violators()
                    );
                    publish(
                        own(AdaptAction::CapRaised, cap, cap + 1, detail),
                        cap + 1,
                        coordinator.floor,
                    );
                    continue;
                }
                Decision::LowerFloor => {
                    coordinator.floor = floor - 1;
                    coordinator.cap = (floor - 1 + width).min(max_level.max(width));
                    let detail = "every instance at the current minimum, spare time".to_owned();
                    publish(
                        own(AdaptAction::FloorLowered, floor, floor - 1, detail),
                        coordinator.cap,
                        floor - 1,
                    );
                    continue;
                }
                Decision::Degrade(m) | Decision::Promote(m) | Decision::Clamp(m) => {
                    let member = &members[m];
                    let (to, action, detail) = match decision {
                        Decision::Degrade(_) => (
                            member.level.saturating_add(1),
                            AdaptAction::Degraded,
                            noted(format!("time violation at {}", violators())),
                        ),
                        Decision::Promote(_) => (
                            member.level.saturating_sub(1),
                            AdaptAction::Promoted,
                            noted("spare time".to_owned()),
                        ),
                        _ => (
                            cap.max(member.min_level),
                            AdaptAction::Promoted,
                            format!("above the current maximum level {cap}"),
                        ),
                    };
                    let index = indices[m];
                    coordinator.pending[index] = Some((to, Instant::now()));
                    let step = Adaptation {
                        component: member.name.clone(),
                        action,
                        from: member.level,
                        to,
                        period: None,
                        quality: None,
                        detail,
                    };
                    publish(step, cap, floor);
                    post(&self.instances[index].handle, Command::SetDegradation(to));
                }
                Decision::Suspend(m) | Decision::Resume(m) => {
                    let index = indices[m];
                    let suspend = matches!(decision, Decision::Suspend(_));
                    coordinator.suspended[index] = suspend;
                    if suspend {
                        coordinator.suspended_now(&members, &self.view.instances, &indices, now);
                    } else {
                        coordinator.resumed_at = Some(now);
                    }
                    let (action, target, detail) = if suspend {
                        (
                            AdaptAction::Suspended,
                            Controllable::Suspended,
                            format!("degradation exhausted; time violation at {}", violators()),
                        )
                    } else {
                        (
                            AdaptAction::Resumed,
                            Controllable::Running,
                            "spare time".to_owned(),
                        )
                    };
                    let level = members[m].level;
                    let step = Adaptation {
                        component: members[m].name.clone(),
                        action,
                        from: level,
                        to: level,
                        period: None,
                        quality: None,
                        detail,
                    };
                    publish(step, cap, floor);
                    post(&self.instances[index].handle, Command::SetState(target));
                }
                Decision::Exhausted if !coordinator.exhausted => {
                    coordinator.exhausted = true;
                    let detail = format!(
                        "every instance at the highest level; time violation at {}",
                        violators()
                    );
                    publish(own(AdaptAction::Exhausted, cap, cap, detail), cap, floor);
                }
                Decision::NotifyHigher | Decision::ReportSpare => {
                    let pressure = decision.pressure();
                    let already = shared
                        .as_ref()
                        .is_some_and(|s| s.snapshot().adaptation.pressure == pressure);
                    if !already {
                        let (action, detail) = if pressure == Pressure::Violation {
                            (
                                AdaptAction::NotifiedHigher,
                                format!(
                                    "every instance at the current maximum level {cap}; time violation at {}",
                                    violators()
                                ),
                            )
                        } else {
                            (
                                AdaptAction::ReportedSpare,
                                "spare time; no instance above the current minimum".to_owned(),
                            )
                        };
                        publish(own(action, cap, cap, detail), cap, floor);
                    }
                }
                Decision::Exhausted | Decision::Hold => {}
            }
            break;
        }
        if let Some(shared) = &shared {
            shared.set_pressure(decision.pressure(), 0.0);
            let (cap, floor) = self
                .coordinator
                .as_ref()
                .map_or((0, 0), |c| (c.cap, c.floor));
            shared.quietly(|monitor| {
                monitor.adaptation.level = cap;
                monitor.adaptation.floor = floor;
                monitor.adaptation.max_level = max_level;
            });
        }
    }
}

impl Coordinator {
    /// The settling time: `settle_periods` of the slowest member's cycles (its period,
    /// plus its section's overrun while it is late), where `settle_periods` is the
    /// longest of the members' own (`hold_periods + window + 1` of their detectors,
    /// published as [`crate::adapt::AdaptStatus::settle_periods`]) and the
    /// compound's configuration's, so that a member with a longer hold-down is not
    /// taken as settled before it can show a verdict; times the reconfiguration
    /// backoff.
    fn settling(&self, members: &[Member], monitors: &[Monitor], indices: &[usize]) -> Duration {
        let cycle = members
            .iter()
            .filter_map(|m| Some(m.period?.mul_f64(1.0 + m.load.clamp(0.0, 10.0))))
            .max()
            .unwrap_or(DEFAULT_SUPERVISION_PERIOD);
        let periods = settle_periods(
            &self.config,
            indices
                .iter()
                .filter_map(|i| monitors.get(*i))
                .map(|m| m.adaptation.settle_periods),
        );
        cycle
            .saturating_mul(periods)
            .saturating_mul(self.backoff.max(1))
    }

    /// A time violation now: promotion waits for the settling time, long enough for
    /// a member degraded now to pass its hold-down and fill its detection window.
    fn settle(
        &mut self,
        members: &[Member],
        monitors: &[Monitor],
        indices: &[usize],
        now: Instant,
    ) {
        let until = crate::thread::later(now, self.settling(members, monitors, indices));
        self.settle_until = Some(self.settle_until.map_or(until, |before| before.max(until)));
    }

    /// An instance was suspended now (reconfiguration): a suspension that follows a
    /// resume within the settling time shows the resume was premature, so the next
    /// resume waits twice as long (up to `max_backoff` times); otherwise the backoff
    /// starts again. Without this, a load that comes and goes would suspend and resume
    /// an instance forever at the settling time's pace.
    fn suspended_now(
        &mut self,
        members: &[Member],
        monitors: &[Monitor],
        indices: &[usize],
        now: Instant,
    ) {
        let window = self.settling(members, monitors, indices);
        let premature = self
            .resumed_at
            .is_some_and(|resumed| now.saturating_duration_since(resumed) <= window);
        self.backoff = next_backoff(self.backoff, premature, self.config.max_backoff);
        self.settle(members, monitors, indices, now);
    }
}

/// The periods a supervisor settles for: the longest of its own configuration's
/// `hold_periods + window + 1` and its members' (`published`).
fn settle_periods(own: &AdaptConfig, published: impl IntoIterator<Item = u32>) -> u32 {
    let own = own
        .hold_periods
        .saturating_add(own.window)
        .saturating_add(1);
    published.into_iter().fold(own, u32::max)
}

/// The reconfiguration backoff after a suspension: doubled when the suspension
/// followed a resume too soon (`premature`), up to `max` (at least 1); 1 otherwise.
fn next_backoff(backoff: u32, premature: bool, max: u32) -> u32 {
    if premature {
        backoff.saturating_mul(2).min(max.max(1))
    } else {
        1
    }
}

/// How long a level commanded to an instance is taken as applied before its monitor
/// shows it (a command the instance rejected is forgotten after this).
const DEFAULT_PENDING: Duration = Duration::from_secs(2);

/// Queue `command` at `handle` without waiting for the answer (the supervisor never
/// waits for an instance in a long section).
fn post(handle: &Handle, command: Command) {
    if let Err(rejected) = handle.post(command) {
        tracing::warn!("adaptation: {rejected}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_backoff_doubles_from_the_second_restart_up_to_its_maximum() {
        let budget = Budget {
            restarts: 10,
            window: Duration::from_secs(10),
            backoff: Duration::from_millis(10),
            backoff_max: Duration::from_millis(50),
        };
        let delays: Vec<_> = (0..6).map(|done| budget.delay(done)).collect();
        assert_eq!(
            delays,
            [0, 10, 20, 40, 50, 50].map(Duration::from_millis).to_vec()
        );
        // No overflow however many restarts were done.
        assert_eq!(budget.delay(usize::MAX), Duration::from_millis(50));
    }

    #[test]
    fn a_compound_settles_for_its_slowest_settling_member() {
        let own = AdaptConfig::default(); // 5 + 4 + 1
        assert_eq!(settle_periods(&own, []), 10);
        assert_eq!(settle_periods(&own, [6, 44, 0]), 44);
        assert_eq!(settle_periods(&own, [6]), 10);
        let huge = AdaptConfig {
            hold_periods: u32::MAX,
            ..own
        };
        assert_eq!(settle_periods(&huge, [1]), u32::MAX);
    }

    #[test]
    fn a_premature_resume_doubles_the_wait_before_the_next_one() {
        // Suspended, resumed, suspended again at once: 2, 4, 8, then the maximum.
        let backoffs: Vec<u32> = (0..5)
            .scan(1, |backoff, _| {
                *backoff = next_backoff(*backoff, true, 8);
                Some(*backoff)
            })
            .collect();
        assert_eq!(backoffs, [2, 4, 8, 8, 8]);
        // A resume that held: back to 1.
        assert_eq!(next_backoff(8, false, 8), 1);
        // No overflow, and a zero maximum still means "no backoff".
        assert_eq!(next_backoff(u32::MAX, true, u32::MAX), u32::MAX);
        assert_eq!(next_backoff(4, true, 0), 1);
    }
}
