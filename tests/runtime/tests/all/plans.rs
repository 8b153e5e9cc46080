//! Exceptions raised from every section kind (entry, periodic, exit) with each
//! continuity plan of paper 3.5 (`retry` that recovers, `retry` that keeps failing,
//! `goto`, `ignore`, `degrade`, no plan), and where each leaves the component.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use coolbot::{Clock, Component, Controllable, State, System, VirtualClock};
use coolbot_runtime_tests::generated::{
    degrade_worker, goto_worker, ignore_worker, plain_worker, worker,
};
use coolbot_runtime_tests::support::{Injected, Rig, Script, Scripted, WAIT, WORKER, eventually};
use worker::Exception;

/// Where a section runs in the test.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    Entry,
    Periodic,
    Exit,
}

impl Kind {
    fn hook(self) -> &'static str {
        match self {
            Kind::Entry => "busy.entry",
            Kind::Periodic => "busy.periodic",
            Kind::Exit => "busy.exit",
        }
    }

    fn name(self) -> &'static str {
        match self {
            Kind::Entry => "Entry",
            Kind::Periodic => "Periodic",
            Kind::Exit => "Exit",
        }
    }
}

/// What the component should do after the exception.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Expect {
    /// Goes on running in user state `user` (None: wherever), at quality `quality`.
    Runs {
        user: Option<&'static str>,
        quality: usize,
    },
    /// Goes to running_error with an error naming the exception and the section.
    Fails,
}

/// The continuity plan of exception `flaky`: one component per plan (`cool/plans.cool`).
#[derive(Debug, Clone, Copy)]
enum Plan {
    /// `retry 2 every 1ms` (`Worker`).
    Retry,
    /// `goto idle` (`GotoWorker`).
    GotoIdle,
    /// `ignore` (`IgnoreWorker`).
    Ignore,
    /// `degrade` (`DegradeWorker`).
    Degrade,
    /// None (`PlainWorker`).
    None,
}

impl Plan {
    /// The rig's worker, of the component whose `flaky` has this plan.
    fn worker(self, script: &Arc<Script>) -> Component {
        let behavior = Scripted::new(script);
        match self {
            Plan::Retry => worker::component(WORKER, behavior),
            Plan::GotoIdle => goto_worker::component(WORKER, behavior),
            Plan::Ignore => ignore_worker::component(WORKER, behavior),
            Plan::Degrade => degrade_worker::component(WORKER, behavior),
            Plan::None => plain_worker::component(WORKER, behavior),
        }
    }
}

const RETRY: Plan = Plan::Retry;
const GOTO_IDLE: Plan = Plan::GotoIdle;
const IGNORE: Plan = Plan::Ignore;
const DEGRADE: Plan = Plan::Degrade;
const NONE: Plan = Plan::None;

/// Raise `flaky` `times` times in a row from section `kind` under `plan`, and check
/// the outcome.
fn case(kind: Kind, plan: Plan, times: u32, expect: Expect) {
    let label = format!("{kind:?} section, plan {plan:?}, {times} exception(s)");
    let script = Script::new();
    let component = plan.worker(&script);
    let rig = Rig::start(Rig::with(System::new(), script, component));
    let injected = Injected {
        hook: kind.hook(),
        exception: Some(Exception::Flaky),
        times,
    };
    match kind {
        Kind::Entry => {
            rig.script.inject(Some(injected));
            rig.command(Controllable::Running).expect("running");
            rig.wait_user("idle");
            rig.feeder().kick.emit();
        }
        Kind::Periodic => {
            rig.run_busy();
            rig.script.inject(Some(injected));
        }
        Kind::Exit => {
            rig.run_busy();
            rig.script.inject(Some(injected));
            // `busy` chooses `idle` after its next periodic section: its exit runs.
            rig.script.choose_idle.store(true, Ordering::SeqCst);
        }
    }
    let injected_all = || rig.script.injected.load(Ordering::SeqCst) == times;
    match expect {
        Expect::Fails => {
            let monitor = rig
                .handle
                .wait_state(State::RunningError, WAIT)
                .unwrap_or_else(|t| panic!("{label}: {t}"));
            assert_eq!(
                monitor.error.as_deref(),
                Some(
                    format!(
                        "exception `flaky` in state `busy` ({} section): injected in {}",
                        kind.name(),
                        kind.hook()
                    )
                    .as_str()
                ),
                "{label}"
            );
            assert!(injected_all(), "{label}");
        }
        Expect::Runs { user, quality } => {
            eventually(injected_all, &label);
            if let Some(user) = user {
                rig.handle
                    .wait_for(|m| m.user_state.as_deref() == Some(user), WAIT)
                    .unwrap_or_else(|t| panic!("{label}: {t}"));
            }
            rig.sync();
            let monitor = rig.handle.snapshot();
            assert_eq!(monitor.state, State::Running, "{label}: {monitor:?}");
            assert_eq!(monitor.error, None, "{label}");
            assert_eq!(monitor.quality, quality, "{label}");
        }
    }
    // The handler ran once per exception that reached the plan (retries re-run the
    // section, not the handler).
    assert_eq!(
        *rig.script.handled.lock().unwrap(),
        [format!("flaky: injected in {}", kind.hook())],
        "{label}"
    );
    assert!(rig.system.shutdown().clean(), "{label}");
}

const KINDS: [Kind; 3] = [Kind::Entry, Kind::Periodic, Kind::Exit];

#[test]
fn retry_recovers_from_every_section_kind() {
    for kind in KINDS {
        case(
            kind,
            RETRY,
            2,
            Expect::Runs {
                user: None,
                quality: 0,
            },
        );
    }
}

#[test]
fn retry_that_keeps_failing_is_running_error_from_every_section_kind() {
    for kind in KINDS {
        case(kind, RETRY, 3, Expect::Fails);
    }
}

#[test]
fn goto_moves_the_user_automaton_from_every_section_kind() {
    // From entry and periodic: to `idle`. From exit: the transition under way goes on
    // (it was already leaving for `idle`).
    for kind in KINDS {
        case(
            kind,
            GOTO_IDLE,
            1,
            Expect::Runs {
                user: Some("idle"),
                quality: 0,
            },
        );
    }
}

#[test]
fn ignore_goes_on_from_every_section_kind() {
    for kind in KINDS {
        let user = if kind == Kind::Exit { "idle" } else { "busy" };
        case(
            kind,
            IGNORE,
            1,
            Expect::Runs {
                user: Some(user),
                quality: 0,
            },
        );
    }
}

#[test]
fn degrade_lowers_the_quality_from_every_section_kind() {
    for kind in KINDS {
        case(
            kind,
            DEGRADE,
            1,
            Expect::Runs {
                user: None,
                quality: 1,
            },
        );
    }
}

#[test]
fn no_plan_is_running_error_from_every_section_kind() {
    for kind in KINDS {
        case(kind, NONE, 1, Expect::Fails);
    }
}

/// The rig's worker under `retry 2 every 1ms`, started on a fresh virtual clock.
fn retrying_on_virtual_clock() -> (Rig, Arc<VirtualClock>) {
    let clock = VirtualClock::new();
    let script = Script::new();
    let worker = Plan::Retry.worker(&script);
    let system = System::with_clock(Clock::virtual_clock(&clock));
    (Rig::start(Rig::with(system, script, worker)), clock)
}

/// That rig in `busy` (entered at 0 ms), its periodic section (due at 5 ms) to raise
/// `flaky` the next `times` times.
fn busy_failing_periodically(times: u32) -> (Rig, Arc<VirtualClock>) {
    let (rig, clock) = retrying_on_virtual_clock();
    rig.run_busy();
    clock.settle().expect("settled");
    rig.script.inject(Some(Injected {
        hook: Kind::Periodic.hook(),
        exception: Some(Exception::Flaky),
        times,
    }));
    (rig, clock)
}

/// A `retry` is a timer of the component's clock, and its thread takes commands while
/// it waits. On a virtual clock: the periodic section fails at 5 ms, its next attempt
/// is due 1 ms later; a `suspend` before it is taken at once, nothing runs while
/// suspended, and the pause moves the attempt (and the periodic deadline it failed
/// at): the second failure comes 1 ms after the resume, the success 1 ms later, and
/// the next periodic section on its period with no deadline missed.
#[test]
fn a_retry_is_a_timer_and_commands_are_taken_while_it_waits() {
    let (rig, clock) = busy_failing_periodically(2);
    let injected = || rig.script.injected.load(Ordering::SeqCst);
    let periodics = || rig.script.periodics.load(Ordering::SeqCst);
    let ms = Duration::from_millis;
    clock.advance(ms(5)).expect("settled");
    assert_eq!(injected(), 1);
    rig.command(Controllable::Suspended).expect("suspended");
    clock.advance(ms(10)).expect("settled");
    assert_eq!(injected(), 1, "nothing runs while suspended");
    rig.command(Controllable::Running).expect("resumed");
    clock.advance(ms(1)).expect("settled");
    assert_eq!(injected(), 2);
    let before = periodics();
    clock.advance(ms(1)).expect("settled");
    assert_eq!(periodics(), before + 1, "the third attempt worked");
    clock.advance(ms(3)).expect("settled");
    assert_eq!(periodics(), before + 2, "on its period again, at 20 ms");
    let monitor = rig.handle.snapshot();
    assert_eq!(monitor.state, State::Running, "{monitor}");
    assert_eq!(monitor.missed_deadlines, 0, "{monitor}");
    assert_eq!(
        *rig.script.handled.lock().unwrap(),
        ["flaky: injected in busy.periodic"]
    );
    assert!(rig.system.shutdown().clean());
}

/// A state whose entry section waits for its retry was never entered: a `ready` then
/// leaves it without its exit section, as on a thread that slept through the retries
/// the command would have found it entered or in `running_error`.
#[test]
fn leaving_a_state_whose_entry_waits_for_its_retry_runs_no_exit_section() {
    let (rig, clock) = retrying_on_virtual_clock();
    rig.command(Controllable::Running).expect("running");
    rig.wait_user("idle");
    rig.script.inject(Some(Injected {
        hook: Kind::Entry.hook(),
        exception: Some(Exception::Flaky),
        times: 2,
    }));
    rig.feeder().kick.emit();
    rig.wait_user("busy");
    eventually(
        || rig.script.injected.load(Ordering::SeqCst) == 1,
        "busy's entry failed once",
    );
    clock.settle().expect("settled");
    rig.command(Controllable::Ready).expect("ready");
    let monitor = rig.wait_state(State::Ready);
    assert_eq!(monitor.error, None, "{monitor}");
    let log = rig.script.log();
    assert_eq!(
        log.last().map(String::as_str),
        Some("busy.entry"),
        "{log:?}"
    );
    assert!(!log.iter().any(|hook| hook == "busy.exit"), "{log:?}");
    // Nothing of the retry is left: run again, the worker starts in `idle`.
    clock.advance(Duration::from_millis(5)).expect("settled");
    assert_eq!(rig.script.injected.load(Ordering::SeqCst), 1);
    rig.command(Controllable::Running).expect("running again");
    rig.wait_user("idle");
    assert!(rig.system.shutdown().clean());
}

/// A section that asked to end and then failed is retried before the task ends, as
/// on a thread that slept through its retries: the attempt at 6 ms asks again and
/// works, and only then does the worker go to `end`.
#[test]
fn a_section_that_asked_to_end_and_failed_is_retried_before_the_end() {
    let (rig, clock) = busy_failing_periodically(1);
    rig.script.end_first.store(true, Ordering::SeqCst);
    clock.advance(Duration::from_millis(5)).expect("settled");
    assert_eq!(rig.handle.state(), State::Running);
    assert_eq!(rig.script.periodics.load(Ordering::SeqCst), 0);
    clock.advance(Duration::from_millis(1)).expect("settled");
    let monitor = rig.wait_state(State::End);
    assert_eq!(rig.script.periodics.load(Ordering::SeqCst), 1, "{monitor}");
    assert!(rig.system.shutdown().clean());
}

/// A period set while a periodic section waits for its retry applies once the
/// retries are over: set to 1 ms at 5 ms, the attempt at 6 ms works and runs alone
/// (it took the deadline at 6 ms, counted missed), then one section a millisecond.
#[test]
fn a_period_set_during_a_retry_applies_after_it() {
    let (rig, clock) = busy_failing_periodically(1);
    let periodics = || rig.script.periodics.load(Ordering::SeqCst);
    clock.advance(Duration::from_millis(5)).expect("settled");
    rig.handle
        .command(coolbot::Command::SetPeriod(Duration::from_millis(1)))
        .expect("period 1 ms");
    clock.advance(Duration::from_millis(1)).expect("settled");
    assert_eq!(periodics(), 1, "the retry alone, at 6 ms");
    assert_eq!(rig.handle.snapshot().missed_deadlines, 1);
    clock.advance(Duration::from_millis(1)).expect("settled");
    assert_eq!(periodics(), 2, "at 7 ms");
    assert!(rig.system.shutdown().clean());
}

/// A retried attempt that panics fails the component at once, as a first panic does:
/// no continuity plan goes on for a panic.
#[test]
fn a_retried_attempt_that_panics_is_running_error_at_once() {
    let (rig, clock) = busy_failing_periodically(1);
    clock.advance(Duration::from_millis(5)).expect("settled");
    rig.script.panic_in(Some(Kind::Periodic.hook()));
    clock.advance(Duration::from_millis(1)).expect("settled");
    let monitor = rig.handle.snapshot();
    assert_eq!(monitor.state, State::RunningError, "{monitor}");
    assert!(
        monitor
            .error
            .as_deref()
            .is_some_and(|error| error.starts_with("panic in state `busy` (Periodic section)")),
        "{monitor}"
    );
    assert!(rig.system.shutdown().clean());
}
