//! Adaptation inside compounds (paper 3.6, Figures 6 and 7): the supervisor degrades
//! its instances within a homogeneity interval, selects whom to degrade, raises its
//! current maximum level at the top, notifies its own supervisor when nested, and
//! promotes back from the top when time is spare. On a virtual clock: the work is time
//! the sections take of it (`Context::spend`, see `coolbot_runtime_tests::adapt`), so
//! every verdict, step and order is the same on every run and every machine.

use coolbot::adapt::AdaptAction;
use coolbot::{Command, CompoundBuilder, MonitorEvent, Pressure};
use coolbot_runtime_tests::adapt::{self, Load, check_homogeneity, member, moves, ms};
use coolbot_runtime_tests::supervision::Coordinating;

const HEAVY: [u64; 3] = [45, 25, 25];
const LIGHT: [u64; 3] = [1, 1, 1];

fn adaptation_steps(
    events: &coolbot::crossbeam_channel::Receiver<MonitorEvent>,
) -> Vec<coolbot::Adaptation> {
    events
        .try_iter()
        .filter_map(|event| match event {
            MonitorEvent::Adaptation(step) => Some(step),
            _ => None,
        })
        .collect()
}

/// `b` (priority -1, the most urgent) runs out of time; `a` (-5) and `c` (-3) do not.
/// The supervisor degrades `b` first (it violates), then, as `b` is at the current
/// maximum level, the others by priority (`a` before `c`), then raises the level; so
/// on until `b` fits. When the load drops, all come back to nominal.
#[test]
fn a_compound_degrades_within_its_homogeneity_interval_and_promotes_back() {
    let heavy = Load::new();
    heavy.set(HEAVY);
    let light = Load::new();
    light.set(LIGHT);
    let group = CompoundBuilder::new("group", Coordinating)
        .instance(member("a", -5, &light))
        .instance(member("b", -1, &heavy))
        .instance(member("c", -3, &light))
        .build()
        .expect("build");
    let (mut system, clock) = adapt::on_virtual_clock();
    let group = system.add(group).expect("add");
    let events = group.subscribe();
    system.run_all().expect("run");
    let b = group.instance("b").expect("b");

    let monitor = adapt::step_until(&clock, &b, "b fits at the bottom of its ladder", |m| {
        m.adaptation.level == 4
    });
    assert_eq!((monitor.period, monitor.quality), (Some(ms(40)), 1));
    let mut steps = adaptation_steps(&events);
    // Properties rather than one exact order (a late wake-up on a loaded machine can
    // make a light member violate too): b, the violator, is degraded first; the
    // others follow before the cap is raised (`check_homogeneity`: every member at
    // the cap before it rises); the cap rose to b's top.
    let degraded: Vec<_> = steps
        .iter()
        .filter(|s| s.action == AdaptAction::Degraded)
        .map(|s| (s.component.as_str(), s.to))
        .collect();
    assert_eq!(degraded.first(), Some(&("b", 1)), "{steps:#?}");
    for name in ["a", "c"] {
        assert!(
            degraded.contains(&(name, 1)),
            "{name} degraded too: {degraded:?}"
        );
    }
    let raised: Vec<_> = steps
        .iter()
        .filter(|s| s.action == AdaptAction::CapRaised)
        .map(|s| s.to)
        .collect();
    assert_eq!(raised, [2, 3, 4], "{steps:#?}");
    let levels = check_homogeneity("group", &["a", "b", "c"], 4, &steps);
    assert_eq!(levels[1], 4);
    // The instances applied what their supervisor asked (through their control
    // ports): their own histories say so.
    let a = group.instance("a").expect("a").snapshot();
    assert_eq!(a.adaptation.level, levels[0]);
    assert_eq!(
        a.adaptation.history.last().map(|s| s.detail.as_str()),
        Some("commanded by its supervisor")
    );

    // The load drops: everyone back to nominal, through the interval.
    heavy.set(LIGHT);
    for name in ["a", "b", "c"] {
        let handle = group.instance(name).expect("instance");
        let monitor = adapt::step_until(&clock, &handle, "nominal", |m| m.adaptation.level == 0);
        assert_eq!(
            (monitor.period, monitor.quality),
            (Some(ms(10)), 0),
            "{name}"
        );
    }
    let monitor = adapt::step_until(&clock, &group, "floor 0", |m| m.adaptation.floor == 0);
    assert!(monitor.adaptation.level <= 1);
    steps.extend(adaptation_steps(&events));
    assert_eq!(
        check_homogeneity("group", &["a", "b", "c"], 4, &steps),
        [0, 0, 0]
    );
    assert!(
        steps.iter().any(|s| s.action == AdaptAction::FloorLowered),
        "promotion lowers the floor from the top"
    );
    // No promotion while b was still violating on its way down: promotions wait for
    // the violations to settle.
    let b_at_top = steps
        .iter()
        .position(|s| s.component == "b" && s.action == AdaptAction::Degraded && s.to == 4)
        .expect("b degraded to 4");
    let first_promoted = steps
        .iter()
        .position(|s| s.action == AdaptAction::Promoted)
        .expect("promotions");
    assert!(b_at_top < first_promoted, "{steps:#?}");
    assert!(system.shutdown().clean());
}

/// A compound inside a compound: the inner one may not degrade its instances beyond
/// the level its supervisor granted (0 at first): it notifies higher, the outer one
/// (the top) grants it a level (degrading it like any instance), raising its own cap
/// when every instance is at it. Promotion comes back down the same way.
#[test]
fn a_nested_compound_notifies_its_supervisor_which_grants_levels() {
    let heavy = Load::new();
    heavy.set(HEAVY);
    let light = Load::new();
    light.set(LIGHT);
    let inner = CompoundBuilder::new("inner", Coordinating)
        .instance(member("x", -1, &heavy))
        .instance(member("y", -2, &light))
        .build()
        .expect("inner");
    let outer = CompoundBuilder::new("outer", Coordinating)
        .instance(inner)
        .instance(member("z", -3, &light))
        .build()
        .expect("outer");
    let (mut system, clock) = adapt::on_virtual_clock();
    let outer = system.add(outer).expect("add");
    let outer_events = outer.subscribe();
    system.run_all().expect("run");
    let inner = outer.instance("inner").expect("inner");
    let x = outer.instance("inner.x").expect("x");
    assert_eq!(inner.snapshot().adaptation.max_level, 4);

    adapt::step_until(&clock, &x, "x at the bottom of its ladder", |m| {
        m.adaptation.level == 4
    });
    let inner_monitor = inner.snapshot();
    assert_eq!(inner_monitor.adaptation.level, 4, "granted by outer");
    let inner_history = &inner_monitor.adaptation.history;
    assert!(
        inner_history
            .iter()
            .any(|s| s.action == AdaptAction::NotifiedHigher && s.component == "inner"),
        "{inner_history:#?}"
    );
    let steps = adaptation_steps(&outer_events);
    // The outer supervisor's first move: grant the violating inner compound level 1
    // (the inner one had notified higher).
    assert!(
        moves(&steps).contains(&("inner".to_owned(), AdaptAction::Degraded, 0, 1)),
        "{steps:#?}"
    );
    // z never violated, yet was degraded to keep the interval homogeneous before the
    // cap was raised.
    assert!(moves(&steps).contains(&("z".to_owned(), AdaptAction::Degraded, 0, 1)));
    check_homogeneity("outer", &["inner", "z"], 4, &steps);

    heavy.set(LIGHT);
    for path in ["inner.x", "inner.y", "z"] {
        let handle = outer.instance(path).expect(path);
        adapt::step_until(&clock, &handle, path, |m| m.adaptation.level == 0);
    }
    let inner_monitor = adapt::step_until(&clock, &inner, "inner granted nothing", |m| {
        m.adaptation.level == 0
    });
    assert!(
        inner_monitor
            .adaptation
            .history
            .iter()
            .any(|s| s.action == AdaptAction::ReportedSpare),
        "{:#?}",
        inner_monitor.adaptation.history
    );
    assert_ne!(inner_monitor.adaptation.pressure, Pressure::Violation);
    assert!(system.shutdown().clean());
}

/// When even the highest level is not enough, the top-level supervisor reconfigures:
/// with `SuspendLowestPriority` it suspends the least urgent instance (never one as
/// urgent as the violator), then reports exhaustion; when time is spare again, the
/// suspended instance is resumed first, then everyone is promoted.
#[test]
fn exhausted_degradation_suspends_the_lowest_priority_instance_until_time_is_spare() {
    let hopeless = Load::new();
    hopeless.set([45, 45, 45]);
    let light = Load::new();
    light.set(LIGHT);
    let group = CompoundBuilder::new("group", Coordinating)
        .instance(member("hi", -1, &hopeless))
        .instance(member("lo", -4, &light))
        .adaptation(coolbot::AdaptConfig {
            reconfiguration: coolbot::Reconfiguration::SuspendLowestPriority,
            ..coolbot::AdaptConfig::default()
        })
        .build()
        .expect("build");
    let (mut system, clock) = adapt::on_virtual_clock();
    let group = system.add(group).expect("add");
    let events = group.subscribe();
    system.run_all().expect("run");
    let lo = group.instance("lo").expect("lo");

    // (The step is published before the turn's verdict: wait for both.)
    adapt::step_until(&clock, &group, "exhausted, under a time violation", |m| {
        m.adaptation
            .history
            .iter()
            .any(|s| s.action == AdaptAction::Exhausted)
            && m.adaptation.pressure == Pressure::Violation
    });
    // (The suspension is queued at lo's control port; it takes it between sections.)
    adapt::step_until(&clock, &lo, "lo suspended", |m| {
        m.state == coolbot::State::Suspended
    });
    let steps = adaptation_steps(&events);
    let reconfiguration: Vec<_> = steps
        .iter()
        .filter(|s| matches!(s.action, AdaptAction::Suspended | AdaptAction::Exhausted))
        .map(|s| (s.component.as_str(), s.action))
        .collect();
    assert_eq!(
        reconfiguration,
        [
            ("lo", AdaptAction::Suspended),
            ("group", AdaptAction::Exhausted)
        ]
    );
    // Suspended only at the end: both were at the top of their ladders first.
    let levels = check_homogeneity("group", &["hi", "lo"], 4, &steps);
    assert_eq!(levels, [4, 4]);

    hopeless.set(LIGHT);
    adapt::step_until(&clock, &lo, "lo resumed and promoted", |m| {
        m.state == coolbot::State::Running && m.adaptation.level == 0
    });
    let hi = group.instance("hi").expect("hi");
    adapt::step_until(&clock, &hi, "hi promoted", |m| m.adaptation.level == 0);
    let steps = adaptation_steps(&events);
    let resumed = steps
        .iter()
        .position(|s| s.action == AdaptAction::Resumed && s.component == "lo")
        .expect("lo resumed");
    let promoted = steps
        .iter()
        .position(|s| s.action == AdaptAction::Promoted)
        .expect("promotions");
    assert!(
        resumed < promoted,
        "resumed before any promotion: {steps:#?}"
    );
    assert!(system.shutdown().clean());
}

/// A compound with adaptation off: its instances detect and publish their verdicts,
/// nothing acts on them (neither the compound nor the instances themselves).
#[test]
fn a_compound_with_adaptation_off_leaves_its_instances_alone() {
    let heavy = Load::new();
    heavy.set(HEAVY);
    let group = CompoundBuilder::new("group", Coordinating)
        .instance(member("b", -1, &heavy))
        .adaptation(coolbot::AdaptConfig::off())
        .build()
        .expect("build");
    let (system, group, clock) = adapt::running_on_virtual_clock(group);
    let b = group.instance("b").expect("b");
    let monitor = adapt::step_until(&clock, &b, "a violation, published", |m| {
        m.adaptation.pressure == Pressure::Violation
    });
    let runs = heavy.runs();
    adapt::step_until_true(&clock, "five more sections", || heavy.runs() >= runs + 5);
    let monitor_now = b.snapshot();
    assert_eq!(monitor_now.adaptation.level, 0);
    assert_eq!(monitor_now.period, monitor.period);
    assert!(monitor_now.adaptation.history.is_empty());
    let compound = group.snapshot();
    assert!(!compound.adaptation.enabled);
    assert!(compound.adaptation.history.is_empty());
    let rejected = group.command(Command::SetDegradation(1)).unwrap_err();
    assert_eq!(rejected.reason, "adaptation is off in this compound");
    assert!(system.shutdown().clean());
}

/// Who owns an instance's level: what is set on it by other means (a command to the
/// instance, its `degrade` continuity plan step, its own `set_period`) is the
/// instance's, and its supervisor keeps it: neither clamps it to its current maximum
/// level nor promotes it below it (its `min_level`).
#[test]
fn a_quality_or_period_set_on_an_instance_of_a_compound_is_kept() {
    let light = Load::new();
    light.set(LIGHT);
    let group = CompoundBuilder::new("group", Coordinating)
        .instance(member("a", -1, &light))
        .instance(member("b", -2, &light))
        .build()
        .expect("build");
    let (system, group, clock) = adapt::running_on_virtual_clock(group);
    let a = group.instance("a").expect("a");
    let b = group.instance("b").expect("b");
    for handle in [&a, &b] {
        handle
            .wait_state(coolbot::State::Running, adapt::WAIT)
            .expect("running");
    }
    a.command(Command::SetQuality(1)).expect("quality 1");
    // Level 3 is above the compound's current maximum (1).
    b.command(Command::SetPeriod(ms(35))).expect("period 35 ms");
    assert_eq!(a.snapshot().adaptation.min_level, 1);
    assert_eq!(b.snapshot().adaptation.min_level, 3);
    // Both have spare time: the supervisor sees their verdicts (it decides on
    // every change of verdict), and twenty sections more.
    for handle in [&a, &b] {
        adapt::step_until(&clock, handle, "spare time", |m| {
            m.adaptation.pressure == Pressure::Spare
        });
    }
    let runs = light.runs();
    adapt::step_until_true(&clock, "twenty more sections", || light.runs() >= runs + 20);
    let (a_now, b_now) = (a.snapshot(), b.snapshot());
    assert_eq!(
        (a_now.period, a_now.quality, a_now.adaptation.level),
        (Some(ms(10)), 1, 1),
        "the compound undid the quality set through a's control port: {:#?}",
        a_now.adaptation.history
    );
    assert_eq!(
        (b_now.period, b_now.quality, b_now.adaptation.level),
        (Some(ms(35)), 0, 3),
        "the compound undid the period set through b's control port: {:#?}",
        b_now.adaptation.history
    );
    let commanded = group
        .snapshot()
        .adaptation
        .history
        .iter()
        .filter(|s| s.component == "a" || s.component == "b")
        .map(ToString::to_string)
        .collect::<Vec<_>>();
    assert!(commanded.is_empty(), "{commanded:#?}");
    assert!(system.shutdown().clean());
}

/// An operator's `SetDegradation` on an instance (`coolctl degrade`) is set by other
/// means too: the compound neither clamps it to its current maximum level nor
/// promotes it back, and the same means move it again (down to 0, releasing it).
#[test]
fn a_degradation_commanded_on_an_instance_of_a_compound_is_kept() {
    let light = Load::new();
    light.set(LIGHT);
    let group = CompoundBuilder::new("group", Coordinating)
        .instance(member("a", -1, &light))
        .build()
        .expect("build");
    let (system, group, clock) = adapt::running_on_virtual_clock(group);
    let a = group.instance("a").expect("a");
    a.wait_state(coolbot::State::Running, adapt::WAIT)
        .expect("running");
    // Level 3 is above the compound's current maximum (1).
    a.command(Command::SetDegradation(3)).expect("level 3");
    let monitor = a.snapshot();
    assert_eq!(
        (monitor.adaptation.level, monitor.adaptation.min_level),
        (3, 3)
    );
    adapt::step_until(&clock, &a, "spare time", |m| {
        m.adaptation.pressure == Pressure::Spare
    });
    let runs = light.runs();
    adapt::step_until_true(&clock, "twenty more sections", || light.runs() >= runs + 20);
    let now = a.snapshot();
    assert_eq!(
        now.adaptation.level, 3,
        "the compound undid the operator's degradation: {:#?}",
        now.adaptation.history
    );
    // The operator releases it: level 0, nothing kept.
    adapt::at_rest(&clock, &light);
    a.command(Command::SetDegradation(0)).expect("level 0");
    let monitor = a.snapshot();
    assert_eq!(
        (monitor.adaptation.level, monitor.adaptation.min_level),
        (0, 0)
    );
    assert!(system.shutdown().clean());
}

/// A designer's selector that answers outside the candidates: its answer is
/// ignored, the default choice taken, and the step says why (no panic in the
/// supervisor).
struct Wrong;

impl coolbot::adapt::Selector for Wrong {
    fn degrade(&self, members: &[coolbot::adapt::Member], _candidates: &[usize]) -> usize {
        members.len() + 3
    }
}

#[test]
fn a_selector_answer_outside_the_candidates_does_not_fail_the_compound() {
    let heavy = Load::new();
    heavy.set(HEAVY);
    let group = CompoundBuilder::new("group", Coordinating)
        .instance(member("b", -1, &heavy))
        .adaptation_selector(Wrong)
        .build()
        .expect("build");
    let (system, group, clock) = adapt::running_on_virtual_clock(group);
    let b = group.instance("b").expect("b");
    adapt::step_until(&clock, &b, "b degraded", |m| m.adaptation.level >= 1);
    let monitor = group.snapshot();
    assert_eq!(monitor.state, coolbot::State::Running, "{monitor:#?}");
    let step = monitor
        .adaptation
        .history
        .iter()
        .find(|s| s.component == "b" && s.action == AdaptAction::Degraded)
        .expect("b's degradation");
    assert!(step.detail.contains("not one of the candidates"), "{step}");
    assert!(system.shutdown().clean());
}

/// Each instance publishes its own settling need (`hold_periods + window + 1`), which
/// the supervisor's settling time covers.
#[test]
fn instances_publish_their_settling_periods() {
    let light = Load::new();
    light.set(LIGHT);
    let group = CompoundBuilder::new("group", Coordinating)
        .instance(
            member("a", -1, &light).with_adaptation(coolbot::AdaptConfig {
                hold_periods: 40,
                ..adapt::quick()
            }),
        )
        .instance(member("b", -1, &light))
        .build()
        .expect("build");
    let (system, group, clock) = adapt::running_on_virtual_clock(group);
    let a = group.instance("a").expect("a");
    let b = group.instance("b").expect("b");
    adapt::step_until(&clock, &a, "running", |m| {
        m.state == coolbot::State::Running
    });
    assert_eq!(a.snapshot().adaptation.settle_periods, 40 + 3 + 1);
    assert_eq!(b.snapshot().adaptation.settle_periods, 2 + 3 + 1);
    assert!(system.shutdown().clean());
}

/// A `degrade` continuity plan step (paper 3.5) in an instance of a compound: the
/// lower quality is the instance's own, and its compound does not revert it when time
/// is spare.
#[test]
fn a_continuity_plan_degradation_is_not_reverted_by_the_compound() {
    let light = Load::new();
    light.set(LIGHT);
    let planned = adapt::planned_sleeper("p", &light).with_adaptation(adapt::quick());
    let group = CompoundBuilder::new("group", Coordinating)
        .instance(planned)
        .instance(member("q", -1, &light))
        .build()
        .expect("build");
    let (system, group, clock) = adapt::running_on_virtual_clock(group);
    let p = group.instance("p").expect("p");
    p.wait_state(coolbot::State::Running, adapt::WAIT)
        .expect("running");
    light.fault.store(true, std::sync::atomic::Ordering::SeqCst);
    let monitor = adapt::step_until(&clock, &p, "the plan's degradation", |m| m.quality == 1);
    assert_eq!(monitor.state, coolbot::State::Running);
    assert_eq!(
        (
            monitor.period,
            monitor.adaptation.level,
            monitor.adaptation.min_level
        ),
        (Some(ms(10)), 1, 1)
    );
    adapt::step_until(&clock, &p, "spare time", |m| {
        m.adaptation.pressure == Pressure::Spare
    });
    let runs = light.runs();
    adapt::step_until_true(&clock, "twenty more sections", || light.runs() >= runs + 20);
    let monitor = p.snapshot();
    assert_eq!(
        (monitor.quality, monitor.adaptation.level),
        (1, 1),
        "{:#?}",
        monitor.adaptation.history
    );
    assert!(
        monitor
            .adaptation
            .history
            .iter()
            .all(|s| s.detail == "a `degrade` continuity plan step"),
        "{:#?}",
        monitor.adaptation.history
    );
    assert!(system.shutdown().clean());
}
