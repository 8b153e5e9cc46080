//! Execution groups, `thread name { a, b, ... }`: what the runtime refuses to run on
//! one thread (`System::group`, `GroupError`), found before it runs, and two rules of
//! the language beside: members are local instances (the runtime refuses a remote
//! one's proxy, but runs the instance here in a program without a network) and their
//! periods are harmonic (the runtime runs any period, each on its own grid). Members are instances of atomic components of this
//! compound, each in one group; a group has a member and a name of its own; no member
//! pulls from another or feeds another's `block` fifo; and the connections among the
//! members form no cycle unless a `last` or `poster` input is on it.

use std::collections::{BTreeMap, BTreeSet};

use super::Checker;
use super::model::{Model, PortKind, TimingEntry};
use crate::ast::{self, ComponentKind, Span};
use crate::diagnostics::Code;

/// Every check of the `thread` members of `compound`.
pub(super) fn threads(checker: &mut Checker<'_, '_>, compound: &ast::Component) {
    let mut names: BTreeMap<&str, Span> = BTreeMap::new();
    // Where each instance was first put on a group's thread, and which group.
    let mut placed: BTreeMap<&str, (Span, &str)> = BTreeMap::new();
    for member in &compound.members {
        let ast::Member::Thread(thread) = member else {
            continue;
        };
        let name = thread.name.name.as_str();
        if let Some(earlier) = names.get(name) {
            let diagnostic = checker
                .error(
                    Code::ThreadDuplicateName,
                    thread.name.span,
                    format!("two execution groups are named `{name}`"),
                )
                .with_label("second group of this name")
                .with_secondary(*earlier, "first group of this name")
                .with_help("give each group a name of its own (its thread is named after it)");
            checker.push(diagnostic);
        } else {
            names.insert(name, thread.name.span);
        }
        if thread.members.is_empty() {
            let diagnostic = checker
                .error(
                    Code::ThreadEmpty,
                    thread.name.span,
                    format!("the execution group `{name}` has no member"),
                )
                .with_label("empty group")
                .with_help("name the instances that share the thread, or remove the group");
            checker.push(diagnostic);
        }
        let mut members: Vec<Member<'_>> = Vec::new();
        for ident in &thread.members {
            if let Some((earlier, group)) = placed.get(ident.name.as_str()) {
                let where_ = if *group == name {
                    "in this group".to_owned()
                } else {
                    format!("in group `{group}`")
                };
                let diagnostic = checker
                    .error(
                        Code::ThreadTwice,
                        ident.span,
                        format!("`{}` is already {where_}", ident.name),
                    )
                    .with_label("named again")
                    .with_secondary(*earlier, "first named here")
                    .with_help("an instance runs on one thread: name it in one group, once");
                checker.push(diagnostic);
                continue;
            }
            if let Some(member) = self::member(checker, compound, ident) {
                members.push(member);
            }
            if Model::instance(compound, &ident.name).is_some() {
                placed.insert(ident.name.as_str(), (ident.span, name));
            }
        }
        periods(checker, &members);
        flow(checker, compound, &members);
    }
}

/// A member of a group that names a local atomic instance.
struct Member<'c> {
    /// The name as written in the group.
    ident: &'c ast::Ident,
    /// The instance.
    instance: &'c ast::Instance,
    /// Its period in nanoseconds (the nominal one), if it has one.
    period: Option<u64>,
}

/// Resolves a member to a local instance of an atomic component, reporting what
/// else it is. `None` also when its component is unknown (reported already).
fn member<'c>(
    checker: &mut Checker<'_, '_>,
    compound: &'c ast::Component,
    ident: &'c ast::Ident,
) -> Option<Member<'c>> {
    let Some(instance) = Model::instance(compound, &ident.name) else {
        let instances: Vec<&str> = compound
            .members
            .iter()
            .filter_map(|member| match member {
                ast::Member::Instance(instance) => Some(instance.name.name.as_str()),
                _ => None,
            })
            .collect();
        checker.unknown(
            Code::ThreadUnknownMember,
            ident,
            "instance",
            &format!(" in compound `{}`", compound.name.name),
            instances,
        );
        return None;
    };
    let component = checker.model.known(&instance.component.name)?;
    if component.kind == ComponentKind::Compound {
        let diagnostic = checker
            .error(
                Code::ThreadNotAtomic,
                ident.span,
                format!(
                    "`{}` is an instance of the compound `{}`: only atomic instances share a thread",
                    ident.name, instance.component.name
                ),
            )
            .with_label("a compound")
            .with_help(
                "a compound supervises its instances on threads of their own; group its atomic \
                 instances inside it instead",
            );
        checker.push(diagnostic);
        return None;
    }
    if let Some(node) = &instance.node {
        let diagnostic = checker
            .error(
                Code::ThreadRemoteMember,
                ident.span,
                format!(
                    "`{}` runs on node \"{}\": a remote instance cannot share a local thread",
                    ident.name, node.value
                ),
            )
            .with_label("a remote instance")
            .with_secondary(node.span, "placed on another node here")
            .with_help("take it out of the group, or drop its `on \"node\"`");
        checker.push(diagnostic);
        return None;
    }
    // The instance's override, else its component's `timing`.
    let enclosing = checker.model.resolved(&compound.name.name);
    let own = enclosing
        .instances
        .iter()
        .find(|resolved| resolved.name == ident.name)
        .and_then(|resolved| resolved.timing.as_deref());
    let period = period(own).or_else(|| period(component.timing.as_deref()));
    Some(Member {
        ident,
        instance,
        period,
    })
}

/// The nominal period of a `timing` block (its last `period` entry's lower bound), in
/// nanoseconds as the runtime gets it (a frequency's period rounded to the nearest).
fn period(timing: Option<&[TimingEntry]>) -> Option<u64> {
    timing?.iter().rev().find_map(|entry| match entry {
        TimingEntry::Period(lo, _) => Some(lo.nanos),
        _ => None,
    })
}

/// Harmonic periods: each member's a whole multiple of the shortest, so that the
/// members fall due together on the group's grid. Aperiodic members do not count.
fn periods(checker: &mut Checker<'_, '_>, members: &[Member<'_>]) {
    let Some(shortest) = members
        .iter()
        .filter(|m| m.period.is_some_and(|p| p > 0))
        .min_by_key(|m| m.period)
    else {
        return;
    };
    let Some(base) = shortest.period else { return };
    for member in members {
        let Some(period) = member.period.filter(|p| *p > 0) else {
            continue;
        };
        if !period.is_multiple_of(base) {
            let diagnostic = checker
                .error(
                    Code::ThreadPeriods,
                    member.ident.span,
                    format!(
                        "the period of `{}` ({}) is not a whole multiple of the period of `{}` ({})",
                        member.ident.name,
                        nanos(period),
                        shortest.ident.name,
                        nanos(base)
                    ),
                )
                .with_label("not harmonic")
                .with_secondary(shortest.ident.span, "the shortest period in the group")
                .with_help(
                    "members of one group run on one grid of deadlines: give each a period that \
                     is a whole multiple of the shortest, or take it out of the group",
                );
            checker.push(diagnostic);
        }
    }
}

/// A period in nanoseconds, written in the largest unit that divides it.
fn nanos(nanos: u64) -> String {
    for (unit, size) in [("s", 1_000_000_000), ("ms", 1_000_000), ("us", 1_000)] {
        if nanos.is_multiple_of(size) {
            return format!("{}{unit}", nanos / size);
        }
    }
    format!("{nanos}ns")
}

/// A connection between two members of one group that the group cannot run: the
/// diagnostic's parts (the message is "`to.port`{fed} `from.port`, a member of the
/// same group: {because}").
struct InGroup {
    code: Code,
    fed: &'static str,
    because: &'static str,
    label: &'static str,
    connection: &'static str,
    help: &'static str,
}

/// A `pull` input fed by a member of its own group.
const PULL_IN_GROUP: InGroup = InGroup {
    code: Code::ThreadPull,
    fed: " pulls from",
    because: "the pull would wait for its own thread",
    label: "pulls from a member",
    connection: "the pull connection",
    help: "take one of the two out of the group, or let the input read what is sent (no `pull`)",
};

/// A `block` fifo fed by a member of its own group.
const BLOCK_IN_GROUP: InGroup = InGroup {
    code: Code::ThreadBlock,
    fed: ", a `block` fifo, is fed by",
    because: "a full queue would stop the thread that empties it",
    label: "blocks a member",
    connection: "the connection",
    help: "give the fifo another policy (`reject`, `drop_oldest`), or take one of the two out \
           of the group",
};

/// The connections among the members: none into a `pull` input (the pull would wait
/// for the thread that waits) nor into a `block` fifo (a full queue would stop the
/// thread that empties it), and no cycle unless a `last` or `poster` input is on
/// it (a queue cycle has no order to run in). As the runtime decides: connections
/// between two different members, as written.
fn flow(checker: &mut Checker<'_, '_>, compound: &ast::Component, members: &[Member<'_>]) {
    let index: BTreeMap<&str, usize> = members
        .iter()
        .enumerate()
        .map(|(i, m)| (m.ident.name.as_str(), i))
        .collect();
    // Edges that order the members: (from, to, the connection).
    let mut edges: Vec<(usize, usize, Span)> = Vec::new();
    for member in &compound.members {
        let ast::Member::Connect(connect) = member else {
            continue;
        };
        let (Some(from), Some(to)) = (&connect.from.instance, &connect.to.instance) else {
            continue;
        };
        let (Some(&from), Some(&to)) = (index.get(from.name.as_str()), index.get(to.name.as_str()))
        else {
            continue;
        };
        if from == to {
            continue;
        }
        let interface = checker.model.resolved(&members[to].instance.component.name);
        let Some(port) = interface.input(&connect.to.port.name) else {
            continue;
        };
        let flaw = if port.pull {
            Some(&PULL_IN_GROUP)
        } else if port.block() {
            Some(&BLOCK_IN_GROUP)
        } else {
            None
        };
        if let Some(flaw) = flaw {
            let (from, to) = (&members[from], &members[to]);
            let message = format!(
                "`{}.{}`{} `{}.{}`, a member of the same group: {}",
                to.ident.name,
                connect.to.port.name,
                flaw.fed,
                from.ident.name,
                connect.from.port.name,
                flaw.because,
            );
            let diagnostic = checker
                .error(flaw.code, to.ident.span, message)
                .with_label(flaw.label)
                .with_secondary(connect.span, flaw.connection)
                .with_help(flaw.help);
            checker.push(diagnostic);
            continue;
        }
        if !matches!(port.kind(), PortKind::Last | PortKind::Poster) {
            edges.push((from, to, connect.span));
        }
    }
    // Peel off members with no edge in from, or none out to, the rest: what stays
    // lies on a cycle or between two.
    let mut left: BTreeSet<usize> = (0..members.len()).collect();
    loop {
        let peel: Vec<usize> = left
            .iter()
            .copied()
            .filter(|m| {
                let inside = |e: &&(usize, usize, Span)| left.contains(&e.0) && left.contains(&e.1);
                !edges.iter().filter(inside).any(|e| e.1 == *m)
                    || !edges.iter().filter(inside).any(|e| e.0 == *m)
            })
            .collect();
        if peel.is_empty() {
            break;
        }
        for m in peel {
            left.remove(&m);
        }
    }
    let Some(&first) = left.first() else { return };
    let names: Vec<String> = left
        .iter()
        .map(|m| format!("`{}`", members[*m].ident.name))
        .collect();
    let mut diagnostic = checker
        .error(
            Code::ThreadCycle,
            members[first].ident.span,
            format!(
                "the connections among {} form a cycle with no `last` or `poster` input to break it",
                names.join(", ")
            ),
        )
        .with_label("on a cycle")
        .with_help(
            "a group runs its members in data-flow order, and a cycle of queues has none: make \
             an input on the cycle `last` or `poster`, or take a member out of the group",
        );
    for (from, to, span) in &edges {
        if left.contains(from) && left.contains(to) {
            diagnostic = diagnostic.with_secondary(*span, "on the cycle");
        }
    }
    checker.push(diagnostic);
}
