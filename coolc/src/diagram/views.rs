//! The three views, built from the resolved components of a checked model.

use super::text;
use super::{Diagram, Edge, EdgeStyle, End, Group, Item, Node, Ports, Shape, View, join};
use crate::checked::Checked;
use crate::checked::model::{
    Component, ComponentKind, DEFAULT_CONTROLLABLES, DEFAULT_OBSERVABLES, Input, Instance,
    InstanceRef, Output, PortRef, State, StateMember, TimingEntry, VarKind, Variable,
};

/// The checked model the views are drawn from.
pub(super) struct Lookup<'a> {
    checked: &'a Checked,
}

/// The state a compound without a `supervisor` is in (as the generated code has it).
const IMPLICIT_STATE: &str = "supervising";

impl<'a> Lookup<'a> {
    pub(super) fn new(checked: &'a Checked) -> Lookup<'a> {
        Lookup { checked }
    }

    pub(super) fn component(&self, name: &str) -> Option<&'a Component> {
        self.checked.component(name)
    }

    /// Every component's name, sorted.
    pub(super) fn names(&self) -> Vec<&'a str> {
        let mut names: Vec<&str> = self
            .checked
            .components()
            .map(|component| component.name.as_str())
            .collect();
        names.sort_unstable();
        names
    }

    // -----------------------------------------------------------------------------
    // Ports, as the model resolved them through exports.

    fn input_label(input: &Input) -> String {
        let kind = input
            .port
            .as_ref()
            .map_or_else(|| "?".to_owned(), text::input_kind);
        format!("{}: {kind}", input.name)
    }

    fn output_label(output: &Output) -> String {
        let kind = output
            .port
            .as_ref()
            .map_or_else(|| "?".to_owned(), text::output_kind);
        format!("{}: {kind}", output.name)
    }

    /// The variables of one kind, as label lines (`odometry: Pose2D`, and a mapped
    /// one with the type of what it maps: `pose: Pose2D = motion.odometry`).
    fn variables(component: &Component, kind: VarKind) -> Vec<String> {
        component
            .variables
            .iter()
            .filter(|variable| variable.kind == kind)
            .map(|variable| match (&variable.written, &variable.mapping) {
                (Some(ty), _) => format!("{}: {ty}", variable.name),
                (None, Some(path)) => match &variable.ty {
                    Some(ty) => format!("{}: {ty} = {}", variable.name, path.join(".")),
                    None => format!("{} = {}", variable.name, path.join(".")),
                },
                (None, None) => variable.name.clone(),
            })
            .collect()
    }

    // -----------------------------------------------------------------------------
    // Interface.

    /// The component with its ports around it (paper Figure 1): the control port
    /// `c` and the inputs on the left, the monitoring port `m` and the outputs on the
    /// right.
    pub(super) fn interface(&self, component: &Component) -> Diagram {
        let name = &component.name;
        let mut items = Vec::new();
        let mut edges = Vec::new();
        let kind = match component.kind {
            ComponentKind::Atomic => "atomic",
            ComponentKind::Compound => "compound",
        };
        let mut lines = vec![name.clone(), format!("«{kind}»")];
        if let Some(timing) = timing_line(component) {
            lines.push(timing);
        }
        items.push(Item::Node(Node {
            id: "component".to_owned(),
            lines,
            shape: Shape::Box,
            dashed: false,
            ports: None,
        }));

        let mut control = vec!["c (control)".to_owned(), DEFAULT_CONTROLLABLES.join(", ")];
        if let Some(configuration) = &component.configuration {
            let fields: Vec<String> = configuration
                .iter()
                .map(|f| format!("{}: {}", f.name, f.ty))
                .collect();
            control.push(format!("configuration {{ {} }}", fields.join(", ")));
        }
        control.extend(Self::variables(component, VarKind::Controllable));
        let mut monitoring = vec!["m (monitoring)".to_owned(), DEFAULT_OBSERVABLES.join(", ")];
        monitoring.extend(Self::variables(component, VarKind::Observable));

        items.push(port_node("in.c", control, true));
        edges.push(edge(End::node("in.c"), End::node("component"), vec![]));
        for input in &component.inputs {
            let id = format!("in.{}", input.name);
            let mut lines = vec![Self::input_label(input)];
            if let Some(target) = &input.export {
                lines.push(format!("= {}", text::port_ref(target)));
            }
            items.push(port_node(&id, lines, false));
            edges.push(edge(End::node(id), End::node("component"), vec![]));
        }
        items.push(port_node("out.m", monitoring, true));
        edges.push(edge(End::node("component"), End::node("out.m"), vec![]));
        for output in &component.outputs {
            let id = format!("out.{}", output.name);
            let mut lines = vec![Self::output_label(output)];
            if let Some(target) = &output.export {
                lines.push(format!("= {}", text::port_ref(target)));
            }
            items.push(port_node(&id, lines, false));
            edges.push(edge(End::node("component"), End::node(id), vec![]));
        }
        Diagram {
            component: name.clone(),
            view: View::Interface,
            left_to_right: true,
            items,
            edges,
        }
    }

    // -----------------------------------------------------------------------------
    // Structure.

    /// A compound's instances (nested compounds as groups), connections, exported
    /// ports, variables, policies, substitutions and redundant groups (Figure 5), and
    /// each instance's execution group (`thread name`) as a line of its box.
    pub(super) fn structure(&self, component: &Component) -> Diagram {
        let mut edges = Vec::new();
        let group = self.compound_group(
            component,
            "",
            vec![format!("«compound» {}", component.name)],
            &mut edges,
            0,
        );
        Diagram {
            component: component.name.clone(),
            view: View::Structure,
            left_to_right: true,
            items: vec![Item::Group(group)],
            edges,
        }
    }

    fn compound_group(
        &self,
        component: &Component,
        prefix: &str,
        label: Vec<String>,
        edges: &mut Vec<Edge>,
        depth: usize,
    ) -> Group {
        let group_id = if prefix.is_empty() {
            "compound".to_owned()
        } else {
            format!("{prefix}:group")
        };
        let mut items = Vec::new();

        // Exported ports: nodes inside the frame, dotted to what they stand for.
        for input in &component.inputs {
            if let Some(target) = &input.export {
                let id = format!("{}in.{}", port_prefix(prefix), input.name);
                items.push(port_node(&id, vec![Self::input_label(input)], false));
                let to = endpoint(prefix, target, false);
                edges.push(Edge {
                    style: EdgeStyle::Dotted,
                    ports: Some(format!("→ {}", text::port_ref(target))),
                    ..edge(End::node(id), to, vec![])
                });
            }
        }
        for output in &component.outputs {
            if let Some(target) = &output.export {
                let id = format!("{}out.{}", port_prefix(prefix), output.name);
                items.push(port_node(&id, vec![Self::output_label(output)], false));
                let from = endpoint(prefix, target, true);
                edges.push(Edge {
                    style: EdgeStyle::Dotted,
                    ports: Some(format!("{} →", text::port_ref(target))),
                    ..edge(from, End::node(id), vec![])
                });
            }
        }

        // Instances, with redundant members gathered in a dashed group.
        let mut instance_items: Vec<(String, Item)> = Vec::new();
        for instance in &component.instances {
            let thread = component
                .threads
                .iter()
                .find(|thread| thread.members.contains(&instance.name))
                .map(|thread| thread.name.as_str());
            let item = self.instance_item(instance, thread, prefix, edges, depth);
            instance_items.push((instance.name.clone(), item));
        }
        for (index, redundant) in component.redundant.iter().enumerate() {
            let names: Vec<&str> = redundant.members.iter().map(String::as_str).collect();
            let Some(first) = instance_items
                .iter()
                .position(|(name, _)| names.contains(&name.as_str()))
            else {
                continue;
            };
            let mut grouped = Vec::new();
            let mut kept = Vec::new();
            for (position, (name, item)) in instance_items.into_iter().enumerate() {
                if names.contains(&name.as_str()) {
                    grouped.push(item);
                } else {
                    kept.push((position, (name, item)));
                }
            }
            let group = Item::Group(Group {
                id: format!("{}redundant.{index}", port_prefix(prefix)),
                label: vec![format!("redundant {}", names.join(", "))],
                dashed: true,
                rounded: false,
                items: grouped,
            });
            let mut rebuilt: Vec<(String, Item)> = Vec::new();
            let mut placed = false;
            for (position, entry) in kept {
                if !placed && position > first {
                    rebuilt.push((String::new(), group.clone()));
                    placed = true;
                }
                rebuilt.push(entry);
            }
            if !placed {
                rebuilt.push((String::new(), group));
            }
            instance_items = rebuilt;
        }
        items.extend(instance_items.into_iter().map(|(_, item)| item));

        // Connections.
        for connect in &component.connections {
            let from = endpoint(prefix, &connect.from, true);
            let to = endpoint(prefix, &connect.to, false);
            let kind = connect.kind.map_or("?", |kind| kind.as_str());
            let mut label = vec![kind.to_owned()];
            if let Some(via) = &connect.via {
                label = vec![format!("{kind} via {via}")];
            }
            edges.push(Edge {
                ports: Some(format!(
                    "{} → {}",
                    text::port_ref(&connect.from),
                    text::port_ref(&connect.to)
                )),
                ..edge(from, to, label)
            });
        }

        // Substitutions.
        for instance in &component.instances {
            if let Some(primary) = &instance.substitutes {
                let from = instance_end(
                    prefix,
                    &InstanceRef {
                        name: instance.name.clone(),
                        compound: instance.compound,
                    },
                );
                let to = instance_end(prefix, primary);
                edges.push(Edge {
                    style: EdgeStyle::Dashed,
                    ..edge(from, to, vec!["substitutes".to_owned()])
                });
            }
        }

        // Variables, the recovery queue and the restart budget, in a note, in the
        // order they are written.
        let mut note: Vec<(usize, String)> = component
            .variables
            .iter()
            .map(|variable| (variable.span.start, variable_line(variable)))
            .collect();
        if let Some(recovery) = &component.recovery {
            let mut parts = Vec::new();
            if let Some(every) = &recovery.retry_every {
                parts.push(format!("retry every {}", text::time(every)));
            }
            if let Some(deadline) = &recovery.deadline {
                parts.push(format!("deadline {}", text::time(deadline)));
            }
            note.push((
                recovery.span.start,
                format!("recovery {{ {} }}", parts.join("; ")),
            ));
        }
        if let Some(restart) = &component.restart {
            let mut parts = Vec::new();
            if let Some((count, window)) = &restart.limit {
                parts.push(format!("limit {} in {}", count, text::time(window)));
            }
            if let Some((first, last)) = &restart.backoff {
                parts.push(format!(
                    "backoff {}..{}",
                    text::time(first),
                    text::time(last)
                ));
            }
            note.push((
                restart.span.start,
                format!("restart {{ {} }}", parts.join("; ")),
            ));
        }
        note.sort_by_key(|(start, _)| *start);
        let note: Vec<String> = note.into_iter().map(|(_, line)| line).collect();
        if !note.is_empty() {
            items.push(Item::Node(Node {
                id: format!("{}variables", port_prefix(prefix)),
                lines: note,
                shape: Shape::Note,
                dashed: false,
                ports: None,
            }));
        }
        Group {
            id: group_id,
            label,
            dashed: false,
            rounded: false,
            items,
        }
    }

    fn instance_item(
        &self,
        instance: &Instance,
        thread: Option<&str>,
        prefix: &str,
        edges: &mut Vec<Edge>,
        depth: usize,
    ) -> Item {
        let path = join(prefix, &instance.name);
        let mut lines = vec![format!("{}: {}", instance.name, instance.component)];
        if let Some(thread) = thread {
            // An execution group: the instances that share its thread.
            lines.push(format!("thread {thread}"));
        }
        if let Some(node) = &instance.node {
            // `on "node"`: on that node behind a proxy when the process is on a
            // network, else in the compound's process (`docs/distribution.md`).
            lines.push(format!("on \"{node}\" (remote when on a network)"));
        }
        if let Some(policy) = &instance.on_error {
            lines.push(format!("on error: {}", policy.name()));
        }
        let inner = self.component(&instance.component);
        match inner {
            Some(inner) if inner.kind == ComponentKind::Compound && depth < 16 => {
                Item::Group(self.compound_group(inner, &path, lines, edges, depth + 1))
            }
            _ => {
                let ports = inner.map(|inner| Ports {
                    inputs: inner
                        .inputs
                        .iter()
                        .map(|i| (format!("in_{}", i.name), Self::input_label(i)))
                        .collect(),
                    outputs: inner
                        .outputs
                        .iter()
                        .map(|o| (format!("out_{}", o.name), Self::output_label(o)))
                        .collect(),
                });
                Item::Node(Node {
                    id: path,
                    lines,
                    shape: Shape::Box,
                    dashed: false,
                    ports,
                })
            }
        }
    }

    // -----------------------------------------------------------------------------
    // Automaton.

    /// The user automaton (atomic) or supervisor (compound): states with their
    /// sections, the initial state, `on`/`after`/`without` transitions, `may`
    /// choices dashed, `when` rules as labels; optionally inside `running` of the
    /// default automaton (Figure 2).
    pub(super) fn automaton(&self, component: &Component, nested: bool) -> Diagram {
        let automaton = component.automaton.as_ref();
        let prefix = if nested { "running." } else { "" };
        let mut items = Vec::new();
        let mut edges = Vec::new();
        let state_id = |name: &str| format!("{prefix}state.{name}");
        match automaton {
            Some(automaton) => {
                if let Some(initial) = &automaton.initial {
                    let id = format!("{prefix}initial");
                    items.push(Item::Node(Node {
                        id: id.clone(),
                        lines: vec![],
                        shape: Shape::Initial,
                        dashed: false,
                        ports: None,
                    }));
                    edges.push(edge(
                        End::node(id),
                        End::node(state_id(&initial.name)),
                        vec![],
                    ));
                }
                for state in &automaton.states {
                    items.push(Item::Node(Node {
                        id: state_id(&state.name),
                        lines: state_lines(state),
                        shape: Shape::Rounded,
                        dashed: false,
                        ports: None,
                    }));
                    for member in &state.members {
                        let from = End::node(state_id(&state.name));
                        match member {
                            StateMember::On { port, target } => edges.push(edge(
                                from,
                                End::node(state_id(&target.name)),
                                vec![format!("on {port}")],
                            )),
                            StateMember::After {
                                delay,
                                without,
                                target,
                            } => {
                                let label = match without {
                                    Some(port) => {
                                        format!("after {} without {port}", text::time(delay))
                                    }
                                    None => format!("after {}", text::time(delay)),
                                };
                                edges.push(edge(
                                    from,
                                    End::node(state_id(&target.name)),
                                    vec![label],
                                ));
                            }
                            StateMember::May(targets) => {
                                for target in targets {
                                    edges.push(Edge {
                                        style: EdgeStyle::Dashed,
                                        ..edge(
                                            from.clone(),
                                            End::node(state_id(&target.name)),
                                            vec!["may".to_owned()],
                                        )
                                    });
                                }
                            }
                            StateMember::When {
                                condition, target, ..
                            } => edges.push(edge(
                                from,
                                End::node(state_id(&target.name)),
                                vec![format!("when {}", text::expr(condition))],
                            )),
                            StateMember::Entry | StateMember::Exit | StateMember::Periodic(_) => {}
                        }
                    }
                }
            }
            None => {
                let name = match component.kind {
                    ComponentKind::Compound => IMPLICIT_STATE,
                    ComponentKind::Atomic => "running",
                };
                let id = format!("{prefix}initial");
                items.push(Item::Node(Node {
                    id: id.clone(),
                    lines: vec![],
                    shape: Shape::Initial,
                    dashed: false,
                    ports: None,
                }));
                items.push(Item::Node(Node {
                    id: state_id(name),
                    lines: vec![name.to_owned(), "(no user automaton declared)".to_owned()],
                    shape: Shape::Rounded,
                    dashed: false,
                    ports: None,
                }));
                edges.push(edge(End::node(id), End::node(state_id(name)), vec![]));
            }
        }
        if nested {
            let (items, default_edges) = default_automaton(items, component);
            edges.splice(0..0, default_edges);
            return Diagram {
                component: component.name.clone(),
                view: View::Automaton,
                left_to_right: false,
                items,
                edges,
            };
        }
        Diagram {
            component: component.name.clone(),
            view: View::Automaton,
            left_to_right: false,
            items,
            edges,
        }
    }
}

/// Where an edge to or from `port` (of an instance of a compound whose items are
/// under `prefix`) ends: the port of an atomic instance's node, the exported port
/// node of a compound instance, or the compound's own exported port node.
fn endpoint(prefix: &str, port: &PortRef, output: bool) -> End {
    let direction = if output { "out" } else { "in" };
    let Some(instance) = &port.instance else {
        return End::node(format!("{}{direction}.{}", port_prefix(prefix), port.port));
    };
    let path = join(prefix, &instance.name);
    if instance.compound {
        End::node(format!("{}{direction}.{}", port_prefix(&path), port.port))
    } else {
        End {
            id: path,
            port: Some(format!("{direction}_{}", port.port)),
        }
    }
}

/// The node or group of an instance.
fn instance_end(prefix: &str, instance: &InstanceRef) -> End {
    let path = join(prefix, &instance.name);
    if instance.compound {
        End::node(format!("{path}:group"))
    } else {
        End::node(path)
    }
}

/// The default automaton (paper Figure 2, `docs/runtime.md`), with `user` inside its
/// `running` state.
fn default_automaton(user: Vec<Item>, component: &Component) -> (Vec<Item>, Vec<Edge>) {
    let keyword = match component.kind {
        ComponentKind::Atomic => "user automaton",
        ComponentKind::Compound => "supervisor",
    };
    let state = |name: &str, dashed: bool| {
        Item::Node(Node {
            id: format!("default.{name}"),
            lines: vec![name.to_owned()],
            shape: Shape::Rounded,
            dashed,
            ports: None,
        })
    };
    let items = vec![
        Item::Node(Node {
            id: "default.initial".to_owned(),
            lines: vec![],
            shape: Shape::Initial,
            dashed: false,
            ports: None,
        }),
        state("starting", false),
        state("ready", false),
        Item::Group(Group {
            id: "running".to_owned(),
            label: vec![format!("running ({keyword})")],
            dashed: false,
            rounded: true,
            items: user,
        }),
        state("suspended", false),
        state("dead", false),
        state("starting_error", true),
        state("running_error", true),
        state("end", true),
    ];
    let d = |name: &str| {
        if name == "running" {
            End::node("running")
        } else {
            End::node(format!("default.{name}"))
        }
    };
    let mut edges = vec![edge(d("initial"), d("starting"), vec![])];
    let transitions: &[(&str, &str, &str)] = &[
        ("starting", "ready", "start ok"),
        ("starting", "starting_error", "start failed"),
        ("ready", "running", "c:running"),
        ("ready", "suspended", "c:suspended"),
        ("running", "ready", "c:ready"),
        ("running", "suspended", "c:suspended"),
        ("running", "running_error", "fault"),
        ("running", "end", "finished"),
        ("suspended", "ready", "c:ready"),
        ("suspended", "running", "c:running"),
        (
            "starting_error",
            "starting",
            "c:ready / c:running / c:suspended",
        ),
        (
            "running_error",
            "starting",
            "c:ready / c:running / c:suspended",
        ),
        ("end", "starting", "c:ready / c:running / c:suspended"),
    ];
    for (from, to, label) in transitions {
        edges.push(edge(d(from), d(to), vec![(*label).to_owned()]));
    }
    for from in [
        "ready",
        "running",
        "suspended",
        "starting_error",
        "running_error",
        "end",
    ] {
        edges.push(Edge {
            style: EdgeStyle::Dashed,
            ..edge(d(from), d("dead"), vec!["c:dead".to_owned()])
        });
    }
    (items, edges)
}

fn edge(from: End, to: End, label: Vec<String>) -> Edge {
    Edge {
        from,
        to,
        label,
        ports: None,
        style: EdgeStyle::Solid,
    }
}

fn port_node(id: &str, lines: Vec<String>, dashed: bool) -> Item {
    Item::Node(Node {
        id: id.to_owned(),
        lines,
        shape: Shape::Port,
        dashed,
        ports: None,
    })
}

/// The prefix of ids inside an instance's group (`base.`), or nothing at the top.
fn port_prefix(prefix: &str) -> String {
    if prefix.is_empty() {
        String::new()
    } else {
        format!("{prefix}:")
    }
}

/// `observable mode: BaseMode = BaseMode::Normal`, `observable pose = motion.odometry`.
fn variable_line(variable: &Variable) -> String {
    let kind = match variable.kind {
        VarKind::Observable => "observable",
        VarKind::Controllable => "controllable",
        VarKind::Local => "local",
    };
    let mut line = format!("{kind} {}", variable.name);
    if let Some(ty) = &variable.written {
        line.push_str(&format!(": {ty}"));
    }
    if let Some(value) = &variable.value {
        line.push_str(&format!(" = {}", text::value(value)));
    } else if let Some(path) = &variable.mapping {
        line.push_str(&format!(" = {}", path.join(".")));
    }
    line
}

/// `period 10ms..40ms, priority 5` from the component's `timing` block.
fn timing_line(component: &Component) -> Option<String> {
    let timing = component.timing.as_ref()?;
    let parts: Vec<String> = timing
        .iter()
        .map(|entry| match entry {
            TimingEntry::Period(lo, hi) => format!("period {}", text::interval(lo, hi.as_ref())),
            TimingEntry::MaxResponse(value) => format!("max_response {}", text::time(value)),
            TimingEntry::Priority(value) => format!("priority {value}"),
            TimingEntry::Quality(levels) => format!("quality {}", levels.join(", ")),
        })
        .collect();
    (!parts.is_empty()).then(|| parts.join("; "))
}

/// A state's name and its sections (`entry · periodic 100ms · exit`).
fn state_lines(state: &State) -> Vec<String> {
    let sections: Vec<String> = state
        .members
        .iter()
        .filter_map(|member| match member {
            StateMember::Entry => Some("entry".to_owned()),
            StateMember::Exit => Some("exit".to_owned()),
            StateMember::Periodic(period) => Some(match period {
                Some(period) => format!("periodic {}", text::time(period)),
                None => "periodic".to_owned(),
            }),
            _ => None,
        })
        .collect();
    let mut lines = vec![state.name.clone()];
    if !sections.is_empty() {
        lines.push(sections.join(" · "));
    }
    lines
}
