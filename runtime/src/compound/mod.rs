//! Compound components (paper 3.4, 3.5): local instances, their connections, a
//! supervisor whose rules watch the instances, and the fault policies (propagate,
//! restart, substitute, ignore) with the recovery queue and redundant groups.
//!
//! A compound is built by [`CompoundBuilder::build`] into an ordinary [`Component`]:
//! it runs on its own thread through the same runner, default automaton
//! ([`crate::table::next`]), control and monitoring ports as an atomic component, so
//! nothing outside can tell them apart. Its code is a `Compound` automaton that owns
//! an inner [`System`] with the instances; the runner's compound hooks
//! ([`Automaton::before_running`], [`Automaton::after_transition`],
//! [`Automaton::supervise`], [`Automaton::wake_at`]) let the instances follow the
//! compound's state and let the supervisor react to their monitoring events.
//! `docs/runtime.md` ("Compound components and supervisors") tells the semantics.
//!

//! The module's files, one idea each (no cycles: `component` holds the compound's
//! state; the others add to it):
//!
//! - `supervisor`: the [`Supervisor`] trait user code implements, and [`SupervisorCx`];
//! - `view`: the [`View`] rules read, and the rules themselves;
//! - `builder`: [`CompoundBuilder`], from a description to a [`Component`];
//! - `error`: [`CompoundError`] (building) and the faults of a running compound;
//! - `component`: the compound automaton, its instances, and how they follow its state;
//! - `supervision`: one supervision turn (exports, events, policies, rules);
//! - `wiring`: who stands for each instance, and the connections that follow;
//! - `exports`: the compound's own ports, following the instance ports they stand for;
//! - `faults`: the policies, the restart budget and the recovery queue;
//! - `adaptation`: the supervisor's coordination of its instances' degradation.

use std::time::Duration;

mod adaptation;
mod builder;
mod component;
mod error;
mod exports;
mod faults;
mod supervision;
mod supervisor;
mod view;
mod wiring;

pub use builder::CompoundBuilder;
pub use error::CompoundError;
pub use faults::Policy;
pub use supervisor::{Supervisor, SupervisorCx};
pub use view::View;

#[allow(unused_imports, reason = "named by the documentation of this module")]
use crate::system::Component;
/// The period of a supervisor's `periodic;` sections when neither the state nor the
/// supervisor's `timing` gives one (`docs/language.md`, "The supervisor").
pub const DEFAULT_SUPERVISION_PERIOD: Duration = Duration::from_millis(100);

/// How long a compound waits for one of its instances to leave `starting`.
pub const INSTANCE_START_TIMEOUT: Duration = Duration::from_secs(5);

/// The default restart budget ([`CompoundBuilder::restart_budget`]): at most this many
/// restarts of one instance ...
pub const DEFAULT_RESTARTS: u32 = 5;
/// ... within this window; one more failure in the window propagates.
pub const DEFAULT_RESTART_WINDOW: Duration = Duration::from_secs(10);
/// The default restart backoff ([`CompoundBuilder::restart_backoff`]): the first
/// restart in a window is immediate, the second waits this long, each further one
/// twice as long as the one before ...
pub const DEFAULT_BACKOFF: Duration = Duration::from_millis(10);
/// ... up to this.
pub const DEFAULT_BACKOFF_MAX: Duration = Duration::from_secs(1);

/// A name made `'static` for the compound's assembled `Spec` (leaked once per build).
fn leak_str(text: &str) -> &'static str {
    Box::leak(text.to_owned().into_boxed_str())
}
