//! [`CompoundBuilder`]: a compound's description (instances, connections, exports,
//! mappings, policies, substitutes, redundant groups, rules) checked and assembled
//! into an ordinary [`Component`].

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use crate::adapt::{AdaptConfig, ProtectPriority, Selector};
use crate::commander::{Commander, DEFAULT_SUPERVISOR_COMMAND_TIMEOUT};
use crate::handle::Handle;
use crate::port::{
    DataOut, ErasedInput, ErasedOutput, FifoIn, InputPort, LastIn, OutputPort, Packet, PosterIn,
    PosterOut, TickIn, TickOut, UfifoIn,
};
use crate::spec::{InputKind, InputSpec, OutputKind, OutputSpec, Spec, VarKind, VarSpec};
use crate::system::{Component, ConnectError, PortSet, System};

use super::coordinator::Coordinator;
use super::error::CompoundError;
use super::exports::{Export, InputExport, OutputExport, TickExport, Twin, route_pulls};
use super::links::{Link, LinkVia, Via};
use super::policy::{
    Budget, DEFAULT_BACKOFF, DEFAULT_BACKOFF_MAX, DEFAULT_RESTART_WINDOW, DEFAULT_RESTARTS, Policy,
};
use super::reads::{Changed, Reads};
use super::state::{Compound, Instance, Mapped, Status};
use super::supervisor::{DEFAULT_SUPERVISION_PERIOD, Supervisor};
use super::view::{OWN_DEFAULTS, Own, Rule, Test, View};

/// A name made `'static` for the compound's assembled `Spec` (leaked once per build).
fn leak_str(text: &str) -> &'static str {
    Box::leak(text.to_owned().into_boxed_str())
}

/// Builds a compound component: instances, connections, mappings, policies,
/// supervisor rules. See the module documentation and `docs/runtime.md`.
pub struct CompoundBuilder {
    pub(super) name: String,
    pub(super) supervisor: Box<dyn Supervisor>,
    pub(super) system: System,
    pub(super) instances: Vec<Instance>,
    pub(super) links: Vec<Link>,
    pub(super) mapped: Vec<(String, String, VarKind)>,
    pub(super) policies: Vec<(String, Policy)>,
    pub(super) substitutes: Vec<(String, String)>,
    pub(super) groups: Vec<Vec<String>>,
    pub(super) rules: Vec<(String, String, Vec<String>, Test)>,
    pub(super) retry_every: Duration,
    pub(super) deadline: Duration,
    pub(super) budget: Budget,
    pub(super) errors: Vec<CompoundError>,
    pub(super) exports: Vec<Box<dyn Export>>,
    pub(super) inputs: Vec<InputSpec>,
    pub(super) outputs: Vec<OutputSpec>,
    pub(super) ports: PortSet,
    pub(super) adaptation: AdaptConfig,
    pub(super) selector: Box<dyn Selector>,
    pub(super) command_timeout: Duration,
}

/// A compound's description checked and resolved ([`CompoundBuilder::resolve`]).
pub(crate) struct Resolved {
    /// The compound's spec: the supervisor's states, the mapped and own variables,
    /// the exported ports.
    pub(crate) spec: &'static Spec,
    pub(super) mapped: Vec<Mapped>,
    pub(super) rules: Vec<Rule>,
    /// What the rules read, resolved to ids.
    pub(super) reads: Reads,
    pub(super) view: View,
    pub(super) group_members: Vec<Vec<usize>>,
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

    /// How long a supervisor's command ([`SupervisorCx::instances`](crate::SupervisorCx::instances)) waits for an
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
    pub(super) fn exported_port<T: 'static>(
        &mut self,
        target: &str,
        input: bool,
        kinds: &'static str,
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
            self.errors.push(CompoundError::Export {
                compound: self.name.clone(),
                target: target.to_owned(),
                direction,
                kinds,
                packets,
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
            full_since: Vec::new(),
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

    pub(super) fn export_output_of<T: Packet>(
        mut self,
        name: &str,
        target: &str,
        kinds: &'static str,
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
                left_at_join: 0,
                retry: None,
            }),
            Err(source) => self.errors.push(CompoundError::Instance {
                compound: self.name.clone(),
                source: Box::new(source),
            }),
        }
        self
    }

    /// An instance declared `on "node"` (`docs/distribution.md`, "Remote instances
    /// from the description"): with a network placer installed on this thread
    /// ([`crate::remote::install`]), a proxy stands here for `component` built on
    /// `node`; without one, or when `node` is this process's own, `component` runs
    /// here as with [`CompoundBuilder::instance`].
    pub fn instance_on(mut self, node: &str, component: Component) -> CompoundBuilder {
        let name = component.name().to_owned();
        match crate::remote::place(&self.name, node, component) {
            Ok(component) => self.instance(component),
            Err(source) => {
                self.errors.push(CompoundError::Placement {
                    compound: self.name.clone(),
                    instance: name,
                    node: node.to_owned(),
                    source,
                });
                self
            }
        }
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
        let link_via: LinkVia = Arc::new(
            move |output: &ErasedOutput, old: Option<&ErasedInput>, input: &ErasedInput| {
                output.type_id == std::any::TypeId::of::<A>()
                    && input.type_id == std::any::TypeId::of::<B>()
                    && crate::port::relink_converted::<A, B>(
                        output,
                        old,
                        input,
                        Arc::clone(&direct),
                    )
            },
        );
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

    /// `thread name { a, b, ... }`: the instances `members` (atomic, local) run on one
    /// thread, an execution group ([`System::group`](crate::System::group)).
    pub fn thread(mut self, name: &str, members: &[&str]) -> CompoundBuilder {
        if let Err(source) = self.system.group(name, members) {
            self.errors.push(CompoundError::Instance {
                compound: self.name.clone(),
                source: Box::new(source),
            });
        }
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
    /// `elapsed_time`. An instance's `period`, `max_response` and `priority` change
    /// with an event; times (`instance.cpu_time`, `instance.elapsed_time` and the
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

    pub(super) fn unknown(&self, what: &'static str, name: &str) -> CompoundError {
        CompoundError::Unknown {
            compound: self.name.clone(),
            what,
            name: name.to_owned(),
        }
    }

    pub(super) fn instance_index(&self, name: &str) -> Result<usize, CompoundError> {
        self.instances
            .iter()
            .position(|i| i.name == name)
            .ok_or_else(|| self.unknown("instance", name))
    }

    pub(super) fn arrangement(&self, detail: String) -> CompoundError {
        CompoundError::Arrangement {
            compound: self.name.clone(),
            detail,
        }
    }

    /// Whether instances `a` and `b` can stand for each other: the same ports (by name,
    /// with their kind, packet type and pull model; queue sizes may differ) and the
    /// same observable and controllable variables (by name, with their kind and
    /// type), in any order. `coolc` checks the same (`coolc::check::interface_mismatch`).
    pub(super) fn same_interface(&self, a: usize, b: usize) -> Result<(), CompoundError> {
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

    /// Everything of the description checked and resolved (policies, substitutes,
    /// groups, connections' ends, mapped variables, rules), the compound's spec and
    /// its supervisor's first view: what [`CompoundBuilder::build`] and the
    /// supervisor harness (`crate::harness::supervisor`) start from.
    pub(crate) fn resolve(&mut self) -> Result<Resolved, CompoundError> {
        if !self.errors.is_empty() {
            return Err(self.errors.swap_remove(0));
        }
        // A substitute has no connections of its own until it stands in: in an
        // execution group it runs where its original's would put it (after what
        // feeds the original, before what the original feeds), so that standing in
        // it is in the same cycle's flow. Its connections only order the group: they
        // never make it refuse to start.
        let made: Vec<(&str, &str)> = self.links.iter().map(Link::ends).collect();
        let stand_ins: Vec<(String, String)> = self
            .substitutes
            .iter()
            .flat_map(|(substitute, primary)| {
                let moved = move |end: &str| {
                    end.split_once('.')
                        .filter(|(instance, _)| instance == primary)
                        .map(|(_, port)| format!("{substitute}.{port}"))
                };
                made.iter()
                    .filter_map(move |&(from, to)| match (moved(from), moved(to)) {
                        (None, None) => None,
                        (moved_from, moved_to) => Some((
                            moved_from.unwrap_or_else(|| from.to_owned()),
                            moved_to.unwrap_or_else(|| to.to_owned()),
                        )),
                    })
            })
            .collect();
        let stand_ins: Vec<(&str, &str)> = stand_ins
            .iter()
            .map(|(from, to)| (from.as_str(), to.as_str()))
            .collect();
        if let Err(source) = self.system.plan_groups(&made, &stand_ins) {
            return Err(CompoundError::Instance {
                compound: self.name.clone(),
                source: Box::new(source),
            });
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
        // A supervisor always has a state (coolc gives a compound without one a
        // `supervising` state); only an atomic component may have no automaton.
        if own.states.is_empty() {
            return Err(CompoundError::NoSupervisorState {
                compound: self.name.clone(),
            });
        }
        if let Err(source) = own.validate() {
            return Err(CompoundError::Supervisor {
                compound: self.name.clone(),
                source,
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
                        source: Box::new(ConnectError::BadAddress {
                            address: address.to_owned(),
                        }),
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
                range: declared.range,
            });
            mapped.push(Mapped {
                instance: index,
                variable: variable.to_owned(),
            });
        }
        variables.extend(own.variables.iter().copied());
        // Rules.
        let mut rules = Vec::new();
        let mut rule_reads = Vec::new();
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
                reads: Vec::new(),
                test,
            });
            rule_reads.push(reads);
        }
        let reads = Reads::new(
            rule_reads.iter().map(Vec::as_slice),
            &self
                .instances
                .iter()
                .map(|i| (i.name.as_str(), i.spec))
                .collect::<Vec<_>>(),
            &self
                .mapped
                .iter()
                .zip(&mapped)
                .map(|((name, _, _), m)| (name.as_str(), m.instance, m.variable.as_str()))
                .collect::<Vec<_>>(),
            &own.variables.iter().map(|v| v.name).collect::<Vec<_>>(),
        );
        for (rule, keys) in rules.iter_mut().zip(&rule_reads) {
            rule.reads = reads.ids_of(keys);
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
        Ok(Resolved {
            spec,
            mapped,
            rules,
            reads,
            view,
            group_members,
        })
    }

    /// The compound as a component, ready for [`System::add`] (or for another
    /// compound's [`CompoundBuilder::instance`]).
    pub fn build(mut self) -> Result<Component, CompoundError> {
        let Resolved {
            spec,
            mapped,
            rules,
            reads,
            view,
            group_members,
        } = self.resolve()?;
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
            changed: Changed::new(reads.len()),
            reads_own: reads.reads_own(),
            reads,
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
            next_timed: None,
            moves: Vec::new(),
            clock_wait: None,
            stop_by: None,
            clock: crate::clock::Clock::real(),
            deferred_faults: false,
        };
        Ok(Component::driven(self.name, Box::new(compound), self.ports).with_instances(handles))
    }

    pub(super) fn check_read(&self, read: &str, own: &Spec) -> Result<(), CompoundError> {
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
                        | "period"
                        | "max_response"
                        | "priority"
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
