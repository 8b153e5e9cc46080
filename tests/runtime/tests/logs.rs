//! What the runtime logs, read from the process's own logger (`coolbot::process`,
//! its output captured): one line for each adaptation step, where the same move is a
//! step of the supervisor that commanded it and of the instance that applied it.

use coolbot::CompoundBuilder;
use coolbot::process;
use coolbot_runtime_tests::adapt::{self, Load, member};
use coolbot_runtime_tests::supervision::Coordinating;

/// A compound degrades `b`, which runs out of time: the supervisor's step is logged;
/// `b`'s own step of the same move (its history says its supervisor commanded it) is
/// not logged again at info.
#[test]
fn a_move_a_supervisor_commands_is_logged_once() {
    process::init_logs("info");
    process::capture_output(true);
    let heavy = Load::new();
    heavy.set([45, 25, 25]);
    let group = CompoundBuilder::new("group", Coordinating)
        .instance(member("b", -1, &heavy))
        .build()
        .expect("build");
    let (system, group, clock) = adapt::running_on_virtual_clock(group);
    let b = group.instance("b").expect("b");
    let monitor = adapt::step_until(&clock, &b, "b degraded", |m| m.adaptation.level >= 1);
    let applied = monitor
        .adaptation
        .history
        .iter()
        .find(|step| step.to == 1)
        .unwrap_or_else(|| panic!("b's own step to level 1: {monitor}"));
    assert_eq!(applied.detail, "commanded by its supervisor");
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
    let lines = process::take_output();
    let moves: Vec<&String> = lines
        .iter()
        .filter(|line| line.contains("adaptation: b Degraded 0 -> 1"))
        .collect();
    assert_eq!(moves.len(), 1, "{lines:#?}");
    assert!(moves[0].contains("INFO"), "{}", moves[0]);
}
