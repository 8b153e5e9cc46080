{#- Written in rustfmt's layout, like user_component.rs. -#}
//! The parts of compound `{{ c.type_name }}`: its supervisor's sections and which
//! behaviour each instance runs.
//!
//! `coolc` wrote this file once and never overwrites it: new supervisor sections get
//! stubs at the end of the `impl Supervisor` block, new instances new methods at the
//! end of the `impl Parts` block. Build the compound with the generated module's
//! `component` function from a `{{ c.user_struct }}` and add it to a
//! `coolbot::System` (or to another compound).

use crate::generated::{{ c.module }}::*;

/// What `{{ c.type_name }}`'s supervisor keeps between sections.
#[derive(Debug, Default)]
pub struct {{ c.supervisor_struct }} {}

{% if c.methods.is_empty() -%}
impl Supervisor for {{ c.supervisor_struct }} {}
{%- else -%}
impl Supervisor for {{ c.supervisor_struct }} {
{%- for method in c.methods %}
{%- if !loop.first %}
{% endif %}
{{ l.stub(method) }}
{%- endfor %}
}
{%- endif %}

/// The behaviours `{{ c.type_name }}`'s instances run: by default this crate's own.
#[derive(Debug, Default)]
pub struct {{ c.user_struct }} {}

{% if c.parts.is_empty() -%}
impl Parts for {{ c.user_struct }} {}
{%- else -%}
impl Parts for {{ c.user_struct }} {
{%- for method in c.parts %}
{%- if !loop.first %}
{% endif %}
{{ l.stub(method) }}
{%- endfor %}
}
{%- endif %}
