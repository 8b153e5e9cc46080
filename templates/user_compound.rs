{#- Written in rustfmt's layout (`l`: coolc/src/layout.rs), like atomic.rs. -#}
//! The parts of compound `{{ c.type_name }}`: which behavior each atomic instance runs.
//!
//! `coolc` wrote this file once and never overwrites it; new instances get new
//! methods at the end of the `impl Parts` block. Start the compound with
//! `crate::generated::{{ c.module }}::build{% if c.uses_converters %}::<crate::converters::Convert>{% endif %}(&mut system, "", &mut {{ c.user_struct }})`.

use crate::generated::{{ c.module }}::*;

/// The behaviors `{{ c.type_name }}`'s instances run: by default this crate's own.
#[derive(Debug, Default)]
pub struct {{ c.user_struct }};

impl Parts for {{ c.user_struct }} {
{%- for method in c.parts %}
{%- if !loop.first %}
{% endif %}
{{ l.stub(method) }}
{%- endfor %}
}
