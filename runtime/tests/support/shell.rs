//! A component with ports and no behaviour, for feeding and reading ports from tests:
//! its spec is built at run time (and leaked, as a `&'static Spec` must be).

use std::sync::{Arc, Mutex};

use coolbot::{
    Automaton, Component, Context, Fault, InputSpec, OutputSpec, PortSet, Spec, StateSpec,
};

type AnswerFn = Box<dyn FnMut(usize) -> Result<(), Fault> + Send>;

/// The shell's code: one state, no sections; pull answers through a closure.
pub struct Shell {
    spec: &'static Spec,
    answer: Arc<Mutex<Option<AnswerFn>>>,
}

impl Automaton for Shell {
    fn spec(&self) -> &'static Spec {
        self.spec
    }
    fn answer(&mut self, output: usize, _cx: &mut Context) -> Result<(), Fault> {
        match self.answer.lock().unwrap().as_mut() {
            Some(answer) => answer(output),
            None => Err(Fault::message("no answer installed")),
        }
    }
}

/// A shell's one state: no sections, no transitions.
const SHELL_STATES: &[StateSpec] = &[StateSpec::new("idle")];

fn leak<T>(items: Vec<T>) -> &'static [T] {
    Box::leak(items.into_boxed_slice())
}

/// Builds a shell component port by port.
pub struct ShellBuilder {
    name: String,
    inputs: Vec<InputSpec>,
    outputs: Vec<OutputSpec>,
    ports: PortSet,
    answer: Arc<Mutex<Option<AnswerFn>>>,
}

impl ShellBuilder {
    pub fn new(name: &str) -> ShellBuilder {
        ShellBuilder {
            name: name.to_owned(),
            inputs: Vec::new(),
            outputs: Vec::new(),
            ports: PortSet::new(),
            answer: Arc::new(Mutex::new(None)),
        }
    }

    pub fn input(mut self, spec: InputSpec, port: &impl coolbot::InputPort) -> ShellBuilder {
        self.inputs.push(spec);
        self.ports = self.ports.input(port);
        self
    }

    pub fn output(mut self, spec: OutputSpec, port: &impl coolbot::OutputPort) -> ShellBuilder {
        self.outputs.push(spec);
        self.ports = self.ports.output(port);
        self
    }

    /// Install the pull answer: called with the output index on the shell's thread.
    pub fn answer(
        self,
        answer: impl FnMut(usize) -> Result<(), Fault> + Send + 'static,
    ) -> ShellBuilder {
        *self.answer.lock().unwrap() = Some(Box::new(answer));
        self
    }

    pub fn build(self) -> Component {
        let spec: &'static Spec = Box::leak(Box::new(
            Spec::new("Shell", "")
                .with_states(SHELL_STATES)
                .with_inputs(leak(self.inputs))
                .with_outputs(leak(self.outputs)),
        ));
        Component::new(
            self.name,
            Box::new(Shell {
                spec,
                answer: self.answer,
            }),
            self.ports,
        )
    }
}

pub fn input(name: &'static str, kind: coolbot::InputKind, pull: bool) -> InputSpec {
    let spec = InputSpec::new(name, kind, "");
    if pull { spec.pulled() } else { spec }
}

pub fn output(name: &'static str, kind: coolbot::OutputKind, pull: bool) -> OutputSpec {
    let spec = OutputSpec::new(name, kind, "");
    if pull { spec.pulled() } else { spec }
}

/// A supervisor with one state and nothing to do (a compound whose instances the
/// test drives).
pub struct Idle;

static IDLE: Spec = Spec::new("Idle", "").with_states(&[StateSpec::new("supervising")]);

impl coolbot::Supervisor for Idle {
    fn spec(&self) -> &'static Spec {
        &IDLE
    }
}
