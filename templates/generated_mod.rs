{%- import "macros.rs" as m -%}
{% call m::header(krate.header()) %}{% endcall %}
//! Generated from the `.cool` descriptions by `coolc`; regenerated on every compile.
//!
//! Each component module holds its configuration, variables, ports, user automaton
//! states, the `Behavior` trait the user implements and `component()`, which builds a
//! `coolbot::Component` from an implementation.
{% for module in modules %}
pub mod {{ module }};
{%- endfor %}

{% include "support.rs" %}
