//! `coolbot::harness`: one component on the test's thread, on a virtual clock. The
//! sequences are exact (no thread, no real time), and they are the runtime's: the
//! harness drives the runner's own per-event step.

mod support;

use std::time::Duration;

use coolbot::harness::{Harness, HarnessError};
use coolbot::{Command, Controllable, State, TaskResult, Value};
use support::worker::{self, Exception};
use support::{Injected, Script, Scripted};

fn ms(n: u64) -> Duration {
    Duration::from_millis(n)
}

fn worker(script: &std::sync::Arc<Script>) -> Harness {
    let behavior = Scripted {
        script: script.clone(),
        token: None,
    };
    Harness::new(worker::component("w", behavior).0).unwrap()
}

#[test]
fn start_run_arrivals_and_periodic_sections_in_exact_order() {
    let script = Script::new();
    let mut h = worker(&script);
    assert_eq!(h.state(), State::Ready);
    assert_eq!(script.full_log(), ["start"]);
    h.run().unwrap();
    assert_eq!(h.state(), State::Running);
    assert_eq!(h.user_state().as_deref(), Some("idle"));
    for n in 0..3u64 {
        h.push("data", n).unwrap();
    }
    h.settle().unwrap();
    assert_eq!(h.user_state().as_deref(), Some("busy"));
    assert_eq!(h.variable("count"), Some(Value::UInt(3)));
    // period 5ms: two periodic sections by 12ms, none before.
    h.advance(ms(4)).unwrap();
    assert_eq!(
        script.periodics.load(std::sync::atomic::Ordering::SeqCst),
        0
    );
    h.advance(ms(8)).unwrap();
    assert_eq!(
        script.full_log(),
        [
            "start",
            "idle.entry",
            "busy.entry",
            "busy.periodic",
            "busy.periodic"
        ]
    );
    assert_eq!(h.elapsed(), ms(12));
    assert_eq!(h.next_due(), Some(ms(3)));
}

#[test]
fn an_after_transition_fires_at_its_time_before_the_periodic_section_due_then() {
    let script = Script::new();
    let mut h = worker(&script);
    h.run().unwrap();
    h.tick("kick").unwrap();
    h.settle().unwrap();
    assert_eq!(h.user_state().as_deref(), Some("busy"));
    // `after 10s -> idle` and the 2000th periodic deadline fall at 10s: timers in
    // declaration order after a `may` choice, `after` before the periodic section.
    h.advance(Duration::from_secs(10) - ms(1)).unwrap();
    assert_eq!(h.user_state().as_deref(), Some("busy"));
    h.advance(ms(1)).unwrap();
    assert_eq!(h.user_state().as_deref(), Some("idle"));
    assert_eq!(
        script.periodics.load(std::sync::atomic::Ordering::SeqCst),
        1999
    );
    let log = script.log();
    assert_eq!(
        log,
        [
            "start",
            "idle.entry",
            "busy.entry",
            "busy.exit",
            "idle.entry"
        ]
    );
}

#[test]
fn a_may_choice_and_a_retry_plan_on_the_harness_clock() {
    let script = Script::new();
    let mut h = worker(&script);
    h.run().unwrap();
    h.push("data", 7u64).unwrap();
    h.settle().unwrap();
    // `exception flaky { retry 2 every 1ms; }`: two failures, then the third call
    // succeeds; the retries wait on the harness's clock.
    script.inject(Some(Injected {
        hook: "busy.periodic",
        exception: Some(Exception::Flaky),
        times: 2,
    }));
    h.advance(ms(5)).unwrap();
    assert_eq!(h.state(), State::Running);
    assert_eq!(
        *script.handled.lock().unwrap(),
        ["flaky: injected in busy.periodic"]
    );
    assert_eq!(h.elapsed(), ms(7));
    // The next periodic section chooses `idle`.
    script
        .choose_idle
        .store(true, std::sync::atomic::Ordering::SeqCst);
    h.advance(ms(5)).unwrap();
    assert_eq!(h.user_state().as_deref(), Some("idle"));
}

#[test]
fn an_undeclared_fault_ends_in_running_error_and_a_restart_runs_start_again() {
    let script = Script::new();
    let mut h = worker(&script);
    h.run().unwrap();
    script.inject(Some(Injected {
        hook: "busy.entry",
        exception: None,
        times: 1,
    }));
    h.tick("kick").unwrap();
    h.settle().unwrap();
    assert_eq!(h.state(), State::RunningError);
    let error = h.error().unwrap();
    assert!(error.contains("injected in busy.entry"), "{error}");
    assert_eq!(h.result(), TaskResult::None);
    h.set_state(Controllable::Ready).unwrap();
    assert_eq!(h.state(), State::Ready);
    assert_eq!(script.log().iter().filter(|e| *e == "start").count(), 2);
}

#[test]
fn commands_and_variables_through_the_control_port() {
    let script = Script::new();
    let mut h = worker(&script);
    h.set("gain", Value::Int(3)).unwrap();
    assert_eq!(h.variable("gain"), Some(Value::Int(3)));
    let refused = h.set("count", Value::UInt(1)).unwrap_err();
    assert!(
        matches!(&refused, HarnessError::Rejected { reason, .. } if reason.contains("observable")),
        "{refused}"
    );
    // Two quality levels: 0 and 1.
    h.command(Command::SetQuality(1)).unwrap();
    assert_eq!(h.quality(), 1);
    let refused = h.command(Command::SetQuality(2)).unwrap_err();
    assert!(
        matches!(refused, HarnessError::Rejected { .. }),
        "{refused}"
    );
}

#[test]
fn wrong_ports_are_errors_that_name_them() {
    let script = Script::new();
    let mut h = worker(&script);
    let error = h.push("nope", 1u64).unwrap_err();
    assert_eq!(
        error.to_string(),
        "`w` has no input `nope` (inputs: data, kick, feed)"
    );
    let error = h.push("data", 1u32).unwrap_err();
    assert!(matches!(error, HarnessError::WrongType { .. }), "{error}");
    let error = h.tick("data").unwrap_err();
    assert!(matches!(error, HarnessError::WrongKind { .. }), "{error}");
    let error = h.push("kick", 1u64).unwrap_err();
    assert!(matches!(error, HarnessError::WrongKind { .. }), "{error}");
    let error = h.take_sent::<u32>("out").unwrap_err();
    assert!(matches!(error, HarnessError::WrongType { .. }), "{error}");
    assert_eq!(h.take_sent::<u64>("out").unwrap(), Vec::<u64>::new());
}
