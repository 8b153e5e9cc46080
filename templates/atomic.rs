{#- Written in rustfmt's layout: see coolc/src/layout.rs (`l`), which lays out the
    parts that depend on the description and says when the result needs a formatter. -#}
{%- import "macros.rs" as m -%}
{% call m::header(krate.header()) %}{% endcall %}
//! Generated code of atomic component `{{ c.type_name }}`.
//!
//! Implement [`Behavior`] (the user file `src/{{ c.module }}.rs` holds the stubs) and
//! call [`component`] to get a `coolbot::Component` to add to a `coolbot::System`.
{%- if !c.doc.is_empty() %}
//!
{{- l.module_doc(&c.doc) }}
{%- endif %}

/// The `configuration` block: the default controllable variable `configuration`.
#[derive(Clone, Debug, PartialEq, ::serde::Serialize, ::serde::Deserialize{% if c.config_derives_default() %}, Default{% endif %})]
#[serde(default, deny_unknown_fields)]
{%- if c.config.is_empty() %}
pub struct Config {}
{%- else %}
pub struct Config {
{%- for f in c.config %}
{{- l.member_doc(&f.doc) }}
{%- if f.renamed() %}
    #[serde(rename = "{{ f.cool_name }}")]
{%- endif %}
{%- if let Some(adapter) = f.serde_with %}
{{ l.serde_with(adapter) }}
{%- endif %}
{{ l.decl(&f.name, &f.ty) }}
{%- endfor %}
}
{%- endif %}
{%- if !c.config_derives_default() %}

impl ::core::default::Default for Config {
    fn default() -> Self {
        {{ l.defaults(&c.config) }}
    }
}
{%- endif %}

/// The component's own variables: observable, controllable and local.
#[derive(Clone, Debug{% if c.vars_derive_default() %}, Default{% endif %})]
{%- if c.vars.is_empty() %}
pub struct Vars {}
{%- else %}
pub struct Vars {
{%- for v in c.vars %}
{{- l.member_doc(&v.field.doc) }}
    /// ({{ v.kind }} variable `{{ v.field.cool_name }}: {{ v.cool_ty }}`.)
{{ l.decl(&v.field.name, &v.field.ty) }}
{%- endfor %}
}
{%- endif %}
{%- if !c.vars_derive_default() %}

impl ::core::default::Default for Vars {
    fn default() -> Self {
        {{ l.var_defaults(&c.vars) }}
    }
}
{%- endif %}

/// The input ports, in declaration order.
{%- if c.inputs.is_empty() %}
pub struct Inputs {}
{%- else %}
pub struct Inputs {
{%- for p in c.inputs %}
{{- l.member_doc(&p.doc) }}
{{ l.decl(&p.field, &p.handle) }}
{%- endfor %}
}
{%- endif %}

/// The output ports, in declaration order.
{%- if c.outputs.is_empty() %}
pub struct Outputs {}
{%- else %}
pub struct Outputs {
{%- for p in c.outputs %}
{{- l.member_doc(&p.doc) }}
{{ l.decl(&p.field, &p.handle) }}
{%- endfor %}
}
{%- endif %}

/// The states of the user automaton (inside the default automaton's `running`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
{%- if c.states.is_empty() %}
pub enum UserState {}
{%- else %}
pub enum UserState {
{%- for s in c.states %}
{{- l.member_doc(&s.doc) }}
{{ l.variant(&s.variant) }}
{%- endfor %}
}
{%- endif %}

impl UserState {
    /// Every state, in declaration order.
    {{ l.all_states(c) }}

    /// The state's index in [`SPEC`]`.states`.
    pub fn index(self) -> usize {
{%- if c.states.is_empty() %}
        match self {}
{%- else %}
        match self {
{%- for s in c.states %}
{{ l.index_arm("UserState", &s.variant, loop.index0) }}
{%- endfor %}
        }
{%- endif %}
    }

    /// The state's name as written in the description.
    pub fn name(self) -> &'static str {
{%- if c.states.is_empty() %}
        match self {}
{%- else %}
        match self {
{%- for s in c.states %}
{{ l.name_arm(&s.variant, &s.cool_name) }}
{%- endfor %}
        }
{%- endif %}
    }
}
{%- for s in c.states %}
{%- if let Some(may_enum) = s.may_enum %}

/// The targets state `{{ s.cool_name }}` may choose (its `may` list): any other
/// transition is unrepresentable.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum {{ may_enum }} {
{%- for (variant, _, name) in s.may %}
    /// Go to state `{{ name }}`.
{{ l.variant(variant) }}
{%- endfor %}
}

impl {{ may_enum }} {
    /// The target state.
    pub fn state(self) -> UserState {
        match self {
{%- for (variant, index, _) in s.may %}
{{ l.may_arm(may_enum, variant, index) }}
{%- endfor %}
        }
    }
}
{%- endif %}
{%- endfor %}

/// The declared exceptions; `Exception::X.raise("why")` is a `coolbot::Fault` to
/// return from a section.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
{%- if c.exceptions.is_empty() %}
pub enum Exception {}
{%- else %}
pub enum Exception {
{%- for e in c.exceptions %}
{{- l.member_doc(&e.doc) }}
{{ l.variant(&e.variant) }}
{%- endfor %}
}
{%- endif %}

impl Exception {
    /// The exception's index in [`SPEC`]`.exceptions`.
    pub fn index(self) -> usize {
{%- if c.exceptions.is_empty() %}
        match self {}
{%- else %}
        match self {
{%- for e in c.exceptions %}
{{ l.index_arm("Exception", &e.variant, loop.index0) }}
{%- endfor %}
        }
{%- endif %}
    }

    /// A fault raising this exception with `message`: its continuity plan runs.
    pub fn raise(
        self,
        message: impl ::core::convert::Into<::std::string::String>,
    ) -> ::coolbot::Fault {
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
{%- for method in c.methods %}
{{ "" }}
{{- l.member_doc(&method.doc) }}
{{ l.declaration(&method.signature) }}
{%- endfor %}
}

/// The static shape of the component, read by the runtime.
{{- l.item_doc(&c.notes) }}
{{ l.spec(&c.spec) }}

/// Builds an unstarted `{{ c.type_name }}` named `name` running `behavior`.
pub fn component(
    name: impl ::core::convert::Into<::std::string::String>,
    behavior: impl Behavior,
) -> ::coolbot::Component {
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
    {{ l.ports_struct("inputs", "Inputs", &c.inputs) }}
    {{ l.ports_struct("outputs", "Outputs", &c.outputs) }}
{{ l.port_set(c) }}
    let glue = __CoolGlue {
        behavior,
        config,
        vars,
        inputs,
        outputs,
{%- if !c.published.is_empty() %}
        published: ::core::default::Default::default(),
{%- endif %}
    };
    ::coolbot::Component::new(name, ::std::boxed::Box::new(glue), ports)
    {%- if let Some(fields) = c.adaptation %}.with_adaptation(
        ::coolbot::AdaptConfig {
        {%- for (name, value) in fields %}
            {{ name }}: {{ value }},
        {%- endfor %}
            ..::coolbot::AdaptConfig::default()
        },
    )
    {%- endif %}
}

/// Tells a network layer how to build `{{ c.type_name }}` on another node and bridge
/// its ports (an instance declared `on "node"`, `docs/distribution.md`): `make`
/// builds one named as asked, with this crate's behaviour.
pub fn register<R: ::coolbot::remote::Registrar>(
    registrar: &mut R,
    make: impl Fn(&str) -> ::coolbot::Component + Send + Sync + 'static,
) {
    registrar.component(SPEC.type_name, ::std::boxed::Box::new(make));
{%- for p in c.inputs %}
    registrar.port::<{{ p.rust_packet }}>(SPEC.type_name, "{{ p.cool_name }}");
{%- endfor %}
{%- for p in c.outputs %}
    registrar.port::<{{ p.rust_packet }}>(SPEC.type_name, "{{ p.cool_name }}");
{%- endfor %}
}

/// Adapts a [`Behavior`] to the runtime's index-based `coolbot::Automaton`.
struct __CoolGlue<B> {
    behavior: B,
    config: Config,
    vars: Vars,
    inputs: Inputs,
    outputs: Outputs,
{%- if !c.published.is_empty() %}
    published: __CoolPublished,
{%- endif %}
}
{%- if !c.published.is_empty() %}

/// The variables the glue compares in their Rust types, as it last reported them to
/// the runtime (`None`: not yet).
#[derive(Default)]
struct __CoolPublished {
{%- for (name, ty) in c.published %}
{{ l.private_decl(name, ty) }}
{%- endfor %}
}
{%- endif %}

impl<B: Behavior> __CoolGlue<B> {
    /// The behavior, and what its sections see.
    fn parts<'a>(&'a mut self, rt: &'a mut ::coolbot::Context) -> (&'a mut B, Cx<'a>) {
        let Self {
            behavior,
            config,
            vars,
            inputs,
            outputs,
{%- if !c.published.is_empty() %}
            ..
{%- endif %}
        } = self;
        let cx = Cx {
            config,
            vars,
            inputs,
            outputs,
            rt,
        };
        (behavior, cx)
    }
}

impl<B: Behavior> ::coolbot::Automaton for __CoolGlue<B> {
    fn spec(&self) -> &'static ::coolbot::Spec {
        &SPEC
    }

    fn start(&mut self, rt: &mut ::coolbot::Context) -> ::coolbot::SectionResult {
        let (behavior, mut cx) = self.parts(rt);
        behavior.start(&mut cx)
    }

    fn stop(&mut self, rt: &mut ::coolbot::Context) {
        let (behavior, mut cx) = self.parts(rt);
        behavior.stop(&mut cx);
    }

    fn section(
        &mut self,
        state: usize,
        section: ::coolbot::Section,
        rt: &mut ::coolbot::Context,
    ) -> ::coolbot::SectionResult {
{%- if c.section_arms.is_empty() %}
        let _ = (state, section, rt);
        Ok(())
{%- else %}
        let (behavior, mut cx) = self.parts(rt);
        match (state, section) {
{%- for (pattern, call) in c.section_arms %}
{{ l.section_arm(pattern, call) }}
{%- endfor %}
            _ => Ok(()),
        }
{%- endif %}
    }

    fn choose(
        &mut self,
        state: usize,
        rt: &mut ::coolbot::Context,
    ) -> ::core::option::Option<usize> {
{%- if c.choose_arms.is_empty() %}
        let _ = (state, rt);
        None
{%- else %}
        let (behavior, mut cx) = self.parts(rt);
        match state {
{%- for arm in c.choose_arms %}
{{ l.choose_arm(arm.state, &arm.method) }}
{%- endfor %}
            _ => None,
        }
{%- endif %}
    }

    fn exception(&mut self, exception: usize, message: &str, rt: &mut ::coolbot::Context) {
{%- if c.exceptions.is_empty() %}
        let _ = (exception, message, rt);
{%- else if c.exceptions.len() == 1 %}
        let (behavior, mut cx) = self.parts(rt);
        if exception == 0 {
{%- for e in c.exceptions %}
{{ l.exception_call(&e.handler) }}
{%- endfor %}
        }
{%- else %}
        let (behavior, mut cx) = self.parts(rt);
        match exception {
{%- for e in c.exceptions %}
{{ l.exception_arm(loop.index0, &e.handler) }}
{%- endfor %}
            _ => {}
        }
{%- endif %}
    }

    fn answer(&mut self, output: usize, rt: &mut ::coolbot::Context) -> ::coolbot::SectionResult {
{%- if c.answer_arms.is_empty() %}
        let _ = (output, rt);
        Ok(())
{%- else %}
        let (behavior, mut cx) = self.parts(rt);
        match output {
{%- for arm in c.answer_arms %}
            {{ arm.output }} => {
{{ l.answer(arm) }}
                Ok(())
            }
{%- endfor %}
            _ => Ok(()),
        }
{%- endif %}
    }

    fn configure(
        &mut self,
        configuration: &::coolbot::Value,
    ) -> ::core::result::Result<(), ::coolbot::ValueRefused> {
        self.config = super::__cool_configure(&self.config, configuration)?;
        Ok(())
    }

    fn set(
        &mut self,
        variable: usize,
        value: &::coolbot::Value,
    ) -> ::core::result::Result<(), ::coolbot::ValueRefused> {
{%- if c.has_controllable() %}
        match variable {
{%- for v in c.vars %}
{%- if v.controllable() %}
            {{ v.spec_index.unwrap_or_default() }} => {
{{ l.set_var(v) }}
                Ok(())
            }
{%- endif %}
{%- endfor %}
            _ => Err(::coolbot::ValueRefused::not_settable(&SPEC, variable)),
        }
{%- else %}
        let _ = value;
        Err(::coolbot::ValueRefused::not_settable(&SPEC, variable))
{%- endif %}
    }

    fn get(&self, variable: usize) -> ::coolbot::Value {
{%- if c.has_exposed() %}
        match variable {
{%- for v in c.vars %}
{%- if let Some(index) = v.spec_index %}
{{ l.get_arm(index, v) }}
{%- endif %}
{%- endfor %}
            _ => ::coolbot::Value::Unit,
        }
{%- else %}
        let _ = variable;
        ::coolbot::Value::Unit
{%- endif %}
    }

    fn configuration(&self) -> ::core::option::Option<::coolbot::Value> {
        ::core::option::Option::Some(super::__cool_to_value(&self.config))
    }
{%- if !c.reports.is_empty() %}

    fn changed_variables(&mut self, changes: &mut ::coolbot::Changes<'_>) {
{%- for report in c.reports %}
{{ l.method_statement(report) }}
{%- endfor %}
    }
{%- endif %}
}
