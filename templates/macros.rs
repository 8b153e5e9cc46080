{#- Shared macros of the Rust templates. -#}
{% macro doc(lines) -%}
{% for line in lines %}
/// {{ line }}
{%- endfor %}
{%- endmacro %}

{% macro header(line) -%}
{{ line }}
{%- endmacro %}
