//! Response times that go unmeasured: an aperiodic atomic component's `max_response`
//! times only the packets an `on` transition handles (`docs/runtime.md`, "Response
//! time"); its other event inputs are read untimed (`coolc::check::unmeasured_response`,
//! a warning), whether the bound is the type's or an instance's override.

use super::Checker;
use super::model::{Component, InputKind, StateMember, TimingEntry};
use crate::ast::{self, ComponentKind, Span};
use crate::diagnostics::{Code, Diagnostic};

/// An aperiodic atomic component with a `max_response`: the runtime measures the
/// response time of the packets an `on` transition handles (`docs/runtime.md`,
/// "Response time"); an event input (a queue or a tick, not pulled) no `on`
/// transition names is read untimed, and the bound only limits how long its
/// sections run there.
pub(super) fn unmeasured_responses(checker: &mut Checker<'_, '_>, component: &ast::Component) {
    let entries: Vec<&ast::TimingEntry> = timing_entries(component).collect();
    let Some(bound) = max_response(entries.iter().copied()) else {
        return;
    };
    if entries
        .iter()
        .any(|entry| matches!(entry, ast::TimingEntry::Period(_)))
    {
        return;
    }
    let resolved = checker.model.resolved(&component.name.name);
    unmeasured(checker, &resolved, bound, &component.name.name);
}

/// An instance's own `max_response` (its `timing` override) on an aperiodic atomic
/// type that has none: the type's own is warned about where it is declared.
pub(super) fn instance_override(checker: &mut Checker<'_, '_>, instance: &ast::Instance) {
    if let Some(timing) = &instance.timing
        && let Some(bound) = max_response(timing.entries.iter())
        && let Some(declared) = checker.model.known(&instance.component.name)
        && declared.kind == ComponentKind::Atomic
        && !declared
            .timing
            .iter()
            .flatten()
            .any(|entry| matches!(entry, TimingEntry::MaxResponse(_) | TimingEntry::Period(..)))
        && !timing
            .entries
            .iter()
            .any(|entry| matches!(entry, ast::TimingEntry::Period(_)))
    {
        let what = format!("{} ({})", instance.name.name, instance.component.name);
        unmeasured(checker, &declared, bound, &what);
    }
}

/// The entries of `component`'s `timing` blocks.
pub(super) fn timing_entries(
    component: &ast::Component,
) -> impl Iterator<Item = &ast::TimingEntry> {
    component.members.iter().flat_map(|member| match member {
        ast::Member::Timing(timing) => timing.entries.as_slice(),
        _ => &[],
    })
}

/// Where `entries` give a `max_response`.
pub(super) fn max_response<'e>(
    mut entries: impl Iterator<Item = &'e ast::TimingEntry>,
) -> Option<Span> {
    entries.find_map(|entry| match entry {
        ast::TimingEntry::MaxResponse(expr) => Some(expr.span),
        _ => None,
    })
}

/// Warn, at `bound` in the checked file, of the event inputs of aperiodic `component`
/// (`what`: the component, or the instance whose override gives the bound) that no
/// `on` transition handles.
pub(super) fn unmeasured(
    checker: &mut Checker<'_, '_>,
    component: &Component,
    bound: Span,
    what: &str,
) {
    let handled: std::collections::BTreeSet<&str> = component
        .automaton
        .iter()
        .flat_map(|automaton| &automaton.states)
        .flat_map(|state| &state.members)
        .filter_map(|member| match member {
            StateMember::On { port, .. } => Some(port.name.as_str()),
            _ => None,
        })
        .collect();
    let untimed: Vec<String> = component
        .inputs
        .iter()
        .filter(|input| {
            // Event inputs (queues and ticks) the component does not pull: a `last` or
            // `poster` input is read for its value, a pulled one answers a request.
            input.port.as_ref().is_some_and(|port| {
                !port.pull
                    && matches!(
                        port.kind,
                        InputKind::Fifo { .. } | InputKind::Ufifo { .. } | InputKind::Tick
                    )
            }) && !handled.contains(input.name.as_str())
        })
        .map(|input| format!("`{}`", input.name))
        .collect();
    if untimed.is_empty() {
        return;
    }
    let diagnostic = Diagnostic::warning(
        Code::UnmeasuredResponse,
        checker.file,
        bound,
        format!(
            "`{what}` has no period: its response times are measured at `on` transitions \
             only, and no `on` handles {}",
            untimed.join(", ")
        ),
    )
    .with_label("not measured for those inputs")
    .with_help(
        "handle the input with `on input -> state;` to time its packets from arrival to the \
         end of the transition's sections; elsewhere `max_response` only bounds how long a \
         section runs",
    );
    checker.push(diagnostic);
}
