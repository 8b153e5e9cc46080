//! Supervisors control their instances (paper 3.4): a supervisor section commands an
//! instance through `SupervisorCx::instances` (state, variables, configuration,
//! period, quality), every command is answered (taken, or refused with a typed
//! reason), every command is a supervision step on the compound's monitoring port,
//! and a hung instance refuses within the commander's bound instead of holding the
//! compound. Rules read the compound's own `result` and times (the latter every
//! supervisor period), and a supervisor state's `may` lets its sections choose.

use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use coolbot::{
    Command, CommandError, Component, CompoundBuilder, Controllable, Handle, Refused, Section,
    SectionResult, State, Step, Supervisor, SupervisorCx, System, TaskResult, TimingSpec, Value,
};
use coolbot_runtime_tests::generated::{
    cell, choosing, commanding, fed_commanding, panicky, plant, watching, worker,
};
use coolbot_runtime_tests::support::{Release, Script, Scripted, Tap, WAIT, eventually};

/// The answers the supervisor's sections got, in order.
type Answers = Arc<Mutex<Vec<(String, Result<(), CommandError>)>>>;

/// The supervisor of `Commanding` (`cool/supervisor_commands.cool`: states
/// `operating`, `stopped`, `degraded`, `probing`, `strict`, each with an entry
/// section, and one own controllable variable `go`, an `i64`, that the test sets to
/// move it), written against the runtime's `coolbot::Supervisor` over the generated
/// `SPEC`: its sections command `w` by name through the untyped `Commander`, whose
/// refusals (an observable or unknown variable, a value of the wrong type, an
/// unknown instance, a quality out of range) the typed handles cannot provoke.
struct Commanding {
    go: i64,
    answers: Answers,
}

impl Supervisor for Commanding {
    fn spec(&self) -> &'static coolbot::Spec {
        &commanding::SPEC
    }

    fn section(
        &mut self,
        state: usize,
        section: Section,
        cx: &mut SupervisorCx<'_>,
    ) -> SectionResult {
        assert_eq!(section, Section::Entry);
        let answer = |what: &str, outcome: Result<(), CommandError>| {
            self.answers
                .lock()
                .unwrap()
                .push((what.to_owned(), outcome));
        };
        match commanding::UserState::ALL[state] {
            commanding::UserState::Stopped => {
                answer("suspend", cx.instances.state("w", Controllable::Suspended))
            }
            commanding::UserState::Degraded => {
                answer("gain", cx.instances.set("w", "gain", 5_i64));
                answer("count", cx.instances.set("w", "count", 1_u64));
                answer("speed", cx.instances.set("w", "speed", 1_i64));
                answer("bad gain", cx.instances.set("w", "gain", "fast"));
                answer("nobody", cx.instances.state("nobody", Controllable::Ready));
                answer(
                    "configure",
                    cx.instances.configure(
                        "w",
                        Value::from_serde(&worker::Config { scale: 7 }).unwrap(),
                    ),
                );
                answer(
                    "period",
                    cx.instances.set_period("w", Duration::from_millis(20)),
                );
                answer("zero period", cx.instances.set_period("w", Duration::ZERO));
                answer("quality", cx.instances.set_quality("w", 1));
                answer("quality 2", cx.instances.set_quality("w", 2));
            }
            commanding::UserState::Probing => {
                answer("run", cx.instances.state("w", Controllable::Running))
            }
            // A refusal given to `?` is the section's fault.
            commanding::UserState::Strict => cx.instances.set("w", "count", 1_u64)?,
            commanding::UserState::Operating => {}
        }
        Ok(())
    }

    fn get(&self, _variable: usize) -> Value {
        Value::from(self.go)
    }

    fn set(&mut self, _variable: usize, value: &Value) -> Result<(), coolbot::ValueRefused> {
        self.go = i64::try_from(value)?;
        Ok(())
    }
}

/// `Commanding`'s rules (the description's `when go == n -> ...`) as closures: a
/// hand-written supervisor gets none from the generated builder.
fn go_rules(builder: CompoundBuilder) -> CompoundBuilder {
    let go = |n: i64| move |view: &coolbot::View| view.own("go") == Some(&Value::from(n));
    [
        ("operating", "stopped", 1),
        ("operating", "degraded", 2),
        ("operating", "probing", 3),
        ("operating", "strict", 4),
        ("stopped", "operating", 0),
        ("degraded", "operating", 0),
        ("probing", "operating", 0),
    ]
    .into_iter()
    .fold(builder, |builder, (from, to, n)| {
        builder.rule(from, to, &["go"], go(n))
    })
}

/// `Commanding` over a generated `Worker` `w` (the returned component) following a
/// fresh script.
fn commanding(answers: &Answers, w: Component) -> CompoundBuilder {
    go_rules(CompoundBuilder::new(
        "base",
        Commanding {
            go: 0,
            answers: Arc::clone(answers),
        },
    ))
    .instance(w)
}

fn worker(name: &str) -> (Component, Arc<Script>) {
    let script = Script::new();
    let component = worker::component(name, Scripted::new(&script));
    (component, script)
}

/// `FedCommanding`'s supervisor: `stopped` suspends `w`, and the answer is logged.
struct Suspending {
    answers: Answers,
}

impl fed_commanding::Supervisor for Suspending {
    fn operating_entry(&mut self, _cx: &mut fed_commanding::Cx<'_>) -> SectionResult {
        Ok(())
    }

    fn stopped_entry(&mut self, cx: &mut fed_commanding::Cx<'_>) -> SectionResult {
        let outcome = cx.instances.w().suspend();
        self.answers
            .lock()
            .unwrap()
            .push(("suspend".to_owned(), outcome));
        Ok(())
    }
}

/// `FedCommanding` with `Suspending`, a scripted `w` and a tap for `f`.
struct FedParts {
    supervisor: Option<Suspending>,
    script: Arc<Script>,
    tap: Option<Tap>,
}

impl fed_commanding::Parts for FedParts {
    fn supervisor(&mut self) -> impl fed_commanding::Supervisor {
        self.supervisor.take().expect("one supervisor")
    }

    fn f(&mut self) -> impl coolbot_runtime_tests::generated::feeder::Behavior {
        self.tap.take().expect("one feeder")
    }

    fn w(&mut self) -> impl worker::Behavior {
        Scripted::new(&self.script)
    }
}

fn set_go(handle: &Handle, n: i64) {
    handle
        .command(Command::Set("go".to_owned(), Value::from(n)))
        .unwrap_or_else(|e| panic!("{e}"));
}

fn wait_user(handle: &Handle, user: &str) {
    handle
        .wait_for(|m| m.user_state.as_deref() == Some(user), WAIT)
        .unwrap_or_else(|t| panic!("{t}"));
}

/// Wait until the supervisor has `n` answers; return them.
fn answers(answers: &Answers, n: usize) -> Vec<(String, Result<(), CommandError>)> {
    eventually(
        || answers.lock().unwrap().len() >= n,
        &format!("the supervisor got {n} answers"),
    );
    answers.lock().unwrap().clone()
}

fn steps(monitor: &coolbot::Monitor) -> Vec<(Step, String)> {
    monitor
        .supervision
        .iter()
        .filter(|s| matches!(s.step, Step::Commanded { .. } | Step::CommandRefused { .. }))
        .map(|s| (s.step.clone(), s.detail.clone()))
        .collect()
}

fn reason(outcome: &Result<(), CommandError>) -> Option<&Refused> {
    outcome.as_ref().err().map(|e| &e.reason)
}

#[test]
fn a_supervisor_suspends_resumes_and_sets_its_instance_and_each_command_is_a_step() {
    let log: Answers = Arc::default();
    let (w, _script) = worker("w");
    let builder = commanding(&log, w);
    let w = builder.instance_handle("w").unwrap();
    let mut system = System::new();
    let base = system.add(builder.build().unwrap()).unwrap();
    system.run_all().unwrap();
    wait_user(&base, "operating");
    assert_eq!(w.state(), State::Running);

    // `stopped` suspends it, and the command is a step.
    set_go(&base, 1);
    let got = answers(&log, 1);
    assert_eq!(got[0], ("suspend".to_owned(), Ok(())));
    assert_eq!(
        w.state(),
        State::Suspended,
        "the transition has run when the command returns"
    );
    let monitor = base
        .wait_for(|m| !steps(m).is_empty(), WAIT)
        .unwrap_or_else(|t| panic!("{t}"));
    assert_eq!(
        steps(&monitor),
        [(
            Step::Commanded {
                command: "suspend".to_owned()
            },
            String::new()
        )]
    );
    assert_eq!(monitor.supervision.last().unwrap().instance, "w");

    // Back to `operating`, then `probing` runs it again.
    set_go(&base, 0);
    wait_user(&base, "operating");
    set_go(&base, 3);
    let got = answers(&log, 2);
    assert_eq!(got[1], ("run".to_owned(), Ok(())));
    assert_eq!(w.state(), State::Running);

    // `degraded`: variables, configuration, period, quality; taken or refused with
    // the reason.
    set_go(&base, 0);
    wait_user(&base, "operating");
    set_go(&base, 2);
    let got = answers(&log, 12);
    let by_name = |name: &str| &got.iter().find(|(n, _)| n == name).unwrap().1;
    assert_eq!(by_name("gain"), &Ok(()));
    assert_eq!(
        reason(by_name("count")),
        Some(&Refused::NotControllable("count".to_owned()))
    );
    assert_eq!(
        reason(by_name("speed")),
        Some(&Refused::UnknownVariable("speed".to_owned()))
    );
    assert!(
        matches!(reason(by_name("bad gain")), Some(Refused::InvalidValue(_))),
        "{:?}",
        by_name("bad gain")
    );
    assert_eq!(reason(by_name("nobody")), Some(&Refused::UnknownInstance));
    assert_eq!(by_name("configure"), &Ok(()));
    assert_eq!(by_name("period"), &Ok(()));
    assert_eq!(reason(by_name("zero period")), Some(&Refused::ZeroPeriod));
    assert_eq!(by_name("quality"), &Ok(()));
    assert_eq!(
        reason(by_name("quality 2")),
        Some(&Refused::QualityOutOfRange {
            level: 2,
            levels: 2
        })
    );
    // An error names the instance and the command, its source is the reason.
    let error = by_name("count").clone().unwrap_err();
    assert_eq!(error.instance, "w");
    assert_eq!(error.command, "set count = 1");
    assert!(std::error::Error::source(&error).is_some());

    let monitor = w.snapshot();
    assert_eq!(
        monitor
            .variables
            .iter()
            .find(|(n, _)| n == "gain")
            .unwrap()
            .1,
        Value::from(5_i64)
    );
    assert_eq!(monitor.period, Some(Duration::from_millis(20)));
    assert_eq!(monitor.quality, 1);

    // Every command is a step, taken or refused (with the reason as detail).
    let monitor = base
        .wait_for(|m| steps(m).len() >= 12, WAIT)
        .unwrap_or_else(|t| panic!("{t}"));
    let steps = steps(&monitor);
    assert_eq!(steps.len(), 12);
    assert!(steps.contains(&(
        Step::CommandRefused {
            command: "set count = 1".to_owned()
        },
        Refused::NotControllable("count".to_owned()).to_string()
    )));
    assert!(steps.contains(&(
        Step::Commanded {
            command: "set gain = 5".to_owned()
        },
        String::new()
    )));
    drop(system);
}

#[test]
fn a_refusal_passed_to_question_mark_takes_the_compound_to_running_error() {
    let (w, _script) = worker("w");
    let builder = commanding(&Answers::default(), w);
    let mut system = System::new();
    let base = system.add(builder.build().unwrap()).unwrap();
    system.run_all().unwrap();
    wait_user(&base, "operating");
    set_go(&base, 4);
    let monitor = base
        .wait_state(State::RunningError, WAIT)
        .unwrap_or_else(|t| panic!("{t}"));
    let error = monitor.error.unwrap_or_default();
    assert!(
        error.contains(
            "instance `w` did not take `set count = 1`: `count` is observable, not controllable"
        ),
        "{error}"
    );
    // The refusal is a step too.
    assert!(monitor.supervision.iter().any(|s| s.step
        == Step::CommandRefused {
            command: "set count = 1".to_owned()
        }));
    drop(system);
}

/// `base` (`FedCommanding` with `Suspending`, a 20 ms command timeout) running, its
/// instance `w` hung in its busy entry section until the returned release is
/// dropped.
struct Hung {
    system: System,
    base: Handle,
    w: Handle,
    log: Answers,
    script: Arc<Script>,
    release: Release,
}

fn hung_worker() -> Hung {
    let log: Answers = Arc::default();
    let script = Script::new();
    let (tap, feeder) = Tap::new();
    let builder = fed_commanding::builder(
        "base",
        FedParts {
            supervisor: Some(Suspending {
                answers: Arc::clone(&log),
            }),
            script: Arc::clone(&script),
            tap: Some(tap),
        },
    )
    .unwrap()
    .command_timeout(Duration::from_millis(20));
    let w = builder.instance_handle("w").unwrap();
    let mut system = System::new();
    let base = system.add(builder.build().unwrap()).unwrap();
    system.run_all().unwrap();
    wait_user(&base, "operating");
    let release = script.hang_in("busy.entry");
    feeder.recv_timeout(WAIT).unwrap().kick.emit();
    eventually(
        || script.hanging.load(Ordering::SeqCst),
        "the worker hangs in busy.entry",
    );
    Hung {
        system,
        base,
        w,
        log,
        script,
        release,
    }
}

#[test]
fn a_command_to_a_hung_instance_is_refused_within_the_bound() {
    let Hung {
        system,
        base,
        w,
        log,
        script,
        release,
    } = hung_worker();
    set_go(&base, 1);
    let got = answers(&log, 1);
    assert!(
        matches!(
            reason(&got[0].1),
            Some(Refused::Busy { .. } | Refused::Stuck)
        ),
        "{got:?}"
    );
    // The compound's thread is free: it answers its own control port and moves on.
    set_go(&base, 0);
    wait_user(&base, "operating");
    let monitor = base
        .wait_for(|m| !steps(m).is_empty(), WAIT)
        .unwrap_or_else(|t| panic!("{t}"));
    assert!(matches!(steps(&monitor)[0].0, Step::CommandRefused { .. }));
    // The withdrawn (or never given) command had no effect once the section returns.
    drop(release);
    eventually(
        || script.returned.load(Ordering::SeqCst) == 1,
        "the hung section returns",
    );
    assert_ne!(w.state(), State::Suspended);
    drop(system);
}

/// A compound suspended as a whole suspends its instances after it ("The instances
/// follow the compound"): one hung in a section does not take the command within the
/// compound's command timeout, and the refusal is a `CommandRefused` step on the
/// compound's monitoring port, not only a log line. The compound's own transition
/// still completes.
#[test]
fn an_instance_that_does_not_follow_its_compound_is_a_refused_step() {
    let Hung {
        system,
        base,
        w,
        script,
        release,
        ..
    } = hung_worker();
    base.command(Command::SetState(Controllable::Suspended))
        .expect("the compound suspends");
    assert_eq!(base.state(), State::Suspended);
    let monitor = base
        .wait_for(
            |m| {
                m.supervision.iter().any(|s| {
                    s.step
                        == Step::CommandRefused {
                            command: "suspend".to_owned(),
                        }
                })
            },
            WAIT,
        )
        .unwrap_or_else(|t| panic!("{t}"));
    let refused = monitor
        .supervision
        .iter()
        .find(|s| matches!(s.step, Step::CommandRefused { .. }))
        .unwrap();
    assert_eq!(refused.instance, "w");
    assert!(
        refused
            .detail
            .contains("busy: the component did not take the command within 20ms"),
        "{refused:?}"
    );
    // The withdrawn command had no effect once the section returns.
    drop(release);
    eventually(
        || script.returned.load(Ordering::SeqCst) == 1,
        "the hung section returns",
    );
    assert_ne!(w.state(), State::Suspended);
    drop(system);
}

/// `Choosing`'s supervisor: `done`'s entry section sets the compound's result,
/// `deciding`'s `choose` moves on once asked to.
struct Choose {
    choose: Arc<std::sync::atomic::AtomicBool>,
}

impl choosing::Supervisor for Choose {
    fn deciding_entry(&mut self, _cx: &mut choosing::Cx<'_>) -> SectionResult {
        Ok(())
    }

    fn deciding_choose(&mut self, _cx: &mut choosing::Cx<'_>) -> Option<choosing::DecidingMay> {
        self.choose
            .load(Ordering::SeqCst)
            .then_some(choosing::DecidingMay::Done)
    }

    fn done_entry(&mut self, cx: &mut choosing::Cx<'_>) -> SectionResult {
        cx.rt.set_result(TaskResult::Fail("given up".to_owned()));
        Ok(())
    }

    fn failed_entry(&mut self, _cx: &mut choosing::Cx<'_>) -> SectionResult {
        Ok(())
    }
}

struct ChoosingParts(Option<Choose>, Arc<Script>);

impl choosing::Parts for ChoosingParts {
    fn supervisor(&mut self) -> impl choosing::Supervisor {
        self.0.take().expect("one supervisor")
    }

    fn w(&mut self) -> impl worker::Behavior {
        Scripted::new(&self.1)
    }
}

#[test]
fn a_supervisor_section_chooses_a_may_target_and_a_rule_reads_the_compounds_own_result() {
    let choose = Arc::new(std::sync::atomic::AtomicBool::new(true));
    let compound = choosing::component(
        "base",
        ChoosingParts(
            Some(Choose {
                choose: Arc::clone(&choose),
            }),
            Script::new(),
        ),
    )
    .unwrap();
    let mut system = System::new();
    let base = system.add(compound).unwrap();
    system.run_all().unwrap();
    // `deciding` -> `done` by `may`; `done`'s entry sets the result; the rule over
    // the own result moves on to `failed`.
    wait_user(&base, "failed");
    assert!(matches!(base.snapshot().result, TaskResult::Fail(_)));
    drop(system);
}

/// `Watching`'s supervisor has no sections.
struct Watch;

impl watching::Supervisor for Watch {
    fn late_entry(&mut self, _cx: &mut watching::Cx<'_>) -> SectionResult {
        Ok(())
    }
}

struct WatchingParts(Arc<Script>, Option<Tap>);

impl watching::Parts for WatchingParts {
    fn supervisor(&mut self) -> impl watching::Supervisor {
        Watch
    }

    fn f(&mut self) -> impl coolbot_runtime_tests::generated::feeder::Behavior {
        self.1.take().expect("one feeder")
    }

    fn w(&mut self) -> impl worker::Behavior {
        Scripted::new(&self.0)
    }
}

#[test]
fn a_rule_over_an_instance_time_is_evaluated_every_supervisor_period() {
    let script = Script::new();
    *script.sleep_in_periodic.lock().unwrap() = Some(Duration::from_millis(1));
    let (tap, feeder) = Tap::new();
    // The rule (`when w.elapsed_time >= 30ms -> late;`) and the supervisor's 10 ms
    // period are the description's.
    let compound = watching::component("base", WatchingParts(script, Some(tap))).unwrap();
    let mut system = System::new();
    let base = system.add(compound).unwrap();
    system.run_all().unwrap();
    wait_user(&base, "watching");
    // Busy: its periodic section adds to its elapsed time every 5 ms.
    feeder.recv_timeout(WAIT).unwrap().kick.emit();
    wait_user(&base, "late");
    drop(system);
}

#[test]
fn a_quality_is_checked_against_the_instance_timing_override() {
    // The worker's component declares two quality levels; this instance's timing
    // override declares three, so level 2 is valid for it.
    let log: Answers = Arc::default();
    let (w, _script) = worker("w");
    let timing = w.timing();
    let w = w.with_timing(TimingSpec {
        qualities: &["full", "reduced", "minimal"],
        ..timing
    });
    let builder = commanding(&log, w);
    let w = builder.instance_handle("w").unwrap();
    let mut system = System::new();
    let base = system.add(builder.build().unwrap()).unwrap();
    system.run_all().unwrap();
    wait_user(&base, "operating");
    set_go(&base, 2);
    let got = answers(&log, 10);
    let by_name = |name: &str| &got.iter().find(|(n, _)| n == name).unwrap().1;
    assert_eq!(by_name("quality 2"), &Ok(()));
    w.wait_for(|m| m.quality == 2, WAIT)
        .unwrap_or_else(|t| panic!("{t}"));
    assert!(system.shutdown().clean());
}

/// `Panicky`'s supervisor: its one state's entry section suspends `w`, then panics.
struct Panics;

impl panicky::Supervisor for Panics {
    fn operating_entry(&mut self, cx: &mut panicky::Cx<'_>) -> SectionResult {
        cx.instances.w().suspend().expect("w takes it");
        panic!("the section fails after its command");
    }
}

struct PanickyParts(Arc<Script>);

impl panicky::Parts for PanickyParts {
    fn supervisor(&mut self) -> impl panicky::Supervisor {
        Panics
    }

    fn w(&mut self) -> impl worker::Behavior {
        Scripted::new(&self.0)
    }
}

#[test]
fn the_commands_of_a_section_that_panics_are_published_with_it() {
    let builder = panicky::builder("base", PanickyParts(Script::new())).unwrap();
    let w = builder.instance_handle("w").unwrap();
    let mut system = System::new();
    let base = system.add(builder.build().unwrap()).unwrap();
    system.run_all().unwrap();
    let failed = base
        .wait_state(State::RunningError, WAIT)
        .unwrap_or_else(|t| panic!("{t}"));
    assert!(
        failed
            .error
            .as_deref()
            .is_some_and(|e| e.contains("the section fails after its command")),
        "{failed:?}"
    );
    // The command it gave before the panic is a step of that section, published with
    // it (not held back for a later section).
    let monitor = base
        .wait_for(|m| !steps(m).is_empty(), WAIT)
        .unwrap_or_else(|t| panic!("the command is a step: {t}"));
    assert_eq!(
        steps(&monitor),
        [(
            Step::Commanded {
                command: "suspend".to_owned()
            },
            String::new()
        )]
    );
    assert_ne!(w.state(), State::Running);
    assert!(system.shutdown().clean());
}

/// The same supervisor and rules in a supervisor harness: no thread, the instance a
/// stand-in. Rules fire on the own variable and on what the test sets of the
/// instance; the commands are recorded and taken as the instance would take them
/// (or refused when asked); they are the compound's supervision steps as on threads.
#[test]
fn a_supervisor_harness_runs_the_rules_and_records_the_commands_without_threads() {
    use coolbot::harness::SupervisorHarness;
    let log: Answers = Arc::default();
    let (w, _script) = worker("w");
    let builder = commanding(&log, w).rule(
        "operating",
        "stopped",
        &["w.state"],
        |view: &coolbot::View| view.state("w") == Some(State::RunningError),
    );
    let mut h = SupervisorHarness::running(builder).unwrap();
    assert_eq!(h.user_state().as_deref(), Some("operating"));
    assert_eq!(h.instance("w").unwrap().state, State::Running);
    assert!(h.take_commands().is_empty());

    // The own variable, through the control port: `stopped` suspends the instance.
    h.set("go", Value::from(1_i64)).unwrap();
    assert_eq!(h.user_state().as_deref(), Some("stopped"));
    assert_eq!(
        h.take_commands(),
        [("w".to_owned(), Command::SetState(Controllable::Suspended))]
    );
    assert_eq!(h.instance("w").unwrap().state, State::Suspended);
    assert_eq!(
        log.lock().unwrap().last().unwrap(),
        &("suspend".to_owned(), Ok(()))
    );

    // Back, then a refusal the test asks for.
    h.set("go", Value::from(0_i64)).unwrap();
    assert_eq!(h.user_state().as_deref(), Some("operating"));
    h.refuse_next(
        "w",
        Refused::Busy {
            waited: Duration::from_millis(250),
        },
    )
    .unwrap();
    h.set("go", Value::from(3_i64)).unwrap();
    assert_eq!(h.user_state().as_deref(), Some("probing"));
    let (what, outcome) = log.lock().unwrap().last().unwrap().clone();
    assert_eq!(what, "run");
    assert!(
        matches!(reason(&outcome), Some(Refused::Busy { .. })),
        "{outcome:?}"
    );
    assert!(
        steps(&h.monitor())
            .iter()
            .any(|(step, detail)| matches!(step, Step::CommandRefused { .. })
                && detail.contains("busy")),
        "{:?}",
        h.monitor().supervision
    );
    h.take_commands();

    // A rule over the instance's state, set by the test.
    h.set("go", Value::from(0_i64)).unwrap();
    assert_eq!(h.user_state().as_deref(), Some("operating"));
    // (No rule reads `go == 5`: `stopped` is kept once entered.)
    h.set("go", Value::from(5_i64)).unwrap();
    assert_eq!(h.user_state().as_deref(), Some("operating"));
    h.set_instance_state("w", State::RunningError).unwrap();
    assert_eq!(h.user_state().as_deref(), Some("stopped"));
    assert_eq!(
        h.take_commands(),
        [("w".to_owned(), Command::SetState(Controllable::Suspended))]
    );

    // Unknown names are errors that say what there is.
    let error = h.set_instance_state("x", State::Running).unwrap_err();
    assert_eq!(
        error.to_string(),
        "`base` has no instance `x` (instances: w)"
    );
    let error = h.set_instance_user_state("w", Some("nope")).unwrap_err();
    assert!(
        error
            .to_string()
            .starts_with("instance `w` has no user state `nope` (states: "),
        "{error}"
    );
    let error = h.set_instance_variable("w", "nope", 1_i64).unwrap_err();
    assert_eq!(error.to_string(), "instance `w` has no variable `nope`");
}

/// What `Cell`'s exit section of `halted` saw: whether the cell was stopping, and the
/// answer to its command to run the joint.
type Exits = Arc<Mutex<Vec<(bool, Result<(), CommandError>)>>>;

/// `Cell`'s supervisor: `halted` suspends the joint on entry and runs it on exit.
struct EmergencyStop {
    exits: Exits,
}

impl cell::Supervisor for EmergencyStop {
    fn halted_entry(&mut self, cx: &mut cell::Cx<'_>) -> SectionResult {
        cx.instances.joint().suspend()?;
        Ok(())
    }

    fn halted_exit(&mut self, cx: &mut cell::Cx<'_>) -> SectionResult {
        let stopping = cx.rt.stopping();
        let outcome = cx.instances.joint().run();
        self.exits.lock().unwrap().push((stopping, outcome));
        Ok(())
    }
}

struct CellParts {
    supervisor: Option<EmergencyStop>,
    script: Arc<Script>,
    tap: Option<Tap>,
}

impl cell::Parts for CellParts {
    fn supervisor(&mut self) -> impl cell::Supervisor {
        self.supervisor.take().expect("one supervisor")
    }

    fn f(&mut self) -> impl coolbot_runtime_tests::generated::feeder::Behavior {
        self.tap.take().expect("one feeder")
    }

    fn joint(&mut self) -> impl worker::Behavior {
        Scripted::new(&self.script)
    }
}

fn set_estop(cell: &Handle, on: bool) {
    cell.command(Command::Set("estop".to_owned(), Value::from(on)))
        .unwrap_or_else(|e| panic!("{e}"));
}

/// The cell's parts: the emergency stop writing into `exits`, a scripted joint.
fn cell_parts(exits: &Exits) -> CellParts {
    CellParts {
        supervisor: Some(EmergencyStop {
            exits: Arc::clone(exits),
        }),
        script: Script::new(),
        tap: Some(Tap::new().0),
    }
}

struct PlantParts(Option<CellParts>);

impl plant::Supervisor for Quiet {}

struct Quiet;

impl plant::Parts for PlantParts {
    fn supervisor(&mut self) -> impl plant::Supervisor {
        Quiet
    }

    fn cell(&mut self) -> impl cell::Parts {
        self.0.take().expect("one cell")
    }
}

/// A supervisor's exit section is told when it runs because the compound shuts down
/// (`Context::stopping`), and a command that would bring an instance to `running`
/// then is refused with a step that says why: an emergency stop's `halted` state,
/// whose exit runs the joint again when a rule leaves it, does not run the joint
/// when the cell shuts down while halted, whether the cell is the system's own
/// component or an instance of another compound (`nested`).
fn a_cell_shutting_down_runs_no_instance_again(nested: bool) {
    let exits: Exits = Arc::default();
    let mut system = System::new();
    let (top, cell) = if nested {
        let plant = system
            .add(plant::component("plant", PlantParts(Some(cell_parts(&exits)))).unwrap())
            .unwrap();
        let cell = plant.instance("cell").unwrap();
        (plant, cell)
    } else {
        let cell = system
            .add(cell::component("cell", cell_parts(&exits)).unwrap())
            .unwrap();
        (cell.clone(), cell)
    };
    let joint = cell.instance("joint").unwrap();
    system.run_all().unwrap();
    wait_user(&cell, "working");

    // A rule leaves `halted`: its exit runs the joint again, and it is not stopping.
    set_estop(&cell, true);
    wait_user(&cell, "halted");
    joint.wait_state(State::Suspended, WAIT).unwrap();
    set_estop(&cell, false);
    wait_user(&cell, "working");
    joint.wait_state(State::Running, WAIT).unwrap();
    assert!(
        matches!(exits.lock().unwrap().as_slice(), [(false, Ok(()))]),
        "{:?}",
        exits.lock().unwrap()
    );

    // Halted again, then shut down: the exit section knows, and the joint goes from
    // suspended to dead, never running.
    set_estop(&cell, true);
    wait_user(&cell, "halted");
    joint.wait_state(State::Suspended, WAIT).unwrap();
    let events = joint.subscribe();
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
    let seen = exits.lock().unwrap().clone();
    assert_eq!(seen.len(), 2, "{seen:?}");
    assert!(seen[1].0, "the exit section is told the cell is stopping");
    assert_eq!(reason(&seen[1].1), Some(&Refused::ShuttingDown));
    let states: Vec<State> = events
        .try_iter()
        .filter_map(|event| match event {
            coolbot::MonitorEvent::State { to, .. } => Some(to),
            _ => None,
        })
        .collect();
    assert_eq!(states, [State::Dead]);
    let refused = cell
        .snapshot()
        .supervision
        .into_iter()
        .find(|s| {
            s.instance == "joint"
                && s.step
                    == Step::CommandRefused {
                        command: "run".to_owned(),
                    }
        })
        .expect("the refusal is a supervision step");
    assert_eq!(
        refused.detail,
        "the compound is shutting down: no instance is brought to running"
    );
    assert_eq!(top.state(), State::Dead);
}

#[test]
fn a_compound_shutting_down_runs_no_instance_again() {
    a_cell_shutting_down_runs_no_instance_again(false);
}

#[test]
fn a_compound_shut_down_by_its_own_compound_runs_no_instance_again() {
    a_cell_shutting_down_runs_no_instance_again(true);
}

/// `Commanding`'s shape with another supervisor: entering `degraded`, it gives `w`
/// periods, `max_response` bounds and priorities at and beyond the control port's
/// ranges (`coolbot::ranges`).
struct Ranging {
    go: i64,
    answers: Answers,
}

impl Supervisor for Ranging {
    fn spec(&self) -> &'static coolbot::Spec {
        &commanding::SPEC
    }

    fn section(
        &mut self,
        state: usize,
        _section: Section,
        cx: &mut SupervisorCx<'_>,
    ) -> SectionResult {
        if !matches!(
            commanding::UserState::ALL[state],
            commanding::UserState::Degraded
        ) {
            return Ok(());
        }
        let hours = |n: u64| Duration::from_secs(3600 * n);
        let w = &mut cx.instances;
        let answers = [
            ("short period", w.set_period("w", Duration::from_micros(50))),
            ("long period", w.set_period("w", hours(2))),
            ("period", w.set_period("w", Duration::from_millis(20))),
            ("zero max_response", w.set_max_response("w", Duration::ZERO)),
            ("long max_response", w.set_max_response("w", hours(2))),
            (
                "max_response",
                w.set_max_response("w", Duration::from_millis(20)),
            ),
            ("huge priority", w.set_priority("w", i32::MAX)),
            ("low priority", w.set_priority("w", -40)),
            ("real-time priority", w.set_priority("w", 5)),
            ("nice priority", w.set_priority("w", -3)),
        ];
        self.answers
            .lock()
            .unwrap()
            .extend(answers.map(|(what, outcome)| (what.to_owned(), outcome)));
        Ok(())
    }

    fn get(&self, _variable: usize) -> Value {
        Value::from(self.go)
    }

    fn set(&mut self, _variable: usize, value: &Value) -> Result<(), coolbot::ValueRefused> {
        self.go = i64::try_from(value)?;
        Ok(())
    }
}

/// A supervisor's periods, bounds and priorities outside the control port's ranges
/// are refused with typed reasons before anything reaches the instance (the
/// stand-in records only what was sent), on the harness's virtual clock.
#[test]
fn a_supervisor_command_outside_its_range_is_refused_before_it_is_sent() {
    use coolbot::harness::SupervisorHarness;
    use coolbot::ranges::{
        MAX_MAX_RESPONSE, MAX_PERIOD, MAX_PRIORITY, MIN_MAX_RESPONSE, MIN_PERIOD, MIN_PRIORITY,
        allow_realtime_priorities,
    };
    // (The only test of this file that sets priorities: the switch is the process's.)
    allow_realtime_priorities(false);
    let log: Answers = Arc::default();
    let (w, _script) = worker("w");
    let builder = go_rules(CompoundBuilder::new(
        "base",
        Ranging {
            go: 0,
            answers: Arc::clone(&log),
        },
    ))
    .instance(w);
    let mut h = SupervisorHarness::running(builder).unwrap();
    h.take_commands();
    h.set("go", Value::from(2_i64)).unwrap();
    assert_eq!(h.user_state().as_deref(), Some("degraded"));
    let got = std::mem::take(&mut *log.lock().unwrap());
    let by_name = |name: &str| &got.iter().find(|(n, _)| n == name).unwrap().1;
    let hours = |n: u64| Duration::from_secs(3600 * n);
    assert_eq!(
        reason(by_name("short period")),
        Some(&Refused::PeriodOutOfRange {
            period: Duration::from_micros(50),
            min: MIN_PERIOD,
            max: MAX_PERIOD
        })
    );
    assert_eq!(
        reason(by_name("long period")),
        Some(&Refused::PeriodOutOfRange {
            period: hours(2),
            min: MIN_PERIOD,
            max: MAX_PERIOD
        })
    );
    assert_eq!(
        reason(by_name("zero max_response")),
        Some(&Refused::ZeroMaxResponse)
    );
    assert_eq!(
        reason(by_name("long max_response")),
        Some(&Refused::MaxResponseOutOfRange {
            max_response: hours(2),
            min: MIN_MAX_RESPONSE,
            max: MAX_MAX_RESPONSE
        })
    );
    assert_eq!(
        reason(by_name("huge priority")),
        Some(&Refused::PriorityOutOfRange {
            priority: i32::MAX,
            min: MIN_PRIORITY,
            max: MAX_PRIORITY
        })
    );
    assert_eq!(
        reason(by_name("low priority")),
        Some(&Refused::PriorityOutOfRange {
            priority: -40,
            min: MIN_PRIORITY,
            max: MAX_PRIORITY
        })
    );
    assert_eq!(
        reason(by_name("real-time priority")),
        Some(&Refused::RealtimePriority { priority: 5 })
    );
    for taken in ["period", "max_response", "nice priority"] {
        assert_eq!(by_name(taken), &Ok(()), "{taken}");
    }
    // Only what was taken reached the instance; each refusal is a step.
    let w = |command| ("w".to_owned(), command);
    assert_eq!(
        h.take_commands(),
        [
            w(Command::SetPeriod(Duration::from_millis(20))),
            w(Command::SetMaxResponse(Duration::from_millis(20))),
            w(Command::SetPriority(-3)),
        ]
    );
    let refused = steps(&h.monitor())
        .into_iter()
        .filter(|(step, _)| matches!(step, Step::CommandRefused { .. }))
        .count();
    assert_eq!(refused, 7);

    // Once the process allows real-time priorities, the same command is taken.
    allow_realtime_priorities(true);
    h.set("go", Value::from(0_i64)).unwrap();
    h.set("go", Value::from(2_i64)).unwrap();
    allow_realtime_priorities(false);
    let got = std::mem::take(&mut *log.lock().unwrap());
    let by_name = |name: &str| &got.iter().find(|(n, _)| n == name).unwrap().1;
    assert_eq!(by_name("real-time priority"), &Ok(()));
    assert!(
        h.take_commands()
            .contains(&("w".to_owned(), Command::SetPriority(5)))
    );
}

/// `Cell`'s supervisor whose `halted` exit takes 5 ms of the clock's time.
struct SlowExit;

impl cell::Supervisor for SlowExit {
    fn halted_entry(&mut self, _cx: &mut cell::Cx<'_>) -> SectionResult {
        Ok(())
    }

    fn halted_exit(&mut self, cx: &mut cell::Cx<'_>) -> SectionResult {
        cx.rt.spend(Duration::from_millis(5));
        Ok(())
    }
}

struct SlowExitParts(Option<SlowExit>, Arc<Script>, Option<Tap>);

impl cell::Parts for SlowExitParts {
    fn supervisor(&mut self) -> impl cell::Supervisor {
        self.0.take().expect("one supervisor")
    }

    fn f(&mut self) -> impl coolbot_runtime_tests::generated::feeder::Behavior {
        self.2.take().expect("one feeder")
    }

    fn joint(&mut self) -> impl worker::Behavior {
        Scripted::new(&self.1)
    }
}

/// `dead` to a component whose exit section takes the clock's time counts as taken
/// once the section does, as any state change does: it does not wait, in real time,
/// for the thread to exit, which only an advance lets it (here an hour, which the
/// command would otherwise wait out: the poll's deadline would fail the test first).
#[test]
fn dead_whose_exit_takes_clock_time_does_not_wait_for_the_thread() {
    let clock = coolbot::VirtualClock::new();
    let mut system = System::with_clock(coolbot::Clock::virtual_clock(&clock));
    let parts = SlowExitParts(Some(SlowExit), Script::new(), Some(Tap::new().0));
    let cell = system.add(cell::component("cell", parts).unwrap()).unwrap();
    system.run_all().unwrap();
    clock.settle().unwrap();
    set_estop(&cell, true);
    clock.settle().unwrap();
    assert_eq!(cell.snapshot().user_state.as_deref(), Some("halted"));
    let patient = cell
        .clone()
        .with_command_timeout(Duration::from_secs(3_600));
    let commanding =
        std::thread::spawn(move || patient.command(Command::SetState(Controllable::Dead)));
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    while !commanding.is_finished() {
        assert!(
            std::time::Instant::now() < deadline,
            "the command waited for the thread"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
    commanding.join().expect("no panic").expect("taken");
    clock.advance(Duration::from_millis(5)).unwrap();
    cell.wait_state(State::Dead, WAIT).unwrap();
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}
