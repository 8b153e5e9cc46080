//! The user automaton inside `running`: `after` timers and watchdogs, `may` choices,
//! periodic sections (missed deadlines, period changes), `end` and `result`, and the
//! control port's variables, configuration and quality. The timers' exact sequences
//! are tested on a virtual clock (`coolbot::clock`), stepped by hand.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use coolbot::{
    Clock, Command, Component, Controllable, MonitorEvent, State, System, TaskResult, Value,
    VirtualClock,
};
use coolbot_runtime_tests::generated::{
    ua_after1s_worker, ua_after30ms_worker, ua_never_worker, ua_timerless_worker,
    ua_watchdog_worker,
};
use coolbot_runtime_tests::support::{Rig, Script, Scripted, WAIT, WORKER, eventually};

/// `busy`'s `after` transitions: one `Worker` variant each (`cool/user_automaton.cool`).
#[derive(Clone, Copy)]
enum Timers {
    /// `after <u64::MAX ns> without feed -> idle` (`UaNeverWorker`).
    Never,
    /// `after 30ms -> idle` (`UaAfter30msWorker`).
    After30ms,
    /// `after 2s without feed -> idle` (`UaWatchdogWorker`).
    Watchdog2s,
    /// `after 1s -> idle` (`UaAfter1sWorker`).
    After1s,
    /// None (`UaTimerlessWorker`).
    Timerless,
}

impl Timers {
    fn worker(self, script: &Arc<Script>) -> Component {
        let behavior = Scripted::new(script);
        match self {
            Timers::Never => ua_never_worker::component(WORKER, behavior),
            Timers::After30ms => ua_after30ms_worker::component(WORKER, behavior),
            Timers::Watchdog2s => ua_watchdog_worker::component(WORKER, behavior),
            Timers::After1s => ua_after1s_worker::component(WORKER, behavior),
            Timers::Timerless => ua_timerless_worker::component(WORKER, behavior),
        }
    }
}

fn rig_with_after(after: Timers) -> Rig {
    let script = Script::new();
    let component = after.worker(&script);
    Rig::start(Rig::with(System::new(), script, component))
}

#[test]
fn choose_takes_a_may_transition() {
    let rig = Rig::started(Script::new());
    rig.run_busy();
    rig.script.clear_log();
    rig.script.choose_idle.store(true, Ordering::SeqCst);
    rig.wait_user("idle");
    // `user_state` changes before the entry section runs: wait for the section too.
    eventually(
        || rig.script.log() == ["busy.exit", "idle.entry"],
        "busy.exit then idle.entry",
    );
}

#[test]
fn a_periodic_section_longer_than_its_period_misses_deadlines() {
    let rig = Rig::started(Script::new());
    let events = rig.handle.subscribe();
    *rig.script.sleep_in_periodic.lock().unwrap() = Some(Duration::from_millis(12));
    rig.run_busy();
    let monitor = rig
        .handle
        .wait_for(|m| m.missed_deadlines >= 2, WAIT)
        .expect("missed");
    assert_eq!(
        monitor.state,
        State::Running,
        "a missed deadline is not a fault"
    );
    // Each miss is announced: wait for the announcements to add up.
    let mut announced = 0;
    for event in events.iter() {
        if let MonitorEvent::MissedDeadline { missed, .. } = event {
            announced += missed;
            if announced >= 2 {
                break;
            }
        }
    }
    assert!(announced <= rig.handle.snapshot().missed_deadlines);
}

#[test]
fn the_period_changes_while_running() {
    let rig = Rig::started(Script::new());
    rig.run_busy();
    let events = rig.handle.subscribe();
    let err = rig
        .handle
        .command(Command::SetPeriod(Duration::ZERO))
        .unwrap_err();
    assert_eq!(err.reason, "a period must be positive");
    rig.handle
        .command(Command::SetPeriod(Duration::from_millis(1)))
        .expect("period");
    assert_eq!(rig.handle.snapshot().period, Some(Duration::from_millis(1)));
    // Published before the command's answer; other events (missed deadlines on a
    // busy machine) may come first.
    assert!(
        events
            .try_iter()
            .any(|event| event == MonitorEvent::Period(Some(Duration::from_millis(1))))
    );
    let before = rig.script.periodics.load(Ordering::SeqCst);
    eventually(
        || rig.script.periodics.load(Ordering::SeqCst) > before + 10,
        "faster periodic sections",
    );
}

#[test]
fn end_finishes_the_task_with_its_result() {
    let rig = Rig::started(Script::new());
    let events = rig.handle.subscribe();
    rig.run_busy();
    rig.script.end_in_periodic.store(true, Ordering::SeqCst);
    let monitor = rig.wait_state(State::End);
    assert_eq!(monitor.result, TaskResult::Success("done".to_owned()));
    assert!(
        rig.script
            .log()
            .ends_with(&["busy.exit".to_owned(), "stop".to_owned()])
    );
    let events: Vec<_> = events.try_iter().collect();
    assert!(events.contains(&MonitorEvent::Result(TaskResult::Success(
        "done".to_owned()
    ))));
    assert!(events.contains(&MonitorEvent::State {
        from: State::Running,
        to: State::End
    }));
}

#[test]
fn variables_are_published_and_controllable_ones_set() {
    let rig = Rig::started(Script::new());
    let events = rig.handle.subscribe();
    rig.command(Controllable::Running).expect("running");
    rig.feeder().data.send(1);
    rig.feeder().data.send(2);
    let monitor = rig
        .handle
        .wait_for(|m| m.variables[0].1 == Value::UInt(2), WAIT)
        .expect("count");
    assert_eq!(monitor.variables[1], ("gain".to_owned(), Value::Int(1)));
    rig.handle
        .command(Command::Set("gain".to_owned(), Value::Int(5)))
        .expect("set gain");
    assert_eq!(rig.handle.snapshot().variables[1].1, Value::Int(5));
    let events: Vec<_> = events.try_iter().collect();
    assert!(
        events.contains(&MonitorEvent::Variable {
            name: "gain".to_owned(),
            value: Value::Int(5)
        }),
        "{events:?}"
    );
    let err = rig
        .handle
        .command(Command::Set("count".to_owned(), Value::UInt(0)))
        .unwrap_err();
    assert_eq!(err.reason, "`count` is observable, not controllable");
    let err = rig
        .handle
        .command(Command::Set("speed".to_owned(), Value::UInt(0)))
        .unwrap_err();
    assert_eq!(
        err.reason,
        "no variable `speed` (its controllable variables: gain; a configuration field is \
         changed with `configure`)"
    );
    let err = rig
        .handle
        .command(Command::Set("gain".to_owned(), Value::Str("x".to_owned())))
        .unwrap_err();
    assert_eq!(
        err.reason,
        "invalid value for `gain`: expected i64, got string"
    );
}

#[test]
fn configuration_and_quality_go_through_the_control_port() {
    let rig = Rig::started(Script::new());
    let configuration = Value::Json(serde_json::json!({ "scale": 3 }));
    rig.handle
        .command(Command::Configure(configuration))
        .expect("configure");
    let err = rig
        .handle
        .command(Command::Configure(Value::Json(
            serde_json::json!({ "scale": "big" }),
        )))
        .unwrap_err();
    // The value's conversion error, with serde's reason after it, once.
    assert_eq!(
        err.reason,
        "invalid configuration: the value does not match its type: invalid type: string \"big\", expected i64"
    );
    rig.handle
        .command(Command::SetQuality(1))
        .expect("quality 1");
    assert_eq!(rig.handle.snapshot().quality, 1);
    let err = rig.handle.command(Command::SetQuality(2)).unwrap_err();
    assert_eq!(err.reason, "quality 2 out of range: 2 level(s)");
    rig.handle
        .command(Command::SetPriority(-9))
        .expect("priority");
    assert_eq!(rig.handle.snapshot().priority, -9);
}

#[test]
fn timing_is_measured() {
    let rig = Rig::started(Script::new());
    *rig.script.sleep_in_periodic.lock().unwrap() = Some(Duration::from_millis(2));
    rig.run_busy();
    eventually(
        || rig.script.periodics.load(Ordering::SeqCst) > 3,
        "periodic sections",
    );
    rig.command(Controllable::Suspended).expect("suspend");
    let monitor = rig.handle.snapshot();
    assert!(
        monitor.elapsed_time >= Duration::from_millis(6),
        "{:?}",
        monitor.elapsed_time
    );
    assert!(monitor.cpu_time > Duration::ZERO);
    assert!(
        monitor.cpu_time < monitor.elapsed_time,
        "sleeping costs no CPU"
    );
}

#[test]
fn absurd_durations_mean_never_or_are_refused_and_do_not_panic() {
    // The longest `after` a description can say (`u64::MAX` nanoseconds; a longer
    // duration literal is an error).
    let rig = rig_with_after(Timers::Never);
    rig.run_busy();
    let patient = rig.handle.clone().with_command_timeout(Duration::MAX);
    // A period beyond the control port's range is refused, with the range.
    let refused = patient
        .command(Command::SetPeriod(Duration::MAX))
        .expect_err("a period of Duration::MAX");
    assert_eq!(
        refused.reason,
        coolbot::Refused::PeriodOutOfRange {
            period: Duration::MAX,
            min: coolbot::ranges::MIN_PERIOD,
            max: coolbot::ranges::MAX_PERIOD,
        }
        .to_string()
    );
    // The longest it takes: practically never, for this test.
    patient
        .command(Command::SetPeriod(coolbot::ranges::MAX_PERIOD))
        .expect("the longest period");
    let monitor = rig
        .handle
        .wait_for(
            |m| m.period == Some(coolbot::ranges::MAX_PERIOD),
            Duration::MAX,
        )
        .expect("waited");
    assert_eq!(monitor.user_state.as_deref(), Some("busy"));
    patient
        .command(Command::SetState(Controllable::Suspended))
        .expect("suspend");
}

// ---------------------------------------------------------------------------------
// On a virtual clock (`coolbot::clock`): the test steps time by hand, and each
// `advance` returns once every timer due by then has fired, so the sequences are
// exact and nothing sleeps.

fn virtual_rig_with_after(after: Timers) -> (Rig, Arc<VirtualClock>) {
    let clock = VirtualClock::new();
    let script = Script::new();
    let component = after.worker(&script);
    let system = System::with_clock(Clock::virtual_clock(&clock));
    let rig = Rig::start(Rig::with(system, script, component));
    rig.run_busy();
    clock.settle().expect("settled");
    rig.script.clear_log();
    (rig, clock)
}

fn ms(n: u64) -> Duration {
    Duration::from_millis(n)
}

#[test]
fn on_a_virtual_clock_after_fires_at_its_delay_exactly_after_every_period_before() {
    let (rig, clock) = virtual_rig_with_after(Timers::After30ms);
    // `busy` is periodic (5 ms): one millisecond at a time, the periodic section runs
    // at 5, 10, ... 25 ms, and nothing else happens before 30 ms.
    for _ in 0..29 {
        clock.advance(ms(1)).expect("settled");
    }
    assert_eq!(rig.script.full_log(), ["busy.periodic"; 5]);
    assert_eq!(rig.handle.snapshot().user_state.as_deref(), Some("busy"));
    // At 30 ms the timer and the periodic section are both due: timers come first.
    clock.advance(ms(1)).expect("settled");
    let mut expected = vec!["busy.periodic"; 5];
    expected.extend(["busy.exit", "idle.entry"]);
    assert_eq!(rig.script.full_log(), expected);
    assert_eq!(rig.handle.snapshot().missed_deadlines, 0);
}

#[test]
fn on_a_virtual_clock_a_watchdog_counts_from_the_last_arrival() {
    let (rig, clock) = virtual_rig_with_after(Timers::Watchdog2s);
    clock.advance(ms(1500)).expect("settled");
    rig.feeder().feed.send(1);
    // The worker sees the arrival at 1.5 s (before the command's answer).
    rig.sync();
    clock.advance(ms(1999)).expect("settled");
    assert_eq!(rig.handle.snapshot().user_state.as_deref(), Some("busy"));
    clock.advance(ms(1)).expect("settled");
    assert_eq!(rig.handle.snapshot().user_state.as_deref(), Some("idle"));
}

#[test]
fn on_a_virtual_clock_after_timers_pause_while_suspended() {
    let (rig, clock) = virtual_rig_with_after(Timers::After1s);
    rig.command(Controllable::Suspended).expect("suspend");
    clock.advance(ms(1200)).expect("settled");
    rig.command(Controllable::Running).expect("resume");
    clock.settle().expect("settled");
    clock.advance(ms(999)).expect("settled");
    assert_eq!(
        rig.handle.snapshot().user_state.as_deref(),
        Some("busy"),
        "the pause does not count"
    );
    clock.advance(ms(1)).expect("settled");
    assert_eq!(rig.handle.snapshot().user_state.as_deref(), Some("idle"));
}

#[test]
fn on_a_virtual_clock_a_jump_over_periods_is_counted_as_missed_deadlines() {
    let (rig, clock) = virtual_rig_with_after(Timers::Timerless);
    clock.advance(ms(5)).expect("settled");
    assert_eq!(rig.script.periodics.load(Ordering::SeqCst), 1);
    assert_eq!(rig.handle.snapshot().missed_deadlines, 0);
    // 20 ms at once: the section due at 10 ms runs late, once; 15, 20 and 25 ms are
    // missed (the next deadline is a period after the late run).
    clock.advance(ms(20)).expect("settled");
    assert_eq!(rig.script.periodics.load(Ordering::SeqCst), 2);
    assert_eq!(rig.handle.snapshot().missed_deadlines, 3);
    clock.advance(ms(5)).expect("settled");
    assert_eq!(rig.script.periodics.load(Ordering::SeqCst), 3);
}

#[test]
fn on_a_virtual_clock_a_section_past_max_response_is_tripped_when_the_clock_passes_it() {
    let (rig, clock) = virtual_rig_with_after(Timers::Timerless);
    let release = rig.script.hang_in("busy.periodic");
    // The periodic section starts at 5 ms and hangs: the worker cannot settle.
    let busy = clock
        .advance_with_timeout(ms(5), ms(50))
        .expect_err("a hung section");
    assert_eq!(busy.busy, ["w"]);
    eventually(
        || rig.script.hanging.load(Ordering::SeqCst),
        "the section started at 5 ms",
    );
    // 500 ms into the section: its max_response, not over it (a section that
    // returned now would not have overrun either).
    let _ = clock.advance_with_timeout(ms(500), ms(1));
    assert_eq!(rig.handle.snapshot().overruns, 0);
    // Past it: tripped at once, as the watchdog does in real time.
    let _ = clock.advance_with_timeout(ms(1), ms(1));
    let monitor = rig.handle.snapshot();
    assert_eq!(monitor.overruns, 1);
    assert_eq!(monitor.state, State::RunningError);
    drop(release);
    clock.settle().expect("settled once the section returned");
}

/// A periodic stage whose `start` hook takes a moment of real time.
struct SlowStart;

impl coolbot_runtime_tests::stage::Behavior for SlowStart {
    fn start(&mut self, _cx: &mut coolbot_runtime_tests::stage::Cx<'_>) -> coolbot::SectionResult {
        std::thread::sleep(Duration::from_millis(2));
        Ok(())
    }

    fn work_periodic(
        &mut self,
        _cx: &mut coolbot_runtime_tests::stage::Cx<'_>,
    ) -> coolbot::SectionResult {
        Ok(())
    }
}

/// A component joins its system's virtual clock before its thread starts, so that
/// `settle` right after `System::start` waits for it to leave `starting` (each try
/// races its thread's start hook against the test).
#[test]
fn settling_right_after_the_system_started_waits_for_every_component() {
    for _ in 0..20 {
        let clock = VirtualClock::new();
        let mut system = System::with_clock(Clock::virtual_clock(&clock));
        let c = system
            .add(coolbot_runtime_tests::stage::component("c", SlowStart))
            .expect("c");
        system.start().expect("started");
        clock.settle().expect("settled");
        assert_eq!(c.state(), State::Ready);
        assert!(system.shutdown().clean());
    }
}

/// Settling may be waited for without a bound.
#[test]
fn advancing_may_wait_for_ever_to_settle() {
    let clock = VirtualClock::new();
    let mut system = System::with_clock(Clock::virtual_clock(&clock));
    system
        .add(coolbot_runtime_tests::stage::component("c", SlowStart))
        .expect("c");
    system.run_all().expect("running");
    clock
        .advance_with_timeout(Duration::from_millis(10), Duration::MAX)
        .expect("settled");
    assert!(system.shutdown().clean());
}
