{#- Written in rustfmt's layout: see coolc/src/layout.rs (`l`), which lays out the
    parts that depend on the description and says when the result needs a formatter. -#}
{%- import "macros.rs" as m -%}
{% call m::header(krate.header()) %}{% endcall %}
//! Generated code of compound component `{{ c.type_name }}`.
//!
//! Implement [`Supervisor`] (the supervisor's sections) and [`Parts`] (which
//! supervisor and which behaviours the instances run; the user file
//! `src/{{ c.module }}.rs` holds starters), then call [`component`] for a
//! `coolbot::Component` that runs the whole hierarchy, or [`builder`] to add to it
//! first. The supervisor's `when` rules are compiled below, one function each.
{%- if !c.doc.is_empty() %}
//!
{{- l.module_doc(&c.doc) }}
{%- endif %}

/// The compound's component type name.
pub const TYPE_NAME: &str = "{{ c.type_name }}";

/// The instances: `(instance name, component type name)`, in declaration order.
{{ l.pairs("INSTANCES", c.instance_pairs()) }}

/// The substitutes: `(instance, the instance it substitutes)`.
{{ l.pairs("SUBSTITUTES", c.substitute_pairs()) }}

/// The connections `(from, to)` as `instance.port`, in declaration order (those
/// through a converter included).
{{ l.pairs("CONNECTIONS", c.connection_pairs()) }}

/// The supervisor's own variables: observable, controllable and local (mapped
/// variables are the instances': the runtime reads and sets them there).
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

/// Initial values of the mapped controllable variables, for an enclosing compound's
/// instance overrides (`None`: the instance's own value).
#[derive(Clone, Debug, Default)]
{%- if c.mapped.is_empty() %}
pub struct Mapped {}
{%- else %}
pub struct Mapped {
{%- for m in c.mapped %}
    /// `controllable {{ m.cool_name }} = {{ m.target }};`
{{ l.mapped_decl(m) }}
{%- endfor %}
}
{%- endif %}

/// The supervisor's states (its user automaton).
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
    {{ l.all_supervisor_states(c) }}

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

/// The targets supervisor state `{{ s.cool_name }}` may choose (its `may` list): any
/// other transition is unrepresentable.
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

/// The supervisor's shape: its states, its own observable and controllable
/// variables, its timing, and the exported ports as the compound will have them
/// (`coolbot::CompoundBuilder::build` replaces them with the ports it exports, and
/// adds the mapped variables).
{{- l.item_doc(&c.notes) }}
{{ l.spec(&c.spec) }}

/// What a supervisor section sees.
pub struct Cx<'a> {
    /// The supervisor's own variables.
    pub vars: &'a mut Vars,
    /// The runtime side: time, result, end of task, period.
    pub rt: &'a mut ::coolbot::Context,
    /// The instances' monitors (their `state`, `user_state`, `result`, `error` and
    /// variables) as last seen.
    pub view: &'a ::coolbot::View,
    /// The instances, to command: `cx.instances.motion().suspend()?`.
    pub instances: Instances<'a>,
}

impl<'a> Cx<'a> {
    /// The context of a section, from the runtime's.
    #[doc(hidden)]
    pub fn __cool_new(vars: &'a mut Vars, cx: &'a mut ::coolbot::SupervisorCx<'_>) -> Cx<'a> {
        Cx {
            vars,
            rt: &mut *cx.rt,
            view: cx.view,
            instances: Instances {
                commander: &mut *cx.instances,
            },
        }
    }
}

/// The compound's instances, one typed handle each. Every command waits (boundedly)
/// for the instance's answer, and is a supervision step on the compound's monitoring
/// port; a refusal is a `coolbot::CommandError` whose `reason` says why.
{%- if c.handles.is_empty() %}
#[allow(dead_code, reason = "no instance to command")]
{%- endif %}
pub struct Instances<'a> {
    commander: &'a mut ::coolbot::Commander,
}

{% if c.handles.is_empty() -%}
impl Instances<'_> {}
{%- else -%}
impl Instances<'_> {
{%- for h in c.handles %}
{%- if !loop.first %}
{% endif %}
    /// Instance `{{ h.instance }}`, a `{{ h.component }}`.
{{ l.open_method(&h.accessor_signature()) }}
{{ l.handle_lit(&h.type_name, "commander", "&mut *self.commander") }}
    }
{%- endfor %}
}
{%- endif %}
{%- for h in c.handles %}

/// Commands to instance `{{ h.instance }}` (a `{{ h.component }}`), through its control
/// port.
pub struct {{ h.type_name }}<'a> {
    commander: &'a mut ::coolbot::Commander,
}

impl {{ h.type_name }}<'_> {
    /// Bring it to `suspended` (its user automaton frozen in its state).
    pub fn suspend(&mut self) -> ::core::result::Result<(), ::coolbot::CommandError> {
{{ l.instance_call("self.commander", "state", &h.instance, "::coolbot::Controllable::Suspended") }}
    }

    /// Bring it to `running` (resumed, or started again after an error).
    pub fn run(&mut self) -> ::core::result::Result<(), ::coolbot::CommandError> {
{{ l.instance_call("self.commander", "state", &h.instance, "::coolbot::Controllable::Running") }}
    }

    /// Bring it to `ready` (its user automaton left).
    pub fn ready(&mut self) -> ::core::result::Result<(), ::coolbot::CommandError> {
{{ l.instance_call("self.commander", "state", &h.instance, "::coolbot::Controllable::Ready") }}
    }

    /// Bring it to `dead` (its thread ends; it takes no command after this).
    pub fn dead(&mut self) -> ::core::result::Result<(), ::coolbot::CommandError> {
{{ l.instance_call("self.commander", "state", &h.instance, "::coolbot::Controllable::Dead") }}
    }
{%- for setter in h.setters %}

    /// Set its controllable variable `{{ setter.variable }}`.
{{ l.open_method(&setter.signature("::core::result::Result<(), ::coolbot::CommandError>")) }}
{{ l.setter_call("self.commander", "set", &h.instance, setter) }}
    }
{%- endfor %}
{%- for (method, variable) in h.observables %}

    /// `{{ variable }}` is observable: it has no setter, and a call does not compile
    /// (the compiler says why).
    #[doc(hidden)]
{{ l.open_method(&ir::Handle::refusal_signature(method)) }}
        Err(value.refuse())
    }
{%- endfor %}
{%- if let Some(config) = h.config %}

    /// Give it a new configuration (its `configuration` block).
{{ l.open_method(&ir::Handle::configure_signature(config)) }}
{{ l.instance_call("self.commander", "configure", &h.instance, "super::__cool_to_value(&configuration)") }}
    }
{%- endif %}

    /// Set its period.
    pub fn set_period(
        &mut self,
        period: ::core::time::Duration,
    ) -> ::core::result::Result<(), ::coolbot::CommandError> {
{{ l.instance_call("self.commander", "set_period", &h.instance, "period") }}
    }
{%- if let Some((quality, _)) = h.quality %}

    /// Set its quality level.
{{ l.open_method(&ir::Handle::quality_signature(quality, "::core::result::Result<(), ::coolbot::CommandError>")) }}
{{ l.instance_call("self.commander", "set_quality", &h.instance, "level.index()") }}
    }
{%- endif %}
}
{%- if let Some((quality, levels)) = h.quality %}

/// The quality levels of instance `{{ h.instance }}`, best first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum {{ quality }} {
{%- for (variant, level) in levels %}
    /// Level `{{ level }}`.
{{ l.variant(variant) }}
{%- endfor %}
}

impl {{ quality }} {
    /// The level's index (0 = best).
    pub fn index(self) -> usize {
        match self {
{%- for (variant, _) in levels %}
{{ l.index_arm(quality, variant, loop.index0) }}
{%- endfor %}
        }
    }
}
{%- endif %}
{%- endfor %}

/// The supervisor's code: one required method per section of its states. Its
/// transitions are the description's `when` rules; a section that fails takes the
/// compound to `running_error`.
{% if c.methods.is_empty() -%}
pub trait Supervisor: ::core::marker::Send + 'static {}
{%- else -%}
pub trait Supervisor: ::core::marker::Send + 'static {
{%- for method in c.methods %}
{%- if !loop.first %}
{{ "" }}
{%- endif %}
{{- l.member_doc(&method.doc) }}
{{ l.declaration(&method.signature) }}
{%- endfor %}
}
{%- endif %}

/// Where the compound's behaviours come from: its supervisor and one method per
/// instance (substitutes and redundant members included: every instance is built).
pub trait Parts {
    /// The supervisor.
    fn supervisor(&mut self) -> impl Supervisor;
{%- for i in c.instances %}
{%- if let Some(module) = i.module %}

    /// Instance `{{ i.name }}`, a `{{ i.component }}`.
{{ l.part_declaration(i, module) }}
{%- endif %}
{%- endfor %}
}

/// The compound `{{ c.type_name }}` named `name`, with its supervisor and instances
/// from `parts`: [`builder`], built.
pub fn component{{ c.generics() }}(
    name: impl ::core::convert::Into<::std::string::String>,
    parts: impl Parts,
) -> ::core::result::Result<::coolbot::Component, ::coolbot::CompoundError> {
    builder{{ c.turbofish() }}(name, parts)?.build()
}

/// Like [`component`], starting from the given own variables and initial values of
/// the mapped controllable ones (an enclosing compound's instance overrides use it).
pub fn component_with{{ c.generics() }}(
    name: impl ::core::convert::Into<::std::string::String>,
    parts: impl Parts,
    vars: Vars,
    mapped: Mapped,
) -> ::core::result::Result<::coolbot::Component, ::coolbot::CompoundError> {
    builder_with{{ c.turbofish() }}(name, parts, vars, mapped)?.build()
}

/// The runtime's builder for compound `{{ c.type_name }}` named `name`, with
/// everything the description says: the instances (behaviours from `parts`, with
/// their overrides), the connections, the exported ports, the mapped variables, the
/// `on error` policies, the substitutes, the redundant groups, the recovery queue and
/// the supervisor's rules. Fails when a nested compound cannot be built.
pub fn builder{{ c.generics() }}(
    name: impl ::core::convert::Into<::std::string::String>,
    parts: impl Parts,
) -> ::core::result::Result<::coolbot::CompoundBuilder, ::coolbot::CompoundError> {
    builder_with{{ c.turbofish() }}(name, parts, Vars::default(), Mapped::default())
}

{{ l.begin_item() }}
/// Like [`builder`], starting from the given own variables and initial values of the
/// mapped controllable ones.
pub fn builder_with{{ c.generics() }}(
    name: impl ::core::convert::Into<::std::string::String>,
    mut parts: impl Parts,
    vars: Vars,
    mapped: Mapped,
) -> ::core::result::Result<::coolbot::CompoundBuilder, ::coolbot::CompoundError> {
    {%- if c.mapped.is_empty() %}
    let _ = mapped;
    {%- endif %}
    let name = name.into();
    let vars = ::std::sync::Arc::new(::std::sync::Mutex::new(vars));
    let supervisor = __CoolSupervisor {
        supervisor: parts.supervisor(),
        vars{% if c.rules_use_vars() %}: ::std::sync::Arc::clone(&vars){% endif %},
    };
{%- if c.builder_notes() %}
    Ok(::coolbot::CompoundBuilder::new(name, supervisor)
{%- for step in c.builder_steps() %}
{%- let last = loop.last %}
{%- match step %}
{%- when ir::BuilderStep::Instance with (i, build) %}
    {%- if !i.unapplied.is_empty() %}
        // Not applied: overrides of `{{ i.name }}`'s mapped variables {{ i.unapplied_text() }} (set them through its control port once it runs).
    {%- endif %}
{{ l.instance_step(i, build, last) }}
{%- when ir::BuilderStep::Connect with (k) %}
{{ l.connect_step(k, last) }}
{%- when ir::BuilderStep::Step with (step) %}
{{ l.builder_step(step, last) }}
{%- when ir::BuilderStep::Rule with (r) %}
{{ l.rule_step(r, last) }}
{%- endmatch %}
{%- endfor %}
{%- if c.builder_steps().is_empty() %})
{%- endif %}
{%- else %}
{{ l.builder_chain(c) }}
{%- endif %}
}
{{ l.end_item() }}

/// Tells a network layer how to build `{{ c.type_name }}` on another node (its
/// supervisor and every instance, there) and bridge its exported ports (an instance
/// declared `on "node"`, `docs/distribution.md`): `make` builds one named as asked,
/// with this crate's parts.
pub fn register<R: ::coolbot::remote::Registrar>(
    registrar: &mut R,
    make: impl Fn(&str) -> ::core::result::Result<::coolbot::Component, ::coolbot::CompoundError>
    + Send
    + Sync
    + 'static,
) {
    registrar.compound(TYPE_NAME, ::std::boxed::Box::new(make));
{%- for (port, packet) in c.exported_ports %}
{{ l.register_port(packet, port) }}
{%- endfor %}
}
{%- for r in c.rules %}

{{ l.begin_item() }}
/// Rule {{ r.doc }}.
#[allow(
    clippy::eq_op,
    clippy::nonminimal_bool,
    clippy::bool_comparison,
    clippy::overly_complex_bool_expr,
    clippy::neg_cmp_op_on_partial_ord,
    clippy::comparison_to_empty
)]
{{ l.open_item_fn(&r.signature()) }}
{{ l.rule_body(r) }}
}
{{ l.end_item() }}
{%- endfor %}
{%- if c.locks() %}

/// The supervisor's variables, shared with the rules that read them.
fn __cool_lock(vars: &::std::sync::Mutex<Vars>) -> ::std::sync::MutexGuard<'_, Vars> {
    vars.lock()
        .unwrap_or_else(::std::sync::PoisonError::into_inner)
}
{%- endif %}

/// Adapts a [`Supervisor`] to the runtime's index-based `coolbot::Supervisor`.
struct __CoolSupervisor<S> {
    supervisor: S,
    vars: ::std::sync::Arc<::std::sync::Mutex<Vars>>,
}

impl<S: Supervisor> ::coolbot::Supervisor for __CoolSupervisor<S> {
    fn spec(&self) -> &'static ::coolbot::Spec {
        &SPEC
    }

    fn section(
        &mut self,
        state: usize,
        section: ::coolbot::Section,
        cx: &mut ::coolbot::SupervisorCx<'_>,
    ) -> ::coolbot::SectionResult {
    {%- if c.section_arms.is_empty() %}
        let _ = (state, section, cx, &self.supervisor);
        Ok(())
    {%- else %}
        let Self { supervisor, vars } = self;
        let mut vars = __cool_lock(vars);
        let mut cx = Cx::__cool_new(&mut vars, cx);
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
        cx: &mut ::coolbot::SupervisorCx<'_>,
    ) -> ::core::option::Option<usize> {
    {%- if c.choose_arms.is_empty() %}
        let _ = (state, cx, &self.supervisor);
        None
    {%- else %}
        let Self { supervisor, vars } = self;
        let mut vars = __cool_lock(vars);
        let mut cx = Cx::__cool_new(&mut vars, cx);
        match state {
{%- for arm in c.choose_arms %}
{{ l.supervisor_choose_arm(arm.state, &arm.method) }}
{%- endfor %}
            _ => None,
        }
    {%- endif %}
    }

    fn get(&self, variable: usize) -> ::coolbot::Value {
    {%- if c.has_exposed() %}
        let vars = __cool_lock(&self.vars);
        match variable {
{%- for v in c.vars %}
{%- if let Some(index) = v.spec_index %}
{{ l.get_arm(index, v) }}
{%- endif %}
{%- endfor %}
            _ => ::coolbot::Value::Unit,
        }
    {%- else %}
        let _ = (variable, &self.vars);
        ::coolbot::Value::Unit
    {%- endif %}
    }

    fn set(
        &mut self,
        variable: usize,
        value: &::coolbot::Value,
    ) -> ::core::result::Result<(), ::coolbot::ValueRefused> {
    {%- if c.has_controllable() %}
        let mut vars = __cool_lock(&self.vars);
        match variable {
{%- for v in c.vars %}
{%- if v.controllable() %}
            {{ v.spec_index.unwrap_or_default() }} => {
{{ l.set_locked_var(v) }}
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
}

/// The result of a [`Harness`] operation.
pub type HarnessResult<T> = ::core::result::Result<T, ::coolbot::harness::HarnessError>;

/// `{{ c.type_name }}`'s supervisor alone for tests (`coolbot::harness::supervisor`):
/// its states, sections and `when` rules run on the caller's thread on a virtual
/// clock, exactly as the compound's thread would run them, while its instances are
/// stand-ins whose state, user state, result, error, quality and variables the test
/// sets, and whose commands from the supervisor the test reads back. Fault policies,
/// the recovery queue, substitution, redundancy and adaptation need the instances
/// themselves: test them with [`component`] on threads.
pub struct Harness {
    inner: ::coolbot::harness::SupervisorHarness,
}

impl Harness {
    /// The compound with the supervisor of `parts` (its instances' behaviours are
    /// built but never run), started: `ready`, every instance `ready`.
{{ l.open_method(&c.harness_signature("new")) }}
{{ l.harness_builder(c) }}
            ::coolbot::harness::HarnessError::Compound(::std::boxed::Box::new(error))
        })?;
        Ok(Harness {
            inner: ::coolbot::harness::SupervisorHarness::new(builder)?,
        })
    }

    /// [`Harness::new`], then `running`: the supervisor enters its initial state and
    /// the instances run.
{{ l.open_method(&c.harness_signature("running")) }}
        let mut harness = Self::new{{ c.turbofish() }}(parts)?;
        harness.inner.run()?;
        Ok(harness)
    }

    /// The untyped harness: commands, the clock, the monitoring snapshot (with the
    /// supervision steps), the stand-ins by name.
    pub fn inner(&mut self) -> &mut ::coolbot::harness::SupervisorHarness {
        &mut self.inner
    }

    /// Runs the supervisor until nothing more is due at the current time.
    pub fn settle(&mut self) -> HarnessResult<()> {
        self.inner.settle()
    }

    /// Moves the virtual clock forward by `by`, timer by timer (periodic sections,
    /// `after` transitions), settling at each.
    pub fn advance(&mut self, by: ::core::time::Duration) -> HarnessResult<()> {
        self.inner.advance(by)
    }

    /// Commands `running` through the control port.
    pub fn run(&mut self) -> HarnessResult<()> {
        self.inner.run()
    }

    /// The compound's default state.
    pub fn state(&self) -> ::coolbot::State {
        self.inner.state()
    }

    /// The supervisor's state, while it has one.
    pub fn user_state(&self) -> ::core::option::Option<UserState> {
        let name = self.inner.user_state()?;
        UserState::ALL
            .into_iter()
            .find(|state| state.name() == name)
    }

    /// A variable of the compound (mapped, or the supervisor's own), by name.
    pub fn variable(&self, name: &str) -> ::core::option::Option<::coolbot::Value> {
        self.inner.variable(name)
    }

    /// The commands the supervisor gave its instances since the last call, in order.
    pub fn take_commands(
        &mut self,
    ) -> ::std::vec::Vec<(::std::string::String, ::coolbot::Command)> {
        self.inner.take_commands()
    }

    /// The stand-ins of the instances, to set what the rules read of them:
    /// `harness.instances().motion().set_state(coolbot::State::RunningError)?`.
    pub fn instances(&mut self) -> StandIns<'_> {
        StandIns {
            inner: &mut self.inner,
        }
    }
}

/// The stand-ins of a [`Harness`]'s instances, one method each.
{%- if c.handles.is_empty() %}
#[allow(dead_code, reason = "no instance to stand in for")]
{%- endif %}
pub struct StandIns<'a> {
    inner: &'a mut ::coolbot::harness::SupervisorHarness,
}

{% if c.handles.is_empty() -%}
impl StandIns<'_> {}
{%- else -%}
impl StandIns<'_> {
{%- for h in c.handles %}
{%- if !loop.first %}
{% endif %}
    /// The stand-in of instance `{{ h.instance }}` (a `{{ h.component }}`).
{{ l.open_method(&h.stand_in_accessor_signature()) }}
{{ l.handle_lit(&h.stand_in_type(), "inner", "&mut *self.inner") }}
    }
{%- endfor %}
}
{%- endif %}
{%- for h in c.handles %}

/// What the test sets of instance `{{ h.instance }}` (a `{{ h.component }}`) in a
/// [`Harness`]: each change is an event of the instance, and the supervisor's rules
/// that read it are evaluated at once.
pub struct {{ h.stand_in_type() }}<'a> {
    inner: &'a mut ::coolbot::harness::SupervisorHarness,
}

impl {{ h.stand_in_type() }}<'_> {
    /// Its default state is now `state` (e.g. `running_error`).
    pub fn set_state(&mut self, state: ::coolbot::State) -> HarnessResult<()> {
{{ l.instance_call("self.inner", "set_instance_state", &h.instance, "state") }}
    }

    /// Its user state is now the one named `user_state` (one of its automaton's), or
    /// none.
    pub fn set_user_state(
        &mut self,
        user_state: ::core::option::Option<&str>,
    ) -> HarnessResult<()> {
{{ l.instance_call("self.inner", "set_instance_user_state", &h.instance, "user_state") }}
    }

    /// Its task result is now `result`.
    pub fn set_result(&mut self, result: ::coolbot::TaskResult) -> HarnessResult<()> {
{{ l.instance_call("self.inner", "set_instance_result", &h.instance, "result") }}
    }

    /// Its last error is now `error`.
    pub fn set_error(&mut self, error: ::core::option::Option<&str>) -> HarnessResult<()> {
{{ l.instance_call("self.inner", "set_instance_error", &h.instance, "error") }}
    }

    /// Its variable `variable` (observable or controllable, by name) is now `value`.
    pub fn put(
        &mut self,
        variable: &str,
        value: impl ::core::convert::Into<::coolbot::Value>,
    ) -> HarnessResult<()> {
{{ l.instance_call("self.inner", "set_instance_variable", &h.instance, "variable, value") }}
    }
{%- for setter in h.setters %}

    /// Its controllable variable `{{ setter.variable }}` is now `value`.
{{ l.open_method(&setter.signature("HarnessResult<()>")) }}
{{ l.setter_call("self.inner", "set_instance_variable", &h.instance, setter) }}
    }
{%- endfor %}
{%- if let Some((quality, _)) = h.quality %}

    /// Its quality level is now `level`.
{{ l.open_method(&ir::Handle::quality_signature(quality, "HarnessResult<()>")) }}
{{ l.instance_call("self.inner", "set_instance_quality", &h.instance, "level.index()") }}
    }
{%- endif %}

    /// What it shows now.
    pub fn monitor(&self) -> HarnessResult<::coolbot::Monitor> {
{{ l.instance_call("self.inner", "instance", &h.instance, "") }}
    }
}
{%- endfor %}
