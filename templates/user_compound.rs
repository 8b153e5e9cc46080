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

impl Supervisor for {{ c.supervisor_struct }} {
{%- for method in c.methods %}
{%- if !loop.first %}
{% endif %}
{% include "user_stub.rs" %}
{%- endfor %}
}

/// The behaviours `{{ c.type_name }}`'s instances run: by default this crate's own.
#[derive(Debug, Default)]
pub struct {{ c.user_struct }} {}

impl Parts for {{ c.user_struct }} {
{%- for method in c.parts %}
{%- if !loop.first %}
{% endif %}
{% include "user_stub.rs" %}
{%- endfor %}
}
