//! Execution groups (`docs/runtime.md`, "Execution groups"): several atomic components
//! on one thread, run in data-flow order, each keeping its own automaton, ports,
//! timing and faults. On the virtual clock: a pass runs before the group settles, so
//! what a packet causes within the group is done when `advance` returns.

use std::sync::Arc;
use std::time::Duration;

use coolbot::{
    Clock, Command, Controllable, Error, GroupError, SectionResult, State, System, VirtualClock,
};
use coolbot_runtime_tests::generated::{
    blocking_relay, checker, control_loop, last_loop, latch, sampler,
};
use coolbot_runtime_tests::support::Log;
use coolbot_runtime_tests::{relay, stage};

const PERIOD: Duration = Duration::from_millis(10);

/// A periodic stage: its input plus one, sent on and logged as `name:value`.
struct Step {
    name: &'static str,
    log: Log,
    count: u64,
    /// Panic in this period (counting from 1).
    panic_at: Option<u64>,
    /// Panic in every period from this one on (counting from 1).
    panic_from: Option<u64>,
    /// In this period, let the clock run on 20 ms inside the section (an overrun of
    /// the 5 ms `max_response`).
    overrun_at: Option<(u64, Arc<VirtualClock>)>,
}

impl stage::Behavior for Step {
    fn work_periodic(&mut self, cx: &mut stage::Cx<'_>) -> SectionResult {
        self.count += 1;
        if self.panic_at == Some(self.count)
            || self.panic_from.is_some_and(|from| self.count >= from)
        {
            panic!("{} broke", self.name);
        }
        if let Some((at, clock)) = &self.overrun_at
            && *at == self.count
        {
            // The other members are on this thread: nobody settles now.
            let _ = clock.advance_with_timeout(Duration::from_millis(20), Duration::ZERO);
        }
        let value = cx.inputs.feed.latest().unwrap_or(0) + 1;
        self.log.push(format!("{}:{value}", self.name));
        cx.outputs.out.send(value);
        Ok(())
    }
}

/// An aperiodic stage: each packet plus one, sent on and logged.
struct Hop {
    name: &'static str,
    log: Log,
    /// Real time each packet takes before it is logged (a slow member).
    pause: Duration,
}

impl relay::Behavior for Hop {
    fn relay_entry(&mut self, cx: &mut relay::Cx<'_>) -> SectionResult {
        while let Some(value) = cx.inputs.feed.recv() {
            std::thread::sleep(self.pause);
            self.log.push(format!("{}:{}", self.name, value + 1));
            cx.outputs.out.send(value + 1);
        }
        Ok(())
    }
}

/// An aperiodic stage named `name` that takes no time, logging into `log`.
fn hop(name: &'static str, log: &Log) -> Hop {
    Hop {
        name,
        log: log.clone(),
        pause: Duration::ZERO,
    }
}

fn step(name: &'static str, log: &Log) -> Step {
    Step {
        name,
        log: log.clone(),
        count: 0,
        panic_at: None,
        panic_from: None,
        overrun_at: None,
    }
}

/// A system on a fresh virtual clock.
fn system() -> (System, Arc<VirtualClock>) {
    let clock = VirtualClock::new();
    (System::with_clock(Clock::virtual_clock(&clock)), clock)
}

/// Three periodic stages `a -> b -> c` (`last` inputs), grouped in the order `c, b, a`.
fn chain(log: &Log, b: Step) -> (System, Arc<VirtualClock>) {
    let (mut system, clock) = system();
    system
        .add(stage::component("a", step("a", log)))
        .expect("a");
    system.add(stage::component("b", b)).expect("b");
    system
        .add(stage::component("c", step("c", log)))
        .expect("c");
    system.connect("a.out", "b.feed").expect("a -> b");
    system.connect("b.out", "c.feed").expect("b -> c");
    system.group("control", &["c", "b", "a"]).expect("group");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    (system, clock)
}

fn tick(clock: &VirtualClock) {
    clock.advance(PERIOD).expect("settled");
}

/// A member whose period is set to one not harmonic with the others' (as adaptation's
/// ladder may) falls due on its own grid: `b` at 15 ms runs alone at 15 and 45 ms,
/// with what `a` last sent, and at 30 ms in the others' pass, in data-flow order.
#[test]
fn a_member_set_to_a_period_not_harmonic_runs_on_its_own_grid() {
    let log = Log::default();
    let (system, clock) = chain(&log, step("b", &log));
    let b = system.handle("b").expect("b");
    b.command(Command::SetPeriod(Duration::from_millis(15)))
        .expect("period 15 ms");
    clock.settle().expect("settled");
    let expected: [&[&str]; 9] = [
        &[],
        &["a:1", "c:1"],
        &["b:2"],
        &["a:1", "c:3"],
        &[],
        &["a:1", "b:2", "c:3"],
        &[],
        &["a:1", "c:3"],
        &["b:2"],
    ];
    for (at, expected) in expected.iter().enumerate() {
        clock.advance(Duration::from_millis(5)).expect("settled");
        assert_eq!(log.take(), *expected, "at {} ms", (at + 1) * 5);
    }
    assert!(system.shutdown().clean());
}

#[test]
fn members_run_in_data_flow_order_and_see_each_others_packets_in_the_same_pass() {
    let log = Log::default();
    let (system, clock) = chain(&log, step("b", &log));
    tick(&clock);
    // Given as `c, b, a`, run as `a, b, c`: each sees what the one before sent in
    // this very period.
    assert_eq!(log.take(), ["a:1", "b:2", "c:3"]);
    tick(&clock);
    assert_eq!(log.take(), ["a:1", "b:2", "c:3"]);
    // Nothing runs between periods.
    clock.advance(PERIOD / 2).expect("settled");
    assert_eq!(log.take(), Vec::<String>::new());
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
    assert!(report.components.iter().all(|c| c.state == State::Dead));
}

#[test]
fn aperiodic_members_run_when_their_inputs_arrive_within_the_pass() {
    let log = Log::default();
    let (mut system, clock) = system();
    system
        .add(stage::component("a", step("a", &log)))
        .expect("a");
    system
        .add(relay::component("r2", hop("r2", &log)))
        .expect("r2");
    system
        .add(relay::component("r1", hop("r1", &log)))
        .expect("r1");
    system.connect("a.out", "r1.feed").expect("a -> r1");
    system.connect("r1.out", "r2.feed").expect("r1 -> r2");
    system.group("chain", &["r2", "r1", "a"]).expect("group");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    tick(&clock);
    // Settled means the group's pass is over: the relays have run, no waiting.
    assert_eq!(log.take(), ["a:1", "r1:2", "r2:3"]);
    tick(&clock);
    assert_eq!(log.take(), ["a:1", "r1:2", "r2:3"]);
}

#[test]
fn settling_after_a_command_waits_for_the_rest_of_the_groups_pass() {
    let log = Log::default();
    let (mut system, clock) = system();
    system
        .add(stage::component("a", step("a", &log)))
        .expect("a");
    system
        .add(relay::component("r1", hop("r1", &log)))
        .expect("r1");
    // Slow: it logs well after `r1`'s command is answered.
    system
        .add(relay::component(
            "r2",
            Hop {
                pause: Duration::from_millis(50),
                ..hop("r2", &log)
            },
        ))
        .expect("r2");
    system.connect("a.out", "r1.feed").expect("a -> r1");
    system.connect("r1.out", "r2.feed").expect("r1 -> r2");
    system.group("chain", &["r1", "r2"]).expect("group");
    system.start().expect("started");
    for name in ["a", "r2"] {
        system
            .handle(name)
            .expect(name)
            .command(Command::SetState(Controllable::Running))
            .expect("running");
    }
    clock.settle().expect("settled");
    tick(&clock);
    // `r1` is still `ready`: `a`'s packet waits at its input.
    assert_eq!(log.take(), ["a:1"]);
    // Running, `r1` relays the packet as it enters its state, before its command is
    // answered; `r2` takes it later in the same pass. Settling waits for that.
    system
        .handle("r1")
        .expect("r1")
        .command(Command::SetState(Controllable::Running))
        .expect("running");
    clock.settle().expect("settled");
    assert_eq!(log.take(), ["r1:2", "r2:3"]);
}

#[test]
fn a_panicking_member_fails_alone_and_the_group_runs_on() {
    let log = Log::default();
    let b = Step {
        panic_at: Some(2),
        ..step("b", &log)
    };
    let (system, clock) = chain(&log, b);
    tick(&clock);
    assert_eq!(log.take(), ["a:1", "b:2", "c:3"]);
    tick(&clock);
    // `b` failed; `c` reads `b`'s last packet; `a` and `c` run on.
    assert_eq!(log.take(), ["a:1", "c:3"]);
    let b = system.handle("b").expect("b");
    let monitor = b.snapshot();
    assert_eq!(monitor.state, State::RunningError);
    assert!(
        monitor
            .error
            .as_deref()
            .is_some_and(|e| e.contains("panic") && e.contains("b broke")),
        "{monitor:?}"
    );
    for other in ["a", "c"] {
        assert_eq!(system.handle(other).expect(other).state(), State::Running);
    }
    tick(&clock);
    assert_eq!(log.take(), ["a:1", "c:3"]);
    // Recovery: `b` restarts on the group's thread and is back in the next period.
    b.command(Command::SetState(Controllable::Running))
        .expect("restart");
    clock.settle().expect("settled");
    tick(&clock);
    assert_eq!(log.take(), ["a:1", "b:2", "c:3"]);
}

/// A stage whose behaviour panics when it is dropped (user code the runtime runs
/// when the component's thread, here its group's, lets the component go).
struct PanicsWhenDropped(Step);

impl stage::Behavior for PanicsWhenDropped {
    fn work_periodic(&mut self, cx: &mut stage::Cx<'_>) -> SectionResult {
        self.0.work_periodic(cx)
    }
}

impl Drop for PanicsWhenDropped {
    fn drop(&mut self) {
        panic!("{} broke as it was dropped", self.0.name);
    }
}

#[test]
fn a_member_whose_drop_panics_ends_alone() {
    coolbot_runtime_tests::support::quiet_component_panics();
    let log = Log::default();
    let (mut system, clock) = system();
    system
        .add(stage::component("a", step("a", &log)))
        .expect("a");
    let b = system
        .add(stage::component("b", PanicsWhenDropped(step("b", &log))))
        .expect("b");
    system.connect("a.out", "b.feed").expect("a -> b");
    system.group("control", &["a", "b"]).expect("group");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    tick(&clock);
    assert_eq!(log.take(), ["a:1", "b:2"]);
    b.command(Command::SetState(Controllable::Dead))
        .expect("dead");
    assert_eq!(b.state(), State::Dead);
    // The group's thread dropped `b` and runs on: `a` answers and keeps its period.
    let a = system.handle("a").expect("a");
    a.command(Command::SetState(Controllable::Suspended))
        .expect("a answers");
    a.command(Command::SetState(Controllable::Running))
        .expect("a answers");
    clock.settle().expect("settled");
    tick(&clock);
    assert_eq!(log.take(), ["a:1"]);
}

#[test]
fn a_suspended_member_is_skipped_until_resumed() {
    let log = Log::default();
    let (system, clock) = chain(&log, step("b", &log));
    let b = system.handle("b").expect("b");
    b.command(Command::SetState(Controllable::Suspended))
        .expect("suspend");
    clock.settle().expect("settled");
    tick(&clock);
    assert_eq!(log.take(), ["a:1", "c:1"]);
    b.command(Command::SetState(Controllable::Running))
        .expect("resume");
    clock.settle().expect("settled");
    tick(&clock);
    assert_eq!(log.take(), ["a:1", "b:2", "c:3"]);
}

#[test]
fn an_overrun_is_charged_to_the_member_that_overran() {
    let log = Log::default();
    let clock = VirtualClock::new();
    let mut system = System::with_clock(Clock::virtual_clock(&clock));
    let a = Step {
        overrun_at: Some((2, Arc::clone(&clock))),
        ..step("a", &log)
    };
    system.add(stage::component("a", a)).expect("a");
    system
        .add(stage::component("b", step("b", &log)))
        .expect("b");
    system.connect("a.out", "b.feed").expect("a -> b");
    system.group("control", &["a", "b"]).expect("group");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    tick(&clock);
    assert_eq!(log.take(), ["a:1", "b:2"]);
    tick(&clock);
    // `a`'s section ran 20 ms against a `max_response` of 5 ms (what it sent went
    // out): the overrun is `a`'s; `b` ran after it, late, and did not overrun.
    assert_eq!(log.take(), ["a:1", "b:2"]);
    let (a, b) = (
        system.handle("a").expect("a"),
        system.handle("b").expect("b"),
    );
    let monitor = a.snapshot();
    assert_eq!(monitor.overruns, 1);
    assert_eq!(monitor.state, State::RunningError);
    assert!(
        monitor
            .error
            .as_deref()
            .is_some_and(|e| e.starts_with("overrun in state `work`")),
        "{monitor:?}"
    );
    assert_eq!(b.snapshot().overruns, 0);
    assert_eq!(b.state(), State::Running);
    tick(&clock);
    assert_eq!(log.take(), ["b:2"]);
}

#[test]
fn each_members_monitor_shows_its_group_and_the_groups_cycles() {
    let log = Log::default();
    let clock = VirtualClock::new();
    let mut system = System::with_clock(Clock::virtual_clock(&clock));
    let a = Step {
        overrun_at: Some((2, Arc::clone(&clock))),
        ..step("a", &log)
    };
    system.add(stage::component("a", a)).expect("a");
    system
        .add(stage::component("b", step("b", &log)))
        .expect("b");
    system
        .add(stage::component("alone", step("alone", &log)))
        .expect("alone");
    system.connect("a.out", "b.feed").expect("a -> b");
    system.group("control", &["b", "a"]).expect("group");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    tick(&clock);
    let group = |name: &str| system.handle(name).expect(name).snapshot().group;
    let first = group("a").expect("a is a member");
    assert_eq!(first.name, "control");
    assert_eq!(first.members, ["a", "b"]);
    assert_eq!(first.period, Some(PERIOD));
    assert!(first.cycles > 0);
    assert_eq!(first.overruns, 0);
    assert_eq!(group("b"), Some(first.clone()));
    assert_eq!(group("alone"), None);
    // `a`'s section lets the clock run on 20 ms: the cycle it is in takes 20 ms,
    // longer than the group's 10 ms period.
    tick(&clock);
    let second = group("b").expect("b is a member");
    assert_eq!(second.overruns, 1);
    assert_eq!(second.worst_cycle, Duration::from_millis(20));
    assert!(second.cycles > first.cycles);
    tick(&clock);
    let third = group("b").expect("b is a member");
    assert_eq!(third.overruns, 1);
    assert_eq!(third.last_cycle, Duration::ZERO);
}

#[test]
fn the_groups_period_is_the_shortest_among_members_running_a_periodic_section() {
    let log = Log::default();
    let clock = VirtualClock::new();
    let mut system = System::with_clock(Clock::virtual_clock(&clock));
    // `slow` lets the clock run on 20 ms inside its second section.
    let slow = Step {
        overrun_at: Some((2, Arc::clone(&clock))),
        ..step("slow", &log)
    };
    system.add(stage::component("slow", slow)).expect("slow");
    system
        .add(stage::component("fast", step("fast", &log)))
        .expect("fast");
    system
        .connect("slow.out", "fast.feed")
        .expect("slow -> fast");
    system.group("control", &["slow", "fast"]).expect("group");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    let (slow, fast) = (
        system.handle("slow").expect("slow"),
        system.handle("fast").expect("fast"),
    );
    slow.command(Command::SetPeriod(PERIOD * 4))
        .expect("period");
    fast.command(Command::SetState(Controllable::Suspended))
        .expect("suspend");
    clock.settle().expect("settled");
    clock.advance(PERIOD * 4).expect("settled");
    assert_eq!(log.take(), ["slow:1"]);
    // The suspended member's 10 ms is not the group's period: `slow`'s 40 ms is.
    let group = slow.snapshot().group.expect("a member");
    assert_eq!(group.period, Some(PERIOD * 4));
    // A 20 ms cycle is within the group's period: no overrun of the group (the
    // section's own overrun of `max_response` is `slow`'s).
    clock.advance(PERIOD * 4).expect("settled");
    assert_eq!(log.take(), ["slow:1"]);
    let group = fast.snapshot().group.expect("a member");
    assert_eq!(group.worst_cycle, Duration::from_millis(20));
    assert_eq!(group.overruns, 0);
    assert_eq!(slow.snapshot().overruns, 1);
    // No member runs a periodic section now: the group has no period.
    clock.advance(PERIOD * 4).expect("settled");
    assert_eq!(fast.snapshot().group.expect("a member").period, None);
}

#[test]
fn a_large_group_waits_on_every_members_doorbell() {
    // More members than the group's wait holds without allocating (32).
    const MEMBERS: usize = 40;
    let log = Log::default();
    let (mut system, clock) = system();
    let names: Vec<&'static str> = (0..MEMBERS)
        .map(|index| &*format!("s{index}").leak())
        .collect();
    for &name in &names {
        system
            .add(stage::component(name, step(name, &log)))
            .expect("stage");
    }
    system.group("large", &names).expect("group");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    tick(&clock);
    assert_eq!(log.take().len(), MEMBERS);
    // A command rings only the last member's bell: the group wakes for it.
    let last = system.handle(names[MEMBERS - 1]).expect("last");
    last.command(Command::SetState(Controllable::Suspended))
        .expect("suspended");
    clock.settle().expect("settled");
    tick(&clock);
    let ran = log.take();
    assert_eq!(ran.len(), MEMBERS - 1);
    assert!(
        !ran.contains(&format!("{}:1", names[MEMBERS - 1])),
        "{ran:?}"
    );
}

#[test]
fn a_group_is_refused_with_what_is_wrong() {
    let log = Log::default();
    let (mut system, _clock) = system();
    system
        .add(stage::component("a", step("a", &log)))
        .expect("a");
    system
        .add(stage::component("b", step("b", &log)))
        .expect("b");
    let refusal = |result: Result<(), Error>| match result {
        Err(Error::Group { source, .. }) => source,
        other => panic!("not a group's refusal: {other:?}"),
    };
    assert_eq!(refusal(system.group("g", &[])), GroupError::Empty);
    assert_eq!(
        refusal(system.group("g", &["a", "x"])),
        GroupError::UnknownMember("x".to_owned())
    );
    assert_eq!(
        refusal(system.group("g", &["a", "a"])),
        GroupError::TwiceGrouped {
            member: "a".to_owned(),
            group: "g".to_owned()
        }
    );
    system.group("g", &["a"]).expect("g");
    assert_eq!(
        refusal(system.group("h", &["b", "a"])),
        GroupError::TwiceGrouped {
            member: "a".to_owned(),
            group: "g".to_owned()
        }
    );
    assert_eq!(
        refusal(system.group("g", &["b"])),
        GroupError::DuplicateName
    );
    system.start().expect("start");
    system
        .add(stage::component("late", step("late", &log)))
        .expect("late");
    assert_eq!(
        refusal(system.group("h", &["late"])),
        GroupError::Started("late".to_owned())
    );
    let error = system.group("h", &["late"]).unwrap_err();
    assert_eq!(
        coolbot::Chain(&error).to_string(),
        "execution group `h`: `late` has already started on a thread of its own"
    );
}

#[test]
fn a_cycle_of_queues_inside_a_group_is_refused_and_a_last_input_breaks_one() {
    let log = Log::default();
    let (mut system, _clock) = system();
    system
        .add(relay::component("r1", hop("r1", &log)))
        .expect("r1");
    system
        .add(relay::component("r2", hop("r2", &log)))
        .expect("r2");
    system.connect("r1.out", "r2.feed").expect("r1 -> r2");
    system.connect("r2.out", "r1.feed").expect("r2 -> r1");
    system.group("loop", &["r1", "r2"]).expect("group");
    match system.start() {
        Err(Error::Group { group, source }) => {
            assert_eq!(group, "loop");
            assert_eq!(source, GroupError::Cycle("`r1`, `r2`".to_owned()));
        }
        other => panic!("started: {other:?}"),
    }
    // Through a `last` input the cycle is broken there: `a` runs first (it is fed
    // only by a `last` input), then `r1`.
    let (mut system, clock) = self::system();
    system
        .add(relay::component("r1", hop("r1", &log)))
        .expect("r1");
    system
        .add(stage::component("a", step("a", &log)))
        .expect("a");
    system.connect("a.out", "r1.feed").expect("a -> r1");
    system.connect("r1.out", "a.feed").expect("r1 -> a");
    system.group("loop", &["r1", "a"]).expect("group");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    tick(&clock);
    assert_eq!(log.take(), ["a:1", "r1:2"]);
    tick(&clock);
    assert_eq!(log.take(), ["a:3", "r1:4"]);
}

#[test]
fn members_are_commanded_and_monitored_each_on_its_own_ports() {
    let log = Log::default();
    let (system, clock) = chain(&log, step("b", &log));
    let c = system.handle("c").expect("c");
    c.command(Command::SetPeriod(PERIOD * 2)).expect("period");
    clock.settle().expect("settled");
    tick(&clock);
    tick(&clock);
    // `c` now runs every other period, on the group's grid.
    assert_eq!(log.take(), ["a:1", "b:2", "a:1", "b:2", "c:3"]);
    assert_eq!(c.snapshot().period, Some(PERIOD * 2));
    assert_eq!(
        system.handle("b").expect("b").snapshot().period,
        Some(PERIOD)
    );
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

/// `a -> b -> c` grouped (given as `c, b, a`) inside compound `base`, with `b2`, a compound around one more
/// `Stage`, substituting `b` on its own thread outside the group.
fn supervised(log: &Log, b: Step) -> (System, Arc<VirtualClock>) {
    use coolbot::{CompoundBuilder, Policy};
    use coolbot_runtime_tests::supervision::Coordinating;
    let clock = VirtualClock::new();
    let mut system = System::with_clock(Clock::virtual_clock(&clock));
    let substitute = CompoundBuilder::new("b2", Coordinating)
        .instance(stage::component("inner", step("b2", log)))
        .export_input::<u64>("feed", "inner.feed")
        .export_output::<u64>("out", "inner.out")
        .build()
        .expect("b2");
    let base = CompoundBuilder::new("base", Coordinating)
        .instance(stage::component("a", step("a", log)))
        .instance(stage::component("b", b))
        .instance(stage::component("c", step("c", log)))
        .instance(substitute)
        .connect("a.out", "b.feed")
        .connect("b.out", "c.feed")
        // Given against the data flow: the compound makes its connections once its
        // system has started, and the group's order counts them all the same.
        .thread("control", &["c", "b", "a"])
        .substitute("b2", "b")
        .on_error("b", Policy::Substitute)
        .build()
        .expect("base");
    system.add(base).expect("base");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    (system, clock)
}

#[test]
fn a_failed_member_is_substituted_by_a_compound_outside_the_group() {
    let log = Log::default();
    let b = Step {
        panic_at: Some(2),
        ..step("b", &log)
    };
    let (system, clock) = supervised(&log, b);
    tick(&clock);
    assert_eq!(log.take(), ["a:1", "b:2", "c:3"]);
    // `b` panics; the compound's supervisor puts `b2` in its place: `b2` runs on its
    // own thread, fed by `a` and feeding `c`, which stay on the group's thread.
    let b2 = system.handle_at("base.b2").expect("b2");
    let mut ticks = 0;
    while !log.take().contains(&"b2:2".to_owned()) {
        tick(&clock);
        ticks += 1;
        assert!(ticks < 10, "no substitution: {:?}", b2.snapshot());
    }
    assert_eq!(
        system.handle_at("base.b").expect("b").state(),
        State::RunningError
    );
    let base = system.handle("base").expect("base");
    assert_eq!(base.state(), State::Running);
    tick(&clock);
    let mut lines = log.take();
    lines.sort();
    // (`b2` and `c` are on two threads: their order within the period is not fixed;
    // `c` reads the newest of `b2`'s packets.)
    assert_eq!(lines, ["a:1", "b2:2", "c:3"]);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

/// Compound `base`: stages `a -> b -> c` and `spare`, which substitutes `b` when it
/// fails; its group is the caller's to add.
fn spared(log: &Log, b: Step) -> coolbot::CompoundBuilder {
    use coolbot::{CompoundBuilder, Policy};
    use coolbot_runtime_tests::supervision::Coordinating;
    CompoundBuilder::new("base", Coordinating)
        .instance(stage::component("a", step("a", log)))
        .instance(stage::component("b", b))
        .instance(stage::component("c", step("c", log)))
        .instance(stage::component("spare", step("spare", log)))
        .connect("a.out", "b.feed")
        .connect("b.out", "c.feed")
        .substitute("spare", "b")
        .on_error("b", Policy::Substitute)
}

/// A substitute that is a member of the group runs, standing in, where its original
/// ran in the data flow (after what feeds it, before what it feeds), whatever its
/// place in the group's list: it has no connections of its own when the group's
/// order is made.
#[test]
fn a_substitute_in_the_group_runs_in_its_originals_place_in_the_flow() {
    let log = Log::default();
    let (mut system, clock) = system();
    let b = Step {
        panic_at: Some(2),
        ..step("b", &log)
    };
    let base = spared(&log, b)
        // The spare first in the list: the order comes from the data flow.
        .thread("control", &["spare", "c", "b", "a"])
        .build()
        .expect("base");
    system.add(base).expect("base");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    tick(&clock);
    assert_eq!(log.take(), ["a:1", "b:2", "c:3"]);
    let spare = system.handle_at("base.spare").expect("spare");
    let mut ticks = 0;
    while !log.take().contains(&"spare:2".to_owned()) {
        tick(&clock);
        ticks += 1;
        assert!(ticks < 10, "no substitution: {:?}", spare.snapshot());
    }
    // Standing in, in one pass: `a`, then the spare with `a`'s packet of this cycle,
    // then `c` with the spare's.
    for _ in 0..3 {
        tick(&clock);
        assert_eq!(log.take(), ["a:1", "spare:2", "c:3"]);
    }
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

/// A substitute's connections only order its group: when, standing in for an
/// original outside the group, they would close a cycle of queues among the members
/// (here `r1 -> orig -> r1`, with `spare` beside `r1`), the group still starts, in the
/// order of its own connections.
#[test]
fn a_substitutes_connections_never_make_its_group_refuse_to_start() {
    use coolbot::{CompoundBuilder, Policy};
    use coolbot_runtime_tests::supervision::Coordinating;
    let log = Log::default();
    let (mut system, clock) = system();
    let base = CompoundBuilder::new("base", Coordinating)
        .instance(relay::component("r1", hop("r1", &log)))
        .instance(relay::component("orig", hop("orig", &log)))
        .instance(relay::component("spare", hop("spare", &log)))
        .connect("r1.out", "orig.feed")
        .connect("orig.out", "r1.feed")
        .thread("loop", &["r1", "spare"])
        .substitute("spare", "orig")
        .on_error("orig", Policy::Substitute)
        .build()
        .expect("the group's own connections make no cycle");
    system.add(base).expect("base");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

/// A member that fails again while on probation after a recovery retry is a step
/// of its own (`Failed`, "again, on probation after a retry", with its error), and
/// the queue retries it again.
#[test]
fn a_member_that_fails_again_on_probation_is_a_step() {
    use coolbot::{MonitorEvent, Step as Done, Supervision};
    let log = Log::default();
    let (mut system, clock) = system();
    let b = Step {
        panic_from: Some(2),
        ..step("b", &log)
    };
    let base = spared(&log, b)
        .thread("control", &["a", "b", "c"])
        .recovery(PERIOD * 3, Duration::from_secs(10))
        .build()
        .expect("base");
    let base = system.add(base).expect("base");
    let events = base.subscribe();
    system.run_all().expect("running");
    clock.settle().expect("settled");
    // The steps about `b`, as published, until `count` of them are in.
    let mut steps: Vec<Supervision> = Vec::new();
    let until = |count: usize, steps: &mut Vec<Supervision>| {
        let deadline = std::time::Instant::now() + Duration::from_secs(60);
        while steps.len() < count {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            match events.recv_timeout(left) {
                Ok(MonitorEvent::Supervision(step)) if step.instance == "b" => steps.push(step),
                Ok(_) => {}
                Err(_) => panic!("{} step(s) about b: {steps:?}", steps.len()),
            }
        }
    };
    // Fails in its second period: substituted and queued.
    tick(&clock);
    tick(&clock);
    until(3, &mut steps);
    assert_eq!(steps[0].step, Done::Failed);
    // The retry (three periods later) runs it again; its next period fails it again.
    for _ in 0..3 {
        tick(&clock);
    }
    until(4, &mut steps);
    assert_eq!(steps[3].step, Done::Retried, "{steps:?}");
    tick(&clock);
    until(5, &mut steps);
    assert_eq!(steps[4].step, Done::Failed, "{steps:?}");
    assert!(
        steps[4]
            .detail
            .starts_with("again, on probation after a retry: ")
            && steps[4].detail.contains("b broke"),
        "{steps:?}"
    );
    // And the queue retries it again.
    for _ in 0..3 {
        tick(&clock);
    }
    until(6, &mut steps);
    assert_eq!(steps[5].step, Done::Retried, "{steps:?}");
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

#[test]
fn a_compound_refuses_a_group_that_cannot_run() {
    use coolbot::{CompoundBuilder, CompoundError};
    use coolbot_runtime_tests::supervision::Coordinating;
    let log = Log::default();
    let built = CompoundBuilder::new("base", Coordinating)
        .instance(relay::component("r1", hop("r1", &log)))
        .instance(relay::component("r2", hop("r2", &log)))
        .connect("r1.out", "r2.feed")
        .connect("r2.out", "r1.feed")
        .thread("loop", &["r1", "r2"])
        .build();
    let Err(error) = built else {
        panic!("a cycle of queues was accepted");
    };
    assert!(matches!(error, CompoundError::Instance { .. }));
    assert_eq!(
        coolbot::Chain(&error).to_string(),
        "compound `base`: execution group `loop`: its members' connections form a cycle through `r1`, `r2` with no `last` or `poster` input to break it"
    );
}

/// A `block` fifo fed by another member would stop, when full, the very thread that
/// empties it: refused when the group starts, naming both ends.
#[test]
fn a_blocking_queue_between_members_is_refused() {
    let log = Log::default();
    let (mut system, _clock) = system();
    system
        .add(relay::component("r1", hop("r1", &log)))
        .expect("r1");
    system
        .add(blocking_relay::component("r2", BlockingHop))
        .expect("r2");
    system.connect("r1.out", "r2.feed").expect("r1 -> r2");
    system.group("g", &["r1", "r2"]).expect("group");
    // Connected once grouped: refused at once.
    system.disconnect("r1.out", "r2.feed").expect("r1 -/-> r2");
    let refused = system.connect("r1.out", "r2.feed").unwrap_err();
    assert_eq!(
        refused.to_string(),
        "cannot connect `r1.out` to `block` fifo `r2.feed`: both run in execution group `g`, and a full queue would stop the thread that empties it"
    );
    // Connected before grouping: refused when the group starts.
    let (mut system, _clock) = self::system();
    system
        .add(relay::component("r1", hop("r1", &log)))
        .expect("r1");
    system
        .add(blocking_relay::component("r2", BlockingHop))
        .expect("r2");
    system.connect("r1.out", "r2.feed").expect("r1 -> r2");
    system.group("g", &["r1", "r2"]).expect("group");
    match system.start() {
        Err(Error::Group { group, source }) => {
            assert_eq!(group, "g");
            assert_eq!(
                source,
                GroupError::Block {
                    input: "r2.feed".to_owned(),
                    output: "r1.out".to_owned(),
                }
            );
        }
        other => panic!("started: {other:?}"),
    }
}

/// `BlockingRelay`'s behaviour: drains its queue.
struct BlockingHop;

impl blocking_relay::Behavior for BlockingHop {
    fn relay_entry(&mut self, cx: &mut blocking_relay::Cx<'_>) -> SectionResult {
        while cx.inputs.feed.recv().is_some() {}
        Ok(())
    }
}

/// A cycle among some members sets aside one `last` input on the cycle only: a
/// chain beside it keeps its data-flow order.
#[test]
fn a_cycle_breaks_only_on_the_cycle() {
    let log = Log::default();
    let (mut system, clock) = system();
    for name in ["b", "a"] {
        system
            .add(stage::component(name, step(name, &log)))
            .expect(name);
    }
    system
        .add(relay::component("r", hop("r", &log)))
        .expect("r");
    system
        .add(stage::component("c", step("c", &log)))
        .expect("c");
    // A chain `a -> b` (into `b`'s `last` input), and a cycle `c -> r -> c` broken at
    // `c`'s `last` input.
    system.connect("a.out", "b.feed").expect("a -> b");
    system.connect("c.out", "r.feed").expect("c -> r");
    system.connect("r.out", "c.feed").expect("r -> c");
    system.group("g", &["b", "a", "r", "c"]).expect("group");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    tick(&clock);
    assert_eq!(log.take(), ["a:1", "b:2", "c:1", "r:2"]);
}

/// The parts of `ControlLoop` (`cool/groups.cool`): every stage logs into `log`; the
/// controller panics in its second period.
struct LoopParts {
    log: Log,
}

/// `ControlLoop` has no supervisor of its own to write.
struct Quiet;

impl control_loop::Supervisor for Quiet {}

impl control_loop::Parts for LoopParts {
    fn supervisor(&mut self) -> impl control_loop::Supervisor {
        Quiet
    }
    fn imu(&mut self) -> impl stage::Behavior {
        step("imu", &self.log)
    }
    fn estimator(&mut self) -> impl stage::Behavior {
        step("estimator", &self.log)
    }
    fn controller(&mut self) -> impl stage::Behavior {
        Step {
            panic_at: Some(2),
            ..step("controller", &self.log)
        }
    }
    fn driver(&mut self) -> impl stage::Behavior {
        step("driver", &self.log)
    }
    fn spare(&mut self) -> impl stage::Behavior {
        step("spare", &self.log)
    }
}

#[test]
fn a_generated_compound_runs_its_thread_group_and_substitutes_a_failed_member() {
    let log = Log::default();
    let (mut system, clock) = system();
    let control = control_loop::component("control", LoopParts { log: log.clone() })
        .expect("the description's group builds");
    system.add(control).expect("control");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    // Grouped as `driver, controller, estimator, imu`, run in data-flow order: the
    // chain goes through in one pass. `driver`'s period is twice the others'.
    tick(&clock);
    assert_eq!(log.take(), ["imu:1", "estimator:2", "controller:3"]);
    clock.advance(PERIOD).expect("settled");
    // The controller panics in its second period; `driver` reads its last packet.
    assert_eq!(log.take(), ["imu:1", "estimator:2", "driver:4"]);
    let controller = system.handle_at("control.controller").expect("controller");
    let monitor = controller.snapshot();
    assert_eq!(monitor.state, State::RunningError, "{monitor:?}");
    assert!(
        monitor
            .error
            .as_deref()
            .is_some_and(|e| e.contains("controller broke")),
        "{monitor:?}"
    );
    // `spare` takes the controller's place, on its own thread, fed by `estimator` and
    // feeding `driver`, which stay on the group's thread.
    let mut ticks = 0;
    while !log.take().contains(&"spare:3".to_owned()) {
        tick(&clock);
        ticks += 1;
        assert!(
            ticks < 10,
            "no substitution: {:?}",
            system.handle("control")
        );
    }
    assert_eq!(
        system.handle("control").expect("control").state(),
        State::Running
    );
    // Two periods: `driver` runs in one of them, reading what `spare` sent.
    tick(&clock);
    tick(&clock);
    let mut lines = log.take();
    lines.sort();
    assert_eq!(
        lines,
        [
            "driver:4",
            "estimator:2",
            "estimator:2",
            "imu:1",
            "imu:1",
            "spare:3",
            "spare:3"
        ]
    );
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

/// The parts of `LastLoop`: both stages log into `log`.
struct PingPong {
    log: Log,
}

impl last_loop::Supervisor for Quiet {}

impl last_loop::Parts for PingPong {
    fn supervisor(&mut self) -> impl last_loop::Supervisor {
        Quiet
    }
    fn ping(&mut self) -> impl stage::Behavior {
        step("ping", &self.log)
    }
    fn pong(&mut self) -> impl stage::Behavior {
        step("pong", &self.log)
    }
}

#[test]
fn a_cycle_that_coolc_accepts_the_runtime_runs() {
    let log = Log::default();
    let (mut system, clock) = system();
    let both = last_loop::component("both", PingPong { log: log.clone() })
        .expect("a cycle through `last` inputs builds");
    system.add(both).expect("both");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    // Written `pong, ping`, connected both ways through `last` inputs: no data-flow
    // order, so the order written; each reads what the other sent before.
    tick(&clock);
    assert_eq!(log.take(), ["pong:1", "ping:2"]);
    tick(&clock);
    assert_eq!(log.take(), ["pong:3", "ping:4"]);
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
}

/// Set aside only on the cycle: with `c -> r -> c` (into `c`'s `last` input) and `r`
/// also feeding `d`'s `last` input, `d` runs after `r` though it is given first.
#[test]
fn a_last_input_off_the_cycle_keeps_its_order() {
    let log = Log::default();
    let (mut system, clock) = system();
    system
        .add(stage::component("d", step("d", &log)))
        .expect("d");
    system
        .add(relay::component("r", hop("r", &log)))
        .expect("r");
    system
        .add(stage::component("c", step("c", &log)))
        .expect("c");
    system.connect("c.out", "r.feed").expect("c -> r");
    system.connect("r.out", "c.feed").expect("r -> c");
    system.connect("r.out", "d.feed").expect("r -> d");
    system.group("g", &["d", "r", "c"]).expect("group");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    tick(&clock);
    // `d` reads what `r` sent in this very pass.
    assert_eq!(log.take(), ["c:1", "r:2", "d:3"]);
}

/// `Checker`'s behaviour: takes its samples each period, and raises `stale` when none
/// came since the last; logs `checked:<samples>` or `stale`.
struct Checking(Log);

impl checker::Behavior for Checking {
    fn checking_periodic(&mut self, cx: &mut checker::Cx<'_>) -> SectionResult {
        let mut samples = 0;
        while cx.inputs.samples.recv().is_some() {
            samples += 1;
        }
        if samples == 0 {
            self.0.push("stale".to_owned());
            return Err(checker::Exception::Stale.raise("no sample since the last period"));
        }
        cx.vars.taken += samples;
        self.0.push(format!("checked:{samples}"));
        Ok(())
    }

    fn on_stale(&mut self, _cx: &mut checker::Cx<'_>, _message: &str) {}
}

/// `Sampler`'s behaviour: one sample a period.
struct Sampling;

impl sampler::Behavior for Sampling {
    fn sampling_periodic(&mut self, cx: &mut sampler::Cx<'_>) -> SectionResult {
        cx.outputs.sample.send(1);
        Ok(())
    }
}

/// A member's `retry` does not hold the group's thread: the checker (10 ms) finds no
/// sample every other period, and its retry a period later finds the one the sampler
/// (20 ms), another member, sent meanwhile. On a thread the retry would sleep and
/// the sampler could not run: the checker would fail.
#[test]
fn a_members_retry_waits_while_the_other_members_run() {
    let log = Log::default();
    let (mut system, clock) = system();
    let checking = system
        .add(checker::component("checker", Checking(log.clone())))
        .expect("checker");
    system
        .add(sampler::component("sampler", Sampling))
        .expect("sampler");
    system
        .connect("sampler.sample", "checker.samples")
        .expect("sampler -> checker");
    system
        .group("control", &["sampler", "checker"])
        .expect("group");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    for _ in 0..6 {
        tick(&clock);
    }
    // At 10 ms no sample yet: `stale`, retried at 20 ms after the sampler's first
    // sample; the deadline at 20 ms the retry took is missed (as it is on a thread of
    // its own, where the retry sleeps); so on at 30 and 40, 50 and 60.
    assert_eq!(
        log.take(),
        [
            "stale",
            "checked:1",
            "stale",
            "checked:1",
            "stale",
            "checked:1"
        ],
        "{}",
        checking.snapshot()
    );
    let monitor = checking.snapshot();
    assert_eq!(monitor.state, State::Running, "{monitor}");
    assert_eq!(monitor.variables[0].1, coolbot::Value::UInt(3));
    assert_eq!(monitor.missed_deadlines, 3, "{monitor}");
    assert!(system.shutdown().clean());
}

/// `Latch`'s behaviour: each section with a sample to take logs it, and one without
/// raises `stale`, logging `<section>:stale`.
struct Latching(Log);

impl Latching {
    fn take(&self, section: &str, cx: &mut latch::Cx<'_>) -> SectionResult {
        match cx.inputs.samples.recv() {
            Some(sample) => {
                self.0.push(format!("{section}:{sample}"));
                Ok(())
            }
            None => {
                self.0.push(format!("{section}:stale"));
                Err(latch::Exception::Stale.raise("no sample yet"))
            }
        }
    }
}

impl latch::Behavior for Latching {
    fn opening_entry(&mut self, cx: &mut latch::Cx<'_>) -> SectionResult {
        self.take("entry", cx)
    }

    fn opening_exit(&mut self, cx: &mut latch::Cx<'_>) -> SectionResult {
        self.take("exit", cx)
    }

    fn open_entry(&mut self, _cx: &mut latch::Cx<'_>) -> SectionResult {
        self.0.push("open".to_owned());
        Ok(())
    }

    fn on_stale(&mut self, _cx: &mut latch::Cx<'_>, _message: &str) {}
}

/// Nor does a `retry` of an entry or an exit section: the latch's entry finds its
/// sample at 20 ms, once the sampler (20 ms), another member, sent it; its exit, due
/// at once (`after 5ms`), finds the next one at 40 ms; nothing else of the latch runs
/// meanwhile. On a thread the retries would sleep and the sampler could not run: the
/// latch would fail on entering its first state.
#[test]
fn a_members_entry_and_exit_retries_wait_while_the_other_members_run() {
    let log = Log::default();
    let (mut system, clock) = system();
    let latching = system
        .add(latch::component("latch", Latching(log.clone())))
        .expect("latch");
    system
        .add(sampler::component("sampler", Sampling))
        .expect("sampler");
    system
        .connect("sampler.sample", "latch.samples")
        .expect("sampler -> latch");
    system
        .group("control", &["latch", "sampler"])
        .expect("group");
    system.run_all().expect("running");
    clock.settle().expect("settled");
    let steps: [&[&str]; 5] = [
        &["entry:stale"],
        &["entry:stale"],
        &["entry:1", "exit:stale"],
        &["exit:stale"],
        &["exit:1", "open"],
    ];
    for (at, expected) in steps.iter().enumerate() {
        if at > 0 {
            tick(&clock);
        }
        assert_eq!(
            log.take(),
            *expected,
            "at {} ms: {}",
            at * 10,
            latching.snapshot()
        );
        let monitor = latching.snapshot();
        assert_eq!(monitor.state, State::Running, "{monitor}");
    }
    let monitor = latching.snapshot();
    assert_eq!(monitor.user_state.as_deref(), Some("open"), "{monitor}");
    assert!(system.shutdown().clean());
}
