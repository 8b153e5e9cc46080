//! Components built from `.cool` descriptions with `coolc`.
//!
//! `generated/` is rewritten by every `coolc compile`; the other modules are yours
//! (`coolc` only adds stubs and module declarations for new members).

pub mod generated;
{% for module in modules %}
pub mod {{ module }};
{%- endfor %}
