//! `DyingCell` (`cool/placement.cool`): a counting `Flaky` on the dying station with a
//! local spare, its parts and the registry both nodes use. The tests of a remote
//! instance's death, of the logs while a node is lost, and of `coolctl top`'s steps
//! pane share it; the tests of a remote instance's death, and of a driver in a
//! process of its own, share the waits for a compound's steps.

use coolbot::{Handle, Monitor, SectionResult, Step, System};
use coolbot_zenoh::agent::Registry;

use crate::generated::{dying_cell, flaky};
use crate::support::PATIENCE;

/// The value of the `u64` variable `name` in `monitor` (0 when it has none).
pub fn counted(monitor: &Monitor, name: &str) -> u64 {
    monitor
        .variables
        .iter()
        .find(|(variable, _)| variable == name)
        .map_or(0, |(_, value)| match value {
            coolbot::Value::UInt(n) => *n,
            _ => 0,
        })
}

/// The steps `compound` has taken about `instance` so far, each with its detail.
pub fn steps(compound: &Handle, instance: &str) -> Vec<(Step, String)> {
    compound
        .snapshot()
        .supervision
        .into_iter()
        .filter(|step| step.instance == instance)
        .map(|step| (step.step, step.detail))
        .collect()
}

/// Waits (at most [`PATIENCE`]) until `compound` has taken a step about `instance`
/// for which `step` holds; the detail of the first such step. Panics with `what` and
/// the steps so far when none comes.
pub fn wait_step(compound: &Handle, instance: &str, step: fn(&Step) -> bool, what: &str) -> String {
    let monitor = compound
        .wait_for(
            |m| {
                m.supervision
                    .iter()
                    .any(|s| s.instance == instance && step(&s.step))
            },
            PATIENCE,
        )
        .unwrap_or_else(|timeout| {
            panic!("{what}: {timeout}; steps {:?}", steps(compound, instance))
        });
    monitor
        .supervision
        .into_iter()
        .find(|s| s.instance == instance && step(&s.step))
        .map(|s| s.detail)
        .unwrap_or_default()
}

/// The cell (`cell`) added to `system`, whose components are all told to run: its
/// remote instance goes through this thread's placer.
pub fn started_cell(system: &mut System) -> Handle {
    let cell = system
        .add(dying_cell::component("cell", Parts).expect("the compound builds"))
        .expect("the cell is added");
    system.run_all().expect("the system runs");
    cell
}

/// `Flaky`'s behaviour: counts its periods.
pub struct Counting;

impl flaky::Behavior for Counting {
    fn going_periodic(&mut self, cx: &mut flaky::Cx<'_>) -> SectionResult {
        cx.vars.periods += 1;
        Ok(())
    }
}

/// The cell's supervisor: nothing of its own.
pub struct Quiet;

impl dying_cell::Supervisor for Quiet {}

/// The cell's parts: two counting `Flaky`s.
pub struct Parts;

impl dying_cell::Parts for Parts {
    fn supervisor(&mut self) -> impl dying_cell::Supervisor {
        Quiet
    }
    fn flaky(&mut self) -> impl flaky::Behavior {
        Counting
    }
    fn spare(&mut self) -> impl flaky::Behavior {
        Counting
    }
}

/// A registry of a counting `Flaky`.
pub fn registry() -> Registry {
    let mut registry = Registry::new();
    flaky::register(&mut registry, |name| flaky::component(name, Counting));
    registry
}
