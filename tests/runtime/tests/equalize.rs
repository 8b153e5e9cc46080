//! Equalization (paper 3.6, `coolbot::equalize`): two periodic components with the same
//! period, started in phase on one core, coincide every period until one of them moves
//! its phase into the other's valley. The test shows the move happen, by one of them,
//! naming the other, no component move again within the hold that follows its move
//! (on a quiet core there is no second move at all; load from other processes on the
//! core may make the sections coincide again later), and nothing move with
//! equalization off; the lateness before
//! and after is measured by `runtime/benches/equalize.rs` (timings stay out of tests).
//!
//! One test, both cases in turn: they pin their threads to the same core.
#![cfg(target_os = "linux")]

use std::time::{Duration, Instant};

use coolbot::adapt::{AdaptAction, Adaptation};
use coolbot::{MonitorEvent, System};
use coolbot_runtime_tests::equalize::{PERIOD, Starts, count, pin_to_one_core, spinner};

/// Run the pair with `equalize` until `done` says so over the `Equalized` steps seen
/// (index of the component, step, the sections each had run when the step was seen)
/// and the sections run; every step seen.
fn run_pair(
    equalize: bool,
    done: impl Fn(&[(usize, Adaptation, [usize; 2])], [usize; 2]) -> bool,
) -> Vec<(usize, Adaptation, [usize; 2])> {
    let starts = [Starts::default(), Starts::default()];
    let mut system = System::new();
    let a = system
        .add(spinner("a", &starts[0], equalize))
        .expect("add a");
    let b = system
        .add(spinner("b", &starts[1], equalize))
        .expect("add b");
    let events = [a.subscribe(), b.subscribe()];
    system.run_all().expect("run");
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut steps = Vec::new();
    loop {
        // (Read before the events: a step is never seen with fewer sections than it
        // came after.)
        let sections = [count(&starts[0]), count(&starts[1])];
        for (index, receiver) in events.iter().enumerate() {
            for event in receiver.try_iter() {
                if let MonitorEvent::Adaptation(step) = event
                    && step.action == AdaptAction::Equalized
                {
                    steps.push((index, step, sections));
                }
            }
        }
        if done(&steps, sections) {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "not done in 30 s: steps {steps:?}, sections {sections:?}"
        );
        std::thread::park_timeout(Duration::from_millis(5));
    }
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
    steps
}

#[test]
fn two_components_in_phase_on_one_core_are_moved_apart_once_unless_turned_off() {
    pin_to_one_core();

    // Off: 50 sections each (the detector acts within 8 periods of a peak when on), no
    // step.
    let steps = run_pair(false, |_, sections| sections.iter().all(|n| *n >= 50));
    assert_eq!(steps, []);

    // On: one of them moves, naming the other; 50 more sections each after the move
    // (beyond the 16-period hold): no other move within the hold.
    let at_move = std::sync::Mutex::new(None::<[usize; 2]>);
    let steps = run_pair(true, |steps, sections| {
        if steps.is_empty() {
            return false;
        }
        let mut at_move = at_move.lock().expect("at move");
        let first = *at_move.get_or_insert(sections);
        sections
            .iter()
            .zip(first)
            .all(|(now, then)| *now >= then + 50)
    });
    let (moved, step, _) = &steps[0];
    let other = ["a", "b"][1 - moved];
    assert_eq!(step.component, ["a", "b"][*moved]);
    assert!(
        step.detail
            .ends_with(&format!("its sections coincided with {other}'s")),
        "{}",
        step.detail
    );
    // Equalization moves a phase, never the level nor the period.
    assert_eq!((step.from, step.to), (0, 0));
    assert_eq!(step.period, Some(PERIOD));
    // A component that moved holds still for `hold_periods` of its periods: its next
    // move comes at least that many sections later (less one: a step is seen up to a
    // section late).
    let hold = coolbot::equalize::EqualizeConfig::default().hold_periods as usize;
    for (later, (index, _, after)) in steps.iter().enumerate() {
        if let Some((_, _, before)) = steps[..later].iter().rev().find(|(i, _, _)| i == index) {
            assert!(
                after[*index] + 1 >= before[*index] + hold,
                "a move within the hold of its component's move before: {steps:?}"
            );
        }
    }
}
