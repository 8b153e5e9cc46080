//! The user automaton: one `initial` that exists, known transition targets and ports,
//! reachability from `initial`, sections given once, periods for `periodic` sections,
//! `when` rules only in supervisors, and continuity plan `goto` targets.

use std::collections::{BTreeMap, BTreeSet};

use super::{Checker, names, rules, values};
use crate::ast::{self, ComponentKind, Span};
use crate::diagnostics::Code;

/// Checks every automaton of `component` (more than one is reported elsewhere) and the
/// `goto` steps of its exceptions.
pub(super) fn automata(checker: &mut Checker<'_, '_>, component: &ast::Component) {
    let automata: Vec<&ast::Automaton> = component
        .members
        .iter()
        .filter_map(|member| match member {
            ast::Member::Automaton(automaton) => Some(automaton),
            _ => None,
        })
        .collect();
    for automaton in &automata {
        self::automaton(checker, component, automaton);
    }
    plan_targets(checker, component, automata.first().copied());
}

fn automaton(
    checker: &mut Checker<'_, '_>,
    component: &ast::Component,
    automaton: &ast::Automaton,
) {
    names::duplicates(checker, automaton.states.iter().map(|s| &s.name), "state");
    names::rust_clashes(
        checker,
        automaton.states.iter().map(|s| &s.name),
        "state",
        &[names::snake, names::camel],
    );
    let states: Vec<&str> = automaton
        .states
        .iter()
        .map(|s| s.name.name.as_str())
        .collect();
    initial(checker, automaton, &states);
    for state in &automaton.states {
        names::value_name(checker, &state.name);
        sections(checker, state);
        triggers(checker, state);
        for member in &state.members {
            state_member(checker, component, automaton, member, &states);
        }
    }
    reachability(checker, component, automaton);
}

/// Exactly one `initial`, naming a state.
fn initial(checker: &mut Checker<'_, '_>, automaton: &ast::Automaton, states: &[&str]) {
    match automaton.initial.as_slice() {
        [] => {
            let mut diagnostic = checker
                .error(
                    Code::InitialState,
                    automaton.keyword_span,
                    "this automaton has no `initial` state",
                )
                .with_label("no `initial` here");
            if let Some(first) = states.first() {
                diagnostic = diagnostic.with_help(format!("add `initial {first};`"));
            }
            checker.push(diagnostic);
        }
        [first, rest @ ..] => {
            for extra in rest {
                let diagnostic = checker
                    .error(
                        Code::InitialState,
                        extra.span,
                        "an automaton has exactly one `initial` state",
                    )
                    .with_label("second `initial`")
                    .with_secondary(first.span, "first `initial`");
                checker.push(diagnostic);
            }
            target(checker, &automaton.initial[0], states);
        }
    }
}

/// Reports a transition target that is not a state.
fn target(checker: &mut Checker<'_, '_>, name: &ast::Ident, states: &[&str]) -> bool {
    if states.contains(&name.name.as_str()) {
        return true;
    }
    checker.unknown(
        Code::UnknownState,
        name,
        "state",
        "",
        states.iter().copied(),
    );
    false
}

/// `entry`, `exit` and `periodic` at most once per state.
fn sections(checker: &mut Checker<'_, '_>, state: &ast::State) {
    let mut seen: Vec<(&str, Span)> = Vec::new();
    for member in &state.members {
        let (name, span) = match member {
            ast::StateMember::Entry(span) => ("entry", *span),
            ast::StateMember::Exit(span) => ("exit", *span),
            ast::StateMember::Periodic { span, .. } => ("periodic", *span),
            _ => continue,
        };
        if let Some((_, first)) = seen.iter().find(|(seen_name, _)| *seen_name == name) {
            let diagnostic = checker
                .error(
                    Code::RepeatedBlock,
                    span,
                    format!("state `{}` declares `{name}` twice", state.name.name),
                )
                .with_label("second declaration")
                .with_secondary(*first, "first declaration");
            checker.push(diagnostic);
        } else {
            seen.push((name, span));
        }
    }
}

/// One `on` per input and one `after` per delay (and watched input) in a state: the
/// first of two would always fire, the second never.
fn triggers(checker: &mut Checker<'_, '_>, state: &ast::State) {
    let mut seen: Vec<(String, Span)> = Vec::new();
    for member in &state.members {
        let (trigger, span) = match member {
            ast::StateMember::On { port, span, .. } => (format!("on {}", port.name), *span),
            ast::StateMember::After {
                delay:
                    ast::Expr {
                        kind: ast::ExprKind::Duration(ns),
                        ..
                    },
                without,
                span,
                ..
            } => {
                let mut trigger = format!("after {}", super::model::duration_text(*ns));
                if let Some(port) = without {
                    trigger.push_str(&format!(" without {}", port.name));
                }
                (trigger, *span)
            }
            _ => continue,
        };
        if let Some((_, first)) = seen.iter().find(|(seen, _)| *seen == trigger) {
            let diagnostic = checker
                .error(
                    Code::RepeatedBlock,
                    span,
                    format!(
                        "state `{}` has two `{trigger}` transitions",
                        state.name.name
                    ),
                )
                .with_label("never fires: the first one always does")
                .with_secondary(*first, "fires first")
                .with_help("keep one of them; to choose among targets, use `may` in a section");
            checker.push(diagnostic);
        } else {
            seen.push((trigger, span));
        }
    }
}

fn state_member(
    checker: &mut Checker<'_, '_>,
    component: &ast::Component,
    automaton: &ast::Automaton,
    member: &ast::StateMember,
    states: &[&str],
) {
    let supervisor = component.kind == ComponentKind::Compound;
    match member {
        ast::StateMember::Entry(_) | ast::StateMember::Exit(_) => {}
        ast::StateMember::Periodic { period, span } => match period {
            Some(period) => {
                values::period(checker, period);
            }
            None => {
                if !supervisor && !has_period(component) {
                    let diagnostic = checker
                        .error(Code::PeriodicWithoutPeriod, *span, "this `periodic` section has no period")
                        .with_label("no period for this section")
                        .with_secondary(component.name.span, format!("`{}` has no `timing {{ period ...; }}`", component.name.name))
                        .with_help("write `periodic 20ms;` or add `timing { period 20ms; }` to the component");
                    checker.push(diagnostic);
                }
            }
        },
        ast::StateMember::On {
            port, target: to, ..
        } => {
            input_port(checker, component, port, "`on`");
            target(checker, to, states);
        }
        ast::StateMember::After {
            delay,
            without,
            target: to,
            ..
        } => {
            values::duration(checker, delay, "`after`");
            if let Some(port) = without {
                input_port(checker, component, port, "`without`");
            }
            target(checker, to, states);
        }
        ast::StateMember::May { targets, .. } => {
            names::duplicates(checker, targets.iter(), "`may` target");
            for to in targets {
                target(checker, to, states);
            }
        }
        ast::StateMember::When {
            condition,
            target: to,
            span,
        } => {
            if automaton.keyword == ast::AutomatonKeyword::Supervisor || supervisor {
                let typed = rules::rule(checker, component, condition);
                checker.rules.insert((checker.file, condition.span), typed);
            } else {
                let diagnostic = checker
                    .error(Code::MisplacedMember, *span, "`when` rules are only allowed in a compound's `supervisor`")
                    .with_label("rule in an atomic automaton")
                    .with_help("react to inputs with `on port -> state;`, or let the section choose with `may -> state;`");
                checker.push(diagnostic);
            }
            target(checker, to, states);
        }
    }
}

/// True when the component's `timing` block gives a period.
fn has_period(component: &ast::Component) -> bool {
    component.members.iter().any(|member| match member {
        ast::Member::Timing(timing) => timing
            .entries
            .iter()
            .any(|e| matches!(e, ast::TimingEntry::Period(_))),
        _ => false,
    })
}

/// `on` and `without` name an input port of this component.
fn input_port(
    checker: &mut Checker<'_, '_>,
    component: &ast::Component,
    port: &ast::Ident,
    what: &str,
) {
    let mut inputs = Vec::new();
    let mut output_span = None;
    for member in &component.members {
        match member {
            ast::Member::Input(input) => inputs.push(input.name.name.as_str()),
            ast::Member::Output(output) if output.name.name == port.name => {
                output_span = Some(output.name.span)
            }
            _ => {}
        }
    }
    if inputs.contains(&port.name.as_str()) {
        return;
    }
    if let Some(output_span) = output_span {
        let diagnostic = checker
            .error(
                Code::UnknownPort,
                port.span,
                format!(
                    "{what} needs an input port, but `{}` is an output",
                    port.name
                ),
            )
            .with_label("an output")
            .with_secondary(output_span, "declared as an output here");
        checker.push(diagnostic);
        return;
    }
    checker.unknown(
        Code::UnknownPort,
        port,
        "input port",
        &format!(" in `{}`", component.name.name),
        inputs,
    );
}

/// Every state is reachable from `initial` through `on`, `after`, `may`, `when` and
/// exception `goto` edges.
fn reachability(
    checker: &mut Checker<'_, '_>,
    component: &ast::Component,
    automaton: &ast::Automaton,
) {
    if checker.incomplete {
        return;
    }
    let Some(initial) = automaton.initial.first() else {
        return;
    };
    if !automaton
        .states
        .iter()
        .any(|state| state.name.name == initial.name)
    {
        // An unknown `initial` is reported already; every state would look unreachable.
        return;
    }
    let mut edges: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
    for state in &automaton.states {
        let entry = edges.entry(state.name.name.as_str()).or_default();
        for member in &state.members {
            match member {
                ast::StateMember::On { target, .. }
                | ast::StateMember::After { target, .. }
                | ast::StateMember::When { target, .. } => entry.push(&target.name),
                ast::StateMember::May { targets, .. } => {
                    entry.extend(targets.iter().map(|t| t.name.as_str()))
                }
                _ => {}
            }
        }
    }
    let mut reached: BTreeSet<&str> = BTreeSet::new();
    let mut todo = vec![initial.name.as_str()];
    // A `goto` in a continuity plan can fire from any state.
    for member in &component.members {
        if let ast::Member::Exception(exception) = member {
            for step in &exception.plan {
                if let ast::PlanKind::Goto(target) = &step.kind {
                    todo.push(&target.name);
                }
            }
        }
    }
    while let Some(state) = todo.pop() {
        if reached.insert(state) {
            todo.extend(edges.get(state).into_iter().flatten().copied());
        }
    }
    for state in &automaton.states {
        if !reached.contains(state.name.name.as_str())
            && !automaton.initial.iter().any(|i| i.name == state.name.name)
        {
            let diagnostic = checker
                .error(Code::UnreachableState, state.name.span, format!("state `{}` cannot be reached", state.name.name))
                .with_label("unreachable")
                .with_secondary(initial.span, "reachability is computed from here")
                .with_help("add a transition to it (`on`, `after`, `may`, `when`, or an exception's `goto`), or remove it");
            checker.push(diagnostic);
        }
    }
}

/// `goto` steps of continuity plans name states of the component's automaton.
fn plan_targets(
    checker: &mut Checker<'_, '_>,
    component: &ast::Component,
    automaton: Option<&ast::Automaton>,
) {
    let states: Vec<&str> = automaton
        .map(|a| a.states.iter().map(|s| s.name.name.as_str()).collect())
        .unwrap_or_default();
    for member in &component.members {
        let ast::Member::Exception(exception) = member else {
            continue;
        };
        for step in &exception.plan {
            if let ast::PlanKind::Goto(to) = &step.kind {
                if automaton.is_none() {
                    let diagnostic = checker
                        .error(
                            Code::UnknownState,
                            to.span,
                            format!(
                                "`goto {}`: `{}` has no automaton",
                                to.name, component.name.name
                            ),
                        )
                        .with_label("no states to go to")
                        .with_help("add an `automaton { ... }` with this state");
                    checker.push(diagnostic);
                } else {
                    target(checker, to, &states);
                }
            }
        }
    }
}
