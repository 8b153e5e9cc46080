//! Compound components: driven like atomic ones, instances following the compound's
//! state, supervisor rules on instance changes, and the fault policies (restart,
//! substitute with the recovery queue, deadline expiry, redundancy, propagation up a
//! three-level hierarchy), with faults injected as panics and declared exceptions.
//!
//! The compounds are `cool/compound.cool`'s, over the generated `Worker` (scripted:
//! `support::compound::Scripts` gives each instance its script) and `Feeder` (its
//! ports handed to the test). A test of the runtime's `CompoundBuilder` itself (a
//! `Policy` the language has no word for, malformed builders) adds to a generated
//! compound's builder.

use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use coolbot::crossbeam_channel::{self, Receiver, Sender};
use coolbot::port::{DataOut, FifoIn};
use coolbot::{
    Command, CompoundBuilder, CompoundError, Controllable, MonitorEvent, Policy, State, Step,
    System, Value,
};
use coolbot_runtime_tests::convert::{COPIES, Convert};
use coolbot_runtime_tests::generated::{
    cmp_already, cmp_budget, cmp_cycles, cmp_exported, cmp_hanging, cmp_ignore, cmp_over_mid,
    cmp_over_top, cmp_restarting, cmp_restarting_stuck, cmp_scan_sink, cmp_soak, cmp_source,
    deep_worker,
};
use coolbot_runtime_tests::generated::{
    cmp_converted, cmp_converted_substitute, cmp_counting, cmp_counting_untimed,
    cmp_deep_substitute, cmp_stepping, cmp_text_sink, cmp_trio, cmp_unconverted,
};
use coolbot_runtime_tests::generated::{
    cmp_converted_cycles, cmp_gone, cmp_mapped_rule, cmp_pair, cmp_quality, cmp_standby,
    cmp_watchdog,
};
use coolbot_runtime_tests::generated::{
    cmp_converted_posters, cmp_forwarding, cmp_path_mid, cmp_path_top, cmp_poster,
    cmp_poster_reader, cmp_posters, cmp_suspended_base, cmp_suspended_fault, cmp_suspended_top,
};
use coolbot_runtime_tests::generated::{
    cmp_driven, cmp_lone, cmp_mid, cmp_ordered, cmp_redundant, cmp_restart, cmp_rules,
    cmp_substitution, cmp_substitution_deadline, cmp_top, feeder, worker,
};
use coolbot_runtime_tests::support::compound::{CompoundRig, Scripts, wait_state};
use coolbot_runtime_tests::support::{Feeder, Injected, Script, Scripted, Tap, WAIT, eventually};

/// The supervisors' log of entry sections (`operating.Entry`), shared with the test.
type Log = Arc<Mutex<Vec<String>>>;

/// Where a compound's behaviours come from: the workers follow their scripts, the
/// feeder hands its ports over (`feed`), the supervisor logs.
struct Parts {
    scripts: Scripts,
    log: Log,
    tap: Option<Tap>,
    feed: Option<Receiver<Feeder>>,
}

impl Parts {
    fn new() -> Parts {
        let (tap, feed) = Tap::new();
        Parts {
            scripts: Scripts::new(),
            log: Log::default(),
            tap: Some(tap),
            feed: Some(feed),
        }
    }

    fn logged(&self) -> Logged {
        Logged(Arc::clone(&self.log))
    }

    fn worker(&self, name: &str) -> Scripted {
        self.scripts.scripted(name)
    }

    fn feeder(&mut self) -> Tap {
        self.tap.take().expect("one feeder per compound")
    }
}

/// A supervisor that logs its entry sections; entering `degraded` counts `faults`.
struct Logged(Log);

impl Logged {
    fn entered(&self, state: &str) -> coolbot::SectionResult {
        self.0.lock().unwrap().push(format!("{state}.Entry"));
        Ok(())
    }
}

impl cmp_driven::Supervisor for Logged {
    fn operating_entry(&mut self, _cx: &mut cmp_driven::Cx<'_>) -> coolbot::SectionResult {
        self.entered("operating")
    }
}

impl cmp_rules::Supervisor for Logged {
    fn operating_entry(&mut self, _cx: &mut cmp_rules::Cx<'_>) -> coolbot::SectionResult {
        self.entered("operating")
    }
    fn degraded_entry(&mut self, cx: &mut cmp_rules::Cx<'_>) -> coolbot::SectionResult {
        cx.vars.faults += 1;
        self.entered("degraded")
    }
}

impl cmp_ordered::Supervisor for Logged {
    fn operating_entry(&mut self, _cx: &mut cmp_ordered::Cx<'_>) -> coolbot::SectionResult {
        self.entered("operating")
    }
    fn first_entry(&mut self, _cx: &mut cmp_ordered::Cx<'_>) -> coolbot::SectionResult {
        self.entered("first")
    }
    fn second_entry(&mut self, _cx: &mut cmp_ordered::Cx<'_>) -> coolbot::SectionResult {
        self.entered("second")
    }
}

/// `Logged` for a compound whose supervisor has one state, `operating`.
macro_rules! operating {
    ($($m:ident),*) => {$(
        impl $m::Supervisor for Logged {
            fn operating_entry(&mut self, _cx: &mut $m::Cx<'_>) -> coolbot::SectionResult {
                self.entered("operating")
            }
        }
    )*};
}

operating!(
    cmp_restart,
    cmp_substitution,
    cmp_substitution_deadline,
    cmp_lone,
    cmp_redundant,
    cmp_mid,
    cmp_top,
    cmp_hanging,
    cmp_restarting,
    cmp_restarting_stuck,
    cmp_budget,
    cmp_exported,
    cmp_soak,
    cmp_cycles,
    cmp_over_mid,
    cmp_over_top,
    cmp_converted,
    cmp_unconverted,
    cmp_converted_substitute,
    cmp_trio,
    cmp_deep_substitute,
    cmp_pair,
    cmp_gone,
    cmp_standby,
    cmp_converted_cycles,
    cmp_path_top,
    cmp_posters,
    cmp_converted_posters,
    cmp_suspended_base,
    cmp_suspended_top,
    cmp_suspended_fault,
    cmp_forwarding
);

impl cmp_path_mid::Supervisor for Logged {
    fn operating_entry(&mut self, _cx: &mut cmp_path_mid::Cx<'_>) -> coolbot::SectionResult {
        self.entered("operating")
    }
    fn degraded_entry(&mut self, cx: &mut cmp_path_mid::Cx<'_>) -> coolbot::SectionResult {
        cx.vars.faults += 1;
        self.entered("degraded")
    }
}

/// `CmpPathTop`: `mid`'s supervisor logs into the log of the `Base` (the top's own
/// logs nowhere the test looks).
impl cmp_path_top::Parts for Parts {
    fn supervisor(&mut self) -> impl cmp_path_top::Supervisor {
        Logged(Log::default())
    }
    fn mid(&mut self) -> impl cmp_path_mid::Parts {
        Parts {
            scripts: self.scripts.clone(),
            log: Arc::clone(&self.log),
            tap: self.tap.take(),
            feed: None,
        }
    }
    fn sibling(&mut self) -> impl worker::Behavior {
        self.worker("sibling")
    }
}

/// `CmpSuspendedTop`: `base`'s parts are the same.
impl cmp_suspended_top::Parts for Parts {
    fn supervisor(&mut self) -> impl cmp_suspended_top::Supervisor {
        self.logged()
    }
    fn base(&mut self) -> impl cmp_suspended_base::Parts {
        Parts {
            scripts: self.scripts.clone(),
            log: Log::default(),
            tap: None,
            feed: None,
        }
    }
}

impl cmp_forwarding::Parts for Parts {
    fn supervisor(&mut self) -> impl cmp_forwarding::Supervisor {
        self.logged()
    }
    fn w(&mut self) -> impl coolbot_runtime_tests::generated::blocking_worker::Behavior {
        self.worker("w")
    }
}

/// A `CmpPoster`'s behaviour: posts `base`, `base + 1`, ... on `map` every period;
/// while `fail` is set it cannot start and its periodic section faults.
struct Posting {
    base: u64,
    posted: u64,
    fail: Arc<std::sync::atomic::AtomicBool>,
}

impl cmp_poster::Behavior for Posting {
    fn start(&mut self, _cx: &mut cmp_poster::Cx<'_>) -> coolbot::SectionResult {
        if self.fail.load(Ordering::SeqCst) {
            return Err(coolbot::Fault::message("cannot start"));
        }
        Ok(())
    }
    fn posting_periodic(&mut self, cx: &mut cmp_poster::Cx<'_>) -> coolbot::SectionResult {
        if self.fail.load(Ordering::SeqCst) {
            return Err(coolbot::Fault::message("broken"));
        }
        cx.outputs.map.post(self.base + self.posted);
        self.posted += 1;
        Ok(())
    }
}

/// A `CmpPosterReader`'s behaviour: hands its input to the test when it starts.
struct PosterHand(Sender<coolbot::port::PosterIn<u64>>);

impl cmp_poster_reader::Behavior for PosterHand {
    fn start(&mut self, cx: &mut cmp_poster_reader::Cx<'_>) -> coolbot::SectionResult {
        let _ = self.0.try_send(cx.inputs.r.clone());
        Ok(())
    }
}

/// The parts of `CmpPosters` and `CmpConvertedPosters`.
struct PosterParts {
    parts: Parts,
    p1: Option<Posting>,
    p2: Option<Posting>,
    c: Option<PosterHand>,
}

/// `PosterParts` for compound `$m`.
macro_rules! poster_parts {
    ($($m:ident),*) => {$(
        impl $m::Parts for PosterParts {
            fn supervisor(&mut self) -> impl $m::Supervisor {
                self.parts.logged()
            }
            fn p1(&mut self) -> impl cmp_poster::Behavior {
                self.p1.take().expect("one p1")
            }
            fn p2(&mut self) -> impl cmp_poster::Behavior {
                self.p2.take().expect("one p2")
            }
            fn c(&mut self) -> impl cmp_poster_reader::Behavior {
                self.c.take().expect("one reader")
            }
        }
    )*};
}

poster_parts!(cmp_posters, cmp_converted_posters);

impl cmp_mapped_rule::Supervisor for Logged {
    fn operating_entry(&mut self, _cx: &mut cmp_mapped_rule::Cx<'_>) -> coolbot::SectionResult {
        self.entered("operating")
    }
    fn degraded_entry(&mut self, _cx: &mut cmp_mapped_rule::Cx<'_>) -> coolbot::SectionResult {
        self.entered("degraded")
    }
}

impl cmp_converted_cycles::Parts for Parts {
    fn supervisor(&mut self) -> impl cmp_converted_cycles::Supervisor {
        self.logged()
    }
    fn w(&mut self) -> impl deep_worker::Behavior {
        self.worker("w")
    }
    fn b(&mut self) -> impl deep_worker::Behavior {
        self.worker("b")
    }
    fn f(&mut self) -> impl feeder::Behavior {
        self.feeder()
    }
}

impl cmp_watchdog::Supervisor for Logged {
    fn operating_entry(&mut self, _cx: &mut cmp_watchdog::Cx<'_>) -> coolbot::SectionResult {
        self.entered("operating")
    }
    fn degraded_entry(&mut self, _cx: &mut cmp_watchdog::Cx<'_>) -> coolbot::SectionResult {
        self.entered("degraded")
    }
    /// The builder's rule moves on, never the choice.
    fn operating_choose(
        &mut self,
        _cx: &mut cmp_watchdog::Cx<'_>,
    ) -> Option<cmp_watchdog::OperatingMay> {
        None
    }
}

impl cmp_quality::Supervisor for Logged {
    fn operating_entry(&mut self, _cx: &mut cmp_quality::Cx<'_>) -> coolbot::SectionResult {
        self.entered("operating")
    }
    fn degraded_entry(&mut self, _cx: &mut cmp_quality::Cx<'_>) -> coolbot::SectionResult {
        self.entered("degraded")
    }
}

impl cmp_already::Supervisor for Logged {
    fn first_entry(&mut self, _cx: &mut cmp_already::Cx<'_>) -> coolbot::SectionResult {
        self.entered("first")
    }
    fn second_entry(&mut self, _cx: &mut cmp_already::Cx<'_>) -> coolbot::SectionResult {
        self.entered("second")
    }
    fn third_entry(&mut self, _cx: &mut cmp_already::Cx<'_>) -> coolbot::SectionResult {
        self.entered("third")
    }
}

impl cmp_ignore::Supervisor for Logged {
    fn operating_entry(&mut self, _cx: &mut cmp_ignore::Cx<'_>) -> coolbot::SectionResult {
        self.entered("operating")
    }
    fn degraded_entry(&mut self, _cx: &mut cmp_ignore::Cx<'_>) -> coolbot::SectionResult {
        self.entered("degraded")
    }
}

/// `Parts` for compound `$m` with supervisor `Logged`, workers `$w` and feeder `$f`.
macro_rules! parts {
    ($m:ident; workers $($w:ident),*; $(feeder $f:ident)?) => {
        impl $m::Parts for Parts {
            fn supervisor(&mut self) -> impl $m::Supervisor {
                self.logged()
            }
            $(
                fn $w(&mut self) -> impl worker::Behavior {
                    self.worker(stringify!($w))
                }
            )*
            $(
                fn $f(&mut self) -> impl feeder::Behavior {
                    self.feeder()
                }
            )?
        }
    };
}

parts!(cmp_driven; workers a, b;);
parts!(cmp_rules; workers w; feeder f);
parts!(cmp_ordered; workers w;);
parts!(cmp_restart; workers w; feeder f);
parts!(cmp_substitution; workers w, b; feeder f);
parts!(cmp_substitution_deadline; workers w, b; feeder f);
parts!(cmp_lone; workers w; feeder f);
parts!(cmp_redundant; workers a, b; feeder f);
parts!(cmp_mid; workers leaf1, leaf2; feeder f);
parts!(cmp_hanging; workers w, b; feeder f);
parts!(cmp_restarting; workers w; feeder f);
parts!(cmp_restarting_stuck; workers w; feeder f);
parts!(cmp_budget; workers w; feeder f);
parts!(cmp_ignore; workers w; feeder f);
parts!(cmp_over_mid; workers leaf1, spare, leaf2; feeder f);
parts!(cmp_already; workers w;);
parts!(cmp_converted_substitute; workers w, b; feeder f);
parts!(cmp_trio; workers a, b, c;);
parts!(cmp_stepping; workers w;);
parts!(cmp_watchdog; workers w; feeder f);
parts!(cmp_pair; workers a, b; feeder f);
parts!(cmp_gone; workers w, b; feeder f);
parts!(cmp_quality; workers w;);
parts!(cmp_standby; workers w, b; feeder f);
parts!(cmp_mapped_rule; workers w, b; feeder f);
parts!(cmp_path_mid; workers leaf; feeder f);
parts!(cmp_suspended_base; workers a;);
parts!(cmp_suspended_fault; workers w; feeder f);

impl cmp_deep_substitute::Parts for DeepParts {
    fn supervisor(&mut self) -> impl cmp_deep_substitute::Supervisor {
        self.0.logged()
    }
    fn w(&mut self) -> impl worker::Behavior {
        self.0.worker("w")
    }
    fn deep(&mut self) -> impl deep_worker::Behavior {
        self.0.worker("deep")
    }
}

/// The parts of a compound with a `DeepWorker`.
struct DeepParts(Parts);

/// A `CmpTextSink`'s behaviour: hands its input to the test when it starts.
struct TextSink(Sender<FifoIn<String>>);

impl cmp_text_sink::Behavior for TextSink {
    fn start(&mut self, cx: &mut cmp_text_sink::Cx<'_>) -> coolbot::SectionResult {
        let _ = self.0.try_send(cx.inputs.text.clone());
        Ok(())
    }
}

/// The parts of `CmpConverted` and `CmpUnconverted`: `Parts`, and the text sink.
struct TextParts(Parts, Option<TextSink>);

/// `TextParts` for compound `$m` (`f` and `sink`).
macro_rules! text_parts {
    ($($m:ident),*) => {$(
        impl $m::Parts for TextParts {
            fn supervisor(&mut self) -> impl $m::Supervisor {
                self.0.logged()
            }
            fn f(&mut self) -> impl feeder::Behavior {
                self.0.feeder()
            }
            fn sink(&mut self) -> impl cmp_text_sink::Behavior {
                self.1.take().expect("one sink")
            }
        }
    )*};
}

text_parts!(cmp_converted, cmp_unconverted);

/// A supervisor counting its periodic sections in its local variable `count`.
struct Counter;

impl cmp_counting::Supervisor for Counter {
    fn counting_periodic(&mut self, cx: &mut cmp_counting::Cx<'_>) -> coolbot::SectionResult {
        cx.vars.count += 1;
        Ok(())
    }
    fn stopped_entry(&mut self, _cx: &mut cmp_counting::Cx<'_>) -> coolbot::SectionResult {
        Ok(())
    }
}

impl cmp_counting_untimed::Supervisor for Counter {
    fn counting_periodic(
        &mut self,
        cx: &mut cmp_counting_untimed::Cx<'_>,
    ) -> coolbot::SectionResult {
        cx.vars.count += 1;
        Ok(())
    }
    fn stopped_entry(&mut self, _cx: &mut cmp_counting_untimed::Cx<'_>) -> coolbot::SectionResult {
        Ok(())
    }
}

/// The parts of a compound whose supervisor is `Counter`.
struct CounterParts(Parts);

impl cmp_counting::Parts for CounterParts {
    fn supervisor(&mut self) -> impl cmp_counting::Supervisor {
        Counter
    }
    fn w(&mut self) -> impl worker::Behavior {
        self.0.worker("w")
    }
}

impl cmp_counting_untimed::Parts for CounterParts {
    fn supervisor(&mut self) -> impl cmp_counting_untimed::Supervisor {
        Counter
    }
    fn w(&mut self) -> impl worker::Behavior {
        self.0.worker("w")
    }
}

/// `CmpStepping`'s supervisor has no sections.
impl cmp_stepping::Supervisor for Logged {}

impl cmp_cycles::Parts for Parts {
    fn supervisor(&mut self) -> impl cmp_cycles::Supervisor {
        self.logged()
    }
    fn w(&mut self) -> impl deep_worker::Behavior {
        self.worker("w")
    }
    fn b(&mut self) -> impl deep_worker::Behavior {
        self.worker("b")
    }
}

impl cmp_soak::Parts for Parts {
    fn supervisor(&mut self) -> impl cmp_soak::Supervisor {
        self.logged()
    }
    fn flaky(&mut self) -> impl worker::Behavior {
        self.worker("flaky")
    }
    fn steady(&mut self) -> impl deep_worker::Behavior {
        self.worker("steady")
    }
    fn f(&mut self) -> impl feeder::Behavior {
        self.feeder()
    }
}

/// `CmpOverTop`: `mid`'s parts are the same (one set of scripts, one feeder).
impl cmp_over_top::Parts for Parts {
    fn supervisor(&mut self) -> impl cmp_over_top::Supervisor {
        self.logged()
    }
    fn mid(&mut self) -> impl cmp_over_mid::Parts {
        Parts {
            scripts: self.scripts.clone(),
            log: Log::default(),
            tap: self.tap.take(),
            feed: None,
        }
    }
}

/// A `CmpSource`'s behaviour: hands its output to the test when it starts.
struct Source(Sender<DataOut<u64>>);

impl cmp_source::Behavior for Source {
    fn start(&mut self, cx: &mut cmp_source::Cx<'_>) -> coolbot::SectionResult {
        let _ = self.0.try_send(cx.outputs.out.clone());
        Ok(())
    }
}

/// A `CmpScanSink`'s behaviour: hands its input to the test when it starts.
struct Sink(Sender<FifoIn<u64>>);

impl cmp_scan_sink::Behavior for Sink {
    fn start(&mut self, cx: &mut cmp_scan_sink::Cx<'_>) -> coolbot::SectionResult {
        let _ = self.0.try_send(cx.inputs.scans.clone());
        Ok(())
    }
}

/// `CmpExported`'s parts: `Parts`, and its source.
struct ExportedParts(Parts, Option<Source>);

impl cmp_exported::Parts for ExportedParts {
    fn supervisor(&mut self) -> impl cmp_exported::Supervisor {
        self.0.logged()
    }
    fn w(&mut self) -> impl deep_worker::Behavior {
        self.0.worker("w")
    }
    fn b(&mut self) -> impl deep_worker::Behavior {
        self.0.worker("b")
    }
    fn src(&mut self) -> impl cmp_source::Behavior {
        self.1.take().expect("one source")
    }
}

/// `CmpTop`: `mid`'s parts are the same (one set of scripts, one feeder).
impl cmp_top::Parts for Parts {
    fn supervisor(&mut self) -> impl cmp_top::Supervisor {
        self.logged()
    }
    fn mid(&mut self) -> impl cmp_mid::Parts {
        Parts {
            scripts: self.scripts.clone(),
            log: Log::default(),
            tap: self.tap.take(),
            feed: None,
        }
    }
    fn sibling(&mut self) -> impl worker::Behavior {
        self.worker("sibling")
    }
}

/// A rig around compound `base`, the scripts of its workers, its supervisor's log,
/// and its feeder's ports (once it started).
struct Base {
    rig: CompoundRig,
    scripts: Scripts,
    log: Log,
    feed: Option<Receiver<Feeder>>,
}

impl Base {
    /// The compound `build` makes from the parts, added to a new system.
    fn new(build: impl FnOnce(Parts) -> Result<coolbot::Component, CompoundError>) -> Base {
        Base::with_rig(CompoundRig::new, build)
    }

    /// The same on a virtual clock.
    fn on_virtual_clock(
        build: impl FnOnce(Parts) -> Result<coolbot::Component, CompoundError>,
    ) -> Base {
        Base::with_rig(CompoundRig::on_virtual_clock, build)
    }

    /// The compound `build` makes from the parts, in the rig `rig` makes of it.
    fn with_rig(
        rig: fn(Result<coolbot::Component, CompoundError>) -> CompoundRig,
        build: impl FnOnce(Parts) -> Result<coolbot::Component, CompoundError>,
    ) -> Base {
        let mut parts = Parts::new();
        let scripts = parts.scripts.clone();
        let log = Arc::clone(&parts.log);
        let feed = parts.feed.take();
        Base {
            rig: rig(build(parts)),
            scripts,
            log,
            feed,
        }
    }

    fn script(&self, name: &str) -> Arc<Script> {
        self.scripts.of(name)
    }

    /// Add a feeder `f` outside the compound, connect its ports to the compound's as
    /// `links` say (`(feeder port, compound port)`), run the system and return the
    /// feeder's ports.
    fn run_fed(&mut self, links: &[(&str, &str)]) -> Feeder {
        let (tap, feed) = Tap::new();
        self.rig.add(feeder::component("f", tap));
        for (from, to) in links {
            self.rig
                .connect(&format!("f.{from}"), &format!("base.{to}"));
        }
        self.rig.run();
        feed.recv_timeout(WAIT).expect("the feeder started")
    }

    /// The feeder's ports (it hands them over when it starts).
    fn feeder(&mut self) -> Feeder {
        self.feed
            .take()
            .expect("a feeder")
            .recv_timeout(WAIT)
            .expect("the feeder started")
    }
}

fn run(handle: &coolbot::Handle, target: Controllable) {
    handle
        .command(Command::SetState(target))
        .unwrap_or_else(|e| panic!("{e}"));
}

fn wait(handle: &coolbot::Handle, state: State) -> coolbot::Monitor {
    wait_state(handle, state)
}

/// Wait until `handle`'s user state is `user` (in whatever default state).
fn wait_user(handle: &coolbot::Handle, user: &str) -> coolbot::Monitor {
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
        exception: Some(worker::Exception::Fatal),
        times: 1,
    }));
}

#[test]
fn a_compound_is_driven_and_observed_like_an_atomic_component() {
    let mut rig = Base::new(|parts| {
        let compound = cmp_driven::component("base", parts)?;
        assert_eq!(compound.spec().type_name, "CmpDriven");
        Ok(compound)
    });
    // An atomic worker beside it, driven by the same commands.
    let atomic = rig
        .rig
        .add(worker::component("atomic", Scripted::new(&Script::new())));
    let base = rig.rig.compound.clone();
    rig.rig.start();
    let (a, b) = (rig.rig.instance("a"), rig.rig.instance("b"));
    wait(&base, State::Ready);
    wait(&atomic, State::Ready);
    assert_eq!(a.state(), State::Ready, "instances start with the compound");

    let sequence = [
        Controllable::Running,
        Controllable::Suspended,
        Controllable::Running,
        Controllable::Ready,
        Controllable::Suspended,
        Controllable::Ready,
        Controllable::Running,
    ];
    for target in sequence {
        run(&base, target);
        run(&atomic, target);
        assert_eq!(base.state(), atomic.state(), "after {target:?}");
        let expected = target.state();
        assert_eq!(base.state(), expected);
        for instance in [&a, &b] {
            assert_eq!(instance.state(), expected, "{} follows", instance.name());
        }
    }
    let monitor = wait_user(&base, "operating");
    assert_eq!(monitor.state, State::Running);
    let names: Vec<&str> = monitor.variables.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["count", "gain", "faults"]);
    assert_eq!(monitor.variables[0].1, Value::UInt(0));

    // Mapped controllable: set through the compound, seen on the instance.
    base.command(Command::Set("gain".to_owned(), Value::Int(7)))
        .expect("set gain");
    b.wait_for(|m| m.variables[1].1 == Value::Int(7), WAIT)
        .expect("b's gain");
    base.wait_for(|m| m.variables[1].1 == Value::Int(7), WAIT)
        .expect("the compound republishes it");
    let rejected = base
        .command(Command::Set("count".to_owned(), Value::UInt(1)))
        .expect_err("observable");
    assert!(rejected.reason.contains("observable"), "{rejected}");
    for command in [
        Command::SetPriority(-3),
        Command::SetPeriod(Duration::from_millis(20)),
        Command::SetMaxResponse(Duration::from_millis(500)),
        Command::SetQuality(0),
    ] {
        base.command(command.clone()).expect("accepted");
        atomic.command(command).expect("accepted");
    }
    assert!(
        rig.log
            .lock()
            .unwrap()
            .iter()
            .all(|e| e == "operating.Entry"),
        "only the initial supervisor state was entered: {:?}",
        rig.log.lock().unwrap()
    );

    // dead: the supervisor first, then the instances; the threads are joined.
    run(&base, Controllable::Dead);
    assert_eq!(base.state(), State::Dead);
    assert_eq!(a.state(), State::Dead);
    assert_eq!(b.state(), State::Dead);
    let report = rig.rig.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn rules_fire_when_an_instance_changes_state() {
    let mut rig = Base::new(|parts| cmp_rules::component("base", parts));
    let script = rig.script("w");
    rig.rig.run();
    let feed = rig.feeder();
    let (base, w) = (rig.rig.compound.clone(), rig.rig.instance("w"));
    wait_user(&base, "operating");
    wait_user(&w, "idle");

    // A declared exception without a plan: w goes to running_error.
    periodic_fault(&script);
    feed.kick.emit();
    let monitor = wait_user(&base, "degraded");
    assert_eq!(
        monitor.state,
        State::Running,
        "ignored: the compound goes on"
    );
    assert_eq!(w.state(), State::RunningError);
    base.wait_for(|m| m.variables[0].1 == Value::UInt(1), WAIT)
        .expect("own variable published");

    // Restarting w by hand fires the second rule.
    run(&w, Controllable::Running);
    wait_user(&base, "operating");
    wait_log(
        &rig.log,
        &["operating.Entry", "degraded.Entry", "operating.Entry"],
    );
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn rules_are_evaluated_in_declaration_order_and_on_entry() {
    // Both rules hold when `operating` is entered: the first declared fires.
    let mut rig = Base::new(|parts| cmp_ordered::component("base", parts));
    rig.rig.run();
    wait_user(&rig.rig.compound, "first");
    wait_log(&rig.log, &["operating.Entry", "first.Entry"]);
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn restart_policy_brings_the_instance_back_and_the_compound_runs_on() {
    let mut rig = Base::new(|parts| cmp_restart::component("base", parts));
    let script = rig.script("w");
    rig.rig.run();
    let feed = rig.feeder();
    let (base, w) = (rig.rig.compound.clone(), rig.rig.instance("w"));
    wait_user(&w, "idle");
    let events = base.subscribe();

    script.panic_in(Some("busy.exit"));
    script.inject(Some(Injected {
        hook: "busy.periodic",
        exception: None,
        times: 1,
    }));
    feed.kick.emit();
    eventually(
        || script.log().iter().filter(|e| *e == "start").count() == 2,
        "w restarted",
    );
    let monitor = wait_user(&w, "idle");
    assert_eq!(monitor.state, State::Running);
    assert_eq!(script.injected.load(Ordering::SeqCst), 1);
    assert_eq!(base.state(), State::Running);
    assert!(
        events
            .try_iter()
            .all(|e| !matches!(e, MonitorEvent::State { .. })),
        "the compound never left running"
    );
    assert!(rig.rig.shutdown().clean());
}

/// A compound `base` with primary `w` (policy substitute), its substitute `b`, and a
/// feeder `f` whose data goes to `w.data` (`CmpSubstitution`, or with a recovery
/// deadline of 200 ms `CmpSubstitutionDeadline`).
struct Substitution {
    rig: CompoundRig,
    base: coolbot::Handle,
    w: coolbot::Handle,
    b: coolbot::Handle,
    w_script: Arc<Script>,
    b_script: Arc<Script>,
    feed: Feeder,
}

fn substitution(short_deadline: bool) -> Substitution {
    let mut rig = Base::new(|parts| {
        if short_deadline {
            cmp_substitution_deadline::component("base", parts)
        } else {
            cmp_substitution::component("base", parts)
        }
    });
    rig.rig.run();
    let feed = rig.feeder();
    let (w, b) = (rig.rig.instance("w"), rig.rig.instance("b"));
    wait_user(&w, "idle");
    assert_eq!(b.state(), State::Ready, "a substitute waits in ready");
    Substitution {
        base: rig.rig.compound.clone(),
        w,
        b,
        w_script: rig.script("w"),
        b_script: rig.script("b"),
        rig: rig.rig,
        feed,
    }
}

impl Substitution {
    /// w fails (a panic) and cannot restart until `start_fails` is cleared.
    fn fail_primary(&self) {
        self.w_script.start_fails.store(true, Ordering::SeqCst);
        self.w_script.panic_in(Some("busy.periodic"));
        self.feed.kick.emit();
        // Packets moved to b before its initial state is entered are arrivals there.
        wait(&self.b, State::Running);
        assert_eq!(self.base.state(), State::Running);
        assert_ne!(self.w.state(), State::Running);
    }
}

#[test]
fn a_substitute_takes_over_and_the_recovered_original_takes_its_place_back() {
    let rig = substitution(false);
    rig.fail_primary();
    // The connections moved: packets go to the substitute.
    rig.feed.data.send(1);
    rig.feed.data.send(2);
    eventually(
        || rig.b_script.received.load(Ordering::SeqCst) == 2,
        "the substitute received both packets",
    );
    rig.base
        .wait_for(|m| m.variables[0].1 == Value::UInt(2), WAIT)
        .expect("the mapped variable follows the substitute");
    // The recovery queue keeps retrying w; it fails in `start` meanwhile.
    rig.w
        .wait_state(State::StartingError, WAIT)
        .expect("retried");
    rig.w_script.panic_in(None);
    rig.w_script.start_fails.store(false, Ordering::SeqCst);
    // w recovers: the arrangement before the fault comes back.
    wait(&rig.b, State::Ready);
    assert_eq!(rig.w.state(), State::Running);
    let before = rig.w_script.received.load(Ordering::SeqCst);
    rig.feed.data.send(3);
    eventually(
        || rig.w_script.received.load(Ordering::SeqCst) == before + 1,
        "w receives again",
    );
    assert_eq!(rig.b_script.received.load(Ordering::SeqCst), 2);
    assert_eq!(rig.base.state(), State::Running);
    // Each step was reported on the compound's monitoring port, in order.
    let monitor = rig
        .base
        .wait_for(
            |m| m.supervision.iter().any(|s| s.step == Step::Recovered),
            WAIT,
        )
        .expect("the recovery is reported");
    let mut steps: Vec<Step> = monitor.supervision.iter().map(|s| s.step.clone()).collect();
    steps.dedup();
    assert_eq!(
        steps,
        [
            Step::Failed,
            Step::Enqueued,
            Step::Substituted { by: "b".to_owned() },
            Step::RetryFailed,
            Step::Retried,
            Step::Recovered
        ]
    );
    // The failed retries say why: a first retry may find w still in its panicking
    // section; the one the test waited for left it in starting_error (its `start`
    // fails).
    let failed: Vec<String> = monitor
        .supervision
        .iter()
        .filter(|s| s.step == Step::RetryFailed)
        .map(|s| s.to_string())
        .collect();
    assert!(
        failed
            .iter()
            .any(|s| s == "w retry failed: starting_error after the restart"),
        "{failed:?}"
    );
    assert!(monitor.supervision.iter().all(|s| s.instance == "w"));
    assert!(monitor.supervision_steps >= 5);
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn at_the_deadline_the_original_is_destroyed_and_the_substitute_stays() {
    let rig = substitution(true);
    let events = rig.base.subscribe();
    rig.fail_primary();
    wait(&rig.w, State::Dead);
    assert_eq!(rig.b.state(), State::Running);
    // The retirement is announced to observers as it happens.
    let until = std::time::Instant::now() + WAIT;
    let mut events = std::iter::from_fn(|| events.recv_deadline(until).ok());
    let retired = events.find_map(|event| match event {
        MonitorEvent::Supervision(step) if step.step == Step::Retired => Some(step),
        _ => None,
    });
    let retired = retired.expect("a retirement event");
    assert_eq!(retired.instance, "w");
    assert!(retired.to_string().starts_with("w retired"), "{retired}");
    assert_eq!(rig.base.state(), State::Running);
    rig.feed.data.send(9);
    eventually(
        || rig.b_script.received.load(Ordering::SeqCst) == 1,
        "the substitute goes on",
    );
    // Stopped and run again, the compound keeps the substitute in the dead one's place.
    run(&rig.base, Controllable::Ready);
    assert_eq!(rig.b.state(), State::Ready);
    run(&rig.base, Controllable::Running);
    wait_user(&rig.b, "idle");
    rig.feed.data.send(10);
    eventually(
        || rig.b_script.received.load(Ordering::SeqCst) == 2,
        "the substitute still has the connections",
    );
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn at_the_deadline_without_a_substitute_the_compound_fails() {
    // `on error w: substitute;` needs a substitute in the language: the runtime's
    // policy without one (the recovery queue alone) is set on the builder.
    let mut rig = Base::new(|parts| {
        cmp_lone::builder("base", parts)?
            .connect("f.kick", "w.kick")
            .on_error("w", Policy::Substitute)
            .recovery(Duration::from_millis(30), Duration::from_millis(150))
            .build()
    });
    let script = rig.script("w");
    rig.rig.run();
    let feed = rig.feeder();
    let (base, w) = (rig.rig.compound.clone(), rig.rig.instance("w"));
    wait_user(&w, "idle");
    script.start_fails.store(true, Ordering::SeqCst);
    script.panic_in(Some("busy.periodic"));
    feed.kick.emit();
    let monitor = wait(&base, State::RunningError);
    let error = monitor.error.expect("error");
    assert!(
        error.contains("`w` did not recover"),
        "the error says why: {error}"
    );
    // Retired: sent `dead` without waiting (its thread takes it when it can).
    w.wait_state(State::Dead, WAIT).expect("w is dead");
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn a_redundant_group_runs_while_one_member_survives() {
    let mut rig = Base::new(|parts| cmp_redundant::component("base", parts));
    let (a_script, b_script) = (rig.script("a"), rig.script("b"));
    rig.rig.run();
    let feed = rig.feeder();
    let (base, a, b) = (
        rig.rig.compound.clone(),
        rig.rig.instance("a"),
        rig.rig.instance("b"),
    );
    wait_user(&a, "idle");
    wait_user(&b, "idle");
    // Every live member receives every packet.
    feed.data.send(1);
    eventually(|| a_script.received.load(Ordering::SeqCst) == 1, "a got it");
    eventually(|| b_script.received.load(Ordering::SeqCst) == 1, "b got it");
    // a fails (a panic; its restarts fail): b goes on alone, the compound goes on.
    a_script.start_fails.store(true, Ordering::SeqCst);
    a_script.panic_in(Some("busy.periodic"));
    wait(&a, State::RunningError);
    feed.data.send(2);
    feed.data.send(3);
    eventually(
        || b_script.received.load(Ordering::SeqCst) == 3,
        "b gets every packet",
    );
    assert_eq!(base.state(), State::Running);
    // b fails too: nobody is left.
    b_script.panic_in(Some("busy.periodic"));
    let monitor = wait(&base, State::RunningError);
    assert!(
        monitor.error.as_deref().unwrap_or("").contains("redundant"),
        "{monitor:?}"
    );
    assert_eq!(a_script.received.load(Ordering::SeqCst), 1);
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn faults_are_handled_in_the_middle_or_propagated_to_the_top_of_three_levels() {
    // mid: leaf1 (restart), leaf2 (propagate), fed by f; top: mid (propagate) and a
    // sibling (`CmpTop`).
    let mut rig = Base::new(|parts| cmp_top::component("top", parts));
    let (script1, script2) = (rig.script("leaf1"), rig.script("leaf2"));
    rig.rig.run();
    let feed = rig.feeder();
    let top = rig.rig.compound.clone();
    let (mid, leaf1, leaf2) = (
        rig.rig.instance("mid"),
        rig.rig.instance("mid.leaf1"),
        rig.rig.instance("mid.leaf2"),
    );
    wait_user(&leaf1, "idle");
    wait_user(&leaf2, "idle");
    assert_eq!(mid.state(), State::Running);

    // leaf1 fails: handled in the middle.
    periodic_fault(&script1);
    feed.kick.emit();
    eventually(
        || script1.log().iter().filter(|e| *e == "start").count() == 2,
        "leaf1 restarted by mid",
    );
    wait_user(&leaf1, "idle");
    assert_eq!(mid.state(), State::Running);
    assert_eq!(top.state(), State::Running);

    // leaf2 fails: mid goes to running_error, top hears it and fails too.
    script2.panic_in(Some("busy.entry"));
    feed.data.send(1);
    let monitor = wait(&top, State::RunningError);
    let error = monitor.error.expect("error");
    assert!(
        error.contains("instance `mid` failed") && error.contains("instance `leaf2` failed"),
        "{error}"
    );
    assert_eq!(mid.state(), State::RunningError);
    assert_eq!(leaf2.state(), State::RunningError);
    assert_eq!(
        leaf1.state(),
        State::Ready,
        "mid's stop brought its running instances to ready"
    );
    assert_eq!(*rig.log.lock().unwrap(), ["operating.Entry"]);

    // The top restarts the whole hierarchy through its control port.
    script2.panic_in(None);
    run(&top, Controllable::Running);
    wait_user(&leaf2, "idle");
    assert_eq!(mid.state(), State::Running);
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn malformed_compounds_are_rejected_with_clear_errors() {
    // The runtime's builder refuses what coolc would: each mistake is added to a
    // generated compound's builder (`CmpLone`: `w`, a worker, and `f`, a feeder).
    let build = |f: fn(CompoundBuilder) -> CompoundBuilder| {
        f(cmp_lone::builder("base", Parts::new()).expect("builder")).build()
    };
    let unknown = build(|b| b.on_error("nobody", Policy::Restart)).expect_err("unknown");
    assert!(
        matches!(
            &unknown,
            CompoundError::Unknown { compound, what: "instance", name }
                if compound == "base" && name == "nobody"
        ),
        "{unknown:?}"
    );
    let rule =
        build(|b| b.rule("operating", "nowhere", &["w.state"], |_| true)).expect_err("state");
    assert!(rule.to_string().contains("`nowhere`"), "{rule}");
    let read =
        build(|b| b.rule("operating", "operating", &["w.speed"], |_| true)).expect_err("var");
    assert!(read.to_string().contains("`w.speed`"), "{read}");
    let substitute = build(|b| b.substitute("f", "w")).expect_err("interface");
    assert!(
        substitute.to_string().contains("same interface"),
        "{substitute}"
    );
    let group = build(|b| b.redundant(&["w"])).expect_err("group of one");
    assert!(group.to_string().contains("at least two"), "{group}");
    let mapped = build(|b| b.map_controllable("c", "w.count")).expect_err("observable");
    assert!(mapped.to_string().contains("observable"), "{mapped}");
    // A bad connection is found when the compound wires it, at start.
    let component = build(|b| b.connect("f.kick", "w.data")).expect("builds");
    let mut system = System::new();
    let base = system.add(component).expect("add");
    system.start().expect("start");
    let monitor = wait(&base, State::StartingError);
    assert!(
        monitor
            .error
            .as_deref()
            .unwrap_or("")
            .contains("cannot connect"),
        "{monitor:?}"
    );
    assert!(system.shutdown().clean());
}

fn starts(script: &Script) -> usize {
    script.log().iter().filter(|e| *e == "start").count()
}

#[test]
fn an_instance_hanging_past_max_response_is_substituted_and_recovers_once_it_returns() {
    let mut rig = Base::new(|parts| cmp_hanging::component("base", parts));
    let (w_script, b_script) = (rig.script("w"), rig.script("b"));
    rig.rig.run();
    let feed = rig.feeder();
    let (base, w, b) = (
        rig.rig.compound.clone(),
        rig.rig.instance("w"),
        rig.rig.instance("b"),
    );
    wait_user(&w, "idle");
    let release = w_script.hang_in("busy.periodic");
    feed.kick.emit();
    // The watchdog moves w to running_error while its section still hangs; the
    // compound substitutes it at once.
    wait_user(&b, "idle");
    assert!(w.is_stuck());
    assert!(w_script.hanging.load(Ordering::SeqCst));
    let monitor = w.snapshot();
    assert_eq!(monitor.state, State::RunningError);
    assert!(
        monitor
            .error
            .as_deref()
            .is_some_and(|e| e.contains("still running after") && e.contains("max_response 500ms")),
        "{monitor:?}"
    );
    assert_eq!(base.state(), State::Running);
    feed.data.send(1);
    eventually(
        || b_script.received.load(Ordering::SeqCst) == 1,
        "the substitute gets the stream",
    );
    // The section returns: the recovery queue restarts w, which takes its place back.
    assert_eq!(starts(&w_script), 1, "no restart while the section hangs");
    drop(release);
    wait(&b, State::Ready);
    assert_eq!(w.state(), State::Running);
    assert_eq!(w_script.returned.load(Ordering::SeqCst), 1);
    assert_eq!(starts(&w_script), 2);
    let before = w_script.received.load(Ordering::SeqCst);
    feed.data.send(2);
    eventually(
        || w_script.received.load(Ordering::SeqCst) == before + 1,
        "w has its connections back",
    );
    assert_eq!(b_script.received.load(Ordering::SeqCst), 1);
    assert_eq!(base.state(), State::Running);
    assert!(rig.rig.shutdown().clean());
}

/// A compound `base` whose instance `w` (with a 500 ms max_response) is restarted on
/// error, within 5 restarts in a minute (backoff 1 ms..4 ms), with a recovery
/// deadline of 30 s (`CmpRestarting`) or 150 ms (`CmpRestartingStuck`), running.
fn restarting(
    short_deadline: bool,
) -> (Base, coolbot::Handle, coolbot::Handle, Arc<Script>, Feeder) {
    let mut rig = Base::new(|parts| {
        if short_deadline {
            cmp_restarting_stuck::component("base", parts)
        } else {
            cmp_restarting::component("base", parts)
        }
    });
    let script = rig.script("w");
    rig.rig.run();
    let feed = rig.feeder();
    let (base, w) = (rig.rig.compound.clone(), rig.rig.instance("w"));
    (rig, base, w, script, feed)
}

#[test]
fn restart_of_an_instance_hanging_past_max_response_waits_for_its_section() {
    let (rig, base, w, script, feed) = restarting(false);
    wait_user(&w, "idle");
    let release = script.hang_in("busy.periodic");
    feed.kick.emit();
    wait(&w, State::RunningError);
    assert!(w.is_stuck());
    assert_eq!(base.state(), State::Running, "the compound runs on");
    assert_eq!(starts(&script), 1);
    drop(release);
    eventually(|| starts(&script) == 2, "w restarted once it returned");
    let monitor = wait_user(&w, "idle");
    assert_eq!(monitor.state, State::Running);
    assert_eq!(monitor.overruns, 1);
    assert_eq!(base.state(), State::Running);
    assert!(rig.rig.shutdown().clean());
}

/// A compound shutting down takes `COMPOUND_STOP_TIMEOUT` at most for its stop, less
/// than a system's shutdown timeout: the system joins the compound's thread though an
/// instance is stuck in a section (waiting for the stuck instance to take `dead`,
/// then for its thread, took the compound past the system's deadline). The report is
/// not clean: it names the instance whose thread was not joined. The instance takes
/// its `dead` once its section returns.
#[test]
fn a_system_shutdown_joins_a_compound_whose_instance_is_stuck() {
    let mut rig = Base::new(|parts| cmp_ignore::component("base", parts));
    let script = rig.script("w");
    rig.rig.run();
    let feed = rig.feeder();
    let (base, w) = (rig.rig.compound.clone(), rig.rig.instance("w"));
    wait_user(&w, "idle");
    let release = script.hang_in("busy.periodic");
    feed.kick.emit();
    // Past its `max_response` the watchdog finds it stuck; the compound ignores it.
    eventually(|| w.is_stuck(), "w is stuck");
    let report = rig.rig.shutdown();
    let compound = report
        .components
        .iter()
        .find(|c| c.name == "base")
        .expect("the compound in the report");
    assert!(compound.joined, "{report:?}");
    assert_eq!(compound.state, State::Dead);
    assert_eq!(compound.unjoined_instances, ["w"], "{report:?}");
    assert!(!report.clean());
    let refused = base
        .snapshot()
        .supervision
        .into_iter()
        .find(|s| {
            s.instance == "w"
                && s.step
                    == Step::CommandRefused {
                        command: "dead".to_owned(),
                    }
        })
        .expect("a refused step for w's `dead`");
    assert!(refused.detail.contains("stuck"), "{refused:?}");
    drop(release);
    w.wait_state(State::Dead, WAIT)
        .expect("w takes its `dead` once its section returns");
}

/// Instances stuck in a section do not take the time of the healthy ones stopped
/// after them: `b` and `c` (declared after `a`, so sent `dead` first) hang, and each
/// waits at most its share of the compound's stop budget, so `a`'s slow `stop` hook
/// (a motor braking, 300 ms) has returned when the system's shutdown returns.
#[test]
fn a_healthy_instance_stops_before_a_shutdown_returns_though_others_are_stuck() {
    let mut rig = Base::new(|parts| cmp_trio::component("base", parts));
    let (sa, sb, sc) = (rig.script("a"), rig.script("b"), rig.script("c"));
    let (tap, feed) = Tap::new();
    rig.rig.add(feeder::component("f", tap));
    rig.rig.connect("f.kick", "base.b_kick");
    rig.rig.connect("f.kick", "base.c_kick");
    rig.rig.run();
    let feed = feed.recv_timeout(WAIT).expect("the feeder started");
    let (a, b, c) = (
        rig.rig.instance("a"),
        rig.rig.instance("b"),
        rig.rig.instance("c"),
    );
    for instance in [&a, &b, &c] {
        wait_user(instance, "idle");
    }
    let rb = sb.hang_in("busy.periodic");
    let rc = sc.hang_in("busy.periodic");
    feed.kick.emit();
    eventually(
        || sb.hanging.load(Ordering::SeqCst) && sc.hanging.load(Ordering::SeqCst),
        "b and c hang",
    );
    // `a`'s `stop` takes a while: released 300 ms after it began.
    let ra = sa.hang_in("stop");
    let braking = {
        let sa = Arc::clone(&sa);
        std::thread::spawn(move || {
            eventually(|| sa.hanging.load(Ordering::SeqCst), "a's stop began");
            std::thread::sleep(Duration::from_millis(300));
            drop(ra);
        })
    };
    let report = rig.rig.shutdown();
    let a_stopped = sa.returned.load(Ordering::SeqCst) == 1;
    braking.join().expect("the brake thread");
    drop((rb, rc));
    assert!(
        a_stopped,
        "a still in its stop hook when shutdown returned: {report:?}"
    );
    let compound = &report.components[0];
    assert!(compound.joined, "{report:?}");
    assert_eq!(compound.unjoined_instances, ["b", "c"], "{report:?}");
}

/// Three levels (`top` > `mid` > `leaf1`, `leaf2`, beside `sibling`), every worker stuck
/// in a section: each level gives up at the end of its own stop budget, and the
/// system's shutdown joins `top`, its report naming the three.
#[test]
fn a_system_shutdown_joins_a_top_compound_whose_leaves_are_stuck_two_levels_down() {
    let mut rig = Base::new(|parts| cmp_top::component("top", parts));
    let (s1, s2, sib) = (
        rig.script("leaf1"),
        rig.script("leaf2"),
        rig.script("sibling"),
    );
    let (tap, kicker) = Tap::new();
    rig.rig.add(feeder::component("kicker", tap));
    rig.rig.connect("kicker.kick", "top.sibling_kick");
    rig.rig.run();
    let kicker = kicker.recv_timeout(WAIT).expect("the kicker started");
    let feed = rig.feeder();
    for path in ["mid.leaf1", "mid.leaf2", "sibling"] {
        wait_user(&rig.rig.instance(path), "idle");
    }
    let releases = [
        s1.hang_in("busy.periodic"),
        s2.hang_in("busy.periodic"),
        sib.hang_in("busy.periodic"),
    ];
    feed.kick.emit();
    feed.data.send(1);
    kicker.kick.emit();
    eventually(
        || {
            [&s1, &s2, &sib]
                .iter()
                .all(|s| s.hanging.load(Ordering::SeqCst))
        },
        "all hang",
    );
    let report = rig.rig.shutdown();
    drop(releases);
    let top = report
        .components
        .iter()
        .find(|c| c.name == "top")
        .expect("top in the report");
    assert!(top.joined, "{report:?}");
    let mut unjoined = top.unjoined_instances.clone();
    unjoined.sort();
    assert!(
        ["mid.leaf1", "mid.leaf2", "sibling"]
            .iter()
            .all(|path| unjoined.iter().any(|u| u == path)),
        "{report:?}"
    );
}

#[test]
fn an_instance_stuck_longer_than_the_recovery_deadline_is_propagated() {
    let (rig, base, w, script, feed) = restarting(true);
    wait_user(&w, "idle");
    let release = script.hang_in("busy.periodic");
    feed.kick.emit();
    let monitor = wait(&base, State::RunningError);
    let error = monitor.error.expect("error");
    assert!(
        error.contains("instance `w` cannot be restarted: it is stuck"),
        "{error}"
    );
    assert!(w.is_stuck());
    drop(release);
    w.wait_for(|_| !w.is_stuck(), WAIT).expect("returned");
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn restart_stops_at_the_budget_and_the_fault_propagates() {
    let (rig, base, w, script) = {
        // w fails in its first entry at every run.
        let mut rig = Base::new(|parts| cmp_budget::component("base", parts));
        let script = rig.script("w");
        script.inject(Some(Injected {
            hook: "idle.entry",
            exception: Some(worker::Exception::Fatal),
            times: 1000,
        }));
        rig.rig.start();
        let (base, w) = (rig.rig.compound.clone(), rig.rig.instance("w"));
        wait(&base, State::Ready);
        (rig, base, w, script)
    };
    base.command(Command::SetState(Controllable::Running))
        .expect("running");
    let monitor = wait(&base, State::RunningError);
    let error = monitor.error.expect("error");
    assert!(
        error.contains(
            "instance `w` failed again after 3 restart(s) within 60s (restart budget spent)"
        ) && error.contains("exception `fatal`"),
        "{error}"
    );
    assert_eq!(starts(&script), 4, "the first run and three restarts");
    let steps: Vec<_> = monitor
        .supervision
        .iter()
        .map(|s| (s.step.clone(), s.detail.starts_with("restart budget spent")))
        .filter(|(step, _)| *step != Step::Failed)
        .collect();
    assert_eq!(
        steps,
        [
            (Step::Restarted, false),
            (Step::Restarted, false),
            (Step::Restarted, false),
            (Step::Propagated, true)
        ],
        "{:?}",
        monitor.supervision
    );
    assert_eq!(script.injected.load(Ordering::SeqCst), 4);
    assert_eq!(w.state(), State::RunningError);
    // The budget starts afresh when the compound is restarted.
    script.inject(None);
    base.command(Command::SetState(Controllable::Running))
        .expect("restart the compound");
    wait_user(&w, "idle");
    assert_eq!(base.state(), State::Running);
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn ignore_leaves_the_instance_in_running_error_where_rules_see_it() {
    let mut rig = Base::new(|parts| cmp_ignore::component("base", parts));
    let script = rig.script("w");
    rig.rig.run();
    let feed = rig.feeder();
    let (base, w) = (rig.rig.compound.clone(), rig.rig.instance("w"));
    wait_user(&w, "idle");
    periodic_fault(&script);
    feed.kick.emit();
    wait_user(&base, "degraded");
    assert_eq!(base.state(), State::Running);
    assert_eq!(w.state(), State::RunningError, "nobody restarted it");
    assert_eq!(starts(&script), 1);
    wait_log(&rig.log, &["operating.Entry", "degraded.Entry"]);
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn without_a_substitute_the_recovery_queue_restarts_the_instance_until_it_recovers() {
    // The substitute policy without a substitute (the recovery queue alone) is the
    // runtime's, not the language's: it is set on the builder.
    let mut rig = Base::new(|parts| {
        cmp_lone::builder("base", parts)?
            .connect("f.kick", "w.kick")
            .connect("f.data", "w.data")
            .on_error("w", Policy::Substitute)
            .recovery(Duration::from_millis(20), Duration::from_secs(30))
            .build()
    });
    let script = rig.script("w");
    rig.rig.run();
    let feed = rig.feeder();
    let (base, w) = (rig.rig.compound.clone(), rig.rig.instance("w"));
    wait_user(&w, "idle");
    // w fails and cannot start again for a while: the queue keeps retrying it.
    script.start_fails.store(true, Ordering::SeqCst);
    periodic_fault(&script);
    feed.kick.emit();
    w.wait_state(State::StartingError, WAIT).expect("retried");
    assert_eq!(base.state(), State::Running, "the compound waits for it");
    // Packets sent meanwhile wait at w's input.
    feed.data.send(7);
    script.start_fails.store(false, Ordering::SeqCst);
    // The queued packet is an arrival in the initial state of the recovered instance:
    // it takes w to `busy`, whose entry reads it.
    wait_user(&w, "busy");
    eventually(
        || script.received.load(Ordering::SeqCst) == 1,
        "the queued packet reaches the recovered instance",
    );
    assert_eq!(base.state(), State::Running);
    assert!(rig.rig.shutdown().clean());
}

/// A stall check for soak loops: fails only when a counter has not moved for `WAIT`.
struct Progress {
    last: Option<usize>,
    since: std::time::Instant,
}

impl Progress {
    fn new() -> Progress {
        Progress {
            last: None,
            since: std::time::Instant::now(),
        }
    }

    /// Whether `count` moved within the last `WAIT`.
    fn check(&mut self, count: usize) -> bool {
        if self.last != Some(count) {
            self.last = Some(count);
            self.since = std::time::Instant::now();
        }
        self.since.elapsed() < WAIT
    }
}

#[test]
fn exported_ports_follow_the_substitute_and_no_packet_is_lost() {
    let (hand, source) = crossbeam_channel::bounded(1);
    let compound = |parts| {
        let base = cmp_exported::component("base", ExportedParts(parts, Some(Source(hand))))?;
        assert_eq!(base.spec().inputs.len(), 2);
        assert_eq!(base.spec().outputs[0].name, "scan");
        Ok(base)
    };
    let mut rig = Base::new(compound);
    let (w_script, b_script) = (rig.script("w"), rig.script("b"));

    // Outside: a feeder into the compound's inputs, a sink on its output.
    let (tap, feed) = Tap::new();
    rig.rig.add(feeder::component("f", tap));
    let (hand, scans) = crossbeam_channel::bounded(1);
    rig.rig.add(cmp_scan_sink::component("sink", Sink(hand)));
    rig.rig.connect("f.data", "base.data");
    rig.rig.connect("f.kick", "base.kick");
    rig.rig.connect("base.scan", "sink.scans");
    rig.rig.start();
    let (base, w, b) = (
        rig.rig.compound.clone(),
        rig.rig.instance("w"),
        rig.rig.instance("b"),
    );
    wait(&base, State::Ready);
    let feed = feed.recv_timeout(WAIT).expect("the feeder started");
    let scans = scans.recv_timeout(WAIT).expect("the sink started");

    // While the compound is ready, packets wait at its own input.
    for packet in 0..5 {
        feed.data.send(packet);
    }
    rig.rig.run();
    eventually(
        || w_script.received.load(Ordering::SeqCst) == 5,
        "queued packets reach w once the compound runs",
    );
    let source = source.recv_timeout(WAIT).expect("the source started");
    source.send(42);
    assert_eq!(scans.recv_timeout(WAIT), Some(42), "the exported output");

    // A steady stream while w fails and b takes over.
    w_script.start_fails.store(true, Ordering::SeqCst);
    w_script.panic_in(Some("busy.periodic"));
    feed.kick.emit();
    let sent = 300;
    for packet in 5..sent {
        feed.data.send(packet);
        if packet % 10 == 0 {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    wait(&b, State::Running);
    eventually(
        || {
            w_script.received.load(Ordering::SeqCst) + b_script.received.load(Ordering::SeqCst)
                == sent
        },
        "every packet reached w or b",
    );
    assert!(b_script.received.load(Ordering::SeqCst) > 0);
    for handle in [&base, &w, &b] {
        assert_eq!(handle.snapshot().overflows, 0, "{}", handle.name());
    }
    assert_eq!(base.state(), State::Running);
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn soak_ten_thousand_injected_faults_restarted_while_a_stream_goes_on() {
    const FAULTS: u32 = 10_000;
    // Every fault is restarted: no budget, no backoff (a zero backoff is the
    // runtime's, not the language's: set on the builder).
    let mut rig = Base::new(|parts| {
        cmp_soak::builder("base", parts)?
            .restart_budget(u32::MAX, Duration::from_secs(1))
            .restart_backoff(Duration::ZERO, Duration::ZERO)
            .build()
    });
    let (flaky_script, steady_script) = (rig.script("flaky"), rig.script("steady"));
    // Every run of `flaky` fails in its first entry, alternately by a declared
    // exception and by a panic, until the faults are used up.
    flaky_script.inject(Some(Injected {
        hook: "idle.entry",
        exception: Some(worker::Exception::Fatal),
        times: FAULTS / 2,
    }));
    rig.rig.run();
    let feed = rig.feeder();
    let (base, flaky, steady) = (
        rig.rig.compound.clone(),
        rig.rig.instance("flaky"),
        rig.rig.instance("steady"),
    );
    let mut sent = 0;
    // No overall time limit (the machine may be loaded): each phase fails only if it
    // makes no progress for `WAIT`.
    let stalled = |phase: &str| {
        format!(
            "{phase} stalled for {WAIT:?}: {:?} {:?}",
            base.snapshot(),
            flaky.snapshot()
        )
    };
    let mut progress = Progress::new();
    // Panics first (a panic comes before the injected exception in the script).
    flaky_script.panic_in(Some("idle.entry"));
    loop {
        let starts = flaky_script.log().iter().filter(|e| *e == "start").count();
        if starts > usize::try_from(FAULTS / 2).unwrap() {
            break;
        }
        assert!(progress.check(starts), "{}", stalled("panics"));
        feed.data.send(sent);
        sent += 1;
        std::thread::sleep(Duration::from_micros(200));
    }
    flaky_script.panic_in(None);
    // Then the declared exceptions, until they are used up.
    let mut progress = Progress::new();
    loop {
        let injected = flaky_script.injected.load(Ordering::SeqCst);
        if injected >= FAULTS / 2 {
            break;
        }
        assert!(
            progress.check(usize::try_from(injected).unwrap()),
            "{}",
            stalled("exceptions")
        );
        feed.data.send(sent);
        sent += 1;
        std::thread::sleep(Duration::from_micros(200));
    }
    wait_user(&flaky, "idle");
    assert_eq!(base.state(), State::Running);
    eventually(
        || steady_script.received.load(Ordering::SeqCst) == sent,
        "every packet of the stream arrived",
    );
    assert_eq!(steady.snapshot().overflows, 0);
    assert_eq!(steady.state(), State::Running);
    let report = rig.rig.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn soak_substitution_cycles_lose_no_packet_on_the_exported_input() {
    const CYCLES: usize = 200;
    let mut rig = Base::new(|parts| cmp_cycles::component("base", parts));
    let (w_script, b_script) = (rig.script("w"), rig.script("b"));
    let feed = rig.run_fed(&[("data", "data")]);
    let (base, w, b) = (
        rig.rig.compound.clone(),
        rig.rig.instance("w"),
        rig.rig.instance("b"),
    );
    wait_user(&w, "idle");
    let mut sent = 0u64;
    for cycle in 0..CYCLES {
        // w fails in its next periodic section (half panics, half declared exceptions)
        // while the stream goes on; b takes over; the queue restarts w, and once it
        // runs on, w takes the stream back. (The restart can be quick: w's failure is
        // seen through its script, not through a state that may last a millisecond.)
        let starts_before = starts(&w_script);
        // In the first cycle w cannot restart until b has had some of the stream
        // (otherwise, on a loaded machine, w may be back before any packet goes out).
        w_script.start_fails.store(cycle == 0, Ordering::SeqCst);
        if cycle % 2 == 0 {
            w_script.panic_in(Some("busy.periodic"));
        } else {
            w_script.inject(Some(Injected {
                hook: "busy.periodic",
                exception: Some(worker::Exception::Fatal),
                times: 1,
            }));
        }
        for _ in 0..5 {
            feed.data.send(sent);
            sent += 1;
        }
        eventually(
            || starts(&w_script) > starts_before,
            &format!("cycle {cycle}: w failed and was restarted"),
        );
        w_script.panic_in(None);
        for _ in 0..5 {
            feed.data.send(sent);
            sent += 1;
        }
        if cycle == 0 {
            eventually(
                || b_script.received.load(Ordering::SeqCst) > 0,
                "b has some of the stream",
            );
            w_script.start_fails.store(false, Ordering::SeqCst);
        }
        // Recovered: b back on standby, w running with the stream.
        b.wait_state(State::Ready, WAIT)
            .unwrap_or_else(|t| panic!("cycle {cycle}: {t}"));
        w.wait_state(State::Running, WAIT)
            .unwrap_or_else(|t| panic!("cycle {cycle}: {t}"));
        assert_eq!(base.state(), State::Running, "cycle {cycle}");
    }
    // Every packet reached w or b, or is counted as lost at an input.
    let lost = || base.snapshot().overflows + w.snapshot().overflows + b.snapshot().overflows;
    eventually(
        || {
            w_script.received.load(Ordering::SeqCst)
                + b_script.received.load(Ordering::SeqCst)
                + lost()
                == sent
        },
        "every packet delivered or counted",
    );
    assert_eq!(lost(), 0, "deep queues: nothing overflowed");
    assert!(b_script.received.load(Ordering::SeqCst) > 0);
    assert!(w_script.log().iter().filter(|e| *e == "start").count() > CYCLES);
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn overruns_are_handled_in_the_middle_or_propagated_to_the_top_of_three_levels() {
    // mid: leaf1 (substitute: spare), leaf2 (propagate), both with a 500 ms
    // max_response, fed by f (`CmpOverMid`, inside `CmpOverTop`).
    let mut rig = Base::new(|parts| cmp_over_top::component("top", parts));
    let (script1, script2) = (rig.script("leaf1"), rig.script("leaf2"));
    rig.rig.run();
    let feed = rig.feeder();
    let top = rig.rig.compound.clone();
    let (mid, leaf1, spare, leaf2) = (
        rig.rig.instance("mid"),
        rig.rig.instance("mid.leaf1"),
        rig.rig.instance("mid.spare"),
        rig.rig.instance("mid.leaf2"),
    );
    wait_user(&leaf1, "idle");
    wait_user(&leaf2, "idle");

    // leaf1 hangs: the middle substitutes it; the top does not notice.
    let release1 = script1.hang_in("busy.periodic");
    feed.kick.emit();
    wait(&spare, State::Running);
    assert!(leaf1.is_stuck());
    assert_eq!(mid.state(), State::Running);
    assert_eq!(top.state(), State::Running);

    // leaf2 hangs: the middle propagates, the top fails with the whole chain named.
    let release2 = script2.hang_in("busy.periodic");
    feed.data.send(1);
    let monitor = wait(&top, State::RunningError);
    let error = monitor.error.expect("error");
    assert!(
        error.contains("instance `mid` failed")
            && error.contains("instance `leaf2` failed")
            && error.contains("still running after"),
        "{error}"
    );
    assert!(leaf2.is_stuck());
    drop(release1);
    drop(release2);
    for (handle, script) in [(&leaf1, &script1), (&leaf2, &script2)] {
        eventually(
            || !handle.is_stuck() && script.returned.load(Ordering::SeqCst) == 1,
            "the sections returned",
        );
    }
    // Restarted from the top once the sections returned, the whole hierarchy runs.
    run(&top, Controllable::Running);
    wait_user(&leaf2, "idle");
    assert_eq!(mid.state(), State::Running);
    assert_eq!(leaf1.state(), State::Running);
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn a_rule_that_already_holds_when_its_state_is_entered_fires_without_another_event() {
    let mut rig = Base::new(|parts| cmp_already::component("base", parts));
    rig.rig.run();
    let (base, w) = (rig.rig.compound.clone(), rig.rig.instance("w"));
    wait_user(&w, "idle");
    let events = w.subscribe();
    run(&w, Controllable::Suspended);
    wait_user(&base, "third");
    wait_log(&rig.log, &["first.Entry", "second.Entry", "third.Entry"]);
    assert_eq!(
        events.try_iter().collect::<Vec<_>>(),
        [MonitorEvent::State {
            from: State::Running,
            to: State::Suspended
        }],
        "the only event w published"
    );
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn a_connection_through_a_converter_converts_inside_a_compound() {
    let (hand, text) = crossbeam_channel::bounded(1);
    let mut rig = Base::new(|parts| {
        cmp_converted::component::<Convert>("base", TextParts(parts, Some(TextSink(hand))))
    });
    rig.rig.run();
    let feed = rig.feeder();
    let text = text.recv_timeout(WAIT).expect("the sink started");
    wait(&rig.rig.compound, State::Running);
    feed.data.send(7);
    feed.data.send(8);
    assert_eq!(text.recv_timeout(WAIT).as_deref(), Some("#7"));
    assert_eq!(text.recv_timeout(WAIT).as_deref(), Some("#8"));
    assert!(rig.rig.shutdown().clean());

    // A converter whose types do not fit the ports (which coolc refuses): the
    // compound fails to start, and says why.
    let (hand, _text) = crossbeam_channel::bounded(1);
    let mut rig = Base::new(|parts| {
        cmp_unconverted::builder("base", TextParts(parts, Some(TextSink(hand))))?
            .connect_via::<u32, String>("f.data", "sink.text", |n| n.to_string())
            .build()
    });
    rig.rig.system.start().expect("start");
    let monitor = wait(&rig.rig.compound, State::StartingError);
    assert!(
        monitor
            .error
            .as_deref()
            .unwrap_or_default()
            .contains("converter"),
        "{monitor:?}"
    );
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn a_converter_between_equal_types_is_applied_and_follows_the_substitute() {
    let calls = &COPIES;
    let mut rig = Base::new(|parts| cmp_converted_substitute::component::<Convert>("base", parts));
    let (w_script, b_script) = (rig.script("w"), rig.script("b"));
    rig.rig.run();
    let feed = rig.feeder();
    let (base, w, b) = (
        rig.rig.compound.clone(),
        rig.rig.instance("w"),
        rig.rig.instance("b"),
    );
    wait_user(&w, "idle");
    feed.data.send(1);
    eventually(
        || w_script.received.load(Ordering::SeqCst) == 1,
        "w receives through the converter",
    );
    assert_eq!(calls.load(Ordering::SeqCst), 1, "the converter ran");

    // w fails: the converted connection moves to b, converter included.
    w_script.start_fails.store(true, Ordering::SeqCst);
    w_script.panic_in(Some("busy.periodic"));
    feed.kick.emit();
    b.wait_for(
        |m| m.state == State::Running && m.user_state.is_some(),
        WAIT,
    )
    .unwrap_or_else(|t| panic!("{t}"));
    feed.data.send(2);
    feed.data.send(3);
    eventually(
        || b_script.received.load(Ordering::SeqCst) == 2,
        "b receives through the converter",
    );
    assert_eq!(calls.load(Ordering::SeqCst), 3);

    // w recovers: back to w, still converted.
    w_script.panic_in(None);
    w_script.start_fails.store(false, Ordering::SeqCst);
    wait(&b, State::Ready);
    let before = w_script.received.load(Ordering::SeqCst);
    feed.data.send(4);
    eventually(
        || w_script.received.load(Ordering::SeqCst) == before + 1,
        "w receives again",
    );
    assert_eq!(calls.load(Ordering::SeqCst), 4);
    assert_eq!(b_script.received.load(Ordering::SeqCst), 2);
    assert_eq!(base.state(), State::Running);
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn a_rule_reading_what_a_section_changed_is_evaluated_after_the_section() {
    // `when count > 3 -> stopped;` reads only the local `count`, which nothing but
    // the periodic section changes.
    let mut rig = Base::new(|parts| cmp_counting::component("base", CounterParts(parts)));
    rig.rig.run();
    let base = rig.rig.compound.clone();
    wait_user(&base, "stopped");
    assert_eq!(base.state(), State::Running);
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn a_supervisor_periodic_section_without_a_period_runs_at_the_default_supervision_period() {
    let mut rig = Base::new(|parts| {
        let component = cmp_counting_untimed::component("base", CounterParts(parts))?;
        assert_eq!(
            component.spec().timing.period,
            Some(coolbot::compound::DEFAULT_SUPERVISION_PERIOD)
        );
        Ok(component)
    });
    rig.rig.run();
    wait_user(&rig.rig.compound, "stopped");
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn substitution_chains_are_refused_in_either_order_and_interfaces_compare_by_name() {
    // coolc refuses these arrangements too (`check::arrangement`): the runtime's
    // builder is given them on `CmpTrio` (workers `a`, `b`, `c`).
    let build = |f: fn(CompoundBuilder) -> CompoundBuilder| {
        f(cmp_trio::builder("base", Parts::new()).expect("builder")).build()
    };
    for chain in [
        build(|b| b.substitute("b", "a").substitute("c", "b")),
        build(|b| b.substitute("c", "b").substitute("b", "a")),
        build(|b| b.substitute("b", "a").substitute("c", "a")),
    ] {
        let error = chain.expect_err("a chain or two substitutes");
        assert!(error.to_string().contains("one substitute"), "{error}");
    }
    // A substitute whose data fifo is deeper: the same interface.
    cmp_deep_substitute::component("base", DeepParts(Parts::new()))
        .expect("queue sizes may differ");
}

#[test]
fn rules_are_evaluated_on_entering_a_state_reached_by_after() {
    let mut rig = Base::new(|parts| cmp_stepping::component("base", parts));
    rig.rig.run();
    let (base, w) = (rig.rig.compound.clone(), rig.rig.instance("w"));
    // w runs long before `second` is entered: no change of w announces anything
    // there; entering the state is what makes its rule evaluated.
    wait_user(&w, "idle");
    wait_user(&base, "fired");
    assert_eq!(base.state(), State::Running);
    assert!(rig.rig.shutdown().clean());
}

/// The steps of `monitor` about `instance`, with their details.
fn steps_of(monitor: &coolbot::Monitor, instance: &str) -> Vec<(Step, String)> {
    monitor
        .supervision
        .iter()
        .filter(|s| s.instance == instance)
        .map(|s| (s.step.clone(), s.detail.clone()))
        .collect()
}

#[test]
fn a_fault_is_handled_once_though_the_watchdog_trips_it_before_the_section_returns() {
    let mut rig = Base::new(|parts| {
        cmp_watchdog::builder("base", parts)?
            // Fires once the compound has seen the section return (the second event of
            // the same fault).
            .rule("operating", "degraded", &["w.error"], |v| {
                v.error("w").is_some_and(|e| e.ends_with("discarded"))
            })
            .build()
    });
    let script = rig.script("w");
    rig.rig.run();
    let feed = rig.feeder();
    let (base, w) = (rig.rig.compound.clone(), rig.rig.instance("w"));
    wait_user(&w, "idle");
    let release = script.hang_in("busy.periodic");
    feed.kick.emit();
    wait(&w, State::RunningError);
    assert!(w.is_stuck());
    drop(release);
    let monitor = wait_user(&base, "degraded");
    let steps: Vec<Step> = steps_of(&monitor, "w")
        .into_iter()
        .map(|(s, _)| s)
        .collect();
    assert_eq!(steps, [Step::Failed, Step::Ignored]);
    assert_eq!(w.state(), State::RunningError);
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn a_failed_member_that_did_not_lead_its_redundant_group_is_not_substituted() {
    let mut rig = Base::new(|parts| cmp_pair::component("base", parts));
    let b_script = rig.script("b");
    rig.rig.run();
    let feed = rig.feeder();
    let (base, a, b) = (
        rig.rig.compound.clone(),
        rig.rig.instance("a"),
        rig.rig.instance("b"),
    );
    wait_user(&a, "idle");
    wait_user(&b, "idle");
    // b (not the leader: a has the connections) fails in its entry, commanded
    // through its own port.
    b_script.start_fails.store(true, Ordering::SeqCst);
    b_script.panic_in(Some("idle.entry"));
    run(&b, Controllable::Ready);
    run(&b, Controllable::Running);
    let monitor = base
        .wait_for(
            |m| {
                m.supervision
                    .iter()
                    .any(|s| s.instance == "b" && s.step == Step::Enqueued)
            },
            WAIT,
        )
        .unwrap_or_else(|t| panic!("{t}"));
    let steps: Vec<Step> = steps_of(&monitor, "b")
        .into_iter()
        .map(|(s, _)| s)
        .collect();
    assert_eq!(steps, [Step::Failed, Step::Enqueued]);
    // a keeps the stream.
    feed.kick.emit();
    wait_user(&a, "busy");
    assert_eq!(base.state(), State::Running);
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn a_substitution_that_cannot_be_done_is_recorded_as_propagated_with_the_reason() {
    let mut rig = Base::new(|parts| cmp_gone::component("base", parts));
    let w_script = rig.script("w");
    rig.rig.run();
    let feed = rig.feeder();
    let (base, w, b) = (
        rig.rig.compound.clone(),
        rig.rig.instance("w"),
        rig.rig.instance("b"),
    );
    wait_user(&w, "idle");
    // The substitute is gone (killed through its own port): it cannot run.
    run(&b, Controllable::Dead);
    w_script.start_fails.store(true, Ordering::SeqCst);
    w_script.panic_in(Some("busy.periodic"));
    feed.kick.emit();
    let monitor = wait(&base, State::RunningError);
    let steps = steps_of(&monitor, "w");
    let kinds: Vec<Step> = steps.iter().map(|(s, _)| s.clone()).collect();
    assert_eq!(kinds, [Step::Failed, Step::Enqueued, Step::Propagated]);
    let reason = &steps[2].1;
    assert!(
        reason.contains("`b` rejected SetState(Running)"),
        "{reason}"
    );
    assert_eq!(monitor.error.as_deref(), Some(reason.as_str()));
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn a_rule_reading_an_instance_quality_is_evaluated_when_it_changes() {
    let mut rig = Base::new(|parts| cmp_quality::component("base", parts));
    rig.rig.run();
    let (base, w) = (rig.rig.compound.clone(), rig.rig.instance("w"));
    wait_user(&w, "idle");
    wait_log(&rig.log, &["operating.Entry"]);
    w.command(Command::SetQuality(1)).expect("quality");
    wait_user(&base, "degraded");
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn packets_moved_to_a_standby_substitute_are_handled_in_its_initial_state() {
    let mut rig = Base::new(|parts| cmp_standby::component("base", parts));
    let (w_script, b_script) = (rig.script("w"), rig.script("b"));
    rig.rig.run();
    let feed = rig.feeder();
    let (base, w, b) = (
        rig.rig.compound.clone(),
        rig.rig.instance("w"),
        rig.rig.instance("b"),
    );
    wait_user(&w, "idle");
    // w hangs in a section: packets queue at its input, unread.
    let release = w_script.hang_in("busy.periodic");
    feed.kick.emit();
    eventually(
        || w_script.hanging.load(Ordering::SeqCst),
        "w hangs in its section",
    );
    for packet in 0..3 {
        feed.data.send(packet);
    }
    // The watchdog fails w; b takes over with the three packets, which fire its
    // `on data` with nothing sent after them.
    eventually(
        || b_script.received.load(Ordering::SeqCst) == 3,
        "the substitute handled the packets moved to it",
    );
    assert_eq!(w_script.received.load(Ordering::SeqCst), 0);
    assert_eq!(b.snapshot().user_state.as_deref(), Some("busy"));
    drop(release);
    assert!(rig.rig.shutdown().clean());
    assert_eq!(base.snapshot().overflows, 0);
}

#[test]
fn soak_substitution_cycles_lose_no_packet_on_a_converted_connection() {
    const CYCLES: usize = 60;
    let mut rig = Base::new(|parts| cmp_converted_cycles::component::<Convert>("base", parts));
    let (w_script, b_script) = (rig.script("w"), rig.script("b"));
    rig.rig.run();
    let feed = rig.feeder();
    let (w, b) = (rig.rig.instance("w"), rig.rig.instance("b"));
    wait_user(&w, "idle");
    // A stream from another thread, through the converter, all along.
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let sender = {
        let stop = Arc::clone(&stop);
        let data = feed.data.clone();
        std::thread::spawn(move || {
            let mut sent = 0u64;
            while !stop.load(Ordering::SeqCst) {
                data.send(sent);
                sent += 1;
                if sent.is_multiple_of(4) {
                    std::thread::sleep(Duration::from_millis(1));
                }
            }
            sent
        })
    };
    for cycle in 0..CYCLES {
        let starts_before = starts(&w_script);
        // In the first cycle w cannot restart until b has had some of the stream.
        w_script.start_fails.store(cycle == 0, Ordering::SeqCst);
        w_script.inject(Some(Injected {
            hook: "busy.periodic",
            exception: Some(worker::Exception::Fatal),
            times: 1,
        }));
        eventually(
            || starts(&w_script) > starts_before,
            &format!("cycle {cycle}: w failed and was restarted"),
        );
        if cycle == 0 {
            eventually(
                || b_script.received.load(Ordering::SeqCst) > 0,
                "b has some of the stream",
            );
            w_script.start_fails.store(false, Ordering::SeqCst);
        }
        b.wait_state(State::Ready, WAIT)
            .unwrap_or_else(|t| panic!("cycle {cycle}: {t}"));
        w.wait_state(State::Running, WAIT)
            .unwrap_or_else(|t| panic!("cycle {cycle}: {t}"));
    }
    stop.store(true, Ordering::SeqCst);
    let sent = sender.join().expect("sender");
    let lost = || w.snapshot().overflows + b.snapshot().overflows;
    eventually(
        || {
            w_script.received.load(Ordering::SeqCst)
                + b_script.received.load(Ordering::SeqCst)
                + lost()
                == sent
        },
        "every packet delivered or counted",
    );
    // (A consumer starved long enough on a loaded machine may overflow its deep
    // queue: such packets are counted above, never lost silently.)
    assert!(b_script.received.load(Ordering::SeqCst) > 0);
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn packets_left_at_a_retired_instance_are_counted_as_lost() {
    // The substitute policy without a substitute is the runtime's: set on the builder
    // of `CmpLone` (whose `w` has the worker's 500 ms `max_response`).
    let mut rig = Base::new(|parts| {
        cmp_lone::builder("base", parts)?
            .connect("f.kick", "w.kick")
            .connect("f.data", "w.data")
            .on_error("w", Policy::Substitute)
            .recovery(Duration::from_millis(20), Duration::from_millis(100))
            .build()
    });
    let script = rig.script("w");
    rig.rig.run();
    let feed = rig.feeder();
    let (base, w) = (rig.rig.compound.clone(), rig.rig.instance("w"));
    wait_user(&w, "idle");
    // w hangs: three packets queue at its input, unread, and nothing stands for it.
    let release = script.hang_in("busy.periodic");
    feed.kick.emit();
    eventually(|| script.hanging.load(Ordering::SeqCst), "w hangs");
    let events = w.subscribe();
    for packet in 0..3 {
        feed.data.send(packet);
    }
    let monitor = wait(&base, State::RunningError);
    let retired = monitor
        .supervision
        .iter()
        .find(|s| s.step == Step::Retired)
        .expect("w retired");
    assert!(
        retired
            .detail
            .ends_with("; 3 packet(s) left at its inputs lost"),
        "{retired:?}"
    );
    assert_eq!(w.snapshot().overflows, 3);
    let lost: u64 = events
        .try_iter()
        .filter_map(|event| match event {
            MonitorEvent::Overflow { lost, .. } => Some(lost),
            _ => None,
        })
        .sum();
    assert_eq!(lost, 3);
    drop(release);
    w.wait_for(|_| !w.is_stuck(), WAIT).expect("returned");
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn a_rule_reads_a_mapped_variable_at_the_instance_standing_in() {
    // `when count == 2 && w.count != count -> degraded;` (`CmpMappedRule`).
    let mut rig = Base::new(|parts| cmp_mapped_rule::component("base", parts));
    let w_script = rig.script("w");
    rig.rig.run();
    let feed = rig.feeder();
    let (base, w, b) = (
        rig.rig.compound.clone(),
        rig.rig.instance("w"),
        rig.rig.instance("b"),
    );
    wait_user(&w, "idle");
    w_script.start_fails.store(true, Ordering::SeqCst);
    w_script.panic_in(Some("busy.periodic"));
    feed.kick.emit();
    wait(&b, State::Running);
    feed.data.send(1);
    feed.data.send(2);
    let monitor = wait_user(&base, "degraded");
    assert_eq!(monitor.variables[0], ("count".to_owned(), Value::UInt(2)));
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn a_built_compound_reaches_its_nested_instances_by_path() {
    // top { mid { leaf (restart), f -> leaf }, sibling }, built whole: only the top
    // handle is kept.
    // (`CmpPathTop` around `CmpPathMid`: `when leaf.gain == 9 -> degraded;`.)
    let mut rig = Base::new(|parts| cmp_path_top::component("top", parts));
    let (script, mid_log) = (rig.script("leaf"), Arc::clone(&rig.log));
    rig.rig.run();
    let feed = rig.feeder();
    let top = rig.rig.compound.clone();

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
    let report = rig.rig.shutdown();
    assert!(report.clean(), "{report:?}");
    assert_eq!(leaf.state(), State::Dead);
    assert_eq!(mid.state(), State::Dead);
    assert!(
        leaf.command(Command::SetState(Controllable::Running))
            .is_err()
    );
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
/// then `p1`'s again, with or without a converter on the connection
/// (`CmpConvertedPosters`, `CmpPosters`).
fn a_poster_reader_follows_its_producer_through_substitution(converted: bool) {
    let p1_fails = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let never = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let (hand, r) = crossbeam_channel::bounded(1);
    let posting = |base, fail: &Arc<std::sync::atomic::AtomicBool>| Posting {
        base,
        posted: 0,
        fail: Arc::clone(fail),
    };
    let (p1, p2) = (posting(1_000_000, &p1_fails), posting(2_000_000, &never));
    let mut rig = Base::new(move |parts| {
        let parts = PosterParts {
            parts,
            p1: Some(p1),
            p2: Some(p2),
            c: Some(PosterHand(hand)),
        };
        if converted {
            cmp_converted_posters::component::<Convert>("base", parts)
        } else {
            cmp_posters::component("base", parts)
        }
    });
    let offset = if converted { 10 } else { 0 };
    rig.rig.run();
    let r = r.recv_timeout(WAIT).expect("the reader started");
    let (base, p1, p2) = (
        rig.rig.compound.clone(),
        rig.rig.instance("p1"),
        rig.rig.instance("p2"),
    );
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
    assert!(rig.rig.shutdown().clean());
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
    // suspended. (`CmpSuspendedTop` maps it as a controllable: the language maps a
    // variable as the kind it is.)
    let mut rig = Base::new(|parts| cmp_suspended_top::component("top", parts));
    rig.rig.run();
    let top = rig.rig.compound.clone();
    let base = rig.rig.instance("base");
    let a = rig.rig.instance("base.a");
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
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn a_fault_while_the_compound_is_suspended_is_handled_when_it_runs_again() {
    // `w` (restart policy) fails while `base` is suspended (commanded to run on its
    // own, then kicked into a panicking section): `base` observes it, and its policy
    // waits until `base` runs again, then restarts it.
    let mut rig = Base::new(|parts| cmp_suspended_fault::component("base", parts));
    let script = rig.script("w");
    rig.rig.run();
    let feed = rig.feeder();
    let (base, w) = (rig.rig.compound.clone(), rig.rig.instance("w"));
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
    assert!(rig.rig.shutdown().clean());
}

#[test]
fn forwarding_an_exported_input_never_waits_for_a_full_blocking_queue() {
    // `CmpForwarding`'s `w` is a `BlockingWorker`: its data fifo is 4 deep and blocks
    // its producer when full; its script hands its inputs to the test.
    let mut rig = Base::new(|parts| cmp_forwarding::component("base", parts));
    let script = rig.script("w");
    let feed = rig.run_fed(&[("data", "data"), ("kick", "kick")]);
    eventually(|| script.inputs.lock().unwrap().is_some(), "w started");
    let w_data = script.inputs().data;
    let (base, w) = (rig.rig.compound.clone(), rig.rig.instance("w"));
    wait_user(&w, "idle");
    // w hangs in a section: its blocking queue fills with four packets, and four more
    // wait at the compound's own input (also four deep).
    let release = script.hang_in("busy.periodic");
    feed.kick.emit();
    eventually(|| script.hanging.load(Ordering::SeqCst), "w hangs");
    for packet in 0..4 {
        feed.data.send(packet);
    }
    eventually(|| w_data.len() == 4, "w's queue is full");
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
    assert!(rig.rig.shutdown().clean());
}

/// On a virtual clock, packets held at an exported input (the instance's `Block` fifo
/// was full) move on as soon as the fifo has room, in real time, as any packet does:
/// the retry is no timer of the clock, so no advance is needed.
#[test]
fn on_a_virtual_clock_packets_held_at_an_exported_input_move_on_without_an_advance() {
    let mut rig = Base::on_virtual_clock(|parts| cmp_forwarding::component("base", parts));
    let script = rig.script("w");
    let feed = rig.run_fed(&[("data", "data"), ("kick", "kick")]);
    eventually(|| script.inputs.lock().unwrap().is_some(), "w started");
    let w_data = script.inputs().data;
    let (base, w) = (rig.rig.compound.clone(), rig.rig.instance("w"));
    wait_user(&w, "idle");
    // In `busy`, w reads its data only in its periodic section, which waits for the
    // clock: w's queue fills with four packets and four wait at the compound's input.
    feed.kick.emit();
    wait_user(&w, "busy");
    // `busy` is published before its entry section runs, and the entry drains the
    // queue too. Settling the clock would not wait for it (settling covers timers,
    // and w came to `busy` on a tick): a command does, which w's thread takes once
    // the turn that entered `busy` is over.
    w.command(Command::SetPriority(0))
        .expect("past busy's entry");
    let clock = rig.rig.clock.clone().expect("a virtual clock");
    for packet in 0..4 {
        feed.data.send(packet);
    }
    eventually(|| w_data.len() == 4, "w's queue is full");
    for packet in 4..8 {
        feed.data.send(packet);
    }
    // A command makes the compound busy on the clock until the end of the turn that
    // handles it, which tries to pass the four on (they came before the command);
    // settling waits for that turn: they wait at the compound's input.
    base.command(Command::SetPriority(0)).expect("sync");
    clock.settle().expect("settles");
    // The test empties w's queue, the clock standing still: the four waiting move on.
    assert_eq!(w_data.drain().collect::<Vec<_>>(), [0, 1, 2, 3]);
    eventually(|| w_data.len() == 4, "the held packets reach w");
    assert_eq!(w_data.drain().collect::<Vec<_>>(), [4, 5, 6, 7]);
    assert_eq!(w.snapshot().overflows, 0);
    assert_eq!(base.snapshot().overflows, 0);
    assert!(rig.rig.shutdown().clean());
}

/// The same on a virtual clock: the state entered by a rule asks for a turn at once
/// (`Compound::wake_at`'s `fresh`) at the clock's time, not at a real
/// `Instant::now()`, which would be later than the virtual time and leave the
/// compound settled and parked with the rule of `second` never evaluated.
#[test]
fn on_a_virtual_clock_a_rule_that_already_holds_when_its_state_is_entered_fires() {
    let mut parts = Parts::new();
    let log = Arc::clone(&parts.log);
    let _ = parts.feed.take();
    let mut rig = CompoundRig::on_virtual_clock(cmp_already::component("base", parts));
    rig.run();
    let clock = rig.clock.clone().expect("a virtual clock");
    let (base, w) = (rig.compound.clone(), rig.instance("w"));
    wait_user(&w, "idle");
    // Real time passes, as it does in any test, while the virtual clock stays at
    // zero: a turn asked for at a real instant would be later than the clock's now.
    std::thread::sleep(Duration::from_millis(20));
    run(&w, Controllable::Suspended);
    eventually(
        || log.lock().unwrap().iter().any(|l| l == "second.Entry"),
        "second entered",
    );
    clock.settle().expect("settles");
    assert_eq!(
        base.snapshot().user_state.as_deref(),
        Some("third"),
        "second's rule held when it was entered"
    );
    assert!(rig.shutdown().clean());
}

/// An instance retired at its recovery deadline while a retry's restart is still
/// under way (its `start` is slow) does not run on once the restart returns: its
/// pending retry is withdrawn and `dead` is posted without waiting, and taken as
/// soon as `start` returns (a `dead` waited for would be withdrawn as busy after its
/// timeout, and the retry's `running` would then complete).
#[test]
fn an_instance_retired_during_a_slow_restart_does_not_run_on() {
    let rig = substitution(true);
    let events = rig.base.subscribe();
    // The first retry's restart hangs in `start` past the deadline (200 ms) and the
    // `dead` command's timeout.
    let release = rig.w_script.hang_in("start");
    rig.w_script.panic_in(Some("busy.periodic"));
    rig.feed.kick.emit();
    wait(&rig.b, State::Running);
    rig.w_script.panic_in(None);
    let until = std::time::Instant::now() + WAIT;
    let mut events = std::iter::from_fn(|| events.recv_deadline(until).ok());
    assert!(
        events.any(|event| matches!(
            event,
            MonitorEvent::Supervision(step) if step.step == Step::Retired
        )),
        "w retired"
    );
    drop(release);
    // Once its `start` returns, w must not be left running outside the arrangement.
    let outcome = rig.w.wait_state(State::Dead, Duration::from_secs(3));
    assert!(
        outcome.is_ok(),
        "retired, yet w is {:?}",
        rig.w.snapshot().state
    );
    assert!(rig.rig.shutdown().clean());
}
