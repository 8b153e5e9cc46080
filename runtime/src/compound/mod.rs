//! Compound components (paper 3.4, 3.5): local instances, their connections, a
//! supervisor whose rules watch the instances, and the fault policies (propagate,
//! restart, substitute, ignore) with the recovery queue and redundant groups.
//!
//! A compound is built by [`CompoundBuilder::build`] into an ordinary [`Component`]:
//! it runs on its own thread through the same runner, default automaton
//! ([`crate::table::next`]), control and monitoring ports as an atomic component, so
//! nothing outside can tell them apart. Its code is a `Compound` automaton that owns
//! an inner [`System`] with the instances; the runner's compound hooks (the
//! crate-private `Driven` trait beside [`Automaton`]: `before_running`,
//! `after_transition`, `supervise`, `wake_at`, `entered`, `set_degradation`) let the
//! instances follow the compound's state and let the supervisor react to their
//! monitoring events. A hand-written or generated automaton implements only
//! [`Automaton`].
//! `docs/runtime.md` ("Compound components and supervisors") tells the semantics.
//!
//! One idea per file, in layers (each uses only the layers above it):
//!
//! - what a description gives: `supervisor` (the [`Supervisor`] trait, [`SupervisorCx`]),
//!   `view` (the [`View`] rules read, and a rule), `reads` (the keys rules read,
//!   resolved to ids when the compound is built, and a turn's changed keys), `policy`
//!   ([`Policy`], the restart budget, a recovery-queue entry), `links` (a declared
//!   connection, a merged stream),
//!   `exports` (the compound's own ports following instance ports), `coordinator`
//!   (what adaptation remembers between turns), `error` (why a compound fails);
//! - `state`: the compound automaton's state (instances, arrangement, supervisor, view);
//! - what a running compound does, each an `impl` of that state: `wiring` (who stands
//!   for each instance, and the connections that follow), `faults` (policies, restarts,
//!   the recovery queue), `in_step` (redundant members that lost input packets
//!   leave their group until resynchronized), `supervision` (one turn: exports, events, rules),
//!   `adaptation` (coordinating its instances' degradation);
//! - `component`: the compound as the runner drives it (`Automaton` and the crate's
//!   compound hooks; the instances follow the compound's state);
//! - `builder`: [`CompoundBuilder`], from a description to a [`Component`];
//! - `stand_in`: the compound with stand-ins for its instances, which the supervisor
//!   harness drives (`crate::harness::supervisor`).

mod adaptation;
mod builder;
mod component;
mod coordinator;
mod error;
mod exports;
mod faults;
mod in_step;
mod links;
mod policy;
mod reads;
mod stand_in;
mod state;
mod supervision;
mod supervisor;
mod view;
mod wiring;

pub use builder::CompoundBuilder;
pub use component::{COMPOUND_STOP_TIMEOUT, INSTANCE_START_TIMEOUT};
pub use error::CompoundError;
pub use exports::MEMBER_STALL;
pub use policy::{
    DEFAULT_BACKOFF, DEFAULT_BACKOFF_MAX, DEFAULT_RESTART_WINDOW, DEFAULT_RESTARTS, Policy,
};
pub use supervisor::{DEFAULT_SUPERVISION_PERIOD, Supervisor, SupervisorCx};
pub use view::View;

pub(crate) use stand_in::Stage;

#[allow(unused_imports, reason = "named by the documentation of this module")]
use crate::{
    automaton::Automaton,
    system::{Component, System},
};
