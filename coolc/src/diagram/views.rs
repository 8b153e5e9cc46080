//! The three views, built from the AST of checked descriptions.

use std::collections::BTreeMap;

use super::text;
use super::{Diagram, Edge, EdgeStyle, End, Group, Item, Node, Ports, Shape, View, join};
use crate::ast::{self, ComponentKind, Member, StateMember};
use crate::check::model::{DEFAULT_CONTROLLABLES, DEFAULT_OBSERVABLES};
use crate::checked::Checked;

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

    pub(super) fn component(&self, name: &str) -> Option<&'a ast::Component> {
        self.checked.component(name).map(|(_, component)| component)
    }

    /// Every component's name, sorted.
    pub(super) fn names(&self) -> Vec<&'a str> {
        let mut names: Vec<&str> = self
            .checked
            .components()
            .map(|(_, component)| component.name.name.as_str())
            .collect();
        names.sort_unstable();
        names
    }

    // -----------------------------------------------------------------------------
    // Ports seen through exports.

    /// The input `port` of `component`, following exports down to the declared kind:
    /// `(kind as written, connection kind)`.
    fn input_kind(&self, component: &ast::Component, port: &str) -> Option<(String, &'static str)> {
        self.input_kind_depth(component, port, 0)
    }

    fn input_kind_depth(
        &self,
        component: &ast::Component,
        port: &str,
        depth: usize,
    ) -> Option<(String, &'static str)> {
        let input = inputs(component).find(|input| input.name.name == port)?;
        match &input.def {
            ast::InputDef::Export(target) => {
                let inner = self.instance_component(component, target)?;
                if depth > 64 {
                    return None;
                }
                self.input_kind_depth(inner, &target.port.name, depth + 1)
            }
            _ => Some((text::input_kind(input)?, text::connection_kind(input)?)),
        }
    }

    /// The output `port` of `component` as written, following exports.
    fn output_kind(&self, component: &ast::Component, port: &str) -> Option<String> {
        self.output_kind_depth(component, port, 0)
    }

    fn output_kind_depth(
        &self,
        component: &ast::Component,
        port: &str,
        depth: usize,
    ) -> Option<String> {
        let output = outputs(component).find(|output| output.name.name == port)?;
        match &output.def {
            ast::OutputDef::Export(target) => {
                let inner = self.instance_component(component, target)?;
                if depth > 64 {
                    return None;
                }
                self.output_kind_depth(inner, &target.port.name, depth + 1)
            }
            _ => text::output_kind(output),
        }
    }

    /// The component type of the instance a port reference names.
    fn instance_component(
        &self,
        component: &ast::Component,
        target: &ast::PortRef,
    ) -> Option<&'a ast::Component> {
        let instance = target.instance.as_ref()?;
        let declared = instances(component).find(|i| i.name.name == instance.name)?;
        self.component(&declared.component.name)
    }

    fn input_label(&self, component: &ast::Component, input: &ast::Input) -> String {
        let kind = self
            .input_kind(component, &input.name.name)
            .map_or_else(|| "?".to_owned(), |(kind, _)| kind);
        format!("{}: {kind}", input.name.name)
    }

    fn output_label(&self, component: &ast::Component, output: &ast::Output) -> String {
        let kind = self
            .output_kind(component, &output.name.name)
            .unwrap_or_else(|| "?".to_owned());
        format!("{}: {kind}", output.name.name)
    }

    /// The variables of one kind, as label lines (`odometry: Pose2D`, and a mapped
    /// one with the type of what it maps: `pose: Pose2D = motion.odometry`).
    fn variables(&self, component: &ast::Component, kind: ast::VarKind) -> Vec<String> {
        component
            .members
            .iter()
            .filter_map(|m| match m {
                Member::Variable(variable) if variable.kind == kind => Some(variable),
                _ => None,
            })
            .map(|variable| match (&variable.ty, &variable.value) {
                (Some(ty), _) => format!("{}: {}", variable.name.name, text::ty(ty)),
                (None, Some(value)) => match self.mapped_type(component, value, 0) {
                    Some(ty) => format!("{}: {ty} = {}", variable.name.name, text::expr(value)),
                    None => format!("{} = {}", variable.name.name, text::expr(value)),
                },
                (None, None) => variable.name.name.clone(),
            })
            .collect()
    }

    /// The type of the instance variable a mapping names (`motion.odometry`),
    /// through mappings of nested compounds; `None` for default variables.
    fn mapped_type(
        &self,
        component: &ast::Component,
        value: &ast::Expr,
        depth: usize,
    ) -> Option<String> {
        let ast::ExprKind::Path(parts) = &value.kind else {
            return None;
        };
        let [instance, name] = parts.as_slice() else {
            return None;
        };
        let declared = instances(component).find(|i| i.name.name == instance.name)?;
        let inner = self.component(&declared.component.name)?;
        let variable = inner.members.iter().find_map(|m| match m {
            Member::Variable(v) if v.name.name == name.name => Some(v),
            _ => None,
        })?;
        match (&variable.ty, &variable.value) {
            (Some(ty), _) => Some(text::ty(ty)),
            (None, Some(value)) if depth < 64 => self.mapped_type(inner, value, depth + 1),
            _ => None,
        }
    }

    // -----------------------------------------------------------------------------
    // Interface.

    /// The component with its ports around it (paper Figure 1): the control port
    /// `c` and the inputs on the left, the monitoring port `m` and the outputs on the
    /// right.
    pub(super) fn interface(&self, component: &ast::Component) -> Diagram {
        let name = &component.name.name;
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
        for member in &component.members {
            if let Member::Configuration(configuration) = member {
                let fields: Vec<String> = configuration
                    .fields
                    .iter()
                    .map(|f| format!("{}: {}", f.name.name, text::ty(&f.ty)))
                    .collect();
                control.push(format!("configuration {{ {} }}", fields.join(", ")));
            }
        }
        control.extend(self.variables(component, ast::VarKind::Controllable));
        let mut monitoring = vec!["m (monitoring)".to_owned(), DEFAULT_OBSERVABLES.join(", ")];
        monitoring.extend(self.variables(component, ast::VarKind::Observable));

        items.push(port_node("in.c", control, true));
        edges.push(edge(End::node("in.c"), End::node("component"), vec![]));
        for input in inputs(component) {
            let id = format!("in.{}", input.name.name);
            let mut lines = vec![self.input_label(component, input)];
            if let ast::InputDef::Export(target) = &input.def {
                lines.push(format!("= {}", text::port_ref(target)));
            }
            items.push(port_node(&id, lines, false));
            edges.push(edge(End::node(id), End::node("component"), vec![]));
        }
        items.push(port_node("out.m", monitoring, true));
        edges.push(edge(End::node("component"), End::node("out.m"), vec![]));
        for output in outputs(component) {
            let id = format!("out.{}", output.name.name);
            let mut lines = vec![self.output_label(component, output)];
            if let ast::OutputDef::Export(target) = &output.def {
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
    /// ports, variables, policies, substitutions and redundant groups (Figure 5).
    pub(super) fn structure(&self, component: &ast::Component) -> Diagram {
        let mut edges = Vec::new();
        let group = self.compound_group(
            component,
            "",
            vec![format!("«compound» {}", component.name.name)],
            &mut edges,
            0,
        );
        Diagram {
            component: component.name.name.clone(),
            view: View::Structure,
            left_to_right: true,
            items: vec![Item::Group(group)],
            edges,
        }
    }

    fn compound_group(
        &self,
        component: &ast::Component,
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
        for input in inputs(component) {
            if let ast::InputDef::Export(target) = &input.def {
                let id = format!("{}in.{}", port_prefix(prefix), input.name.name);
                items.push(port_node(
                    &id,
                    vec![self.input_label(component, input)],
                    false,
                ));
                let to = self.endpoint(component, prefix, target, false);
                edges.push(Edge {
                    style: EdgeStyle::Dotted,
                    ports: Some(format!("→ {}", text::port_ref(target))),
                    ..edge(End::node(id), to, vec![])
                });
            }
        }
        for output in outputs(component) {
            if let ast::OutputDef::Export(target) = &output.def {
                let id = format!("{}out.{}", port_prefix(prefix), output.name.name);
                items.push(port_node(
                    &id,
                    vec![self.output_label(component, output)],
                    false,
                ));
                let from = self.endpoint(component, prefix, target, true);
                edges.push(Edge {
                    style: EdgeStyle::Dotted,
                    ports: Some(format!("{} →", text::port_ref(target))),
                    ..edge(from, End::node(id), vec![])
                });
            }
        }

        // Instances, with redundant members gathered in a dashed group.
        let policies: BTreeMap<&str, &str> = component
            .members
            .iter()
            .filter_map(|m| match m {
                Member::OnError(on) => Some((on.instance.name.as_str(), on.policy.name.as_str())),
                _ => None,
            })
            .collect();
        let mut instance_items: Vec<(String, Item)> = Vec::new();
        for instance in instances(component) {
            let item = self.instance_item(instance, prefix, &policies, edges, depth);
            instance_items.push((instance.name.name.clone(), item));
        }
        for (index, members) in component
            .members
            .iter()
            .filter_map(|m| match m {
                Member::Redundant(r) => Some(&r.members),
                _ => None,
            })
            .enumerate()
        {
            let names: Vec<&str> = members.iter().map(|m| m.name.as_str()).collect();
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
        for member in &component.members {
            if let Member::Connect(connect) = member {
                let from = self.endpoint(component, prefix, &connect.from, true);
                let to = self.endpoint(component, prefix, &connect.to, false);
                let kind = self
                    .port_component(component, &connect.to)
                    .and_then(|(inner, port)| self.input_kind(inner, port))
                    .map_or("?", |(_, kind)| kind);
                let mut label = vec![kind.to_owned()];
                if let Some(via) = &connect.via {
                    label = vec![format!("{kind} via {}", via.name)];
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
        }

        // Substitutions.
        for instance in instances(component) {
            if let Some(primary) = &instance.substitutes {
                let from = self.instance_end(component, prefix, &instance.name.name);
                let to = self.instance_end(component, prefix, &primary.name);
                edges.push(Edge {
                    style: EdgeStyle::Dashed,
                    ..edge(from, to, vec!["substitutes".to_owned()])
                });
            }
        }

        // Variables, the recovery queue and the restart budget, in a note.
        let mut note = Vec::new();
        for member in &component.members {
            match member {
                Member::Variable(variable) => note.push(variable_line(variable)),
                Member::Recovery(recovery) => {
                    let mut parts = Vec::new();
                    if let Some(every) = &recovery.retry_every {
                        parts.push(format!("retry every {}", text::expr(every)));
                    }
                    if let Some(deadline) = &recovery.deadline {
                        parts.push(format!("deadline {}", text::expr(deadline)));
                    }
                    note.push(format!("recovery {{ {} }}", parts.join("; ")));
                }
                Member::Restart(restart) => {
                    let mut parts = Vec::new();
                    if let Some((count, window)) = &restart.limit {
                        parts.push(format!(
                            "limit {} in {}",
                            text::expr(count),
                            text::expr(window)
                        ));
                    }
                    if let Some((first, last)) = &restart.backoff {
                        parts.push(format!(
                            "backoff {}..{}",
                            text::expr(first),
                            text::expr(last)
                        ));
                    }
                    note.push(format!("restart {{ {} }}", parts.join("; ")));
                }
                _ => {}
            }
        }
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
        instance: &ast::Instance,
        prefix: &str,
        policies: &BTreeMap<&str, &str>,
        edges: &mut Vec<Edge>,
        depth: usize,
    ) -> Item {
        let path = join(prefix, &instance.name.name);
        let mut lines = vec![format!(
            "{}: {}",
            instance.name.name, instance.component.name
        )];
        if let Some(node) = &instance.node {
            // `on "node"`: on that node behind a proxy when the process is on a
            // network, else in the compound's process (`docs/distribution.md`).
            lines.push(format!("on \"{}\" (remote when on a network)", node.value));
        }
        if let Some(policy) = policies.get(instance.name.name.as_str()) {
            lines.push(format!("on error: {policy}"));
        }
        let inner = self.component(&instance.component.name);
        match inner {
            Some(inner) if inner.kind == ComponentKind::Compound && depth < 16 => {
                Item::Group(self.compound_group(inner, &path, lines, edges, depth + 1))
            }
            _ => {
                let ports = inner.map(|inner| Ports {
                    inputs: inputs(inner)
                        .map(|i| (format!("in_{}", i.name.name), self.input_label(inner, i)))
                        .collect(),
                    outputs: outputs(inner)
                        .map(|o| (format!("out_{}", o.name.name), self.output_label(inner, o)))
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

    /// The component and port name a port reference of `component` reaches (one
    /// level: the instance's component, or `component` itself for a bare port).
    fn port_component<'p>(
        &self,
        component: &'a ast::Component,
        port: &'p ast::PortRef,
    ) -> Option<(&'a ast::Component, &'p str)> {
        match &port.instance {
            Some(_) => Some((self.instance_component(component, port)?, &port.port.name)),
            None => Some((component, &port.port.name)),
        }
    }

    /// Where an edge to or from `port` (of an instance of `component`, whose items
    /// are under `prefix`) ends: the port of an atomic instance's node, the exported
    /// port node of a compound instance, or the compound's own exported port node.
    fn endpoint(
        &self,
        component: &ast::Component,
        prefix: &str,
        port: &ast::PortRef,
        output: bool,
    ) -> End {
        let direction = if output { "out" } else { "in" };
        let Some(instance) = &port.instance else {
            return End::node(format!(
                "{}{direction}.{}",
                port_prefix(prefix),
                port.port.name
            ));
        };
        let path = join(prefix, &instance.name);
        match self.instance_component(component, port) {
            Some(inner) if inner.kind == ComponentKind::Compound => End::node(format!(
                "{}{direction}.{}",
                port_prefix(&path),
                port.port.name
            )),
            _ => End {
                id: path,
                port: Some(format!("{direction}_{}", port.port.name)),
            },
        }
    }

    /// The node or group of an instance.
    fn instance_end(&self, component: &ast::Component, prefix: &str, name: &str) -> End {
        let path = join(prefix, name);
        let compound = instances(component)
            .find(|i| i.name.name == name)
            .and_then(|i| self.component(&i.component.name))
            .is_some_and(|c| c.kind == ComponentKind::Compound);
        if compound {
            End::node(format!("{path}:group"))
        } else {
            End::node(path)
        }
    }

    // -----------------------------------------------------------------------------
    // Automaton.

    /// The user automaton (atomic) or supervisor (compound): states with their
    /// sections, the initial state, `on`/`after`/`without` transitions, `may`
    /// choices dashed, `when` rules as labels; optionally inside `running` of the
    /// default automaton (Figure 2).
    pub(super) fn automaton(&self, component: &ast::Component, nested: bool) -> Diagram {
        let automaton = component.members.iter().find_map(|m| match m {
            Member::Automaton(automaton) => Some(automaton),
            _ => None,
        });
        let prefix = if nested { "running." } else { "" };
        let mut items = Vec::new();
        let mut edges = Vec::new();
        let state_id = |name: &str| format!("{prefix}state.{name}");
        match automaton {
            Some(automaton) => {
                if let Some(initial) = automaton.initial.first() {
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
                        id: state_id(&state.name.name),
                        lines: state_lines(state),
                        shape: Shape::Rounded,
                        dashed: false,
                        ports: None,
                    }));
                    for member in &state.members {
                        let from = End::node(state_id(&state.name.name));
                        match member {
                            StateMember::On { port, target, .. } => edges.push(edge(
                                from,
                                End::node(state_id(&target.name)),
                                vec![format!("on {}", port.name)],
                            )),
                            StateMember::After {
                                delay,
                                without,
                                target,
                                ..
                            } => {
                                let label = match without {
                                    Some(port) => {
                                        format!("after {} without {}", text::expr(delay), port.name)
                                    }
                                    None => format!("after {}", text::expr(delay)),
                                };
                                edges.push(edge(
                                    from,
                                    End::node(state_id(&target.name)),
                                    vec![label],
                                ));
                            }
                            StateMember::May { targets, .. } => {
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
                            StateMember::Entry(_)
                            | StateMember::Exit(_)
                            | StateMember::Periodic { .. } => {}
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
                component: component.name.name.clone(),
                view: View::Automaton,
                left_to_right: false,
                items,
                edges,
            };
        }
        Diagram {
            component: component.name.name.clone(),
            view: View::Automaton,
            left_to_right: false,
            items,
            edges,
        }
    }
}

/// The default automaton (paper Figure 2, `docs/runtime.md`), with `user` inside its
/// `running` state.
fn default_automaton(user: Vec<Item>, component: &ast::Component) -> (Vec<Item>, Vec<Edge>) {
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

fn inputs(component: &ast::Component) -> impl Iterator<Item = &ast::Input> {
    component.members.iter().filter_map(|m| match m {
        Member::Input(input) => Some(input),
        _ => None,
    })
}

fn outputs(component: &ast::Component) -> impl Iterator<Item = &ast::Output> {
    component.members.iter().filter_map(|m| match m {
        Member::Output(output) => Some(output),
        _ => None,
    })
}

fn instances(component: &ast::Component) -> impl Iterator<Item = &ast::Instance> {
    component.members.iter().filter_map(|m| match m {
        Member::Instance(instance) => Some(instance),
        _ => None,
    })
}

/// `observable mode: BaseMode = BaseMode::Normal`, `observable pose = motion.odometry`.
fn variable_line(variable: &ast::Variable) -> String {
    let kind = match variable.kind {
        ast::VarKind::Observable => "observable",
        ast::VarKind::Controllable => "controllable",
        ast::VarKind::Local => "local",
    };
    let mut line = format!("{kind} {}", variable.name.name);
    if let Some(ty) = &variable.ty {
        line.push_str(&format!(": {}", text::ty(ty)));
    }
    if let Some(value) = &variable.value {
        line.push_str(&format!(" = {}", text::expr(value)));
    }
    line
}

/// `period 10ms..40ms, priority 5` from the component's `timing` block.
fn timing_line(component: &ast::Component) -> Option<String> {
    let timing = component.members.iter().find_map(|m| match m {
        Member::Timing(timing) => Some(timing),
        _ => None,
    })?;
    let parts: Vec<String> = timing
        .entries
        .iter()
        .map(|entry| match entry {
            ast::TimingEntry::Period(interval) => format!("period {}", text::interval(interval)),
            ast::TimingEntry::MaxResponse(value) => format!("max_response {}", text::expr(value)),
            ast::TimingEntry::Priority(value) => format!("priority {}", text::expr(value)),
            ast::TimingEntry::Quality(levels, _) => format!(
                "quality {}",
                levels
                    .iter()
                    .map(|l| l.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        })
        .collect();
    (!parts.is_empty()).then(|| parts.join("; "))
}

/// A state's name and its sections (`entry · periodic 100ms · exit`).
fn state_lines(state: &ast::State) -> Vec<String> {
    let sections: Vec<String> = state
        .members
        .iter()
        .filter_map(|member| match member {
            StateMember::Entry(_) => Some("entry".to_owned()),
            StateMember::Exit(_) => Some("exit".to_owned()),
            StateMember::Periodic { period, .. } => Some(match period {
                Some(period) => format!("periodic {}", text::expr(period)),
                None => "periodic".to_owned(),
            }),
            _ => None,
        })
        .collect();
    let mut lines = vec![state.name.name.clone()];
    if !sections.is_empty() {
        lines.push(sections.join(" · "));
    }
    lines
}
