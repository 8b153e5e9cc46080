//! Remote instances (`instance x: T on "node";`): the seam between a compound and a
//! network layer (`docs/distribution.md`, "Remote instances from the description").
//!
//! The core runtime has no network code. A network layer (`coolbot-zenoh`) installs a
//! [`Placer`] on the thread that builds the compounds ([`install`]); a compound built
//! there while one is installed
//! asks it, for each instance declared `on "node"`, for the far end of a *proxy*
//! ([`Remote`]): the ports the proxy has in the instance's place (same names, kinds
//! and packet types, bridged to the instance on its node) and a [`RemoteEnd`] that
//! builds the instance there, forwards commands and reports what the instance's
//! monitoring port says. The proxy is a component with the instance's spec, so the
//! compound's connections, rules, mapped variables, policies, substitution,
//! redundancy and supervisor commands work on it unchanged:
//!
//! - its user state, result, error and variables mirror the remote instance's, and so
//!   do its quality level, period, missed deadlines, overruns, CPU and elapsed time
//!   (rules reading `<instance>.quality` or `.cpu_time` read the remote instance's;
//!   the proxy's own thread's times are not published);
//! - the remote instance failing (`running_error`, `starting_error`), going to `dead`
//!   without the compound's command (an operator's `coolctl set`, its agent stopping),
//!   falling silent (its monitoring port unanswered for longer than the network
//!   layer's bound, [`RemoteEnd::view`]) or its node being lost, is a fault of the
//!   proxy (`running_error` with the reason), handled by the compound's policy; the
//!   remote instance finishing its task (`end`) ends the proxy's too;
//! - commands given to the proxy go to the remote instance (state changes, variables,
//!   configuration, period, quality, priority, degradation), each answered by it;
//! - a restart of the proxy (a policy's or the recovery queue's) builds the instance
//!   again (a new generation) if it is gone: its node lost it, it is `dead`, or it fell
//!   silent.
//!
//! With no placer installed (a process that is not on a network) an `on "node"`
//! instance runs in the compound's own process, and a `tracing` line says so.

use std::cell::RefCell;
use std::marker::PhantomData;
use std::sync::Arc;
use std::time::{Duration, Instant};

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::automaton::{Automaton, Driven};
use crate::monitor::{Command, Monitor, MonitorEvent};
use crate::port::Packet;
use crate::spec::{Spec, StateSpec, TimingSpec};
use crate::table::{Controllable, State};
use crate::wake::Waker;
use crate::{Chain, Component, CompoundError, Context, Fault, PortSet, Value, ValueRefused};

/// How a [`Registrar`] builds a compound: by instance name, or why not.
pub type MakeCompound = Box<dyn Fn(&str) -> Result<Component, CompoundError> + Send + Sync>;

/// A network layer's error, as a [`RemoteEnd`] or a [`Placer`] returns it: the layer's
/// own error, kept whole (its sources too); the runtime shows it with its chain
/// ([`Chain`]).
pub type NetworkError = Box<dyn std::error::Error + Send + Sync>;

/// What a network layer is told about a component type so that its instances can be
/// built on another node and bridged: generated crates call it from each component's
/// `register` function (one call per component type, one per port; a compound's
/// ports are its exported ones).
pub trait Registrar {
    /// Component type `type_name` is built by `make(instance_name)` (with its default
    /// configuration and variables; overrides come as commands).
    fn component(
        &mut self,
        type_name: &'static str,
        make: Box<dyn Fn(&str) -> Component + Send + Sync>,
    );

    /// Compound type `type_name` is built by `make(instance_name)` (its supervisor
    /// and instances from the crate's default parts), or fails with why not.
    fn compound(&mut self, type_name: &'static str, make: MakeCompound);

    /// Port `port` of component type `type_name` carries `T` (`()` for a tick port).
    fn port<T: Packet + Serialize + DeserializeOwned>(
        &mut self,
        type_name: &'static str,
        port: &'static str,
    );
}

/// One instance declared `on "node"`, as a compound asks a [`Placer`] for it.
#[derive(Debug, Clone)]
pub struct Placement {
    /// The node it is to run on.
    pub node: String,
    /// The compound that declares it.
    pub compound: String,
    /// The instance's name in the compound.
    pub name: String,
    /// Its component type.
    pub spec: &'static Spec,
    /// Its effective timing block (the instance's `timing` override, or the spec's),
    /// quality levels included.
    pub timing: TimingSpec,
    /// Its adaptation settings (the instance's `adaptation` block, or the defaults).
    pub adaptation: crate::adapt::AdaptConfig,
    /// Its configuration with the instance's overrides, when the component reports
    /// one ([`Automaton::configuration`]).
    pub configuration: Option<Value>,
    /// Its controllable variables with the instance's overrides, in declaration order.
    pub variables: Vec<(String, Value)>,
}

/// The far end of a proxy: what a [`Placer`] returns for a [`Placement`].
pub struct Remote {
    /// The proxy's ports, in the spec's declaration order: what arrives at its inputs
    /// is to reach the remote instance's inputs (the network layer forwards it when
    /// [`RemoteEnd::pump`] is called, or on its own), and what the remote instance
    /// sends is sent on its outputs.
    pub ports: PortSet,
    /// The instance on its node.
    pub end: Box<dyn RemoteEnd>,
}

impl std::fmt::Debug for Remote {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Remote")
    }
}

/// The remote instance as the proxy's thread sees it. Every method runs on the
/// proxy's thread; none may wait longer than a network round trip.
pub trait RemoteEnd: Send + 'static {
    /// Build the instance on its node and leave it `ready` (the proxy's `start`, and a
    /// restart after the node lost it); `waker` is rung whenever something changes
    /// (the instance's monitoring events, the node's liveliness). `Err`: why not.
    fn instantiate(&mut self, waker: Option<Waker>) -> Result<(), NetworkError>;

    /// Whether the instance must be built again before it can run: never built, or
    /// gone since (its node was lost, it went to `dead`, it fell silent).
    fn needs_instance(&self) -> bool;

    /// How often the proxy's thread is to call [`RemoteEnd::pump`] and
    /// [`RemoteEnd::view`] while nothing else wakes it (the end asks for the remote
    /// snapshot then, and judges silence), if at all.
    fn poll_every(&self) -> Option<Duration> {
        None
    }

    /// Give `command` to the remote instance; its answer.
    fn command(&mut self, command: &Command) -> Result<(), NetworkError>;

    /// Forward what waits at the proxy's inputs (called on every turn of the proxy).
    fn pump(&mut self);

    /// A consumer here pulled the proxy's pull output `output` (an index into the
    /// spec's outputs): ask the remote instance for its answer and send it on the
    /// proxy's output (this runs inside the proxy's answer to that request). `Err`:
    /// why no answer came (the consumer's pull then times out).
    fn pull(&mut self, output: usize) -> Result<(), NetworkError>;

    /// The remote instance's monitoring port as last heard (`Ok(None)`: nothing new),
    /// or why it cannot be heard: its node is lost, or it has not answered for longer
    /// than the end's bound.
    fn view(&mut self) -> Result<Option<Monitor>, NetworkError>;

    /// The proxy is dead: kill the remote instance if its node is there, and stop
    /// listening.
    fn release(&mut self);
}

/// Builds the far ends of proxies: a network layer's, installed for the process with
/// [`install`].
pub trait Placer: Send + Sync {
    /// The far end for `placement`, or `Ok(None)` if `placement.node` is this
    /// process's own node (the instance then runs here).
    fn place(&self, placement: &Placement) -> Result<Option<Remote>, NetworkError>;
}

thread_local! {
    static PLACER: RefCell<Option<Arc<dyn Placer>>> = const { RefCell::new(None) };
}

/// `placer` places the `on "node"` instances of the compounds built on this thread
/// while the returned guard lives (a process builds its compounds on the thread that
/// opened its node; two systems built on two threads of one process, as tests do,
/// do not see each other's placer). Dropping the guard restores what was installed
/// before.
#[must_use = "the placer is uninstalled when the guard is dropped"]
pub fn install(placer: Arc<dyn Placer>) -> Installed {
    let previous = PLACER.with(|slot| slot.replace(Some(placer)));
    Installed {
        previous,
        _thread: PhantomData,
    }
}

/// Keeps a placer installed on this thread ([`install`]); not `Send`: it is dropped
/// on the thread that installed it.
pub struct Installed {
    previous: Option<Arc<dyn Placer>>,
    _thread: PhantomData<*const ()>,
}

impl std::fmt::Debug for Installed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Installed")
    }
}

impl Drop for Installed {
    fn drop(&mut self) {
        let previous = self.previous.take();
        PLACER.with(|slot| *slot.borrow_mut() = previous);
    }
}

/// The placer installed on this thread, if any.
pub(crate) fn placer() -> Option<Arc<dyn Placer>> {
    PLACER.with(|slot| slot.borrow().clone())
}

/// What a compound does with an instance declared `on node`: the proxy that stands
/// for it, or the local component itself when there is no placer or the node is this
/// process's own.
pub(crate) fn place(
    compound: &str,
    node: &str,
    local: Component,
) -> Result<Component, NetworkError> {
    let Some(placer) = placer() else {
        tracing::info!(
            compound,
            instance = local.name(),
            node,
            "runs in this process: no network placer is installed"
        );
        return Ok(local);
    };
    let spec = local.spec();
    let of_compound = local.is_compound();
    let variables = spec
        .variables
        .iter()
        .enumerate()
        .filter(|(_, var)| var.kind == crate::spec::VarKind::Controllable)
        .map(|(index, var)| (var.name.to_owned(), local.automaton_get(index)))
        // A compound's mapped variables read its instances, which have published
        // nothing before they run: no value to send (an atomic component's values
        // are all sent).
        .filter(|(_, value)| !of_compound || *value != Value::Unit)
        .collect();
    let placement = Placement {
        node: node.to_owned(),
        compound: compound.to_owned(),
        name: local.name().to_owned(),
        spec,
        timing: local.timing(),
        adaptation: local.adaptation(),
        configuration: local.configuration(),
        variables,
    };
    let Some(remote) = placer.place(&placement)? else {
        return Ok(local);
    };
    Ok(proxy(&placement, remote))
}

/// The proxy's own spec: the instance's ports, variables, exceptions and timing, and
/// its user states by name, with no sections and no transitions of their own (the
/// proxy's user state follows the remote instance's).
fn proxy_spec(spec: &'static Spec) -> &'static Spec {
    let states: Vec<StateSpec> = spec
        .states
        .iter()
        .map(|state| StateSpec {
            name: state.name,
            entry: false,
            exit: false,
            periodic: None,
            on: &[],
            after: &[],
            may: &[],
        })
        .collect();
    Box::leak(Box::new(Spec {
        type_name: spec.type_name,
        doc: spec.doc,
        states: Box::leak(states.into_boxed_slice()),
        initial: spec.initial,
        inputs: spec.inputs,
        outputs: spec.outputs,
        variables: spec.variables,
        exceptions: spec.exceptions,
        timing: TimingSpec {
            max_response: None,
            ..spec.timing
        },
    }))
}

fn proxy(placement: &Placement, remote: Remote) -> Component {
    let spec = proxy_spec(placement.spec);
    let proxy = Proxy {
        spec,
        node: placement.node.clone(),
        end: remote.end,
        view: None,
        applied: Vec::new(),
        clock: crate::clock::Clock::real(),
        next_poll: None,
    };
    Component::driven(placement.name.clone(), Box::new(proxy), remote.ports)
        .with_timing(TimingSpec {
            period: None,
            max_period: None,
            max_response: None,
            ..placement.timing
        })
        .with_adaptation(crate::adapt::AdaptConfig::off())
}

/// Show on the proxy's monitoring port what the remote instance's shows of its
/// timing: quality level (an event, so that rules reading `<instance>.quality` see
/// it), period (an event), response bound and priority, missed deadlines, overruns, CPU and elapsed time (the
/// proxy's runner publishes none of its own thread's: `Driven::mirrors_times`),
/// response times and adaptation status; and its losses: what the remote inputs lost,
/// and what was lost on the way here (port `network`), each added to the proxy's own
/// count at that port with an `Overflow` event. `applied` holds the totals of the
/// current remote instance already added (cleared when a new one is built).
fn overlay(view: &Monitor, applied: &mut Vec<(String, u64)>, cx: &Context) {
    let Some(shared) = &cx.shared else {
        return;
    };
    for (port, total) in &view.port_overflows {
        let slot = crate::monitor::count_at(applied, port);
        let lost = total.saturating_sub(*slot);
        *slot = *total;
        shared.add_overflows(port, lost);
    }
    // Before the CPU time, as a runner publishes them: a snapshot never shows a CPU
    // time newer than the elapsed time.
    shared.set_elapsed(crate::time::nanos(view.elapsed_time));
    shared.update(|monitor| {
        let mut events = Vec::new();
        monitor.response = view.response;
        monitor.adaptation = view.adaptation.clone();
        follow(
            &mut monitor.quality,
            view.quality,
            MonitorEvent::Quality,
            &mut events,
        );
        follow(
            &mut monitor.period,
            view.period,
            MonitorEvent::Period,
            &mut events,
        );
        follow(
            &mut monitor.max_response,
            view.max_response,
            MonitorEvent::MaxResponse,
            &mut events,
        );
        follow(
            &mut monitor.priority,
            view.priority,
            MonitorEvent::Priority,
            &mut events,
        );
        monitor.missed_deadlines = view.missed_deadlines;
        monitor.overruns = view.overruns;
        monitor.cpu_time = view.cpu_time;
        events
    });
}

/// Set `field` to the remote value `now`, with its event when it changed.
fn follow<T: PartialEq + Copy>(
    field: &mut T,
    now: T,
    event: fn(T) -> MonitorEvent,
    events: &mut Vec<MonitorEvent>,
) {
    if *field != now {
        *field = now;
        events.push(event(now));
    }
}

/// Stands for an instance on another node (see the module documentation).
struct Proxy {
    spec: &'static Spec,
    node: String,
    end: Box<dyn RemoteEnd>,
    /// The remote monitoring port as last heard.
    view: Option<Monitor>,
    /// The remote loss totals already added to the proxy's monitor ([`overlay`]).
    applied: Vec<(String, u64)>,
    /// The proxy's clock (its runner's), for [`Proxy::next_poll`].
    clock: crate::clock::Clock,
    /// When the proxy's thread is next to look at the remote end though nothing woke
    /// it ([`RemoteEnd::poll_every`]).
    next_poll: Option<Instant>,
}

/// Why the remote instance's view is a fault of the proxy, if it is: it failed, or it
/// is dead (the proxy sends `dead` only as it dies itself, and never looks again: a
/// dead instance it sees was not its compound's doing).
fn failure(view: &Monitor) -> Option<String> {
    let error = view.error.clone();
    match view.state {
        State::RunningError | State::StartingError => {
            Some(error.unwrap_or_else(|| "the remote instance failed".to_owned()))
        }
        State::Dead => Some(match error {
            Some(error) => format!(
                "the remote instance went to dead without this compound's command ({error})"
            ),
            None => "the remote instance went to dead without this compound's command".to_owned(),
        }),
        _ => None,
    }
}

/// Why the remote end failed the proxy: the network layer's error, after the node.
#[derive(Debug, thiserror::Error)]
#[error("on node `{node}`")]
struct OnNode {
    node: String,
    #[source]
    source: NetworkError,
}

impl Proxy {
    fn on_node(&self, source: NetworkError) -> OnNode {
        OnNode {
            node: self.node.clone(),
            source,
        }
    }

    fn forward(&mut self, command: Command) -> Result<(), Fault> {
        self.end
            .command(&command)
            .map_err(|source| Fault::from(self.on_node(source)))
    }

    /// Read the remote view and show it on the proxy's monitor ([`overlay`]); a fault
    /// when the node is lost or the instance failed. A failing view is shown too:
    /// the losses it reports are counted before the fault (the network layer counts
    /// them reported, and a new instance's counts start again).
    fn refresh(&mut self, cx: &Context) -> Result<(), Fault> {
        match self.end.view() {
            // (The reason names the node.)
            Err(error) => Err(Fault::message(Chain(&*error).to_string())),
            Ok(None) => Ok(()),
            Ok(Some(view)) => {
                overlay(&view, &mut self.applied, cx);
                let failed = failure(&view);
                self.view = Some(view);
                match failed {
                    Some(reason) => {
                        Err(Fault::message(format!("on node `{}`: {reason}", self.node)))
                    }
                    None => Ok(()),
                }
            }
        }
    }

    /// Schedule the next look at the remote end ([`RemoteEnd::poll_every`]).
    fn schedule_poll(&mut self) {
        let now = self.clock.now();
        if self.next_poll.is_none_or(|due| now >= due) {
            self.next_poll = self
                .end
                .poll_every()
                .map(|every| crate::time::later(now, every));
        }
    }
}

impl Automaton for Proxy {
    fn spec(&self) -> &'static Spec {
        self.spec
    }

    fn start(&mut self, cx: &mut Context) -> Result<(), Fault> {
        if self.end.needs_instance() {
            // A new remote instance: its view and loss counts start again.
            self.view = None;
            self.applied.clear();
            self.end
                .instantiate(cx.waker())
                .map_err(|source| Fault::from(self.on_node(source)))?;
        } else {
            // A restart: the remote instance restarts too.
            self.forward(Command::SetState(Controllable::Ready))?;
        }
        self.refresh(cx)
    }

    fn answer(&mut self, output: usize, _cx: &mut Context) -> Result<(), Fault> {
        // No answer is not a fault of the proxy: the consumer's pull times out, as
        // when a local producer does not answer.
        if let Err(error) = self.end.pull(output) {
            crate::limited!((&self.node, output), |held| tracing::warn!(
                node = %self.node,
                output = self.spec.outputs.get(output).map_or("?", |o| o.name),
                "pull through the proxy: {}{held}",
                Chain(&*error)
            ));
        }
        Ok(())
    }

    fn configure(&mut self, configuration: &Value) -> Result<(), ValueRefused> {
        self.end
            .command(&Command::Configure(configuration.clone()))
            .map_err(|source| ValueRefused::Remote {
                node: self.node.clone(),
                source,
            })
    }

    fn set(&mut self, variable: usize, value: &Value) -> Result<(), ValueRefused> {
        let name = self.spec.variables[variable].name.to_owned();
        self.end
            .command(&Command::Set(name, value.clone()))
            .map_err(|source| ValueRefused::Remote {
                node: self.node.clone(),
                source,
            })
    }

    fn get(&self, variable: usize) -> Value {
        let name = self.spec.variables[variable].name;
        self.view
            .as_ref()
            .and_then(|view| view.variables.iter().find(|(n, _)| n == name))
            .map_or(Value::Unit, |(_, value)| value.clone())
    }
}

impl Driven for Proxy {
    fn supervises(&self) -> bool {
        true
    }

    fn before_running(&mut self, _cx: &mut Context) -> Result<(), Fault> {
        self.forward(Command::SetState(Controllable::Running))
    }

    fn after_transition(&mut self, from: State, to: State, _cx: &mut Context) {
        let command = match to {
            State::Suspended => Controllable::Suspended,
            State::Ready if from != State::Starting => Controllable::Ready,
            State::Dead => {
                self.end.release();
                return;
            }
            _ => return,
        };
        if let Err(fault) = self.forward(Command::SetState(command)) {
            crate::limited!(&self.node, |held| tracing::warn!("{}{held}", fault.text()));
        }
    }

    fn mirrors_times(&self) -> bool {
        true
    }

    fn supervise(&mut self, state: usize, cx: &mut Context) -> Result<Option<usize>, Fault> {
        self.schedule_poll();
        self.end.pump();
        self.refresh(cx)?;
        let Some(view) = &self.view else {
            return Ok(None);
        };
        // On every turn, new view or not (idempotent: only what changed is published).
        overlay(view, &mut self.applied, cx);
        cx.set_result(view.result.clone());
        if view.state == State::End {
            // The remote instance finished its task: so does the proxy (its runner
            // looks at the request on its next turn, which the bell brings at once).
            cx.end();
            if let Some(waker) = cx.waker() {
                waker.wake();
            }
            return Ok(None);
        }
        let target = view
            .user_state
            .as_deref()
            .and_then(|name| self.spec.state_index(name));
        Ok(target.filter(|&target| target != state))
    }

    fn wake_at(&self) -> Option<Instant> {
        self.next_poll
    }

    fn set_clock(&mut self, clock: &crate::clock::Clock) {
        self.clock = clock.clone();
    }

    fn observe(&mut self, cx: &mut Context) {
        self.end.pump();
        if let Ok(Some(view)) = self.end.view() {
            overlay(&view, &mut self.applied, cx);
            self.view = Some(view);
        }
    }

    fn forward(&mut self, command: &Command) -> Option<Result<(), NetworkError>> {
        match command {
            Command::SetPeriod(_)
            | Command::SetMaxResponse(_)
            | Command::SetPriority(_)
            | Command::SetQuality(_)
            | Command::SetDegradation(_) => Some(
                self.end
                    .command(command)
                    .map_err(|source| self.on_node(source).into()),
            ),
            Command::SetState(_) | Command::Configure(_) | Command::Set(..) => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use std::collections::VecDeque;
    use std::sync::{Arc, Mutex};

    use super::{Automaton, Driven, NetworkError, Proxy, RemoteEnd};
    use crate::Context;
    use crate::monitor::{Command, Monitor, Shared};
    use crate::spec::{Spec, TimingSpec};
    use crate::table::State;
    use crate::wake::Waker;

    static SPEC: Spec = Spec::new("Far", "");

    /// A far end that returns the views the test queued, one per look.
    struct Queued(Arc<Mutex<VecDeque<Monitor>>>);

    impl RemoteEnd for Queued {
        fn instantiate(&mut self, _waker: Option<Waker>) -> Result<(), NetworkError> {
            Ok(())
        }
        fn needs_instance(&self) -> bool {
            false
        }
        fn command(&mut self, _command: &Command) -> Result<(), NetworkError> {
            Ok(())
        }
        fn pump(&mut self) {}
        fn pull(&mut self, _output: usize) -> Result<(), NetworkError> {
            Ok(())
        }
        fn view(&mut self) -> Result<Option<Monitor>, NetworkError> {
            Ok(self.0.lock().expect("views").pop_front())
        }
        fn release(&mut self) {}
    }

    /// The far instance's view: in `state`, with `lost` counted on the way here.
    fn view(state: State, lost: u64) -> Monitor {
        let mut view = Monitor::starting("far".to_owned(), &SPEC, &TimingSpec::NONE);
        view.state = state;
        view.port_overflows.push(("@network".to_owned(), lost));
        view
    }

    fn network(shared: &Shared) -> u64 {
        shared
            .snapshot()
            .port_overflows
            .iter()
            .find(|(port, _)| port == "@network")
            .map_or(0, |(_, lost)| *lost)
    }

    #[test]
    fn losses_in_the_view_that_fails_the_proxy_are_counted() {
        let views = Arc::new(Mutex::new(VecDeque::from([
            view(State::Running, 3),
            view(State::RunningError, 10),
        ])));
        let mut proxy = Proxy {
            spec: &SPEC,
            node: "far".to_owned(),
            end: Box::new(Queued(Arc::clone(&views))),
            view: None,
            applied: Vec::new(),
            clock: crate::clock::Clock::real(),
            next_poll: None,
        };
        let shared = Arc::new(Shared::new(
            Monitor::starting("proxy".to_owned(), &SPEC, &TimingSpec::NONE),
            Vec::new(),
        ));
        let mut cx = Context::new("proxy", None);
        cx.shared = Some(Arc::clone(&shared));

        // A restart of a running proxy: the far instance's view comes, running.
        proxy.start(&mut cx).expect("the far instance runs");
        assert_eq!(network(&shared), 3);
        // Then it fails, with 7 more lost on the way: the fault, and all 10 counted.
        let fault = proxy
            .supervise(0, &mut cx)
            .expect_err("the far instance failed");
        assert!(fault.text().contains("on node `far`"), "{}", fault.text());
        assert_eq!(network(&shared), 10);
    }
}
