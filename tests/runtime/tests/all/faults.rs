//! Fault containment and continuity plans: panics and faults lead to `running_error`
//! with the message in `error`, other components go on, restarts work, plans recover,
//! `dead` joins the thread, and dropping a system leaves no thread behind.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use coolbot::{Command, Controllable, State, System};
use coolbot_runtime_tests::support::{
    self, Injected, Rig, Script, Scripted, WAIT, WORKER, eventually,
};
use coolbot_runtime_tests::worker::{self, Exception};

#[test]
fn a_panic_goes_to_running_error_and_the_others_go_on() {
    support::quiet_component_panics();
    let rig = Rig::started(Script::new());
    // A second, independent worker in the same system.
    let mut rig = rig;
    let other_script = Script::new();
    let other = worker::component("other", Scripted::new(&other_script));
    let other = rig.system.add(other).expect("add other");
    other.wait_state(State::Ready, WAIT).expect("other ready");
    rig.run_busy();
    other
        .command(Command::SetState(Controllable::Running))
        .expect("other running");
    rig.script.panic_in(Some("busy.periodic"));
    let monitor = rig.wait_state(State::RunningError);
    assert_eq!(
        monitor.error.as_deref(),
        Some("panic in state `busy` (Periodic section): boom in busy.periodic")
    );
    assert_eq!(
        monitor.user_state.as_deref(),
        Some("busy"),
        "the failing state stays visible"
    );
    assert!(
        rig.script.log().ends_with(&["stop".to_owned()]),
        "stop released the resources"
    );
    assert_eq!(other.state(), State::Running);
    // Restart through the control port.
    rig.script.panic_in(None);
    rig.command(Controllable::Running).expect("restart");
    let monitor = rig.wait_user("idle");
    assert_eq!(monitor.error, None, "a successful start clears the error");
    rig.feeder().kick.emit();
    rig.wait_user("busy");
    let before = rig.script.periodics.load(Ordering::SeqCst);
    eventually(
        || rig.script.periodics.load(Ordering::SeqCst) > before + 2,
        "periodic again",
    );
}

#[test]
fn a_panicking_start_goes_to_starting_error() {
    support::quiet_component_panics();
    let script = Script::new();
    script.panic_in(Some("start"));
    let rig = Rig::started(script);
    let monitor = rig.wait_state(State::StartingError);
    assert_eq!(
        monitor.error.as_deref(),
        Some("panic in start: boom in start")
    );
    rig.script.panic_in(None);
    rig.command(Controllable::Ready).expect("retry start");
    assert_eq!(rig.handle.state(), State::Ready);
}

#[test]
fn an_undeclared_fault_goes_to_running_error() {
    let rig = Rig::started(Script::new());
    rig.script.inject(Some(Injected {
        hook: "busy.entry",
        exception: None,
        times: 1,
    }));
    rig.command(Controllable::Running).expect("running");
    rig.feeder().kick.emit();
    let monitor = rig.wait_state(State::RunningError);
    assert_eq!(
        monitor.error.as_deref(),
        Some("fault in state `busy` (Entry section): injected in busy.entry")
    );
}

#[test]
fn a_retry_plan_recovers_when_a_retry_succeeds() {
    let rig = Rig::started(Script::new());
    rig.run_busy();
    rig.script.inject(Some(Injected {
        hook: "busy.periodic",
        exception: Some(Exception::Flaky),
        times: 2,
    }));
    eventually(
        || rig.script.injected.load(Ordering::SeqCst) == 2,
        "injected twice",
    );
    let before = rig.script.periodics.load(Ordering::SeqCst);
    eventually(
        || rig.script.periodics.load(Ordering::SeqCst) > before + 2,
        "goes on",
    );
    assert_eq!(rig.handle.state(), State::Running);
    assert_eq!(
        *rig.script.handled.lock().unwrap(),
        vec!["flaky: injected in busy.periodic"],
        "the handler ran once"
    );
}

#[test]
fn a_retry_plan_that_keeps_failing_goes_to_running_error() {
    let rig = Rig::started(Script::new());
    rig.run_busy();
    rig.script.inject(Some(Injected {
        hook: "busy.periodic",
        exception: Some(Exception::Flaky),
        times: 3,
    }));
    let monitor = rig.wait_state(State::RunningError);
    assert_eq!(
        monitor.error.as_deref(),
        Some("exception `flaky` in state `busy` (Periodic section): injected in busy.periodic")
    );
    assert_eq!(
        rig.script.injected.load(Ordering::SeqCst),
        3,
        "the first run and two retries"
    );
}

#[test]
fn an_exception_without_a_plan_goes_to_running_error_after_its_handler() {
    let rig = Rig::started(Script::new());
    rig.run_busy();
    rig.script.inject(Some(Injected {
        hook: "busy.periodic",
        exception: Some(Exception::Fatal),
        times: 1,
    }));
    let monitor = rig.wait_state(State::RunningError);
    assert!(monitor.error.unwrap().starts_with("exception `fatal`"));
    assert_eq!(
        *rig.script.handled.lock().unwrap(),
        vec!["fatal: injected in busy.periodic"]
    );
}

#[test]
fn a_goto_plan_moves_the_user_automaton() {
    let rig = Rig::started(Script::new());
    rig.run_busy();
    rig.script.clear_log();
    rig.script.inject(Some(Injected {
        hook: "busy.periodic",
        exception: Some(Exception::Detour),
        times: 1,
    }));
    rig.wait_user("idle");
    // `user_state` changes before the entry section runs: wait for the section too.
    eventually(
        || rig.script.log() == ["busy.exit", "idle.entry"],
        "busy.exit then idle.entry",
    );
    assert_eq!(rig.handle.snapshot().error, None);
}

#[test]
fn a_degrade_plan_lowers_the_quality_until_there_is_no_lower_level() {
    let rig = Rig::started(Script::new());
    rig.run_busy();
    let events = rig.handle.subscribe();
    rig.script.inject(Some(Injected {
        hook: "busy.periodic",
        exception: Some(Exception::Wobbly),
        times: 1,
    }));
    let monitor = rig
        .handle
        .wait_for(|m| m.quality == 1, WAIT)
        .expect("degraded");
    assert_eq!(monitor.state, State::Running);
    assert!(
        events
            .iter()
            .any(|event| event == coolbot::MonitorEvent::Quality(1))
    );
    rig.script.inject(Some(Injected {
        hook: "busy.periodic",
        exception: Some(Exception::Wobbly),
        times: 1,
    }));
    let monitor = rig.wait_state(State::RunningError);
    assert!(monitor.error.unwrap().starts_with("exception `wobbly`"));
}

#[test]
fn a_failing_exit_section_leads_to_a_defined_state() {
    support::quiet_component_panics();
    // Leaving for `ready`: running_error.
    let rig = Rig::started(Script::new());
    rig.run_busy();
    rig.script.panic_in(Some("busy.exit"));
    rig.command(Controllable::Ready).expect("accepted");
    let monitor = rig.wait_state(State::RunningError);
    assert!(monitor.error.unwrap().contains("boom in busy.exit"));
    // Leaving for `dead`: dead, with the error recorded.
    let rig = Rig::started(Script::new());
    rig.run_busy();
    rig.script.panic_in(Some("busy.exit"));
    rig.command(Controllable::Dead).expect("accepted");
    let monitor = rig.wait_state(State::Dead);
    assert!(monitor.error.unwrap().contains("boom in busy.exit"));
    assert!(
        rig.script
            .log()
            .ends_with(&["busy.exit".to_owned(), "stop".to_owned()])
    );
}

#[test]
fn a_panicking_stop_is_recorded_and_the_transition_completes() {
    support::quiet_component_panics();
    let rig = Rig::started(Script::new());
    rig.script.panic_in(Some("stop"));
    rig.command(Controllable::Dead).expect("dead");
    let monitor = rig.handle.snapshot();
    assert_eq!(monitor.state, State::Dead);
    assert_eq!(
        monitor.error.as_deref(),
        Some("panic in stop: boom in stop")
    );
}

/// A rig whose worker's behaviour holds `token` (dropped with the behaviour).
fn unstarted_with_token(token: &Arc<()>) -> Rig {
    let script = Script::new();
    let behavior = Scripted {
        script: Arc::clone(&script),
        token: Some(Arc::clone(token)),
    };
    Rig::with(System::new(), script, worker::component(WORKER, behavior))
}

fn rig_with_token() -> (Rig, Arc<()>) {
    let token = Arc::new(());
    let rig = Rig::start(unstarted_with_token(&token));
    (rig, token)
}

#[test]
fn dead_joins_the_thread() {
    let (rig, token) = rig_with_token();
    rig.run_busy();
    assert_eq!(
        Arc::strong_count(&token),
        2,
        "the behaviour lives on the thread"
    );
    rig.command(Controllable::Dead).expect("dead");
    assert_eq!(
        Arc::strong_count(&token),
        1,
        "the thread ended and dropped the behaviour"
    );
    let err = rig.command(Controllable::Running).unwrap_err();
    assert!(err.reason.contains("ended"), "{err}");
}

#[test]
fn dropping_a_running_system_leaves_no_thread_behind() {
    let (rig, token) = rig_with_token();
    rig.run_busy();
    let handle = rig.handle.clone();
    drop(rig);
    assert_eq!(Arc::strong_count(&token), 1, "the thread was joined");
    assert_eq!(handle.state(), State::Dead);
    assert!(rig_with_token_shutdown_report().clean());
}

fn rig_with_token_shutdown_report() -> coolbot::Report {
    let (rig, token) = rig_with_token();
    rig.run_busy();
    let report = rig.system.shutdown();
    assert_eq!(Arc::strong_count(&token), 1);
    assert_eq!(report.components.len(), 2);
    for component in &report.components {
        assert!(component.joined, "{component:?}");
        assert_eq!(component.state, State::Dead);
    }
    report
}

#[test]
fn a_system_that_never_started_drops_cleanly() {
    let token = Arc::new(());
    {
        let rig = unstarted_with_token(&token);
        let err = rig.command(Controllable::Running).unwrap_err();
        assert!(err.reason.contains("not been started"), "{err}");
        let report = rig.system.shutdown();
        assert!(
            report
                .components
                .iter()
                .all(|c| !c.joined && c.state == State::Starting)
        );
    }
    assert_eq!(Arc::strong_count(&token), 1);
}

#[test]
fn a_command_is_withdrawn_if_a_long_section_outlasts_the_command_timeout() {
    let rig = Rig::started(Script::new());
    rig.run_busy();
    *rig.script.sleep_in_periodic.lock().unwrap() = Some(Duration::from_millis(300));
    // Wait until a long periodic section is under way.
    let before = rig.script.periodics.load(Ordering::SeqCst);
    eventually(
        || rig.script.periodics.load(Ordering::SeqCst) > before,
        "in a long section",
    );
    let impatient = rig
        .handle
        .clone()
        .with_command_timeout(Duration::from_millis(20));

    let err = impatient
        .command(Command::SetState(Controllable::Ready))
        .unwrap_err();
    assert!(err.reason.starts_with("busy"), "{err}");
    // A patient command is applied when the section returns.
    *rig.script.sleep_in_periodic.lock().unwrap() = None;
    rig.command(Controllable::Suspended)
        .expect("applied after the section");
    assert_eq!(
        rig.handle.state(),
        State::Suspended,
        "the withdrawn `ready` was never applied"
    );
}

/// Withdrawn commands wait in the control queue until the thread takes them; they
/// take no room from later ones: a component hung in a section through more
/// withdrawn commands than its queue holds refuses each as busy, never "queue full"
/// (a full queue drops the withdrawn ones first: a shutdown's `dead` finds room).
#[test]
fn withdrawn_commands_do_not_fill_the_control_queue() {
    let rig = Rig::started(Script::new());
    rig.run_busy();
    let release = rig.script.hang_in("busy.periodic");
    eventually(
        || rig.script.hanging.load(Ordering::SeqCst),
        "hung in a periodic section",
    );
    let impatient = rig
        .handle
        .clone()
        .with_command_timeout(Duration::from_millis(1));
    for _ in 0..2 * coolbot::CONTROL_CAPACITY {
        let refused = impatient
            .command(Command::SetQuality(0))
            .expect_err("the component is busy");
        assert!(refused.reason.starts_with("busy"), "{refused}");
    }
    // Once the section returns, the withdrawn commands are dropped unapplied.
    drop(release);
    rig.command(Controllable::Suspended)
        .expect("applied after the section");
    assert_eq!(rig.handle.state(), State::Suspended);
}

#[test]
fn a_section_that_returns_after_max_response_is_a_fault() {
    let rig = Rig::started(Script::new());
    rig.run_busy();
    let events = rig.handle.subscribe();
    // The tiny bound is set once `busy`'s entry has returned: from then on only
    // periodic sections run, and any of them that overruns (the sleeping one, or
    // an ordinary one preempted on a loaded machine) is the fault this test expects.
    rig.handle
        .command(Command::SetMaxResponse(Duration::from_millis(1)))
        .expect("max_response");
    // The section also asks to end the task: an overrun section's requests are
    // discarded, so the component goes to running_error, not to end.
    rig.script.end_in_periodic.store(true, Ordering::SeqCst);
    *rig.script.sleep_in_periodic.lock().unwrap() = Some(Duration::from_millis(3));
    // The watchdog may trip the section before it returns (`still running after`);
    // once it has returned, the error says so and the outcome is gone.
    let monitor = rig
        .handle
        .wait_for(
            |m| {
                m.state == State::RunningError
                    && m.error.as_deref().is_some_and(|e| e.ends_with("discarded"))
            },
            WAIT,
        )
        .expect("running_error once the section returned");
    assert!(monitor.overruns >= 1);
    assert!(!rig.handle.is_stuck());
    assert_eq!(monitor.max_response, Some(Duration::from_millis(1)));
    let error = monitor.error.expect("error");
    assert!(
        error.starts_with("overrun in state `busy` (Periodic section): ")
            && error.ends_with("max_response 1ms; its outcome was discarded")
            && (error.contains(": ran ") || error.contains(": returned after ")),
        "{error}"
    );
    eventually(
        || rig.script.log().ends_with(&["stop".to_owned()]),
        "the fault runs stop",
    );
    let events: Vec<_> = events.try_iter().collect();
    assert!(
        events
            .iter()
            .any(|event| matches!(event, coolbot::MonitorEvent::Overrun { .. })),
        "{events:?}"
    );
    assert!(!events.contains(&coolbot::MonitorEvent::State {
        from: State::Running,
        to: State::End
    }));
    // A restart works (with a bound that ordinary entry sections never reach).
    *rig.script.sleep_in_periodic.lock().unwrap() = None;
    rig.script.end_in_periodic.store(false, Ordering::SeqCst);
    rig.handle
        .command(Command::SetMaxResponse(Duration::from_secs(1)))
        .expect("max_response");
    rig.command(Controllable::Running).expect("restart");
    let monitor = rig.wait_user("idle");
    assert_eq!(monitor.error, None);
}

/// (A component whose ports do not match its spec, which coolc never generates, is
/// refused too: `runtime/tests/invalid_specs.rs`.)
#[test]
fn components_with_the_same_name_or_a_bad_name_are_refused() {
    let mut system = System::new();
    let a = worker::component("w", Scripted::new(&Script::new()));
    let b = worker::component("w", Scripted::new(&Script::new()));
    let c = worker::component("x.y", Scripted::new(&Script::new()));
    system.add(a).expect("first");
    assert_eq!(
        system.add(b).unwrap_err().to_string(),
        "a component named `w` already exists"
    );
    assert!(matches!(system.add(c), Err(coolbot::Error::InvalidName(_))));
}

#[test]
fn a_hanging_section_is_tripped_by_the_watchdog_before_it_returns() {
    let rig = Rig::started(Script::new());
    rig.handle
        .command(Command::SetMaxResponse(Duration::from_millis(500)))
        .expect("max_response");
    rig.run_busy();
    let release = rig.script.hang_in("busy.periodic");
    let monitor = rig.wait_state(State::RunningError);
    // The section has not returned: the watchdog published the fault.
    assert!(rig.handle.is_stuck());
    assert!(rig.script.hanging.load(Ordering::SeqCst));
    assert_eq!(rig.script.returned.load(Ordering::SeqCst), 0);
    assert_eq!(monitor.overruns, 1);
    let error = monitor.error.expect("error");
    assert!(
        error.starts_with("overrun in state `busy` (Periodic section): still running after ")
            && error.ends_with(", max_response 500ms"),
        "{error}"
    );
    // Commands wait for the section: an impatient one is withdrawn.
    let impatient = rig
        .handle
        .clone()
        .with_command_timeout(Duration::from_millis(20));
    let busy = impatient
        .command(Command::SetState(Controllable::Running))
        .unwrap_err();
    assert!(busy.reason.starts_with("busy"), "{busy}");
    // The section returns: its outcome is discarded, the fault completes (stop), and
    // the component stays in running_error, counted once.
    drop(release);
    let monitor = rig
        .handle
        .wait_for(
            |m| m.error.as_deref().is_some_and(|e| e.ends_with("discarded")),
            WAIT,
        )
        .expect("the section returned");
    assert!(!rig.handle.is_stuck());
    assert_eq!(monitor.state, State::RunningError);
    assert!(
        monitor
            .error
            .as_deref()
            .is_some_and(|e| e.contains(": returned after ")),
        "{monitor:?}"
    );
    eventually(
        || rig.script.log().ends_with(&["stop".to_owned()]),
        "stop ran after the section returned",
    );
    assert_eq!(rig.handle.snapshot().overruns, 1);
    assert_eq!(rig.handle.state(), State::RunningError);
    // A restart works once the section has returned.
    rig.command(Controllable::Running).expect("restart");
    let monitor = rig.wait_user("idle");
    assert_eq!(monitor.error, None);
}

#[test]
fn shutdown_finishes_while_a_section_never_returns() {
    let rig = Rig::started(Script::new());
    rig.handle
        .command(Command::SetMaxResponse(Duration::from_millis(500)))
        .expect("max_response");
    rig.run_busy();
    let release = rig.script.hang_in("busy.periodic");
    rig.wait_state(State::RunningError);
    let Rig {
        system,
        handle,
        script,
        ..
    } = rig;
    // The thread cannot be joined: shutdown gives up on it after its timeout and says
    // so in the report.
    let report = system.shutdown();
    let stuck = report
        .components
        .iter()
        .find(|c| c.name == "w")
        .expect("w in the report");
    assert!(!stuck.joined, "{report:?}");
    assert_eq!(stuck.state, State::RunningError);
    assert!(
        stuck
            .error
            .as_deref()
            .is_some_and(|e| e.contains("still running after")),
        "{report:?}"
    );
    assert!(!report.clean());
    assert!(
        report
            .components
            .iter()
            .filter(|c| c.name != "w")
            .all(|c| c.joined),
        "the others were joined: {report:?}"
    );
    // When the section finally returns, the thread takes the `dead` shutdown sent.
    drop(release);
    handle
        .wait_state(State::Dead, WAIT)
        .expect("dead once the section returned");
    assert_eq!(script.returned.load(Ordering::SeqCst), 1);
}
