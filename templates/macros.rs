{#- Shared macros of the Rust templates. -#}
{% macro doc(lines) -%}
{% for line in lines %}
/// {{ line }}
{%- endfor %}
{%- endmacro %}

{% macro header(line) -%}
{{ line }}
{%- endmacro %}

{#- A packet's struct and, when its defaults are not the fields' own, its `Default`. -#}
{% macro packet(p) -%}
#[derive(Clone, Debug, PartialEq, ::serde::Serialize, ::serde::Deserialize{% if p.derives_default() %}, Default{% endif %}
{%- endmacro %}
