//! What a compound's supervisor is to the runtime: the [`Supervisor`] trait (its
//! states' sections, its own variables, its `may` choices) and the [`SupervisorCx`]
//! its sections receive.

use crate::automaton::{Context, Section, SectionResult, ValueRefused};
use crate::commander::Commander;
use crate::spec::Spec;
use std::time::Duration;

use crate::value::Value;

use super::view::View;

/// The period of a supervisor's `periodic;` sections when neither the state nor the
/// supervisor's `timing` gives one (`docs/language.md`, "The supervisor").
pub const DEFAULT_SUPERVISION_PERIOD: Duration = Duration::from_millis(100);

/// The supervisor of a compound: its user automaton (states and sections, like an
/// atomic component's) and its own variables. Transitions are fired by rules
/// ([`CompoundBuilder::rule`](crate::CompoundBuilder::rule)), not by ports.
pub trait Supervisor: Send + 'static {
    /// The supervisor's shape: `states` (with their `on`, `after` and `may`),
    /// `initial`, its own `variables` and `timing` (a period for periodic sections).
    /// Its ports are replaced by the ones the builder exports; exceptions are not
    /// used.
    fn spec(&self) -> &'static Spec;

    /// Run one section of one supervisor state.
    fn section(
        &mut self,
        _state: usize,
        _section: Section,
        _cx: &mut SupervisorCx<'_>,
    ) -> SectionResult {
        Ok(())
    }

    /// The value of own variable `variable` (an index into `spec().variables`).
    fn get(&self, _variable: usize) -> Value {
        Value::Unit
    }

    /// Set own controllable variable `variable`. The default refuses
    /// ([`ValueRefused::NotSettable`]).
    fn set(&mut self, variable: usize, _value: &Value) -> Result<(), ValueRefused> {
        Err(ValueRefused::not_settable(self.spec(), variable))
    }

    /// For states with `may` (`spec().states[state].may`): called after each entry or
    /// periodic section of `state`, the target to go to (one of the state's `may`
    /// targets, an index into `spec().states`), if any. The default stays.
    fn choose(&mut self, _state: usize, _cx: &mut SupervisorCx<'_>) -> Option<usize> {
        None
    }
}

/// What a supervisor section sees: the runtime context, the view of the instances'
/// monitors, and the commander of its instances.
pub struct SupervisorCx<'a> {
    /// Time, result, end, period of the compound.
    pub rt: &'a mut Context,
    /// The instances' monitors and the supervisor's own variables, as last seen.
    pub view: &'a View,
    /// Commands to the instances (state, variables, configuration, period,
    /// quality), each answered, each a supervision step (`crate::commander`).
    pub instances: &'a mut Commander,
}
