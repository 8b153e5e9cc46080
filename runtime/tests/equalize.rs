//! Equalization (paper 3.6, `coolbot::equalize`): two periodic components with the same
//! period, started in phase on one core, coincide every period until one of them moves
//! its phase into the other's valley. The test shows the move happen, once, by one of
//! them, naming the other, and nothing move with equalization off; the lateness before
//! and after is measured by `benches/equalize.rs` (timings stay out of tests).
//!
//! One test, both cases in turn: they pin their threads to the same core.
#![cfg(target_os = "linux")]

mod equalize_common;

use std::time::{Duration, Instant};

use coolbot::adapt::{AdaptAction, Adaptation};
use coolbot::{MonitorEvent, System};
use equalize_common::{PERIOD, Starts, count, pin_to_one_core, spinner};

/// Run the pair with `equalize` until `done` says so over the `Equalized` steps seen
/// (index of the component, step) and the sections run; every step seen.
fn run_pair(
    equalize: bool,
    done: impl Fn(&[(usize, Adaptation)], [usize; 2]) -> bool,
) -> Vec<(usize, Adaptation)> {
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
        for (index, receiver) in events.iter().enumerate() {
            for event in receiver.try_iter() {
                if let MonitorEvent::Adaptation(step) = event
                    && step.action == AdaptAction::Equalized
                {
                    steps.push((index, step));
                }
            }
        }
        let sections = [count(&starts[0]), count(&starts[1])];
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

    // On: one of them moves, naming the other; 50 sections after the move, it was the
    // only move.
    let steps = run_pair(true, |steps, sections| {
        !steps.is_empty() && sections.iter().all(|n| *n >= 50)
    });
    let (moved, step) = &steps[0];
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
    assert_eq!(steps.len(), 1, "more than one move: {steps:?}");
}
