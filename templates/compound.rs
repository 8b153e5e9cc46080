{%- import "macros.rs" as m -%}
{% call m::header(krate.sources_text()) %}{% endcall %}
//! Generated code of compound component `{{ c.type_name }}` (partial).
//!
//! This module lists the compound's instances and connections and wires the
//! connections between instances already added to a `coolbot::System`. The
//! supervisor, exported ports, mapped variables and error policies are not generated
//! yet.
{%- if !c.doc.is_empty() %}
//!
{%- for line in c.doc %}
//! {{ line }}
{%- endfor %}
{%- endif %}

/// The compound's component type name.
pub const TYPE_NAME: &str = "{{ c.type_name }}";

/// The instances: `(instance name, component type name)`, in declaration order.
pub const INSTANCES: &[(&str, &str)] = &[
{%- for i in c.instances %}
    ("{{ i.name }}", "{{ i.component }}"),
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
pub fn connect{% if c.uses_converters %}<C: super::types::Converters>{% endif %}(system: &mut ::coolbot::System, prefix: &str) -> ::core::result::Result<(), ::coolbot::ConnectError> {
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
