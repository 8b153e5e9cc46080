{%- import "macros.rs" as m -%}
{% call m::header(krate.sources_text()) %}{% endcall %}
//! Generated code of compound component `{{ c.type_name }}` (partial).
//!
//! [`build`] adds the compound's atomic instances to a `coolbot::System` (their
//! behaviors come from your [`Parts`]) and wires the declared connections. Not
//! generated yet: the supervisor automaton and its rules, exported ports, mapped
//! variables, instance timing overrides, error policies and the recovery queue, substitutes
//! (listed, not started), remote nodes (instances run locally) and compound instances
//! (nested compounds).
{%- if !c.doc.is_empty() %}
//!
{%- for line in c.doc %}
//! {{ line }}
{%- endfor %}
{%- endif %}

/// The behaviors of the compound's atomic instances, one method per instance that
/// [`build`] starts.
pub trait Parts {
{%- for i in c.instances %}
{%- if i.built() %}
{%- if let Some(module) = i.module %}
    /// The behavior of instance `{{ i.name }}`, a `{{ i.component }}`.
    fn {{ i.method }}(&mut self) -> impl super::{{ module }}::Behavior;
{%- endif %}
{%- endif %}
{%- endfor %}
}

/// Why [`build`] failed.
#[derive(Debug)]
pub enum BuildError {
    /// An instance could not be added.
    Add(::coolbot::Error),
    /// A connection was refused.
    Connect(::coolbot::ConnectError),
}

impl ::core::fmt::Display for BuildError {
    fn fmt(&self, f: &mut ::core::fmt::Formatter<'_>) -> ::core::fmt::Result {
        match self {
            BuildError::Add(error) => ::core::write!(f, "building {{ c.type_name }}: {error}"),
            BuildError::Connect(error) => ::core::write!(f, "connecting {{ c.type_name }}: {error}"),
        }
    }
}

impl ::std::error::Error for BuildError {}

impl ::core::convert::From<::coolbot::Error> for BuildError {
    fn from(error: ::coolbot::Error) -> Self {
        BuildError::Add(error)
    }
}

impl ::core::convert::From<::coolbot::ConnectError> for BuildError {
    fn from(error: ::coolbot::ConnectError) -> Self {
        BuildError::Connect(error)
    }
}

/// Adds the atomic instances to `system` as `{prefix}{instance}` with the behaviors
/// `parts` gives, then connects them as the description says. Returns their
/// handles in declaration order.
pub fn build{% if c.uses_converters %}<C: super::types::Converters + 'static>{% endif %}(system: &mut ::coolbot::System, prefix: &str, parts: &mut impl Parts) -> ::core::result::Result<::std::vec::Vec<::coolbot::Handle>, BuildError> {
{%- if !c.builds_any() %}
    let _ = parts;
{%- endif %}
    let handles = ::std::vec![
{%- for i in c.instances %}
{%- if i.built() %}
{%- if let Some(module) = i.module %}
{%- if !i.has_overrides() %}
        system.add(super::{{ module }}::component(::std::format!("{prefix}{{ i.name }}"), parts.{{ i.method }}()))?,
{%- else %}
        // Instance `{{ i.name }}` with the overrides of the description.
        system.add(super::{{ module }}::component_with(
            ::std::format!("{prefix}{{ i.name }}"),
            parts.{{ i.method }}(),
            {%- if i.config_overrides.is_empty() %}
            super::{{ module }}::Config::default(),
            {%- else %}
            super::{{ module }}::Config {
                {%- for (field, value) in i.config_overrides %}
                {{ field }}: {{ value }},
                {%- endfor %}
                ..super::{{ module }}::Config::default()
            },
            {%- endif %}
            {%- if i.var_overrides.is_empty() %}
            super::{{ module }}::Vars::default(),
            {%- else %}
            super::{{ module }}::Vars {
                {%- for (field, value) in i.var_overrides %}
                {{ field }}: {{ value }},
                {%- endfor %}
                ..super::{{ module }}::Vars::default()
            },
            {%- endif %}
        ))?,
{%- endif %}
{%- endif %}
{%- endif %}
{%- endfor %}
    ];
    connect{% if c.uses_converters %}::<C>{% endif %}(system, prefix)?;
    Ok(handles)
}

/// The compound's component type name.
pub const TYPE_NAME: &str = "{{ c.type_name }}";

/// The instances: `(instance name, component type name)`, in declaration order.
pub const INSTANCES: &[(&str, &str)] = &[
{%- for i in c.instances %}
    ("{{ i.name }}", "{{ i.component }}"),
{%- endfor %}
];

/// The substitutes: `(instance, the instance it substitutes)`.
pub const SUBSTITUTES: &[(&str, &str)] = &[
{%- for i in c.instances %}
{%- if let Some(other) = i.substitutes %}
    ("{{ i.name }}", "{{ other }}"),
{%- endif %}
{%- endfor %}
];

/// The connections `(from, to)` as `instance.port`, in declaration order (those
/// through a converter included).
pub const CONNECTIONS: &[(&str, &str)] = &[
{%- for k in c.connections %}
    ("{{ k.from }}", "{{ k.to }}"),
{%- endfor %}
];

/// Connects the instances, added to `system` under the names `{prefix}{instance}`
/// (`prefix` is `""` for plain instance names, or e.g. `"base_"`), as the
/// description says.
pub fn connect{% if c.uses_converters %}<C: super::types::Converters + 'static>{% endif %}(system: &mut ::coolbot::System, prefix: &str) -> ::core::result::Result<(), ::coolbot::ConnectError> {
{%- if c.connections.is_empty() %}
    let _ = (system, prefix);
{%- endif %}
{%- for k in c.connections %}
    {%- if let Some(via) = k.via %}
    system.connect_via(&::std::format!("{prefix}{{ k.from }}"), &::std::format!("{prefix}{{ k.to }}"), C::{{ via }})?;
    {%- else %}
    system.connect(&::std::format!("{prefix}{{ k.from }}"), &::std::format!("{prefix}{{ k.to }}"))?;
    {%- endif %}
{%- endfor %}
    Ok(())
}
