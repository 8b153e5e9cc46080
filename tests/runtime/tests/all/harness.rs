//! `coolbot::harness`: one component on the test's thread, on a virtual clock. The
//! sequences are exact (no thread, no real time), and they are the runtime's: the
//! harness drives the runner's own per-event step.

use std::time::Duration;

use coolbot::crossbeam_channel::{self, Sender};
use coolbot::harness::{Harness, HarnessError};
use coolbot::port::DataOut;
use coolbot::{Command, Controllable, State, TaskResult, Value};
use coolbot_runtime_tests::generated::harness_source;
use coolbot_runtime_tests::support::{Injected, Script, Scripted, WAIT};
use coolbot_runtime_tests::worker::{self, Exception};

fn ms(n: u64) -> Duration {
    Duration::from_millis(n)
}

fn worker(script: &std::sync::Arc<Script>) -> Harness {
    Harness::new(worker::component("w", Scripted::new(script))).unwrap()
}

/// Hands the `HarnessSource`'s output to the test when it starts.
struct Hand(Sender<DataOut<u64>>);

impl harness_source::Behavior for Hand {
    fn start(&mut self, cx: &mut harness_source::Cx<'_>) -> coolbot::SectionResult {
        let _ = self.0.send(cx.outputs.out.clone());
        Ok(())
    }
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
    // succeeds; the retries are timers of the harness's clock, 1 ms apart.
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
    let injected = || script.injected.load(std::sync::atomic::Ordering::SeqCst);
    assert_eq!((injected(), h.next_due()), (1, Some(ms(1))));
    h.advance(ms(1)).unwrap();
    assert_eq!((injected(), h.next_due()), (2, Some(ms(1))));
    h.advance(ms(1)).unwrap();
    assert_eq!(h.elapsed(), ms(7));
    // Recovered at 7 ms: the next periodic section is due on its period, at 10 ms.
    assert_eq!(h.error(), None);
    assert_eq!(h.next_due(), Some(ms(3)));
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

/// The reason `h` gives for refusing `command`.
fn refusal(h: &mut Harness, command: Command) -> String {
    match h.command(command.clone()) {
        Err(HarnessError::Rejected { reason, .. }) => reason,
        other => panic!("{command:?} was not refused: {other:?}"),
    }
}

#[test]
fn commands_outside_their_ranges_are_refused_with_the_range_and_change_nothing() {
    use coolbot::Refused;
    use coolbot::ranges::{
        MAX_MAX_RESPONSE, MAX_PERIOD, MAX_PRIORITY, MIN_MAX_RESPONSE, MIN_PERIOD, MIN_PRIORITY,
        allow_realtime_priorities,
    };
    // (The only test of this file that sets priorities: the switch is the process's.)
    allow_realtime_priorities(false);
    let script = Script::new();
    let mut h = worker(&script);
    h.run().unwrap();
    let hour = Duration::from_secs(3600);
    for (command, refused) in [
        (
            Command::SetMaxResponse(Duration::ZERO),
            Refused::ZeroMaxResponse,
        ),
        (
            Command::SetMaxResponse(hour * 2),
            Refused::MaxResponseOutOfRange {
                max_response: hour * 2,
                min: MIN_MAX_RESPONSE,
                max: MAX_MAX_RESPONSE,
            },
        ),
        (Command::SetPeriod(Duration::ZERO), Refused::ZeroPeriod),
        (
            Command::SetPeriod(Duration::from_micros(99)),
            Refused::PeriodOutOfRange {
                period: Duration::from_micros(99),
                min: MIN_PERIOD,
                max: MAX_PERIOD,
            },
        ),
        (
            Command::SetPriority(i32::MAX),
            Refused::PriorityOutOfRange {
                priority: i32::MAX,
                min: MIN_PRIORITY,
                max: MAX_PRIORITY,
            },
        ),
        (
            Command::SetPriority(MIN_PRIORITY - 1),
            Refused::PriorityOutOfRange {
                priority: MIN_PRIORITY - 1,
                min: MIN_PRIORITY,
                max: MAX_PRIORITY,
            },
        ),
        (
            Command::SetPriority(5),
            Refused::RealtimePriority { priority: 5 },
        ),
    ] {
        assert_eq!(refusal(&mut h, command), refused.to_string());
    }
    // Nothing was applied: the timing block's values hold, and a zero `max_response`
    // (which would make every periodic section a fault) did not reach the watchdog.
    let monitor = h.monitor();
    assert_eq!(monitor.max_response, Some(ms(500)));
    assert_eq!(monitor.period, Some(ms(5)));
    assert_eq!(monitor.priority, 0);
    h.push("data", 1u64).unwrap();
    h.advance(ms(50)).unwrap();
    assert_eq!(h.user_state().as_deref(), Some("busy"));
    assert_eq!(h.state(), State::Running);
    assert_eq!(h.error(), None);

    // The ends of the ranges are taken.
    h.command(Command::SetPeriod(MIN_PERIOD)).unwrap();
    h.command(Command::SetMaxResponse(MAX_MAX_RESPONSE))
        .unwrap();
    h.command(Command::SetPriority(MIN_PRIORITY)).unwrap();
    let monitor = h.monitor();
    assert_eq!(
        (monitor.period, monitor.max_response, monitor.priority),
        (Some(MIN_PERIOD), Some(MAX_MAX_RESPONSE), MIN_PRIORITY)
    );
    // A real-time priority, once the process allows them.
    allow_realtime_priorities(true);
    h.command(Command::SetPriority(5)).unwrap();
    assert_eq!(h.monitor().priority, 5);
    allow_realtime_priorities(false);
    assert_eq!(
        refusal(&mut h, Command::SetPriority(MAX_PRIORITY)),
        Refused::RealtimePriority {
            priority: MAX_PRIORITY
        }
        .to_string()
    );
}

#[test]
fn a_refusal_quotes_a_short_prefix_of_what_it_refuses() {
    let script = Script::new();
    let mut h = worker(&script);
    let huge = "x".repeat(1 << 20);
    // An unknown variable with a megabyte name.
    let error = h
        .command(Command::Set(huge.clone(), Value::Int(1)))
        .unwrap_err();
    let HarnessError::Rejected {
        command, reason, ..
    } = &error
    else {
        panic!("{error}");
    };
    assert!(reason.starts_with("no variable `xxxx"), "{reason}");
    assert!(
        reason.contains(&format!("... ({} bytes in all)` (", huge.len())),
        "{reason}"
    );
    assert!(command.len() < 120, "{command}");
    assert!(error.to_string().len() < 300, "{error}");
    // A configuration the component refuses, whose decoder quotes the value.
    let error = h
        .configure(Value::Json(serde_json::json!({ "scale": huge })))
        .unwrap_err();
    let HarnessError::Rejected { reason, .. } = &error else {
        panic!("{error}");
    };
    assert!(reason.starts_with("invalid configuration:"), "{reason}");
    assert!(reason.len() < 400, "{} bytes", reason.len());
    assert!(error.to_string().len() < 600, "{error}");
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

#[test]
fn a_recording_replays_into_the_harness_at_its_recorded_times() {
    use coolbot::System;
    use coolbot::clock::{Clock, VirtualClock};
    use coolbot::harness::replay::{Replay, ReplayError};
    use coolbot::record::Recorder;

    // A recording of a producer's `out` (u64), stamped by a virtual clock: packets 1
    // and 2 at 0ms, 3 at 12ms.
    let dir = std::env::temp_dir().join(format!("coolbot-harness-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("replay.mcap");
    {
        let clock = VirtualClock::new();
        let mut system = System::new();
        let (hand, out) = crossbeam_channel::bounded(1);
        system
            .add(harness_source::component("src", Hand(hand)))
            .unwrap();
        system.run_all().unwrap();
        let out = out.recv_timeout(WAIT).expect("the source started");
        let mut recorder = Recorder::new().clock(Clock::virtual_clock(&clock));
        recorder.tap::<u64>(&system, "src.out").unwrap();
        let recording = recorder.start(&path).unwrap();
        out.send(1);
        out.send(2);
        clock.advance(ms(12)).unwrap();
        out.send(3);
        assert_eq!(recording.finish().unwrap().ports[0].recorded, 3);
    }

    let script = Script::new();
    let mut h = worker(&script);
    h.run().unwrap();
    let mut replay = Replay::open(&path).unwrap();
    let error = replay.route::<u64>("src.nope", &h, "data").unwrap_err();
    assert!(matches!(error, ReplayError::NotRecorded { .. }), "{error}");
    let error = replay.route::<u32>("src.out", &h, "data").unwrap_err();
    assert!(
        matches!(error, ReplayError::Harness(HarnessError::WrongType { .. })),
        "{error}"
    );
    replay.route::<u64>("src.out", &h, "data").unwrap();
    let replayed = replay.play(&mut h).unwrap();
    assert_eq!(replayed.sent["src.out"], 3);
    let (first, last) = replayed.span.unwrap();
    assert_eq!(last - first, ms(12));
    // Packets 1 and 2 woke `busy` at 0ms (its entry counted them); the periodic
    // sections at 5ms and 10ms found nothing; packet 3 came at 12ms, after them.
    assert_eq!(h.elapsed(), ms(12));
    assert_eq!(h.variable("count"), Some(Value::UInt(2)));
    assert_eq!(
        script.periodics.load(std::sync::atomic::Ordering::SeqCst),
        2
    );
    h.advance(ms(3)).unwrap();
    assert_eq!(h.variable("count"), Some(Value::UInt(3)));
    let _ = std::fs::remove_dir_all(&dir);
}
