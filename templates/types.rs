{#- Written in rustfmt's layout: see coolc/src/layout.rs (`l`), which lays out the
    parts that depend on the description and says when the result needs a formatter. -#}
{%- import "macros.rs" as m -%}
{% call m::header(krate.header()) %}{% endcall %}
//! Packets, enums, extern packets and converters of the descriptions.
{%- for e in types.externs %}

{{ l.item_doc_lines(&e.doc) }}{{ l.type_alias(e) }}
{%- endfor %}
{%- for p in types.packets %}

{% call packet(p, 0) %}{% endcall %}
{%- endfor %}
{%- for e in types.enums %}

{{ l.item_doc_lines(&e.doc) }}{{ l.enum_derive(e) }}
{%- if e.variants.is_empty() %}
pub enum {{ e.name }} {}
{%- else %}
pub enum {{ e.name }} {
{%- for v in e.variants %}
{{- l.member_doc(&v.doc) }}
{%- if loop.first %}
    #[default]
{%- endif %}
{%- if v.name != v.cool_name %}
{{ l.variant_rename(&v.cool_name) }}
{%- endif %}
{{ l.variant(&v.name) }}
{%- endfor %}
}
{%- endif %}
{%- endfor %}
{%- if !types.converters.is_empty() %}

/// The converters of the descriptions: implement this trait in `src/converters.rs`.
///
/// A connection declared `via` a converter calls its method on every packet.
pub trait Converters {
{%- for c in types.converters %}
{{- l.member_doc(&c.doc) }}
    /// Converter `{{ c.cool_name }}`.
{{ l.declaration(&c.signature()) }}
{%- endfor %}
}
{%- endif %}
{%- if !types.ros.is_empty() %}

/// The ROS 2 message types the descriptions import (`import ros`) and every type
/// they reference, one module per package; the types module names each imported one.
#[allow(
    clippy::approx_constant,
    reason = "constants and defaults are the values the `.msg` files write"
)]
pub mod ros {
{%- for package in types.ros %}
{%- if !loop.first %}
{{ "" }}
{%- endif %}
    /// The ROS 2 package `{{ package.package }}`.
    pub mod {{ package.module }} {
{%- for message in package.messages %}
{%- let p = message.packet %}
{%- if !loop.first %}
{{ "" }}
{%- endif %}
{% call packet(p, 8) %}{% endcall %}
{%- if !message.constants.is_empty() %}

        impl {{ p.name }} {
{%- for c in message.constants %}
{{- l.ros_const_doc(&c.doc) }}
{{ l.ros_const(&c.lhs(), &c.value) }}
{%- endfor %}
        }
{%- endif %}

        impl ::coolbot::ros::RosType for {{ p.name }} {
{{ l.ros_const("const NAME: &'static str =", &message.name) }}
{{ l.ros_const("const DDS_NAME: &'static str =", &message.dds_name) }}
{{ l.ros_const("const TYPE_HASH: &'static str =", &message.hash) }}
{{ l.ros_const("const MESSAGE_DEFINITION: &'static str =", &message.definition) }}
        }
{%- endfor %}
    }
{%- endfor %}
}
{%- endif %}

{#- A packet's struct at `indent` and, when its defaults are not the fields' own,
    its `Default`. -#}
{% macro packet(p, indent) -%}
{{ l.doc_lines(&p.doc, indent) }}{{ l.packet_derive(p, indent) }}
{%- if p.fields.is_empty() %}
{{ l.open(indent) }}pub struct {{ p.name }} {}
{%- else %}
{{ l.open(indent) }}pub struct {{ p.name }} {
{%- for f in p.fields %}
{{- l.field_doc(&f.doc, indent) }}
{%- if f.renamed() %}
{{ l.field_rename(indent, &f.cool_name) }}
{%- endif %}
{%- if let Some(adapter) = f.serde_with %}
{{ l.field_serde_with(indent, adapter) }}
{%- endif %}
{{ l.field_decl(indent, f) }}
{%- endfor %}
{{ l.open(indent) }}}
{%- endif %}
{%- if p.writes_default() %}

{{ l.open(indent) }}impl ::core::default::Default for {{ p.name }} {
{{ l.open(indent) }}    fn default() -> Self {
{{ l.default_body(&p.fields, indent) }}
{{ l.open(indent) }}    }
{{ l.open(indent) }}}
{%- endif %}
{%- endmacro %}
