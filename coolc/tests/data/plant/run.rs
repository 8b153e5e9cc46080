//! Runs the generated `Plant` hierarchy (source, the `Cell` compound, sink) on the
//! runtime: packets cross the cell's exported ports, a fault injected into the
//! cell's primary worker is handled inside the cell (its backup substitutes it and
//! the cell's supervisor rule moves its state), and the plant's rule sees the nested
//! supervisor's state. Every check is on monitor snapshots.

use std::time::Duration;

use coolbot::{Command, Monitor, State, System, Value};
use plant::generated::types::Mode;
use plant::generated::{cell, plant as plant_module};
use plant::plant::PlantParts;

const WAIT: Duration = Duration::from_secs(20);

fn variable(monitor: &Monitor, name: &str) -> Option<Value> {
    monitor
        .variables
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, v)| v.clone())
}

fn count(monitor: &Monitor, name: &str) -> u64 {
    variable(monitor, name)
        .and_then(|v| u64::try_from(&v).ok())
        .unwrap_or(0)
}

#[test]
fn a_failed_leaf_is_substituted_and_the_supervisors_follow() {
    assert_eq!(cell::SUBSTITUTES, &[("backup", "primary")]);
    let component = plant_module::component("plant", PlantParts::default()).unwrap();
    // The compound's interface: its mapped variables, then its own.
    let names: Vec<&str> = component.spec().variables.iter().map(|v| v.name).collect();
    assert_eq!(
        names,
        [
            "received",
            "last",
            "switches",
            "cell_mode",
            "fail",
            "cell_limit",
            "alarms"
        ]
    );
    let mut system = System::new();
    let plant = system.add(component).unwrap();
    system.run_all().unwrap();

    // Packets flow source -> cell (exported input) -> primary -> cell (exported
    // output) -> sink.
    let monitor = plant.wait_for(|m| count(m, "received") >= 5, WAIT).unwrap();
    assert_eq!(monitor.state, State::Running);
    assert_eq!(monitor.user_state.as_deref(), Some("watching"));
    assert_eq!(count(&monitor, "alarms"), 0);
    // `instance cell: Cell { limit = 5; scale = 3; }`: the cell's own `limit`, seen
    // through the mapped `cell_limit`, and its mapped `scale`, which reaches the
    // primary worker (`gain = 2`): every count arrives multiplied by 6.
    assert_eq!(count(&monitor, "cell_limit"), 5);
    let last = count(&monitor, "last");
    assert!(last > 0 && last.is_multiple_of(6), "last = {last}");

    // The fault, set through the plant's control port down to the primary worker.
    plant
        .command(Command::Set("fail".to_owned(), Value::Bool(true)))
        .unwrap();

    // The cell's backup takes over and its rule moves it to `backup`; the plant's
    // rule sees that and moves it to `alarmed`, whose entry section counts it.
    let monitor = plant
        .wait_for(
            |m| m.user_state.as_deref() == Some("alarmed") && count(m, "alarms") == 1,
            WAIT,
        )
        .unwrap();
    assert_eq!(monitor.state, State::Running, "the fault did not propagate");
    assert_eq!(count(&monitor, "switches"), 1);
    let received = count(&monitor, "received");

    // Packets keep arriving (through the backup, then the recovered primary).
    plant
        .wait_for(|m| count(m, "received") >= received + 10, WAIT)
        .unwrap();

    // The primary recovers from the queue: the cell's rule takes it back to
    // `normal`, whose entry section sets its mode back.
    let monitor = plant
        .wait_for(
            |m| {
                variable(m, "cell_mode").and_then(|v| v.to_serde::<Mode>().ok())
                    == Some(Mode::Normal)
                    && count(m, "switches") == 1
            },
            WAIT,
        )
        .unwrap();
    assert_eq!(monitor.user_state.as_deref(), Some("alarmed"));
    assert_eq!(monitor.state, State::Running);

    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn rules_read_every_kind_of_value() {
    let builder =
        plant::generated::probe::builder("probe", plant::probe::ProbeParts::default()).unwrap();
    let gauge = builder.instance_handle("g").unwrap();
    let mut system = System::new();
    let probe = system.add(builder.build().unwrap()).unwrap();
    system.run_all().unwrap();
    // `waiting` -> `seen` (the one rule that holds once the gauge is ready) ->
    // `done` (the gauge's result); none of the rules to `failed` ever holds.
    let monitor = probe
        .wait_for(
            |m| matches!(m.user_state.as_deref(), Some("done" | "failed")),
            WAIT,
        )
        .unwrap();
    assert_eq!(monitor.user_state.as_deref(), Some("done"));
    assert_eq!(count(&monitor, "count"), 1);
    assert!(count(&monitor, "seen_level") >= 3);
    // `g`'s own levels are `best, fine, coarse`: set to the third, the rule in `done`
    // over `g.quality` fires.
    assert_eq!(gauge.snapshot().quality, 0);
    gauge.command(Command::SetQuality(2)).unwrap();
    let monitor = probe
        .wait_for(|m| m.user_state.as_deref() == Some("lowered"), WAIT)
        .unwrap();
    assert_eq!(monitor.state, State::Running);
    assert_eq!(gauge.snapshot().quality, 2);
    // The timing variables, each announced by its event: the rule over `period`
    // alone, then the one over `max_response` and `priority`.
    gauge
        .command(Command::SetPeriod(Duration::from_millis(30)))
        .unwrap();
    probe
        .wait_for(|m| m.user_state.as_deref() == Some("paced"), WAIT)
        .unwrap();
    gauge
        .command(Command::SetMaxResponse(Duration::from_millis(25)))
        .unwrap();
    gauge.command(Command::SetPriority(-1)).unwrap();
    let monitor = probe
        .wait_for(|m| m.user_state.as_deref() == Some("retimed"), WAIT)
        .unwrap();
    assert_eq!(monitor.state, State::Running);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn a_rule_over_a_mapped_variable_reads_the_substitute_standing_in() {
    let component =
        plant::generated::swap::component("swap", plant::swap::SwapParts::default()).unwrap();
    let mut system = System::new();
    let swap = system.add(component).unwrap();
    system.run_all().unwrap();
    // `main` runs at scale 1: the rule `scale == 7` does not hold.
    let monitor = swap
        .wait_for(
            |m| m.state == State::Running && count(m, "scale") == 1,
            WAIT,
        )
        .unwrap();
    assert_eq!(monitor.user_state.as_deref(), Some("watching"));
    // `main` fails; `stand` (`scale = 7`) substitutes it and the rule reads its scale.
    swap.command(Command::Set("fail".to_owned(), Value::Bool(true)))
        .unwrap();
    let monitor = swap
        .wait_for(|m| m.user_state.as_deref() == Some("swapped"), WAIT)
        .unwrap();
    assert_eq!(monitor.state, State::Running);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn a_rule_reading_a_local_variable_fires_after_the_section_that_changed_it() {
    let component =
        plant::generated::ticker::component("ticker", plant::ticker::TickerParts::default())
            .unwrap();
    let mut system = System::new();
    let ticker = system.add(component).unwrap();
    system.run_all().unwrap();
    // `ticks` is local: no monitoring event announces it; the rule is evaluated after
    // each periodic section that counts it up.
    let monitor = ticker
        .wait_for(|m| m.user_state.as_deref() == Some("counted"), WAIT)
        .unwrap();
    assert_eq!(monitor.state, State::Running);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn a_supervisor_moves_on_a_packet_at_an_exported_input() {
    let gate =
        plant::generated::gate::component("gate", plant::gate::GateParts::default()).unwrap();
    let mut system = System::new();
    let handle = system.add(gate).unwrap();
    system
        .add(plant::generated::source::component(
            "source",
            plant::source::Source::default(),
        ))
        .unwrap();
    system.run_all().unwrap();
    let monitor = handle
        .wait_for(|m| m.state == State::Running, WAIT)
        .unwrap();
    assert_eq!(monitor.user_state.as_deref(), Some("closed"));
    system.connect("source.out", "gate.input").unwrap();
    handle
        .wait_for(|m| m.user_state.as_deref() == Some("open"), WAIT)
        .unwrap();
    // The supervisor's `after 300ms without input`: the source disconnected, the gate
    // goes quiet; connected again, it opens.
    system.disconnect("source.out", "gate.input").unwrap();
    handle
        .wait_for(|m| m.user_state.as_deref() == Some("quiet"), WAIT)
        .unwrap();
    system.connect("source.out", "gate.input").unwrap();
    handle
        .wait_for(|m| m.user_state.as_deref() == Some("open"), WAIT)
        .unwrap();
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn a_redundant_group_keeps_the_stream_when_a_member_fails() {
    let pair =
        plant::generated::pair::component("pair", plant::pair::PairParts::default()).unwrap();
    let mut system = System::new();
    let handle = system.add(pair).unwrap();
    system
        .add(plant::generated::source::component(
            "source",
            plant::source::Source::default(),
        ))
        .unwrap();
    let sink = system
        .add(plant::generated::sink::component(
            "sink",
            plant::sink::Sink::default(),
        ))
        .unwrap();
    system.connect("source.out", "pair.input").unwrap();
    system.connect("pair.out", "sink.input").unwrap();
    system.run_all().unwrap();
    let monitor = sink.wait_for(|m| count(m, "received") >= 5, WAIT).unwrap();
    let received = count(&monitor, "received");
    handle
        .command(Command::Set("fail_a".to_owned(), Value::Bool(true)))
        .unwrap();
    // The other member takes the group's connections: packets keep coming.
    sink.wait_for(|m| count(m, "received") >= received + 10, WAIT)
        .unwrap();
    assert_eq!(handle.snapshot().state, State::Running);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn the_restart_budget_of_the_description_bounds_the_restarts() {
    use coolbot::Step;
    // `restart { limit 1 in 1min; ... }`: the first failure is restarted in place,
    // the second spends the budget and the compound fails.
    let restarter = plant::generated::restarter::component(
        "restarter",
        plant::restarter::RestarterParts::default(),
    )
    .unwrap();
    let mut system = System::new();
    let handle = system.add(restarter).unwrap();
    system.run_all().unwrap();
    let fail = || {
        handle
            .command(Command::Set("fail".to_owned(), Value::Bool(true)))
            .unwrap()
    };
    fail();
    let monitor = handle
        .wait_for(
            |m| m.supervision.iter().any(|s| s.step == Step::Restarted),
            WAIT,
        )
        .unwrap();
    assert_eq!(monitor.state, State::Running);
    let worker = handle.instance("w").unwrap();
    worker.wait_state(State::Running, WAIT).unwrap();
    fail();
    let monitor = handle.wait_state(State::RunningError, WAIT).unwrap();
    let steps: Vec<&Step> = monitor.supervision.iter().map(|s| &s.step).collect();
    assert_eq!(
        steps,
        [
            &Step::Failed,
            &Step::Restarted,
            &Step::Failed,
            &Step::Propagated
        ],
        "{:?}",
        monitor.supervision
    );
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn an_atomic_local_variable_is_kept_between_sections_and_never_published() {
    let component = plant::generated::source::component("source", plant::source::Source::default());
    let mut system = System::new();
    let source = system.add(component).unwrap();
    system.run_all().unwrap();
    // `sent` is copied from the local `ticks` each period: it counts up only if the
    // local keeps its value from one section to the next.
    let monitor = source.wait_for(|m| count(m, "sent") >= 3, WAIT).unwrap();
    let names: Vec<&str> = monitor.variables.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["sent"], "a local is not published");
    let refused = source
        .command(Command::Set("ticks".to_owned(), Value::UInt(0)))
        .expect_err("a local is not settable");
    assert!(refused.reason.contains("ticks"), "{refused}");
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn an_extern_packet_is_carried_like_a_packet() {
    let component =
        plant::generated::labels::component("labels", plant::labels::LabelsParts::default())
            .unwrap();
    let mut system = System::new();
    let labels = system.add(component).unwrap();
    system.run_all().unwrap();
    let reader = labels.instance("reader").unwrap();
    // `label 1` ... `label 9` are 7 characters long.
    let monitor = reader.wait_for(|m| count(m, "got") >= 3, WAIT).unwrap();
    assert_eq!(count(&monitor, "last_len"), 7);
    // A variable of an extern packet type is published too (its `Value` compared).
    let last = variable(&monitor, "last").map(|value| value.to_serde::<Option<String>>());
    assert!(
        matches!(&last, Some(Ok(Some(label))) if label.starts_with("label ")),
        "{last:?}"
    );
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn a_compounds_own_timing_applies_to_its_thread_sections_and_quality() {
    let component = plant::generated::slowpoke::component(
        "slowpoke",
        plant::slowpoke::SlowpokeParts::default(),
    )
    .unwrap();
    let mut system = System::new();
    let slowpoke = system.add(component).unwrap();
    system.run_all().unwrap();
    // `priority 2` is applied to the compound's own thread: real-time round-robin
    // where the process may, else what the OS allowed, and why (published).
    let monitor = slowpoke
        .wait_for(|m| m.os_priority != coolbot::OsPriority::Inherited, WAIT)
        .unwrap();
    assert_eq!(monitor.priority, 2);
    assert!(
        matches!(
            monitor.os_priority,
            coolbot::OsPriority::RoundRobin(2)
                | coolbot::OsPriority::Nice(_)
                | coolbot::OsPriority::NotApplied(_)
        ),
        "{:?}",
        monitor.os_priority
    );
    // Its own quality levels: set through its control port, read by its rule.
    slowpoke.command(Command::SetQuality(1)).unwrap();
    let monitor = slowpoke
        .wait_for(|m| m.user_state.as_deref() == Some("leaning"), WAIT)
        .unwrap();
    assert_eq!(monitor.quality, 1);
    // `max_response 40ms` watches its supervisor's sections: one that stalls 200 ms
    // is an overrun, and the compound fails.
    slowpoke
        .command(Command::Set("stall_ms".to_owned(), Value::UInt(200)))
        .unwrap();
    let monitor = slowpoke
        .wait_for(|m| m.state == State::RunningError, WAIT)
        .unwrap();
    assert!(monitor.overruns >= 1, "{monitor:?}");
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}
