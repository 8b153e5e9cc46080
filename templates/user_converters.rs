{#- Written in rustfmt's layout, like user_component.rs. -#}
//! The converters of the descriptions: fill in the stubs.
//!
//! `coolc` wrote this file once and never overwrites it; new converters get new stubs
//! at the end of the `impl Converters` block.

/// Implements the generated `Converters` trait; pass it to the compound builders.
#[derive(Debug, Default)]
pub struct Convert;

impl crate::generated::types::Converters for Convert {
{%- for method in methods %}
{%- if !loop.first %}
{% endif %}
{{ l.stub(method) }}
{%- endfor %}
}
