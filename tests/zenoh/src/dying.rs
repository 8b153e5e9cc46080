//! `DyingCell` (`cool/placement.cool`): a counting `Flaky` on the dying station with a
//! local spare, its parts and the registry both nodes use. The tests of a remote
//! instance's death, of the logs while a node is lost, and of `coolctl top`'s steps
//! pane share it.

use coolbot::SectionResult;
use coolbot_zenoh::agent::Registry;

use crate::generated::{dying_cell, flaky};

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
