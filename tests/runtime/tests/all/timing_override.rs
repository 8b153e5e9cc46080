//! `Component::with_timing`: an instance's own `timing` block replaces the spec's for
//! the runner (period, max_response, quality levels) and the monitor. (That it also
//! replaces it for validation, a spec without the period its periodic state needs,
//! which coolc refuses to generate, is in `runtime/tests/invalid_specs.rs`.)

use std::sync::atomic::Ordering;
use std::time::Duration;

use coolbot::{Command, Controllable, State, System, TimingSpec};
use coolbot_runtime_tests::support::{Rig, Script, Scripted, WAIT, WORKER, eventually};
use coolbot_runtime_tests::worker;

const OVERRIDE: TimingSpec = TimingSpec {
    period: Some(Duration::from_millis(20)),
    max_period: Some(Duration::from_millis(40)),
    max_response: Some(Duration::from_millis(300)),
    priority: 7,
    qualities: &["full", "reduced", "minimal"],
};

#[test]
fn the_runner_uses_the_instance_timing() {
    let script = Script::new();
    // The spec's own block: 5 ms period, 500 ms max_response, two quality levels.
    let component = worker::component(WORKER, Scripted::new(&script)).with_timing(OVERRIDE);
    let mut rig = Rig::with(System::new(), script.clone(), component);
    rig.system.run_all().expect("run");
    let handle = rig.handle.clone();
    let kick = rig.feeder().kick.clone();

    // Three quality levels: level 2 exists only in the override.
    handle
        .command(Command::SetQuality(2))
        .expect("quality 2 of 3");
    assert!(handle.command(Command::SetQuality(3)).is_err());

    // A periodic section sleeping 400 ms overruns the override's 300 ms max_response
    // (the spec's 500 ms would not be overrun): a fault. (Ordinary sections stay far
    // below 300 ms even on a loaded machine.)
    *script.sleep_in_periodic.lock().unwrap() = Some(Duration::from_millis(400));
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
            .is_some_and(|e| e.contains("max_response 300ms")),
        "{monitor:?}"
    );
    assert_eq!(monitor.period, Some(Duration::from_millis(20)));
    handle
        .command(Command::SetState(Controllable::Dead))
        .expect("dead");
    let report = rig.system.shutdown();
    assert!(report.clean());
    assert_eq!(report.components[0].state, State::Dead);
}
