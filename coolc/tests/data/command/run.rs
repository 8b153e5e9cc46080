//! Runs the generated `Base` compound: its supervisor commands its drive through the
//! typed handles of the generated `Cx` (suspends it when stopped, runs it again,
//! lowers its speed, quality and configuration when degraded), every command is a
//! supervision step, a `may` choice moves the supervisor, and rules read the
//! compound's own result and error and the drive's controllable speed and times.

use std::time::Duration;

use command::base::BaseParts;
use command::generated::base;
use coolbot::{Command, Handle, Monitor, State, Step, System, Value};

const WAIT: Duration = Duration::from_secs(20);

fn variable(monitor: &Monitor, name: &str) -> Option<Value> {
    monitor
        .variables
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, v)| v.clone())
}

fn set_mode(base: &Handle, mode: u32) {
    base.command(Command::Set("mode".to_owned(), Value::from(mode)))
        .unwrap();
}

fn wait_user(base: &Handle, user: &str) -> Monitor {
    base.wait_for(|m| m.user_state.as_deref() == Some(user), WAIT)
        .unwrap_or_else(|t| panic!("{t}"))
}

/// The supervisor's commands to `motion`, as `(step, detail)`.
fn commands(monitor: &Monitor) -> Vec<(Step, String)> {
    monitor
        .supervision
        .iter()
        .filter(|s| s.instance == "motion")
        .filter(|s| matches!(s.step, Step::Commanded { .. } | Step::CommandRefused { .. }))
        .map(|s| (s.step.clone(), s.detail.clone()))
        .collect()
}

fn commanded(command: &str) -> (Step, String) {
    (
        Step::Commanded {
            command: command.to_owned(),
        },
        String::new(),
    )
}

#[test]
fn the_supervisor_suspends_slows_and_resumes_its_drive() {
    let mut system = System::new();
    let base = system
        .add(base::component("base", BaseParts::default()).unwrap())
        .unwrap();
    let motion = base.instance("motion").unwrap();
    system.run_all().unwrap();
    wait_user(&base, "operating");
    motion
        .wait_for(
            |m| variable(m, "travelled").and_then(|v| f64::try_from(&v).ok()) > Some(0.0),
            WAIT,
        )
        .unwrap();

    // `stopped` really stops the platform: the drive is suspended.
    set_mode(&base, 1);
    wait_user(&base, "stopped");
    motion.wait_state(State::Suspended, WAIT).unwrap();
    let monitor = base
        .wait_for(|m| commands(m).contains(&commanded("suspend")), WAIT)
        .unwrap();
    assert_eq!(monitor.state, State::Running, "the base itself runs on");

    // Back to `operating`: its entry runs the drive again.
    set_mode(&base, 0);
    wait_user(&base, "operating");
    motion.wait_state(State::Running, WAIT).unwrap();

    // `degraded` lowers the controllable speed, the quality and the acceleration; a
    // zero period is refused with its reason.
    set_mode(&base, 2);
    let monitor = base
        .wait_for(
            |m| variable(m, "refusals") == Some(Value::from(1_u32)),
            WAIT,
        )
        .unwrap();
    assert_eq!(monitor.user_state.as_deref(), Some("degraded"));
    let drive = motion
        .wait_for(
            |m| variable(m, "accel_used") == Some(Value::from(0.5_f64)),
            WAIT,
        )
        .unwrap();
    assert_eq!(variable(&drive, "speed"), Some(Value::from(0.25_f64)));
    assert_eq!(drive.quality, 1);
    let steps = commands(&base.snapshot());
    for expected in ["set speed = 0.25", "quality 1", "configure"] {
        assert!(
            steps.contains(&commanded(expected)),
            "{expected}: {steps:?}"
        );
    }
    assert!(
        steps.iter().any(|(step, detail)| matches!(
            step,
            Step::CommandRefused { command } if command == "period 0ns"
        ) && detail == "a period must be positive"),
        "{steps:?}"
    );

    // The rule over the drive's controllable speed lets it back once asked.
    set_mode(&base, 0);
    wait_user(&base, "operating");
    drop(system);
}

#[test]
fn a_may_choice_and_rules_over_the_compounds_own_result_and_times_move_the_supervisor() {
    let mut system = System::new();
    let base = system
        .add(base::component("base", BaseParts::default()).unwrap())
        .unwrap();
    system.run_all().unwrap();
    wait_user(&base, "operating");
    // `checking` chooses `judged`, whose entry sets the base's result to `fail`; the
    // rule over the own result moves to `failed`, and the rule over the drive's
    // elapsed time and the base's own CPU time to `timed`.
    set_mode(&base, 3);
    let monitor = wait_user(&base, "timed");
    assert!(matches!(monitor.result, coolbot::TaskResult::Fail(_)));
    drop(system);
}
