//! `coolbot::process`'s panic hook: a panic the runtime catches in a watched
//! component is one line naming it, its states and the message; a panic on another
//! thread goes to the previous hook (the default: printed in full), not to that line.
//! The example robot's tests (`examples/mobile-base/tests/all/process.rs`) run a whole
//! process: signals, a clean shutdown, the line on stderr.

use std::time::{Duration, Instant};

use coolbot::State;
use coolbot::process::{self, Process};
use coolbot_runtime_tests::stage;
use coolbot_runtime_tests::support::{Rig, Script};

/// A periodic stage that panics in every section when told to.
struct Breaks(bool);

impl stage::Behavior for Breaks {
    fn work_periodic(&mut self, _cx: &mut stage::Cx<'_>) -> coolbot::SectionResult {
        assert!(!self.0, "the second member broke");
        Ok(())
    }
}

/// Everything captured until `wanted` holds for one line (or a minute passes).
fn captured_until(wanted: impl Fn(&str) -> bool) -> Vec<String> {
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut lines = Vec::new();
    while Instant::now() < deadline {
        lines.extend(process::take_output());
        if lines.iter().any(|line| wanted(line)) {
            return lines;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    panic!("no such line within a minute: {lines:?}");
}

#[test]
fn a_caught_panic_is_one_line_and_other_panics_are_not() {
    // No logger: this test looks only at the panic hook's lines.
    let process = Process::builder().logs(false).init().expect("signals");
    process::capture_output(true);

    let rig = Rig::started(Script::new());
    process::watch_system(&rig.system);
    rig.run_busy();
    rig.script.panic_in(Some("busy.periodic"));
    rig.wait_state(State::RunningError);
    let lines = captured_until(|line| line.starts_with("panic caught in "));
    let caught: Vec<&String> = lines
        .iter()
        .filter(|line| line.starts_with("panic caught in "))
        .collect();
    assert_eq!(caught.len(), 1, "{lines:?}");
    assert!(
        caught[0].starts_with("panic caught in w (running, busy): boom in busy.periodic at "),
        "{}",
        caught[0]
    );
    // The location is the scripted behaviour's panic, in the support module.
    assert!(
        caught[0].contains("tests/runtime/src/support.rs"),
        "{}",
        caught[0]
    );

    // A panic on a thread that is no component's: not this hook's line (the default
    // hook prints it on stderr, in full).
    let outside = std::thread::Builder::new()
        .name("not-a-component".to_owned())
        .spawn(|| panic!("outside any component"))
        .expect("spawned")
        .join();
    assert!(outside.is_err());
    assert!(
        process::take_output()
            .iter()
            .all(|line| !line.contains("outside any component")),
        "a panic outside components was taken for a component's"
    );

    // Two components on one thread (an execution group): the line names the one
    // whose section panicked, not the first on the thread.
    let mut grouped = coolbot::System::new();
    grouped
        .add(stage::component("steady", Breaks(false)))
        .expect("steady");
    grouped
        .add(stage::component("breaking", Breaks(true)))
        .expect("breaking");
    grouped
        .group("control", &["steady", "breaking"])
        .expect("the group");
    grouped.run_all().expect("running");
    process::watch_system(&grouped);
    let lines = captured_until(|line| line.contains("the second member broke"));
    let caught: Vec<&String> = lines
        .iter()
        .filter(|line| line.contains("the second member broke"))
        .collect();
    assert!(
        caught[0].starts_with("panic caught in breaking (running, work): "),
        "{}",
        caught[0]
    );
    process::forget_system(&grouped);
    assert!(grouped.shutdown().clean());

    // Forgotten components are no longer named: their panics print in full too.
    let shutdown = process.shutdown(rig.system);
    assert!(shutdown.clean(), "{shutdown}");
    assert!(
        shutdown.to_string().starts_with("shutdown clean: "),
        "{shutdown}"
    );
    process::capture_output(false);
}
