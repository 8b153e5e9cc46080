//! `coolbot`: the CoolBOT runtime. Components are port automata on their own threads.
//!
//! A component is a [`Component`] (its code as a [`Automaton`], its typed ports as a
//! [`PortSet`]); a [`System`] runs components, one named OS thread each, and connects
//! their ports. Every component follows the default automaton of the CoolBOT paper
//! ([`table::next`]), is controlled through its control port and observed through its
//! monitoring port ([`Handle`]). `docs/runtime.md` explains the semantics.
#![deny(missing_docs)]

mod automaton;
mod monitor;
pub mod port;
mod runner;
mod spec;
mod system;
pub mod table;
mod thread;
mod value;

pub use crate::automaton::{Automaton, Context, Fault, Section, SectionResult, TaskResult};
pub use crate::monitor::{
    Command, DEFAULT_COMMAND_TIMEOUT, Handle, Monitor, MonitorEvent, OBSERVER_CAPACITY, Rejected,
    Timeout,
};
pub use crate::port::{InputPort, OutputPort, Packet, PullError};
pub use crate::spec::{
    AfterSpec, ExceptionSpec, InputKind, InputSpec, OnSpec, OutputKind, OutputSpec, OverflowPolicy,
    PeriodicSpec, PlanStep, Spec, StateSpec, TimingSpec, VarKind, VarSpec,
};
pub use crate::system::{
    Component, ComponentReport, ConnectError, Error, PortSet, Report, SHUTDOWN_TIMEOUT, System,
};
pub use crate::table::{Controllable, State};
pub use crate::value::{Time, Value, ValueError};

/// Re-exported so generated code and users need not depend on it themselves.
pub use crossbeam_channel;
