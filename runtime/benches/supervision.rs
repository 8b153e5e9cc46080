//! Compound supervision, side by side with the direct path written by hand.
//!
//! 1. **Fault to substitute running.** A compound holds a leaf, its declared
//!    substitute (policy `substitute`) and a source whose tick output drives the leaf.
//!    The leaf's entry section fails (a declared fault) and stamps the time just before
//!    it returns; the substitute stamps the time its first entry section runs after it
//!    was commanded to `running`. The sample is the difference: the leaf's fault
//!    transition (its `stop`), its monitoring event, the compound's wake-up and policy,
//!    the connection moved to the substitute, the `running` command and the
//!    substitute's entry. Between samples the recovery queue (retry every 1 ms) brings
//!    the leaf back and the substitute goes back to standby.
//!    The baseline is the same three components in a plain `System` and a hand-written
//!    reaction: a thread subscribed to the leaf's monitoring port that, on
//!    `running_error`, disconnects the source from the leaf, connects it to the standby
//!    and commands the standby to `running`.
//! 2. **Rules over 100 instances.** A compound of 100 instances, each with a
//!    controllable `v`; its supervisor (states `a` and `b`) has 101 rules in `a`: one
//!    per instance (`n<i>.v == u64::MAX`, never true here) and last `n0.v` odd -> `b`;
//!    in `b`, `n0.v` even -> `a`. The bench sets `n0.v` through the instance's control
//!    port, alternately odd and even.
//!    - *event to transition*: from just before the `set` command to the supervisor's
//!      entry section of the new state (each sample 300 us after the last, on both
//!      sides, so that the supervisor is idle when the event comes). Baseline: a hand-written supervisor thread
//!      selecting over the 100 instances' monitoring ports, refreshing the changed
//!      instance's snapshot and evaluating the rules that read it, in the same order,
//!      with the same test closures; its sample ends when a test holds.
//!    - *evaluation round*: on entering `a`, the compound evaluates all 101 rules; the
//!      round is timed from the first test's call to the last test's return.
//!      Baseline: the same 101 test closures in a plain loop over a plain table of
//!      the instances' variables.
//!
//! No goal is set for these figures; they are reported.
//!
//! `cargo bench -p coolbot --bench supervision` (add `-- --quick` for a smoke run).

#[macro_use]
mod common;

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use coolbot::port::{TickIn, TickOut};
use coolbot::{
    Automaton, Command, Component, CompoundBuilder, Context, Controllable, Fault, Handle,
    InputKind, MonitorEvent, OutputKind, Policy, PortSet, Section, SectionResult, Spec, State,
    StateSpec, Supervisor, SupervisorCx, System, TimingSpec, Value, ValueRefused, VarKind, VarSpec,
    View,
};
use crossbeam_channel::{Receiver, Sender, bounded, unbounded};

use common::{Figure, Glue, Goal, Mode, Samples, Table};

const ROUNDS: usize = 3;
const WAIT: Duration = Duration::from_secs(30);

one_state_spec! {
    static LEAF = "Leaf",
    inputs: [("kick", InputKind::Tick)],
    outputs: [],
    on: [0],
    periodic: None,
}

one_state_spec! {
    static SOURCE = "Source",
    inputs: [],
    outputs: [("out", OutputKind::Tick)],
    on: [],
    periodic: None,
}

/// A supervisor (or a compound of no interest) with `states`, none periodic; its
/// entry sections stamp the time on `entered`.
struct Stamping {
    spec: &'static Spec,
    entered: Sender<(usize, Instant)>,
}

impl Stamping {
    fn new(states: &[&'static str], entered: Sender<(usize, Instant)>) -> Stamping {
        let states: Vec<StateSpec> = states
            .iter()
            .map(|name| StateSpec {
                name,
                entry: true,
                exit: false,
                periodic: None,
                on: &[],
                after: &[],
                may: &[],
            })
            .collect();
        let spec = Box::leak(Box::new(Spec {
            type_name: "Bench",
            doc: "",
            states: Box::leak(states.into_boxed_slice()),
            initial: 0,
            inputs: &[],
            outputs: &[],
            variables: &[],
            exceptions: &[],
            timing: TimingSpec::NONE,
        }));
        Stamping { spec, entered }
    }
}

impl Supervisor for Stamping {
    fn spec(&self) -> &'static Spec {
        self.spec
    }

    fn section(
        &mut self,
        state: usize,
        section: Section,
        _: &mut SupervisorCx<'_>,
    ) -> SectionResult {
        if section == Section::Entry {
            let _ = self.entered.try_send((state, Instant::now()));
        }
        Ok(())
    }
}

// -------------------------------------------------------------------------------------
// 1. Fault to substitute running.

/// What the leaf and the standby share with the bench.
#[derive(Default)]
struct FaultProbe {
    /// The leaf's next entry fails.
    fail: AtomicBool,
    /// The standby's next entry stamps its time.
    armed: AtomicBool,
    /// When the leaf's failing section returned.
    failed_at: Mutex<Option<Instant>>,
}

fn leaf(name: &str, probe: &Arc<FaultProbe>) -> Component {
    let kick = TickIn::new();
    let probe = Arc::clone(probe);
    let body = Box::new(move |section: Section, _: &mut Context| {
        if section == Section::Entry && probe.fail.swap(false, Ordering::SeqCst) {
            *probe.failed_at.lock().expect("probe") = Some(Instant::now());
            return Err(Fault::message("injected"));
        }
        Ok(())
    });
    Component::new(name, Glue::boxed(&LEAF, body), PortSet::new().input(&kick))
}

fn standby(name: &str, probe: &Arc<FaultProbe>, running: Sender<Instant>) -> Component {
    let kick = TickIn::new();
    let probe = Arc::clone(probe);
    let body = Box::new(move |section: Section, _: &mut Context| {
        if section == Section::Entry && probe.armed.swap(false, Ordering::SeqCst) {
            let _ = running.try_send(Instant::now());
        }
        Ok(())
    });
    Component::new(name, Glue::boxed(&LEAF, body), PortSet::new().input(&kick))
}

fn source(name: &str) -> (Component, TickOut) {
    let out = TickOut::new();
    let body = Box::new(|_: Section, _: &mut Context| Ok(()));
    let component = Component::new(
        name,
        Glue::boxed(&SOURCE, body),
        PortSet::new().output(&out),
    );
    (component, out)
}

/// Wait until `handle` runs its user automaton.
fn running(handle: &Handle) {
    handle
        .wait_for(
            |m| m.state == State::Running && m.user_state.is_some(),
            WAIT,
        )
        .unwrap_or_else(|t| panic!("{t}"));
}

/// One fault: fail the leaf, wait for the standby's stamp.
fn one_fault(probe: &FaultProbe, kick: &TickOut, stamped: &Receiver<Instant>) -> Duration {
    probe.armed.store(true, Ordering::SeqCst);
    probe.fail.store(true, Ordering::SeqCst);
    kick.emit();
    let running_at = common::expect(stamped, WAIT, "the substitute's entry");
    let failed_at = probe
        .failed_at
        .lock()
        .expect("probe")
        .take()
        .expect("the leaf failed");
    running_at.saturating_duration_since(failed_at)
}

fn fault_project(samples: usize) -> Vec<Duration> {
    let probe = Arc::new(FaultProbe::default());
    let (stamp, stamped) = bounded(4);
    let (entered, _entries) = unbounded();
    let (src, kick) = source("src");
    let builder = CompoundBuilder::new("base", Stamping::new(&["operating"], entered))
        .instance(leaf("leaf", &probe))
        .instance(standby("standby", &probe, stamp))
        .instance(src)
        .substitute("standby", "leaf")
        .connect("src.out", "leaf.kick")
        .on_error("leaf", Policy::Substitute)
        .recovery(Duration::from_millis(1), Duration::from_secs(600));
    let leaf = builder.instance_handle("leaf").expect("leaf");
    let spare = builder.instance_handle("standby").expect("standby");
    let mut system = System::new();
    system.add(builder.build().expect("build")).expect("add");
    system.run_all().expect("run");
    let mut out = Vec::with_capacity(samples);
    for _ in 0..samples {
        running(&leaf);
        out.push(one_fault(&probe, &kick, &stamped));
        // The recovery queue restarts the leaf; the standby goes back to `ready`.
        spare
            .wait_state(State::Ready, WAIT)
            .unwrap_or_else(|t| panic!("{t}"));
    }
    assert!(system.shutdown().clean(), "unclean shutdown");
    out
}

/// What the bench asks of the hand-written reaction thread.
enum Ask {
    /// Restart the leaf and put it back in the standby's place.
    Restore,
    /// End.
    Stop,
}

fn fault_baseline(samples: usize) -> Vec<Duration> {
    let probe = Arc::new(FaultProbe::default());
    let (stamp, stamped) = bounded(4);
    let (src, kick) = source("src");
    let mut system = System::new();
    let leaf = system.add(leaf("leaf", &probe)).expect("leaf");
    let spare = system
        .add(standby("standby", &probe, stamp))
        .expect("standby");
    system.add(src).expect("src");
    system.connect("src.out", "leaf.kick").expect("connect");
    system.start().expect("start");
    for handle in [&leaf, &system.handle("src").expect("src")] {
        handle
            .wait_state(State::Ready, WAIT)
            .unwrap_or_else(|t| panic!("{t}"));
        handle
            .command(Command::SetState(Controllable::Running))
            .expect("running");
    }
    spare
        .wait_state(State::Ready, WAIT)
        .unwrap_or_else(|t| panic!("{t}"));
    // The direct path: a thread that watches the leaf and reacts by hand.
    let (ask, asks) = unbounded::<Ask>();
    let (done, restored) = bounded::<()>(1);
    let events = leaf.subscribe();
    let (reactor_leaf, reactor_spare) = (leaf.clone(), spare.clone());
    let reactor = std::thread::spawn(move || {
        loop {
            crossbeam_channel::select! {
                recv(events) -> event => {
                    if let Ok(MonitorEvent::State { to: State::RunningError, .. }) = event {
                        system.disconnect("src.out", "leaf.kick").expect("disconnect");
                        system.connect("src.out", "standby.kick").expect("connect");
                        reactor_spare
                            .command(Command::SetState(Controllable::Running))
                            .expect("standby running");
                    }
                }
                recv(asks) -> ask => match ask {
                    Ok(Ask::Restore) => {
                        reactor_leaf
                            .command(Command::SetState(Controllable::Running))
                            .expect("leaf restart");
                        system.disconnect("src.out", "standby.kick").expect("disconnect");
                        system.connect("src.out", "leaf.kick").expect("connect");
                        reactor_spare
                            .command(Command::SetState(Controllable::Ready))
                            .expect("standby ready");
                        let _ = done.send(());
                    }
                    Ok(Ask::Stop) | Err(_) => break,
                },
            }
        }
        assert!(system.shutdown().clean(), "unclean shutdown");
    });
    let mut out = Vec::with_capacity(samples);
    for _ in 0..samples {
        running(&leaf);
        out.push(one_fault(&probe, &kick, &stamped));
        ask.send(Ask::Restore).expect("reactor");
        common::expect(&restored, WAIT, "the hand-written restore");
    }
    ask.send(Ask::Stop).expect("reactor");
    reactor.join().expect("reactor thread");
    out
}

// -------------------------------------------------------------------------------------
// 2. Rules over 100 instances.

const INSTANCES: usize = 100;

/// The pause before each rule sample, on both sides: the supervisor has finished with
/// the previous transition (on entering `a` the compound evaluates its 101 rules, about
/// 20 us) before the next event comes.
const SETTLE: Duration = Duration::from_micros(300);

static NODE: Spec = Spec::new("Node", "")
    .with_states(&[StateSpec::new("idle")])
    .with_variables(&[VarSpec::new("v", VarKind::Controllable, "u64")]);

/// An instance with one controllable `v: u64`.
struct Node {
    v: u64,
}

impl Automaton for Node {
    fn spec(&self) -> &'static Spec {
        &NODE
    }
    fn set(&mut self, _: usize, value: &Value) -> Result<(), ValueRefused> {
        self.v = u64::try_from(value).map_err(ValueRefused::other)?;
        Ok(())
    }
    fn get(&self, _: usize) -> Value {
        Value::UInt(self.v)
    }
}

fn node_name(index: usize) -> String {
    format!("n{index}")
}

/// A rule's test over a lookup of `instance.variable` as a u64: the closures both
/// sides evaluate.
type Lookup<'a> = &'a dyn Fn(&str, &str) -> Option<u64>;
type Test = Arc<dyn Fn(Lookup<'_>) -> bool + Send + Sync>;

/// The rules of state `a`, in order: one per instance (never true here), then `n0.v`
/// odd. Each returns `(reads, test)`.
fn rules_of_a() -> Vec<(String, Test)> {
    let mut rules: Vec<(String, Test)> = (0..INSTANCES)
        .map(|index| {
            let name = node_name(index);
            let read = format!("{name}.v");
            let test: Test = Arc::new(move |look: Lookup<'_>| look(&name, "v") == Some(u64::MAX));
            (read, test)
        })
        .collect();
    rules.push((
        "n0.v".to_owned(),
        Arc::new(|look: Lookup<'_>| look("n0", "v").is_some_and(|v| v % 2 == 1)),
    ));
    rules
}

fn rule_of_b() -> Test {
    Arc::new(|look: Lookup<'_>| look("n0", "v").is_some_and(|v| v > 0 && v % 2 == 0))
}

fn view_lookup(view: &View) -> impl Fn(&str, &str) -> Option<u64> + '_ {
    move |instance: &str, variable: &str| match view.var(instance, variable) {
        Some(Value::UInt(v)) => Some(*v),
        _ => None,
    }
}

/// Times one evaluation round of state `a`: the first test's call to the last's return.
#[derive(Default)]
struct RoundClock {
    first: Mutex<Option<Instant>>,
    calls: AtomicUsize,
    rounds: Mutex<Vec<Duration>>,
}

/// Rule-evaluation samples: (event to transition, evaluation rounds).
fn rules_project(samples: usize) -> (Vec<Duration>, Vec<Duration>) {
    let (entered, entries) = unbounded();
    let clock = Arc::new(RoundClock::default());
    let mut builder = CompoundBuilder::new("base", Stamping::new(&["a", "b"], entered));
    for index in 0..INSTANCES {
        builder = builder.instance(Component::new(
            node_name(index),
            Box::new(Node { v: 0 }),
            PortSet::new(),
        ));
    }
    let rules = rules_of_a();
    let count = rules.len();
    for (position, (read, test)) in rules.into_iter().enumerate() {
        let clock = Arc::clone(&clock);
        builder = builder.rule("a", "b", &[read.as_str()], move |view: &View| {
            if position == 0 {
                *clock.first.lock().expect("clock") = Some(Instant::now());
                clock.calls.store(0, Ordering::Relaxed);
            }
            let holds = test(&view_lookup(view));
            if clock.calls.fetch_add(1, Ordering::Relaxed) + 1 == count
                && let Some(first) = clock.first.lock().expect("clock").take()
            {
                clock.rounds.lock().expect("clock").push(first.elapsed());
            }
            holds
        });
    }
    let back = rule_of_b();
    builder = builder.rule("b", "a", &["n0.v"], move |view: &View| {
        back(&view_lookup(view))
    });
    let n0 = builder.instance_handle("n0").expect("n0");
    let mut system = System::new();
    system.add(builder.build().expect("build")).expect("add");
    system.run_all().expect("run");
    let (state, _) = common::expect(&entries, WAIT, "the supervisor's first entry");
    assert_eq!(state, 0);
    let mut latencies = Vec::with_capacity(samples);
    for value in 1..=samples as u64 {
        std::thread::sleep(SETTLE);
        let started = Instant::now();
        n0.command(Command::Set("v".to_owned(), Value::UInt(value)))
            .expect("set v");
        let (state, at) = common::expect(&entries, WAIT, "the supervisor's transition");
        assert_eq!(state, usize::from(value % 2 == 1), "the rule's target");
        latencies.push(at.saturating_duration_since(started));
    }
    assert!(system.shutdown().clean(), "unclean shutdown");
    let rounds = std::mem::take(&mut *clock.rounds.lock().expect("clock"));
    (latencies, rounds)
}

/// The hand-written supervisor: select over the instances' monitoring ports.
fn rules_baseline(samples: usize) -> Vec<Duration> {
    let mut system = System::new();
    let handles: Vec<Handle> = (0..INSTANCES)
        .map(|index| {
            system
                .add(Component::new(
                    node_name(index),
                    Box::new(Node { v: 0 }),
                    PortSet::new(),
                ))
                .expect("add")
        })
        .collect();
    system.run_all().expect("run");
    let (fired, transitions) = unbounded::<(usize, Instant)>();
    let (stop, stopped) = bounded::<()>(1);
    // Subscribed before the first change, then snapshots.
    let receivers: Vec<_> = handles.iter().map(Handle::subscribe).collect();
    let watched: Vec<Handle> = handles.clone();
    let supervisor = std::thread::spawn(move || {
        let mut table: Vec<(String, Vec<(String, Value)>)> = watched
            .iter()
            .map(|h| {
                let m = h.snapshot();
                (m.name, m.variables)
            })
            .collect();
        let rules_a = rules_of_a();
        let rule_b = rule_of_b();
        let mut state = 0usize;
        let mut select = crossbeam_channel::Select::new();
        for receiver in &receivers {
            select.recv(receiver);
        }
        let stop_index = select.recv(&stopped);
        loop {
            let operation = select.select();
            let index = operation.index();
            if index == stop_index {
                let _ = operation.recv(&stopped);
                break;
            }
            let Ok(event) = operation.recv(&receivers[index]) else {
                break;
            };
            let MonitorEvent::Variable { name, value } = event else {
                continue;
            };
            if let Some(slot) = table[index].1.iter_mut().find(|(n, _)| *n == name) {
                slot.1 = value;
            }
            let read = format!("{}.{name}", table[index].0);
            let look = |instance: &str, variable: &str| {
                table
                    .iter()
                    .find(|(n, _)| n == instance)?
                    .1
                    .iter()
                    .find(|(n, _)| n == variable)
                    .and_then(|(_, v)| match v {
                        Value::UInt(v) => Some(*v),
                        _ => None,
                    })
            };
            let holds = if state == 0 {
                rules_a
                    .iter()
                    .filter(|(reads, _)| *reads == read)
                    .any(|(_, test)| test(&look))
            } else {
                read == "n0.v" && rule_b(&look)
            };
            if holds {
                state = 1 - state;
                let _ = fired.send((state, Instant::now()));
            }
        }
    });
    let n0 = &handles[0];
    let mut latencies = Vec::with_capacity(samples);
    for value in 1..=samples as u64 {
        std::thread::sleep(SETTLE);
        let started = Instant::now();
        n0.command(Command::Set("v".to_owned(), Value::UInt(value)))
            .expect("set v");
        let (state, at) = common::expect(&transitions, WAIT, "the hand-written transition");
        assert_eq!(state, usize::from(value % 2 == 1), "the rule's target");
        latencies.push(at.saturating_duration_since(started));
    }
    stop.send(()).expect("stop");
    supervisor.join().expect("supervisor thread");
    assert!(system.shutdown().clean(), "unclean shutdown");
    latencies
}

/// The same 101 tests of state `a` in a plain loop over a plain table.
fn round_baseline(rounds: usize) -> Vec<Duration> {
    let table: Vec<(String, Vec<(String, Value)>)> = (0..INSTANCES)
        .map(|index| {
            (
                node_name(index),
                vec![("v".to_owned(), Value::UInt(2 * index as u64))],
            )
        })
        .collect();
    let look = |instance: &str, variable: &str| {
        table
            .iter()
            .find(|(n, _)| n == instance)?
            .1
            .iter()
            .find(|(n, _)| n == variable)
            .and_then(|(_, v)| match v {
                Value::UInt(v) => Some(*v),
                _ => None,
            })
    };
    let rules = rules_of_a();
    (0..rounds)
        .map(|_| {
            let started = Instant::now();
            let holds = rules.iter().any(|(_, test)| test(&look));
            let took = started.elapsed();
            assert!(!holds, "no rule of `a` holds with even values");
            took
        })
        .collect()
}

fn main() {
    let mode = Mode::from_env();
    let mut table = Table::new("Compound supervision", mode);

    let per_round = mode.scale(600, 30) / ROUNDS;
    let (project, baseline) = common::alternate(
        ROUNDS,
        || fault_project(per_round),
        || fault_baseline(per_round),
    );
    let (project, baseline) = (Samples::new(project), Samples::new(baseline));
    table.row(
        "fault to substitute running p50",
        Figure::Time(project.p50()),
        Figure::Time(baseline.p50()),
        Goal::None,
    );
    table.row(
        "fault to substitute running p99",
        Figure::Time(project.p99()),
        Figure::Time(baseline.p99()),
        Goal::None,
    );
    table.note(&format!(
        "fault to substitute: {} samples per side; max project {:?}, baseline {:?}",
        project.len(),
        project.max(),
        baseline.max()
    ));

    let per_round = mode.scale(3_000, 150) / ROUNDS;
    let mut rounds = Vec::new();
    let (project, baseline) = common::alternate(
        ROUNDS,
        || {
            let (latencies, evaluated) = rules_project(per_round);
            rounds.extend(evaluated);
            latencies
        },
        || rules_baseline(per_round),
    );
    let (project, baseline) = (Samples::new(project), Samples::new(baseline));
    table.row(
        "rules, 100 instances: event to transition p50",
        Figure::Time(project.p50()),
        Figure::Time(baseline.p50()),
        Goal::None,
    );
    table.row(
        "rules, 100 instances: event to transition p99",
        Figure::Time(project.p99()),
        Figure::Time(baseline.p99()),
        Goal::None,
    );
    let rounds = Samples::new(rounds);
    let plain = Samples::new(round_baseline(rounds.len().max(1_000)));
    table.row(
        "rules, 100 instances: evaluation round (101 tests) p50",
        Figure::Time(rounds.p50()),
        Figure::Time(plain.p50()),
        Goal::None,
    );
    table.row(
        "rules, 100 instances: evaluation round (101 tests) p99",
        Figure::Time(rounds.p99()),
        Figure::Time(plain.p99()),
        Goal::None,
    );
    table.note(&format!(
        "rules: {} transitions per side; {} full evaluation rounds in the compound (on each \
         entry to `a`), {} in the plain loop",
        project.len(),
        rounds.len(),
        plain.len()
    ));
    table.print();
}
