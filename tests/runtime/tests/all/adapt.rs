//! Adaptation of a component no compound supervises (paper 3.6, local level): under
//! time violations it stretches its period step by step within its interval, then
//! lowers its quality; when time is spare again it is promoted back, quality first.
//! On a virtual clock: the work is time the sections take of it (`Context::spend`),
//! set per quality level, so that every verdict and step is the same on every run and
//! every machine (the load profile's test, about CPU time, runs on the real clock).

use std::sync::atomic::Ordering;

use coolbot::adapt::AdaptAction;
use coolbot::{AdaptConfig, Command, MonitorEvent, Pressure, System};
use coolbot_runtime_tests::adapt::{
    Load, at_rest, eventually, fixed_sleeper, moves, ms, on_virtual_clock, quick, sleeper,
    steady_sleeper, step_until, step_until_true,
};
use coolbot_runtime_tests::generated::adapt_sleeper;

/// At quality 0 the section sleeps 45 ms (longer than the longest period, 40 ms), at
/// quality 1 25 ms (within 40 ms, and not spare at ratio 0.5).
const HEAVY: [u64; 3] = [45, 25, 25];
const LIGHT: [u64; 3] = [1, 1, 1];

#[test]
fn a_standalone_component_degrades_frequency_then_quality_and_is_promoted_back() {
    let load = Load::new();
    load.set(HEAVY);
    let (mut system, clock) = on_virtual_clock();
    let handle = system
        .add(sleeper("s", &load).with_adaptation(quick()))
        .expect("add");
    let events = handle.subscribe();
    system.run_all().expect("run");

    // Degraded to the bottom of the ladder: 40 ms and quality 1.
    let monitor = step_until(&clock, &handle, "fully degraded", |m| {
        m.adaptation.level == 4
    });
    assert_eq!(monitor.period, Some(ms(40)));
    assert_eq!(monitor.quality, 1);
    assert_eq!(monitor.adaptation.max_level, 4);
    assert!(monitor.adaptation.enabled);
    let degraded: Vec<_> = monitor
        .adaptation
        .history
        .iter()
        .filter(|step| step.action == AdaptAction::Degraded)
        .map(|step| (step.to, step.period, step.quality))
        .collect();
    // Frequency first, in equal steps within [10 ms, 40 ms], then quality.
    assert_eq!(
        degraded,
        [
            (1, Some(ms(20)), Some(0)),
            (2, Some(ms(30)), Some(0)),
            (3, Some(ms(40)), Some(0)),
            (4, Some(ms(40)), Some(1)),
        ]
    );
    // The section itself saw the changes through its context.
    step_until_true(&clock, "a section at quality 1", || {
        load.lowest_quality.load(Ordering::SeqCst) == 1
    });
    assert_eq!(load.longest_period.load(Ordering::SeqCst), 40_000);

    // Stable at the bottom: ten more sections, and no promotion probe (25 ms of 40
    // is not spare at ratio 0.5), nor any other step.
    let runs = load.runs();
    step_until_true(&clock, "ten more sections", || load.runs() >= runs + 10);
    let monitor = handle.snapshot();
    assert_eq!(monitor.adaptation.level, 4);
    assert!(
        monitor
            .adaptation
            .history
            .iter()
            .all(|step| step.action == AdaptAction::Degraded),
        "{:#?}",
        monitor.adaptation.history
    );

    // The load drops: promoted back to nominal one level at a time, quality first,
    // each level with its own period.
    load.set(LIGHT);
    let monitor = step_until(&clock, &handle, "back to nominal", |m| {
        m.adaptation.level == 0
    });
    assert_eq!(monitor.period, Some(ms(10)));
    assert_eq!(monitor.quality, 0);
    let steps: Vec<_> = monitor
        .adaptation
        .history
        .iter()
        .map(|step| (step.action, step.from, step.to, step.period, step.quality))
        .collect();
    let (degraded, promoted) = (AdaptAction::Degraded, AdaptAction::Promoted);
    assert_eq!(
        steps,
        [
            (degraded, 0, 1, Some(ms(20)), Some(0)),
            (degraded, 1, 2, Some(ms(30)), Some(0)),
            (degraded, 2, 3, Some(ms(40)), Some(0)),
            (degraded, 3, 4, Some(ms(40)), Some(1)),
            (promoted, 4, 3, Some(ms(40)), Some(0)),
            (promoted, 3, 2, Some(ms(30)), Some(0)),
            (promoted, 2, 1, Some(ms(20)), Some(0)),
            (promoted, 1, 0, Some(ms(10)), Some(0)),
        ]
    );
    for step in &monitor.adaptation.history {
        let (period, _) = ladder_setting(step.to);
        assert_eq!(step.period, period, "the period of its level: {step}");
    }
    step_until_true(&clock, "a section at 10 ms again", || {
        load.last_period.load(Ordering::SeqCst) == 10_000
    });

    // Every step was announced on the monitoring port, with the period and quality
    // changes it made, and the verdicts that led to it.
    let events: Vec<_> = events.try_iter().collect();
    let steps = events
        .iter()
        .filter(|e| {
            matches!(e, MonitorEvent::Adaptation(step)
                if matches!(step.action, AdaptAction::Degraded | AdaptAction::Promoted))
        })
        .count();
    assert_eq!(steps, moves(&monitor.adaptation.history).len());
    assert!(events.contains(&MonitorEvent::Period(Some(ms(40)))));
    assert!(events.contains(&MonitorEvent::Quality(1)));
    assert!(events.contains(&MonitorEvent::Pressure(Pressure::Violation)));
    assert!(events.contains(&MonitorEvent::Pressure(Pressure::Spare)));
    assert!(system.shutdown().clean());
}

#[test]
fn a_member_of_an_execution_group_degrades_and_is_promoted_back_on_the_groups_thread() {
    let (load, other) = (Load::new(), Load::new());
    load.set(HEAVY);
    other.set(LIGHT);
    let (mut system, clock) = on_virtual_clock();
    let handle = system
        .add(sleeper("s", &load).with_adaptation(quick()))
        .expect("add s");
    let steady = system.add(steady_sleeper("t", &other)).expect("add t");
    system.group("pair", &["s", "t"]).expect("the group");
    system.run_all().expect("run");

    // The member's ladder, its detector and its level work as on a thread of its own:
    // down to 40 ms and quality 1, which its section sees.
    let monitor = step_until(&clock, &handle, "fully degraded", |m| {
        m.adaptation.level == 4
    });
    assert_eq!(monitor.group.map(|g| g.name), Some("pair".to_owned()));
    assert_eq!((monitor.period, monitor.quality), (Some(ms(40)), 1));
    step_until_true(&clock, "a section at quality 1", || {
        load.lowest_quality.load(Ordering::SeqCst) == 1
    });
    // The other member, with nothing to degrade, keeps its period and runs on.
    let runs = other.runs();
    step_until_true(&clock, "the other member runs on", || {
        other.runs() >= runs + 5
    });
    assert_eq!(steady.snapshot().period, Some(ms(10)));
    assert_eq!(steady.snapshot().adaptation.level, 0);

    // The load drops: promoted back to nominal.
    load.set(LIGHT);
    let monitor = step_until(&clock, &handle, "back to nominal", |m| {
        m.adaptation.level == 0
    });
    assert_eq!((monitor.period, monitor.quality), (Some(ms(10)), 0));
    step_until_true(&clock, "a section at 10 ms again", || {
        load.last_period.load(Ordering::SeqCst) == 10_000
    });
    assert!(system.shutdown().clean());
}

/// The period of `level` on `AdaptSleeper`'s nominal path (3 period steps).
fn ladder_setting(level: u32) -> (Option<std::time::Duration>, usize) {
    coolbot::adapt::Ladder::new(&adapt_sleeper::SPEC.timing, 3).setting(level)
}

#[test]
fn adaptation_turned_off_leaves_period_and_quality_alone() {
    let load = Load::new();
    load.set(HEAVY);
    let (mut system, clock) = on_virtual_clock();
    let handle = system
        .add(sleeper("s", &load).with_adaptation(AdaptConfig::off()))
        .expect("add");
    system.run_all().expect("run");
    step_until_true(&clock, "ten sections", || load.runs() >= 10);
    let monitor = step_until(&clock, &handle, "missed deadlines", |m| {
        m.missed_deadlines >= 5
    });
    assert_eq!(monitor.period, Some(ms(10)));
    assert_eq!(monitor.quality, 0);
    assert!(!monitor.adaptation.enabled);
    assert_eq!(monitor.adaptation.pressure, Pressure::Nominal);
    assert!(monitor.adaptation.history.is_empty());
    // The ladder is still there for the control port (the work stops, so that the
    // component is at rest between two sections when it is commanded).
    load.set([0, 0, 0]);
    at_rest(&clock, &load);
    handle
        .command(Command::SetDegradation(2))
        .expect("level 2 of 4");
    let monitor = handle.snapshot();
    assert_eq!(monitor.period, Some(ms(30)));
    assert_eq!(monitor.adaptation.level, 2);
    assert!(system.shutdown().clean());
}

#[test]
fn without_a_period_interval_adaptation_is_off_unless_asked_and_then_uses_quality_only() {
    let load = Load::new();
    load.set([15, 1, 1]);
    let (mut system, clock) = on_virtual_clock();
    let default = system.add(fixed_sleeper("d", &load)).expect("add");
    let asked = system
        .add(fixed_sleeper("a", &load).with_adaptation(AdaptConfig {
            enabled: Some(true),
            // Never spare: no promotion probe back to quality 0.
            spare_ratio: 0.0,
            ..quick()
        }))
        .expect("add");
    system.run_all().expect("run");
    let monitor = step_until(&clock, &asked, "quality lowered", |m| {
        m.adaptation.level == 1
    });
    assert_eq!(monitor.quality, 1);
    assert_eq!(
        monitor.period,
        Some(ms(10)),
        "no period interval: no period step"
    );
    assert!(monitor.adaptation.enabled);
    // The other one, same work, same spec, default settings: off.
    let monitor = step_until(&clock, &default, "missed deadlines", |m| {
        m.missed_deadlines >= 5
    });
    assert!(!monitor.adaptation.enabled);
    assert_eq!(monitor.adaptation.max_level, 1);
    assert_eq!((monitor.quality, monitor.adaptation.level), (0, 0));
    assert!(system.shutdown().clean());
}

#[test]
fn set_degradation_goes_through_the_ladder_and_rejects_what_is_not_on_it() {
    let load = Load::new();
    load.set(LIGHT);
    let (mut system, clock) = on_virtual_clock();
    let handle = system
        .add(sleeper("s", &load).with_adaptation(AdaptConfig::off()))
        .expect("add");
    let fixed = system.add(steady_sleeper("f", &load)).expect("add");
    system.run_all().expect("run");
    at_rest(&clock, &load);
    handle.command(Command::SetDegradation(4)).expect("level 4");
    let monitor = handle.snapshot();
    assert_eq!((monitor.period, monitor.quality), (Some(ms(40)), 1));
    at_rest(&clock, &load);
    handle.command(Command::SetDegradation(1)).expect("level 1");
    let monitor = handle.snapshot();
    assert_eq!((monitor.period, monitor.quality), (Some(ms(20)), 0));
    assert_eq!(
        moves(&monitor.adaptation.history),
        [
            ("s".to_owned(), AdaptAction::Degraded, 0, 4),
            ("s".to_owned(), AdaptAction::Promoted, 4, 1),
        ]
    );
    at_rest(&clock, &load);
    let rejected = handle.command(Command::SetDegradation(5)).unwrap_err();
    assert_eq!(
        rejected.reason,
        "degradation level 5 out of range: the highest is 4"
    );
    at_rest(&clock, &load);
    let rejected = fixed.command(Command::SetDegradation(1)).unwrap_err();
    assert!(
        rejected.reason.starts_with("no adaptation levels"),
        "{rejected}"
    );
    // A period set by other means moves the level with it.
    at_rest(&clock, &load);
    handle.command(Command::SetPeriod(ms(35))).expect("period");
    assert_eq!(handle.snapshot().adaptation.level, 3);
    at_rest(&clock, &load);
    handle.command(Command::SetQuality(1)).expect("quality");
    let monitor = handle.snapshot();
    assert_eq!(monitor.adaptation.level, 4);
    let last: Vec<_> = monitor.adaptation.history[2..]
        .iter()
        .map(|step| (step.action, step.from, step.to, step.detail.as_str()))
        .collect();
    assert_eq!(
        last,
        [
            (
                AdaptAction::Degraded,
                1,
                3,
                "period set through the control port or by the component"
            ),
            (
                AdaptAction::Degraded,
                3,
                4,
                "quality set through the control port"
            ),
        ]
    );
    assert!(system.shutdown().clean());
}

#[test]
fn the_load_profile_tells_computing_from_waiting() {
    let sleeping = Load::new();
    sleeping.set([4, 4, 4]);
    let spinning = Load::new();
    spinning.set([4, 4, 4]);
    spinning.spin.store(true, Ordering::SeqCst);
    let mut system = System::new();
    let waiter = system
        .add(sleeper("sleeps", &sleeping).with_adaptation(quick()))
        .expect("add");
    let computer = system
        .add(sleeper("spins", &spinning).with_adaptation(quick()))
        .expect("add");
    system.run_all().expect("run");
    eventually("fifty sections each", || {
        sleeping.runs() >= 50 && spinning.runs() >= 50
    });
    let (sleeps, spins) = (waiter.snapshot(), computer.snapshot());
    // Both spend about 40 % of their period in their section ...
    assert!(sleeps.adaptation.load > 0.2, "{:?}", sleeps.adaptation);
    assert!(spins.adaptation.load > 0.2, "{:?}", spins.adaptation);
    // ... but only one computes (how much CPU it gets depends on the machine's load:
    // only the comparison is asserted).
    assert!(spins.adaptation.cpu_share > 0.0, "{:?}", spins.adaptation);
    assert!(
        sleeps.adaptation.cpu_share < spins.adaptation.cpu_share / 2.0,
        "{:?} {:?}",
        sleeps.adaptation,
        spins.adaptation
    );
    assert!(system.shutdown().clean());
}

/// The periods a component published, in order.
fn periods(
    events: &coolbot::crossbeam_channel::Receiver<MonitorEvent>,
) -> Vec<std::time::Duration> {
    events
        .try_iter()
        .filter_map(|e| match e {
            MonitorEvent::Period(Some(p)) => Some(p),
            _ => None,
        })
        .collect()
}

/// A quality set by other means puts the component off the nominal path (a lower
/// quality at a shorter period than the path has): the level is the period's step
/// plus the quality, and promotions move one axis at a time from there, never to a
/// longer period. The quality set is the floor: promotions bring the period back and
/// leave the quality.
#[test]
fn a_quality_set_by_other_means_is_kept_and_promotions_never_lengthen_the_period() {
    let load = Load::new();
    load.set(LIGHT);
    let (mut system, clock) = on_virtual_clock();
    let handle = system
        .add(sleeper("s", &load).with_adaptation(quick()))
        .expect("add");
    system.run_all().expect("run");
    at_rest(&clock, &load);
    handle.command(Command::SetQuality(1)).expect("quality");
    let monitor = handle.snapshot();
    assert_eq!((monitor.period, monitor.quality), (Some(ms(10)), 1));
    assert_eq!(
        (monitor.adaptation.level, monitor.adaptation.min_level),
        (1, 1),
        "10 ms (step 0) at quality 1"
    );
    // Further along: 30 ms, then the quality set again.
    at_rest(&clock, &load);
    handle.command(Command::SetDegradation(3)).expect("level 3");
    assert_eq!(
        (handle.snapshot().period, handle.snapshot().quality),
        (Some(ms(30)), 1),
        "a degradation stretches the period first"
    );
    let events = handle.subscribe();
    // Spare time: promoted to the floor, the period shortening at every step.
    let monitor = step_until(&clock, &handle, "promoted to its floor", |m| {
        m.adaptation.level == 1 && m.period == Some(ms(10))
    });
    assert_eq!(monitor.quality, 1, "the quality set is kept");
    let periods = periods(&events);
    assert!(
        periods.windows(2).all(|w| w[1] <= w[0]) && periods.iter().all(|p| *p <= ms(30)),
        "a promotion lengthened the period: {periods:?}"
    );
    assert_eq!(periods.last(), Some(&ms(10)), "{periods:?}");
    // The floor holds: more spare periods, no promotion below it.
    let runs = load.runs();
    step_until_true(&clock, "twenty more sections", || load.runs() >= runs + 20);
    let monitor = handle.snapshot();
    assert_eq!((monitor.adaptation.level, monitor.quality), (1, 1));
    at_rest(&clock, &load);
    let rejected = handle.command(Command::SetDegradation(0)).unwrap_err();
    assert!(rejected.reason.contains("below 1"), "{rejected}");
    // The same means release it.
    at_rest(&clock, &load);
    handle.command(Command::SetQuality(0)).expect("quality 0");
    let monitor = handle.snapshot();
    assert_eq!(
        (monitor.adaptation.level, monitor.adaptation.min_level),
        (0, 0)
    );
    assert!(system.shutdown().clean());
}

/// A quality set by other means at the nominal period leaves the period steps to
/// degrade: a violation stretches the period (it is not exhausted at 10 ms).
#[test]
fn a_quality_set_by_other_means_leaves_the_period_steps_to_degrade() {
    let load = Load::new();
    // 15 ms of work at every quality: too long for 10 ms, fine at 20 ms and more.
    load.set([15, 15, 15]);
    let (mut system, clock) = on_virtual_clock();
    let handle = system
        .add(sleeper("s", &load).with_adaptation(quick()))
        .expect("add");
    system.run_all().expect("run");
    at_rest(&clock, &load);
    handle.command(Command::SetQuality(1)).expect("quality");
    let monitor = step_until(&clock, &handle, "degraded for time", |m| {
        m.adaptation
            .history
            .iter()
            .any(|s| s.action == AdaptAction::Degraded && s.detail == "time violation")
            && m.quality == 1
    });
    assert!(
        monitor.period > Some(ms(10)),
        "exhausted at 10 ms while the interval goes to 40 ms: {:#?}",
        monitor.adaptation.history
    );
    for step in &monitor.adaptation.history {
        assert_ne!(step.action, AdaptAction::Exhausted, "{step}");
        if step.detail == "time violation" && step.from >= 1 {
            // From quality 1, a degradation keeps the quality and stretches the period.
            assert_eq!(step.quality, Some(1), "{step}");
        }
    }
    assert!(system.shutdown().clean());
}

/// Odd settings are made safe: more violations than the window holds still detects
/// (clamped to the window); a huge number of period steps is clamped, and levels are
/// computed, not searched.
#[test]
fn odd_adaptation_settings_are_clamped() {
    let late = Load::new();
    late.set([45, 45, 45]);
    let light = Load::new();
    light.set(LIGHT);
    let (mut system, clock) = on_virtual_clock();
    let strict = system
        .add(sleeper("strict", &late).with_adaptation(AdaptConfig {
            violations: 5,
            window: 4,
            ..quick()
        }))
        .expect("add");
    let fine = system
        .add(sleeper("fine", &light).with_adaptation(AdaptConfig {
            period_steps: u32::MAX,
            ..AdaptConfig::off()
        }))
        .expect("a huge period_steps is not a panic");
    system.run_all().expect("run");
    let monitor = step_until(&clock, &strict, "a violation", |m| m.adaptation.level > 0);
    assert!(monitor.period > Some(ms(10)), "{monitor:#?}");
    let monitor = fine.snapshot();
    let max = monitor.adaptation.max_level;
    assert_eq!(max, coolbot::adapt::MAX_PERIOD_STEPS + 1);
    at_rest(&clock, &light);
    fine.command(Command::SetPeriod(ms(25))).expect("period");
    assert_eq!(fine.snapshot().adaptation.level, max / 2);
    at_rest(&clock, &light);
    fine.command(Command::SetDegradation(max)).expect("the top");
    let monitor = fine.snapshot();
    assert_eq!((monitor.period, monitor.quality), (Some(ms(40)), 1));
    assert!(system.shutdown().clean());
}
