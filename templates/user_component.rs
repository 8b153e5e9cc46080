{#- Written in rustfmt's layout, like atomic.rs. -#}
//! The code of component `{{ c.type_name }}`: fill in the stubs.
//!
//! `coolc` wrote this file once and never overwrites it: when the description gains a
//! state, section, exception or pull output, `coolc compile` adds the new stubs at the
//! end of the `impl Behavior` block and leaves everything else as you wrote it. A
//! panic in a stub is caught by the runtime and takes the component to
//! `running_error`.

use crate::generated::{{ c.module }}::*;

/// What `{{ c.type_name }}` keeps between sections.
#[derive(Debug, Default)]
pub struct {{ c.user_struct }} {}
{% if c.methods.is_empty() %}
impl Behavior for {{ c.user_struct }} {}
{%- else %}
impl Behavior for {{ c.user_struct }} {
{%- for method in c.methods %}
{%- if !loop.first %}
{% endif %}
{{ l.stub(method) }}
{%- endfor %}
}
{%- endif %}
