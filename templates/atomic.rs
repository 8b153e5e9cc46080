{%- import "macros.rs" as m -%}
{% call m::header(krate.sources_text()) %}{% endcall %}
//! Generated code of atomic component `{{ c.type_name }}`.
//!
//! Implement [`Behavior`] (the user file `src/{{ c.module }}.rs` holds the stubs) and
//! call [`component`] to get a `coolbot::Component` to add to a `coolbot::System`.
{%- if !c.doc.is_empty() %}
//!
{%- for line in c.doc %}
//! {{ line }}
{%- endfor %}
{%- endif %}

/// The `configuration` block: the default controllable variable `configuration`.
#[derive(Clone, Debug, PartialEq, ::serde::Serialize, ::serde::Deserialize{% if c.config_derives_default() %}, Default{% endif %})]
#[serde(default)]
pub struct Config {
{%- for f in c.config %}
{%- call m::doc(&f.doc) %}{% endcall %}
    {%- if f.renamed() %}
    #[serde(rename = "{{ f.cool_name }}")]
    {%- endif %}
    pub {{ f.name }}: {{ f.ty }},
{%- endfor %}
}

{% if !c.config_derives_default() %}
impl ::core::default::Default for Config {
    fn default() -> Self {
        Self {
        {%- for f in c.config %}
            {{ f.name }}: {{ f.default }},
        {%- endfor %}
        }
    }
}
{% endif %}

/// The component's own variables: observable, controllable and local.
#[derive(Clone, Debug{% if c.vars_derive_default() %}, Default{% endif %})]
pub struct Vars {
{%- for v in c.vars %}
{%- call m::doc(&v.field.doc) %}{% endcall %}
    /// ({{ v.kind }} variable `{{ v.field.cool_name }}: {{ v.cool_ty }}`.)
    pub {{ v.field.name }}: {{ v.field.ty }},
{%- endfor %}
}

{% if !c.vars_derive_default() %}
impl ::core::default::Default for Vars {
    fn default() -> Self {
        Self {
        {%- for v in c.vars %}
            {{ v.field.name }}: {{ v.field.default }},
        {%- endfor %}
        }
    }
}
{% endif %}

/// The input ports, in declaration order.
pub struct Inputs {
{%- for p in c.inputs %}
{%- call m::doc(&p.doc) %}{% endcall %}
    pub {{ p.field }}: {{ p.handle }},
{%- endfor %}
}

/// The output ports, in declaration order.
pub struct Outputs {
{%- for p in c.outputs %}
{%- call m::doc(&p.doc) %}{% endcall %}
    pub {{ p.field }}: {{ p.handle }},
{%- endfor %}
}

/// The states of the user automaton (inside the default automaton's `running`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum UserState {
{%- for s in c.states %}
{%- call m::doc(&s.doc) %}{% endcall %}
    {{ s.variant }},
{%- endfor %}
}

impl UserState {
    /// Every state, in declaration order.
    pub const ALL: [UserState; {{ c.states.len() }}] = [{% for s in c.states %}UserState::{{ s.variant }},{% endfor %}];

    /// The state's index in [`SPEC`]`.states`.
    pub fn index(self) -> usize {
        match self {
        {%- for s in c.states %}
            UserState::{{ s.variant }} => {{ loop.index0 }},
        {%- endfor %}
        }
    }

    /// The state's name as written in the description.
    pub fn name(self) -> &'static str {
        match self {
        {%- for s in c.states %}
            UserState::{{ s.variant }} => "{{ s.cool_name }}",
        {%- endfor %}
        }
    }
}
{% for s in c.states %}
{%- if let Some(may_enum) = s.may_enum %}
/// The targets state `{{ s.cool_name }}` may choose (its `may` list): any other
/// transition is unrepresentable.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum {{ may_enum }} {
{%- for (variant, _, name) in s.may %}
    /// Go to state `{{ name }}`.
    {{ variant }},
{%- endfor %}
}

impl {{ may_enum }} {
    /// The target state.
    pub fn state(self) -> UserState {
        match self {
        {%- for (variant, index, _) in s.may %}
            {{ may_enum }}::{{ variant }} => UserState::ALL[{{ index }}],
        {%- endfor %}
        }
    }
}
{% endif %}
{%- endfor %}

/// The declared exceptions; `Exception::X.raise("why")` is a `coolbot::Fault` to
/// return from a section.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Exception {
{%- for e in c.exceptions %}
{%- call m::doc(&e.doc) %}{% endcall %}
    {{ e.variant }},
{%- endfor %}
}

impl Exception {
    /// The exception's index in [`SPEC`]`.exceptions`.
    pub fn index(self) -> usize {
        match self {
        {%- for e in c.exceptions %}
            Exception::{{ e.variant }} => {{ loop.index0 }},
        {%- endfor %}
        }
    }

    /// A fault raising this exception with `message`: its continuity plan runs.
    pub fn raise(self, message: impl ::core::convert::Into<::std::string::String>) -> ::coolbot::Fault {
        ::coolbot::Fault::exception(self.index(), message)
    }
}

/// What a section sees.
pub struct Cx<'a> {
    /// The current configuration.
    pub config: &'a Config,
    /// The component's variables.
    pub vars: &'a mut Vars,
    /// The input ports.
    pub inputs: &'a Inputs,
    /// The output ports.
    pub outputs: &'a Outputs,
    /// The runtime side: time, result, end of task, period, quality.
    pub rt: &'a mut ::coolbot::Context,
}

/// The component's code: one required method per section, `may` choice, exception
/// handler and pull answer, so a missing one is a compile error that names it.
///
/// A section returns `Err(fault)` to raise an exception (see [`Exception::raise`]);
/// any other error, or a panic, takes the component to `running_error`.
pub trait Behavior: ::core::marker::Send + 'static {
    /// Called in the default automaton's `starting` state (acquire resources, read
    /// the configuration). An error takes the component to `starting_error`.
    fn start(&mut self, cx: &mut Cx<'_>) -> ::coolbot::SectionResult {
        let _ = cx;
        Ok(())
    }

    /// Called when the component leaves `running`/`suspended` for `ready`, `dead`
    /// or `end` (release resources).
    fn stop(&mut self, cx: &mut Cx<'_>) {
        let _ = cx;
    }
{% for method in c.methods %}


{% call m::doc(&method.doc) %}{% endcall %}
    {{ method.signature }};
{%- endfor %}
}

/// The static shape of the component, read by the runtime.
pub static SPEC: ::coolbot::Spec = ::coolbot::Spec {
    type_name: "{{ c.type_name }}",
    doc: {{ c.doc_literal() }},
    states: &[
    {%- for s in c.states %}
        {{ s.spec }},
    {%- endfor %}
    ],
    initial: {{ c.initial }},
    inputs: &[
    {%- for p in c.inputs %}
        ::coolbot::InputSpec { name: "{{ p.cool_name }}", kind: {{ p.kind }}, packet: "{{ p.packet }}", pull: {{ p.pull }} },
    {%- endfor %}
    ],
    outputs: &[
    {%- for p in c.outputs %}
        ::coolbot::OutputSpec { name: "{{ p.cool_name }}", kind: {{ p.kind }}, packet: "{{ p.packet }}", pull: {{ p.pull }} },
    {%- endfor %}
    ],
    variables: &[
    {%- for v in c.vars %}
    {%- if v.spec_index.is_some() %}
        ::coolbot::VarSpec { name: "{{ v.field.cool_name }}", kind: ::coolbot::VarKind::{{ v.kind }}, ty: "{{ v.cool_ty }}", doc: {{ v.doc_literal() }} },
    {%- endif %}
    {%- endfor %}
    ],
    exceptions: &[
    {%- for e in c.exceptions %}
        {{ e.spec }},
    {%- endfor %}
    ],
    timing: {{ c.timing }},
};

/// Builds an unstarted `{{ c.type_name }}` named `name` running `behavior`.
pub fn component(name: impl ::core::convert::Into<::std::string::String>, behavior: impl Behavior) -> ::coolbot::Component {
    component_with(name, behavior, Config::default(), Vars::default())
}

/// Like [`component`], starting from the given configuration and variables (a
/// compound's instance overrides use it).
pub fn component_with(
    name: impl ::core::convert::Into<::std::string::String>,
    behavior: impl Behavior,
    config: Config,
    vars: Vars,
) -> ::coolbot::Component {
    let inputs = Inputs {
    {%- for p in c.inputs %}
        {{ p.field }}: {{ p.ctor }},
    {%- endfor %}
    };
    let outputs = Outputs {
    {%- for p in c.outputs %}
        {{ p.field }}: {{ p.ctor }},
    {%- endfor %}
    };
    let ports = ::coolbot::PortSet::new()
    {%- for p in c.inputs %}
        .input(&inputs.{{ p.field }})
    {%- endfor %}
    {%- for p in c.outputs %}
        .output(&outputs.{{ p.field }})
    {%- endfor %};
    let glue = __CoolGlue {
        behavior,
        config,
        vars,
        inputs,
        outputs,
    };
    ::coolbot::Component::new(name, ::std::boxed::Box::new(glue), ports)
}

/// Adapts a [`Behavior`] to the runtime's index-based `coolbot::Automaton`.
struct __CoolGlue<B> {
    behavior: B,
    config: Config,
    vars: Vars,
    inputs: Inputs,
    outputs: Outputs,
}

impl<B: Behavior> ::coolbot::Automaton for __CoolGlue<B> {
    fn spec(&self) -> &'static ::coolbot::Spec {
        &SPEC
    }

    fn start(&mut self, rt: &mut ::coolbot::Context) -> ::coolbot::SectionResult {
        let Self { behavior, config, vars, inputs, outputs } = self;
        let mut cx = Cx { config, vars, inputs, outputs, rt };
        behavior.start(&mut cx)
    }

    fn stop(&mut self, rt: &mut ::coolbot::Context) {
        let Self { behavior, config, vars, inputs, outputs } = self;
        let mut cx = Cx { config, vars, inputs, outputs, rt };
        behavior.stop(&mut cx);
    }

    fn section(&mut self, state: usize, section: ::coolbot::Section, rt: &mut ::coolbot::Context) -> ::coolbot::SectionResult {
    {%- if c.section_arms.is_empty() %}
        let _ = (state, section, rt);
        Ok(())
    {%- else %}
        let Self { behavior, config, vars, inputs, outputs } = self;
        let mut cx = Cx { config, vars, inputs, outputs, rt };
        match (state, section) {
        {%- for (pattern, call) in c.section_arms %}
            {{ pattern }} => {{ call }},
        {%- endfor %}
            _ => Ok(()),
        }
    {%- endif %}
    }

    fn choose(&mut self, state: usize, rt: &mut ::coolbot::Context) -> ::core::option::Option<usize> {
    {%- if c.choose_arms.is_empty() %}
        let _ = (state, rt);
        None
    {%- else %}
        let Self { behavior, config, vars, inputs, outputs } = self;
        let mut cx = Cx { config, vars, inputs, outputs, rt };
        match state {
        {%- for arm in c.choose_arms %}
            {{ arm.state }} => behavior.{{ arm.method }}(&mut cx).map(|target| target.state().index()),
        {%- endfor %}
            _ => None,
        }
    {%- endif %}
    }

    fn exception(&mut self, exception: usize, message: &str, rt: &mut ::coolbot::Context) {
    {%- if c.exceptions.is_empty() %}
        let _ = (exception, message, rt);
    {%- else %}
        let Self { behavior, config, vars, inputs, outputs } = self;
        let mut cx = Cx { config, vars, inputs, outputs, rt };
        let handlers: [fn(&mut B, &mut Cx<'_>, &str); {{ c.exceptions.len() }}] = [
        {%- for e in c.exceptions %}
            B::{{ e.handler }},
        {%- endfor %}
        ];
        if let Some(handler) = handlers.get(exception) {
            handler(behavior, &mut cx, message);
        }
    {%- endif %}
    }

    fn answer(&mut self, output: usize, rt: &mut ::coolbot::Context) -> ::coolbot::SectionResult {
    {%- if c.answer_arms.is_empty() %}
        let _ = (output, rt);
        Ok(())
    {%- else %}
        let Self { behavior, config, vars, inputs, outputs } = self;
        let mut cx = Cx { config, vars, inputs, outputs: &*outputs, rt };
        match output {
        {%- for arm in c.answer_arms %}
            {{ arm.output }} => {
                let packet = behavior.{{ arm.method }}(&mut cx)?;
                outputs.{{ arm.field }}.{{ arm.send }}(packet);
                Ok(())
            }
        {%- endfor %}
            _ => Ok(()),
        }
    {%- endif %}
    }

    fn configure(&mut self, configuration: &::coolbot::Value) -> ::core::result::Result<(), ::std::string::String> {
        self.config = super::__cool_configure(&self.config, configuration)?;
        Ok(())
    }

    fn set(&mut self, variable: usize, value: &::coolbot::Value) -> ::core::result::Result<(), ::std::string::String> {
    {%- if c.has_controllable() %}
        match variable {
        {%- for v in c.vars %}
        {%- if v.controllable() %}
            {{ v.spec_index.unwrap_or_default() }} => {
                self.vars.{{ v.field.name }} = {{ v.from_value }}?;
                Ok(())
            }
        {%- endif %}
        {%- endfor %}
            _ => Err(::std::format!("variable {variable} of {{ c.type_name }} is not controllable")),
        }
    {%- else %}
        let _ = value;
        Err(::std::format!("variable {variable} of {{ c.type_name }} is not controllable"))
    {%- endif %}
    }

    fn get(&self, variable: usize) -> ::coolbot::Value {
    {%- if c.has_exposed() %}
        match variable {
        {%- for v in c.vars %}
        {%- if let Some(index) = v.spec_index %}
            {{ index }} => {{ v.to_value }},
        {%- endif %}
        {%- endfor %}
            _ => ::coolbot::Value::Unit,
        }
    {%- else %}
        let _ = variable;
        ::coolbot::Value::Unit
    {%- endif %}
    }
}
