//! `Component::with_timing`: an instance's own `timing` block replaces the spec's for
//! validation, the runner (period, max_response, quality levels) and the monitor.

mod support;

use std::sync::atomic::Ordering;
use std::time::Duration;

use coolbot::port::{FifoIn, TickOut};
use coolbot::{Command, Controllable, OutputKind, OverflowPolicy, Spec, State, System, TimingSpec};
use support::shell::{self, ShellBuilder};
use support::{Script, Scripted, WAIT, eventually, worker};

/// The Worker's shape with no `timing` block at all: its periodic `busy` state has no
/// period, so the spec alone is refused.
static UNTIMED: Spec = Spec {
    timing: TimingSpec::NONE,
    ..worker::SPEC
};

const OVERRIDE: TimingSpec = TimingSpec {
    period: Some(Duration::from_millis(20)),
    max_period: Some(Duration::from_millis(40)),
    max_response: Some(Duration::from_millis(1)),
    priority: 7,
    qualities: &["full", "reduced", "minimal"],
};

fn worker(spec: &'static Spec, script: &std::sync::Arc<Script>) -> coolbot::Component {
    let behavior = Scripted {
        script: std::sync::Arc::clone(script),
        token: None,
    };
    let (component, _inputs, _outputs) =
        worker::component_with("w", behavior, spec, FifoIn::new(4, OverflowPolicy::Reject));
    component
}

#[test]
fn a_spec_without_a_period_is_accepted_with_an_instance_period() {
    let script = Script::new();
    let mut system = System::new();
    let refused = system.add(worker(&UNTIMED, &script)).unwrap_err();
    assert_eq!(
        refused.to_string(),
        "component `w`: invalid spec: state `busy` has a periodic section but neither it nor the component has a period"
    );
    let component = worker(&UNTIMED, &script).with_timing(OVERRIDE);
    assert_eq!(component.timing().period, OVERRIDE.period);
    assert_eq!(component.spec().timing.period, None);
    let handle = system.add(component).expect("accepted with the override");
    let monitor = handle.snapshot();
    assert_eq!(monitor.period, Some(Duration::from_millis(20)));
    assert_eq!(monitor.max_response, Some(Duration::from_millis(1)));
    assert_eq!(monitor.priority, 7);
}

#[test]
fn the_runner_uses_the_instance_timing() {
    let script = Script::new();
    let mut system = System::new();
    // The spec's own block: 5 ms period, 500 ms max_response, two quality levels.
    let component = worker(&worker::SPEC, &script).with_timing(OVERRIDE);
    let handle = system.add(component).expect("add");
    let kick = TickOut::new();
    let feeder = ShellBuilder::new("f")
        .output(shell::output("kick", OutputKind::Tick, false), &kick)
        .build();
    system.add(feeder).expect("add feeder");
    system.connect("f.kick", "w.kick").expect("connect");
    system.run_all().expect("run");

    // Three quality levels: level 2 exists only in the override.
    handle
        .command(Command::SetQuality(2))
        .expect("quality 2 of 3");
    assert!(handle.command(Command::SetQuality(3)).is_err());

    // A periodic section sleeping 5 ms overruns the override's 1 ms max_response (the
    // spec's 500 ms would not be overrun): a fault.
    *script.sleep_in_periodic.lock().unwrap() = Some(Duration::from_millis(5));
    handle
        .wait_for(|m| m.user_state.as_deref() == Some("idle"), WAIT)
        .expect("idle");
    kick.emit();
    eventually(
        || script.periodics.load(Ordering::SeqCst) >= 1,
        "a periodic section",
    );
    let monitor = handle
        .wait_for(|m| m.overruns >= 1 && m.state == State::RunningError, WAIT)
        .expect("the overrun is counted, and is a fault");
    assert!(
        monitor
            .error
            .as_deref()
            .is_some_and(|e| e.contains("max_response 1ms")),
        "{monitor:?}"
    );
    assert_eq!(monitor.period, Some(Duration::from_millis(20)));
    handle
        .command(Command::SetState(Controllable::Dead))
        .expect("dead");
    let report = system.shutdown();
    assert!(report.clean());
    assert_eq!(report.components[0].state, State::Dead);
}
