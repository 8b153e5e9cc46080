//! Lowering a user automaton (an atomic's) or a supervisor (a compound's) from the
//! resolved model: each state's `SPEC` entry (sections, `on`, `after`, `may`), the
//! section and choice stubs with their glue arms, and, for a supervisor, its `when`
//! rules for the rule compiler (`compound/rules.rs`).

use super::{duration_code, option_duration};
use crate::checked::model::{Automaton, Ref, State, StateMember, Typed};
use crate::ident;
use crate::ir;

/// A lowered automaton.
pub(super) struct Lowered<'m> {
    pub(super) states: Vec<ir::State>,
    /// The index of the initial state.
    pub(super) initial: usize,
    pub(super) methods: Vec<ir::Method>,
    pub(super) section_arms: Vec<(String, ir::Code)>,
    pub(super) choose_arms: Vec<ir::ChooseArm>,
    /// Every `when` rule, in order (a supervisor's).
    pub(super) when: Vec<When<'m>>,
}

/// A supervisor's `when` rule: its state, its typed condition, and its target.
pub(super) struct When<'m> {
    pub(super) state: String,
    pub(super) condition: &'m Typed,
    pub(super) target: String,
}

/// The states of `automaton` (none when it is not written), with stubs worded for
/// `owner`. States and ports are referred to by the indices the model resolved.
pub(super) fn states(automaton: Option<&Automaton>, owner: SectionOwner) -> Lowered<'_> {
    let states_model: &[State] = automaton.map_or(&[], |a| a.states.as_slice());
    let initial = automaton
        .and_then(|a| a.initial.as_ref())
        .map_or(0, |initial| initial.index);
    let mut states = Vec::new();
    let mut methods = Vec::new();
    let mut section_arms = Vec::new();
    let mut choose_arms = Vec::new();
    let mut when = Vec::new();
    for (index, state) in states_model.iter().enumerate() {
        let name = &state.name;
        let (mut entry, mut exit, mut periodic) = (false, false, None);
        let (mut on, mut after, mut may) = (Vec::new(), Vec::new(), Vec::new());
        for member in &state.members {
            match member {
                StateMember::Entry => entry = true,
                StateMember::Exit => exit = true,
                StateMember::Periodic(period) => {
                    periodic = Some(ir::Code::some(ir::Code::structure(
                        "::coolbot::PeriodicSpec",
                        vec![("period", option_duration(period.as_ref()))],
                    )));
                }
                StateMember::On { port, target } => on.push(ir::Code::structure(
                    "::coolbot::OnSpec",
                    vec![("port", index_code(port)), ("target", index_code(target))],
                )),
                StateMember::After {
                    delay,
                    without,
                    target,
                } => after.push(ir::Code::structure(
                    "::coolbot::AfterSpec",
                    vec![
                        ("delay", duration_code(delay.nanos)),
                        (
                            "without",
                            ir::Code::option(without.as_ref().map(index_code)),
                        ),
                        ("target", index_code(target)),
                    ],
                )),
                StateMember::May(targets) => may_targets(targets, &mut may),
                StateMember::When {
                    condition, target, ..
                } => when.push(When {
                    state: name.clone(),
                    condition,
                    target: target.name.clone(),
                }),
            }
        }
        let docs = SectionDocs::of(state);
        section_stubs(
            &StateSections {
                index,
                name,
                entry,
                periodic: periodic.is_some(),
                exit,
                docs: SectionDocs::of(state),
            },
            owner,
            &mut methods,
            &mut section_arms,
        );
        let may_enum = (!may.is_empty()).then(|| format!("{}May", ident::camel_raw(name)));
        if let Some(may_enum) = &may_enum {
            choose_stub(
                index,
                name,
                may_enum,
                &may,
                &docs.may,
                &mut methods,
                &mut choose_arms,
            );
        }
        let spec = ir::Code::structure(
            "::coolbot::StateSpec",
            vec![
                ("name", ir::Code::string(name)),
                ("entry", ir::Code::atom(entry.to_string())),
                ("exit", ir::Code::atom(exit.to_string())),
                (
                    "periodic",
                    periodic.unwrap_or_else(|| ir::Code::atom("None")),
                ),
                ("on", ir::Code::slice(on)),
                ("after", ir::Code::slice(after)),
                (
                    "may",
                    ir::Code::slice(
                        may.iter()
                            .map(|(_, i, _)| ir::Code::atom(i.to_string()))
                            .collect(),
                    ),
                ),
            ],
        );
        states.push(ir::State {
            doc: state.doc.clone(),
            cool_name: name.clone(),
            variant: ident::camel(name),
            may_enum,
            may,
            spec,
        });
    }
    Lowered {
        states,
        initial,
        methods,
        section_arms,
        choose_arms,
        when,
    }
}

/// The index a state or port reference resolved to.
fn index_code(reference: &Ref) -> ir::Code {
    ir::Code::atom(reference.index.to_string())
}

/// Adds `may` targets `targets` to `may` as `(variant, index, name)`, each once.
fn may_targets(targets: &[Ref], may: &mut Vec<(String, usize, String)>) {
    for target in targets {
        if !may.iter().any(|(_, _, n)| *n == target.name) {
            may.push((
                ident::camel(&target.name),
                target.index,
                target.name.clone(),
            ));
        }
    }
}

/// The `<state>_choose` stub of state `name` (index `index`) whose `may` targets are
/// `may`, returning `Option<may_enum>`, and its glue arm.
pub(super) fn choose_stub(
    index: usize,
    name: &str,
    may_enum: &str,
    may: &[(String, usize, String)],
    written: &[String],
    methods: &mut Vec<ir::Method>,
    choose_arms: &mut Vec<ir::ChooseArm>,
) {
    let method = ident::method("", name, "_choose");
    let targets: Vec<String> = may.iter().map(|(_, _, n)| format!("`{n}`")).collect();
    methods.push(ir::Method {
        name: method.clone(),
        doc: with_written(
            format!(
                "Called after each section of state `{name}`: return a target ({}) to move there, or `None` to stay.",
                targets.join(", ")
            ),
            written,
        ),
        signature: format!(
            "fn {method}(&mut self, cx: &mut Cx<'_>) -> ::core::option::Option<{may_enum}>"
        ),
        user_signature: format!("fn {method}(&mut self, cx: &mut Cx<'_>) -> Option<{may_enum}>"),
        stub_body: vec![
            ir::StubLine::Comment(format!(
                "// State `{name}`: return Some({may_enum}::...) to leave it."
            )),
            ir::StubLine::Statement("let _ = cx;".to_owned()),
            ir::StubLine::Value(ir::Code::atom("None")),
        ],
    });
    choose_arms.push(ir::ChooseArm {
        state: index,
        method,
        may_enum: may_enum.to_owned(),
        targets: may.iter().map(|(v, i, _)| (v.clone(), *i)).collect(),
    });
}

/// Whose user automaton a state belongs to: the wording of its stubs and the receiver
/// the glue calls them on.
#[derive(Clone, Copy)]
pub(super) enum SectionOwner {
    /// An atomic component's `Behavior` (`behavior.<state>_<section>`).
    Atomic,
    /// A compound's `Supervisor` (`supervisor.<state>_<section>`).
    Supervisor,
}

/// The sections one state declares.
pub(super) struct StateSections<'a> {
    /// The state's index in `SPEC.states`.
    pub(super) index: usize,
    /// The state's name.
    pub(super) name: &'a str,
    pub(super) entry: bool,
    pub(super) periodic: bool,
    pub(super) exit: bool,
    /// The doc comments written on the state's sections and `may` rules.
    pub(super) docs: SectionDocs,
}

/// The doc comments on a state's sections and `may` rules: they document the trait
/// methods generated for them.
#[derive(Default)]
pub(super) struct SectionDocs {
    pub(super) entry: Vec<String>,
    pub(super) periodic: Vec<String>,
    pub(super) exit: Vec<String>,
    pub(super) may: Vec<String>,
}

impl SectionDocs {
    /// The doc comments of a resolved state's sections and `may` rules.
    pub(super) fn of(state: &State) -> SectionDocs {
        let mut docs = SectionDocs::default();
        for (member, doc) in state.members.iter().zip(&state.member_docs) {
            let lines = match member {
                StateMember::Entry => &mut docs.entry,
                StateMember::Periodic(_) => &mut docs.periodic,
                StateMember::Exit => &mut docs.exit,
                StateMember::May(_) => &mut docs.may,
                _ => continue,
            };
            lines.extend(doc.iter().cloned());
        }
        docs
    }
}

/// `first`, then (after an empty line) the written doc comment `written`, if any.
fn with_written(first: String, written: &[String]) -> Vec<String> {
    let mut lines = vec![first];
    if !written.is_empty() {
        lines.push(String::new());
        lines.extend(written.iter().cloned());
    }
    lines
}

/// One required stub and one glue arm per declared section of a state, in the order
/// entry, periodic, exit.
pub(super) fn section_stubs(
    state: &StateSections<'_>,
    owner: SectionOwner,
    methods: &mut Vec<ir::Method>,
    section_arms: &mut Vec<(String, ir::Code)>,
) {
    let (subject, of_state, comment_state, receiver) = match owner {
        SectionOwner::Atomic => ("automaton", "state", "State", "behavior"),
        SectionOwner::Supervisor => (
            "supervisor",
            "supervisor state",
            "Supervisor state",
            "supervisor",
        ),
    };
    let name = state.name;
    let kinds = [
        (
            state.entry,
            "entry",
            "Entry",
            format!("runs once each time the {subject} enters the state"),
            &state.docs.entry,
        ),
        (
            state.periodic,
            "periodic",
            "Periodic",
            "runs once per period while in the state".to_owned(),
            &state.docs.periodic,
        ),
        (
            state.exit,
            "exit",
            "Exit",
            format!("runs once each time the {subject} leaves the state"),
            &state.docs.exit,
        ),
    ];
    for (present, suffix, section, when, written) in kinds {
        if !present {
            continue;
        }
        let method = ident::method("", name, &format!("_{suffix}"));
        methods.push(ir::Method {
            name: method.clone(),
            doc: with_written(
                format!("The {suffix} section of {of_state} `{name}`: {when}."),
                written,
            ),
            signature: format!(
                "fn {method}(&mut self, cx: &mut Cx<'_>) -> ::coolbot::SectionResult"
            ),
            user_signature: format!(
                "fn {method}(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult"
            ),
            stub_body: vec![
                ir::StubLine::Comment(format!(
                    "// {comment_state} `{name}`, {suffix} section: {when}."
                )),
                ir::StubLine::Statement("let _ = cx;".to_owned()),
                ir::StubLine::Value(ir::Code::call("Ok", vec![ir::Code::atom("()")])),
            ],
        });
        section_arms.push((
            format!("({}, ::coolbot::Section::{section})", state.index),
            ir::Code::atom(receiver).method(
                method,
                vec![ir::Code::prefix("&mut ", ir::Code::atom("cx"))],
            ),
        ));
    }
}
