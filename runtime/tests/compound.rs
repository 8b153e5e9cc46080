//! Compound components: driven like atomic ones, instances following the compound's
//! state, supervisor rules on instance changes, and the fault policies (restart,
//! substitute with the recovery queue, deadline expiry, redundancy, propagation up a
//! three-level hierarchy), with faults injected as panics and declared exceptions.
//!
//! Being moved to `tests/runtime/tests/compound.rs` (generated components and
//! compounds instead of the hand-made ones here): the tests no longer here are there.

mod support;

use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use coolbot::port::{DataOut, TickOut};
use coolbot::{
    Command, Component, CompoundBuilder, Controllable, Handle, OutputKind, Policy, Section,
    SectionResult, Spec, State, StateSpec, Step, Supervisor, SupervisorCx, System, TimingSpec,
    Value, VarKind, VarSpec,
};
use support::shell::{self, ShellBuilder};
use support::worker::{self, Exception};
use support::{Injected, Script, Scripted, WAIT, eventually};

/// A supervisor whose states each have an entry section that logs; one own
/// observable variable `faults`, counted up by the `degraded` entry if it exists.
struct Sup {
    spec: &'static Spec,
    log: Arc<Mutex<Vec<String>>>,
    faults: u64,
}

impl Sup {
    fn new(states: &[&'static str]) -> (Sup, Arc<Mutex<Vec<String>>>) {
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
            type_name: "TestCompound",
            doc: "",
            states: Box::leak(states.into_boxed_slice()),
            initial: 0,
            inputs: &[],
            outputs: &[],
            variables: &[VarSpec {
                name: "faults",
                kind: VarKind::Observable,
                ty: "u64",
                doc: "",
            }],
            exceptions: &[],
            timing: TimingSpec::NONE,
        }));
        let log = Arc::new(Mutex::new(Vec::new()));
        (
            Sup {
                spec,
                log: Arc::clone(&log),
                faults: 0,
            },
            log,
        )
    }
}

impl Supervisor for Sup {
    fn spec(&self) -> &'static Spec {
        self.spec
    }

    fn section(
        &mut self,
        state: usize,
        section: Section,
        _cx: &mut SupervisorCx<'_>,
    ) -> SectionResult {
        let name = self.spec.states[state].name;
        if name == "degraded" && section == Section::Entry {
            self.faults += 1;
        }
        self.log.lock().unwrap().push(format!("{name}.{section:?}"));
        Ok(())
    }

    fn get(&self, _variable: usize) -> Value {
        Value::from(self.faults)
    }
}

/// A worker instance with its script.
fn worker(name: &str) -> (Component, Arc<Script>) {
    let script = Script::new();
    let (component, _, _) = worker::component(
        name,
        Scripted {
            script: Arc::clone(&script),
            token: None,
        },
    );
    (component, script)
}

/// A feeder instance `f` with a tick output `kick` and data outputs `data`, `feed`.
struct Feeder {
    kick: TickOut,
    data: DataOut<u64>,
}

fn feeder(name: &str) -> (Component, Feeder) {
    let feeder = Feeder {
        kick: TickOut::new(),
        data: DataOut::new(),
    };
    let component = ShellBuilder::new(name)
        .output(shell::output("kick", OutputKind::Tick, false), &feeder.kick)
        .output(shell::output("data", OutputKind::Data, false), &feeder.data)
        .build();
    (component, feeder)
}

fn run(handle: &Handle, target: Controllable) {
    handle
        .command(Command::SetState(target))
        .unwrap_or_else(|e| panic!("{e}"));
}

fn wait(handle: &Handle, state: State) -> coolbot::Monitor {
    handle
        .wait_state(state, WAIT)
        .unwrap_or_else(|t| panic!("{t}"))
}

fn wait_user(handle: &Handle, user: &str) -> coolbot::Monitor {
    handle
        .wait_for(|m| m.user_state.as_deref() == Some(user), WAIT)
        .unwrap_or_else(|t| panic!("{t}"))
}

/// Wait until the supervisor's log is `expected` (`user_state` changes before the
/// entry section runs: a state wait alone does not see the section).
fn wait_log(log: &Mutex<Vec<String>>, expected: &[&str]) {
    eventually(
        || *log.lock().unwrap() == expected,
        &format!("the supervisor's log becomes {expected:?}"),
    );
}

fn periodic_fault(script: &Script) {
    script.inject(Some(Injected {
        hook: "busy.periodic",
        exception: Some(Exception::Fatal),
        times: 1,
    }));
}

#[test]
fn forwarding_an_exported_input_never_waits_for_a_full_blocking_queue() {
    static BLOCKING: std::sync::OnceLock<&'static Spec> = std::sync::OnceLock::new();
    let spec = *BLOCKING.get_or_init(|| {
        let mut inputs = worker::SPEC.inputs.to_vec();
        inputs[worker::DATA].kind = coolbot::InputKind::Fifo {
            capacity: 4,
            policy: coolbot::OverflowPolicy::Block,
        };
        let mut spec = worker::SPEC;
        spec.inputs = Box::leak(inputs.into_boxed_slice());
        Box::leak(Box::new(spec))
    });
    let script = Script::new();
    let (w, w_inputs, _) = worker::component_with(
        "w",
        Scripted {
            script: Arc::clone(&script),
            token: None,
        },
        spec,
        coolbot::port::FifoIn::new(4, coolbot::OverflowPolicy::Block),
    );
    let (sup, _) = Sup::new(&["operating"]);
    let builder = CompoundBuilder::new("base", sup)
        .instance(w)
        .on_error("w", Policy::Ignore)
        .export_input::<u64>("data", "w.data")
        .export_tick_input("kick", "w.kick");
    let w = builder.instance_handle("w").expect("w");
    let (f, feed) = feeder("f");
    let mut system = System::new();
    let base = system.add(builder.build().expect("build")).expect("add");
    system.add(f).expect("feeder");
    system.connect("f.data", "base.data").expect("data");
    system.connect("f.kick", "base.kick").expect("kick");
    system.run_all().expect("run");
    wait_user(&w, "idle");
    // w hangs in a section: its blocking queue fills with four packets, and four more
    // wait at the compound's own input (also four deep).
    let release = script.hang_in("busy.periodic");
    feed.kick.emit();
    eventually(|| script.hanging.load(Ordering::SeqCst), "w hangs");
    for packet in 0..4 {
        feed.data.send(packet);
    }
    eventually(|| w_inputs.data.len() == 4, "w's queue is full");
    // (The compound's own queue is empty again: these four do not wait there.)
    for packet in 4..8 {
        feed.data.send(packet);
    }
    // Two round trips through the compound's control port: its turns went on, and
    // none of them waited to push a packet into w's full queue until it gave up.
    for _ in 0..2 {
        base.command(Command::SetPriority(0)).expect("sync");
    }
    assert_eq!(w.snapshot().overflows, 0, "nothing given up at w");
    assert_eq!(base.snapshot().overflows, 0);
    // The section returns (w is failed and ignored): nothing was lost meanwhile.
    drop(release);
    w.wait_for(|_| !w.is_stuck(), WAIT).expect("returned");
    assert_eq!(w.snapshot().overflows, 0);
    assert_eq!(base.snapshot().overflows, 0);
    assert!(system.shutdown().clean());
}

#[test]
fn a_built_compound_reaches_its_nested_instances_by_path() {
    // top { mid { leaf (restart), f -> leaf }, sibling }, built whole: only the top
    // handle is kept.
    let (mid_sup, mid_log) = Sup::new(&["operating", "degraded"]);
    let (leaf, script) = worker("leaf");
    let (f, feed) = feeder("f");
    let mid = CompoundBuilder::new("mid", mid_sup)
        .instance(leaf)
        .instance(f)
        .connect("f.kick", "leaf.kick")
        .on_error("leaf", Policy::Restart)
        .rule("operating", "degraded", &["leaf.gain"], |v| {
            v.var("leaf", "gain") == Some(&Value::from(9_i64))
        })
        .build()
        .expect("mid");
    let (top_sup, _) = Sup::new(&["operating"]);
    let (sibling, _) = worker("sibling");
    let top = CompoundBuilder::new("top", top_sup)
        .instance(mid)
        .instance(sibling)
        .build()
        .expect("top");
    let mut system = System::new();
    let top = system.add(top).expect("add");
    system.run_all().expect("run");

    assert_eq!(top.instances(), ["mid", "sibling"]);
    let mid = top.instance("mid").expect("mid");
    assert_eq!(mid.name(), "mid");
    assert_eq!(mid.instances(), ["leaf", "f"]);
    let leaf = top.instance("mid.leaf").expect("mid.leaf");
    assert_eq!(leaf.name(), "leaf");
    assert!(leaf.instances().is_empty(), "an atomic component has none");
    assert_eq!(
        mid.instance("leaf").expect("leaf").name(),
        "leaf",
        "a path is relative to the handle it starts from"
    );
    for unknown in [
        "",
        "nope",
        "mid.nope",
        "mid..leaf",
        "mid.leaf.x",
        "sibling.x",
        ".",
    ] {
        assert!(top.instance(unknown).is_none(), "`{unknown}` resolves");
    }
    assert!(leaf.instance("leaf").is_none(), "atomic: nothing inside");

    // The snapshot is the leaf's own, live.
    let monitor = wait_user(&leaf, "idle");
    assert_eq!(monitor.name, "leaf");
    assert_eq!(monitor.state, State::Running);
    assert_eq!(
        monitor.variables,
        [
            ("count".to_owned(), Value::from(0_u64)),
            ("gain".to_owned(), Value::from(1_i64))
        ]
    );

    // A command through the path reaches the leaf, and mid's supervisor sees it.
    leaf.command(Command::Set("gain".to_owned(), Value::from(9_i64)))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        leaf.snapshot().variables[1],
        ("gain".to_owned(), Value::from(9_i64))
    );
    wait_user(&mid, "degraded");
    wait_log(&mid_log, &["operating.Entry", "degraded.Entry"]);
    mid.wait_for(|m| m.variables[0].1 == Value::UInt(1), WAIT)
        .expect("mid's own variable, read through the path");

    // A fault in the leaf: mid's policy restarts it, and the step is on mid's port.
    periodic_fault(&script);
    feed.kick.emit();
    mid.wait_for(
        |m| {
            m.supervision
                .iter()
                .any(|s| s.instance == "leaf" && s.step == Step::Restarted)
        },
        WAIT,
    )
    .unwrap_or_else(|t| panic!("{t}"));
    wait_user(&leaf, "idle");
    assert_eq!(top.state(), State::Running);

    // The handles outlive the compound without keeping its instances alive.
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
    assert_eq!(leaf.state(), State::Dead);
    assert_eq!(mid.state(), State::Dead);
    assert!(
        leaf.command(Command::SetState(Controllable::Running))
            .is_err()
    );
}

/// A component posting on its poster output `map` every 5 ms: `base`, `base + 1`, …;
/// while `fail` is set it cannot start and its periodic section faults.
struct Poster {
    out: coolbot::port::PosterOut<u64>,
    base: u64,
    posted: u64,
    fail: Arc<std::sync::atomic::AtomicBool>,
}

static POSTER: Spec = Spec {
    type_name: "Poster",
    doc: "",
    states: &[StateSpec {
        name: "posting",
        entry: false,
        exit: false,
        periodic: Some(coolbot::PeriodicSpec { period: None }),
        on: &[],
        after: &[],
        may: &[],
    }],
    initial: 0,
    inputs: &[],
    outputs: &[coolbot::OutputSpec {
        name: "map",
        kind: OutputKind::Poster,
        packet: "u64",
        pull: false,
    }],
    variables: &[],
    exceptions: &[],
    timing: TimingSpec {
        period: Some(Duration::from_millis(5)),
        ..TimingSpec::NONE
    },
};

impl coolbot::Automaton for Poster {
    fn spec(&self) -> &'static Spec {
        &POSTER
    }
    fn start(&mut self, _cx: &mut coolbot::Context) -> Result<(), coolbot::Fault> {
        if self.fail.load(Ordering::SeqCst) {
            return Err(coolbot::Fault::message("cannot start"));
        }
        Ok(())
    }
    fn stop(&mut self, _cx: &mut coolbot::Context) {}
    fn section(&mut self, _s: usize, _sec: Section, _cx: &mut coolbot::Context) -> SectionResult {
        if self.fail.load(Ordering::SeqCst) {
            return Err(coolbot::Fault::message("broken"));
        }
        self.out.post(self.base + self.posted);
        self.posted += 1;
        Ok(())
    }
    fn choose(&mut self, _s: usize, _cx: &mut coolbot::Context) -> Option<usize> {
        None
    }
    fn exception(&mut self, _e: usize, _m: &str, _cx: &mut coolbot::Context) {}
    fn answer(&mut self, _o: usize, _cx: &mut coolbot::Context) -> Result<(), coolbot::Fault> {
        Ok(())
    }
    fn configure(&mut self, _c: &Value) -> Result<(), String> {
        Ok(())
    }
    fn set(&mut self, _v: usize, _value: &Value) -> Result<(), String> {
        Err("no variables".into())
    }
    fn get(&self, _v: usize) -> Value {
        Value::Unit
    }
}

fn poster(name: &str, base: u64, fail: &Arc<std::sync::atomic::AtomicBool>) -> Component {
    let out = coolbot::port::PosterOut::new();
    Component::new(
        name,
        Box::new(Poster {
            out: out.clone(),
            base,
            posted: 0,
            fail: Arc::clone(fail),
        }),
        coolbot::PortSet::new().output(&out),
    )
}

/// Wait until the poster input `r` reads a value for which `wanted` holds, through
/// `read` (`read` or `take_new`).
fn reads(what: &str, read: impl Fn() -> Option<u64>, wanted: impl Fn(u64) -> bool) {
    let deadline = std::time::Instant::now() + WAIT;
    let mut last = None;
    loop {
        if let Some(value) = read() {
            last = Some(value);
            if wanted(value) {
                return;
            }
        }
        assert!(
            std::time::Instant::now() < deadline,
            "timed out waiting for the reader to read {what}; it read {last:?} last"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// A poster reader in a compound whose producer `p1` is substituted by `p2` and then
/// recovers: the reader reads the stand-in's post (with `read` and with `take_new`),
/// then `p1`'s again, with or without a converter on the connection.
fn a_poster_reader_follows_its_producer_through_substitution(converted: bool) {
    let p1_fails = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let never = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let r = coolbot::port::PosterIn::<u64>::new();
    let reader = ShellBuilder::new("c")
        .input(shell::input("r", coolbot::InputKind::Poster, false), &r)
        .build();
    let (sup, _) = Sup::new(&["operating"]);
    let builder = CompoundBuilder::new("base", sup)
        .instance(poster("p1", 1_000_000, &p1_fails))
        .instance(poster("p2", 2_000_000, &never))
        .instance(reader)
        .substitute("p2", "p1")
        .on_error("p1", Policy::Substitute)
        .recovery(Duration::from_millis(40), Duration::from_secs(60));
    let builder = if converted {
        builder.connect_via::<u64, u64>("p1.map", "c.r", |n| n + 10)
    } else {
        builder.connect("p1.map", "c.r")
    };
    let offset = if converted { 10 } else { 0 };
    let p1 = builder.instance_handle("p1").expect("p1");
    let p2 = builder.instance_handle("p2").expect("p2");
    let mut system = System::new();
    let base = system.add(builder.build().expect("build")).expect("add");
    system.run_all().expect("run");
    let from_p1 = |v: u64| (1_000_000 + offset..2_000_000).contains(&v);
    let from_p2 = |v: u64| v >= 2_000_000 + offset;
    reads("a post of p1", || r.read(), from_p1);

    // p1 faults: p2 stands in, and the reader reads p2's posts from its first.
    p1_fails.store(true, Ordering::SeqCst);
    p2.wait_for(|m| m.state == State::Running, WAIT)
        .unwrap_or_else(|t| panic!("{t}"));
    reads("a post of the substitute p2", || r.read(), from_p2);
    reads("a new post of p2 with take_new", || r.take_new(), from_p2);

    // p1 recovers: the reader reads p1 again.
    p1_fails.store(false, Ordering::SeqCst);
    wait(&p2, State::Ready);
    p1.wait_for(|m| m.state == State::Running, WAIT)
        .unwrap_or_else(|t| panic!("{t}"));
    reads("a post of p1 after its recovery", || r.take_new(), from_p1);
    assert_eq!(base.state(), State::Running);
    assert!(system.shutdown().clean());
}

#[test]
fn a_poster_reader_reads_the_substitute_after_a_substitution() {
    a_poster_reader_follows_its_producer_through_substitution(false);
}

#[test]
fn a_converted_poster_reader_reads_the_substitute_after_a_substitution() {
    a_poster_reader_follows_its_producer_through_substitution(true);
}

#[test]
fn a_suspended_compound_keeps_its_mapped_variables_current_up_the_hierarchy() {
    // `top` runs and maps `gain` onto `base`'s, which maps it onto its worker `a`'s.
    // `base` is suspended (and `a` with it); `a`'s gain changes meanwhile: monitoring
    // is observation, so `base` and `top` publish the new value while `base` stays
    // suspended.
    let (sup, _) = Sup::new(&["operating"]);
    let (a, _) = worker("a");
    let base = CompoundBuilder::new("base", sup)
        .instance(a)
        .map_controllable("gain", "a.gain")
        .build()
        .expect("build base");
    let (top_sup, _) = Sup::new(&["operating"]);
    let top = CompoundBuilder::new("top", top_sup)
        .instance(base)
        .map_observable("gain", "base.gain")
        .build()
        .expect("build top");
    let mut system = System::new();
    let top = system.add(top).expect("add top");
    system.run_all().expect("run");
    let base = top.instance("base").expect("base");
    let a = top.instance("base.a").expect("a");
    wait(&a, State::Running);
    run(&base, Controllable::Suspended);
    wait(&a, State::Suspended);
    assert_eq!(top.state(), State::Running);
    let gain = |m: &coolbot::Monitor| m.variables[0].1.clone();
    a.command(Command::Set("gain".to_owned(), Value::Int(9)))
        .expect("a suspended instance takes a Set");
    base.wait_for(|m| gain(m) == Value::Int(9), WAIT)
        .expect("the suspended compound publishes its instance's change");
    top.wait_for(|m| gain(m) == Value::Int(9), WAIT)
        .expect("and so does the compound above it");
    assert_eq!(
        base.state(),
        State::Suspended,
        "it observed, it did not run"
    );
    assert_eq!(a.state(), State::Suspended);
    assert!(system.shutdown().clean());
}

#[test]
fn a_fault_while_the_compound_is_suspended_is_handled_when_it_runs_again() {
    // `w` (restart policy) fails while `base` is suspended (commanded to run on its
    // own, then kicked into a panicking section): `base` observes it, and its policy
    // waits until `base` runs again, then restarts it.
    let (sup, _) = Sup::new(&["operating"]);
    let (w, script) = worker("w");
    let (f, feed) = feeder("f");
    let builder = CompoundBuilder::new("base", sup)
        .instance(w)
        .instance(f)
        .connect("f.kick", "w.kick")
        .on_error("w", Policy::Restart)
        .map_controllable("gain", "w.gain");
    let w = builder.instance_handle("w").expect("w");
    let mut system = System::new();
    let base = system.add(builder.build().expect("build")).expect("add");
    system.run_all().expect("run");
    wait(&w, State::Running);
    run(&base, Controllable::Suspended);
    wait(&w, State::Suspended);
    script.panic_in(Some("busy.periodic"));
    run(&w, Controllable::Running);
    feed.kick.emit();
    wait(&w, State::RunningError);
    // A change after the fault, published by `base` once it has taken `w`'s events
    // up to there (the fault included).
    w.command(Command::Set("gain".to_owned(), Value::Int(4)))
        .expect("set gain");
    let observed = base
        .wait_for(|m| m.variables[0].1 == Value::Int(4), WAIT)
        .unwrap_or_else(|t| panic!("{t}"));
    assert_eq!(observed.state, State::Suspended);
    assert!(
        observed.supervision.iter().all(|s| s.instance != "w"),
        "no policy acted while suspended: {:?}",
        observed.supervision
    );
    assert_eq!(
        w.state(),
        State::RunningError,
        "not restarted while suspended"
    );
    // Running again: the deferred policy restarts it.
    script.panic_in(None);
    run(&base, Controllable::Running);
    let restarted = base
        .wait_for(
            |m| {
                m.supervision
                    .iter()
                    .any(|s| s.instance == "w" && s.step == Step::Restarted)
            },
            WAIT,
        )
        .unwrap_or_else(|t| panic!("{t}"));
    assert!(
        restarted
            .supervision
            .iter()
            .any(|s| s.instance == "w" && s.step == Step::Failed),
        "{:?}",
        restarted.supervision
    );
    wait(&w, State::Running);
    assert!(system.shutdown().clean());
}
